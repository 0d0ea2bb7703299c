//! The `dynocomp design` command: arguments, per-axis design with progress,
//! image, summary (text or JSON) and optional report.

use anyhow::{bail, Context, Result};
use clap::Args;
use dynocomp_core::image::{AxisImage, AxisScaling, AxisSummary, CoeffImage, DesignMethod};
use serde::Serialize;
use sha2::{Digest, Sha256};
use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;

use crate::bands::{self, Band};
use crate::design::{AxisDesign, DesignOptions, FitMethod};
use crate::discretize::{Discretization, MATCH_BAND_FRACTION};
use crate::fit::rfp::RfpOptions;
use crate::frf::{axis_name, Frf};
use crate::io;
use crate::paper::PaperDiagnostics;

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
    /// Tooth-passing frequency (Hz), when --spindle-rpm and --teeth are given.
    pub fn tooth_passing_hz(&self) -> Option<f64> {
        Some(bands::tooth_passing_hz(self.spindle_rpm?, self.teeth?))
    }

    /// The validated bands for this FRF and sample rate (empty = whole band).
    /// With any band, a static band from the first FRF line up to a quarter
    /// of the lowest band is added: the mean cutting force needs it, and the
    /// Kalman filter's force state is only observable through G(0).
    pub fn resolve(&self, frf: &Frf, fs_hz: f64) -> Result<Vec<Band>> {
        let max_hz = frf.freq_hz[frf.freq_hz.len() - 1].min(MATCH_BAND_FRACTION * fs_hz);
        let mut out = Vec::new();
        if let (Some(rpm), Some(z)) = (self.spindle_rpm, self.teeth) {
            out.extend(bands::from_tooth_passing(rpm, z, self.harmonics, self.band_width, max_hz)?);
        }
        for b in &self.band {
            out.push(bands::parse_band(b)?);
        }
        if let Some(path) = &self.bands_from {
            let rec = io::signal_csv::read_signal_csv(path)?;
            let rate = match rec.sample_rate_from_time() {
                Some((r, _)) => r,
                None => fs_hz,
            };
            for (axis, x) in &rec.channels {
                let found = bands::from_record_spectrum(x, rate, max_hz, &bands::SpectrumPeakOptions::default())
                    .with_context(|| format!("{}: column f{}", path.display(), axis_name(*axis)))?;
                out.extend(found.into_iter().map(|b| Band { label: format!("f{} {}", axis_name(*axis), b.label), ..b }));
            }
        }
        if out.is_empty() {
            return Ok(out);
        }
        let n = frf.freq_hz.len();
        let first = frf.freq_hz[0];
        let lowest = out.iter().map(|b| b.lo_hz).fold(f64::INFINITY, f64::min);
        let static_hi = (0.25 * lowest).max(frf.freq_hz[4.min(n - 1)]);
        out.push(Band { lo_hz: first, hi_hz: static_hi, label: "static".into() });
        let spacing = (frf.freq_hz[n - 1] - first) / (n - 1) as f64;
        bands::validate(out, max_hz, 3.0 * spacing)
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
    /// (`crate::force_prior`); the box image stays the default design.
    Harmonics,
    /// q of the box design chosen for the force spectrum of --force-record
    /// instead of a flat spectrum of --force-rms (`crate::force_spectrum`):
    /// the same filter structure and cost, tuned for the cut.
    Spectrum,
    /// q of the box design chosen for a flat force spectrum at the in-band
    /// force level of --force-record instead of --force-rms: predicted
    /// errors for the cut's force, as robust to chatter as the default.
    Level,
}

/// The opt-in harmonic force prior (issue #12, optional part).
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
    /// as the default).
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
        let bad = || anyhow::anyhow!("--paper-orders `{text}`: expected NB:NA, e.g. 6:8 (numerator ≤ denominator order)");
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
    /// Measured FRF: UFF58 (.uff/.unv) or CSV. `design` takes it twice for
    /// a set-up in two states (before and after machining, issue #15).
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
    #[arg(long, value_enum, default_value_t = Discretization::Fit)]
    pub discretization: Discretization,
}

impl DesignInputArgs {
    /// The (first) measured FRF.
    pub fn frf(&self) -> &std::path::Path {
        &self.frf[0]
    }

    /// `--fs` must be a whole number of Hz that an image can hold.
    pub fn check_fs(&self) -> Result<()> {
        let fs = self.fs;
        if !(fs.is_finite() && (1_000.0..=1_000_000.0).contains(&fs) && fs.fract() == 0.0) {
            bail!("--fs {fs}: the sample rate must be a whole number of Hz in 1000..=1000000");
        }
        Ok(())
    }

    /// R per axis (N²) from `--idle` or `--noise-variance`.
    pub fn noise_variances(&self, frf: &Frf) -> Result<[Option<f64>; 3]> {
        noise_variances(self.idle.as_deref(), self.noise_variance, frf)
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
    /// Declared output latency L (samples): the fixed lag of the smoother
    /// (default 4; the paper's method has no lag and accepts only 0).
    #[arg(long)]
    pub latency: Option<usize>,
    /// Highest model order the fit may use.
    #[arg(long, default_value_t = 24)]
    pub max_order: usize,
    /// Force at ADC/DAC full scale (N): ±full scale maps to codes 0..4095.
    #[arg(long, default_value_t = 5000.0)]
    pub full_scale: f64,
    /// Design method: `vf` (default: vector fitting, fixed-lag Kalman
    /// smoother) or `paper` (the seed paper: RFP + Gauss–Newton, continuous
    /// Riccati, Tustin with prewarping).
    #[arg(long, default_value = "vf", value_parser = ["vf", "paper"])]
    pub method: String,
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
    /// own 60 %. The realizations within it are preferred; an image above
    /// it is still written, marked offline-only.
    #[arg(long, default_value_t = 60.0, value_name = "PCT")]
    pub max_load: f64,
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
            vf: crate::fit::vf::VfOptions { max_order: self.max_order, ..Default::default() },
            discretization: self.input.discretization,
            ..Default::default()
        }
    }
}

/// Machine-readable summary of one axis.
#[derive(Debug, Serialize)]
pub struct AxisJson {
    /// Axis letter.
    pub axis: &'static str,
    /// Fitted model order.
    pub model_order: usize,
    /// Order search trace (order, weighted RMS error).
    pub order_trace: Vec<(usize, f64)>,
    /// Relative RMS fit error over the coherent band.
    pub fit_nrmse: f64,
    /// Coherent band (Hz).
    pub coherent_band_hz: (f64, f64),
    /// Chosen q (N²/sample).
    pub q: f64,
    /// R (N²).
    pub r: f64,
    /// Flat band (Hz).
    pub flat_band_hz: (f64, f64),
    /// White-noise gain.
    pub noise_gain: f64,
    /// Predicted in-band relative error √J.
    pub predicted_error: f64,
    /// Predicted in-band relative error of the uncompensated force; the
    /// design is refused unless `predicted_error` is below it.
    pub raw_predicted_error: f64,
    /// Compensated band (Hz): the coherent band capped at 0.45 fs.
    pub compensated_band_hz: (f64, f64),
    /// Discrete model: `fit`, `foh`, `zoh` (null for the paper's Tustin).
    pub discretization: Option<&'static str>,
    /// Model match max |Ĝ_d/Ĝ − 1| over the compensated band (null for the paper's method).
    pub model_match: Option<f64>,
    /// Advance D (samples) and FIR taps of the discrete model, and the
    /// condition number of its least-squares fit.
    pub discrete_advance: Option<usize>,
    /// FIR taps of the discrete model.
    pub discrete_taps: Option<usize>,
    /// Condition number of the discrete model's least-squares fit.
    pub discrete_condition: Option<f64>,
    /// Notes (e.g. FRF lines beyond 0.45 fs).
    pub notes: Vec<String>,
    /// Sections / FIR taps in the image.
    pub sections: usize,
    /// FIR taps.
    pub fir_taps: usize,
    /// Riccati residual.
    pub dare_residual: f64,
    /// f32 verification: frequency-response error, time-domain error, max pole radius.
    pub verify_freq_error: f64,
    /// Time-domain error of the f32 kernel.
    pub verify_time_error: f64,
    /// Largest pole radius.
    pub max_pole_radius: f64,
    /// Natural frequency (Hz) and damping of each fitted mode.
    pub modes: Vec<(f64, f64)>,
    /// Design time of this axis (s).
    pub design_time_s: f64,
    /// Relative RMS fit error on coherent lines outside the bands (null
    /// without bands).
    pub fit_nrmse_out_of_band: Option<f64>,
    /// Condition numbers, observability rank, Riccati residual and prewarp
    /// frequency of `--method paper`.
    pub paper: Option<PaperDiagnostics>,
    /// Predicted in-band error when the sensor modes shift by −5…+5 %
    /// (`crate::sensitivity`), with the shifts where it doubles.
    pub sensitivity: Option<crate::sensitivity::Sensitivity>,
    /// The harmonic force prior of `compensate --offline` (null without
    /// `--force-prior harmonics`).
    pub force_prior: Option<ForcePriorJson>,
    /// The record's force spectrum q was chosen for (null without
    /// `--force-prior spectrum`).
    pub force_spectrum: Option<crate::force_spectrum::AxisForceSpectrum>,
}

/// The force prior of one axis in the `--json` summary.
#[derive(Debug, Serialize)]
pub struct ForcePriorJson {
    /// Where it applies: always `compensate --offline`.
    pub applies_to: &'static str,
    /// The prior (lines, intensities, q_bb) as stored in the sidecar.
    pub prior: crate::force_prior::HarmonicPrior,
    /// Predicted errors: steady cut (the record's spectrum) and flat spectrum,
    /// with the prior, the default smoother and no compensation.
    pub prediction: crate::force_prior::PriorPrediction,
    /// Share of the record's in-band force away from the harmonics.
    pub off_line_share: f64,
    /// Spindle speed whose harmonics best fit the record (rpm).
    pub record_spindle_rpm: f64,
}

/// Machine-readable summary of the whole design.
#[derive(Debug, Serialize)]
pub struct DesignJson {
    /// Image path.
    pub image: String,
    /// Image id.
    pub image_id: String,
    /// Sample rate (Hz).
    pub fs_hz: f64,
    /// Declared latency (samples).
    pub latency_samples: usize,
    /// Method.
    pub method: &'static str,
    /// Fitting bands (empty = whole coherent band).
    pub bands: Vec<Band>,
    /// Axes.
    pub axes: Vec<AxisJson>,
    /// Total design time (s).
    pub design_time_s: f64,
    /// Predicted CPU load of the box at `fs_hz` (`dynocomp_core::budget`).
    pub box_load: crate::load::LoadReport,
    /// Offline-only: over the load limit, the box never runs it.
    pub offline_only: bool,
    /// How the latency was chosen (absent when `--latency` was given).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub latency_choice: Option<crate::latency::LatencyChoice>,
}

/// Measurement-noise variance R (N²) per axis of `frf`: the variance of
/// each column of the `idle` record, or `noise_variance` for all axes.
pub fn noise_variances(idle: Option<&std::path::Path>, noise_variance: Option<f64>, frf: &Frf) -> Result<[Option<f64>; 3]> {
    let mut r = [None; 3];
    match (idle, noise_variance) {
        (Some(path), _) => {
            let rec = io::signal_csv::read_signal_csv(path)?;
            for a in &frf.axes {
                let Some(x) = rec.channel(a.axis) else {
                    bail!("{}: no column f{} for axis {} of the FRF", path.display(), axis_name(a.axis), axis_name(a.axis));
                };
                if x.len() < 100 {
                    bail!("{}: only {} samples; an idle record needs at least 100 to estimate R", path.display(), x.len());
                }
                let var = crate::metrics::sample_variance(x);
                if !(var > 0.0) {
                    bail!("{}: column f{} has zero variance; is it a real idle record?", path.display(), axis_name(a.axis));
                }
                r[a.axis] = Some(var);
            }
        }
        (None, Some(v)) => {
            if !(v > 0.0 && v.is_finite()) {
                bail!("--noise-variance must be a positive number of N², got {v}");
            }
            for a in &frf.axes {
                r[a.axis] = Some(v);
            }
        }
        (None, None) => bail!("give --idle FILE (a record without engagement) or --noise-variance N2 to set the measurement noise R"),
    }
    Ok(r)
}

/// Build the image from the per-axis designs (method Paper when they were
/// designed by `--method paper`).
pub fn build_image(designs: &[AxisDesign], fs_hz: u32, latency: usize, full_scale_n: f64, source_sha256: [u8; 32]) -> Result<CoeffImage> {
    let mut axes = [None; 3];
    let newton_per_code = (2.0 * full_scale_n / 4096.0) as f32;
    let scaling = AxisScaling {
        adc_offset_code: 2048.0,
        newton_per_code,
        dac_code_per_newton: 1.0 / newton_per_code,
        dac_offset_code: 2048.0,
    };
    for d in designs {
        axes[d.axis] = Some(AxisImage {
            axis: d.axis as u8,
            scaling,
            filter: d.filter,
            summary: AxisSummary {
                model_order: d.model.order() as u16,
                fit_nrmse: d.fit_nrmse as f32,
                flat_lo_hz: d.flat_band_hz.0 as f32,
                flat_hi_hz: d.flat_band_hz.1 as f32,
                noise_gain: d.noise_gain as f32,
                q: d.kalman.q,
                r: d.kalman.r,
            },
        });
    }
    Ok(CoeffImage {
        fs_hz,
        latency_samples: u16::try_from(latency).context("latency too large")?,
        flags: 0,
        method: if designs.iter().any(|d| d.paper.is_some()) { DesignMethod::Paper } else { DesignMethod::VectorFitting },
        source_sha256,
        created_unix_s: std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_secs())
            .unwrap_or(0),
        axes,
    })
}

/// One-screen text summary.
pub fn render_summary(designs: &[AxisDesign], fs: f64, latency: usize, image: &str, id: u32, method: &str) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "image {image} (id {id:08x}): fs {fs} Hz, latency {latency} samples ({:.1} µs), method {method}",
        latency as f64 * 1e6 / fs
    );
    if let Some(d) = designs.first().filter(|d| !d.bands.is_empty()) {
        let _ = writeln!(s, "fitting bands: {}", bands::describe(&d.bands));
    }
    let _ = writeln!(
        s,
        "{:<4} {:>5} {:>7} {:>13} {:>10} {:>9} {:>15} {:>6} {:>7} {:>7} {:>8} {:>7}",
        "axis", "order", "fit err", "coherent (Hz)", "Q (N²)", "R (N²)", "flat band (Hz)", "noise", "pred.", "raw", "match", "sec+fir"
    );
    for d in designs {
        let _ = writeln!(
            s,
            "{:<4} {:>5} {:>6.2}% {:>6.0}-{:<6.0} {:>10.3e} {:>9.4} {:>7.0}-{:<7.0} {:>6.2} {:>6.2}% {:>6.2}% {:>8} {:>4}+{}",
            axis_name(d.axis),
            d.model.order(),
            d.fit_nrmse * 100.0,
            d.coherent_band_hz.0,
            d.coherent_band_hz.1,
            d.kalman.q,
            d.kalman.r,
            d.flat_band_hz.0,
            d.flat_band_hz.1,
            d.noise_gain,
            d.predicted_error * 100.0,
            d.raw_predicted_error * 100.0,
            if d.model_match.is_finite() { format!("{:.3}%", d.model_match * 100.0) } else { "tustin".to_string() },
            d.filter.sections().len(),
            d.filter.fir().len()
        );
    }
    for d in designs {
        if let Some((dm, fd)) = &d.discrete {
            let _ = writeln!(
                s,
                "{} discrete model: {} (advance {} samples, {} FIR taps, LS condition {:.1e}{}); match {:.3} % over {:.0}-{:.0} Hz",
                axis_name(d.axis),
                dm.method.name(),
                dm.advance,
                dm.fir.len(),
                fd.condition,
                if fd.modes_above_nyquist > 0 { format!(", {} mode(s) above fs/2 fitted by their tail", fd.modes_above_nyquist) } else { String::new() },
                d.model_match * 100.0,
                d.compensated_band_hz.0,
                d.compensated_band_hz.1
            );
        }
        for n in &d.notes {
            let _ = writeln!(s, "note: {n}");
        }
    }
    for d in designs {
        if let Some(sens) = &d.sensitivity {
            let _ = writeln!(s, "{}", crate::sensitivity::summary_line(axis_name(d.axis), sens));
        }
    }
    for d in designs {
        if let Some((tf, p)) = &d.paper {
            let _ = writeln!(s, "{}", paper_line(d.axis, tf.nb(), tf.na(), p));
        }
    }
    let spectrum = match designs.iter().find_map(|d| d.force_spectrum.as_ref()) {
        Some(s) if !s.level_only => "the force spectrum of --force-record",
        Some(_) => "a flat force spectrum at the level of --force-record",
        None => "a flat force spectrum",
    };
    let _ = writeln!(
        s,
        "flat band: |H·Ĝ| within ±5 % and ±5° of the pure {latency}-sample delay (fitted model Ĝ); noise: white-noise gain; pred.: predicted in-band RMS error for {spectrum}; raw: the same for no compensation; match: max |Ĝ_d/Ĝ − 1| of the discrete model over the compensated band"
    );
    s
}

/// One line of the paper's diagnostics for an axis.
pub fn paper_line(axis: usize, nb: usize, na: usize, p: &PaperDiagnostics) -> String {
    format!(
        "{} paper {nb}:{na}: cond RFP {:.1e}, GN {:.1e}, companion {:.1e}; observability rank {}/{} (cond {:.1e}); CARE residual {:.1e}; Tustin prewarp {:.1} Hz; frequency scale {:.1} Hz",
        axis_name(axis),
        p.rfp_condition,
        p.jacobian_condition,
        p.companion_condition,
        p.observability_rank,
        p.observability_dim,
        p.observability_condition,
        p.care_residual,
        p.prewarp_hz,
        p.frequency_scale_hz
    )
}

/// Run `dynocomp design`.
pub fn run(args: &DesignArgs) -> Result<()> {
    let harmonics = args.prior.force_prior == ForcePrior::Harmonics;
    // Both read the record's force spectrum; `level` keeps only its power.
    let spectrum = matches!(args.prior.force_prior, ForcePrior::Spectrum | ForcePrior::Level);
    if harmonics {
        check_prior_args(args)?;
    } else if spectrum {
        check_spectrum_args(args)?;
    } else if args.prior.force_record.is_some() || args.prior.line_width.is_some() {
        bail!("--force-record belongs to --force-prior harmonics, spectrum or level, --line-width to --force-prior harmonics");
    }
    match args.input.frf.len() {
        1 => {}
        2 => return crate::two_state_cmd::run(args),
        n => bail!("--frf given {n} times: give one FRF, or two (before and after) for a set-up in two states"),
    }
    let paper = args.method == "paper";
    let latency = match (paper, args.latency) {
        (true, Some(l)) if l != 0 => bail!("--latency {l}: the paper's method (a Kalman filter, not a smoother) has no lag; omit --latency or give 0"),
        (true, _) => 0,
        (false, l) => l.unwrap_or(crate::latency::DEFAULT_LATENCY),
    };
    // Without --latency, the default method's latency is chosen (crate::latency).
    let auto_latency = !paper && args.latency.is_none() && !args.parallel;
    args.input.check_fs()?;
    if latency > 16 {
        bail!("--latency {}: at most 16 samples", latency);
    }
    let box_limit = f64::from(dynocomp_core::budget::BOX_LOAD_LIMIT_PERMILLE) / 10.0;
    if !(args.max_load > 0.0 && args.max_load <= box_limit) {
        bail!("--max-load {}: the load limit must be above 0 and at most the box's {box_limit} %", args.max_load);
    }
    let limit_permille = (args.max_load * 10.0).floor() as u32;
    let t0 = Instant::now();
    let bytes = std::fs::read(args.input.frf()).with_context(|| format!("{}: cannot read", args.input.frf().display()))?;
    let sha: [u8; 32] = Sha256::digest(&bytes).into();
    let frf = io::parse_frf(args.input.frf(), &bytes)?;
    let r = args.input.noise_variances(&frf)?;
    // With the harmonic prior, --spindle-rpm/--teeth place the prior's
    // lines, not fitting bands: the design covers the whole band.
    let band_args = if harmonics { BandArgs { spindle_rpm: None, teeth: None, ..args.bands.clone() } } else { args.bands.clone() };
    let bands = band_args.resolve(&frf, args.input.fs).with_context(|| format!("{}", args.input.frf().display()))?;
    let method = if paper { args.paper.method(args.bands.tooth_passing_hz(), args.input.fs)? } else { FitMethod::Vf };
    let opts = DesignOptions {
        method,
        bands: bands.clone(),
        paper_orders_auto: paper && args.paper.auto(),
        axis_cycle_budget: Some(dynocomp_core::budget::axis_budget(
            args.input.fs as u32,
            limit_permille,
            frf.axes.len().max(1) as u32,
        )),
        ..args.base_options(latency)
    };
    // The representative record is read before anything is designed.
    let opts = match spectrum {
        false => opts,
        true => {
            let path = args.prior.force_record.as_ref().expect("checked by check_spectrum_args");
            let rec = read_force_record(path, args.input.fs)?;
            let channels = [0, 1, 2].map(|a| rec.channel(a).map(|c| c.to_vec()));
            DesignOptions {
                force_record: Some(std::sync::Arc::new(crate::force_spectrum::ForceRecord { source: path.display().to_string(), channels })),
                force_record_level_only: args.prior.force_prior == ForcePrior::Level,
                ..opts
            }
        }
    };
    let method_name = if paper { "paper" } else { "vf" };
    if args.parallel {
        return crate::parallel::run(args, &frf, &r, &opts, &bands, latency, sha);
    }
    // The axes are independent: design them on parallel threads (the box
    // has three, the host at least two cores), report in axis order.
    eprintln!("designing {} axes ({} lines each)…", frf.axes.len(), frf.freq_hz.len());
    let rv: Vec<f64> = frf.axes.iter().map(|a| r[a.axis].expect("R set for every FRF axis")).collect();
    let (results, latency_choice) = if auto_latency {
        let (d, c) = crate::latency::design_axes_choosing_latency(&frf.freq_hz, &frf.axes, &rv, &opts, Some(limit_permille), |_, what| eprintln!("  {what}…"));
        (d, Some(c))
    } else {
        (crate::latency::design_axes(&frf.freq_hz, &frf.axes, &rv, &opts), None)
    };
    let latency = latency_choice.as_ref().map_or(latency, |c| c.chosen);
    let mut designs = Vec::new();
    let mut times = Vec::new();
    for (a, (d, dt)) in frf.axes.iter().zip(results) {
        let d = d.with_context(|| format!("{}", args.input.frf().display()))?;
        eprintln!("  axis {}: order {}, q {:.3e}, {:.0} ms", axis_name(a.axis), d.model.order(), d.kalman.q, dt * 1e3);
        times.push(dt);
        designs.push(d);
    }
    // The prior is built and checked before anything is written.
    let priors = if harmonics { build_priors(args, &designs, &r)? } else { designs.iter().map(|_| None).collect() };
    let mut image = build_image(&designs, args.input.fs as u32, latency, args.full_scale, sha)?;
    let box_load = crate::load::report(&image, limit_permille);
    if !box_load.fits {
        image.flags |= dynocomp_core::image::FLAG_OFFLINE_ONLY;
        eprintln!(
            "WARNING: OFFLINE-ONLY IMAGE: predicted box CPU load {:.1} % ({} cycles per sample) at {} Hz exceeds the limit of {:.0} %; \
             the box could run it up to {} Hz. Written for `dynocomp compensate` only: `flash` refuses it and the box would stay in bypass.",
            box_load.load_pct[1],
            box_load.cycles[1],
            image.fs_hz,
            box_load.limit_pct,
            box_load.max_fs_hz
        );
    }
    io::image_file::write_image(&args.out, &image)?;
    if !paper {
        // The model sidecar of `compensate --offline` (crate::smoother).
        let models: Vec<_> = designs.iter().map(|d| (d.axis, &d.model, d.discrete.as_ref().map(|x| &x.0))).collect();
        let mut sidecar = crate::smoother::ModelSidecar::new(&image, &models);
        for ((m, p), d) in sidecar.axes.iter_mut().zip(&priors).zip(&designs) {
            m.force_prior = p.as_ref().map(|p| p.prior.clone());
            // A flat spectrum at the record's level is as safe as the
            // default: no note for `compensate`.
            m.force_spectrum = d
                .force_spectrum
                .as_ref()
                .filter(|s| !s.level_only)
                .map(|s| s.provenance(args.prior.force_record.as_ref().map(|p| p.display().to_string()).unwrap_or_default()));
        }
        crate::smoother::write_sidecar(&args.out, &sidecar)?;
    }
    let id = image.id();
    let mut summary = render_summary(&designs, args.input.fs, latency, &args.out.display().to_string(), id, method_name);
    if let Some(c) = &latency_choice {
        let names: Vec<&str> = designs.iter().map(|d| axis_name(d.axis)).collect();
        summary.push_str(&crate::latency::describe(c, &names));
        summary.push('\n');
    }
    for (d, p) in designs.iter().zip(&priors) {
        if let Some(p) = p {
            summary.push_str(&prior_line(d.axis, p));
        }
        if let Some(s) = &d.force_spectrum {
            summary.push_str(&spectrum_line(d.axis, s, args.input.force_rms));
        }
    }
    summary.push_str(&crate::load::describe(&box_load, image.fs_hz));
    summary.push_str(if box_load.fits { "\n" } else { "  OVER THE LIMIT: offline-only image\n" });
    if let Some(dir) = &args.report {
        let files = crate::report::write_report(dir, &frf, &designs, args.input.fs, &summary)?;
        eprintln!("report: {} files in {} (open index.html)", files.len(), dir.display());
    }
    if args.json {
        let j = DesignJson {
            image: args.out.display().to_string(),
            image_id: format!("{id:08x}"),
            fs_hz: args.input.fs,
            latency_samples: latency,
            method: method_name,
            bands,
            design_time_s: t0.elapsed().as_secs_f64(),
            offline_only: image.is_offline_only(),
            latency_choice: latency_choice.clone(),
            box_load,
            axes: designs
                .iter()
                .zip(&times)
                .zip(&priors)
                .map(|((d, t), p)| AxisJson {
                    axis: axis_name(d.axis),
                    model_order: d.model.order(),
                    order_trace: d.order_trace.clone(),
                    fit_nrmse: d.fit_nrmse,
                    coherent_band_hz: d.coherent_band_hz,
                    q: d.kalman.q,
                    r: d.kalman.r,
                    flat_band_hz: d.flat_band_hz,
                    noise_gain: d.noise_gain,
                    predicted_error: d.predicted_error,
                    raw_predicted_error: d.raw_predicted_error,
                    compensated_band_hz: d.compensated_band_hz,
                    discretization: d.discrete.as_ref().map(|x| x.0.method.name()),
                    model_match: d.model_match.is_finite().then_some(d.model_match),
                    discrete_advance: d.discrete.as_ref().map(|x| x.0.advance),
                    discrete_taps: d.discrete.as_ref().map(|x| x.0.fir.len()),
                    discrete_condition: d.discrete.as_ref().map(|x| x.1.condition),
                    notes: d.notes.clone(),
                    sections: d.filter.sections().len(),
                    fir_taps: d.filter.fir().len(),
                    dare_residual: d.kalman.dare_residual,
                    verify_freq_error: d.verification.freq_error,
                    verify_time_error: d.verification.time_error,
                    max_pole_radius: d.verification.max_pole_radius,
                    modes: d.model.modes(),
                    design_time_s: *t,
                    fit_nrmse_out_of_band: (!d.bands.is_empty() && d.fit_nrmse_out_of_band.is_finite()).then_some(d.fit_nrmse_out_of_band),
                    paper: d.paper.as_ref().map(|p| p.1.clone()),
                    sensitivity: d.sensitivity.clone(),
                    force_prior: p.as_ref().map(|p| ForcePriorJson {
                        applies_to: "compensate --offline",
                        prior: p.prior.clone(),
                        prediction: p.prediction,
                        off_line_share: p.record.off_line_share,
                        record_spindle_rpm: 60.0 * p.record.best_spindle_hz,
                    }),
                    force_spectrum: d.force_spectrum.clone(),
                })
                .collect(),
        };
        println!("{}", serde_json::to_string_pretty(&j)?);
    } else {
        print!("{summary}");
        eprintln!("designed in {:.0} ms", t0.elapsed().as_secs_f64() * 1e3);
    }
    Ok(())
}

/// The conditions of `--force-prior harmonics`: one FRF, the default
/// method, no parallel elaboration, a spindle speed, teeth and a record.
fn check_prior_args(args: &DesignArgs) -> Result<()> {
    if args.input.frf.len() != 1 || args.method != "vf" || args.parallel {
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
    if args.input.frf.len() != 1 || args.method != "vf" || args.parallel {
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

/// Read a representative record (`--force-record`) sampled at `fs_hz`.
fn read_force_record(path: &std::path::Path, fs_hz: f64) -> Result<io::signal_csv::SignalRecord> {
    let rec = io::signal_csv::read_signal_csv(path)?;
    if let Some((rate, _)) = rec.sample_rate_from_time() {
        if (rate - fs_hz).abs() > 1e-6 * fs_hz {
            bail!("{}: sampled at {rate:.1} Hz (column t_s), not at --fs {fs_hz}; record the cut at the box's rate", path.display());
        }
    }
    Ok(rec)
}

/// The harmonic force prior of each designed axis (`crate::force_prior`),
/// tuned from `--force-record`, with the smoother's checks (Riccati
/// residual, closed-loop stability) and the refusal of a prior predicted
/// worse than no compensation.
fn build_priors(args: &DesignArgs, designs: &[AxisDesign], r: &[Option<f64>; 3]) -> Result<Vec<Option<crate::force_prior::AxisPrior>>> {
    let path = args.prior.force_record.as_ref().expect("checked by check_prior_args");
    let shown = path.display();
    let rec = read_force_record(path, args.input.fs)?;
    let opts = crate::force_prior::PriorOptions {
        spindle_rpm: args.bands.spindle_rpm.expect("checked"),
        teeth: args.bands.teeth.expect("checked"),
        line_width_hz: args.prior.line_width,
        unchecked: false,
    };
    let mut out = Vec::new();
    for d in designs {
        let name = axis_name(d.axis);
        let y = rec.channel(d.axis).ok_or_else(|| anyhow::anyhow!("{shown}: no column f{name} for axis {name}; the force record needs every designed axis"))?;
        let dm = &d.discrete.as_ref().ok_or_else(|| anyhow::anyhow!("axis {name}: no discrete model"))?.0;
        let rv = r[d.axis].expect("R set for every designed axis");
        let built = crate::force_prior::build_axis_prior(&opts, dm, &|f| d.model.frf(f), rv, d.kalman.q, d.compensated_band_hz, y)
            .with_context(|| format!("{shown}: axis {name}: --force-prior harmonics"))?;
        crate::smoother::Smoother::with_force_prior(dm, &built.prior, rv).with_context(|| format!("axis {name}: the smoother with the force prior"))?;
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

/// One summary line of an axis designed on a record's force spectrum (or
/// its level).
fn spectrum_line(axis: usize, s: &crate::force_spectrum::AxisForceSpectrum, force_rms: f64) -> String {
    if s.level_only {
        return format!(
            "{} q chosen for a flat force spectrum at the level of --force-record ({:.2} N RMS in the band, in place of --force-rms {force_rms} N): predicted {:.3} %\n",
            axis_name(axis),
            s.force_rms_n,
            100.0 * s.predicted_error
        );
    }
    format!(
        "{} q chosen for the force spectrum of --force-record ({:.2} N RMS in the band, in place of a flat --force-rms {force_rms} N): predicted {:.3} % for that spectrum, {:.3} % for a flat spectrum of the same power (a broadband force: chatter, transients)\n",
        axis_name(axis),
        s.force_rms_n,
        100.0 * s.predicted_error,
        100.0 * s.flat_predicted_error
    )
}

/// One summary line of an axis's force prior.
fn prior_line(axis: usize, p: &crate::force_prior::AxisPrior) -> String {
    let pr = &p.prior;
    let e = &p.prediction;
    format!(
        "{} force prior (compensate --offline only; the box runs the default design): {} harmonics of {:.2} Hz (TPF {:.2} Hz), line width {:.2} Hz, q_bb {:.3e}; predicted {:.3} % on the record's steady cut against {:.3} % for the default smoother (raw {:.2} %); for a flat force spectrum {:.2} % against {:.3} %; {:.2} % of the record's force off the harmonics\n",
        axis_name(axis),
        pr.lines.len(),
        pr.spindle_hz,
        pr.spindle_hz * f64::from(pr.teeth),
        pr.line_width_hz,
        pr.q_broadband,
        100.0 * e.with_prior,
        100.0 * e.default_smoother,
        100.0 * e.raw,
        100.0 * e.with_prior_flat,
        100.0 * e.default_flat,
        100.0 * p.record.off_line_share
    )
}
