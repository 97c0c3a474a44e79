//! The rate limit of the live topics (`--ros2-hz`), pure: the caller passes "now". Wall time
//! only decides which ticks are published; it never touches the simulation.

use std::time::{Duration, Instant};

/// Lets a tick through once its slot has come: slots are `1/hz` apart, counted from the first
/// tick let through, so ticks offered every 10 ms at 30 Hz go out 30 times a second (not every
/// 40 ms, as "an interval since the last one" would give). A pause does not bank slots.
#[derive(Debug, Clone)]
pub struct Pacer {
    interval: Duration,
    next: Option<Instant>,
}

impl Pacer {
    /// At most `hz` ticks a second (the caller checks the range: `--ros2-hz`). A rate slower
    /// than one a day (a tiny, zero or negative one, whose interval no `Duration` may even
    /// hold) is one a day, rather than a panic.
    pub fn new(hz: f64) -> Self {
        let day = Duration::from_secs(86_400);
        Pacer {
            interval: Duration::try_from_secs_f64(1.0 / hz).map_or(day, |d| d.min(day)),
            next: None,
        }
    }

    /// Whether the tick offered at `now` goes out: the first always does, and so does one
    /// that must (`force`: the plan's last tick, so a subscriber sees where the team ended; it
    /// takes the next slot).
    pub fn due(&mut self, now: Instant, force: bool) -> bool {
        let due = force || self.next.is_none_or(|at| now >= at);
        if due {
            self.next = Some(match self.next {
                Some(at) if at + self.interval > now => at + self.interval,
                _ => now + self.interval,
            });
        }
        due
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ticks_go_out_at_most_at_the_rate_and_the_forced_one_always() {
        let t0 = Instant::now();
        let ms = |n: u64| t0 + Duration::from_millis(n);
        let mut p = Pacer::new(10.0);
        assert!(p.due(ms(0), false), "the first tick goes out");
        assert!(!p.due(ms(50), false));
        assert!(p.due(ms(100), false), "an interval later");
        assert!(!p.due(ms(199), false));
        assert!(
            p.due(ms(150), true) && !p.due(ms(200), false),
            "forced, and counted"
        );
        // Ticks offered every 1 ms or every 10 ms over one second at 30 Hz: 30 go out.
        for step_ms in [1, 10] {
            let mut p = Pacer::new(30.0);
            let sent = (0..1000 / step_ms)
                .filter(|&k| p.due(ms(k * step_ms), false))
                .count();
            assert_eq!(sent, 30, "a tick every {step_ms} ms");
        }
        // Rates no `Duration` holds are one tick a day.
        for hz in [1e-20, 5e-324, 0.0, -1.0] {
            let mut p = Pacer::new(hz);
            assert!(p.due(ms(0), false) && !p.due(ms(1000), false), "{hz}");
        }
        // After a pause the slots start again from the next tick: no burst.
        let mut p = Pacer::new(10.0);
        assert!(p.due(ms(0), false) && p.due(ms(5000), false) && !p.due(ms(5050), false));
    }
}
