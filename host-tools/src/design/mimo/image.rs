//! The 3x3 image (format 3, `docs/image-format.md` §13) of a 3x3 design:
//! the verified f32 filter, the scaling of each axis, and per output row its
//! design summary and whether it is the 3x3 design's row or the per-axis one.

use anyhow::{Context, Result};
use dynocomp_core::image::{AxisChannel, AxisSummary, DesignMethod, MatrixImage, RowDesign};
use num_complex::Complex64;

use super::{MatrixDesign, RowSource};
use crate::frf::Frf;
use crate::realize::image::scaling;

/// Tolerance of the 3x3 flat band: |(H·Ĝ)_ii·e^{j2πfL/fs} − 1| within 5 %
/// in magnitude and 5° in phase (as the per-axis flat band), and every
/// cross term |(H·Ĝ)_ij| within 5 % of the direct force.
pub const FLAT_TOLERANCE: f64 = 0.05;

/// The image of `md`, designed from the FRF `frf` (whose file hashes to
/// `source_sha256`) for a box whose 12-bit codes span ±`full_scale_n` N,
/// created now.
pub fn build_matrix_image(
    md: &MatrixDesign,
    frf: &Frf,
    full_scale_n: f64,
    source_sha256: [u8; 32],
) -> Result<MatrixImage> {
    let s = &md.summary;
    let fs = s.fs_hz;
    let axes = std::array::from_fn(|i| AxisChannel {
        axis: i as u8,
        scaling: scaling(full_scale_n),
        summary: row_summary(md, frf, i),
    });
    Ok(MatrixImage {
        fs_hz: fs.round() as u32,
        latency_samples: u16::try_from(s.latency).context("latency too large")?,
        flags: 0,
        method: DesignMethod::VectorFitting,
        source_sha256,
        created_unix_s: std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_secs())
            .unwrap_or(0),
        axes,
        filter: md.filter,
        rows: md.rows.map(|r| match r {
            RowSource::Matrix => RowDesign::Matrix,
            RowSource::PerAxis => RowDesign::PerAxis,
        }),
    })
}

/// What `inspect` shows of output row `i`: the per-axis design's own
/// summary where the row is per axis; for a 3x3 row the matrix fit's order,
/// its direct entry's fit error, the flat band of the realized row against
/// the 3x3 model ([`flat_band_3x3`]), its noise gain and its q and R.
fn row_summary(md: &MatrixDesign, frf: &Frf, i: usize) -> AxisSummary {
    let s = &md.summary;
    let pred = &s.axes[i];
    match (md.rows[i], &md.per_axis[i]) {
        (RowSource::PerAxis, Some(d)) => d.image_axis().summary,
        _ => {
            let fit = s.fit.as_ref();
            let fit_nrmse = fit.map_or(f64::NAN, |f| f.entry_error[i][i]);
            let flat = flat_band_3x3(md, frf, i);
            let (q, r) = s.kalman.as_ref().map_or((f64::NAN, f64::NAN), |k| (k.q[i], k.r[i]));
            AxisSummary {
                model_order: fit.map_or(0, |f| f.order) as u16,
                fit_nrmse: fit_nrmse as f32,
                flat_lo_hz: flat.0 as f32,
                flat_hi_hz: flat.1 as f32,
                noise_gain: pred.noise_gain as f32,
                q,
                r,
            }
        }
    }
}

/// The flat band of row `i` of the realized compensator H against the 3x3
/// model Ĝ, on the FRF's lines inside the row's compensated band: from its
/// first line up to the last before the first line where (H·Ĝ)_ii, its
/// latency removed, leaves 1 ± 5 % or ±5°, or a cross term |(H·Ĝ)_ij|
/// exceeds 5 %. (0, 0) without a 3x3 model.
pub fn flat_band_3x3(md: &MatrixDesign, frf: &Frf, i: usize) -> (f64, f64) {
    let Some(model) = &md.model else { return (0.0, 0.0) };
    let s = &md.summary;
    let (fs, lag) = (s.fs_hz, s.latency as f64);
    let band = s.axes[i].band_hz;
    let mut lo = None;
    let mut hi = 0.0;
    for f in frf.freq_hz.iter().copied().filter(|f| *f >= band.0 && *f <= band.1) {
        let h = md.realization.freq_response(f, fs);
        let g = model.frf(f);
        let row: [Complex64; 3] = std::array::from_fn(|j| (0..3).map(|k| h[i][k] * g[(k, j)]).sum());
        let e = row[i] * Complex64::from_polar(1.0, 2.0 * std::f64::consts::PI * f * lag / fs);
        let direct_ok = (e.norm() - 1.0).abs() <= FLAT_TOLERANCE && e.arg().abs() <= 5f64.to_radians();
        let cross_ok = (0..3).filter(|j| *j != i).all(|j| row[j].norm() <= FLAT_TOLERANCE);
        if !(direct_ok && cross_ok) {
            break;
        }
        lo.get_or_insert(f);
        hi = f;
    }
    lo.map_or((0.0, 0.0), |l| (l, hi))
}
