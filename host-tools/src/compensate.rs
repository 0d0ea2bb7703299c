//! Offline compensation of recorded forces (`dynocomp compensate`):
//!
//! * a box image (format 1) runs through the core kernel, bit-exact with the
//!   box: the same f32 kernel code (its block path, bit-identical to the box's
//!   per-sample `step`), the same coefficients, one thread per axis
//!   ([`compensate_record`]);
//! * a parallel-elaboration image (format 2, offline only) splits the record
//!   into its bands with zero-phase filters, runs each band through its own
//!   compensator (the same kernel) and sums ([`compensate_parallel`]);
//! * `--offline` runs the fixed-interval smoother of [`crate::smoother`]
//!   instead (f64, zero lag, offline only).

use anyhow::{bail, Context, Result};
use dynocomp_core::image::{CoeffImage, ParallelImage};
use dynocomp_core::kernel::{AxisFilter, AxisState};

use crate::frf::axis_name;
use crate::io::signal_csv::SignalRecord;

/// Relative tolerance between the rate implied by `t_s` and the image's rate.
pub const FS_TOLERANCE: f64 = 1e-4;

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
/// kernel is fed L extra samples that hold the record's last value, so the
/// last L output samples are estimates made with that held input.
pub fn compensate_record(image: &CoeffImage, rec: &SignalRecord, raw_timing: bool, source: &str) -> Result<SignalRecord> {
    let latency = if raw_timing { 0 } else { usize::from(image.latency_samples) };
    let mut jobs = Vec::with_capacity(rec.channels.len());
    for (axis, samples) in &rec.channels {
        let Some(axis_img) = image.axes.get(*axis).copied().flatten() else {
            bail!(
                "{source}: column f{} has no compensator in the image (it covers {}); drop the column or design for that axis",
                axis_name(*axis),
                image.axes.iter().flatten().map(|a| axis_name(a.axis as usize)).collect::<Vec<_>>().join(", ")
            );
        };
        jobs.push((*axis, axis_img.filter, samples));
    }
    // The axes are independent: all but the last on threads of their own,
    // the last on this thread (one axis spawns nothing).
    let results: Vec<(usize, Result<Vec<f64>, usize>)> = std::thread::scope(|scope| {
        let (last, others) = match jobs.split_last() {
            Some((last, others)) => (Some(last), others),
            None => (None, &jobs[..]),
        };
        let handles: Vec<_> = others
            .iter()
            .map(|(axis, filter, samples)| (*axis, scope.spawn(move || compensate_axis(filter, samples, latency))))
            .collect();
        let last = last.map(|(axis, filter, samples)| (*axis, compensate_axis(filter, samples, latency)));
        handles
            .into_iter()
            .map(|(axis, h)| (axis, h.join().unwrap_or_else(|e| std::panic::resume_unwind(e))))
            .chain(last)
            .collect()
    });
    let mut channels = Vec::with_capacity(results.len());
    for (axis, out) in results {
        match out {
            Ok(out) => channels.push((axis, out)),
            Err(k) => bail!("{source}: compensated f{} became non-finite at sample {k}; the image is unusable for this record", axis_name(axis)),
        }
    }
    Ok(SignalRecord { t_s: rec.t_s.clone(), channels })
}

/// One axis through the core kernel's block path (bit-identical to stepping
/// it sample by sample, as the box does), the input followed by `latency`
/// copies of its last value, and the first `latency` outputs dropped.
/// Err(k): the first sample k (counting the fed samples) whose output is
/// non-finite.
fn compensate_axis(filter: &AxisFilter, samples: &[f64], latency: usize) -> Result<Vec<f64>, usize> {
    let last = samples.last().copied().unwrap_or(0.0);
    let input: Vec<f32> = samples.iter().copied().chain(std::iter::repeat_n(last, latency)).map(|u| u as f32).collect();
    let mut y = vec![0.0f32; input.len()];
    filter.process_block(&mut AxisState::default(), &input, &mut y);
    let mut out = Vec::with_capacity(samples.len());
    for (k, &v) in y.iter().enumerate() {
        if !v.is_finite() {
            return Err(k);
        }
        if k >= latency {
            out.push(f64::from(v));
        }
    }
    Ok(out)
}

/// Parallel elaboration (paper §3.3), **offline only**: split every force
/// column into the image's bands with the zero-phase crossovers of
/// [`crate::bandsplit`], run band k through band k's compensator with
/// [`compensate_record`] (the core kernel, as for any image), and sum the
/// bands. The split adds no phase and its bands sum to the input, so the
/// result differs from the input only by what the band compensators do.
pub fn compensate_parallel(image: &ParallelImage, rec: &SignalRecord, raw_timing: bool, source: &str) -> Result<SignalRecord> {
    let edges: Vec<(f64, f64)> = image.bands().iter().map(|b| (f64::from(b.lo_hz), f64::from(b.hi_hz))).collect();
    let crossovers = crate::bandsplit::crossovers(&edges)?;
    let fs = f64::from(image.fs_hz);
    // split[c][k]: column c, band k
    let split: Vec<Vec<Vec<f64>>> = rec
        .channels
        .iter()
        .map(|(_, x)| crate::bandsplit::split(x, fs, &crossovers))
        .collect::<Result<_>>()?;
    let mut sum: Vec<(usize, Vec<f64>)> = rec.channels.iter().map(|(a, x)| (*a, vec![0.0; x.len()])).collect();
    for k in 0..image.bands().len() {
        let band_img = image.band_image(k).ok_or_else(|| anyhow::anyhow!("band {k} missing"))?;
        let band_rec = SignalRecord {
            t_s: None,
            channels: rec.channels.iter().zip(&split).map(|((a, _), s)| (*a, s[k].clone())).collect(),
        };
        let out = compensate_record(&band_img, &band_rec, raw_timing, source)
            .with_context(|| format!("band {k} ({:.0}-{:.0} Hz)", edges[k].0, edges[k].1))?;
        for ((_, acc), (_, y)) in sum.iter_mut().zip(&out.channels) {
            for (a, v) in acc.iter_mut().zip(y) {
                *a += v;
            }
        }
    }
    Ok(SignalRecord { t_s: rec.t_s.clone(), channels: sum })
}

/// Check a record's `t_s` column (if any) against a sample rate (Hz).
pub fn check_rate(fs_hz: u32, rec: &SignalRecord, source: &str) -> Result<()> {
    if let Some((fs, jitter)) = rec.sample_rate_from_time() {
        let want = f64::from(fs_hz);
        if ((fs - want) / want).abs() > FS_TOLERANCE {
            bail!(
                "{source}: column t_s implies a sample rate of {fs:.3} Hz, but the image was designed for {want} Hz; \
                 resample the record or design for its rate"
            );
        }
        if jitter > 0.01 {
            bail!("{source}: column t_s is not uniformly spaced (a step deviates {:.1} % from the mean)", jitter * 100.0);
        }
    }
    Ok(())
}
