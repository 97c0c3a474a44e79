//! How many pieces a Crazyflie needs: it evaluates each piece in single precision and keeps
//! them in a small trajectory memory. This file bounds the single-precision error of a piece
//! and picks the fewest equal pieces that keep it under a tolerance.
//!
//! The model of the firmware's evaluation (crazyflie-firmware `pptraj.c`, cflib `Poly4D`):
//! every coefficient and every piece duration is stored as f32; the time local to a piece is
//! found by subtracting the f32 durations of the earlier pieces; the polynomial is evaluated by
//! Horner's rule in f32 (its two zero leading coefficients of the 8 stored add no error).
//! With the unit roundoff u = 2^-24 and gamma_n = n u / (1 - n u) (Higham, Accuracy and
//! Stability of Numerical Algorithms, eq. 5.3), the error at local time t in [0, d] is at most
//!
//! ```text
//!   gamma_{2n+1} sum_m |c_m| (d (1 + u))^m       rounded coefficients, Horner (n = 5)
//! + u d |p'|_max                                  local time rounded to f32
//! + gamma_{K+1} T_total |p'|_max                  piece start drift from K rounded durations
//! ```
//!
//! where |p'|_max <= sum_m m |c_m| d^(m-1) on the piece, and T_total is the whole chain's duration
//! (a mission's, take-off to landing, hovers included).

use cdm_math::Real;

use super::poly::{pieces, AgentTrajectory, Cut, PolyPiece, DEGREE};

/// Unit roundoff of f32.
const U: Real = f32::EPSILON as Real / 2.0;

/// gamma_n (Higham eq. 3.8).
fn gamma(n: usize) -> Real {
    let nu = n as Real * U;
    nu / (1.0 - nu)
}

/// A Crazyflie's trajectory memory, bytes (crazyflie-firmware `TRAJECTORY_MEMORY_SIZE`).
pub const TRAJECTORY_MEMORY_BYTES: usize = 4096;
/// Bytes of one uncompressed piece: 4 axes x 8 f32 coefficients + an f32 duration (cflib
/// `Poly4D.pack`).
pub const PIECE_BYTES: usize = 4 * 8 * 4 + 4;
/// The most pieces the memory holds.
pub const MAX_PIECES: usize = TRAJECTORY_MEMORY_BYTES / PIECE_BYTES;
/// The tolerance of the issue: f32 evaluation within 1 mm of the exact trajectory.
pub const DEFAULT_TOLERANCE_M: Real = 1e-3;

/// The f32 error bound of one piece (the largest of its three axes), metres.
pub fn piece_bound_m(p: &PolyPiece, count: usize, t_total_s: Real) -> Real {
    let d = p.duration_s;
    let d_hat = d * (1.0 + U);
    let mut worst: Real = 0.0;
    for axis in 0..3 {
        let c: [Real; DEGREE + 1] = std::array::from_fn(|m| p.coeffs[m][axis].abs());
        let horner: Real = (0..=DEGREE).map(|m| c[m] * d_hat.powi(m as i32)).sum();
        let slope: Real = (1..=DEGREE)
            .map(|m| m as Real * c[m] * d.powi(m as i32 - 1))
            .sum();
        let bound =
            gamma(2 * DEGREE + 1) * horner + U * d * slope + gamma(count + 1) * t_total_s * slope;
        worst = worst.max(bound);
    }
    worst
}

/// The f32 error bound of a whole team cut by `cut`, and the pieces per member, metres.
pub fn team_bound_m(trajs: &[AgentTrajectory], cut: Cut) -> (Real, usize) {
    let mut worst: Real = 0.0;
    let mut count = 0;
    for t in trajs {
        let ps = pieces(t, cut);
        count = count.max(ps.len());
        // The start drift accumulates over every piece of the chain, to its end.
        for p in &ps {
            worst = worst.max(piece_bound_m(p, ps.len(), t.duration_s()));
        }
    }
    (worst, count)
}

/// The chosen cut of a Crazyflie export.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CrazyflieSplit {
    /// How each member's chain is cut (`Cut::Count(n)`: the longest motion in n pieces).
    pub cut: Cut,
    /// Pieces per member, hovers included.
    pub pieces: usize,
    /// The longest piece, seconds.
    pub piece_duration_s: Real,
    /// The f32 error bound at that cut (the largest over members, pieces and axes), metres.
    pub f32_bound_m: Real,
    pub bytes: usize,
}

/// Why no cut fits a Crazyflie. The bound is not monotone in the number of pieces: shorter
/// pieces shrink the Horner term, more durations add start drift, so past an optimum (a dozen
/// pieces for the quintic) more memory would not help: the search covers every count the
/// memory holds.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[error("float32 evaluation cannot stay within {tolerance_m} m in the Crazyflie's trajectory memory: the smallest bound is {best_bound_m:.3e} m with {best_pieces} pieces ({best_bytes} bytes); the memory holds {max_pieces} pieces of {piece_bytes} bytes ({budget_bytes} bytes); the coordinates are too large for single precision (bring the plan near the origin with --scale and --origin)")]
pub struct SplitError {
    pub tolerance_m: Real,
    pub best_bound_m: Real,
    pub best_pieces: usize,
    pub best_bytes: usize,
    pub max_pieces: usize,
    pub piece_bytes: usize,
    pub budget_bytes: usize,
}

/// The fewest pieces (`Cut::Count(n)` for n = 1, 2, ... while the memory holds them) whose f32
/// bound is within `tolerance_m`. A mission's hovers take one piece each.
pub fn crazyflie_split(
    trajs: &[AgentTrajectory],
    tolerance_m: Real,
) -> Result<CrazyflieSplit, SplitError> {
    let mut best = (Real::INFINITY, 1);
    for n in 1..=MAX_PIECES {
        let cut = Cut::Count(n);
        let (bound, count) = team_bound_m(trajs, cut);
        if count > MAX_PIECES {
            // A mission too long for the memory even at one piece per phase names that count.
            if n == 1 {
                best = (bound, count);
            }
            break;
        }
        if bound <= tolerance_m {
            let longest = trajs
                .iter()
                .flat_map(|t| pieces(t, cut))
                .map(|p| p.duration_s)
                .fold(0.0, Real::max);
            return Ok(CrazyflieSplit {
                cut,
                pieces: count,
                piece_duration_s: longest,
                f32_bound_m: bound,
                bytes: count * PIECE_BYTES,
            });
        }
        if bound < best.0 {
            best = (bound, count);
        }
    }
    Err(SplitError {
        tolerance_m,
        best_bound_m: best.0,
        best_pieces: best.1,
        best_bytes: best.1 * PIECE_BYTES,
        max_pieces: MAX_PIECES,
        piece_bytes: PIECE_BYTES,
        budget_bytes: TRAJECTORY_MEMORY_BYTES,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use cdm_math::Vec3;
    use cdm_model::plan::TeamPlan;

    fn traj(scale: Real, t_total_s: Real) -> AgentTrajectory {
        let s = |x: Real, y: Real, z: Real| Vec3::new(x, y, z) * scale;
        let plan = TeamPlan::new(
            t_total_s,
            [
                s(360.0, 0.0, 900.0),
                s(72.0, 108.0, 1008.0),
                s(108.0, -72.0, 1080.0),
            ],
            [
                s(224.0, 434.0, 560.0),
                s(126.0, 224.0, 560.0),
                s(322.0, 224.0, 560.0),
            ],
        )
        .unwrap();
        AgentTrajectory::new(&plan, 1, &[0.0, 0.0, 1.0])
    }

    /// The bound holds: f32 Horner on f32 coefficients and f32 local time, against f64.
    #[test]
    fn bound_covers_the_f32_evaluation() {
        for (scale, count) in [(1.0, 31), (0.01, 1), (0.01, 4), (0.5, 9)] {
            let tr = traj(scale, 200.0);
            for p in pieces(&tr, Cut::Count(count)) {
                let bound = piece_bound_m(&p, count, 200.0);
                for k in 0..=500 {
                    let u = p.duration_s * k as Real / 500.0;
                    let exact = p.eval(u);
                    let uf = u as f32;
                    for axis in 0..3 {
                        let v = p
                            .coeffs
                            .iter()
                            .rev()
                            .fold(0.0f32, |acc, c| acc * uf + c[axis] as f32);
                        let err = (v as Real - exact[axis]).abs();
                        assert!(
                            err <= bound,
                            "scale={scale} count={count} err={err} bound={bound}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn split_picks_the_fewest_pieces_or_refuses() {
        let lab = [traj(0.01, 200.0)];
        let s = crazyflie_split(&lab, 1e-3).unwrap();
        assert!(s.f32_bound_m <= 1e-3 && s.pieces <= MAX_PIECES);
        if s.pieces > 1 {
            assert!(team_bound_m(&lab, Cut::Count(s.pieces - 1)).0 > 1e-3);
        }
        assert_eq!(s.bytes, s.pieces * 132);
        // Kilometre coordinates: single precision alone is ~1e-4 m there, so 1 um is impossible
        // with any number of pieces the memory holds.
        let far = [traj(1.0, 200.0)];
        let e = crazyflie_split(&far, 1e-6).unwrap_err();
        assert!(e.best_bound_m > 1e-6 && e.best_pieces <= MAX_PIECES);
        assert_eq!(e.budget_bytes, 4096);
    }
}
