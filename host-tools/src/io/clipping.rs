//! Clipping in a force record: a charge amplifier or an ADC driven past its
//! range holds its rail, so the record shows plateaus of identical samples
//! at its own maximum or minimum. A compensator inverts the dynamometer's
//! response and cannot undo a flat top: the output is wrong around every
//! plateau, and nothing else in the record says so.
//!
//! [`clip_watch`] wraps a reader and follows each channel's extremes as the
//! samples pass ([`Extremes`]); [`Extremes::clipped`] then judges them. A
//! channel is taken as clipped at an extreme when the extreme value is held
//! on two or more consecutive samples at least [`MIN_PLATEAUS`] times. With
//! noise above the ADC's resolution, as every real amplifier has, two equal
//! consecutive samples at the very maximum of a record are rare, and the
//! same value held again elsewhere rarer still.

use std::sync::{Arc, Mutex};

use super::signal::{Block, SignalReader, Tap};

/// Plateaus (runs of ≥ 2 equal samples at the extreme) that make a clip.
pub const MIN_PLATEAUS: usize = 2;

/// One extreme of one channel: its value, how often it occurs, in how many
/// plateaus, and where the first sample at it lies (0-based).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Extreme {
    /// The extreme value (N).
    pub value: f64,
    /// Samples at exactly that value.
    pub samples: u64,
    /// Runs of two or more consecutive samples at it.
    pub plateaus: u64,
    /// First sample at it.
    pub first: u64,
    /// Length of the run at it that the last sample belongs to (0: the
    /// last sample was not at it).
    run: u64,
}

impl Extreme {
    /// Follow sample `k` of value `v`; `better(v, value)` says whether `v`
    /// is beyond the extreme so far.
    fn push(&mut self, k: u64, v: f64, better: impl Fn(f64, f64) -> bool) {
        if k == 0 || better(v, self.value) {
            *self = Extreme { value: v, samples: 1, plateaus: 0, first: k, run: 1 };
        } else if v == self.value {
            self.samples += 1;
            self.run += 1;
            if self.run == 2 {
                self.plateaus += 1;
            }
        } else {
            self.run = 0;
        }
    }
}

/// The extremes of every channel of a record, followed sample by sample.
#[derive(Clone, Debug, Default)]
pub struct Extremes {
    /// Axis of each channel (0 = x).
    pub axes: Vec<usize>,
    /// Per channel, its maximum and its minimum.
    pub channels: Vec<(Extreme, Extreme)>,
    /// Samples seen per channel.
    pub n: u64,
}

/// One clipped extreme of one channel.
#[derive(Clone, Debug, PartialEq)]
pub struct Clipped {
    /// The channel's axis (0 = x).
    pub axis: usize,
    /// Whether it is the maximum (else the minimum).
    pub at_max: bool,
    /// The extreme.
    pub extreme: Extreme,
}

impl Clipped {
    /// The warning for the user: the record `source` and what the clip
    /// spoils (`spoils`, e.g. "the compensated force is wrong around them").
    pub fn warning(&self, source: &str, spoils: &str) -> String {
        let e = &self.extreme;
        format!(
            "warning: {source}: f{} holds its {} {} N on {} samples, in {} plateaus (the first at sample {}): \
             the amplifier or the ADC clipped there, and {spoils}. Measure again with a larger range",
            crate::frf::axis_name(self.axis),
            if self.at_max { "maximum" } else { "minimum" },
            e.value,
            e.samples,
            e.plateaus,
            e.first + 1
        )
    }
}

impl Extremes {
    /// Follow `m` samples of each channel of `blk`.
    pub fn push(&mut self, blk: &Block, m: usize) {
        self.push_channels(blk.channels.iter().map(|c| &c[..m]), m);
    }

    /// Follow the next `m` samples of each channel, given as `channels`
    /// (each `m` long).
    fn push_channels<'a>(&mut self, channels: impl ExactSizeIterator<Item = &'a [f64]>, m: usize) {
        if self.channels.len() < channels.len() {
            self.channels.resize(channels.len(), Default::default());
        }
        let first = self.n;
        for (c, (hi, lo)) in channels.zip(&mut self.channels) {
            if c.is_empty() {
                continue;
            }
            // Most blocks neither reach nor pass the extremes so far: their
            // own range, found first, lets them through without the
            // sample-by-sample scan (which a run across blocks needs only
            // where a block touches the extreme).
            let (top, bottom) = range(c);
            if first == 0 || top >= hi.value {
                c.iter().enumerate().for_each(|(k, v)| hi.push(first + k as u64, *v, |a, b| a > b));
            } else {
                hi.run = 0;
            }
            if first == 0 || bottom <= lo.value {
                c.iter().enumerate().for_each(|(k, v)| lo.push(first + k as u64, *v, |a, b| a < b));
            } else {
                lo.run = 0;
            }
        }
        self.n += m as u64;
    }

    /// The extremes of a whole record's channels `(axis, samples)`.
    pub fn of_channels(channels: &[(usize, Vec<f64>)]) -> Extremes {
        let mut e = Extremes { axes: channels.iter().map(|c| c.0).collect(), ..Default::default() };
        let n = channels.iter().map(|c| c.1.len()).min().unwrap_or(0);
        e.push_channels(channels.iter().map(|c| &c.1[..n]), n);
        e
    }

    /// The extremes held on [`MIN_PLATEAUS`] plateaus or more. A constant
    /// channel (its maximum equal to its minimum) is not a clip.
    pub fn clipped(&self) -> Vec<Clipped> {
        let mut out = Vec::new();
        for (c, (hi, lo)) in self.channels.iter().enumerate() {
            if hi.value == lo.value {
                continue;
            }
            let axis = self.axes.get(c).copied().unwrap_or(c);
            for (at_max, e) in [(true, hi), (false, lo)] {
                if e.plateaus >= MIN_PLATEAUS as u64 {
                    out.push(Clipped { axis, at_max, extreme: *e });
                }
            }
        }
        out
    }
}

/// The largest and the smallest value of `c` (not empty), in eight lanes
/// that the compiler turns into vector compares.
fn range(c: &[f64]) -> (f64, f64) {
    let (mut top, mut bottom) = ([c[0]; 8], [c[0]; 8]);
    let chunks = c.chunks_exact(8);
    let rest = chunks.remainder();
    for ch in chunks {
        for i in 0..8 {
            top[i] = if ch[i] > top[i] { ch[i] } else { top[i] };
            bottom[i] = if ch[i] < bottom[i] { ch[i] } else { bottom[i] };
        }
    }
    let fold = |lanes: [f64; 8], pick: fn(f64, f64) -> f64| rest.iter().copied().chain(lanes).fold(c[0], pick);
    (fold(top, f64::max), fold(bottom, f64::min))
}

/// `inner` with its channels' [`Extremes`] followed into the handle
/// returned beside it, read once the record has been read.
pub fn clip_watch(inner: Box<dyn SignalReader>) -> (Box<dyn SignalReader>, Arc<Mutex<Extremes>>) {
    let seen = Arc::new(Mutex::new(Extremes { axes: inner.axes().to_vec(), ..Default::default() }));
    let handle = seen.clone();
    let tap = Tap::new(inner, move |blk: &Block, m: usize, _: &[usize]| {
        // A poisoned lock only means a panic elsewhere; the counts stay valid.
        seen.lock().unwrap_or_else(|p| p.into_inner()).push(blk, m);
        Ok(())
    });
    (Box::new(tap), handle)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    /// A 16-bit ADC of ±`range` N on a sine of `amp` N at `f` Hz with the
    /// simulator's noise (R = 0.05 N²), at 25.6 kHz for 0.4 s.
    fn adc_record(amp: f64, f: f64, range: f64, seed: u64) -> Vec<f64> {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let noise = Normal::new(0.0, 0.05f64.sqrt()).unwrap();
        let lsb = 2.0 * range / 65_536.0;
        (0..10_240)
            .map(|k| {
                let v = amp * (2.0 * std::f64::consts::PI * f * k as f64 / 25_600.0).sin() + noise.sample(&mut rng);
                (v / lsb).round().clamp(-32_768.0, 32_767.0) * lsb
            })
            .collect()
    }

    fn judge(x: &[f64]) -> Vec<Clipped> {
        // The runs carry across block boundaries: blocks of 1000, 13, 7 and
        // 1 samples judge alike.
        let by = |size: usize| {
            let mut e = Extremes { axes: vec![2], ..Default::default() };
            for c in x.chunks(size) {
                e.push(&Block { t_s: Vec::new(), channels: vec![c.to_vec()] }, c.len());
            }
            e.clipped()
        };
        let c = by(1000);
        assert_eq!(c, by(13));
        assert_eq!(c, by(7));
        assert_eq!(c, by(1));
        c
    }

    /// A sine 10 % past the rails is found clipped at both extremes, with
    /// a plateau per period; within the rails (the negative control, 20
    /// seeds, amplitudes up to 99 % of the range, 20 Hz where the peaks are
    /// flattest and 230 Hz) nothing is.
    #[test]
    fn plateaus_at_the_rails_are_clipping_and_noisy_peaks_are_not() {
        let c = judge(&adc_record(2_200.0, 230.0, 2_000.0, 1));
        assert_eq!(c.len(), 2, "{c:?}");
        assert!(c.iter().all(|c| c.axis == 2 && c.extreme.plateaus >= 80), "{c:?}");
        assert!((c[0].extreme.value - 2_000.0).abs() < 0.1 && c[0].at_max);
        assert!(c[0].warning("rec.csv", "x").contains("fz holds its maximum"), "{}", c[0].warning("rec.csv", "x"));
        for seed in 0..20 {
            for amp in [100.0, 1_000.0, 1_980.0] {
                for f in [20.0, 230.0] {
                    assert!(judge(&adc_record(amp, f, 2_000.0, seed)).is_empty(), "seed {seed}, {amp} N, {f} Hz");
                }
            }
        }
        // The block's range, in lanes and in the rest.
        let v: Vec<f64> = (0..21).map(|k| ((k * 7) % 11) as f64 - 5.0).collect();
        assert_eq!(range(&v), (5.0, -5.0));
        assert_eq!(range(&v[..3]), (2.0, -5.0));
        assert_eq!(range(&v[16..]), (4.0, -4.0));
        // A constant channel is not clipped, nor one plateau alone.
        assert!(judge(&[3.0; 50]).is_empty());
        assert!(judge(&[0.0, 1.0, 5.0, 5.0, 5.0, 1.0, 0.0, 2.0]).is_empty());
        assert_eq!(judge(&[0.0, 5.0, 5.0, 1.0, 5.0, 5.0, 0.0]).len(), 1);
    }
}
