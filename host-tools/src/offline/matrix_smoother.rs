//! Offline zero-lag estimation with the 3x3 model (`dynocomp compensate
//! --offline` on a 3x3 image, format 3): the fixed-interval smoother of the
//! 3x3 design's own model ([`MatrixSmoother`]), with a 3-component force
//! state, so the crosstalk is compensated as on the box but without its
//! latency. Rows the design chose per axis are smoothed per axis
//! ([`crate::offline::smoother`]), as the image runs them. **Offline only**:
//! every estimate uses the whole record. f64 throughout.

use anyhow::{bail, Context, Result};
use nalgebra::{DMatrix, DVector};

use dynocomp_core::image::{MatrixImage, RowDesign};

use crate::design::axis::AxisDesign;
use crate::design::mimo::kalman::{solve_dare_refined, MatrixAugmentedPlant};
use crate::design::mimo::MatrixDesign;
use crate::fit::linalg::eigenvalues;
use crate::frf::axis_name;
use crate::io::signal_csv::SignalRecord;
pub use crate::offline::matrix_model::MatrixModelJson;
use crate::offline::sidecar::ModelSidecar;
use crate::offline::smoother::{smoother_for, Smoother, SpilledEstimate, SpilledRun};
use std::path::Path;

/// The model sidecar of the 3x3 image `image` of `md`: the per-axis
/// models of the rows the image runs per axis, and the 3x3 model.
pub fn matrix_sidecar(image: &MatrixImage, md: &MatrixDesign) -> ModelSidecar {
    let per_axis: Vec<&AxisDesign> = (0..3)
        .filter(|i| image.rows[*i] == RowDesign::PerAxis)
        .filter_map(|i| md.per_axis.get(i).and_then(Option::as_ref))
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
/// the filter DARE ([`solve_dare_refined`], residual-checked), S = C P Cᵀ + R,
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
        let dare = solve_dare_refined(plant, q, r)?;
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
    /// force and innovation, all the backward pass needs);
    /// [`SpilledMatrixForward`] is the same computation with those on disk.
    pub fn smooth(&self, y: [&[f64]; 3]) -> [Vec<f64>; 3] {
        let len = y[0].len();
        let d = if len == 0 { 0 } else { self.advance };
        let mut sc = Scratch::new(self.a.nrows());
        let kept: Vec<[f64; 6]> = (0..len + d)
            .map(|t| self.forward_step(&mut sc, std::array::from_fn(|i| y[i][t.saturating_sub(d)])))
            .collect();
        sc.clear();
        let mut out: [Vec<f64>; 3] = std::array::from_fn(|_| vec![0.0; len + d]);
        for t in (0..len + d).rev() {
            let f = self.backward_step(&mut sc, kept[t]);
            (0..3).for_each(|i| out[i][t] = f[i]);
        }
        out.map(|mut v| {
            v.truncate(len);
            v
        })
    }

    /// One forward step ([`MatrixSmoother`]) from the prior x⁻_k in `sc`,
    /// left holding x⁻_{k+1}: returns x⁻_k's force components and the
    /// innovation e_k, all the backward pass needs.
    fn forward_step(&self, sc: &mut Scratch, y: [f64; 3]) -> [f64; 6] {
        self.c.mul_to(&sc.x, &mut sc.three);
        let e = [y[0] - sc.three[0], y[1] - sc.three[1], y[2] - sc.three[2]];
        let f = self.force;
        let kept = [sc.x[f], sc.x[f + 1], sc.x[f + 2], e[0], e[1], e[2]];
        sc.x.gemv(1.0, &self.k, &DVector::from_column_slice(&e), 1.0);
        self.a.mul_to(&sc.x, &mut sc.next);
        std::mem::swap(&mut sc.x, &mut sc.next);
        kept
    }

    /// One backward step ([`MatrixSmoother`]) from λ̂_k in `sc` (its `x`),
    /// left holding λ̂_{k−1}: returns F̂_k|N from what the forward step kept.
    fn backward_step(&self, sc: &mut Scratch, kept: [f64; 6]) -> [f64; 3] {
        let [f0, f1, f2, e0, e1, e2] = kept;
        // w = S⁻¹ e + Kᵀ λ̂;  λ̃ = λ̂ − Cᵀ w
        self.k.tr_mul_to(&sc.x, &mut sc.three);
        let w = &self.s_inv * DVector::from_column_slice(&[e0, e1, e2]) + &sc.three;
        sc.x.gemv_tr(-1.0, &self.c, &w, 1.0);
        let epl = &self.ep * &sc.x;
        let out = [f0 - epl[0], f1 - epl[1], f2 - epl[2]];
        self.a.tr_mul_to(&sc.x, &mut sc.next);
        std::mem::swap(&mut sc.x, &mut sc.next);
        out
    }
}

/// The state vector of a pass (x⁻ forward, λ̂ backward) and scratch.
struct Scratch {
    x: DVector<f64>,
    next: DVector<f64>,
    three: DVector<f64>,
}

impl Scratch {
    fn new(n: usize) -> Self {
        Scratch { x: DVector::zeros(n), next: DVector::zeros(n), three: DVector::zeros(3) }
    }

    fn clear(&mut self) {
        self.x.fill(0.0);
    }
}

/// The [`MatrixSmoother`] over a record of any length: the forward pass
/// takes the record block by block and writes each sample's prior force
/// and innovation (48 bytes) to an unnamed temporary file; the backward pass
/// reads it from its end in chunks and writes each force's estimates in
/// their places to a file of its own, which [`SpilledEstimate`] reads
/// forward. Same steps, same bits as [`MatrixSmoother::smooth`]; memory
/// independent of the record's length.
pub struct SpilledMatrixForward<'s> {
    sm: &'s MatrixSmoother,
    sc: Scratch,
    spill: std::io::BufWriter<std::fs::File>,
    /// Samples of y taken.
    n_y: u64,
    /// Samples of ỹ run (n_y + D once y has begun).
    n_run: u64,
}

impl<'s> SpilledMatrixForward<'s> {
    /// Start the forward pass; the temporary files go to `dir`.
    pub fn new(sm: &'s MatrixSmoother, dir: &Path) -> Result<Self> {
        let file = tempfile::tempfile_in(dir).with_context(|| {
            format!("{}: cannot create a temporary file for the 3x3 smoother's forward pass", dir.display())
        })?;
        Ok(SpilledMatrixForward {
            sm,
            sc: Scratch::new(sm.a.nrows()),
            spill: std::io::BufWriter::with_capacity(1 << 20, file),
            n_y: 0,
            n_run: 0,
        })
    }

    /// Take the next samples of fx, fy and fz (N, equal lengths).
    pub fn push(&mut self, y: [&[f64]; 3]) -> Result<()> {
        use std::io::Write;
        let len = y[0].len();
        let d = if self.n_y == 0 && len > 0 { self.sm.advance } else { 0 };
        for t in 0..len + d {
            let kept = self.sm.forward_step(&mut self.sc, std::array::from_fn(|i| y[i][t.saturating_sub(d)]));
            for v in kept {
                self.spill.write_all(&v.to_le_bytes())?;
            }
        }
        self.n_y += len as u64;
        self.n_run += (len + d) as u64;
        Ok(())
    }

    /// The backward pass: the estimates F̂_k|N of fx, fy and fz for every
    /// sample taken, each in a temporary file in `dir`. `on_chunk` is told
    /// the samples done. Refuses a non-finite estimate, naming the force
    /// and the sample.
    pub fn backward(self, dir: &Path, source: &str, on_chunk: &dyn Fn(u64)) -> Result<[SpilledEstimate; 3]> {
        let spill = self.spill.into_inner().map_err(|e| e.into_error());
        let mut sc = Scratch::new(self.sm.a.nrows());
        let run = SpilledRun { n_run: self.n_run, n_y: self.n_y, dir, what: "the 3x3 smoother", source };
        run.backward(spill, &|i| format!("f{}", axis_name(i)), on_chunk, |kept: [f64; 6]| {
            self.sm.backward_step(&mut sc, kept)
        })
    }
}

/// The model checks of `compensate --offline` on a 3x3 image: the record's
/// channels, the sidecar's 3x3 model and its agreement with the image.
fn checked_model<'a>(
    image: &MatrixImage,
    sidecar: &'a ModelSidecar,
    axes: &[usize],
    source: &str,
) -> Result<&'a MatrixModelJson> {
    crate::offline::compensate::check_three(axes, source)?;
    let Some(model) = &sidecar.matrix else {
        bail!("{source}: the model sidecar of this 3x3 image holds no 3x3 model (written by an older version); re-run `dynocomp design`");
    };
    for (i, row) in image.rows.iter().enumerate() {
        let s = &image.axes[i].summary;
        if *row == RowDesign::Matrix && (s.q != model.q[i] || s.r != model.r[i]) {
            bail!("{source}: the sidecar's 3x3 model does not hold row {}'s q and R of the image; re-run `dynocomp design`", axis_name(i));
        }
    }
    Ok(model)
}

/// The smoothers of `compensate --offline` on a 3x3 image: the 3x3
/// smoother of the sidecar's model, and per row the image runs per axis,
/// that axis's own smoother ([`smoother_for`]) with the image's q and R.
pub struct MatrixSmoothers {
    /// The 3x3 smoother.
    pub matrix: MatrixSmoother,
    /// Per output row, its per-axis smoother where the image runs it per axis.
    pub per_axis: [Option<Smoother>; 3],
}

impl MatrixSmoothers {
    /// The smoothers of `image` from its `sidecar` for a record from
    /// `source` with the channels `axes` (fx, fy and fz).
    pub fn new(image: &MatrixImage, sidecar: &ModelSidecar, axes: &[usize], source: &str) -> Result<Self> {
        let model = checked_model(image, sidecar, axes, source)?;
        let plant = model.plant(f64::from(image.fs_hz), source)?;
        let matrix = MatrixSmoother::new(&plant, model.q, model.r, model.advance)
            .with_context(|| format!("{source}: the 3x3 smoother"))?;
        let mut per_axis = [None, None, None];
        for (i, row) in image.rows.iter().enumerate() {
            if *row == RowDesign::PerAxis {
                let s = &image.axes[i].summary;
                per_axis[i] = Some(smoother_for(sidecar, i, s.q, s.r, source)?);
            }
        }
        Ok(MatrixSmoothers { matrix, per_axis })
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
    let axes: Vec<usize> = rec.channels.iter().map(|c| c.0).collect();
    let sm = MatrixSmoothers::new(image, sidecar, &axes, source)?;
    let y: [&[f64]; 3] = std::array::from_fn(|i| rec.channels[i].1.as_slice());
    let mut out = sm.matrix.smooth(y);
    for (i, one) in sm.per_axis.iter().enumerate() {
        if let Some(one) = one {
            out[i] = one.smooth(y[i]);
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
    use crate::design::kalman::ForceShape;

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
            box_reduction: Some(None),
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

    /// The spilled passes give the in-memory smoother's estimates bit for
    /// bit, for block cuttings that do and do not fall on the backward
    /// pass's chunks (70 000 samples: two chunks), with an advance. Control:
    /// a record one sample shorter differs in its estimates near the end.
    #[test]
    fn the_spilled_smoother_equals_the_in_memory_one_bit_for_bit() {
        let mut m = model(
            [0.3, 0.5, 0.1],
            [[0.2, 0.05, 0.0], [0.03, -0.4, 0.02], [0.0, 0.1, 0.6]],
            diag([1.0; 3]),
            diag([0.05; 3]),
            2,
        );
        m.force_shape = [Some(ForceShape { corner_hz: 6_000.0, order: 4 }), None, None];
        let plant = m.plant(FS, "test").unwrap();
        let sm = MatrixSmoother::new(&plant, m.q, m.r, m.advance).unwrap();
        let n = 70_000;
        let y: Vec<Vec<f64>> = (0..3).map(|i| signal(20 + i as u64, n)).collect();
        let want = sm.smooth([&y[0], &y[1], &y[2]]);
        let dir = std::env::temp_dir();
        for block in [1_000, 8_192, 65_536, n] {
            let mut f = SpilledMatrixForward::new(&sm, &dir).unwrap();
            for s in (0..n).step_by(block) {
                let e = (s + block).min(n);
                f.push([&y[0][s..e], &y[1][s..e], &y[2][s..e]]).unwrap();
            }
            let done = std::cell::Cell::new(0u64);
            let mut est = f.backward(&dir, "test", &|k| done.set(done.get() + k)).unwrap();
            assert_eq!(done.get(), n as u64, "progress");
            for (i, e) in est.iter_mut().enumerate() {
                let mut got = Vec::new();
                e.read(n, &mut got).unwrap();
                assert!(got.iter().zip(&want[i]).all(|(a, b)| a.to_bits() == b.to_bits()), "block {block}, force {i}");
                assert_eq!(e.left(), 0);
            }
        }
        let shorter = sm.smooth([&y[0][..n - 1], &y[1][..n - 1], &y[2][..n - 1]]);
        assert!(
            shorter[0][n - 10..].iter().zip(&want[0][n - 10..]).any(|(a, b)| a.to_bits() != b.to_bits()),
            "control"
        );
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

    /// The smoother's response that the design predicts `compensate
    /// --offline` by ([`crate::design::mimo::response::smoother_responses`],
    /// the Wiener formula) is the smoother's own: an impulse on each
    /// channel, in the middle of a record long enough for both passes to
    /// settle, run through [`MatrixSmoother::smooth`] (an advance, an FIR
    /// tap, a shaped force and coupled channels), its output's DFT on a few
    /// lines. Negative control: the formula with another q differs.
    #[test]
    fn the_predicted_response_is_the_smoothers_own() {
        use crate::design::mimo::response::smoother_responses;
        use num_complex::Complex64;
        let c = [[0.3, 0.2, -0.15], [0.25, 0.2, 0.1], [-0.1, 0.2, 0.4]];
        let d = [[1.0, 0.5, 0.4], [0.6, 1.0, -0.5], [0.4, 0.5, 1.0]];
        let mut m = model([0.6, 0.4, 0.2], c, d, diag([0.1, -0.05, 0.2]), 2);
        m.force_shape[1] = Some(ForceShape { corner_hz: 5000.0, order: 4 });
        let plant = m.plant(FS, "test").unwrap();
        let sm = MatrixSmoother::new(&plant, m.q, m.r, m.advance).unwrap();
        let (len, mid) = (4096, 2048);
        let lines = [0.0, 37.5, 400.0, 2100.0, 5000.0, 9000.0, 12_700.0].map(|f: f64| f.max(1.0));
        let predicted = smoother_responses(&plant, m.q, m.r, &lines, FS);
        let mut worst: f64 = 0.0;
        for j in 0..3 {
            let mut y = vec![vec![0.0; len]; 3];
            y[j][mid] = 1.0;
            let out = sm.smooth([&y[0], &y[1], &y[2]]);
            for (k, f) in lines.iter().enumerate() {
                let w = 2.0 * std::f64::consts::PI * f / FS;
                for i in 0..3 {
                    let h: Complex64 =
                        (0..len).map(|t| out[i][t] * Complex64::from_polar(1.0, -w * (t as f64 - mid as f64))).sum();
                    let p = predicted[k][(i, j)];
                    worst = worst.max((h - p).norm() / (1.0 + p.norm()));
                }
            }
        }
        assert!(worst < 1e-6, "the Wiener formula differs from the smoother's response by {worst:e}");
        let other = smoother_responses(&plant, m.q.map(|q| 3.0 * q), m.r, &lines, FS);
        let moved = other.iter().zip(&predicted).map(|(a, b)| (a - b).norm() / (1.0 + b.norm())).fold(0.0, f64::max);
        assert!(moved > 1e-3, "negative control: q tripled moved the response by only {moved:e}");
    }

    /// Spoils a valid sidecar model in place.
    type Spoil = Box<dyn Fn(&mut MatrixModelJson)>;

    /// A sidecar's 3x3 model that is malformed is refused with a message
    /// that names it; a valid one is taken.
    #[test]
    fn malformed_models_are_refused() {
        let good = model([0.3, 0.5, 0.1], diag([0.2; 3]), diag([1.0; 3]), diag([0.0; 3]), 1);
        assert!(good.plant(FS, "s.json").is_ok());
        let cases: Vec<(Spoil, &str)> = vec![
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
