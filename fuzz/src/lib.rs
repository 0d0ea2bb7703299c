//! Shared checks of the fuzz targets (docs/fuzzing.md).
//!
//! A target for a new reader is a few lines: parse the bytes, on success
//! round-trip through the writer if there is one, on failure call
//! [`assert_names_place`] with the name the reader was given.

use dynocomp_core::image::CoeffImage;

/// A coefficient image the project's `design` wrote for the bundled example
/// (`images/example.dcimg`): the valid image the handler, store and
/// sidecar targets start from.
pub const EXAMPLE_IMAGE: &[u8] = include_bytes!("../images/example.dcimg");

/// The project's images (`images/`): two per-axis box images written by
/// `dynocomp design` on the bundled example (latency 4 and 0), one
/// parallel, offline-only image (format 2), and two 3x3 images (format 3):
/// the worked example of docs/image-format.md §13.7 (runs in the box) and
/// the realistic filter of tests/image_matrix.rs (see [`box_runnable`]),
/// for the targets that upload or store them.
pub const IMAGES: [&[u8]; 5] = [
    EXAMPLE_IMAGE,
    include_bytes!("../images/lat0.dcimg"),
    include_bytes!("../images/parallel.dcimg"),
    include_bytes!("../images/matrix_doc.dcimg"),
    include_bytes!("../images/matrix.dcimg"),
];

/// Whether the box runs a valid image: not offline-only, its sample rate
/// in the box's range, its predicted load within the box's limit
/// (docs/image-format.md §13.6, docs/store.md).
pub fn box_runnable(img: &dynocomp_core::image::BoxImage) -> bool {
    use dynocomp_core::budget::{check_load, BOX_LOAD_LIMIT_PERMILLE};
    !img.is_offline_only()
        && dynocomp_core::sample::BOX_FS_RANGE_HZ.contains(&img.fs_hz())
        && check_load(img, BOX_LOAD_LIMIT_PERMILLE).is_ok()
}

/// The parsed [`EXAMPLE_IMAGE`].
pub fn example_image() -> CoeffImage {
    CoeffImage::parse(EXAMPLE_IMAGE).expect("the example seed image parses")
}

/// Words that name a place inside an input.
const PLACE_WORDS: &[&str] = &["line ", "column ", "record ", "dataset", "offset", "byte ", "field", "header", "value"];

/// Phrases of errors about the input as a whole (the file is the place).
const WHOLE_INPUT: &[&str] =
    &["empty file", "no data rows", "no samples", "no uff dataset", "no frf", "no force column"];

/// The error of a rejected input names the input (`source`, first) and a
/// place in it: a line/column/record/offset/field, or it is an error about
/// the whole file. `msg` is the full context chain (`{:#}`).
pub fn assert_names_place(msg: &str, source: &str) {
    assert_names_place_or(msg, source, &[]);
}

/// [`assert_names_place`], with more words that name a place in this
/// format (e.g. a JSON field).
pub fn assert_names_place_or(msg: &str, source: &str, more: &[&str]) {
    assert!(msg.starts_with(&format!("{source}:")), "error does not start with the input's name `{source}`: {msg}");
    let lower = msg.to_ascii_lowercase();
    assert!(
        PLACE_WORDS.iter().chain(WHOLE_INPUT).chain(more).any(|w| lower.contains(w)),
        "error names no place (line/column/record/offset/field) in `{source}`: {msg}"
    );
    assert!(!msg.contains('\n'), "error is not one line: {msg}");
}

/// A per-process scratch path under /dev/shm (RAM) for readers and writers
/// that only take paths.
pub fn scratch_path(name: &str) -> std::path::PathBuf {
    let dir = if std::path::Path::new("/dev/shm").is_dir() { "/dev/shm".into() } else { std::env::temp_dir() };
    dir.join(format!("dynocomp-fuzz-{}-{name}", std::process::id()))
}
