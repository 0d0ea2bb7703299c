//! Shared test fixtures: modal filters designed in f64 from continuous modes.
#![allow(dead_code)]

use dynocomp_core::image::{AxisImage, AxisScaling, AxisSummary, CoeffImage, DesignMethod};
use dynocomp_core::kernel::{AxisFilter, Section};
use std::path::Path;
use std::process::Command;

/// `cargo build --release --target thumbv7em-none-eabihf` in `dir`, with the
/// firmware's own code generation (the release profile of `dir`'s
/// workspace, fat LTO): without a fast host build's CARGO_PROFILE_*
/// overrides or encoded RUSTFLAGS (scripts/test.sh and CI set them), and
/// without CI's clippy wrapper (.ci/run), which lints the host build.
pub fn firmware_cargo_build(dir: &Path) -> Command {
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let mut build = Command::new(cargo);
    build
        .current_dir(dir)
        .args(["build", "--release", "--target", "thumbv7em-none-eabihf"])
        .env_remove("CARGO_ENCODED_RUSTFLAGS")
        .env_remove("RUSTC_WORKSPACE_WRAPPER")
        .env_remove("CLIPPY_ARGS");
    for (k, _) in std::env::vars_os() {
        if k.to_str().is_some_and(|k| k.starts_with("CARGO_PROFILE_")) {
            build.env_remove(k);
        }
    }
    build
}

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

/// A deterministic generator of values in [-1, 1) (xorshift64).
pub struct Xorshift(pub u64);

impl Xorshift {
    pub fn next(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    }
}

/// A realistic 3x3 compensator at `fs_hz`: `pairs` normal-form pairs
/// (modes 100 Hz … 22 kHz, 1-5 % damping), `diagonals` diagonal sections
/// (real poles 0.97 and 0.6), `taps` FIR taps, every B, C and tap entry
/// non-zero (dense), output gains scaled to each mode's decay (as a
/// compensator's residues are), and the direct term chosen so that the DC
/// gain is the identity (to f32 rounding).
#[allow(dead_code)]
pub fn mimo_test_filter(
    fs_hz: f64,
    pairs: usize,
    diagonals: usize,
    taps: usize,
    seed: u64,
) -> dynocomp_core::mimo::MimoFilter {
    use dynocomp_core::mimo::{MimoFilter, MimoSection};
    let mut rng = Xorshift(seed);
    let mut secs = Vec::new();
    for k in 0..pairs {
        let f = (100.0 * 200.0f64.powf(k as f64 / (pairs.max(2) - 1) as f64)).min(22_000.0);
        let zeta = 0.01 + 0.01 * (k % 5) as f64;
        let w = 2.0 * std::f64::consts::PI * f / fs_hz;
        let r = (-zeta * w).exp();
        let th = w * (1.0 - zeta * zeta).sqrt();
        let (sigma, omega) = ((r * th.cos() - 1.0) as f32, (r * th.sin()) as f32);
        let g = 0.3 * (1.0 - r * r);
        let b = [[0; 3].map(|_| rng.next() as f32), [0; 3].map(|_| rng.next() as f32)];
        let c = [
            [0; 2].map(|_| (g * rng.next()) as f32),
            [0; 2].map(|_| (g * rng.next()) as f32),
            [0; 2].map(|_| (g * rng.next()) as f32),
        ];
        secs.push(MimoSection { delta: [sigma, omega, -omega, sigma], b, c });
    }
    for _ in 0..diagonals {
        let b = [[0; 3].map(|_| rng.next() as f32), [0; 3].map(|_| rng.next() as f32)];
        let c = [
            [0; 2].map(|_| (0.01 * rng.next()) as f32),
            [0; 2].map(|_| (0.01 * rng.next()) as f32),
            [0; 2].map(|_| (0.01 * rng.next()) as f32),
        ];
        secs.push(MimoSection { delta: [0.97 - 1.0, 0.0, 0.0, 0.6 - 1.0], b, c });
    }
    let fir: Vec<[[f32; 3]; 3]> = (0..taps)
        .map(|m| {
            let s = 0.1 * (-0.4 * m as f64).exp();
            [
                [0; 3].map(|_| (s * rng.next()) as f32),
                [0; 3].map(|_| (s * rng.next()) as f32),
                [0; 3].map(|_| (s * rng.next()) as f32),
            ]
        })
        .collect();
    let zero = [[0.0f32; 3]; 3];
    let rest = MimoFilter::new(&secs, zero, &fir).expect("test filter is valid").dc_gain();
    let d = core::array::from_fn(|i| core::array::from_fn(|j| (if i == j { 1.0 } else { 0.0 } - rest[i][j]) as f32));
    MimoFilter::new(&secs, d, &fir).expect("test filter is valid")
}

/// A valid 3x3 image of `filter` (scaling as [`image_with`]).
#[allow(dead_code)]
pub fn matrix_image(filter: dynocomp_core::mimo::MimoFilter, fs_hz: u32) -> dynocomp_core::image::MatrixImage {
    use dynocomp_core::image::{AxisChannel, MatrixImage, RowDesign};
    let per_axis = image_with(AxisFilter::gain(1.0).expect("gain"), &[0, 1, 2], fs_hz);
    let ch = |i: usize| {
        let a = per_axis.axes[i].expect("all axes");
        AxisChannel { axis: i as u8, scaling: a.scaling, summary: a.summary }
    };
    MatrixImage {
        fs_hz,
        latency_samples: 4,
        flags: 0,
        method: DesignMethod::VectorFitting,
        source_sha256: [7; 32],
        created_unix_s: 1_790_000_000,
        axes: [ch(0), ch(1), ch(2)],
        filter,
        rows: [RowDesign::Matrix, RowDesign::PerAxis, RowDesign::Matrix],
    }
}

/// The encoded bytes of a valid 3x3 image.
#[allow(dead_code)]
pub fn encode_matrix(img: &dynocomp_core::image::MatrixImage) -> Vec<u8> {
    let mut buf = vec![0u8; dynocomp_core::image::MAX_MATRIX_IMAGE_LEN];
    let n = img.encode(&mut buf).expect("encode 3x3 test image");
    buf.truncate(n);
    buf
}
