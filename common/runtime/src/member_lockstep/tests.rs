//! Every protocol decision of a member with a fake clock (a `Duration` passed in), a fake vehicle
//! and, for the loop, a fake transport: no process, no shared memory, no sleeping.

use std::cell::Cell;
use std::collections::VecDeque;
use std::sync::atomic::AtomicBool;

use cdm_math::{Vec2, Vec3};
use cdm_model::control::ControlFault;
use cdm_model::formation::{Link, Member, Role};

use super::*;
use crate::member_core::{Finished, ALIVE_CHECK};
use crate::member_loop::{fly, LoopError};
use crate::messages::{StopReason, STATUS_FAULT};
use crate::seams::{Clock, MemberTransport, VehicleFault};
use cdm_model::step::StepFault;

const HASH: u64 = 0xc0ffee;
const LAST: u64 = 100;
const ME: u32 = 10;

/// A vehicle that stays put, or fails its tick `fail_at` (its link is lost when `link_lost`,
/// otherwise its controller fails).
#[derive(Debug)]
struct Still {
    ticks: u64,
    fail_at: Option<u64>,
    link_lost: bool,
}

impl Vehicle for Still {
    fn state(&self) -> [f64; 12] {
        [self.ticks as f64; 12]
    }

    fn fly_tick(&mut self, tick: u64, _: &[Flat; 3]) -> Result<(), VehicleFault> {
        if self.fail_at == Some(tick) && self.link_lost {
            let what = format!("agent {ME}: vehicle lost");
            let loss = crate::messages::VehicleLoss::Lost;
            return Err(VehicleFault::Link { what, loss });
        }
        if self.fail_at == Some(tick) {
            return Err(VehicleFault::Step(StepFault::Control(
                ControlFault::SingularThrust {
                    thrust_mps2: 0.0,
                    min_thrust_mps2: 1.0,
                },
            )));
        }
        self.ticks += 1;
        Ok(())
    }
}

fn member(role: Role) -> Member {
    Member {
        id: ME,
        role,
        position: Vec3::zeros(),
        start: Vec3::zeros(),
        planar: Vec2::zeros(),
        alpha: [1.0, 0.0, 0.0],
        link: (role == Role::Follower).then_some(Link {
            in_neighbors: [1, 2, 3],
            weights: [0.2, 0.3, 0.5],
        }),
    }
}

fn core(role: Role, fail_at: Option<u64>) -> LockstepCore<Still> {
    let v = Still {
        ticks: 0,
        fail_at,
        link_lost: false,
    };
    let parts = (v, LockstepClock::default());
    MemberCore::new(
        &member(role),
        HASH,
        LAST,
        parts,
        Deadlines::default(),
        Duration::ZERO,
    )
}

/// A clock message as the loop hands it on (lockstep reads neither clock).
fn on_clock(c: &mut LockstepCore<Still>, m: &ClockMsg) -> Result<Option<Finished>, MemberFault> {
    c.on_clock(m, Duration::ZERO, 0)
}

fn state(id: u32, tick: u64) -> StateMsg {
    StateMsg::ok(tick, HASH, id, [0.0; 12])
}

/// Polls until the core blocks (a wait or a fail), answering orchestrator checks with `alive`;
/// returns the ticks published and the blocking action.
fn run_until_blocked(c: &mut LockstepCore<Still>, now: Duration) -> (Vec<u64>, Action) {
    let mut published = Vec::new();
    loop {
        match c.poll(now) {
            Action::Publish(m) => published.push(m.tick),
            Action::CheckOrchestrator => c.on_orchestrator_alive(true),
            Action::Poll | Action::NotifyReaders => {}
            a => return (published, a),
        }
    }
}

fn fault_of(a: &Action) -> (&Option<StateMsg>, &MemberFault) {
    match a {
        Action::Fail { report, fault } => (report, fault),
        other => panic!("expected a fail, got {other:?}"),
    }
}

#[test]
fn grant_window_bounds_what_a_member_publishes_and_computes() {
    let mut c = core(Role::Primary, None);
    let (published, a) = run_until_blocked(&mut c, Duration::ZERO);
    assert!(published.is_empty(), "published before any grant");
    assert!(matches!(a, Action::Wait(_)), "{a:?}");
    on_clock(&mut c, &ClockMsg::run(2, HASH)).unwrap();
    let (published, a) = run_until_blocked(&mut c, Duration::ZERO);
    assert_eq!(published, [0, 1, 2], "a leader runs up to the grant");
    assert_eq!(
        c.tick(),
        2,
        "and does not compute tick 3 before it is granted"
    );
    assert!(matches!(a, Action::Wait(_)), "{a:?}");
    // A stale grant changes nothing; a larger one lets it go on.
    on_clock(&mut c, &ClockMsg::run(1, HASH)).unwrap();
    assert_eq!(
        run_until_blocked(&mut c, Duration::ZERO).0,
        Vec::<u64>::new()
    );
    on_clock(&mut c, &ClockMsg::run(4, HASH)).unwrap();
    assert_eq!(run_until_blocked(&mut c, Duration::ZERO).0, [3, 4]);
}

#[test]
fn follower_waits_for_all_three_neighbours() {
    let mut c = core(Role::Follower, None);
    on_clock(&mut c, &ClockMsg::run(5, HASH)).unwrap();
    assert_eq!(run_until_blocked(&mut c, Duration::ZERO).0, [0]);
    c.on_neighbor(&state(1, 0));
    c.on_neighbor(&state(2, 0));
    c.on_neighbor(&state(99, 0)); // not an in-neighbour: ignored
    assert_eq!(
        run_until_blocked(&mut c, Duration::ZERO).0,
        Vec::<u64>::new()
    );
    c.on_neighbor(&state(3, 0));
    assert_eq!(run_until_blocked(&mut c, Duration::ZERO).0, [1]);
}

#[test]
fn tick_gap_is_reported_naming_the_neighbour() {
    let mut c = core(Role::Follower, None);
    on_clock(&mut c, &ClockMsg::run(5, HASH)).unwrap();
    run_until_blocked(&mut c, Duration::ZERO);
    c.on_neighbor(&state(1, 0));
    c.on_neighbor(&state(2, 0));
    c.on_neighbor(&state(3, 1)); // tick 0 of neighbour 3 was lost
    let (_, a) = run_until_blocked(&mut c, Duration::ZERO);
    let (report, fault) = fault_of(&a);
    assert_eq!(
        *fault,
        MemberFault::TickGap {
            tick: 0,
            peer: 3,
            later: 1
        }
    );
    let r = report.expect("a tick gap is reported to the team");
    assert_eq!(
        r.status(),
        AgentStatus::Fault {
            code: FaultCode::TickGap,
            peer: Some(3)
        }
    );
}

#[test]
fn silent_neighbour_ends_the_member_after_the_silence_deadline() {
    let mut c = core(Role::Follower, None);
    on_clock(&mut c, &ClockMsg::run(5, HASH)).unwrap();
    c.on_neighbor(&state(1, 0));
    c.on_neighbor(&state(3, 0));
    let (_, a) = run_until_blocked(&mut c, Duration::ZERO);
    assert!(matches!(a, Action::Wait(_)), "{a:?}");
    let almost = Deadlines::default().silence - Duration::from_millis(1);
    assert!(matches!(
        run_until_blocked(&mut c, almost).1,
        Action::Wait(_)
    ));
    let (_, a) = run_until_blocked(&mut c, Deadlines::default().silence);
    let (report, fault) = fault_of(&a);
    assert!(
        report.is_none(),
        "silence is not reported as this member's fault"
    );
    match fault {
        MemberFault::Silent {
            tick: 0,
            waiting_for,
            ..
        } => {
            assert_eq!(
                *waiting_for,
                WaitingFor::States {
                    tick: 0,
                    missing: vec![2]
                }
            );
            assert_eq!(
                waiting_for.to_string(),
                "tick-0 states of in-neighbours [2]"
            );
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn neighbour_fault_notice_is_not_a_state_and_a_foreign_state_is_a_fault() {
    let mut c = core(Role::Follower, None);
    on_clock(&mut c, &ClockMsg::run(5, HASH)).unwrap();
    run_until_blocked(&mut c, Duration::ZERO);
    let notice = state(1, 0).with_status(AgentStatus::Fault {
        code: FaultCode::Control,
        peer: None,
    });
    c.on_neighbor(&notice);
    c.on_neighbor(&state(2, 0));
    c.on_neighbor(&state(3, 0));
    let (published, a) = run_until_blocked(&mut c, Duration::ZERO);
    assert!(
        published.is_empty(),
        "a fault notice was used as neighbour 1's state"
    );
    assert!(matches!(a, Action::Wait(_)), "{a:?}");
    // The orchestrator then stops the team: a normal end.
    let stop = ClockMsg::stop(5, HASH, StopReason::AgentFault);
    let done = on_clock(&mut c, &stop)
        .unwrap()
        .expect("a stop finishes the member");
    assert_eq!(done.reason, StopReason::AgentFault.code());

    let mut c = core(Role::Follower, None);
    on_clock(&mut c, &ClockMsg::run(5, HASH)).unwrap();
    c.on_neighbor(&StateMsg::ok(0, HASH + 1, 2, [0.0; 12]));
    let (_, a) = run_until_blocked(&mut c, Duration::ZERO);
    let (report, fault) = fault_of(&a);
    assert_eq!(
        *fault,
        MemberFault::ForeignState {
            tick: 0,
            peer: 2,
            peer_tick: 0
        }
    );
    let r = report.expect("reported");
    assert_eq!(r.status, STATUS_FAULT);
    assert_eq!(
        r.status(),
        AgentStatus::Fault {
            code: FaultCode::NeighborFault,
            peer: Some(2)
        }
    );
}

#[test]
fn lost_orchestrator_is_noticed_at_the_next_check() {
    let mut c = core(Role::Primary, None);
    assert!(matches!(c.poll(Duration::ZERO), Action::Wait(_)));
    assert_eq!(c.poll(ALIVE_CHECK), Action::CheckOrchestrator);
    c.on_orchestrator_alive(false);
    let a = c.poll(ALIVE_CHECK);
    assert_eq!(
        a,
        Action::Fail {
            report: None,
            fault: MemberFault::OrchestratorLost { tick: 0 }
        }
    );
}

#[test]
fn join_is_refused_for_another_scenario_and_ends_after_the_join_deadline() {
    let mut c = core(Role::Follower, None);
    let err = on_clock(&mut c, &ClockMsg::run(3, HASH ^ 1)).unwrap_err();
    assert_eq!(
        err,
        MemberFault::ScenarioMismatch {
            mine: HASH,
            team: HASH ^ 1
        }
    );
    // No grant: the join deadline (not the silence one) applies.
    let silence = Deadlines::default().silence;
    assert!(matches!(
        run_until_blocked(&mut c, silence).1,
        Action::Wait(_)
    ));
    let (_, a) = run_until_blocked(&mut c, Deadlines::default().join);
    match fault_of(&a).1 {
        MemberFault::Silent { waiting_for, .. } => assert_eq!(*waiting_for, WaitingFor::Start),
        other => panic!("{other:?}"),
    }
}

#[test]
fn own_step_fault_is_reported_with_the_state_before_it() {
    let mut c = core(Role::Primary, Some(1));
    on_clock(&mut c, &ClockMsg::run(5, HASH)).unwrap();
    let (published, a) = run_until_blocked(&mut c, Duration::ZERO);
    assert_eq!(published, [0, 1]);
    let (report, fault) = fault_of(&a);
    assert!(
        matches!(fault, MemberFault::Step { tick: 1, .. }),
        "{fault:?}"
    );
    let r = report.expect("reported");
    assert_eq!(r.tick, 1);
    assert_eq!(
        r.status(),
        AgentStatus::Fault {
            code: FaultCode::Control,
            peer: None
        }
    );
}

#[test]
fn a_lost_vehicle_is_reported_as_such_with_the_state_before_it() {
    let v = Still {
        ticks: 0,
        fail_at: Some(2),
        link_lost: true,
    };
    let parts = (v, LockstepClock::default());
    let me = member(Role::Primary);
    let mut c = MemberCore::new(&me, HASH, LAST, parts, Deadlines::default(), Duration::ZERO);
    on_clock(&mut c, &ClockMsg::run(5, HASH)).unwrap();
    let (published, a) = run_until_blocked(&mut c, Duration::ZERO);
    assert_eq!(published, [0, 1, 2]);
    let (report, fault) = fault_of(&a);
    let expected = MemberFault::Vehicle {
        tick: 2,
        what: format!("agent {ME}: vehicle lost"),
    };
    assert_eq!(fault, &expected);
    let r = report.expect("reported");
    assert_eq!((r.tick, r.id), (2, ME));
    let code = FaultCode::VehicleLost;
    assert_eq!(r.status(), AgentStatus::Fault { code, peer: None });
}

/// A clock the test moves; the fake transport's `wait` moves it by the timeout.
#[derive(Default)]
struct FakeClock(Cell<Duration>);

impl Clock for FakeClock {
    fn now(&self) -> Duration {
        self.0.get()
    }
}

/// An in-memory transport: scripted clock messages and neighbour states, one per wait.
struct FakeTransport<'a> {
    clock: &'a FakeClock,
    grants: VecDeque<ClockMsg>,
    states: VecDeque<StateMsg>,
    published: Vec<StateMsg>,
    alive: bool,
}

impl MemberTransport for FakeTransport<'_> {
    type Error = std::convert::Infallible;
    fn publish(&mut self, msg: StateMsg) -> Result<usize, Self::Error> {
        self.published.push(msg);
        Ok(1)
    }
    fn publish_quietly(&mut self, msg: StateMsg) -> Result<usize, Self::Error> {
        self.publish(msg)
    }
    fn notify_readers(&mut self) -> Result<(), Self::Error> {
        Ok(())
    }
    fn receive_neighbors(&mut self, mut f: impl FnMut(StateMsg)) -> Result<usize, Self::Error> {
        let n = self.states.len();
        self.states.drain(..).for_each(&mut f);
        Ok(n)
    }
    fn latest_clock(&mut self) -> Result<Option<ClockMsg>, Self::Error> {
        Ok(self.grants.pop_front())
    }
    fn wait(&mut self, timeout: Duration) -> Result<bool, Self::Error> {
        self.clock.0.set(self.clock.0.get() + timeout);
        Ok(false)
    }
    fn orchestrator_alive(&self) -> bool {
        self.alive
    }
}

#[test]
fn the_loop_flies_a_leader_to_the_stop_and_notices_a_lost_orchestrator() {
    let clock = FakeClock::default();
    let mut t = FakeTransport {
        clock: &clock,
        grants: [
            ClockMsg::run(3, HASH),
            ClockMsg::stop(3, HASH, StopReason::Finished),
        ]
        .into(),
        states: VecDeque::new(),
        published: Vec::new(),
        alive: true,
    };
    let mut c = core(Role::Primary, None);
    let stop = AtomicBool::new(false);
    let done = fly(&mut c, &mut t, &clock, &stop, None).unwrap();
    assert_eq!(
        done,
        Finished {
            tick: 3,
            reason: StopReason::Finished.code()
        }
    );
    let ticks: Vec<u64> = t.published.iter().map(|m| m.tick).collect();
    assert_eq!(ticks, [0, 1, 2, 3]);

    // The orchestrator dies after the first grant: the member stops within one alive check.
    t.grants = [ClockMsg::run(1, HASH)].into();
    t.published.clear();
    t.alive = false;
    let mut c = core(Role::Primary, None);
    match fly(&mut c, &mut t, &clock, &stop, None) {
        Err(LoopError::Fault(MemberFault::OrchestratorLost { tick: 1 })) => {}
        other => panic!("{other:?}"),
    }
}

/// Over links 2 ticks late (link.rs) tick k waits only for the states of tick k - 2: the first
/// two ticks fly on the neighbours' known starts, and a state of a later tick is kept (it is
/// still in flight), not taken for a gap.
#[test]
fn delayed_links_wait_only_for_the_states_usable_at_the_tick() {
    use cdm_model::link::{LinkModel, LinkSpec};
    let spec = LinkSpec {
        delay_ms: 20.0,
        ..LinkSpec::default()
    };
    let cfg = StepConfig {
        gains: [8.0, 24.0, 51.5625, 23.4375],
        dt_s: 0.01,
        substeps: 1,
        neighbor_model: NeighborModel::Taylor,
    };
    let start = Flat::rest(Vec3::zeros());
    let mut c = core(Role::Follower, None).with_links(LinkModel::new(spec, 0.01), &cfg, [start; 3]);
    on_clock(&mut c, &ClockMsg::run(10, HASH)).unwrap();
    let (published, a) = run_until_blocked(&mut c, Duration::ZERO);
    assert_eq!(
        published,
        [0, 1, 2],
        "ticks 0 and 1 need no neighbour state"
    );
    assert!(matches!(a, Action::Wait(_)), "{a:?}");
    for id in [1, 2, 3] {
        c.on_neighbor(&state(id, 0));
    }
    c.on_neighbor(&state(1, 1));
    assert_eq!(run_until_blocked(&mut c, Duration::ZERO).0, [3]);
    match run_until_blocked(&mut c, Duration::from_secs(60)).1 {
        Action::Fail {
            fault: MemberFault::Silent { waiting_for, .. },
            ..
        } => assert_eq!(
            waiting_for,
            WaitingFor::States {
                tick: 1,
                missing: vec![2, 3]
            }
        ),
        other => panic!("expected a silence naming the missing states, got {other:?}"),
    }
}
