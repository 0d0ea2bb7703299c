//! Streaming force records: a [`SignalReader`] yields a record in
//! blocks of samples, a [`SignalWriter`] takes them, so `compensate` holds a
//! block, never the record. CSV ([`crate::io::signal_csv`]) and UFF 58 time
//! histories ([`crate::io::uff_signal`]) implement both.

use anyhow::{bail, Result};

/// Samples per block of the streaming paths: 8192 samples x (3 axes + time)
/// x 8 bytes = 256 KiB per buffer, small against the 64 MB memory target and
/// large enough that per-block overheads do not show.
pub const BLOCK: usize = 8192;

/// A block of a force record: the samples of each channel (in the reader's
/// axis order) and, if the record has them, their times.
#[derive(Clone, Debug, Default)]
pub struct Block {
    /// Sample times (s); empty when the record has no time column.
    pub t_s: Vec<f64>,
    /// One vector per channel, all of the same length.
    pub channels: Vec<Vec<f64>>,
}

impl Block {
    /// Append the times of samples `first..first + n` of an evenly sampled
    /// record (s): t0 + k·dt, each from its own index (no accumulated
    /// rounding), for readers of formats that store a start and an
    /// increment instead of times (TDMS, UFF 58).
    pub fn push_even_times(&mut self, t0: f64, dt: f64, first: u64, n: usize) {
        self.t_s.extend((0..n as u64).map(|k| t0 + (first + k) as f64 * dt));
    }

    /// An empty block for `n_channels` channels.
    pub fn new(n_channels: usize) -> Block {
        Block { t_s: Vec::new(), channels: vec![Vec::new(); n_channels] }
    }

    /// Samples in the block.
    pub fn len(&self) -> usize {
        self.channels.first().map_or(0, Vec::len)
    }

    /// Whether the block has no samples.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Remove every sample, keeping the allocations.
    pub fn clear(&mut self) {
        self.t_s.clear();
        self.channels.iter_mut().for_each(Vec::clear);
    }
}

/// A force record read block by block (on a thread of its own in
/// `compensate`, hence `Send`).
pub trait SignalReader: Send {
    /// Axis of each channel (0 = x, 1 = y, 2 = z), ascending.
    fn axes(&self) -> &[usize];
    /// Whether the blocks carry sample times.
    fn has_time(&self) -> bool;
    /// Sample rate the file declares in its header (Hz), if any.
    fn declared_fs_hz(&self) -> Option<f64> {
        None
    }
    /// Total number of samples the reader will deliver, when it is known
    /// before reading (the UFF and TDMS readers count them in their index
    /// pass): a UFF output of that length is written in place.
    fn len_hint(&self) -> Option<u64> {
        None
    }
    /// Clear `blk` and fill it with up to `max` samples (`max` > 0); returns
    /// the number read, 0 at the end of the record.
    fn read_block(&mut self, blk: &mut Block, max: usize) -> Result<usize>;
}

/// A force record written block by block (in the axis order it was
/// created with).
pub trait SignalWriter {
    /// Append samples: `t_s` (if the output has times) and one slice per
    /// channel, all of the same length.
    fn write_block(&mut self, t_s: Option<&[f64]>, channels: &[&[f64]]) -> Result<()>;
    /// Write whatever the format puts after the last sample.
    fn finish(&mut self) -> Result<()>;
}

/// Mean spacing and worst deviation of a time column, tracked sample by
/// sample in constant memory: the same numbers as
/// [`crate::io::signal_csv::SignalRecord::sample_rate_from_time`] on the
/// whole column (mean spacing (t_last − t_0)/(n − 1), worst |step − mean| /
/// mean, which is reached at the smallest or the largest step).
#[derive(Clone, Copy, Debug, Default)]
pub struct RateTracker {
    first: Option<f64>,
    last: f64,
    n: u64,
    min_step: f64,
    max_step: f64,
}

impl RateTracker {
    /// Take the next sample times.
    pub fn push(&mut self, t: &[f64]) {
        for &v in t {
            match self.first {
                None => {
                    self.first = Some(v);
                    self.min_step = f64::INFINITY;
                    self.max_step = f64::NEG_INFINITY;
                }
                Some(_) => {
                    let step = v - self.last;
                    self.min_step = self.min_step.min(step);
                    self.max_step = self.max_step.max(step);
                }
            }
            self.last = v;
            self.n += 1;
        }
    }

    /// (rate in Hz, worst relative deviation of a step from the mean), once
    /// two or more times were seen.
    pub fn rate(&self) -> Option<(f64, f64)> {
        let first = self.first?;
        if self.n < 2 {
            return None;
        }
        let dt = (self.last - first) / (self.n - 1) as f64;
        let worst = ((self.max_step - dt).abs() / dt).max((self.min_step - dt).abs() / dt);
        Some((1.0 / dt, worst))
    }
}

/// Factor from a force channel's unit to N (TDMS `unit_string`, UFF
/// record 9): "N" (or empty) 1, "kN" 1000, "mN" 0.001; None for anything
/// else, which the readers refuse (a record in lbf or V is not read as N).
pub fn newton_per_unit(unit: &str) -> Option<f64> {
    match unit.trim() {
        "" | "N" | "n" | "newton" | "Newton" | "NEWTON" => Some(1.0),
        "kN" | "KN" | "kn" => Some(1000.0),
        "mN" => Some(0.001),
        _ => None,
    }
}

/// Default bound on the magnitude of a force record's values (N): the
/// full scale of the charge amplifiers. 100 kN is above the range of every
/// table dynamometer of the Kistler 9257/9255/9129 class (5-60 kN) and far
/// below what a corrupted value makes of a force (a flipped exponent bit,
/// a wrong data type: 10⁹ N and more). A value beyond it is an input error.
pub const DEFAULT_FULL_SCALE_N: f64 = 1.0e5;

/// `--max-force N`, checked: a positive number of newtons (`inf`: only
/// finite values are required).
pub fn check_max_force(n: f64) -> Result<f64> {
    if !(n > 0.0) {
        bail!("--max-force {n}: the full scale must be a positive force in N");
    }
    Ok(n)
}

/// Whether `v` is a plausible force for the bound `full_scale_n` (N): finite
/// and |v| ≤ full scale (false for NaN).
#[inline]
pub fn plausible(v: f64, full_scale_n: f64) -> bool {
    v.abs() <= full_scale_n
}

/// The error for an implausible force value `v` (N) at `place` (e.g.
/// "line 7, column 2 (`fx`)" or "sample 12 of channel `Fx`") of `source`.
pub fn implausible(source: &str, place: &str, v: f64, full_scale_n: f64) -> anyhow::Error {
    if v.is_finite() {
        anyhow::anyhow!(
            "{source}: {place}: {v:e} N is beyond the full scale of ±{full_scale_n:e} N: no charge amplifier outputs it \
             (a corrupted value, or set the full scale)"
        )
    } else {
        anyhow::anyhow!("{source}: {place}: value is {v}; values must be finite")
    }
}

/// A reader that shows every block it reads to `on_block` (the block, its
/// number of samples and the channels' axes), which may refuse it with an
/// error.
pub struct Tap<F> {
    inner: Box<dyn SignalReader>,
    on_block: F,
}

impl<F: FnMut(&Block, usize, &[usize]) -> Result<()> + Send> Tap<F> {
    /// Read `inner`, showing each block to `on_block(block, samples, axes)`.
    pub fn new(inner: Box<dyn SignalReader>, on_block: F) -> Self {
        Tap { inner, on_block }
    }
}

impl<F: FnMut(&Block, usize, &[usize]) -> Result<()> + Send> SignalReader for Tap<F> {
    fn axes(&self) -> &[usize] {
        self.inner.axes()
    }
    fn has_time(&self) -> bool {
        self.inner.has_time()
    }
    fn declared_fs_hz(&self) -> Option<f64> {
        self.inner.declared_fs_hz()
    }
    fn len_hint(&self) -> Option<u64> {
        self.inner.len_hint()
    }
    fn read_block(&mut self, blk: &mut Block, max: usize) -> Result<usize> {
        let m = self.inner.read_block(blk, max)?;
        (self.on_block)(blk, m, self.inner.axes())?;
        Ok(m)
    }
}

/// A reader whose force values are checked against a full scale
/// ([`plausible`]): an implausible value is an error naming the source,
/// the sample (1-based) and the channel. For readers that do not check
/// themselves (the CSV reader checks each row as it parses it, with its
/// line number).
pub fn bounded(inner: Box<dyn SignalReader>, source: &str, full_scale_n: f64) -> Box<dyn SignalReader> {
    let source = source.to_string();
    // Samples delivered so far.
    let mut n = 0u64;
    Box::new(Tap::new(inner, move |blk: &Block, m: usize, axes: &[usize]| {
        for (c, axis) in blk.channels.iter().zip(axes) {
            if let Some(k) = c[..m].iter().position(|v| !plausible(*v, full_scale_n)) {
                let place = format!("sample {} of f{}", n + k as u64 + 1, crate::frf::axis_name(*axis));
                return Err(implausible(&source, &place, c[k], full_scale_n));
            }
        }
        n += m as u64;
        Ok(())
    }))
}

/// Relative tolerance between a file's sample rate and the image's.
pub const FS_TOLERANCE: f64 = 1e-4;

/// Check a sample rate found in `source` (from `what`, e.g. "column t_s")
/// against the image's `fs_hz`, and the spacing's uniformity.
pub fn check_rate_value(fs_hz: u32, found: (f64, f64), source: &str, what: &str) -> Result<()> {
    let (fs, jitter) = found;
    let want = f64::from(fs_hz);
    let off = ((fs - want) / want).abs();
    if off.is_nan() || off > FS_TOLERANCE {
        bail!(
            "{source}: {what} implies a sample rate of {fs:.3} Hz, but the image was designed for {want} Hz; \
             resample the record or design for its rate"
        );
    }
    if jitter > 0.01 {
        bail!("{source}: {what} is not uniformly spaced (a step deviates {:.1} % from the mean)", jitter * 100.0);
    }
    Ok(())
}

/// Check the rate `found` in the `t_s` column of the record `source`
/// against `--fs` (Hz), for a record that must be sampled at the box's
/// rate (`why` says what for): off by more than [`FS_TOLERANCE`] or
/// unevenly spaced is an error naming the file and both rates.
pub fn check_rate_against_fs(found: (f64, f64), fs_hz: f64, source: &str, why: &str) -> Result<()> {
    let (fs, jitter) = found;
    let off = ((fs - fs_hz) / fs_hz).abs();
    if off.is_nan() || off > FS_TOLERANCE {
        bail!("{source}: sampled at {fs:.1} Hz (column t_s), not at --fs {fs_hz} Hz; {why}");
    }
    if jitter > 0.01 {
        bail!("{source}: column t_s is not uniformly spaced (a step deviates {:.1} % from the mean)", jitter * 100.0);
    }
    Ok(())
}

/// A whole record: its times (if any) and one vector per channel.
pub type WholeRecord = (Option<Vec<f64>>, Vec<Vec<f64>>);

/// Read a whole record from `reader` (for the paths that need it whole:
/// `--offline`, parallel elaboration): (times if any, channels).
pub fn read_all(reader: &mut dyn SignalReader) -> Result<WholeRecord> {
    let n_ch = reader.axes().len();
    let mut t = Vec::new();
    let mut ch: Vec<Vec<f64>> = vec![Vec::new(); n_ch];
    let mut blk = Block::new(n_ch);
    while reader.read_block(&mut blk, BLOCK)? > 0 {
        t.extend_from_slice(&blk.t_s);
        for (c, b) in ch.iter_mut().zip(&blk.channels) {
            c.extend_from_slice(b);
        }
    }
    Ok((reader.has_time().then_some(t), ch))
}

/// Channel-to-axis map given with `--channels`: `fx=NAME,fy=NAME,...`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ChannelMap {
    /// (axis, channel name as given).
    pub pairs: Vec<(usize, String)>,
}

impl ChannelMap {
    /// Parse `fx=A,fy=B,fz=C` (any subset).
    pub fn parse(s: &str) -> Result<ChannelMap> {
        let mut pairs: Vec<(usize, String)> = Vec::new();
        for item in s.split(',').map(str::trim).filter(|i| !i.is_empty()) {
            let Some((k, v)) = item.split_once('=') else {
                bail!("`{item}`: expected AXIS=CHANNEL, e.g. fx=1 or fx=Force X");
            };
            let axis = match k.trim().to_ascii_lowercase().as_str() {
                "fx" | "x" => 0,
                "fy" | "y" => 1,
                "fz" | "z" => 2,
                other => bail!("`{item}`: unknown axis `{other}` (fx, fy or fz)"),
            };
            if pairs.iter().any(|p| p.0 == axis) {
                bail!("`{item}`: axis given twice");
            }
            pairs.push((axis, v.trim().to_string()));
        }
        if pairs.is_empty() {
            bail!("no channel given");
        }
        Ok(ChannelMap { pairs })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::signal_csv::SignalRecord;

    /// The streaming tracker gives the whole-column figures bit for bit,
    /// however the column is cut into blocks; a column with one irregular
    /// step reads as irregular.
    #[test]
    fn rate_tracker_matches_the_whole_column() {
        let mut t: Vec<f64> = (0..1000).map(|k| k as f64 / 51200.0 + 0.25).collect();
        for irregular in [false, true] {
            if irregular {
                t[500] += 0.3 / 51200.0;
            }
            let rec = SignalRecord { t_s: Some(t.clone()), channels: vec![(0, vec![0.0; t.len()])] };
            let want = rec.sample_rate_from_time().unwrap();
            for cut in [1, 7, 999, 1000] {
                let mut tr = RateTracker::default();
                for c in t.chunks(cut) {
                    tr.push(c);
                }
                let got = tr.rate().unwrap();
                assert_eq!(got.0.to_bits(), want.0.to_bits());
                assert_eq!(got.1.to_bits(), want.1.to_bits());
            }
            assert_eq!(check_rate_value(51200, want, "f", "t").is_ok(), !irregular);
        }
        assert!(check_rate_value(48000, (51200.0, 0.0), "f", "t").is_err());
        assert!(check_rate_value(48000, (f64::NAN, 0.0), "f", "t").is_err());
        assert!(RateTracker::default().rate().is_none());
    }
}
