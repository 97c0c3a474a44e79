//! `orchestrator launch`: create the team's services, spawn one process per quadcopter (or wait
//! for hand-started ones), step the shared clock, audit every tick live, and stop the team.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use cdm_records::audit::{AuditReport, Auditor};
use cdm_team::telemetry_thread::ThreadedSink;

use crate::realtime::Elsewhere;
use cdm_engine::loss::{LossSchedule, LossState};
use cdm_hosts::OtherHosts;
use cdm_iox::{describe_spawn_error, raise_fd_limit, OrchestratorPorts, TeamLayout, TeamName};
use cdm_math::vec3;
use cdm_model::outcome::FaultKind;
use cdm_records::record::TickRecorder;
use cdm_records::rundir::RunDir;
use cdm_records::telemetry::TelemetrySink;
use cdm_runtime::messages::{ClockMsg, LossNotice, StateMsg, SteerNotice, StopReason};
use cdm_runtime::seams::{Clock, MonotonicClock};
use cdm_runtime::team_core::{nap_before_wait, TeamConfig, TeamCore, TickStates};
use cdm_runtime::team_fault::{InterruptedAt, TeamFault};
use cdm_runtime::team_loss::TeamLosses;
use cdm_scenario::Scenario;
use cdm_viewer::live::LiveView;

use crate::channel::{Answered, CommandAnswer, CommandChannel, CommandRequest};
use crate::feeds::Feeds;
use crate::steer::{FlightAt, LiveSteer, Steer};

use crate::launch_error::LaunchError;
use cdm_team::team::{
    check_children, fault, first_exited_but, member_binaries_present, spawn_member, stop_team,
    Spawned, Stop,
};
use cdm_team::template::MemberTemplate;

/// Options of a launch, validated.
pub struct LaunchOptions {
    pub team: TeamName,
    pub out: PathBuf,
    pub force: bool,
    pub every: u64,
    /// The telemetry file's format.
    pub telemetry: cdm_records::telemetry::TelemetryFormat,
    pub window: u32,
    pub spawn: bool,
    pub agent_timeout: Duration,
    pub join_timeout: Duration,
    /// Where the launch's notices go (the binary prints them, or drops them under `--quiet`).
    pub notices: std::sync::Arc<dyn cdm_team::notices::NoticeSink>,
    /// End the run at the tick of its first safety violation (telemetry kept, verdict UNSAFE).
    pub stop_on_violation: bool,
    /// Fly only ticks 0..=K of the plan.
    pub max_ticks: Option<u64>,
    /// Serve the live view on this address.
    pub serve: Option<std::net::SocketAddr>,
    /// Publish the run live on ROS 2 (`--ros2`, `--ros2-hz`).
    pub ros2: Option<cdm_ros2::Ros2Options>,
    /// Serve the run live to Foxglove (`--foxglove`, `--foxglove-hz`).
    pub foxglove: Option<cdm_foxglove::FoxgloveOptions>,
    /// Across hosts (`--hosts`, `--listen`).
    pub hosts: cdm_hosts::HostOptions,
    /// `--realtime`: fly on the wall clock, the orchestrator monitors (`realtime.rs`).
    pub realtime: Option<crate::realtime::RealtimeOptions>,
    /// What the members fly (forwarded to the spawned members; printed for hand-started ones).
    pub vehicles: cdm_member::vehicles::Vehicles,
    /// Members to kill once they have published a tick (`--lose`, validated).
    pub losses: cdm_engine::loss::LossSchedule,
    /// What a lost member does to the run (`--on-loss`).
    pub on_loss: cdm_engine::loss::OnLoss,
    /// `--commands FILE`, decided before the flight (the scenario launched is the commanded
    /// one: its plan the same before every switch).
    pub commands: Option<crate::steer::FileCommands>,
    /// `--realtime --commands FILE`: the file's commands, each certified and proposed to the
    /// leaders in flight, ahead of its switch tick, as a live command is (`realtime_steer.rs`).
    pub realtime_commands: Vec<cdm_scenario::TimedCommand>,
    /// `--on-interrupt land`: the first SIGINT or SIGTERM lands the team (certified as a
    /// command), then the run ends as usual; a second one stops it at once.
    pub land_on_interrupt: bool,
}

/// When the orchestrator process started (set first thing in `main`): start-up is measured from
/// here to the first grant.
pub static PROCESS_START: std::sync::OnceLock<Instant> = std::sync::OnceLock::new();

/// What a finished launch reports.
pub struct Launched {
    /// The audit report (also written to audit.json).
    pub report: AuditReport,
    /// Wall time of the ticking phase.
    pub ticking: Duration,
    /// From the command's start to the first grant (zero when the team never ticked).
    pub startup: Duration,
    /// The members' peak resident memory, read just before the team was stopped (spawned teams
    /// only).
    pub member_peak_rss: Option<cdm_team::team::MembersPeak>,
    /// The live view (`--serve`), kept serving until the caller drops it.
    pub live: Option<LiveView>,
}

/// What watches every completed tick: the audit, and the live feeds (`--serve`, `--ros2`).
struct Watchers<'a> {
    audit: &'a mut Auditor,
    live: &'a mut Feeds,
    /// The other hosts' members, through the bridge (`--hosts`): their exits, kills and links.
    hosts: &'a dyn OtherHosts,
    /// The commands the team takes in flight, and where they come from.
    steer: Steer<'a>,
}

/// Run a launch to the end.
pub fn launch(s: &Scenario, o: &LaunchOptions) -> Result<Launched, LaunchError> {
    // The stop signals are caught only from here on: until now nothing needs cleaning up, and a
    // wait in the preflight (a ROS 2 participant or zenoh session opening) ends at once on one.
    let mut live = preflight(s, o)?;
    let interrupted = cdm_process::signals::install();
    let hosts = cdm_hosts::HostPlan::new(s, &o.hosts, &o.team, o.notices.clone())?;
    let layout = team_layout(s, o, &hosts)?;
    let mut ports = OrchestratorPorts::create(&o.team, &layout).map_err(LaunchError::Ports)?;
    let others = hosts.start_bridge(s, &o.team, crate::flight::flight_of(o))?;
    // Only now, with the team name ours, touch the run directory: a refused second launch of a
    // running team writes nothing (not even into the first one's --out).
    let dir = RunDir::create(&o.out, o.force).map_err(LaunchError::RunDir)?;
    let member_file = write_inputs(&dir, s, o)?;
    // Humans start members with scenario.toml; spawned members read the JSON copy (same hash).
    let scenario_file = dir.path().join("scenario.toml");
    log_stale(&ports, &o.team);
    let here = |id: u32| hosts.runs_here(id);
    let mut children = start_members(s, o, &dir, &mut ports, (&member_file, &scenario_file), here)?;
    let mut audit = Auditor::new(s);
    let mut steered = LiveSteer::new(s, o.commands.as_ref());
    let channel = command_channel(o)?;
    let result = if let Some(rt) = &o.realtime {
        let elsewhere = |id: u32| others.reporting(id);
        let team = (&mut ports, children.as_mut_slice(), &elsewhere as Elsewhere);
        let watch = (
            &mut audit,
            &mut live,
            Steer::new(channel.as_ref(), &mut steered, &dir),
        );
        crate::realtime::run(s, o, rt, &dir, team, watch, interrupted)
    } else {
        run_team(
            s,
            o,
            &dir,
            &mut ports,
            &mut children,
            Watchers {
                audit: &mut audit,
                live: &mut live,
                hosts: others.as_ref(),
                steer: Steer::new(channel.as_ref(), &mut steered, &dir),
            },
            interrupted,
        )
    };
    // No command is taken once the flight is over.
    drop(channel);
    let ended = Instant::now();
    let (complete, reason, first_tick) = match result {
        Ok((t, complete)) => (complete, StopReason::Finished, Some(t)),
        Err((fault, reason)) => {
            audit.fault(others.explain(fault));
            (false, reason, None)
        }
    };
    let member_peak_rss = cdm_team::team::members_peak_rss(&children);
    stop_team(&mut ports, &mut children, s, reason);
    if let Err(e) = ports.shutdown() {
        tracing::warn!("{e}");
    }
    let mut report = audit.finish(complete);
    report.commands = steered.records().iter().map(|r| r.summary()).collect();
    for l in &mut report.losses {
        l.host = others.host_of(l.id);
    }
    others.finish(&dir, report.ticks);
    dir.write_audit(&report).map_err(LaunchError::Write)?;
    live.finish(&report, &*o.notices);
    Ok(Launched {
        report,
        ticking: first_tick.map_or(Duration::ZERO, |t| ended - t),
        startup: startup(first_tick),
        member_peak_rss,
        live: live.view,
    })
}

/// The channel `orchestrator command` reaches the team by: in lockstep and in real time, on
/// one host or several (a command's notice rides the clock's message, which the link carries
/// whole to the other hosts' members; in real time a command is proposed, acknowledged by the
/// leaders, whose states carry the acknowledgement back over the link, then final), with model
/// or MAVLink vehicles.
fn command_channel(o: &LaunchOptions) -> Result<Option<CommandChannel>, LaunchError> {
    Ok(Some(CommandChannel::open(&o.team)?))
}

/// Says what a previous team of this name left that creating the ports removed.
fn log_stale(ports: &OrchestratorPorts, team: &TeamName) {
    if ports.stale_nodes_removed() > 0 {
        tracing::info!(
            removed = ports.stale_nodes_removed(),
            "removed stale resources of a previous team {team}"
        );
    }
}

/// The run's inputs: commands.json (`--commands`), scenario.toml, and the members' JSON copy
/// (its path returned).
fn write_inputs(dir: &RunDir, s: &Scenario, o: &LaunchOptions) -> Result<PathBuf, LaunchError> {
    if let Some(c) = &o.commands {
        crate::steer::write_commands(dir, &c.records)?;
    }
    dir.write_scenario(s).map_err(LaunchError::Write)?;
    dir.write_member_scenario(s).map_err(LaunchError::Write)
}

/// Before anything is created: the member binaries are there, the real-time scheduling asked
/// for is granted, the live feeds (`--serve`, `--ros2`) are started, the file-descriptor limit
/// is raised.
fn preflight(s: &Scenario, o: &LaunchOptions) -> Result<Feeds, LaunchError> {
    if o.spawn {
        member_binaries_present()?;
    }
    crate::realtime::schedule(o)?;
    let commands = o
        .commands
        .as_ref()
        .map(|c| c.summaries())
        .unwrap_or_default();
    let (ros2, foxglove) = (o.ros2.as_ref(), o.foxglove.as_ref());
    let live = Feeds::start(s, o.serve, ros2, foxglove, &commands, &*o.notices)?;
    match raise_fd_limit() {
        Ok(n) => tracing::debug!(limit = n, "file-descriptor limit"),
        Err(e) => tracing::warn!("{e}"),
    }
    Ok(live)
}

/// The team's services: every member's state and wake-up, sized for the window (and the
/// longest link delay), with room for repairs under `--on-loss repair`; edges whose two ends
/// run on other hosts are left out.
fn team_layout(
    s: &Scenario,
    o: &LaunchOptions,
    hosts: &cdm_hosts::HostPlan,
) -> Result<TeamLayout, LaunchError> {
    let ids: Vec<u32> = s.formation.members.iter().map(|m| m.id).collect();
    let ins: BTreeMap<u32, Vec<u32>> = s
        .formation
        .members
        .iter()
        .filter_map(|m| m.link.map(|l| (m.id, l.in_neighbors.to_vec())))
        .collect();
    // Over delayed links a repair's new reader also needs its new in-neighbour's states of the
    // longest delay back (`LinkModel::oldest_candidate`): the buffers and history grow by it.
    let delay = u32::try_from(s.link_model().max_ticks()).unwrap_or(u32::MAX);
    let buffers = o.window.saturating_add(delay);
    let mut layout = TeamLayout::new(ids.clone(), ins, buffers)
        .map_err(LaunchError::Layout)?
        .with_scenario_hash(s.content_hash());
    if o.on_loss == cdm_engine::loss::OnLoss::Repair {
        let room = cdm_team::loss::repair_room(s, buffers);
        // A killed daemon loses its host's members at once (lockstep repair across hosts).
        let room = cdm_team::loss::with_group_losses(room, s, &hosts.remote_groups());
        layout = layout.with_repair_room(room);
    }
    // Lockstep on one host: members pass clock messages on (5 of the orchestrator's 11 file
    // descriptors per member saved; N = 2000 fits this machine's 20,000).
    if o.realtime.is_none() && o.hosts.hosts <= 1 {
        layout = layout.with_relayed_wakes();
    }
    Ok(hosts.hide_remote_edges(layout))
}

/// From the command's start to the first tick (zero for a team that never flew).
fn startup(first_tick: Option<Instant>) -> Duration {
    match (PROCESS_START.get(), first_tick) {
        (Some(&t0), Some(t)) => t.saturating_duration_since(t0),
        _ => Duration::ZERO,
    }
}

/// Spawns member `id`. Under `--on-interrupt land` in a process group of its own: a terminal's
/// Ctrl-C (SIGINT to the whole foreground group) then reaches the orchestrator alone, which
/// lands the team, instead of stopping every member at once.
fn spawn(
    o: &LaunchOptions,
    member_file: &std::path::Path,
    (id, role): (u32, cdm_model::formation::Role),
    flags: &[String],
) -> std::io::Result<std::process::Child> {
    if !o.land_on_interrupt {
        return spawn_member(member_file, &o.team, id, role, flags);
    }
    use std::os::unix::process::CommandExt;
    cdm_team::team::member_command(member_file, &o.team, id, role, flags)?
        .process_group(0)
        .spawn()
}

/// Spawns one process per member (`--spawn`), or tells how to start them by hand.
fn start_members(
    s: &Scenario,
    o: &LaunchOptions,
    dir: &RunDir,
    ports: &mut OrchestratorPorts,
    (member_file, scenario_file): (&std::path::Path, &std::path::Path),
    runs_here: impl Fn(u32) -> bool,
) -> Result<Vec<Spawned>, LaunchError> {
    let mut children = Vec::new();
    let record = crate::realtime::recording_flags(o, dir)?;
    if o.spawn {
        // Members forked from the template share its process group; a team that lands on the
        // terminal's interrupt needs its members out of the terminal's group, one by one.
        let mut template = match o.land_on_interrupt {
            true => None,
            false => member_template(member_file),
        };
        // With --hosts K, the other hosts' daemons spawn theirs.
        for m in s.formation.members.iter().filter(|m| runs_here(m.id)) {
            let mut flags = crate::realtime::member_flags(o);
            flags.extend(record.iter().cloned());
            flags.extend(o.vehicles.member_args());
            if o.realtime.is_none() {
                flags.extend(cdm_team::member_priority::lockstep_flags(o.agent_timeout));
            }
            let started = match template.as_mut() {
                Some(t) => t.fork(member_file, &o.team, (m.id, m.role), &flags),
                None => spawn(o, member_file, (m.id, m.role), &flags).map(Into::into),
            };
            match started {
                Ok(c) => {
                    if o.realtime.is_none() {
                        cdm_team::member_priority::lower(c.id());
                    }
                    children.push(Spawned { id: m.id, child: c });
                }
                Err(e) => {
                    if let Some(t) = template.take() {
                        t.finish();
                    }
                    stop_team(ports, &mut children, s, StopReason::AgentFault);
                    return Err(spawn_failed(s, dir, m.id, &e));
                }
            }
        }
        if let Some(t) = template {
            t.finish();
        }
    } else {
        tell_hand_start(s, o, scenario_file, record);
    }
    Ok(children)
}

/// A member that could not start: the run's audit says so, and the launch's error.
fn spawn_failed(s: &Scenario, dir: &RunDir, id: u32, e: &std::io::Error) -> LaunchError {
    let error = LaunchError::Spawn {
        id,
        what: describe_spawn_error(e),
    };
    let mut audit = Auditor::new(s);
    let text = error.to_string();
    audit.fault(fault(FaultKind::SpawnFailed, Some(id), None, 0, text));
    let _ = dir.write_audit(&audit.finish(false));
    error
}

/// Hand-started members are told every flag a spawned one gets, `--record` among them.
fn tell_hand_start(
    s: &Scenario,
    o: &LaunchOptions,
    scenario_file: &std::path::Path,
    record: Vec<String>,
) {
    let mut flags = crate::realtime::member_flags(o);
    flags.extend(record);
    flags.extend(o.vehicles.member_args());
    let of = |leader: bool| -> Vec<u32> {
        let members = s.formation.members.iter();
        members
            .filter(|m| m.role.is_leader() == leader)
            .map(|m| m.id)
            .collect()
    };
    o.notices.notice(&crate::notice::LaunchNotice::StartByHand {
        team: o.team.to_string(),
        members: s.formation.members.len(),
        scenario: scenario_file.to_path_buf(),
        flags,
        leaders: of(true),
        followers: of(false),
    });
}

/// The template every member is forked from (a member started from its binary pays its `exec`
/// and its scenario, a thousand times at N = 1000); `None`, and members started one by one,
/// when it cannot start.
fn member_template(member_file: &std::path::Path) -> Option<MemberTemplate> {
    match MemberTemplate::start(member_file) {
        Ok(t) => Some(t),
        Err(e) => {
            tracing::warn!("members started one by one: no member template: {e}");
            None
        }
    }
}

/// The stop of a run interrupted by SIGINT, SIGTERM, SIGHUP or SIGQUIT before it started.
fn interrupted_before_start() -> Stop {
    TeamFault::Interrupted {
        signal: cdm_process::signals::received().to_string(),
        at: InterruptedAt::BeforeStart,
    }
    .stop()
}

/// The stop when the team did not gather in time: names the members no process joined as (or,
/// when all joined, those still waiting for a neighbour's ports).
fn join_timeout(r: &cdm_iox::Readiness, team: &TeamName, within: Duration) -> Stop {
    let missing = r.not_joined();
    let (ids, what) = if missing.is_empty() {
        (r.waiting_for(), "did not connect to their neighbours in")
    } else {
        (missing, "did not join")
    };
    let list: Vec<String> = ids.iter().map(u32::to_string).collect();
    let message = format!(
        "agents {} {what} team {team} within {} s",
        list.join(", "),
        within.as_secs_f64()
    );
    (
        fault(
            FaultKind::JoinTimeout,
            ids.first().copied(),
            None,
            0,
            message,
        ),
        StopReason::AgentSilent,
    )
}

/// Wait for every process to open its ports, record the subscription graph, then tick; returns
/// when ticking began and whether every tick of the plan was completed.
fn run_team(
    s: &Scenario,
    o: &LaunchOptions,
    dir: &RunDir,
    ports: &mut OrchestratorPorts,
    children: &mut [Spawned],
    watchers: Watchers<'_>,
    interrupted: &AtomicBool,
) -> Result<(Instant, bool), Stop> {
    gather(s, o, ports, children, interrupted)?;
    write_subscriptions(s, ports, dir);
    let io_fault = |e: String| {
        (
            fault(FaultKind::Io, None, None, 0, e),
            StopReason::AgentFault,
        )
    };
    let tel = cdm_team::telemetry::open(dir, o.telemetry, o.every, s)
        .map_err(|e| io_fault(e.to_string()))?;
    // The file is written on its own thread: the loop the members wait for only hands the
    // rows over (cdm_team::telemetry_thread).
    let members = s.formation.members.len();
    let mut tel =
        ThreadedSink::start(tel, o.every, members).map_err(|e| io_fault(e.to_string()))?;
    fly_team(s, o, ports, children, &mut tel, watchers, interrupted)
}

/// Readiness: every process opened its ports, within a deadline.
pub(crate) fn gather(
    s: &Scenario,
    o: &LaunchOptions,
    ports: &mut OrchestratorPorts,
    children: &mut [Spawned],
    interrupted: &AtomicBool,
) -> Result<(), Stop> {
    let n = s.formation.members.len();
    // Members of real vehicles join once their vehicle is heard (and armed): as long as
    // --join-timeout allows, like hand-started ones.
    let join_deadline = if o.spawn && o.vehicles == cdm_member::vehicles::Vehicles::Model {
        Duration::from_secs(30) + Duration::from_millis(60 * n as u64)
    } else {
        o.join_timeout
    };
    let started = Instant::now();
    loop {
        if interrupted.load(Ordering::Relaxed) {
            return Err(interrupted_before_start());
        }
        if ports.readiness().is_complete() {
            ports.gathered();
            break;
        }
        check_children(children, 0)?;
        if started.elapsed() > join_deadline {
            return Err(join_timeout(&ports.readiness(), &o.team, join_deadline));
        }
        let _ = ports.wait(Duration::from_millis(20));
    }
    tracing::info!(
        agents = n,
        startup_s = started.elapsed().as_secs_f64(),
        "team {} ready",
        o.team
    );
    Ok(())
}

/// The subscription graph as iceoryx2 sees it (subscriptions.json, best effort).
pub(crate) fn write_subscriptions(s: &Scenario, ports: &OrchestratorPorts, dir: &RunDir) {
    let ids = s.formation.members.iter().map(|m| m.id);
    let subs: BTreeMap<String, Vec<String>> = match ports.subscriber_graph(ids) {
        Ok(graph) => graph
            .into_iter()
            .map(|(id, nodes)| (id.to_string(), nodes))
            .collect(),
        Err(e) => {
            tracing::warn!("subscriptions.json not written: {e}");
            return;
        }
    };
    let text = serde_json::to_string_pretty(&subs).unwrap_or_default();
    let _ =
        cdm_records::rundir::write_atomic(&dir.path().join("subscriptions.json"), text.as_bytes());
}

/// A telemetry write or flush that failed (a full disk) at `tick`: a fault, the file keeps its
/// whole ticks and no later tick may follow a gap.
fn io_stop(tick: u64) -> impl Fn(std::io::Error) -> Stop {
    move |e| {
        (
            cdm_records::record::write_fault(tick, &e),
            StopReason::AgentFault,
        )
    }
}

/// A transport error of the orchestrator's ports at `tick`.
fn transport_stop<E: std::fmt::Display>(tick: u64) -> impl Fn(E) -> Stop {
    move |e| {
        (
            fault(FaultKind::Transport, None, None, tick, e.to_string()),
            StopReason::AgentFault,
        )
    }
}

/// The team's protocol core (sans I/O) for this launch: lockstep over its members, window
/// and deadlines, and the scripted losses.
fn team_core(s: &Scenario, o: &LaunchOptions, last: u64, now: Duration) -> TeamCore {
    let cfg = TeamConfig {
        ids: s.formation.members.iter().map(|m| m.id).collect(),
        window: o.window,
        last_tick: last,
        agent_timeout: o.agent_timeout,
    };
    let book = TeamLosses::new(s, &cdm_team::loss::scripted_kills(&o.losses));
    let notices = o.commands.as_ref().map(|c| c.notices.clone());
    TeamCore::lockstep(cfg, now)
        .with_losses(book, repairs(o))
        .with_commands(notices.unwrap_or_default())
}

/// Whether the team repairs its losses: `--on-loss repair` with members this launch spawned
/// (it kills a silent one); in real time on one host only (a loss across hosts stays the host's
/// fault there).
pub fn repairs(o: &LaunchOptions) -> bool {
    let one_host_if_realtime = o.realtime.is_none() || o.hosts.hosts <= 1;
    o.on_loss == cdm_engine::loss::OnLoss::Repair && o.spawn && one_host_if_realtime
}

/// The lockstep flight: the team core paced by grants, in the one loop (`fly.rs`).
fn fly_team(
    s: &Scenario,
    o: &LaunchOptions,
    ports: &mut OrchestratorPorts,
    children: &mut [Spawned],
    tel: &mut dyn TelemetrySink,
    watchers: Watchers<'_>,
    interrupted: &AtomicBool,
) -> Result<(Instant, bool), Stop> {
    let last = o.max_ticks.map_or(s.last_tick(), |k| k.min(s.last_tick()));
    let clock = MonotonicClock::start();
    let mut core = team_core(s, o, last, clock.now());
    let mut io = LockstepIo {
        o,
        hash: s.content_hash(),
        last,
        ports,
        children,
        tel,
        w: watchers,
        rec: Recorder::new(s, last, &*o.notices),
        ticking: None,
        granted: 0,
        flown: std::sync::Arc::new(s.clone()),
        switching: None,
        interrupt_landing: false,
    };
    let all = crate::fly::fly(&mut core, &mut io, &clock, interrupted)?;
    Ok((io.ticking.unwrap_or_else(Instant::now), all))
}

/// The lockstep loop's I/O: grants on the clock channel, complete ticks audited and written,
/// waits woken by the members.
struct LockstepIo<'a, 'w> {
    o: &'a LaunchOptions,
    hash: u64,
    last: u64,
    ports: &'a mut OrchestratorPorts,
    children: &'a mut [Spawned],
    tel: &'a mut dyn TelemetrySink,
    w: Watchers<'w>,
    rec: Recorder,
    /// When the first grant went out.
    ticking: Option<Instant>,
    /// The highest tick granted so far.
    granted: u64,
    /// The plan flown, as commanded so far (the same before every switch).
    flown: std::sync::Arc<Scenario>,
    /// The latest accepted command's switch tick, until every member has flown it, and when
    /// it was accepted (logged: from the answer to the switch).
    switching: Option<(u64, Instant)>,
    /// An interrupt asked for a landing already (`--on-interrupt land`).
    interrupt_landing: bool,
}

impl crate::fly::TeamIo for LockstepIo<'_, '_> {
    fn receive(&mut self, core: &mut TeamCore, now: Duration) -> Result<(), Stop> {
        self.ports
            .receive_notified_states(|msg| core.on_state(&msg, now))
            .map_err(transport_stop(core.position()))?;
        self.serve_command(core)
    }

    fn land_on_interrupt(&mut self, core: &mut TeamCore, signal: &'static str) -> bool {
        if !self.o.land_on_interrupt || self.interrupt_landing {
            return false;
        }
        self.interrupt_landing = true;
        self.land_now(core, signal)
    }

    fn grant(&mut self, core: &TeamCore, g: u64) -> Result<(), Stop> {
        self.publish(notices(ClockMsg::run(g, self.hash), core), core)?;
        self.granted = g;
        self.ticking.get_or_insert_with(Instant::now);
        Ok(())
    }

    fn announce(&mut self, core: &TeamCore, n: LossNotice) -> Result<(), Stop> {
        let msg = notices(ClockMsg::run(self.granted, self.hash), core).with_loss(Some(n));
        self.publish(msg, core)
    }

    fn steer(&mut self, core: &mut TeamCore, n: SteerNotice) -> Result<(), Stop> {
        let msg = notices(ClockMsg::run(self.granted, self.hash), core).with_steer(Some(n));
        self.publish(msg, core)
    }

    fn complete(
        &mut self,
        core: &mut TeamCore,
        tick: u64,
        states: TickStates,
    ) -> Result<Option<bool>, Stop> {
        let stop = self.o.stop_on_violation;
        let s = std::sync::Arc::clone(&self.flown);
        let (w, tel) = (&mut self.w, &mut *self.tel);
        let ends = self.rec.complete(&s, (tick, states), core, w, tel, stop)?;
        if let Some((switch, accepted)) = self.switching.filter(|&(k, _)| tick >= k) {
            let ms = accepted.elapsed().as_secs_f64() * 1e3;
            tracing::info!(
                tick = switch,
                after_ms = ms,
                "every member flew the switch tick"
            );
            self.switching = None;
        }
        Ok(ends.then_some(tick >= self.last))
    }

    /// [`check_exited`] after a read of every member: one that died after sending states,
    /// before it would have woken the orchestrator, is read here (reads otherwise go by
    /// wake-ups).
    fn check_exited(&mut self, core: &mut TeamCore, now: Duration) -> Result<(), Stop> {
        self.ports
            .receive_states(|msg| core.on_state(&msg, now))
            .map_err(transport_stop(core.position()))?;
        check_exited(core, self.children, self.w.hosts, now);
        Ok(())
    }

    fn kill(&mut self, id: u32) {
        cdm_team::loss::kill_and_reap(self.children, id);
        self.w.hosts.kill(id);
    }

    /// On this host's shared memory, or (with `--hosts`) through the bridge, which knows where
    /// each reader runs.
    fn linked(&self, reader: u32, writer: u32) -> bool {
        self.w.hosts.linked(self.ports, reader, writer)
    }

    fn flush(&mut self, at: u64) -> Result<(), Stop> {
        self.tel.flush().map_err(io_stop(at))
    }

    /// Waits at most `d` for the members' wake-ups, after a nap when they are far from the
    /// grant (`nap_before_wait`: their wake-ups then cost the orchestrator one).
    fn wait(&mut self, core: &TeamCore, d: Duration) {
        let window = u64::from(self.o.window);
        let nap = nap_before_wait(self.granted, core.position(), window).min(d);
        if !nap.is_zero() {
            std::thread::sleep(nap);
        }
        // A command is looked for at least this often while the members are slow to answer.
        let d = match self.w.steer.channel {
            Some(_) => (d - nap).min(COMMAND_POLL),
            None => d - nap,
        };
        let _ = self.ports.wait(d);
    }

    fn end(&mut self, core: &TeamCore, finished: bool) -> Result<(), Stop> {
        if !finished {
            let _ = self.tel.flush();
            return Ok(());
        }
        self.rec.progress.finish();
        self.tel.finish().map_err(io_stop(core.position()))
    }
}

/// How often a lockstep loop waiting for its members looks for a command, at the least.
const COMMAND_POLL: Duration = Duration::from_millis(50);

impl LockstepIo<'_, '_> {
    /// Answers the command waiting on the channel, if one is. It is decided here, between two
    /// turns of the loop (the grants pause meanwhile): its switch is the first tick not granted
    /// yet, so no member has flown past it, and the flight up to it is the same whichever
    /// wall-clock instant the command came at. An accepted one goes to the core, which
    /// announces it before granting its switch tick.
    fn serve_command(&mut self, core: &mut TeamCore) -> Result<(), Stop> {
        let Some(channel) = self.w.steer.channel else {
            return Ok(());
        };
        let at = self.flight_at(core);
        let live = &mut *self.w.steer.live;
        let mut decided = None;
        channel.serve_one(|request| match request {
            Err(why) => CommandAnswer::without_switch(Answered::BadInput, why.to_string()),
            Ok(r) => {
                let d = live.decide(r, at);
                let answer = d.answer.clone();
                decided = Some(d);
                answer
            }
        });
        match decided {
            Some(d) => self.apply(core, d).map(drop),
            None => Ok(()),
        }
    }

    /// Where the flight is for a command decided now: the first tick not granted yet is free.
    fn flight_at(&self, core: &TeamCore) -> FlightAt {
        FlightAt {
            first_free: self.granted + 1,
            complete: core.position(),
            last: self.last,
        }
    }

    /// `--on-interrupt land`, the first interrupt: a land decided now as an operator's is.
    /// True when it is accepted, or the team lands already.
    fn land_now(&mut self, core: &mut TeamCore, signal: &'static str) -> bool {
        let d = (self.w.steer.live).decide(CommandRequest::land(), self.flight_at(core));
        let t_s = self.granted as f64 * self.flown.dt_s();
        let landing = (self.flown.plan.phases().last())
            .is_some_and(|p| p.kind == cdm_model::plan::PhaseKind::Landing && p.t_start_s <= t_s);
        let text = d.answer.text.clone();
        let landed = matches!(self.apply(core, d), Ok(true)) || landing;
        let what = if landed {
            "landing the team (--on-interrupt land); a second signal stops it at once"
        } else {
            "the team cannot land now; stopping it"
        };
        self.o
            .notices
            .notice(&format_args!("{signal}: {what}\n  {text}"));
        landed
    }

    /// A decided command: an accepted one goes to the core, which announces it before
    /// granting its switch tick; a recorded one goes to commands.json, the live view and the
    /// progress line. True when accepted.
    fn apply(&mut self, core: &mut TeamCore, d: crate::steer::LiveDecision) -> Result<bool, Stop> {
        tracing::info!(answer = ?d.answer.answer, decided_ms = d.answer.decided_ms, "{}", d.answer.text);
        if !d.recorded {
            return Ok(false);
        }
        let accepted = d.accepted.is_some();
        if let Some((notice, flown, last)) = d.accepted {
            self.switching = Some((notice.tick, std::time::Instant::now()));
            let last = self.o.max_ticks.map_or(last, |k| k.min(last));
            core.command(notice, last);
            self.w.audit.replan(&flown);
            self.flown = flown;
            self.last = last;
            self.rec.progress.set_last_tick(last);
        }
        let steer = &mut self.w.steer;
        if let Some(r) = steer.live.records().last() {
            self.w.live.command(&r.summary());
        }
        let (n_accepted, refused) = steer.live.counts();
        self.rec.progress.set_commands(n_accepted, refused);
        crate::steer::write_commands(steer.dir, steer.live.records()).map_err(|e| {
            (
                fault(FaultKind::Io, None, None, core.position(), e.to_string()),
                StopReason::AgentFault,
            )
        })?;
        Ok(accepted)
    }

    fn publish(&mut self, msg: ClockMsg, core: &TeamCore) -> Result<(), Stop> {
        self.ports
            .publish_clock(msg)
            .map(drop)
            .map_err(transport_stop(core.position()))
    }
}

/// `msg` with the latest loss and command notices (every clock message repeats them).
fn notices(msg: ClockMsg, core: &TeamCore) -> ClockMsg {
    msg.with_loss(core.losses().and_then(|l| l.notice()))
        .with_steer(core.steer_notice())
}

/// Hands the team core the first member that exited and is not already lost: one of ours, or
/// one the bridge reports from another host.
fn check_exited(
    core: &mut TeamCore,
    children: &mut [Spawned],
    hosts: &dyn OtherHosts,
    now: Duration,
) {
    let lost = |id| core.losses().is_some_and(|l| l.is_lost(id));
    if let Some((id, how)) = first_exited_but(children, lost) {
        core.on_exited(id, how, now);
    }
    // Every remote exit at once: a lost host's members are lost together, as members killed
    // at the same tick on one host.
    while let Some((id, how)) = hosts.take_exited() {
        core.on_exited(id, how, now);
    }
}

/// What every complete tick gets: the shared audit and telemetry of `simulate`
/// (`TickRecorder`), then the live view and the progress line.
struct Recorder {
    tick: TickRecorder,
    progress: Box<dyn cdm_team::notices::TickProgress>,
    /// The losses' audit records (as `simulate` writes them).
    losses: LossState,
}

impl Recorder {
    fn new(s: &Scenario, last: u64, notices: &dyn cdm_team::notices::NoticeSink) -> Self {
        Recorder {
            tick: TickRecorder::new(s),
            progress: notices.progress("launch", last, s.dt_s()),
            losses: LossState::new(s, LossSchedule::default()),
        }
    }

    /// Before tick `tick` is audited: record the losses whose repair applies from it (their
    /// bodies leave the audit; their rows leave telemetry, having no state).
    fn lose(&mut self, s: &Scenario, tick: u64, book: Option<&TeamLosses>, audit: &mut Auditor) {
        for (cause, ids) in book.map(|b| b.due_at(tick)).unwrap_or_default() {
            self.losses.record(s, tick, &ids, cause, audit);
        }
    }

    /// Complete tick `tick`: its losses, audit and telemetry, then its states go back to the
    /// core. True when the run ends here, at its first violation (`stop_on_violation`).
    fn complete(
        &mut self,
        s: &Scenario,
        (tick, states): (u64, TickStates),
        core: &mut TeamCore,
        w: &mut Watchers<'_>,
        tel: &mut dyn TelemetrySink,
        stop_on_violation: bool,
    ) -> Result<bool, Stop> {
        self.lose(s, tick, core.losses(), w.audit);
        self.record(s, tick, &states, w.audit, w.live, tel)?;
        core.recycle(states);
        if stop_on_violation && w.audit.violation_count() > 0 {
            w.audit.stop_on_violation();
            self.progress.finish();
            let _ = tel.flush();
            return Ok(true);
        }
        Ok(false)
    }

    fn record(
        &mut self,
        s: &Scenario,
        tick: u64,
        states: &[Option<StateMsg>],
        audit: &mut Auditor,
        live: &mut Feeds,
        tel: &mut dyn TelemetrySink,
    ) -> Result<(), Stop> {
        let member = |k: usize| {
            states[k].map(|m| {
                let x = m.state;
                (vec3([x[0], x[1], x[2]]), vec3([x[3], x[4], x[5]]))
            })
        };
        let t = self
            .tick
            .record(s, tick, audit, tel, member)
            .map_err(|f| (f, StopReason::AgentFault))?;
        let (pos, ht) = (self.tick.positions(), self.tick.desired());
        live.tick(tick, t, (pos, ht), |k| states[k].is_some(), audit.report());
        self.progress.tick(tick, audit.report());
        Ok(())
    }
}
