//! The Q criterion: what a compensator H predicts to achieve on a plant Ĝ
//! ([`criterion_j`]). q is chosen to minimize it, subject to the white-noise
//! gain of H staying below `max_noise_gain`; √J is reported as the predicted
//! in-band error.

use num_complex::Complex64;
use std::f64::consts::PI;

use crate::design::bands::Band;

/// White-noise gain of H estimated from its response: RMS of |H| over
/// 0..fs/2 (Parseval) on a 512-point midpoint grid, for responses that are
/// not one state space (`compare`'s parallel elaboration). It undersamples
/// peaks narrower than fs/1024; a state space has the exact
/// [`crate::numeric::lti::StateSpace::white_noise_gain`].
pub fn noise_gain(response: impl Fn(f64) -> Complex64, fs_hz: f64) -> f64 {
    let n = 512;
    let s: f64 = (0..n).map(|i| response((i as f64 + 0.5) / n as f64 * fs_hz / 2.0).norm_sqr()).sum();
    (s / n as f64).sqrt()
}

/// The flat band of H·G: from the first line of `mask` up to the last line
/// before the first masked line where |H·G·e^{jωL/fs}| leaves 1 ± 5 % or its
/// phase leaves ±5°.
pub fn flat_band(
    response: impl Fn(f64) -> Complex64,
    freq_hz: &[f64],
    frf: &[Complex64],
    mask: &[bool],
    lag: usize,
    fs_hz: f64,
) -> (f64, f64) {
    let mut lo = None;
    let mut hi = 0.0;
    for ((f, g), m) in freq_hz.iter().zip(frf).zip(mask) {
        if !*m {
            continue;
        }
        let e = response(*f) * g * Complex64::from_polar(1.0, 2.0 * PI * f * lag as f64 / fs_hz);
        if !is_flat(e) {
            break;
        }
        lo.get_or_insert(*f);
        hi = *f;
    }
    match lo {
        Some(l) => (l, hi),
        None => (0.0, 0.0),
    }
}

/// Whether a compensated response H·G·e^{jωL/fs} is flat: within 1 ± 5 % in
/// magnitude and ±5° in phase.
pub fn is_flat(e: Complex64) -> bool {
    (e.norm() - 1.0).abs() <= 0.05 && e.arg().abs() <= 5f64.to_radians()
}

/// The longest run of consecutive lines `freq_hz` inside `band` (Hz) on
/// which the compensated response `e` (H·G·e^{jωL/fs}, e.g. with a measured
/// G) [`is_flat`]: its first and last line (Hz), or `None` if no line is.
/// Unlike [`flat_band`] it does not stop at the first line that is not
/// flat, so a noisy line near the band's bottom does not end it.
pub fn longest_flat_run(freq_hz: &[f64], e: &[Complex64], band: (f64, f64)) -> Option<(f64, f64)> {
    let mut best: Option<(usize, usize)> = None;
    let mut start: Option<usize> = None;
    for (i, (f, e)) in freq_hz.iter().zip(e).enumerate() {
        if *f >= band.0 && *f <= band.1 && is_flat(*e) {
            let s = *start.get_or_insert(i);
            if best.is_none_or(|(b0, b1)| i - s > b1 - b0) {
                best = Some((s, i));
            }
        } else {
            start = None;
        }
    }
    best.map(|(a, b)| (freq_hz[a], freq_hz[b]))
}

/// Below this ratio of a better estimate's predicted error to the box
/// filter's, both with the fit's uncertainty, the summaries point to it:
/// `compensate --offline`, or a longer look-ahead
/// ([`crate::design::look_ahead`]), for a force record's spectrum only.
pub const OFFLINE_MUCH_BETTER: f64 = 0.5;

/// √(J + J_fit) from √J = `error` and √J_fit = `fit`: a predicted error with
/// the fitted model's own uncertainty counted; `error` where `fit` is not
/// known (NaN).
pub fn with_fit_uncertainty(error: f64, fit: f64) -> f64 {
    match fit.is_finite() {
        true => error.hypot(fit),
        false => error,
    }
}

/// The noise factor of J ([`criterion_j`]): (2R/fs)·(f_hi − f_lo)/force_rms², the
/// in-band noise variance relative to the force's, for `band_width_hz` = the
/// summed width of the criterion's bands.
pub fn noise_term(r: f64, fs_hz: f64, band_width_hz: f64, force_rms: f64) -> f64 {
    2.0 * r / fs_hz * band_width_hz / (force_rms * force_rms)
}

/// J of the Q criterion: mean over the grid of |H·G·e^{j2πfL/fs} − 1|² plus
/// `noise`·mean |H|², with `grid` = (f, G(j2πf)) (the plant the filter meets)
/// and `h` = H(e^{j2πf/fs}) on the same lines.
///
/// For a force with a flat spectrum of RMS `force_rms` (N) in the band
/// [f_lo, f_hi] and white measurement noise of variance R it is the
/// predicted relative error variance of the compensated force in the band:
///
/// J(q) = mean_f |H(f)·Ĝ(f)·e^{j2πfL/fs} − 1|²  +  (2R/fs)·(f_hi − f_lo)/force_rms² · mean_f |H(f)|²
///
/// (distortion of the force + amplified noise inside the band, both relative
/// to the force variance; the noise factor is [`noise_term`]). With a
/// record's force spectrum the mean over the lines in the distortion term
/// becomes a mean weighted by the force's power in each line's cell
/// ([`criterion_j_weighted`]).
pub fn criterion_j(grid: &[(f64, Complex64)], h: &[Complex64], lag: usize, fs_hz: f64, noise: f64) -> f64 {
    let (mut dist, mut amp) = (0.0, 0.0);
    for ((f, g), h) in grid.iter().zip(h) {
        dist += distortion(*f, *g, *h, lag, fs_hz).norm_sqr();
        amp += h.norm_sqr();
    }
    let n = grid.len() as f64;
    dist / n + noise * amp / n
}

/// The distortion H·G·e^{j2πfL/fs} − 1 of one line of the Q criterion
/// ([`criterion_j`]), with G = G(j2πf) and H = H(e^{j2πf/fs}).
pub fn distortion(f_hz: f64, g: Complex64, h: Complex64, lag: usize, fs_hz: f64) -> Complex64 {
    h * g * Complex64::from_polar(1.0, 2.0 * PI * f_hz * lag as f64 / fs_hz) - 1.0
}

/// J for the criterion's force spectrum: [`criterion_j`] when `weights` is
/// `None` (flat), else with the distortion of line i weighted by
/// `weights[i]` (Σ = 1: the force's share there, [`crate::design::force_spectrum`]);
/// the noise term stays the mean over the lines (white noise).
pub fn criterion_j_weighted(
    grid: &[(f64, Complex64)],
    h: &[Complex64],
    weights: Option<&[f64]>,
    lag: usize,
    fs_hz: f64,
    noise: f64,
) -> f64 {
    let Some(weights) = weights else {
        return criterion_j(grid, h, lag, fs_hz, noise);
    };
    let (mut dist, mut amp) = (0.0, 0.0);
    for (((f, g), h), w) in grid.iter().zip(h).zip(weights) {
        dist += w * distortion(*f, *g, *h, lag, fs_hz).norm_sqr();
        amp += h.norm_sqr();
    }
    dist + noise * amp / grid.len() as f64
}

/// The frequency ranges of the Q criterion of a design: its fitting bands,
/// or the compensated band without bands.
pub fn criterion_ranges(bands: &[Band], compensated_band_hz: (f64, f64)) -> Vec<(f64, f64)> {
    if bands.is_empty() {
        vec![compensated_band_hz]
    } else {
        bands.iter().map(|b| (b.lo_hz, b.hi_hz)).collect()
    }
}

/// The lines of the Q criterion: 200 spread over `ranges` (see
/// [`criterion_ranges`]), the centres of [`criterion_cells`].
pub fn criterion_grid(ranges: &[(f64, f64)]) -> Vec<f64> {
    band_grid(ranges, 200)
}

/// The cells (lo, hi) (Hz) whose centres are [`criterion_grid`]: each line
/// stands for the force in its cell ([`crate::design::force_spectrum`]).
pub fn criterion_cells(ranges: &[(f64, f64)]) -> Vec<(f64, f64)> {
    band_cells(ranges, 200)
}

/// `n` frequencies spread over `bands` in proportion to their widths (Hz).
fn band_grid(bands: &[(f64, f64)], n: usize) -> Vec<f64> {
    let total: f64 = bands.iter().map(|b| b.1 - b.0).sum();
    let mut out = Vec::with_capacity(n + bands.len());
    for b in bands {
        let k = ((n as f64 * (b.1 - b.0) / total).round() as usize).max(4);
        out.extend((0..k).map(|i| b.0 + (b.1 - b.0) * (i as f64 + 0.5) / k as f64));
    }
    out
}

/// The cells of [`band_grid`]: each of its frequencies is the centre of one.
fn band_cells(bands: &[(f64, f64)], n: usize) -> Vec<(f64, f64)> {
    let total: f64 = bands.iter().map(|b| b.1 - b.0).sum();
    let mut out = Vec::with_capacity(n + bands.len());
    for b in bands {
        let k = ((n as f64 * (b.1 - b.0) / total).round() as usize).max(4);
        let w = (b.1 - b.0) / k as f64;
        out.extend((0..k).map(|i| (b.0 + w * i as f64, b.0 + w * (i + 1) as f64)));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn longest_flat_run_skips_a_bad_line_at_the_bottom_and_stops_at_one_inside() {
        let f: Vec<f64> = (0..10).map(|i| 100.0 * i as f64).collect();
        let one = Complex64::new(1.0, 0.0);
        let mut e = vec![one; 10];
        assert_eq!(longest_flat_run(&f, &e, (100.0, 800.0)), Some((100.0, 800.0)), "limited to the band");
        e[1] = Complex64::new(1.06, 0.0); // 6 % off at the bottom
        e[7] = Complex64::from_polar(1.0, 6f64.to_radians()); // 6° off near the top
        assert_eq!(longest_flat_run(&f, &e, (0.0, 900.0)), Some((200.0, 600.0)));
        // within the tolerances on both edges: still flat
        e[1] = Complex64::new(1.049, 0.0);
        e[7] = Complex64::from_polar(0.951, 4.9f64.to_radians());
        assert_eq!(longest_flat_run(&f, &e, (0.0, 900.0)), Some((0.0, 900.0)));
        assert_eq!(longest_flat_run(&f, &[2.0 * one; 10], (0.0, 900.0)), None);
    }
}
