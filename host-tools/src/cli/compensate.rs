//! `dynocomp compensate` (DESIGN.md CLI contract, extended by issue #14):
//! reads a force record in any supported format, compensates it, writes it
//! atomically in the input's format (or `--output-format`), and with
//! `--report DIR` writes a page of plots of what the compensation did.
//!
//! Memory per sample of the record (f64 on the host):
//! * box image (default): none — the record streams through in blocks of
//!   [`BLOCK`] samples ([`StreamCompensator`]); the report's accumulators are
//!   bounded too, except with `--truth` (24 bytes per sample and axis for the
//!   whole-record NRMSE, see [`crate::report::compensation`]);
//! * `--offline` (fixed-interval smoother, stationary or with `--drift`):
//!   none — the forward pass runs over blocks and spills 16 bytes per sample
//!   and axis to a temporary file beside the output (the time-varying
//!   smoother of `--drift` adds its covariance every 4096 samples, about 1.2
//!   bytes per sample), the backward pass reads it back in chunks and writes
//!   the estimates (8 bytes per sample and axis) to a second one, and the
//!   input is read again to write the output block by block
//!   ([`crate::offline::smoother::SpilledForward`],
//!   [`crate::offline::drift::SpilledDriftForward`]). A pipe, which cannot be
//!   read twice, is kept in a temporary file during the first reading (8
//!   bytes per sample and column, [`crate::io::spool`]). Temporary disk
//!   space: 24-26 bytes per sample and axis, plus the spooled pipe (≈ 13 GB
//!   for an hour of 3 axes at 51.2 kHz from a file), freed at the end;
//! * `--offline` with a harmonic force prior (checked against the whole
//!   record) and parallel-elaboration images: the record is read whole (8
//!   bytes per sample and column, `t_s` included) and the output is held
//!   whole (8 bytes per sample and axis) before it is written block by
//!   block; besides, the smoother keeps 16 bytes per sample of the axis it
//!   is smoothing, and the parallel split every band (about 8·(bands + 2)
//!   bytes per sample and axis). These are not bounded.

use anyhow::{anyhow, bail, Context, Result};
use std::path::{Path, PathBuf};

use crate::offline::compensate::{compensate_parallel, StreamCompensator};
use crate::report::compensation::ReportAccumulator;
use crate::io::image_file::{read_any_image, AnyImage};
use crate::io::signal::{check_rate_value, read_all, Block, RateTracker, SignalReader, BLOCK};
use crate::io::signal_csv::SignalRecord;
use crate::io::signal_file::{open_signal, writer_for, SignalFormat};
use crate::io::signal::ChannelMap;

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
    /// follows the input unless --output-format says otherwise.
    #[arg(long)]
    pub output: PathBuf,
    /// Output format: csv, uff (ASCII dataset 58), uff58b (binary) or tdms.
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
    /// declared latency.
    #[arg(long)]
    pub raw_timing: bool,
    /// Offline only: zero-lag fixed-interval (Rauch-Tung-Striebel
    /// equivalent) smoother in f64 instead of the box's causal filter.
    /// Needs the model sidecar `<image>.model.json` that `design` writes.
    #[arg(long, conflicts_with = "raw_timing")]
    pub offline: bool,
    /// With --offline: the set-up drifts from the first FRF's state at START
    /// to the second's at END (seconds; linear in the state variable,
    /// constant outside): a time-varying smoother with the two states of a
    /// `design --frf BEFORE --frf AFTER` sidecar (issue #15).
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
    /// --input: the report adds it, the error and the NRMSE.
    #[arg(long, value_name = "FILE", requires = "report")]
    pub truth: Option<PathBuf>,
    /// Spindle speed (rpm) for the report's tooth-passing frequency marks.
    #[arg(long, requires = "teeth")]
    pub spindle_rpm: Option<f64>,
    /// Number of teeth of the cutter (with --spindle-rpm).
    #[arg(long, requires = "spindle_rpm")]
    pub teeth: Option<u32>,
    /// Band limit of the report's NRMSE (Hz); default: the project's
    /// scoring band, min(4 kHz, 0.4 fs).
    #[arg(long)]
    pub band_hz: Option<f64>,
}

/// An image whose q was chosen for a record's force spectrum says so every
/// time it is used (its sidecar keeps that).
fn print_spectrum_notes(sidecar: &crate::offline::sidecar::ModelSidecar) {
    for m in &sidecar.axes {
        if let Some(p) = &m.force_spectrum {
            eprintln!("{}", p.note(&m.axis));
        }
    }
}

/// Run `dynocomp compensate`.
pub fn run(a: &CompensateArgs) -> Result<()> {
    let img = read_any_image(&a.coeffs)?;
    let source = a.input.display().to_string();
    let map = a.channels.as_deref().map(ChannelMap::parse).transpose().context("--channels")?;
    let (mut reader, in_fmt) = open_signal(&a.input, map.as_ref())?;
    let fs = img.fs_hz();
    if let Some(f) = reader.declared_fs_hz() {
        check_rate_value(fs, (f, 0.0), &source, "the file's sampling interval")?;
    }
    let out_fmt = a.output_format.unwrap_or(in_fmt);
    let axes = reader.axes().to_vec();
    let has_time = reader.has_time();
    if let Some(r) = a.spindle_rpm {
        if !(r.is_finite() && r > 0.0) {
            bail!("--spindle-rpm {r}: must be > 0");
        }
    }
    let tpf = a.spindle_rpm.zip(a.teeth).map(|(r, z)| r / 60.0 * f64::from(z));
    let mut truth = match &a.truth {
        Some(p) => {
            let (t, _) = open_signal(p, map.as_ref())?;
            for ax in &axes {
                if !t.axes().contains(ax) {
                    bail!("{}: no f{} channel, but the input has one", p.display(), crate::frf::axis_name(*ax));
                }
            }
            Some((p.display().to_string(), t))
        }
        None => None,
    };
    let mut acc = a.report.as_ref().map(|_| ReportAccumulator::new(&axes, f64::from(fs), tpf, truth.is_some()));
    let progress = progress_bar(reader.len_hint());
    let how: String;
    let n_samples;
    match (&img, a.offline) {
        (AnyImage::Inline(i), false) => {
            // The box path does not need the sidecar; one that is there
            // may still say the image was tuned for a record's spectrum.
            if crate::offline::sidecar::sidecar_path(&a.coeffs).exists() {
                if let Ok(sc) = crate::offline::sidecar::read_sidecar(&a.coeffs, i) {
                    print_spectrum_notes(&sc);
                }
            }
            let mut comp = StreamCompensator::new(i, &axes, a.raw_timing, &source)?;
            how = format!(
                "box filter, latency {} samples{}, streamed in blocks of {BLOCK}",
                i.latency_samples,
                if a.raw_timing { ", not removed" } else { ", removed" }
            );
            n_samples = write_output(&a.output, out_fmt, &axes, has_time, reader.len_hint(), fs, |w| {
                stream_box(&mut *reader, &mut comp, w, fs, &source, acc.as_mut(), truth.as_mut(), &progress)
            })?;
        }
        (AnyImage::Parallel(p), false) => {
            how = format!("parallel elaboration, {} bands, zero-phase split (offline only, whole record in memory)", p.bands().len());
            let rec = whole_record(&mut *reader, fs, &source)?;
            let out = compensate_parallel(p, &rec, a.raw_timing, &source)?;
            n_samples = write_whole(a, out_fmt, &rec, &out, fs, acc.as_mut(), truth.as_mut())?;
        }
        (AnyImage::Inline(i), true) => {
            let drift = a.drift.as_deref().map(crate::offline::drift::parse_interval).transpose()?;
            let mut sidecar = crate::offline::sidecar::read_sidecar(&a.coeffs, i)?;
            print_spectrum_notes(&sidecar);
            if a.no_force_prior {
                sidecar.axes.iter_mut().for_each(|m| m.force_prior = None);
            }
            let priors: Vec<&str> = sidecar.axes.iter().filter(|m| m.force_prior.is_some()).map(|m| m.axis.as_str()).collect();
            // The smoothers run in bounded memory (a pipe, read once, is
            // spooled for its second reading); the force prior (checked
            // against the whole record) keeps the record whole. The
            // time-varying smoother has no force model (and a two-state
            // design makes no prior).
            if priors.is_empty() || drift.is_some() {
                let dir = crate::io::atomic::output_dir(&a.output);
                let mut input = crate::io::spool::TwoReadings::new(reader, &a.input, dir)?;
                let spilled = format!(
                    "spilled to temporary files beside the output{}, memory independent of the record's length",
                    if input.spooled() { ", with the input (a pipe) for its second reading" } else { "" }
                );
                let smoothers;
                let drifting;
                let models: Vec<Box<dyn Fn(f64) -> crate::fit::PoleResidueModel + '_>>;
                let passes: Vec<Box<dyn crate::offline::smoother::SpilledPass + '_>> = match drift {
                    Some((s0, s1)) => {
                        how = format!("time-varying fixed-interval smoother, two FRF states, drift {s0}-{s1} s, zero lag (offline only; forward pass and covariance checkpoints {spilled})");
                        if !priors.is_empty() {
                            eprintln!("warning: the harmonic force prior of axis {} is not used: the time-varying smoother of --drift has no force model", priors.join(", "));
                        }
                        drifting = axes.iter().map(|&ax| crate::offline::drift::axis_drift(i, &sidecar, ax, &source, (s0, s1))).collect::<Result<Vec<_>>>()?;
                        models = drifting.iter().map(|(ts, _)| Box::new(move |s: f64| ts.at(s)) as Box<dyn Fn(f64) -> _>).collect();
                        models
                            .iter()
                            .zip(&drifting)
                            .zip(&axes)
                            .map(|((m, (_, opts)), &ax)| {
                                crate::offline::drift::SpilledDriftForward::new(&**m, opts, dir)
                                    .map(|p| Box::new(p) as Box<dyn crate::offline::smoother::SpilledPass>)
                                    .with_context(|| format!("{source}: axis {}", crate::frf::axis_name(ax)))
                            })
                            .collect::<Result<_>>()?
                    }
                    None => {
                        how = format!("fixed-interval smoother, zero lag (offline only; forward pass {spilled})");
                        smoothers = axes.iter().map(|&ax| crate::offline::smoother::axis_smoother(i, &sidecar, ax, &source)).collect::<Result<Vec<_>>>()?;
                        smoothers.iter().map(|sm| crate::offline::smoother::SpilledForward::new(sm, dir).map(|p| Box::new(p) as Box<dyn crate::offline::smoother::SpilledPass>)).collect::<Result<_>>()?
                    }
                };
                let len_hint = input.first().len_hint();
                progress.set_length(len_hint.unwrap_or(0) * 2);
                let est = smooth_spilled(input.first(), passes, &axes, dir, fs, &source, &progress)?;
                // The input is read a second time, for its times and the report.
                let mut again = input.second(|| Ok(open_signal(&a.input, map.as_ref())?.0))?;
                n_samples = write_output(&a.output, out_fmt, &axes, has_time, len_hint.or(again.len_hint()), fs, |w| {
                    write_spilled(&mut *again, est, w, &source, acc.as_mut(), truth.as_mut(), &progress)
                })?;
            } else {
                how = format!("fixed-interval smoother, zero lag, harmonic force prior on axis {} (offline only, whole record in memory for the force prior)", priors.join(", "));
                let rec = whole_record(&mut *reader, fs, &source)?;
                let out = crate::offline::smoother::smooth_record(i, &sidecar, &rec, &source)?;
                n_samples = write_whole(a, out_fmt, &rec, &out, fs, acc.as_mut(), truth.as_mut())?;
            }
        }
        (AnyImage::Parallel(_), true) => bail!(
            "{}: --offline needs a box image (format 1) and its model sidecar; this is a parallel-elaboration image",
            a.coeffs.display()
        ),
    }
    progress.finish_and_clear();
    eprintln!(
        "compensated {n_samples} samples x {} axes at {fs} Hz ({how}) -> {}",
        axes.len(),
        a.output.display()
    );
    if let (Some(acc), Some(dir)) = (acc, &a.report) {
        let summary = format!(
            "input:  {source}\nimage:  {}\noutput: {}\n{n_samples} samples x {} axes at {fs} Hz ({:.3} s); {how}",
            a.coeffs.display(),
            a.output.display(),
            axes.len(),
            n_samples as f64 / f64::from(fs),
        );
        // The project's one scoring band (the same as `examples/score.rs`
        // and the rates harness), not the image's flat band.
        let band = |_axis: usize| -> f64 { a.band_hz.unwrap_or_else(|| crate::metrics::scoring_band_hz(f64::from(fs))) };
        let (files, scores) = acc.write(dir, &summary, &band)?;
        for s in scores {
            eprintln!("{s}");
        }
        eprintln!("report: {}", files.last().map_or_else(|| dir.display().to_string(), |p| p.display().to_string()));
    }
    Ok(())
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
    let style = if len.is_some() { "{wide_bar} {human_pos}/{human_len} {msg}, eta {eta}" } else { "{spinner} {human_pos} {msg}, {per_sec}" };
    if let Ok(s) = indicatif::ProgressStyle::with_template(style) {
        pb.set_style(s);
    }
    if let Some(n) = len {
        pb.set_length(n);
    }
    pb.set_message(unit);
}

/// Write `path` atomically in `fmt` with a writer for `axes`; `body` writes
/// the samples and returns how many.
fn write_output(
    path: &Path,
    fmt: SignalFormat,
    axes: &[usize],
    has_time: bool,
    len: Option<u64>,
    fs: u32,
    body: impl FnOnce(&mut dyn crate::io::signal::SignalWriter) -> Result<u64>,
) -> Result<u64> {
    let mut n = 0;
    crate::io::atomic::write_atomic_file(path, |w, file| {
        let mut writer = writer_for(fmt, w, Some(file), axes, has_time, len, f64::from(fs), path)?;
        n = body(&mut *writer)?;
        writer.finish()
    })?;
    Ok(n)
}

/// The box path: read, compensate, write and observe block by block; the
/// output lags the input by the removed latency, so the inputs (and times)
/// wait in `pending` until their outputs exist. Returns the samples written.
#[allow(clippy::too_many_arguments)]
fn stream_box(
    reader: &mut dyn SignalReader,
    comp: &mut StreamCompensator<'_>,
    w: &mut dyn crate::io::signal::SignalWriter,
    fs: u32,
    source: &str,
    mut acc: Option<&mut ReportAccumulator>,
    mut truth: Option<&mut (String, Box<dyn SignalReader>)>,
    progress: &indicatif::ProgressBar,
) -> Result<u64> {
    let n_ch = reader.axes().len();
    let axes = reader.axes().to_vec();
    let has_time = reader.has_time();
    let mut pending = Block::new(n_ch);
    let mut out: Vec<Vec<f64>> = vec![Vec::with_capacity(BLOCK); n_ch];
    let mut rate = RateTracker::default();
    let mut tq = TruthQueue::default();
    let mut written = 0u64;
    // Parsing runs on a thread of its own, a block ahead of the kernel and
    // the writer (two cores: parse || compensate + format); blocks go back
    // for reuse.
    std::thread::scope(|s| -> Result<()> {
        let (tx, rx) = std::sync::mpsc::sync_channel::<Result<Block>>(2);
        let (back_tx, back_rx) = std::sync::mpsc::channel::<Block>();
        s.spawn(move || loop {
            let mut blk = back_rx.try_recv().unwrap_or_else(|_| Block::new(n_ch));
            let r = reader.read_block(&mut blk, BLOCK);
            let end = !matches!(r, Ok(n) if n > 0);
            if tx.send(r.map(|_| blk)).is_err() || end {
                break;
            }
        });
        loop {
            let blk = rx.recv().map_err(|_| anyhow!("{source}: the reader stopped"))??;
            let n = blk.len();
            rate.push(&blk.t_s);
            pending.t_s.extend_from_slice(&blk.t_s);
            for (p, b) in pending.channels.iter_mut().zip(&blk.channels) {
                p.extend_from_slice(b);
            }
            for o in &mut out {
                o.clear();
            }
            let m = if n == 0 { comp.finish(&mut out) } else { comp.push(&blk.channels, &mut out) }.with_context(|| source.to_string())?;
            let _ = back_tx.send(blk);
            let t = has_time.then(|| &pending.t_s[..m]);
            let outs: Vec<&[f64]> = out.iter().map(Vec::as_slice).collect();
            w.write_block(t, &outs)?;
            if let Some(acc) = acc.as_deref_mut() {
                let meas: Vec<&[f64]> = pending.channels.iter().map(|c| &c[..m]).collect();
                observe(acc, truth.as_deref_mut(), &mut tq, &axes, &meas, &outs, m)?;
            }
            pending.t_s.drain(..m.min(pending.t_s.len()));
            for p in &mut pending.channels {
                p.drain(..m);
            }
            written += m as u64;
            progress.inc(n as u64);
            if n == 0 {
                return Ok(());
            }
        }
    })?;
    if let Some(found) = rate.rate() {
        check_rate_value(fs, found, source, "column t_s")?;
    }
    Ok(written)
}

/// `--offline` over a record of any length: the forward pass of each
/// axis's smoother over the blocks of `reader`, spilled, then its backward
/// pass ([`crate::offline::smoother::SpilledForward`]). Checks the record's rate.
fn smooth_spilled(
    reader: &mut dyn SignalReader,
    mut fwd: Vec<Box<dyn crate::offline::smoother::SpilledPass + '_>>,
    axes: &[usize],
    dir: &Path,
    fs: u32,
    source: &str,
    progress: &indicatif::ProgressBar,
) -> Result<Vec<crate::offline::smoother::SpilledEstimate>> {
    let mut blk = Block::new(axes.len());
    let mut rate = RateTracker::default();
    while reader.read_block(&mut blk, BLOCK)? > 0 {
        rate.push(&blk.t_s);
        for (f, y) in fwd.iter_mut().zip(&blk.channels) {
            f.push(y)?;
        }
        progress.inc(blk.len() as u64);
    }
    if let Some(found) = rate.rate() {
        check_rate_value(fs, found, source, "column t_s")?;
    }
    let per_axis = |n: u64| progress.inc(n / axes.len().max(1) as u64);
    fwd.into_iter()
        .zip(axes)
        .map(|(f, &ax)| f.backward(dir, &format!("f{}", crate::frf::axis_name(ax)), source, &per_axis))
        .collect()
}

/// Write the estimates of [`smooth_spilled`] block by block, with the
/// times of the input read again (`again`), and observe them for the report.
fn write_spilled(
    again: &mut dyn SignalReader,
    mut est: Vec<crate::offline::smoother::SpilledEstimate>,
    w: &mut dyn crate::io::signal::SignalWriter,
    source: &str,
    mut acc: Option<&mut ReportAccumulator>,
    mut truth: Option<&mut (String, Box<dyn SignalReader>)>,
    progress: &indicatif::ProgressBar,
) -> Result<u64> {
    let axes = again.axes().to_vec();
    let mut blk = Block::new(axes.len());
    let mut out: Vec<Vec<f64>> = vec![Vec::with_capacity(BLOCK); axes.len()];
    let mut tq = TruthQueue::default();
    let mut written = 0u64;
    loop {
        let m = again.read_block(&mut blk, BLOCK)?;
        if m == 0 {
            break;
        }
        if est.iter().any(|e| e.left() < m as u64) {
            bail!("{source}: the input changed while it was compensated (longer on the second reading)");
        }
        for (e, o) in est.iter_mut().zip(&mut out) {
            e.read(m, o)?;
        }
        let outs: Vec<&[f64]> = out.iter().map(Vec::as_slice).collect();
        w.write_block((!blk.t_s.is_empty()).then_some(&blk.t_s[..]), &outs)?;
        if let Some(acc) = acc.as_deref_mut() {
            let meas: Vec<&[f64]> = blk.channels.iter().map(Vec::as_slice).collect();
            observe(acc, truth.as_deref_mut(), &mut tq, &axes, &meas, &outs, m)?;
        }
        written += m as u64;
        progress.inc(m as u64);
    }
    if est.iter().any(|e| e.left() > 0) {
        bail!("{source}: the input changed while it was compensated (shorter on the second reading)");
    }
    Ok(written)
}

/// Observe `m` samples of measured and compensated force for the report,
/// with the next `m` samples of the true force when there is one.
fn observe(
    acc: &mut ReportAccumulator,
    truth: Option<&mut (String, Box<dyn SignalReader>)>,
    tq: &mut TruthQueue,
    axes: &[usize],
    meas: &[&[f64]],
    outs: &[&[f64]],
    m: usize,
) -> Result<()> {
    match truth {
        Some((tsrc, tr)) => {
            let tv = tq.take(&mut **tr, tsrc, axes, m)?;
            let tv: Vec<&[f64]> = tv.iter().map(|v| &v[..m]).collect();
            acc.observe(meas, outs, Some(&tv));
            tq.consume(m);
        }
        None => acc.observe(meas, outs, None),
    }
    Ok(())
}

/// Samples of the truth record read ahead of their use, per input channel.
#[derive(Default)]
struct TruthQueue {
    blk: Option<Block>,
    queue: Vec<Vec<f64>>,
}

impl TruthQueue {
    /// The next `m` truth samples of each of `axes` (at the front of the
    /// returned vectors); an error if the truth record ends first.
    fn take(&mut self, r: &mut dyn SignalReader, source: &str, axes: &[usize], m: usize) -> Result<&[Vec<f64>]> {
        let slots: Vec<usize> = axes.iter().map(|a| r.axes().iter().position(|x| x == a).unwrap_or(0)).collect();
        if self.queue.len() != axes.len() {
            self.queue = vec![Vec::new(); axes.len()];
        }
        let blk = self.blk.get_or_insert_with(|| Block::new(r.axes().len()));
        while self.queue[0].len() < m {
            if r.read_block(blk, BLOCK)? == 0 {
                bail!("{source}: the true force record is shorter than the input");
            }
            for (q, &s) in self.queue.iter_mut().zip(&slots) {
                q.extend_from_slice(&blk.channels[s]);
            }
        }
        Ok(&self.queue)
    }

    /// Drop the first `m` samples (handed out by [`TruthQueue::take`]).
    fn consume(&mut self, m: usize) {
        for q in &mut self.queue {
            q.drain(..m);
        }
    }
}


fn whole_record(reader: &mut dyn SignalReader, fs: u32, source: &str) -> Result<SignalRecord> {
    let axes = reader.axes().to_vec();
    let (t_s, ch) = read_all(reader)?;
    let rec = SignalRecord { t_s, channels: axes.into_iter().zip(ch).collect() };
    if let Some(found) = rec.sample_rate_from_time() {
        check_rate_value(fs, found, source, "column t_s")?;
    }
    Ok(rec)
}

/// Write a whole compensated record (and observe it for the report).
fn write_whole(
    a: &CompensateArgs,
    fmt: SignalFormat,
    rec: &SignalRecord,
    out: &SignalRecord,
    fs: u32,
    acc: Option<&mut ReportAccumulator>,
    truth: Option<&mut (String, Box<dyn SignalReader>)>,
) -> Result<u64> {
    let axes: Vec<usize> = out.channels.iter().map(|c| c.0).collect();
    let n = write_output(&a.output, fmt, &axes, rec.t_s.is_some(), Some(rec.len() as u64), fs, |w| {
        for s in (0..out.len()).step_by(BLOCK) {
            let e = (s + BLOCK).min(out.len());
            let chans: Vec<&[f64]> = out.channels.iter().map(|c| &c.1[s..e]).collect();
            w.write_block(rec.t_s.as_ref().map(|t| &t[s..e]), &chans)?;
        }
        Ok(out.len() as u64)
    })?;
    if let Some(acc) = acc {
        let meas: Vec<&[f64]> = rec.channels.iter().map(|c| c.1.as_slice()).collect();
        let comp: Vec<&[f64]> = out.channels.iter().map(|c| c.1.as_slice()).collect();
        match truth {
            Some((tsrc, tr)) => {
                let taxes = tr.axes().to_vec();
                let (_, t) = read_all(&mut **tr)?;
                if t.first().map_or(0, Vec::len) < out.len() {
                    bail!("{tsrc}: the true force record is shorter than the input");
                }
                let tv: Vec<&[f64]> = axes
                    .iter()
                    .map(|ax| taxes.iter().position(|x| x == ax).map(|s| &t[s][..out.len()]).ok_or_else(|| anyhow!("{tsrc}: axis missing")))
                    .collect::<Result<_>>()?;
                acc.observe(&meas, &comp, Some(&tv));
            }
            None => acc.observe(&meas, &comp, None),
        }
    }
    Ok(n)
}
