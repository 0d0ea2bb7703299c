//! Force-record files by format: opening a reader by extension or content,
//! and a writer for an output format.

use anyhow::{bail, Context, Result};
use std::io::Write;
use std::path::Path;

use crate::io::signal::{bounded, ChannelMap, SignalReader, SignalWriter, DEFAULT_FULL_SCALE_N};
use crate::io::signal_csv::{CsvReader, CsvWriter};
use crate::io::tdms::{looks_like_tdms, TdmsReader, TdmsWriter};
use crate::io::uff_signal::{UffReader, UffWriter};

/// File formats of force records.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum SignalFormat {
    /// Signal CSV: columns [t_s,] fx, fy, fz in N (README "File formats").
    Csv,
    /// UFF dataset 58 time histories, ASCII (values as E20.12).
    Uff,
    /// UFF dataset 58b time histories, binary (little-endian f64).
    Uff58b,
    /// NI TDMS (interleaved little-endian f64 channels Fx, Fy, Fz).
    Tdms,
}

/// Whether `path` is a regular file, which can be opened and read again
/// from its start (a pipe or a device such as /dev/stdin cannot: its bytes
/// are gone once read).
pub fn can_read_twice(path: &Path) -> bool {
    std::fs::metadata(path).is_ok_and(|m| m.is_file())
}

/// Open the force record `path`: its reader and its format (by extension,
/// otherwise by content), with force values checked against the default
/// full scale ([`open_signal_checked`]).
pub fn open_signal(path: &Path, map: Option<&ChannelMap>) -> Result<(Box<dyn SignalReader>, SignalFormat)> {
    open_signal_checked(path, map, DEFAULT_FULL_SCALE_N)
}

/// Open the force record `path` as [`open_signal`]; every force value must
/// be finite and within ±`full_scale_n` (N), otherwise reading fails with
/// the file, the line or sample, and the column named.
///
/// `-` is standard input, read as CSV: the other formats cannot come from a
/// pipe (a TDMS file is read through its segment index and at offsets, a
/// UFF record is indexed in a first pass and read in a second).
pub fn open_signal_checked(
    path: &Path,
    map: Option<&ChannelMap>,
    full_scale_n: f64,
) -> Result<(Box<dyn SignalReader>, SignalFormat)> {
    if crate::io::atomic::is_stdio(path) {
        if map.is_some() {
            bail!("standard input (`-`) is read as CSV, whose columns are named fx, fy, fz; --channels applies to UFF and TDMS files");
        }
        return Ok((Box::new(CsvReader::stdin()?.with_full_scale(full_scale_n)), SignalFormat::Csv));
    }
    let (reader, fmt) = open_by_format(path, map, full_scale_n)?;
    let reader: Box<dyn SignalReader> = match fmt {
        SignalFormat::Csv => reader,
        _ => bounded(reader, &path.display().to_string(), full_scale_n),
    };
    Ok((reader, fmt))
}

/// The reader of `path` by its format; the CSV reader checks its values
/// against `full_scale_n` itself (with line numbers), the others do not.
fn open_by_format(
    path: &Path,
    map: Option<&ChannelMap>,
    full_scale_n: f64,
) -> Result<(Box<dyn SignalReader>, SignalFormat)> {
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    let sniff = || -> Result<Vec<u8>> {
        let mut head = vec![0u8; 4096];
        let n = std::fs::File::open(path)
            .and_then(|mut f| std::io::Read::read(&mut f, &mut head))
            .with_context(|| format!("{}: cannot read", path.display()))?;
        head.truncate(n);
        Ok(head)
    };
    // A pipe or device (e.g. /dev/stdin) cannot be sniffed without
    // consuming what the reader needs: read as CSV.
    let sniffable = || can_read_twice(path);
    let is_tdms = match ext.as_deref() {
        Some("tdms") => true,
        Some("csv" | "uff" | "unv" | "uf") => false,
        _ => sniffable() && looks_like_tdms(&sniff()?),
    };
    if is_tdms {
        return Ok((Box::new(TdmsReader::open(path, map)?), SignalFormat::Tdms));
    }
    let is_uff = match ext.as_deref() {
        Some("csv") => false,
        Some("uff" | "unv" | "uf") => true,
        _ if !sniffable() => false,
        _ => crate::io::uff::looks_like_uff(&sniff()?),
    };
    if is_uff {
        let r = UffReader::open(path, map)?;
        let fmt = if r.is_binary() { SignalFormat::Uff58b } else { SignalFormat::Uff };
        return Ok((Box::new(r), fmt));
    }
    if map.is_some() {
        bail!("{}: --channels applies to UFF and TDMS records; a CSV names its columns fx, fy, fz", path.display());
    }
    Ok((Box::new(CsvReader::open(path)?.with_full_scale(full_scale_n)), SignalFormat::Csv))
}

/// A writer of `fmt` into `w` for `axes` (with a time column if
/// `has_time`); `len`: the number of samples if known, `fs_hz` the sample
/// rate. `file`: the file under `w`, if it is one; a UFF record of known
/// length is then written in place ([`UffWriter::placed`]), otherwise
/// through spill files in the output's folder.
#[allow(clippy::too_many_arguments)]
pub fn writer_for<'w>(
    fmt: SignalFormat,
    w: &'w mut dyn Write,
    file: Option<&'w std::fs::File>,
    axes: &[usize],
    has_time: bool,
    len: Option<u64>,
    fs_hz: f64,
    path: &Path,
) -> Result<Box<dyn SignalWriter + 'w>> {
    let dir = crate::io::atomic::output_dir(path);
    let inner: Box<dyn SignalWriter + 'w> = match (fmt, file, len) {
        (SignalFormat::Csv, ..) => Box::new(CsvWriter::new(w, axes, has_time)?),
        (SignalFormat::Uff | SignalFormat::Uff58b, Some(f), Some(n)) => {
            Box::new(UffWriter::placed(f, n, axes, fs_hz, fmt == SignalFormat::Uff58b)?)
        }
        (SignalFormat::Uff | SignalFormat::Uff58b, ..) => {
            Box::new(UffWriter::new_in(w, axes, fs_hz, fmt == SignalFormat::Uff58b, dir)?)
        }
        (SignalFormat::Tdms, ..) => Box::new(TdmsWriter::new(w, axes, fs_hz, 0.0)?),
    };
    Ok(Box::new(FiniteOnly { inner, axes: axes.to_vec(), written: 0 }))
}

/// Refuses a non-finite sample before the format sees it: none of the
/// formats' readers takes one back (the UFF writer would print `NaNe+00`,
/// the CSV writer `NaN`), so a NaN or ∞ is an error naming the sample and
/// the channel, and the caller's atomic write leaves no file.
struct FiniteOnly<'w> {
    inner: Box<dyn SignalWriter + 'w>,
    axes: Vec<usize>,
    /// Samples written so far.
    written: u64,
}

impl SignalWriter for FiniteOnly<'_> {
    fn write_block(&mut self, t_s: Option<&[f64]>, channels: &[&[f64]]) -> Result<()> {
        // (column, axis; None for the time column)
        let columns =
            t_s.map(|t| (t, None)).into_iter().chain(channels.iter().zip(&self.axes).map(|(c, &a)| (*c, Some(a))));
        for (c, axis) in columns {
            if let Some(i) = c.iter().position(|v| !v.is_finite()) {
                let name = axis.map_or_else(|| "t_s".to_string(), |a| format!("f{}", crate::frf::axis_name(a)));
                bail!(
                    "sample {} of {name} is {}: the output formats cannot carry a non-finite value; nothing is written",
                    self.written + i as u64,
                    c[i]
                );
            }
        }
        self.written += channels.first().map_or(0, |c| c.len()) as u64;
        self.inner.write_block(t_s, channels)
    }

    fn finish(&mut self) -> Result<()> {
        self.inner.finish()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every format refuses a non-finite sample, naming it; finite blocks
    /// before it are accepted (negative control).
    #[test]
    fn a_non_finite_sample_is_refused_in_every_format() {
        for fmt in [SignalFormat::Csv, SignalFormat::Uff, SignalFormat::Uff58b, SignalFormat::Tdms] {
            let dir = tempfile::tempdir().unwrap();
            let path = dir.path().join("out");
            let mut buf: Vec<u8> = Vec::new();
            let mut w = writer_for(fmt, &mut buf, None, &[0, 2], true, None, 1000.0, &path).unwrap();
            let t = [0.0, 0.001, 0.002];
            w.write_block(Some(&t), &[&[1.0, 2.0, 3.0], &[4.0, 5.0, 6.0]]).unwrap();
            let e = w
                .write_block(Some(&[0.003, 0.004, 0.005]), &[&[1.0, 2.0, 3.0], &[4.0, f64::NAN, 6.0]])
                .unwrap_err()
                .to_string();
            assert!(e.contains("sample 4 of fz is NaN"), "{fmt:?}: {e}");
            let e = w.write_block(Some(&[0.003, f64::INFINITY]), &[&[1.0, 2.0], &[4.0, 5.0]]).unwrap_err().to_string();
            assert!(e.contains("sample 4 of t_s is inf"), "{fmt:?}: {e}");
        }
    }
}
