//! Modal quantities of a pole-residue model: natural frequencies, modal
//! shares (the static gain a mode contributes), and which pairs are the
//! dynamometer's own (sensor) modes rather than the machine's.

use num_complex::Complex64;
use std::f64::consts::PI;

use crate::fit::{PoleResidueModel, Term};

/// Natural frequency (Hz) of the pole `p`.
pub fn fn_hz(p: Complex64) -> f64 {
    p.norm() / (2.0 * PI)
}

/// The upper pole −ζω + jω√(1 − ζ²) of natural frequency `w` (rad/s) and
/// damping ratio `zeta`.
pub fn pole_at(w: f64, zeta: f64) -> Complex64 {
    Complex64::new(-zeta * w, w * (1.0 - zeta * zeta).sqrt())
}

/// The modal share of the pair ρ/(s − p) + c.c.: ρ·2jω_d/ω_n², the r of
/// r·ω²/(s² + 2ζωs + ω²) (real for a classically damped mode; the static
/// gain the mode contributes).
pub fn modal_share(pole: Complex64, residue: Complex64) -> Complex64 {
    residue * 2.0 * Complex64::i() * pole.im / pole.norm_sqr()
}

/// The residue ρ of the pair at `pole` whose modal share is `share` (the
/// inverse of [`modal_share`]).
pub fn residue_of_share(pole: Complex64, share: Complex64) -> Complex64 {
    share * pole.norm_sqr() / (2.0 * Complex64::i() * pole.im)
}

/// Sensor modes: fitted pairs at or above this fraction of the main mode's
/// natural frequency (the main mode: the pair of the largest modal share).
pub const SENSOR_FRACTION: f64 = 0.5;

/// Modal share 2|ρ|/|p| of a pair: how much of the static gain it carries.
fn share(pole: Complex64, residue: Complex64) -> f64 {
    2.0 * residue.norm() / pole.norm()
}

/// Natural frequency of the main mode (the pair of the largest modal
/// share) as an angular frequency (rad/s); None without pairs.
fn main_mode_rad_s(model: &PoleResidueModel) -> Option<f64> {
    model
        .terms
        .iter()
        .filter_map(|t| match *t {
            Term::Pair { pole, residue } => Some((pole.norm(), share(pole, residue))),
            Term::Real { .. } => None,
        })
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .map(|m| m.0)
}

/// Lowest natural frequency of a sensor mode (Hz): [`SENSOR_FRACTION`] × the
/// main mode's; None without pairs.
pub fn sensor_modes_from_hz(model: &PoleResidueModel) -> Option<f64> {
    main_mode_rad_s(model).map(|w| SENSOR_FRACTION * w / std::f64::consts::TAU)
}

/// Indices into `model.terms` of the sensor modes ([`SENSOR_FRACTION`]);
/// empty without pairs.
pub fn sensor_mode_indices(model: &PoleResidueModel) -> Vec<usize> {
    let Some(w_main) = main_mode_rad_s(model) else { return Vec::new() };
    model
        .terms
        .iter()
        .enumerate()
        .filter(|(_, t)| matches!(t, Term::Pair { pole, .. } if pole.norm() >= SENSOR_FRACTION * w_main))
        .map(|(i, _)| i)
        .collect()
}
