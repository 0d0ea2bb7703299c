//! `dynocomp compensate`: a force record in any supported format compensated
//! into a file of the same channels ([`crate::offline::record`]: the box's
//! filter, parallel elaboration or the zero-lag smoother), written
//! atomically in the input's format (or `--output-format`), and with
//! `--report DIR` a page of plots of what the compensation did
//! ([`crate::report::compensation`]).

use anyhow::{bail, Context, Result};
use std::path::{Path, PathBuf};

use crate::io::image_file::{read_any_image, AnyImage};
use crate::io::signal::check_max_force;
use crate::io::signal::{check_rate_value, ChannelMap};
use crate::io::signal_file::{open_signal_checked, SignalFormat};
use crate::offline::record::{compensate_file, Compensated, Compensation, Monitor, Observer, RecordJob, Truth};
use crate::report::compensation::ReportAccumulator;

/// `dynocomp compensate` arguments.
#[derive(clap::Args, Debug)]
pub struct CompensateArgs {
    /// Coefficient image (.dcimg).
    #[arg(long)]
    pub coeffs: PathBuf,
    /// Input force record: CSV (columns [t_s,] fx, fy, fz in N; any subset),
    /// UFF 58/58b time histories (function type 1) or NI TDMS, by extension
    /// or content.
    #[arg(long)]
    pub input: PathBuf,
    /// Output force record (same channels), written atomically; its format
    /// is --output-format, else the output's extension (.csv, .tdms,
    /// .uff/.unv/.uf), else the input's. An extension that contradicts
    /// --output-format is an error. `-` writes
    /// it to standard output (the input `-` reads CSV from standard input).
    #[arg(long)]
    pub output: PathBuf,
    /// Output format: csv, uff (ASCII dataset 58), uff58b (binary) or tdms
    /// (it must agree with the output's extension, if that names a format).
    #[arg(long, value_enum)]
    pub output_format: Option<SignalFormat>,
    /// Channel-to-axis map for UFF records whose response directions do not
    /// say the axis, e.g. `fx=1,fy=2,fz=3` (UFF: response node number) or by
    /// name (`fx=Force X`, matched against the record's ID line); for TDMS
    /// records whose channel names do not say it, by channel name or
    /// `GROUP/NAME` (case-insensitive).
    #[arg(long)]
    pub channels: Option<String>,
    /// Keep the box's timing: do not shift the output back by the image's
    /// declared latency. Without it, the last L samples are finished with
    /// the record's predicted continuation as their look-ahead (README,
    /// "Latency").
    #[arg(long)]
    pub raw_timing: bool,
    /// Offline only: zero-lag fixed-interval (Rauch-Tung-Striebel
    /// equivalent) smoother in f64 instead of the box's causal filter; with a
    /// 3x3 image, the 3x3 model's smoother (crosstalk compensated). Needs
    /// the model sidecar `<image>.model.json` that `design` writes.
    #[arg(long, conflicts_with = "raw_timing")]
    pub offline: bool,
    /// With --offline: the set-up drifts from the first FRF's state at START
    /// to the second's at END (seconds; linear in the state variable,
    /// constant outside): a time-varying smoother with the two states of a
    /// `design --frf BEFORE --frf AFTER` sidecar.
    #[arg(long, value_name = "START:END", requires = "offline")]
    pub drift: Option<String>,
    /// With --offline: ignore the harmonic force prior of the model sidecar
    /// (`design --force-prior harmonics`) and use the default force model.
    #[arg(long, requires = "offline")]
    pub no_force_prior: bool,
    /// Write a report of the compensation (index.html and SVG plots) into DIR.
    #[arg(long, value_name = "DIR")]
    pub report: Option<PathBuf>,
    /// True force of the record (e.g. from `simulate`), same format rules as
    /// --input: prints, per axis, the NRMSE of the measured and the
    /// compensated force against it (band-limited, and the output as
    /// written; README "Accuracy"); with --report the pages show it too.
    #[arg(long, value_name = "FILE")]
    pub truth: Option<PathBuf>,
    /// Spindle speed (rpm) for the report's tooth-passing frequency marks.
    #[arg(long, requires = "teeth")]
    pub spindle_rpm: Option<f64>,
    /// Number of teeth of the cutter (with --spindle-rpm).
    #[arg(long, requires = "spindle_rpm")]
    pub teeth: Option<u32>,
    /// Largest plausible force (N): the full scale of the charge amplifier
    /// or ADC. A value of the input or the true force beyond ± this, or not
    /// finite, is an input error that names the sample.
    #[arg(long, default_value_t = crate::io::signal::DEFAULT_FULL_SCALE_N, value_name = "N")]
    pub max_force: f64,
    /// Band limit of the NRMSE against --truth (Hz); default: the
    /// project's scoring band, min(4 kHz, 0.4 fs).
    #[arg(long)]
    pub band_hz: Option<f64>,
}

/// Run `dynocomp compensate`.
pub fn run(a: &CompensateArgs) -> Result<()> {
    let Options { job, axes, fs, tpf, extremes } = Options::new(a)?;
    let has_truth = job.truth.is_some();
    let keep = a.report.is_some() || has_truth;
    let mut acc = keep.then(|| ReportAccumulator::new(&axes, f64::from(fs), tpf, has_truth));
    let progress = progress_bar(job.input.len_hint());
    let done = compensate_file(job, acc.as_mut().map(|r| r as &mut dyn Observer), &Terminal(&progress))?;
    progress.finish_and_clear();
    let Compensated { samples: n_samples, how } = done;
    eprintln!("compensated {n_samples} samples x {} axes at {fs} Hz ({how}) -> {}", axes.len(), a.output.display());
    let clips = extremes.lock().unwrap_or_else(|p| p.into_inner()).clipped();
    let clipped: Vec<String> = clips
        .iter()
        .map(|c| c.warning(&a.input.display().to_string(), "the compensated force is wrong around them"))
        .collect();
    if let Some(acc) = acc.as_mut() {
        acc.mark_clipped(&clips);
    }
    clipped.iter().for_each(|w| eprintln!("{w}"));
    // The project's one scoring band (the same as `examples/score.rs` and
    // the rates harness), not the image's flat band.
    let band = |_axis: usize| -> f64 { a.band_hz.unwrap_or_else(|| crate::metrics::scoring_band_hz(f64::from(fs))) };
    if let (Some(acc), None) = (&acc, &a.report) {
        for s in acc.score_lines(&band) {
            eprintln!("{s}");
        }
    }
    if let (Some(acc), Some(dir)) = (acc, &a.report) {
        let mut summary = format!(
            "input:  {}\nimage:  {}\noutput: {}\n{n_samples} samples x {} axes at {fs} Hz ({:.3} s); {how}",
            a.input.display(),
            a.coeffs.display(),
            a.output.display(),
            axes.len(),
            n_samples as f64 / f64::from(fs),
        );
        clipped.iter().for_each(|w| summary.push_str(&format!("\n{w}")));
        write_report(acc, dir, &summary, &band)?;
    }
    Ok(())
}

/// The arguments checked and the files opened, in this order (the first
/// problem is the one reported): the image, the channel map, the input and
/// its declared rate, the spindle speed, the true force and its channels,
/// the method and the drift interval.
struct Options {
    job: RecordJob,
    /// The input's channels.
    axes: Vec<usize>,
    /// The image's sample rate (Hz).
    fs: u32,
    /// The tooth-passing frequency for the report (Hz).
    tpf: Option<f64>,
    /// The input's extremes, followed as it is read ([`crate::io::clipping`]).
    extremes: std::sync::Arc<std::sync::Mutex<crate::io::clipping::Extremes>>,
}

impl Options {
    fn new(a: &CompensateArgs) -> Result<Self> {
        let sidecar = crate::offline::sidecar::sidecar_path(&a.coeffs);
        let mut inputs = vec![
            ("--input", a.input.as_path()),
            ("--coeffs", a.coeffs.as_path()),
            ("the model sidecar of --coeffs", &sidecar),
        ];
        inputs.extend(a.truth.as_deref().map(|p| ("--truth", p)));
        crate::io::atomic::ensure_not_an_input(&[("--output", &a.output)], &inputs)?;
        let img = read_any_image(&a.coeffs)?;
        let source = a.input.display().to_string();
        let map = a.channels.as_deref().map(ChannelMap::parse).transpose().context("--channels")?;
        let max_force = check_max_force(a.max_force)?;
        let (input, in_fmt) = open_signal_checked(&a.input, map.as_ref(), max_force)?;
        let (input, extremes) = crate::io::clipping::clip_watch(input);
        let fs = img.fs_hz();
        if let Some(f) = input.declared_fs_hz() {
            check_rate_value(fs, (f, 0.0), &source, "the file's sampling interval")?;
        }
        let axes = input.axes().to_vec();
        crate::cli::design_args::check_spindle(a.spindle_rpm, a.teeth)?;
        let tpf = a.spindle_rpm.zip(a.teeth).map(|(r, z)| r / 60.0 * f64::from(z));
        let truth = match &a.truth {
            Some(p) => {
                let (t, _) = open_signal_checked(p, map.as_ref(), max_force)?;
                for ax in &axes {
                    if !t.axes().contains(ax) {
                        bail!("{}: no f{} channel, but the input has one", p.display(), crate::frf::axis_name(*ax));
                    }
                }
                Some(Truth { source: p.display().to_string(), reader: t })
            }
            None => None,
        };
        let compensation = match (img, a.offline) {
            (AnyImage::Inline(i), false) => Compensation::Box(i),
            (AnyImage::Parallel(p), false) => Compensation::Parallel(p),
            (AnyImage::Inline(image), true) => Compensation::Smoother {
                drift: a.drift.as_deref().map(crate::offline::drift::parse_interval).transpose()?,
                force_prior: !a.no_force_prior,
                image,
            },
            (AnyImage::Matrix(m), false) => Compensation::Matrix(m),
            (AnyImage::Matrix(_), true) if a.drift.is_some() => bail!(
                "{}: --drift needs an image designed from two FRFs (`design --frf BEFORE --frf AFTER`); \
                 this 3x3 image has one state: drop --drift for its zero-lag 3x3 smoother",
                a.coeffs.display()
            ),
            (AnyImage::Matrix(m), true) => Compensation::MatrixSmoother(m),
            (AnyImage::Parallel(_), true) => bail!(
                "{}: --offline needs a box image (format 1) and its model sidecar; this is a parallel-elaboration image",
                a.coeffs.display()
            ),
        };
        let job = RecordJob {
            compensation,
            image_path: a.coeffs.clone(),
            input,
            input_path: a.input.clone(),
            channels: map,
            full_scale_n: max_force,
            output: a.output.clone(),
            output_format: output_format(&a.output, a.output_format, in_fmt)?,
            raw_timing: a.raw_timing,
            truth,
        };
        Ok(Options { job, axes, fs, tpf, extremes })
    }
}

/// The format of the output `path`: `given` (`--output-format`), else the
/// one its extension names, else the input's `input`; an error when `given`
/// contradicts the extension (TDMS bytes in `x.csv`).
fn output_format(path: &Path, given: Option<SignalFormat>, input: SignalFormat) -> Result<SignalFormat> {
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    let named: Option<&[SignalFormat]> = match ext.as_deref() {
        Some("csv") => Some(&[SignalFormat::Csv]),
        Some("tdms") => Some(&[SignalFormat::Tdms]),
        Some("uff" | "unv" | "uf") => Some(&[SignalFormat::Uff, SignalFormat::Uff58b]),
        _ => None,
    };
    match (given, named) {
        (Some(g), Some(n)) if !n.contains(&g) => bail!(
            "{}: the extension .{} does not fit --output-format {}; name the output after its format",
            path.display(),
            ext.unwrap_or_default(),
            clap::ValueEnum::to_possible_value(&g).map_or_else(String::new, |v| v.get_name().to_string())
        ),
        (Some(g), _) => Ok(g),
        (None, Some(n)) if n.contains(&input) => Ok(input),
        (None, Some(n)) => Ok(n[0]),
        (None, None) => Ok(input),
    }
}

/// Write the report into `dir` with `summary` on top and print its NRMSE
/// lines and where it is.
fn write_report(acc: ReportAccumulator, dir: &Path, summary: &str, band: &dyn Fn(usize) -> f64) -> Result<()> {
    let (files, scores) = acc.write(dir, summary, band)?;
    for s in scores {
        eprintln!("{s}");
    }
    eprintln!("report: {}", files.last().map_or_else(|| dir.display().to_string(), |p| p.display().to_string()));
    Ok(())
}

/// Progress on a bar, notes on stderr.
struct Terminal<'a>(&'a indicatif::ProgressBar);

impl Monitor for Terminal<'_> {
    fn note(&self, line: &str) {
        eprintln!("{line}");
    }

    fn set_length(&self, samples: u64) {
        self.0.set_length(samples);
    }

    fn advance(&self, samples: u64) {
        self.0.inc(samples);
    }
}

/// A progress bar on stderr, drawn only when stderr is a terminal
/// (indicatif hides it otherwise).
fn progress_bar(len: Option<u64>) -> indicatif::ProgressBar {
    let pb = indicatif::ProgressBar::with_draw_target(len, indicatif::ProgressDrawTarget::stderr());
    restyle(&pb, len, "samples");
    pb
}

/// Give `pb` the length `len` (a bar with an ETA; a spinner if unknown),
/// counting `unit`.
fn restyle(pb: &indicatif::ProgressBar, len: Option<u64>, unit: &'static str) {
    let style = if len.is_some() {
        "{wide_bar} {human_pos}/{human_len} {msg}, eta {eta}"
    } else {
        "{spinner} {human_pos} {msg}, {per_sec}"
    };
    if let Ok(s) = indicatif::ProgressStyle::with_template(style) {
        pb.set_style(s);
    }
    if let Some(n) = len {
        pb.set_length(n);
    }
    pb.set_message(unit);
}
