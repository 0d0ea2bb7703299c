//! Coefficient image codec: round trip and rejection of every corruption.

mod common;
use common::*;
use dynocomp_core::image::*;
use dynocomp_core::kernel::{AxisFilter, Section, MAX_FIR};
use proptest::prelude::*;

fn encode(img: &CoeffImage) -> Vec<u8> {
    let mut buf = vec![0u8; MAX_IMAGE_LEN];
    let n = img.encode(&mut buf).expect("encode");
    buf.truncate(n);
    buf
}

fn full_image() -> CoeffImage {
    let (blocks, d) = filter_24(51_200.0);
    image_with(kernel_filter(&blocks, d), &[0, 1, 2], 51_200)
}

/// Like `full_image`, with `taps` FIR taps on every axis.
fn image_with_taps(taps: usize) -> CoeffImage {
    let (blocks, d) = filter_24(51_200.0);
    let secs: Vec<Section> = blocks.iter().map(to_section).collect();
    let fir: Vec<f32> = (0..taps).map(|j| 0.1 / (j as f32 + 1.0)).collect();
    image_with(AxisFilter::with_fir(&secs, d as f32, &fir).unwrap(), &[0, 1, 2], 51_200)
}

#[test]
fn round_trip_preserves_every_field() {
    let mut img = image_with_taps(5);
    img.latency_samples = 6;
    img.method = DesignMethod::VectorFitting;
    img.axes[1] = None;
    let bytes = encode(&img);
    assert_eq!(bytes.len(), encoded_len(&img));
    assert_eq!(bytes.len(), HEADER_LEN + 2 * (AXIS_HEADER_LEN + 24 * SECTION_LEN + 5 * TAP_LEN) + CRC_LEN);
    assert_eq!(&bytes[..4], b"DCIM");
    let back = CoeffImage::parse(&bytes).expect("parse");
    assert_eq!(back, img);
    assert_eq!(back.axis_mask(), 0b101);
    // bit patterns of the coefficients survive exactly
    let a = back.axes[2].unwrap().filter;
    let b = img.axes[2].unwrap().filter;
    for (x, y) in a.sections().iter().zip(b.sections()) {
        assert_eq!(x.delta.map(f32::to_bits), y.delta.map(f32::to_bits));
    }
}

#[test]
fn max_size_image_fits_the_declared_maximum() {
    let bytes = encode(&image_with_taps(MAX_FIR));
    assert_eq!(bytes.len(), MAX_IMAGE_LEN);
    const { assert!(MAX_IMAGE_LEN <= 8 * 1024, "must fit one 8 KiB flash slot") };
}

#[test]
fn parse_prefix_reads_an_image_inside_an_erased_flash_slot() {
    let bytes = encode(&full_image());
    let mut slot = vec![0xFFu8; 8192];
    slot[..bytes.len()].copy_from_slice(&bytes);
    assert_eq!(CoeffImage::parse_prefix(&slot).unwrap(), full_image());
    assert_eq!(CoeffImage::parse_prefix(&vec![0xFFu8; 8192]), Err(ImageError::BadMagic));
    assert!(CoeffImage::parse_prefix(&slot[..bytes.len() - 1]).is_err());
}

#[test]
fn every_single_bit_flip_is_rejected() {
    let bytes = encode(&image_with_taps(3));
    let mut flipped = bytes.clone();
    for i in 0..bytes.len() * 8 {
        flipped[i / 8] ^= 1 << (i % 8);
        assert!(CoeffImage::parse(&flipped).is_err(), "bit {i} flip accepted");
        assert!(CoeffImage::parse_prefix(&flipped).is_err(), "bit {i} flip accepted in slot");
        flipped[i / 8] ^= 1 << (i % 8);
    }
    assert!(CoeffImage::parse(&flipped).is_ok());
}

#[test]
fn every_truncation_is_rejected() {
    let mut img = image_with_taps(4);
    img.axes[0] = None;
    let bytes = encode(&img);
    for n in 0..bytes.len() {
        let r = CoeffImage::parse(&bytes[..n]);
        assert!(r.is_err(), "truncation to {n} bytes accepted");
        assert!(CoeffImage::parse_prefix(&bytes[..n]).is_err(), "prefix truncation to {n} accepted");
    }
    // and a trailing extra byte is not silently accepted by the exact parser
    let mut long = bytes.clone();
    long.push(0);
    assert!(CoeffImage::parse(&long).is_err());
}

#[test]
fn wrong_versions_are_rejected_even_with_a_valid_crc() {
    let bytes = encode(&full_image());
    for v in [0u16, 4, 0x0100, u16::MAX] {
        let mut b = bytes.clone();
        b[4..6].copy_from_slice(&v.to_le_bytes());
        fix_crc(&mut b);
        assert_eq!(CoeffImage::parse(&b), Err(ImageError::UnsupportedVersion(v)));
        assert_eq!(BoxImage::parse(&b), Err(ImageError::UnsupportedVersion(v)));
    }
    // version 3 is the 3x3 image: not a per-axis image, and its own parser
    // refuses these bytes (a version-1 body)
    let mut b = bytes.clone();
    b[4..6].copy_from_slice(&3u16.to_le_bytes());
    fix_crc(&mut b);
    assert_eq!(CoeffImage::parse(&b), Err(ImageError::NotPerAxisImage));
    assert!(BoxImage::parse(&b).is_err());
    // version 2 is the parallel-elaboration image: named as such, never run
    let mut b = bytes.clone();
    b[4..6].copy_from_slice(&2u16.to_le_bytes());
    fix_crc(&mut b);
    assert_eq!(CoeffImage::parse(&b), Err(ImageError::ParallelOfflineOnly));
}

#[test]
fn semantic_errors_behind_a_valid_crc_are_rejected() {
    let bytes = encode(&full_image());
    // sample rate out of range (offset 12)
    let mut b = bytes.clone();
    b[12..16].copy_from_slice(&5u32.to_le_bytes());
    fix_crc(&mut b);
    assert_eq!(CoeffImage::parse(&b), Err(ImageError::SampleRateOutOfRange(5)));
    // unknown flag (offset 19)
    let mut b = bytes.clone();
    b[19] = 0x80;
    fix_crc(&mut b);
    assert_eq!(CoeffImage::parse(&b), Err(ImageError::UnknownFlags(0x80)));
    // a NaN coefficient in the first section of axis x
    let first_section = HEADER_LEN + AXIS_HEADER_LEN;
    let mut b = bytes.clone();
    b[first_section..first_section + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    fix_crc(&mut b);
    assert_eq!(CoeffImage::parse(&b), Err(ImageError::NonFiniteCoefficient { axis: 0, section: 0 }));
    // an unstable section: Δ11 = +0.5 (pole outside the unit circle)
    let mut b = bytes.clone();
    b[first_section..first_section + 4].copy_from_slice(&0.5f32.to_le_bytes());
    fix_crc(&mut b);
    assert_eq!(CoeffImage::parse(&b), Err(ImageError::UnstableSection { axis: 0, section: 0 }));
    // a stable section of a shape the kernel does not run: Δ21 changed so the
    // block is triangular (neither a normal-form pair nor diagonal)
    let mut b = bytes.clone();
    let d12 = f32::from_le_bytes(b[first_section + 4..first_section + 8].try_into().unwrap());
    let d21 = if d12 == 0.0 { 1.0e-3f32 } else { 0.0 };
    b[first_section + 8..first_section + 12].copy_from_slice(&d21.to_le_bytes());
    fix_crc(&mut b);
    assert_eq!(CoeffImage::parse(&b), Err(ImageError::NotModalSection { axis: 0, section: 0 }));
    // section count larger than the maximum
    let mut b = bytes.clone();
    b[HEADER_LEN + 1] = 25;
    fix_crc(&mut b);
    assert!(matches!(CoeffImage::parse(&b), Err(ImageError::TooManySections { .. })));
    // too many FIR taps
    let mut b = bytes.clone();
    b[HEADER_LEN + 2] = (MAX_FIR + 1) as u8;
    fix_crc(&mut b);
    assert!(matches!(CoeffImage::parse(&b), Err(ImageError::TooManyTaps { .. })));
    // zero input gain (newton_per_code at axis offset 12)
    let mut b = bytes.clone();
    b[HEADER_LEN + 12..HEADER_LEN + 16].copy_from_slice(&0f32.to_le_bytes());
    fix_crc(&mut b);
    assert_eq!(CoeffImage::parse(&b), Err(ImageError::BadScaling { axis: 0 }));
}

#[test]
fn encoder_refuses_invalid_images() {
    let mut img = full_image();
    img.fs_hz = 10;
    let mut buf = vec![0u8; MAX_IMAGE_LEN];
    assert_eq!(img.encode(&mut buf), Err(ImageError::SampleRateOutOfRange(10)));
    let mut img = full_image();
    img.axes = [None; 3];
    assert_eq!(img.encode(&mut buf), Err(ImageError::BadAxisMask(0)));
    let img = full_image();
    assert!(matches!(img.encode(&mut buf[..100]), Err(ImageError::BufferTooSmall { .. })));
}

fn arb_section() -> impl Strategy<Value = Section> {
    // stable by construction: a rotation with radius in (0.2, 0.999999)
    (0.2f64..0.999_999, 0.0f64..3.1, -10.0f32..10.0, -10.0f32..10.0, -10.0f32..10.0).prop_map(|(r, th, b, c1, c2)| {
        let (s, co) = th.sin_cos();
        Section {
            delta: [(r * co - 1.0) as f32, (r * s) as f32, (-r * s) as f32, (r * co - 1.0) as f32],
            b: [b, 0.0],
            c: [c1, c2],
        }
    })
}

fn arb_image() -> impl Strategy<Value = CoeffImage> {
    (
        1_000u32..=1_000_000,
        0u16..=MAX_LATENCY_SAMPLES,
        1u8..8,
        proptest::collection::vec(arb_section(), 0..=24),
        -5.0f32..5.0,
        proptest::collection::vec(-1.0f32..1.0, 0..=MAX_FIR),
    )
        .prop_map(|(fs, lat, mask, secs, d, fir)| {
            // Within the image's checks: pole margin, and each section's
            // gain bound (hence its DC gain) at most 2.5, so that the axis's
            // gain bound and DC gain stay below MAX_GAIN_BOUND and MAX_DC_GAIN.
            let secs: Vec<Section> = secs
                .into_iter()
                .filter(|s| s.poles_within(1.0 - MIN_POLE_MARGIN))
                .map(|mut s| {
                    let k = (2.5 / s.gain_bound()).min(1.0) as f32;
                    s.c = s.c.map(|c| c * k);
                    s
                })
                .collect();
            let filter = AxisFilter::with_fir(&secs, d, &fir).unwrap();
            let axes: Vec<usize> = (0..3).filter(|i| mask & (1 << i) != 0).collect();
            let mut img = image_with(filter, &axes, fs);
            img.latency_samples = lat;
            img
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn arbitrary_valid_images_round_trip(img in arb_image()) {
        let bytes = encode(&img);
        prop_assert_eq!(CoeffImage::parse(&bytes), Ok(img));
    }

    #[test]
    fn random_bytes_never_parse_and_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..3000)) {
        prop_assert!(CoeffImage::parse(&bytes).is_err());
        prop_assert!(CoeffImage::parse_prefix(&bytes).is_err());
    }

    #[test]
    fn random_bytes_behind_a_valid_header_never_panic(tail in proptest::collection::vec(any::<u8>(), 0..3000), keep in 0usize..64) {
        // valid magic/version/header prefix, random remainder, CRC made valid:
        // exercises the structural checks behind the CRC
        let good = encode(&full_image());
        let mut b: Vec<u8> = good[..keep.max(12)].to_vec();
        b.extend_from_slice(&tail);
        if b.len() >= 16 {
            let len = b.len() as u32;
            b[8..12].copy_from_slice(&len.to_le_bytes());
            fix_crc(&mut b);
        }
        let _ = CoeffImage::parse(&b);
        let _ = CoeffImage::parse_prefix(&b);
    }

    #[test]
    fn random_multi_byte_corruption_is_rejected(pos in 0usize..MAX_IMAGE_LEN, val in 1u8..=255, pos2 in 0usize..MAX_IMAGE_LEN) {
        let good = encode(&full_image());
        let mut b = good.clone();
        b[pos % good.len()] ^= val;
        b[pos2 % good.len()] ^= val.rotate_left(3);
        if b != good {
            prop_assert!(CoeffImage::parse(&b).is_err());
        }
    }
}
