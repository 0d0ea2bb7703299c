//! Coefficient image files (`.dcimg`): the core codec plus file handling.

use anyhow::{Context, Result};
use dynocomp_core::image::{CoeffImage, MAX_IMAGE_LEN};
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
    let bytes = encode_image(image)?;
    let back = CoeffImage::parse(&bytes).map_err(|e| anyhow::anyhow!("{}: encoded image does not parse: {e}", path.display()))?;
    anyhow::ensure!(back == *image, "{}: encoded image does not decode to the design", path.display());
    write_bytes_atomic(path, &bytes)
}
