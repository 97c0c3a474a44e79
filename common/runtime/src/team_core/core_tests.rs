//! The team core's decisions with a fake clock (plain `Duration`s) and no process: each test
//! feeds states, exits and time, and reads the actions.

use std::time::Duration;

use super::*;
use crate::messages::{AgentStatus, FaultCode, StateMsg, StopReason};
use crate::process_exit::ProcessExit;
use cdm_model::outcome::FaultKind;

const HASH: u64 = 7;

fn ms(t: u64) -> Duration {
    Duration::from_millis(t)
}

fn core(ids: &[u32], window: u32, last_tick: u64) -> TeamCore {
    let cfg = TeamConfig {
        ids: ids.to_vec(),
        window,
        last_tick,
        agent_timeout: Duration::from_secs(10),
    };
    TeamCore::lockstep(cfg, ms(0))
}

fn state(id: u32, tick: u64) -> StateMsg {
    StateMsg::ok(tick, HASH, id, [tick as f64; 12])
}

fn report(id: u32, tick: u64, code: FaultCode, peer: Option<u32>) -> StateMsg {
    state(id, tick).with_status(AgentStatus::Fault { code, peer })
}

/// What one burst of actions did, up to the first wait, poll, finish or stop.
#[derive(Debug, Default)]
struct Turn {
    grants: Vec<u64>,
    complete: Vec<u64>,
    exit_checks: usize,
    end: Option<TeamAction>,
}

/// Runs the core at `now` until it waits, polls, finishes or stops, as the loop does (complete
/// ticks are checked whole and recycled; an exit check finds `exited`).
fn turn(c: &mut TeamCore, now: Duration, exited: Option<(u32, ProcessExit)>) -> Turn {
    let mut t = Turn::default();
    c.on_turn(now);
    for _ in 0..10_000 {
        match c.next_action(now) {
            TeamAction::Grant(g) => t.grants.push(g),
            TeamAction::Complete { tick, states } => {
                assert!(states.iter().all(|s| s.is_some_and(|m| m.tick == tick)));
                t.complete.push(tick);
                c.recycle(states);
            }
            TeamAction::Flush => {}
            TeamAction::CheckExited => {
                t.exit_checks += 1;
                if let Some((id, how)) = &exited {
                    c.on_exited(*id, how.clone(), now);
                }
            }
            end => {
                t.end = Some(end);
                return t;
            }
        }
    }
    panic!("the core never waited");
}

fn stop_of(t: &Turn) -> (FaultRecord, StopReason) {
    match &t.end {
        Some(TeamAction::Stop(f, r)) => (f.clone(), *r),
        other => panic!("expected a stop, got {other:?}"),
    }
}

fn send(c: &mut TeamCore, ids: &[u32], ticks: std::ops::RangeInclusive<u64>, now: Duration) {
    for tick in ticks {
        for &id in ids {
            c.on_state(&state(id, tick), now);
        }
    }
}

#[test]
fn the_grant_window_opens_first_then_moves_in_half_windows() {
    let ids = [1, 2, 3];
    let mut c = core(&ids, 4, 100);
    let t = turn(&mut c, ms(0), None);
    assert_eq!(t.grants, [3], "the first grant is a whole window");
    assert_eq!(t.end, Some(TeamAction::Wait(WAIT_SLICE)));
    // A state beyond the grant is not counted (a member cannot have computed it).
    c.on_state(&state(1, 9), ms(1));
    send(&mut c, &ids, 0..=0, ms(1));
    let t = turn(&mut c, ms(1), None);
    assert_eq!(
        (t.grants.as_slice(), t.complete.as_slice()),
        (&[][..], &[0][..])
    );
    assert_eq!(
        t.end,
        Some(TeamAction::Poll),
        "progress polls again at once"
    );
    send(&mut c, &ids, 1..=1, ms(2));
    let t = turn(&mut c, ms(2), None);
    assert_eq!(t.grants, [5], "half a window (2) completed: grant 2 more");
    assert_eq!(t.complete, [1]);
    // Window 1 is strict lockstep, and the last tick ends the run.
    let mut c = core(&ids, 1, 2);
    assert_eq!(turn(&mut c, ms(0), None).grants, [0]);
    for tick in 0..=2 {
        send(&mut c, &ids, tick..=tick, ms(tick + 1));
        let t = turn(&mut c, ms(tick + 1), None);
        assert_eq!(t.complete, [tick]);
        if tick < 2 {
            assert_eq!(t.grants, [tick + 1]);
        }
    }
    assert_eq!(turn(&mut c, ms(9), None).end, Some(TeamAction::Finished));
}

#[test]
fn the_root_cause_wins_over_an_earlier_echo() {
    let ids = [1, 2, 3];
    let mut c = core(&ids, 8, 100);
    turn(&mut c, ms(0), None);
    send(&mut c, &ids, 0..=3, ms(1));
    // Member 3 stops because its neighbour did (an echo, one tick earlier in its own count);
    // member 2 names the cause.
    c.on_state(&report(3, 3, FaultCode::NeighborFault, Some(2)), ms(1));
    c.on_state(&report(2, 4, FaultCode::Control, None), ms(1));
    let t = turn(&mut c, ms(1), None);
    assert_eq!(t.complete, [0, 1, 2, 3]);
    assert!(
        !matches!(t.end, Some(TeamAction::Stop(..))),
        "member 1 may still send tick 4"
    );
    // Members 2 and 3 send no more: once member 1's tick 4 is in, nothing else is owed.
    send(&mut c, &[1], 4..=4, ms(2));
    let t = turn(&mut c, ms(2), None);
    let (f, reason) = stop_of(&t);
    assert_eq!((f.kind, f.agent, f.tick), (FaultKind::Control, Some(2), 4));
    assert_eq!(reason, StopReason::AgentFault);
    assert!(
        f.message.contains("agent 2 reported Control at tick 4"),
        "{}",
        f.message
    );
}

#[test]
fn a_fault_waits_for_every_tick_before_it_however_late_a_live_member_sends_it() {
    let ids = [1, 2, 3];
    let mut c = core(&ids, 16, 100);
    turn(&mut c, ms(0), None);
    // Member 3 starts slowly (a loaded machine): members 1 and 2 run ahead and 2 faults.
    send(&mut c, &[1, 2], 0..=5, ms(1));
    c.on_state(&report(2, 5, FaultCode::Control, None), ms(1));
    let mut now = ms(1);
    while now < ms(3000) {
        let t = turn(&mut c, now, None);
        assert!(
            t.complete.is_empty(),
            "nothing is complete without member 3"
        );
        assert_eq!(t.end, Some(TeamAction::Wait(WAIT_SLICE)), "at {now:?}");
        now += ms(20);
    }
    send(&mut c, &[3], 0..=6, ms(3001));
    let t = turn(&mut c, ms(3001), None);
    assert_eq!(t.complete, [0, 1, 2, 3, 4, 5], "the ticks simulate keeps");
    let (f, _) = stop_of(&t);
    assert_eq!((f.kind, f.agent, f.tick), (FaultKind::Control, Some(2), 5));
    // A member that never sends is waited for no longer than the silence deadline.
    let mut c = core(&ids, 16, 100);
    turn(&mut c, ms(0), None);
    send(&mut c, &[1, 2], 0..=5, ms(1));
    c.on_state(&report(2, 5, FaultCode::Control, None), ms(1));
    // The loop turns every 20 ms (a longer gap would be an orchestrator stall).
    let mut now = ms(1);
    while now + ms(20) < Duration::from_secs(10) {
        now += ms(20);
        assert_eq!(
            turn(&mut c, now, None).end,
            Some(TeamAction::Wait(WAIT_SLICE))
        );
    }
    let (f, _) = stop_of(&turn(&mut c, now + ms(20), None));
    assert_eq!((f.kind, f.agent, f.tick), (FaultKind::Control, Some(2), 5));
}

#[test]
fn a_lost_vehicle_is_recorded_as_vehicle_lost_naming_the_member() {
    let ids = [1, 2];
    let mut c = core(&ids, 16, 100);
    turn(&mut c, ms(0), None);
    send(&mut c, &ids, 0..=2, ms(1));
    c.on_state(&report(2, 2, FaultCode::VehicleLost, None), ms(1));
    let t = turn(&mut c, ms(1), None);
    let (f, reason) = stop_of(&t);
    assert_eq!(
        (f.kind, f.agent, f.tick),
        (FaultKind::VehicleLost, Some(2), 2)
    );
    assert_eq!(reason, StopReason::AgentFault);
}

#[test]
fn a_fault_at_tick_k_keeps_ticks_0_to_k_and_no_later_one() {
    let ids = [1, 2];
    let mut c = core(&ids, 16, 100);
    turn(&mut c, ms(0), None);
    send(&mut c, &ids, 0..=6, ms(1));
    c.on_state(&report(1, 3, FaultCode::Control, None), ms(1));
    let t = turn(&mut c, ms(1), None);
    assert_eq!(
        t.complete,
        [0, 1, 2, 3],
        "tick 3 is complete and kept, tick 4 is not"
    );
    let (f, _) = stop_of(&t);
    assert_eq!((f.agent, f.tick), (Some(1), 3));
}

#[test]
fn a_silent_member_is_named_after_the_timeout() {
    let ids = [1, 2, 3];
    let mut c = core(&ids, 4, 100);
    turn(&mut c, ms(0), None);
    send(&mut c, &[1, 3], 0..=0, ms(5));
    let t = turn(&mut c, ms(5), None);
    assert!(t.complete.is_empty());
    assert_eq!(t.end, Some(TeamAction::Wait(WAIT_SLICE)));
    // Just within the timeout: still waiting (the loop turns every 20 ms, no stall).
    let mut now = ms(5);
    while now + ms(20) < Duration::from_secs(10) {
        now += ms(20);
        assert!(!matches!(
            turn(&mut c, now, None).end,
            Some(TeamAction::Stop(..))
        ));
    }
    let t = turn(&mut c, now + ms(20), None);
    let (f, reason) = stop_of(&t);
    assert_eq!(
        (f.kind, f.agent, f.tick),
        (FaultKind::AgentSilent, Some(2), 0)
    );
    assert_eq!(reason, StopReason::AgentSilent);
    assert!(
        f.message.contains("agents [2] sent no state for tick 0"),
        "{}",
        f.message
    );
}

#[test]
fn an_exited_member_is_blamed_for_the_first_tick_it_never_sent() {
    let ids = [1, 2, 3];
    let mut c = core(&ids, 16, 100);
    turn(&mut c, ms(0), None);
    // Member 2 published ticks 0..=4 and died; the others ran on to tick 9.
    send(&mut c, &[1, 3], 0..=9, ms(1));
    send(&mut c, &[2], 0..=4, ms(1));
    let t = turn(&mut c, ms(1), None);
    assert_eq!(
        t.complete,
        [0, 1, 2, 3, 4],
        "its published states are audited first"
    );
    let t = turn(&mut c, ms(200), Some((2, ProcessExit::Signal(9))));
    assert_eq!(t.exit_checks, 1);
    assert_eq!(
        t.end,
        Some(TeamAction::Wait(WAIT_SLICE)),
        "the exit waits for its grace"
    );
    let t = turn(&mut c, ms(200) + FAULT_GRACE, None);
    let (f, reason) = stop_of(&t);
    assert_eq!(
        (f.kind, f.agent, f.tick),
        (FaultKind::AgentExited, Some(2), 5)
    );
    assert_eq!(reason, StopReason::AgentFault);
    assert_eq!(f.message, "agent 2 was killed by signal 9 at tick 5");
}

#[test]
fn a_non_finite_state_nobody_reads_is_named_by_the_orchestrator() {
    let ids = [1, 2];
    let mut c = core(&ids, 8, 100);
    turn(&mut c, ms(0), None);
    send(&mut c, &ids, 0..=1, ms(1));
    c.on_state(&state(1, 2), ms(1));
    let mut bad = state(2, 2);
    bad.state[4] = f64::NAN;
    c.on_state(&bad, ms(1));
    let t = turn(&mut c, ms(1), None);
    assert_eq!(t.complete, [0, 1], "the non-finite tick is never complete");
    assert_eq!(
        turn(&mut c, ms(400), None).end,
        Some(TeamAction::Wait(WAIT_SLICE))
    );
    let t = turn(&mut c, ms(1) + FAULT_GRACE + ms(1), None);
    let (f, _) = stop_of(&t);
    assert_eq!(
        (f.kind, f.agent, f.tick),
        (FaultKind::NonFiniteState, Some(2), 2)
    );
    // A reader's report naming both members outranks the orchestrator's own finding.
    let mut c = core(&ids, 8, 100);
    turn(&mut c, ms(0), None);
    c.on_state(&bad, ms(1));
    c.on_state(&report(1, 2, FaultCode::NonFinite, Some(2)), ms(2));
    let (f, _) = stop_of(&turn(&mut c, ms(1000), None));
    assert_eq!(
        (f.kind, f.agent, f.peer),
        (FaultKind::AgentFault, Some(1), Some(2))
    );
}

#[test]
fn an_interrupt_stops_at_the_next_tick_and_a_stall_takes_the_blame() {
    let ids = [1, 2];
    let mut c = core(&ids, 4, 100);
    turn(&mut c, ms(0), None);
    send(&mut c, &ids, 0..=1, ms(1));
    turn(&mut c, ms(1), None);
    c.on_interrupt("SIGINT");
    let (f, reason) = stop_of(&turn(&mut c, ms(2), None));
    assert_eq!(
        (f.kind, f.tick, reason),
        (FaultKind::Interrupted, 2, StopReason::Interrupted)
    );
    // The orchestrator did not run for 20 s; its members then went silent: the stall is named.
    let mut c = core(&ids, 4, 100);
    turn(&mut c, ms(0), None);
    let t = turn(&mut c, Duration::from_secs(20), None);
    assert_eq!(
        t.end,
        Some(TeamAction::Wait(WAIT_SLICE)),
        "a stall restarts the timeout"
    );
    for s in 21..=30 {
        let t = turn(&mut c, Duration::from_secs(s), None);
        assert_eq!(t.end, Some(TeamAction::Wait(WAIT_SLICE)));
    }
    let (f, _) = stop_of(&turn(&mut c, Duration::from_millis(31_500), None));
    assert_eq!(f.kind, FaultKind::OrchestratorStalled);
}
