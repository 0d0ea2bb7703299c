//! `dynocomp compensate --report DIR`: what the compensation did to a
//! record, after the paper's Figs. 10-12, per axis: the whole record, a zoom
//! on a steady stretch of the cut and the amplitude spectra
//! ([`ReportAccumulator::write`]). Everything is accumulated while the record
//! streams through ([`ReportAccumulator::observe`]), so the report's memory
//! does not grow with the record, except for the NRMSE against `--truth`.

use anyhow::{Context, Result};
use plotters::prelude::*;
use rustfft::{num_complex::Complex64, Fft, FftPlanner};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::frf::axis_name;
use crate::report::page::{write_pages, Page};
use crate::report::plot::{build_chart, draw_line, legend_headroom, legend_off_data, mesh, perr, plot_px_height};

/// Pixel columns of the overview; the envelopes keep between this many and
/// twice this many (min, max) buckets.
pub const ENVELOPE_COLUMNS: usize = 1000;
/// Welch segment length (samples): 6.25 Hz resolution at 51.2 kHz.
pub const WELCH_N: usize = 8192;
/// Tooth periods in the zoom window (when the TPF is known).
const ZOOM_TOOTH_PERIODS: f64 = 5.0;

const C_MEAS: RGBColor = RGBColor(127, 127, 127);
const C_COMP: RGBColor = RGBColor(31, 119, 180);
const C_TRUE: RGBColor = RGBColor(44, 160, 44);
const C_ERR: RGBColor = RGBColor(214, 39, 40);
const C_TPF: RGBColor = RGBColor(230, 120, 0);
/// The measured channel's clipped extremes ([`crate::io::clipping`]).
const C_CLIP: RGBColor = RGBColor(148, 0, 211);
/// Error above the band.
const C_ABOVE: RGBColor = RGBColor(255, 127, 14);
/// The compensated band's shading.
const C_BAND: RGBColor = RGBColor(31, 119, 180);

/// Min/max envelope of a stream of samples in bounded memory: buckets of
/// `span` samples; when [`ENVELOPE_COLUMNS`]·2 buckets are full, neighbours
/// merge and `span` doubles.
#[derive(Clone, Debug)]
pub struct Envelope {
    span: u64,
    buckets: Vec<(f64, f64)>,
    cur: (f64, f64),
    cur_n: u64,
    n: u64,
}

impl Default for Envelope {
    fn default() -> Self {
        Envelope {
            span: 1,
            buckets: Vec::with_capacity(2 * ENVELOPE_COLUMNS),
            cur: (f64::INFINITY, f64::NEG_INFINITY),
            cur_n: 0,
            n: 0,
        }
    }
}

impl Envelope {
    /// Take the next samples.
    pub fn push(&mut self, x: &[f64]) {
        for &v in x {
            self.cur = (self.cur.0.min(v), self.cur.1.max(v));
            self.cur_n += 1;
            if self.cur_n == self.span {
                self.buckets.push(self.cur);
                self.cur = (f64::INFINITY, f64::NEG_INFINITY);
                self.cur_n = 0;
                if self.buckets.len() == 2 * ENVELOPE_COLUMNS {
                    for i in 0..ENVELOPE_COLUMNS {
                        let (a, b) = (self.buckets[2 * i], self.buckets[2 * i + 1]);
                        self.buckets[i] = (a.0.min(b.0), a.1.max(b.1));
                    }
                    self.buckets.truncate(ENVELOPE_COLUMNS);
                    self.span *= 2;
                }
            }
        }
        self.n += x.len() as u64;
    }

    /// Samples seen.
    pub fn len(&self) -> u64 {
        self.n
    }

    /// Whether no sample was seen.
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// The buckets as (first sample, last sample, min, max), the partial
    /// last one included.
    pub fn buckets(&self) -> Vec<(u64, u64, f64, f64)> {
        let mut v: Vec<(u64, u64, f64, f64)> = self
            .buckets
            .iter()
            .enumerate()
            .map(|(i, b)| (i as u64 * self.span, (i as u64 + 1) * self.span - 1, b.0, b.1))
            .collect();
        if self.cur_n > 0 {
            let s = self.buckets.len() as u64 * self.span;
            v.push((s, s + self.cur_n - 1, self.cur.0, self.cur.1));
        }
        v
    }
}

/// Welch amplitude spectrum accumulated segment by segment: Hann window of
/// [`WELCH_N`] samples, 50 % overlap, mean power per bin; amplitude
/// 2·sqrt(mean |X|²)/Σw, so a sine of amplitude A reads A at its bin.
pub struct Welch {
    n: usize,
    win: Vec<f64>,
    buf: Vec<f64>,
    acc: Vec<f64>,
    segs: u64,
    fft: Arc<dyn Fft<f64>>,
    scratch: Vec<Complex64>,
}

impl Welch {
    /// An empty accumulator of `n`-sample segments.
    pub fn new(n: usize) -> Welch {
        let win = hann(n);
        let fft = FftPlanner::new().plan_fft_forward(n);
        Welch {
            n,
            win,
            buf: Vec::with_capacity(2 * n),
            acc: vec![0.0; n / 2 + 1],
            segs: 0,
            fft,
            scratch: vec![Complex64::default(); n],
        }
    }

    /// Take the next samples.
    pub fn push(&mut self, x: &[f64]) {
        self.buf.extend_from_slice(x);
        let hop = self.n / 2;
        let mut start = 0;
        while self.buf.len() - start >= self.n {
            self.segment(start, self.n);
            start += hop;
        }
        self.buf.drain(..start);
    }

    fn segment(&mut self, start: usize, len: usize) {
        let win = if len == self.n { self.win.clone() } else { hann(len) };
        let seg = &self.buf[start..start + len];
        let mean = seg.iter().sum::<f64>() / len as f64;
        for (k, s) in self.scratch.iter_mut().enumerate() {
            *s = if k < len { Complex64::new((seg[k] - mean) * win[k], 0.0) } else { Complex64::default() };
        }
        self.fft.process(&mut self.scratch);
        let norm = 2.0 / win.iter().sum::<f64>();
        for (a, x) in self.acc.iter_mut().zip(&self.scratch) {
            *a += (x.norm() * norm).powi(2);
        }
        self.segs += 1;
    }

    /// (bin frequencies in Hz, amplitudes); a record shorter than one
    /// segment gives one zero-padded segment of its own length.
    pub fn spectrum(&mut self, fs_hz: f64) -> (Vec<f64>, Vec<f64>) {
        if self.segs == 0 && self.buf.len() >= 16 {
            self.segment(0, self.buf.len());
        }
        let df = fs_hz / self.n as f64;
        let segs = self.segs.max(1) as f64;
        let f = (0..self.acc.len()).map(|k| k as f64 * df).collect();
        let a = self.acc.iter().map(|p| (p / segs).sqrt()).collect();
        (f, a)
    }
}

fn hann(n: usize) -> Vec<f64> {
    (0..n).map(|k| 0.5 - 0.5 * (2.0 * std::f64::consts::PI * k as f64 / n as f64).cos()).collect()
}

/// Strongest line of an amplitude spectrum above `f_min` Hz (its frequency,
/// refined by a parabola through the peak bin and its neighbours).
pub fn strongest_line(f: &[f64], a: &[f64], f_min: f64) -> Option<f64> {
    let k = (1..a.len().saturating_sub(1)).filter(|&k| f[k] >= f_min).max_by(|&i, &j| a[i].total_cmp(&a[j]))?;
    if a[k].is_nan() || a[k] <= 0.0 {
        return None;
    }
    let (l, c, r) = (a[k - 1], a[k], a[k + 1]);
    let den = l - 2.0 * c + r;
    let off = if den.abs() > 0.0 { 0.5 * (l - r) / den } else { 0.0 };
    Some(f[k] + off.clamp(-0.5, 0.5) * (f[1] - f[0]))
}

/// Running statistics of one zoom window: its sum of squares deviation.
fn window_std(x: &[f64]) -> f64 {
    let n = x.len() as f64;
    let m = x.iter().sum::<f64>() / n;
    (x.iter().map(|v| (v - m).powi(2)).sum::<f64>() / n).sqrt()
}

/// One axis's kept zoom samples: measured, compensated, true.
type ZoomWindow = [Vec<f64>; 3];

/// Per-axis signals of one observation (aligned sample for sample).
struct AxisAcc {
    axis: usize,
    meas: Envelope,
    comp: Envelope,
    truth: Envelope,
    err: Envelope,
    w_meas: Welch,
    w_comp: Welch,
    w_truth: Welch,
    /// Whole records for the NRMSE (only with a truth).
    keep: Option<[Vec<f64>; 3]>,
}

/// Everything the compensation report needs, accumulated block by block:
/// envelopes that halve their resolution when full, a Welch spectrum summed
/// segment by segment, and a short kept window for the zoom. The one
/// exception is the NRMSE against `--truth`, which follows the project's
/// single convention ([`crate::metrics::accuracy`]: zero-phase FFT band limit
/// over the whole record) and therefore keeps the compensated, measured and
/// true forces of each axis (24 bytes per sample and axis) when `--truth` is
/// given.
pub struct ReportAccumulator {
    fs_hz: f64,
    axes: Vec<AxisAcc>,
    has_truth: bool,
    zoom_len: usize,
    /// The window being filled: per axis (measured, compensated, truth).
    cur: Vec<ZoomWindow>,
    cur_start: u64,
    /// Std (summed over axes) of the last windows, newest last.
    recent: Vec<f64>,
    best: Option<(u64, f64, Vec<ZoomWindow>)>,
    max_std: f64,
    n: u64,
    tpf_given: Option<f64>,
    /// The input's clipped extremes, marked on the overviews.
    clipped: Vec<crate::io::clipping::Clipped>,
}

impl ReportAccumulator {
    /// An accumulator for `axes` at `fs_hz`; `tpf_hz` if the spindle speed
    /// and teeth were given; `has_truth` with `--truth`.
    pub fn new(axes: &[usize], fs_hz: f64, tpf_hz: Option<f64>, has_truth: bool) -> Self {
        let zoom_len = match tpf_hz {
            Some(t) if t > 0.0 => ((ZOOM_TOOTH_PERIODS * fs_hz / t).round() as usize).clamp(64, 1 << 15),
            _ => ((0.02 * fs_hz).round() as usize).clamp(64, 1 << 15),
        };
        let n3 = || [Vec::new(), Vec::new(), Vec::new()];
        ReportAccumulator {
            fs_hz,
            axes: axes
                .iter()
                .map(|&axis| AxisAcc {
                    axis,
                    meas: Envelope::default(),
                    comp: Envelope::default(),
                    truth: Envelope::default(),
                    err: Envelope::default(),
                    w_meas: Welch::new(WELCH_N),
                    w_comp: Welch::new(WELCH_N),
                    w_truth: Welch::new(WELCH_N),
                    keep: has_truth.then(n3),
                })
                .collect(),
            has_truth,
            zoom_len,
            cur: axes.iter().map(|_| n3()).collect(),
            cur_start: 0,
            recent: Vec::new(),
            best: None,
            clipped: Vec::new(),
            max_std: 0.0,
            n: 0,
            tpf_given: tpf_hz,
        }
    }

    /// Take the next aligned samples: per channel the measured and the
    /// compensated force, and the true force if there is one.
    pub fn observe(&mut self, meas: &[&[f64]], comp: &[&[f64]], truth: Option<&[&[f64]]>) {
        let n = comp.first().map_or(0, |c| c.len());
        let mut err = Vec::new();
        for (i, a) in self.axes.iter_mut().enumerate() {
            a.meas.push(meas[i]);
            a.comp.push(comp[i]);
            a.w_meas.push(meas[i]);
            a.w_comp.push(comp[i]);
            if let Some(t) = truth {
                a.truth.push(t[i]);
                a.w_truth.push(t[i]);
                err.clear();
                err.extend(comp[i].iter().zip(t[i]).map(|(c, t)| c - t));
                a.err.push(&err);
                if let Some(k) = &mut a.keep {
                    k[0].extend_from_slice(meas[i]);
                    k[1].extend_from_slice(comp[i]);
                    k[2].extend_from_slice(t[i]);
                }
            }
        }
        // Zoom windows: fill, score, keep the steadiest strong one.
        let mut k = 0;
        while k < n {
            let room = self.zoom_len - self.cur[0][0].len();
            let take = room.min(n - k);
            for (i, c) in self.cur.iter_mut().enumerate() {
                c[0].extend_from_slice(&meas[i][k..k + take]);
                c[1].extend_from_slice(&comp[i][k..k + take]);
                if let Some(t) = truth {
                    c[2].extend_from_slice(&t[i][k..k + take]);
                }
            }
            k += take;
            if self.cur[0][0].len() == self.zoom_len {
                self.close_window();
            }
        }
        self.n += n as u64;
    }

    /// Score the full window: steady = its level and its two predecessors'
    /// agree; strong = at least 30 % of the strongest window so far. The
    /// steadiest strong window is kept.
    fn close_window(&mut self) {
        let s: f64 = self.cur.iter().map(|c| window_std(&c[1])).sum();
        self.recent.push(s);
        if self.recent.len() > 3 {
            self.recent.remove(0);
        }
        self.max_std = self.max_std.max(s);
        let start = self.cur_start;
        self.cur_start += self.zoom_len as u64;
        if self.recent.len() < 3 {
            // the first windows: keep one so that short records show something
            if self.best.is_none() {
                self.best = Some((start, f64::INFINITY, self.cur.clone()));
            }
            self.cur.iter_mut().for_each(|c| c.iter_mut().for_each(Vec::clear));
            return;
        }
        let (lo, hi) = self.recent.iter().fold((f64::INFINITY, 0.0f64), |(l, h), &v| (l.min(v), h.max(v)));
        let variation = if hi > 0.0 { (hi - lo) / hi } else { f64::INFINITY };
        let strong = s >= 0.3 * self.max_std;
        let replace = match &self.best {
            None => true,
            Some((_, bv, w)) => {
                let best_std: f64 = w.iter().map(|c| window_std(&c[1])).sum();
                (strong && variation < *bv) || best_std < 0.3 * self.max_std
            }
        };
        if replace && strong {
            self.best = Some((start, variation, self.cur.clone()));
        }
        self.cur.iter_mut().for_each(|c| c.iter_mut().for_each(Vec::clear));
    }

    /// The NRMSE line of each axis against the true force (empty without
    /// one), as [`ReportAccumulator::write`] prints them, without a report.
    pub fn score_lines(&self, band_hz: &dyn Fn(usize) -> f64) -> Vec<String> {
        let fs = self.fs_hz;
        let scored = self.axes.iter().filter_map(|a| a.keep.as_ref().map(|k| (a.axis, k)));
        scored.map(|(axis, k)| Score::of(k, fs, band_hz(axis)).line(axis_name(axis))).collect()
    }

    /// Mark the input's clipped extremes `clipped` on the overviews.
    pub fn mark_clipped(&mut self, clipped: &[crate::io::clipping::Clipped]) {
        self.clipped = clipped.to_vec();
    }

    /// Render the report into `dir`: three SVGs per axis and `index.html`
    /// with `summary` on top. `band_hz`: the NRMSE's band limit per axis.
    /// Returns the files written, `index.html` last, and the NRMSE lines.
    pub fn write(
        mut self,
        dir: &Path,
        summary: &str,
        band_hz: &dyn Fn(usize) -> f64,
    ) -> Result<(Vec<PathBuf>, Vec<String>)> {
        let mut pages = Vec::new();
        let mut sections = Vec::new();
        let mut score_lines = Vec::new();
        // The kept zoom window, or the partial one of a short record.
        let (zoom_start, zoom) = match self.best.take() {
            Some((s, _, w)) => (s, w),
            None => (self.cur_start, self.cur.clone()),
        };
        let how = Rendering {
            fs: self.fs_hz,
            has_truth: self.has_truth,
            tpf_given: self.tpf_given,
            zoom_start,
            clipped: std::mem::take(&mut self.clipped),
        };
        for (i, a) in self.axes.iter_mut().enumerate() {
            let name = axis_name(a.axis);
            let score = a.keep.as_ref().map(|k| Score::of(k, self.fs_hz, band_hz(a.axis)));
            let (entries, svgs) = how.axis(a, &zoom[i], score.as_ref(), band_hz(a.axis))?;
            for ((file, _, _), svg) in entries.iter().zip(svgs) {
                pages.push(Page { name: file.clone(), content: svg });
            }
            sections.push((format!("Axis {name}"), entries));
            score_lines.extend(score.map(|s| s.line(name)));
        }
        let mut text = summary.to_string();
        for l in &score_lines {
            text.push('\n');
            text.push_str(l);
        }
        let index = crate::report::page::index_html("dynocomp compensation report", &text, &sections);
        pages.push(Page { name: "index.html".into(), content: index });
        Ok((write_pages(dir, &pages)?, score_lines))
    }
}

/// The NRMSE of the measured and the compensated force against the true
/// force ([`crate::metrics::accuracy`]), both low-passed at `band_hz`, and
/// the compensated force as written ([`crate::metrics::accuracy_as_written`]).
struct Score {
    band_hz: f64,
    raw: crate::metrics::Accuracy,
    comp: crate::metrics::Accuracy,
    written: crate::metrics::AsWritten,
}

impl Score {
    /// From the kept whole records (measured, compensated, true).
    fn of(k: &[Vec<f64>; 3], fs: f64, band_hz: f64) -> Self {
        let comp = crate::metrics::accuracy(&k[1], &k[2], fs, band_hz);
        let raw = crate::metrics::accuracy(&k[0], &k[2], fs, band_hz);
        let written = crate::metrics::accuracy_as_written(&k[1], &k[2], fs, band_hz);
        Score { band_hz, raw, comp, written }
    }

    /// The figures in %: raw, compensated, both peak-to-peak normalized,
    /// the output as written and the perfect band-limited estimate.
    fn percents(&self) -> [f64; 6] {
        let (r, c, w) = (&self.raw, &self.comp, &self.written);
        [r.nrmse, c.nrmse, r.nrmse_p2p, c.nrmse_p2p, w.output.nrmse, w.perfect.nrmse].map(|v| v * 100.0)
    }

    /// The sentence of the overview's caption.
    fn caption(&self) -> String {
        let (b, [raw, comp, raw_p2p, comp_p2p, written, perfect]) = (self.band_hz, self.percents());
        format!(
            "NRMSE against the true force (RMS error / std of the true force, both low-passed at {b:.0} Hz, \
             5 % of the record excluded at each end): measured {raw:.3} %, compensated {comp:.3} % \
             (peak-to-peak normalization: {raw_p2p:.3} % and {comp_p2p:.3} %). As written, unfiltered, against the \
             true force through the anti-aliasing filter alone: {written:.3} %, where a perfect estimate \
             band-limited to {b:.0} Hz reaches {perfect:.3} %.",
        )
    }

    /// The line of the summary and of stderr for axis `name`.
    fn line(&self, name: &str) -> String {
        let (b, [raw, comp, raw_p2p, comp_p2p, written, perfect]) = (self.band_hz, self.percents());
        format!(
            "f{name}: NRMSE measured {raw:.3} %, compensated {comp:.3} % (band {b:.0} Hz; p2p-normalized \
             {raw_p2p:.3} % / {comp_p2p:.3} %); as written {written:.3} % vs {perfect:.3} % for a perfect \
             band-limited estimate",
        )
    }
}

/// What every axis's pages of [`ReportAccumulator::write`] share.
struct Rendering {
    fs: f64,
    has_truth: bool,
    /// The tooth-passing frequency given (Hz).
    tpf_given: Option<f64>,
    /// The first sample of the zoom window.
    zoom_start: u64,
    /// The input's clipped extremes.
    clipped: Vec<crate::io::clipping::Clipped>,
}

impl Rendering {
    /// The overview, zoom and spectrum of axis `a` with their (file, title,
    /// caption) entries; `zoom`: its kept window, `score`: its NRMSE with a
    /// true force.
    fn axis(
        &self,
        a: &mut AxisAcc,
        zoom: &ZoomWindow,
        score: Option<&Score>,
        band_hz: f64,
    ) -> Result<(Vec<Entry>, [String; 3])> {
        let (fs, has_truth) = (self.fs, self.has_truth);
        let name = axis_name(a.axis);
        let (f, am) = a.w_meas.spectrum(fs);
        let (_, ac) = a.w_comp.spectrum(fs);
        let at = if has_truth { Some(a.w_truth.spectrum(fs).1) } else { None };
        let (tpf, tpf_how) = match self.tpf_given {
            Some(t) => (Some(t), "from --spindle-rpm and --teeth".to_string()),
            None => match strongest_line(&f, &ac, 20.0) {
                Some(t) => (Some(t), "the strongest line of the compensated spectrum".to_string()),
                None => (None, String::new()),
            },
        };
        let score = score.map(Score::caption).unwrap_or_default();
        let mut zw = zoom.clone();
        if let Some(t) = tpf.filter(|t| *t > 0.0) {
            let keep = ((ZOOM_TOOTH_PERIODS * fs / t).round() as usize).max(16);
            zw.iter_mut().for_each(|v| v.truncate(keep));
        }
        let clips: Vec<&crate::io::clipping::Clipped> = self.clipped.iter().filter(|c| c.axis == a.axis).collect();
        let overview =
            plot_overview(a, fs, band_hz, &clips).with_context(|| format!("report: axis {name}: overview"))?;
        let zoom_svg = plot_zoom(&zw, self.zoom_start, fs, has_truth, name)
            .with_context(|| format!("report: axis {name}: zoom"))?;
        let spec = plot_spectrum(&f, [&am, &ac], at.as_deref(), tpf, band_hz, name)
            .with_context(|| format!("report: axis {name}: spectrum"))?;
        let dur = a.meas.len() as f64 / fs;
        let entries = vec![
            (
                format!("{name}_overview.svg"),
                format!("Axis {name}: the whole record"),
                format!(
                    "{} samples ({dur:.3} s). Shaded bands: the minimum and maximum of each pixel column (min/max envelope) of the \
                     measured force (grey) and the compensated force (blue){}.{}",
                    a.meas.len(),
                    if has_truth {
                        ", the true force on top (green outline) and, below, the error compensated − true split at the band \
                         edge: in the band (red, what the NRMSE scores) and above it (orange, noise the NRMSE leaves out; \
                         low-pass the output to remove it)"
                    } else {
                        ""
                    },
                    if score.is_empty() { String::new() } else { format!(" {score}") }
                ) + &clip_caption(&clips, fs),
            ),
            (
                format!("{name}_zoom.svg"),
                format!("Axis {name}: zoom on a steady stretch of the cut"),
                format!(
                    "{} samples from t = {:.4} s, every sample drawn: the window whose level agrees best with the two before it \
                     among those at least 30 % as strong as the strongest.",
                    zw[0].len(),
                    self.zoom_start as f64 / fs
                ),
            ),
            (
                format!("{name}_spectrum.svg"),
                format!("Axis {name}: amplitude spectra"),
                format!(
                    "Welch amplitude spectra (Hann window of {WELCH_N} samples, {:.2} Hz resolution, 50 % overlap, mean power) \
                     of the measured and compensated forces{}. Top: the compensated band (shaded, up to {band_hz:.0} Hz) \
                     and a little beyond; bottom: up to Nyquist, where everything right of the band is out of band. {}",
                    fs / WELCH_N as f64,
                    if has_truth { " and of the true force (dashed, on top)" } else { "" },
                    match tpf {
                        Some(t) => format!("Dotted: the tooth-passing frequency {t:.1} Hz ({tpf_how}) and its harmonics in the band."),
                        None => "No tooth-passing frequency given or found.".to_string(),
                    }
                ),
            ),
        ];
        Ok((entries, [overview, zoom_svg, spec]))
    }
}

/// A page's (file, title, caption) in the index.
type Entry = (String, String, String);

impl crate::offline::record::Observer for ReportAccumulator {
    fn observe(&mut self, measured: &[&[f64]], compensated: &[&[f64]], truth: Option<&[&[f64]]>) {
        ReportAccumulator::observe(self, measured, compensated, truth);
    }
}

/// Draw an envelope as a filled band (one polygon, max edge then min edge
/// backwards), or as a line when every bucket is a single sample.
fn draw_envelope(
    chart: &mut crate::report::plot::Chart<'_>,
    env: &[(u64, u64, f64, f64)],
    fs: f64,
    color: RGBColor,
    alpha: f64,
    label: &str,
) -> Result<()> {
    let t = |s: u64| s as f64 / fs;
    let mut pts: Vec<(f64, f64)> = Vec::with_capacity(4 * env.len());
    for &(a, b, _, hi) in env {
        pts.push((t(a), hi));
        pts.push((t(b), hi));
    }
    for &(a, b, lo, _) in env.iter().rev() {
        pts.push((t(b), lo));
        pts.push((t(a), lo));
    }
    let fill = color.mix(alpha).filled();
    let edge = ShapeStyle::from(&color).stroke_width(1);
    chart.draw_series(std::iter::once(Polygon::new(pts, fill))).map_err(perr)?;
    let top: Vec<(f64, f64)> = env.iter().map(|&(a, b, _, hi)| (0.5 * (t(a) + t(b)), hi)).collect();
    let bot: Vec<(f64, f64)> = env.iter().map(|&(a, b, lo, _)| (0.5 * (t(a) + t(b)), lo)).collect();
    chart.draw_series(std::iter::once(PathElement::new(bot, edge))).map_err(perr)?;
    chart.draw_series(std::iter::once(PathElement::new(top, edge))).map_err(perr)?.label(label).legend(
        move |(x, y)| {
            let swatch: DynElement<'static, SVGBackend, (i32, i32)> = if alpha > 0.0 {
                Rectangle::new([(x, y - 6), (x + 20, y + 6)], fill).into_dyn()
            } else {
                PathElement::new(vec![(x, y - 4), (x + 20, y - 4)], edge).into_dyn()
            };
            swatch
        },
    );
    Ok(())
}

fn range_of<'a>(envs: impl Iterator<Item = &'a [(u64, u64, f64, f64)]>) -> (f64, f64) {
    let (lo, hi) = envs.flatten().fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), e| (l.min(e.2), h.max(e.3)));
    if lo.is_finite() && hi.is_finite() {
        crate::report::plot::pad_range((lo, hi), 0.05, 1e-9)
    } else {
        (-1.0, 1.0)
    }
}

/// `a_overview.svg`: the whole record, measured and compensated (and the
/// true force and the error with `--truth`), drawn as min/max envelopes
/// over at most [`ENVELOPE_COLUMNS`]-2x that many buckets, never every
/// sample. With the truth, the error is split at `band_hz` (the kept
/// records, zero-phase FFT split as [`crate::metrics::lowpass`]): in the
/// band, what the NRMSE scores, and above it, each on its own scale.
fn plot_overview(a: &AxisAcc, fs: f64, band_hz: f64, clips: &[&crate::io::clipping::Clipped]) -> Result<String> {
    let name = axis_name(a.axis);
    let (m, c, t) = (a.meas.buckets(), a.comp.buckets(), a.truth.buckets());
    let errors = a.keep.as_ref().map(|k| {
        let e: Vec<f64> = k[1].iter().zip(&k[2]).map(|(c, t)| c - t).collect();
        let low = crate::metrics::lowpass(&e, fs, band_hz);
        let high: Vec<f64> = e.iter().zip(&low).map(|(e, l)| e - l).collect();
        [envelope_of(&low), envelope_of(&high)]
    });
    let xr = (0.0, (a.meas.len().max(2) - 1) as f64 / fs);
    let mut svg = String::new();
    {
        let h = if errors.is_some() { 900 } else { 440 };
        let root = SVGBackend::with_string(&mut svg, (1100, h)).into_drawing_area();
        root.fill(&WHITE).map_err(perr)?;
        let (top, bottom) = if errors.is_some() { root.split_vertically(440) } else { (root.clone(), root.clone()) };
        let mut labels: Vec<&str> =
            if errors.is_some() { vec!["measured", "compensated", "true"] } else { vec!["measured", "compensated"] };
        if !clips.is_empty() {
            labels.push(CLIP_LABEL);
        }
        let yr = range_of([m.as_slice(), c.as_slice(), t.as_slice()].into_iter());
        let yr = legend_headroom(yr, labels.len(), plot_px_height(&top));
        let mut ch = build_chart(&top, &format!("f{name}: measured and compensated force, whole record"), xr, yr)?;
        mesh(&mut ch, "time (s)", "force (N)", &fmt_s, &fmt_n, 8)?;
        draw_envelope(&mut ch, &m, fs, C_MEAS, 0.35, "measured")?;
        draw_envelope(&mut ch, &c, fs, C_COMP, 0.35, "compensated")?;
        if errors.is_some() {
            draw_envelope(&mut ch, &t, fs, C_TRUE, 0.0, "true")?;
        }
        let (pm, pc, pt) = (envelope_line(&m, fs), envelope_line(&c, fs), envelope_line(&t, fs));
        let mut shown: Vec<&[(f64, f64)]> = if errors.is_some() { vec![&pm, &pc, &pt] } else { vec![&pm, &pc] };
        let rails: Vec<Vec<(f64, f64)>> =
            clips.iter().map(|c| vec![(xr.0, c.extreme.value), (xr.1, c.extreme.value)]).collect();
        for (k, rail) in rails.iter().enumerate() {
            draw_line(&mut ch, rail, yr, f64::INFINITY, C_CLIP, 2, true, if k == 0 { CLIP_LABEL } else { "" })?;
            shown.push(rail);
        }
        legend_off_data(&mut ch, SeriesLabelPosition::UpperRight, &labels, &shown)?;
        if let Some([low, high]) = errors {
            let (band_area, above_area) = bottom.split_vertically(230);
            let panels = [
                (band_area, low, C_ERR, format!("f{name}: error in the band, 0-{band_hz:.0} Hz (scored by the NRMSE)")),
                (above_area, high, C_ABOVE, format!("f{name}: error above {band_hz:.0} Hz (out of band, not scored)")),
            ];
            // The NRMSE leaves out 5 % at each end (filter edges, start-up):
            // the scale follows the scored part, the ends are shaded.
            let n = a.meas.len();
            let (s0, s1) = (n / 20, n - n / 20);
            let edges = [(xr.0, s0 as f64 / fs), (s1 as f64 / fs, xr.1)];
            for (area, env, color, title) in panels {
                let scored: Vec<_> = env.iter().copied().filter(|b| b.0 >= s0 && b.1 < s1).collect();
                let yr = range_of(std::iter::once(if scored.is_empty() { env.as_slice() } else { scored.as_slice() }));
                let labels = ["not scored (ends)", "compensated − true"];
                let yr = legend_headroom(yr, labels.len(), plot_px_height(&area));
                let mut ch = build_chart(&area, &title, xr, yr)?;
                mesh(&mut ch, "time (s)", "error (N)", &fmt_s, &fmt_n, 5)?;
                for (k, e) in edges.iter().enumerate() {
                    let label = if k == 0 { "not scored (ends)" } else { "" };
                    crate::report::plot::shade(&mut ch, *e, xr, yr, C_MEAS, 0.15, label)?;
                }
                let clipped: Vec<_> = env.iter().map(|&(a, b, lo, hi)| (a, b, lo.max(yr.0), hi.min(yr.1))).collect();
                draw_envelope(&mut ch, &clipped, fs, color, 0.35, labels[1])?;
                legend_off_data(&mut ch, SeriesLabelPosition::UpperRight, &labels, &[&envelope_line(&clipped, fs)])?;
            }
        }
        root.present().map_err(perr)?;
    }
    Ok(svg)
}

/// The overview's legend entry for the clipped extremes.
const CLIP_LABEL: &str = "clipped (measured)";

/// The overview caption's sentence on `clips` (empty without any).
fn clip_caption(clips: &[&crate::io::clipping::Clipped], fs: f64) -> String {
    if clips.is_empty() {
        return String::new();
    }
    let each: Vec<String> = clips
        .iter()
        .map(|c| {
            let e = &c.extreme;
            format!(
                "its {} {} N on {} samples in {} plateaus, the first at t = {:.4} s",
                if c.at_max { "maximum" } else { "minimum" },
                e.value,
                e.samples,
                e.plateaus,
                e.first as f64 / fs
            )
        })
        .collect();
    format!(
        " Clipped: the measured force holds {}. Dashed violet: where it was clipped; the compensated force is wrong \
         around those samples. Measure again with a larger range.",
        each.join("; and ")
    )
}

/// An envelope as one polyline (s, N) through each bucket's minimum and
/// maximum: the pixels it covers, for placing a legend off it.
fn envelope_line(env: &[(u64, u64, f64, f64)], fs: f64) -> Vec<(f64, f64)> {
    env.iter().flat_map(|&(a, b, lo, hi)| [(a as f64 / fs, lo), (b as f64 / fs, hi)]).collect()
}

/// The min/max envelope of a whole record.
fn envelope_of(x: &[f64]) -> Vec<(u64, u64, f64, f64)> {
    let mut e = Envelope::default();
    e.push(x);
    e.buckets()
}

/// `a_zoom.svg`: a few tooth periods where the cut is steady, every
/// sample, measured and compensated overlaid.
fn plot_zoom(w: &[Vec<f64>; 3], start: u64, fs: f64, has_truth: bool, name: &str) -> Result<String> {
    let t0 = start as f64 / fs;
    let pts = |x: &[f64]| -> Vec<(f64, f64)> {
        x.iter().enumerate().map(|(k, v)| ((t0 + k as f64 / fs) * 1e3, *v)).collect()
    };
    let n = w[0].len().max(2);
    let xr = (t0 * 1e3, (t0 + (n - 1) as f64 / fs) * 1e3);
    let all = w[0].iter().chain(&w[1]).chain(if has_truth { &w[2][..] } else { &[][..] }).copied();
    let yr =
        crate::report::plot::finite_range(all).map_or((-1.0, 1.0), |r| crate::report::plot::pad_range(r, 0.05, 1e-9));
    let labels: &[&str] = if has_truth { &["measured", "compensated", "true"] } else { &["measured", "compensated"] };
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (1100, 440)).into_drawing_area();
        root.fill(&WHITE).map_err(perr)?;
        let yr = legend_headroom(yr, labels.len(), plot_px_height(&root));
        let mut ch = build_chart(&root, &format!("f{name}: steady cut, every sample"), xr, yr)?;
        mesh(&mut ch, "time (ms)", "force (N)", &fmt_n, &fmt_n, 8)?;
        let big = (yr.1 - yr.0) * 10.0;
        let lines: Vec<Vec<(f64, f64)>> = w.iter().take(labels.len()).map(|x| pts(x)).collect();
        draw_line(&mut ch, &lines[0], yr, big, C_MEAS, 2, false, labels[0])?;
        draw_line(&mut ch, &lines[1], yr, big, C_COMP, 2, false, labels[1])?;
        if has_truth {
            draw_line(&mut ch, &lines[2], yr, big, C_TRUE, 2, true, labels[2])?;
        }
        let shown: Vec<&[(f64, f64)]> = lines.iter().map(|l| l.as_slice()).collect();
        legend_off_data(&mut ch, SeriesLabelPosition::UpperRight, labels, &shown)?;
        root.present().map_err(perr)?;
    }
    Ok(svg)
}

/// `a_spectrum.svg`: Welch amplitude spectra of the measured and
/// compensated (`[am, ac]`) and true forces in two panels: the compensated
/// band (up to `band_hz`, shaded) and a little beyond, with the
/// tooth-passing frequency and its harmonics in the band marked (given by
/// `--spindle-rpm`/`--teeth`, else the strongest line of the compensated
/// spectrum); and the whole range up to Nyquist, the band shaded.
fn plot_spectrum(
    f: &[f64],
    [am, ac]: [&[f64]; 2],
    at: Option<&[f64]>,
    tpf: Option<f64>,
    band_hz: f64,
    name: &str,
) -> Result<String> {
    let db = |v: &f64| 20.0 * v.max(1e-12).log10();
    let fmax = f.last().copied().unwrap_or(1.0);
    let peak = am.iter().chain(ac).copied().fold(0.0f64, f64::max).max(1e-9);
    let yr = (db(&peak) - 100.0, db(&peak) + 10.0);
    let pts = |a: &[f64], hi: f64| -> Vec<(f64, f64)> {
        f.iter().zip(a).skip(1).take_while(|(f, _)| **f <= hi).map(|(f, a)| (*f, db(a))).collect()
    };
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (1100, 860)).into_drawing_area();
        root.fill(&WHITE).map_err(perr)?;
        let (top, bottom) = root.split_vertically(470);
        let zoom_hi = (1.25 * band_hz).min(fmax);
        let panels = [
            (top, zoom_hi, format!("f{name}: amplitude spectra in the compensated band (0-{band_hz:.0} Hz)")),
            (bottom, fmax, format!("f{name}: amplitude spectra up to Nyquist")),
        ];
        for (i, (area, hi, title)) in panels.into_iter().enumerate() {
            let xr = (0.0, hi);
            let tpf_label = tpf.filter(|t| *t > 0.0 && i == 0).map(|t| format!("TPF {t:.1} Hz and harmonics"));
            let mut labels = vec!["compensated band"];
            labels.extend(tpf_label.as_deref());
            labels.extend(["measured", "compensated", "true"].iter().take(if at.is_some() { 3 } else { 2 }));
            let yr = legend_headroom(yr, labels.len(), plot_px_height(&area));
            let mut ch = build_chart(&area, &title, xr, yr)?;
            mesh(&mut ch, "frequency (Hz)", "amplitude (dB re 1 N)", &crate::report::plot::hz, &fmt_n, 10)?;
            crate::report::plot::shade(&mut ch, (0.0, band_hz), xr, yr, C_BAND, 0.12, "compensated band")?;
            if let (Some(t), Some(tpf_label)) = (tpf.filter(|t| *t > 0.0 && i == 0), &tpf_label) {
                let style = ShapeStyle::from(&C_TPF.mix(0.7)).stroke_width(1);
                let harmonics = (1..=40).map(|k| k as f64 * t).take_while(|x| *x <= band_hz.min(hi));
                for (k, x) in harmonics.enumerate() {
                    let ann =
                        ch.draw_series(DashedLineSeries::new(vec![(x, yr.0), (x, yr.1)], 2, 5, style)).map_err(perr)?;
                    if k == 0 {
                        ann.label(tpf_label.clone())
                            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], style));
                    }
                }
            }
            let big = 1e9;
            let (lm, lc) = (pts(am, hi), pts(ac, hi));
            let lt = at.map(|at| pts(at, hi)).unwrap_or_default();
            draw_line(&mut ch, &lm, yr, big, C_MEAS, 2, false, "measured")?;
            draw_line(&mut ch, &lc, yr, big, C_COMP, 1, false, "compensated")?;
            if at.is_some() {
                draw_line(&mut ch, &lt, yr, big, C_TRUE, 2, true, "true")?;
            }
            legend_off_data(&mut ch, SeriesLabelPosition::LowerRight, &labels, &[&lm, &lc, &lt])?;
        }
        root.present().map_err(perr)?;
    }
    Ok(svg)
}

fn fmt_s(v: &f64) -> String {
    format!("{}", (v * 1e6).round() / 1e6)
}

fn fmt_n(v: &f64) -> String {
    let r = (v * 1e3).round() / 1e3;
    format!("{}", if r == 0.0 { 0.0 } else { r })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The envelope's buckets hold the exact min and max of the samples they
    /// cover (checked against a direct computation), stay within
    /// 2·ENVELOPE_COLUMNS, and cover every sample once, in any block cutting.
    #[test]
    fn envelope_is_exact_and_bounded() {
        let x: Vec<f64> = (0..123_457).map(|k| ((k as f64) * 0.013).sin() * (1.0 + (k % 97) as f64)).collect();
        for cut in [1, 1000, 123_457] {
            let mut e = Envelope::default();
            x.chunks(cut).for_each(|c| e.push(c));
            let b = e.buckets();
            assert!(b.len() <= 2 * ENVELOPE_COLUMNS + 1 && b.len() >= ENVELOPE_COLUMNS, "{}", b.len());
            let mut next = 0u64;
            for &(s, l, lo, hi) in &b {
                assert_eq!(s, next);
                let seg = &x[s as usize..=l as usize];
                assert_eq!(lo, seg.iter().copied().fold(f64::INFINITY, f64::min));
                assert_eq!(hi, seg.iter().copied().fold(f64::NEG_INFINITY, f64::max));
                next = l + 1;
            }
            assert_eq!(next, x.len() as u64);
        }
    }

    /// A sine of amplitude 3 N at 1100 Hz reads 3 N (within the Hann
    /// window's scalloping, < 16 %) at its line, the strongest line found is
    /// 1100 Hz within a bin, and a record without a line finds none.
    #[test]
    fn welch_reads_a_sine_amplitude_and_its_frequency() {
        let fs = 51200.0;
        let x: Vec<f64> =
            (0..200_000).map(|k| 3.0 * (2.0 * std::f64::consts::PI * 1100.0 * k as f64 / fs).sin() + 5.0).collect();
        let mut w = Welch::new(WELCH_N);
        x.chunks(777).for_each(|c| w.push(c));
        let (f, a) = w.spectrum(fs);
        let k = (1100.0 / (fs / WELCH_N as f64)).round() as usize;
        let peak = a[k - 1..=k + 1].iter().copied().fold(0.0, f64::max);
        assert!((peak - 3.0).abs() < 0.16 * 3.0, "{peak}");
        let found = strongest_line(&f, &a, 20.0).unwrap();
        assert!((found - 1100.0).abs() < fs / WELCH_N as f64, "{found}");
        let mut z = Welch::new(WELCH_N);
        z.push(&vec![1.0; 50_000]);
        let (f, a) = z.spectrum(fs);
        assert!(strongest_line(&f, &a, 20.0).is_none());
    }
}
