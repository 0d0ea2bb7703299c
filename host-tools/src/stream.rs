//! `dynocomp stream --serial PORT --output FILE.csv [--duration S | --samples N]`:
//! record the box's stream of raw and compensated samples, converted to
//! newtons with the running image's scaling, and report lost frames.
//!
//! Loss accounting: every stream frame carries a sequence number (+1 per
//! frame sent). A gap between two received frames is a run of lost frames;
//! after `StopStream` the box's `stream_next_seq` (status) reveals frames
//! lost after the last one received. Frames lost before the first received
//! frame cannot be told from "not yet started" and are not counted.
//! Samples the box itself dropped (its queue full) show as gaps in the
//! sample index and are counted separately.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use dynocomp_core::protocol::{AxisSummaryWire, Request, StreamFrame};
use dynocomp_core::sample::SampleFlags;
use dynocomp_core::AXES;

use crate::io::atomic::write_atomic;
use crate::serial_link::Link;

/// Options of `dynocomp stream`.
#[derive(clap::Args, Debug, Clone)]
pub struct StreamArgs {
    /// Serial port of the box (e.g. /dev/ttyACM0).
    #[arg(long)]
    pub serial: String,
    /// Output CSV (t_s, fx, fy, fz, raw_fx, raw_fy, raw_fz for the axes of
    /// the image), written atomically.
    #[arg(long)]
    pub output: PathBuf,
    /// Record this long (seconds).
    #[arg(long, conflicts_with = "samples")]
    pub duration: Option<f64>,
    /// Record this many samples.
    #[arg(long)]
    pub samples: Option<usize>,
    /// Keep one sample out of N (default: the smallest N that keeps the
    /// stream at or below 20 000 samples/s, what USB full speed carries).
    #[arg(long)]
    pub decimation: Option<u16>,
}

/// Streamed samples per second the default decimation aims at.
pub const DEFAULT_STREAM_RATE: u32 = 20_000;

/// What a recording got and lost.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct StreamReport {
    /// Frames received.
    pub frames: u64,
    /// Frames lost (sum of the sequence-number gaps).
    pub lost_frames: u64,
    /// Lost sequence-number ranges (inclusive).
    pub lost_ranges: Vec<(u32, u32)>,
    /// Samples written.
    pub samples: usize,
    /// Samples missing inside received frames' index range that the box
    /// did not send (its queue overflowed), excluding lost frames' samples.
    pub index_gaps: u64,
}

impl StreamReport {
    /// One line for the user.
    pub fn summary(&self) -> String {
        let ranges: Vec<String> = self
            .lost_ranges
            .iter()
            .map(|&(a, b)| if a == b { a.to_string() } else { format!("{a}..{b}") })
            .collect();
        format!(
            "{} samples in {} frames; lost frames: {}{}",
            self.samples,
            self.frames,
            self.lost_frames,
            if ranges.is_empty() { String::new() } else { format!(" (seq {})", ranges.join(", ")) }
        )
    }
}

/// Tracks frame sequence numbers and records losses.
#[derive(Clone, Debug, Default)]
pub struct LossCounter {
    last: Option<u32>,
    /// The report so far.
    pub report: StreamReport,
}

impl LossCounter {
    /// Account for a frame with sequence number `seq`.
    pub fn frame(&mut self, seq: u32) {
        self.report.frames += 1;
        if let Some(last) = self.last {
            self.gap_to(last, seq);
        }
        self.last = Some(seq);
    }

    /// Frames `last+1 .. next` were not received.
    fn gap_to(&mut self, last: u32, next: u32) {
        let gap = next.wrapping_sub(last).wrapping_sub(1);
        if gap > 0 && gap < u32::MAX / 2 {
            self.report.lost_frames += u64::from(gap);
            self.report.lost_ranges.push((last.wrapping_add(1), next.wrapping_sub(1)));
        }
    }

    /// End of recording: the box's next sequence number.
    pub fn finish(&mut self, next_seq: u32) {
        if let Some(last) = self.last {
            self.gap_to(last, next_seq);
        }
    }
}

/// One CSV row's worth of a sample.
struct Row {
    index: u64,
    force: [f64; AXES],
    raw: [f64; AXES],
}

fn newton(code: u16, a: &AxisSummaryWire) -> f64 {
    (f64::from(code) - f64::from(a.adc_offset_code)) * f64::from(a.newton_per_code)
}

fn dac_newton(code: u16, a: &AxisSummaryWire) -> f64 {
    (f64::from(code) - f64::from(a.dac_offset_code)) / f64::from(a.dac_code_per_newton)
}

/// Record from an open link. `stop(samples, elapsed)` ends the recording.
/// At most `max_rows` samples are written (all if `None`).
pub fn record(
    link: &mut Link,
    decimation: Option<u16>,
    output: &Path,
    max_rows: Option<usize>,
    mut stop: impl FnMut(usize, Duration) -> bool,
) -> Result<StreamReport> {
    let status = link.status()?;
    let Some(image) = status.image else {
        bail!("the box runs no image ({:?}): no scaling to convert codes to newtons; flash an image first", status.bypass);
    };
    let fs = status.fs_hz;
    let dec = decimation.unwrap_or_else(|| fs.div_ceil(DEFAULT_STREAM_RATE).clamp(1, u32::from(u16::MAX)) as u16);
    if dec == 0 {
        bail!("--decimation must be at least 1");
    }
    let axes: Vec<(usize, AxisSummaryWire)> = image.axes.iter().enumerate().filter_map(|(i, a)| a.map(|a| (i, a))).collect();
    link.stream.clear();
    link.command(Request::StartStream { decimation: dec })?;
    let mut loss = LossCounter::default();
    let mut rows: Vec<Row> = Vec::new();
    // t_s is the box's sample index / fs (time since the sample path
    // started); the box's u32 index wraps (11.9 h at 100 kHz) and is
    // unwrapped here.
    let mut epoch = 0u64;
    let mut prev_first: Option<u32> = None;
    let start = Instant::now();
    let mut take = |f: StreamFrame, loss: &mut LossCounter, rows: &mut Vec<Row>| {
        loss.frame(f.seq);
        if prev_first.is_some_and(|p| f.first_sample < p) {
            epoch += 1 << 32;
        }
        prev_first = Some(f.first_sample);
        for (k, s) in f.valid().iter().enumerate() {
            let idx = epoch + u64::from(f.first_sample) + k as u64 * u64::from(f.step);
            let bypass = SampleFlags(s.flags).has(SampleFlags::BYPASS);
            let mut force = [f64::NAN; AXES];
            let mut raw = [f64::NAN; AXES];
            for &(i, a) in &axes {
                raw[i] = newton(s.raw[i], &a);
                force[i] = if bypass { newton(s.out[i], &a) } else { dac_newton(s.out[i], &a) };
            }
            rows.push(Row { index: idx, force, raw });
        }
    };
    while !stop(rows.len(), start.elapsed()) {
        while let Some(f) = link.stream.pop_front() {
            take(f, &mut loss, &mut rows);
        }
        for m in link.poll(Duration::from_millis(5))? {
            if let dynocomp_core::protocol::BoxMessage::Stream(f) = m {
                take(f, &mut loss, &mut rows);
            }
        }
        if start.elapsed() > Duration::from_secs(2) && loss.report.frames == 0 {
            // Best effort: leave the box as found.
            let _ = link.command(Request::StopStream);
            bail!("no stream frames from the box within 2 s");
        }
    }
    // Stop, collecting the frames still in flight, then ask where the box's
    // sequence counter ended.
    link.command(Request::StopStream)?;
    while let Some(f) = link.stream.pop_front() {
        take(f, &mut loss, &mut rows);
    }
    let end = link.status()?;
    while let Some(f) = link.stream.pop_front() {
        take(f, &mut loss, &mut rows);
    }
    loss.finish(end.stream_next_seq);
    // Sample-index gaps not explained by lost frames: with index steps of
    // `dec`, count the missing positions between consecutive rows.
    let mut gaps = 0u64;
    for w in rows.windows(2) {
        let d = w[1].index.saturating_sub(w[0].index);
        gaps += (d / u64::from(dec)).saturating_sub(1);
    }
    let lost_samples_in_frames = loss.report.lost_frames * dynocomp_core::protocol::STREAM_BATCH as u64;
    loss.report.index_gaps = gaps.saturating_sub(lost_samples_in_frames);
    if let Some(m) = max_rows {
        rows.truncate(m);
    }
    loss.report.samples = rows.len();

    let names = ["fx", "fy", "fz"];
    write_atomic(output, |w: &mut dyn Write| {
        let mut header = vec!["t_s".to_string()];
        header.extend(axes.iter().map(|&(i, _)| names[i].to_string()));
        header.extend(axes.iter().map(|&(i, _)| format!("raw_{}", names[i])));
        writeln!(w, "{}", header.join(","))?;
        for r in &rows {
            let mut line = format!("{}", r.index as f64 / f64::from(fs));
            for &(i, _) in &axes {
                line.push_str(&format!(",{}", r.force[i]));
            }
            for &(i, _) in &axes {
                line.push_str(&format!(",{}", r.raw[i]));
            }
            writeln!(w, "{line}")?;
        }
        Ok(())
    })
    .with_context(|| format!("{}: cannot write the recording", output.display()))?;
    Ok(loss.report)
}

/// `dynocomp stream`.
pub fn run(args: &StreamArgs) -> Result<StreamReport> {
    if args.duration.is_none() && args.samples.is_none() {
        bail!("give --duration S or --samples N");
    }
    if let Some(d) = args.duration {
        if !(d > 0.0 && d.is_finite()) {
            bail!("--duration {d}: must be a positive number of seconds");
        }
    }
    let mut link = Link::open(&args.serial)?;
    let (dur, n) = (args.duration, args.samples);
    let report = record(&mut link, args.decimation, &args.output, n, |got, t| {
        n.is_some_and(|n| got >= n) || dur.is_some_and(|d| t.as_secs_f64() >= d)
    })?;
    eprintln!("{} -> {}", report.summary(), args.output.display());
    Ok(report)
}
