//! The 3x3 model a 3x3 image's sidecar holds for `compensate --offline`
//! ([`MatrixModelJson`]): the 3x3 design's discrete model as plant states,
//! q, R and force shapes, validated into the smoother's augmented plant
//! ([`crate::offline::matrix_smoother`] runs it).

use anyhow::Result;
use nalgebra::{DMatrix, Matrix3};
use serde::{Deserialize, Serialize};

use crate::design::kalman::ForceShape;
use crate::design::mimo::discrete::{DiscreteMatrixModel, PlantStates};
use crate::design::mimo::kalman::{augmented_plant_shaped, MatrixAugmentedPlant};
use crate::design::mimo::reduce::ReductionFigures;
use crate::design::mimo::MatrixDesign;
use crate::fit::linalg::eigenvalues;

/// Largest plant order a sidecar may hold: the 3x3 fit's highest order
/// ([`crate::design::mimo::MATRIX_MAX_ORDER`]) times its three inputs, with
/// room to spare. A larger one is refused before anything is allocated.
pub const MAX_PLANT_STATES: usize = 256;

/// The 3x3 model of a 3x3 image in its sidecar: the discrete model's plant
/// states, direct term, FIR taps and advance
/// ([`crate::design::mimo::discrete`]), q and R of the 3x3 rows and their
/// band-limited force models. Matrices are stored row by row.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MatrixModelJson {
    /// Advance D of the discrete model (samples).
    pub advance: usize,
    /// Plant state transition A (n × n).
    pub plant_a: Vec<Vec<f64>>,
    /// Plant force input B (n × 3).
    pub plant_b: Vec<Vec<f64>>,
    /// Plant output C (3 × n).
    pub plant_c: Vec<Vec<f64>>,
    /// Direct term d (N/N; row: channel, column: force direction).
    pub d: [[f64; 3]; 3],
    /// FIR taps h_1, h_2, … of the discrete model (N/N).
    pub fir: Vec<[[f64; 3]; 3]>,
    /// Process noise q per force axis (N²/sample).
    pub q: [f64; 3],
    /// Measurement noise R per channel (N²).
    pub r: [f64; 3],
    /// The band-limited force model per force axis (`None`: random walk).
    pub force_shape: [Option<ForceShape>; 3],
    /// Whether the image holds the 3x3 block reduced to fit the box's load
    /// limit: `Some(Some(_))` what the reduction did, `Some(None)` (`null`)
    /// the full filter, `None` (the key absent) a sidecar written before
    /// reductions were recorded, which cannot tell.
    #[serde(default, deserialize_with = "present", skip_serializing_if = "Option::is_none")]
    pub box_reduction: Option<Option<ReductionFigures>>,
}

/// The sidecar's record of `md`'s reduction: the figures where the image
/// holds the reduced filter, `Some(None)` where it holds the full one, and
/// nothing where a figure is not finite (JSON would write it as `null`,
/// which would not read back).
fn recorded_reduction(md: &MatrixDesign) -> Option<Option<ReductionFigures>> {
    match md.summary.reduction.as_ref().filter(|r| r.used) {
        None => Some(None),
        Some(r) => {
            let finite =
                r.full_predicted.iter().chain(&r.predicted).all(|v| v.is_finite()) && r.hankel_bound.is_finite();
            finite.then(|| Some(r.clone()))
        }
    }
}

/// A key that is present, even as `null`, is `Some` (serde's `Option`
/// alone reads `null` and an absent key alike).
fn present<'de, D, T>(d: D) -> std::result::Result<Option<T>, D::Error>
where
    D: serde::Deserializer<'de>,
    T: Deserialize<'de>,
{
    T::deserialize(d).map(Some)
}

fn rows_of(m: &DMatrix<f64>) -> Vec<Vec<f64>> {
    m.row_iter().map(|r| r.iter().copied().collect()).collect()
}

fn matrix3(m: &Matrix3<f64>) -> [[f64; 3]; 3] {
    std::array::from_fn(|i| std::array::from_fn(|j| m[(i, j)]))
}

impl MatrixModelJson {
    /// The sidecar's 3x3 model of `md`; `None` where the design has no 3x3
    /// Kalman design (every row per axis).
    pub fn of_design(md: &MatrixDesign) -> Option<Self> {
        let ((dm, plant), k) = (md.discrete.as_ref()?, md.kalman.as_ref()?);
        let force_shape = md.summary.kalman.as_ref().map_or([None; 3], |f| f.force_shape);
        Some(MatrixModelJson {
            advance: dm.advance,
            plant_a: rows_of(&plant.a),
            plant_b: rows_of(&plant.b),
            plant_c: rows_of(&plant.c),
            d: matrix3(&dm.d),
            fir: dm.fir.iter().map(matrix3).collect(),
            q: k.q,
            r: k.r,
            force_shape,
            box_reduction: recorded_reduction(md),
        })
    }

    /// The augmented plant of the smoother (latency 0), validated: sizes,
    /// finite values, a stable plant, a short advance and FIR, positive q
    /// and R, force shapes below fs/2. Errors name `source`.
    pub fn plant(&self, fs_hz: f64, source: &str) -> Result<MatrixAugmentedPlant> {
        let bad = |what: &str| anyhow::anyhow!("{source}: the 3x3 model {what}; re-run `dynocomp design`");
        let n = self.plant_a.len();
        if n == 0 || n > MAX_PLANT_STATES {
            return Err(bad(&format!("has {n} plant states (1 to {MAX_PLANT_STATES})")));
        }
        let dense = |rows: &[Vec<f64>], r: usize, c: usize, name: &str| -> Result<DMatrix<f64>> {
            if rows.len() != r || rows.iter().any(|row| row.len() != c) {
                return Err(bad(&format!("matrix {name} is not {r} × {c}")));
            }
            if rows.iter().flatten().any(|v| !v.is_finite()) {
                return Err(bad(&format!("matrix {name} has non-finite values")));
            }
            Ok(DMatrix::from_fn(r, c, |i, j| rows[i][j]))
        };
        let a = dense(&self.plant_a, n, n, "A")?;
        let b = dense(&self.plant_b, n, 3, "B")?;
        let c = dense(&self.plant_c, 3, n, "C")?;
        let finite3 = |m: &[[f64; 3]; 3]| m.iter().flatten().all(|v| v.is_finite());
        if !finite3(&self.d) || !self.fir.iter().all(finite3) {
            return Err(bad("has non-finite direct or FIR terms"));
        }
        if self.advance > 64 || self.fir.len() > 64 {
            return Err(bad(&format!(
                "is too long (advance {}, {} FIR taps; at most 64)",
                self.advance,
                self.fir.len()
            )));
        }
        if !self.q.iter().chain(&self.r).all(|v| *v > 0.0 && v.is_finite()) {
            return Err(bad("has a q or R that is not positive and finite"));
        }
        for s in self.force_shape.iter().flatten() {
            if !(s.corner_hz > 0.0 && s.corner_hz < fs_hz / 2.0 && matches!(s.order, 2 | 4)) {
                return Err(bad(&format!(
                    "has a force shape (corner {} Hz, order {}) not valid at {fs_hz} Hz",
                    s.corner_hz, s.order
                )));
            }
        }
        let eig = eigenvalues(&a, "its plant").map_err(|e| bad(&format!("cannot be checked ({e})")))?;
        let radius = eig.iter().map(|z| z.norm()).fold(0.0, f64::max);
        if !(radius < 1.0) {
            return Err(bad(&format!("is not stable (spectral radius {radius:.6})")));
        }
        let to3 = |m: &[[f64; 3]; 3]| Matrix3::from_fn(|i, j| m[i][j]);
        // The poles and residues are not stored: the plant states realize
        // them, and the augmented plant reads only fs, d, the FIR and D.
        let dm = DiscreteMatrixModel {
            fs_hz,
            poles: Vec::new(),
            residues: Vec::new(),
            d: to3(&self.d),
            fir: self.fir.iter().map(to3).collect(),
            advance: self.advance,
        };
        let plant = PlantStates { a, b, c, ranks: Vec::new(), dropped_bound: 0.0, error: 0.0 };
        Ok(augmented_plant_shaped(&dm, &plant, 0, self.force_shape))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::numeric::balanced::Reduction;

    fn model(box_reduction: Option<Option<ReductionFigures>>) -> MatrixModelJson {
        MatrixModelJson {
            advance: 0,
            plant_a: vec![vec![0.5]],
            plant_b: vec![vec![1.0, 0.0, 0.0]],
            plant_c: vec![vec![1.0], vec![0.0], vec![0.0]],
            d: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            fir: Vec::new(),
            q: [1.0; 3],
            r: [0.05; 3],
            force_shape: [None; 3],
            box_reduction,
        }
    }

    /// The three states of `box_reduction` (reduced, full, not recorded)
    /// survive write → read, as the sidecar fuzz target requires; the key
    /// is absent for "not recorded", as in sidecars older than the key.
    /// Control: `null` and an absent key read differently.
    #[test]
    fn the_reduction_record_reads_back_in_each_of_its_three_states() {
        let figures = ReductionFigures {
            used: true,
            reason: "fits".into(),
            full_states: 112,
            states: 55,
            method: Reduction::Truncation,
            hankel_bound: 0.02,
            full_load_permille: 810,
            load_permille: 591,
            full_predicted: [0.0022, 0.0029, 0.0015],
            predicted: [0.0039, 0.0038, 0.0024],
            full_not_realized: None,
        };
        for state in [Some(Some(figures)), Some(None), None] {
            let m = model(state);
            let text = serde_json::to_string(&m).unwrap();
            assert_eq!(text.contains("box_reduction"), m.box_reduction.is_some(), "{text}");
            let back: MatrixModelJson = serde_json::from_str(&text).unwrap();
            assert_eq!(back, m, "{text}");
        }
        let null = serde_json::to_string(&model(Some(None))).unwrap();
        let absent = serde_json::to_string(&model(None)).unwrap();
        let read = |t: &str| serde_json::from_str::<MatrixModelJson>(t).unwrap().box_reduction;
        assert_ne!(read(&null), read(&absent));
    }
}
