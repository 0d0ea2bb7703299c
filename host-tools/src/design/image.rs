//! The coefficient image of a set of designs: one per axis
//! ([`build_image`]), or one per fitting band for parallel elaboration
//! ([`build_parallel_image`]).

use anyhow::{Context, Result};
use dynocomp_core::image::{AxisSummary, BandImage, CoeffImage, DesignMethod, ParallelImage};

use crate::design::axis::AxisDesign;
use crate::design::bands::Band;
use crate::realize::image::ImageAxis;

impl AxisDesign {
    /// What the image holds of this axis.
    pub fn image_axis(&self) -> ImageAxis {
        ImageAxis {
            axis: self.axis,
            filter: self.filter,
            summary: AxisSummary {
                model_order: self.model.order() as u16,
                // A pass-through axis has no fit: 0 in the image.
                fit_nrmse: if self.fit_nrmse.is_finite() { self.fit_nrmse as f32 } else { 0.0 },
                flat_lo_hz: self.flat_band_hz.0 as f32,
                flat_hi_hz: self.flat_band_hz.1 as f32,
                noise_gain: self.noise_gain as f32,
                q: self.kalman.q,
                r: self.kalman.r,
            },
        }
    }
}

/// The image of the per-axis `designs` (method Paper when they were
/// designed by `--method paper`).
pub fn build_image(
    designs: &[AxisDesign],
    fs_hz: u32,
    latency: usize,
    full_scale_n: f64,
    source_sha256: [u8; 32],
) -> Result<CoeffImage> {
    let axes: Vec<ImageAxis> = designs.iter().map(AxisDesign::image_axis).collect();
    let method =
        if designs.iter().any(|d| d.paper.is_some()) { DesignMethod::Paper } else { DesignMethod::VectorFitting };
    crate::realize::image::build_image(&axes, method, fs_hz, latency, full_scale_n, source_sha256)
}

/// The parallel image of per-band designs (each band's filters verified by
/// the design's quantize/verify step), with the bands' edges.
pub fn build_parallel_image(
    per_band: &[Vec<AxisDesign>],
    bands: &[Band],
    fs_hz: u32,
    latency: usize,
    full_scale_n: f64,
    source_sha256: [u8; 32],
) -> Result<ParallelImage> {
    let mut images = Vec::with_capacity(per_band.len());
    let mut method = DesignMethod::VectorFitting;
    let mut created = 0;
    for (designs, band) in per_band.iter().zip(bands) {
        let img = build_image(designs, fs_hz, latency, full_scale_n, source_sha256)?;
        method = img.method;
        created = img.created_unix_s;
        images.push(BandImage { lo_hz: band.lo_hz as f32, hi_hz: band.hi_hz as f32, axes: img.axes });
    }
    let latency = u16::try_from(latency).context("latency too large")?;
    ParallelImage::new(fs_hz, latency, method, source_sha256, created, &images)
        .map_err(|e| anyhow::anyhow!("parallel image: {e}"))
}
