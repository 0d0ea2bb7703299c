//! The worked 3x3 example (format version 3) of `docs/image-format.md`
//! §13.7, checked byte for byte: the test builds the documented image,
//! encodes it, renders the annotated dump and requires the doc to hold that
//! dump verbatim between the `BEGIN/END image_doc_example_v3` markers.

use dynocomp_core::image::*;
use dynocomp_core::mimo::{MimoFilter, MimoSection};

const DOC: &str = include_str!("../docs/image-format.md");
const BEGIN: &str = "<!-- BEGIN image_doc_example_v3 -->";
const END: &str = "<!-- END image_doc_example_v3 -->";

/// The example: one diagonal section (real pole z = 0.5 on state 1, driven
/// by u_x, read by y_x and y_y), one tap on z, a direct term that makes the
/// DC gain rows x and z identity rows and row y read −0.0 of u_x at DC.
fn example_image() -> MatrixImage {
    let section = MimoSection {
        delta: [-0.5, 0.0, 0.0, -1.0],
        b: [[1.0, 0.0, 0.0], [0.0, 0.0, 0.0]],
        c: [[0.25, 0.0], [0.125, 0.0], [0.0, 0.0]],
    };
    let d = [[0.5, 0.0, 0.0], [-0.25, 1.0, 0.0], [0.0, 0.0, 0.875]];
    let h1 = [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.125]];
    let filter = MimoFilter::new(&[section], d, &[h1]).expect("valid filter");
    let scaling = AxisScaling {
        adc_offset_code: 2048.0,
        newton_per_code: 2.5,
        dac_code_per_newton: 0.4,
        dac_offset_code: 2048.0,
    };
    let summary = AxisSummary { model_order: 2, ..AxisSummary::default() };
    let ch = |axis| AxisChannel { axis, scaling, summary };
    MatrixImage {
        fs_hz: 51_200,
        latency_samples: 2,
        flags: 0,
        method: DesignMethod::Manual,
        source_sha256: [0; 32],
        created_unix_s: 0,
        axes: [ch(0), ch(1), ch(2)],
        filter,
        rows: [RowDesign::Matrix, RowDesign::Matrix, RowDesign::PerAxis],
    }
}

/// Field sizes and annotations, in encoding order.
fn fields() -> Vec<(usize, String)> {
    let mut f: Vec<(usize, String)> = [
        (4, "magic = \"DCIM\""),
        (2, "format_version = 3"),
        (2, "header_len = 64"),
        (4, "total_len = 380"),
        (4, "fs_hz = 51200"),
        (2, "latency_samples = 2"),
        (1, "axis_mask = 0b111 (required)"),
        (1, "flags = 0"),
        (1, "method = 0 (Manual)"),
        (3, "reserved (zero)"),
        (16, "source_sha256[0..16] (none: zeros)"),
        (16, "source_sha256[16..32]"),
        (8, "created_unix_s = 0 (unknown)"),
    ]
    .iter()
    .map(|&(n, s)| (n, s.to_string()))
    .collect();
    for (i, name) in ["x", "y", "z"].iter().enumerate() {
        let a = 64 + 56 * i;
        for (n, s) in [
            (1, format!("ax{i}+00 axis = {i} ({name})")),
            (3, format!("ax{i}+01 reserved (zero)")),
            (2, format!("ax{i}+04 model_order = 2")),
            (2, format!("ax{i}+06 reserved (zero)")),
            (4, format!("ax{i}+08 adc_offset_code = 2048.0")),
            (4, format!("ax{i}+12 newton_per_code = 2.5")),
            (4, format!("ax{i}+16 dac_code_per_newton = 0.4")),
            (4, format!("ax{i}+20 dac_offset_code = 2048.0")),
            (16, format!("ax{i}+24 fit_nrmse, flat_lo_hz, flat_hi_hz, noise_gain = 0.0")),
            (8, format!("ax{i}+40 q = 0.0 (f64)")),
            (8, format!("ax{i}+48 r = 0.0 (f64)")),
        ] {
            f.push((n, s));
        }
        assert_eq!(a + 56, 64 + 56 * (i + 1));
    }
    f.push((1, "flt+00 n_sections = 1".into()));
    f.push((1, "flt+01 n_taps = 1".into()));
    f.push((2, "flt+02 reserved (zero)".into()));
    f.push((12, "flt+04 d row x = [0.5, 0.0, 0.0]".into()));
    f.push((12, "flt+16 d row y = [-0.25, 1.0, 0.0]".into()));
    f.push((12, "flt+28 d row z = [0.0, 0.0, 0.875]".into()));
    f.push((16, "sec0 Δ = [-0.5, 0.0, 0.0, -1.0] (pole 0.5; state 2 unused)".into()));
    f.push((12, "sec0 b state 1 = [1.0, 0.0, 0.0] (from u_x)".into()));
    f.push((12, "sec0 b state 2 = [0.0, 0.0, 0.0]".into()));
    f.push((8, "sec0 c row x = [0.25, 0.0]".into()));
    f.push((8, "sec0 c row y = [0.125, 0.0]".into()));
    f.push((8, "sec0 c row z = [0.0, 0.0]".into()));
    f.push((12, "h1 row x = [0.0, 0.0, 0.0] (delay 1)".into()));
    f.push((12, "h1 row y = [0.0, 0.0, 0.0]".into()));
    f.push((12, "h1 row z = [0.0, 0.0, 0.125]".into()));
    f.push((4, "rows = x 3x3 (1), y 3x3 (1), z per-axis (0), reserved 0".into()));
    f.push((4, "crc32 = 0x09b9f1db".into()));
    f
}

/// `offset | hex | annotation` lines, at most 16 bytes of hex per line
/// (longer fields continue on the next line with an empty annotation).
fn annotated_dump(bytes: &[u8]) -> String {
    let mut out = String::new();
    let mut pos = 0;
    for (len, label) in fields() {
        for (k, chunk) in bytes[pos..pos + len].chunks(16).enumerate() {
            let hex: Vec<String> = chunk.iter().map(|b| format!("{b:02x}")).collect();
            let at = pos + 16 * k;
            let text = if k == 0 { label.as_str() } else { "" };
            out.push_str(format!("{at:04x} | {:<47} | {text}", hex.join(" ")).trim_end());
            out.push('\n');
        }
        pos += len;
    }
    assert_eq!(pos, bytes.len(), "the fields must cover the whole image");
    out
}

fn dump_in_doc() -> String {
    let start = DOC.find(BEGIN).expect("doc has the BEGIN marker") + BEGIN.len();
    let end = DOC[start..].find(END).expect("doc has the END marker") + start;
    DOC[start..end]
        .lines()
        .filter(|l| !l.trim().is_empty() && !l.trim_start().starts_with("```"))
        .map(|l| format!("{}\n", l.trim_end()))
        .collect()
}

fn encode(img: &MatrixImage) -> Vec<u8> {
    let mut buf = vec![0u8; MAX_MATRIX_IMAGE_LEN];
    let n = img.encode(&mut buf).expect("encode");
    buf.truncate(n);
    buf
}

#[test]
fn doc_hex_dump_matches_the_encoder() {
    let bytes = encode(&example_image());
    let expected = annotated_dump(&bytes);
    assert_eq!(
        dump_in_doc(),
        expected,
        "docs/image-format.md §13.7 is out of date; the encoder now produces:\n{expected}"
    );
}

#[test]
fn doc_example_sizes_crc_and_dc_gain() {
    let img = example_image();
    let bytes = encode(&img);
    assert_eq!(bytes.len(), 380);
    assert_eq!(bytes.len(), MIN_MATRIX_IMAGE_LEN + MIMO_SECTION_LEN + MIMO_TAP_LEN);
    assert_eq!(bytes.len(), matrix_encoded_len(&img));
    assert_eq!(MIN_MATRIX_IMAGE_LEN, 280);
    assert_eq!(MAX_MATRIX_IMAGE_LEN, 4216);
    let crc = CRC32.checksum(&bytes[..bytes.len() - 4]);
    assert_eq!(&bytes[bytes.len() - 4..], &crc.to_le_bytes());
    assert_eq!(img.id(), crc);
    assert_eq!(img.id(), 0x09b9_f1db, "update the crc32 line of fields() and the doc");
    assert_eq!(CRC32.checksum(&bytes), 0x2144_DF1C);
    // DC gain as the doc states it: rows x and z are identity rows, row y
    // reads u_x with gain −0.25 + 2·0.125 = 0 and u_y with 1.
    let dc = img.filter.dc_gain();
    assert_eq!(dc, [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]);
}

#[test]
fn doc_example_round_trips_and_sits_in_an_erased_slot() {
    let img = example_image();
    let bytes = encode(&img);
    assert_eq!(MatrixImage::parse(&bytes), Ok(img));
    let mut slot = vec![0xFFu8; 8 * 1024];
    slot[..bytes.len()].copy_from_slice(&bytes);
    assert_eq!(BoxImage::parse_prefix(&slot), Ok(BoxImage::Matrix(img)));
}
