//! What the compensator outputs above its band (DESIGN.md, "Accuracy": the
//! output as written). The inverse of Ĝ amplifies the measurement noise
//! above the sensor modes by |Ĝ|⁻², so a compensator designed for its band
//! alone writes more noise above the band than the raw signal holds there.
//! By default ([`AboveBand::Quiet`]) the design
//!
//! - models the force as band-limited: a random walk through a
//!   Butterworth low-pass of order [`SHAPE_ORDER`] with its corner
//!   [`SHAPE_CORNER_FACTOR`] times above the band's top
//!   ([`crate::design::kalman::ForceShape`]), so the smoother takes what it
//!   measures far above the band for noise; and
//! - chooses q for the in-band error J plus the noise the compensator
//!   writes above the band ([`out_of_band_j`], weight
//!   [`OUT_OF_BAND_WEIGHT`]), so the q search cannot buy a last trace of
//!   in-band accuracy with a large amplification above it.

use crate::design::kalman::ForceShape;
use crate::numeric::lti::StateSpace;

/// The design's treatment of the band above the compensated one
/// (`design --above-band`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum AboveBand {
    /// Band-limited force model and the out-of-band noise in the q criterion.
    #[default]
    Quiet,
    /// The random-walk force and the in-band criterion alone: the exact
    /// inverse continues above the band, with its amplified noise (for an
    /// output that is low-passed to the band before use).
    Inverse,
}

impl AboveBand {
    /// The force shape for a band whose top is `f_top_hz` at `fs_hz`:
    /// `None` for [`AboveBand::Inverse`], or where the corner would lie
    /// above 0.45 fs (the anti-aliasing filters' pass band: nothing to
    /// shape there).
    pub fn force_shape(self, f_top_hz: f64, fs_hz: f64) -> Option<ForceShape> {
        let corner_hz = SHAPE_CORNER_FACTOR * f_top_hz;
        (self == AboveBand::Quiet && corner_hz < 0.45 * fs_hz).then_some(ForceShape { corner_hz, order: SHAPE_ORDER })
    }

    /// Weight of the out-of-band noise in the q criterion ([`out_of_band_j`]).
    pub fn out_of_band_weight(self) -> f64 {
        match self {
            AboveBand::Quiet => OUT_OF_BAND_WEIGHT,
            AboveBand::Inverse => 0.0,
        }
    }
}

/// Order of the band-limited force model's low-pass.
pub const SHAPE_ORDER: usize = 4;

/// Corner of the band-limited force model over the compensated band's top:
/// high enough that the prior's droop stays out of the band (at the band's
/// top the order-4 prior with its corner at 1.2x is at −0.6 dB).
pub const SHAPE_CORNER_FACTOR: f64 = 1.2;

/// Weight of the out-of-band noise against the in-band error in the q
/// criterion: 1, so that q minimizes the predicted error of the output as
/// written (in-band error plus the noise written above the band). On the
/// rates harness's 72 axes, 0.1 and 0.3 left the output as written 1.6-1.8x
/// (median) from its best at 25.6-102.4 kHz; 1 brings it to 1.07-1.27x, with
/// the median band-limited error unchanged (BENCHMARKS.md, "The output as
/// written").
pub const OUT_OF_BAND_WEIGHT: f64 = 1.0;

/// Lines of the out-of-band criterion, evenly spread from the band's top to
/// fs/2.
const OUT_OF_BAND_LINES: usize = 64;

/// The out-of-band noise of the compensator `h` relative to the in-band
/// force power `force_power_n2` (N²), for white measurement noise of
/// variance R (N²) at `fs_hz`:
///
/// ```text
/// J_out = (2R/fs)·(fs/2 − f_top)·mean_{f_top < f < fs/2} |H(f)|² / P_F
/// ```
///
/// the variance the compensator writes above the band (the in-band noise
/// term of [`crate::design::criterion::criterion_j`] continued above it).
pub fn out_of_band_j(h: &StateSpace, f_top_hz: f64, fs_hz: f64, r: f64, force_power_n2: f64) -> f64 {
    let lines = out_of_band_lines(f_top_hz, fs_hz);
    if lines.is_empty() {
        return 0.0;
    }
    let mean = h.freq_responses(&lines, fs_hz).iter().map(|h| h.norm_sqr()).sum::<f64>() / lines.len() as f64;
    out_of_band_noise_factor(f_top_hz, fs_hz, force_power_n2) * r * mean
}

/// The lines of [`out_of_band_j`] (Hz): [`OUT_OF_BAND_LINES`] evenly spread
/// over (f_top, fs/2); none where the band reaches fs/2.
pub fn out_of_band_lines(f_top_hz: f64, fs_hz: f64) -> Vec<f64> {
    let nyquist = fs_hz / 2.0;
    if !(f_top_hz < nyquist) {
        return Vec::new();
    }
    (0..OUT_OF_BAND_LINES)
        .map(|i| f_top_hz + (nyquist - f_top_hz) * (i as f64 + 0.5) / OUT_OF_BAND_LINES as f64)
        .collect()
}

/// (2/fs)·(fs/2 − f_top)/P_F: the out-of-band noise variance per unit of
/// R·mean|H|², relative to the in-band force power P_F (N²)
/// ([`crate::design::criterion::noise_term`] over the band above f_top).
pub fn out_of_band_noise_factor(f_top_hz: f64, fs_hz: f64, force_power_n2: f64) -> f64 {
    crate::design::criterion::noise_term(1.0, fs_hz, (fs_hz / 2.0 - f_top_hz).max(0.0), force_power_n2.sqrt())
}

/// The summary's line on the output above the band, for the axes' force
/// shapes `(axis name, shape)`.
pub fn describe(shapes: &[(&str, Option<ForceShape>)]) -> String {
    let quiet: Vec<String> =
        shapes.iter().filter_map(|(n, s)| s.map(|s| format!("{n} above {:.0} Hz", s.corner_hz))).collect();
    if quiet.is_empty() {
        return "above the band: the exact inverse goes on, with its amplified noise; low-pass the output to the band before reading it\n".into();
    }
    format!(
        "above the band: quiet: the force is modelled as band-limited (order-{SHAPE_ORDER} low-pass, {}) and q counts the noise written above the band; `--above-band inverse` for the exact inverse there\n",
        quiet.join(", ")
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::design::discretize::{discretize, Discretization};
    use crate::design::kalman::{augmented_plant, augmented_plant_shaped, design_shaped};
    use crate::fit::{PoleResidueModel, Term};
    use num_complex::Complex64;
    use std::f64::consts::PI;

    /// |S(e^{j2πf/fs})| of the shape's all-pole sections.
    fn shape_gain(shape: ForceShape, f: f64, fs: f64) -> f64 {
        let zi = Complex64::from_polar(1.0, -2.0 * PI * f / fs);
        shape.sections(fs).iter().map(|&(a1, a2, g)| (g * zi / (1.0 - a1 * zi + a2 * zi * zi)).norm()).product()
    }

    #[test]
    fn the_force_shape_is_a_unit_gain_butterworth_low_pass() {
        let fs = 51_200.0;
        let shape = ForceShape { corner_hz: 4_800.0, order: 4 };
        assert!((shape_gain(shape, 0.0, fs) - 1.0).abs() < 1e-12, "unit gain at DC");
        let at_corner = shape_gain(shape, 4_800.0, fs);
        // The matched poles' discrete response: 0.75 at the corner (analog
        // 0.707), 0.079 one octave up (0.0625), 0.010 two octaves up (0.0039).
        assert!((at_corner - 0.5f64.sqrt()).abs() < 0.06, "about −3 dB at the corner: {at_corner}");
        assert!(shape_gain(shape, 9_600.0, fs) < 0.1);
        assert!(shape_gain(shape, 19_200.0, fs) < 0.02);
        // At the band's top (4 kHz, the corner at 1.2x): 0.938, −0.56 dB.
        assert!(shape_gain(shape, 4_000.0, fs) > 0.93);
        let order2 = ForceShape { corner_hz: 4_800.0, order: 2 };
        assert!(shape_gain(order2, 19_200.0, fs) > 0.04, "control: order 2 falls only 12 dB/octave");
    }

    fn sensor(fs: f64) -> crate::design::discretize::DiscreteModel {
        // One sensor mode at 3 kHz, 3 % damping, unit static gain.
        let (w, z) = (2.0 * PI * 3_000.0, 0.03);
        let p = Complex64::new(-z * w, w * (1.0 - z * z).sqrt());
        let residue = Complex64::new(0.0, -w * w / (2.0 * p.im));
        let model = PoleResidueModel { terms: vec![Term::Pair { pole: p, residue }], d: 0.0 };
        discretize(&model, fs, Discretization::Foh, (0.0, 0.0)).unwrap().0
    }

    #[test]
    fn without_a_shape_the_plant_is_the_random_walk_one() {
        let dm = sensor(51_200.0);
        let (a, b) = (augmented_plant(&dm, 4), augmented_plant_shaped(&dm, 4, None));
        assert_eq!((a.a, a.g, a.c, a.lag), (b.a, b.g, b.c, b.lag));
    }

    /// Same q, R and lag: the shaped design keeps H·G ≈ e^{−jωL} in the band
    /// and writes far less above it than the random-walk design (control).
    #[test]
    fn the_shaped_compensator_is_quiet_above_the_band_and_unchanged_in_it() {
        let fs = 51_200.0;
        let dm = sensor(fs);
        let (q, r, lag) = (1e3, 0.05, 4);
        let shape = AboveBand::Quiet.force_shape(4_000.0, fs);
        assert!(shape.is_some());
        let quiet = design_shaped(&dm, q, r, lag, shape).unwrap().compensator;
        let inverse = design_shaped(&dm, q, r, lag, None).unwrap().compensator;
        for f in [500.0, 2_000.0, 3_000.0] {
            let g = dm.eval_z(Complex64::from_polar(1.0, 2.0 * PI * f / fs));
            let delay = Complex64::from_polar(1.0, 2.0 * PI * f * lag as f64 / fs);
            let e = (quiet.freq_response(f, fs) * g * delay - 1.0).norm();
            assert!(e < 0.02, "in band at {f} Hz: |H·G·e^(jωL) − 1| = {e}");
        }
        for f in [10_000.0, 15_000.0, 20_000.0] {
            let (hq, hi) = (quiet.freq_response(f, fs).norm(), inverse.freq_response(f, fs).norm());
            eprintln!("{f} Hz: |H| {hq} quiet vs {hi} inverse");
            assert!(hq < 0.6 * hi, "above the band at {f} Hz: |H| {hq} quiet vs {hi} inverse");
        }
        let oob = |h| out_of_band_j(h, 4_000.0, fs, r, 100.0 * 100.0);
        eprintln!("J_out {} vs {}", oob(&quiet), oob(&inverse));
        assert!(oob(&quiet) < 0.5 * oob(&inverse), "J_out {} vs {}", oob(&quiet), oob(&inverse));
    }
}
