//! The coefficient image of realized filters: scaling of the box's ADC and
//! DAC codes, one filter and its design summary per axis
//! (`docs/image-format.md`).

use anyhow::{Context, Result};
use dynocomp_core::image::{AxisImage, AxisScaling, AxisSummary, CoeffImage, DesignMethod};
use dynocomp_core::kernel::AxisFilter;

/// What the image holds of one axis: its f32 filter and design summary.
#[derive(Clone, Copy, Debug)]
pub struct ImageAxis {
    /// Axis index (0 = x, 1 = y, 2 = z).
    pub axis: usize,
    /// The verified f32 filter the box runs.
    pub filter: AxisFilter,
    /// Fit error, flat band, noise gain, q and R, as `inspect` shows them.
    pub summary: AxisSummary,
}

/// ADC and DAC scaling of a 12-bit box whose codes 0..4095 span
/// ±`full_scale_n` N.
pub fn scaling(full_scale_n: f64) -> AxisScaling {
    let newton_per_code = (2.0 * full_scale_n / 4096.0) as f32;
    AxisScaling {
        adc_offset_code: 2048.0,
        newton_per_code,
        dac_code_per_newton: 1.0 / newton_per_code,
        dac_offset_code: 2048.0,
    }
}

/// The image of `axes`, created now.
pub fn build_image(
    axes: &[ImageAxis],
    method: DesignMethod,
    fs_hz: u32,
    latency: usize,
    full_scale_n: f64,
    source_sha256: [u8; 32],
) -> Result<CoeffImage> {
    let mut slots = [None; 3];
    let scaling = scaling(full_scale_n);
    for a in axes {
        slots[a.axis] = Some(AxisImage { axis: a.axis as u8, scaling, filter: a.filter, summary: a.summary });
    }
    Ok(CoeffImage {
        fs_hz,
        latency_samples: u16::try_from(latency).context("latency too large")?,
        flags: 0,
        method,
        source_sha256,
        created_unix_s: std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_secs())
            .unwrap_or(0),
        axes: slots,
    })
}
