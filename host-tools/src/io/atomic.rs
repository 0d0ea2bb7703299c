//! Atomic output files (DESIGN.md, CLI contract: "no output file left behind").
//!
//! Everything the tool writes goes through [`write_atomic`]: the content is
//! written to a temporary file in the destination's directory and renamed over
//! the destination only after it was written and flushed completely. On any
//! error the temporary file is removed and the destination is untouched.
//!
//! While the content is produced, a second thread flushes what was written
//! so far to the disk every [`WRITEBACK_PERIOD`], so that the final `fsync`
//! has only the tail left: the disk writes overlap the computation instead
//! of following it (74 MB take 0.10 s of `fsync` on this project's
//! benchmark disk, as long as a whole TDMS → TDMS compensation).

use anyhow::{anyhow, Context, Result};
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;
use std::sync::mpsc::{channel, Receiver, RecvTimeoutError};
use std::time::Duration;

/// How often the write-back thread of [`write_atomic`] flushes the
/// temporary file while it is being written.
pub const WRITEBACK_PERIOD: Duration = Duration::from_millis(10);

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
    write_atomic_file(path, |w, _| write(w))
}

/// [`write_atomic`], with the temporary file itself beside the buffered
/// writer over it, for writers that place data at offsets (positioned
/// writes, which do not move the file's cursor). A writer that uses both
/// must flush the buffered one before placing anything after its end.
pub fn write_atomic_file(path: &Path, write: impl FnOnce(&mut dyn Write, &File) -> Result<()>) -> Result<()> {
    let dir = output_dir(path);
    let tmp = tempfile::Builder::new()
        .prefix(".dynocomp-")
        .suffix(".tmp")
        .tempfile_in(dir)
        .with_context(|| format!("{}: cannot create a temporary file in {}", path.display(), dir.display()))?;
    let file = tmp.as_file();
    std::thread::scope(|scope| -> Result<()> {
        // A cloned handle shares the open file description, hence its
        // write-back error state: an error the background flush sees is
        // returned from here, never lost to the final sync below.
        let (done, until_done) = channel::<()>();
        let writeback = match file.try_clone() {
            Ok(f) => Some(scope.spawn(move || write_back(&f, &until_done))),
            Err(_) => None,
        };
        let written = (|| -> Result<()> {
            let mut w = BufWriter::new(file);
            write(&mut w, file).with_context(|| format!("{}: not written", path.display()))?;
            w.flush().with_context(|| format!("{}: write failed", path.display()))
        })();
        drop(done);
        let synced = match writeback.map(|h| h.join()) {
            Some(Ok(r)) => r.with_context(|| format!("{}: sync failed", path.display())),
            Some(Err(_)) => Err(anyhow!("{}: the write-back thread panicked", path.display())),
            None => Ok(()),
        };
        written.and(synced)
    })?;
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

/// Flush `file`'s written data to the disk every [`WRITEBACK_PERIOD`] until
/// `until_done` is closed; the first error ends it.
fn write_back(file: &File, until_done: &Receiver<()>) -> std::io::Result<()> {
    loop {
        match until_done.recv_timeout(WRITEBACK_PERIOD) {
            Err(RecvTimeoutError::Timeout) => file.sync_data()?,
            _ => return Ok(()),
        }
    }
}

/// Write `bytes` to `path` atomically.
pub fn write_bytes_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomic(path, |w| Ok(w.write_all(bytes)?))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn leftovers(dir: &Path) -> Vec<String> {
        std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.starts_with(".dynocomp-"))
            .collect()
    }

    /// A write that lasts several write-back periods (the background flush
    /// runs during it) ends with exactly the bytes written, and no temporary
    /// file beside it.
    #[test]
    fn slow_write_is_complete_with_write_back_running() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.bin");
        let chunk: Vec<u8> = (0..=255u8).cycle().take(1 << 16).collect();
        write_atomic(&path, |w| {
            for k in 0..8u8 {
                w.write_all(&chunk)?;
                w.write_all(&[k])?;
                std::thread::sleep(WRITEBACK_PERIOD * 2);
            }
            Ok(())
        })
        .unwrap();
        let got = std::fs::read(&path).unwrap();
        assert_eq!(got.len(), 8 * (chunk.len() + 1));
        for (k, part) in got.chunks(chunk.len() + 1).enumerate() {
            assert_eq!(&part[..chunk.len()], chunk.as_slice());
            assert_eq!(part[chunk.len()], k as u8);
        }
        assert!(leftovers(dir.path()).is_empty());
    }

    /// A write that fails half way leaves the destination as it was and no
    /// temporary file, and the error names the destination.
    #[test]
    fn failed_write_leaves_destination_untouched() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.csv");
        std::fs::write(&path, b"previous").unwrap();
        let err = write_atomic(&path, |w| {
            w.write_all(&[b'x'; 100_000])?;
            std::thread::sleep(WRITEBACK_PERIOD * 3);
            anyhow::bail!("input line 7: not a number")
        })
        .unwrap_err();
        let msg = format!("{err:#}");
        assert!(msg.contains("out.csv") && msg.contains("line 7"), "{msg}");
        assert_eq!(std::fs::read(&path).unwrap(), b"previous");
        assert!(leftovers(dir.path()).is_empty());
    }
}
