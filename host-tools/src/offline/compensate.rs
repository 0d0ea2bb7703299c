//! Offline compensation of recorded forces through the core kernel, bit-exact
//! with the box: the same f32 kernel code (its block path, bit-identical to
//! the box's per-sample `step`), the same coefficients, the axes in lockstep
//! ([`compensate_record`], [`StreamCompensator`]). A parallel-elaboration image
//! (offline only) splits the record into its bands with zero-phase filters,
//! runs each band through its own compensator and sums
//! ([`compensate_parallel`]).

use anyhow::{bail, Context, Result};
use dynocomp_core::image::{CoeffImage, MatrixImage, ParallelImage};
use dynocomp_core::kernel::{process_blocks, AxisFilter, AxisState, BlockJob, LOCKSTEP_AXES};
use dynocomp_core::mimo::{MimoFilter, MimoState};

use crate::frf::axis_name;
use crate::io::signal_csv::SignalRecord;
use crate::numeric::predict::{predict_after, WINDOW as PREDICT_WINDOW};

/// Relative tolerance between the rate implied by `t_s` and the image's rate.
pub use crate::io::signal::FS_TOLERANCE;

/// Check a record's `t_s` column (if any) against the image's sample rate.
pub fn check_sample_rate(image: &CoeffImage, rec: &SignalRecord, source: &str) -> Result<()> {
    check_rate(image.fs_hz, rec, source)
}

/// Compensate every force column of `rec` with the image's compensator for
/// that axis.
///
/// Each column is converted to f32 and run through the core kernel, exactly as
/// the box does after its ADC scaling. With `raw_timing == false` the output is
/// aligned to the input: the image's declared latency L (samples) is removed by
/// shifting the output back by L samples; to keep the record's length the
/// kernel is fed L extra samples, the record's continuation predicted from
/// its end ([`look_ahead`]), so the last L output samples are estimates made
/// with a predicted rather than a measured look-ahead.
pub fn compensate_record(
    image: &CoeffImage,
    rec: &SignalRecord,
    raw_timing: bool,
    source: &str,
) -> Result<SignalRecord> {
    let axes: Vec<usize> = rec.channels.iter().map(|c| c.0).collect();
    // Room for the latency's look-ahead, added in place by the kernel run.
    let room = usize::from(image.latency_samples);
    let inputs = rec
        .channels
        .iter()
        .map(|(_, x)| {
            let mut v = Vec::with_capacity(x.len() + room);
            v.extend(x.iter().map(|&u| u as f32));
            v
        })
        .collect();
    let outputs = compensate_f32(image, &axes, inputs, raw_timing, source)?;
    Ok(SignalRecord { t_s: rec.t_s.clone(), channels: axes.into_iter().zip(outputs).collect() })
}

/// [`compensate_record`] on channels already in the box's input precision
/// (f32, N): `inputs[c]` is the channel of axis `axes[c]` (0 = x), all of
/// the same length; the outputs (N) in the same order, aligned as
/// [`compensate_record`] aligns them. For callers whose samples are not a
/// [`SignalRecord`] (e.g. arrays of another language): the one conversion
/// to f32 is theirs, the kernel run is this one.
pub fn compensate_f32(
    image: &CoeffImage,
    axes: &[usize],
    inputs: Vec<Vec<f32>>,
    raw_timing: bool,
    source: &str,
) -> Result<Vec<Vec<f64>>> {
    let mut outputs: Vec<Vec<f64>> = inputs.iter().map(|u| vec![0.0; u.len()]).collect();
    let mut sinks: Vec<&mut [f64]> = outputs.iter_mut().map(Vec::as_mut_slice).collect();
    compensate_f32_into(image, axes, inputs, raw_timing, source, &mut sinks)?;
    Ok(outputs)
}

/// [`compensate_f32`] writing channel c's outputs (N) into `outputs[c]`,
/// which has its input's length: a caller's own buffer (e.g. an array of
/// another language), written once.
pub fn compensate_f32_into(
    image: &CoeffImage,
    axes: &[usize],
    inputs: Vec<Vec<f32>>,
    raw_timing: bool,
    source: &str,
    outputs: &mut [&mut [f64]],
) -> Result<()> {
    let latency = if raw_timing { 0 } else { usize::from(image.latency_samples) };
    anyhow::ensure!(
        outputs.len() == axes.len()
            && inputs.len() == axes.len()
            && inputs.iter().zip(&*outputs).all(|(u, o)| u.len() == o.len()),
        "{source}: one output of its input's length per channel"
    );
    let mut jobs = Vec::with_capacity(axes.len());
    for (axis, input) in axes.iter().zip(inputs) {
        jobs.push((axis_filter(image, *axis, source)?, input));
    }
    for ((axis, y), out) in axes.iter().zip(run_kernel(jobs, latency)).zip(outputs.iter_mut()) {
        if let Some(k) = y.iter().position(|v| !v.is_finite()) {
            bail!(
                "{source}: compensated f{} became non-finite at sample {k}; the image is unusable for this record",
                axis_name(*axis)
            );
        }
        for (o, &v) in out.iter_mut().zip(&y[latency..]) {
            *o = f64::from(v);
        }
    }
    Ok(())
}

/// The image's compensator for the record's column of `axis`; an error
/// naming the axes the image covers if it has none.
fn axis_filter<'a>(image: &'a CoeffImage, axis: usize, source: &str) -> Result<&'a AxisFilter> {
    match image.axes.get(axis).and_then(Option::as_ref) {
        Some(axis_img) => Ok(&axis_img.filter),
        None => bail!(
            "{source}: column f{} has no compensator in the image (it covers {}); drop the column or design for that axis",
            axis_name(axis),
            image.axes.iter().flatten().map(|a| axis_name(a.axis as usize)).collect::<Vec<_>>().join(", ")
        ),
    }
}

/// Every axis through [`run_kernel`], inputs in f64, outputs without the
/// first `latency`; Err(k): the first sample k (counting the fed samples)
/// whose output is non-finite.
#[cfg(test)]
fn run_axes(axes: &[(&AxisFilter, &[f64])], latency: usize) -> Vec<Result<Vec<f64>, usize>> {
    let inputs = axes.iter().map(|(f, x)| (*f, x.iter().map(|&u| u as f32).collect())).collect();
    run_kernel(inputs, latency).iter().map(|y| drop_latency(y, latency)).collect()
}

/// Every axis through the core kernel's block path (bit-identical to stepping
/// it sample by sample, as the box does), each input followed by its
/// `latency` samples of [`look_ahead`]: the f32 outputs in the order of `axes`, each
/// `latency` samples longer than its input (the first `latency` to drop).
///
/// The axes are independent. Up to [`LOCKSTEP_AXES`] of them run in
/// lockstep on this thread, one per vector lane ([`process_blocks`], the
/// same numbers): a pair's recurrence is serial in time, so one axis alone
/// leaves most of a core idle, and three axes in lockstep take 0.58 of the
/// time of three in turn (BENCHMARKS.md). That beats giving axes threads of
/// their own: on two cores, x and y in lockstep on one and z on the other
/// took 1.24x as long as all three in lockstep on one.
fn run_kernel(mut axes: Vec<(&AxisFilter, Vec<f32>)>, latency: usize) -> Vec<Vec<f32>> {
    axes.chunks_mut(LOCKSTEP_AXES).flat_map(|group| run_group(group, latency)).collect()
}

/// The axes of one group of [`run_kernel`], in lockstep; each input is
/// extended in place by its `latency` samples of [`look_ahead`].
fn run_group(group: &mut [(&AxisFilter, Vec<f32>)], latency: usize) -> Vec<Vec<f32>> {
    for (_, input) in group.iter_mut() {
        let tail = look_ahead(input, latency);
        input.extend(tail);
    }
    let mut outputs: Vec<Vec<f32>> = group.iter().map(|(_, u)| vec![0.0f32; u.len()]).collect();
    let mut states = vec![AxisState::default(); group.len()];
    let mut jobs: Vec<BlockJob<'_>> = group
        .iter()
        .zip(outputs.iter_mut().zip(states.iter_mut()))
        .map(|((filter, input), (output, state))| BlockJob { filter, state, input, output })
        .collect();
    process_blocks(&mut jobs);
    outputs
}

/// The `latency` samples fed after a record's last one (`history`, f32 as
/// the kernel takes it), so that its last outputs have the look-ahead of
/// the fixed-lag smoother: the measurement's continuation predicted by
/// [`predict_after`] (an AR model of the record's end), or the last value
/// held if the record is too short to fit one (under 16 samples).
pub fn look_ahead(history: &[f32], latency: usize) -> Vec<f32> {
    if latency == 0 {
        return Vec::new();
    }
    let window: Vec<f64> =
        history[history.len().saturating_sub(PREDICT_WINDOW)..].iter().map(|&v| f64::from(v)).collect();
    match predict_after(&window, latency) {
        Some(p) => p.iter().map(|&v| v as f32).collect(),
        None => vec![history.last().copied().unwrap_or(0.0); latency],
    }
}

/// The kernel's outputs as f64 without the first `latency`; Err(k): the
/// first non-finite output k.
#[cfg(test)]
fn drop_latency(y: &[f32], latency: usize) -> Result<Vec<f64>, usize> {
    match y.iter().position(|v| !v.is_finite()) {
        Some(k) => Err(k),
        None => Ok(y.iter().skip(latency).map(|&v| f64::from(v)).collect()),
    }
}

/// The box-filter path of `compensate` over a record of any length: the
/// image's compensators applied block by block with their states carried
/// over, so memory does not grow with the record. The outputs are those of
/// [`compensate_record`] bit for bit (the kernel's block path equals its
/// per-sample `step` for any block lengths): the first `latency` outputs
/// dropped and, at [`StreamCompensator::finish`], the input's predicted
/// continuation ([`look_ahead`]) fed to produce the last `latency` outputs.
pub struct StreamCompensator {
    /// The image's compensators (copies: a compensator outlives the image
    /// it came from) and their states.
    kernel: Kernel,
    axes: Vec<usize>,
    /// Outputs still to drop (the declared latency, at the start).
    to_drop: usize,
    latency: usize,
    /// Samples fed per axis so far.
    fed: usize,
    /// Each channel's last inputs (up to twice the prediction window), for
    /// the look-ahead fed at [`StreamCompensator::finish`].
    history: Vec<Vec<f32>>,
    input: Vec<Vec<f32>>,
    output: Vec<Vec<f32>>,
}

/// The compensators a [`StreamCompensator`] runs.
enum Kernel {
    /// A box image's per-axis compensators, in lockstep.
    PerAxis { filters: Vec<AxisFilter>, states: Vec<AxisState> },
    /// A 3x3 image's filter on fx, fy and fz together, with its frames
    /// (one input and one output per sample) as scratch.
    Matrix { filter: Box<MimoFilter>, state: Box<MimoState>, frames: Vec<[f32; 3]>, outs: Vec<[f32; 3]> },
}

impl StreamCompensator {
    /// Compensators for the channels `axes` of a record from `source`.
    pub fn new(image: &CoeffImage, axes: &[usize], raw_timing: bool, source: &str) -> Result<Self> {
        let filters = axes.iter().map(|&axis| axis_filter(image, axis, source).cloned()).collect::<Result<Vec<_>>>()?;
        let states = vec![AxisState::default(); axes.len()];
        Ok(Self::with_kernel(Kernel::PerAxis { filters, states }, axes, image.latency_samples, raw_timing))
    }

    /// The 3x3 image's filter for a record from `source`, whose channels
    /// `axes` must be fx, fy and fz: the outputs of [`compensate_matrix`]
    /// bit for bit, in blocks.
    pub fn matrix(image: &MatrixImage, axes: &[usize], raw_timing: bool, source: &str) -> Result<Self> {
        check_three(axes, source)?;
        let kernel = Kernel::Matrix {
            filter: Box::new(image.filter),
            state: Box::default(),
            frames: Vec::new(),
            outs: Vec::new(),
        };
        Ok(Self::with_kernel(kernel, axes, image.latency_samples, raw_timing))
    }

    fn with_kernel(kernel: Kernel, axes: &[usize], latency: u16, raw_timing: bool) -> Self {
        let latency = if raw_timing { 0 } else { usize::from(latency) };
        let n = axes.len();
        StreamCompensator {
            kernel,
            axes: axes.to_vec(),
            to_drop: latency,
            latency,
            fed: 0,
            history: vec![Vec::new(); n],
            input: vec![Vec::new(); n],
            output: vec![Vec::new(); n],
        }
    }

    /// The latency this compensator removes (samples).
    pub fn latency(&self) -> usize {
        self.latency
    }

    /// Compensate the next block (one slice per channel, equal lengths) and
    /// append the outputs it completes to `out` (one vector per channel):
    /// as many as the block has, fewer while the latency is being dropped.
    pub fn push(&mut self, block: &[Vec<f64>], out: &mut [Vec<f64>]) -> Result<usize> {
        for ((inp, b), hist) in self.input.iter_mut().zip(block).zip(&mut self.history) {
            inp.clear();
            inp.extend(b.iter().map(|&u| u as f32));
            hist.extend_from_slice(inp);
            if hist.len() > 2 * PREDICT_WINDOW {
                hist.drain(..hist.len() - PREDICT_WINDOW);
            }
        }
        self.run(out)
    }

    /// Feed the latency's look-ahead ([`look_ahead`]: the input's
    /// continuation predicted from its end) and append the last outputs to
    /// `out`.
    pub fn finish(&mut self, out: &mut [Vec<f64>]) -> Result<usize> {
        for (inp, hist) in self.input.iter_mut().zip(&self.history) {
            *inp = look_ahead(hist, self.latency);
        }
        self.run(out)
    }

    fn run(&mut self, out: &mut [Vec<f64>]) -> Result<usize> {
        let n = self.input.first().map_or(0, Vec::len);
        for o in self.output.iter_mut() {
            o.clear();
            o.resize(n, 0.0);
        }
        match &mut self.kernel {
            Kernel::PerAxis { filters, states } => {
                for (((filters, states), inputs), outputs) in filters
                    .chunks(LOCKSTEP_AXES)
                    .zip(states.chunks_mut(LOCKSTEP_AXES))
                    .zip(self.input.chunks(LOCKSTEP_AXES))
                    .zip(self.output.chunks_mut(LOCKSTEP_AXES))
                {
                    let mut jobs: Vec<BlockJob<'_>> = filters
                        .iter()
                        .zip(states.iter_mut())
                        .zip(inputs)
                        .zip(outputs.iter_mut())
                        .map(|(((filter, state), input), output)| BlockJob { filter, state, input, output })
                        .collect();
                    process_blocks(&mut jobs);
                }
            }
            Kernel::Matrix { filter, state, frames, outs } => {
                frames.clear();
                frames.extend((0..n).map(|k| std::array::from_fn(|c| self.input[c][k])));
                outs.clear();
                outs.resize(n, [0.0; 3]);
                filter.process(state, frames, outs);
                for (c, o) in self.output.iter_mut().enumerate() {
                    o.iter_mut().zip(outs.iter()).for_each(|(v, y)| *v = y[c]);
                }
            }
        }
        for (axis, y) in self.axes.iter().zip(&self.output) {
            if let Some(k) = y.iter().position(|v| !v.is_finite()) {
                bail!(
                    "compensated f{} became non-finite at sample {}; the image is unusable for this record",
                    axis_name(*axis),
                    self.fed + k
                );
            }
        }
        self.fed += n;
        let skip = self.to_drop.min(n);
        self.to_drop -= skip;
        for (o, y) in out.iter_mut().zip(&self.output) {
            o.extend(y[skip..].iter().map(|&v| f64::from(v)));
        }
        Ok(n - skip)
    }
}

/// Parallel elaboration (paper §3.3), **offline only**: split every force
/// column into the image's bands with the zero-phase crossovers of
/// [`crate::offline::bandsplit`], run band k through band k's compensator with
/// [`compensate_record`] (the core kernel, as for any image), and sum the
/// bands. The split adds no phase and its bands sum to the input, so the
/// result differs from the input only by what the band compensators do.
pub fn compensate_parallel(
    image: &ParallelImage,
    rec: &SignalRecord,
    raw_timing: bool,
    source: &str,
) -> Result<SignalRecord> {
    let edges: Vec<(f64, f64)> = image.bands().iter().map(|b| (f64::from(b.lo_hz), f64::from(b.hi_hz))).collect();
    let crossovers = crate::design::bands::crossovers(&edges)?;
    let fs = f64::from(image.fs_hz);
    // The look-ahead of the last L samples is predicted once, on the record
    // itself (as for a box image), and split with it: the bands then sum to
    // what one filter would be fed, and each band keeps the box's timing
    // until the L first outputs are dropped below.
    let lag = if raw_timing { 0 } else { usize::from(image.latency_samples) };
    // split[c][k]: column c, band k
    let split: Vec<Vec<Vec<f64>>> = rec
        .channels
        .iter()
        .map(|(_, x)| {
            let mut fed = x.clone();
            let end = &x[x.len().saturating_sub(PREDICT_WINDOW)..];
            let history: Vec<f32> = end.iter().map(|&u| u as f32).collect();
            fed.extend(look_ahead(&history, if x.is_empty() { 0 } else { lag }).iter().map(|&v| f64::from(v)));
            crate::offline::bandsplit::split(&fed, fs, &crossovers)
        })
        .collect::<Result<_>>()?;
    let mut sum: Vec<(usize, Vec<f64>)> = rec.channels.iter().map(|(a, x)| (*a, vec![0.0; x.len()])).collect();
    for k in 0..image.bands().len() {
        let band_img = image.band_image(k).ok_or_else(|| anyhow::anyhow!("band {k} missing"))?;
        let band_rec = SignalRecord {
            t_s: None,
            channels: rec.channels.iter().zip(&split).map(|((a, _), s)| (*a, s[k].clone())).collect(),
        };
        let out = compensate_record(&band_img, &band_rec, true, source)
            .with_context(|| format!("band {k} ({:.0}-{:.0} Hz)", edges[k].0, edges[k].1))?;
        for ((_, acc), (_, y)) in sum.iter_mut().zip(&out.channels) {
            for (a, v) in acc.iter_mut().zip(y.iter().skip(lag)) {
                *a += v;
            }
        }
    }
    Ok(SignalRecord { t_s: rec.t_s.clone(), channels: sum })
}

/// A whole record through a 3x3 image's filter (format 3), as the box runs
/// it: the one f32 kernel ([`dynocomp_core::mimo::MimoFilter`]) on the
/// three force channels together, so the record must have fx, fy and fz.
/// Unless `raw_timing`, the output is shifted back by the declared latency
/// L, the last L samples computed from each channel's predicted
/// continuation ([`look_ahead`]).
pub fn compensate_matrix(
    image: &MatrixImage,
    rec: &SignalRecord,
    raw_timing: bool,
    source: &str,
) -> Result<SignalRecord> {
    check_three(&rec.channels.iter().map(|c| c.0).collect::<Vec<_>>(), source)?;
    let n = rec.len();
    let lag = if raw_timing { 0 } else { usize::from(image.latency_samples) };
    let columns: Vec<Vec<f32>> = rec
        .channels
        .iter()
        .map(|(_, x)| {
            let mut v: Vec<f32> = x.iter().map(|&u| u as f32).collect();
            let tail = look_ahead(&v, if n == 0 { 0 } else { lag });
            v.extend(tail);
            v
        })
        .collect();
    let input: Vec<[f32; 3]> = (0..columns[0].len()).map(|k| std::array::from_fn(|c| columns[c][k])).collect();
    let mut output = vec![[0.0f32; 3]; input.len()];
    let mut state = dynocomp_core::mimo::MimoState::default();
    image.filter.process(&mut state, &input, &mut output);
    if let Some(k) = output.iter().position(|y| !y.iter().all(|v| v.is_finite())) {
        bail!("{source}: the compensated force became non-finite at sample {k}; the image is unusable for this record");
    }
    let channels =
        (0..3).map(|c| (c, output[lag.min(output.len())..].iter().map(|y| f64::from(y[c])).collect())).collect();
    Ok(SignalRecord { t_s: rec.t_s.clone(), channels })
}

/// A 3x3 image takes fx, fy and fz together, in that order: refuse a
/// record whose channels `axes` are others, naming what it has.
pub fn check_three(axes: &[usize], source: &str) -> Result<()> {
    if axes != [0, 1, 2] {
        let have: Vec<&str> = axes.iter().map(|a| axis_name(*a)).collect();
        bail!(
            "{source}: a 3x3 image compensates fx, fy and fz together, and the record has {}; \
             record all three force channels",
            if have.is_empty() { "none".to_string() } else { have.join(", ") }
        );
    }
    Ok(())
}

/// Check a record's `t_s` column (if any) against a sample rate (Hz)
/// ([`crate::io::signal::check_rate_value`]).
pub fn check_rate(fs_hz: u32, rec: &SignalRecord, source: &str) -> Result<()> {
    match rec.sample_rate_from_time() {
        Some(found) => crate::io::signal::check_rate_value(fs_hz, found, source, "column t_s"),
        None => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use dynocomp_core::kernel::Section;

    /// A different filter per axis: `a + 1` pairs (so groups of unequal
    /// sizes meet), a real pole and `a` taps.
    fn filter(a: usize) -> AxisFilter {
        let mut secs: Vec<Section> = (0..=a)
            .map(|i| {
                let (re, im) = (0.97 - 0.01 * i as f32, 0.05 + 0.03 * (i + a) as f32);
                Section { delta: [re - 1.0, im, -im, re - 1.0], b: [1.0, 0.0], c: [0.3 + 0.1 * a as f32, -0.2] }
            })
            .collect();
        secs.push(Section::first_order(0.5, 1.0, 0.7));
        let taps: Vec<f32> = (0..a).map(|j| 0.1 * (j as f32 + 1.0)).collect();
        AxisFilter::with_fir(&secs, 0.5, &taps).unwrap()
    }

    /// 1-5 axes (one lockstep group, or a group and a rest) give each axis,
    /// in its own place, exactly the box's per-sample `step` outputs (bit for bit,
    /// latency dropped, the look-ahead fed after the input), and names the
    /// first non-finite sample of the axis that has one.
    #[test]
    fn every_axis_gets_the_box_outputs_in_its_place() {
        let latency = 3;
        for n_axes in 1..=5 {
            let filters: Vec<AxisFilter> = (0..n_axes).map(filter).collect();
            let inputs: Vec<Vec<f64>> = (0..n_axes)
                .map(|a| (0..1500).map(|k| ((k * (a + 3)) as f64 * 0.37).sin() * 100.0 + a as f64).collect())
                .collect();
            let want: Vec<Vec<f64>> = filters
                .iter()
                .zip(&inputs)
                .map(|(f, u)| {
                    let mut st = AxisState::default();
                    let mut fed: Vec<f32> = u.iter().map(|&v| v as f32).collect();
                    fed.extend(look_ahead(&fed, latency));
                    fed.iter().map(|&v| f64::from(f.step(&mut st, v))).skip(latency).collect()
                })
                .collect();
            let axes: Vec<(&AxisFilter, &[f64])> =
                filters.iter().zip(&inputs).map(|(f, u)| (f, u.as_slice())).collect();
            let got = run_axes(&axes, latency);
            assert_eq!(got.len(), n_axes);
            for (a, (g, w)) in got.iter().zip(&want).enumerate() {
                let g = g.as_ref().unwrap();
                assert_eq!(g.len(), w.len());
                for (k, (x, y)) in g.iter().zip(w).enumerate() {
                    assert_eq!(x.to_bits(), y.to_bits(), "{n_axes} axes: axis {a}, sample {k}");
                }
            }
        }
        let mut bad = vec![1.0; 100];
        bad[40] = f64::NAN;
        let (f0, f1) = (filter(0), filter(1));
        let ok = vec![1.0; 100];
        let got = run_axes(&[(&f0, ok.as_slice()), (&f1, bad.as_slice())], 0);
        assert!(got[0].is_ok());
        assert_eq!(got[1], Err(40));
    }
}
