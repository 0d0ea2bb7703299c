//! Frequency response data as measured by an impact test (DESIGN.md, step 1).
//!
//! The dynamometer is one 3x3 system, `Fm(s) = G(s)·Fa(s)` (DESIGN.md, "Signal
//! chain and mathematics"): entry G_ij is the response of channel i to a force
//! in direction j (N/N). An impact test in direction j records all three
//! channels and so measures column j. [`Frf`] holds the direct entries G_ii in
//! [`Frf::axes`] (what a per-axis design uses) and, when the test measured them,
//! the off-diagonal entries G_ij, i ≠ j, in [`Frf::cross`].

use nalgebra::Matrix3;
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

/// One off-diagonal entry G_ij (i ≠ j) of the FRF matrix: the response of
/// `channel` i to a force (hammer) in `direction` j, N/N, with the coherence
/// γ² of that channel in that test when the analyser exported it.
#[derive(Clone, Debug, PartialEq)]
pub struct CrossFrf {
    /// Measured channel i (0 = x, 1 = y, 2 = z).
    pub channel: Axis,
    /// Force (hammer) direction j (0 = x, 1 = y, 2 = z), different from `channel`.
    pub direction: Axis,
    /// Complex FRF values, one per frequency line (N/N).
    pub frf: Vec<Complex64>,
    /// Ordinary coherence γ² per frequency line, if present (0..=1).
    pub coherence: Option<Vec<f64>>,
}

/// A measured FRF set: common frequency lines, the direct FRFs G_ii of the
/// axes present and any measured cross FRFs G_ij.
#[derive(Clone, Debug, PartialEq)]
pub struct Frf {
    /// Frequency lines (Hz), strictly ascending, uniform or not.
    pub freq_hz: Vec<f64>,
    /// Direct FRFs G_ii, ascending by axis index, each with `freq_hz.len()` values.
    pub axes: Vec<AxisFrf>,
    /// Cross FRFs G_ij (i ≠ j), ascending by (channel, direction), each with
    /// `freq_hz.len()` values; empty when only the direct FRFs were measured.
    pub cross: Vec<CrossFrf>,
}

/// A borrowed view of one entry G_ij of an [`Frf`], direct or cross.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrfEntry<'a> {
    /// Measured channel i.
    pub channel: Axis,
    /// Force direction j.
    pub direction: Axis,
    /// Values per frequency line (N/N).
    pub frf: &'a [Complex64],
    /// Coherence γ² per frequency line, if present.
    pub coherence: Option<&'a [f64]>,
}

impl Frf {
    /// An FRF set of direct FRFs only (no cross entries).
    pub fn direct(freq_hz: Vec<f64>, axes: Vec<AxisFrf>) -> Self {
        Self { freq_hz, axes, cross: Vec::new() }
    }

    /// The FRF of `axis`, if present.
    pub fn axis(&self, axis: Axis) -> Option<&AxisFrf> {
        self.axes.iter().find(|a| a.axis == axis)
    }

    /// Entry G_ij (channel i, force direction j), direct or cross, if present.
    pub fn entry(&self, channel: Axis, direction: Axis) -> Option<FrfEntry<'_>> {
        if channel == direction {
            self.axis(channel).map(|a| FrfEntry { channel, direction, frf: &a.frf, coherence: a.coherence.as_deref() })
        } else {
            self.cross.iter().find(|c| c.channel == channel && c.direction == direction).map(|c| FrfEntry {
                channel,
                direction,
                frf: &c.frf,
                coherence: c.coherence.as_deref(),
            })
        }
    }

    /// Every entry present, row by row (channel, then direction).
    pub fn entries(&self) -> impl Iterator<Item = FrfEntry<'_>> {
        (0..9).filter_map(move |k| self.entry(k / 3, k % 3))
    }

    /// Whether any cross FRF G_ij (i ≠ j) is present.
    pub fn has_cross(&self) -> bool {
        !self.cross.is_empty()
    }

    /// Which of the nine entries are present.
    pub fn matrix_status(&self) -> MatrixStatus {
        let mut present = [[false; 3]; 3];
        for e in self.entries() {
            present[e.channel][e.direction] = true;
        }
        MatrixStatus { present }
    }

    /// The full 3x3 matrix G at frequency line `line` (`G[(i, j)]` = G_ij),
    /// or `None` when an entry is missing or `line` is out of range.
    pub fn matrix_at(&self, line: usize) -> Option<Matrix3<Complex64>> {
        let mut g = Matrix3::zeros();
        for i in 0..3 {
            for j in 0..3 {
                g[(i, j)] = *self.entry(i, j)?.frf.get(line)?;
            }
        }
        Some(g)
    }
}

/// How complete the 3x3 FRF matrix of an [`Frf`] is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MatrixKind {
    /// No cross FRF: a per-axis design, crosstalk not compensated.
    DirectOnly,
    /// All nine entries.
    Complete,
    /// Some but not all of the nine entries, with at least one cross FRF.
    Incomplete,
}

/// Which entries G_ij of the FRF matrix are present.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MatrixStatus {
    /// `present[i][j]`: entry G_ij (channel i, force direction j) is present.
    pub present: [[bool; 3]; 3],
}

impl MatrixStatus {
    /// Direct only, complete, or incomplete.
    pub fn kind(&self) -> MatrixKind {
        let cross = (0..9).any(|k| k / 3 != k % 3 && self.present[k / 3][k % 3]);
        if !cross {
            MatrixKind::DirectOnly
        } else if self.missing().is_empty() {
            MatrixKind::Complete
        } else {
            MatrixKind::Incomplete
        }
    }

    /// Whether all nine entries are present.
    pub fn is_complete(&self) -> bool {
        self.kind() == MatrixKind::Complete
    }

    /// Missing entries (channel, direction), row by row.
    pub fn missing(&self) -> Vec<(Axis, Axis)> {
        (0..9).map(|k| (k / 3, k % 3)).filter(|&(i, j)| !self.present[i][j]).collect()
    }

    /// Missing off-diagonal entries, row by row.
    pub fn missing_cross(&self) -> Vec<(Axis, Axis)> {
        self.missing().into_iter().filter(|(i, j)| i != j).collect()
    }

    /// Missing direct entries.
    pub fn missing_direct(&self) -> Vec<(Axis, Axis)> {
        self.missing().into_iter().filter(|(i, j)| i == j).collect()
    }

    /// What a design can do with this matrix, for the user; `None` when the
    /// matrix is complete. E.g. "cross FRFs missing: xy, zx; crosstalk is not
    /// compensated, the design is per axis from the direct FRFs".
    pub fn message(&self) -> Option<String> {
        let names = |v: Vec<(Axis, Axis)>| v.iter().map(|&(i, j)| entry_name(i, j)).collect::<Vec<_>>().join(", ");
        let direct_missing = self.missing_direct();
        let direct_note = if direct_missing.is_empty() {
            String::new()
        } else {
            format!(" (direct FRFs missing: {})", names(direct_missing))
        };
        match self.kind() {
            MatrixKind::Complete => None,
            MatrixKind::DirectOnly => {
                Some(format!("only direct FRFs{direct_note}: crosstalk is not compensated, the design is per axis"))
            }
            MatrixKind::Incomplete => Some(format!(
                "cross FRFs missing: {}{direct_note}; crosstalk is not compensated, the design is per axis \
                 from the direct FRFs",
                names(self.missing_cross())
            )),
        }
    }
}

/// Axis letter of an axis index.
pub fn axis_name(axis: Axis) -> &'static str {
    dynocomp_core::AXIS_NAMES.get(axis).copied().unwrap_or("?")
}

/// Name of entry G_ij: channel letter then direction letter (`xy` = channel
/// x, force y).
pub fn entry_name(channel: Axis, direction: Axis) -> String {
    format!("{}{}", axis_name(channel), axis_name(direction))
}
