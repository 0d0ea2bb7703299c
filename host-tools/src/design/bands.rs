//! Fitting bands (paper §3.2 "band-fitting", §3.3 "parallel elaboration").
//!
//! A band is a frequency interval `[lo_hz, hi_hz]` (Hz) where the cutting
//! force has content and where the fit must be accurate. Bands come from the
//! tooth-passing frequency TPF = rpm/60 · Z and its harmonics
//! ([`from_tooth_passing`], paper §3.2, Fig. 5), explicit `LO:HI` strings
//! ([`parse_band`], `--band`), or the peaks of a measured force record's
//! spectrum, chatter included ([`from_record_spectrum`], paper §3.2 last
//! paragraph); all are validated by [`validate`].

use anyhow::{bail, Context, Result};
use rustfft::{num_complex::Complex64, FftPlanner};
use serde::Serialize;
use std::f64::consts::PI;

/// One fitting band (Hz).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Band {
    /// Lower edge (Hz).
    pub lo_hz: f64,
    /// Upper edge (Hz).
    pub hi_hz: f64,
    /// Where the band came from, e.g. `TPF×2`, `--band`, `peak 1234 Hz`.
    pub label: String,
}

impl Band {
    /// Centre frequency (Hz), arithmetic mean of the edges.
    pub fn centre_hz(&self) -> f64 {
        0.5 * (self.lo_hz + self.hi_hz)
    }

    /// Width (Hz).
    pub fn width_hz(&self) -> f64 {
        self.hi_hz - self.lo_hz
    }

    /// Whether `f_hz` lies in the band (edges included).
    pub fn contains(&self, f_hz: f64) -> bool {
        f_hz >= self.lo_hz && f_hz <= self.hi_hz
    }
}

/// Tooth-passing frequency (Hz) of a spindle at `spindle_rpm` (rev/min) with
/// `teeth` cutting edges: `TPF = rpm/60 · Z` (paper §3.2).
pub fn tooth_passing_hz(spindle_rpm: f64, teeth: u32) -> f64 {
    spindle_rpm / 60.0 * f64::from(teeth)
}

/// Bands around the tooth-passing frequency and its harmonics `1..=harmonics`
/// (paper §3.2, Fig. 5). Each band is `k·TPF · (1 ± rel_half_width)` (Hz).
/// Harmonics above `max_hz` (the usable band: Nyquist or the FRF's last
/// coherent line) are dropped; it is an error if none remains.
pub fn from_tooth_passing(
    spindle_rpm: f64,
    teeth: u32,
    harmonics: u32,
    rel_half_width: f64,
    max_hz: f64,
) -> Result<Vec<Band>> {
    if !(spindle_rpm.is_finite() && spindle_rpm > 0.0) {
        bail!("--spindle-rpm {spindle_rpm}: must be a positive number of rev/min");
    }
    if teeth == 0 {
        bail!("--teeth 0: a cutter has at least one tooth");
    }
    if harmonics == 0 {
        bail!("--harmonics 0: give at least 1 (the tooth-passing frequency itself)");
    }
    if !(rel_half_width > 0.0 && rel_half_width < 0.5) {
        bail!("band half-width {rel_half_width}: must be in (0, 0.5) of the harmonic frequency so that harmonics do not overlap");
    }
    let tpf = tooth_passing_hz(spindle_rpm, teeth);
    let mut bands = Vec::new();
    for k in 1..=harmonics {
        let c = f64::from(k) * tpf;
        if c * (1.0 - rel_half_width) >= max_hz {
            break;
        }
        bands.push(Band {
            lo_hz: c * (1.0 - rel_half_width),
            hi_hz: (c * (1.0 + rel_half_width)).min(max_hz),
            label: if k == 1 { format!("TPF {c:.1} Hz") } else { format!("TPF×{k} {c:.1} Hz") },
        });
    }
    if bands.is_empty() {
        bail!(
            "tooth-passing frequency {tpf:.1} Hz ({spindle_rpm} rpm × {teeth} teeth / 60) is above the usable band (≤ {max_hz:.1} Hz): check --spindle-rpm and --teeth"
        );
    }
    Ok(bands)
}

/// Parse one `--band LO:HI` (Hz), e.g. `800:1200`.
pub fn parse_band(s: &str) -> Result<Band> {
    let Some((lo, hi)) = s.split_once(':') else {
        bail!("--band `{s}`: expected LO:HI in Hz, e.g. 800:1200");
    };
    let lo: f64 = lo.trim().parse().with_context(|| format!("--band `{s}`: `{}` is not a number of Hz", lo.trim()))?;
    let hi: f64 = hi.trim().parse().with_context(|| format!("--band `{s}`: `{}` is not a number of Hz", hi.trim()))?;
    if !(lo.is_finite() && hi.is_finite() && lo >= 0.0 && hi > lo) {
        bail!("--band `{s}`: need 0 ≤ LO < HI (Hz)");
    }
    Ok(Band { lo_hz: lo, hi_hz: hi, label: "--band".into() })
}

/// Sort the bands, merge overlapping or touching ones (labels joined with
/// `+`), and reject bands outside `[0, max_hz]` or narrower than `min_width_hz`
/// (less than a few FRF lines cannot constrain a fit). `max_hz` is the usable
/// band (Nyquist or the last FRF line).
pub fn validate(mut bands: Vec<Band>, max_hz: f64, min_width_hz: f64) -> Result<Vec<Band>> {
    if bands.is_empty() {
        bail!("no fitting band given");
    }
    for b in &bands {
        if !(b.lo_hz >= 0.0 && b.hi_hz > b.lo_hz) {
            bail!("band {} {:.1}..{:.1} Hz: need 0 ≤ LO < HI", b.label, b.lo_hz, b.hi_hz);
        }
        if b.lo_hz >= max_hz {
            bail!("band {} {:.1}..{:.1} Hz: starts above the usable band (≤ {max_hz:.1} Hz, the FRF's last line or Nyquist)", b.label, b.lo_hz, b.hi_hz);
        }
    }
    bands.sort_by(|a, b| a.lo_hz.total_cmp(&b.lo_hz));
    let mut merged: Vec<Band> = Vec::with_capacity(bands.len());
    for mut b in bands {
        b.hi_hz = b.hi_hz.min(max_hz);
        match merged.last_mut() {
            Some(last) if b.lo_hz <= last.hi_hz => {
                last.hi_hz = last.hi_hz.max(b.hi_hz);
                last.label = format!("{}+{}", last.label, b.label);
            }
            _ => merged.push(b),
        }
    }
    for b in &merged {
        if b.width_hz() < min_width_hz {
            bail!(
                "band {} {:.1}..{:.1} Hz is {:.1} Hz wide, narrower than {min_width_hz:.1} Hz (a few FRF lines): widen it",
                b.label,
                b.lo_hz,
                b.hi_hz,
                b.width_hz()
            );
        }
    }
    Ok(merged)
}

/// For each frequency line, whether it lies in any band.
pub fn band_mask(freq_hz: &[f64], bands: &[Band]) -> Vec<bool> {
    freq_hz.iter().map(|f| bands.iter().any(|b| b.contains(*f))).collect()
}

/// One-line list of bands, e.g. `180–220 Hz (TPF 200.0 Hz), 380–420 Hz (…)`.
pub fn describe(bands: &[Band]) -> String {
    bands.iter().map(|b| format!("{:.0}–{:.0} Hz ({})", b.lo_hz, b.hi_hz, b.label)).collect::<Vec<_>>().join(", ")
}

/// One-sided power spectral density by Welch's method (Hann window, 50 %
/// overlap, segments of `segment_len` samples): frequencies (Hz) and PSD
/// (N²/Hz) at `k·fs/segment_len`, k = 0..=segment_len/2.
pub fn welch_psd(x: &[f64], fs_hz: f64, segment_len: usize) -> Result<(Vec<f64>, Vec<f64>)> {
    if segment_len < 16 || x.len() < segment_len {
        bail!("record of {} samples is too short for a spectrum with {segment_len}-sample segments", x.len());
    }
    let window: Vec<f64> =
        (0..segment_len).map(|i| 0.5 - 0.5 * (2.0 * PI * i as f64 / segment_len as f64).cos()).collect();
    let w_power: f64 = window.iter().map(|w| w * w).sum();
    let fft = FftPlanner::<f64>::new().plan_fft_forward(segment_len);
    let half = segment_len / 2;
    let mut psd = vec![0.0; half + 1];
    let hop = segment_len / 2;
    let mut count = 0usize;
    let mut buf = vec![Complex64::new(0.0, 0.0); segment_len];
    let mut start = 0;
    while start + segment_len <= x.len() {
        let seg = &x[start..start + segment_len];
        let mean = seg.iter().sum::<f64>() / segment_len as f64;
        for ((b, v), w) in buf.iter_mut().zip(seg).zip(&window) {
            *b = Complex64::new((v - mean) * w, 0.0);
        }
        fft.process(&mut buf);
        for (k, p) in psd.iter_mut().enumerate() {
            let one_sided = if k == 0 || k == half { 1.0 } else { 2.0 };
            *p += one_sided * buf[k].norm_sqr() / (fs_hz * w_power);
        }
        count += 1;
        start += hop;
    }
    for p in &mut psd {
        *p /= count as f64;
    }
    let freq = (0..=half).map(|k| k as f64 * fs_hz / segment_len as f64).collect();
    Ok((freq, psd))
}

/// Options of [`from_record_spectrum`].
#[derive(Clone, Copy, Debug)]
pub struct SpectrumPeakOptions {
    /// Welch segment length (samples); resolution fs/segment_len.
    pub segment_len: usize,
    /// A peak must exceed the spectrum's median by this factor (power ratio).
    pub min_prominence: f64,
    /// A peak's power must be at least this fraction of the largest peak's.
    pub min_relative_power: f64,
    /// Half-width of each band around a peak, relative to the peak frequency.
    pub rel_half_width: f64,
    /// Lowest half-width (Hz), so low-frequency peaks still span several lines.
    pub min_half_width_hz: f64,
    /// At most this many bands (the strongest peaks).
    pub max_bands: usize,
}

impl Default for SpectrumPeakOptions {
    fn default() -> Self {
        Self {
            segment_len: 4096,
            min_prominence: 30.0,
            min_relative_power: 1e-3,
            rel_half_width: 0.05,
            min_half_width_hz: 20.0,
            max_bands: 12,
        }
    }
}

/// Bands around the peaks of a measured force record's spectrum, found a
/// posteriori (paper §3.2, last paragraph): harmonics of the tooth-passing
/// frequency and non-harmonic peaks such as chatter alike. `x` are samples
/// (N) at `fs_hz`; peaks above `max_hz` are ignored. A peak is a local
/// maximum of the Welch PSD that stands `min_prominence` above the median
/// PSD and has at least `min_relative_power` of the strongest peak's power.
/// The DC line is never a peak (the static force needs no band).
pub fn from_record_spectrum(x: &[f64], fs_hz: f64, max_hz: f64, opts: &SpectrumPeakOptions) -> Result<Vec<Band>> {
    let seg = opts.segment_len.min(x.len().next_power_of_two() / 2).max(16);
    let (freq, psd) = welch_psd(x, fs_hz, seg)?;
    let mut sorted = psd.clone();
    sorted.sort_by(f64::total_cmp);
    let median = sorted[sorted.len() / 2].max(f64::MIN_POSITIVE);
    let df = fs_hz / seg as f64;
    let mut peaks: Vec<(f64, f64)> = Vec::new();
    for k in 2..psd.len() - 1 {
        if freq[k] > max_hz {
            break;
        }
        if psd[k] > psd[k - 1] && psd[k] >= psd[k + 1] && psd[k] > opts.min_prominence * median {
            // Parabolic interpolation of the peak frequency on log power.
            let (a, b, c) = (psd[k - 1].ln(), psd[k].ln(), psd[k + 1].ln());
            let denom = a - 2.0 * b + c;
            let delta = if denom.abs() > 0.0 { 0.5 * (a - c) / denom } else { 0.0 };
            peaks.push((freq[k] + delta.clamp(-0.5, 0.5) * df, psd[k]));
        }
    }
    let strongest = peaks.iter().map(|p| p.1).fold(0.0, f64::max);
    peaks.retain(|p| p.1 >= opts.min_relative_power * strongest);
    peaks.sort_by(|a, b| b.1.total_cmp(&a.1));
    peaks.truncate(opts.max_bands);
    if peaks.is_empty() {
        bail!("no spectral peak stands {:.0}× above the median below {max_hz:.0} Hz: is it a cutting record? give --band or --spindle-rpm instead", opts.min_prominence);
    }
    let bands = peaks
        .iter()
        .map(|&(f, _)| {
            let hw = (f * opts.rel_half_width).max(opts.min_half_width_hz).max(2.0 * df);
            Band { lo_hz: (f - hw).max(0.0), hi_hz: (f + hw).min(max_hz), label: format!("peak {f:.0} Hz") }
        })
        .collect();
    Ok(bands)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tooth_passing_bands_are_centred_on_harmonics() {
        // 6000 rpm, 4 teeth: TPF = 400 Hz.
        let b = from_tooth_passing(6000.0, 4, 3, 0.1, 10_000.0).unwrap();
        assert_eq!(b.len(), 3);
        for (k, band) in b.iter().enumerate() {
            let c = 400.0 * (k + 1) as f64;
            assert!((band.centre_hz() - c).abs() < 1e-9, "{band:?}");
            assert!((band.width_hz() - 0.2 * c).abs() < 1e-9);
        }
        // Harmonics above max_hz are dropped, the last one clipped.
        let b = from_tooth_passing(6000.0, 4, 5, 0.1, 1150.0).unwrap();
        assert_eq!(b.len(), 3);
        assert_eq!(b[2].hi_hz, 1150.0);
        assert!(from_tooth_passing(60000.0, 4, 1, 0.1, 1000.0).is_err());
        assert!(from_tooth_passing(6000.0, 0, 1, 0.1, 1000.0).is_err());
    }

    #[test]
    fn parse_and_validate() {
        let b = parse_band("800:1200").unwrap();
        assert_eq!((b.lo_hz, b.hi_hz), (800.0, 1200.0));
        assert!(parse_band("800-1200").is_err());
        assert!(parse_band("1200:800").is_err());
        assert!(parse_band("x:800").is_err());
        let v = validate(
            vec![parse_band("900:1500").unwrap(), parse_band("100:200").unwrap(), parse_band("800:1000").unwrap()],
            5000.0,
            10.0,
        )
        .unwrap();
        assert_eq!(v.len(), 2);
        assert_eq!((v[0].lo_hz, v[0].hi_hz), (100.0, 200.0));
        assert_eq!((v[1].lo_hz, v[1].hi_hz), (800.0, 1500.0));
        assert!(validate(vec![parse_band("6000:7000").unwrap()], 5000.0, 10.0).is_err());
        assert!(validate(vec![parse_band("100:105").unwrap()], 5000.0, 10.0).is_err());
        let clipped = validate(vec![parse_band("4000:7000").unwrap()], 5000.0, 10.0).unwrap();
        assert_eq!(clipped[0].hi_hz, 5000.0);
    }

    #[test]
    fn spectrum_peaks_find_harmonics_and_a_non_harmonic_line() {
        // TPF 300 Hz and its 2nd harmonic, plus "chatter" at 1370 Hz, in noise.
        use rand::{RngExt, SeedableRng};
        let fs = 20_000.0;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let x: Vec<f64> = (0..60_000)
            .map(|i| {
                let t = i as f64 / fs;
                50.0 + 20.0 * (2.0 * PI * 300.0 * t).sin()
                    + 8.0 * (2.0 * PI * 600.0 * t).sin()
                    + 3.0 * (2.0 * PI * 1370.0 * t).sin()
                    + rng.random_range(-1.0..1.0)
            })
            .collect();
        let bands =
            validate(from_record_spectrum(&x, fs, 5000.0, &SpectrumPeakOptions::default()).unwrap(), 5000.0, 5.0)
                .unwrap();
        assert_eq!(bands.len(), 3, "{bands:?}");
        for (b, f) in bands.iter().zip([300.0, 600.0, 1370.0]) {
            assert!(b.contains(f), "{b:?} should contain {f}");
            assert!((b.centre_hz() - f).abs() < 2.0, "{b:?} centred near {f}");
        }
        // Pure noise has no peak to find.
        let noise: Vec<f64> = (0..60_000).map(|_| rng.random_range(-1.0..1.0)).collect();
        assert!(from_record_spectrum(&noise, fs, 5000.0, &SpectrumPeakOptions::default()).is_err());
    }

    #[test]
    fn welch_psd_integrates_to_the_variance() {
        let fs = 10_000.0;
        let x: Vec<f64> = (0..40_000).map(|i| 2.0 * (2.0 * PI * 1000.0 * i as f64 / fs).sin()).collect();
        let (f, p) = welch_psd(&x, fs, 1024).unwrap();
        let df = f[1] - f[0];
        let power: f64 = p.iter().sum::<f64>() * df;
        // A 2 N amplitude sine has variance 2 N².
        assert!((power - 2.0).abs() < 0.02, "{power}");
    }
}

/// Crossover frequencies (Hz) between consecutive bands `[lo, hi]` (Hz,
/// ascending, not overlapping): the middle of each gap, f_c = (hi_k +
/// lo_k+1)/2, so that every frequency belongs to a band of the split
/// ([`crate::offline::bandsplit`]).
pub fn crossovers(bands: &[(f64, f64)]) -> Result<Vec<f64>> {
    for (k, w) in bands.windows(2).enumerate() {
        if !(w[0].0 < w[0].1 && w[0].1 <= w[1].0 && w[1].0 < w[1].1) {
            bail!("bands {k} and {} are not ascending and disjoint: {:?} then {:?} Hz", k + 1, w[0], w[1]);
        }
    }
    Ok(bands.windows(2).map(|w| 0.5 * (w[0].1 + w[1].0)).collect())
}

/// The (lo, hi) edges of `bands` (Hz), in order.
pub fn ranges_hz(bands: &[Band]) -> Vec<(f64, f64)> {
    bands.iter().map(|b| (b.lo_hz, b.hi_hz)).collect()
}

/// Where the fitting bands come from (`design`'s and `compare`'s band
/// flags): the tooth-passing harmonics of a spindle speed, explicit bands
/// `LO:HI`, and the peaks of a measured record's spectrum.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BandSpec {
    /// Spindle speed (rev/min) and teeth: bands around the tooth-passing
    /// frequency rpm/60·Z and its harmonics.
    pub tooth_passing: Option<(f64, u32)>,
    /// Harmonics of the tooth-passing frequency to fit (1 = TPF only).
    pub harmonics: u32,
    /// Half-width of each harmonic band, relative to its centre frequency.
    pub band_width: f64,
    /// Explicit bands, `LO:HI` in Hz.
    pub bands: Vec<String>,
    /// A measured force record (signal CSV) whose spectral peaks are bands.
    pub bands_from: Option<std::path::PathBuf>,
    /// Largest plausible force (N) of that record's values (`None`: the
    /// default, [`crate::io::signal::DEFAULT_FULL_SCALE_N`]).
    pub max_force_n: Option<f64>,
}

impl BandSpec {
    /// Tooth-passing frequency (Hz), when a spindle speed and teeth are given.
    pub fn tooth_passing_hz(&self) -> Option<f64> {
        self.tooth_passing.map(|(rpm, z)| tooth_passing_hz(rpm, z))
    }

    /// The validated bands for this FRF and sample rate (empty = whole band).
    /// With any band, a static band from the first FRF line up to a quarter
    /// of the lowest band is added: the mean cutting force needs it, and the
    /// Kalman filter's force state is only observable through G(0).
    pub fn resolve(&self, frf: &crate::frf::Frf, fs_hz: f64) -> Result<Vec<Band>> {
        let max_hz = frf.freq_hz[frf.freq_hz.len() - 1].min(crate::design::discretize::MATCH_BAND_FRACTION * fs_hz);
        let mut out = Vec::new();
        if let Some((rpm, z)) = self.tooth_passing {
            out.extend(from_tooth_passing(rpm, z, self.harmonics, self.band_width, max_hz)?);
        }
        for b in &self.bands {
            out.push(parse_band(b)?);
        }
        if let Some(path) = &self.bands_from {
            let full_scale = self.max_force_n.unwrap_or(crate::io::signal::DEFAULT_FULL_SCALE_N);
            let rec = crate::io::signal_csv::read_signal_csv_checked(path, full_scale)?;
            let rate = match rec.sample_rate_from_time() {
                Some((r, _)) => r,
                None => fs_hz,
            };
            for (axis, x) in &rec.channels {
                let name = crate::frf::axis_name(*axis);
                let found = from_record_spectrum(x, rate, max_hz, &SpectrumPeakOptions::default())
                    .with_context(|| format!("{}: column f{name}", path.display()))?;
                out.extend(found.into_iter().map(|b| Band { label: format!("f{name} {}", b.label), ..b }));
            }
        }
        if out.is_empty() {
            return Ok(out);
        }
        let n = frf.freq_hz.len();
        let first = frf.freq_hz[0];
        let lowest = out.iter().map(|b| b.lo_hz).fold(f64::INFINITY, f64::min);
        let static_hi = (0.25 * lowest).max(frf.freq_hz[4.min(n - 1)]);
        out.push(Band { lo_hz: first, hi_hz: static_hi, label: "static".into() });
        let spacing = (frf.freq_hz[n - 1] - first) / (n - 1) as f64;
        validate(out, max_hz, 3.0 * spacing)
    }

    /// The spec of the band flags among `flags` (`--spindle-rpm RPM --teeth Z
    /// [--harmonics K] [--band-width REL] [--band LO:HI]...`, as a simulator
    /// preset prints them for `design`); other flags are skipped with their
    /// value when they take one.
    pub fn from_flags(flags: &[String]) -> Result<BandSpec> {
        let mut spec = BandSpec { harmonics: 4, band_width: 0.1, ..Default::default() };
        let (mut rpm, mut teeth) = (None, None);
        let mut it = flags.iter();
        while let Some(flag) = it.next() {
            let mut value = || it.next().with_context(|| format!("{flag} needs a value"));
            match flag.as_str() {
                "--spindle-rpm" => {
                    rpm = Some(value()?.parse::<f64>().with_context(|| format!("{flag}: not a number"))?)
                }
                "--teeth" => {
                    teeth = Some(value()?.parse::<u32>().with_context(|| format!("{flag}: not a whole number"))?)
                }
                "--harmonics" => {
                    spec.harmonics = value()?.parse().with_context(|| format!("{flag}: not a whole number"))?
                }
                "--band-width" => {
                    spec.band_width = value()?.parse().with_context(|| format!("{flag}: not a number"))?
                }
                "--band" => spec.bands.push(value()?.clone()),
                "--bands-from" => spec.bands_from = Some(value()?.into()),
                _ => bail!("{flag}: not a band flag"),
            }
        }
        spec.tooth_passing = match (rpm, teeth) {
            (Some(r), Some(z)) => Some((r, z)),
            (None, None) => None,
            _ => bail!("--spindle-rpm and --teeth go together"),
        };
        Ok(spec)
    }
}
