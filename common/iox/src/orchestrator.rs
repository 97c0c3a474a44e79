//! The orchestrator's side: creates every service of a team and owns the clock.

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use iceoryx2::node::NodeView;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::service::builder::event::EventCreateError;
use iceoryx2::service::builder::publish_subscribe::PublishSubscribeCreateError;
use iceoryx2::service::port_factory::event::PortFactory as EventService;
use iceoryx2::service::port_factory::publish_subscribe::PortFactory as PubSubService;

use super::dead_teams::{remove_dead, scan_teams};
use super::notified::{max_event_id, Notified, Sweep};
use super::{
    create_node, init_logging, process_config, service_error, service_name, wait_on, TeamLayout,
    TeamName, TeamProcess, TransportError, CLOCK_BUFFER, OBSERVER_SLOTS, SPARE_NODES,
};
use crate::messages::{ClockMsg, StateMsg};
use crate::resend::{resend_room, RESEND_STATES_KEY};
use crate::wire::{ClockWire, StateBatchWire, Wire};

const WHO: TeamProcess = TeamProcess::Orchestrator;

/// One member's state service, read by the orchestrator.
struct StateReader {
    service: PubSubService<ipc::Service, StateBatchWire, ()>,
    subscriber: Subscriber<ipc::Service, StateBatchWire, ()>,
}

/// One member's wake event. The orchestrator created it and holds it while the team gathers
/// (members open it meanwhile); with relayed wake-ups it lets go of it at the first clock
/// message unless it notifies the member itself (a root, or a reader of a lost member).
struct WakeEvent {
    /// `None` once let go: the member and its in-neighbours hold it from then on.
    service: Option<EventService<ipc::Service>>,
    notifier: Option<Notifier<ipc::Service>>,
    /// (listeners, notifiers) when the service was let go, for [`OrchestratorPorts::readiness`].
    counts: (usize, usize),
}

/// Every port of the orchestrator. Fields drop in order: ports first, the node last.
struct Ports {
    states: BTreeMap<u32, StateReader>,
    clock: PubSubService<ipc::Service, ClockWire, ()>,
    clock_publisher: Publisher<ipc::Service, ClockWire, ()>,
    wakes: BTreeMap<u32, WakeEvent>,
    /// True once the wake events nobody here notifies were let go (relayed wake-ups).
    wakes_let_go: bool,
    /// Lost members whose readers the orchestrator now wakes itself (relayed wake-ups).
    losses_seen: std::collections::BTreeSet<u32>,
    wake_orch: EventService<ipc::Service>,
    listener: Listener<ipc::Service>,
    /// The node must outlive the ports created from it.
    node: Node<ipc::Service>,
}

/// The orchestrator's ports: a subscriber on every `state/<id>`, the clock publisher, a notifier
/// on `wake/<id>` of every member it wakes itself ([`TeamLayout::wake_roots`]: all of them unless
/// wake-ups are relayed) and the listener of `wake/orch`.
///
/// Dropping it (or [`shutdown`](Self::shutdown)) releases the ports and then removes the
/// resources of team members that died; what live members still hold disappears when they exit.
pub struct OrchestratorPorts {
    /// Always `Some` until `Drop` takes it to release the ports before sweeping dead nodes.
    ports: Option<Ports>,
    team: TeamName,
    layout: TeamLayout,
    stale_nodes_removed: usize,
    /// Who woke the orchestrator since its last read ([`Self::receive_notified_states`]).
    notified: Notified,
}

/// How far one member has connected its ports (see [`OrchestratorPorts::readiness`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct AgentReadiness {
    /// The member.
    pub id: u32,
    /// Publishers on `state/<id>` (1 when the member is up).
    pub state_publishers: usize,
    /// Subscribers on `state/<id>`, the orchestrator's included.
    pub state_subscribers: usize,
    /// Out-degree on this host + 1 (the orchestrator).
    pub expected_state_subscribers: usize,
    /// Listeners on `wake/<id>` (1 when the member is up).
    pub wake_listeners: usize,
    /// Notifiers on `wake/<id>`, the orchestrator's included.
    pub wake_notifiers: usize,
    /// In-degree on this host + 1 (the orchestrator).
    pub expected_wake_notifiers: usize,
}

impl AgentReadiness {
    /// True when the member and all its neighbours' ports towards it are connected.
    pub fn is_complete(&self) -> bool {
        self.state_publishers == 1
            // An observer may already be subscribed: at least the team's readers. Every member
            // takes its state subscriptions before its notifier on wake/orch, so once all of
            // those are in (`Readiness::is_complete`), no member's subscription is missing.
            && self.state_subscribers >= self.expected_state_subscribers
            && self.wake_listeners == 1
            && self.wake_notifiers == self.expected_wake_notifiers
    }
}

/// Port counts of the whole team; complete when every member has opened all its ports, which is
/// when the orchestrator may grant tick 0 (history is 0: a sample sent earlier reaches nobody).
/// Counts come from iceoryx2's dynamic config and include ports of dead processes until they are
/// cleaned.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Readiness {
    /// Per member, in id order.
    pub agents: Vec<AgentReadiness>,
    /// Subscribers on the clock (the team size when complete).
    pub clock_subscribers: usize,
    /// Notifiers on `wake/orch` (the team size when complete).
    pub orchestrator_wake_notifiers: usize,
}

impl Readiness {
    /// True when every port of every member is connected.
    pub fn is_complete(&self) -> bool {
        let n = self.agents.len();
        self.clock_subscribers == n
            && self.orchestrator_wake_notifiers == n
            && self.agents.iter().all(AgentReadiness::is_complete)
    }

    /// Members that have not joined: no process has opened their own ports (state publisher,
    /// wake listener). Members that joined but wait on a neighbour are not among them.
    pub fn not_joined(&self) -> Vec<u32> {
        self.agents
            .iter()
            .filter(|a| a.state_publishers == 0 || a.wake_listeners == 0)
            .map(|a| a.id)
            .collect()
    }

    /// Members whose own or incoming ports are not all connected yet.
    pub fn waiting_for(&self) -> Vec<u32> {
        self.agents
            .iter()
            .filter(|a| !a.is_complete())
            .map(|a| a.id)
            .collect()
    }
}

/// A node's id and, when its details can be read, its name.
fn id_and_name(
    state: &NodeState<ipc::Service>,
) -> (iceoryx2::identifiers::UniqueNodeId, Option<String>) {
    match state {
        NodeState::Alive(v) => (*v.id(), v.details().as_ref().map(|d| d.name().to_string())),
        NodeState::Dead(v) => (*v.id(), v.details().as_ref().map(|d| d.name().to_string())),
        NodeState::Inaccessible(i) | NodeState::Undefined(i) => (*i, None),
    }
}

impl OrchestratorPorts {
    /// Creates the team: refuses when a live process of `team` exists, removes the files of
    /// every team of this user whose processes are all dead (this team's previous run included;
    /// logged per team) and the dead nodes of no known team, then creates every service sized to `layout` and opens the
    /// orchestrator's ports.
    pub fn create(team: &TeamName, layout: &TeamLayout) -> Result<Self, TransportError> {
        init_logging();
        // The clean-up below removes files by name: only in a root that is ours alone.
        super::ownership::check_root(super::iox2_location())?;
        let cfg = process_config();
        let registry = scan_teams(cfg)?;
        if let Some(scan) = registry.teams.get(team).filter(|s| !s.alive.is_empty()) {
            return Err(TransportError::TeamAlreadyRunning {
                team: team.clone(),
                live: scan.alive.join(", "),
            });
        }
        let mut stale_nodes_removed = 0;
        let cleaned = remove_dead(registry);
        if cleaned.unknown_nodes > 0 {
            tracing::info!(
                nodes = cleaned.unknown_nodes,
                "removed dead iceoryx2 nodes of no known team (only their monitor files were left)"
            );
        }
        for gone in cleaned.teams {
            if &gone.team == team {
                stale_nodes_removed = gone.removed;
            }
            tracing::info!(team = %gone.team, found = gone.dead_nodes, removed = gone.removed,
                "removed stale resources of a team whose processes are all dead");
        }

        let agents = layout.ids().len();
        let need = super::limits::shm_need_bytes(agents, layout.window());
        let dir = super::limits::SHM_DIR;
        if let Some(free) = super::limits::free_bytes(dir).filter(|&f| f < need) {
            return Err(TransportError::ShmFull {
                team: team.clone(),
                dir,
                free_kib: free / 1024,
                agents,
                window: layout.window(),
                need_kib: need / 1024,
            });
        }
        if let Some(u) = super::limits::fd_short(agents, layout.relays_wakes()) {
            return Err(TransportError::FdLimitTooLow {
                team: team.clone(),
                agents,
                need: u.need,
                soft: u.soft,
                hard: u.hard,
            });
        }
        let node = create_node(team, WHO)?;
        let ports = Ports::create(node, team, layout)?;
        tracing::debug!(team = %team, agents = layout.ids().len(), "team created");
        Ok(Self {
            ports: Some(ports),
            team: team.clone(),
            layout: layout.clone(),
            stale_nodes_removed,
            notified: Notified::new(Instant::now()),
        })
    }

    /// The team.
    pub fn team(&self) -> &TeamName {
        &self.team
    }

    /// The layout the services were sized for.
    pub fn layout(&self) -> &TeamLayout {
        &self.layout
    }

    /// How many dead nodes of a previous run [`create`](Self::create) cleaned.
    pub fn stale_nodes_removed(&self) -> usize {
        self.stale_nodes_removed
    }

    /// Publishes a clock message, then wakes the members it wakes itself (every member, or with
    /// relayed wake-ups the [`TeamLayout::wake_roots`] and the readers of lost members). Returns
    /// how many members' listeners were reached (fewer than those woken means some member is not
    /// listening: dead or not yet up).
    pub fn publish_clock(&mut self, msg: ClockMsg) -> Result<usize, TransportError> {
        if self.layout.relays_wakes() {
            self.let_go_of_wakes();
            self.wake_readers_of_loss(&msg);
        }
        let p = self.ports();
        p.clock_publisher
            .send_copy(Wire(msg))
            .map_err(|e| self.error(&self.team.clock_service(), "send", e))?;
        let mut reached = 0;
        for (&id, wake) in &p.wakes {
            if let Some(notifier) = &wake.notifier {
                reached += notifier
                    .notify()
                    .map_err(|e| self.error(&self.team.wake_service(id), "notify", e))?;
            }
        }
        Ok(reached)
    }

    /// Call once every member has joined ([`Readiness::is_complete`]): with relayed wake-ups
    /// every member now holds its own wake event and its in-neighbours their notifiers on it,
    /// so the orchestrator lets go of those it does not notify, 2 file descriptors each (static
    /// file and segment), before the first [`receive_states`](Self::receive_states) opens 2 more
    /// per member (its publisher's data and connection segments). The first clock message does
    /// it otherwise. Nothing without relayed wake-ups.
    pub fn gathered(&mut self) {
        if self.layout.relays_wakes() {
            self.let_go_of_wakes();
        }
    }

    /// See [`Self::gathered`].
    fn let_go_of_wakes(&mut self) {
        let Some(p) = self.ports.as_mut().filter(|p| !p.wakes_let_go) else {
            return;
        };
        p.wakes_let_go = true;
        for wake in p.wakes.values_mut().filter(|w| w.notifier.is_none()) {
            if let Some(service) = wake.service.take() {
                let d = service.dynamic_config();
                wake.counts = (d.number_of_listeners(), d.number_of_notifiers());
            }
        }
    }

    /// Relayed wake-ups: the readers of a newly lost member may have no live in-neighbour to
    /// pass clock messages on until their repair applies (a degraded follower never again), so
    /// from its first notice on the orchestrator wakes them itself. Best effort: a reader
    /// that cannot be reached still reads the clock at least every wait slice of its own.
    fn wake_readers_of_loss(&mut self, msg: &ClockMsg) {
        let Some(lost) = msg.loss().map(|n| n.id) else {
            return;
        };
        let Some(p) = self.ports.as_mut() else {
            return;
        };
        if !p.losses_seen.insert(lost) {
            return;
        }
        for &reader in self.layout.out_neighbors(lost) {
            let Some(wake) = p.wakes.get_mut(&reader).filter(|w| w.notifier.is_none()) else {
                continue;
            };
            let name = self.team.wake_service(reader);
            match open_notifier(&p.node, &self.team, &name) {
                Ok((service, notifier)) => {
                    wake.service = Some(service);
                    wake.notifier = Some(notifier);
                }
                Err(e) => tracing::warn!(team = %self.team, lost, reader, error = %e,
                    "cannot wake a reader of a lost member directly"),
            }
        }
    }

    /// Drains every state subscriber (members in id order, each member's states oldest first) into
    /// `f`; returns how many states were delivered.
    pub fn receive_states(&mut self, mut f: impl FnMut(StateMsg)) -> Result<usize, TransportError> {
        let mut count = 0;
        for (&id, reader) in &self.ports().states {
            count += Self::drain(&self.team, id, reader, &mut f)?;
        }
        Ok(count)
    }

    /// [`receive_states`](Self::receive_states) for the members that woke the orchestrator
    /// since the last read (lockstep: each member sends its states before it wakes
    /// `wake/orch` with its own id), and for every member at the first read, after a wake-up
    /// without an id, and at least every [`FULL_SWEEP`](crate::notified::FULL_SWEEP).
    pub fn receive_notified_states(
        &mut self,
        mut f: impl FnMut(StateMsg),
    ) -> Result<usize, TransportError> {
        // Wake-ups that came while the orchestrator was busy (it did not wait for them).
        let notified = &mut self.notified;
        let ports = self
            .ports
            .as_ref()
            .expect("orchestrator ports are present until shutdown");
        let pending = ports.listener.try_wait(|a| notified.note(a.id.as_value()));
        pending.map_err(|e| {
            service_error(
                &self.team,
                WHO,
                &self.team.orchestrator_wake_service(),
                "wait",
                e,
            )
        })?;
        let now = Instant::now();
        let (count, all) = match self.notified.sweep(now) {
            Sweep::All => (self.receive_states(&mut f)?, true),
            Sweep::Only(ids) => {
                let states = &ports.states;
                let mut count = 0;
                for id in ids {
                    if let Some(reader) = states.get(id) {
                        count += Self::drain(&self.team, *id, reader, &mut f)?;
                    }
                }
                (count, false)
            }
        };
        self.notified.read(all, now);
        Ok(count)
    }

    /// Every state member `id` sent, oldest first.
    fn drain(
        team: &TeamName,
        id: u32,
        reader: &StateReader,
        f: &mut impl FnMut(StateMsg),
    ) -> Result<usize, TransportError> {
        let mut count = 0;
        while let Some(sample) = reader
            .subscriber
            .receive()
            .map_err(|e| service_error(team, WHO, &team.state_service(id), "receive", e))?
        {
            let states = sample.payload().0.states();
            states.iter().for_each(|m| f(*m));
            count += states.len();
        }
        Ok(count)
    }

    /// Blocks until a member notifies `wake/orch` or `timeout` passes; true when woken. Then
    /// drain with [`receive_states`](Self::receive_states) or
    /// [`receive_notified_states`](Self::receive_notified_states): notifications merge.
    pub fn wait(&mut self, timeout: Duration) -> Result<bool, TransportError> {
        let notified = &mut self.notified;
        let on_event = |a: iceoryx2::port::EventActivation| notified.note(a.id.as_value());
        let ports = self
            .ports
            .as_ref()
            .expect("orchestrator ports are present until shutdown");
        wait_on(
            &ports.listener,
            (timeout, on_event),
            &self.team,
            WHO,
            || self.team.orchestrator_wake_service(),
        )
    }

    /// Port counts of every service: lets the orchestrator wait until all members are up.
    pub fn readiness(&self) -> Readiness {
        let p = self.ports();
        let agents = self
            .layout
            .ids()
            .iter()
            .filter_map(|&id| {
                let state = p.states.get(&id)?.service.dynamic_config();
                let wake = p.wakes.get(&id)?;
                let (wake_listeners, wake_notifiers) =
                    wake.service.as_ref().map_or(wake.counts, |s| {
                        let d = s.dynamic_config();
                        (d.number_of_listeners(), d.number_of_notifiers())
                    });
                let mine = usize::from(wake.notifier.is_some());
                Some(AgentReadiness {
                    id,
                    state_publishers: state.number_of_publishers(),
                    state_subscribers: state.number_of_subscribers(),
                    expected_state_subscribers: self.layout.visible_out_degree(id) + 1,
                    wake_listeners,
                    wake_notifiers,
                    expected_wake_notifiers: self.layout.visible_in_degree(id) + mine,
                })
            })
            .collect();
        Readiness {
            agents,
            clock_subscribers: p.clock.dynamic_config().number_of_subscribers(),
            orchestrator_wake_notifiers: p.wake_orch.dynamic_config().number_of_notifiers(),
        }
    }

    /// Names of the nodes subscribed to `state/<id>`, sorted (the orchestrator's own included);
    /// empty for an id outside the team. Lets a test check that the subscription graph is the
    /// communication graph.
    pub fn subscriber_nodes(&self, id: u32) -> Result<Vec<String>, TransportError> {
        let Some(reader) = self.ports().states.get(&id) else {
            return Ok(vec![]);
        };
        let mut node_ids = vec![];
        reader.service.dynamic_config().list_subscribers(|s| {
            node_ids.push(s.node_id);
            CallbackProgression::Continue
        });
        self.node_names(&node_ids, |f| reader.service.nodes(f).map(|_| ()))
    }

    /// `subscriber_nodes` for every id at once (subscriptions.json): the nodes' names are read
    /// once for the whole registry instead of once per service and node. Per service that was
    /// about five node-detail files per member, 0.44 s of start-up at N = 1000.
    pub fn subscriber_graph(
        &self,
        ids: impl IntoIterator<Item = u32>,
    ) -> Result<BTreeMap<u32, Vec<String>>, TransportError> {
        let mut names = BTreeMap::new();
        Node::<ipc::Service>::list(self.ports().node.config(), |state| {
            if let (node_id, Some(name)) = id_and_name(&state) {
                names.insert(node_id, name);
            }
            CallbackProgression::Continue
        })
        .map_err(|e| TransportError::NodeList {
            team: self.team.clone(),
            detail: format!("{e:?}"),
        })?;
        let mut graph = BTreeMap::new();
        for id in ids {
            let mut nodes = vec![];
            if let Some(reader) = self.ports().states.get(&id) {
                reader.service.dynamic_config().list_subscribers(|s| {
                    nodes.push(
                        names
                            .get(&s.node_id)
                            .cloned()
                            .unwrap_or_else(|| format!("<node {}>", s.node_id)),
                    );
                    CallbackProgression::Continue
                });
            }
            nodes.sort();
            graph.insert(id, nodes);
        }
        Ok(graph)
    }

    /// Names of the nodes notifying `wake/<id>`, sorted (the orchestrator's own included, if it
    /// wakes `id` itself).
    pub fn notifier_nodes(&self, id: u32) -> Result<Vec<String>, TransportError> {
        let p = self.ports();
        let Some(wake) = p.wakes.get(&id) else {
            return Ok(vec![]);
        };
        // A wake event let go of (relayed wake-ups) is opened again for the question: rare (a
        // repair's links), and its holders keep it alive.
        let opened;
        let service = match &wake.service {
            Some(s) => s,
            None => {
                let name = self.team.wake_service(id);
                opened = super::member::open_event(&p.node, &self.team, WHO, &name)?;
                &opened
            }
        };
        let mut node_ids = vec![];
        service.dynamic_config().list_notifiers(|n| {
            node_ids.push(n.node_id);
            CallbackProgression::Continue
        });
        self.node_names(&node_ids, |f| service.nodes(f).map(|_| ()))
    }

    /// True when member `reader` subscribes to `state/<writer>` and `writer` notifies
    /// `wake/<reader>`: a link a repair opened is connected.
    pub fn linked(&self, reader: u32, writer: u32) -> Result<bool, TransportError> {
        let r = self.team.node_name(TeamProcess::Agent(reader));
        let w = self.team.node_name(TeamProcess::Agent(writer));
        Ok(
            self.subscriber_nodes(writer)?.contains(&r)
                && self.notifier_nodes(reader)?.contains(&w),
        )
    }

    /// The names of the nodes of `node_ids` (one entry per port), listed by `nodes`.
    fn node_names<E: std::fmt::Debug>(
        &self,
        node_ids: &[iceoryx2::identifiers::UniqueNodeId],
        nodes: impl FnOnce(
            &mut dyn FnMut(NodeState<ipc::Service>) -> CallbackProgression,
        ) -> Result<(), E>,
    ) -> Result<Vec<String>, TransportError> {
        let mut names = vec![];
        nodes(&mut |state| {
            let (node_id, name) = id_and_name(&state);
            // A node with several subscribers on one service would be listed once per port.
            let ports = node_ids.iter().filter(|&&n| n == node_id).count();
            let name = name.unwrap_or_else(|| format!("<node {node_id}>"));
            names.extend(std::iter::repeat_n(name, ports));
            CallbackProgression::Continue
        })
        .map_err(|e| TransportError::NodeList {
            team: self.team.clone(),
            detail: format!("{e:?}"),
        })?;
        names.sort();
        Ok(names)
    }

    /// Releases every port and the node, then removes the resources of dead team members;
    /// returns how many dead nodes were cleaned. Dropping does the same, logging instead.
    pub fn shutdown(mut self) -> Result<usize, TransportError> {
        drop(self.ports.take());
        super::remove_dead_nodes(&self.team)
    }

    fn ports(&self) -> &Ports {
        // `ports` is only taken in `shutdown` and `drop`, which consume or end `self`.
        self.ports
            .as_ref()
            .expect("orchestrator ports are present until shutdown")
    }

    fn error(&self, service: &str, op: &'static str, e: impl std::fmt::Debug) -> TransportError {
        service_error(&self.team, WHO, service, op, e)
    }
}

impl Drop for OrchestratorPorts {
    fn drop(&mut self) {
        if self.ports.take().is_some() {
            if let Err(e) = super::remove_dead_nodes(&self.team) {
                tracing::warn!(team = %self.team, error = %e, "cannot sweep dead team members");
            }
        }
    }
}

impl Ports {
    fn create(
        node: Node<ipc::Service>,
        team: &TeamName,
        layout: &TeamLayout,
    ) -> Result<Self, TransportError> {
        let n = layout.ids().len();
        let buffer = layout.window() as usize + 2;
        let err =
            |service: &str, op, e: &dyn std::fmt::Debug| service_error(team, WHO, service, op, e);

        let mut states = BTreeMap::new();
        let mut wakes = BTreeMap::new();
        let roots: std::collections::BTreeSet<u32> = layout.wake_roots().into_iter().collect();
        for &id in layout.ids() {
            let root = roots.contains(&id);
            let (reader, wake) = member_services(&node, team, layout, id, buffer, root)?;
            states.insert(id, reader);
            wakes.insert(id, wake);
        }

        let name = team.clock_service();
        let clock = node
            .service_builder(&service_name(team, WHO, &name)?)
            .publish_subscribe::<ClockWire>()
            .max_publishers(1)
            .max_subscribers(n)
            .max_nodes(n + 1 + SPARE_NODES)
            .subscriber_max_buffer_size(CLOCK_BUFFER)
            .subscriber_max_borrowed_samples(1)
            .history_size(0)
            .enable_safe_overflow(true)
            .create_with_attributes(&scenario_attribute(team, layout.scenario_hash())?)
            .map_err(|e| pubsub_create_error(team, &name, e))?;
        let clock_publisher = clock
            .publisher_builder()
            .max_loaned_samples(1)
            .create()
            .map_err(|e| err(&name, "create publisher", &e))?;

        let name = team.orchestrator_wake_service();
        let wake_orch = node
            .service_builder(&service_name(team, WHO, &name)?)
            .event()
            .max_listeners(1)
            .max_notifiers(n)
            .max_nodes(n + 1 + SPARE_NODES)
            .event_id_max_value(max_event_id(layout.ids()))
            .create()
            .map_err(|e| event_create_error(team, &name, e))?;
        let listener = wake_orch
            .listener_builder()
            .create()
            .map_err(|e| err(&name, "create listener", &e))?;

        Ok(Self {
            states,
            clock,
            clock_publisher,
            wakes,
            wakes_let_go: false,
            losses_seen: Default::default(),
            wake_orch,
            listener,
            node,
        })
    }
}

/// Member `id`'s state service (its one publisher, its readers' and repairs' subscriber slots,
/// the orchestrator's own subscriber) and its wake-up event (a notifier per writer, and a slot
/// for the orchestrator's, which it takes at once when it wakes `id` itself: `root`).
fn member_services(
    node: &Node<ipc::Service>,
    team: &TeamName,
    layout: &TeamLayout,
    id: u32,
    buffer: usize,
    root: bool,
) -> Result<(StateReader, WakeEvent), TransportError> {
    let err = |service: &str, op, e: &dyn std::fmt::Debug| service_error(team, WHO, service, op, e);
    let (extra_readers, extra_writers) = layout.repair_slots(id);
    let outs = layout.out_neighbors(id).len() + extra_readers;
    let name = team.state_service(id);
    // A repair's new reader gets the states published before it subscribed: the publisher sends
    // its last `resend` states again at the hand-over (crate::resend), not from a history.
    let resend = layout.history().min(buffer);
    let buffer = buffer + resend_room(resend);
    let service = node
        .service_builder(&service_name(team, WHO, &name)?)
        .publish_subscribe::<StateBatchWire>()
        .max_publishers(1)
        .max_subscribers(outs + 1 + OBSERVER_SLOTS)
        .max_nodes(outs + 2 + SPARE_NODES + OBSERVER_SLOTS)
        .subscriber_max_buffer_size(buffer)
        .subscriber_max_borrowed_samples(1)
        .history_size(0)
        .enable_safe_overflow(true)
        .create_with_attributes(&resend_attribute(team, resend)?)
        .map_err(|e| pubsub_create_error(team, &name, e))?;
    let subscriber = service
        .subscriber_builder()
        .buffer_size(buffer)
        .create()
        .map_err(|e| err(&name, "create subscriber", &e))?;
    let reader = StateReader {
        service,
        subscriber,
    };

    let ins = layout.in_neighbors(id).len() + extra_writers;
    let name = team.wake_service(id);
    let service = node
        .service_builder(&service_name(team, WHO, &name)?)
        .event()
        .max_listeners(1)
        .max_notifiers(ins + 1)
        .max_nodes(ins + 2 + SPARE_NODES)
        .create()
        .map_err(|e| event_create_error(team, &name, e))?;
    let notifier = match root {
        true => Some(
            service
                .notifier_builder()
                .create()
                .map_err(|e| err(&name, "create notifier", &e))?,
        ),
        false => None,
    };
    let wake = WakeEvent {
        service: Some(service),
        notifier,
        counts: (0, 0),
    };
    Ok((reader, wake))
}

/// Opens the wake event `name` the orchestrator created and let go of, and a notifier on it
/// (the slot it left free).
fn open_notifier(
    node: &Node<ipc::Service>,
    team: &TeamName,
    name: &str,
) -> Result<(EventService<ipc::Service>, Notifier<ipc::Service>), TransportError> {
    let service = super::member::open_event(node, team, WHO, name)?;
    let notifier = service
        .notifier_builder()
        .create()
        .map_err(|e| service_error(team, WHO, name, "create notifier", e))?;
    Ok((service, notifier))
}

/// A service that already exists means another orchestrator won the race (or live members of a
/// previous run still hold it).
fn pubsub_create_error(
    team: &TeamName,
    service: &str,
    e: PublishSubscribeCreateError,
) -> TransportError {
    match e {
        PublishSubscribeCreateError::AlreadyExists
        | PublishSubscribeCreateError::IsBeingCreatedByAnotherInstance => {
            TransportError::TeamAlreadyRunning {
                team: team.clone(),
                live: format!("service {service} already exists"),
            }
        }
        e => service_error(team, WHO, service, "create service", e),
    }
}

/// See [`pubsub_create_error`].
fn event_create_error(team: &TeamName, service: &str, e: EventCreateError) -> TransportError {
    match e {
        EventCreateError::AlreadyExists | EventCreateError::IsBeingCreatedByAnotherInstance => {
            TransportError::TeamAlreadyRunning {
                team: team.clone(),
                live: format!("service {service} already exists"),
            }
        }
        e => service_error(team, WHO, service, "create service", e),
    }
}

/// The attribute of a state service that tells its member how many states to send again at a
/// hand-over ([`RESEND_STATES_KEY`]).
fn resend_attribute(
    team: &TeamName,
    states: usize,
) -> Result<iceoryx2::service::attribute::AttributeSpecifier, TransportError> {
    attribute(team, "resend", RESEND_STATES_KEY, &states.to_string())
}

/// The clock service's attribute carrying the scenario hash.
fn scenario_attribute(
    team: &TeamName,
    hash: u64,
) -> Result<iceoryx2::service::attribute::AttributeSpecifier, TransportError> {
    attribute(
        team,
        "scenario hash",
        super::SCENARIO_HASH_KEY,
        &super::scenario_hash_value(hash),
    )
}

/// One service attribute `key = value`; `what` names it in the error.
fn attribute(
    team: &TeamName,
    what: &str,
    key: &str,
    value: &str,
) -> Result<iceoryx2::service::attribute::AttributeSpecifier, TransportError> {
    use iceoryx2::service::attribute::{AttributeKey, AttributeSpecifier, AttributeValue};
    let bad = |e: &dyn std::fmt::Debug| TransportError::InvalidLayout {
        reason: format!("team {team}: cannot define the {what} attribute: {e:?}"),
    };
    let key = AttributeKey::try_from(key).map_err(|e| bad(&e))?;
    let value = AttributeValue::try_from(value).map_err(|e| bad(&e))?;
    AttributeSpecifier::new()
        .define(&key, &value)
        .map_err(|e| bad(&e))
}
