//! Stability of the control gains (eq. 26, Remark 3). Because W is block lower-triangular, the
//! team's characteristic polynomial factors into s^4 + k1 s^3 + k2 s^2 - k3 mu s - k4 mu for
//! every eigenvalue mu of W (mu = -1 for leaders, mu in spec(L) for followers).

use cdm_math::{eigenvalues_by_components, Complex as C, DMat, Real};

/// Roots of s^4 + k1 s^3 + k2 s^2 - k3 mu s - k4 mu for one (complex) eigenvalue mu of W.
pub fn mode_roots(gains: &[Real; 4], mu: (Real, Real)) -> [(Real, Real); 4] {
    let mu = C::new(mu.0, mu.1);
    let [k1, k2, k3, k4] = *gains;
    let coeffs = [
        C::new(1.0, 0.0),
        C::new(k1, 0.0),
        C::new(k2, 0.0),
        -mu * k3,
        -mu * k4,
    ];
    let r = durand_kerner(&coeffs);
    r.map(|z| (z.re, z.im))
}

/// Smallest distance of any root from the imaginary axis, signed: positive when every root of
/// every mode is in the open left half-plane (stable), negative otherwise. `l` is the
/// follower-follower block of W (eq. 2); spec(W) = {-1} u spec(L) since W is block triangular.
/// NaN when the eigenvalues of L cannot be computed.
pub fn stability_margin(gains: &[Real; 4], l: &DMat) -> Real {
    let Some(mut mus) = eigenvalues_by_components(l) else {
        return Real::NAN;
    };
    mus.push((-1.0, 0.0));
    margin_for(gains, &mus)
}

/// The margin over a given set of eigenvalues of W.
pub fn margin_for(gains: &[Real; 4], mus: &[(Real, Real)]) -> Real {
    let mut margin = Real::INFINITY;
    for mu in mus {
        for (re, _) in mode_roots(gains, *mu) {
            margin = margin.min(-re);
        }
    }
    margin
}

/// Roots of a monic quartic with complex coefficients (Durand-Kerner iteration).
fn durand_kerner(c: &[C; 5]) -> [C; 4] {
    let eval = |z: C| (((c[0] * z + c[1]) * z + c[2]) * z + c[3]) * z + c[4];
    let scale = 1.0 + c[1..].iter().map(|x| x.norm()).fold(0.0, Real::max);
    let seed = C::new(0.4, 0.9);
    let mut z: [C; 4] = std::array::from_fn(|k| seed.powu(k as u32) * scale);
    for _ in 0..500 {
        let mut delta: Real = 0.0;
        for i in 0..4 {
            let mut denom = C::new(1.0, 0.0);
            for j in 0..4 {
                if i != j {
                    denom *= z[i] - z[j];
                }
            }
            if denom.norm() == 0.0 {
                denom = C::new(1e-12, 0.0);
            }
            let step = eval(z[i]) / denom;
            z[i] -= step;
            delta = delta.max(step.norm());
        }
        if delta < 1e-14 * scale {
            break;
        }
    }
    z
}

#[cfg(test)]
mod tests {
    use super::*;

    const PAPER: [Real; 4] = [8.0, 24.0, 51.5625, 23.4375];

    #[test]
    fn leader_roots_match_errata() {
        let mut r = mode_roots(&PAPER, (-1.0, 0.0));
        r.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
        let expect = [
            (-5.10, 0.0),
            (-1.158, -2.552),
            (-1.158, 2.552),
            (-0.585, 0.0),
        ];
        for (g, e) in r.iter().zip(expect) {
            assert!(
                (g.0 - e.0).abs() < 5e-3 && (g.1 - e.1).abs() < 5e-3,
                "{r:?}"
            );
        }
        assert!(margin_for(&PAPER, &[(-1.0, 0.0)]) > 0.5);
    }

    #[test]
    fn unstable_gains_have_negative_margin() {
        assert!(margin_for(&[1.0, 1.0, 10.0, 1.0], &[(-1.0, 0.0)]) < 0.0);
        // mu = 0 puts a root at the origin: not stable.
        assert!(margin_for(&PAPER, &[(0.0, 0.0)]) <= 1e-9);
    }
}
