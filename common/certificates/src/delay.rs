//! What link delay does to the guarantee: the largest delay at which a plan still
//! meets E_max <= delta (eq. 34 against eq. 38).
//!
//! The paper assumes continuous exchange (eqs. 24-25). Over delayed links a follower steers by
//! its neighbours' newest states, extrapolated from their own time (`link.rs`), so the
//! deviation grows with the delay until the team leaves its safety margin. Every state is
//! delayed by the same whole number of ticks (no jitter, no loss: the scenario's own `[link]`
//! is not what is certified). Each trial delay is flown on the team's exactly linear error
//! dynamics (`linear_certificate.rs`, the delay a shift of the neighbour terms), so the search
//! costs about as much as T_threshold's; only a graph the linear model does not cover (a cycle)
//! is flown by the nonlinear engine, as its T_threshold is.

use serde::Serialize;

use crate::linear_certificate::LinearTeam;
use cdm_engine::engine::max_follower_deviation_within;
use cdm_math::Real;
use cdm_model::link::{LinkSpec, MAX_DELAY_MS};
use cdm_scenario::Scenario;

/// The outcome of the search, in whole ticks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum DelayBound {
    /// E_max > delta even with no delay.
    None,
    /// The largest delay (ticks) with E_max <= delta; one more tick breaks it.
    Ticks(u64),
    /// E_max <= delta at every delay up to the cap (ticks) searched.
    AtLeast(u64),
}

/// Where a delay search stops and where its doubling starts (ticks).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DelaySearch {
    /// The largest delay searched.
    pub cap_ticks: u64,
    /// The first delay tried after none (at least one).
    pub first_ticks: u64,
}

/// The largest whole-tick delay d in [0, cap_ticks] with `fly(d) <= delta_m`: doubling from
/// `first_ticks` (at least one) to the first failure, then bisection. It assumes E_max grows with the delay (true in
/// every flight measured, BENCHMARKS.md); a non-finite E_max (a faulted flight) fails.
pub fn max_delay_ticks(
    mut fly: impl FnMut(u64) -> Real,
    delta_m: Real,
    search: DelaySearch,
) -> DelayBound {
    let DelaySearch {
        cap_ticks,
        first_ticks: first,
    } = search;
    let mut ok = |d: u64| {
        let e = fly(d);
        e.is_finite() && e <= delta_m
    };
    if !ok(0) {
        return DelayBound::None;
    }
    let (mut lo, mut hi) = (0u64, first.max(1));
    loop {
        if hi >= cap_ticks {
            if ok(cap_ticks) {
                return DelayBound::AtLeast(cap_ticks);
            }
            hi = cap_ticks;
            break;
        }
        if !ok(hi) {
            break;
        }
        lo = hi;
        hi *= 2;
    }
    while hi - lo > 1 {
        let mid = lo + (hi - lo) / 2;
        if ok(mid) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    DelayBound::Ticks(lo)
}

/// The same scenario with every state `delay_ms` late (no jitter, no loss).
pub fn at_delay(s: &Scenario, delay_ms: Real) -> Scenario {
    let spec = LinkSpec {
        delay_ms,
        ..LinkSpec::default()
    };
    let mut v = s.clone();
    v.file.link = Some(spec).filter(|l| !l.is_perfect());
    v
}

/// E_max of `s` flown by the nonlinear engine with every state `delay_ms` late (infinite when
/// the flight faults), ending the flight once it exceeds `limit_m`.
pub fn deviation_at_delay(s: &Scenario, delay_ms: Real, limit_m: Real) -> Real {
    max_follower_deviation_within(&at_delay(s, delay_ms), limit_m).unwrap_or(Real::INFINITY)
}

/// The largest link delay (whole ticks at the scenario's comm_hz) at which `s` still meets
/// E_max <= delta_m, searched up to the plan's length (or a minute): on `linear`, the scenario's
/// linear team, when there is one, else by flying. `e0_m` is E_max without delay (known).
pub fn max_link_delay(
    s: &Scenario,
    delta_m: Real,
    e0_m: Real,
    linear: Option<&LinearTeam>,
) -> DelayBound {
    let dt_ms = s.dt_s() * 1000.0;
    let search = DelaySearch {
        cap_ticks: s.last_tick().min((MAX_DELAY_MS / dt_ms) as u64),
        // Delays below a quarter of a second pass on every team measured (BENCHMARKS.md):
        // starting the doubling there saves the flights of 1, 2, 4, .. ticks.
        first_ticks: (0.25 / s.dt_s()).round() as u64,
    };
    match linear {
        Some(team) => max_link_delay_linear(team, s.file.t_total_s, delta_m, e0_m, search),
        None => max_delay_ticks(
            |d| match d {
                0 => e0_m,
                _ => deviation_at_delay(s, d as Real * dt_ms, delta_m),
            },
            delta_m,
            search,
        ),
    }
}

/// [`max_link_delay`] of one motion of `t_s` seconds on its linear team (a mission's phase),
/// searched over `search`. Only "E_max <= delta?" is asked: `meets` answers it
/// without computing E_max.
pub fn max_link_delay_linear(
    team: &LinearTeam,
    t_s: Real,
    delta_m: Real,
    e0_m: Real,
    search: DelaySearch,
) -> DelayBound {
    max_delay_ticks(
        |d| match d {
            0 => e0_m,
            _ if team.meets(t_s, d, delta_m) => 0.0,
            _ => Real::INFINITY,
        },
        delta_m,
        search,
    )
}

/// The largest delay searched for a motion of `t_s` seconds at ticks of `dt_s`, and the first
/// delay tried (ticks).
pub fn delay_search(t_s: Real, dt_s: Real) -> DelaySearch {
    DelaySearch {
        cap_ticks: cdm_scenario::last_tick_of(t_s, 1.0 / dt_s)
            .min((MAX_DELAY_MS / (dt_s * 1000.0)) as u64),
        first_ticks: (0.25 / dt_s).round() as u64,
    }
}

/// A [`DelayBound`] in milliseconds at ticks of `dt_s`: (delay, "at least") or `None`.
pub fn bound_ms(b: DelayBound, dt_s: Real) -> (Option<Real>, bool) {
    let ms = |d: u64| d as Real * dt_s * 1000.0;
    match b {
        DelayBound::None => (None, false),
        DelayBound::Ticks(d) => (Some(ms(d)), false),
        DelayBound::AtLeast(d) => (Some(ms(d)), true),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn search(breaks_at: u64, cap: u64) -> (DelayBound, usize) {
        search_from(breaks_at, cap, 1)
    }

    fn range(cap_ticks: u64, first_ticks: u64) -> DelaySearch {
        DelaySearch {
            cap_ticks,
            first_ticks,
        }
    }

    fn search_from(breaks_at: u64, cap: u64, first: u64) -> (DelayBound, usize) {
        let mut flights = 0;
        let b = max_delay_ticks(
            |d| {
                flights += 1;
                if d >= breaks_at {
                    2.0
                } else {
                    1.0
                }
            },
            1.5,
            range(cap, first),
        );
        (b, flights)
    }

    #[test]
    fn finds_the_last_passing_tick() {
        for breaks_at in [1, 2, 3, 7, 8, 9, 100, 513] {
            assert_eq!(
                search(breaks_at, 10_000).0,
                DelayBound::Ticks(breaks_at - 1)
            );
        }
        let (_, flights) = search(513, 10_000);
        assert!(flights <= 2 * 11 + 1, "{flights} flights");
    }

    #[test]
    fn any_first_guess_finds_the_same_tick() {
        for first in [1, 3, 25, 64, 1000] {
            for breaks_at in [1, 2, 30, 91, 144, 513] {
                let (b, flights) = search_from(breaks_at, 10_000, first);
                assert_eq!(b, DelayBound::Ticks(breaks_at - 1), "first {first}");
                assert!(flights <= 2 * 14 + 1, "{flights} flights");
            }
        }
        assert_eq!(search_from(1000, 100, 25).0, DelayBound::AtLeast(100));
    }

    #[test]
    fn reports_none_and_the_cap() {
        assert_eq!(search(0, 100).0, DelayBound::None);
        assert_eq!(search(1000, 100).0, DelayBound::AtLeast(100));
        assert_eq!(search(100, 100).0, DelayBound::Ticks(99));
        assert_eq!(search(70, 100).0, DelayBound::Ticks(69));
    }

    #[test]
    fn a_faulted_flight_fails() {
        let b = max_delay_ticks(
            |d| if d >= 5 { Real::INFINITY } else { 0.0 },
            1.0,
            range(50, 1),
        );
        assert_eq!(b, DelayBound::Ticks(4));
        let nan = max_delay_ticks(|d| if d >= 3 { Real::NAN } else { 0.0 }, 1.0, range(50, 2));
        assert_eq!(nan, DelayBound::Ticks(2));
    }
}
