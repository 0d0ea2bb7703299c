//! Dense factorizations of nalgebra matrices by faer's blocked kernels:
//! the R of a Householder QR and LU solves.
//! nalgebra stays the crate's matrix type; these borrow its column-major
//! storage and return nalgebra matrices.

use faer::linalg::solvers::Solve;
use faer::{Mat, MatRef};
use nalgebra::DMatrix;

fn view(a: &DMatrix<f64>) -> MatRef<'_, f64> {
    MatRef::from_column_major_slice(a.as_slice(), a.nrows(), a.ncols())
}

fn to_nalgebra(m: MatRef<'_, f64>) -> DMatrix<f64> {
    DMatrix::from_fn(m.nrows(), m.ncols(), |i, j| m[(i, j)])
}

/// The upper-triangular factor R (min(rows, cols) × cols) of A = QR,
/// factored in place: `a` is overwritten (R in its upper triangle,
/// Householder vectors below). Row signs may differ from another QR's;
/// RᵀR = AᵀA either way.
pub fn qr_r_in_place(a: &mut DMatrix<f64>) -> DMatrix<f64> {
    use faer::dyn_stack::{MemBuffer, MemStack};
    use faer::linalg::qr::no_pivoting::factor;
    let (rows, cols) = a.shape();
    let size = rows.min(cols);
    let blocksize = factor::recommended_blocksize::<f64>(rows, cols);
    let mut q_coeff = Mat::<f64>::zeros(blocksize, size);
    let par = faer::Par::Seq;
    let mut mem = MemBuffer::new(factor::qr_in_place_scratch::<f64>(rows, cols, blocksize, par, Default::default()));
    let qr = faer::MatMut::from_column_major_slice_mut(a.as_mut_slice(), rows, cols);
    factor::qr_in_place(qr, q_coeff.as_mut(), par, MemStack::new(&mut mem), Default::default());
    DMatrix::from_fn(size, cols, |i, j| if i <= j { a[(i, j)] } else { 0.0 })
}

/// A square matrix's LU factorization with partial pivoting, for solves
/// with many right-hand sides.
pub struct Lu(faer::linalg::solvers::PartialPivLu<f64>);

impl Lu {
    /// Factor `a`; `None` when U has a zero or non-finite pivot (singular).
    pub fn new(a: &DMatrix<f64>) -> Option<Lu> {
        assert_eq!(a.nrows(), a.ncols(), "LU of a non-square matrix");
        let lu = view(a).partial_piv_lu();
        let u = lu.U();
        (0..u.nrows()).all(|i| u[(i, i)] != 0.0 && u[(i, i)].is_finite()).then_some(Lu(lu))
    }

    /// X with A X = B.
    pub fn solve(&self, b: &DMatrix<f64>) -> DMatrix<f64> {
        to_nalgebra(self.0.solve(view(b)).as_ref())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(rows: usize, cols: usize, seed: u64) -> DMatrix<f64> {
        let mut s = seed;
        DMatrix::from_fn(rows, cols, |_, _| {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        })
    }

    #[test]
    fn qr_r_in_place_is_triangular_and_reproduces_the_gram_matrix() {
        let a = sample(300, 20, 1);
        let r = qr_r_in_place(&mut a.clone());
        assert_eq!((r.nrows(), r.ncols()), (20, 20));
        assert!((0..20).all(|j| (j + 1..20).all(|i| r[(i, j)] == 0.0)));
        let gram = a.transpose() * &a;
        let err = (r.transpose() * &r - &gram).norm() / gram.norm();
        assert!(err < 1e-13, "RᵀR against AᵀA: {err:e}");
        // Control: the R of another matrix does not reproduce it.
        let other = qr_r_in_place(&mut sample(300, 20, 2));
        assert!((other.transpose() * &other - &gram).norm() / gram.norm() > 0.1);
    }

    #[test]
    fn lu_solves_many_right_hand_sides_and_refuses_a_singular_matrix() {
        let a = sample(50, 50, 5) + DMatrix::identity(50, 50) * 3.0;
        let b = sample(50, 30, 6);
        let x = Lu::new(&a).expect("regular").solve(&b);
        assert!((&a * &x - &b).norm() < 1e-12 * b.norm());
        let mut singular = a.clone();
        singular.column_mut(7).fill(0.0);
        assert!(Lu::new(&singular).is_none(), "a zero column is singular");
    }
}
