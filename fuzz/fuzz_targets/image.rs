//! Coefficient image codec, formats 1, 2 and 3 (`src/image.rs`).
//!
//! Byte 0 of the input is a mode: bit 0 set = repair the trailing CRC-32
//! before parsing (so mutations get past the envelope to the semantic
//! checks), bit 1 set = parse as format 2 (parallel) first, bit 2 set =
//! parse as format 3 (3x3) first. The rest is the image; every parser sees
//! it, and `BoxImage::parse` must agree with the one its version selects.
//!
//! Checks: never panics; the host's reader (`io::image_file::parse_any_image`)
//! agrees with the version's parser and its error names the file and a
//! place (`assert_names_place_or`); an accepted image validates and re-encodes to the
//! very same bytes (encode → parse → encode); `parse_prefix` of the image
//! followed by junk gives the same image; a rejected image's error is true of
//! the bytes (the field it names holds what it says, axis/section/tap/band
//! indices are in range) and no semantic error is reported for bytes whose
//! CRC does not match; an accepted image's filters keep their output within
//! their gain bound for inputs within ±1.
#![no_main]

use dynocomp::io::image_file::{parse_any_image, AnyImage};
use dynocomp_core::image::*;
use dynocomp_core::kernel::{MAX_FIR, MAX_SECTIONS};
use dynocomp_core::mimo::{MimoState, MAX_MIMO_FIR, MAX_MIMO_SECTIONS};
use dynocomp_fuzz::assert_names_place_or;
use libfuzzer_sys::fuzz_target;

/// The name the host's reader is given for the input.
const SOURCE: &str = "fuzz.dcimg";

/// What an image error names instead of a line or column: the header field
/// (magic, format version, length, CRC, sample rate, latency, axis mask,
/// flags, method), the axis, band, row, section or tap, or the whole image
/// (truncated).
const IMAGE_PLACES: &[&str] = &[
    "truncated",
    "magic",
    "format version",
    "length",
    "crc",
    "sample rate",
    "latency",
    "axis mask",
    "flag",
    "method",
    "axis ",
    "band",
    "row ",
    "section",
    "tap",
    "direct term",
];

/// The host's reader (`inspect`, `compensate`) takes what the version's own
/// parser takes, and its one-line error names the file and a place.
fn check_host(bytes: &[u8]) {
    let own = match peek_version(bytes) {
        Some(PARALLEL_FORMAT_VERSION) => ParallelImage::parse(bytes).map(|p| p.id()),
        Some(MATRIX_FORMAT_VERSION) => MatrixImage::parse(bytes).map(|m| m.id()),
        _ => CoeffImage::parse(bytes).map(|i| i.id()),
    };
    match parse_any_image(bytes, SOURCE) {
        Ok(img) => {
            assert_eq!(own, Ok(img.id()), "the host's reader and the version's parser disagree");
            let expected = match img {
                AnyImage::Inline(_) => FORMAT_VERSION,
                AnyImage::Parallel(_) => PARALLEL_FORMAT_VERSION,
                AnyImage::Matrix(_) => MATRIX_FORMAT_VERSION,
            };
            assert_eq!(peek_version(bytes), Some(expected));
        }
        Err(e) => {
            assert!(own.is_err(), "the host's reader refused an image its version's parser takes: {e:#}");
            assert_names_place_or(&format!("{e:#}"), SOURCE, IMAGE_PLACES);
        }
    }
}

fn le16(b: &[u8], at: usize) -> Option<u16> {
    Some(u16::from_le_bytes(b.get(at..at + 2)?.try_into().ok()?))
}
fn le32(b: &[u8], at: usize) -> Option<u32> {
    Some(u32::from_le_bytes(b.get(at..at + 4)?.try_into().ok()?))
}

/// The error `e` from parsing `bytes` as format `version` is true of them.
fn check_error(e: ImageError, bytes: &[u8], version: u16) {
    use ImageError::*;
    let len = bytes.len();
    let crc_ok = len >= CRC_LEN && le32(bytes, len - CRC_LEN) == Some(CRC32.checksum(&bytes[..len - CRC_LEN]));
    match e {
        Truncated { needed, have } => {
            assert_eq!(have as usize, len);
            assert!(needed as usize > len);
            return;
        }
        BadMagic => {
            assert_ne!(bytes.get(..4), Some(&MAGIC[..]));
            return;
        }
        UnsupportedVersion(v) => {
            assert_eq!(le16(bytes, 4), Some(v));
            assert_ne!(v, version);
            // Formats 2 and 3 are named as such.
            assert!(v != PARALLEL_FORMAT_VERSION && v != MATRIX_FORMAT_VERSION);
            return;
        }
        ParallelOfflineOnly => {
            assert_ne!(version, PARALLEL_FORMAT_VERSION);
            assert_eq!(le16(bytes, 4), Some(PARALLEL_FORMAT_VERSION));
            return;
        }
        NotPerAxisImage => {
            assert_ne!(version, MATRIX_FORMAT_VERSION);
            assert_eq!(le16(bytes, 4), Some(MATRIX_FORMAT_VERSION));
            return;
        }
        BadHeaderLength(l) => {
            assert_eq!(le16(bytes, 6), Some(l));
            assert_ne!(usize::from(l), HEADER_LEN);
            return;
        }
        BadLength(_) => return,
        BadCrc { stored, computed } => {
            assert_ne!(stored, computed);
            assert_eq!(le32(bytes, len - CRC_LEN), Some(stored));
            assert_eq!(CRC32.checksum(&bytes[..len - CRC_LEN]), computed);
            return;
        }
        BufferTooSmall { .. } => panic!("parse reported an encoder error: {e}"),
        TooManyTaps { axis, .. } | BadScaling { axis } | BadSummary { axis } => {
            assert!(usize::from(axis) < dynocomp_core::AXES)
        }
        NonFiniteTap { axis, tap } => assert!(usize::from(axis) < dynocomp_core::AXES && usize::from(tap) < MAX_FIR),
        TooManySections { axis, count } => {
            assert!(usize::from(axis) < dynocomp_core::AXES && usize::from(count) > MAX_SECTIONS)
        }
        NonFiniteCoefficient { axis, section }
        | UnstableSection { axis, section }
        | NotModalSection { axis, section } => {
            assert!(usize::from(axis) < dynocomp_core::AXES);
            assert!(usize::from(section) < MAX_SECTIONS || section == 255, "section index {section} out of range");
        }
        CoefficientOutOfRange { axis, section } | PoleMarginTooSmall { axis, section } => {
            assert!(usize::from(axis) < dynocomp_core::AXES);
            assert!(usize::from(section) < MAX_SECTIONS || section == 255, "section index {section} out of range");
        }
        TapOutOfRange { axis, tap } => assert!(usize::from(axis) < dynocomp_core::AXES && usize::from(tap) < MAX_FIR),
        GainBoundTooLarge { axis, bound } => {
            assert!(usize::from(axis) < dynocomp_core::AXES);
            assert!(f64::from(bound) >= MAX_GAIN_BOUND.floor(), "gain bound {bound} reported within the limit");
        }
        DcGainOutOfRange { axis } => assert!(usize::from(axis) < dynocomp_core::AXES),
        AxisMismatch { expected, .. } => assert!(usize::from(expected) < dynocomp_core::AXES),
        BadBandCount(n) => assert!(n == 0 || usize::from(n) > MAX_BANDS),
        BadBand { band } | BandAxesDiffer { band } => {
            assert_eq!(version, PARALLEL_FORMAT_VERSION);
            assert!(usize::from(band) < MAX_BANDS && band < bytes[21]);
        }
        SampleRateOutOfRange(fs) => assert!(!FS_RANGE_HZ.contains(&fs)),
        LatencyOutOfRange(l) => assert!(l > MAX_LATENCY_SAMPLES),
        BadAxisMask(_) | UnknownFlags(_) | UnknownMethod(_) | ReservedNotZero | ParallelNotOfflineOnly => {}
        BadRowDesign { row, code } => assert!(usize::from(row) < 3 && code > 1),
        MatrixTooManySections(n) => assert!(usize::from(n) > MAX_MIMO_SECTIONS),
        MatrixTooManyTaps(n) => assert!(usize::from(n) > MAX_MIMO_FIR),
        MatrixNonFinite { section } | MatrixCoefficientOutOfRange { section } => {
            assert!(usize::from(section) < MAX_MIMO_SECTIONS || section == 255, "section index {section} out of range");
        }
        MatrixUnstableSection { section }
        | MatrixNotModalSection { section }
        | MatrixPoleMarginTooSmall { section } => {
            assert!(usize::from(section) < MAX_MIMO_SECTIONS, "section index {section} out of range");
        }
        MatrixNonFiniteTap { tap } | MatrixTapOutOfRange { tap } => assert!(usize::from(tap) < MAX_MIMO_FIR),
        MatrixGainBoundTooLarge { row, bound } => {
            assert!(usize::from(row) < 3);
            assert!(f64::from(bound) >= MAX_GAIN_BOUND.floor(), "row gain bound {bound} reported within the limit");
        }
        MatrixDcGainOutOfRange { row } => assert!(usize::from(row) < 3),
    }
    if matches!(
        e,
        BadRowDesign { .. }
            | MatrixTooManySections(_)
            | MatrixTooManyTaps(_)
            | MatrixNonFinite { .. }
            | MatrixNonFiniteTap { .. }
            | MatrixUnstableSection { .. }
            | MatrixNotModalSection { .. }
            | MatrixCoefficientOutOfRange { .. }
            | MatrixTapOutOfRange { .. }
            | MatrixPoleMarginTooSmall { .. }
            | MatrixGainBoundTooLarge { .. }
            | MatrixDcGainOutOfRange { .. }
    ) {
        assert_eq!(version, MATRIX_FORMAT_VERSION, "3x3 error {e} from the format-{version} parser");
    }
    // Everything below the envelope is only checked once the CRC matched.
    assert!(crc_ok, "semantic error {e} reported for bytes whose CRC does not match");
}

/// Samples of the bounded-output check of an accepted image.
const RUN: usize = 512;

/// An accepted axis filter keeps its promise: for inputs with |u| ≤ 1 (a
/// pattern of ±1 and 0 taken from the fuzz input) the f32 kernel's output
/// stays within the filter's gain bound, itself within MAX_GAIN_BOUND, and
/// the DC gain within MAX_DC_GAIN.
fn check_bounded(img: &CoeffImage, pattern: &[u8]) {
    for a in img.axes.iter().flatten() {
        let bound = a.filter.gain_bound();
        assert!(bound <= MAX_GAIN_BOUND, "accepted axis {} with gain bound {bound}", a.axis);
        assert!(a.filter.dc_gain().abs() <= MAX_DC_GAIN);
        let mut st = dynocomp_core::kernel::AxisState::default();
        for k in 0..RUN {
            let u = match pattern.get(k % pattern.len().max(1)).map_or(1, |b| b % 3) {
                0 => -1.0,
                1 => 1.0,
                _ => 0.0,
            };
            let y = f64::from(a.filter.step(&mut st, u));
            assert!(y.abs() <= bound * (1.0 + 1e-4) + 1e-6, "axis {}: |y| = {y} beyond the gain bound {bound}", a.axis);
        }
    }
}

fn check_v1(bytes: &[u8]) {
    match CoeffImage::parse(bytes) {
        Ok(img) => {
            check_bounded(&img, bytes);
            let mut buf = vec![0u8; MAX_IMAGE_LEN];
            let n = img.encode(&mut buf).expect("an accepted image validates and encodes");
            assert_eq!(&buf[..n], bytes, "encode(parse(bytes)) != bytes");
            assert_eq!(encoded_len(&img), n);
            assert_eq!(CoeffImage::parse(&buf[..n]), Ok(img));
            let mut region = bytes.to_vec();
            region.extend_from_slice(&[0xA5; 37]);
            assert_eq!(CoeffImage::parse_prefix(&region), Ok(img), "parse_prefix with trailing junk");
        }
        Err(e) => {
            check_error(e, bytes, FORMAT_VERSION);
            // parse_prefix never accepts what parse of the declared prefix refuses.
            if let Some(n) = declared_len(bytes).filter(|&n| n <= bytes.len()) {
                if let Ok(img) = CoeffImage::parse_prefix(bytes) {
                    assert_eq!(CoeffImage::parse(&bytes[..n]), Ok(img));
                }
            }
        }
    }
}

fn check_v2(bytes: &[u8]) {
    match ParallelImage::parse(bytes) {
        Ok(img) => {
            assert!(img.flags & FLAG_OFFLINE_ONLY != 0, "an accepted parallel image is offline only");
            let mut buf = vec![0u8; MAX_PARALLEL_IMAGE_LEN];
            let n = img.encode(&mut buf).expect("an accepted parallel image validates and encodes");
            assert_eq!(&buf[..n], bytes, "encode(parse(bytes)) != bytes (format 2)");
            assert_eq!(parallel_encoded_len(&img), n);
            for k in 0..img.bands().len() {
                assert!(img.band_image(k).is_some());
            }
            assert!(img.band_image(img.bands().len()).is_none());
            // The box's parser refuses it from the version field alone.
            assert_eq!(CoeffImage::parse(bytes), Err(ImageError::ParallelOfflineOnly));
        }
        Err(e) => check_error(e, bytes, PARALLEL_FORMAT_VERSION),
    }
}

/// An accepted 3x3 filter keeps its promises: each output row within its
/// gain bound for inputs with |u_j| ≤ 1 (a ±1/0 pattern per input), each
/// bound within MAX_GAIN_BOUND, each DC row within MAX_DC_ROW_DEVIATION of
/// the identity row.
fn check_matrix_bounded(img: &MatrixImage, pattern: &[u8]) {
    let f = &img.filter;
    let bounds: [f64; 3] = core::array::from_fn(|i| f.row_gain_bound(i));
    for (i, b) in bounds.iter().enumerate() {
        assert!(*b <= MAX_GAIN_BOUND, "accepted row {i} with gain bound {b}");
        let dev: f64 = f.dc_gain()[i].iter().enumerate().map(|(j, v)| (v - if i == j { 1.0 } else { 0.0 }).abs()).sum();
        assert!(dev <= MAX_DC_ROW_DEVIATION, "accepted row {i} with DC deviation {dev}");
    }
    let mut st = MimoState::default();
    let n = pattern.len().max(1);
    for k in 0..RUN {
        let u: [f32; 3] = core::array::from_fn(|j| match pattern.get((3 * k + j) % n).map_or(1, |b| b % 3) {
            0 => -1.0,
            1 => 1.0,
            _ => 0.0,
        });
        let y = f.step(&mut st, u);
        for i in 0..3 {
            let v = f64::from(y[i]);
            assert!(
                v.abs() <= bounds[i] * (1.0 + 1e-4) + 1e-6,
                "row {i}: |y| = {v} beyond the gain bound {}",
                bounds[i]
            );
        }
    }
}

fn check_v3(bytes: &[u8]) {
    match MatrixImage::parse(bytes) {
        Ok(img) => {
            check_matrix_bounded(&img, bytes);
            let mut buf = vec![0u8; MAX_MATRIX_IMAGE_LEN];
            let n = img.encode(&mut buf).expect("an accepted 3x3 image validates and encodes");
            assert_eq!(&buf[..n], bytes, "encode(parse(bytes)) != bytes (format 3)");
            assert_eq!(matrix_encoded_len(&img), n);
            assert_eq!(BoxImage::parse(bytes), Ok(BoxImage::Matrix(img)));
            assert_eq!(CoeffImage::parse(bytes), Err(ImageError::NotPerAxisImage));
            let mut region = bytes.to_vec();
            region.extend_from_slice(&[0xA5; 37]);
            assert_eq!(BoxImage::parse_prefix(&region), Ok(BoxImage::Matrix(img)), "parse_prefix with trailing junk");
        }
        Err(e) => {
            check_error(e, bytes, MATRIX_FORMAT_VERSION);
            if let Some(n) = declared_len(bytes).filter(|&n| n <= bytes.len()) {
                if let Ok(img) = MatrixImage::parse_prefix(bytes) {
                    assert_eq!(MatrixImage::parse(&bytes[..n]), Ok(img));
                }
            }
        }
    }
    // The box's reader agrees with the parser the version selects.
    match BoxImage::parse(bytes) {
        Ok(BoxImage::Matrix(m)) => assert_eq!(MatrixImage::parse(bytes), Ok(m)),
        Ok(BoxImage::PerAxis(i)) => assert_eq!(CoeffImage::parse(bytes), Ok(i)),
        Err(e) if peek_version(bytes) == Some(MATRIX_FORMAT_VERSION) => assert_eq!(MatrixImage::parse(bytes), Err(e)),
        Err(e) => assert_eq!(CoeffImage::parse(bytes), Err(e)),
    }
}

fuzz_target!(|data: &[u8]| {
    let Some((&mode, rest)) = data.split_first() else { return };
    let mut bytes = rest.to_vec();
    if mode & 1 == 1 && bytes.len() >= CRC_LEN {
        let n = bytes.len() - CRC_LEN;
        let crc = CRC32.checksum(&bytes[..n]);
        bytes[n..].copy_from_slice(&crc.to_le_bytes());
    }
    if mode & 4 == 4 {
        check_v3(&bytes);
    }
    if mode & 2 == 2 {
        check_v2(&bytes);
        check_v1(&bytes);
    } else {
        check_v1(&bytes);
        check_v2(&bytes);
    }
    if mode & 4 == 0 {
        check_v3(&bytes);
    }
    check_host(&bytes);
});
