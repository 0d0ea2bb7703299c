//! `dynocomp stream --serial PORT --output FILE.csv [--duration S | --samples N]`:
//! record the box's stream of raw and compensated samples, converted to
//! newtons with the running image's scaling ([`record`]), and report lost
//! frames ([`LossCounter`]) and the box's health over the recording
//! ([`BoxLoad`]).

use std::io::Write;
use std::path::Path;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use dynocomp_core::protocol::{AxisSummaryWire, Request, Status, StreamFrame};
use dynocomp_core::sample::SampleFlags;
use dynocomp_core::AXES;

use crate::io::atomic::write_atomic;
use crate::link::serial::Link;

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
    /// The box's overruns and interrupt cost (status before and after).
    pub box_load: BoxLoad,
}

/// The sample path's health over a recording, from the box's status before
/// and after it: missed sample deadlines (overruns) during the recording,
/// with a warning if there were any, and the sample interrupt's cost in CPU
/// cycles (mean, max; DWT cycle counter on the box) as a share of the
/// sample period ([`BoxLoad::summary`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct BoxLoad {
    /// Sample rate of the box, Hz.
    pub fs_hz: u32,
    /// The box's core clock, Hz (0 = unknown: virtual box).
    pub core_clock_hz: u32,
    /// Missed sample deadlines during the recording.
    pub overruns: u32,
    /// Missed sample deadlines since the box booted.
    pub overruns_since_boot: u32,
    /// Mean cycles of the sample interrupt (last complete window; 0 = not
    /// measured).
    pub isr_cycles_mean: u32,
    /// Most cycles of any sample interrupt since boot (0 = not measured).
    pub isr_cycles_max: u32,
}

impl BoxLoad {
    /// From the status before (`start`) and after (`end`) a recording.
    pub fn from_statuses(start: &Status, end: &Status) -> BoxLoad {
        BoxLoad {
            fs_hz: end.fs_hz,
            core_clock_hz: end.core_clock_hz,
            overruns: end.counters.overruns.wrapping_sub(start.counters.overruns),
            overruns_since_boot: end.counters.overruns,
            isr_cycles_mean: end.counters.isr_cycles_mean,
            isr_cycles_max: end.counters.isr_cycles_max,
        }
    }

    /// Lines for the user: overruns and the sample interrupt's cost, e.g.
    /// `sample interrupt: mean 1234, max 2345 cycles = 37.2 % (max 70.6 %)
    /// of the sample period at 51200 Hz and 170 MHz`, then a `WARNING:`
    /// line for overruns during the recording and for an interrupt that
    /// took longer than a sample period.
    pub fn summary(&self) -> Vec<String> {
        let mut lines = Vec::new();
        let before = self.overruns_since_boot.wrapping_sub(self.overruns);
        lines.push(format!(
            "box: overruns (missed sample deadlines): {} during this recording, {} since boot",
            self.overruns, self.overruns_since_boot
        ));
        let measured = self.core_clock_hz > 0 && self.fs_hz > 0 && self.isr_cycles_max > 0;
        let period = if measured { f64::from(self.core_clock_hz) / f64::from(self.fs_hz) } else { 0.0 };
        if measured {
            let pct = |c: u32| 100.0 * f64::from(c) / period;
            let mean = if self.isr_cycles_mean > 0 {
                format!(
                    "mean {}, max {} cycles = {:.1} % (max {:.1} %)",
                    self.isr_cycles_mean,
                    self.isr_cycles_max,
                    pct(self.isr_cycles_mean),
                    pct(self.isr_cycles_max)
                )
            } else {
                format!(
                    "mean not yet available, max {} cycles = {:.1} %",
                    self.isr_cycles_max,
                    pct(self.isr_cycles_max)
                )
            };
            lines.push(format!(
                "sample interrupt: {mean} of the sample period at {} Hz and {} MHz ({:.0} cycles per sample)",
                self.fs_hz,
                f64::from(self.core_clock_hz) / 1e6,
                period
            ));
        } else {
            lines.push("sample interrupt: cycle count not measured (the box reports none: virtual box, or no DWT cycle counter)".to_string());
        }
        if self.overruns > 0 {
            lines.push(format!(
                "WARNING: the box missed {} sample deadline(s) during this recording: samples were lost or output late (lower the sample rate or the filter order)",
                self.overruns
            ));
        } else if before > 0 {
            lines
                .push(format!("note: {before} overrun(s) happened before this recording (since boot), none during it"));
        }
        if measured && f64::from(self.isr_cycles_max) >= period {
            lines.push(format!(
                "WARNING: the slowest sample interrupt ({} cycles) took longer than a sample period ({:.0} cycles)",
                self.isr_cycles_max, period
            ));
        }
        lines
    }
}

impl StreamReport {
    /// One line for the user.
    pub fn summary(&self) -> String {
        let ranges: Vec<String> =
            self.lost_ranges.iter().map(|&(a, b)| if a == b { a.to_string() } else { format!("{a}..{b}") }).collect();
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
///
/// Every stream frame carries a sequence number (+1 per frame sent). A gap
/// between two received frames is a run of lost frames; after `StopStream`
/// the box's `stream_next_seq` (status) reveals frames lost after the last
/// one received ([`LossCounter::finish`]). Frames lost before the first
/// received frame cannot be told from "not yet started" and are not
/// counted. Samples the box itself dropped (its queue full) show as gaps in
/// the sample index and are counted separately
/// ([`StreamReport::index_gaps`]).
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
        let why = status.bypass.map_or_else(|| "no reason given".to_string(), |r| r.to_string());
        bail!("the box runs no image ({why}): no scaling to convert codes to newtons; flash an image first");
    };
    let fs = status.fs_hz;
    let dec = decimation.unwrap_or_else(|| fs.div_ceil(DEFAULT_STREAM_RATE).clamp(1, u32::from(u16::MAX)) as u16);
    if dec == 0 {
        bail!("--decimation must be at least 1");
    }
    let axes: Vec<(usize, AxisSummaryWire)> =
        image.axes.iter().enumerate().filter_map(|(i, a)| a.map(|a| (i, a))).collect();
    link.stream.clear();
    link.command(Request::StartStream { decimation: dec })?;
    let mut rec = Recording { axes: &axes, epoch: 0, prev_first: None, loss: LossCounter::default(), rows: Vec::new() };
    let start = Instant::now();
    while !stop(rec.rows.len(), start.elapsed()) {
        while let Some(f) = link.stream.pop_front() {
            rec.take(f);
        }
        for m in link.poll(Duration::from_millis(5))? {
            if let dynocomp_core::protocol::BoxMessage::Stream(f) = m {
                rec.take(f);
            }
        }
        if start.elapsed() > Duration::from_secs(2) && rec.loss.report.frames == 0 {
            // Best effort: leave the box as found.
            let _ = link.command(Request::StopStream);
            bail!("no stream frames from the box within 2 s");
        }
    }
    // Stop, collecting the frames still in flight, then ask where the box's
    // sequence counter ended.
    link.command(Request::StopStream)?;
    while let Some(f) = link.stream.pop_front() {
        rec.take(f);
    }
    let end = link.status()?;
    while let Some(f) = link.stream.pop_front() {
        rec.take(f);
    }
    let Recording { mut loss, mut rows, .. } = rec;
    loss.finish(end.stream_next_seq);
    loss.report.box_load = BoxLoad::from_statuses(&status, &end);
    let lost_samples_in_frames = loss.report.lost_frames * dynocomp_core::protocol::STREAM_BATCH as u64;
    loss.report.index_gaps = index_gaps(&rows, dec).saturating_sub(lost_samples_in_frames);
    if let Some(m) = max_rows {
        rows.truncate(m);
    }
    loss.report.samples = rows.len();
    write_rows(output, &axes, &rows, fs)
        .with_context(|| format!("{}: cannot write the recording", output.display()))?;
    Ok(loss.report)
}

/// The rows of a recording so far, with its losses.
struct Recording<'a> {
    /// The image's axes and their scaling.
    axes: &'a [(usize, AxisSummaryWire)],
    /// t_s is the box's sample index / fs (time since the sample path
    /// started); the box's u32 index wraps (11.9 h at 100 kHz) and is
    /// unwrapped here: the wraps so far, times 2³².
    epoch: u64,
    /// The first sample index of the previous frame.
    prev_first: Option<u32>,
    loss: LossCounter,
    rows: Vec<Row>,
}

impl Recording<'_> {
    /// Account for frame `f` and convert its valid samples to newtons: the
    /// raw ADC codes, and the compensated DAC codes (the ADC codes passed
    /// through in bypass).
    fn take(&mut self, f: StreamFrame) {
        self.loss.frame(f.seq);
        if self.prev_first.is_some_and(|p| f.first_sample < p) {
            self.epoch += 1 << 32;
        }
        self.prev_first = Some(f.first_sample);
        for (k, s) in f.valid().iter().enumerate() {
            let idx = self.epoch + u64::from(f.first_sample) + k as u64 * u64::from(f.step);
            let bypass = SampleFlags(s.flags).has(SampleFlags::BYPASS);
            let mut force = [f64::NAN; AXES];
            let mut raw = [f64::NAN; AXES];
            for &(i, a) in self.axes {
                raw[i] = newton(s.raw[i], &a);
                force[i] = if bypass { newton(s.out[i], &a) } else { dac_newton(s.out[i], &a) };
            }
            self.rows.push(Row { index: idx, force, raw });
        }
    }
}

/// Missing sample positions between consecutive rows, with index steps of
/// `dec` (lost frames' samples included).
fn index_gaps(rows: &[Row], dec: u16) -> u64 {
    let mut gaps = 0u64;
    for w in rows.windows(2) {
        let d = w[1].index.saturating_sub(w[0].index);
        gaps += (d / u64::from(dec)).saturating_sub(1);
    }
    gaps
}

/// Write the recording atomically as CSV: `t_s`, the compensated force of
/// each axis, then its raw force.
fn write_rows(output: &Path, axes: &[(usize, AxisSummaryWire)], rows: &[Row], fs: u32) -> Result<()> {
    let names = ["fx", "fy", "fz"];
    write_atomic(output, |w: &mut dyn Write| {
        let mut header = vec!["t_s".to_string()];
        header.extend(axes.iter().map(|&(i, _)| names[i].to_string()));
        header.extend(axes.iter().map(|&(i, _)| format!("raw_{}", names[i])));
        writeln!(w, "{}", header.join(","))?;
        for r in rows {
            let mut line = format!("{}", r.index as f64 / f64::from(fs));
            for &(i, _) in axes {
                line.push_str(&format!(",{}", r.force[i]));
            }
            for &(i, _) in axes {
                line.push_str(&format!(",{}", r.raw[i]));
            }
            writeln!(w, "{line}")?;
        }
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn load(overruns: u32, since_boot: u32, mean: u32, max: u32) -> BoxLoad {
        BoxLoad {
            fs_hz: 51_200,
            core_clock_hz: 170_000_000,
            overruns,
            overruns_since_boot: since_boot,
            isr_cycles_mean: mean,
            isr_cycles_max: max,
        }
    }

    #[test]
    fn interrupt_cost_is_shown_as_a_share_of_the_sample_period() {
        // 170 MHz / 51.2 kHz = 3 320.3 cycles per sample.
        let lines = load(0, 0, 1_234, 2_345).summary();
        assert_eq!(
            lines,
            vec![
                "box: overruns (missed sample deadlines): 0 during this recording, 0 since boot".to_string(),
                "sample interrupt: mean 1234, max 2345 cycles = 37.2 % (max 70.6 %) of the sample period at 51200 Hz and 170 MHz (3320 cycles per sample)".to_string(),
            ]
        );
        // Another clock and rate: 100 kHz at 168.5 MHz = 1 685 cycles.
        let l = BoxLoad { fs_hz: 100_000, core_clock_hz: 168_500_000, ..load(0, 0, 337, 1_685) }.summary();
        assert!(
            l[1].contains("= 20.0 % (max 100.0 %) of the sample period at 100000 Hz and 168.5 MHz (1685 cycles"),
            "{l:?}"
        );
        // The interrupt took a whole period: warned.
        assert!(
            l.iter().any(|s| s.starts_with(
                "WARNING: the slowest sample interrupt (1685 cycles) took longer than a sample period (1685 cycles)"
            )),
            "{l:?}"
        );
    }

    #[test]
    fn overruns_during_the_recording_are_a_warning() {
        let l = load(3, 5, 1_000, 1_500).summary();
        assert!(l[0].contains("3 during this recording, 5 since boot"), "{l:?}");
        assert!(
            l.iter().any(|s| s.starts_with("WARNING: the box missed 3 sample deadline(s) during this recording")),
            "{l:?}"
        );
        // Only before the recording: a note, no warning.
        let l = load(0, 5, 1_000, 1_500).summary();
        assert!(l.iter().all(|s| !s.contains("WARNING")), "{l:?}");
        assert!(l.iter().any(|s| s.starts_with("note: 5 overrun(s) happened before this recording")), "{l:?}");
        // None at all: neither.
        let l = load(0, 0, 1_000, 1_500).summary();
        assert!(l.iter().all(|s| !s.contains("WARNING") && !s.starts_with("note")), "{l:?}");
    }

    #[test]
    fn overruns_are_counted_across_the_box_counter_wrapping() {
        let mut a = Status {
            protocol: dynocomp_core::protocol::PROTOCOL_VERSION,
            firmware: [0, 1, 0],
            fs_hz: 51_200,
            core_clock_hz: 170_000_000,
            bypass: None,
            active: None,
            image: None,
            counters: Default::default(),
            stream_decimation: None,
            stream_next_seq: 0,
        };
        a.counters.overruns = u32::MAX;
        let mut b = a;
        b.counters.overruns = 1;
        b.counters.isr_cycles_mean = 1_100;
        b.counters.isr_cycles_max = 2_000;
        b.counters.isr_cycles_last = 1_050;
        assert_eq!(
            BoxLoad::from_statuses(&a, &b),
            BoxLoad { overruns: 2, overruns_since_boot: 1, ..load(0, 0, 1_100, 2_000) }
        );
    }

    #[test]
    fn a_box_without_cycle_counts_says_not_measured() {
        for l in [
            BoxLoad { core_clock_hz: 0, ..load(0, 0, 0, 0) },
            BoxLoad { core_clock_hz: 0, ..load(0, 0, 1_000, 2_000) },
            load(0, 0, 0, 0),
        ] {
            let lines = l.summary();
            assert!(lines[1].contains("not measured"), "{lines:?}");
            assert!(!lines[1].contains('%'), "{lines:?}");
        }
        // Max known but no complete mean window yet.
        let l = load(0, 0, 0, 1_660).summary();
        assert!(
            l[1].starts_with("sample interrupt: mean not yet available, max 1660 cycles = 50.0 % of the sample period"),
            "{l:?}"
        );
    }
}
