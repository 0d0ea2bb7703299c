//! The 3x3 image (format version 3): its byte layout read back field by
//! field at the offsets `docs/image-format.md` §13 documents, a round trip,
//! the loader's checks each with the value just inside its bound (accepted)
//! and just outside (refused), and the bounds themselves against the
//! filter's simulated response (the ℓ1 gain bound against the ℓ1 norm of
//! each row's impulse response, the DC gain against the step response).

mod common;
use common::*;

use dynocomp_core::image::*;
use dynocomp_core::mimo::{MimoFilter, MimoSection, MimoState};

fn realistic() -> MatrixImage {
    matrix_image(mimo_test_filter(51_200.0, 20, 2, 8, 0x5EED), 51_200)
}

fn f32_at(b: &[u8], at: usize) -> f32 {
    f32::from_le_bytes(b[at..at + 4].try_into().unwrap())
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(b[at..at + 4].try_into().unwrap())
}

/// Offsets of the documented layout.
const AXIS0: usize = 64;
const FILTER: usize = 64 + 3 * 56;
const SECTIONS: usize = FILTER + 40;

#[test]
fn the_bytes_are_at_the_documented_offsets() {
    let img = realistic();
    let b = encode_matrix(&img);
    let (ns, nt) = (22usize, 8usize);
    assert_eq!(b.len(), 280 + 64 * ns + 36 * nt);
    assert_eq!(&b[0..4], b"DCIM");
    assert_eq!(u16::from_le_bytes([b[4], b[5]]), 3);
    assert_eq!(u16::from_le_bytes([b[6], b[7]]), 64);
    assert_eq!(u32_at(&b, 8) as usize, b.len());
    assert_eq!(u32_at(&b, 12), 51_200);
    assert_eq!(b[18], 0b111);
    assert_eq!(b[20], 1, "method VectorFitting");
    for i in 0..3 {
        let blk = AXIS0 + 56 * i;
        let a = &img.axes[i];
        assert_eq!(b[blk], i as u8);
        assert_eq!(&b[blk + 1..blk + 4], &[0, 0, 0]);
        assert_eq!(u16::from_le_bytes([b[blk + 4], b[blk + 5]]), a.summary.model_order);
        assert_eq!(f32_at(&b, blk + 8), a.scaling.adc_offset_code);
        assert_eq!(f32_at(&b, blk + 12), a.scaling.newton_per_code);
        assert_eq!(f32_at(&b, blk + 16), a.scaling.dac_code_per_newton);
        assert_eq!(f32_at(&b, blk + 20), a.scaling.dac_offset_code);
        assert_eq!(f32_at(&b, blk + 24), a.summary.fit_nrmse);
        assert_eq!(f32_at(&b, blk + 36), a.summary.noise_gain);
        assert_eq!(f64::from_le_bytes(b[blk + 40..blk + 48].try_into().unwrap()), a.summary.q);
        assert_eq!(f64::from_le_bytes(b[blk + 48..blk + 56].try_into().unwrap()), a.summary.r);
    }
    let f = &img.filter;
    assert_eq!((b[FILTER] as usize, b[FILTER + 1] as usize), (ns, nt));
    assert_eq!(&b[FILTER + 2..FILTER + 4], &[0, 0]);
    for i in 0..3 {
        for j in 0..3 {
            assert_eq!(f32_at(&b, FILTER + 4 + 4 * (3 * i + j)), f.d()[i][j]);
        }
    }
    for (k, s) in f.sections().iter().enumerate() {
        let at = SECTIONS + 64 * k;
        let flat: Vec<f32> = s.delta.iter().chain(s.b.iter().flatten()).chain(s.c.iter().flatten()).copied().collect();
        for (v, x) in flat.iter().enumerate() {
            assert_eq!(f32_at(&b, at + 4 * v), *x, "section {k} value {v}");
        }
        // b[1][2] (state 2, input z) at +36, c[2][1] (output z, state 2) at +60
        assert_eq!(f32_at(&b, at + 36), s.b[1][2]);
        assert_eq!(f32_at(&b, at + 60), s.c[2][1]);
    }
    let taps = SECTIONS + 64 * ns;
    for (m, h) in f.fir().iter().enumerate() {
        for (i, row) in h.iter().enumerate() {
            for (j, x) in row.iter().enumerate() {
                assert_eq!(f32_at(&b, taps + 36 * m + 4 * (3 * i + j)), *x);
            }
        }
    }
    let rows = taps + 36 * nt;
    assert_eq!(&b[rows..rows + 4], &[1, 0, 1, 0], "row record: x 3x3, y per-axis, z 3x3");
    let n = b.len();
    assert_eq!(u32_at(&b, n - 4), CRC32.checksum(&b[..n - 4]));
    assert_eq!(img.id(), u32_at(&b, n - 4));
}

#[test]
fn a_3x3_image_round_trips_exactly_and_from_a_flash_slot() {
    let img = realistic();
    let b = encode_matrix(&img);
    assert_eq!(MatrixImage::parse(&b), Ok(img));
    assert_eq!(BoxImage::parse(&b), Ok(BoxImage::Matrix(img)));
    let mut slot = vec![0xFFu8; 8192];
    slot[..b.len()].copy_from_slice(&b);
    assert_eq!(BoxImage::parse_prefix(&slot), Ok(BoxImage::Matrix(img)));
    assert_eq!(MatrixImage::parse_prefix(&slot), Ok(img));
    // The per-axis reader names it; the largest image fits a slot.
    assert_eq!(CoeffImage::parse(&b), Err(ImageError::NotPerAxisImage));
    assert_eq!(CoeffImage::parse_prefix(&slot), Err(ImageError::NotPerAxisImage));
    const { assert!(MAX_MATRIX_IMAGE_LEN + 32 <= 8192 && MAX_MATRIX_IMAGE_LEN == 4216) };
    // A truncated image in a slot reports the missing bytes.
    assert_eq!(
        BoxImage::parse_prefix(&b[..b.len() - 1]),
        Err(ImageError::Truncated { needed: b.len() as u32, have: b.len() as u32 - 1 })
    );
    // A per-axis image through BoxImage encodes to the same bytes as before.
    let v1 = image_with(dynocomp_core::kernel::AxisFilter::gain(1.5).unwrap(), &[0, 2], 51_200);
    let mut buf = vec![0u8; MAX_BOX_IMAGE_LEN];
    let n = BoxImage::PerAxis(v1).encode(&mut buf).unwrap();
    assert_eq!(&buf[..n], &encode_image(&v1)[..]);
    assert_eq!(BoxImage::PerAxis(v1).id(), v1.id());
}

#[test]
fn every_single_bit_flip_is_rejected() {
    let img = matrix_image(mimo_test_filter(51_200.0, 3, 1, 2, 9), 51_200);
    let b = encode_matrix(&img);
    for at in 0..b.len() {
        for bit in 0..8 {
            let mut c = b.clone();
            c[at] ^= 1 << bit;
            assert!(BoxImage::parse(&c).is_err(), "flip at byte {at} bit {bit} accepted");
        }
    }
}

/// `b` with the f32 at `at` set to `v` and the CRC recomputed.
fn with_f32(b: &[u8], at: usize, v: f32) -> Vec<u8> {
    let mut c = b.to_vec();
    c[at..at + 4].copy_from_slice(&v.to_le_bytes());
    fix_crc(&mut c);
    c
}

fn with_byte(b: &[u8], at: usize, v: u8) -> Vec<u8> {
    let mut c = b.to_vec();
    c[at] = v;
    fix_crc(&mut c);
    c
}

#[test]
fn structural_errors_are_named() {
    let b = encode_matrix(&realistic());
    let p = |c: &[u8]| MatrixImage::parse(c).err();
    assert_eq!(p(&with_byte(&b, 18, 0b011)), Some(ImageError::BadAxisMask(0b011)));
    assert_eq!(p(&with_byte(&b, 21, 1)), Some(ImageError::ReservedNotZero));
    assert_eq!(p(&with_byte(&b, 20, 3)), Some(ImageError::UnknownMethod(3)));
    assert_eq!(p(&with_byte(&b, AXIS0 + 56, 2)), Some(ImageError::AxisMismatch { expected: 1, found: 2 }));
    assert_eq!(p(&with_byte(&b, AXIS0 + 2, 1)), Some(ImageError::ReservedNotZero));
    assert_eq!(p(&with_byte(&b, FILTER, 49)), Some(ImageError::MatrixTooManySections(49)));
    assert_eq!(p(&with_byte(&b, FILTER + 1, 25)), Some(ImageError::MatrixTooManyTaps(25)));
    // Counts that fit the limits but not the length.
    assert_eq!(p(&with_byte(&b, FILTER, 23)), Some(ImageError::BadLength(b.len() as u32)));
    assert_eq!(p(&with_byte(&b, FILTER + 3, 1)), Some(ImageError::ReservedNotZero));
    let rows = b.len() - 8;
    assert_eq!(p(&with_byte(&b, rows + 1, 2)), Some(ImageError::BadRowDesign { row: 1, code: 2 }));
    assert_eq!(p(&with_byte(&b, rows + 3, 1)), Some(ImageError::ReservedNotZero));
    assert_eq!(p(&with_f32(&b, FILTER + 4 + 4 * 5, f32::NAN)), Some(ImageError::MatrixNonFinite { section: 255 }));
    assert_eq!(
        p(&with_f32(&b, SECTIONS + 64 * 3 + 44, f32::INFINITY)),
        Some(ImageError::MatrixNonFinite { section: 3 })
    );
    let taps = SECTIONS + 64 * 22;
    assert_eq!(p(&with_f32(&b, taps + 36 * 7 + 8, f32::NAN)), Some(ImageError::MatrixNonFiniteTap { tap: 7 }));
    // σ = 0.5 on a pair: |1 + σ ± jω| > 1.
    let c = with_f32(&with_f32(&b, SECTIONS, 0.5), SECTIONS + 12, 0.5);
    assert_eq!(p(&c), Some(ImageError::MatrixUnstableSection { section: 0 }));
    // Δ22 ≠ Δ11 on a pair: neither shape.
    assert_eq!(p(&with_f32(&b, SECTIONS + 64 + 12, -0.5)), Some(ImageError::MatrixNotModalSection { section: 1 }));
    assert_eq!(
        p(&with_f32(&b, 12, 500.0)),
        Some(ImageError::SampleRateOutOfRange(u32::from_le_bytes(500f32.to_le_bytes())))
    );
    assert_eq!(p(&with_f32(&b, AXIS0 + 56 + 12, 0.0)), Some(ImageError::BadScaling { axis: 1 }));
    assert_eq!(p(&with_f32(&b, AXIS0 + 112 + 36, -1.0)), Some(ImageError::BadSummary { axis: 2 }));
    // Negative control: the unmodified bytes (CRC recomputed) parse.
    assert!(p(&with_byte(&b, 18, 0b111)).is_none());
}

/// A pure 3x3 gain image (no section, no tap) with direct term `d`.
fn gain_image(d: [[f32; 3]; 3]) -> Result<MatrixImage, ImageError> {
    let img = matrix_image(MimoFilter::new(&[], d, &[]).unwrap(), 51_200);
    let mut buf = vec![0u8; MAX_MATRIX_IMAGE_LEN];
    img.encode(&mut buf).map(|_| img)
}

const I3: [[f32; 3]; 3] = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

#[test]
fn the_dc_rows_must_be_near_the_identity() {
    // Row deviation Σ_j |H_ij(1) − δ_ij| = 0.49: accepted; 0.51: refused.
    for (row, dev, ok) in [(0usize, 0.49f32, true), (0, 0.51, false), (2, 0.49, true), (2, 0.51, false)] {
        let mut d = I3;
        d[row][1] += dev * 0.5;
        d[row][row] -= dev * 0.5;
        let r = gain_image(d);
        assert_eq!(r.is_ok(), ok, "row {row} deviation {dev}: {r:?}");
        if !ok {
            assert_eq!(r.err(), Some(ImageError::MatrixDcGainOutOfRange { row: row as u8 }));
        }
    }
    // The realistic filter: its step response settles at the DC matrix the
    // loader checks (the f32 kernel, 200 000 samples, slowest mode 100 Hz
    // at 1 % damping: decayed by e⁻²⁴).
    let f = realistic().filter;
    let dc = f.dc_gain();
    for j in 0..3 {
        let mut st = MimoState::default();
        let mut u = [0.0f32; 3];
        u[j] = 1.0;
        let mut y = [0.0f32; 3];
        for _ in 0..200_000 {
            y = f.step(&mut st, u);
        }
        for i in 0..3 {
            assert!(
                (f64::from(y[i]) - dc[i][j]).abs() < 1e-4,
                "H({i},{j})(1) = {} by the formula, {} by the step",
                dc[i][j],
                y[i]
            );
        }
    }
}

#[test]
fn the_row_gain_bound_bounds_the_impulse_response() {
    // ℓ1 norm of each row's impulse responses (three inputs), simulated
    // with the f32 kernel, never exceeds the bound; and the bound is not
    // loose beyond the documented factor 2√2 per section (here < 10×).
    let f = realistic().filter;
    let mut l1 = [0.0f64; 3];
    for j in 0..3 {
        let mut st = MimoState::default();
        for k in 0..200_000 {
            let mut u = [0.0f32; 3];
            if k == 0 {
                u[j] = 1.0;
            }
            let y = f.step(&mut st, u);
            for i in 0..3 {
                l1[i] += f64::from(y[i].abs());
            }
        }
    }
    for (i, l) in l1.iter().enumerate() {
        let bound = f.row_gain_bound(i);
        assert!(*l <= bound, "row {i}: ℓ1 {l} above bound {bound}");
        assert!(bound < 10.0 * l, "row {i}: bound {bound} vs ℓ1 {l}");
    }
}

#[test]
fn coefficient_margin_and_gain_bounds_are_enforced_at_their_limits() {
    let base = realistic();
    let enc = |img: &MatrixImage| {
        let mut buf = vec![0u8; MAX_MATRIX_IMAGE_LEN];
        img.encode(&mut buf).map(|n| buf[..n].to_vec())
    };
    let with_sections = |secs: &[MimoSection], d| {
        let mut img = base;
        img.filter = MimoFilter::new(secs, d, &[]).unwrap();
        img
    };
    // A diagonal section whose unused state is x₂: pole 1 − margin.
    let sec = |p: f32, c: f32| MimoSection {
        delta: [p - 1.0, 0.0, 0.0, -1.0],
        b: [[1e-3, 0.0, 0.0], [0.0; 3]],
        c: [[c, 0.0], [0.0; 2], [0.0; 2]],
    };
    // Pole margin: 1 − 2·10⁻⁷ accepted, 1 − 6·10⁻⁸ refused (f32 steps
    // near 1 are 6·10⁻⁸).
    assert!(enc(&with_sections(&[sec(1.0 - 2.4e-7, 1e-4)], I3)).is_ok());
    assert_eq!(
        enc(&with_sections(&[sec(1.0 - 6e-8, 1e-4)], I3)).err(),
        Some(ImageError::MatrixPoleMarginTooSmall { section: 0 })
    );
    // Coefficient bound: 10⁶ accepted, the next f32 above refused.
    let big = MimoSection {
        delta: [-0.5, 0.0, 0.0, -1.0],
        b: [[1.0e6, 0.0, 0.0], [0.0; 3]],
        c: [[1e-7, 0.0], [0.0; 2], [0.0; 2]],
    };
    assert!(enc(&with_sections(&[big], I3)).is_ok());
    let mut bigger = big;
    bigger.b[0][0] = f32::from_bits(1.0e6f32.to_bits() + 1);
    assert_eq!(enc(&with_sections(&[bigger], I3)).err(), Some(ImageError::MatrixCoefficientOutOfRange { section: 0 }));
    let mut d = I3;
    d[1][2] = 2.0e6;
    assert_eq!(enc(&with_sections(&[], d)).err(), Some(ImageError::MatrixCoefficientOutOfRange { section: 255 }));
    // Gain bound: a band-pass pair on row y (output gains chosen so that
    // its DC gain c·(−Δ)⁻¹·b is 0) whose bound is just under and just over
    // 10⁴.
    let pair = |g: f64| {
        let (sigma, omega) = (-1e-3f32, 0.01f32);
        let (s, w) = (f64::from(sigma), f64::from(omega));
        let rho2 = (1.0 + s).powi(2) + w * w;
        // (−Δ)⁻¹·[1, 0] = −[σ, ω] / (σ² + ω²)
        let (x1, x2) = (-s / (s * s + w * w), -w / (s * s + w * w));
        let ratio = -x1 / x2; // c2 = ratio·c1 cancels the DC gain
        let c1 = g * (1.0 - rho2) / (2.0 * (1.0 + ratio.abs()));
        let c = [c1 as f32, (c1 * ratio) as f32];
        MimoSection { delta: [sigma, omega, -omega, sigma], b: [[0.0, 1.0, 0.0], [0.0; 3]], c: [[0.0; 2], c, [0.0; 2]] }
    };
    for (g, ok) in [(9_990.0, true), (10_010.0, false)] {
        let img = with_sections(&[pair(g)], I3);
        let bound = img.filter.row_gain_bound(1);
        // The identity row of d adds Σ_j |d_1j| = 1.
        assert!((bound - 1.0 - g).abs() < 0.01, "bound {bound} for {g}");
        assert!((img.filter.dc_gain()[1][1] - 1.0).abs() < 1e-3, "the DC check must not decide");
        match enc(&img) {
            Ok(_) => assert!(ok, "gain bound {bound} accepted"),
            Err(e) => assert_eq!((ok, e), (false, ImageError::MatrixGainBoundTooLarge { row: 1, bound: bound as u32 })),
        }
    }
}

#[test]
fn the_errors_display_on_one_line() {
    for e in [
        ImageError::NotPerAxisImage,
        ImageError::BadRowDesign { row: 1, code: 7 },
        ImageError::MatrixTooManySections(49),
        ImageError::MatrixTooManyTaps(30),
        ImageError::MatrixNonFinite { section: 255 },
        ImageError::MatrixNonFinite { section: 4 },
        ImageError::MatrixNonFiniteTap { tap: 2 },
        ImageError::MatrixUnstableSection { section: 1 },
        ImageError::MatrixNotModalSection { section: 1 },
        ImageError::MatrixCoefficientOutOfRange { section: 255 },
        ImageError::MatrixCoefficientOutOfRange { section: 3 },
        ImageError::MatrixTapOutOfRange { tap: 0 },
        ImageError::MatrixPoleMarginTooSmall { section: 0 },
        ImageError::MatrixGainBoundTooLarge { row: 2, bound: 12_345 },
        ImageError::MatrixDcGainOutOfRange { row: 0 },
    ] {
        let s = e.to_string();
        assert!(!s.contains('\n') && !s.is_empty() && s.len() < 160, "{e:?}: {s}");
    }
}
