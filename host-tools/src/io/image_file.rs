//! Coefficient image files (`.dcimg`): the core codec plus file handling.
//! Formats 1 (per axis) and 3 (3x3) are what the box runs; format 2
//! (parallel elaboration) is offline only. [`read_any_image`] reads all three.

use anyhow::{Context, Result};
use dynocomp_core::image::{
    peek_version, CoeffImage, ImageError, MatrixImage, ParallelImage, MATRIX_FORMAT_VERSION, MAX_IMAGE_LEN,
    MAX_MATRIX_IMAGE_LEN, MAX_PARALLEL_IMAGE_LEN, PARALLEL_FORMAT_VERSION,
};
use std::path::Path;

use crate::io::atomic::write_bytes_atomic;

/// Read and validate a coefficient image file.
pub fn read_image(path: &Path) -> Result<CoeffImage> {
    let bytes = std::fs::read(path).with_context(|| format!("{}: cannot read", path.display()))?;
    CoeffImage::parse(&bytes).map_err(|e| anyhow::anyhow!("{}: invalid coefficient image: {e}", path.display()))
}

/// Encode an image to bytes.
pub fn encode_image(image: &CoeffImage) -> Result<Vec<u8>> {
    let mut buf = vec![0u8; MAX_IMAGE_LEN];
    let n = image.encode(&mut buf).map_err(|e| anyhow::anyhow!("cannot encode image: {e}"))?;
    buf.truncate(n);
    Ok(buf)
}

/// Encode and write an image atomically, then read it back and check that it
/// decodes to the same value (the file on disk is what the box will get).
pub fn write_image(path: &Path, image: &CoeffImage) -> Result<()> {
    write_bytes_atomic(path, &encode_image_checked(path, image)?)
}

/// The bytes of `image` (to be written at `path`), checked to decode to the
/// same value.
pub fn encode_image_checked(path: &Path, image: &CoeffImage) -> Result<Vec<u8>> {
    let bytes = encode_image(image)?;
    let back = CoeffImage::parse(&bytes)
        .map_err(|e| anyhow::anyhow!("{}: encoded image does not parse: {e}", path.display()))?;
    anyhow::ensure!(back == *image, "{}: encoded image does not decode to the design", path.display());
    Ok(bytes)
}

/// Any coefficient image file: a per-axis box image (format 1), a
/// parallel-elaboration image (format 2, offline only) or a 3x3 box image
/// (format 3).
// One value per command run: the size difference of the variants (a box
// image is ~2.7 KiB) does not matter.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Debug)]
pub enum AnyImage {
    /// One compensator per axis (what the box runs).
    Inline(CoeffImage),
    /// One compensator per band and axis; offline only (paper §3.3).
    Parallel(Box<ParallelImage>),
    /// One 3x3 compensator for the three axes (crosstalk compensated).
    Matrix(Box<MatrixImage>),
}

impl AnyImage {
    /// The image id (its CRC-32).
    pub fn id(&self) -> u32 {
        match self {
            AnyImage::Inline(i) => i.id(),
            AnyImage::Parallel(p) => p.id(),
            AnyImage::Matrix(m) => m.id(),
        }
    }

    /// Sample rate (Hz).
    pub fn fs_hz(&self) -> u32 {
        match self {
            AnyImage::Inline(i) => i.fs_hz,
            AnyImage::Parallel(p) => p.fs_hz,
            AnyImage::Matrix(m) => m.fs_hz,
        }
    }

    /// Source FRF hash.
    pub fn source_sha256(&self) -> [u8; 32] {
        match self {
            AnyImage::Inline(i) => i.source_sha256,
            AnyImage::Parallel(p) => p.source_sha256,
            AnyImage::Matrix(m) => m.source_sha256,
        }
    }
}

/// Read and validate an image file of any format (chosen by its version
/// field).
pub fn read_any_image(path: &Path) -> Result<AnyImage> {
    let bytes = std::fs::read(path).with_context(|| format!("{}: cannot read", path.display()))?;
    parse_any_image(&bytes, &path.display().to_string())
}

/// Parse and validate image bytes of any format; the one-line error starts
/// with `source` (the file's name).
pub fn parse_any_image(bytes: &[u8], source: &str) -> Result<AnyImage> {
    let bad = |e: ImageError| anyhow::anyhow!("{source}: invalid coefficient image: {e}");
    match peek_version(bytes) {
        Some(PARALLEL_FORMAT_VERSION) => Ok(AnyImage::Parallel(Box::new(ParallelImage::parse(bytes).map_err(bad)?))),
        Some(MATRIX_FORMAT_VERSION) => Ok(AnyImage::Matrix(Box::new(MatrixImage::parse(bytes).map_err(bad)?))),
        _ => Ok(AnyImage::Inline(CoeffImage::parse(bytes).map_err(bad)?)),
    }
}

/// Encode a parallel image, check that it decodes to the same value, and
/// write it atomically.
pub fn write_parallel_image(path: &Path, image: &ParallelImage) -> Result<()> {
    let mut buf = vec![0u8; MAX_PARALLEL_IMAGE_LEN];
    let n = image.encode(&mut buf).map_err(|e| anyhow::anyhow!("cannot encode parallel image: {e}"))?;
    buf.truncate(n);
    let back = ParallelImage::parse(&buf)
        .map_err(|e| anyhow::anyhow!("{}: encoded parallel image does not parse: {e}", path.display()))?;
    anyhow::ensure!(back == *image, "{}: encoded parallel image does not decode to the design", path.display());
    write_bytes_atomic(path, &buf)
}

/// Encode a 3x3 image (format 3) to bytes: the core's validation
/// ([`MatrixImage::encode`]) first, so an invalid filter or header is
/// refused here, never written.
pub fn encode_matrix_image(image: &MatrixImage) -> Result<Vec<u8>> {
    let mut buf = vec![0u8; MAX_MATRIX_IMAGE_LEN];
    let n = image.encode(&mut buf).map_err(|e| anyhow::anyhow!("cannot encode 3x3 image: {e}"))?;
    buf.truncate(n);
    Ok(buf)
}

/// Encode a 3x3 image and check that it decodes to the same value (`path`
/// names it in errors).
pub fn encode_matrix_image_checked(path: &Path, image: &MatrixImage) -> Result<Vec<u8>> {
    let bytes = encode_matrix_image(image)?;
    let back = MatrixImage::parse(&bytes)
        .map_err(|e| anyhow::anyhow!("{}: encoded 3x3 image does not parse: {e}", path.display()))?;
    anyhow::ensure!(back == *image, "{}: encoded 3x3 image does not decode to the design", path.display());
    Ok(bytes)
}
