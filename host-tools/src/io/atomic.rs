//! Atomic output files (DESIGN.md, CLI contract: "no output file left behind").
//!
//! Everything the tool writes goes through [`write_atomic`]: the content is
//! written to a temporary file in the destination's directory and renamed over
//! the destination only after it was written and flushed completely. On any
//! error the temporary file is removed and the destination is untouched.

use anyhow::{Context, Result};
use std::io::{BufWriter, Write};
use std::path::Path;

/// The folder of the output `path` (`.` for a bare file name): where its
/// temporary file goes, and the temporary files of writers and passes too
/// large for memory (the disk the user chose for a large output).
pub fn output_dir(path: &Path) -> &Path {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    }
}

/// Write `path` atomically with the bytes produced by `write`.
pub fn write_atomic(path: &Path, write: impl FnOnce(&mut dyn Write) -> Result<()>) -> Result<()> {
    let dir = output_dir(path);
    let tmp = tempfile::Builder::new()
        .prefix(".dynocomp-")
        .suffix(".tmp")
        .tempfile_in(dir)
        .with_context(|| format!("{}: cannot create a temporary file in {}", path.display(), dir.display()))?;
    {
        let mut w = BufWriter::new(tmp.as_file());
        write(&mut w).with_context(|| format!("{}: not written", path.display()))?;
        w.flush().with_context(|| format!("{}: write failed", path.display()))?;
    }
    // tempfile creates 0600 files; outputs are ordinary files (0644).
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let _ = tmp.as_file().set_permissions(std::fs::Permissions::from_mode(0o644));
    }
    tmp.as_file()
        .sync_all()
        .with_context(|| format!("{}: sync failed", path.display()))?;
    tmp.persist(path)
        .map_err(|e| e.error)
        .with_context(|| format!("{}: cannot move the finished file into place", path.display()))?;
    Ok(())
}

/// Write `bytes` to `path` atomically.
pub fn write_bytes_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomic(path, |w| Ok(w.write_all(bytes)?))
}
