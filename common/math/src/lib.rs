//! The one place that names nalgebra: every other module uses these aliases, so the numeric
//! backend (and the scalar type) can change in one file.

pub type Real = f64;
pub type Vec2 = nalgebra::Vector2<Real>;
pub type Vec3 = nalgebra::Vector3<Real>;
pub type Mat2 = nalgebra::Matrix2<Real>;
pub type Mat3 = nalgebra::Matrix3<Real>;
pub type DMat = nalgebra::DMatrix<Real>;
pub type DVec = nalgebra::DVector<Real>;
/// A complex number (the closed-loop modes of eq. 26).
pub type Complex = nalgebra::Complex<Real>;
/// One axis of a 4th-order chain (position, velocity, acceleration, jerk) and its maps.
pub type Vec4 = nalgebra::Vector4<Real>;
pub type Mat4 = nalgebra::Matrix4<Real>;
/// A chain with its input generator (exact discretisation by one matrix exponential).
pub type Mat8 = nalgebra::SMatrix<Real, 8, 8>;

/// Gravity in m/s^2 (Appendix A).
pub const GRAVITY_MPS2: Real = 9.81;

/// A 3-vector from a plain array (wire and file formats carry arrays).
pub fn vec3(a: [Real; 3]) -> Vec3 {
    Vec3::new(a[0], a[1], a[2])
}

/// A plain array from a 3-vector.
pub fn arr3(v: &Vec3) -> [Real; 3] {
    [v.x, v.y, v.z]
}

/// True when every component is finite.
pub fn all_finite(v: &Vec3) -> bool {
    v.iter().all(|c| c.is_finite())
}

/// Singular values of a 3x3 matrix in ascending order. For `Q` these are the eigenvalues of
/// `U_D = sqrt(Q^T Q)` (polar decomposition, Sec. VI-A).
pub fn singular_values_ascending(m: &Mat3) -> [Real; 3] {
    let sym = m.transpose() * m;
    let eig = nalgebra::SymmetricEigen::new(sym);
    let mut v = [
        eig.eigenvalues[0].max(0.0).sqrt(),
        eig.eigenvalues[1].max(0.0).sqrt(),
        eig.eigenvalues[2].max(0.0).sqrt(),
    ];
    v.sort_by(|a, b| a.total_cmp(b));
    v
}

/// Complex eigenvalues of a real square matrix, block by block: the strongly connected components
/// of its off-diagonal pattern put it, after a permutation, in block-triangular form, whose
/// eigenvalues are those of the diagonal blocks. A component of one index contributes its
/// diagonal entry exactly; larger ones go to [`eigenvalues_complex`]. For the L of an acyclic
/// graph (every component a single follower) this is exact and O(n^2), where the Schur
/// iteration on the whole matrix may not converge (an eigenvalue -1 of multiplicity n).
pub fn eigenvalues_by_components(m: &DMat) -> Option<Vec<(Real, Real)>> {
    let n = m.nrows();
    let mut out = Vec::with_capacity(n);
    for comp in strong_components(m) {
        if let [k] = comp[..] {
            out.push((m[(k, k)], 0.0));
            continue;
        }
        let sub = DMat::from_fn(comp.len(), comp.len(), |i, j| m[(comp[i], comp[j])]);
        out.extend(eigenvalues_complex(&sub)?);
    }
    Some(out)
}

/// Strongly connected components of the graph with an edge i -> j wherever `m[(i, j)] != 0`
/// (i != j); Kosaraju's algorithm without recursion. Each component's indices are sorted.
fn strong_components(m: &DMat) -> Vec<Vec<usize>> {
    let n = m.nrows();
    let edges = |i: usize, transposed: bool| {
        (0..n).filter(move |&j| {
            let v = if transposed { m[(j, i)] } else { m[(i, j)] };
            j != i && v != 0.0
        })
    };
    // 1. Finish order of a depth-first search.
    let mut seen = vec![false; n];
    let mut order = Vec::with_capacity(n);
    for root in 0..n {
        if seen[root] {
            continue;
        }
        seen[root] = true;
        let mut stack = vec![(root, edges(root, false).collect::<Vec<_>>())];
        while let Some((v, next)) = stack.last_mut() {
            match next.pop() {
                Some(w) if !seen[w] => {
                    seen[w] = true;
                    let succ = edges(w, false).collect();
                    stack.push((w, succ));
                }
                Some(_) => {}
                None => {
                    order.push(*v);
                    stack.pop();
                }
            }
        }
    }
    // 2. Components on the transposed graph, in reverse finish order.
    let mut comp_of = vec![usize::MAX; n];
    let mut comps: Vec<Vec<usize>> = Vec::new();
    for &root in order.iter().rev() {
        if comp_of[root] != usize::MAX {
            continue;
        }
        let c = comps.len();
        comp_of[root] = c;
        let mut members = vec![root];
        let mut todo = vec![root];
        while let Some(v) = todo.pop() {
            for w in edges(v, true) {
                if comp_of[w] == usize::MAX {
                    comp_of[w] = c;
                    members.push(w);
                    todo.push(w);
                }
            }
        }
        members.sort_unstable();
        comps.push(members);
    }
    comps
}

/// Complex eigenvalues of a real square matrix (re, im), or `None` when the Schur iteration does
/// not converge within a bounded number of sweeps (never loops forever).
pub fn eigenvalues_complex(m: &DMat) -> Option<Vec<(Real, Real)>> {
    let n = m.nrows();
    if n == 0 {
        return Some(Vec::new());
    }
    let schur = nalgebra::Schur::try_new(m.clone(), 1e-13, 200 * n.max(10))?;
    Some(
        schur
            .complex_eigenvalues()
            .iter()
            .map(|c| (c.re, c.im))
            .collect(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sorted(mut v: Vec<(Real, Real)>) -> Vec<(Real, Real)> {
        v.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
        v
    }

    #[test]
    fn an_acyclic_l_has_its_diagonal_as_spectrum_at_any_size() {
        // L of an acyclic graph: -1 on the diagonal, positive weights below it.
        let n = 300;
        let l = DMat::from_fn(n, n, |i, j| match i.cmp(&j) {
            std::cmp::Ordering::Equal => -1.0,
            std::cmp::Ordering::Greater if i - j <= 3 => 0.3,
            _ => 0.0,
        });
        let ev = eigenvalues_by_components(&l).expect("spectrum");
        assert_eq!(ev.len(), n);
        assert!(ev.iter().all(|&e| e == (-1.0, 0.0)), "{ev:?}");
    }

    #[test]
    fn components_with_cycles_match_the_whole_matrix() {
        // Indices 0 <-> 2 form a cycle, 1 hangs below it, 3 <-> 4 another cycle below 1.
        let mut m = DMat::zeros(5, 5);
        for (i, j, v) in [
            (0, 0, -1.0),
            (0, 2, 0.4),
            (2, 2, -1.0),
            (2, 0, 0.7),
            (1, 1, -2.0),
            (1, 0, 0.5),
            (3, 3, -1.5),
            (3, 4, 0.9),
            (4, 4, -0.5),
            (4, 3, -0.8),
            (3, 1, 0.2),
        ] {
            m[(i, j)] = v;
        }
        let by_parts = sorted(eigenvalues_by_components(&m).expect("spectrum"));
        let whole = sorted(eigenvalues_complex(&m).expect("spectrum"));
        assert_eq!(by_parts.len(), 5);
        for (a, b) in by_parts.iter().zip(&whole) {
            assert!(
                (a.0 - b.0).abs() < 1e-9 && (a.1 - b.1).abs() < 1e-9,
                "{by_parts:?} vs {whole:?}"
            );
        }
        let comps = strong_components(&m);
        assert_eq!(comps.len(), 3, "{comps:?}");
    }
}
