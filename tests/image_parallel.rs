//! Parallel-elaboration images (format version 2, offline only): round trip,
//! byte layout, refusal by the box's parser and mode selection, and
//! rejection of every corruption (fuzzed).

mod common;
use common::*;
use dynocomp_core::image::*;
use dynocomp_core::kernel::{AxisFilter, Section, MAX_FIR};
use dynocomp_core::sample::{process_sample, select_mode, BypassReason, Mode, SampleFlags, SampleState};
use proptest::prelude::*;

fn band(lo: f32, hi: f32, filter: AxisFilter, axes: &[usize]) -> BandImage {
    let img = image_with(filter, axes, 51_200);
    BandImage { lo_hz: lo, hi_hz: hi, axes: img.axes }
}

/// Three bands on x and z with different filters (a gain, 24 sections, 24
/// sections + FIR taps).
fn parallel() -> ParallelImage {
    let (blocks, d) = filter_24(51_200.0);
    let secs: Vec<Section> = blocks.iter().map(to_section).collect();
    let fir: Vec<f32> = (0..MAX_FIR).map(|j| 0.1 / (j as f32 + 1.0)).collect();
    let bands = [
        band(900.0, 1300.0, AxisFilter::gain(1.5).unwrap(), &[0, 2]),
        band(2000.0, 2600.0, kernel_filter(&blocks, d), &[0, 2]),
        band(3100.0, 3900.0, AxisFilter::with_fir(&secs, d as f32, &fir).unwrap(), &[0, 2]),
    ];
    ParallelImage::new(51_200, 4, DesignMethod::VectorFitting, [7; 32], 1_790_000_000, &bands).unwrap()
}

// The largest parallel image is larger than a flash slot (files only), and
// the box-runnable maximum still fits one.
const _: () = assert!(MAX_PARALLEL_IMAGE_LEN > 8 * 1024 && MAX_IMAGE_LEN <= 8 * 1024);

fn encode(img: &ParallelImage) -> Vec<u8> {
    let mut buf = vec![0u8; MAX_PARALLEL_IMAGE_LEN];
    let n = img.encode(&mut buf).expect("encode");
    buf.truncate(n);
    buf
}

#[test]
fn round_trip_and_layout() {
    let img = parallel();
    let bytes = encode(&img);
    assert_eq!(bytes.len(), parallel_encoded_len(&img));
    // header: magic, version 2, header_len 64, total_len, mask 0b101,
    // flags = offline only, n_bands in byte 21
    assert_eq!(&bytes[..4], b"DCIM");
    assert_eq!(u16::from_le_bytes([bytes[4], bytes[5]]), 2);
    assert_eq!(u16::from_le_bytes([bytes[6], bytes[7]]), 64);
    assert_eq!(u32::from_le_bytes(bytes[8..12].try_into().unwrap()) as usize, bytes.len());
    assert_eq!(bytes[18], 0b101);
    assert_eq!(bytes[19], FLAG_OFFLINE_ONLY);
    assert_eq!(bytes[21], 3);
    assert_eq!(&bytes[22..24], &[0, 0]);
    // band table right after the header, then the axis blocks band by band
    let edges: Vec<f32> = bytes[64..64 + 24].chunks(4).map(|c| f32::from_le_bytes(c.try_into().unwrap())).collect();
    assert_eq!(edges, [900.0, 1300.0, 2000.0, 2600.0, 3100.0, 3900.0]);
    assert_eq!(bytes[88], 0, "band 0 starts with the x axis block");
    assert_eq!(bytes[88 + AXIS_HEADER_LEN], 2, "band 0, axis z follows x (no sections, no taps)");
    let expected_len = HEADER_LEN
        + 3 * BAND_RECORD_LEN
        + 2 * AXIS_HEADER_LEN
        + 2 * (AXIS_HEADER_LEN + 24 * SECTION_LEN)
        + 2 * (AXIS_HEADER_LEN + 24 * SECTION_LEN + MAX_FIR * TAP_LEN)
        + CRC_LEN;
    assert_eq!(bytes.len(), expected_len);
    assert_eq!(CRC32.checksum(&bytes), 0x2144_DF1C, "CRC residue of a valid image");
    let back = ParallelImage::parse(&bytes).unwrap();
    assert_eq!(back, img);
    assert_eq!(back.bands().len(), 3);
    assert_eq!(back.id(), u32::from_le_bytes(bytes[bytes.len() - 4..].try_into().unwrap()));
    let b2 = back.band_image(2).unwrap();
    assert!(b2.is_offline_only());
    assert_eq!(b2.axes, img.bands()[2].axes);
    assert!(back.band_image(3).is_none());
}

#[test]
fn the_box_never_runs_a_parallel_image() {
    let bytes = encode(&parallel());
    // a version-1 reader refuses it by name
    assert_eq!(CoeffImage::parse(&bytes), Err(ImageError::ParallelOfflineOnly));
    // in a flash slot (whole, or only its first part: a large parallel image
    // does not fit a slot) the box refuses it before reading its length
    let mut slot = vec![0xFFu8; 8192];
    let n = bytes.len().min(slot.len());
    slot[..n].copy_from_slice(&bytes[..n]);
    let loaded = CoeffImage::parse_prefix(&slot);
    assert_eq!(loaded, Err(ImageError::ParallelOfflineOnly));
    assert_eq!(CoeffImage::parse_prefix(&bytes[..200]), Err(ImageError::ParallelOfflineOnly));
    let loaded = loaded.map(dynocomp_core::image::BoxImage::from);
    let mode = select_mode(Some(&loaded), false);
    assert!(matches!(mode, Mode::Bypass(BypassReason::OfflineOnly)), "{mode:?}");
    let mut st = SampleState::default();
    let (dac, flags) = process_sample([1000, 2000, 3000], mode, &mut st);
    assert_eq!(dac, [1000, 2000, 3000], "bypass: raw codes out");
    assert!(flags.has(SampleFlags::BYPASS));
    // nor does the coefficient store's slot verification (used at boot and
    // before an upload is committed) accept it
    let crc = dynocomp_core::image::CRC32.checksum(&bytes);
    assert_eq!(
        dynocomp_core::store::verify_image(&bytes, crc).err(),
        Some(dynocomp_core::protocol::LinkError::Image(ImageError::ParallelOfflineOnly))
    );
    // and a version-1 image is not a parallel image
    let v1 = image_with(AxisFilter::gain(1.0).unwrap(), &[0], 51_200);
    let mut buf = vec![0u8; MAX_IMAGE_LEN];
    let n = v1.encode(&mut buf).unwrap();
    assert_eq!(ParallelImage::parse(&buf[..n]), Err(ImageError::UnsupportedVersion(1)));
}

#[test]
fn invalid_parallel_images_are_refused() {
    let g = AxisFilter::gain(1.0).unwrap();
    let mk = |bands: &[BandImage]| ParallelImage::new(51_200, 0, DesignMethod::Manual, [0; 32], 0, bands);
    assert_eq!(mk(&[]), Err(ImageError::BadBandCount(0)));
    let nine: Vec<BandImage> = (0..9).map(|k| band(100.0 * k as f32, 100.0 * k as f32 + 50.0, g, &[0])).collect();
    assert_eq!(mk(&nine), Err(ImageError::BadBandCount(9)));
    assert!(mk(&nine[..8]).is_ok());
    // overlapping, reversed, empty, above Nyquist, non-finite
    assert_eq!(mk(&[band(100.0, 300.0, g, &[0]), band(250.0, 400.0, g, &[0])]), Err(ImageError::BadBand { band: 1 }));
    assert_eq!(mk(&[band(300.0, 100.0, g, &[0])]), Err(ImageError::BadBand { band: 0 }));
    assert_eq!(mk(&[band(300.0, 300.0, g, &[0])]), Err(ImageError::BadBand { band: 0 }));
    assert_eq!(mk(&[band(300.0, 25_601.0, g, &[0])]), Err(ImageError::BadBand { band: 0 }));
    assert_eq!(mk(&[band(f32::NAN, 300.0, g, &[0])]), Err(ImageError::BadBand { band: 0 }));
    assert_eq!(mk(&[band(-1.0, 300.0, g, &[0])]), Err(ImageError::BadBand { band: 0 }));
    // touching bands are fine; different axes per band are not
    assert!(mk(&[band(100.0, 300.0, g, &[0]), band(300.0, 400.0, g, &[0])]).is_ok());
    assert_eq!(
        mk(&[band(100.0, 300.0, g, &[0]), band(300.0, 400.0, g, &[0, 1])]),
        Err(ImageError::BandAxesDiffer { band: 1 })
    );

    // behind a valid CRC: flag cleared, band count 0 / 9, reserved byte set
    let bytes = encode(&parallel());
    let edit = |i: usize, v: u8| {
        let mut b = bytes.clone();
        b[i] = v;
        fix_crc(&mut b);
        ParallelImage::parse(&b)
    };
    assert_eq!(edit(19, 0), Err(ImageError::ParallelNotOfflineOnly));
    assert_eq!(edit(21, 0), Err(ImageError::BadBandCount(0)));
    assert_eq!(edit(21, 9), Err(ImageError::BadBandCount(9)));
    assert_eq!(edit(22, 1), Err(ImageError::ReservedNotZero));
    // a band count that disagrees with the contents: the band table and the
    // axis blocks no longer line up (here band 2's edges read as an axis block)
    assert_eq!(edit(21, 2), Err(ImageError::TooManySections { axis: 0, count: 192 }));
    assert_eq!(edit(21, 4), Err(ImageError::ReservedNotZero));
    // band 1's lower edge below band 0's upper edge
    let mut b = bytes.clone();
    b[72..76].copy_from_slice(&1000f32.to_le_bytes());
    fix_crc(&mut b);
    assert_eq!(ParallelImage::parse(&b), Err(ImageError::BadBand { band: 1 }));
}

#[test]
fn every_single_bit_flip_and_truncation_is_rejected() {
    let bytes = encode(&parallel());
    let mut flipped = bytes.clone();
    for i in 0..bytes.len() * 8 {
        flipped[i / 8] ^= 1 << (i % 8);
        assert!(ParallelImage::parse(&flipped).is_err(), "bit {i} flipped was accepted");
        assert!(CoeffImage::parse_prefix(&flipped).is_err(), "bit {i}: the box accepted a parallel image");
        flipped[i / 8] ^= 1 << (i % 8);
    }
    for n in 0..bytes.len() {
        assert!(ParallelImage::parse(&bytes[..n]).is_err(), "truncated to {n} accepted");
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn random_bytes_never_parse_and_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..6000)) {
        prop_assert!(ParallelImage::parse(&bytes).is_err());
    }

    #[test]
    fn random_bytes_behind_a_valid_parallel_header_never_panic(tail in proptest::collection::vec(any::<u8>(), 0..6000), keep in 12usize..120, n_bands in 0u8..12) {
        // valid v2 header prefix, random remainder, length and CRC made valid:
        // exercises the band table and axis blocks behind the CRC
        let good = encode(&parallel());
        let mut b: Vec<u8> = good[..keep].to_vec();
        b.extend_from_slice(&tail);
        if b.len() >= 24 {
            b[21] = n_bands;
            let len = b.len() as u32;
            b[8..12].copy_from_slice(&len.to_le_bytes());
            fix_crc(&mut b);
        }
        let _ = ParallelImage::parse(&b);
        prop_assert!(CoeffImage::parse(&b).is_err());
        prop_assert!(CoeffImage::parse_prefix(&b).is_err());
    }

    #[test]
    fn random_multi_byte_corruption_is_rejected(pos in 0usize..MAX_PARALLEL_IMAGE_LEN, val in 1u8..=255, pos2 in 0usize..MAX_PARALLEL_IMAGE_LEN) {
        let good = encode(&parallel());
        let mut b = good.clone();
        b[pos % good.len()] ^= val;
        b[pos2 % good.len()] ^= val.rotate_left(3);
        if b != good {
            prop_assert!(ParallelImage::parse(&b).is_err());
        }
    }

    #[test]
    fn arbitrary_band_sets_round_trip(edges in proptest::collection::vec(1.0f32..25_000.0, 2..=16), gains in proptest::collection::vec(-5.0f32..5.0, 8)) {
        let mut e = edges.clone();
        e.sort_by(f32::total_cmp);
        e.dedup();
        let bands: Vec<BandImage> = e.chunks_exact(2)
            .filter(|c| c[1] > c[0])
            .zip(&gains)
            .map(|(c, g)| band(c[0], c[1], AxisFilter::gain(*g).unwrap(), &[1]))
            .collect();
        prop_assume!(!bands.is_empty());
        let img = ParallelImage::new(51_200, 2, DesignMethod::Paper, [1; 32], 5, &bands).unwrap();
        prop_assert_eq!(ParallelImage::parse(&encode(&img)), Ok(img));
    }
}
