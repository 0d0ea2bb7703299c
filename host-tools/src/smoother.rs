//! Offline zero-phase estimation of recorded forces (`dynocomp compensate
//! --offline`): a fixed-interval smoother. **Offline only**: every estimate
//! uses the whole record, past and future, so it has no lag and no place in
//! the box.
//!
//! **Model.** The same augmented plant as the box's compensator
//! ([`crate::kalman`], DESIGN.md steps 2-3): the discrete model Ĝ_d(z) =
//! z^D·M(z) of the design ([`crate::discretize`]), the applied force a random
//! walk F_{k+1} = F_k + w_k, E[w²] = q, measurement ỹ_k = y_{k−D} = c·x_k + v_k,
//! E[v²] = R, with q and R the values the design chose and stored in the
//! image (`inspect` shows them). The record is run as ỹ (D samples of y_0
//! in front), so the estimate of F_k uses every sample of y.
//! The image does not hold the model itself, so `dynocomp design` writes it
//! next to the image as a sidecar `<image>.model.json` ([`ModelSidecar`]):
//! the fitted Ĝ(s) and the discrete model of the design (a sidecar without
//! the discrete model, from an older version, gets the first-order hold of
//! Ĝ(s), which that version used), tied to
//! the image by its id (CRC-32) and the source FRF's SHA-256;
//! `compensate --offline` refuses a missing or foreign sidecar. Only the
//! default method (vf) writes a sidecar; `--method paper` images (continuous
//! Q, Tustin) are refused by `--offline` with a message saying so.
//!
//! **Smoother.** Steady-state Kalman filter forward, then the modified
//! Bryson–Frazier backward pass (Bierman 1977), which gives the same
//! estimates as the Rauch–Tung–Striebel smoother without inverting any
//! covariance. With P the prior covariance of the filter DARE (solved and
//! residual-checked by [`kalman::solve_filter_dare`]), S = cᵀPc + R,
//! K = Pc/S, C̃ = I − K cᵀ:
//!
//! ```text
//! forward:   e_k = y_k − cᵀ x⁻_k,   x⁻_{k+1} = A (x⁻_k + K e_k),   x⁻_0 = 0
//! backward:  λ̂_{N−1} = 0
//!            λ̃_k = −c e_k / S + C̃ᵀ λ̂_k,   x̂_k|N = x⁻_k − P λ̃_k,   λ̂_{k−1} = Aᵀ λ̃_k
//! ```
//!
//! The backward recursion runs through (A C̃)ᵀ, whose spectral radius is the
//! (checked, < 1) closed-loop radius of the filter, so it is stable. The
//! force estimate is the F_k component of x̂_k|N (N).
//!
//! Computed in f64 on the host. It is an estimator, not the box's filter:
//! the box's arithmetic stays in the core kernel only.

use anyhow::{bail, Context, Result};
use nalgebra::{DMatrix, DVector};
use num_complex::Complex64;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

use crate::discretize::{discretize, DiscreteModel, Discretization};
use crate::fit::{PoleResidueModel, Term};
use crate::frf::axis_name;
use crate::io::one_line;
use crate::io::signal_csv::SignalRecord;
use crate::kalman;
use dynocomp_core::image::{CoeffImage, DesignMethod};

/// Format tag of the model sidecar.
pub const SIDECAR_FORMAT: &str = "dynocomp-model/1";

/// One pole-residue term of a sidecar model (rad/s).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum TermJson {
    /// Real pole p (rad/s) with real residue r (rad/s).
    Real {
        /// Pole (rad/s).
        pole: f64,
        /// Residue (rad/s).
        residue: f64,
    },
    /// Complex pair: the pole with Im > 0 and its residue, as [re, im] (rad/s).
    Pair {
        /// Pole [re, im] (rad/s).
        pole: [f64; 2],
        /// Residue [re, im] (rad/s).
        residue: [f64; 2],
    },
}

/// The fitted sensor model G(s) of one axis.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AxisModelJson {
    /// Axis letter (x, y, z).
    pub axis: String,
    /// Direct term d (N/N).
    pub d: f64,
    /// Pole-residue terms.
    pub terms: Vec<TermJson>,
    /// The discrete model of the design (absent in older sidecars: FOH).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub discrete: Option<DiscreteModel>,
    /// Both states of a design from two FRFs (`design --frf A --frf B`,
    /// issue #15; absent otherwise and in older sidecars).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub two_state: Option<crate::two_state::TwoStateJson>,
    /// The harmonic force prior of `compensate --offline` (`design
    /// --force-prior harmonics`; absent otherwise and in older sidecars).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub force_prior: Option<crate::force_prior::HarmonicPrior>,
    /// The record's force spectrum q was chosen for (`design --force-prior
    /// spectrum`; absent otherwise and in older sidecars).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub force_spectrum: Option<crate::force_spectrum::SpectrumProvenance>,
}

/// The sidecar's terms of a pole-residue model.
pub fn terms_to_json(m: &PoleResidueModel) -> Vec<TermJson> {
    m.terms
        .iter()
        .map(|t| match *t {
            Term::Real { pole, residue } => TermJson::Real { pole, residue },
            Term::Pair { pole, residue } => TermJson::Pair { pole: [pole.re, pole.im], residue: [residue.re, residue.im] },
        })
        .collect()
}

/// The pole-residue model of sidecar terms, validated (finite, stable poles
/// with Im > 0); the error names `source` and axis `name`.
pub fn model_from_json(d: f64, terms: &[TermJson], source: &str, name: &str) -> Result<PoleResidueModel> {
    let model = PoleResidueModel {
        terms: terms
            .iter()
            .map(|t| match t {
                TermJson::Real { pole, residue } => Term::Real { pole: *pole, residue: *residue },
                TermJson::Pair { pole, residue } => Term::Pair {
                    pole: Complex64::new(pole[0], pole[1]),
                    residue: Complex64::new(residue[0], residue[1]),
                },
            })
            .collect(),
        d,
    };
    let finite = d.is_finite()
        && terms.iter().all(|t| match t {
            TermJson::Real { pole, residue } => pole.is_finite() && residue.is_finite(),
            TermJson::Pair { pole, residue } => pole.iter().chain(residue).all(|v| v.is_finite()) && pole[1] > 0.0,
        });
    if !finite || !model.is_stable() {
        bail!("{source}: axis {name}: the model has non-finite values or unstable poles; re-run `dynocomp design`");
    }
    Ok(model)
}

/// The sidecar `<image>.model.json` written by `dynocomp design`: the fitted
/// model per axis, tied to one image.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModelSidecar {
    /// Always [`SIDECAR_FORMAT`].
    pub format: String,
    /// Id (CRC-32, 8 hex digits) of the image this model belongs to.
    pub image_id: String,
    /// SHA-256 of the source FRF file (hex), as in the image.
    pub source_sha256: String,
    /// Sample rate of the image (Hz).
    pub fs_hz: f64,
    /// Models per axis.
    pub axes: Vec<AxisModelJson>,
}

/// Path of the model sidecar of an image: `<image>.model.json`.
pub fn sidecar_path(image: &Path) -> PathBuf {
    let mut s = image.as_os_str().to_owned();
    s.push(".model.json");
    PathBuf::from(s)
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

impl ModelSidecar {
    /// Sidecar for `image` with the given per-axis models `(axis, model)`.
    pub fn new(image: &CoeffImage, models: &[(usize, &PoleResidueModel, Option<&DiscreteModel>)]) -> Self {
        let axes = models
            .iter()
            .map(|(axis, m, dm)| AxisModelJson {
                discrete: dm.cloned(),
                axis: axis_name(*axis).to_string(),
                d: m.d,
                terms: terms_to_json(m),
                two_state: None,
                force_prior: None,
                force_spectrum: None,
            })
            .collect();
        ModelSidecar {
            format: SIDECAR_FORMAT.into(),
            image_id: format!("{:08x}", image.id()),
            source_sha256: hex(&image.source_sha256),
            fs_hz: f64::from(image.fs_hz),
            axes,
        }
    }

    /// The model of `axis`, validated (finite, stable poles with Im ≥ 0).
    pub fn model(&self, axis: usize, source: &str) -> Result<PoleResidueModel> {
        let name = axis_name(axis);
        let Some(a) = self.axes.iter().find(|a| a.axis == name) else {
            bail!("{source}: no model for axis {name}; re-run `dynocomp design` for this axis");
        };
        model_from_json(a.d, &a.terms, source, name)
    }

    /// The discrete model of `axis` for the smoother: the stored one,
    /// validated (finite, poles inside the unit circle, a short advance), or
    /// the first-order hold of Ĝ(s) for a sidecar that has none.
    pub fn discrete_model(&self, axis: usize, source: &str) -> Result<DiscreteModel> {
        let model = self.model(axis, source)?;
        let name = axis_name(axis);
        let stored = self.axes.iter().find(|a| a.axis == name).and_then(|a| a.discrete.clone());
        let Some(dm) = stored else {
            return Ok(discretize(&model, self.fs_hz, Discretization::Foh, (0.0, 0.0))?.0);
        };
        let finite = dm.d.is_finite()
            && dm.fir.iter().all(|v| v.is_finite())
            && dm.terms.iter().all(|t| match *t {
                crate::discretize::DTerm::Real { pole, residue } => pole.is_finite() && residue.is_finite(),
                crate::discretize::DTerm::Pair { pole, residue } => [pole.0, pole.1, residue.0, residue.1].iter().all(|v| v.is_finite()),
            });
        if !finite || !(dm.pole_radius() < 1.0) || dm.fs_hz != self.fs_hz || dm.advance > 64 || dm.fir.len() > 64 {
            bail!("{source}: axis {name}: the discrete model is not valid (non-finite, unstable, another rate, or too long); re-run `dynocomp design`");
        }
        Ok(dm)
    }
}

/// Write the sidecar of `image` (at `image_path`) atomically.
pub fn write_sidecar(image_path: &Path, sidecar: &ModelSidecar) -> Result<()> {
    let path = sidecar_path(image_path);
    let text = serde_json::to_string_pretty(sidecar)?;
    crate::io::atomic::write_bytes_atomic(&path, text.as_bytes())
}

/// Read the sidecar of the image at `image_path` and check that it belongs
/// to `image` (id, source hash, rate).
pub fn read_sidecar(image_path: &Path, image: &CoeffImage) -> Result<ModelSidecar> {
    if image.method != DesignMethod::VectorFitting {
        bail!(
            "{}: --offline needs an image designed with the default method (vf): the smoother uses its discrete-time q and R and fitted model",
            image_path.display()
        );
    }
    let path = sidecar_path(image_path);
    let shown = path.display().to_string();
    let text = std::fs::read_to_string(&path).with_context(|| {
        format!("{shown}: cannot read the model sidecar that --offline needs (`dynocomp design` writes it next to the image)")
    })?;
    parse_sidecar(&text, &shown, image, image_path)
}

/// Parse the text of a model sidecar (shown as `shown` in errors) and check
/// that it belongs to `image`, stored at `image_path`: the pure part of
/// [`read_sidecar`].
pub fn parse_sidecar(text: &str, shown: &str, image: &CoeffImage, image_path: &Path) -> Result<ModelSidecar> {
    // serde_json's message quotes the offending value (an unknown `kind`),
    // which may hold newlines: escaped, so the error stays one line.
    let s: ModelSidecar = serde_json::from_str(text).map_err(|e| anyhow::anyhow!("{shown}: not a valid model sidecar: {}", one_line(&e.to_string())))?;
    if s.format != SIDECAR_FORMAT {
        bail!("{shown}: format `{}`, expected `{SIDECAR_FORMAT}`", one_line(&s.format));
    }
    let id = format!("{:08x}", image.id());
    if s.image_id != id || s.source_sha256 != hex(&image.source_sha256) || s.fs_hz != f64::from(image.fs_hz) {
        bail!(
            "{shown}: belongs to image {} (source {}), not to {} (image {id}); re-run `dynocomp design` to write both together",
            one_line(&s.image_id),
            one_line(s.source_sha256.get(..12).unwrap_or(&s.source_sha256)),
            image_path.display()
        );
    }
    Ok(s)
}

/// The steady-state fixed-interval smoother of one axis (module doc).
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
        if !(q > 0.0 && q.is_finite() && r > 0.0 && r.is_finite()) {
            bail!("smoother needs q > 0 and R > 0 (got q = {q}, R = {r}); the image's design summary holds them");
        }
        let plant = kalman::augmented_plant(dm, 0);
        let qm = &plant.g * plant.g.transpose() * q;
        let mut force_row = DVector::<f64>::zeros(plant.a.nrows());
        force_row[plant.n_plant] = 1.0;
        Self::from_plant(plant, &qm, force_row, r, dm.advance)
    }

    /// Build the smoother for the discrete model `dm` with the harmonic
    /// force prior `prior` (its q_bb and line intensities,
    /// [`crate::force_prior`]) and measurement noise R (N²).
    pub fn with_force_prior(dm: &DiscreteModel, prior: &crate::force_prior::HarmonicPrior, r: f64) -> Result<Self> {
        if !(prior.q_broadband > 0.0 && prior.q_broadband.is_finite() && r > 0.0 && r.is_finite()) {
            bail!("smoother needs q_bb > 0 and R > 0 (got q_bb = {}, R = {r})", prior.q_broadband);
        }
        let (plant, qm, force_row) = crate::force_prior::plant_with_prior(dm, prior);
        Self::from_plant(plant, &qm, force_row, r, dm.advance)
    }

    fn from_plant(plant: kalman::AugmentedPlant, qm: &DMatrix<f64>, force_row: DVector<f64>, r: f64, advance: usize) -> Result<Self> {
        let sol = kalman::solve_filter_dare(&plant.a, &plant.c, qm, r)?;
        let s = (plant.c.transpose() * &sol.p * &plant.c)[(0, 0)] + r;
        let k = &sol.p * &plant.c / s;
        let n = plant.a.nrows();
        let closed = &plant.a * (DMatrix::<f64>::identity(n, n) - &k * plant.c.transpose());
        let radius = closed.complex_eigenvalues().iter().map(|z| z.norm()).fold(0.0, f64::max);
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

    /// One forward step (module doc) from the prior x⁻_k (in `prior`, left
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

    /// One backward step (module doc) from λ̂_k (in `lambda_hat`, left
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
    /// innovation e_k and the force component of its prior x⁻_k (module
    /// doc: F̂_k|N = x⁻_k[F] − (P λ̃_k)[F]), so only those two are kept.
    /// [`SpilledForward`] is the same computation with those 16 bytes on
    /// disk.
    pub fn smooth(&self, y: &[f64]) -> Vec<f64> {
        // ỹ_k = y_{k−D}: D copies of y_0 in front; F̂_k for k < len(y).
        let d = if y.is_empty() { 0 } else { self.advance };
        let y_tilde = std::iter::repeat_n(y.first().copied().unwrap_or(0.0), d).chain(y.iter().copied());
        let n = self.a.nrows();
        let (mut prior, mut next) = (DVector::<f64>::zeros(n), DVector::<f64>::zeros(n));
        let (mut prior_force, mut innov): (Vec<f64>, Vec<f64>) = y_tilde.map(|yk| self.forward_step(&mut prior, &mut next, yk)).unzip();
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

/// Pairs (x⁻_k[F], e_k) per chunk of the spilled backward pass: 1 MiB.
const SPILL_CHUNK: usize = 1 << 16;

/// The smoother of one axis over a record of any length (issue #14,
/// "a backward pass over blocks spilled to a temporary file"): the
/// forward pass takes the record block by block and writes each sample's
/// x⁻_k[F] and e_k (16 bytes, f64) to an unnamed temporary file; then
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
/// drift smoother's [`crate::two_state::SpilledDriftForward`]).
pub trait SpilledPass {
    /// Take the next samples of y (N).
    fn push(&mut self, y: &[f64]) -> Result<()>;
    /// The backward pass: the estimates F̂_k|N of every sample taken, in a
    /// temporary file in `dir`. `on_chunk` is told the samples done (for a
    /// progress bar). Refuses a non-finite estimate, naming `name` and the
    /// sample.
    fn backward(self: Box<Self>, dir: &Path, name: &str, source: &str, on_chunk: &dyn Fn(u64)) -> Result<SpilledEstimate>;
}

/// Feed the block `y` to `step` as ỹ_k = y_{k−D} (the smoothers' delayed
/// measurement): in front of the record's first samples (`first`: nothing
/// taken yet), D = `advance` copies of y_0.
pub(crate) fn feed_delayed(y: &[f64], advance: usize, first: bool, mut step: impl FnMut(f64) -> Result<()>) -> Result<()> {
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

    fn backward(self: Box<Self>, dir: &Path, name: &str, source: &str, on_chunk: &dyn Fn(u64)) -> Result<SpilledEstimate> {
        SpilledForward::backward(*self, dir, name, source, on_chunk)
    }
}

impl<'s> SpilledForward<'s> {
    /// Start the forward pass; the temporary files go to `dir`.
    pub fn new(sm: &'s Smoother, dir: &Path) -> Result<Self> {
        let n = sm.a.nrows();
        let file = tempfile::tempfile_in(dir).with_context(|| format!("{}: cannot create a temporary file for the smoother's forward pass", dir.display()))?;
        Ok(SpilledForward { sm, prior: DVector::zeros(n), next: DVector::zeros(n), spill: std::io::BufWriter::with_capacity(1 << 20, file), n_y: 0, n_pairs: 0 })
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
        use std::io::{Read, Seek, SeekFrom, Write};
        let io_err = |e: std::io::Error| anyhow::anyhow!("{}: temporary file of the smoother: {e}", dir.display());
        let mut spill = self.spill.into_inner().map_err(|e| io_err(e.into_error()))?;
        let mut out = tempfile::tempfile_in(dir).map_err(io_err)?;
        let n_pairs = usize::try_from(self.n_pairs).map_err(|_| anyhow::anyhow!("{source}: record too long"))?;
        let n_y = self.n_y as usize;
        let p_row = self.sm.p_row();
        let mut lambda_hat = DVector::<f64>::zeros(self.sm.a.nrows());
        let mut bytes = vec![0u8; 16 * SPILL_CHUNK];
        let mut est = Vec::with_capacity(SPILL_CHUNK);
        let mut hi = n_pairs;
        while hi > 0 {
            let lo = hi.saturating_sub(SPILL_CHUNK);
            let buf = &mut bytes[..16 * (hi - lo)];
            spill.seek(SeekFrom::Start(16 * lo as u64)).map_err(io_err)?;
            spill.read_exact(buf).map_err(io_err)?;
            est.clear();
            for k in (lo..hi).rev() {
                let pair = &buf[16 * (k - lo)..16 * (k - lo + 1)];
                let f = f64::from_le_bytes(pair[..8].try_into().unwrap_or_default());
                let e = f64::from_le_bytes(pair[8..].try_into().unwrap_or_default());
                let v = self.sm.backward_step(&mut lambda_hat, &p_row, f, e);
                if k < n_y && !v.is_finite() {
                    bail!("{source}: smoothed {name} became non-finite at sample {k}");
                }
                est.push(v);
            }
            // est holds F̂_{hi−1} … F̂_lo; keep k < n_y, in order.
            let keep_hi = hi.min(n_y);
            if lo < keep_hi {
                let mut chunk: Vec<u8> = Vec::with_capacity(8 * (keep_hi - lo));
                for v in est[hi - keep_hi..].iter().rev() {
                    chunk.extend_from_slice(&v.to_le_bytes());
                }
                out.seek(SeekFrom::Start(8 * lo as u64)).map_err(io_err)?;
                out.write_all(&chunk).map_err(io_err)?;
                on_chunk((keep_hi - lo) as u64);
            }
            hi = lo;
        }
        SpilledEstimate::new(out, self.n_y).map_err(io_err)
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

/// The smoother of `axis` (0 = x): the sidecar's discrete model, q and R
/// from the image.
pub fn axis_smoother(image: &CoeffImage, sidecar: &ModelSidecar, axis: usize, source: &str) -> Result<Smoother> {
    let a = image_axis(image, axis, source)?;
    let dm = sidecar.discrete_model(axis, source)?;
    Smoother::new(&dm, a.summary.q, a.summary.r).with_context(|| format!("{source}: axis {}", axis_name(axis)))
}

/// `compensate --offline`: smooth every force column of `rec` with the
/// model of its axis from the sidecar and q, R from the image.
pub fn smooth_record(image: &CoeffImage, sidecar: &ModelSidecar, rec: &SignalRecord, source: &str) -> Result<SignalRecord> {
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
                crate::force_prior::check_record(p, y, &|f| model.frf(f), a.summary.r)
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
