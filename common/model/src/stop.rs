//! Bringing the primary leaders to rest along the straight segment they are flying: a new time
//! scaling of the same path (eq. 15 with another s(t)), so every leader path stays the segment it
//! was certified on and every other member stays the same affine combination of them (eq. 13).
//!
//! At the switch the segment's parameter is s0 with rate v0 >= 0 and acceleration a0 (eq. 16's
//! quintic, or an earlier stop). The stop's rate over its duration T_h, u = tau / T_h, is the
//! cubic
//!
//! ```text
//! s'(tau) = (1 - u)^2 (v0 (1 + 2u) + T_h a0 u)
//! ```
//!
//! the Hermite cubic that starts with s' = v0, s'' = a0 (so position, velocity and acceleration
//! are continuous at the switch: only s''' and s'''' jump, as at every phase's start, ERRATA 12)
//! and ends at rest with s'' = 0. The bracket is linear in u, so s' >= 0 on the whole stop (s
//! never runs back) exactly when 3 v0 + T_h a0 >= 0; the distance is
//! s(T_h) - s0 = T_h v0 / 2 + T_h^2 a0 / 12.

use cdm_math::Real;

/// The largest |s''| of eq. 16's quintic over a travel time T: 10 / (sqrt(3) T^2), at
/// tau = 1/2 -+ 1/(2 sqrt 3).
pub fn quintic_peak_acceleration(t_total_s: Real) -> Real {
    10.0 / (3.0_f64.sqrt() * t_total_s * t_total_s)
}

/// A stop of a segment's time scaling, in that segment's own units of s (0 at its start, 1 at
/// its end), from the switch (tau = 0) to rest (tau = `t_s`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StopProfile {
    /// Duration T_h, seconds (a whole number of ticks).
    pub t_s: Real,
    /// s' at the switch (1/s).
    pub v0: Real,
    /// s'' at the switch (1/s^2).
    pub a0: Real,
}

impl StopProfile {
    /// The quickest stop, on whole ticks of `dt_s`, whose |s''| never exceeds `peak_acc` (the
    /// segment's own quintic's peak: no leader accelerates harder than the plan made it) and
    /// that ends at s <= 1 - s0 further on (short of the segment's end). `None` when none exists
    /// (near the segment's end the quintic itself is the quickest such stop: keep it).
    pub fn quickest(
        s0: Real,
        v0: Real,
        a0: Real,
        peak_acc: Real,
        dt_s: Real,
    ) -> Option<StopProfile> {
        if !(s0.is_finite() && v0.is_finite() && a0.is_finite() && v0 >= 0.0 && dt_s > 0.0) {
            return None;
        }
        // The quintic's own rest-to-rest time at that peak bounds how long a stop may need.
        const MAX_STEPS: u64 = 10_000_000;
        for k in 1..=MAX_STEPS {
            let stop = StopProfile {
                t_s: k as Real * dt_s,
                v0,
                a0,
            };
            if 3.0 * v0 + stop.t_s * a0 < 0.0 || s0 + stop.distance() > 1.0 {
                // Both only get worse with a longer stop (the distance grows while s' >= 0).
                return None;
            }
            if stop.peak_acceleration() <= peak_acc * (1.0 + 1e-9) {
                return Some(stop);
            }
        }
        None
    }

    /// s(T_h) - s0.
    pub fn distance(&self) -> Real {
        let t = self.t_s;
        t * self.v0 / 2.0 + t * t * self.a0 / 12.0
    }

    /// max |s''| over the stop: s'' is a quadratic in u, so its ends and its vertex.
    pub fn peak_acceleration(&self) -> Real {
        let (v0, a0, t) = (self.v0, self.a0, self.t_s);
        // s''(u) = (v0 P''(u) + T a0 Q''(u)) / T, P'' = 6u^2 - 6u, Q'' = 3u^2 - 4u + 1.
        let c2 = 6.0 * v0 / t + 3.0 * a0;
        let c1 = -6.0 * v0 / t - 4.0 * a0;
        let c0 = a0;
        let at = |u: Real| (c2 * u * u + c1 * u + c0).abs();
        let mut m = at(0.0).max(at(1.0));
        if c2 != 0.0 {
            let u = -c1 / (2.0 * c2);
            if u > 0.0 && u < 1.0 {
                m = m.max(at(u));
            }
        }
        m
    }

    /// max s' over the stop: s' is a cubic in u, so its ends and the roots of s'' (the
    /// quadratic of [`StopProfile::peak_acceleration`]) inside (0, 1).
    pub fn peak_speed(&self) -> Real {
        let (v0, a0, t) = (self.v0, self.a0, self.t_s);
        let (c2, c1, c0) = (6.0 * v0 / t + 3.0 * a0, -6.0 * v0 / t - 4.0 * a0, a0);
        let speed = |u: Real| self.derivatives(u * t)[1];
        let mut roots = Vec::with_capacity(2);
        if c2 == 0.0 {
            if c1 != 0.0 {
                roots.push(-c0 / c1);
            }
        } else {
            let disc = c1 * c1 - 4.0 * c2 * c0;
            if disc >= 0.0 {
                let r = disc.sqrt();
                roots.extend([(-c1 - r) / (2.0 * c2), (-c1 + r) / (2.0 * c2)]);
            }
        }
        (roots.into_iter().filter(|u| *u > 0.0 && *u < 1.0))
            .map(speed)
            .fold(speed(0.0).max(speed(1.0)), Real::max)
    }

    /// [s - s0, s', s'', s''', s''''] at `tau` seconds into the stop (clamped to it).
    pub fn derivatives(&self, tau: Real) -> [Real; 5] {
        let (v0, a0, t) = (self.v0, self.a0, self.t_s);
        let u = (tau / t).clamp(0.0, 1.0);
        let (u2, u3, u4) = (u * u, u * u * u, u * u * u * u);
        // P = integral of (1-w)^2 (1+2w), Q = integral of w (1-w)^2, from 0 to u.
        let p = [
            u - u3 + u4 / 2.0,
            1.0 - 3.0 * u2 + 2.0 * u3,
            6.0 * u2 - 6.0 * u,
        ];
        let q = [
            u2 / 2.0 - 2.0 * u3 / 3.0 + u4 / 4.0,
            u - 2.0 * u2 + u3,
            3.0 * u2 - 4.0 * u + 1.0,
        ];
        [
            t * (v0 * p[0] + t * a0 * q[0]),
            v0 * p[1] + t * a0 * q[1],
            (v0 * p[2] + t * a0 * q[2]) / t,
            (v0 * (12.0 * u - 6.0) + t * a0 * (6.0 * u - 4.0)) / (t * t),
            (12.0 * v0 + 6.0 * t * a0) / (t * t * t),
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::{Quintic, Segment};

    /// Continuous with the quintic at the switch, at rest at the end, never running back, and
    /// never faster than the quintic's peak; each derivative is the slope of the one before.
    #[test]
    fn a_stop_continues_the_quintic_and_comes_to_rest() {
        let q = Quintic { t_total_s: 100.0 };
        let peak = quintic_peak_acceleration(100.0);
        for t_sw in [5.0, 20.0, 35.0, 50.0, 62.0] {
            let [s0, v0, a0, _, _] = q.derivatives(t_sw, Segment::Motion);
            let stop = StopProfile::quickest(s0, v0, a0, peak, 0.01).expect("a stop exists");
            let d0 = stop.derivatives(0.0);
            assert!(d0[0].abs() < 1e-15 && (d0[1] - v0).abs() < 1e-15);
            assert!((d0[2] - a0).abs() < 1e-12, "{t_sw}: {d0:?} vs {a0}");
            let end = stop.derivatives(stop.t_s);
            assert!(end[1].abs() < 1e-12 && end[2].abs() < 1e-12, "{end:?}");
            assert!((end[0] - stop.distance()).abs() < 1e-12);
            assert!(s0 + stop.distance() <= 1.0);
            assert!(stop.peak_acceleration() <= peak * (1.0 + 1e-9));
            // One tick shorter would be too fast or overshoot: it is the quickest.
            let shorter = StopProfile {
                t_s: stop.t_s - 0.01,
                ..stop
            };
            assert!(
                shorter.peak_acceleration() > peak || 3.0 * v0 + shorter.t_s * a0 < 0.0,
                "{t_sw}"
            );
            let n = 1000;
            for k in 0..=n {
                let tau = stop.t_s * k as Real / n as Real;
                let d = stop.derivatives(tau);
                assert!(d[1] >= -1e-15, "runs back at {tau}: {d:?}");
                assert!(d[2].abs() <= peak * (1.0 + 1e-9));
                if k > 0 && k < n {
                    let h = 1e-5;
                    let (p, m) = (stop.derivatives(tau + h), stop.derivatives(tau - h));
                    for j in 0..4 {
                        let fd = (p[j] - m[j]) / (2.0 * h);
                        assert!((fd - d[j + 1]).abs() < 1e-6 * (1.0 + d[j + 1].abs()));
                    }
                }
            }
        }
    }

    /// The stop's peak speed is its cubic's largest value: no sample of a dense scan exceeds it,
    /// and the best sample comes within the scan's resolution of it.
    #[test]
    fn the_peak_speed_bounds_a_dense_scan_of_the_stop() {
        let q = Quintic { t_total_s: 100.0 };
        let peak = quintic_peak_acceleration(100.0);
        for t_sw in [5.0, 20.0, 35.0, 50.0] {
            let [s0, v0, a0, _, _] = q.derivatives(t_sw, Segment::Motion);
            let stop = StopProfile::quickest(s0, v0, a0, peak, 0.01).expect("a stop exists");
            let exact = stop.peak_speed();
            let n = 20_000;
            let scanned = (0..=n)
                .map(|k| stop.derivatives(stop.t_s * k as Real / n as Real)[1])
                .fold(Real::MIN, Real::max);
            assert!(
                scanned <= exact * (1.0 + 1e-12),
                "{t_sw}: {scanned} > {exact}"
            );
            assert!(
                exact - scanned <= 1e-6 * exact,
                "{t_sw}: {scanned} vs {exact}"
            );
            assert!(exact >= v0);
        }
    }

    /// Past 2/3 of the segment the quintic already brakes about as hard as it may: the cubic
    /// stop at that peak would overshoot the segment's end (the hold then keeps the quintic).
    #[test]
    fn late_in_the_segment_no_stop_ends_short_of_it() {
        let q = Quintic { t_total_s: 100.0 };
        let peak = quintic_peak_acceleration(100.0);
        let [s0, v0, a0, _, _] = q.derivatives(70.0, Segment::Motion);
        assert_eq!(StopProfile::quickest(s0, v0, a0, peak, 0.01), None);
        assert_eq!(StopProfile::quickest(0.5, -1.0, 0.0, peak, 0.01), None);
        assert_eq!(StopProfile::quickest(0.5, Real::NAN, 0.0, peak, 0.01), None);
    }
}
