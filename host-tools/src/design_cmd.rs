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

use crate::design::{design_axis, AxisDesign, DesignOptions};
use crate::frf::{axis_name, Frf};
use crate::io;

/// Arguments of `dynocomp design` (DESIGN.md, CLI contract).
#[derive(Args, Debug, Clone)]
pub struct DesignArgs {
    /// Measured FRF: UFF58 (.uff/.unv) or CSV.
    #[arg(long)]
    pub frf: PathBuf,
    /// Sample rate of the box (Hz).
    #[arg(long)]
    pub fs: f64,
    /// Output coefficient image (.dcimg), written atomically.
    #[arg(long)]
    pub out: PathBuf,
    /// Idle record (cutting without engagement, signal CSV): R per axis is its variance.
    #[arg(long, conflicts_with = "noise_variance")]
    pub idle: Option<PathBuf>,
    /// Measurement-noise variance R (N²), for all axes.
    #[arg(long)]
    pub noise_variance: Option<f64>,
    /// Declared output latency L (samples): the fixed lag of the smoother.
    #[arg(long, default_value_t = 4)]
    pub latency: usize,
    /// Assumed RMS of the cutting force inside the band (N), for the Q criterion.
    #[arg(long, default_value_t = 100.0)]
    pub force_rms: f64,
    /// Upper limit of the compensator's white-noise gain.
    #[arg(long, default_value_t = 30.0)]
    pub max_noise_gain: f64,
    /// Highest model order the fit may use.
    #[arg(long, default_value_t = 24)]
    pub max_order: usize,
    /// Force at ADC/DAC full scale (N): ±full scale maps to codes 0..4095.
    #[arg(long, default_value_t = 5000.0)]
    pub full_scale: f64,
    /// Design method (only `vf`, the default, in this version).
    #[arg(long, default_value = "vf")]
    pub method: String,
    /// Write plots and an index.html into this directory.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Print the summary as JSON on stdout.
    #[arg(long)]
    pub json: bool,
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
    /// Axes.
    pub axes: Vec<AxisJson>,
    /// Total design time (s).
    pub design_time_s: f64,
}

fn noise_variances(args: &DesignArgs, frf: &Frf) -> Result<[Option<f64>; 3]> {
    let mut r = [None; 3];
    match (&args.idle, args.noise_variance) {
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

/// Build the image from the per-axis designs.
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
        method: DesignMethod::VectorFitting,
        source_sha256,
        created_unix_s: std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_secs())
            .unwrap_or(0),
        axes,
    })
}

/// One-screen text summary.
pub fn render_summary(designs: &[AxisDesign], fs: f64, latency: usize, image: &str, id: u32) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "image {image} (id {id:08x}): fs {fs} Hz, latency {latency} samples ({:.1} µs), method vf",
        latency as f64 * 1e6 / fs
    );
    let _ = writeln!(
        s,
        "{:<4} {:>5} {:>7} {:>13} {:>10} {:>9} {:>15} {:>6} {:>7} {:>7}",
        "axis", "order", "fit err", "coherent (Hz)", "Q (N²)", "R (N²)", "flat band (Hz)", "noise", "pred.", "sec+fir"
    );
    for d in designs {
        let _ = writeln!(
            s,
            "{:<4} {:>5} {:>6.2}% {:>6.0}-{:<6.0} {:>10.3e} {:>9.4} {:>7.0}-{:<7.0} {:>6.2} {:>6.2}% {:>4}+{}",
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
            d.filter.sections().len(),
            d.filter.fir().len()
        );
    }
    let _ = writeln!(
        s,
        "flat band: |H·Ĝ| within ±5 % and ±5° of the pure {latency}-sample delay (fitted model Ĝ); noise: white-noise gain; pred.: predicted in-band RMS error for a flat force spectrum"
    );
    s
}

/// Run `dynocomp design`.
pub fn run(args: &DesignArgs) -> Result<()> {
    if args.method != "vf" {
        bail!("--method {}: only `vf` is available in this version", args.method);
    }
    if !(args.fs.is_finite() && args.fs >= 1_000.0 && args.fs <= 1_000_000.0 && args.fs.fract() == 0.0) {
        bail!("--fs {}: the sample rate must be a whole number of Hz in 1000..=1000000", args.fs);
    }
    if args.latency > 16 {
        bail!("--latency {}: at most 16 samples", args.latency);
    }
    let t0 = Instant::now();
    let bytes = std::fs::read(&args.frf).with_context(|| format!("{}: cannot read", args.frf.display()))?;
    let sha: [u8; 32] = Sha256::digest(&bytes).into();
    let frf = io::read_frf(&args.frf)?;
    let r = noise_variances(args, &frf)?;
    let opts = DesignOptions {
        fs_hz: args.fs,
        lag: args.latency,
        force_rms: args.force_rms,
        max_noise_gain: args.max_noise_gain,
        vf: crate::fit::vf::VfOptions { max_order: args.max_order, ..Default::default() },
        ..Default::default()
    };
    let mut designs = Vec::new();
    let mut times = Vec::new();
    for a in &frf.axes {
        let ta = Instant::now();
        eprint!("designing axis {} ({} lines)… ", axis_name(a.axis), frf.freq_hz.len());
        let rv = r[a.axis].expect("R set for every FRF axis");
        let d = design_axis(&frf.freq_hz, a, rv, &opts).with_context(|| format!("{}", args.frf.display()))?;
        let dt = ta.elapsed().as_secs_f64();
        eprintln!("order {}, q {:.3e}, {:.0} ms", d.model.order(), d.kalman.q, dt * 1e3);
        times.push(dt);
        designs.push(d);
    }
    let image = build_image(&designs, args.fs as u32, args.latency, args.full_scale, sha)?;
    io::image_file::write_image(&args.out, &image)?;
    let id = image.id();
    let summary = render_summary(&designs, args.fs, args.latency, &args.out.display().to_string(), id);
    if let Some(dir) = &args.report {
        let files = crate::report::write_report(dir, &frf, &designs, args.fs, &summary)?;
        eprintln!("report: {} files in {} (open index.html)", files.len(), dir.display());
    }
    if args.json {
        let j = DesignJson {
            image: args.out.display().to_string(),
            image_id: format!("{id:08x}"),
            fs_hz: args.fs,
            latency_samples: args.latency,
            method: "vf",
            design_time_s: t0.elapsed().as_secs_f64(),
            axes: designs
                .iter()
                .zip(&times)
                .map(|(d, t)| AxisJson {
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
                    sections: d.filter.sections().len(),
                    fir_taps: d.filter.fir().len(),
                    dare_residual: d.kalman.dare_residual,
                    verify_freq_error: d.verification.freq_error,
                    verify_time_error: d.verification.time_error,
                    max_pole_radius: d.verification.max_pole_radius,
                    modes: d.model.modes(),
                    design_time_s: *t,
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
