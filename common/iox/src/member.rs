//! A team member's side (one member process): opens the services the orchestrator created.

use std::collections::BTreeMap;
use std::time::Duration;

use iceoryx2::identifiers::UniqueNodeId;
use iceoryx2::port::listener::{Listener, ListenerCreateError};
use iceoryx2::port::notifier::{Notifier, NotifierCreateError};
use iceoryx2::port::publisher::{Publisher, PublisherCreateError};
use iceoryx2::port::subscriber::{Subscriber, SubscriberCreateError};
use iceoryx2::prelude::*;
use iceoryx2::service::builder::event::EventOpenError;
use iceoryx2::service::builder::publish_subscribe::PublishSubscribeOpenError;
use iceoryx2::service::port_factory::event::PortFactory as EventService;
use iceoryx2::service::port_factory::publish_subscribe::PortFactory as PubSubService;

use super::{
    create_named_node, init_logging, service_error, service_name, wait_on, TeamName, TeamProcess,
    TransportError, CLOCK_BUFFER,
};
use crate::messages::{ClockMsg, StateMsg};
use crate::resend::{Held, Recent, RESEND_STATES_KEY};
use crate::wire::{ClockWire, StateBatch, StateBatchWire};

/// A neighbour's state service, read by this member.
struct NeighborReader {
    _service: PubSubService<ipc::Service, StateBatchWire, ()>,
    subscriber: Subscriber<ipc::Service, StateBatchWire, ()>,
    /// A repair's new in-neighbour: its states wait for its repeats (`crate::resend`).
    held: Held,
}

/// A wake event this member notifies.
struct WakeWriter {
    _service: EventService<ipc::Service>,
    notifier: Notifier<ipc::Service>,
}

/// One member's ports: the publisher of its `state/<id>`, subscribers on its in-neighbours' states
/// and the clock, the listener of its `wake/<id>`, and notifiers on its out-neighbours' wake
/// events and `wake/orch`. Fields drop in order: ports first, the node last.
pub struct MemberPorts {
    team: TeamName,
    id: u32,
    publisher: Publisher<ipc::Service, StateBatchWire, ()>,
    /// States published quietly and not yet sent: they go out as one sample when the batch is
    /// full or the readers are woken ([`Self::notify_readers`]), whichever comes first.
    pending: StateBatch,
    /// The last states published, sent again at a repair's hand-over (`crate::resend`).
    recent: Recent,
    _state: PubSubService<ipc::Service, StateBatchWire, ()>,
    neighbors: BTreeMap<u32, NeighborReader>,
    clock_subscriber: Subscriber<ipc::Service, ClockWire, ()>,
    _clock: PubSubService<ipc::Service, ClockWire, ()>,
    listener: Listener<ipc::Service>,
    _wake: EventService<ipc::Service>,
    out_wakes: BTreeMap<u32, WakeWriter>,
    wake_orch: WakeWriter,
    /// The orchestrator's node, found through the clock's publisher when opening.
    orchestrator: Option<UniqueNodeId>,
    /// Held, never read: the node must outlive the ports created from it.
    _node: Node<ipc::Service>,
}

impl MemberPorts {
    /// Opens member `id`'s ports in `team`. Fails with [`TransportError::ScenarioMismatch`] when the
    /// team flies another scenario (checked before any port is taken), [`TransportError::TeamNotFound`] when no
    /// orchestrator created the team, [`TransportError::NotInTeam`] when `id` (or an in-neighbour)
    /// has no state service, [`TransportError::AgentAlreadyRunning`] when another process holds
    /// member `id`, and [`TransportError::NotANeighbor`] when the team's layout has no such edge.
    pub fn open(
        team: &TeamName,
        id: u32,
        scenario_hash: u64,
        in_neighbors: &[u32],
        out_neighbors: &[u32],
    ) -> Result<Self, TransportError> {
        let node = team.node_name(TeamProcess::Agent(id));
        Self::open_as(team, id, node, scenario_hash, in_neighbors, out_neighbors)
    }

    /// Opens member `id`'s ports on behalf of a member that runs on another host (`host`), for the
    /// bridge that carries its states over the network. The ports are a member's
    /// (so the team's layout and limits hold unchanged); only the node's name differs,
    /// `cdm/<team>/host/<host>/agent/<id>`, so `subscriptions.json` shows which edges cross
    /// hosts. `in_neighbors` and `out_neighbors` are the member's neighbours on this host only.
    pub fn open_relay(
        team: &TeamName,
        host: u32,
        id: u32,
        scenario_hash: u64,
        in_neighbors: &[u32],
        out_neighbors: &[u32],
    ) -> Result<Self, TransportError> {
        let node = team.relay_node_name(host, id);
        Self::open_as(team, id, node, scenario_hash, in_neighbors, out_neighbors)
    }

    fn open_as(
        team: &TeamName,
        id: u32,
        node_name: String,
        scenario_hash: u64,
        in_neighbors: &[u32],
        out_neighbors: &[u32],
    ) -> Result<Self, TransportError> {
        init_logging();
        let who = TeamProcess::Agent(id);
        let node = create_named_node(team, who, node_name)?;
        // The clock first: its absence means the whole team is missing.
        let clock = open_clock(&node, team, who)?;
        // The team's scenario must be ours before we take any slot in it.
        check_scenario_hash(&clock, team, id, scenario_hash)?;
        // Then the member's identity: its exclusive publisher slot and wake-up listener.
        let own = OwnPorts::open(&node, team, id)?;
        let neighbors = open_neighbors(&node, team, id, in_neighbors)?;
        let mut out_wakes = BTreeMap::new();
        for &peer in out_neighbors {
            let name = team.wake_service(peer);
            let writer = open_wake_writer(&node, team, who, &name, (peer, false))?;
            out_wakes.insert(peer, writer);
        }
        let name = team.orchestrator_wake_service();
        let wake_orch = open_wake_writer(&node, team, who, &name, (id, true))?;
        // The clock subscriber last: once the orchestrator counts it (and the notifier on
        // wake/orch), every other port of this member is in place.
        let clock_subscriber = clock
            .subscriber_builder()
            .buffer_size(CLOCK_BUFFER)
            .create()
            .map_err(|e| service_error(team, who, &team.clock_service(), "create subscriber", e))?;
        let mut orchestrator = None;
        clock.dynamic_config().list_publishers(|p| {
            orchestrator = Some(p.node_id);
            CallbackProgression::Stop
        });
        Ok(Self {
            team: team.clone(),
            id,
            publisher: own.publisher,
            pending: StateBatch::EMPTY,
            recent: Recent::new(resend_states(&own.state)),
            _state: own.state,
            neighbors,
            clock_subscriber,
            _clock: clock,
            listener: own.listener,
            _wake: own.wake,
            out_wakes,
            wake_orch,
            orchestrator,
            _node: node,
        })
    }

    /// The member id.
    pub fn id(&self) -> u32 {
        self.id
    }

    /// The team.
    pub fn team(&self) -> &TeamName {
        &self.team
    }

    /// Publishes this member's state (with the states published quietly before it), then (after
    /// the send returned) wakes its out-neighbours and the orchestrator. Returns how many
    /// subscribers the sample reached. A state carrying another member's id is refused.
    pub fn publish(&mut self, msg: StateMsg) -> Result<usize, TransportError> {
        let reached = self.publish_quietly(msg)?;
        let flushed = self.flush()?;
        self.notify_readers()?;
        Ok(reached.max(flushed))
    }

    /// Publishes `msg` without waking anyone: the caller must call [`Self::notify_readers`]
    /// before it sleeps, so every published state is followed by a wake-up (notify on block).
    /// The state joins the batch of the states published since the last wake-up; a full batch
    /// is sent at once (returns how many subscribers it reached), otherwise it waits for
    /// [`Self::notify_readers`] or [`Self::flush`] (returns 0).
    pub fn publish_quietly(&mut self, msg: StateMsg) -> Result<usize, TransportError> {
        if msg.id != self.id {
            return Err(TransportError::ForeignState {
                team: self.team.clone(),
                id: self.id,
                msg_id: msg.id,
                service: self.team.state_service(self.id),
            });
        }
        self.recent.push(msg);
        if self.pending.push(msg) {
            return self.flush();
        }
        Ok(0)
    }

    /// Sends the pending batch, if any, as one sample, without waking anyone; returns how many
    /// subscribers it reached.
    pub fn flush(&mut self) -> Result<usize, TransportError> {
        let reached = self.send(self.pending)?;
        self.pending.clear();
        Ok(reached)
    }

    /// Sends `batch` as one sample (nothing when it is empty); returns how many subscribers it
    /// reached.
    fn send(&self, batch: StateBatch) -> Result<usize, TransportError> {
        let states = batch.states();
        if states.is_empty() {
            return Ok(0);
        }
        let service = || self.team.state_service(self.id);
        let mut sample = self
            .publisher
            .loan_uninit()
            .map_err(|e| self.error(&service(), "loan", e))?;
        let dst: *mut StateBatchWire = sample.payload_mut().as_mut_ptr();
        // SAFETY: `dst` is the loaned chunk, sized and aligned for a `StateBatchWire` (`Wire` is
        // `repr(transparent)` over `StateBatch`) and part of a shared-memory segment, so its
        // bytes are initialized memory (zero-filled by the kernel, or an earlier sample's);
        // `write_prefix` sets the length and the states readers read.
        let sample = unsafe {
            StateBatch::write_prefix(dst.cast(), states, batch.flags);
            sample.assume_init()
        };
        sample.send().map_err(|e| self.error(&service(), "send", e))
    }

    /// Sends the states published quietly, then wakes every out-neighbour and the orchestrator
    /// (events merge: cheap to repeat).
    pub fn notify_readers(&mut self) -> Result<(), TransportError> {
        self.flush()?;
        for (&peer, wake) in &self.out_wakes {
            wake.notifier
                .notify()
                .map_err(|e| self.error(&self.team.wake_service(peer), "notify", e))?;
        }
        self.wake_orch
            .notifier
            .notify()
            .map_err(|e| self.error(&self.team.orchestrator_wake_service(), "notify", e))?;
        Ok(())
    }

    /// Drains every in-neighbour's subscriber (neighbours in id order, each one's states oldest
    /// first) into `f`; returns how many states were delivered.
    pub fn receive_neighbors(
        &mut self,
        mut f: impl FnMut(StateMsg),
    ) -> Result<usize, TransportError> {
        let mut count = 0;
        let (team, who) = (&self.team, TeamProcess::Agent(self.id));
        for (&peer, reader) in &mut self.neighbors {
            while let Some(sample) = reader
                .subscriber
                .receive()
                .map_err(|e| service_error(team, who, &team.state_service(peer), "receive", e))?
            {
                count += reader.held.take(&sample.payload().0, &mut f);
            }
        }
        Ok(count)
    }

    /// Drains the clock and returns the newest grant received since the last call, if any.
    pub fn latest_clock(&mut self) -> Result<Option<ClockMsg>, TransportError> {
        let mut newest = None;
        while let Some(sample) = self
            .clock_subscriber
            .receive()
            .map_err(|e| self.error(&self.team.clock_service(), "receive", e))?
        {
            newest = Some(sample.payload().0);
        }
        Ok(newest)
    }

    /// Drains the clock, every message oldest first (loss notices must not be skipped).
    pub fn receive_clock(&mut self, mut f: impl FnMut(ClockMsg)) -> Result<usize, TransportError> {
        let mut count = 0;
        while let Some(sample) = self
            .clock_subscriber
            .receive()
            .map_err(|e| self.error(&self.team.clock_service(), "receive", e))?
        {
            f(sample.payload().0);
            count += 1;
        }
        Ok(count)
    }

    /// After a loss: subscribes to `subscribe`'s states (a new subscriber gets the states its
    /// publisher published before, sent again at its [`Self::hand_over`]) and opens notifiers on `notify`'s wake events. The orchestrator sized
    /// the services for the repairs (`TeamLayout::with_repair_links`).
    pub fn connect(&mut self, subscribe: &[u32], notify: &[u32]) -> Result<(), TransportError> {
        let who = TeamProcess::Agent(self.id);
        for &peer in subscribe {
            if self.neighbors.contains_key(&peer) {
                continue;
            }
            let name = self.team.state_service(peer);
            let service = open_state(&self._node, &self.team, who, peer)?;
            let subscriber = service.subscriber_builder().create().map_err(|e| match e {
                SubscriberCreateError::ExceedsMaxSupportedSubscribers => {
                    not_a_neighbor(&self.team, self.id, peer, &name, "subscriber")
                }
                e => self.error(&name, "create subscriber", e),
            })?;
            let reader = NeighborReader {
                _service: service,
                subscriber,
                held: Held::until_resent(),
            };
            self.neighbors.insert(peer, reader);
        }
        for &peer in notify {
            if self.out_wakes.contains_key(&peer) {
                continue;
            }
            let name = self.team.wake_service(peer);
            let writer = open_wake_writer(&self._node, &self.team, who, &name, (peer, false))?;
            self.out_wakes.insert(peer, writer);
        }
        Ok(())
    }

    /// True when the states this port sends again at a hand-over go back to `tick` without a
    /// gap (a relay standing in for another host's member: see `Recent::reaches`).
    pub fn history_reaches(&self, tick: u64) -> bool {
        self.recent.reaches(tick)
    }

    /// Every new link of a repair is connected: the publisher connects its new subscribers,
    /// sends its last states again (every reader gets them; a repeated state changes nothing,
    /// `crate::resend`), then wakes every reader.
    pub fn hand_over(&mut self) -> Result<(), TransportError> {
        use iceoryx2::port::update_connections::UpdateConnections;
        self.flush()?;
        self.publisher
            .update_connections()
            .map_err(|e| self.error(&self.team.state_service(self.id), "update connections", e))?;
        for batch in self.recent.batches() {
            self.send(batch)?;
        }
        self.notify_readers()
    }

    /// Blocks until a neighbour or the orchestrator notifies `wake/<id>` or `timeout` passes;
    /// true when woken. Then drain both the clock and the neighbours: notifications merge.
    pub fn wait(&mut self, timeout: Duration) -> Result<bool, TransportError> {
        // Nothing published may stay behind while this member sleeps (callers notify first;
        // this keeps a forgotten notify from holding states back until the next one).
        self.flush()?;
        wait_on(
            &self.listener,
            (timeout, |_| {}),
            &self.team,
            TeamProcess::Agent(self.id),
            || self.team.wake_service(self.id),
        )
    }

    /// True while the orchestrator's node is alive. Checks only the few nodes attached to this
    /// member's state service (its out-neighbours, itself and the orchestrator, whose subscriber
    /// is there for the team's lifetime; with relayed wake-ups it holds no port on most wake
    /// events), so it is cheap enough for every half second. A registry that cannot be read
    /// counts as dead (fail-safe: stop).
    pub fn orchestrator_alive(&self) -> bool {
        let Some(orchestrator) = self.orchestrator else {
            return false;
        };
        let mut alive = false;
        let listed = self._state.nodes(|state| {
            if *state.node_id() == orchestrator {
                alive = matches!(state, NodeState::Alive(_));
                return CallbackProgression::Stop;
            }
            CallbackProgression::Continue
        });
        if let Err(e) = listed {
            tracing::warn!(team = %self.team, id = self.id, error = ?e,
                "cannot read the node registry; treating the orchestrator as gone");
            return false;
        }
        alive
    }

    fn error(&self, service: &str, op: &'static str, e: impl std::fmt::Debug) -> TransportError {
        service_error(&self.team, TeamProcess::Agent(self.id), service, op, e)
    }
}

/// The member's own ports: the one publisher of `state/<id>` and the one listener of `wake/<id>`
/// (a second process for the same id finds either taken).
struct OwnPorts {
    state: PubSubService<ipc::Service, StateBatchWire, ()>,
    publisher: Publisher<ipc::Service, StateBatchWire, ()>,
    wake: EventService<ipc::Service>,
    listener: Listener<ipc::Service>,
}

impl OwnPorts {
    fn open(node: &Node<ipc::Service>, team: &TeamName, id: u32) -> Result<Self, TransportError> {
        let who = TeamProcess::Agent(id);
        let name = team.state_service(id);
        let state = open_state(node, team, who, id)?;
        let publisher = state
            .publisher_builder()
            .max_loaned_samples(1)
            .create()
            .map_err(|e| match e {
                PublisherCreateError::ExceedsMaxSupportedPublishers => {
                    already_running(team, id, &name, "publisher")
                }
                e => service_error(team, who, &name, "create publisher", e),
            })?;
        let name = team.wake_service(id);
        let wake = open_event(node, team, who, &name)?;
        let listener = wake.listener_builder().create().map_err(|e| match e {
            ListenerCreateError::ExceedsMaxSupportedListeners => {
                already_running(team, id, &name, "listener")
            }
            e => service_error(team, who, &name, "create listener", e),
        })?;
        Ok(Self {
            state,
            publisher,
            wake,
            listener,
        })
    }
}

/// How many states member's `state` service asks it to send again at a hand-over (0 when the
/// team has no repairs or the attribute is missing).
fn resend_states(state: &PubSubService<ipc::Service, StateBatchWire, ()>) -> usize {
    use iceoryx2::service::attribute::AttributeKey;
    let Ok(key) = AttributeKey::try_from(RESEND_STATES_KEY) else {
        return 0;
    };
    state
        .attributes()
        .key_value(&key, 0)
        .and_then(|v| v.to_string().parse().ok())
        .unwrap_or(0)
}

/// Opens the team's clock service; a missing one means no orchestrator created the team.
fn open_clock(
    node: &Node<ipc::Service>,
    team: &TeamName,
    who: TeamProcess,
) -> Result<PubSubService<ipc::Service, ClockWire, ()>, TransportError> {
    let name = team.clock_service();
    node.service_builder(&service_name(team, who, &name)?)
        .publish_subscribe::<ClockWire>()
        .open()
        .map_err(|e| match e {
            PublishSubscribeOpenError::DoesNotExist => TransportError::TeamNotFound {
                team: team.clone(),
                who,
                service: name.clone(),
            },
            e => service_error(team, who, &name, "open service", e),
        })
}

/// Refuses a team whose clock service carries another scenario hash than `scenario_hash`.
fn check_scenario_hash(
    clock: &PubSubService<ipc::Service, ClockWire, ()>,
    team: &TeamName,
    id: u32,
    scenario_hash: u64,
) -> Result<(), TransportError> {
    use iceoryx2::service::attribute::AttributeKey;
    let name = team.clock_service();
    let key = AttributeKey::try_from(super::SCENARIO_HASH_KEY)
        .map_err(|e| service_error(team, TeamProcess::Agent(id), &name, "attribute key", e))?;
    let team_hash = clock
        .attributes()
        .key_value(&key, 0)
        .map(|v| v.to_string())
        .unwrap_or_else(|| "none".into());
    if team_hash != super::scenario_hash_value(scenario_hash) {
        return Err(TransportError::ScenarioMismatch {
            team: team.clone(),
            id,
            mine: scenario_hash,
            team_hash,
        });
    }
    Ok(())
}

/// One subscriber per in-neighbour's state service; a service without a free subscriber slot
/// for us means we are not that member's reader.
fn open_neighbors(
    node: &Node<ipc::Service>,
    team: &TeamName,
    id: u32,
    in_neighbors: &[u32],
) -> Result<BTreeMap<u32, NeighborReader>, TransportError> {
    let who = TeamProcess::Agent(id);
    let mut neighbors = BTreeMap::new();
    for &peer in in_neighbors {
        let name = team.state_service(peer);
        let service = open_state(node, team, who, peer)?;
        let subscriber = service.subscriber_builder().create().map_err(|e| match e {
            SubscriberCreateError::ExceedsMaxSupportedSubscribers => {
                not_a_neighbor(team, id, peer, &name, "subscriber")
            }
            e => service_error(team, who, &name, "create subscriber", e),
        })?;
        neighbors.insert(
            peer,
            NeighborReader {
                _service: service,
                subscriber,
                held: Held::default(),
            },
        );
    }
    Ok(neighbors)
}

/// Opens `state/<owner>`: a missing service means `owner` is not in the team; a full node table
/// on one's own service means another process is this member.
fn open_state(
    node: &Node<ipc::Service>,
    team: &TeamName,
    who: TeamProcess,
    owner: u32,
) -> Result<PubSubService<ipc::Service, StateBatchWire, ()>, TransportError> {
    let name = team.state_service(owner);
    node.service_builder(&service_name(team, who, &name)?)
        .publish_subscribe::<StateBatchWire>()
        .open()
        .map_err(|e| match (e, who) {
            (PublishSubscribeOpenError::DoesNotExist, _) => TransportError::NotInTeam {
                team: team.clone(),
                id: owner,
                service: name.clone(),
            },
            (PublishSubscribeOpenError::ExceedsMaxNumberOfNodes, TeamProcess::Agent(me))
                if me == owner =>
            {
                already_running(team, owner, &name, "node")
            }
            (PublishSubscribeOpenError::ExceedsMaxNumberOfNodes, TeamProcess::Agent(me)) => {
                not_a_neighbor(team, me, owner, &name, "node")
            }
            (e, _) => service_error(team, who, &name, "open service", e),
        })
}

/// Opens an event service of the team (a missing one means the team is incomplete).
pub(crate) fn open_event(
    node: &Node<ipc::Service>,
    team: &TeamName,
    who: TeamProcess,
    name: &str,
) -> Result<EventService<ipc::Service>, TransportError> {
    node.service_builder(&service_name(team, who, name)?)
        .event()
        .open()
        .map_err(|e| match e {
            EventOpenError::DoesNotExist => TransportError::TeamNotFound {
                team: team.clone(),
                who,
                service: name.to_owned(),
            },
            e => service_error(team, who, name, "open service", e),
        })
}

/// Opens a notifier on `name` (the wake event of `peer`, or `wake/orch`); a full notifier table
/// means the layout has no edge from this member to `peer`.
fn open_wake_writer(
    node: &Node<ipc::Service>,
    team: &TeamName,
    who: TeamProcess,
    name: &str,
    (peer, orchestrator): (u32, bool),
) -> Result<WakeWriter, TransportError> {
    let service = open_event(node, team, who, name)?;
    let mut builder = service.notifier_builder();
    if orchestrator {
        // `wake/orch` learns who woke it (crate::notified): the id + 1 when the service has room.
        let max = service.static_config().event_id_max_value();
        builder = builder.default_event_id(EventId::new(crate::notified::event_id_of(peer, max)));
    }
    let notifier = builder.create().map_err(|e| match (e, who) {
        (NotifierCreateError::ExceedsMaxSupportedNotifiers, TeamProcess::Agent(me)) => {
            not_a_neighbor(team, me, peer, name, "notifier")
        }
        (e, _) => service_error(team, who, name, "create notifier", e),
    })?;
    Ok(WakeWriter {
        _service: service,
        notifier,
    })
}

fn already_running(team: &TeamName, id: u32, service: &str, port: &'static str) -> TransportError {
    TransportError::AgentAlreadyRunning {
        team: team.clone(),
        id,
        service: service.to_owned(),
        port,
    }
}

fn not_a_neighbor(
    team: &TeamName,
    id: u32,
    peer: u32,
    service: &str,
    port: &'static str,
) -> TransportError {
    TransportError::NotANeighbor {
        team: team.clone(),
        id,
        peer,
        service: service.to_owned(),
        port,
    }
}

impl Drop for MemberPorts {
    /// Sends what was published quietly: a member that stops between a publish and its next
    /// wake-up keeps those states visible while its ports live, as when every state was a sample.
    fn drop(&mut self) {
        if let Err(e) = self.flush() {
            tracing::debug!(team = %self.team, id = self.id, error = %e,
                "cannot send the last states while closing the ports");
        }
    }
}

impl cdm_runtime::seams::MemberTransport for MemberPorts {
    type Error = TransportError;

    fn publish(&mut self, msg: StateMsg) -> Result<usize, TransportError> {
        MemberPorts::publish(self, msg)
    }

    fn publish_quietly(&mut self, msg: StateMsg) -> Result<usize, TransportError> {
        MemberPorts::publish_quietly(self, msg)
    }

    fn notify_readers(&mut self) -> Result<(), TransportError> {
        MemberPorts::notify_readers(self)
    }

    fn flush(&mut self) -> Result<(), TransportError> {
        MemberPorts::flush(self).map(drop)
    }

    fn receive_neighbors(&mut self, f: impl FnMut(StateMsg)) -> Result<usize, TransportError> {
        MemberPorts::receive_neighbors(self, f)
    }

    fn latest_clock(&mut self) -> Result<Option<ClockMsg>, TransportError> {
        MemberPorts::latest_clock(self)
    }

    fn wait(&mut self, timeout: Duration) -> Result<bool, TransportError> {
        MemberPorts::wait(self, timeout)
    }

    fn orchestrator_alive(&self) -> bool {
        MemberPorts::orchestrator_alive(self)
    }

    fn receive_clock(&mut self, f: impl FnMut(ClockMsg)) -> Result<usize, TransportError> {
        MemberPorts::receive_clock(self, f)
    }

    fn connect(&mut self, subscribe: &[u32], notify: &[u32]) -> Result<bool, TransportError> {
        MemberPorts::connect(self, subscribe, notify).map(|()| true)
    }

    fn hand_over(&mut self) -> Result<bool, TransportError> {
        MemberPorts::hand_over(self).map(|()| true)
    }
}
