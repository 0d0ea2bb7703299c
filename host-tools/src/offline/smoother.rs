//! Offline zero-phase estimation of recorded forces (`dynocomp compensate
//! --offline`): the fixed-interval smoother of the design's own model
//! ([`Smoother`]), in memory or spilled to disk ([`SpilledForward`]).
//! **Offline only**: every estimate uses the whole record, past and future,
//! so it has no lag and no place in the box. It is an estimator in f64, not
//! the box's filter: the box's arithmetic stays in the core kernel.

use anyhow::{bail, Context, Result};
use nalgebra::{DMatrix, DVector};
use std::path::Path;

use crate::design::axis::AxisDesign;
use crate::design::discretize::DiscreteModel;
use crate::design::kalman;
use crate::frf::axis_name;
use crate::io::signal_csv::SignalRecord;
use crate::offline::force_prior::{build_axis_prior, AxisPrior, PriorOptions};
use crate::offline::sidecar::ModelSidecar;
use dynocomp_core::image::CoeffImage;

/// The steady-state fixed-interval smoother of one axis.
///
/// **Model.** The same augmented plant as the box's compensator
/// ([`crate::design::kalman`], DESIGN.md steps 2-3): the discrete model
/// Ĝ_d(z) = z^D·M(z) of the design ([`crate::design::discretize`]), the
/// applied force a random walk F_{k+1} = F_k + w_k, E\[w²\] = q (through the
/// design's band-limiting low-pass where it has one, [`kalman::ForceShape`]), measurement
/// ỹ_k = y_{k−D} = c·x_k + v_k, E\[v²\] = R, with q and R the values the design
/// chose and stored in the image (`inspect` shows them). The record is run
/// as ỹ (D samples of y_0 in front), so the estimate of F_k uses every sample
/// of y. The image does not hold the model itself: it comes from the image's
/// sidecar ([`crate::offline::sidecar`]).
///
/// **Smoother.** Steady-state Kalman filter forward, then the modified
/// Bryson–Frazier backward pass (Bierman 1977), which gives the same
/// estimates as the Rauch–Tung–Striebel smoother without inverting any
/// covariance. With P the prior covariance of the filter DARE (solved and
/// residual-checked by [`kalman::solve_filter_dare`]), S = cᵀPc + R,
/// K = Pc/S, C̃ = I − K cᵀ:
///
/// ```text
/// forward:   e_k = y_k − cᵀ x⁻_k,   x⁻_{k+1} = A (x⁻_k + K e_k),   x⁻_0 = 0
/// backward:  λ̂_{N−1} = 0
///            λ̃_k = −c e_k / S + C̃ᵀ λ̂_k,   x̂_k|N = x⁻_k − P λ̃_k,   λ̂_{k−1} = Aᵀ λ̃_k
/// ```
///
/// The backward recursion runs through (A C̃)ᵀ, whose spectral radius is the
/// (checked, < 1) closed-loop radius of the filter, so it is stable. The
/// force estimate is the F_k component of x̂_k|N (N).
#[derive(Clone, Debug)]
pub struct Smoother {
    a: DMatrix<f64>,
    c: DVector<f64>,
    p: DMatrix<f64>,
    k: DVector<f64>,
    s: f64,
    /// Row o with F_k = oᵀx_k: one state for the random walk, the sum of
    /// the broadband state and the resonators with a force prior.
    force_row: DVector<f64>,
    /// Advance D of the discrete model (samples).
    advance: usize,
    /// Relative residual of the DARE solution.
    pub dare_residual: f64,
    /// Spectral radius of A(I − K cᵀ), the backward recursion's matrix (transposed).
    pub closed_loop_radius: f64,
}

impl Smoother {
    /// Build the smoother for the discrete model `dm`, process noise q
    /// (N²/sample) and measurement noise R (N²).
    pub fn new(dm: &DiscreteModel, q: f64, r: f64) -> Result<Self> {
        Self::shaped(dm, q, r, None)
    }

    /// [`Smoother::new`] with the design's band-limited force model
    /// ([`kalman::ForceShape`]; `None`: the random walk).
    pub fn shaped(dm: &DiscreteModel, q: f64, r: f64, shape: Option<kalman::ForceShape>) -> Result<Self> {
        if !(q > 0.0 && q.is_finite() && r > 0.0 && r.is_finite()) {
            bail!("smoother needs q > 0 and R > 0 (got q = {q}, R = {r}); the image's design summary holds them");
        }
        let plant = kalman::augmented_plant_shaped(dm, 0, shape);
        let qm = &plant.g * plant.g.transpose() * q;
        let mut force_row = DVector::<f64>::zeros(plant.a.nrows());
        force_row[plant.n_plant] = 1.0;
        Self::from_plant(plant, &qm, force_row, r, dm.advance)
    }

    /// Build the smoother for the discrete model `dm` with the harmonic
    /// force prior `prior` (its q_bb and line intensities,
    /// [`crate::offline::force_prior`]) and measurement noise R (N²).
    pub fn with_force_prior(
        dm: &DiscreteModel,
        prior: &crate::offline::force_prior::HarmonicPrior,
        r: f64,
    ) -> Result<Self> {
        if !(prior.q_broadband > 0.0 && prior.q_broadband.is_finite() && r > 0.0 && r.is_finite()) {
            bail!("smoother needs q_bb > 0 and R > 0 (got q_bb = {}, R = {r})", prior.q_broadband);
        }
        let (plant, qm, force_row) = crate::offline::force_prior::plant_with_prior(dm, prior);
        Self::from_plant(plant, &qm, force_row, r, dm.advance)
    }

    fn from_plant(
        plant: kalman::AugmentedPlant,
        qm: &DMatrix<f64>,
        force_row: DVector<f64>,
        r: f64,
        advance: usize,
    ) -> Result<Self> {
        let sol = kalman::solve_filter_dare(&plant.a, &plant.c, qm, r)?;
        let s = (plant.c.transpose() * &sol.p * &plant.c)[(0, 0)] + r;
        let k = &sol.p * &plant.c / s;
        let n = plant.a.nrows();
        let closed = &plant.a * (DMatrix::<f64>::identity(n, n) - &k * plant.c.transpose());
        let eig = crate::fit::linalg::eigenvalues(&closed, "smoother: the filter's closed loop")?;
        let radius = eig.iter().map(|z| z.norm()).fold(0.0, f64::max);
        if radius.is_nan() || radius >= 1.0 {
            bail!("smoother: the filter's closed loop is not stable (spectral radius {radius:.9}); the model may be unobservable");
        }
        Ok(Smoother {
            a: plant.a,
            c: plant.c,
            p: sol.p,
            k,
            s,
            force_row,
            advance,
            dare_residual: sol.residual,
            closed_loop_radius: radius,
        })
    }

    /// One forward step ([`Smoother`]) from the prior x⁻_k (in `prior`, left
    /// holding x⁻_{k+1}; `next` is scratch): returns the prior's force
    /// component x⁻_k[F] and the innovation e_k, all the backward pass needs.
    fn forward_step(&self, prior: &mut DVector<f64>, next: &mut DVector<f64>, yk: f64) -> (f64, f64) {
        let e = yk - self.c.dot(prior);
        let prior_force = self.force_row.dot(prior);
        prior.axpy(e, &self.k, 1.0);
        self.a.mul_to(prior, next);
        std::mem::swap(prior, next);
        (prior_force, e)
    }

    /// One backward step ([`Smoother`]) from λ̂_k (in `lambda_hat`, left
    /// holding λ̂_{k−1}): returns F̂_k|N given x⁻_k[F] and e_k.
    fn backward_step(&self, lambda_hat: &mut DVector<f64>, p_row: &DVector<f64>, prior_force: f64, e: f64) -> f64 {
        // λ̃ = −c e/S + (I − K cᵀ)ᵀ λ̂ = −c e/S + λ̂ − c (Kᵀ λ̂)
        let kl = self.k.dot(lambda_hat);
        let lambda_tilde = &*lambda_hat - &self.c * (e / self.s + kl);
        let estimate = prior_force - p_row.dot(&lambda_tilde);
        *lambda_hat = self.a.tr_mul(&lambda_tilde);
        estimate
    }

    /// Pᵀo, the backward pass's output map (row F of P without a force
    /// prior), as a column.
    fn p_row(&self) -> DVector<f64> {
        self.p.tr_mul(&self.force_row)
    }

    /// Smoothed force estimate F̂_k|N (N) for every sample of `y` (N).
    ///
    /// Memory: 16 bytes per sample besides `y` and the result. The
    /// backward pass needs, of the forward pass, only each sample's
    /// innovation e_k and the force component of its prior x⁻_k
    /// (F̂_k|N = x⁻_k\[F\] − (P λ̃_k)\[F\], [`Smoother`]), so only those two are
    /// kept.
    /// [`SpilledForward`] is the same computation with those 16 bytes on
    /// disk.
    pub fn smooth(&self, y: &[f64]) -> Vec<f64> {
        // ỹ_k = y_{k−D}: D copies of y_0 in front; F̂_k for k < len(y).
        let d = if y.is_empty() { 0 } else { self.advance };
        let y_tilde = std::iter::repeat_n(y.first().copied().unwrap_or(0.0), d).chain(y.iter().copied());
        let n = self.a.nrows();
        let (mut prior, mut next) = (DVector::<f64>::zeros(n), DVector::<f64>::zeros(n));
        let (mut prior_force, mut innov): (Vec<f64>, Vec<f64>) =
            y_tilde.map(|yk| self.forward_step(&mut prior, &mut next, yk)).unzip();
        let p_row = self.p_row();
        let mut lambda_hat = DVector::<f64>::zeros(n);
        for k in (0..prior_force.len()).rev() {
            prior_force[k] = self.backward_step(&mut lambda_hat, &p_row, prior_force[k], innov[k]);
        }
        innov.clear();
        prior_force.truncate(y.len());
        prior_force
    }
}

/// Records per chunk of a spilled backward pass ([`SpilledRun`]): 1 MiB of
/// the per-axis smoother's pairs (x⁻_k[F], e_k), 3 MiB of the 3x3 smoother's.
const SPILL_CHUNK: usize = 1 << 16;

/// The smoother of one axis over a record of any length: the forward pass takes the record block by block and writes each sample's
/// x⁻_k\[F\] and e_k (16 bytes, f64) to an unnamed temporary file; then
/// [`SpilledForward::backward`] reads that file from its end in chunks and
/// writes the estimates in their places to a second one, which
/// [`SpilledEstimate`] reads forward. Same steps, same arithmetic, same bits
/// as [`Smoother::smooth`]; memory independent of the record's length.
pub struct SpilledForward<'s> {
    sm: &'s Smoother,
    prior: DVector<f64>,
    next: DVector<f64>,
    spill: std::io::BufWriter<std::fs::File>,
    /// Samples of y taken.
    n_y: u64,
    /// Pairs written (samples of ỹ: n_y + D once y has begun).
    n_pairs: u64,
}

/// A smoother's forward pass over a record taken block by block, spilled
/// to temporary files, and its backward pass ([`SpilledForward`], and the
/// drift smoother's [`crate::offline::drift::SpilledDriftForward`]).
pub trait SpilledPass {
    /// Take the next samples of y (N).
    fn push(&mut self, y: &[f64]) -> Result<()>;
    /// The backward pass: the estimates F̂_k|N of every sample taken, in a
    /// temporary file in `dir`. `on_chunk` is told the samples done (for a
    /// progress bar). Refuses a non-finite estimate, naming `name` and the
    /// sample.
    fn backward(
        self: Box<Self>,
        dir: &Path,
        name: &str,
        source: &str,
        on_chunk: &dyn Fn(u64),
    ) -> Result<SpilledEstimate>;
}

/// Feed the block `y` to `step` as ỹ_k = y_{k−D} (the smoothers' delayed
/// measurement): in front of the record's first samples (`first`: nothing
/// taken yet), D = `advance` copies of y_0.
pub(crate) fn feed_delayed(
    y: &[f64],
    advance: usize,
    first: bool,
    mut step: impl FnMut(f64) -> Result<()>,
) -> Result<()> {
    if let (true, Some(&y0)) = (first, y.first()) {
        for _ in 0..advance {
            step(y0)?;
        }
    }
    y.iter().try_for_each(|&v| step(v))
}

impl SpilledPass for SpilledForward<'_> {
    fn push(&mut self, y: &[f64]) -> Result<()> {
        SpilledForward::push(self, y)
    }

    fn backward(
        self: Box<Self>,
        dir: &Path,
        name: &str,
        source: &str,
        on_chunk: &dyn Fn(u64),
    ) -> Result<SpilledEstimate> {
        SpilledForward::backward(*self, dir, name, source, on_chunk)
    }
}

impl<'s> SpilledForward<'s> {
    /// Start the forward pass; the temporary files go to `dir`.
    pub fn new(sm: &'s Smoother, dir: &Path) -> Result<Self> {
        let n = sm.a.nrows();
        let file = tempfile::tempfile_in(dir).with_context(|| {
            format!("{}: cannot create a temporary file for the smoother's forward pass", dir.display())
        })?;
        Ok(SpilledForward {
            sm,
            prior: DVector::zeros(n),
            next: DVector::zeros(n),
            spill: std::io::BufWriter::with_capacity(1 << 20, file),
            n_y: 0,
            n_pairs: 0,
        })
    }

    /// Take the next samples of y (N).
    pub fn push(&mut self, y: &[f64]) -> Result<()> {
        let (first, advance) = (self.n_y == 0, self.sm.advance);
        feed_delayed(y, advance, first, |v| self.step(v))?;
        self.n_y += y.len() as u64;
        Ok(())
    }

    fn step(&mut self, yk: f64) -> Result<()> {
        use std::io::Write;
        let (f, e) = self.sm.forward_step(&mut self.prior, &mut self.next, yk);
        self.spill.write_all(&f.to_le_bytes())?;
        self.spill.write_all(&e.to_le_bytes())?;
        self.n_pairs += 1;
        Ok(())
    }

    /// The backward pass over the spilled forward pass: the estimates
    /// F̂_k|N, k < samples of y, in a temporary file in `dir`. `on_chunk`
    /// is told the samples done (for a progress bar). Refuses a
    /// non-finite estimate, naming the sample.
    pub fn backward(self, dir: &Path, name: &str, source: &str, on_chunk: &dyn Fn(u64)) -> Result<SpilledEstimate> {
        let spill = self.spill.into_inner().map_err(|e| e.into_error());
        let p_row = self.sm.p_row();
        let mut lambda_hat = DVector::<f64>::zeros(self.sm.a.nrows());
        let run = SpilledRun { n_run: self.n_pairs, n_y: self.n_y, dir, what: "the smoother", source };
        let [est] = run.backward(spill, &|_| name.to_string(), on_chunk, |[f, e]: [f64; 2]| {
            [self.sm.backward_step(&mut lambda_hat, &p_row, f, e)]
        })?;
        Ok(est)
    }
}

/// A forward pass spilled to a temporary file: `n_run` records of IN f64
/// (little-endian) each, of which the first `n_y` are the record's samples
/// (the rest the advance D in front); temporary files go to `dir`, and
/// errors name `what` and `source`.
pub(crate) struct SpilledRun<'a> {
    /// Records written by the forward pass.
    pub n_run: u64,
    /// Samples of the record among them.
    pub n_y: u64,
    /// Where the estimates' temporary files go.
    pub dir: &'a Path,
    /// The smoother, for I/O errors ("the smoother").
    pub what: &'a str,
    /// The record, for the other errors.
    pub source: &'a str,
}

impl SpilledRun<'_> {
    /// The backward pass over the records of `spill` ([`SpilledForward`],
    /// [`crate::offline::matrix_smoother::SpilledMatrixForward`]): read from
    /// the end in chunks of [`SPILL_CHUNK`], each record through `step`
    /// (which carries the backward state), its OUT estimates of the first
    /// `n_y` samples written in their places to one temporary file each,
    /// read forward by the [`SpilledEstimate`]s returned. `on_chunk` is told
    /// the samples done. Refuses a non-finite estimate, naming the estimate
    /// (`name` of its index) and the sample.
    pub fn backward<const IN: usize, const OUT: usize>(
        &self,
        spill: std::io::Result<std::fs::File>,
        name: &dyn Fn(usize) -> String,
        on_chunk: &dyn Fn(u64),
        mut step: impl FnMut([f64; IN]) -> [f64; OUT],
    ) -> Result<[SpilledEstimate; OUT]> {
        use std::io::{Read, Seek, SeekFrom, Write};
        let (dir, source) = (self.dir, self.source);
        let io_err = |e: std::io::Error| anyhow::anyhow!("{}: temporary file of {}: {e}", dir.display(), self.what);
        let mut spill = spill.map_err(io_err)?;
        let mut outs = Vec::with_capacity(OUT);
        for _ in 0..OUT {
            outs.push(tempfile::tempfile_in(dir).map_err(io_err)?);
        }
        let n_run = usize::try_from(self.n_run).map_err(|_| anyhow::anyhow!("{source}: record too long"))?;
        let n_y = self.n_y as usize;
        let width = 8 * IN;
        let mut bytes = vec![0u8; width * SPILL_CHUNK];
        let mut est: Vec<[f64; OUT]> = Vec::with_capacity(SPILL_CHUNK);
        let mut hi = n_run;
        while hi > 0 {
            let lo = hi.saturating_sub(SPILL_CHUNK);
            let buf = &mut bytes[..width * (hi - lo)];
            spill.seek(SeekFrom::Start((width * lo) as u64)).map_err(io_err)?;
            spill.read_exact(buf).map_err(io_err)?;
            est.clear();
            for k in (lo..hi).rev() {
                let rec = &buf[width * (k - lo)..width * (k - lo + 1)];
                let v = step(std::array::from_fn(|j| {
                    f64::from_le_bytes(rec[8 * j..8 * j + 8].try_into().unwrap_or_default())
                }));
                if let (true, Some(i)) = (k < n_y, v.iter().position(|x| !x.is_finite())) {
                    bail!("{source}: smoothed {} became non-finite at sample {k}", name(i));
                }
                est.push(v);
            }
            // est holds F̂_{hi−1} … F̂_lo; keep k < n_y, in order.
            let keep_hi = hi.min(n_y);
            if lo < keep_hi {
                for (i, out) in outs.iter_mut().enumerate() {
                    let chunk: Vec<u8> = est[hi - keep_hi..].iter().rev().flat_map(|v| v[i].to_le_bytes()).collect();
                    out.seek(SeekFrom::Start(8 * lo as u64)).map_err(io_err)?;
                    out.write_all(&chunk).map_err(io_err)?;
                }
                on_chunk((keep_hi - lo) as u64);
            }
            hi = lo;
        }
        let est: Vec<SpilledEstimate> =
            outs.into_iter().map(|f| SpilledEstimate::new(f, self.n_y).map_err(io_err)).collect::<Result<_>>()?;
        Ok(est.try_into().unwrap_or_else(|_| unreachable!("one estimate file per output")))
    }
}

/// The estimates of a [`SpilledForward`] pass, read forward.
pub struct SpilledEstimate {
    r: std::io::BufReader<std::fs::File>,
    left: u64,
}

impl SpilledEstimate {
    /// The `n` estimates (f64, little-endian) written to `file`, read from
    /// its start.
    pub fn new(mut file: std::fs::File, n: u64) -> std::io::Result<Self> {
        use std::io::Seek;
        file.seek(std::io::SeekFrom::Start(0))?;
        Ok(SpilledEstimate { r: std::io::BufReader::with_capacity(1 << 20, file), left: n })
    }

    /// The next `n` estimates (N) into `out` (cleared first); an error if
    /// fewer are left.
    pub fn read(&mut self, n: usize, out: &mut Vec<f64>) -> Result<()> {
        use std::io::Read;
        if (n as u64) > self.left {
            bail!("internal error: the smoother has {} estimates left, {n} asked for", self.left);
        }
        out.clear();
        let mut b = [0u8; 8];
        for _ in 0..n {
            self.r.read_exact(&mut b).context("temporary file of the smoother")?;
            out.push(f64::from_le_bytes(b));
        }
        self.left -= n as u64;
        Ok(())
    }

    /// Estimates not yet read.
    pub fn left(&self) -> u64 {
        self.left
    }
}

/// The image's compensator of `axis` (its q and R), or why the column
/// cannot be smoothed.
fn image_axis(image: &CoeffImage, axis: usize, source: &str) -> Result<dynocomp_core::image::AxisImage> {
    image.axes.get(axis).copied().flatten().ok_or_else(|| {
        anyhow::anyhow!("{source}: column f{} has no compensator (and no q, R) in the image; drop the column or design for that axis", axis_name(axis))
    })
}

/// The smoother of `axis` (0 = x): the sidecar's discrete model and force
/// shape, q and R from the image.
pub fn axis_smoother(image: &CoeffImage, sidecar: &ModelSidecar, axis: usize, source: &str) -> Result<Smoother> {
    let a = image_axis(image, axis, source)?;
    smoother_for(sidecar, axis, a.summary.q, a.summary.r, source)
}

/// The smoother of `axis` (0 = x): the sidecar's discrete model and force
/// shape, with process noise `q` (N²/sample) and measurement noise `r` (N²)
/// (an image's figures for that axis).
pub fn smoother_for(sidecar: &ModelSidecar, axis: usize, q: f64, r: f64, source: &str) -> Result<Smoother> {
    let dm = sidecar.discrete_model(axis, source)?;
    let name = axis_name(axis);
    if let Some(why) = sidecar.passed_through_raw(axis) {
        // An axis `design` passed through raw: its model is Ĝ = 1 and its
        // force free to move each sample (q = PASS_THROUGH_Q_RATIO·R), so
        // the estimate is the measurement, to R/q.
        eprintln!("WARNING: axis {name} is NOT COMPENSATED (passed through raw): {why}");
        return Smoother::new(&dm, PASS_THROUGH_Q_RATIO * r, r).with_context(|| format!("{source}: axis {name}"));
    }
    let shape = sidecar.force_shape(axis, source)?;
    Smoother::shaped(&dm, q, r, shape).with_context(|| format!("{source}: axis {name}"))
}

/// q/R of the smoother of an axis passed through raw ([`axis_smoother`]).
pub const PASS_THROUGH_Q_RATIO: f64 = 1e12;

/// `compensate --offline`: smooth every force column of `rec` with the
/// model of its axis from the sidecar and q, R from the image.
pub fn smooth_record(
    image: &CoeffImage,
    sidecar: &ModelSidecar,
    rec: &SignalRecord,
    source: &str,
) -> Result<SignalRecord> {
    let mut channels = Vec::with_capacity(rec.channels.len());
    for (axis, y) in &rec.channels {
        let name = axis_name(*axis);
        let sm = match sidecar.axes.iter().find(|m| m.axis == name).and_then(|m| m.force_prior.as_ref()) {
            None => axis_smoother(image, sidecar, *axis, source)?,
            Some(p) => {
                let a = image_axis(image, *axis, source)?;
                let dm = sidecar.discrete_model(*axis, source)?;
                if p.fs_hz != sidecar.fs_hz {
                    bail!("{source}: axis {name}: the force prior is for {} Hz, the image for {} Hz; re-run `dynocomp design`", p.fs_hz, sidecar.fs_hz);
                }
                let model = sidecar.model(*axis, source)?;
                crate::offline::force_prior::check_record(p, y, &|f| model.frf(f), a.summary.r)
                    .and_then(|_| Smoother::with_force_prior(&dm, p, a.summary.r))
                    .context("force prior")
                    .with_context(|| format!("{source}: axis {name}"))?
            }
        };
        let out = sm.smooth(y);
        if let Some(k) = out.iter().position(|v| !v.is_finite()) {
            bail!("{source}: smoothed f{} became non-finite at sample {k}", axis_name(*axis));
        }
        channels.push((*axis, out));
    }
    Ok(SignalRecord { t_s: rec.t_s.clone(), channels })
}

/// The harmonic force prior of each designed axis (`crate::offline::force_prior`),
/// tuned from `--force-record`, with the smoother's checks (Riccati
/// residual, closed-loop stability) and the refusal of a prior predicted
/// worse than no compensation.
/// `rec` is the representative record (`shown` names it in errors).
pub fn build_priors(
    opts: &PriorOptions,
    rec: &SignalRecord,
    shown: &str,
    designs: &[AxisDesign],
    r: &[Option<f64>; 3],
) -> Result<Vec<Option<AxisPrior>>> {
    let mut out = Vec::new();
    for d in designs {
        if d.pass_through.is_some() {
            out.push(None);
            continue;
        }
        let name = axis_name(d.axis);
        let y = rec.channel(d.axis).ok_or_else(|| {
            anyhow::anyhow!("{shown}: no column f{name} for axis {name}; the force record needs every designed axis")
        })?;
        let dm = &d.discrete.as_ref().ok_or_else(|| anyhow::anyhow!("axis {name}: no discrete model"))?.0;
        let rv = r[d.axis].expect("R set for every designed axis");
        let built = build_axis_prior(opts, dm, &|f| d.model.frf(f), rv, d.kalman.q, d.compensated_band_hz, y)
            .with_context(|| format!("{shown}: axis {name}: --force-prior harmonics"))?;
        Smoother::with_force_prior(dm, &built.prior, rv)
            .with_context(|| format!("axis {name}: the smoother with the force prior"))?;
        let p = built.prediction;
        if p.with_prior.partial_cmp(&p.raw) != Some(std::cmp::Ordering::Less) {
            bail!(
                "axis {name}: the offline estimate with the force prior would be worse than no compensation on the record's spectrum ({:.2} % against {:.2} %); no image written; drop --force-prior",
                100.0 * p.with_prior,
                100.0 * p.raw
            );
        }
        out.push(Some(built));
    }
    Ok(out)
}
