//! The arguments `design` and `compare` share, as clap parses them, and
//! their conversion into the library's options.

use anyhow::{bail, Context, Result};
use clap::Args;
use std::path::PathBuf;

use crate::design::axis::{DesignOptions, FitMethod};
use crate::design::bands::{Band, BandSpec};
use crate::design::discretize::Discretization;
use crate::design::force_spectrum::ForceRecord;
use crate::fit::rfp::RfpOptions;
use crate::frf::Frf;

/// Design method (`--method`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum Method {
    // Vector fitting and the fixed-lag Kalman smoother (the default); the
    // seed paper's method. Plain comments: `--method`'s help lists the values.
    #[default]
    Vf,
    Paper,
}

impl Method {
    /// Its name on the command line and in summaries.
    pub fn name(self) -> &'static str {
        match self {
            Method::Vf => "vf",
            Method::Paper => "paper",
        }
    }
}

/// Discrete model of the Kalman design (`--discretization`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum DiscretizationArg {
    /// Fit on the unit circle to the sampled-data relation (README "Discrete model")
    #[default]
    Fit,
    /// First-order hold: force linear between samples
    Foh,
    /// Zero-order hold: force constant over each sample
    Zoh,
}

impl From<DiscretizationArg> for Discretization {
    fn from(d: DiscretizationArg) -> Self {
        match d {
            DiscretizationArg::Fit => Discretization::Fit,
            DiscretizationArg::Foh => Discretization::Foh,
            DiscretizationArg::Zoh => Discretization::Zoh,
        }
    }
}

/// Fitting bands (paper §3.2), shared by `design` and `compare`.
#[derive(Args, Debug, Clone, Default)]
pub struct BandArgs {
    /// Spindle speed (rev/min): with --teeth, bands around the tooth-passing
    /// frequency rpm/60·Z and its harmonics.
    #[arg(long, requires = "teeth")]
    pub spindle_rpm: Option<f64>,
    /// Number of teeth Z of the cutter (with --spindle-rpm).
    #[arg(long, requires = "spindle_rpm")]
    pub teeth: Option<u32>,
    /// Harmonics of the tooth-passing frequency to fit (1 = TPF only).
    #[arg(long, default_value_t = 4)]
    pub harmonics: u32,
    /// Half-width of each harmonic band, relative to its centre frequency.
    #[arg(long, default_value_t = 0.1)]
    pub band_width: f64,
    /// A fitting band LO:HI in Hz (repeatable).
    #[arg(long = "band", value_name = "LO:HI")]
    pub band: Vec<String>,
    /// Find the bands a posteriori from the spectrum of this measured force
    /// record (signal CSV), including non-harmonic peaks such as chatter.
    #[arg(long, value_name = "RECORD")]
    pub bands_from: Option<PathBuf>,
}

impl BandArgs {
    /// The library's band specification of these flags (the record of
    /// `--bands-from` checked against the default full scale).
    pub fn spec(&self) -> BandSpec {
        BandSpec {
            max_force_n: None,
            tooth_passing: self.spindle_rpm.zip(self.teeth),
            harmonics: self.harmonics,
            band_width: self.band_width,
            bands: self.band.clone(),
            bands_from: self.bands_from.clone(),
        }
    }

    /// Tooth-passing frequency (Hz), when --spindle-rpm and --teeth are given.
    pub fn tooth_passing_hz(&self) -> Option<f64> {
        self.spec().tooth_passing_hz()
    }

    /// The validated bands for this FRF and sample rate ([`BandSpec::resolve`]),
    /// the record of `--bands-from` within ±`max_force_n` (N).
    pub fn resolve(&self, frf: &Frf, fs_hz: f64, max_force_n: f64) -> Result<Vec<Band>> {
        BandSpec { max_force_n: Some(max_force_n), ..self.spec() }.resolve(frf, fs_hz)
    }
}

/// The force model of the offline estimate (`--force-prior`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum ForcePrior {
    /// The random walk of the default design: safe for chatter and transients.
    #[default]
    Default,
    /// Tooth-passing and runout harmonics of --spindle-rpm in the Kalman
    /// state of `compensate --offline`, tuned from --force-record
    /// (README "Force priors"); the box image stays the default design.
    Harmonics,
    /// q of the box design chosen for the force spectrum of --force-record
    /// instead of a flat spectrum of --force-rms (README "Force priors"):
    /// the same filter structure and cost, tuned for the cut.
    Spectrum,
    /// q of the box design chosen for a flat force spectrum at the in-band
    /// force level of --force-record instead of --force-rms: predicted
    /// errors for the cut's force, as robust to chatter as the default.
    Level,
}

/// The opt-in harmonic force prior.
#[derive(Args, Debug, Clone, Default)]
pub struct PriorArgs {
    /// Force model: `default` (random walk, q for a flat force spectrum of
    /// --force-rms), `harmonics` (the spindle harmonics of
    /// --spindle-rpm/--teeth in the Kalman state of `compensate --offline`,
    /// tuned from --force-record; the box image is unchanged; --spindle-rpm
    /// then makes no fitting bands), `spectrum` (q of the box image and of
    /// the offline smoother chosen for the force spectrum of --force-record)
    /// or `level` (q for a flat spectrum at the record's in-band force level
    /// instead of --force-rms: honest predicted errors, as safe for chatter
    /// as the default). With all nine FRFs, `spectrum` and `level` also
    /// count the record's mean force, which the static crosstalk carries
    /// into the other axes.
    #[arg(long, value_enum, default_value_t = ForcePrior::Default)]
    pub force_prior: ForcePrior,
    /// A representative record of the cut (signal CSV, same rate, raw
    /// measured forces, a column per designed axis): the harmonics'
    /// amplitudes or the force spectrum are measured in it.
    #[arg(long, value_name = "FILE")]
    pub force_record: Option<PathBuf>,
    /// Bandwidth of each harmonic line of the prior (Hz; default a quarter
    /// of the spindle frequency).
    #[arg(long, value_name = "HZ")]
    pub line_width: Option<f64>,
}

/// The paper's method (`--method paper`).
#[derive(Args, Debug, Clone)]
pub struct PaperArgs {
    /// Numerator and denominator orders NB:NA of the paper's fit (eq. (1)).
    /// Default: chosen per axis, the highest orders that keep the fit stable
    /// and the augmented system observable and well-conditioned, with the
    /// best in-band fit (the summary says which and why).
    #[arg(long, value_name = "NB:NA")]
    pub paper_orders: Option<String>,
    /// Tustin prewarp frequency (Hz); default: the tooth-passing frequency if
    /// given, else the centre of the fitted band.
    #[arg(long)]
    pub prewarp_hz: Option<f64>,
}

impl PaperArgs {
    /// Whether the orders are chosen per axis (no --paper-orders).
    pub fn auto(&self) -> bool {
        self.paper_orders.is_none()
    }

    /// Parse --paper-orders (6:8, the paper's, when not given: the largest
    /// orders of parallel elaboration's per-segment search).
    pub fn orders(&self) -> Result<(usize, usize)> {
        let Some(text) = &self.paper_orders else { return Ok((6, 8)) };
        let bad =
            || anyhow::anyhow!("--paper-orders `{text}`: expected NB:NA, e.g. 6:8 (numerator ≤ denominator order)");
        let (nb, na) = text.split_once(':').ok_or_else(bad)?;
        let (nb, na): (usize, usize) = (nb.trim().parse().map_err(|_| bad())?, na.trim().parse().map_err(|_| bad())?);
        if na == 0 || nb > na || na > 40 {
            return Err(bad());
        }
        Ok((nb, na))
    }

    /// The fit method for these arguments (`tooth_passing_hz` is the default prewarp).
    pub fn method(&self, tooth_passing_hz: Option<f64>, fs_hz: f64) -> Result<FitMethod> {
        let (nb, na) = self.orders()?;
        let prewarp_hz = self.prewarp_hz.or(tooth_passing_hz);
        if let Some(p) = prewarp_hz {
            if !(p > 0.0 && p < fs_hz / 2.0) {
                bail!("--prewarp-hz {p}: must lie between 0 and the Nyquist frequency {} Hz", fs_hz / 2.0);
            }
        }
        Ok(FitMethod::Paper { rfp: RfpOptions { nb, na, ..Default::default() }, prewarp_hz })
    }
}

/// The inputs `design` and `compare` share: the measured FRF, the box's
/// sample rate, the noise model and the assumptions of the Q criterion.
#[derive(Args, Debug, Clone)]
pub struct DesignInputArgs {
    /// Measured FRF: UFF58 (.uff/.unv) or CSV (README "File formats",
    /// docs/frf-matrix.md). With `design` only, give it twice for a set-up
    /// in two states (before and after machining; README "Two states").
    #[arg(long, required = true)]
    pub frf: Vec<PathBuf>,
    /// Sample rate of the box (Hz).
    #[arg(long)]
    pub fs: f64,
    /// Idle record (cutting without engagement, signal CSV): R per axis is its variance.
    #[arg(long, conflicts_with = "noise_variance")]
    pub idle: Option<PathBuf>,
    /// Measurement-noise variance R (N²), for all axes.
    #[arg(long)]
    pub noise_variance: Option<f64>,
    /// Assumed RMS of the cutting force inside the band (N), for the Q criterion.
    #[arg(long, default_value_t = 100.0)]
    pub force_rms: f64,
    /// Upper limit of the compensator's white-noise gain.
    #[arg(long, default_value_t = 30.0)]
    pub max_noise_gain: f64,
    /// Discrete model of the Kalman design: `fit` (default: matched on the
    /// unit circle to the sampled-data relation of a band-limited chain up
    /// to 0.45 fs), or the hold equivalents `foh`/`zoh` for comparison.
    #[arg(long, value_enum, default_value_t = DiscretizationArg::Fit)]
    pub discretization: DiscretizationArg,
    /// Largest plausible force (N) in the records read (--idle,
    /// --force-record, --bands-from): the full scale of the charge
    /// amplifier or ADC. A value beyond ± this, or not finite, is an input
    /// error that names the sample.
    #[arg(long, default_value_t = crate::io::signal::DEFAULT_FULL_SCALE_N, value_name = "N")]
    pub max_force: f64,
}

impl DesignInputArgs {
    /// The (first) measured FRF.
    pub fn frf(&self) -> &std::path::Path {
        &self.frf[0]
    }

    /// `--fs` must be a whole number of Hz that an image can hold.
    /// `--force-rms` and `--max-noise-gain` must be positive, and the
    /// spindle of the bands a real one.
    pub fn check_values(&self, bands: &BandArgs) -> Result<()> {
        let fs = self.fs;
        if !(fs.is_finite() && (1_000.0..=1_000_000.0).contains(&fs) && fs.fract() == 0.0) {
            bail!("--fs {fs}: the sample rate must be a whole number of Hz in 1000..=1000000");
        }
        if !(self.force_rms.is_finite() && self.force_rms > 0.0) {
            bail!("--force-rms {}: the assumed in-band force must be a positive number of N", self.force_rms);
        }
        if !(self.max_noise_gain.is_finite() && self.max_noise_gain > 0.0) {
            bail!("--max-noise-gain {}: must be a positive number", self.max_noise_gain);
        }
        check_spindle(bands.spindle_rpm, bands.teeth)
    }

    /// R per axis (N²) from `--idle` (sampled at `--fs`, values within
    /// `--max-force`) or `--noise-variance`.
    pub fn noise_variances(&self, frf: &Frf) -> Result<[Option<f64>; 3]> {
        let max_force = crate::io::signal::check_max_force(self.max_force)?;
        let checks = crate::design::noise::IdleChecks { fs_hz: Some(self.fs), full_scale_n: max_force };
        crate::design::noise::noise_variances_checked(self.idle.as_deref(), self.noise_variance, frf, &checks)
    }
}

/// Arguments of `dynocomp design` (DESIGN.md, CLI contract).
#[derive(Args, Debug, Clone)]
pub struct DesignArgs {
    /// The FRF, sample rate, noise and Q-criterion inputs.
    #[command(flatten)]
    pub input: DesignInputArgs,
    /// Output coefficient image (.dcimg), written atomically.
    #[arg(long)]
    pub out: PathBuf,
    /// Declared output latency L (samples): the fixed lag of the smoother.
    /// Without it the design starts at 4 and takes up to 8 where that
    /// predicts a clearly smaller error (README "Latency"); the paper's
    /// method has no lag and accepts only 0.
    #[arg(long)]
    pub latency: Option<usize>,
    /// Highest model order the fit may use.
    #[arg(long, default_value_t = 24)]
    pub max_order: usize,
    /// Force at ADC/DAC full scale (N, 0.01 to 1e7): ±full scale maps to
    /// codes 0..4095.
    #[arg(long, default_value_t = 5000.0)]
    pub full_scale: f64,
    /// Design method: `vf` (default: vector fitting, fixed-lag Kalman
    /// smoother) or `paper` (the seed paper: RFP + Gauss–Newton, continuous
    /// Riccati, Tustin with prewarping).
    #[arg(long, value_enum, default_value_t = Method::Vf)]
    pub method: Method,
    /// Options of `--method paper`.
    #[command(flatten)]
    pub paper: PaperArgs,
    /// Fitting bands.
    #[command(flatten)]
    pub bands: BandArgs,
    /// The opt-in force prior of the offline estimate.
    #[command(flatten)]
    pub prior: PriorArgs,
    /// Parallel elaboration (paper §3.3, offline only): one compensator per
    /// band in one image (format 2) that `compensate` runs band by band
    /// after a zero-phase split; the box never runs it. Needs bands.
    #[arg(long)]
    pub parallel: bool,
    /// Write plots and an index.html into this directory.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Print the summary as JSON on stdout.
    #[arg(long)]
    pub json: bool,
    /// Largest predicted CPU load of the box's sample interrupt (% of the
    /// sample period at 170 MHz, pessimistic estimate), at most the box's
    /// own 60 %. The realizations within it are preferred; a 3x3 filter
    /// above it is reduced to fit where every axis still beats its per-axis
    /// design. An image above it is still written, marked offline-only.
    #[arg(long, default_value_t = 60.0, value_name = "PCT")]
    pub max_load: f64,
    /// 3x3 design: keep the full filter where it is over the load limit
    /// (written offline-only) instead of reducing it to one the box runs.
    /// `compensate --offline` uses the full model either way.
    #[arg(long)]
    pub full_order: bool,
    /// 3x3 design: fit each entry's residues freely instead of holding each
    /// mode's nine residues to one mode shape (rank one) where the lines
    /// allow it. For comparison, or for a structure whose repeated modes the
    /// fit does not catch (docs/frf-matrix.md).
    #[arg(long)]
    pub free_residues: bool,
    /// Design each axis from its direct FRF alone even when the FRF file
    /// holds all nine entries: crosstalk is not compensated. Without it a
    /// complete matrix gets the 3x3 design (README "Crosstalk").
    #[arg(long)]
    pub per_axis: bool,
    /// What the compensator writes above its band: `quiet` (default: the
    /// force modelled as band-limited and q chosen with the noise above
    /// the band counted, so the output as written carries little more noise
    /// there than the raw signal), or `inverse` (the exact inverse goes on
    /// above the band with its amplified noise: low-pass the output to the
    /// band before reading it). Band-fitted and paper designs, and designs
    /// with --force-prior, are `inverse`.
    #[arg(long, value_enum, default_value_t = AboveBandArg::Quiet)]
    pub above_band: AboveBandArg,
    /// Refuse the image when an axis cannot be compensated. Without it such
    /// an axis of the default design is passed through raw (its measured
    /// force, delayed by the latency), with a warning that gives the reason,
    /// and the other axes are compensated. Designs with --method paper,
    /// fitting bands or --force-prior refuse in any case.
    #[arg(long)]
    pub strict: bool,
}

/// What the compensator outputs above its band (`--above-band`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum AboveBandArg {
    /// Band-limited force model; the noise above the band counted in q's choice
    #[default]
    Quiet,
    /// The exact inverse continued above the band
    Inverse,
}

impl From<AboveBandArg> for crate::design::above_band::AboveBand {
    fn from(a: AboveBandArg) -> Self {
        match a {
            AboveBandArg::Quiet => Self::Quiet,
            AboveBandArg::Inverse => Self::Inverse,
        }
    }
}

impl DesignArgs {
    /// The design options every `design` run shares: rate, latency, the Q
    /// criterion's inputs, the fit's highest order and the discretization.
    pub fn base_options(&self, latency: usize) -> DesignOptions {
        DesignOptions {
            fs_hz: self.input.fs,
            lag: latency,
            force_rms: self.input.force_rms,
            max_noise_gain: self.input.max_noise_gain,
            vf: crate::fit::vf::VfOptions {
                max_order: self.max_order,
                rank_one_residues: !self.free_residues,
                ..Default::default()
            },
            discretization: self.input.discretization.into(),
            above_band: self.above_band.into(),
            ..Default::default()
        }
    }
}

/// `design`'s arguments for one FRF, validated: what one design run needs.
pub struct DesignSetup {
    /// The measured FRF and the SHA-256 of its file.
    pub frf: Frf,
    /// SHA-256 of the FRF file, recorded in the image.
    pub sha: [u8; 32],
    /// R per axis (N²).
    pub r: [Option<f64>; 3],
    /// The fitting bands (empty: the whole coherent band).
    pub bands: Vec<Band>,
    /// The options every axis is designed with.
    pub opts: DesignOptions,
    /// The declared latency (samples), or where its choice starts.
    pub latency: usize,
    /// The latency is chosen by the design (no `--latency`, default method).
    pub auto_latency: bool,
    /// The box's load limit (‰ of the sample period).
    pub limit_permille: u32,
}

impl DesignSetup {
    /// Validate `args` (one `--frf`) and read the FRF, R and the force record.
    pub fn new(args: &DesignArgs) -> Result<Self> {
        let paper = args.method == Method::Paper;
        let latency = match (paper, args.latency) {
            (true, Some(l)) if l != 0 => bail!("--latency {l}: the paper's method (a Kalman filter, not a smoother) has no lag; omit --latency or give 0"),
            (true, _) => 0,
            (false, l) => l.unwrap_or(crate::design::latency::DEFAULT_LATENCY),
        };
        args.input.check_values(&args.bands)?;
        if latency > 16 {
            bail!("--latency {}: at most 16 samples", latency);
        }
        let box_limit = f64::from(dynocomp_core::budget::BOX_LOAD_LIMIT_PERMILLE) / 10.0;
        if !(args.max_load > 0.0 && args.max_load <= box_limit) {
            bail!("--max-load {}: the load limit must be above 0 and at most the box's {box_limit} %", args.max_load);
        }
        let limit_permille = (args.max_load * 10.0).floor() as u32;
        let path = args.input.frf();
        let (frf, sha) = crate::io::read_frf_arg(path)?;
        let r = args.input.noise_variances(&frf)?;
        // With the harmonic prior, --spindle-rpm/--teeth place the prior's
        // lines, not fitting bands: the design covers the whole band.
        let mut spec = BandSpec { max_force_n: Some(args.input.max_force), ..args.bands.spec() };
        if args.prior.force_prior == ForcePrior::Harmonics {
            spec.tooth_passing = None;
        }
        let bands = spec.resolve(&frf, args.input.fs).with_context(|| format!("{}", path.display()))?;
        let method =
            if paper { args.paper.method(args.bands.tooth_passing_hz(), args.input.fs)? } else { FitMethod::Vf };
        let axis_budget =
            dynocomp_core::budget::axis_budget(args.input.fs as u32, limit_permille, frf.axes.len().max(1) as u32);
        let opts = DesignOptions {
            method,
            bands: bands.clone(),
            paper_orders_auto: paper && args.paper.auto(),
            axis_cycle_budget: Some(axis_budget),
            force_record: force_record(args)?,
            force_record_level_only: args.prior.force_prior == ForcePrior::Level,
            order_search_progress: Some(crate::design::progress::Progress::stderr()),
            ..args.base_options(latency)
        };
        // Without --latency, the default method's latency is chosen (crate::design::latency).
        let auto_latency = !paper && args.latency.is_none() && !args.parallel;
        Ok(DesignSetup { frf, sha, r, bands, opts, latency, auto_latency, limit_permille })
    }
}

/// Most teeth of a cutter `--teeth` takes.
pub const MAX_TEETH: u32 = 100;
/// Fastest spindle `--spindle-rpm` takes (rev/min).
pub const MAX_SPINDLE_RPM: f64 = 200_000.0;

/// `--spindle-rpm` in (0, 200000] and `--teeth` in 1..=100, where given.
pub fn check_spindle(rpm: Option<f64>, teeth: Option<u32>) -> Result<()> {
    if let Some(r) = rpm {
        if !(r.is_finite() && r > 0.0 && r <= MAX_SPINDLE_RPM) {
            bail!("--spindle-rpm {r}: the spindle speed must be above 0 and at most {MAX_SPINDLE_RPM} rev/min");
        }
    }
    if let Some(z) = teeth {
        if !(1..=MAX_TEETH).contains(&z) {
            bail!("--teeth {z}: a cutter has 1 to {MAX_TEETH} teeth");
        }
    }
    Ok(())
}

/// Refuse an `--out` (or its model sidecar) that is one of the inputs:
/// writing it would destroy that input.
pub fn check_outputs_are_not_inputs(args: &DesignArgs) -> Result<()> {
    let sidecar = crate::offline::sidecar::sidecar_path(&args.out);
    let outputs = [("--out", args.out.as_path()), ("the model sidecar of --out", sidecar.as_path())];
    let mut inputs: Vec<(&str, &std::path::Path)> = args.input.frf.iter().map(|p| ("--frf", p.as_path())).collect();
    inputs.extend(args.input.idle.as_deref().map(|p| ("--idle", p)));
    inputs.extend(args.bands.bands_from.as_deref().map(|p| ("--bands-from", p)));
    inputs.extend(args.prior.force_record.as_deref().map(|p| ("--force-record", p)));
    crate::io::atomic::ensure_not_an_input(&outputs, &inputs)
}

/// Range of `--full-scale` (N): from a micro-dynamometer's few newtons to
/// far beyond any table dynamometer; the image's f32 scaling holds both.
pub const FULL_SCALE_RANGE_N: std::ops::RangeInclusive<f64> = 0.01..=1.0e7;

/// Check the force-prior flags against the rest, and `--full-scale`
/// (before anything is read).
pub fn check_prior_flags(args: &DesignArgs) -> Result<()> {
    args.input.check_values(&args.bands)?;
    if !FULL_SCALE_RANGE_N.contains(&args.full_scale) {
        bail!(
            "--full-scale {}: the force at the box's ADC and DAC full scale must be a number of N in {}..={:e}",
            args.full_scale,
            FULL_SCALE_RANGE_N.start(),
            FULL_SCALE_RANGE_N.end()
        );
    }
    match args.prior.force_prior {
        ForcePrior::Harmonics => check_prior_args(args),
        ForcePrior::Spectrum | ForcePrior::Level => check_spectrum_args(args),
        ForcePrior::Default if args.prior.force_record.is_some() || args.prior.line_width.is_some() => {
            bail!("--force-record belongs to --force-prior harmonics, spectrum or level, --line-width to --force-prior harmonics")
        }
        ForcePrior::Default => Ok(()),
    }
}

/// The representative record of `--force-prior spectrum` or `level`, read
/// before anything is designed.
fn force_record(args: &DesignArgs) -> Result<Option<std::sync::Arc<ForceRecord>>> {
    if !matches!(args.prior.force_prior, ForcePrior::Spectrum | ForcePrior::Level) {
        return Ok(None);
    }
    let path = args.prior.force_record.as_ref().expect("checked by check_spectrum_args");
    let rec = read_force_record(path, args.input.fs, args.input.max_force)?;
    let channels = [0, 1, 2].map(|a| rec.channel(a).map(|c| c.to_vec()));
    Ok(Some(std::sync::Arc::new(ForceRecord { source: path.display().to_string(), channels })))
}

/// The conditions of `--force-prior harmonics`: one FRF, the default
/// method, no parallel elaboration, a spindle speed, teeth and a record.
fn check_prior_args(args: &DesignArgs) -> Result<()> {
    if args.input.frf.len() != 1 || args.method != Method::Vf || args.parallel {
        bail!("--force-prior harmonics works with one --frf and the default method (vf), without --parallel: it shapes the offline smoother of a box design");
    }
    if args.bands.spindle_rpm.is_none() || args.bands.teeth.is_none() {
        bail!("--force-prior harmonics needs --spindle-rpm RPM and --teeth Z (where the harmonics are)");
    }
    if args.prior.force_record.is_none() {
        bail!("--force-prior harmonics needs --force-record FILE: a representative measured record of the cut, to tune the harmonics' intensities");
    }
    Ok(())
}

/// The conditions of `--force-prior spectrum` and `level`: one FRF, the
/// default method, no parallel elaboration, a record, no line width.
fn check_spectrum_args(args: &DesignArgs) -> Result<()> {
    let name = if args.prior.force_prior == ForcePrior::Level { "level" } else { "spectrum" };
    if args.input.frf.len() != 1 || args.method != Method::Vf || args.parallel {
        bail!("--force-prior {name} works with one --frf and the default method (vf), without --parallel");
    }
    if args.prior.force_record.is_none() {
        bail!("--force-prior {name} needs --force-record FILE: a representative measured record of the cut, whose in-band force {name} q is chosen for");
    }
    if args.prior.line_width.is_some() {
        bail!("--line-width belongs to --force-prior harmonics");
    }
    Ok(())
}

/// Read a representative record (`--force-record`) sampled at `fs_hz`,
/// its values within ±`full_scale_n` (N).
pub fn read_force_record(
    path: &std::path::Path,
    fs_hz: f64,
    full_scale_n: f64,
) -> Result<crate::io::signal_csv::SignalRecord> {
    let rec = crate::io::signal_csv::read_signal_csv_checked(path, full_scale_n)?;
    if let Some(found) = rec.sample_rate_from_time() {
        let why = "record the cut at the box's rate";
        crate::io::signal::check_rate_against_fs(found, fs_hz, &path.display().to_string(), why)?;
    }
    // A clipped record's spectrum is not the cut's: say so, design anyway.
    for c in crate::io::clipping::Extremes::of_channels(&rec.channels).clipped() {
        eprintln!("{}", c.warning(&path.display().to_string(), "the force spectrum taken from it is not the cut's"));
    }
    Ok(rec)
}
