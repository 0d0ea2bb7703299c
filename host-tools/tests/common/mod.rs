//! Shared fixtures of the host-tools tests: small coefficient images.
#![allow(dead_code)]

use dynocomp_core::image::{
    AxisImage, AxisScaling, AxisSummary, CoeffImage, DesignMethod, AXIS_HEADER_LEN, CRC32, FLAG_OFFLINE_ONLY,
    HEADER_LEN, MAX_IMAGE_LEN,
};
use dynocomp_core::kernel::{AxisFilter, Section};

/// A valid, box-runnable image on all three axes whose content (and so id)
/// depends on `variant`: one real-pole section (pole 0.5) and a direct term.
pub fn image(variant: u32, fs_hz: u32, flags: u8) -> CoeffImage {
    let section = Section::first_order(0.5, 1.0, 0.001 * variant as f32);
    let filter = AxisFilter::with_fir(&[section], 1.0, &[]).expect("valid filter");
    let axis = |i: u8| AxisImage {
        axis: i,
        scaling: AxisScaling {
            adc_offset_code: 2048.0,
            newton_per_code: 0.5 * f32::from(i + 1),
            dac_code_per_newton: 2.0 / f32::from(i + 1),
            dac_offset_code: 2048.0,
        },
        filter,
        summary: AxisSummary {
            model_order: 2,
            fit_nrmse: 0.01,
            flat_lo_hz: 0.0,
            flat_hi_hz: 2000.0,
            noise_gain: 1.5,
            q: 1.0,
            r: 0.1,
        },
    };
    CoeffImage {
        fs_hz,
        latency_samples: 0,
        flags,
        method: DesignMethod::Manual,
        source_sha256: [variant as u8; 32],
        created_unix_s: u64::from(variant),
        axes: [Some(axis(0)), Some(axis(1)), Some(axis(2))],
    }
}

/// Encoded bytes of an image.
pub fn bytes(img: &CoeffImage) -> Vec<u8> {
    let mut buf = vec![0u8; MAX_IMAGE_LEN];
    let n = img.encode(&mut buf).expect("encodes");
    buf.truncate(n);
    buf
}

/// Encoded bytes of a valid image (variant `v`, 51.2 kHz).
pub fn good(v: u32) -> Vec<u8> {
    bytes(&image(v, 51_200, 0))
}

/// An offline-only image (parses, but the box must not run it).
pub fn offline_only() -> Vec<u8> {
    bytes(&image(90, 51_200, FLAG_OFFLINE_ONLY))
}

/// An image at 5 kHz: valid, but outside the box's 10-200 kHz range.
pub fn slow() -> Vec<u8> {
    bytes(&image(91, 5_000, 0))
}

/// An image at 200 kHz (in the box's range): three small axes, but the
/// interrupt's fixed part and three axis calls alone are predicted above
/// the box's 60 % CPU limit of the 850-cycle period (`dynocomp_core::budget`).
pub fn over_budget() -> Vec<u8> {
    bytes(&image(93, 200_000, 0))
}

/// An image whose first section has its pole at z = 1.5 (unstable), with a
/// correct CRC, so only the stability check can reject it.
pub fn unstable() -> Vec<u8> {
    let mut b = good(92);
    // First section of axis 0: Δ11 = pole − 1 at offset HEADER_LEN + AXIS_HEADER_LEN.
    let at = HEADER_LEN + AXIS_HEADER_LEN;
    b[at..at + 4].copy_from_slice(&0.5f32.to_le_bytes());
    fix_crc(&mut b);
    b
}

/// Recompute the trailing CRC of an image after patching it.
pub fn fix_crc(b: &mut [u8]) {
    let n = b.len();
    let crc = CRC32.checksum(&b[..n - 4]);
    b[n - 4..].copy_from_slice(&crc.to_le_bytes());
}

/// The image id (`CoeffImage::id`) of encoded bytes, computed by parsing.
pub fn id(b: &[u8]) -> u32 {
    CoeffImage::parse(b).expect("fixture parses").id()
}
