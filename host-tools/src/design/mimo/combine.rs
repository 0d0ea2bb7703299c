//! One 3-in, 3-out compensator from rows of different designs: per output
//! axis the 3x3 design's row or the per-axis design's (which reads its own
//! channel only), as blocks with their own states (block diagonal), so the
//! one 3x3 kernel runs them all.

use nalgebra::DMatrix;
use serde::Serialize;

use crate::numeric::lti::{MimoStateSpace, StateSpace};
use crate::realize::mimo::block_sum;

/// Where an output axis's estimate comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum RowSource {
    /// Row i of the 3x3 design (all three channels).
    Matrix,
    /// The per-axis design of axis i (channel i only).
    PerAxis,
}

/// The compensator of `rows` as blocks (each a 3-in, 3-out state space that
/// is zero outside its rows) and their sum as one block-diagonal state
/// space. `matrix` is the 3x3 design (needed where a row is
/// [`RowSource::Matrix`]) and `per_axis[i]` axis i's compensator (where row
/// i is [`RowSource::PerAxis`]).
pub fn combine(
    rows: [RowSource; 3],
    matrix: Option<&MimoStateSpace>,
    per_axis: [Option<&StateSpace>; 3],
) -> anyhow::Result<(Vec<MimoStateSpace>, MimoStateSpace)> {
    let mut blocks = Vec::new();
    if rows.contains(&RowSource::Matrix) {
        let Some(m) = matrix else { anyhow::bail!("a row of the 3x3 design without the 3x3 design") };
        let mut b = m.clone();
        for (i, row) in rows.iter().enumerate() {
            if *row != RowSource::Matrix {
                b.c.row_mut(i).fill(0.0);
                b.d.row_mut(i).fill(0.0);
            }
        }
        blocks.push(b);
    }
    for (i, row) in rows.iter().enumerate() {
        if *row == RowSource::PerAxis {
            let Some(s) = per_axis[i] else { anyhow::bail!("axis {i}: a per-axis row without its design") };
            blocks.push(embed(s, i));
        }
    }
    let total = block_sum(&blocks);
    Ok((blocks, total))
}

/// A SISO compensator of channel i as a 3-in, 3-out state space.
fn embed(s: &StateSpace, i: usize) -> MimoStateSpace {
    let n = s.a.nrows();
    let mut b = DMatrix::zeros(n, 3);
    b.column_mut(i).copy_from(&s.b);
    let mut c = DMatrix::zeros(3, n);
    c.row_mut(i).copy_from(&s.c.transpose());
    let mut d = DMatrix::zeros(3, 3);
    d[(i, i)] = s.d;
    MimoStateSpace { a: s.a.clone(), b, c, d }
}
