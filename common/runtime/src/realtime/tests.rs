//! Every real-time decision of a member and of the monitor with a fake clock (a `Duration`
//! passed in) and a fake vehicle: no process, no shared memory, no sleeping.

use cdm_math::{vec3, Vec2};
use cdm_model::control::ControlFault;
use cdm_model::formation::{Link, Role};
use cdm_model::link::LinkSpec;

use super::*;
use crate::member_core::Finished;
use crate::messages::{AgentStatus, StopReason, STATUS_FAULT};
use crate::realtime_monitor::{MonitorCore, MonitorEvent, RunFigures};
use crate::seams::VehicleFault;
use cdm_model::step::StepFault;

const HASH: u64 = 0xc0ffee;
const DT: f64 = 0.01;
const ME: u32 = 10;
const UNIX_START: u64 = 1_000_000_000_000;

/// A vehicle that stays put and counts its ticks (and the offsets it was flown at).
#[derive(Debug, Default)]
struct Still {
    flown: Vec<TickAt>,
    fail: bool,
}

impl Vehicle for Still {
    fn state(&self) -> [f64; 12] {
        let mut x = [0.0; 12];
        x[6] = 9.81; // hovering thrust: a finite, flat state
        x
    }

    fn fly_tick(&mut self, _: u64, _: &[Flat; 3]) -> Result<(), VehicleFault> {
        unreachable!("real time flies with fly_tick_at")
    }

    fn fly_tick_at(&mut self, at: TickAt, _: &[Flat; 3]) -> Result<(), VehicleFault> {
        if self.fail {
            return Err(VehicleFault::Step(StepFault::Control(
                ControlFault::SingularThrust {
                    thrust_mps2: 0.0,
                    min_thrust_mps2: 1.0,
                },
            )));
        }
        self.flown.push(at);
        Ok(())
    }
}

fn follower() -> Member {
    Member {
        id: ME,
        role: Role::Follower,
        position: Vec3::zeros(),
        start: Vec3::zeros(),
        planar: Vec2::zeros(),
        alpha: [1.0, 0.0, 0.0],
        link: Some(Link {
            in_neighbors: [1, 2, 3],
            weights: [0.2, 0.3, 0.5],
        }),
    }
}

fn core(phase_seed: u32) -> RealtimeCore<Still> {
    core_over(phase_seed, LinkModel::perfect(DT))
}

fn core_over(phase_seed: u32, links: LinkModel) -> RealtimeCore<Still> {
    let setup = RealtimeSetup {
        hash: HASH,
        last: 1000,
        dt_s: DT,
        stale_after: STALE_AFTER,
        deadlines: Deadlines::default(),
        links,
    };
    let mut c = RealtimeCore::realtime(
        &follower(),
        [Vec3::zeros(); 3],
        setup,
        Still::default(),
        Duration::ZERO,
    );
    // The start is announced 1 s ahead of this member's clock (at 0 s).
    let start = ClockMsg::realtime(UNIX_START + 1_000_000_000, HASH, phase_seed);
    assert_eq!(c.on_clock(&start, Duration::ZERO, UNIX_START), Ok(None));
    c
}

fn state(id: u32, tick: u64) -> StateMsg {
    let mut x = [0.0; 12];
    x[6] = 9.81;
    StateMsg::ok(tick, HASH, id, x)
}

fn secs(s: f64) -> Duration {
    Duration::from_secs_f64(s)
}

#[test]
fn phase_offsets_are_seeded_spread_and_in_one_period() {
    let phases: Vec<f64> = (1..=100).map(|id| phase_offset_s(7, id, DT)).collect();
    assert!(phases.iter().all(|p| (0.0..DT).contains(p)));
    assert_eq!(
        phases,
        (1..=100)
            .map(|id| phase_offset_s(7, id, DT))
            .collect::<Vec<_>>()
    );
    let mut sorted = phases.clone();
    sorted.sort_by(f64::total_cmp);
    sorted.dedup();
    assert_eq!(sorted.len(), 100, "distinct offsets");
    assert!(sorted[0] < 0.2 * DT && sorted[99] > 0.8 * DT, "{sorted:?}");
    assert_ne!(phase_offset_s(8, 1, DT), phase_offset_s(7, 1, DT));
    assert_eq!(phase_offset_s(PHASES_ALIGNED, 5, DT), 0.0);
}

/// The offsets are SplitMix64's (cdm-model `link::splitmix64`), bit for bit the values of the
/// formula this file once wrote out by itself.
#[test]
fn phase_offsets_are_pinned_to_the_bit() {
    let pinned: [(u32, u32, f64, u64); 5] = [
        (0x1, 1, 0.01, 0x3f54_a61f_c708_8b3e),
        (0x7, 10, 0.01, 0x3f59_ddca_0d73_b1c8),
        (0x3, 999, 0.02, 0x3f73_49e0_aca0_ebee),
        (0xdead_beef, 4_000_000_000, 0.005, 0x3f5e_363a_1e02_e7b1),
        (0x2a, 7, 1.0 / 60.0, 0x3f67_a67d_a9a7_22bc),
    ];
    for (seed, id, dt, bits) in pinned {
        assert_eq!(
            phase_offset_s(seed, id, dt).to_bits(),
            bits,
            "{seed} {id} {dt}"
        );
    }
}

#[test]
fn a_member_waits_for_its_instant_then_publishes_and_flies_at_its_phase() {
    let mut c = core(PHASES_ALIGNED);
    // Before the start: ask whether the orchestrator lives every half second, else wait, at
    // most until tick 0's instant (1 s).
    assert_eq!(c.poll(secs(0.999)), Action::CheckOrchestrator);
    c.on_orchestrator_alive(true);
    match c.poll(secs(0.999)) {
        Action::Wait(d) => assert!(d <= secs(0.001) + Duration::from_nanos(1), "{d:?}"),
        a => panic!("{a:?}"),
    }
    match c.poll(secs(1.0)) {
        Action::Publish(m) => assert_eq!((m.tick, m.id, m.status), (0, ME, 0)),
        a => panic!("{a:?}"),
    }
    assert_eq!(c.poll(secs(1.0)), Action::Poll);
    assert_eq!(c.tick(), 1);
    assert_eq!(c.pacing().ticks, 1);
    assert!(matches!(c.poll(secs(1.005)), Action::Wait(d) if d <= secs(0.005)));

    let mut c = core(3);
    let phase = phase_offset_s(3, ME, DT);
    let due = secs(1.0 + phase);
    assert_eq!(c.poll(due - secs(1e-4)), Action::CheckOrchestrator);
    c.on_orchestrator_alive(true);
    assert!(matches!(c.poll(due - secs(1e-4)), Action::Wait(_)));
    assert!(matches!(c.poll(due), Action::Publish(_)));
    assert_eq!(c.poll(due), Action::Poll);
    assert_eq!(
        c.m.vehicle.flown,
        vec![TickAt {
            tick: 0,
            offset_s: phase
        }]
    );
}

#[test]
fn a_tick_computed_over_a_period_late_is_a_late_tick() {
    let mut c = core(PHASES_ALIGNED);
    let _ = c.poll(secs(1.0 + 1.5 * DT));
    let _ = c.poll(secs(1.0 + 1.5 * DT));
    assert_eq!((c.pacing().ticks, c.pacing().late_ticks), (1, 1));
    let _ = c.poll(secs(1.0 + 1.5 * DT)); // tick 1 (due 1.01 s) is half a period late
    let _ = c.poll(secs(1.0 + 1.5 * DT));
    assert_eq!((c.pacing().ticks, c.pacing().late_ticks), (2, 1));
    assert!((c.pacing().max_late_ms - 15.0).abs() < 1e-6);
}

#[test]
fn neighbour_ages_are_own_time_minus_the_newest_stamp() {
    let mut c = core(PHASES_ALIGNED);
    for id in [1, 2, 3] {
        c.on_neighbor(&state(id, 40));
        c.on_neighbor(&state(id, 39)); // older: ignored
    }
    let now = secs(1.0 + 42.0 * DT);
    // Catch up to tick 42: ages 0.42 - 0.40 = 20 ms for each neighbour.
    while c.tick() < 43 {
        let _ = c.poll(now);
    }
    let p = MemberPacing::from_msg(&c.pacing().to_msg(ME, HASH)).expect("a pacing message");
    assert_eq!(p.ticks, 43);
    assert!((p.age_max_ms - 20.0).abs() < 1e-6, "{p:?}");
}

#[test]
fn over_delayed_links_a_state_is_used_only_once_its_delay_has_passed() {
    let spec = LinkSpec {
        delay_ms: 25.0,
        ..LinkSpec::default()
    };
    let mut c = core_over(PHASES_ALIGNED, LinkModel::new(spec, DT));
    for id in [1, 2, 3] {
        c.on_neighbor(&state(id, 40));
    }
    // Tick 42 (own time 0.42 s): the tick-40 states (stamp 0.40 s) are 5 ms short of their
    // 25 ms, so the follower still extrapolates from where its neighbours started.
    let now = secs(1.0 + 42.0 * DT);
    while c.tick() < 43 {
        let _ = c.poll(now);
    }
    assert_eq!(c.timing.heard, [None; 3]);
    // Tick 43 (0.43 s): released, 30 ms old when used.
    let now = secs(1.0 + 43.0 * DT);
    while c.tick() < 44 {
        let _ = c.poll(now);
    }
    assert!(c
        .timing
        .heard
        .iter()
        .all(|h| h.is_some_and(|(t, _)| t == 40)));
}

#[test]
fn a_stale_neighbour_is_reported_and_the_member_holds() {
    let mut c = core(PHASES_ALIGNED);
    c.on_neighbor(&state(1, 0));
    c.on_neighbor(&state(2, 60));
    c.on_neighbor(&state(3, 60));
    let now = secs(1.0 + 60.0 * DT);
    let mut last = Action::Poll;
    for _ in 0..200 {
        last = c.poll(now);
        if matches!(last, Action::Fail { .. }) {
            break;
        }
    }
    let Action::Fail { report, fault } = last else {
        panic!("{last:?}")
    };
    let r = report.expect("reported to the team");
    assert_eq!((r.status, r.fault_peer), (STATUS_FAULT, 1));
    assert_eq!(
        r.status(),
        AgentStatus::Fault {
            code: FaultCode::NeighborSilent,
            peer: Some(1)
        }
    );
    match fault {
        MemberFault::NeighborStale { tick, peer, age } => {
            assert_eq!((tick, peer), (51, 1));
            assert!(
                age > STALE_AFTER && age < STALE_AFTER + secs(DT + 1e-9),
                "{age:?}"
            );
        }
        f => panic!("{f:?}"),
    }
    assert_eq!(
        c.m.vehicle.flown.len(),
        51,
        "ticks 0..=50 flown, none after"
    );
}

#[test]
fn clock_messages_mismatch_start_and_stop() {
    let mut c = core(PHASES_ALIGNED);
    assert_eq!(
        c.on_clock(&ClockMsg::run(5, HASH), secs(2.0), UNIX_START),
        Err(MemberFault::ModeMismatch {
            member_realtime: true
        })
    );
    assert!(matches!(
        c.on_clock(&ClockMsg::realtime(0, HASH + 1, 1), secs(2.0), UNIX_START),
        Err(MemberFault::ScenarioMismatch { .. })
    ));
    let stop = ClockMsg::stop(9, HASH, StopReason::Finished);
    assert_eq!(
        c.on_clock(&stop, secs(2.0), UNIX_START),
        Ok(Some(Finished {
            tick: 0,
            reason: stop.reason
        }))
    );
}

#[test]
fn a_failed_tick_is_reported_with_its_fault() {
    let mut c = core(PHASES_ALIGNED);
    c.m.vehicle.fail = true;
    let _ = c.poll(secs(1.0));
    assert!(matches!(
        c.poll(secs(1.0)),
        Action::Fail {
            report: Some(_),
            fault: MemberFault::Step { tick: 0, .. }
        }
    ));
}

#[test]
fn pacing_quantiles_round_trip_through_the_message() {
    let mut p = MemberPacing::default();
    for k in 0..100 {
        p.age(f64::from(k) * 1e-4); // 0.0 .. 9.9 ms
    }
    p.tick(0.0, DT);
    let f = MemberPacing::from_msg(&p.to_msg(4, HASH)).expect("pacing");
    assert_eq!((f.id, f.ticks, f.late_ticks, f.age_samples), (4, 1, 0, 100));
    // The 50th and 99th of the 100 ages, to a bin.
    assert!((f.age_p50_ms - 4.9).abs() <= AGE_BIN_MS, "{f:?}");
    assert!((f.age_p99_ms - 9.8).abs() <= AGE_BIN_MS, "{f:?}");
    assert!((f.age_max_ms - 9.9).abs() < 1e-9, "{f:?}");
    assert_eq!(MemberPacing::from_msg(&state(4, 1)), None);
}

fn monitor() -> MonitorCore {
    let members = [
        (1, vec3([0.0, 0.0, 0.0]), false),
        (2, vec3([10.0, 0.0, 0.0]), true),
    ];
    MonitorCore::new(&members, HASH, (DT, 0.5), PHASES_ALIGNED)
}

#[test]
fn the_monitor_brings_newest_states_to_its_instants() {
    let mut m = monitor();
    // Member 1 moves at 2 m/s along x (state layout: r, v, F, angles...).
    let mut x = [0.0; 12];
    x[3] = 2.0;
    x[6] = 9.81;
    assert_eq!(
        m.on_state(&StateMsg::ok(10, HASH, 1, x)),
        MonitorEvent::Nothing
    );
    let (r, v) = m.state_at(0, 0.15);
    assert!(
        (r.x - 0.1).abs() < 1e-12 && (v.x - 2.0).abs() < 1e-12,
        "{r:?} {v:?}"
    );
    // Before its first state a member is at rest where it started.
    assert_eq!(m.state_at(1, 0.15).0, vec3([10.0, 0.0, 0.0]));
    // A state stamped after the instant is not used for it.
    x[0] = 5.0;
    m.on_state(&StateMsg::ok(20, HASH, 1, x));
    assert!((m.state_at(0, 0.15).0.x - 0.1).abs() < 1e-12);
    assert!((m.state_at(0, 0.2).0.x - 5.0).abs() < 1e-12);
}

/// An audit instant waits for the slowest member (`heard_until`: the oldest newest stamp), and
/// an instant older than every kept state is taken from the oldest kept state moved back to it,
/// never from where the member started (which read as a false violation once the monitor fell
/// behind its ring under load).
#[test]
fn the_monitor_waits_for_the_slowest_member_and_never_falls_back_to_rest() {
    let mut m = monitor();
    assert_eq!(m.heard_until(), 0.0, "nothing heard yet");
    // Member 1 moves at 2 m/s along x from x = 0; ticks 1..=100 overflow its ring (0.5 s / DT
    // + 8 = 58 states), so ticks 43..=100 are kept.
    for tick in 1..=100u64 {
        let mut x = [0.0; 12];
        x[0] = 2.0 * tick as f64 * DT;
        x[3] = 2.0;
        x[6] = 9.81;
        m.on_state(&StateMsg::ok(tick, HASH, 1, x));
    }
    assert_eq!(m.heard_until(), 0.0, "member 2 not heard yet");
    m.on_state(&StateMsg::ok(30, HASH, 2, [0.0; 12]));
    assert!(
        (m.heard_until() - 30.0 * DT).abs() < 1e-12,
        "{}",
        m.heard_until()
    );
    let (r, _) = m.state_at(0, 5.0 * DT);
    assert!(
        (r.x - 0.1).abs() < 1e-9,
        "moved back from tick 43, not at rest: {r:?}"
    );
}

#[test]
fn the_monitor_names_the_stalest_member_and_passes_on_fault_reports() {
    let mut m = monitor();
    m.on_state(&state(1, 100));
    m.on_state(&state(2, 40));
    assert_eq!(m.stale(1.0, 0.5), Some((2, 40, 1.0 - 0.4)));
    assert_eq!(m.stale(0.85, 0.5), None);
    let report = state(2, 41).with_status(AgentStatus::Fault {
        code: FaultCode::NeighborSilent,
        peer: Some(1),
    });
    assert_eq!(
        m.on_state(&report),
        MonitorEvent::Fault {
            id: 2,
            tick: 41,
            code: FaultCode::NeighborSilent,
            peer: Some(1)
        }
    );
    let mut nan = state(1, 101);
    nan.state[0] = f64::NAN;
    assert_eq!(
        m.on_state(&nan),
        MonitorEvent::NonFinite { id: 1, tick: 101 }
    );
}

#[test]
fn the_monitor_sums_the_members_pacing_reports() {
    let mut m = monitor();
    let mut leader = MemberPacing::default();
    let mut follower = MemberPacing::default();
    for _ in 0..99 {
        leader.tick(0.0, DT);
        follower.tick(0.0, DT);
        follower.age(0.004);
    }
    leader.tick(0.02, DT);
    follower.tick(0.0, DT);
    follower.age(0.03);
    m.on_state(&leader.to_msg(1, HASH));
    m.stopping();
    assert!(!m.final_reports_in(|_| true));
    m.on_state(&follower.to_msg(2, HASH));
    assert!(m.final_reports_in(|id| id == 2));
    let run = RunFigures {
        audits: 10,
        audit_hz: 100.0,
        phase_seed: 0,
        stale_after_s: 0.5,
        wall_s: 1.0,
        team_cpu_cores: None,
    };
    let f = m.figures(run);
    assert_eq!((f.ticks, f.late_ticks, f.members_reported), (200, 1, 2));
    assert!((f.late_ticks_pct - 0.5).abs() < 1e-12);
    assert!((f.neighbor_age_ms_p50 - 4.0).abs() <= AGE_BIN_MS, "{f:?}");
    assert!((f.neighbor_age_ms_max - 30.0).abs() < 1e-9, "{f:?}");
    let slowest = f.slowest_member.expect("slowest");
    assert_eq!((slowest.id, slowest.late_ticks), (1, 1));
}
