//! The command channel of a running team (`orchestrator command TEAM ...`): a Unix socket in
//! this user's iceoryx2 root (owner-only, checked before iceoryx2 writes anything, like the
//! team's other files), one JSON line asked and one answered per connection. The launch loop
//! polls it between its turns without blocking the grants; the peer's uid is read from the
//! socket (`SO_PEERCRED`) and anyone but the team's owner is refused.

use std::io::{BufRead, BufReader, Read, Write};
use std::os::fd::AsRawFd;
use std::os::unix::fs::PermissionsExt;
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::PathBuf;
use std::time::Duration;

use cdm_iox::TeamName;
use serde::{Deserialize, Serialize};

/// How long the team waits for a request's line, and to hand its answer over: a client that
/// stalls holds the flight no longer than this.
const REQUEST_WITHIN: Duration = Duration::from_millis(500);

/// The longest request line read.
const MAX_REQUEST_BYTES: u64 = 64 * 1024;

/// One command to the team, as `orchestrator command` sends it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CommandRequest {
    /// `hold`, `resume`, `land` or `goto`.
    pub command: String,
    /// `goto`: the primary leaders' new positions, ascending id order.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub goals: Option<Vec<[f64; 3]>>,
    /// `goto`: the travel time, seconds.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub travel_s: Option<f64>,
}

impl CommandRequest {
    /// `land` (an interrupt under `--on-interrupt land` asks for it too).
    pub fn land() -> Self {
        CommandRequest {
            command: "land".into(),
            goals: None,
            travel_s: None,
        }
    }
}

/// What became of a command, as its exit code tells it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Answered {
    /// Certified SAFE: the team flies it from the switch tick.
    Accepted,
    /// Certified UNSAFE: nothing changed.
    Unsafe,
    /// Malformed, or it does not apply to the team now: nothing changed.
    BadInput,
    /// The team cannot take a command now (its flight is ending, or this pacing takes none).
    Unavailable,
}

/// The team's answer.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CommandAnswer {
    pub answer: Answered,
    /// The tick the command takes (or would have taken) effect at.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub switch_tick: Option<u64>,
    /// Its simulation time, seconds.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub t_switch_s: Option<f64>,
    /// For a person: the certificate's summary, or why not.
    pub text: String,
    /// How long the team took to decide it (reading the request, certifying), milliseconds.
    #[serde(default)]
    pub decided_ms: f64,
}

impl CommandAnswer {
    /// An answer with no switch.
    pub fn without_switch(answer: Answered, text: String) -> Self {
        CommandAnswer {
            answer,
            switch_tick: None,
            t_switch_s: None,
            text,
            decided_ms: 0.0,
        }
    }
}

/// Where team `team`'s channel is.
pub fn socket_path(team: &TeamName) -> PathBuf {
    PathBuf::from(cdm_iox::iox2_root()).join(format!("{team}.command"))
}

/// Removes the channels of teams whose orchestrator died without removing them (killed): the
/// sockets in the iceoryx2 root nothing listens on. Returns their teams' names.
pub fn remove_dead_channels() -> Vec<String> {
    let Ok(entries) = std::fs::read_dir(cdm_iox::iox2_root()) else {
        return Vec::new();
    };
    let mut removed = Vec::new();
    for e in entries.flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        let Some(team) = name.strip_suffix(".command") else {
            continue;
        };
        let dead = matches!(
            UnixStream::connect(e.path()),
            Err(err) if err.kind() == std::io::ErrorKind::ConnectionRefused
        );
        if dead && std::fs::remove_file(e.path()).is_ok() {
            removed.push(team.to_string());
        }
    }
    removed
}

/// Why the channel could not be opened or used.
#[derive(Debug, thiserror::Error)]
pub enum ChannelError {
    /// The socket could not be made.
    #[error("the command channel {path}: {source}")]
    Open {
        path: PathBuf,
        source: std::io::Error,
    },
}

/// The listening end, owned by the launch; its socket is removed when it is dropped.
#[derive(Debug)]
pub struct CommandChannel {
    listener: UnixListener,
    path: PathBuf,
}

impl CommandChannel {
    /// Opens team `team`'s channel. Call it once the team's name is this launch's (its ports
    /// created): a socket left by an orchestrator that died is that team's, and replaced.
    pub fn open(team: &TeamName) -> Result<Self, ChannelError> {
        let path = socket_path(team);
        let err = |source| ChannelError::Open {
            path: path.clone(),
            source,
        };
        match std::fs::remove_file(&path) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => return Err(err(e)),
            _ => {}
        }
        let listener = UnixListener::bind(&path).map_err(err)?;
        // The root is owner-only already; the socket is too.
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o600)).map_err(err)?;
        listener.set_nonblocking(true).map_err(err)?;
        Ok(CommandChannel { listener, path })
    }

    /// Answers the request waiting, if one is, with `handle`; true when one was answered. Never
    /// waits for a connection.
    pub fn serve_one(&self, handle: impl FnOnce(Request) -> CommandAnswer) -> bool {
        let Some((pending, request)) = self.take_one() else {
            return false;
        };
        pending.answer(handle(request));
        true
    }

    /// The request waiting, if one is, with the connection to answer it on later (a real-time
    /// command is answered once the leaders acknowledged it). A peer that is not the owner is
    /// answered at once, and one that asks nothing is let go. Never waits for a connection.
    pub fn take_one(&self) -> Option<(PendingAnswer, Request)> {
        let stream = match self.listener.accept() {
            Ok((s, _)) => s,
            Err(e) => {
                if e.kind() != std::io::ErrorKind::WouldBlock {
                    tracing::warn!("command channel {}: {e}", self.path.display());
                }
                return None;
            }
        };
        let pending = PendingAnswer {
            stream,
            started: std::time::Instant::now(),
        };
        match owner_only(&pending.stream).and_then(|()| read_request(&pending.stream)) {
            // A peer that asks nothing (`orchestrator clean` looking for live channels).
            Ok(None) => None,
            Err(why) => {
                pending.answer(CommandAnswer::without_switch(
                    Answered::Unavailable,
                    why.to_string(),
                ));
                None
            }
            Ok(Some(request)) => Some((pending, request)),
        }
    }
}

/// A request read whose answer is still to come.
#[derive(Debug)]
pub struct PendingAnswer {
    stream: UnixStream,
    started: std::time::Instant,
}

impl PendingAnswer {
    /// Sends `answer` (its `decided_ms` the time since the request was taken).
    pub fn answer(self, mut answer: CommandAnswer) {
        answer.decided_ms = self.started.elapsed().as_secs_f64() * 1e3;
        if let Err(e) = write_line(&self.stream, &answer) {
            tracing::warn!("command channel: the answer was not delivered: {e}");
        }
    }
}

impl Drop for CommandChannel {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.path);
    }
}

/// Why a connection to the channel brought no request to decide (its answer says so).
#[derive(Debug, thiserror::Error)]
pub enum PeerError {
    /// The peer's credentials cannot be read.
    #[error("the command's sender is unknown: {0}")]
    Unknown(std::io::Error),
    /// Another user than the team's owner.
    #[error("only the team's owner (uid {owner}) commands it, not uid {peer}")]
    NotOwner { owner: u32, peer: u32 },
    /// The socket refused its read deadline.
    #[error("{0}")]
    Deadline(std::io::Error),
    /// The request's line could not be read (in time).
    #[error("the request was not read: {0}")]
    Read(std::io::Error),
}

/// A request line that is not a command (the peer's input).
#[derive(Debug, thiserror::Error)]
#[error("the request: {0}")]
pub struct MalformedRequest(serde_json::Error);

/// Refuses a peer that is not this user.
fn owner_only(stream: &UnixStream) -> Result<(), PeerError> {
    let mut cred = libc::ucred {
        pid: 0,
        uid: u32::MAX,
        gid: u32::MAX,
    };
    let mut len = std::mem::size_of::<libc::ucred>() as libc::socklen_t;
    // SAFETY: getsockopt(2) writes at most `len` bytes into `cred`, which we own.
    let rc = unsafe {
        libc::getsockopt(
            stream.as_raw_fd(),
            libc::SOL_SOCKET,
            libc::SO_PEERCRED,
            (&mut cred as *mut libc::ucred).cast(),
            &mut len,
        )
    };
    // SAFETY: getuid(2) cannot fail and touches no memory of ours.
    let me = unsafe { libc::getuid() };
    if rc != 0 {
        return Err(PeerError::Unknown(std::io::Error::last_os_error()));
    }
    if cred.uid != me {
        tracing::warn!(uid = cred.uid, "a command from another user was refused");
        return Err(PeerError::NotOwner {
            owner: me,
            peer: cred.uid,
        });
    }
    Ok(())
}

/// A request as read: the command, or why it is none (malformed: bad input).
pub type Request = Result<CommandRequest, MalformedRequest>;

/// The request of a peer that may command the team: `None` when it asked nothing; `Err` when
/// the line could not be read at all.
fn read_request(stream: &UnixStream) -> Result<Option<Request>, PeerError> {
    stream
        .set_read_timeout(Some(REQUEST_WITHIN))
        .map_err(PeerError::Deadline)?;
    let mut line = String::new();
    BufReader::new(stream.take(MAX_REQUEST_BYTES))
        .read_line(&mut line)
        .map_err(PeerError::Read)?;
    if line.is_empty() {
        return Ok(None);
    }
    Ok(Some(
        serde_json::from_str(line.trim_end()).map_err(MalformedRequest),
    ))
}

fn write_line<T: Serialize>(mut stream: &UnixStream, value: &T) -> std::io::Result<()> {
    stream.set_write_timeout(Some(REQUEST_WITHIN))?;
    let mut text = serde_json::to_string(value).map_err(std::io::Error::other)?;
    text.push('\n');
    stream.write_all(text.as_bytes())
}

/// Why a command got no answer.
#[derive(Debug, thiserror::Error)]
pub enum SendError {
    /// Nothing listens on the team's channel.
    #[error("no team {team} takes commands here ({path}: {source}); is it launched on this host by this user, with model vehicles?")]
    NoTeam {
        team: TeamName,
        path: PathBuf,
        source: std::io::Error,
    },
    /// The team did not answer in time.
    #[error("team {team} did not answer within {within:?} (the command may still be decided: see its commands.json)")]
    NoAnswer { team: TeamName, within: Duration },
    /// The connection failed midway, or the answer was not one.
    #[error("team {team}: {detail}")]
    Broken { team: TeamName, detail: String },
}

/// Sends `request` to team `team` and waits at most `within` for its answer.
pub fn send(
    team: &TeamName,
    request: &CommandRequest,
    within: Duration,
) -> Result<CommandAnswer, SendError> {
    let path = socket_path(team);
    let broken = |detail: String| SendError::Broken {
        team: team.clone(),
        detail,
    };
    let stream = UnixStream::connect(&path).map_err(|source| SendError::NoTeam {
        team: team.clone(),
        path: path.clone(),
        source,
    })?;
    write_line(&stream, request).map_err(|e| broken(format!("the command was not sent: {e}")))?;
    stream
        .set_read_timeout(Some(within))
        .map_err(|e| broken(e.to_string()))?;
    let mut line = String::new();
    match BufReader::new(&stream).read_line(&mut line) {
        Ok(0) => {
            return Err(broken(
                "the team closed the channel without an answer".into(),
            ))
        }
        Ok(_) => {}
        Err(e)
            if matches!(
                e.kind(),
                std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
            ) =>
        {
            return Err(SendError::NoAnswer {
                team: team.clone(),
                within,
            })
        }
        Err(e) => return Err(broken(format!("no answer: {e}"))),
    }
    serde_json::from_str(line.trim_end())
        .map_err(|e| broken(format!("an answer that is not one: {e}")))
}
