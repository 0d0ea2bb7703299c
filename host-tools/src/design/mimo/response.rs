//! The 3x3 compensator's frequency response for any Kalman gain K on fixed
//! lines, from the augmented plant's resolvent computed once: what the q
//! search ([`super::criterion::choose_q`]) evaluates for every candidate.
//!
//! With Φ = (zI − A)⁻¹ of the augmented plant ([`MatrixAugmentedPlant`]),
//! the compensator of [`super::kalman::design`] (step 4) has
//! H(z) = E(I − KC)(zI − A(I − KC))⁻¹AK + EK. Since
//! zI − A(I − KC) = (zI − A)(I + ΦAKC) and ΦA = zΦ − I, with U = ΦAK:
//!
//! H(z) = E(I − KC)·U·(I + CU)⁻¹ + EK,  CU = z(CΦ)K − CK,  EU = z(EΦ)K − EK,
//!
//! so per line only 3×n by n×3 products and one 3x3 solve, where the direct
//! evaluation ([`MimoStateSpace::freq_responses`]) eliminates an n×n system.
//! [`smoother_responses`] is the same for the offline smoother.

use nalgebra::{DMatrix, Matrix3};
use num_complex::Complex64;

use super::kalman::{MatrixAugmentedPlant, MatrixKalman};
use crate::numeric::lti::left_resolvent;

/// Largest difference between [`PlantResolvent::responses`] and the direct
/// evaluation at the checked lines, relative to 1 + ‖H‖_F: above it the
/// direct evaluation is used on every line.
pub const MAX_SHORTCUT_ERROR: f64 = 1e-9;

/// Lines checked against the direct evaluation per gain: the lowest, the
/// highest and those where |CΦ| and |EΦ| are largest (nearest the plant's
/// poles, where the shortcut loses most).
const CHECKED_LINES: usize = 4;

/// CΦ and EΦ of one augmented plant on fixed lines.
pub struct PlantResolvent {
    /// The lines (Hz).
    f_hz: Vec<f64>,
    /// Sample rate (Hz).
    fs_hz: f64,
    /// z = e^{j·2π·f/fs} per line.
    z: Vec<Complex64>,
    /// Per line CΦ (first 3 rows) and EΦ (last 3), 6 × n.
    rows: Vec<DMatrix<Complex64>>,
    /// Measurement matrix C (3 × n).
    c: DMatrix<f64>,
    /// First of the three output states (E selects them).
    out: usize,
    /// The lines [`Self::responses`] checks.
    checked: Vec<usize>,
}

impl PlantResolvent {
    /// CΦ and EΦ of `plant` on the lines `f_hz` (Hz).
    pub fn new(plant: &MatrixAugmentedPlant, f_hz: &[f64], fs_hz: f64) -> Self {
        let n = plant.a.nrows();
        let out = plant.output_index();
        let sel = DMatrix::from_fn(6, n, |i, j| if i < 3 { plant.c[(i, j)] } else { f64::from(j == out + i - 3) });
        let rows = left_resolvent(&plant.a, &sel, f_hz, fs_hz);
        let z = f_hz.iter().map(|f| Complex64::from_polar(1.0, 2.0 * std::f64::consts::PI * f / fs_hz)).collect();
        let mut by_size: Vec<usize> = (0..f_hz.len()).collect();
        by_size.sort_by(|&a, &b| rows[b].norm().total_cmp(&rows[a].norm()));
        let mut checked = vec![0, f_hz.len().saturating_sub(1)];
        checked.extend(by_size.into_iter().take(CHECKED_LINES - 2));
        checked.sort_unstable();
        checked.dedup();
        checked.retain(|&k| k < f_hz.len());
        PlantResolvent { f_hz: f_hz.to_vec(), fs_hz, z, rows, c: plant.c.clone(), out, checked }
    }

    /// H(z) of `k`'s compensator on every line: the shortcut of the module
    /// docs, checked against the direct evaluation at a few lines; the
    /// direct evaluation on every line where they differ by more than
    /// [`MAX_SHORTCUT_ERROR`].
    pub fn responses(&self, k: &MatrixKalman) -> Vec<DMatrix<Complex64>> {
        let h = self.shortcut(&k.gain);
        let checked: Vec<f64> = self.checked.iter().map(|&i| self.f_hz[i]).collect();
        let direct = k.compensator.freq_responses(&checked, self.fs_hz);
        let agrees = self.checked.iter().zip(&direct).all(|(&i, d)| {
            let diff = (&h[i] - d).norm();
            diff <= MAX_SHORTCUT_ERROR * (1.0 + d.norm())
        });
        if agrees {
            h
        } else {
            k.compensator.freq_responses(&self.f_hz, self.fs_hz)
        }
    }

    /// H(z) of the gain `k` (n × 3) by the module docs' formula; NaN where
    /// I + CU is singular.
    pub fn shortcut(&self, k: &DMatrix<f64>) -> Vec<DMatrix<Complex64>> {
        let ck = to_matrix3(&(&self.c * k));
        let ek = to_matrix3(&k.rows(self.out, 3).into_owned());
        let kc = k.map(|v| Complex64::new(v, 0.0));
        self.rows
            .iter()
            .zip(&self.z)
            .map(|(rows, z)| {
                let phi_k = rows * &kc;
                let cu = Matrix3::from_fn(|i, j| z * phi_k[(i, j)]) - ck;
                let eu = Matrix3::from_fn(|i, j| z * phi_k[(i + 3, j)]) - ek;
                let ret = Matrix3::identity() + cu;
                let h = ret
                    .try_inverse()
                    .map(|inv| (eu - ek * cu) * inv + ek)
                    .unwrap_or_else(|| Matrix3::from_element(Complex64::new(f64::NAN, f64::NAN)));
                DMatrix::from_fn(3, 3, |i, j| h[(i, j)])
            })
            .collect()
    }
}

/// The response (3x3 per line, from ỹ to F̂) of the steady-state
/// fixed-interval smoother of `plant` ([`crate::offline::matrix_smoother`],
/// `compensate --offline`) for process noise Q = diag(`q`) (N²/sample) and
/// measurement noise R = diag(`r`) (N²), on the lines `f_hz` (Hz), its
/// estimate the state at [`MatrixAugmentedPlant::output_index`] (so that
/// [`super::criterion::MatrixCriterion::row_error`] judges it at latency
/// 0, as the box's filter at its own). In steady state the smoother is the
/// non-causal Wiener filter of the model's spectra (Kailath, Sayed &
/// Hassibi, *Linear Estimation*, 2000): with Φ = (zI − A)⁻¹, T_y = CΦΓ and T_F = EΦΓ,
///
/// H(z) = T_F Q T_yᴴ · (T_y Q T_yᴴ + R)⁻¹.
///
/// NaN on a line where zI − A or the bracket is singular (z = 1 for a
/// random-walk force).
pub fn smoother_responses(
    plant: &MatrixAugmentedPlant,
    q: [f64; 3],
    r: [f64; 3],
    f_hz: &[f64],
    fs_hz: f64,
) -> Vec<DMatrix<Complex64>> {
    let n = plant.a.nrows();
    let out = plant.output_index();
    let sel = DMatrix::from_fn(6, n, |i, j| if i < 3 { plant.c[(i, j)] } else { f64::from(j == out + i - 3) });
    let gamma = plant.g.map(|v| Complex64::new(v, 0.0));
    let qm = Matrix3::from_diagonal(&nalgebra::Vector3::from(q.map(|v| Complex64::new(v, 0.0))));
    let rm = Matrix3::from_diagonal(&nalgebra::Vector3::from(r.map(|v| Complex64::new(v, 0.0))));
    left_resolvent(&plant.a, &sel, f_hz, fs_hz)
        .iter()
        .map(|rows| {
            let t = rows * &gamma;
            let ty = Matrix3::from_fn(|i, j| t[(i, j)]);
            let tf = Matrix3::from_fn(|i, j| t[(i + 3, j)]);
            let cross = qm * ty.adjoint();
            let h = (ty * cross + rm)
                .try_inverse()
                .map(|inv| tf * cross * inv)
                .unwrap_or_else(|| Matrix3::from_element(Complex64::new(f64::NAN, f64::NAN)));
            DMatrix::from_fn(3, 3, |i, j| h[(i, j)])
        })
        .collect()
}

/// A real 3×3 matrix as a complex `Matrix3`.
fn to_matrix3(m: &DMatrix<f64>) -> Matrix3<Complex64> {
    Matrix3::from_fn(|i, j| Complex64::new(m[(i, j)], 0.0))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::numeric::lti::MimoStateSpace;

    /// A random stable augmented-plant-like system and gain: the shortcut
    /// equals the direct evaluation of the compensator it stands for (an
    /// independent computation: an n×n elimination per line).
    #[test]
    fn shortcut_matches_the_direct_response() {
        let n = 14;
        let mut seed = 7u64;
        let mut rnd = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64) - 0.5
        };
        let a = DMatrix::from_fn(n, n, |_, _| 0.25 * rnd());
        let c = DMatrix::from_fn(3, n, |_, _| rnd());
        let gain = DMatrix::from_fn(n, 3, |_, _| 0.3 * rnd());
        let plant =
            MatrixAugmentedPlant { a: a.clone(), g: DMatrix::zeros(n, 3), c: c.clone(), n_plant: n - 3, lag: 0 };
        let out = plant.output_index();
        let i_kc = DMatrix::<f64>::identity(n, n) - &gain * &c;
        let comp = MimoStateSpace {
            a: &a * &i_kc,
            b: &a * &gain,
            c: i_kc.rows(out, 3).into_owned(),
            d: gain.rows(out, 3).into_owned(),
        };
        let f: Vec<f64> = (0..40).map(|k| 10.0 + 120.0 * k as f64).collect();
        let res = PlantResolvent::new(&plant, &f, 10240.0);
        let direct = comp.freq_responses(&f, 10240.0);
        let short = res.shortcut(&gain);
        let worst = short.iter().zip(&direct).map(|(s, d)| (s - d).norm() / d.norm()).fold(0.0, f64::max);
        assert!(worst < 1e-12, "shortcut differs from the direct response by {worst:e}");
        // Negative control: the shortcut of another gain is not this response.
        let other = res.shortcut(&(&gain * 1.01));
        let moved = other.iter().zip(&direct).map(|(s, d)| (s - d).norm() / d.norm()).fold(0.0, f64::max);
        assert!(moved > 1e-4, "a 1 % change of K moved the response by only {moved:e}");
    }
}
