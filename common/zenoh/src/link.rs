//! The zenoh session of a host and the two channels of a host pair (the only module that names
//! zenoh). Synchronous: zenoh runs its own threads; callers poll with deadlines.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc;
use std::sync::Arc;
use std::time::{Duration, Instant};

use serde::de::DeserializeOwned;
use serde::Serialize;
use zenoh::qos::CongestionControl;
use zenoh::Wait;

use crate::frame::{decode, encode, DecodeError, JoinReply, JoinRequest};

/// What went wrong on the network side, naming the endpoint or key.
#[derive(Debug, thiserror::Error)]
pub enum NetError {
    /// The endpoint is not of zenoh's form (`tcp/10.77.0.1:7447`).
    #[error("endpoint {endpoint:?}: {detail} (expected zenoh's form, e.g. tcp/10.77.0.1:7447)")]
    Endpoint { endpoint: String, detail: String },
    /// zenoh refused to open the session (the address is not ours, the port is taken).
    #[error("cannot open a zenoh session on {endpoint}: {detail}")]
    Open { endpoint: String, detail: String },
    /// Declaring a publisher, subscriber or queryable failed.
    #[error("zenoh: cannot declare {what} on {key}: {detail}")]
    Declare {
        what: &'static str,
        key: String,
        detail: String,
    },
    /// A frame could not be sent.
    #[error("zenoh: cannot send on {key}: {detail}")]
    Send { key: String, detail: String },
    /// A frame could not be decoded.
    #[error("frame on {key}: {source}")]
    Decode {
        key: String,
        #[source]
        source: DecodeError,
    },
    /// Nobody answered a join request before the deadline.
    #[error("no orchestrator answered on {endpoint} within {waited_s:.0} s{hint}")]
    NoAnswer {
        endpoint: String,
        waited_s: f64,
        /// Under TLS a refused handshake looks like silence to the refused side.
        hint: &'static str,
    },
    /// The peer's liveliness token on `key` went away: its zenoh session closed (the process
    /// exited or was killed; its TCP connection closed). A partition closes nothing: the
    /// callers' silence deadline covers it.
    #[error("its zenoh session closed (liveliness token {key} gone)")]
    PeerGone { key: String },
}

/// After a peer's token goes, frames it sent just before may still be on their way (zenoh
/// carries declarations with a higher priority than data): they are delivered first, then the
/// loss is reported.
const GONE_GRACE: Duration = Duration::from_millis(150);

/// What a channel's receiving queue carries.
enum Event {
    Frame(Vec<u8>),
    /// The peer's liveliness token was undeclared.
    PeerGone,
}

/// The liveliness key that says the sender on `key` is alive.
fn alive_key(key: &str) -> String {
    format!("{key}/alive")
}

/// The zenoh key of the frames towards host `host`'s daemon.
pub fn down_key(team: &str, host: u32) -> String {
    format!("cdm/{team}/host/{host}/down")
}

/// The zenoh key of the frames from host `host`'s daemon.
pub fn up_key(team: &str, host: u32) -> String {
    format!("cdm/{team}/host/{host}/up")
}

/// The key of a join request for host `host` (`any`: the first free one) of `team` (`*`: any
/// team at the endpoint). With TLS, only host k's certificate may ask on `join/k`.
pub fn join_key(team: Option<&str>, host: Option<u32>) -> String {
    let slot = host.map_or_else(|| "any".to_owned(), |k| k.to_string());
    format!("cdm/{}/join/{slot}", team.unwrap_or("*"))
}

/// The key expressions host `host`'s daemon may use (zenoh's access control on the
/// orchestrator's side): its own two channels and its own join slot, nothing of another host.
pub fn host_key_exprs(host: u32) -> Vec<String> {
    vec![
        format!("cdm/*/host/{host}/**"),
        format!("cdm/*/join/{host}"),
    ]
}

/// The key expressions the orchestrator may use (access control on a daemon's side).
pub fn orchestrator_key_exprs() -> Vec<String> {
    vec!["cdm/**".to_owned()]
}

/// How a session proves who it is and checks its peers.
#[derive(Debug, Clone)]
pub enum Security {
    /// Mutual TLS (`tls/` endpoints): each side shows a certificate of the team's authority and
    /// checks the other's against it; zenoh's access control then lets each peer, known by its
    /// certificate's common name, use only its own keys.
    Tls {
        /// The team's authority certificate.
        ca: PathBuf,
        /// This side's certificate and key.
        cert: PathBuf,
        key: PathBuf,
        /// Who may connect, and on which keys.
        peers: Vec<Peer>,
    },
    /// Plain TCP (`tcp/` endpoints, `--insecure`): whoever reaches the port is a peer.
    Insecure,
}

/// A peer allowed by its certificate's common name, on these key expressions only.
#[derive(Debug, Clone)]
pub struct Peer {
    pub common_name: String,
    pub key_exprs: Vec<String>,
}

impl Security {
    /// The endpoint protocol this security goes with.
    pub fn protocol(&self) -> &'static str {
        match self {
            Security::Tls { .. } => "tls",
            Security::Insecure => "tcp",
        }
    }
}

/// Every message kind zenoh's access control knows (zenoh-config 1.10's `AclMessage`).
const ACL_MESSAGES: [&str; 9] = [
    "put",
    "delete",
    "declare_subscriber",
    "query",
    "declare_queryable",
    "reply",
    "liveliness_token",
    "declare_liveliness_subscriber",
    "liveliness_query",
];

/// zenoh's `access_control` section: deny by default; each peer, matched by its certificate's
/// common name, may exchange anything on its own key expressions, in both directions.
fn access_control(peers: &[Peer]) -> serde_json::Value {
    let (mut rules, mut subjects, mut policies) = (Vec::new(), Vec::new(), Vec::new());
    for (i, p) in peers.iter().enumerate() {
        rules.push(serde_json::json!({
            "id": format!("rule{i}"),
            "permission": "allow",
            "flows": ["ingress", "egress"],
            "messages": ACL_MESSAGES,
            "key_exprs": p.key_exprs,
        }));
        subjects.push(serde_json::json!({
            "id": format!("subject{i}"),
            "cert_common_names": [p.common_name],
        }));
        policies.push(serde_json::json!({
            "id": format!("policy{i}"),
            "rules": [format!("rule{i}")],
            "subjects": [format!("subject{i}")],
        }));
    }
    serde_json::json!({
        "enabled": true,
        "default_permission": "deny",
        "rules": rules,
        "subjects": subjects,
        "policies": policies,
    })
}

/// One zenoh session (peer mode, TLS or TCP, no multicast scouting: hosts find each other
/// through the one endpoint given on the command line, nothing else).
pub struct Net {
    session: zenoh::Session,
    endpoint: String,
    tls: bool,
}

impl Net {
    /// The orchestrator's side: listen on `endpoint`.
    pub fn listen(endpoint: &str, security: &Security) -> Result<Self, NetError> {
        Self::open(endpoint, "listen", security)
    }

    /// A daemon's side: connect to the orchestrator's `endpoint` (zenoh retries in the
    /// background until it answers; [`Net::join`] bounds the wait).
    pub fn connect(endpoint: &str, security: &Security) -> Result<Self, NetError> {
        Self::open(endpoint, "connect", security)
    }

    fn open(endpoint: &str, side: &str, security: &Security) -> Result<Self, NetError> {
        let bad = |detail: String| NetError::Endpoint {
            endpoint: endpoint.to_owned(),
            detail,
        };
        let parsed: zenoh::config::EndPoint = endpoint.parse().map_err(|e| bad(format!("{e}")))?;
        let protocol = parsed.protocol().as_str().to_owned();
        if protocol != security.protocol() {
            return Err(bad(format!(
                "a {protocol} endpoint where a {} one is needed",
                security.protocol()
            )));
        }
        let mut cfg = zenoh::Config::default();
        let set = |cfg: &mut zenoh::Config, k: &str, v: &str| {
            cfg.insert_json5(k, v).map_err(|e| NetError::Open {
                endpoint: endpoint.to_owned(),
                detail: format!("config {k}: {e}"),
            })
        };
        set(&mut cfg, "mode", "\"peer\"")?;
        let other = if side == "listen" {
            "connect"
        } else {
            "listen"
        };
        set(
            &mut cfg,
            &format!("{side}/endpoints"),
            &format!("[\"{endpoint}\"]"),
        )?;
        // A listener does not also listen on zenoh's default (every interface, a random port);
        // a connecting peer listens on nothing and keeps trying in the background while the
        // orchestrator is not up yet (zenoh's default for peers); `Net::join` bounds the wait.
        set(&mut cfg, &format!("{other}/endpoints"), "[]")?;
        set(&mut cfg, "scouting/multicast/enabled", "false")?;
        set(&mut cfg, "scouting/gossip/enabled", "false")?;
        set(&mut cfg, "adminspace/enabled", "false")?;
        if let Security::Tls {
            ca,
            cert,
            key,
            peers,
        } = security
        {
            let path = |p: &Path| serde_json::Value::from(p.to_string_lossy()).to_string();
            let tls = "transport/link/tls";
            set(&mut cfg, &format!("{tls}/root_ca_certificate"), &path(ca))?;
            for s in ["listen", "connect"] {
                set(&mut cfg, &format!("{tls}/{s}_certificate"), &path(cert))?;
                set(&mut cfg, &format!("{tls}/{s}_private_key"), &path(key))?;
            }
            set(&mut cfg, &format!("{tls}/enable_mtls"), "true")?;
            // Peers are known by the authority and their certificate's common name (access
            // control below), not by an address: the field network decides the address.
            set(&mut cfg, &format!("{tls}/verify_name_on_connect"), "false")?;
            set(
                &mut cfg,
                "access_control",
                &access_control(peers).to_string(),
            )?;
        }
        let session = zenoh::open(cfg).wait().map_err(|e| NetError::Open {
            endpoint: endpoint.to_owned(),
            detail: e.to_string(),
        })?;
        if let Security::Tls { peers, .. } = security {
            name_links(&session, peers, endpoint)?;
        }
        Ok(Self {
            session,
            endpoint: endpoint.to_owned(),
            tls: matches!(security, Security::Tls { .. }),
        })
    }

    /// The endpoint given on the command line.
    pub fn endpoint(&self) -> &str {
        &self.endpoint
    }

    /// A channel that sends on `out_key` and receives what arrives on `in_key`. Each side
    /// declares a liveliness token beside its out key and watches the other's: a peer whose
    /// session closes (killed, exited) is seen as soon as its TCP connection drops.
    pub fn channel(&self, out_key: &str, in_key: &str) -> Result<Channel, NetError> {
        let declare = |what, key: &str, e: zenoh::Error| NetError::Declare {
            what,
            key: key.to_owned(),
            detail: e.to_string(),
        };
        let (tx, rx) = mpsc::channel();
        let (token, watch) = self.liveliness(out_key, in_key, tx.clone())?;
        // Lockstep needs every frame: block (bounded by zenoh's own close timeout) rather than
        // drop under congestion; one publisher per direction keeps the frames in order.
        let publisher = self
            .session
            .declare_publisher(out_key.to_owned())
            .congestion_control(CongestionControl::Block)
            .wait()
            .map_err(|e| declare("a publisher", out_key, e))?;
        // An unbounded queue: zenoh's receiving thread never blocks on us, so two hosts that
        // both send can never wait on each other (a window bounds what is in flight).
        let received = Arc::new(AtomicU64::new(0));
        let counter = received.clone();
        let subscriber = self
            .session
            .declare_subscriber(in_key.to_owned())
            .callback(move |sample| {
                let bytes = sample.payload().to_bytes().into_owned();
                counter.fetch_add(bytes.len() as u64, Ordering::Relaxed);
                let _ = tx.send(Event::Frame(bytes));
            })
            .wait()
            .map_err(|e| declare("a subscriber", in_key, e))?;
        Ok(Channel {
            publisher,
            _subscriber: subscriber,
            _token: token,
            _watch: watch,
            rx,
            ahead: None,
            gone_since: None,
            peer_key: alive_key(in_key),
            out_key: out_key.to_owned(),
            in_key: in_key.to_owned(),
            sent: 0,
            received,
        })
    }

    /// Declares this side's liveliness token beside `out_key` and watches the peer's beside
    /// `in_key`: its undeclaration (the peer's session closed) is queued as [`Event::PeerGone`].
    fn liveliness(
        &self,
        out_key: &str,
        in_key: &str,
        tx: mpsc::Sender<Event>,
    ) -> Result<
        (
            zenoh::liveliness::LivelinessToken,
            zenoh::pubsub::Subscriber<()>,
        ),
        NetError,
    > {
        let declare = |what, key: &str, e: zenoh::Error| NetError::Declare {
            what,
            key: key.to_owned(),
            detail: e.to_string(),
        };
        let alive = alive_key(out_key);
        let token = self
            .session
            .liveliness()
            .declare_token(alive.clone())
            .wait()
            .map_err(|e| declare("a liveliness token", &alive, e))?;
        let peer_key = alive_key(in_key);
        // History: a peer whose token is already up is seen at once; only its Delete matters.
        let watch = self
            .session
            .liveliness()
            .declare_subscriber(peer_key.clone())
            .history(true)
            .callback(move |sample| {
                if sample.kind() == zenoh::sample::SampleKind::Delete {
                    let _ = tx.send(Event::PeerGone);
                }
            })
            .wait()
            .map_err(|e| declare("a liveliness subscriber", &peer_key, e))?;
        Ok((token, watch))
    }

    /// Serves join requests for `team` (see [`JoinDesk`]): on every slot (`join/*`), or, with
    /// `hosts: Some(k)`, on `join/1` .. `join/k` one by one, so that access control shows each
    /// host only its own slot (a host that does not see a queryable cannot even ask).
    pub fn join_desk(&self, team: &str, hosts: Option<u32>) -> Result<JoinDesk, NetError> {
        let keys: Vec<String> = match hosts {
            None => vec![format!("cdm/{team}/join/*")],
            Some(k) => (1..=k).map(|h| join_key(Some(team), Some(h))).collect(),
        };
        let mut queryables = Vec::new();
        for key in keys {
            let q = self
                .session
                .declare_queryable(key.clone())
                .wait()
                .map_err(|e| NetError::Declare {
                    what: "a queryable",
                    key: key.clone(),
                    detail: e.to_string(),
                })?;
            queryables.push(q);
        }
        Ok(JoinDesk {
            queryables,
            team: team.to_owned(),
        })
    }

    /// Asks to join, retrying every half second until an orchestrator answers or `within`
    /// passes. The request goes to any team's orchestrator at the endpoint, so that one of
    /// another team answers with a refusal naming both teams rather than with silence.
    pub fn join(&self, request: &JoinRequest, within: Duration) -> Result<JoinReply, NetError> {
        let key = join_key(None, request.host);
        let until = Instant::now() + within;
        let payload = encode(request);
        while Instant::now() < until {
            let replies = self
                .session
                .get(key.clone())
                .payload(payload.clone())
                .timeout(Duration::from_millis(500))
                .wait()
                .map_err(|e| NetError::Declare {
                    what: "a query",
                    key: key.clone(),
                    detail: e.to_string(),
                })?;
            while let Ok(reply) = replies.recv() {
                if let Ok(sample) = reply.result() {
                    let bytes = sample.payload().to_bytes();
                    return decode(&bytes).map_err(|source| NetError::Decode {
                        key: key.clone(),
                        source,
                    });
                }
            }
            std::thread::sleep(Duration::from_millis(200));
        }
        // The orchestrator's TLS refuses a certificate of another authority, or of a host
        // number not in its team, during the handshake: this side only sees no answer.
        let hint = if self.tls {
            " (over TLS: is this host's certificate from the team's authority, and is its \
             host number in the team? The orchestrator's log names the refused handshake)"
        } else {
            ""
        };
        Err(NetError::NoAnswer {
            endpoint: self.endpoint.clone(),
            waited_s: within.as_secs_f64(),
            hint,
        })
    }
}

/// Logs every TLS link as it opens, by its peer's address and certificate: a team's peer by
/// name (info), any other certificate of the team's authority as refused (warn), since zenoh's
/// access control denies it everything without a word. A certificate of another authority
/// never gets this far: the handshake fails, logged by the TLS link with the peer's address.
fn name_links(session: &zenoh::Session, peers: &[Peer], endpoint: &str) -> Result<(), NetError> {
    let names: Vec<String> = peers.iter().map(|p| p.common_name.clone()).collect();
    session
        .info()
        .link_events_listener()
        .callback(move |event| {
            if event.kind() != zenoh::sample::SampleKind::Put {
                return;
            }
            let link = event.link();
            let name = link.auth_identifier().unwrap_or("");
            if names.iter().any(|n| n == name) {
                tracing::info!("{name:?} connected from {}", link.dst());
            } else {
                tracing::warn!(
                    "a peer at {} with certificate {name:?} connected: not one of this \
                     session's peers {names:?}, so it can neither read nor send anything",
                    link.dst()
                );
            }
        })
        .background()
        .wait()
        .map_err(|e| NetError::Open {
            endpoint: endpoint.to_owned(),
            detail: format!("link events: {e}"),
        })
}

/// One direction pair between the orchestrator and one daemon: frames out on one key, frames in
/// from the other, both counted in bytes (for BENCHMARKS).
pub struct Channel {
    publisher: zenoh::pubsub::Publisher<'static>,
    _subscriber: zenoh::pubsub::Subscriber<()>,
    _token: zenoh::liveliness::LivelinessToken,
    _watch: zenoh::pubsub::Subscriber<()>,
    rx: mpsc::Receiver<Event>,
    /// An event taken by [`Channel::wait`], returned by the next receive.
    ahead: Option<Event>,
    /// When the peer's liveliness token went (reported after [`GONE_GRACE`]).
    gone_since: Option<Instant>,
    peer_key: String,
    out_key: String,
    in_key: String,
    sent: u64,
    received: Arc<AtomicU64>,
}

impl Channel {
    /// Sends one frame.
    pub fn send<T: Serialize>(&mut self, frame: &T) -> Result<(), NetError> {
        let bytes = encode(frame);
        self.sent += bytes.len() as u64;
        self.publisher
            .put(bytes)
            .wait()
            .map_err(|e| NetError::Send {
                key: self.out_key.clone(),
                detail: e.to_string(),
            })
    }

    /// The next frame received, if any (never blocks); [`NetError::PeerGone`] once the peer's
    /// session closed and every frame it sent before was delivered.
    pub fn try_recv<T: DeserializeOwned>(&mut self) -> Result<Option<T>, NetError> {
        while let Some(event) = self.ahead.take().or_else(|| self.rx.try_recv().ok()) {
            match event {
                Event::Frame(bytes) => return self.decode(&bytes).map(Some),
                Event::PeerGone => {
                    self.gone_since.get_or_insert_with(Instant::now);
                }
            }
        }
        match self.gone_since {
            Some(t) if t.elapsed() >= GONE_GRACE => Err(NetError::PeerGone {
                key: self.peer_key.clone(),
            }),
            _ => Ok(None),
        }
    }

    /// Sleeps until a frame arrives or `timeout` passes (the frame stays for the next receive).
    pub fn wait(&mut self, timeout: Duration) {
        if self.ahead.is_none() {
            let timeout = match self.gone_since {
                // Wake when the grace is over, to report the loss.
                Some(t) => timeout.min(GONE_GRACE.saturating_sub(t.elapsed())),
                None => timeout,
            };
            self.ahead = self.rx.recv_timeout(timeout).ok();
        }
    }

    fn decode<T: DeserializeOwned>(&self, bytes: &[u8]) -> Result<T, NetError> {
        decode(bytes).map_err(|source| NetError::Decode {
            key: self.in_key.clone(),
            source,
        })
    }

    /// Payload bytes sent and received so far.
    pub fn bytes(&self) -> (u64, u64) {
        (self.sent, self.received.load(Ordering::Relaxed))
    }
}

/// The orchestrator's join desk: zenoh queryables on `cdm/<team>/join/<slot>`.
pub struct JoinDesk {
    queryables:
        Vec<zenoh::query::Queryable<zenoh::handlers::FifoChannelHandler<zenoh::query::Query>>>,
    team: String,
}

/// A join request waiting for its answer.
pub struct PendingJoin {
    query: zenoh::query::Query,
    /// What the daemon asked (an undecodable request is answered with a refusal at once).
    pub request: JoinRequest,
    /// The host number of the key it asked on (`None`: `join/any`). With TLS, access control
    /// lets only that host's certificate ask there.
    pub slot: Option<u32>,
    /// Where the answer goes (the asked key, with this team's name).
    reply_key: String,
}

impl JoinDesk {
    /// The next join request, if any; an undecodable one is refused here (a foreign peer).
    pub fn poll(&self) -> Option<PendingJoin> {
        let next = || {
            self.queryables
                .iter()
                .find_map(|q| q.try_recv().ok().flatten())
        };
        while let Some(query) = next() {
            let asked = query
                .key_expr()
                .as_str()
                .rsplit('/')
                .next()
                .unwrap_or_default();
            let slot = asked.parse::<u32>().ok();
            let reply_key = join_key(Some(&self.team), slot);
            let bytes = query.payload().map(|p| p.to_bytes().into_owned());
            match decode::<JoinRequest>(&bytes.unwrap_or_default()) {
                Ok(request) => {
                    return Some(PendingJoin {
                        query,
                        request,
                        slot,
                        reply_key,
                    })
                }
                Err(e) => {
                    let no = JoinReply::Refused(format!("undecodable join request: {e}"));
                    let _ = query.reply(reply_key, encode(&no)).wait();
                }
            }
        }
        None
    }
}

impl PendingJoin {
    /// Answers the request.
    pub fn answer(self, reply: &JoinReply) {
        if let Err(e) = self.query.reply(self.reply_key, encode(reply)).wait() {
            tracing::warn!(error = %e, "cannot answer a join request");
        }
    }
}
