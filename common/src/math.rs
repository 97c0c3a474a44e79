//! The one place that names nalgebra: every other module uses these aliases, so the numeric
//! backend (and the scalar type) can change in one file.

pub type Real = f64;
pub type Vec2 = nalgebra::Vector2<Real>;
pub type Vec3 = nalgebra::Vector3<Real>;
pub type Mat2 = nalgebra::Matrix2<Real>;
pub type Mat3 = nalgebra::Matrix3<Real>;
pub type DMat = nalgebra::DMatrix<Real>;
pub type DVec = nalgebra::DVector<Real>;

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
