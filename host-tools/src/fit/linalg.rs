//! Iterative decompositions of the fits with an iteration limit.
//!
//! nalgebra's `complex_eigenvalues`, `svd`, `singular_values` and
//! `Schur::new` iterate until convergence with no limit (`max_niter = 0`):
//! its real Schur iteration has no exceptional shift, and a companion
//! matrix can make it cycle for ever. Every eigenvalue and singular-value
//! computation of the fits goes through this module instead: each has a
//! limit of [`sweeps`] iterations (LAPACK's `dlahqr` allows 30·max(10, n)),
//! falls back once to an equivalent problem that converges differently
//! (a balanced matrix, then the complex Schur form), and reports
//! non-convergence as an error that names what did not converge.

use anyhow::{bail, Result};
use nalgebra::{DMatrix, DVector, Schur, SymmetricEigen, SVD};
use num_complex::Complex64;

/// Iteration limit of one decomposition of an n×n (or n-column) matrix:
/// 30·max(10, n) sweeps in total, as LAPACK's `dlahqr`.
pub fn sweeps(n: usize) -> usize {
    30 * n.max(10)
}

/// Convergence tolerance of the SVD: nalgebra's own for `svd` and
/// `singular_values` (5·ε), so a converged result is the same to the bit.
const SVD_EPS: f64 = 5.0 * f64::EPSILON;

/// The first non-finite entry of `m`, as (row, column), if any.
fn non_finite(m: &DMatrix<f64>) -> Option<(usize, usize)> {
    let k = m.iter().position(|v| !v.is_finite())?;
    Some((k % m.nrows(), k / m.nrows()))
}

/// Eigenvalues of the real square matrix `m`; `what` names the matrix in
/// errors (e.g. "the companion matrix of the 8:10 RFP denominator").
///
/// The real Schur form first (the same numbers as nalgebra's
/// `complex_eigenvalues` where that converges), then, if it does not
/// converge within [`sweeps`], the real Schur form of the Parlett–Reinsch
/// balanced matrix (a diagonal similarity by powers of 2: same
/// eigenvalues), then the complex Schur form, whose complex shifts break
/// the cycles of the real iteration. An error if all three fail, or if `m`
/// has a non-finite entry.
pub fn eigenvalues(m: &DMatrix<f64>, what: &str) -> Result<Vec<Complex64>> {
    let n = m.nrows();
    if n != m.ncols() {
        bail!("{what}: eigenvalues of a {n}×{} matrix, which is not square", m.ncols());
    }
    if let Some((i, j)) = non_finite(m) {
        bail!("{what}: entry ({i}, {j}) is {}, eigenvalues undefined", m[(i, j)]);
    }
    let eps = f64::EPSILON;
    if let Some(s) = Schur::try_new(m.clone(), eps, sweeps(n)) {
        return Ok(s.complex_eigenvalues().iter().copied().collect());
    }
    let mut balanced = m.clone();
    nalgebra::linalg::balancing::balance_parlett_reinsch(&mut balanced);
    if let Some(s) = Schur::try_new(balanced, eps, sweeps(n)) {
        return Ok(s.complex_eigenvalues().iter().copied().collect());
    }
    let complex = m.map(|v| Complex64::new(v, 0.0));
    if let Some(s) = Schur::try_new(complex, eps, sweeps(n)) {
        let (_, t) = s.unpack();
        return Ok(t.diagonal().iter().copied().collect());
    }
    bail!(
        "{what}: the eigenvalue iteration (Schur) of the {n}×{n} matrix did not converge within {} sweeps, \
         balanced or in complex arithmetic",
        sweeps(n)
    )
}

/// Roots of the polynomial with ascending real coefficients `a` (a_n ≠ 0),
/// as the eigenvalues of its companion matrix ([`eigenvalues`]); `what`
/// names the polynomial in errors.
pub fn poly_roots(a: &[f64], what: &str) -> Result<Vec<Complex64>> {
    let Some(n) = a.len().checked_sub(1) else {
        return Ok(Vec::new());
    };
    if n == 0 {
        return Ok(Vec::new());
    }
    let lead = a[n];
    if !(lead != 0.0 && lead.is_finite()) {
        bail!("{what}: leading coefficient {lead}, roots undefined");
    }
    let m = DMatrix::<f64>::from_fn(n, n, |i, j| {
        if i == 0 {
            -a[n - 1 - j] / lead
        } else if i == j + 1 {
            1.0
        } else {
            0.0
        }
    });
    eigenvalues(&m, &format!("{what} (companion matrix)"))
}

/// Singular value decomposition of `m` with U and V, at most [`sweeps`]
/// of its column count; `what` names the matrix in errors. The same
/// decomposition as nalgebra's `svd(true, true)` where that converges.
pub fn svd(m: DMatrix<f64>, what: &str) -> Result<SVD<f64, nalgebra::Dyn, nalgebra::Dyn>> {
    let (rows, cols) = m.shape();
    if rows == 0 || cols == 0 {
        bail!("{what}: singular values of an empty {rows}×{cols} matrix");
    }
    if let Some((i, j)) = non_finite(&m) {
        bail!("{what}: entry ({i}, {j}) is {}, singular values undefined", m[(i, j)]);
    }
    let limit = sweeps(rows.min(cols));
    let Some(first) = SVD::try_new(m.clone(), true, true, SVD_EPS, limit) else {
        bail!("{what}: the singular value iteration (SVD) of the {rows}×{cols} matrix did not converge within {limit} sweeps")
    };
    checked_svd(first, &m, what)
}

/// `first`, an SVD of `m`, where its factors rebuild `m` to
/// [`SVD_RECONSTRUCTION_TOL`]; else faer's thin SVD of `m`, checked the
/// same way. nalgebra's SVD loses accuracy with small nonzero singular
/// values (dimforge/nalgebra#1172).
pub fn checked_svd(
    first: SVD<f64, nalgebra::Dyn, nalgebra::Dyn>,
    m: &DMatrix<f64>,
    what: &str,
) -> Result<SVD<f64, nalgebra::Dyn, nalgebra::Dyn>> {
    if svd_miss(&first, m) <= SVD_RECONSTRUCTION_TOL {
        return Ok(first);
    }
    let (rows, cols) = m.shape();
    let second = faer_svd(m).ok_or_else(|| anyhow::anyhow!("{what}: the SVD of the {rows}×{cols} matrix failed"))?;
    let miss = svd_miss(&second, m);
    if !(miss <= SVD_RECONSTRUCTION_TOL) {
        bail!("{what}: the SVD of the {rows}×{cols} matrix misses it by {miss:.1e} of its norm (limit {SVD_RECONSTRUCTION_TOL:.0e})");
    }
    Ok(second)
}

/// Largest accepted ‖U Σ Vᴴ − M‖_F / ‖M‖_F of a checked SVD ([`svd`],
/// [`checked_svd`], and the 3x3 residues of the plant).
pub const SVD_RECONSTRUCTION_TOL: f64 = 1e-12;

/// ‖U Σ Vᵀ − M‖_F / ‖M‖_F of an SVD of `m` (infinite without U or V).
fn svd_miss(svd: &SVD<f64, nalgebra::Dyn, nalgebra::Dyn>, m: &DMatrix<f64>) -> f64 {
    let (Some(u), Some(v_t)) = (&svd.u, &svd.v_t) else { return f64::INFINITY };
    let rebuilt = u * DMatrix::from_diagonal(&svd.singular_values) * v_t;
    let miss = (rebuilt - m).norm() / m.norm().max(f64::MIN_POSITIVE);
    if miss.is_nan() {
        f64::INFINITY
    } else {
        miss
    }
}

/// faer's thin SVD of `m`, in nalgebra's form.
fn faer_svd(m: &DMatrix<f64>) -> Option<SVD<f64, nalgebra::Dyn, nalgebra::Dyn>> {
    let f = faer::Mat::<f64>::from_fn(m.nrows(), m.ncols(), |i, j| m[(i, j)]);
    let svd = f.thin_svd().ok()?;
    let (u, s, v) = (svd.U(), svd.S().column_vector(), svd.V());
    Some(SVD {
        u: Some(DMatrix::from_fn(u.nrows(), u.ncols(), |i, j| u[(i, j)])),
        v_t: Some(DMatrix::from_fn(v.ncols(), v.nrows(), |i, j| v[(j, i)])),
        singular_values: DVector::from_fn(s.nrows(), |k, _| s[k]),
    })
}

/// Singular values of `m` (descending), as [`svd`] without U and V.
pub fn singular_values(m: &DMatrix<f64>, what: &str) -> Result<DVector<f64>> {
    let (rows, cols) = m.shape();
    if rows == 0 || cols == 0 {
        bail!("{what}: singular values of an empty {rows}×{cols} matrix");
    }
    if let Some((i, j)) = non_finite(m) {
        bail!("{what}: entry ({i}, {j}) is {}, singular values undefined", m[(i, j)]);
    }
    let limit = sweeps(rows.min(cols));
    match SVD::try_new(m.clone(), false, false, SVD_EPS, limit) {
        Some(s) => Ok(s.singular_values),
        None => bail!("{what}: the singular value iteration (SVD) of the {rows}×{cols} matrix did not converge within {limit} sweeps"),
    }
}

/// Eigenvalues of the symmetric matrix `m` (only its lower triangle is
/// read), at most [`sweeps`] iterations; `what` names it in errors (for
/// nalgebra's `symmetric_eigenvalues`, which has no limit).
pub fn symmetric_eigenvalues(m: &DMatrix<f64>, what: &str) -> Result<DVector<f64>> {
    let n = m.nrows();
    if n != m.ncols() {
        bail!("{what}: eigenvalues of a {n}×{} matrix, which is not square", m.ncols());
    }
    if let Some((i, j)) = non_finite(m) {
        bail!("{what}: entry ({i}, {j}) is {}, eigenvalues undefined", m[(i, j)]);
    }
    match SymmetricEigen::try_new(m.clone(), f64::EPSILON, sweeps(n)) {
        Some(e) => Ok(e.eigenvalues),
        None => bail!(
            "{what}: the symmetric eigenvalue iteration of the {n}×{n} matrix did not converge within {} sweeps",
            sweeps(n)
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 3x3 matrix of singular values 0.5 and two small ones (found among
    /// random ones built from them: about one in 350 is missed this way,
    /// dimforge/nalgebra#1172): [`svd`]'s factors rebuild it to rounding
    /// and are orthonormal. The control: nalgebra's SVD alone misses it
    /// by 2.6e-4, so the check is what catches it.
    #[test]
    fn an_svd_that_misses_its_matrix_is_replaced() {
        let m = DMatrix::from_column_slice(
            3,
            3,
            &[
                0.31086093980226964,
                0.2758313304630396,
                0.041296096708988046,
                0.13311319695174165,
                0.11812651830731134,
                0.0176916435542775,
                0.1556885275747328,
                0.13762982350347078,
                0.020262143024400374,
            ],
        );
        let plain = SVD::try_new(m.clone(), true, true, SVD_EPS, sweeps(3)).unwrap();
        assert!(svd_miss(&plain, &m) > 1e-8, "control: nalgebra's SVD rebuilt it to {:.1e}", svd_miss(&plain, &m));
        let checked = svd(m.clone(), "test").unwrap();
        assert!(svd_miss(&checked, &m) < 1e-14, "{:.1e}", svd_miss(&checked, &m));
        let (u, v_t) = (checked.u.unwrap(), checked.v_t.unwrap());
        assert!((u.transpose() * &u - DMatrix::identity(3, 3)).norm() < 1e-14);
        assert!((&v_t * v_t.transpose() - DMatrix::identity(3, 3)).norm() < 1e-14);
        // Where nalgebra's SVD rebuilds its matrix, it is kept as it is.
        let well = DMatrix::from_row_slice(3, 3, &[2.0, 0.3, -0.1, 0.3, 1.0, 0.2, -0.1, 0.2, 0.5]);
        let own = well.clone().svd(true, true);
        let kept = checked_svd(own.clone(), &well, "test").unwrap();
        assert_eq!(kept.singular_values, own.singular_values);
        assert_eq!(kept.u, own.u);
    }
}
