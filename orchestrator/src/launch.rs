//! `orchestrator launch`: create the team's services, spawn one process per quadcopter (or wait
//! for hand-started ones), step the shared clock, audit every tick live, and stop the team.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use common::audit::{AuditReport, Auditor, FaultRecord};

use crate::viewer::live::LiveView;
use common::engine::desired_positions;
use common::formation::Role;
use common::math::{vec3, Vec3};
use common::messages::{AgentStatus, ClockMsg, FaultCode, StateMsg, StopReason};
use common::outcome::FaultKind;
use common::rundir::RunDir;
use common::scenario::Scenario;
use common::simulate::id_order;
use common::step::tick_time;
use common::team_core::{first_grant, next_grant, FaultRank};
use common::telemetry::Row;
use common::transport::{
    describe_spawn_error, raise_fd_limit, OrchestratorPorts, TeamLayout, TeamName,
};

use crate::team::{
    check_children, exited_fault, fault, first_exited, member_binaries_present, spawn_member,
    stop_team, Spawned, Stop,
};
use crate::Failure;

/// Options of a launch, validated.
pub struct LaunchOptions {
    pub team: TeamName,
    pub out: PathBuf,
    pub force: bool,
    pub every: u64,
    /// The telemetry file's format.
    pub telemetry: common::telemetry::TelemetryFormat,
    pub window: u32,
    pub spawn: bool,
    pub agent_timeout: Duration,
    pub join_timeout: Duration,
    pub quiet: bool,
    /// End the run at the tick of its first safety violation (telemetry kept, verdict UNSAFE).
    pub stop_on_violation: bool,
    /// Fly only ticks 0..=K of the plan.
    pub max_ticks: Option<u64>,
    /// Serve the live view on this address.
    pub serve: Option<std::net::SocketAddr>,
    /// Across hosts (`--hosts`, `--listen`; issue 12).
    pub hosts: crate::host::HostOptions,
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
    /// The member with the largest peak resident memory and that peak in KiB, read just before
    /// the team was stopped (spawned teams only).
    pub member_peak_rss: Option<(u32, u64)>,
    /// The live view (`--serve`), kept serving until the caller drops it.
    pub live: Option<LiveView>,
}

/// What watches every completed tick: the audit, and the live view when `--serve` asked for one.
struct Watchers<'a> {
    audit: &'a mut Auditor,
    live: &'a mut Option<LiveView>,
}

/// Starts the live view before the team, so a bad address stops nothing (exit 2).
fn start_live(s: &Scenario, addr: &str, quiet: bool) -> Result<LiveView, Failure> {
    let view = LiveView::start(addr, s, Auditor::new(s).numbers()).map_err(Failure::bad_input)?;
    if !quiet {
        out!("live view: http://{}/", view.addr());
    }
    Ok(view)
}

/// Run a launch to the end.
pub fn launch(s: &Scenario, o: &LaunchOptions) -> Result<Launched, Failure> {
    let interrupted = common::signals::install();
    if o.spawn {
        member_binaries_present()?;
    }
    let mut live = match o.serve {
        Some(addr) => Some(start_live(s, &addr.to_string(), o.quiet)?),
        None => None,
    };
    match raise_fd_limit() {
        Ok(n) => tracing::debug!(limit = n, "file-descriptor limit"),
        Err(e) => tracing::warn!("{e}"),
    }
    let ids: Vec<u32> = s.formation.members.iter().map(|m| m.id).collect();
    let ins: BTreeMap<u32, Vec<u32>> = s
        .formation
        .members
        .iter()
        .filter_map(|m| m.link.map(|l| (m.id, l.in_neighbors.to_vec())))
        .collect();
    let hosts = crate::host::Plan::new(s, &o.hosts, &o.team, o.quiet)?;
    let layout = TeamLayout::new(ids.clone(), ins, o.window)
        .map_err(Failure::fault)?
        .with_scenario_hash(s.content_hash());
    let layout = hosts.hide_remote_edges(layout);
    let mut ports = OrchestratorPorts::create(&o.team, &layout).map_err(Failure::bad_input)?;
    let bridge = hosts.start_bridge(s, &o.team, o.window)?;
    // Only now, with the team name ours, touch the run directory: a refused second launch of a
    // running team writes nothing (not even into the first one's --out).
    let dir = RunDir::create(&o.out, o.force).map_err(Failure::from)?;
    dir.write_scenario(s).map_err(Failure::fault)?;
    // Humans start members with scenario.toml; spawned members read the JSON copy (same hash).
    let scenario_file = dir.path().join("scenario.toml");
    let member_file = dir.write_member_scenario(s).map_err(Failure::fault)?;
    if ports.stale_nodes_removed() > 0 {
        tracing::info!(
            removed = ports.stale_nodes_removed(),
            "removed stale resources of a previous team {}",
            o.team
        );
    }
    let mut children = Vec::new();
    if o.spawn {
        for m in s.formation.members.iter().filter(|m| hosts.runs_here(m.id)) {
            match spawn_member(&member_file, &o.team, m.id, m.role) {
                Ok(c) => children.push(Spawned { id: m.id, child: c }),
                Err(e) => {
                    stop_team(&mut ports, &mut children, s, StopReason::AgentFault);
                    let what = format!("cannot start agent {}: {}", m.id, describe_spawn_error(&e));
                    let mut audit = Auditor::new(s);
                    audit.fault(fault(
                        FaultKind::SpawnFailed,
                        Some(m.id),
                        None,
                        0,
                        what.clone(),
                    ));
                    let _ = dir.write_audit(&audit.finish(false));
                    return Err(Failure::fault(what));
                }
            }
        }
    } else if !o.quiet {
        out!(
            "team {} waits for {} processes; start each with:\n  leader --scenario {} --team {} --id ID   (ids {:?})\n  agent  --scenario {} --team {} --id ID   (ids {:?})",
            o.team,
            ids.len(),
            scenario_file.display(),
            o.team,
            s.formation.members.iter().filter(|m| m.role.is_leader()).map(|m| m.id).collect::<Vec<_>>(),
            scenario_file.display(),
            o.team,
            s.formation.members.iter().filter(|m| m.role == Role::Follower).map(|m| m.id).collect::<Vec<_>>(),
        );
    }
    let mut audit = Auditor::new(s);
    let result = run_team(
        s,
        o,
        &dir,
        &mut ports,
        &mut children,
        Watchers {
            audit: &mut audit,
            live: &mut live,
        },
        interrupted,
    );
    let ended = Instant::now();
    let (complete, reason, first_tick) = match result {
        Ok((t, complete)) => (complete, StopReason::Finished, Some(t)),
        Err((fault, reason)) => {
            audit.fault(fault);
            (false, reason, None)
        }
    };
    let member_peak_rss = crate::team::largest_member_peak_rss(&children);
    stop_team(&mut ports, &mut children, s, reason);
    let shut = ports.shutdown();
    if let Err(e) = shut {
        tracing::warn!("{e}");
    }
    let report = audit.finish(complete);
    if let Some(b) = bridge {
        b.finish(&dir, report.ticks, o.quiet);
    }
    dir.write_audit(&report).map_err(Failure::fault)?;
    if let Some(v) = &live {
        v.finish(&report);
    }
    let startup = match (PROCESS_START.get(), first_tick) {
        (Some(&t0), Some(t)) => t.saturating_duration_since(t0),
        _ => Duration::ZERO,
    };
    Ok(Launched {
        report,
        ticking: first_tick.map_or(Duration::ZERO, |t| ended - t),
        startup,
        member_peak_rss,
        live,
    })
}

/// How long a non-finite state waits for a reader's fault report (which names both agents),
/// and a reported fault for the complete ticks before it.
const FAULT_GRACE: Duration = Duration::from_millis(500);

/// The stop of a run interrupted by SIGINT, SIGTERM, SIGHUP or SIGQUIT.
fn interrupted_at(tick: u64, when: &str) -> Stop {
    (
        fault(
            FaultKind::Interrupted,
            None,
            None,
            tick,
            format!("interrupted by {} {when}", common::signals::received()),
        ),
        StopReason::Interrupted,
    )
}

/// The stop when the team did not gather in time: names the agents no process joined as (or,
/// when all joined, those still waiting for a neighbour's ports).
fn join_timeout(r: &common::transport::Readiness, team: &TeamName, within: Duration) -> Stop {
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
    interrupted: &std::sync::atomic::AtomicBool,
) -> Result<(Instant, bool), Stop> {
    let Watchers { audit, live } = watchers;
    let hash = s.content_hash();
    let n = s.formation.members.len();
    // 1. Readiness, with a deadline.
    let join_deadline = if o.spawn {
        Duration::from_secs(30) + Duration::from_millis(60 * n as u64)
    } else {
        o.join_timeout
    };
    let started = Instant::now();
    loop {
        if interrupted.load(Ordering::Relaxed) {
            return Err(interrupted_at(0, "before the start"));
        }
        if ports.readiness().is_complete() {
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
    // 2. The subscription graph as iceoryx2 sees it.
    let mut subs = BTreeMap::new();
    for m in &s.formation.members {
        let nodes = ports.subscriber_nodes(m.id).unwrap_or_default();
        subs.insert(m.id.to_string(), nodes);
    }
    let text = serde_json::to_string_pretty(&subs).unwrap_or_default();
    let _ = common::rundir::write_atomic(&dir.path().join("subscriptions.json"), text.as_bytes());

    // 3. Tick.
    let mut tel = crate::telemetry::open(dir, o.telemetry, o.every).map_err(|e| {
        (
            fault(FaultKind::Io, None, None, 0, e.to_string()),
            StopReason::AgentFault,
        )
    })?;
    let last = o.max_ticks.map_or(s.last_tick(), |k| k.min(s.last_tick()));
    let order = id_order(s);
    let index: BTreeMap<u32, usize> = s
        .formation
        .members
        .iter()
        .enumerate()
        .map(|(k, m)| (m.id, k))
        .collect();
    let window = u64::from(o.window.max(1));
    let mut pending: BTreeMap<u64, (Vec<Option<StateMsg>>, usize)> = BTreeMap::new();
    let mut spare: Vec<Vec<Option<StateMsg>>> = Vec::new();
    let mut next_tick: u64 = 0; // the next tick to complete
    let mut grant = first_grant(window, last);
    let send = |ports: &mut OrchestratorPorts, g: u64| ports.publish_clock(ClockMsg::run(g, hash));
    send(ports, grant).map_err(|e| {
        (
            fault(FaultKind::Transport, None, None, 0, e.to_string()),
            StopReason::AgentFault,
        )
    })?;
    let ticking = Instant::now();
    let mut progress = crate::progress::Progress::new("launch", last, s.dt_s(), o.quiet);
    let mut last_progress = Instant::now();
    let mut last_child_check = Instant::now();
    let mut last_flush = Instant::now();
    let mut ht = Vec::new();
    let mut pos: Vec<Vec3> = vec![Vec3::zeros(); n];
    let mut rows: Vec<Row> = Vec::with_capacity(n);
    // A non-finite state is never audited or written: its readers report it with both ids; if
    // none does within the grace (the sender has no out-neighbours), the orchestrator does.
    let mut non_finite: Option<(u32, u64, Instant)> = None;
    // A fault reported at tick k: the reporter published tick k and failed computing k + 1, so
    // ticks 0..=k are complete as soon as every state is in (as in `simulate`). The team stops
    // then, or after the grace when tick k cannot complete (a non-finite state is never used).
    let mut stopping: Option<(FaultRecord, Instant, FaultRank)> = None;
    // A member process seen exited: its id, how, and when it was seen.
    let mut exited: Option<(u32, String, Instant)> = None;
    let mut stall = crate::stall::StallWatch::new(Instant::now());
    loop {
        if interrupted.load(Ordering::Relaxed) {
            return Err(interrupted_at(next_tick, &format!("at tick {next_tick}")));
        }
        // The orchestrator itself did not run for a while: its members get a fresh timeout, and
        // a member that stopped meanwhile is blamed on the stall (`stall.explain`).
        if stall.turn(Instant::now(), next_tick) {
            last_progress = Instant::now();
        }
        // The best fault report met in this drain, and its rank.
        let mut bad: Option<(FaultRecord, FaultRank)> = None;
        ports
            .receive_states(|msg| {
                let Some(&k) = index.get(&msg.id) else { return };
                if let AgentStatus::Fault { code, peer } = msg.status() {
                    let rank = FaultRank {
                        echo: code == FaultCode::NeighborFault,
                        tick: msg.tick,
                        member: k,
                    };
                    if rank.outranks(bad.as_ref().map(|(_, r)| r)) {
                        // The same kind as `simulate` records for a controller fault.
                        let kind = if code == FaultCode::Control {
                            FaultKind::Control
                        } else {
                            FaultKind::AgentFault
                        };
                        let on = peer.map_or_else(String::new, |p| format!(" (peer {p})"));
                        let what = format!(
                            "agent {} reported {code:?} at tick {}{on}",
                            msg.id, msg.tick
                        );
                        bad = Some((fault(kind, Some(msg.id), peer, msg.tick, what), rank));
                    }
                    return;
                }
                if msg.tick < next_tick || msg.tick > grant {
                    return;
                }
                if msg.state.iter().any(|v| !v.is_finite()) {
                    non_finite.get_or_insert((msg.id, msg.tick, Instant::now()));
                    return;
                }
                let slot = pending
                    .entry(msg.tick)
                    .or_insert_with(|| (spare.pop().unwrap_or_else(|| vec![None; n]), 0));
                if slot.0[k].is_none() {
                    slot.1 += 1;
                }
                slot.0[k] = Some(msg);
            })
            .map_err(|e| {
                (
                    fault(FaultKind::Transport, None, None, next_tick, e.to_string()),
                    StopReason::AgentFault,
                )
            })?;
        if let Some((f, rank)) = bad {
            if rank.outranks(stopping.as_ref().map(|(_, _, r)| r)) {
                let since = stopping.as_ref().map_or_else(Instant::now, |(_, t, _)| *t);
                stopping = Some((f, since, rank));
            }
        }
        if let Some((id, tick, _)) = non_finite.filter(|(_, _, t)| t.elapsed() > FAULT_GRACE) {
            let what = format!("agent {id} published a non-finite state at tick {tick}");
            let f = fault(FaultKind::NonFiniteState, Some(id), None, tick, what);
            let since = Instant::now().checked_sub(FAULT_GRACE);
            let rank = FaultRank {
                echo: false,
                tick,
                member: usize::MAX,
            };
            stopping.get_or_insert((f, since.unwrap_or_else(Instant::now), rank));
        }
        // Grant before auditing and writing: members go on while the orchestrator does its share.
        // Grant in steps of half a window (at least 1): every grant wakes members, so fewer,
        // larger grants mean fewer wake-ups per tick; members keep up to a window queued.
        let mut complete = next_tick;
        while pending.get(&complete).is_some_and(|(_, c)| *c == n) {
            complete += 1;
        }
        if let Some(want) = next_grant(complete, grant, window, last) {
            grant = want;
            send(ports, grant).map_err(|e| {
                (
                    fault(FaultKind::Transport, None, None, next_tick, e.to_string()),
                    StopReason::AgentFault,
                )
            })?;
        }
        let mut progressed = false;
        while next_tick < complete && stopping.as_ref().is_none_or(|(f, ..)| next_tick <= f.tick) {
            let Some((mut states, _)) = pending.remove(&next_tick) else {
                break;
            };
            let tick = next_tick;
            let t = tick_time(tick, s.dt_s());
            desired_positions(s, t, &mut ht);
            for (k, st) in states.iter().enumerate() {
                if let Some(m) = st {
                    pos[k] = vec3([m.state[0], m.state[1], m.state[2]]);
                }
            }
            audit.observe(tick, t, &pos, &ht);
            if let Some(v) = live.as_mut() {
                v.tick(tick, t, &pos, &ht, audit.report());
            }
            progress.tick(tick, audit.report());
            if tel.keeps(tick) {
                rows.clear();
                for &k in &order {
                    let m = &s.formation.members[k];
                    let st = states[k].map(|x| x.state).unwrap_or([f64::NAN; 12]);
                    rows.push(Row {
                        tick,
                        t_s: t,
                        id: m.id,
                        role: m.role,
                        r: vec3([st[0], st[1], st[2]]),
                        v: vec3([st[3], st[4], st[5]]),
                        ht: ht[k],
                    });
                }
                tel.write_tick(&rows).map_err(|e| {
                    (
                        fault(
                            FaultKind::Io,
                            None,
                            None,
                            tick,
                            format!("cannot write telemetry: {e}"),
                        ),
                        StopReason::AgentFault,
                    )
                })?;
            }
            // The slot vector serves a later tick (no allocation per tick).
            states.fill(None);
            spare.push(states);
            next_tick += 1;
            progressed = true;
            if o.stop_on_violation && audit.violation_count() > 0 {
                audit.stop_on_violation();
                progress.finish();
                let _ = tel.flush();
                return Ok((ticking, next_tick > last));
            }
        }
        if let Some((f, since, rank)) = stopping.take() {
            if next_tick > f.tick || since.elapsed() >= FAULT_GRACE {
                return Err((f, StopReason::AgentFault));
            }
            stopping = Some((f, since, rank));
        }
        // A failed flush (a full disk) is a fault: the file keeps its whole ticks, no later
        // tick may follow a gap.
        let io = |e: std::io::Error| {
            let what = format!("cannot write telemetry: {e}");
            (
                fault(FaultKind::Io, None, None, next_tick, what),
                StopReason::AgentFault,
            )
        };
        if next_tick > last {
            progress.finish();
            tel.finish().map_err(io)?;
            return Ok((ticking, true));
        }
        if progressed {
            last_progress = Instant::now();
            // Complete ticks reach the file at least every 100 ms (and at every stop).
            if last_flush.elapsed() > Duration::from_millis(100) {
                tel.flush().map_err(io)?;
                last_flush = Instant::now();
            }
            continue;
        }
        // While stopping on a reported fault, the reporter's own exit is not a second fault.
        if exited.is_none()
            && stopping.is_none()
            && last_child_check.elapsed() > Duration::from_millis(100)
        {
            last_child_check = Instant::now();
            exited = first_exited(children).map(|(id, how)| (id, how, Instant::now()));
        }
        // Members run up to a window ahead of the audit: the states a dead member published
        // are audited and written first, and its fault is the first tick it never sent.
        if let Some((id, how, since)) = exited.as_ref().filter(|_| stopping.is_none()) {
            let k = index[id];
            let lacks = pending.get(&next_tick).is_none_or(|(v, _)| v[k].is_none());
            if lacks && since.elapsed() >= FAULT_GRACE {
                let _ = tel.flush();
                let (f, reason) = exited_fault(*id, how, next_tick);
                return Err((stall.explain(f, Instant::now()), reason));
            }
        }
        if stopping.is_none() && last_progress.elapsed() > o.agent_timeout {
            let _ = tel.flush();
            let have = pending.get(&next_tick);
            let missing: Vec<u32> = s
                .formation
                .members
                .iter()
                .enumerate()
                .filter(|(k, _)| have.is_none_or(|(v, _)| v[*k].is_none()))
                .map(|(_, m)| m.id)
                .collect();
            let f = fault(
                FaultKind::AgentSilent,
                missing.first().copied(),
                None,
                next_tick,
                format!(
                    "agents {missing:?} sent no state for tick {next_tick} within {:?}",
                    o.agent_timeout
                ),
            );
            return Err((stall.explain(f, Instant::now()), StopReason::AgentSilent));
        }
        let _ = ports.wait(Duration::from_millis(20));
    }
}
