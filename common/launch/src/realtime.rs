//! `launch --realtime`: the orchestrator as a monitor. It announces the start instant, then
//! never grants or waits for anyone: it audits at its own rate from the newest state of every
//! member brought to common instants, writes telemetry with the usual columns (rows at the
//! audit instants, through `TickRecorder` as lockstep does), and stops the team at the end of
//! the plan, on a fault, a stale or exited member, or a signal. With `--on-loss repair` (the
//! default, members spawned on one host) a dead, stale or vehicle-lost member, or `--lose`, is a
//! loss instead: killed if need be, recorded, announced on the clock channel, and repaired
//! around by its readers. Every decision is cdm-runtime's team core over its real-time pacing
//! (no I/O, driven by the clock passed in), flown by the one loop of `fly.rs`; this file moves
//! messages, sleeps, and writes files.

use std::os::unix::fs::DirBuilderExt;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use crate::feeds::Feeds;
use cdm_engine::loss::{LossAt, LossSchedule, LossState};
use cdm_iox::OrchestratorPorts;
use cdm_math::Vec3;
use cdm_model::formation::Role;
use cdm_model::outcome::FaultKind;
use cdm_records::audit::{Auditor, LossRecord, RealtimeFigures};
use cdm_records::record::{write_fault, TickRecorder};
use cdm_records::rundir::RunDir;
use cdm_records::telemetry::TelemetrySink;
use cdm_runtime::messages::{ClockMsg, LossNotice, SteerNotice, StopReason};
use cdm_runtime::realtime_loop::unix_now_ns;
use cdm_runtime::realtime_monitor::{MonitorCore, RunFigures};
use cdm_runtime::seams::{Clock, MonotonicClock};
use cdm_runtime::team_core::Pacing;
use cdm_runtime::team_core::{LostMember, RealtimePlan, TeamCore, WallClock, MEMBER_STALE_FACTOR};
use cdm_runtime::team_loss::TeamLosses;
use cdm_scenario::Scenario;

use crate::launch::LaunchOptions;
use crate::launch_error::LaunchError;
use crate::realtime_steer::RealtimeSteer;
use crate::vehicle_reports::VehicleBook;
use cdm_team::team::{fault, first_exited_but, Spawned, Stop};

/// Which members run on other hosts and may still send reports (`launch --hosts`: those whose
/// daemon neither stopped nor was lost).
pub type Elsewhere<'a> = &'a dyn Fn(u32) -> bool;

/// Validated real-time options.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RealtimeOptions {
    pub audit_hz: f64,
    pub stale_after: Duration,
    pub phase_seed: u32,
    pub rt_priority: Option<u8>,
    /// Spawned members write their recordings (`recording/<id>.mcap`).
    pub record: bool,
}

/// `--rt-priority`: the orchestrator takes SCHED_FIFO itself before it creates or spawns
/// anything (spawned members are also told with the flag, for hand-started ones), so a
/// machine that does not allow it is refused up front with exit 2.
pub fn schedule(o: &LaunchOptions) -> Result<(), LaunchError> {
    match o.realtime.as_ref().and_then(|rt| rt.rt_priority) {
        Some(p) => Ok(cdm_process::sched::fifo(p)?),
        None => Ok(()),
    }
}

/// How long a member stopped by `--lose` has to exit after SIGTERM before it is SIGKILLed (it
/// reads the signal within a tick; the monitor's loop waits meanwhile).
const SCRIPTED_GRACE: Duration = Duration::from_millis(200);

/// The state buffer a real-time team needs (ticks of states kept per subscriber): readers read
/// the newest state at their own rate, so a few periods are plenty.
pub const REALTIME_WINDOW: u32 = 16;

/// The member flags of a real-time launch (spawned members get them; hand-started ones are told).
/// A team that repairs its losses gives its members [`MEMBER_STALE_FACTOR`] times the stale
/// bound: the monitor finds a silent member first, and its readers switch before they give up.
pub fn member_flags(o: &LaunchOptions) -> Vec<String> {
    match &o.realtime {
        Some(rt) => {
            let factor = if crate::launch::repairs(o) {
                MEMBER_STALE_FACTOR
            } else {
                1
            };
            let mut flags = vec![
                "--realtime".into(),
                "--stale-after".into(),
                (rt.stale_after * factor).as_secs_f64().to_string(),
            ];
            if let Some(p) = rt.rt_priority {
                flags.extend(["--rt-priority".into(), p.to_string()]);
            }
            flags
        }
        None => Vec::new(),
    }
}

/// `--record DIR` for the members a real-time launch spawns: the run directory's recording
/// folder (created here, readable by this user only), where each member writes the neighbour
/// states its ticks flew on (cdm-recording), so `replay` can fly the run again. None in
/// lockstep, which replays without one.
pub fn recording_flags(o: &LaunchOptions, dir: &RunDir) -> Result<Vec<String>, LaunchError> {
    if !o.realtime.as_ref().is_some_and(|rt| rt.record) {
        return Ok(Vec::new());
    }
    let at = dir.path().join(cdm_recording::DIR);
    let made = std::fs::DirBuilder::new()
        .mode(0o700)
        .create(&at)
        .or_else(|e| match e.kind() {
            std::io::ErrorKind::AlreadyExists if at.is_dir() => Ok(()),
            _ => Err(e),
        });
    made.map_err(|e| LaunchError::RecordingDir {
        reason: cdm_files::describe(&at, &e),
        path: at.clone(),
    })?;
    let at = at.canonicalize().unwrap_or(at);
    Ok(vec!["--record".into(), at.display().to_string()])
}

/// Wall-clock lead of the start instant over its announcement, so every member has the clock
/// message before tick 0 (members wake on it at once; the lead covers a loaded machine).
fn start_lead(agents: usize) -> Duration {
    Duration::from_millis(300) + Duration::from_micros(500 * agents as u64)
}

/// Gathers the team, announces the start, monitors until the end of the plan or a fault, and
/// adds the pacing figures to the audit. Returns when the flight began and whether the whole
/// plan was audited (as the lockstep loop does); the caller stops the team. `team`'s third part
/// says which members run on other hosts whose final reports may still come (`launch --hosts`).
pub(crate) fn run(
    s: &Scenario,
    o: &LaunchOptions,
    rt: &RealtimeOptions,
    dir: &RunDir,
    team: (&mut OrchestratorPorts, &mut [Spawned], Elsewhere),
    (audit, live, steer): (&mut Auditor, &mut Feeds, crate::steer::Steer),
    interrupted: &AtomicBool,
) -> Result<(Instant, bool), Stop> {
    let (ports, children, elsewhere) = team;
    crate::launch::gather(s, o, ports, children, interrupted)?;
    crate::team_arm::arm_team(s, o, ports, children, interrupted)?;
    crate::launch::write_subscriptions(s, ports, dir);
    let mut tel = open_telemetry(s, o, dir)?;
    let (mut core, clock, start, start_msg) = announce(s, o, rt, ports)?;
    let hash = s.content_hash();
    let plan = *wall_clock(&mut core).plan();
    let (last_audit, period_s) = (plan.last_audit, plan.period_s);
    let mut m = Monitor {
        s,
        ports,
        children,
        audit,
        live,
        tel: tel.as_mut(),
        rec: TickRecorder::new(s),
        at: Vec::with_capacity(s.formation.members.len()),
        vehicles: VehicleBook::new(hash),
        losses: LossState::new(s, LossSchedule::default()),
        lost: Vec::new(),
        out: vec![false; s.formation.members.len()],
        start_msg,
        scripted: (cdm_team::loss::scripted_kills(&o.losses).into_iter())
            .map(|(id, _)| id)
            .collect(),
        progress: o.notices.progress("launch", last_audit, period_s),
        notices: o.notices.clone(),
        steer: RealtimeSteer::new(
            (steer, clock),
            s,
            (o.max_ticks, o.land_on_interrupt, &o.realtime_commands),
            o.notices.clone(),
        ),
    };
    let cpu_at_start = team_cpu_s(m.children);
    let result = crate::fly::fly(&mut core, &mut m, &clock, interrupted);
    let (mut vehicles, ports, children) = (m.vehicles, m.ports, m.children);
    let book = wall_clock(&mut core);
    let audits = book.audits();
    let cpu_s = team_cpu_s(children) - cpu_at_start;
    let flight_s = Instant::now()
        .saturating_duration_since(start)
        .as_secs_f64();
    // Whatever ended the flight: tell the members, and take their final pacing reports.
    let reason = result
        .as_ref()
        .map_or_else(|(_, r)| *r, |_| StopReason::Finished);
    let book = book.book_mut();
    book.stopping();
    let _ = ports.publish_clock(ClockMsg::stop(s.last_tick(), hash, reason));
    collect_final_reports(book, ports, (children, elsewhere), &mut vehicles);
    vehicles.record(audit);
    let cpu_cores = (!children.is_empty() && flight_s > 0.0).then(|| cpu_s / flight_s);
    let figures = book.figures(run_figures(rt, audits, flight_s, cpu_cores));
    o.notices
        .notice(&FiguresLine(&figures, s.formation.members.len()));
    audit.set_realtime(figures);
    match result {
        Ok(complete) => {
            let io = |e: std::io::Error| (write_fault(audits, &e), StopReason::AgentFault);
            tel.finish().map_err(io)?;
            Ok((start, complete))
        }
        Err(stop) => {
            let _ = tel.flush();
            Err(stop)
        }
    }
}

/// The run's telemetry file; a file that cannot be opened stops the team as an I/O fault.
fn open_telemetry(
    s: &Scenario,
    o: &LaunchOptions,
    dir: &RunDir,
) -> Result<Box<dyn cdm_records::telemetry::TelemetrySink + Send>, Stop> {
    cdm_team::telemetry::open(dir, o.telemetry, o.every, s).map_err(|e| {
        let f = fault(FaultKind::Io, None, None, 0, e.to_string());
        (f, StopReason::AgentFault)
    })
}

/// The monitor's own figures of a flight of `wall_s` seconds with `audits` instants audited.
fn run_figures(
    rt: &RealtimeOptions,
    audits: u64,
    wall_s: f64,
    team_cpu_cores: Option<f64>,
) -> RunFigures {
    RunFigures {
        audits,
        audit_hz: rt.audit_hz,
        phase_seed: rt.phase_seed,
        stale_after_s: rt.stale_after.as_secs_f64(),
        wall_s,
        team_cpu_cores,
    }
}

/// The real-time pacing of a team core (always, for the core [`announce`] made).
fn wall_clock(core: &mut TeamCore) -> &mut WallClock {
    core.wall_clock_mut()
        .expect("the real-time launch makes a real-time team core")
}

/// The team core of `s`'s flight on a clock started now, the start instant it announced (tick
/// 0's instant on this process's monotonic clock) and the clock message that announced it.
fn announce(
    s: &Scenario,
    o: &LaunchOptions,
    rt: &RealtimeOptions,
    ports: &mut OrchestratorPorts,
) -> Result<(TeamCore, MonotonicClock, Instant, ClockMsg), Stop> {
    let members: Vec<_> = s
        .formation
        .members
        .iter()
        .map(|m| (m.id, m.start, m.role == Role::Follower))
        .collect();
    let hash = s.content_hash();
    let history = (s.dt_s(), rt.stale_after.as_secs_f64());
    let book = MonitorCore::new(&members, hash, history, rt.phase_seed);
    let lead = start_lead(members.len());
    let start_ns = unix_now_ns() + lead.as_nanos() as u64;
    let (started, clock) = (Instant::now(), MonotonicClock::start());
    let last = o.max_ticks.map_or(s.last_tick(), |k| k.min(s.last_tick()));
    let plan = RealtimePlan::new(lead, (last, s.dt_s()), rt.audit_hz, rt.stale_after);
    let start_msg = ClockMsg::realtime(start_ns, hash, rt.phase_seed);
    ports
        .publish_clock(start_msg)
        .map_err(|e| transport(e, 0))?;
    let scripted = cdm_team::loss::scripted_kills(&o.losses);
    let core = TeamCore::realtime(plan, book, clock.now())
        .with_losses(TeamLosses::new(s, &scripted), crate::launch::repairs(o));
    Ok((core, clock, started + lead, start_msg))
}

/// The pacing line of the summary (and what the links dropped, when they are impaired), for a
/// team of this many members.
struct FiguresLine<'a>(&'a RealtimeFigures, usize);

impl std::fmt::Display for FiguresLine<'_> {
    fn fmt(&self, out: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let FiguresLine(f, agents) = *self;
        write!(
            out,
            "  real time: {} ticks, {} late ({:.3} %), neighbour age p50 {:.2} ms, p99 {:.2} ms, max {:.2} ms ({} of {} members reported)",
            f.ticks,
            f.late_ticks,
            f.late_ticks_pct,
            f.neighbor_age_ms_p50,
            f.neighbor_age_ms_p99,
            f.neighbor_age_ms_max,
            f.members_reported,
            agents
        )?;
        if f.link_states_lost > 0 {
            write!(
                out,
                "; the links dropped {} of {} neighbour states",
                f.link_states_lost, f.link_states_received
            )?;
        }
        Ok(())
    }
}

/// Waits (at most 1.5 s) for the final pacing report of every member still running, here or
/// (`elsewhere`) on another host.
fn collect_final_reports(
    core: &mut MonitorCore,
    ports: &mut OrchestratorPorts,
    (children, elsewhere): (&mut [Spawned], Elsewhere),
    vehicles: &mut VehicleBook,
) {
    let until = Instant::now() + Duration::from_millis(1500);
    while Instant::now() < until {
        let _ = ports.receive_states(|msg| {
            if !vehicles.take(&msg) {
                core.on_state(&msg);
            }
        });
        let mut running = Vec::new();
        for c in children.iter_mut() {
            if matches!(c.child.try_wait(), Ok(None)) {
                running.push(c.id);
            }
        }
        // Hand-started teams (no children): wait for everyone, bounded.
        let alive = |id: u32| children.is_empty() || running.contains(&id) || elsewhere(id);
        if core.final_reports_in(alive) {
            return;
        }
        let _ = ports.wait(Duration::from_millis(20));
    }
}

/// CPU seconds (user + system) used so far by this process and its running members, from
/// /proc/<pid>/stat (fields 14 and 15, in clock ticks). The difference over the flight is the
/// team's CPU (members that exit meanwhile drop out: a faulted flight reads low).
fn team_cpu_s(children: &[Spawned]) -> f64 {
    // SAFETY: sysconf takes no pointers.
    let hz = unsafe { libc::sysconf(libc::_SC_CLK_TCK) }.max(1) as f64;
    let ticks = |path: String| -> u64 {
        let Ok(text) = std::fs::read_to_string(path) else {
            return 0;
        };
        // The command name (field 2) may hold spaces: count fields after its closing ')'.
        let rest = text.rsplit_once(')').map_or("", |(_, r)| r);
        let f: Vec<u64> = rest
            .split_whitespace()
            .skip(11)
            .take(2)
            .filter_map(|v| v.parse().ok())
            .collect();
        f.iter().sum()
    };
    let own = ticks("/proc/self/stat".into());
    let members: u64 = children
        .iter()
        .map(|c| ticks(format!("/proc/{}/stat", c.child.id())))
        .sum();
    (own + members) as f64 / hz
}

fn transport(e: impl std::fmt::Display, tick: u64) -> Stop {
    let f = fault(FaultKind::Transport, None, None, tick, e.to_string());
    (f, StopReason::AgentFault)
}

/// The real-time loop's I/O: states drained (vehicle reports kept aside), audit instants
/// written, losses recorded, plain sleeps.
struct Monitor<'a, 'p> {
    s: &'a Scenario,
    ports: &'p mut OrchestratorPorts,
    children: &'p mut [Spawned],
    audit: &'a mut Auditor,
    /// The live feeds (`--serve`, `--ros2`): every audited instant is offered to them (each
    /// sends at most its own rate).
    live: &'a mut Feeds,
    tel: &'a mut dyn TelemetrySink,
    /// The shared per-tick audit and telemetry (`cdm_records::record`).
    rec: TickRecorder,
    /// Every member's position and velocity at the instant being audited (formation order).
    at: Vec<(Vec3, Vec3)>,
    /// The members' vehicle reports (MAVLink), kept out of the monitor.
    vehicles: VehicleBook,
    /// The losses' audit records (the repair `simulate` records, loss after loss).
    losses: LossState,
    /// The audit records of losses found whose member is still audited (up to its newest
    /// state), with the instant it leaves from.
    lost: Vec<(u64, Vec<LossRecord>)>,
    /// Members out of the audit and telemetry (formation order).
    out: Vec<bool>,
    /// The start's clock message: loss and command notices ride on copies of it.
    start_msg: ClockMsg,
    /// The members `--lose` stops.
    scripted: Vec<u32>,
    progress: Box<dyn cdm_team::notices::TickProgress>,
    notices: std::sync::Arc<dyn cdm_team::notices::NoticeSink>,
    /// Commands to the team in flight, and the plan as commanded so far.
    steer: RealtimeSteer<'a>,
}

impl crate::fly::TeamIo for Monitor<'_, '_> {
    /// Takes every state and report that arrived (the core keeps the fault that stops it).
    fn receive(&mut self, core: &mut TeamCore, now: Duration) -> Result<(), Stop> {
        let vehicles = &mut self.vehicles;
        let at = core.position();
        self.ports
            .receive_states(|msg| {
                if !vehicles.take(&msg) {
                    core.on_state(&msg, now);
                }
            })
            .map_err(|e| transport(e, at))?;
        (self.steer).serve(core, (&mut *self.live, &mut *self.progress))
    }

    fn announce(&mut self, core: &TeamCore, n: LossNotice) -> Result<(), Stop> {
        let msg = self
            .start_msg
            .with_loss(Some(n))
            .with_steer(core.steer_notice());
        let at = core.position();
        self.ports
            .publish_clock(msg)
            .map(drop)
            .map_err(|e| transport(e, at))
    }

    fn steer(&mut self, core: &mut TeamCore, n: SteerNotice) -> Result<(), Stop> {
        let loss = core.losses().and_then(|l| l.notice());
        let msg = self.start_msg.with_loss(loss).with_steer(Some(n));
        let at = core.position();
        self.ports
            .publish_clock(msg)
            .map_err(|e| transport(e, at))?;
        (self.steer).on_notice(
            core,
            n,
            (&mut *self.audit, &mut *self.live, &mut *self.progress),
        )
    }

    fn land_on_interrupt(&mut self, core: &mut TeamCore, signal: &'static str) -> bool {
        (self.steer).land_on_interrupt(core, signal, (&mut *self.live, &mut *self.progress))
    }

    fn audit(&mut self, core: &TeamCore, index: u64, t_s: f64) -> Result<(), Stop> {
        let Pacing::Realtime(w) = core.pacing() else {
            return Ok(());
        };
        self.audit_once(w.book(), index, t_s)?;
        self.progress.tick(index, self.audit.report());
        Ok(())
    }

    fn lost(&mut self, lost: LostMember) {
        self.lose(lost);
    }

    fn check_exited(&mut self, core: &mut TeamCore, now: Duration) -> Result<(), Stop> {
        let gone = |id| core.is_gone(id);
        if let Some((id, how)) = first_exited_but(self.children, gone) {
            core.on_exited(id, how, now);
        }
        Ok(())
    }

    /// A scripted loss (`--lose`) is stopped by SIGTERM, so its recording holds every tick it
    /// flew and `replay` flies through it; a silent member (perhaps hung) is SIGKILLed.
    fn kill(&mut self, id: u32) {
        if self.scripted.contains(&id) {
            cdm_team::loss::stop_and_reap(self.children, id, SCRIPTED_GRACE);
        } else {
            cdm_team::loss::kill_and_reap(self.children, id);
        }
    }

    fn linked(&self, reader: u32, writer: u32) -> bool {
        self.ports.linked(reader, writer).unwrap_or(false)
    }

    fn flush(&mut self, _at: u64) -> Result<(), Stop> {
        let _ = self.tel.flush();
        Ok(())
    }

    /// A plain sleep: the transport's timed wait is coarser, and members do not wake the
    /// monitor in real time.
    fn wait(&mut self, _core: &TeamCore, d: Duration) {
        std::thread::sleep(d);
    }

    fn end(&mut self, _core: &TeamCore, finished: bool) -> Result<(), Stop> {
        self.steer.end();
        if finished {
            self.progress.finish();
        }
        self.record_losses(u64::MAX);
        Ok(())
    }
}

impl Monitor<'_, '_> {
    /// Audits and writes the instant `t_s` (audit index `index`) with the recorder `simulate`
    /// and lockstep `launch` use: the same audit, the same columns. Lost members have no row.
    fn audit_once(&mut self, book: &MonitorCore, index: u64, t_s: f64) -> Result<(), Stop> {
        self.record_losses(index);
        let n = self.s.formation.members.len();
        self.at.clear();
        self.at.extend((0..n).map(|k| book.state_at(k, t_s)));
        let (at, out) = (&self.at, &self.out);
        let member = |k: usize| (!out[k]).then(|| at[k]);
        // The commanded plan: the same as the launched one before every switch.
        let flown = std::sync::Arc::clone(self.steer.flown());
        self.rec
            .record_at(&flown, (index, t_s), self.audit, self.tel, member)
            .map_err(|f| (f, StopReason::AgentFault))?;
        // The feeds count ticks of the plan (dt), as in lockstep; an audit instant is at most
        // half a tick from its nearest one. A lost member is no longer shown.
        let tick = (t_s / self.s.dt_s()).round() as u64;
        let shown = (self.rec.positions(), self.rec.desired());
        self.live
            .tick(tick, t_s, shown, |k| !out[k], self.audit.report());
        Ok(())
    }

    /// A member lost: the repair is computed now, in the order the losses were found (each
    /// repairs the graph the one before left, as the members do), and said; the audit takes
    /// the record at the instant the body leaves ([`Self::record_losses`]).
    fn lose(&mut self, l: LostMember) {
        let at = LossAt {
            last_tick: l.last_tick.unwrap_or(0),
            tick: l.index,
            t_s: l.t_s,
            repair_tick: Some(l.tick),
        };
        let (r, records) = self.losses.repair(self.s, at, &[l.id], l.cause);
        let switched: Vec<u32> = r.retriangulated.iter().map(|x| x.id).collect();
        self.notices.notice(&crate::notice::LaunchNotice::Lost {
            id: l.id,
            cause: l.cause,
            last_tick: at.last_tick,
            readers: switched,
            repair_tick: l.tick,
        });
        self.lost.push((l.index, records));
    }

    /// The losses whose member leaves the audit at or before instant `index`: from now on its
    /// body is out of the audit and telemetry.
    fn record_losses(&mut self, index: u64) {
        let (now, later): (Vec<_>, Vec<_>) = std::mem::take(&mut self.lost)
            .into_iter()
            .partition(|(from, _)| *from <= index);
        self.lost = later;
        for rec in now.into_iter().flat_map(|(_, records)| records) {
            if let Some(k) = self.s.formation.members.iter().position(|m| m.id == rec.id) {
                self.out[k] = true;
            }
            self.audit.lose(rec);
        }
    }
}
