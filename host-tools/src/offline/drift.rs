//! The fixed-interval smoother whose model moves between two measured
//! states during the record (`compensate --offline --drift START:END`,
//! [`smooth_drifting`]): a time-varying Kalman filter forward and the modified
//! Bryson–Frazier recursion backward, in f64. With a constant model it
//! reproduces the stationary [`crate::offline::smoother::Smoother`]. Its memory
//! does not grow with the record beyond 16 bytes per sample, on disk with
//! [`SpilledDriftForward`].

use anyhow::{bail, Context, Result};
use nalgebra::{DMatrix, DVector};
use std::f64::consts::PI;
use std::path::Path;

use dynocomp_core::image::CoeffImage;

use crate::design::discretize::{fit_with_structure, DiscreteModel};
use crate::design::kalman::{augmented_plant, solve_filter_dare};
use crate::design::two_state::model::TwoState;
use crate::fit::PoleResidueModel;
use crate::frf::axis_name;
use crate::offline::sidecar::ModelSidecar;
use crate::offline::smoother::{SpilledEstimate, SpilledPass};

/// Quantization levels of the state variable s in the time-varying smoother.
pub const S_LEVELS: usize = 256;

/// The state variable at time `t_s` of a drift from `start_s` to `end_s`.
pub fn state_at(t_s: f64, start_s: f64, end_s: f64) -> f64 {
    if t_s <= start_s {
        0.0
    } else if t_s >= end_s {
        1.0
    } else {
        (t_s - start_s) / (end_s - start_s)
    }
}

/// One step's model in the smoother's augmented coordinates: A as its
/// nonzero entries row by row (at most 3 per row: a mode's 2x2 block and
/// its force input, a delay-line shift, the force's random walk;
/// [`crate::design::kalman::augmented_plant`]), so that A·x and A·M cost O(n) and
/// O(n²) instead of O(n²) and O(n³).
struct Plant {
    /// Row i's entries (column, value): `entries[row_start[i]..row_start[i + 1]]`.
    entries: Vec<(usize, f64)>,
    row_start: Vec<usize>,
    c: DVector<f64>,
}

impl Plant {
    fn new(a: &DMatrix<f64>, c: DVector<f64>) -> Plant {
        let mut entries = Vec::new();
        let mut row_start = vec![0];
        for i in 0..a.nrows() {
            entries.extend((0..a.ncols()).filter(|&j| a[(i, j)] != 0.0).map(|j| (j, a[(i, j)])));
            row_start.push(entries.len());
        }
        Plant { entries, row_start, c }
    }

    fn row(&self, i: usize) -> &[(usize, f64)] {
        &self.entries[self.row_start[i]..self.row_start[i + 1]]
    }

    /// out = A·x.
    fn mul_vec(&self, x: &DVector<f64>, out: &mut DVector<f64>) {
        for i in 0..out.len() {
            out[i] = self.row(i).iter().map(|&(j, v)| v * x[j]).sum();
        }
    }

    /// out = Aᵀ·x.
    fn tr_mul_vec(&self, x: &DVector<f64>, out: &mut DVector<f64>) {
        out.fill(0.0);
        for i in 0..x.len() {
            for &(j, v) in self.row(i) {
                out[j] += v * x[i];
            }
        }
    }

    /// out = A·Mᵀ (column by column: out[:, l] = A·M[l, :]ᵀ).
    fn mul_tr(&self, m: &DMatrix<f64>, out: &mut DMatrix<f64>) {
        let n = m.nrows();
        for l in 0..n {
            for i in 0..n {
                out[(i, l)] = self.row(i).iter().map(|&(j, v)| v * m[(l, j)]).sum();
            }
        }
    }
}

/// The covariance half of the time-varying Kalman filter: the prior error
/// covariance P_k and the step's gain, innovation variance and the row of
/// P_k that carries the force. It does not depend on the record, so the
/// backward pass recomputes it segment by segment from checkpoints of the
/// forward pass ([`drift_passes`]) instead of keeping it per sample.
///
/// **Frozen covariance.** Where the model does not change from one step to
/// the next and P_{k+1} equals P_k to [`FROZEN_TOLERANCE`] (relative, the
/// largest entry), P is held until the model changes again: the stationary
/// stretches before and after the drift then cost O(n) per sample, not
/// O(n²). Recomputation from a checkpoint takes the same decisions, so the
/// backward pass sees the forward pass's numbers exactly.
#[derive(Clone)]
struct Covariance {
    p: DMatrix<f64>,
    frozen: bool,
    /// The last step's gain; the next step reuses it unless `stale` (P
    /// changed since, or none yet).
    gain: Option<Gain>,
    stale: bool,
}

/// Relative change of P below which it is held (`Covariance`): a few
/// hundred f64 roundings of its largest entry.
const FROZEN_TOLERANCE: f64 = 1e-13;

/// One step's measurement quantities from P_k and c_k.
#[derive(Clone)]
struct Gain {
    /// K_k = P_k c_k / S_k.
    k: DVector<f64>,
    /// S_k = c_kᵀ P_k c_k + R.
    s: f64,
    /// Row `force` of P_k.
    p_row: DVector<f64>,
}

/// Work buffers of [`Covariance::advance`].
struct Scratch {
    pp: DMatrix<f64>,
    t: DMatrix<f64>,
    next: DMatrix<f64>,
}

impl Covariance {
    fn gain(&self, pl: &Plant, r: f64, force: usize) -> Gain {
        let pc = &self.p * &pl.c;
        let s = pl.c.dot(&pc) + r;
        Gain { k: &pc / s, s, p_row: self.p.row(force).transpose() }
    }

    /// Step k: its gain (the cached one while P is frozen), and P advanced
    /// to P_{k+1}. The forward pass and the backward pass's recomputation
    /// both step through here, so they agree exactly.
    fn step(&mut self, pl: &Plant, same_model_next: bool, r: f64, q: f64, force: usize, w: &mut Scratch) -> &Gain {
        let g = match self.gain.take() {
            Some(g) if !self.stale => g,
            _ => self.gain(pl, r, force),
        };
        self.stale = !self.advance(pl, &g, same_model_next, q, force, w);
        self.gain.insert(g)
    }

    /// P_{k+1} = A_k (P_k − K_k S_k K_kᵀ) A_kᵀ + q·g gᵀ (g the force's
    /// unit vector), or P held if frozen and the next step keeps the model;
    /// true if held.
    fn advance(
        &mut self,
        pl: &Plant,
        gain: &Gain,
        same_model_next: bool,
        q: f64,
        force: usize,
        w: &mut Scratch,
    ) -> bool {
        if self.frozen && same_model_next {
            return true;
        }
        w.pp.copy_from(&self.p);
        w.pp.ger(-gain.s, &gain.k, &gain.k, 1.0);
        // T = A·Pp (Pp symmetric: A·Ppᵀ), then P' = A·Tᵀ = A Pp Aᵀ.
        pl.mul_tr(&w.pp, &mut w.t);
        pl.mul_tr(&w.t, &mut w.next);
        w.next[(force, force)] += q;
        let n = w.next.nrows();
        for i in 0..n {
            for j in 0..i {
                let v = 0.5 * (w.next[(i, j)] + w.next[(j, i)]);
                w.next[(i, j)] = v;
                w.next[(j, i)] = v;
            }
        }
        let scale = w.next.amax();
        let change = w.next.iter().zip(self.p.iter()).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        self.frozen = same_model_next && change <= FROZEN_TOLERANCE * scale;
        std::mem::swap(&mut self.p, &mut w.next);
        false
    }
}

/// Settings of [`smooth_drifting`].
#[derive(Clone, Copy, Debug)]
pub struct DriftSmoothing {
    /// Sample rate of the record (Hz).
    pub fs_hz: f64,
    /// The drift's start and end (s): state 0 before, 1 after.
    pub interval_s: (f64, f64),
    /// Compensated band of the unit-circle discretization (Hz).
    pub band_hz: (f64, f64),
    /// (FIR taps, advance) of state 0's discrete model.
    pub structure: (usize, usize),
    /// Process noise q (N²/sample).
    pub q: f64,
    /// Measurement noise R (N²).
    pub r: f64,
}

/// Smoothed force estimate (N) of the record `y` (N) while the model moves
/// from `model_at(0)` to `model_at(1)` over `opts.interval_s`; `model_at(s)`
/// returns the continuous model at state s.
///
/// The model moves from state 0 at `start_s` to state 1 at `end_s`, linearly
/// in s, constant outside. s is quantized to [`S_LEVELS`] levels (a 5 % drift
/// moves in steps of 0.02 %); each level's continuous model is discretized on
/// the unit circle with the same FIR taps and advance as state 0's
/// ([`crate::design::discretize::fit_with_structure`]), so every step has the
/// same augmented state layout ([`crate::design::kalman::augmented_plant`]).
/// The forward pass is the exact time-varying Kalman filter (covariance
/// propagated through every step's A, c; P⁻₀ = state 0's stationary DARE
/// solution), the backward pass the modified Bryson–Frazier recursion with
/// each step's own K, c, S and A (the same estimates as Rauch–Tung–Striebel,
/// no covariance inversion).
///
/// **Memory.** The covariance recursion does not depend on the record, so
/// the forward pass keeps P only at checkpoints (every √N samples,
/// [`segment_len`]) besides 16 bytes per sample (the innovation and the
/// prior's force estimate), and the backward pass recomputes each segment's
/// gains from its checkpoint. A is applied as its nonzero entries (≤ 3 per
/// row), and P is held where it has converged and the model does not change
/// (before and after the drift).
pub fn smooth_drifting(
    y: &[f64],
    model_at: &dyn Fn(f64) -> PoleResidueModel,
    opts: &DriftSmoothing,
) -> Result<Vec<f64>> {
    smooth_drifting_in_segments(y, model_at, opts, segment_len(y.len()), &|_| {})
}

/// Samples per checkpoint of the covariance for a record of `len` samples:
/// about √len (at least 4096), so that the checkpoints (n² values each)
/// and one segment's gains (2n + 1 values per sample) stay tens of MB for
/// a record of an hour at 51.2 kHz (n ≈ 25).
pub fn segment_len(len: usize) -> usize {
    ((len as f64).sqrt().ceil() as usize).max(4096)
}

/// [`smooth_drifting`] with the covariance checkpointed every `segment`
/// samples (≥ 1); `progress(m)` is called as the passes advance by m
/// samples (2·(len + advance) in all).
///
/// **Memory:** 16 bytes per sample (the innovation and the prior's force
/// estimate), one covariance (n² values) per `segment` samples, and one
/// segment's gains; the output. **Cost:** the covariance is propagated
/// twice where it is not frozen (`Covariance`).
pub fn smooth_drifting_in_segments(
    y: &[f64],
    model_at: &dyn Fn(f64) -> PoleResidueModel,
    opts: &DriftSmoothing,
    segment: usize,
    progress: &dyn Fn(u64),
) -> Result<Vec<f64>> {
    Ok(drift_passes(y, model_at, opts, Some(segment.max(1)), progress)?.0)
}

/// Log-likelihood (nats) of the record `y` (N) under the drifting model of
/// [`smooth_drifting`]: the forward pass's innovations e_k and their
/// variances S_k, ℓ = −½ Σ_k (ln 2πS_k + e_k²/S_k) (the prediction-error
/// decomposition), over the record's own samples (not the D copies of y₀ in
/// front). Differences of ℓ between models say how much better one
/// explains the record; used to ask whether a record can tell the drift's
/// end state (`examples/drift_from_record.rs`).
pub fn drift_log_likelihood(
    y: &[f64],
    model_at: &dyn Fn(f64) -> PoleResidueModel,
    opts: &DriftSmoothing,
) -> Result<f64> {
    Ok(drift_passes(y, model_at, opts, None, &|_| {})?.1)
}

/// The forward pass's state ([`smooth_drifting`]): each level's plant, built when
/// the pass first reaches it, P⁻_k and x⁻_k. Step k takes ỹ_k.
struct DriftForward<'m> {
    model_at: &'m dyn Fn(f64) -> PoleResidueModel,
    opts: DriftSmoothing,
    plants: Vec<Option<Plant>>,
    n: usize,
    force: usize,
    cov: Covariance,
    x: DVector<f64>,
    xp: DVector<f64>,
    w: Scratch,
    /// Steps taken.
    k: usize,
    /// Log-likelihood of the steps after the D copies of y₀ (nats).
    log_lik: f64,
}

/// Model level (0 ..= [`S_LEVELS`]) of step k: the state at time k/fs.
fn level_of(opts: &DriftSmoothing, k: usize) -> usize {
    (state_at(k as f64 / opts.fs_hz, opts.interval_s.0, opts.interval_s.1) * S_LEVELS as f64).round() as usize
}

impl<'m> DriftForward<'m> {
    fn new(model_at: &'m dyn Fn(f64) -> PoleResidueModel, opts: &DriftSmoothing) -> Result<Self> {
        let DriftSmoothing { interval_s: (start_s, end_s), q, r, .. } = *opts;
        if !(q > 0.0 && q.is_finite() && r > 0.0 && r.is_finite()) {
            bail!("smoother needs q > 0 and R > 0 (got q = {q}, R = {r})");
        }
        if !(start_s.is_finite() && end_s.is_finite() && end_s > start_s) {
            bail!("--drift {start_s}:{end_s}: need START < END (s)");
        }
        let plant0 = augmented_plant(&Self::discrete(model_at, opts, 0)?, 0);
        let n = plant0.a.nrows();
        let qm = &plant0.g * plant0.g.transpose() * q;
        let sol = solve_filter_dare(&plant0.a, &plant0.c, &qm, r)?;
        let mut plants: Vec<Option<Plant>> = (0..=S_LEVELS).map(|_| None).collect();
        let force = plant0.n_plant;
        plants[0] = Some(Plant::new(&plant0.a, plant0.c));
        Ok(DriftForward {
            model_at,
            opts: *opts,
            plants,
            n,
            force,
            cov: Covariance { p: sol.p, frozen: false, gain: None, stale: true },
            x: DVector::zeros(n),
            xp: DVector::zeros(n),
            w: Scratch { pp: DMatrix::zeros(n, n), t: DMatrix::zeros(n, n), next: DMatrix::zeros(n, n) },
            k: 0,
            log_lik: 0.0,
        })
    }

    fn discrete(
        model_at: &dyn Fn(f64) -> PoleResidueModel,
        opts: &DriftSmoothing,
        level: usize,
    ) -> Result<DiscreteModel> {
        let s = level as f64 / S_LEVELS as f64;
        let (taps, advance) = opts.structure;
        fit_with_structure(&model_at(s), opts.fs_hz, opts.band_hz, taps, advance)
            .with_context(|| format!("model at state s = {s:.3}"))
    }

    /// P⁻ of the next step, for a checkpoint (its gain is recomputed: the
    /// same bits, as P and the model are the same).
    fn checkpoint(&self) -> Covariance {
        Covariance { p: self.cov.p.clone(), frozen: self.cov.frozen, gain: None, stale: true }
    }

    /// Step k with ỹ_k: (x⁻_k[F], e_k), the prior's force estimate and the
    /// innovation, for the backward pass.
    fn step(&mut self, yk: f64) -> Result<(f64, f64)> {
        let (k, n, force) = (self.k, self.n, self.force);
        let level = level_of(&self.opts, k);
        if self.plants[level].is_none() {
            let pl = augmented_plant(&Self::discrete(self.model_at, &self.opts, level)?, 0);
            if pl.a.nrows() != n {
                bail!(
                    "the model at state s = {:.3} has another state size ({} vs {n}); a mode crossed fs/2",
                    level as f64 / S_LEVELS as f64,
                    pl.a.nrows()
                );
            }
            self.plants[level] = Some(Plant::new(&pl.a, pl.c));
        }
        let pl = self.plants[level].as_ref().expect("built above");
        // Whether step k + 1 keeps the model (P may be held); after the
        // last step P is not used.
        let same_next = level_of(&self.opts, k + 1) == level;
        let g = self.cov.step(pl, same_next, self.opts.r, self.opts.q, force, &mut self.w);
        let prior_f = self.x[force];
        let e = yk - pl.c.dot(&self.x);
        if k >= self.opts.structure.1 {
            self.log_lik -= 0.5 * ((2.0 * PI * g.s).ln() + e * e / g.s);
        }
        self.xp.copy_from(&self.x);
        self.xp.axpy(e, &g.k, 1.0);
        pl.mul_vec(&self.xp, &mut self.x);
        self.k += 1;
        Ok((prior_f, e))
    }

    /// The backward pass over the steps taken.
    fn into_backward(self) -> DriftBackward {
        let n = self.n;
        DriftBackward {
            opts: self.opts,
            plants: self.plants,
            force: self.force,
            lambda_hat: DVector::zeros(n),
            lambda_tilde: DVector::zeros(n),
            gains: Vec::new(),
            w: self.w,
        }
    }
}

/// The modified Bryson–Frazier pass, one checkpointed segment at a time
/// from the record's end.
struct DriftBackward {
    opts: DriftSmoothing,
    plants: Vec<Option<Plant>>,
    force: usize,
    lambda_hat: DVector<f64>,
    lambda_tilde: DVector<f64>,
    gains: Vec<Gain>,
    w: Scratch,
}

impl DriftBackward {
    /// F̂_k|N for k = k0 … k0 + out.len() − 1 (the segment before the ones
    /// already done) into `out`, from the checkpoint `start` (P⁻ of step
    /// k0) and the forward pass's x⁻_k[F] and e_k of the same steps.
    fn segment(&mut self, start: Covariance, k0: usize, prior_f: &[f64], es: &[f64], out: &mut [f64]) {
        let DriftBackward { opts, plants, force, lambda_hat, lambda_tilde, gains, w, .. } = self;
        let plant = |k: usize| plants[level_of(opts, k)].as_ref().expect("reached by the forward pass");
        let k1 = k0 + out.len();
        // Recompute the segment's gains from its checkpoint, exactly as the
        // forward pass did.
        let mut cov = start;
        gains.clear();
        for k in k0..k1 {
            let same_next = level_of(opts, k + 1) == level_of(opts, k);
            gains.push(cov.step(plant(k), same_next, opts.r, opts.q, *force, w).clone());
        }
        for k in (k0..k1).rev() {
            let g = &gains[k - k0];
            let kl = g.k.dot(lambda_hat);
            lambda_tilde.copy_from(lambda_hat);
            lambda_tilde.axpy(-(es[k - k0] / g.s + kl), &plant(k).c, 1.0);
            out[k - k0] = prior_f[k - k0] - g.p_row.dot(lambda_tilde);
            if k > 0 {
                plant(k - 1).tr_mul_vec(lambda_tilde, lambda_hat);
            }
        }
    }
}

/// The forward pass, and with `segment` the backward pass with the
/// covariance checkpointed every `segment` samples: (smoothed force
/// estimate, or nothing; log-likelihood of the record).
fn drift_passes(
    y: &[f64],
    model_at: &dyn Fn(f64) -> PoleResidueModel,
    opts: &DriftSmoothing,
    segment: Option<usize>,
    progress: &dyn Fn(u64),
) -> Result<(Vec<f64>, f64)> {
    let mut fwd = DriftForward::new(model_at, opts)?;
    let advance = opts.structure.1;
    // ỹ_k = y_{k−D}: D copies of y_0 in front (as the stationary smoother).
    let yt: Vec<f64> =
        std::iter::repeat_n(y.first().copied().unwrap_or(0.0), advance).chain(y.iter().copied()).collect();
    let len = yt.len();
    let kept = if segment.is_some() { len } else { 0 };
    let mut es = Vec::with_capacity(kept);
    let mut prior_f = Vec::with_capacity(kept);
    let mut checkpoints: Vec<Covariance> = Vec::new();
    for (k, &yk) in yt.iter().enumerate() {
        if segment.is_some_and(|seg| k % seg == 0) {
            checkpoints.push(fwd.checkpoint());
        }
        let (f, e) = fwd.step(yk)?;
        if segment.is_some() {
            prior_f.push(f);
            es.push(e);
        }
        if k % 4096 == 4095 {
            progress(4096);
        }
    }
    progress((len % 4096) as u64);
    let log_lik = fwd.log_lik;
    let Some(seg) = segment else {
        if !log_lik.is_finite() {
            bail!("the time-varying filter's likelihood became non-finite");
        }
        return Ok((Vec::new(), log_lik));
    };
    let mut bw = fwd.into_backward();
    let mut out = vec![0.0; len];
    for (j, start) in checkpoints.into_iter().enumerate().rev() {
        let (k0, k1) = (j * seg, ((j + 1) * seg).min(len));
        bw.segment(start, k0, &prior_f[k0..k1], &es[k0..k1], &mut out[k0..k1]);
        progress((k1 - k0) as u64);
    }
    if let Some(k) = out.iter().position(|v| !v.is_finite()) {
        bail!("the time-varying smoother became non-finite at sample {k}");
    }
    out.truncate(len - advance.min(len));
    Ok((out, log_lik))
}

/// Samples per checkpoint of [`SpilledDriftForward`] (the checkpoints go to
/// a temporary file: n² values per segment, about 1.2 bytes per sample at
/// n ≈ 25; one segment's gains and spilled pairs in memory, ~2 MB).
pub const SPILLED_SEGMENT: usize = 4096;

/// The drift smoother ([`smooth_drifting`]) over a record taken block by
/// block, in memory independent of the record's length: the forward pass
/// writes x⁻_k\[F\] and e_k (16 bytes per sample) and every
/// [`SPILLED_SEGMENT`]-th P⁻ to temporary files; [`SpilledPass::backward`]
/// reads them back one segment at a time from the end, recomputes the
/// segment's gains from its checkpoint, and writes the estimates to a third.
/// Same steps and arithmetic as [`smooth_drifting_in_segments`] with that
/// segment length.
pub struct SpilledDriftForward<'m> {
    fwd: DriftForward<'m>,
    pairs: std::io::BufWriter<std::fs::File>,
    checkpoints: std::io::BufWriter<std::fs::File>,
    /// Samples of y taken.
    n_y: u64,
}

impl<'m> SpilledDriftForward<'m> {
    /// Start the forward pass; the temporary files go to `dir`.
    pub fn new(model_at: &'m dyn Fn(f64) -> PoleResidueModel, opts: &DriftSmoothing, dir: &Path) -> Result<Self> {
        let fwd = DriftForward::new(model_at, opts)?;
        let temp = || {
            tempfile::tempfile_in(dir).map(|f| std::io::BufWriter::with_capacity(1 << 20, f)).with_context(|| {
                format!("{}: cannot create a temporary file for the drift smoother's forward pass", dir.display())
            })
        };
        Ok(SpilledDriftForward { fwd, pairs: temp()?, checkpoints: temp()?, n_y: 0 })
    }

    fn step(&mut self, yk: f64) -> Result<()> {
        use std::io::Write;
        if self.fwd.k.is_multiple_of(SPILLED_SEGMENT) {
            let c = self.fwd.checkpoint();
            for v in c.p.iter().chain(std::iter::once(&f64::from(u8::from(c.frozen)))) {
                self.checkpoints.write_all(&v.to_le_bytes())?;
            }
        }
        let (f, e) = self.fwd.step(yk)?;
        self.pairs.write_all(&f.to_le_bytes())?;
        self.pairs.write_all(&e.to_le_bytes())?;
        Ok(())
    }
}

impl SpilledPass for SpilledDriftForward<'_> {
    fn push(&mut self, y: &[f64]) -> Result<()> {
        let (first, advance) = (self.n_y == 0, self.fwd.opts.structure.1);
        crate::offline::smoother::feed_delayed(y, advance, first, |v| self.step(v))?;
        self.n_y += y.len() as u64;
        Ok(())
    }

    fn backward(
        self: Box<Self>,
        dir: &Path,
        name: &str,
        source: &str,
        on_chunk: &dyn Fn(u64),
    ) -> Result<SpilledEstimate> {
        use std::io::{Read, Seek, SeekFrom, Write};
        let io_err =
            |e: std::io::Error| anyhow::anyhow!("{}: temporary file of the drift smoother: {e}", dir.display());
        let SpilledDriftForward { fwd, pairs, checkpoints, n_y } = *self;
        let mut pairs = pairs.into_inner().map_err(|e| io_err(e.into_error()))?;
        let mut checkpoints = checkpoints.into_inner().map_err(|e| io_err(e.into_error()))?;
        let mut out = tempfile::tempfile_in(dir).map_err(io_err)?;
        let n_y = usize::try_from(n_y).map_err(|_| anyhow::anyhow!("{source}: record too long"))?;
        let (n, len) = (fwd.n, fwd.k);
        let mut bw = fwd.into_backward();
        let mut bytes = vec![0u8; 16 * SPILLED_SEGMENT];
        let mut p_bytes = vec![0u8; 8 * (n * n + 1)];
        let (mut prior_f, mut es, mut est) = (Vec::new(), Vec::new(), vec![0.0; SPILLED_SEGMENT]);
        let f64_at = |b: &[u8], i: usize| f64::from_le_bytes(b[8 * i..8 * i + 8].try_into().unwrap_or_default());
        for j in (0..len.div_ceil(SPILLED_SEGMENT)).rev() {
            let (k0, k1) = (j * SPILLED_SEGMENT, ((j + 1) * SPILLED_SEGMENT).min(len));
            let buf = &mut bytes[..16 * (k1 - k0)];
            pairs.seek(SeekFrom::Start(16 * k0 as u64)).map_err(io_err)?;
            pairs.read_exact(buf).map_err(io_err)?;
            prior_f.clear();
            es.clear();
            for i in 0..k1 - k0 {
                prior_f.push(f64_at(buf, 2 * i));
                es.push(f64_at(buf, 2 * i + 1));
            }
            checkpoints.seek(SeekFrom::Start((j * p_bytes.len()) as u64)).map_err(io_err)?;
            checkpoints.read_exact(&mut p_bytes).map_err(io_err)?;
            let p = DMatrix::from_iterator(n, n, (0..n * n).map(|i| f64_at(&p_bytes, i)));
            let start = Covariance { p, frozen: f64_at(&p_bytes, n * n) != 0.0, gain: None, stale: true };
            let seg = &mut est[..k1 - k0];
            bw.segment(start, k0, &prior_f, &es, seg);
            // Keep F̂_k for the record's own samples, k < n_y.
            let keep = k1.min(n_y).saturating_sub(k0);
            if let Some(i) = seg[..keep].iter().position(|v| !v.is_finite()) {
                bail!("{source}: smoothed {name} became non-finite at sample {}", k0 + i);
            }
            if keep > 0 {
                let chunk: Vec<u8> = seg[..keep].iter().flat_map(|v| v.to_le_bytes()).collect();
                out.seek(SeekFrom::Start(8 * k0 as u64)).map_err(io_err)?;
                out.write_all(&chunk).map_err(io_err)?;
                on_chunk(keep as u64);
            }
        }
        SpilledEstimate::new(out, n_y as u64).map_err(io_err)
    }
}

/// The two states of `axis` from the sidecar and the drift smoother's
/// settings (q and R from the image), or why the column cannot follow a drift.
pub fn axis_drift(
    image: &CoeffImage,
    sidecar: &ModelSidecar,
    axis: usize,
    source: &str,
    interval_s: (f64, f64),
) -> Result<(TwoState, DriftSmoothing)> {
    let name = axis_name(axis);
    let Some(a) = image.axes.get(axis).copied().flatten() else {
        bail!("{source}: column f{name} has no compensator (and no q, R) in the image; drop the column or design for that axis");
    };
    let Some(entry) = sidecar.axes.iter().find(|m| m.axis == name).and_then(|m| m.two_state.as_ref()) else {
        bail!("{source}: --drift needs two FRF states for axis {name} in the model sidecar: design with `--frf BEFORE --frf AFTER`");
    };
    let ts = entry.states(source, name)?;
    let opts = DriftSmoothing {
        fs_hz: f64::from(image.fs_hz),
        interval_s,
        band_hz: entry.band_hz,
        structure: (entry.fir_taps, entry.advance),
        q: a.summary.q,
        r: a.summary.r,
    };
    Ok((ts, opts))
}

/// Parse `--drift START:END` (seconds, 0 ≤ START < END).
pub fn parse_interval(s: &str) -> Result<(f64, f64)> {
    let bad = || anyhow::anyhow!("--drift {s}: expected START:END in seconds with 0 ≤ START < END, e.g. 0.5:12");
    let (a, b) = s.split_once(':').ok_or_else(bad)?;
    let (a, b): (f64, f64) = (a.trim().parse().map_err(|_| bad())?, b.trim().parse().map_err(|_| bad())?);
    if !(a.is_finite() && b.is_finite() && a >= 0.0 && b > a) {
        return Err(bad());
    }
    Ok((a, b))
}
