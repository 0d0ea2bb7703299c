//! The disturbance Kalman filter and fixed-lag smoother of the 3x3 model
//! ([`crate::design::kalman`] with a 3-component force state).
//! [`augmented_plant`] builds the estimator's model, [`design`] the
//! compensator.

use anyhow::{bail, Result};
use nalgebra::DMatrix;

use super::discrete::{DiscreteMatrixModel, PlantStates};
use crate::design::kalman::{shape_states, structured_doubling, wire_shape, ForceShape};
use crate::fit::linalg::eigenvalues;
use crate::numeric::lti::MimoStateSpace;

/// Largest accepted DARE residual relative to its terms ([`design`], step 3):
/// ‖P − Ric(P)‖_F / (‖A P Aᵀ‖_F + ‖A P Cᵀ S⁻¹ C P Aᵀ‖_F + ‖Γ Q Γᵀ‖_F),
/// which a backward-stable solution keeps near machine precision however
/// ill-conditioned the equation (a residual relative to ‖P‖ alone reads
/// the cancellation between the terms as error).
pub const MAX_DARE_RESIDUAL: f64 = 1e-9;

/// The augmented plant of the 3x3 estimator:
/// 1. Augmented state x = [x_p; F_k; F_{k−1}; …; F_{k−N}] (each F a 3-vector,
///    N = max(L + D, M)), with the plant states x_p of
///    [`super::discrete::plant_states`] driven by F_k and the force a random
///    walk F_{k+1} = F_k + w_k, E[w wᵀ] = Q = diag(q_x, q_y, q_z) (N²/sample).
/// 2. Measurement ỹ_k = y_{k−D} = C_p x_p + d F_k + Σ h_m F_{k−m} + v_k,
///    E[v vᵀ] = R = diag(R_x, R_y, R_z) (N²).
#[derive(Clone, Debug)]
pub struct MatrixAugmentedPlant {
    /// State transition (n × n).
    pub a: DMatrix<f64>,
    /// Process-noise input Γ (n × 3): the force increments w.
    pub g: DMatrix<f64>,
    /// Measurement (3 × n).
    pub c: DMatrix<f64>,
    /// Plant states n_p.
    pub n_plant: usize,
    /// Lag of the estimate in the model's time frame: L + D (samples).
    pub lag: usize,
}

impl MatrixAugmentedPlant {
    /// Whether `other` poses the same filter DARE: the same A, Γ and C (the
    /// lag, which only picks the output states, may differ).
    pub fn same_riccati_equation(&self, other: &MatrixAugmentedPlant) -> bool {
        (&self.a, &self.g, &self.c) == (&other.a, &other.g, &other.c)
    }

    /// Index of the first of the three states F_{k−L−D} the compensator outputs.
    pub fn output_index(&self) -> usize {
        self.n_plant + 3 * self.lag
    }
}

/// The augmented plant of `dm` (its poles' part realized as `plant`) for a
/// declared latency of `lag` samples: also the model of an offline
/// smoother of the 3x3 system.
pub fn augmented_plant(dm: &DiscreteMatrixModel, plant: &PlantStates, lag: usize) -> MatrixAugmentedPlant {
    augmented_plant_shaped(dm, plant, lag, [None; 3])
}

/// [`augmented_plant`] with force j band-limited by `shapes[j]`
/// ([`ForceShape`], as [`crate::design::kalman::augmented_plant_shaped`]
/// per force): its random walk u_j drives the shape's all-pole sections,
/// the last section's output is F_k's component j and its second state
/// F_{k−1}'s (the delay line then has at least one stage). The shaping
/// states follow the delay line: the three u_j, then two per force for each
/// section before the last. Without shapes, exactly [`augmented_plant`].
pub fn augmented_plant_shaped(
    dm: &DiscreteMatrixModel,
    plant: &PlantStates,
    lag: usize,
    shapes: [Option<ForceShape>; 3],
) -> MatrixAugmentedPlant {
    let n_plant = plant.a.nrows();
    let model_lag = lag + dm.advance;
    let sections: [Vec<(f64, f64, f64)>; 3] = shapes.map(|s| s.map(|s| s.sections(dm.fs_hz)).unwrap_or_default());
    let shaped = sections.iter().any(|s| !s.is_empty());
    let n_delay = model_lag.max(dm.fir.len()).max(usize::from(shaped));
    let n_shape: usize = sections.iter().map(|s| shape_states(s)).sum();
    let n = n_plant + 3 * (1 + n_delay) + n_shape;
    let f = n_plant;
    let mut a = DMatrix::<f64>::zeros(n, n);
    let mut g = DMatrix::<f64>::zeros(n, 3);
    let mut c = DMatrix::<f64>::zeros(3, n);
    a.view_mut((0, 0), (n_plant, n_plant)).copy_from(&plant.a);
    a.view_mut((0, f), (n_plant, 3)).copy_from(&plant.b);
    c.view_mut((0, 0), (3, n_plant)).copy_from(&plant.c);
    let mut next = f + 3 * (1 + n_delay);
    for k in 0..3 {
        for j in 1..=n_delay {
            a[(f + 3 * j + k, f + 3 * (j - 1) + k)] = 1.0;
        }
        let secs = &sections[k];
        if secs.is_empty() {
            a[(f + k, f + k)] = 1.0;
            g[(f + k, k)] = 1.0;
            continue;
        }
        let u = next;
        next += shape_states(secs);
        g[(u, k)] = 1.0;
        wire_shape(&mut a, secs, u, f + k, f + 3 + k);
    }
    for i in 0..3 {
        for k in 0..3 {
            c[(i, f + k)] = dm.d[(i, k)];
            for (m, h) in dm.fir.iter().enumerate() {
                c[(i, f + 3 * (m + 1) + k)] = h[(i, k)];
            }
        }
    }
    MatrixAugmentedPlant { a, g, c, n_plant, lag: model_lag }
}

/// The filter DARE of a 3x3 augmented plant, solved and checked
/// ([`design`], step 3): the prior covariance P, the innovation covariance
/// S = C P Cᵀ + R and its inverse, the residual relative to the equation's
/// terms and the doubling steps.
#[derive(Clone, Debug)]
pub struct MatrixDare {
    /// Prior state covariance P (n × n).
    pub p: DMatrix<f64>,
    /// Innovation covariance S = C P Cᵀ + R (3 × 3), symmetrized.
    pub s: DMatrix<f64>,
    /// S⁻¹ (by Cholesky).
    pub s_inv: DMatrix<f64>,
    /// Residual relative to the equation's terms ([`MAX_DARE_RESIDUAL`]).
    pub residual: f64,
    /// Doubling steps.
    pub iterations: usize,
}

/// Solve the filter DARE P = A P Aᵀ − A P Cᵀ (C P Cᵀ + R)⁻¹ C P Aᵀ + Γ Q Γᵀ
/// of `plant` for Q = diag(`q`) (N²/sample) and R = diag(`r`) (N²) by
/// structured doubling with G = Cᵀ R⁻¹ C, and check it: S positive
/// definite and the residual, judged against the size of the equation's
/// terms, at most [`MAX_DARE_RESIDUAL`]. The doubling alone: the designs
/// use [`solve_dare_refined`].
pub fn solve_dare(plant: &MatrixAugmentedPlant, q: [f64; 3], r: [f64; 3]) -> Result<MatrixDare> {
    solve_dare_with(plant, q, r, false)
}

/// [`solve_dare`] with Newton steps where the doubling's residual is over
/// the limit ([`newton_polish`]). The box's compensator ([`design`]), its q
/// search and the offline smoother ([`crate::offline::matrix_smoother`])
/// all solve with it: on the plate's set-ups the doubling's rounding leaves
/// 4e-9 to 6e-8 of the terms at large q, and a q search that left those q
/// out stopped decades short of its best (BENCHMARKS.md, "The q search").
pub fn solve_dare_refined(plant: &MatrixAugmentedPlant, q: [f64; 3], r: [f64; 3]) -> Result<MatrixDare> {
    solve_dare_with(plant, q, r, true)
}

fn solve_dare_with(plant: &MatrixAugmentedPlant, q: [f64; 3], r: [f64; 3], refine: bool) -> Result<MatrixDare> {
    for (k, (qk, rk)) in q.iter().zip(&r).enumerate() {
        if !(*rk > 0.0 && rk.is_finite()) {
            bail!("measurement noise variance R of channel {k} must be positive and finite, got {rk}");
        }
        if !(*qk > 0.0 && qk.is_finite()) {
            bail!("process noise intensity q of force {k} must be positive and finite, got {qk}");
        }
    }
    let (a, c, g) = (&plant.a, &plant.c, &plant.g);
    let q_m = g * DMatrix::from_diagonal(&nalgebra::DVector::from_column_slice(&q)) * g.transpose();
    let r_inv = DMatrix::from_diagonal(&nalgebra::DVector::from_iterator(3, r.iter().map(|v| 1.0 / v)));
    let (p, iterations) = structured_doubling(a.transpose(), c.transpose() * r_inv * c, q_m.clone())?;
    let mut terms = riccati_terms(plant, &q_m, r, p)?;
    let mut polished = "";
    if refine && !(terms.residual <= MAX_DARE_RESIDUAL) {
        terms = newton_polish(plant, &q_m, r, terms)?;
        polished = " and Newton refinement";
    }
    let RiccatiTerms { p, s, s_inv, residual, .. } = terms;
    if !(residual <= MAX_DARE_RESIDUAL) {
        bail!(
            "3x3 Riccati solution rejected: residual {residual:.2e} of its terms after {iterations} doubling \
             steps{polished} (needs ≤ {MAX_DARE_RESIDUAL:.0e})"
        );
    }
    Ok(MatrixDare { p, s, s_inv, residual, iterations })
}

/// A candidate solution P of the filter DARE with its innovation
/// covariance S = C P Cᵀ + R, S⁻¹, Ric(P), the predictor gain
/// K̄ = A P Cᵀ S⁻¹ and the residual ‖P − Ric(P)‖_F relative to the terms
/// of Ric ([`MAX_DARE_RESIDUAL`]).
struct RiccatiTerms {
    p: DMatrix<f64>,
    s: DMatrix<f64>,
    s_inv: DMatrix<f64>,
    ric: DMatrix<f64>,
    kbar: DMatrix<f64>,
    residual: f64,
}

fn riccati_terms(
    plant: &MatrixAugmentedPlant,
    q_m: &DMatrix<f64>,
    r: [f64; 3],
    p: DMatrix<f64>,
) -> Result<RiccatiTerms> {
    let (a, c) = (&plant.a, &plant.c);
    let s = c * &p * c.transpose() + DMatrix::from_diagonal(&nalgebra::DVector::from_column_slice(&r));
    let s = (&s + s.transpose()) * 0.5;
    let Some(chol) = s.clone().cholesky() else {
        bail!("3x3 Kalman filter: the innovation covariance C P Cᵀ + R is not positive definite");
    };
    let s_inv = chol.inverse();
    let apa = a * &p * a.transpose();
    let apc = a * &p * c.transpose();
    let gain_term = &apc * &s_inv * apc.transpose();
    let ric = &apa - &gain_term + q_m;
    let scale = apa.norm() + gain_term.norm() + q_m.norm();
    let residual = (&p - &ric).norm() / scale.max(f64::MIN_POSITIVE);
    let kbar = apc * &s_inv;
    Ok(RiccatiTerms { p, s, s_inv, ric, kbar, residual })
}

/// Newton's method (defect correction) on a DARE solution whose residual
/// is over the limit, as the per-axis solver does
/// ([`crate::design::kalman::solve_filter_dare`]): with Acl = A − K̄ C,
/// Ric(P + X) ≈ Ric(P) + Acl X Aclᵀ, so X solves the Stein equation
/// X = Acl X Aclᵀ + (Ric(P) − P); a step is kept only if it lowers the
/// residual. The doubling's rounding grows with the spread of the plant's
/// time scales; the Newton steps work on the residual itself.
fn newton_polish(
    plant: &MatrixAugmentedPlant,
    q_m: &DMatrix<f64>,
    r: [f64; 3],
    mut terms: RiccatiTerms,
) -> Result<RiccatiTerms> {
    for _ in 0..crate::design::kalman::NEWTON_STEPS {
        if terms.residual <= MAX_DARE_RESIDUAL * 1e-3 {
            break;
        }
        let acl = &plant.a - &terms.kbar * &plant.c;
        let Some(x) = crate::numeric::lti::stein_smith(&acl, &terms.ric - &terms.p) else { break };
        let next = &terms.p + x;
        let next = (&next + next.transpose()) * 0.5;
        let Ok(polished) = riccati_terms(plant, q_m, r, next) else { break };
        if !(polished.residual < terms.residual) {
            break;
        }
        terms = polished;
    }
    Ok(terms)
}

/// The 3x3 compensator with its diagnostics.
#[derive(Clone, Debug)]
pub struct MatrixKalman {
    /// Compensator y → F̂[k−L] (3 in, 3 out, f64).
    pub compensator: MimoStateSpace,
    /// Kalman gain K = P Cᵀ S⁻¹ (n × 3).
    pub gain: DMatrix<f64>,
    /// DARE residual relative to its terms ([`MAX_DARE_RESIDUAL`]).
    pub dare_residual: f64,
    /// Doubling steps.
    pub dare_iterations: usize,
    /// Condition number of S = C P Cᵀ + R.
    pub innovation_condition: f64,
    /// Spectral radius of A(I − K C).
    pub closed_loop_radius: f64,
    /// Declared latency L (samples).
    pub lag: usize,
    /// Process noise q per force axis (N²/sample).
    pub q: [f64; 3],
    /// Measurement noise R per channel (N²).
    pub r: [f64; 3],
}

/// Design the compensator of `plant` for process noise `q` and measurement
/// noise `r` on the plant's steps 1-2 ([`MatrixAugmentedPlant`]); `lag` is
/// the declared latency L.
///
/// 3. Filter DARE P = A P Aᵀ − A P Cᵀ (C P Cᵀ + R)⁻¹ C P Aᵀ + Γ Q Γᵀ by
///    structured doubling with G = Cᵀ R⁻¹ C (`structured_doubling`),
///    polished by Newton steps ([`solve_dare_refined`]). Its residual,
///    judged against the size of the equation's terms, must stay below
///    [`MAX_DARE_RESIDUAL`], and the closed loop A(I − K C) must be stable.
/// 4. Compensator from ỹ to F̂[k−L−D] (3 in, 3 out), K = P Cᵀ S⁻¹, S = C P Cᵀ + R:
///    x̂⁻\[k+1\] = A(I − K C) x̂⁻\[k\] + A K ỹ\[k\],
///    F̂\[k−L−D\] = E (I − K C) x̂⁻\[k\] + E K ỹ\[k\],
///    E selecting F_{k−L−D}. Fed with y (D samples earlier than ỹ), it
///    outputs F̂[k−L]: the declared latency is L.
pub fn design(plant: &MatrixAugmentedPlant, q: [f64; 3], r: [f64; 3], lag: usize) -> Result<MatrixKalman> {
    let (a, c) = (&plant.a, &plant.c);
    let n = a.nrows();
    let MatrixDare { p, s, s_inv, residual: dare_residual, iterations } = solve_dare_refined(plant, q, r)?;
    let s_eig = crate::fit::linalg::symmetric_eigenvalues(&s, "the innovation covariance")?;
    let innovation_condition = s_eig.max() / s_eig.min();
    let k = &p * c.transpose() * &s_inv;
    let i_kc = DMatrix::<f64>::identity(n, n) - &k * c;
    let out = plant.output_index();
    let comp =
        MimoStateSpace { a: a * &i_kc, b: a * &k, c: i_kc.rows(out, 3).into_owned(), d: k.rows(out, 3).into_owned() };
    let radius = eigenvalues(&comp.a, "the 3x3 compensator")?.iter().map(|z| z.norm()).fold(0.0, f64::max);
    if !(radius < 1.0) {
        bail!(
            "3x3 Kalman compensator is not stable (spectral radius {radius:.9}); the fitted model may be unobservable"
        );
    }
    Ok(MatrixKalman {
        compensator: comp,
        gain: k,
        dare_residual,
        dare_iterations: iterations,
        innovation_condition,
        closed_loop_radius: radius,
        lag,
        q,
        r,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::design::discretize::{DTerm, DiscreteModel, Discretization};
    use crate::design::kalman::design_shaped;
    use nalgebra::Matrix3;

    /// Three uncoupled axes (one real pole each, different direct terms)
    /// as a 3x3 model and its plant states.
    fn diagonal(fs: f64, poles: [f64; 3], res: [f64; 3], d: [f64; 3]) -> (DiscreteMatrixModel, PlantStates) {
        let dm = DiscreteMatrixModel {
            fs_hz: fs,
            poles: Vec::new(),
            residues: Vec::new(),
            d: Matrix3::from_diagonal(&nalgebra::Vector3::from(d)),
            fir: Vec::new(),
            advance: 0,
        };
        let plant = PlantStates {
            a: DMatrix::from_diagonal(&nalgebra::DVector::from_column_slice(&poles)),
            b: DMatrix::identity(3, 3),
            c: DMatrix::from_diagonal(&nalgebra::DVector::from_column_slice(&res)),
            ranks: vec![1; 3],
            dropped_bound: 0.0,
            error: 0.0,
        };
        (dm, plant)
    }

    /// A DARE solution off by a relative 1e-6 (as doubling on a plant with
    /// widely spread time scales can leave it) is polished by the Newton
    /// steps back to the doubling's solution, within the residual limit.
    /// Negative control: unpolished, its residual is over the limit.
    #[test]
    fn newton_steps_polish_a_dare_solution_over_the_residual_limit() {
        let (dm, plant) = diagonal(25_600.0, [0.999, 0.95, 0.2], [0.2, -0.4, 0.6], [1.0, 2.0, 0.5]);
        let aug = augmented_plant(&dm, &plant, 4);
        let (q, r) = ([1e2, 3e1, 1e3], [0.05, 0.02, 0.1]);
        let exact = solve_dare(&aug, q, r).unwrap();
        let n = exact.p.nrows();
        let bump = DMatrix::from_fn(n, n, |i, j| ((i * 7 + j * 7) % 11) as f64 - 5.0);
        let p = &exact.p + bump * (1e-6 * exact.p.norm() / (n as f64 * 5.0));
        let q_m = &aug.g * DMatrix::from_diagonal(&nalgebra::DVector::from_column_slice(&q)) * aug.g.transpose();
        let off = riccati_terms(&aug, &q_m, r, p).unwrap();
        assert!(
            off.residual > MAX_DARE_RESIDUAL,
            "control: the perturbed P must fail the check ({:.1e})",
            off.residual
        );
        let polished = newton_polish(&aug, &q_m, r, off).unwrap();
        assert!(polished.residual <= MAX_DARE_RESIDUAL, "polished residual {:.1e}", polished.residual);
        let moved = (&polished.p - &exact.p).norm() / exact.p.norm();
        assert!(moved < 1e-9, "the polished P is the DARE's solution: {moved:.1e} from the doubling's");
        // The refined solver gives the doubling's own solution where it passes.
        let refined = solve_dare_refined(&aug, q, r).unwrap();
        assert_eq!(refined.p, exact.p);
    }

    /// On uncoupled axes the shaped 3x3 compensator is the three shaped
    /// per-axis compensators ([`crate::design::kalman::augmented_plant_shaped`],
    /// whose shape wiring it shares; what this checks is the 3x3 layout):
    /// each force's shape on its own axis, a mix of shapes and none, and
    /// nothing off the diagonal. Negative control: the per-axis design without the
    /// shape differs from the shaped 3x3 row above the band.
    #[test]
    fn the_shaped_plant_of_uncoupled_axes_is_the_per_axis_shaped_plant() {
        let fs = 51_200.0;
        let (poles, res, d) = ([0.3, 0.5, 0.1], [0.2, -0.4, 0.6], [1.0, 2.0, 0.5]);
        let shapes = [
            Some(ForceShape { corner_hz: 4_800.0, order: 4 }),
            Some(ForceShape { corner_hz: 6_000.0, order: 2 }),
            None,
        ];
        let (q, r, lag) = ([1e3, 3e2, 1e4], [0.05, 0.02, 0.1], 3);
        let (dm, plant) = diagonal(fs, poles, res, d);
        let m = design(&augmented_plant_shaped(&dm, &plant, lag, shapes), q, r, lag).unwrap().compensator;
        let lines = [300.0, 2_000.0, 4_000.0, 8_000.0, 15_000.0, 24_000.0];
        let hm = m.freq_responses(&lines, fs);
        let per_axis = |i: usize, shape| {
            let dm1 = DiscreteModel {
                fs_hz: fs,
                method: Discretization::Foh,
                terms: vec![DTerm::Real { pole: poles[i], residue: res[i] }],
                d: d[i],
                fir: Vec::new(),
                advance: 0,
            };
            design_shaped(&dm1, q[i], r[i], lag, shape).unwrap().compensator.freq_responses(&lines, fs)
        };
        for i in 0..3 {
            let h1 = per_axis(i, shapes[i]);
            for (k, f) in lines.iter().enumerate() {
                let e = (hm[k][(i, i)] - h1[k]).norm() / h1[k].norm();
                assert!(e < 1e-7, "axis {i} at {f} Hz: 3x3 {} against per axis {}", hm[k][(i, i)], h1[k]);
                for j in (0..3).filter(|&j| j != i) {
                    assert!(hm[k][(i, j)].norm() < 1e-9, "H[{i}][{j}] at {f} Hz = {}", hm[k][(i, j)]);
                }
            }
        }
        let unshaped = per_axis(0, None);
        let moved =
            (3..lines.len()).map(|k| (hm[k][(0, 0)] - unshaped[k]).norm() / unshaped[k].norm()).fold(0.0, f64::max);
        assert!(moved > 0.1, "control: the shape should change the response above the band, moved {moved}");
        // Without shapes the shaped constructor is the random-walk one.
        let (a, b) = (augmented_plant(&dm, &plant, lag), augmented_plant_shaped(&dm, &plant, lag, [None; 3]));
        assert_eq!((a.a, a.g, a.c, a.lag), (b.a, b.g, b.c, b.lag));
    }

    /// The premise of the q search's shortcut ([`crate::design::mimo`]'s
    /// `design_3x3`): where the FIR taps reach past the latency, the box
    /// filter's augmented plant and the offline smoother's (latency 0)
    /// have the same A, Γ and C, so one Riccati equation. Negative control:
    /// one sample more of latency adds a delay stage, and the equations differ.
    #[test]
    fn the_filter_s_equation_is_the_smoother_s_where_the_taps_reach_past_the_latency() {
        let (mut dm, plant) = diagonal(25_600.0, [0.9, 0.5, 0.2], [0.2, -0.4, 0.6], [1.0, 2.0, 0.5]);
        dm.fir = vec![Matrix3::identity() * 0.3; 3];
        dm.advance = 1;
        let smoother = augmented_plant(&dm, &plant, 0);
        let same = |lag: usize| augmented_plant(&dm, &plant, lag).same_riccati_equation(&smoother);
        assert!(same(1) && same(2), "the taps reach past latencies 1 and 2");
        assert!(!same(3), "control: latency 3 has a delay stage more");
    }
}
