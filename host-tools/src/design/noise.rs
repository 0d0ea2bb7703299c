//! The measurement noise R (N²) of each axis: from an idle record (cutting
//! without engagement) or given.

use anyhow::{bail, Result};
use std::path::Path;

use crate::frf::{axis_name, Frf};
use crate::io;

/// R per axis of `frf` (N²): the variance of each column of the `idle`
/// record, or `noise_variance` for all axes.
pub fn noise_variances(idle: Option<&Path>, noise_variance: Option<f64>, frf: &Frf) -> Result<[Option<f64>; 3]> {
    let mut r = [None; 3];
    match (idle, noise_variance) {
        (Some(path), _) => {
            let rec = io::signal_csv::read_signal_csv(path)?;
            for a in &frf.axes {
                let Some(x) = rec.channel(a.axis) else {
                    bail!(
                        "{}: no column f{} for axis {} of the FRF",
                        path.display(),
                        axis_name(a.axis),
                        axis_name(a.axis)
                    );
                };
                if x.len() < 100 {
                    bail!(
                        "{}: only {} samples; an idle record needs at least 100 to estimate R",
                        path.display(),
                        x.len()
                    );
                }
                let var = crate::metrics::sample_variance(x);
                if !(var > 0.0) {
                    bail!(
                        "{}: column f{} has zero variance; is it a real idle record?",
                        path.display(),
                        axis_name(a.axis)
                    );
                }
                r[a.axis] = Some(var);
            }
        }
        (None, Some(v)) => {
            if !(v > 0.0 && v.is_finite()) {
                bail!("--noise-variance must be a positive number of N², got {v}");
            }
            for a in &frf.axes {
                r[a.axis] = Some(v);
            }
        }
        (None, None) => bail!(
            "give --idle FILE (a record without engagement) or --noise-variance N2 to set the measurement noise R"
        ),
    }
    Ok(r)
}
