//! A band-fitted or paper-method axis beside the default design of the same
//! FRF ([`compare`]): both compensators judged on the same force spectrum
//! and the same plant, so that a design asked for by a flag is never
//! silently worse than the one without it.

use num_complex::Complex64;

use crate::design::above_band::out_of_band_j;
use crate::design::axis::AxisDesign;
use crate::design::criterion::{criterion_grid, criterion_j, noise_term};

/// Relative margin by which the asked-for design's predicted error may
/// exceed the default's before the default is preferred, so that a
/// near-tie keeps what the user asked for (it is still reported).
pub const MARGIN: f64 = 1.1;

/// The asked-for design and the default design of one axis, judged alike.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct VersusDefault {
    /// Axis name.
    pub axis: &'static str,
    /// Predicted error (fraction) of the asked-for design: in band, plus
    /// the noise written above it where `above_band` is set.
    pub asked_error: f64,
    /// Predicted error (fraction) of the default design, judged alike.
    pub default_error: f64,
    /// Whether the noise each design writes above the band is counted
    /// (the default design is quiet above its band): the errors are then
    /// those of the output as written.
    pub above_band: bool,
    /// The band both are judged over (Hz): the default design's
    /// compensated band.
    pub band_hz: (f64, f64),
    /// Whether the default is better by more than [`MARGIN`].
    pub default_better: bool,
}

/// Judge `asked` (band-fitted or paper method) and `default` (the default
/// design of the same FRF) on the same force spectrum and plant.
///
/// **Rule (stated).** Both compensators' predicted in-band error √J
/// ([`criterion_j`]: distortion plus amplified noise, each design with its
/// own R and lag) for a force with a flat spectrum over the default
/// design's compensated band (the band accuracy is stated over, DESIGN.md),
/// on the default design's fitted model there ([`criterion_grid`]): the
/// one model of the whole band (a band fit is accurate only in its bands,
/// and the measured FRF's line noise would add the same floor to both).
/// With `out_of_band_weight` > 0 (the default design's
/// [`crate::design::above_band::AboveBand::out_of_band_weight`]: quiet
/// above its band) each error also counts that weight times the noise the
/// compensator writes above the band ([`out_of_band_j`]), as the default
/// design's q criterion does: the error of the output as written, which a
/// band-limited judge does not see (a band-fitted axis of the bundled
/// example with q = 1.3e13 matched the default in band, 0.609 % against
/// 0.607 % on the true force, and wrote 57 % as written against 5.0 %).
/// The default is better where its error is less than the asked-for
/// design's by more than [`MARGIN`].
pub fn compare(
    asked: &AxisDesign,
    default: &AxisDesign,
    force_rms: f64,
    fs_hz: f64,
    out_of_band_weight: f64,
) -> VersusDefault {
    let band = default.compensated_band_hz;
    let freqs = criterion_grid(&[band]);
    let plant: Vec<(f64, Complex64)> = freqs.iter().map(|f| (*f, default.fitted_frf(*f))).collect();
    let error = |d: &AxisDesign| {
        let c = &d.kalman.compensator;
        let h = c.freq_responses(&freqs, fs_hz);
        let noise = noise_term(d.kalman.r, fs_hz, band.1 - band.0, force_rms);
        let above = if out_of_band_weight > 0.0 {
            out_of_band_weight * out_of_band_j(c, band.1, fs_hz, d.kalman.r, force_rms * force_rms)
        } else {
            0.0
        };
        (criterion_j(&plant, &h, d.kalman.lag, fs_hz, noise) + above).sqrt()
    };
    let (asked_error, default_error) = (error(asked), error(default));
    VersusDefault {
        axis: crate::frf::axis_name(asked.axis),
        asked_error,
        default_error,
        above_band: out_of_band_weight > 0.0,
        band_hz: band,
        // NaN keeps the asked-for design.
        default_better: default_error * MARGIN < asked_error,
    }
}

/// The summary line of `v`: what was compared, and what was done about it
/// (`replaced`: the default design was used for the axis) with the
/// command that gives the better design (`better_command`).
pub fn describe(v: &VersusDefault, replaced: bool, better_command: &str) -> String {
    let judged = format!(
        "predicts {:.3} % against {:.3} % for the default design (flat force spectrum over {:.0}-{:.0} Hz, on the default design's fitted model{})",
        100.0 * v.asked_error,
        100.0 * v.default_error,
        v.band_hz.0,
        v.band_hz.1,
        if v.above_band { ", with the noise each writes above the band" } else { "" }
    );
    if !v.default_better {
        return format!("{} asked-for design {judged}: kept\n", v.axis);
    }
    if replaced {
        format!("WARNING: {} asked-for design {judged}: the image carries the default design for this axis ({better_command})\n", v.axis)
    } else {
        format!("WARNING: {} asked-for design {judged}; {better_command}\n", v.axis)
    }
}
