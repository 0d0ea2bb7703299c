//! Where the 3x3 image's filter leaves an output axis further from the
//! force than no compensation does: the check the per-axis design makes
//! around a non-minimum-phase zero ([`crate::design::phase_limit`]), made
//! here on every line of each row's band, since the 3x3 model's
//! transmission zeros are not computed. A causal compensator cannot invert
//! such a zero and flips the phase there; whatever the cause, a cut with its
//! force at those lines is compensated worse than not at all, and the
//! predictions, for a flat force spectrum, do not show it.

use num_complex::Complex64;
use serde::Serialize;
use std::f64::consts::TAU;

use super::MatrixDesign;
use crate::frf::axis_name;

/// Smallest excess of the box's error over raw that is reported: 10 % of
/// the force at that frequency, as [`crate::design::phase_limit`].
pub const WORSE_MARGIN: f64 = 0.1;

/// One output row's lines where the box is worse than raw.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RowWorse {
    /// Axis letter.
    pub axis: &'static str,
    /// The first and last line where the excess is over [`WORSE_MARGIN`] (Hz).
    pub worse_hz: (f64, f64),
    /// The line of the largest excess (Hz).
    pub at_hz: f64,
    /// There: ‖row_i(H·Ĝ·e^{jωL/fs} − I)‖ and ‖row_i(Ĝ − I)‖ (2-norms of
    /// the row, relative to the force).
    pub errors: (f64, f64),
}

/// For each output row of `md`, the lines of `freq_hz` in its compensated
/// band where the realized compensator H at the declared latency L leaves
/// the 3x3 model further from the delayed identity than the model itself
/// is from the identity, by more than [`WORSE_MARGIN`]:
/// ‖row_i(H·Ĝ·e^{jωL/fs} − I)‖ − ‖row_i(Ĝ − I)‖ > 0.1. None without a 3x3
/// model.
pub fn rows_worse_than_raw(md: &MatrixDesign, freq_hz: &[f64]) -> Vec<RowWorse> {
    let Some(model) = &md.model else { return Vec::new() };
    let s = &md.summary;
    let (fs, lag) = (s.fs_hz, s.latency as f64);
    let in_band = |i: usize, f: f64| f > 0.0 && f >= s.axes[i].band_hz.0 && f <= s.axes[i].band_hz.1;
    // Per row, the lines (f, box error, raw error) worse by the margin.
    let mut worse: [Vec<(f64, f64, f64)>; 3] = Default::default();
    for &f in freq_hz.iter().filter(|f| (0..s.axes.len()).any(|i| in_band(i, **f))) {
        let h = md.realization.freq_response(f, fs);
        let g = model.frf(f);
        let delay = Complex64::from_polar(1.0, TAU * f * lag / fs);
        for (i, rows) in worse.iter_mut().enumerate().take(s.axes.len()).filter(|(i, _)| in_band(*i, f)) {
            let eye = |j: usize| if i == j { 1.0 } else { 0.0 };
            let boxed = (0..3)
                .map(|j| ((0..3).map(|k| h[i][k] * g[(k, j)]).sum::<Complex64>() * delay - eye(j)).norm_sqr())
                .sum::<f64>()
                .sqrt();
            let raw = (0..3).map(|j| (g[(i, j)] - eye(j)).norm_sqr()).sum::<f64>().sqrt();
            if boxed - raw > WORSE_MARGIN {
                rows.push((f, boxed, raw));
            }
        }
    }
    let mut out = Vec::new();
    for (i, rows) in worse.iter().enumerate() {
        let Some(peak) = rows.iter().max_by(|a, b| (a.1 - a.2).total_cmp(&(b.1 - b.2))) else { continue };
        out.push(RowWorse {
            axis: axis_name(i),
            worse_hz: (rows[0].0, rows[rows.len() - 1].0),
            at_hz: peak.0,
            errors: (peak.1, peak.2),
        });
    }
    out
}

/// The summary's WARNING for one [`RowWorse`].
pub fn warning(w: &RowWorse) -> String {
    format!(
        "WARNING: axis {}: from {:.0} to {:.0} Hz the 3x3 image's output is further from the force than the raw \
         measurement (at {:.0} Hz its row error is {:.2} where raw is {:.2}); a cut with its force there is compensated \
         worse than not at all, and the predicted errors, for a flat force spectrum, do not show it. A non-minimum-phase \
         zero, which no causal compensator inverts, is the usual cause. `--force-prior spectrum --force-record REC` \
         predicts for the cut's own spectrum; `compensate --offline`, not bound by causality, may do better there.",
        w.axis, w.worse_hz.0, w.worse_hz.1, w.at_hz, w.errors.0, w.errors.1
    )
}
