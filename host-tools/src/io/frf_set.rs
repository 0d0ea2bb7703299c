//! One state's FRF matrix from one file or from several (one per hammer
//! direction, say): the files are read and their entries merged into one
//! [`Frf`] (DESIGN.md, "Signal chain and mathematics") by [`read_frf_arg`],
//! [`read_frf_set`] and [`merge_frf_files`]. A leaf of the chain.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};

use super::{frf_csv, uff};
use crate::frf::{entry_name, Frf};

/// Relative tolerance on frequency lines, of the largest line (as within one UFF file).
const FREQ_RTOL: f64 = 1e-6;

/// Units of FRF CSV: force over force in newtons, by the format's definition.
pub const CSV_UNITS: &str = "N/N";

/// One parsed FRF file, with what the merge compares.
#[derive(Clone, Debug, PartialEq)]
pub struct FrfFile {
    /// The file's name as given (used in messages).
    pub source: String,
    /// Its entries.
    pub frf: Frf,
    /// Force units of its FRFs as labelled (`"N/N"`), or `None` when unlabelled.
    pub units: Option<String>,
}

/// Parse the bytes of the FRF file `path`, keeping the units label for
/// [`merge_frf_files`]: the format follows from the extension (`.csv`;
/// `.uff`, `.unv`, `.uf`), otherwise from the content (a first non-blank
/// line `-1` means UFF). [`super::parse_frf`] is this without the units.
pub fn parse_frf_file(path: &Path, bytes: &[u8]) -> Result<FrfFile> {
    let source = path.display().to_string();
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    let uff_format = match ext.as_deref() {
        Some("csv") => false,
        Some("uff" | "unv" | "uf") => true,
        _ => uff::looks_like_uff(bytes),
    };
    if uff_format {
        let (frf, units) = uff::parse_uff58_units(bytes, &source)?;
        Ok(FrfFile { source, frf, units })
    } else {
        let frf = frf_csv::parse_frf_csv_bytes(bytes, &source)?;
        Ok(FrfFile { source, frf, units: Some(CSV_UNITS.to_string()) })
    }
}

/// Read the FRF files of one matrix and merge them ([`merge_frf_files`]).
/// One path reads exactly as [`super::read_frf`] does.
pub fn read_frf_set(paths: &[PathBuf]) -> Result<Frf> {
    let files = paths
        .iter()
        .map(|p| {
            let bytes = std::fs::read(p).with_context(|| format!("{}: cannot read", p.display()))?;
            parse_frf_file(p, &bytes)
        })
        .collect::<Result<Vec<_>>>()?;
    merge_frf_files(&files)
}

/// Read one `--frf` value: a file, or the files of one matrix separated by
/// commas ([`split_frf_list`], merged by [`merge_frf_files`]). Returns the
/// FRF set and the SHA-256 of the files' bytes in the order given (of the
/// file's bytes for one file), which the image records.
pub fn read_frf_arg(value: &Path) -> Result<(Frf, [u8; 32])> {
    use sha2::{Digest, Sha256};
    let text = value.to_string_lossy();
    let paths = if value.exists() || !text.contains(',') { vec![value.to_path_buf()] } else { split_frf_list(&text)? };
    let mut sha = Sha256::new();
    let mut files = Vec::with_capacity(paths.len());
    for p in &paths {
        let bytes = std::fs::read(p).with_context(|| format!("{}: cannot read", p.display()))?;
        sha.update(&bytes);
        files.push(parse_frf_file(p, &bytes)?);
    }
    Ok((merge_frf_files(&files)?, sha.finalize().into()))
}

/// Split one `--frf` value into the files of one matrix: `a.uff,b.uff` →
/// `[a.uff, b.uff]`. An empty name (`a.uff,,b.uff`, a trailing comma) or a
/// file named twice is refused.
///
/// On the command line the files of one matrix are one `--frf` value, the
/// names separated by commas (`--frf hx.uff,hy.uff,hz.uff`), so the two-state
/// `--frf BEFORE --frf AFTER` keeps its meaning. A file name cannot contain a
/// comma there.
pub fn split_frf_list(value: &str) -> Result<Vec<PathBuf>> {
    let parts: Vec<&str> = value.split(',').collect();
    let mut out: Vec<PathBuf> = Vec::with_capacity(parts.len());
    for (k, p) in parts.iter().enumerate() {
        if p.trim().is_empty() {
            bail!(
                "--frf {}: file name {} of {} is empty (the files of one matrix are separated by single commas)",
                super::one_line(value),
                k + 1,
                parts.len()
            );
        }
        let path = PathBuf::from(p);
        if out.contains(&path) {
            bail!("--frf {}: {} is named twice", super::one_line(value), super::one_line(p));
        }
        out.push(path);
    }
    Ok(out)
}

/// Merge the entries of `files` (one state's matrix) into one [`Frf`] on the
/// first file's frequency lines. Refuses an empty list, an entry given twice,
/// different frequency lines and different units, naming both files and
/// what to do.
///
/// The merge refuses, with a message naming both files:
/// - an entry G_ij given by two files (or twice in one list);
/// - frequency lines that differ (number, or any line by more than 1e-6 of
///   the span): the files of one matrix come from one analyser set-up;
/// - FRFs labelled with different force units (UFF records 9/10; FRF CSV is
///   N/N by its definition). Unlabelled FRFs are compared with nothing.
pub fn merge_frf_files(files: &[FrfFile]) -> Result<Frf> {
    let Some(first) = files.first() else {
        bail!("no FRF file given");
    };
    if files.len() == 1 {
        return Ok(first.frf.clone());
    }
    // Which file holds each entry.
    let mut owner: [Option<usize>; 9] = [None; 9];
    let mut units: Option<(usize, &str)> = None;
    for (k, f) in files.iter().enumerate() {
        check_grid(first, f)?;
        if let Some(u) = f.units.as_deref() {
            match units {
                Some((o, prev)) if !prev.eq_ignore_ascii_case(u) => bail!(
                    "{}: FRFs in units {}, but {} has them in {}: the files of one matrix must use the same \
                     units; export every hammer direction as N/N",
                    f.source,
                    super::one_line(u),
                    files[o].source,
                    super::one_line(prev)
                ),
                Some(_) => {}
                None => units = Some((k, u)),
            }
        }
        for e in f.frf.entries() {
            let slot = &mut owner[3 * e.channel + e.direction];
            if let Some(o) = *slot {
                let name = entry_name(e.channel, e.direction);
                let what = if e.channel == e.direction { "direct" } else { "cross" };
                bail!(
                    "{}: holds entry {name} ({what} FRF, channel {}, force {}), which {} holds too: \
                     give each entry of the matrix in one file only",
                    f.source,
                    crate::frf::axis_name(e.channel),
                    crate::frf::axis_name(e.direction),
                    files[o].source
                );
            }
            *slot = Some(k);
        }
    }
    // Every entry has one owner now: take them all.
    let mut merged = Frf::direct(first.frf.freq_hz.clone(), Vec::new());
    for f in files {
        merged.axes.extend(f.frf.axes.iter().cloned());
        merged.cross.extend(f.frf.cross.iter().cloned());
    }
    merged.axes.sort_by_key(|a| a.axis);
    merged.cross.sort_by_key(|c| (c.channel, c.direction));
    Ok(merged)
}

/// `f`'s frequency lines against the first file's.
fn check_grid(first: &FrfFile, f: &FrfFile) -> Result<()> {
    let (a, b) = (&first.frf.freq_hz, &f.frf.freq_hz);
    let span = |v: &[f64]| match (v.first(), v.last()) {
        (Some(lo), Some(hi)) => format!("{} lines from {lo} to {hi} Hz", v.len()),
        _ => "no lines".to_string(),
    };
    let fix = "the files of one matrix must share the same frequency lines; \
               export every hammer direction with the same span and resolution";
    if a.len() != b.len() {
        bail!("{}: {}, but {} has {}: {fix}", f.source, span(b), first.source, span(a));
    }
    let scale = a.iter().chain(b.iter()).fold(0.0f64, |m, v| m.max(v.abs()));
    if let Some(i) = (0..a.len()).find(|&i| (a[i] - b[i]).abs() > FREQ_RTOL * scale) {
        bail!(
            "{}: frequency line {} is {} Hz, but {} Hz in {} ({} against {}): {fix}",
            f.source,
            i + 1,
            b[i],
            a[i],
            first.source,
            span(b),
            span(a)
        );
    }
    Ok(())
}
