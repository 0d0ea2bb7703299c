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

/// A valid 3x3 image (format 3) on x, y, z at `fs_hz`: `pairs` lightly
/// damped pole pairs from 200 Hz up, every pair fed by all three inputs and
/// seen by all three outputs (crosstalk terms non-zero), `taps` FIR taps,
/// and the direct term chosen so that the DC gain is the identity. Scaling
/// as [`image`] (0.5·(i+1) N/code in, 2/(i+1) codes/N out, mid-scale 2048).
pub fn matrix_image(variant: u32, fs_hz: u32, pairs: usize, taps: usize) -> dynocomp_core::image::MatrixImage {
    use dynocomp_core::image::{AxisChannel, MatrixImage, RowDesign};
    use dynocomp_core::mimo::{MimoFilter, MimoSection};
    let fs = f64::from(fs_hz);
    let v = variant as f32;
    let sections: Vec<MimoSection> = (0..pairs)
        .map(|k| {
            let w = 2.0 * std::f64::consts::PI * 200.0 * 1.7f64.powi(k as i32) / fs;
            let r = (-0.02 * w).exp();
            let (sigma, omega) = ((r * w.cos() - 1.0) as f32, (r * w.sin()) as f32);
            let g = (0.2 * (1.0 - r)) as f32;
            let kf = k as f32;
            MimoSection {
                delta: [sigma, omega, -omega, sigma],
                b: [[1.0, 0.3 + 0.01 * v, -0.2], [0.1 * kf, -0.5, 0.4]],
                c: [[g, -0.5 * g], [0.3 * g, g], [-0.2 * g, 0.7 * g]],
            }
        })
        .collect();
    let fir: Vec<[[f32; 3]; 3]> = (0..taps)
        .map(|m| {
            let s = 0.02 / (m as f32 + 1.0);
            [[s, -0.5 * s, 0.2 * s], [0.1 * s, s, -0.3 * s], [0.4 * s, 0.0, s]]
        })
        .collect();
    let zero = [[0.0f32; 3]; 3];
    let rest = MimoFilter::new(&sections, zero, &fir).expect("valid 3x3 filter").dc_gain();
    let d = std::array::from_fn(|i| std::array::from_fn(|j| (f64::from(u8::from(i == j)) - rest[i][j]) as f32));
    let filter = MimoFilter::new(&sections, d, &fir).expect("valid 3x3 filter");
    let per_axis = image(variant, fs_hz, 0);
    let ch = |i: usize| {
        let a = per_axis.axes[i].expect("all axes");
        AxisChannel { axis: i as u8, scaling: a.scaling, summary: a.summary }
    };
    MatrixImage {
        fs_hz,
        latency_samples: 2,
        flags: 0,
        method: DesignMethod::VectorFitting,
        source_sha256: [variant as u8; 32],
        created_unix_s: u64::from(variant),
        axes: [ch(0), ch(1), ch(2)],
        filter,
        rows: [RowDesign::Matrix, RowDesign::PerAxis, RowDesign::Matrix],
    }
}

/// Encoded bytes of a 3x3 image.
pub fn matrix_bytes(img: &dynocomp_core::image::MatrixImage) -> Vec<u8> {
    dynocomp::io::image_file::encode_matrix_image(img).expect("3x3 fixture encodes")
}
