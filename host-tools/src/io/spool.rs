//! A record read once (from a pipe) kept on disk so that it can be read a
//! second time: `compensate --offline` runs its forward pass over the
//! input, then reads the input again to write the output beside its times
//! ([`TwoReadings`], [`Spooling`], [`Replay`]).

use anyhow::{bail, Context, Result};
use std::fs::File;
use std::io::{BufReader, BufWriter, Read, Seek, SeekFrom, Write};
use std::path::Path;

use super::signal::{Block, SignalReader};

/// The first reading of a record, copied to disk as it goes.
///
/// Wraps any [`SignalReader`]: every block it hands out is also appended, as
/// little-endian f64 (the time, if any, then one value per channel, sample by
/// sample), to an unnamed temporary file. After the last block
/// [`Spooling::replay`] returns a [`SignalReader`] over that file that
/// delivers the same samples, bit for bit. Cost: 8 bytes per sample and
/// column on disk (freed when the replay is dropped), a few blocks of memory.
pub struct Spooling {
    inner: Box<dyn SignalReader>,
    axes: Vec<usize>,
    has_time: bool,
    spool: BufWriter<File>,
    samples: u64,
    ended: bool,
}

impl Spooling {
    /// Spool `inner` to an unnamed temporary file in `dir` (the output's
    /// folder: the disk chosen for a large output).
    pub fn new(inner: Box<dyn SignalReader>, dir: &Path) -> Result<Self> {
        let file = tempfile::tempfile_in(dir).with_context(|| {
            format!("{}: cannot create a temporary file to keep the input for its second reading", dir.display())
        })?;
        let (axes, has_time) = (inner.axes().to_vec(), inner.has_time());
        Ok(Spooling { inner, axes, has_time, spool: BufWriter::with_capacity(1 << 20, file), samples: 0, ended: false })
    }

    /// The second reading: the same samples, from the spool. An error
    /// unless the first reading ran to the end of the record.
    pub fn replay(self) -> Result<Replay> {
        if !self.ended {
            bail!("internal: the input was replayed before its first reading ended");
        }
        let mut file = self
            .spool
            .into_inner()
            .map_err(|e| e.into_error())
            .context("cannot write the temporary copy of the input")?;
        file.seek(SeekFrom::Start(0)).context("cannot rewind the temporary copy of the input")?;
        Ok(Replay {
            file: BufReader::with_capacity(1 << 20, file),
            axes: self.axes,
            has_time: self.has_time,
            left: self.samples,
            row: Vec::new(),
        })
    }
}

impl SignalReader for Spooling {
    fn axes(&self) -> &[usize] {
        &self.axes
    }
    fn has_time(&self) -> bool {
        self.has_time
    }
    fn declared_fs_hz(&self) -> Option<f64> {
        self.inner.declared_fs_hz()
    }
    fn len_hint(&self) -> Option<u64> {
        self.inner.len_hint()
    }
    fn read_block(&mut self, blk: &mut Block, max: usize) -> Result<usize> {
        let m = self.inner.read_block(blk, max)?;
        self.ended |= m == 0;
        for k in 0..m {
            if self.has_time {
                self.spool.write_all(&blk.t_s[k].to_le_bytes())?;
            }
            for c in &blk.channels {
                self.spool.write_all(&c[k].to_le_bytes())?;
            }
        }
        self.samples += m as u64;
        Ok(m)
    }
}

/// The second reading of a [`Spooling`] record.
///
/// The input's parsing and its errors (which name the input and the place)
/// happen once, in the first reading; the replay only reads back numbers
/// this process wrote.
pub struct Replay {
    file: BufReader<File>,
    axes: Vec<usize>,
    has_time: bool,
    left: u64,
    row: Vec<u8>,
}

impl SignalReader for Replay {
    fn axes(&self) -> &[usize] {
        &self.axes
    }
    fn has_time(&self) -> bool {
        self.has_time
    }
    fn len_hint(&self) -> Option<u64> {
        Some(self.left)
    }
    fn read_block(&mut self, blk: &mut Block, max: usize) -> Result<usize> {
        blk.clear();
        let m = max.min(usize::try_from(self.left).unwrap_or(usize::MAX));
        let cols = self.axes.len() + usize::from(self.has_time);
        self.row.resize(8 * cols, 0);
        let value = |row: &[u8], j: usize| f64::from_le_bytes(row[8 * j..8 * j + 8].try_into().expect("8 bytes"));
        for _ in 0..m {
            self.file.read_exact(&mut self.row).context("cannot read the temporary copy of the input back")?;
            let off = usize::from(self.has_time);
            if self.has_time {
                blk.t_s.push(value(&self.row, 0));
            }
            for (j, c) in blk.channels.iter_mut().enumerate() {
                c.push(value(&self.row, off + j));
            }
        }
        self.left -= m as u64;
        Ok(m)
    }
}

/// A record that `compensate --offline` reads twice: a file is opened
/// again for the second reading, anything else (a pipe, `/dev/stdin`) is
/// spooled during the first.
pub enum TwoReadings {
    /// A regular file: the second reading opens it again.
    Reopen(Box<dyn SignalReader>),
    /// A pipe: kept on disk during the first reading.
    Spool(Spooling),
}

impl TwoReadings {
    /// The readings of `first`, opened from `path`; a spool (if `path` is
    /// not a regular file) goes to `dir`.
    pub fn new(first: Box<dyn SignalReader>, path: &Path, dir: &Path) -> Result<Self> {
        Ok(if super::signal_file::can_read_twice(path) {
            TwoReadings::Reopen(first)
        } else {
            TwoReadings::Spool(Spooling::new(first, dir)?)
        })
    }

    /// Whether the input is kept in a temporary file for its second reading.
    pub fn spooled(&self) -> bool {
        matches!(self, TwoReadings::Spool(_))
    }

    /// The first reading.
    pub fn first(&mut self) -> &mut dyn SignalReader {
        match self {
            TwoReadings::Reopen(r) => &mut **r,
            TwoReadings::Spool(s) => s,
        }
    }

    /// The second reading, once the first has ended: `reopen` opens the file
    /// again; a pipe is replayed from its spool.
    pub fn second(self, reopen: impl FnOnce() -> Result<Box<dyn SignalReader>>) -> Result<Box<dyn SignalReader>> {
        match self {
            TwoReadings::Reopen(_) => reopen(),
            TwoReadings::Spool(s) => Ok(Box::new(s.replay()?)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::signal::BLOCK;

    /// A reader of a made-up record: `n` samples, values that use all the
    /// bits of an f64 (so a lossy copy would show), delivered in blocks of
    /// at most `chunk`.
    struct Made {
        axes: Vec<usize>,
        time: bool,
        n: usize,
        at: usize,
        chunk: usize,
    }

    fn value(k: usize, j: usize) -> f64 {
        ((k * 7 + j) as f64 * 0.123_456_789_012_345_67).sin() * 1e3 + 1.0 / 3.0
    }

    impl SignalReader for Made {
        fn axes(&self) -> &[usize] {
            &self.axes
        }
        fn has_time(&self) -> bool {
            self.time
        }
        fn read_block(&mut self, blk: &mut Block, max: usize) -> Result<usize> {
            blk.clear();
            let m = max.min(self.chunk).min(self.n - self.at);
            for k in self.at..self.at + m {
                if self.time {
                    blk.t_s.push(k as f64 / 51_200.0);
                }
                for (j, c) in blk.channels.iter_mut().enumerate() {
                    c.push(value(k, j));
                }
            }
            self.at += m;
            Ok(m)
        }
    }

    fn drain(r: &mut dyn SignalReader, max: usize) -> Block {
        let mut all = Block::new(r.axes().len());
        let mut blk = Block::new(r.axes().len());
        while r.read_block(&mut blk, max).unwrap() > 0 {
            all.t_s.extend_from_slice(&blk.t_s);
            for (a, c) in all.channels.iter_mut().zip(&blk.channels) {
                a.extend_from_slice(c);
            }
        }
        all
    }

    fn bits(b: &Block) -> Vec<Vec<u64>> {
        std::iter::once(&b.t_s).chain(&b.channels).map(|c| c.iter().map(|v| v.to_bits()).collect()).collect()
    }

    #[test]
    fn the_replay_delivers_the_first_reading_bit_for_bit() {
        let dir = tempfile::tempdir().unwrap();
        for (axes, time, n, chunk, max) in [
            (vec![0, 1, 2], true, 3 * BLOCK + 17, BLOCK, BLOCK),
            (vec![1], false, 1000, 7, BLOCK),
            (vec![0, 2], true, 5, 3, 2),
            (vec![0, 1, 2], false, 0, 1, BLOCK),
        ] {
            let made = Made { axes: axes.clone(), time, n, at: 0, chunk };
            let mut first = Spooling::new(Box::new(made), dir.path()).unwrap();
            let a = drain(&mut first, max);
            assert_eq!(a.len(), n);
            let mut again = first.replay().unwrap();
            assert_eq!((again.axes(), again.has_time(), again.len_hint()), (&axes[..], time, Some(n as u64)));
            // Read back in other block sizes than the first reading used.
            let b = drain(&mut again, 333);
            assert_eq!(bits(&a), bits(&b), "{axes:?} time {time} n {n}");
            let mut blk = Block::new(axes.len());
            assert_eq!(again.read_block(&mut blk, BLOCK).unwrap(), 0, "the replay ends where the record did");
        }
    }

    #[test]
    fn a_replay_before_the_end_of_the_first_reading_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let made = Made { axes: vec![0], time: true, n: 100, at: 0, chunk: 10 };
        let mut first = Spooling::new(Box::new(made), dir.path()).unwrap();
        let mut blk = Block::new(1);
        assert_eq!(first.read_block(&mut blk, BLOCK).unwrap(), 10);
        let e = first.replay().err().expect("refused").to_string();
        assert!(e.contains("before its first reading ended"), "{e}");
    }

    #[test]
    fn the_spool_is_not_left_on_disk() {
        let dir = tempfile::tempdir().unwrap();
        let made = Made { axes: vec![0, 1], time: true, n: 2000, at: 0, chunk: BLOCK };
        let mut first = Spooling::new(Box::new(made), dir.path()).unwrap();
        drain(&mut first, BLOCK);
        let again = first.replay().unwrap();
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0, "an unnamed temporary file");
        drop(again);
    }
}
