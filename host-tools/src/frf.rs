//! Frequency response data as measured by an impact test (DESIGN.md, step 1).

use num_complex::Complex64;

/// Axis index: 0 = x, 1 = y, 2 = z (the core's order).
pub type Axis = usize;

/// One axis's measured FRF G(jω) = Fm/Fa (dimensionless, N/N) and, when the
/// analyser exported it, the coherence γ² (0..=1) of the same test.
#[derive(Clone, Debug, PartialEq)]
pub struct AxisFrf {
    /// Axis index (0 = x, 1 = y, 2 = z).
    pub axis: Axis,
    /// Complex FRF values, one per frequency line (N/N).
    pub frf: Vec<Complex64>,
    /// Ordinary coherence γ² per frequency line, if present (0..=1).
    pub coherence: Option<Vec<f64>>,
}

/// A measured FRF set: common frequency lines and one [`AxisFrf`] per axis
/// present, in ascending axis order.
#[derive(Clone, Debug, PartialEq)]
pub struct Frf {
    /// Frequency lines (Hz), strictly ascending, uniform or not.
    pub freq_hz: Vec<f64>,
    /// Axes present, ascending by axis index, each with `freq_hz.len()` values.
    pub axes: Vec<AxisFrf>,
}

impl Frf {
    /// The FRF of `axis`, if present.
    pub fn axis(&self, axis: Axis) -> Option<&AxisFrf> {
        self.axes.iter().find(|a| a.axis == axis)
    }
}

/// Axis letter of an axis index.
pub fn axis_name(axis: Axis) -> &'static str {
    dynocomp_core::AXIS_NAMES.get(axis).copied().unwrap_or("?")
}
