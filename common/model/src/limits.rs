//! What a vehicle can fly: speed and acceleration limits, checked exactly on a rest-to-rest
//! motion of the quintic (eq. 16), and the downwash metric in which two members must stay apart.
//!
//! In a phase every member's desired position is r_i,HT(t) = a_i + s(t) D_i (eqs. 13, 15), with
//! D_i = sum_j alpha_ij (goal_j - start_j) fixed over the phase. So its velocity is D_i s'(t) and
//! its acceleration D_i s''(t): every component shares one scalar profile, and the largest
//! horizontal speed is |D_i,xy| max s', the largest climb max(D_i,z, 0) max s', and so on. The
//! maxima of s' and |s''| over [0, T] are closed forms (below), so the bound is exact, not
//! sampled, and scales as 1/T (speed) and 1/T^2 (acceleration).

use cdm_math::{Real, Vec3};

/// max over [0, T] of s'(t) times T: s' = 30 tau^2 (1 - tau)^2 / T peaks at tau = 1/2, where it
/// is 30/16.
pub const PEAK_SPEED_TIMES_T: Real = 1.875;

/// max over [0, T] of |s''(t)| times T^2: s'' = 60 tau (1 - tau) (1 - 2 tau) / T^2 has its
/// extremes where 1 - 6 tau + 6 tau^2 = 0, tau = (3 -+ sqrt 3) / 6, and there
/// |s''| T^2 = 60 tau (1 - tau) |1 - 2 tau| = 10 / sqrt 3.
pub const PEAK_ACCEL_TIMES_T2: Real = 5.773_502_691_896_258;

/// tau of the first acceleration peak, (3 - sqrt 3) / 6 (the second is 1 - this).
pub const TAU_PEAK_ACCEL: Real = 0.211_324_865_405_187_1;

/// One of the vehicle's limits, named as its `[vehicle]` key.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Limit {
    /// Horizontal speed |v_xy|.
    SpeedXy,
    /// Climb rate max(v_z, 0).
    SpeedUp,
    /// Descent rate max(-v_z, 0).
    SpeedDown,
    /// Horizontal acceleration |a_xy|.
    AccelXy,
    /// Vertical acceleration |a_z|.
    AccelZ,
}

impl Limit {
    /// Every limit, in the file's order.
    pub const ALL: [Limit; 5] = [
        Limit::SpeedXy,
        Limit::SpeedUp,
        Limit::SpeedDown,
        Limit::AccelXy,
        Limit::AccelZ,
    ];

    /// The `[vehicle]` key.
    pub fn key(self) -> &'static str {
        match self {
            Limit::SpeedXy => "max_speed_xy_m_s",
            Limit::SpeedUp => "max_speed_up_m_s",
            Limit::SpeedDown => "max_speed_down_m_s",
            Limit::AccelXy => "max_accel_xy_m_s2",
            Limit::AccelZ => "max_accel_z_m_s2",
        }
    }

    /// The unit of its values.
    pub fn unit(self) -> &'static str {
        if self.is_accel() {
            "m/s^2"
        } else {
            "m/s"
        }
    }

    /// An acceleration (scales as 1/T^2) rather than a speed (1/T).
    pub fn is_accel(self) -> bool {
        matches!(self, Limit::AccelXy | Limit::AccelZ)
    }

    /// The part of a velocity or acceleration vector this limit bounds.
    pub fn measure(self, v: &Vec3) -> Real {
        match self {
            Limit::SpeedXy | Limit::AccelXy => v.x.hypot(v.y),
            Limit::SpeedUp => v.z.max(0.0),
            Limit::SpeedDown => (-v.z).max(0.0),
            Limit::AccelZ => v.z.abs(),
        }
    }

    /// The largest value of this limit's measure over a rest-to-rest quintic motion by `d` in
    /// `t_total_s` (exact: the measure of D s'(t) or D s''(t) is |measure(D)| times |s'| or
    /// |s''|, whose maxima are the constants above).
    pub fn peak(self, d: &Vec3, t_total_s: Real) -> Real {
        if self.is_accel() {
            self.measure(d) * PEAK_ACCEL_TIMES_T2 / (t_total_s * t_total_s)
        } else {
            self.measure(d) * PEAK_SPEED_TIMES_T / t_total_s
        }
    }

    /// Where in the motion the peak is, as a fraction tau of its travel time (the first of the
    /// two acceleration peaks).
    pub fn tau_of_peak(self) -> Real {
        if self.is_accel() {
            TAU_PEAK_ACCEL
        } else {
            0.5
        }
    }

    /// The shortest travel time of a motion by `d` whose peak meets `max` (0 when the motion
    /// does not load this limit): peak(T) = peak(T0) (T0 / T)^k with k = 1 for a speed, 2 for
    /// an acceleration.
    pub fn shortest_time(self, d: &Vec3, max: Real) -> Real {
        let m = self.measure(d);
        if self.is_accel() {
            (m * PEAK_ACCEL_TIMES_T2 / max).sqrt()
        } else {
            m * PEAK_SPEED_TIMES_T / max
        }
    }
}

/// The downwash metric: d(v) = sqrt(vx^2 + vy^2 + (vz / ratio)^2). Each member occupies the
/// ellipsoid d(p - r_i) <= eps (horizontal semi-axis eps, vertical ratio eps), and two such
/// ellipsoids are disjoint exactly when d(r_i - r_j) > 2 eps (d is a norm, so they are its balls).
pub fn downwash_distance(v: &Vec3, ratio: Real) -> Real {
    scaled(v, ratio).norm()
}

/// `v` with its vertical component divided by `ratio`: the metric's Euclidean image.
pub fn scaled(v: &Vec3, ratio: Real) -> Vec3 {
    Vec3::new(v.x, v.y, v.z / ratio)
}

/// The smallest downwash distance over the segment a + s (b - a), s in [0, 1], and the s where
/// it is reached (exact: the closest point to the origin of the scaled segment).
pub fn segment_min_downwash(a: &Vec3, b: &Vec3, ratio: Real) -> (Real, Real) {
    let (c, e) = (scaled(a, ratio), scaled(&(b - a), ratio));
    let ee = e.norm_squared();
    let s = if ee > 0.0 {
        (-c.dot(&e) / ee).clamp(0.0, 1.0)
    } else {
        0.0
    };
    ((c + e * s).norm(), s)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::{Quintic, Segment};

    /// The closed-form peaks against a dense scan of the quintic's own derivatives.
    #[test]
    fn the_peaks_are_the_quintics_maxima() {
        let q = Quintic { t_total_s: 7.0 };
        let (mut v, mut a) = (0.0_f64, 0.0_f64);
        for k in 0..=200_000 {
            let d = q.derivatives(7.0 * k as Real / 200_000.0, Segment::Motion);
            v = v.max(d[1]);
            a = a.max(d[2].abs());
        }
        assert!((v * 7.0 - PEAK_SPEED_TIMES_T).abs() < 1e-9, "{v}");
        assert!((a * 49.0 - PEAK_ACCEL_TIMES_T2).abs() < 1e-8, "{a}");
        assert!((PEAK_ACCEL_TIMES_T2 - 10.0 / 3.0_f64.sqrt()).abs() < 1e-15);
        assert!((TAU_PEAK_ACCEL - (3.0 - 3.0_f64.sqrt()) / 6.0).abs() < 1e-15);
        let at = q.derivatives(7.0 * TAU_PEAK_ACCEL, Segment::Motion)[2];
        assert!((at * 49.0 - PEAK_ACCEL_TIMES_T2).abs() < 1e-12);
    }

    #[test]
    fn peaks_split_by_direction_and_scale_with_time() {
        let d = Vec3::new(3.0, 4.0, -12.0);
        assert_eq!(Limit::SpeedXy.peak(&d, 10.0), 5.0 * 0.1875);
        assert_eq!(Limit::SpeedUp.peak(&d, 10.0), 0.0);
        assert_eq!(Limit::SpeedDown.peak(&d, 10.0), 12.0 * 0.1875);
        for l in Limit::ALL {
            let t = l.shortest_time(&d, 0.5);
            if l == Limit::SpeedUp {
                assert_eq!(t, 0.0);
            } else {
                assert!((l.peak(&d, t) - 0.5).abs() < 1e-12, "{l:?}");
            }
        }
    }

    #[test]
    fn the_downwash_segment_minimum_is_the_closest_point() {
        let (a, b) = (Vec3::new(-1.0, 0.0, 3.0), Vec3::new(1.0, 0.0, 3.0));
        let (d, s) = segment_min_downwash(&a, &b, 3.0);
        assert!((d - 1.0).abs() < 1e-15 && (s - 0.5).abs() < 1e-15);
        let dense = (0..=10_000)
            .map(|k| downwash_distance(&(a + (b - a) * (k as Real / 1e4)), 3.0))
            .fold(Real::INFINITY, Real::min);
        assert!((dense - d).abs() < 1e-12);
        // A pair stacked 2 m apart vertically is 1 m apart for ratio 2; side by side, 2 m.
        assert_eq!(downwash_distance(&Vec3::new(0.0, 0.0, 2.0), 2.0), 1.0);
        assert_eq!(downwash_distance(&Vec3::new(2.0, 0.0, 0.0), 2.0), 2.0);
    }
}
