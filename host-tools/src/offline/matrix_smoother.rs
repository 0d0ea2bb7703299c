//! Offline zero-lag estimation with the 3x3 model (`dynocomp compensate
//! --offline` on a 3x3 image, format 3): the fixed-interval smoother of the
//! 3x3 design's own model ([`MatrixSmoother`]), with a 3-component force
//! state, so the crosstalk is compensated as on the box but without its
//! latency. Rows the design chose per axis are smoothed per axis
//! ([`crate::offline::smoother`]), as the image runs them. **Offline only**:
//! every estimate uses the whole record. f64 throughout.

use anyhow::{bail, Context, Result};
use nalgebra::{DMatrix, DVector, Matrix3};
use serde::{Deserialize, Serialize};

use dynocomp_core::image::{MatrixImage, RowDesign};

use crate::design::kalman::ForceShape;
use crate::design::mimo::discrete::{DiscreteMatrixModel, PlantStates};
use crate::design::mimo::kalman::{augmented_plant_shaped, solve_dare, MatrixAugmentedPlant};
use crate::design::mimo::MatrixDesign;
use crate::fit::linalg::eigenvalues;
use crate::frf::axis_name;
use crate::io::signal_csv::SignalRecord;
use crate::offline::sidecar::ModelSidecar;
use crate::offline::smoother::smoother_for;

/// Largest plant order a sidecar may hold: the 3x3 fit's highest order
/// ([`crate::design::mimo::MATRIX_MAX_ORDER`]) times its three inputs, with
/// room to spare. A larger one is refused before anything is allocated.
pub const MAX_PLANT_STATES: usize = 256;

/// The 3x3 model of a 3x3 image in its sidecar: the discrete model's plant
/// states, direct term, FIR taps and advance
/// ([`crate::design::mimo::discrete`]), q and R of the 3x3 rows and their
/// band-limited force models. Matrices are stored row by row.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MatrixModelJson {
    /// Advance D of the discrete model (samples).
    pub advance: usize,
    /// Plant state transition A (n × n).
    pub plant_a: Vec<Vec<f64>>,
    /// Plant force input B (n × 3).
    pub plant_b: Vec<Vec<f64>>,
    /// Plant output C (3 × n).
    pub plant_c: Vec<Vec<f64>>,
    /// Direct term d (N/N; row: channel, column: force direction).
    pub d: [[f64; 3]; 3],
    /// FIR taps h_1, h_2, … of the discrete model (N/N).
    pub fir: Vec<[[f64; 3]; 3]>,
    /// Process noise q per force axis (N²/sample).
    pub q: [f64; 3],
    /// Measurement noise R per channel (N²).
    pub r: [f64; 3],
    /// The band-limited force model per force axis (`None`: random walk).
    pub force_shape: [Option<ForceShape>; 3],
}

fn rows_of(m: &DMatrix<f64>) -> Vec<Vec<f64>> {
    m.row_iter().map(|r| r.iter().copied().collect()).collect()
}

fn matrix3(m: &Matrix3<f64>) -> [[f64; 3]; 3] {
    std::array::from_fn(|i| std::array::from_fn(|j| m[(i, j)]))
}

impl MatrixModelJson {
    /// The sidecar's 3x3 model of `md`; `None` where the design has no 3x3
    /// Kalman design (every row per axis).
    pub fn of_design(md: &MatrixDesign) -> Option<Self> {
        let ((dm, plant), k) = (md.discrete.as_ref()?, md.kalman.as_ref()?);
        let force_shape = md.summary.kalman.as_ref().map_or([None; 3], |f| f.force_shape);
        Some(MatrixModelJson {
            advance: dm.advance,
            plant_a: rows_of(&plant.a),
            plant_b: rows_of(&plant.b),
            plant_c: rows_of(&plant.c),
            d: matrix3(&dm.d),
            fir: dm.fir.iter().map(matrix3).collect(),
            q: k.q,
            r: k.r,
            force_shape,
        })
    }

    /// The augmented plant of the smoother (latency 0), validated: sizes,
    /// finite values, a stable plant, a short advance and FIR, positive q
    /// and R, force shapes below fs/2. Errors name `source`.
    pub fn plant(&self, fs_hz: f64, source: &str) -> Result<MatrixAugmentedPlant> {
        let bad = |what: &str| anyhow::anyhow!("{source}: the 3x3 model {what}; re-run `dynocomp design`");
        let n = self.plant_a.len();
        if n == 0 || n > MAX_PLANT_STATES {
            return Err(bad(&format!("has {n} plant states (1 to {MAX_PLANT_STATES})")));
        }
        let dense = |rows: &[Vec<f64>], r: usize, c: usize, name: &str| -> Result<DMatrix<f64>> {
            if rows.len() != r || rows.iter().any(|row| row.len() != c) {
                return Err(bad(&format!("matrix {name} is not {r} × {c}")));
            }
            if rows.iter().flatten().any(|v| !v.is_finite()) {
                return Err(bad(&format!("matrix {name} has non-finite values")));
            }
            Ok(DMatrix::from_fn(r, c, |i, j| rows[i][j]))
        };
        let a = dense(&self.plant_a, n, n, "A")?;
        let b = dense(&self.plant_b, n, 3, "B")?;
        let c = dense(&self.plant_c, 3, n, "C")?;
        let finite3 = |m: &[[f64; 3]; 3]| m.iter().flatten().all(|v| v.is_finite());
        if !finite3(&self.d) || !self.fir.iter().all(finite3) {
            return Err(bad("has non-finite direct or FIR terms"));
        }
        if self.advance > 64 || self.fir.len() > 64 {
            return Err(bad(&format!(
                "is too long (advance {}, {} FIR taps; at most 64)",
                self.advance,
                self.fir.len()
            )));
        }
        if !self.q.iter().chain(&self.r).all(|v| *v > 0.0 && v.is_finite()) {
            return Err(bad("has a q or R that is not positive and finite"));
        }
        for s in self.force_shape.iter().flatten() {
            if !(s.corner_hz > 0.0 && s.corner_hz < fs_hz / 2.0 && matches!(s.order, 2 | 4)) {
                return Err(bad(&format!(
                    "has a force shape (corner {} Hz, order {}) not valid at {fs_hz} Hz",
                    s.corner_hz, s.order
                )));
            }
        }
        let eig = eigenvalues(&a, "its plant").map_err(|e| bad(&format!("cannot be checked ({e})")))?;
        let radius = eig.iter().map(|z| z.norm()).fold(0.0, f64::max);
        if !(radius < 1.0) {
            return Err(bad(&format!("is not stable (spectral radius {radius:.6})")));
        }
        let to3 = |m: &[[f64; 3]; 3]| Matrix3::from_fn(|i, j| m[i][j]);
        // The poles and residues are not stored: the plant states realize
        // them, and the augmented plant reads only fs, d, the FIR and D.
        let dm = DiscreteMatrixModel {
            fs_hz,
            poles: Vec::new(),
            residues: Vec::new(),
            d: to3(&self.d),
            fir: self.fir.iter().map(to3).collect(),
            advance: self.advance,
        };
        let plant = PlantStates { a, b, c, ranks: Vec::new(), dropped_bound: 0.0, error: 0.0 };
        Ok(augmented_plant_shaped(&dm, &plant, 0, self.force_shape))
    }
}

/// The model sidecar of the 3x3 image `image` of `md`: the per-axis
/// models of the rows the image runs per axis, and the 3x3 model.
pub fn matrix_sidecar(image: &MatrixImage, md: &MatrixDesign) -> ModelSidecar {
    let per_axis: Vec<_> = (0..3)
        .filter(|i| image.rows[*i] == RowDesign::PerAxis)
        .filter_map(|i| md.per_axis.get(i).cloned().flatten())
        .collect();
    let mut sidecar = ModelSidecar::of_designs(image, &per_axis);
    sidecar.matrix = MatrixModelJson::of_design(md);
    sidecar
}

/// The steady-state fixed-interval smoother of the 3x3 system.
///
/// **Model.** The 3x3 design's augmented plant at latency 0
/// ([`crate::design::mimo::kalman::MatrixAugmentedPlant`]): plant states
/// driven by the 3-component force F_k, each component a random walk of
/// intensity q_j (through its band-limiting low-pass where the design has
/// one), measurement ỹ_k = y_{k−D} = C x_k + v_k, E[v vᵀ] = diag(R), with q
/// and R the design's. The record runs as ỹ (D samples of y_0 in front).
///
/// **Smoother.** [`crate::offline::smoother::Smoother`] with a vector
/// measurement: steady-state Kalman filter forward, modified
/// Bryson–Frazier backward (Bierman 1977). With P the prior covariance of
/// the filter DARE ([`solve_dare`], residual-checked), S = C P Cᵀ + R,
/// K = P Cᵀ S⁻¹:
///
/// ```text
/// forward:   e_k = ỹ_k − C x⁻_k,   x⁻_{k+1} = A (x⁻_k + K e_k),   x⁻_0 = 0
/// backward:  λ̂_{N−1} = 0
///            λ̃_k = λ̂_k − Cᵀ (S⁻¹ e_k + Kᵀ λ̂_k),   F̂_k|N = E x⁻_k − E P λ̃_k,
///            λ̂_{k−1} = Aᵀ λ̃_k
/// ```
///
/// E selects F_k. The backward recursion runs through (A (I − K C))ᵀ,
/// whose spectral radius is checked < 1.
#[derive(Clone, Debug)]
pub struct MatrixSmoother {
    a: DMatrix<f64>,
    c: DMatrix<f64>,
    k: DMatrix<f64>,
    s_inv: DMatrix<f64>,
    /// E P (3 × n): the backward pass's output map.
    ep: DMatrix<f64>,
    /// Index of F_k's first component in the state.
    force: usize,
    /// Advance D of the discrete model (samples).
    advance: usize,
    /// DARE residual relative to its terms.
    pub dare_residual: f64,
    /// Spectral radius of A(I − K C).
    pub closed_loop_radius: f64,
}

impl MatrixSmoother {
    /// The smoother of `plant` (latency 0) for process noise `q` (N²/sample)
    /// and measurement noise `r` (N²), the discrete model advanced by
    /// `advance` samples.
    pub fn new(plant: &MatrixAugmentedPlant, q: [f64; 3], r: [f64; 3], advance: usize) -> Result<Self> {
        let dare = solve_dare(plant, q, r)?;
        let (a, c) = (&plant.a, &plant.c);
        let n = a.nrows();
        let k = &dare.p * c.transpose() * &dare.s_inv;
        let closed = a * (DMatrix::<f64>::identity(n, n) - &k * c);
        let radius =
            eigenvalues(&closed, "the 3x3 smoother's closed loop")?.iter().map(|z| z.norm()).fold(0.0, f64::max);
        if !(radius < 1.0) {
            bail!("3x3 smoother: the filter's closed loop is not stable (spectral radius {radius:.9}); the model may be unobservable");
        }
        let force = plant.n_plant;
        let ep = dare.p.rows(force, 3).into_owned();
        Ok(MatrixSmoother {
            a: a.clone(),
            c: c.clone(),
            k,
            s_inv: dare.s_inv,
            ep,
            force,
            advance,
            dare_residual: dare.residual,
            closed_loop_radius: radius,
        })
    }

    /// Smoothed forces F̂_k|N (N) for every sample of the channels `y` (N,
    /// equal lengths). Memory: 48 bytes per sample (each sample's prior
    /// force and innovation, all the backward pass needs).
    pub fn smooth(&self, y: [&[f64]; 3]) -> [Vec<f64>; 3] {
        let len = y[0].len();
        let d = if len == 0 { 0 } else { self.advance };
        let n = self.a.nrows();
        let (mut x, mut next) = (DVector::<f64>::zeros(n), DVector::<f64>::zeros(n));
        let mut kept: Vec<[f64; 6]> = Vec::with_capacity(len + d);
        let mut cx = DVector::<f64>::zeros(3);
        for t in 0..len + d {
            let yk = |i: usize| y[i][t.saturating_sub(d)];
            self.c.mul_to(&x, &mut cx);
            let e = [yk(0) - cx[0], yk(1) - cx[1], yk(2) - cx[2]];
            kept.push([x[self.force], x[self.force + 1], x[self.force + 2], e[0], e[1], e[2]]);
            x.gemv(1.0, &self.k, &DVector::from_column_slice(&e), 1.0);
            self.a.mul_to(&x, &mut next);
            std::mem::swap(&mut x, &mut next);
        }
        let mut lambda = DVector::<f64>::zeros(n);
        let mut ktl = DVector::<f64>::zeros(3);
        let mut out: [Vec<f64>; 3] = std::array::from_fn(|_| vec![0.0; len + d]);
        for t in (0..len + d).rev() {
            let [f0, f1, f2, e0, e1, e2] = kept[t];
            // w = S⁻¹ e + Kᵀ λ̂;  λ̃ = λ̂ − Cᵀ w
            self.k.tr_mul_to(&lambda, &mut ktl);
            let w = &self.s_inv * DVector::from_column_slice(&[e0, e1, e2]) + &ktl;
            lambda.gemv_tr(-1.0, &self.c, &w, 1.0);
            let epl = &self.ep * &lambda;
            for (i, prior) in [f0, f1, f2].into_iter().enumerate() {
                out[i][t] = prior - epl[i];
            }
            self.a.tr_mul_to(&lambda, &mut next);
            std::mem::swap(&mut lambda, &mut next);
        }
        out.map(|mut v| {
            v.truncate(len);
            v
        })
    }
}

/// `compensate --offline` with a 3x3 image: the record's fx, fy and fz
/// together through the [`MatrixSmoother`] of the sidecar's 3x3 model;
/// each row the image runs per axis smoothed instead with that axis's own
/// model and q, R ([`smoother_for`]), as the box runs it.
pub fn smooth_matrix_record(
    image: &MatrixImage,
    sidecar: &ModelSidecar,
    rec: &SignalRecord,
    source: &str,
) -> Result<SignalRecord> {
    crate::offline::compensate::check_three_channels(rec, source)?;
    let Some(model) = &sidecar.matrix else {
        bail!("{source}: the model sidecar of this 3x3 image holds no 3x3 model (written by an older version); re-run `dynocomp design`");
    };
    for (i, row) in image.rows.iter().enumerate() {
        let s = &image.axes[i].summary;
        if *row == RowDesign::Matrix && (s.q != model.q[i] || s.r != model.r[i]) {
            bail!("{source}: the sidecar's 3x3 model does not hold row {}'s q and R of the image; re-run `dynocomp design`", axis_name(i));
        }
    }
    let fs = f64::from(image.fs_hz);
    let plant = model.plant(fs, source)?;
    let y: [&[f64]; 3] = std::array::from_fn(|i| rec.channels[i].1.as_slice());
    let mut out = MatrixSmoother::new(&plant, model.q, model.r, model.advance)
        .with_context(|| format!("{source}: the 3x3 smoother"))?
        .smooth(y);
    for (i, row) in image.rows.iter().enumerate() {
        if *row == RowDesign::PerAxis {
            let s = &image.axes[i].summary;
            out[i] = smoother_for(sidecar, i, s.q, s.r, source)?.smooth(y[i]);
        }
    }
    let mut channels = Vec::with_capacity(3);
    for (i, v) in out.into_iter().enumerate() {
        if let Some(k) = v.iter().position(|x| !x.is_finite()) {
            bail!("{source}: smoothed f{} became non-finite at sample {k}", axis_name(i));
        }
        channels.push((i, v));
    }
    Ok(SignalRecord { t_s: rec.t_s.clone(), channels })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::design::discretize::{DTerm, DiscreteModel, Discretization};
    use crate::offline::smoother::Smoother;

    const FS: f64 = 25_600.0;

    /// A 3x3 model of one real pole per force (A = diag(poles), B = I) whose
    /// channels see the forces through `c` and the direct term `d`, advanced
    /// by `advance` with one FIR tap `h`.
    fn model(poles: [f64; 3], c: [[f64; 3]; 3], d: [[f64; 3]; 3], h: [[f64; 3]; 3], advance: usize) -> MatrixModelJson {
        MatrixModelJson {
            advance,
            plant_a: (0..3).map(|i| (0..3).map(|j| if i == j { poles[i] } else { 0.0 }).collect()).collect(),
            plant_b: (0..3).map(|i| (0..3).map(|j| f64::from(u8::from(i == j))).collect()).collect(),
            plant_c: c.iter().map(|r| r.to_vec()).collect(),
            d,
            fir: vec![h],
            q: [1e2, 3e1, 1e3],
            r: [0.05, 0.02, 0.1],
            force_shape: [None; 3],
        }
    }

    fn diag(v: [f64; 3]) -> [[f64; 3]; 3] {
        std::array::from_fn(|i| std::array::from_fn(|j| if i == j { v[i] } else { 0.0 }))
    }

    /// Deterministic white noise, uniform on ±0.5.
    fn uniform(seed: u64, n: usize) -> Vec<f64> {
        let mut s = seed.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
        (0..n)
            .map(|_| {
                s = s.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
                (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
            })
            .collect()
    }

    /// A deterministic broadband signal (N).
    fn signal(seed: u64, n: usize) -> Vec<f64> {
        let u = uniform(seed, n);
        (0..n).map(|k| 10.0 * (2.0 * std::f64::consts::PI * 300.0 * k as f64 / FS).sin() + u[k]).collect()
    }

    /// On uncoupled axes the 3x3 smoother is the three per-axis smoothers
    /// ([`Smoother`], tested on its own against the truth), with shapes on
    /// two forces, an advance and an FIR tap: what this checks is the vector
    /// measurement's algebra and the 3x3 layout. Negative control: the
    /// per-axis smoother without x's shape differs.
    #[test]
    fn uncoupled_axes_smooth_as_three_per_axis_smoothers() {
        let (poles, res, d, h) = ([0.3, 0.5, 0.1], [0.2, -0.4, 0.6], [1.0, 2.0, 0.5], [0.05, -0.02, 0.1]);
        let mut m = model(poles, diag(res), diag(d), diag(h), 2);
        let shape = ForceShape { corner_hz: 6_000.0, order: 4 };
        m.force_shape = [Some(shape), None, Some(ForceShape { corner_hz: 8_000.0, order: 2 })];
        let plant = m.plant(FS, "test").unwrap();
        let sm = MatrixSmoother::new(&plant, m.q, m.r, m.advance).unwrap();
        let y: Vec<Vec<f64>> = (0..3).map(|i| signal(i as u64, 3000)).collect();
        let out = sm.smooth([&y[0], &y[1], &y[2]]);
        let per_axis = |i: usize, shape| {
            let dm = DiscreteModel {
                fs_hz: FS,
                method: Discretization::Foh,
                terms: vec![DTerm::Real { pole: poles[i], residue: res[i] }],
                d: d[i],
                fir: vec![h[i]],
                advance: 2,
            };
            Smoother::shaped(&dm, m.q[i], m.r[i], shape).unwrap().smooth(&y[i])
        };
        let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
        let diff = |a: &[f64], b: &[f64]| rms(&a.iter().zip(b).map(|(x, y)| x - y).collect::<Vec<_>>()) / rms(b);
        for i in 0..3 {
            let one = per_axis(i, m.force_shape[i]);
            assert_eq!(out[i].len(), y[i].len());
            let e = diff(&out[i], &one);
            assert!(e < 1e-9, "axis {i}: 3x3 against per axis differs by {e:.2e} of its RMS");
        }
        let control = diff(&out[0], &per_axis(0, None));
        assert!(control > 1e-4, "negative control: the shape should matter, differs by {control:.2e}");
    }

    /// Coupled channels: forces simulated through a model with 40-60 %
    /// crosstalk, measured with noise of variance R. The 3x3 smoother
    /// recovers each force to within 0.5 % of its RMS; the per-axis smoothers
    /// of the direct entries (blind to the crosstalk, the negative control)
    /// miss by more than 20 %.
    #[test]
    fn coupled_channels_are_separated_against_the_simulated_force() {
        let poles = [0.6, 0.4, 0.2];
        let c = [[0.3, 0.2, -0.15], [0.25, 0.2, 0.1], [-0.1, 0.2, 0.4]];
        let d = [[1.0, 0.5, 0.4], [0.6, 1.0, -0.5], [0.4, 0.5, 1.0]];
        let mut m = model(poles, c, d, diag([0.0; 3]), 0);
        m.fir.clear();
        m.r = [1e-4; 3];
        m.q = [5.0; 3];
        let n = 4000;
        let f: Vec<Vec<f64>> = (0..3)
            .map(|i| {
                let w = 2.0 * std::f64::consts::PI * (150.0 + 110.0 * i as f64) / FS;
                (0..n).map(|k| 20.0 * (w * k as f64).sin() + 5.0 * (3.1 * w * k as f64).cos()).collect()
            })
            .collect();
        // Noise of standard deviation 0.01 N (variance R = 1e-4 N²).
        let noise: Vec<Vec<f64>> =
            (0..3).map(|i| uniform(10 + i as u64, n).iter().map(|v| 0.0346 * v).collect()).collect();
        let mut x = [0.0; 3];
        let mut y = vec![vec![0.0; n]; 3];
        for k in 0..n {
            for i in 0..3 {
                y[i][k] = (0..3).map(|j| c[i][j] * x[j] + d[i][j] * f[j][k]).sum::<f64>() + noise[i][k];
            }
            for j in 0..3 {
                x[j] = poles[j] * x[j] + f[j][k];
            }
        }
        let plant = m.plant(FS, "test").unwrap();
        let out = MatrixSmoother::new(&plant, m.q, m.r, 0).unwrap().smooth([&y[0], &y[1], &y[2]]);
        let rel = |est: &[f64], t: &[f64]| {
            let s = 200..est.len() - 200;
            let e: f64 = s.clone().map(|k| (est[k] - t[k]).powi(2)).sum();
            let p: f64 = s.map(|k| t[k] * t[k]).sum();
            (e / p).sqrt()
        };
        for i in 0..3 {
            let err = rel(&out[i], &f[i]);
            assert!(err < 0.005, "force {i}: 3x3 smoother off by {:.2} %", 100.0 * err);
            let dm = DiscreteModel {
                fs_hz: FS,
                method: Discretization::Foh,
                terms: vec![DTerm::Real { pole: poles[i], residue: c[i][i] }],
                d: d[i][i],
                fir: Vec::new(),
                advance: 0,
            };
            let blind = Smoother::new(&dm, m.q[i], m.r[i]).unwrap().smooth(&y[i]);
            let blind_err = rel(&blind, &f[i]);
            eprintln!("force {i}: 3x3 {:.3} %, per axis {:.1} %", 100.0 * err, 100.0 * blind_err);
            assert!(blind_err > 0.2, "negative control: force {i} per axis off by only {:.2} %", 100.0 * blind_err);
        }
    }

    /// A sidecar's 3x3 model that is malformed is refused with a message
    /// that names it; a valid one is taken.
    #[test]
    fn malformed_models_are_refused() {
        let good = model([0.3, 0.5, 0.1], diag([0.2; 3]), diag([1.0; 3]), diag([0.0; 3]), 1);
        assert!(good.plant(FS, "s.json").is_ok());
        let cases: Vec<(Box<dyn Fn(&mut MatrixModelJson)>, &str)> = vec![
            (Box::new(|m| m.plant_b.pop().map(|_| ()).unwrap()), "matrix B is not 3 × 3"),
            (Box::new(|m| m.plant_a[0][0] = 1.5), "not stable"),
            (Box::new(|m| m.plant_c[1][2] = f64::INFINITY), "non-finite"),
            (Box::new(|m| m.r[2] = 0.0), "q or R"),
            (Box::new(|m| m.advance = 1000), "too long"),
            (Box::new(|m| m.plant_a.clear()), "0 plant states"),
            (Box::new(|m| m.force_shape[1] = Some(ForceShape { corner_hz: 20_000.0, order: 4 })), "force shape"),
        ];
        for (spoil, what) in cases {
            let mut m = good.clone();
            spoil(&mut m);
            let e = m.plant(FS, "s.json").unwrap_err().to_string();
            assert!(e.starts_with("s.json: the 3x3 model") && e.contains(what), "{what}: {e}");
        }
    }
}
