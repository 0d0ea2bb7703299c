//! A force record compensated from file to file ([`compensate_file`]): read
//! in blocks, run through the box's kernel, parallel elaboration or a
//! smoother, written atomically in any signal format, with every written
//! block shown to an [`Observer`] (e.g. a report) beside the true force.

use anyhow::{anyhow, bail, Context, Result};
use std::path::{Path, PathBuf};

use dynocomp_core::image::{CoeffImage, MatrixImage, ParallelImage};

use crate::frf::axis_name;
use crate::io::signal::ChannelMap;
use crate::io::signal::{check_rate_value, read_all, Block, RateTracker, SignalReader, SignalWriter, BLOCK};
use crate::io::signal_csv::SignalRecord;
use crate::io::signal_file::{open_signal_checked, writer_for, SignalFormat};
use crate::offline::compensate::{compensate_parallel, StreamCompensator};
use crate::offline::sidecar::{read_sidecar, sidecar_path, ModelSidecar};
use crate::offline::smoother::{SpilledEstimate, SpilledPass};

/// How a record is compensated, with the image that does it.
pub enum Compensation {
    /// The box's causal filter (a box image), bit-exact with the box.
    Box(CoeffImage),
    /// Parallel elaboration (a parallel-elaboration image), offline only.
    Parallel(Box<ParallelImage>),
    /// A 3x3 image's filter (format 3) on fx, fy and fz together, bit-exact
    /// with the box.
    Matrix(Box<MatrixImage>),
    /// The zero-lag fixed-interval smoother of a 3x3 image's model (its
    /// sidecar), on fx, fy and fz together
    /// ([`crate::offline::matrix_smoother`]).
    MatrixSmoother(Box<MatrixImage>),
    /// The zero-lag fixed-interval smoother on the box image's model
    /// sidecar: stationary, or time-varying between the sidecar's two states
    /// from `drift.0` to `drift.1` (s); with the sidecar's harmonic force
    /// prior if `force_prior`.
    Smoother {
        /// The box image whose sidecar holds the models.
        image: CoeffImage,
        /// Drift interval (s), `None`: stationary.
        drift: Option<(f64, f64)>,
        /// Use the sidecar's harmonic force prior, where it has one.
        force_prior: bool,
    },
}

impl Compensation {
    /// The image's sample rate (Hz).
    pub fn fs_hz(&self) -> u32 {
        match self {
            Compensation::Box(i) | Compensation::Smoother { image: i, .. } => i.fs_hz,
            Compensation::Parallel(p) => p.fs_hz,
            Compensation::Matrix(m) | Compensation::MatrixSmoother(m) => m.fs_hz,
        }
    }
}

/// One record to compensate: the input already opened (its rate checked
/// against the image by the caller if it declares one).
pub struct RecordJob {
    /// What compensates it.
    pub compensation: Compensation,
    /// The image's file, beside which its model sidecar lies.
    pub image_path: PathBuf,
    /// The input, opened.
    pub input: Box<dyn SignalReader>,
    /// The input's file, read again by the smoothers.
    pub input_path: PathBuf,
    /// The channel map the input was opened with.
    pub channels: Option<ChannelMap>,
    /// The full scale the input was opened with (N): a second reading
    /// checks its values against the same bound.
    pub full_scale_n: f64,
    /// The output file, written atomically (`-`: standard output).
    pub output: PathBuf,
    /// Its format.
    pub output_format: SignalFormat,
    /// Keep the box's timing: do not remove the image's declared latency.
    pub raw_timing: bool,
    /// The true force of the record, read alongside for the observer.
    pub truth: Option<Truth>,
}

/// A true force record with every channel of the input.
pub struct Truth {
    /// Its name in messages.
    pub source: String,
    /// The record, opened.
    pub reader: Box<dyn SignalReader>,
}

/// What [`compensate_file`] did.
pub struct Compensated {
    /// Samples written per channel.
    pub samples: u64,
    /// How, in words (method, latency, memory).
    pub how: String,
}

/// Sees every block of the output as it is written.
pub trait Observer {
    /// The same samples of each channel: measured, compensated and, with a
    /// [`Truth`], the true force.
    fn observe(&mut self, measured: &[&[f64]], compensated: &[&[f64]], truth: Option<&[&[f64]]>);
}

/// Where [`compensate_file`] tells its user what happens.
pub trait Monitor {
    /// A note or a warning, one line.
    fn note(&self, line: &str);
    /// The work to do, in samples (reading and writing counted apart).
    fn set_length(&self, samples: u64);
    /// `samples` more done.
    fn advance(&self, samples: u64);
}

/// Compensate `job`'s record into its output, showing the written blocks to
/// `observer`. Returns the samples written and how.
///
/// Memory per sample of the record (f64 on the host):
/// * [`Compensation::Box`] and [`Compensation::Matrix`]: none. The record streams through in blocks of
///   [`BLOCK`] samples ([`StreamCompensator`]); what the observer keeps is
///   its own affair (a report with a true force keeps the whole record);
/// * [`Compensation::Smoother`], stationary or drifting, and
///   [`Compensation::MatrixSmoother`] (48 bytes per sample spilled, all three
///   axes together): none. The forward
///   pass runs over blocks and spills 16 bytes per sample and axis to a
///   temporary file beside the output (the time-varying smoother adds its
///   covariance every 4096 samples, about 1.2 bytes per sample), the
///   backward pass reads it back in chunks and writes the estimates (8
///   bytes per sample and axis) to a second one, and the input is read again
///   to write the output block by block
///   ([`crate::offline::smoother::SpilledForward`],
///   [`crate::offline::drift::SpilledDriftForward`]). A pipe, which cannot
///   be read twice, is kept in a temporary file during the first reading (8
///   bytes per sample and column, [`crate::io::spool`]). Temporary disk
///   space: 24-26 bytes per sample and axis, plus the spooled pipe, freed at
///   the end;
/// * the stationary smoother with a harmonic force prior (checked against
///   the whole record) and [`Compensation::Parallel`]: the record is read
///   whole (8 bytes per sample and column, `t_s` included) and the output is
///   held whole (8 bytes per sample and axis) before it is written block by
///   block; besides, the smoother keeps 16 bytes per sample of the axis it
///   is smoothing, and the parallel split every band (about 8·(bands + 2)
///   bytes per sample and axis). These are not bounded.
pub fn compensate_file(
    job: RecordJob,
    observer: Option<&mut dyn Observer>,
    monitor: &dyn Monitor,
) -> Result<Compensated> {
    let RecordJob {
        compensation,
        image_path,
        input,
        input_path,
        channels,
        full_scale_n,
        output,
        output_format,
        raw_timing,
        truth,
    } = job;
    let axes = input.axes().to_vec();
    let target = Target {
        output: &output,
        format: output_format,
        fs: compensation.fs_hz(),
        source: &input_path.display().to_string(),
        axes: &axes,
        has_time: input.has_time(),
        monitor,
    };
    let mut observed = Observed { observer, truth, queue: TruthQueue::default() };
    let obs = &mut observed;
    match compensation {
        Compensation::Box(image) => compensate_box(&image, &image_path, input, raw_timing, &target, obs),
        Compensation::Parallel(image) => {
            let how = format!(
                "parallel elaboration, {} bands, zero-phase split (offline only, whole record in memory)",
                image.bands().len()
            );
            compensate_whole(input, &target, obs, how, |rec| {
                compensate_parallel(&image, rec, raw_timing, target.source)
            })
        }
        Compensation::Matrix(image) => {
            let comp = StreamCompensator::matrix(&image, target.axes, raw_timing, target.source)?;
            stream_compensated(input, comp, matrix_how(image.latency_samples, raw_timing), &target, obs)
        }
        Compensation::MatrixSmoother(image) => {
            let reading = Reading { input, path: &input_path, channels: channels.as_ref(), full_scale_n };
            smooth_matrix_spilled(&image, &image_path, reading, &target, obs)
        }
        Compensation::Smoother { image, drift, force_prior } => {
            let reading = Reading { input, path: &input_path, channels: channels.as_ref(), full_scale_n };
            smooth(&image, &image_path, drift, force_prior, reading, &target, obs)
        }
    }
}

/// Read the whole record into memory, compensate it with `compensate` and
/// write it; `how` says what compensated it.
fn compensate_whole(
    mut input: Box<dyn SignalReader>,
    target: &Target<'_>,
    obs: &mut Observed<'_>,
    how: String,
    compensate: impl FnOnce(&SignalRecord) -> Result<SignalRecord>,
) -> Result<Compensated> {
    let rec = whole_record(&mut *input, target.fs, target.source)?;
    let out = compensate(&rec)?;
    Ok(Compensated { samples: target.write_whole(&rec, &out, obs)?, how })
}

/// How a 3x3 image of latency `l` (samples) compensates.
fn matrix_how(l: u16, raw_timing: bool) -> String {
    if raw_timing {
        format!("3x3 filter of the box, crosstalk compensated, latency {l} samples kept, streamed in blocks of {BLOCK}")
    } else {
        format!(
            "3x3 filter of the box, crosstalk compensated, latency {l} samples removed; the last {l} samples \
             use a predicted look-ahead; streamed in blocks of {BLOCK}"
        )
    }
}

/// The smoother on the image's sidecar, with its harmonic force prior if
/// `force_prior` (and the sidecar has one). The smoothers run in bounded
/// memory (a pipe, read once, is spooled for its second reading); the force
/// prior (checked against the whole record) keeps the record whole. The
/// time-varying smoother has no force model (and a two-state design makes
/// no prior).
fn smooth(
    image: &CoeffImage,
    image_path: &Path,
    drift: Option<(f64, f64)>,
    force_prior: bool,
    reading: Reading<'_>,
    target: &Target<'_>,
    obs: &mut Observed<'_>,
) -> Result<Compensated> {
    let mut sidecar = read_sidecar(image_path, image)?;
    note_spectra(&sidecar, target.monitor);
    if !force_prior {
        sidecar.axes.iter_mut().for_each(|m| m.force_prior = None);
    }
    let priors: Vec<&str> = sidecar.axes.iter().filter(|m| m.force_prior.is_some()).map(|m| m.axis.as_str()).collect();
    if priors.is_empty() || drift.is_some() {
        return smooth_spilled(image, &sidecar, drift, &priors, reading, target, obs);
    }
    let how = format!(
        "fixed-interval smoother, zero lag, harmonic force prior on axis {} (offline only, whole record in memory \
         for the force prior)",
        priors.join(", ")
    );
    compensate_whole(reading.input, target, obs, how, |rec| {
        crate::offline::smoother::smooth_record(image, &sidecar, rec, target.source)
    })
}

/// An image whose q was chosen for a record's force spectrum says so every
/// time it is used (its sidecar keeps that).
fn note_spectra(sidecar: &ModelSidecar, monitor: &dyn Monitor) {
    for m in &sidecar.axes {
        if let Some(p) = &m.force_spectrum {
            monitor.note(&p.note(&m.axis));
        }
    }
}

/// The output of [`compensate_file`], and where progress goes.
struct Target<'a> {
    output: &'a Path,
    format: SignalFormat,
    fs: u32,
    /// The input's name in messages.
    source: &'a str,
    /// The input's channels.
    axes: &'a [usize],
    /// Whether the input has a `t_s` column.
    has_time: bool,
    monitor: &'a dyn Monitor,
}

impl Target<'_> {
    /// Write the output atomically with a writer for the input's channels
    /// (`len` samples, if known); `body` writes the samples and returns how
    /// many.
    fn write(
        &self,
        has_time: bool,
        len: Option<u64>,
        body: impl FnOnce(&mut dyn SignalWriter) -> Result<u64>,
    ) -> Result<u64> {
        let (path, fs) = (self.output, f64::from(self.fs));
        let mut n = 0;
        crate::io::atomic::write_atomic_output(path, |w, file| {
            let mut writer = writer_for(self.format, w, file, self.axes, has_time, len, fs, path)?;
            n = body(&mut *writer)?;
            writer.finish()
        })?;
        Ok(n)
    }

    /// Write a whole compensated record `out` block by block, with the
    /// times of the input `rec`, then show it to the observer.
    fn write_whole(&self, rec: &SignalRecord, out: &SignalRecord, observed: &mut Observed<'_>) -> Result<u64> {
        let n = self.write(rec.t_s.is_some(), Some(rec.len() as u64), |w| {
            for s in (0..out.len()).step_by(BLOCK) {
                let e = (s + BLOCK).min(out.len());
                let chans: Vec<&[f64]> = out.channels.iter().map(|c| &c.1[s..e]).collect();
                w.write_block(rec.t_s.as_ref().map(|t| &t[s..e]), &chans)?;
            }
            Ok(out.len() as u64)
        })?;
        observed.whole(rec, out)?;
        Ok(n)
    }
}

/// The observer, if any, with the true force read alongside the output.
struct Observed<'a> {
    observer: Option<&'a mut dyn Observer>,
    truth: Option<Truth>,
    queue: TruthQueue,
}

impl Observed<'_> {
    /// Show `m` samples of measured and compensated force of `axes` to the
    /// observer, with the next `m` samples of the true force when there is
    /// one.
    fn block(&mut self, axes: &[usize], meas: &[&[f64]], outs: &[&[f64]], m: usize) -> Result<()> {
        let Some(obs) = self.observer.as_deref_mut() else { return Ok(()) };
        match &mut self.truth {
            Some(Truth { source, reader }) => {
                let tv = self.queue.take(&mut **reader, source, axes, m)?;
                let tv: Vec<&[f64]> = tv.iter().map(|v| &v[..m]).collect();
                obs.observe(meas, outs, Some(&tv));
                self.queue.consume(m);
            }
            None => obs.observe(meas, outs, None),
        }
        Ok(())
    }

    /// Show a whole record `rec` and its compensation `out` to the
    /// observer, with the whole true force when there is one.
    fn whole(&mut self, rec: &SignalRecord, out: &SignalRecord) -> Result<()> {
        let Some(obs) = self.observer.as_deref_mut() else { return Ok(()) };
        let axes: Vec<usize> = out.channels.iter().map(|c| c.0).collect();
        let meas: Vec<&[f64]> = rec.channels.iter().map(|c| c.1.as_slice()).collect();
        let comp: Vec<&[f64]> = out.channels.iter().map(|c| c.1.as_slice()).collect();
        match &mut self.truth {
            Some(Truth { source: tsrc, reader: tr }) => {
                let taxes = tr.axes().to_vec();
                let (_, t) = read_all(&mut **tr)?;
                if t.first().map_or(0, Vec::len) < out.len() {
                    bail!("{tsrc}: the true force record is shorter than the input");
                }
                let tv: Vec<&[f64]> = axes
                    .iter()
                    .map(|ax| {
                        taxes
                            .iter()
                            .position(|x| x == ax)
                            .map(|s| &t[s][..out.len()])
                            .ok_or_else(|| anyhow!("{tsrc}: axis missing"))
                    })
                    .collect::<Result<_>>()?;
                obs.observe(&meas, &comp, Some(&tv));
            }
            None => obs.observe(&meas, &comp, None),
        }
        Ok(())
    }
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

/// The whole record of `reader`, its `t_s` (if any) checked against `fs`.
fn whole_record(reader: &mut dyn SignalReader, fs: u32, source: &str) -> Result<SignalRecord> {
    let axes = reader.axes().to_vec();
    let (t_s, ch) = read_all(reader)?;
    let rec = SignalRecord { t_s, channels: axes.into_iter().zip(ch).collect() };
    crate::offline::compensate::check_rate(fs, &rec, source)?;
    Ok(rec)
}

/// The box path, block by block ([`stream_box`]). It does not need the
/// sidecar; one that is there may still say the image was tuned for a
/// record's spectrum.
fn compensate_box(
    image: &CoeffImage,
    image_path: &Path,
    reader: Box<dyn SignalReader>,
    raw_timing: bool,
    target: &Target<'_>,
    observed: &mut Observed<'_>,
) -> Result<Compensated> {
    if sidecar_path(image_path).exists() {
        if let Ok(sc) = read_sidecar(image_path, image) {
            note_spectra(&sc, target.monitor);
            for m in sc.axes.iter().filter(|m| target.axes.iter().any(|&a| axis_name(a) == m.axis)) {
                for p in &m.phase_limits {
                    target.monitor.note(&crate::design::phase_limit::compensate_note(&m.axis, p));
                }
            }
        }
    }
    let comp = StreamCompensator::new(image, target.axes, raw_timing, target.source)?;
    let l = image.latency_samples;
    let removed = match (raw_timing, l) {
        (true, _) => ", not removed".to_string(),
        (false, 0) => ", removed".to_string(),
        // The fixed-lag smoother's last L estimates have no measured
        // look-ahead: the record's predicted continuation stands in for it.
        (false, l) => format!(", removed; the last {l} samples use a predicted look-ahead"),
    };
    let how = format!("box filter, latency {l} samples{removed}, streamed in blocks of {BLOCK}");
    stream_compensated(reader, comp, how, target, observed)
}

/// Stream the record of `reader` through `comp` into the target
/// ([`stream_box`]); `how` says what compensated it.
fn stream_compensated(
    mut reader: Box<dyn SignalReader>,
    mut comp: StreamCompensator,
    how: String,
    target: &Target<'_>,
    observed: &mut Observed<'_>,
) -> Result<Compensated> {
    let len = reader.len_hint();
    let samples = target.write(target.has_time, len, |w| stream_box(&mut *reader, &mut comp, w, target, observed))?;
    Ok(Compensated { samples, how })
}

/// Read, compensate, write and observe block by block; the output lags the
/// input by the removed latency, so the inputs (and times) wait in
/// `pending` until their outputs exist. Parsing runs on a thread of its
/// own, a block ahead of the kernel and the writer (two cores: parse ||
/// compensate + format); blocks go back for reuse. Checks the record's
/// rate. Returns the samples written.
fn stream_box(
    reader: &mut dyn SignalReader,
    comp: &mut StreamCompensator,
    w: &mut dyn SignalWriter,
    target: &Target<'_>,
    observed: &mut Observed<'_>,
) -> Result<u64> {
    let (fs, source) = (target.fs, target.source);
    let n_ch = reader.axes().len();
    let axes = reader.axes().to_vec();
    let has_time = reader.has_time();
    let mut pending = Block::new(n_ch);
    let mut out: Vec<Vec<f64>> = vec![Vec::with_capacity(BLOCK); n_ch];
    let mut rate = RateTracker::default();
    let mut written = 0u64;
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
            let m = if n == 0 { comp.finish(&mut out) } else { comp.push(&blk.channels, &mut out) }
                .with_context(|| source.to_string())?;
            let _ = back_tx.send(blk);
            let t = has_time.then(|| &pending.t_s[..m]);
            let outs: Vec<&[f64]> = out.iter().map(Vec::as_slice).collect();
            w.write_block(t, &outs)?;
            let meas: Vec<&[f64]> = pending.channels.iter().map(|c| &c[..m]).collect();
            observed.block(&axes, &meas, &outs, m)?;
            pending.t_s.drain(..m.min(pending.t_s.len()));
            for p in &mut pending.channels {
                p.drain(..m);
            }
            written += m as u64;
            target.monitor.advance(n as u64);
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

/// The input of a smoother, read twice: once for the forward pass, once
/// for its times and the observer.
struct Reading<'a> {
    input: Box<dyn SignalReader>,
    path: &'a Path,
    channels: Option<&'a ChannelMap>,
    /// The bound of its values (N).
    full_scale_n: f64,
}

/// A smoother over a record of any length, in bounded memory: the
/// time-varying one over `drift` (which has no force model: the prior of
/// the axes `priors` is not used), else the stationary one.
fn smooth_spilled(
    image: &CoeffImage,
    sidecar: &ModelSidecar,
    drift: Option<(f64, f64)>,
    priors: &[&str],
    reading: Reading<'_>,
    target: &Target<'_>,
    observed: &mut Observed<'_>,
) -> Result<Compensated> {
    let (spill, input, spilled) = Spill::open(reading, target)?;
    let (dir, source) = (spill.dir, target.source);
    match drift {
        Some((s0, s1)) => {
            let how = format!("time-varying fixed-interval smoother, two FRF states, drift {s0}-{s1} s, zero lag (offline only; forward pass and covariance checkpoints {spilled})");
            if !priors.is_empty() {
                target.monitor.note(&format!(
                    "warning: the harmonic force prior of axis {} is not used: the time-varying smoother of --drift has no force model",
                    priors.join(", ")
                ));
            }
            let columns = target
                .axes
                .iter()
                .map(|&ax| drift_column(image, sidecar, ax, source, (s0, s1), target.monitor))
                .collect::<Result<Vec<_>>>()?;
            let passes = columns
                .iter()
                .zip(target.axes)
                .map(|(c, &ax)| {
                    match c {
                        DriftColumn::Follows(model_at, opts) => {
                            crate::offline::drift::SpilledDriftForward::new(&**model_at, opts, dir)
                                .map(|p| Box::new(p) as Box<dyn SpilledPass>)
                        }
                        DriftColumn::Holds(sm) => crate::offline::smoother::SpilledForward::new(sm, dir)
                            .map(|p| Box::new(p) as Box<dyn SpilledPass>),
                    }
                    .with_context(|| format!("{source}: axis {}", axis_name(ax)))
                })
                .collect::<Result<_>>()?;
            Ok(Compensated { samples: spill.run(input, Box::new(PerChannel(passes)), target, observed)?, how })
        }
        None => {
            let how = format!("fixed-interval smoother, zero lag (offline only; forward pass {spilled})");
            let smoothers = target
                .axes
                .iter()
                .map(|&ax| crate::offline::smoother::axis_smoother(image, sidecar, ax, source))
                .collect::<Result<Vec<_>>>()?;
            let passes = smoothers
                .iter()
                .map(|sm| {
                    crate::offline::smoother::SpilledForward::new(sm, dir).map(|p| Box::new(p) as Box<dyn SpilledPass>)
                })
                .collect::<Result<_>>()?;
            Ok(Compensated { samples: spill.run(input, Box::new(PerChannel(passes)), target, observed)?, how })
        }
    }
}

/// `compensate --offline` on a 3x3 image: the 3x3 smoother's passes
/// spilled to temporary files beside the output, in memory independent of
/// the record's length; the input read twice as [`smooth_spilled`] does.
fn smooth_matrix_spilled(
    image: &MatrixImage,
    image_path: &Path,
    reading: Reading<'_>,
    target: &Target<'_>,
    observed: &mut Observed<'_>,
) -> Result<Compensated> {
    let sidecar = read_sidecar(image_path, image)?;
    let sm = crate::offline::matrix_smoother::MatrixSmoothers::new(image, &sidecar, target.axes, target.source)?;
    let (spill, input, spilled) = Spill::open(reading, target)?;
    let per_axis: Vec<&str> = (0..3).filter(|i| sm.per_axis[*i].is_some()).map(axis_name).collect();
    let how = format!(
        "3x3 fixed-interval smoother, zero lag, crosstalk compensated{} (offline only; forward pass {spilled})",
        if per_axis.is_empty() {
            String::new()
        } else {
            format!("; axis {} smoothed per axis, as the image designs it", per_axis.join(", "))
        }
    );
    let mut pass = Matrix {
        matrix: crate::offline::matrix_smoother::SpilledMatrixForward::new(&sm.matrix, spill.dir)?,
        per_axis: [None, None, None],
    };
    for (slot, p) in pass.per_axis.iter_mut().zip(&sm.per_axis) {
        if let Some(p) = p {
            *slot = Some(crate::offline::smoother::SpilledForward::new(p, spill.dir)?);
        }
    }
    Ok(Compensated { samples: spill.run(input, Box::new(pass), target, observed)?, how })
}

/// How `compensate --offline --drift` smooths one column.
enum DriftColumn {
    /// Following the drift between the sidecar's two states: the model at
    /// state s, and the smoother's settings.
    Follows(ModelAt, crate::offline::drift::DriftSmoothing),
    /// With the first state's model alone: the design from two FRFs could
    /// not pair the axis's states, or passed it through raw.
    Holds(crate::offline::smoother::Smoother),
}

/// The model Ĝ at state s ∈ [0, 1] of a set-up moving between two states.
type ModelAt = Box<dyn Fn(f64) -> crate::fit::PoleResidueModel>;

/// The drift smoothing of column `axis`: both states where the sidecar has
/// them; the stationary smoother, with a warning on `monitor`, where the
/// two-state design held the first state or passed the axis through raw;
/// else why the column cannot follow a drift.
fn drift_column(
    image: &CoeffImage,
    sidecar: &ModelSidecar,
    axis: usize,
    source: &str,
    interval_s: (f64, f64),
    monitor: &dyn Monitor,
) -> Result<DriftColumn> {
    if let Some(why) = sidecar.holds_first_state(axis) {
        monitor.note(&format!(
            "warning: axis {} does NOT FOLLOW the drift: smoothed with the first FRF's model alone ({why})",
            axis_name(axis)
        ));
    } else if sidecar.passed_through_raw(axis).is_none() {
        let (ts, opts) = crate::offline::drift::axis_drift(image, sidecar, axis, source, interval_s)?;
        return Ok(DriftColumn::Follows(Box::new(move |s| ts.at(s)), opts));
    }
    Ok(DriftColumn::Holds(crate::offline::smoother::axis_smoother(image, sidecar, axis, source)?))
}

/// Where the passes of [`smooth_spilled`] and [`smooth_matrix_spilled`]
/// spill (`dir`), and the input's file, opened again for its second reading.
struct Spill<'a> {
    dir: &'a Path,
    path: &'a Path,
    channels: Option<&'a ChannelMap>,
    full_scale_n: f64,
}

impl<'a> Spill<'a> {
    /// The input of `reading` for two readings, spilling beside the
    /// target's output, and the words that say so for `how`.
    fn open(reading: Reading<'a>, target: &Target<'a>) -> Result<(Self, crate::io::spool::TwoReadings, String)> {
        let dir = crate::io::atomic::output_dir(target.output);
        let input = crate::io::spool::TwoReadings::new(reading.input, reading.path, dir)?;
        let words = format!(
            "spilled to temporary files beside the output{}, memory independent of the record's length",
            if input.spooled() { ", with the input (a pipe) for its second reading" } else { "" }
        );
        let spill = Spill { dir, path: reading.path, channels: reading.channels, full_scale_n: reading.full_scale_n };
        Ok((spill, input, words))
    }

    /// The input's file opened again, with the first reading's checks.
    fn reopen(&self) -> Result<Box<dyn SignalReader>> {
        Ok(open_signal_checked(self.path, self.channels, self.full_scale_n)?.0)
    }

    /// The passes over the input's first reading, spilled, then their
    /// backward passes ([`Spill::smooth`]); then the output written with
    /// the input's second reading ([`Spill::write`]). Returns the samples
    /// written.
    fn run(
        &self,
        mut input: crate::io::spool::TwoReadings,
        pass: Box<dyn RecordPass + '_>,
        target: &Target<'_>,
        observed: &mut Observed<'_>,
    ) -> Result<u64> {
        let len_hint = input.first().len_hint();
        target.monitor.set_length(len_hint.unwrap_or(0) * 2);
        let est = self.smooth(input.first(), pass, target)?;
        // The input is read a second time, for its times and the observer.
        let mut again = input.second(|| self.reopen())?;
        let len = len_hint.or(again.len_hint());
        target.write(target.has_time, len, |w| write_spilled(&mut *again, est, w, target, observed))
    }

    /// The forward pass over the blocks of `reader`, spilled, then its
    /// backward pass ([`RecordPass`]). Checks the record's rate.
    fn smooth(
        &self,
        reader: &mut dyn SignalReader,
        mut pass: Box<dyn RecordPass + '_>,
        target: &Target<'_>,
    ) -> Result<Vec<SpilledEstimate>> {
        let source = target.source;
        let mut blk = Block::new(target.axes.len());
        let mut rate = RateTracker::default();
        while reader.read_block(&mut blk, BLOCK)? > 0 {
            rate.push(&blk.t_s);
            pass.push(&blk.channels)?;
            target.monitor.advance(blk.len() as u64);
        }
        if let Some(found) = rate.rate() {
            check_rate_value(target.fs, found, source, "column t_s")?;
        }
        pass.backward(self.dir, target.axes, source, &|n| target.monitor.advance(n))
    }
}

/// A smoother's passes over a record's channels, spilled to temporary
/// files: forward block by block, then backward to one estimate per
/// channel ([`Spill::smooth`]).
trait RecordPass {
    /// Take the next block (one slice per channel, equal lengths).
    fn push(&mut self, channels: &[Vec<f64>]) -> Result<()>;
    /// The backward passes, in `dir`: the estimates of the channels `axes`;
    /// `on_chunk` is told the samples done, over all channels.
    fn backward(
        self: Box<Self>,
        dir: &Path,
        axes: &[usize],
        source: &str,
        on_chunk: &dyn Fn(u64),
    ) -> Result<Vec<SpilledEstimate>>;
}

/// One smoother per channel ([`SpilledPass`]).
struct PerChannel<'a>(Vec<Box<dyn SpilledPass + 'a>>);

impl RecordPass for PerChannel<'_> {
    fn push(&mut self, channels: &[Vec<f64>]) -> Result<()> {
        self.0.iter_mut().zip(channels).try_for_each(|(f, y)| f.push(y))
    }

    fn backward(
        self: Box<Self>,
        dir: &Path,
        axes: &[usize],
        source: &str,
        on_chunk: &dyn Fn(u64),
    ) -> Result<Vec<SpilledEstimate>> {
        let per_axis = |n: u64| on_chunk(n / axes.len().max(1) as u64);
        self.0
            .into_iter()
            .zip(axes)
            .map(|(f, &ax)| f.backward(dir, &format!("f{}", axis_name(ax)), source, &per_axis))
            .collect()
    }
}

/// The 3x3 smoother on fx, fy and fz together, and the per-axis smoother
/// of each row the image runs per axis, whose estimate takes that row's
/// place ([`crate::offline::matrix_smoother::MatrixSmoothers`]).
struct Matrix<'a> {
    matrix: crate::offline::matrix_smoother::SpilledMatrixForward<'a>,
    per_axis: [Option<crate::offline::smoother::SpilledForward<'a>>; 3],
}

impl RecordPass for Matrix<'_> {
    fn push(&mut self, channels: &[Vec<f64>]) -> Result<()> {
        self.matrix.push(std::array::from_fn(|i| channels[i].as_slice()))?;
        for (p, y) in self.per_axis.iter_mut().zip(channels) {
            if let Some(p) = p {
                p.push(y)?;
            }
        }
        Ok(())
    }

    fn backward(
        self: Box<Self>,
        dir: &Path,
        _axes: &[usize],
        source: &str,
        on_chunk: &dyn Fn(u64),
    ) -> Result<Vec<SpilledEstimate>> {
        let est = self.matrix.backward(dir, source, on_chunk)?;
        est.into_iter()
            .zip(self.per_axis)
            .enumerate()
            .map(|(i, (m, p))| match p {
                Some(p) => p.backward(dir, &format!("f{}", axis_name(i)), source, &|_| ()),
                None => Ok(m),
            })
            .collect()
    }
}

/// Write the estimates of [`Spill::smooth`] block by block, with the times
/// of the input read again (`again`), and show them to the observer.
fn write_spilled(
    again: &mut dyn SignalReader,
    mut est: Vec<SpilledEstimate>,
    w: &mut dyn SignalWriter,
    target: &Target<'_>,
    observed: &mut Observed<'_>,
) -> Result<u64> {
    let source = target.source;
    let axes = again.axes().to_vec();
    let mut blk = Block::new(axes.len());
    let mut out: Vec<Vec<f64>> = vec![Vec::with_capacity(BLOCK); axes.len()];
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
        let meas: Vec<&[f64]> = blk.channels.iter().map(Vec::as_slice).collect();
        observed.block(&axes, &meas, &outs, m)?;
        written += m as u64;
        target.monitor.advance(m as u64);
    }
    if est.iter().any(|e| e.left() > 0) {
        bail!("{source}: the input changed while it was compensated (shorter on the second reading)");
    }
    Ok(written)
}
