//! The worked example of `docs/image-format.md`, checked byte for byte.
//!
//! The test builds the documented 1-axis, 1-section, 1-tap image, encodes it,
//! renders the annotated hex dump below and requires the doc to contain that
//! dump verbatim between the `BEGIN/END image_doc_example` markers. If the
//! codec's layout changes, this test fails and prints the new dump, so the
//! document cannot drift from `src/image.rs`.

use dynocomp_core::image::*;
use dynocomp_core::kernel::{AxisFilter, Section};

const DOC: &str = include_str!("../docs/image-format.md");
const BEGIN: &str = "<!-- BEGIN image_doc_example -->";
const END: &str = "<!-- END image_doc_example -->";

/// The example image of the doc.
fn example_image() -> CoeffImage {
    // Real pole z = 0.5, b = 1, c = 2 → Δ = [−0.5, 0, 0, −1], b = [1, 0], c = [2, 0].
    let section = Section::first_order(0.5, 1.0, 2.0);
    let filter = AxisFilter::with_fir(&[section], 0.25, &[0.125]).expect("valid filter");
    CoeffImage {
        fs_hz: 51_200,
        latency_samples: 2,
        flags: 0,
        method: DesignMethod::Manual,
        source_sha256: [0; 32],
        created_unix_s: 0,
        axes: [
            Some(AxisImage {
                axis: 0,
                scaling: AxisScaling {
                    adc_offset_code: 2048.0,
                    newton_per_code: 2.5,
                    dac_code_per_newton: 0.4,
                    dac_offset_code: 2048.0,
                },
                filter,
                summary: AxisSummary {
                    model_order: 2,
                    fit_nrmse: 0.0,
                    flat_lo_hz: 0.0,
                    flat_hi_hz: 0.0,
                    noise_gain: 0.0,
                    q: 0.0,
                    r: 0.0,
                },
            }),
            None,
            None,
        ],
    }
}

/// Field sizes and annotations of the example, in encoding order.
const FIELDS: &[(usize, &str)] = &[
    // --- header (64 bytes)
    (4, "magic = \"DCIM\""),
    (2, "format_version = 1"),
    (2, "header_len = 64"),
    (4, "total_len = 164"),
    (4, "fs_hz = 51200"),
    (2, "latency_samples = 2"),
    (1, "axis_mask = 0b001 (x only)"),
    (1, "flags = 0"),
    (1, "method = 0 (Manual)"),
    (3, "reserved (zero)"),
    (16, "source_sha256[0..16] (none: zeros)"),
    (16, "source_sha256[16..32]"),
    (8, "created_unix_s = 0 (unknown)"),
    // --- axis block, axis 0 (60 bytes)
    (1, "blk+00 axis = 0 (x)"),
    (1, "blk+01 n_sections = 1"),
    (1, "blk+02 n_taps = 1"),
    (1, "blk+03 reserved (zero)"),
    (2, "blk+04 model_order = 2"),
    (2, "blk+06 reserved (zero)"),
    (4, "blk+08 adc_offset_code = 2048.0"),
    (4, "blk+12 newton_per_code = 2.5"),
    (4, "blk+16 dac_code_per_newton = 0.4 (f32 0x3ecccccd)"),
    (4, "blk+20 dac_offset_code = 2048.0"),
    (4, "blk+24 d = 0.25"),
    (4, "blk+28 fit_nrmse = 0.0"),
    (4, "blk+32 flat_lo_hz = 0.0"),
    (4, "blk+36 flat_hi_hz = 0.0"),
    (4, "blk+40 noise_gain = 0.0"),
    (8, "blk+44 q = 0.0 (f64)"),
    (8, "blk+52 r = 0.0 (f64)"),
    // --- section 0 (32 bytes)
    (4, "sec0 Δ11 = -0.5 (pole 0.5)"),
    (4, "sec0 Δ12 = 0.0"),
    (4, "sec0 Δ21 = 0.0"),
    (4, "sec0 Δ22 = -1.0 (unused state)"),
    (4, "sec0 b1 = 1.0"),
    (4, "sec0 b2 = 0.0"),
    (4, "sec0 c1 = 2.0"),
    (4, "sec0 c2 = 0.0"),
    // --- FIR taps (4 bytes each)
    (4, "h1 = 0.125 (delay 1)"),
    // --- trailer
    (4, "crc32 = 0x3c98f3cb"),
];

/// Render `bytes` as `offset | hex bytes | annotation` lines.
fn annotated_dump(bytes: &[u8]) -> String {
    let mut out = String::new();
    let mut pos = 0;
    for &(len, label) in FIELDS {
        let hex: Vec<String> = bytes[pos..pos + len].iter().map(|b| format!("{b:02x}")).collect();
        out.push_str(&format!("{pos:04x} | {:<47} | {label}\n", hex.join(" ")));
        pos += len;
    }
    assert_eq!(pos, bytes.len(), "FIELDS must cover the whole image");
    out
}

/// The dump as printed in the doc (inside the fenced block between the markers).
fn dump_in_doc() -> String {
    let start = DOC.find(BEGIN).expect("doc has the BEGIN marker") + BEGIN.len();
    let end = DOC[start..].find(END).expect("doc has the END marker") + start;
    DOC[start..end]
        .lines()
        .filter(|l| !l.trim().is_empty() && !l.trim_start().starts_with("```"))
        .map(|l| format!("{}\n", l.trim_end()))
        .collect()
}

fn encode(img: &CoeffImage) -> Vec<u8> {
    let mut buf = vec![0u8; MAX_IMAGE_LEN];
    let n = img.encode(&mut buf).expect("encode");
    buf.truncate(n);
    buf
}

#[test]
fn doc_hex_dump_matches_the_encoder() {
    let bytes = encode(&example_image());
    let expected = annotated_dump(&bytes);
    let expected_trimmed: String = expected.lines().map(|l| format!("{}\n", l.trim_end())).collect();
    assert_eq!(
        dump_in_doc(),
        expected_trimmed,
        "docs/image-format.md's worked example is out of date; the encoder now produces:\n{expected}"
    );
}

#[test]
fn doc_example_sizes_and_crc() {
    let img = example_image();
    let bytes = encode(&img);
    assert_eq!(bytes.len(), 164);
    assert_eq!(bytes.len(), HEADER_LEN + AXIS_HEADER_LEN + SECTION_LEN + TAP_LEN + CRC_LEN);
    assert_eq!(bytes.len(), encoded_len(&img));
    assert_eq!(img.id(), 0x3c98_f3cb);
    // The CRC is CRC-32/ISO-HDLC over every byte before it, stored little-endian.
    let crc = CRC32.checksum(&bytes[..bytes.len() - 4]);
    assert_eq!(&bytes[bytes.len() - 4..], &crc.to_le_bytes());
    // Constants quoted by the doc.
    assert_eq!(CRC32.checksum(b"123456789"), 0xCBF4_3926);
    assert_eq!(crc::CRC_32_ISO_HDLC.poly, 0x04C1_1DB7);
    assert_eq!(crc::CRC_32_ISO_HDLC.init, 0xFFFF_FFFF);
    assert_eq!(crc::CRC_32_ISO_HDLC.xorout, 0xFFFF_FFFF);
    const { assert!(crc::CRC_32_ISO_HDLC.refin && crc::CRC_32_ISO_HDLC.refout) };
    // CRC over the whole image, CRC included, gives the fixed residue.
    assert_eq!(CRC32.checksum(&bytes), 0x2144_DF1C);
    assert_eq!(MIN_IMAGE_LEN, 128);
    assert_eq!(MAX_IMAGE_LEN, 2840);
}

#[test]
fn doc_example_round_trips_and_sits_in_an_erased_slot() {
    let img = example_image();
    let bytes = encode(&img);
    assert_eq!(CoeffImage::parse(&bytes), Ok(img));
    let mut slot = vec![0xFFu8; 8 * 1024];
    slot[..bytes.len()].copy_from_slice(&bytes);
    assert_eq!(CoeffImage::parse_prefix(&slot), Ok(img));
    assert_eq!(CoeffImage::parse_prefix(&[0xFF; 8 * 1024]), Err(ImageError::BadMagic));
}
