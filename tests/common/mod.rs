//! Shared test fixtures: modal filters designed in f64 from continuous modes.
#![allow(dead_code)]

use dynocomp_core::image::{AxisImage, AxisScaling, AxisSummary, CoeffImage, DesignMethod};
use dynocomp_core::kernel::{AxisFilter, Section};

/// A 2x2 modal block in f64: A (not A − I), b, c.
#[derive(Clone, Copy, Debug)]
pub struct Block64 {
    pub a: [[f64; 2]; 2],
    pub b: [f64; 2],
    pub c: [f64; 2],
}

/// The discrete block of a continuous mode (natural frequency `f_hz`, damping
/// ratio `zeta`) sampled at `fs_hz`: poles z = exp(s·T), s = −ζω ± jω√(1−ζ²),
/// in real rotation form A = r·[[cos θ, sin θ], [−sin θ, cos θ]].
/// `b = [|1 − z|, 0]` normalizes the block's gain; `c` is given.
pub fn mode_block(f_hz: f64, zeta: f64, fs_hz: f64, c: [f64; 2]) -> Block64 {
    let w = 2.0 * std::f64::consts::PI * f_hz;
    let t = 1.0 / fs_hz;
    let r = (-zeta * w * t).exp();
    let th = w * (1.0 - zeta * zeta).sqrt() * t;
    let (s, co) = th.sin_cos();
    let z_re = r * co;
    let z_im = r * s;
    let gain = ((1.0 - z_re).powi(2) + z_im.powi(2)).sqrt();
    Block64 { a: [[r * co, r * s], [-r * s, r * co]], b: [gain, 0.0], c }
}

/// Round an f64 block to the kernel's f32 delta form. `A − I` is formed in
/// f64 before rounding, which is the point of the delta form.
pub fn to_section(b: &Block64) -> Section {
    Section {
        delta: [(b.a[0][0] - 1.0) as f32, b.a[0][1] as f32, b.a[1][0] as f32, (b.a[1][1] - 1.0) as f32],
        b: [b.b[0] as f32, b.b[1] as f32],
        c: [b.c[0] as f32, b.c[1] as f32],
    }
}

/// A 24-section test filter spanning 100 Hz .. 20 kHz at fs = 51.2 kHz,
/// including a 100 Hz mode with 1 % damping (issue #2's acceptance case).
pub fn filter_24(fs_hz: f64) -> (Vec<Block64>, f64) {
    let mut blocks = Vec::new();
    blocks.push(mode_block(100.0, 0.01, fs_hz, [0.8, -0.3]));
    for i in 1..24 {
        let f = 150.0 * (20_000.0f64 / 150.0).powf(i as f64 / 23.0);
        let zeta = 0.01 + 0.04 * ((i * 7) % 11) as f64 / 10.0;
        let sign = if i % 2 == 0 { 1.0 } else { -1.0 };
        blocks.push(mode_block(f, zeta, fs_hz, [sign * 0.5 / (1.0 + i as f64 * 0.1), 0.2]));
    }
    (blocks, 0.25)
}

/// The f32 kernel filter of a set of f64 blocks.
pub fn kernel_filter(blocks: &[Block64], d: f64) -> AxisFilter {
    let secs: Vec<Section> = blocks.iter().map(to_section).collect();
    AxisFilter::new(&secs, d as f32).expect("test filter is valid")
}

/// A valid image with the given filter on the given axes.
pub fn image_with(filter: AxisFilter, axes: &[usize], fs_hz: u32) -> CoeffImage {
    let mut img = CoeffImage {
        fs_hz,
        latency_samples: 0,
        flags: 0,
        method: DesignMethod::Manual,
        source_sha256: [7; 32],
        created_unix_s: 1_790_000_000,
        axes: [None; 3],
    };
    for &a in axes {
        img.axes[a] = Some(AxisImage {
            axis: a as u8,
            scaling: AxisScaling {
                adc_offset_code: 2048.0,
                newton_per_code: 2.5,
                dac_code_per_newton: 0.4,
                dac_offset_code: 2048.0,
            },
            filter,
            summary: AxisSummary {
                model_order: 12,
                fit_nrmse: 0.012,
                flat_lo_hz: 0.0,
                flat_hi_hz: 3800.0,
                noise_gain: 3.1,
                q: 2.0e6,
                r: 0.05,
            },
        });
    }
    img
}

/// The encoded bytes of a valid image.
pub fn encode_image(img: &CoeffImage) -> Vec<u8> {
    let mut buf = vec![0u8; dynocomp_core::image::MAX_IMAGE_LEN];
    let n = img.encode(&mut buf).expect("encode test image");
    buf.truncate(n);
    buf
}

/// Recompute the trailing CRC after deliberately editing a field, so that a
/// test reaches the semantic check behind the CRC.
pub fn fix_crc(bytes: &mut [u8]) {
    let n = bytes.len();
    let crc = dynocomp_core::image::CRC32.checksum(&bytes[..n - 4]);
    bytes[n - 4..].copy_from_slice(&crc.to_le_bytes());
}
