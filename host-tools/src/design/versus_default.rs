//! A band-fitted or paper-method axis beside the default design of the same
//! FRF ([`compare`]): both compensators judged on the same force spectrum
//! and the same plant, so that a design asked for by a flag is never
//! silently worse than the one without it.

use num_complex::Complex64;

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
    /// Predicted in-band error (fraction) of the asked-for design.
    pub asked_error: f64,
    /// Predicted in-band error (fraction) of the default design.
    pub default_error: f64,
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
/// The default is better where its error is less than the asked-for
/// design's by more than [`MARGIN`].
pub fn compare(asked: &AxisDesign, default: &AxisDesign, force_rms: f64, fs_hz: f64) -> VersusDefault {
    let band = default.compensated_band_hz;
    let freqs = criterion_grid(&[band]);
    let plant: Vec<(f64, Complex64)> = freqs.iter().map(|f| (*f, default.fitted_frf(*f))).collect();
    let error = |d: &AxisDesign| {
        let h = d.kalman.compensator.freq_responses(&freqs, fs_hz);
        let noise = noise_term(d.kalman.r, fs_hz, band.1 - band.0, force_rms);
        criterion_j(&plant, &h, d.kalman.lag, fs_hz, noise).sqrt()
    };
    let (asked_error, default_error) = (error(asked), error(default));
    VersusDefault {
        axis: crate::frf::axis_name(asked.axis),
        asked_error,
        default_error,
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
        "predicts {:.3} % against {:.3} % for the default design (flat force spectrum over {:.0}-{:.0} Hz, on the default design's fitted model)",
        100.0 * v.asked_error,
        100.0 * v.default_error,
        v.band_hz.0,
        v.band_hz.1
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
