//! Modes a fit left out, seeded where its residual exceeds the impact
//! test's noise: one procedure for the per-axis fit ([`super::vf`]) and the
//! common-pole fit of the matrix ([`super::matrix`]).
//!
//! Vector fitting relocates its poles from linearly spaced ones, on every
//! few lines. A weak, lightly damped
//! machine mode that a few impacts barely support can get no pole at any
//! order, and its residual stays: a window of lines where the fit leaves far
//! more χ² than the noise explains ([`excess_windows`]). [`seed_pairs`]
//! tries a pair there and keeps it where the BIC does.

use crate::numeric::parallel::map_on_threads;
use num_complex::Complex64;
use std::f64::consts::PI;

use super::Pole;

/// Most pole pairs [`seed_pairs`] adds.
pub const MAX_SEEDS: usize = 3;

/// Lines per window of [`excess_windows`].
pub const EXCESS_WINDOW: usize = 30;

/// Damping ratios a seeded pair is tried with.
const SEED_ZETAS: [f64; 4] = [0.005, 0.01, 0.02, 0.04];

/// Windows of the residual tried per round of [`seed_pairs`].
const SEED_WINDOWS: usize = 3;

/// A window of lines where a fit leaves more than the noise.
#[derive(Clone, Copy, Debug)]
pub struct ResidualWindow {
    /// First and last line (Hz).
    pub band_hz: (f64, f64),
    /// The line of largest residual in the window (Hz).
    pub peak_hz: f64,
    /// Σ w|Ĝ − H|²/σ̂² − N_w over the window's N_w real data points: the
    /// χ² the fit leaves above the noise's expectation, in units of σ̂².
    pub excess: f64,
}

/// Windows of [`EXCESS_WINDOW`] lines of `freq_hz` (starting every third of
/// a window) where a fit leaves more χ² than the noise scale `sigma2`
/// explains, the largest excess first, overlapping windows dropped.
/// `residuals` holds, per line, Σ w|Ĝ − H|² over the entries fitted and the
/// real data points on it (two per entry of positive weight).
///
/// A mode the fit left out shows as a window of large excess: a pair the
/// BIC would take lowers the χ² by more than its penalty (its real
/// parameters times ln N), and a window whose excess is below that cannot
/// hold one.
pub fn excess_windows(freq_hz: &[f64], residuals: &[(f64, usize)], sigma2: f64) -> Vec<ResidualWindow> {
    if residuals.len() < EXCESS_WINDOW || residuals.len() != freq_hz.len() || !(sigma2 > 0.0) {
        return Vec::new();
    }
    let mut windows: Vec<(usize, ResidualWindow)> = (0..=residuals.len() - EXCESS_WINDOW)
        .step_by(EXCESS_WINDOW / 3)
        .map(|a| {
            let w = &residuals[a..a + EXCESS_WINDOW];
            let chi2: f64 = w.iter().map(|l| l.0).sum::<f64>() / sigma2;
            let points: usize = w.iter().map(|l| l.1).sum();
            let peak = (0..EXCESS_WINDOW).max_by(|&i, &j| w[i].0.total_cmp(&w[j].0)).unwrap_or(0);
            let window = ResidualWindow {
                band_hz: (freq_hz[a], freq_hz[a + EXCESS_WINDOW - 1]),
                peak_hz: freq_hz[a + peak],
                excess: chi2 - points as f64,
            };
            (a, window)
        })
        .collect();
    windows.sort_by(|a, b| b.1.excess.total_cmp(&a.1.excess));
    let mut kept: Vec<(usize, ResidualWindow)> = Vec::new();
    for (a, w) in windows {
        if kept.iter().all(|(b, _)| a.abs_diff(*b) >= EXCESS_WINDOW) {
            kept.push((a, w));
        }
    }
    kept.into_iter().map(|(_, w)| w).collect()
}

/// The model with the poles given and its residues refitted, and its
/// weighted residual ([`Seeding::refit`]).
pub(crate) type Refit<'a, M> = &'a (dyn Fn(&[Pole]) -> Option<(M, f64)> + Sync);

/// A fit [`seed_pairs`] works on: its lines, its noise scale, and how to
/// read and refit a model `M`.
pub(crate) struct Seeding<'a, M> {
    /// Frequency lines (Hz).
    pub(crate) freq_hz: &'a [f64],
    /// The fit's frequency scale (rad/s): [`Pole`]s are in its units.
    pub(crate) w_scale: f64,
    /// The order search's noise scale σ̂² (the coherence weights are the
    /// inverse variances up to the factor it carries).
    pub(crate) sigma2: f64,
    /// The BIC penalty of one more pair: its real parameters (the pole's two
    /// and every entry's complex residue) times ln N.
    pub(crate) pair_penalty: f64,
    /// Skip a window whose line of largest residual lies within a fitted
    /// pair's half-power bandwidth (where the matrix fit's split of close
    /// modes has tried a second pair already).
    pub(crate) skip_at_pairs: bool,
    /// Lowest first line (Hz) of a window tried.
    pub(crate) lowest_window_hz: f64,
    /// Highest line of largest residual (Hz) of a window tried.
    pub(crate) highest_peak_hz: f64,
    /// Lines a seeded pair's half-power bandwidth 2ζ·f must span (0: any
    /// damping of [`SEED_ZETAS`]): see [`seed_zetas`].
    pub(crate) resolved_lines: f64,
    /// The model's poles, normalized by `w_scale`.
    pub(crate) poles: &'a dyn Fn(&M) -> Vec<Pole>,
    /// Per line, Σ w|Ĝ − H|² and the real data points ([`excess_windows`]).
    pub(crate) residuals: &'a dyn Fn(&M) -> Vec<(f64, usize)>,
    /// The model with these poles and its residues refitted by weighted
    /// least squares, and its weighted residual Σ w|Ĝ − H|²; `None` where the
    /// fit fails or is unstable.
    pub(crate) refit: Refit<'a, M>,
}

/// Median spacing (Hz) of the lines `freq_hz`; 0 for fewer than two.
pub(crate) fn line_spacing_hz(freq_hz: &[f64]) -> f64 {
    let mut d: Vec<f64> = freq_hz.windows(2).map(|w| w[1] - w[0]).filter(|d| *d > 0.0).collect();
    d.sort_by(f64::total_cmp);
    d.get(d.len() / 2).copied().unwrap_or(0.0)
}

/// The dampings a pair seeded at `f_hz` is tried with: those of
/// [`SEED_ZETAS`] whose half-power bandwidth 2ζ·f spans at least
/// `resolved_lines` lines of spacing `spacing_hz`, else that bound alone.
/// A pair narrower than that is not resolved by the lines: it fits the
/// noise of one or two of them. On the random sweep's seeds 0-199, 21 pairs
/// seeded per axis ended with a bandwidth of 0.5-3 lines. All but two lay
/// 3-43 % from every true mode, and sweep seeds 104 z and 140 y lost 1.12x
/// and 1.42x to theirs. Every seeded pair that brought an axis closer to its
/// floor spanned 4 lines or more.
fn seed_zetas(f_hz: f64, spacing_hz: f64, resolved_lines: f64) -> Vec<f64> {
    let least = resolved_lines * spacing_hz / (2.0 * f_hz);
    let zetas: Vec<f64> = SEED_ZETAS.iter().copied().filter(|z| *z >= least).collect();
    if zetas.is_empty() && least.is_finite() {
        vec![least]
    } else {
        zetas
    }
}

/// Pairs added where `model` (weighted residual `rss`) leaves more than the
/// noise.
///
/// In each of the [`SEED_WINDOWS`] windows of largest excess above a pair's
/// BIC penalty ([`excess_windows`]), a pair is tried at the line of largest
/// residual with each damping ratio of [`SEED_ZETAS`], every other pole
/// kept, the residues refitted. The trial of least residual is kept if it
/// lowers the BIC (RSS/σ̂² + p·ln N), and the search repeats, up to
/// [`MAX_SEEDS`] times. A maximum-likelihood refinement after it moves the
/// pair to its pole. Returns the model and, per pair seeded, the line (Hz)
/// and the pole (rad/s).
pub(crate) fn seed_pairs<M: Send>(s: &Seeding<M>, model: M, rss: f64) -> (M, Vec<(f64, Complex64)>) {
    let (mut model, mut rss) = (model, rss);
    let mut seeded = Vec::new();
    let spacing = line_spacing_hz(s.freq_hz);
    for _ in 0..MAX_SEEDS {
        let poles = (s.poles)(&model);
        let at_pair = |f: f64| {
            let w = 2.0 * PI * f / s.w_scale;
            poles.iter().any(|q| q.pair && (q.p.im - w).abs() <= -q.p.re)
        };
        let windows: Vec<ResidualWindow> = excess_windows(s.freq_hz, &(s.residuals)(&model), s.sigma2)
            .into_iter()
            .filter(|w| {
                w.excess > s.pair_penalty && w.band_hz.0 >= s.lowest_window_hz && w.peak_hz <= s.highest_peak_hz
            })
            .filter(|w| !(s.skip_at_pairs && at_pair(w.peak_hz)))
            .take(SEED_WINDOWS)
            .collect();
        let starts: Vec<(f64, f64)> = windows
            .iter()
            .flat_map(|w| seed_zetas(w.peak_hz, spacing, s.resolved_lines).into_iter().map(move |z| (w.peak_hz, z)))
            .collect();
        let (refit, w_scale) = (s.refit, s.w_scale);
        let trials = map_on_threads(&starts, |&(f, zeta)| {
            let mut with = poles.clone();
            let w = 2.0 * PI * f;
            let p = Complex64::new(-zeta * w, w * (1.0 - zeta * zeta).sqrt());
            with.push(Pole { p: p / w_scale, pair: true });
            let (m, r) = refit(&with)?;
            r.is_finite().then_some((r, m, (f, p)))
        });
        match trials.into_iter().flatten().min_by(|a, b| a.0.total_cmp(&b.0)) {
            // The BIC with one pair more: (r − rss)/σ̂² + penalty < 0.
            Some((r, m, seed)) if r + s.pair_penalty * s.sigma2 < rss => {
                (model, rss) = (m, r);
                seeded.push(seed);
            }
            _ => break,
        }
    }
    (model, seeded)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_seed_is_tried_only_with_a_bandwidth_the_lines_resolve() {
        // 300 Hz on 4 Hz lines: three lines need ζ ≥ 0.02.
        assert_eq!(seed_zetas(300.0, 4.0, 3.0), vec![0.02, 0.04]);
        // 100 Hz on 4 Hz lines: none of the usual dampings spans three
        // lines, so the bound itself is tried.
        let z = seed_zetas(100.0, 4.0, 3.0);
        assert_eq!(z.len(), 1);
        assert!((z[0] - 0.06).abs() < 1e-12 && 2.0 * z[0] * 100.0 >= 3.0 * 4.0 - 1e-9, "{z:?}");
        // 2 kHz on 0.5 Hz lines: every damping resolves.
        assert_eq!(seed_zetas(2000.0, 0.5, 3.0), SEED_ZETAS.to_vec());
        // Control: without the bound, every damping at 300 Hz.
        assert_eq!(seed_zetas(300.0, 4.0, 0.0), SEED_ZETAS.to_vec());
        assert_eq!(line_spacing_hz(&[4.0, 8.0, 12.0, 20.0, 24.0]), 4.0);
    }
}
