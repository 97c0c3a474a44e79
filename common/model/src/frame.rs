//! The continuum reference frame (CRF) of the primary leaders (eqs. 7-10), in-plane coordinates
//! (eq. 12), and the homogeneous transformation `Q`, `d` over the moving frame (eqs. 5, 11).

use cdm_math::{singular_values_ascending, Mat3, Real, Vec3};

/// Below this sine of the angle between `r2 - r1` and `r3 - r1` the primary leaders count as
/// collinear and the rank condition of eq. 7 is considered violated.
pub const MIN_LEADER_SINE: Real = 1e-2;

/// The primary leaders do not span a plane (eq. 7 violated).
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[error("primary leaders are (nearly) collinear: sine of the angle at leader 1 is {sine:.3e} (needs >= {MIN_LEADER_SINE:e}, eq. 7)")]
pub struct CollinearLeaders {
    /// |(r2 - r1) x (r3 - r1)| / (|r2 - r1| |r3 - r1|).
    pub sine: Real,
}

/// Orthonormal CRF bases e1, e2, e3 (eqs. 8-10) of a triangle r1, r2, r3.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frame {
    pub origin: Vec3,
    pub e1: Vec3,
    pub e2: Vec3,
    pub e3: Vec3,
    /// rho_1 of eq. 8b.
    pub rho1: Real,
}

/// Sine of the angle at r1 of the triangle r1, r2, r3 (0 when degenerate).
pub fn leader_sine(r1: &Vec3, r2: &Vec3, r3: &Vec3) -> Real {
    let u = r2 - r1;
    let w = r3 - r1;
    let denom = u.norm() * w.norm();
    if denom <= 0.0 || !denom.is_finite() {
        return 0.0;
    }
    u.cross(&w).norm() / denom
}

impl Frame {
    /// The CRF of eqs. 8-10: e1 along r2 - r1, e2 from the foot point r_B1 towards r3, e3 = e1 x e2.
    pub fn new(r1: &Vec3, r2: &Vec3, r3: &Vec3) -> Result<Self, CollinearLeaders> {
        let sine = leader_sine(r1, r2, r3);
        if sine.is_nan() || sine < MIN_LEADER_SINE {
            return Err(CollinearLeaders { sine });
        }
        let u = r2 - r1;
        let rho1 = u.dot(&(r3 - r1)) / u.dot(&u); // eq. 8b
        let rb1 = r1 + u * rho1; // eq. 8a
        let e1 = u / u.norm();
        let e2 = (r3 - rb1) / (r3 - rb1).norm();
        let e3 = e1.cross(&e2);
        Ok(Frame {
            origin: *r1,
            e1,
            e2,
            e3,
            rho1,
        })
    }

    /// In-plane coordinates (gamma, beta) of p (eq. 12) and its signed distance along e3.
    pub fn coords(&self, p: &Vec3) -> (Real, Real, Real) {
        let rel = p - self.origin;
        (rel.dot(&self.e1), rel.dot(&self.e2), rel.dot(&self.e3))
    }

    /// The point of the plane with in-plane coordinates (gamma, beta).
    pub fn point(&self, gamma: Real, beta: Real) -> Vec3 {
        self.origin + self.e1 * gamma + self.e2 * beta
    }
}

/// The homogeneous transformation r_HT = Q r_0 + d (eq. 5) fixed by the primary leaders.
///
/// Eq. 11 with a virtual leader at distance Xi along e3 is badly conditioned (ERRATA, "useful
/// identities"); this uses the equivalent closed form Q(t) = [u w n](t) [u w n](t0)^{-1} with
/// u = r2 - r1, w = r3 - r1, n = unit(u x w), which does not depend on Xi.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Homogeneous {
    r1_0: Vec3,
    basis0_inv: Mat3,
}

impl Homogeneous {
    /// Fix the reference configuration of the primary leaders at t0.
    pub fn new(r0: &[Vec3; 3]) -> Result<Self, CollinearLeaders> {
        let basis0 = basis(r0)?;
        let basis0_inv = basis0.try_inverse().ok_or(CollinearLeaders { sine: 0.0 })?;
        Ok(Homogeneous {
            r1_0: r0[0],
            basis0_inv,
        })
    }

    /// Q and d for the primary leaders at positions `r` (eq. 11 in closed form).
    pub fn q_d(&self, r: &[Vec3; 3]) -> Result<(Mat3, Vec3), CollinearLeaders> {
        let q = basis(r)? * self.basis0_inv;
        let d = r[0] - q * self.r1_0;
        Ok((q, d))
    }
}

fn basis(r: &[Vec3; 3]) -> Result<Mat3, CollinearLeaders> {
    let sine = leader_sine(&r[0], &r[1], &r[2]);
    if sine.is_nan() || sine < MIN_LEADER_SINE {
        return Err(CollinearLeaders { sine });
    }
    let u = r[1] - r[0];
    let w = r[2] - r[0];
    let n = u.cross(&w).normalize();
    Ok(Mat3::from_columns(&[u, w, n]))
}

/// Eigenvalues of U_D = sqrt(Q^T Q) in ascending order (polar decomposition Q = R_D U_D,
/// Sec. VI-A): the singular values of Q.
pub fn deformation_eigenvalues(q: &Mat3) -> [Real; 3] {
    singular_values_ascending(q)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn paper_leaders() -> [Vec3; 3] {
        [
            Vec3::new(360.0, 0.0, 900.0),
            Vec3::new(72.0, 108.0, 1008.0),
            Vec3::new(108.0, -72.0, 1080.0),
        ]
    }

    #[test]
    fn paper_crf_bases_at_t0() {
        let r = paper_leaders();
        let f = Frame::new(&r[0], &r[1], &r[2]).unwrap();
        let close = |v: &Vec3, e: [Real; 3]| (0..3).all(|i| (v[i] - e[i]).abs() < 5e-5);
        assert!(close(&f.e1, [-0.8835, 0.3313, 0.3313]), "{:?}", f.e1);
        assert!(close(&f.e2, [-0.1280, -0.8509, 0.5096]), "{:?}", f.e2);
        assert!(close(&f.e3, [0.4507, 0.4078, 0.7941]), "{:?}", f.e3);
        assert!((f.rho1 - 0.79268).abs() < 1e-5, "{}", f.rho1);
        assert!(f.e1.dot(&f.e2).abs() < 1e-12 && (f.e3.norm() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn q_is_identity_at_t0_and_maps_leaders() {
        let r = paper_leaders();
        let h = Homogeneous::new(&r).unwrap();
        let (q, d) = h.q_d(&r).unwrap();
        assert!((q - Mat3::identity()).norm() < 1e-12 && d.norm() < 1e-9);
        let g = [
            Vec3::new(224.0, 434.0, 560.0),
            Vec3::new(126.0, 224.0, 560.0),
            Vec3::new(322.0, 224.0, 560.0),
        ];
        let (q, d) = h.q_d(&g).unwrap();
        for i in 0..3 {
            assert!((q * r[i] + d - g[i]).norm() < 1e-9);
        }
        let ev = deformation_eigenvalues(&q);
        let expect = [0.6845, 0.9958, 1.0];
        for i in 0..3 {
            assert!((ev[i] - expect[i]).abs() < 5e-4, "{ev:?}");
        }
    }

    #[test]
    fn collinear_leaders_are_refused() {
        let r = [
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(2.0, 1e-4, 0.0),
        ];
        assert!(Frame::new(&r[0], &r[1], &r[2]).is_err());
        assert!(Homogeneous::new(&r).is_err());
    }
}
