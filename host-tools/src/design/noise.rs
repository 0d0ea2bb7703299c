//! The measurement noise R (N²) of each axis: from an idle record (cutting
//! without engagement) or given.

use anyhow::{bail, Result};
use std::path::Path;

use crate::frf::{axis_name, Frf};
use crate::io;

/// R per axis of `frf` (N²): the variance of each column of the `idle`
/// record, or `noise_variance` for all axes.
pub fn noise_variances(idle: Option<&Path>, noise_variance: Option<f64>, frf: &Frf) -> Result<[Option<f64>; 3]> {
    noise_variances_checked(idle, noise_variance, frf, &IdleChecks::default())
}

/// What an idle record is checked against.
#[derive(Clone, Copy, Debug)]
pub struct IdleChecks {
    /// The box's sample rate (Hz): a record whose `t_s` column says another
    /// rate is refused. `None`: not checked.
    pub fs_hz: Option<f64>,
    /// Largest plausible force (N) of a value.
    pub full_scale_n: f64,
}

impl Default for IdleChecks {
    fn default() -> Self {
        IdleChecks { fs_hz: None, full_scale_n: io::signal::DEFAULT_FULL_SCALE_N }
    }
}

/// [`noise_variances`] with the idle record checked against `checks`: R is
/// the noise at the box's rate, so a record sampled at another rate would
/// give another R.
pub fn noise_variances_checked(
    idle: Option<&Path>,
    noise_variance: Option<f64>,
    frf: &Frf,
    checks: &IdleChecks,
) -> Result<[Option<f64>; 3]> {
    let mut r = [None; 3];
    match (idle, noise_variance) {
        (Some(path), _) => {
            let rec = io::signal_csv::read_signal_csv_checked(path, checks.full_scale_n)?;
            if let (Some(fs), Some(found)) = (checks.fs_hz, rec.sample_rate_from_time()) {
                let why = "R is the noise at the box's rate: record the idle noise at --fs";
                io::signal::check_rate_against_fs(found, fs, &path.display().to_string(), why)?;
            }
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
