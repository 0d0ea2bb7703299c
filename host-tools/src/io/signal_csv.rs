//! Force records as CSV (DESIGN.md, CLI contract "Signal CSV").
//!
//! Header row; columns `fx`, `fy`, `fz` (any subset, in N); an optional first
//! column `t_s` (seconds). Output files use the same layout.
//!
//! Every force value must be finite and within the full scale (N; default
//! [`DEFAULT_FULL_SCALE_N`], [`CsvReader::with_full_scale`]); a line longer
//! than [`MAX_LINE_BYTES`] is refused before it is held in memory whole.
//! `-` reads standard input ([`CsvReader::stdin`]).

use anyhow::{anyhow, bail, Context, Result};
use std::fs::File;
use std::io::{BufRead, BufReader, Read, Write};
use std::path::Path;

use crate::frf::axis_name;
use crate::io::atomic::write_atomic;
use crate::io::decimal;
use crate::io::one_line;
use crate::io::signal::{implausible, plausible, read_all, Block, SignalReader, SignalWriter, DEFAULT_FULL_SCALE_N};

/// Longest line a signal CSV may have (bytes): a row of a few numbers is
/// tens of bytes; a file with a longer line is not a signal CSV, and is not
/// read into memory whole to say so.
pub const MAX_LINE_BYTES: usize = 1 << 20;

/// A multi-axis force record.
#[derive(Clone, Debug, PartialEq)]
pub struct SignalRecord {
    /// Sample times (s), if the file had a `t_s` column.
    pub t_s: Option<Vec<f64>>,
    /// `(axis, samples in N)` in ascending axis order (0 = x, 1 = y, 2 = z).
    pub channels: Vec<(usize, Vec<f64>)>,
}

impl SignalRecord {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.channels.first().map_or(0, |c| c.1.len())
    }

    /// Whether the record has no samples.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The samples of `axis`, if present.
    pub fn channel(&self, axis: usize) -> Option<&[f64]> {
        self.channels.iter().find(|c| c.0 == axis).map(|c| c.1.as_slice())
    }

    /// Sample rate implied by the `t_s` column (Hz), from its mean spacing, and
    /// the largest deviation of any spacing from that mean (relative).
    pub fn sample_rate_from_time(&self) -> Option<(f64, f64)> {
        let t = self.t_s.as_ref()?;
        if t.len() < 2 {
            return None;
        }
        let dt = (t[t.len() - 1] - t[0]) / (t.len() - 1) as f64;
        let worst = t.windows(2).map(|w| ((w[1] - w[0]) - dt).abs() / dt).fold(0.0, f64::max);
        Some((1.0 / dt, worst))
    }
}

fn column_axis(name: &str) -> Option<usize> {
    match name {
        "fx" => Some(0),
        "fy" => Some(1),
        "fz" => Some(2),
        _ => None,
    }
}

/// Columns a force record may carry besides t_s, fx, fy, fz, which the
/// reader checks as numbers and otherwise ignores: the raw (uncompensated)
/// forces that `dynocomp stream` records next to the compensated ones.
pub const IGNORED_COLUMNS: [&str; 3] = ["raw_fx", "raw_fy", "raw_fz"];

/// Read a force record from `path` (forces within the default full scale).
pub fn read_signal_csv(path: &Path) -> Result<SignalRecord> {
    read_signal_csv_checked(path, DEFAULT_FULL_SCALE_N)
}

/// Read a force record from `path`, refusing forces beyond ±`full_scale_n`
/// (N; `f64::INFINITY` checks only that they are finite).
pub fn read_signal_csv_checked(path: &Path, full_scale_n: f64) -> Result<SignalRecord> {
    let mut r = CsvReader::open(path)?.with_full_scale(full_scale_n);
    record_from(&mut r)
}

/// Parse a force record from CSV text; `source` names the input in errors.
pub fn parse_signal_csv(text: &str, source: &str) -> Result<SignalRecord> {
    let mut r = CsvReader::new(text.as_bytes(), source)?;
    record_from(&mut r)
}

fn record_from(r: &mut dyn SignalReader) -> Result<SignalRecord> {
    let axes = r.axes().to_vec();
    let (t_s, data) = read_all(r)?;
    Ok(SignalRecord { t_s, channels: axes.into_iter().zip(data).collect() })
}

/// The columns of a signal CSV, from its header.
#[derive(Default)]
struct Columns {
    /// Column names, lower case.
    names: Vec<String>,
    /// Data column of each CSV column (None: time or an ignored column).
    slot_of: Vec<Option<usize>>,
    /// Whether the first column is `t_s`.
    has_time: bool,
    /// Bound on the force values (N).
    full_scale_n: f64,
}

/// A signal CSV read block by block: no allocation per value, and lines
/// parsed in place in the reader's buffer, one pass over their bytes
/// ([`decimal::parse_f64`]: Clinger's fast path for plain decimals, the
/// standard library's parser for the rest).
pub struct CsvReader<R: BufRead> {
    r: R,
    source: String,
    cols: Columns,
    axes: Vec<usize>,
    /// Lines read so far (1-based number of the last line).
    lineno: usize,
    line: Vec<u8>,
    prev_t: Option<f64>,
    n: u64,
    done: bool,
}

impl CsvReader<BufReader<File>> {
    /// Open `path` and read its header.
    pub fn open(path: &Path) -> Result<Self> {
        let f = File::open(path).with_context(|| format!("{}: cannot read", path.display()))?;
        CsvReader::new(BufReader::with_capacity(1 << 20, f), &path.display().to_string())
    }
}

impl CsvReader<BufReader<std::io::Stdin>> {
    /// Read the record from standard input (named "standard input" in
    /// errors), header first.
    pub fn stdin() -> Result<Self> {
        CsvReader::new(BufReader::with_capacity(1 << 20, std::io::stdin()), "standard input")
    }
}

impl<R: BufRead> CsvReader<R> {
    /// Read the header of the CSV in `r`; `source` names it in errors.
    pub fn new(r: R, source: &str) -> Result<Self> {
        let mut me = CsvReader {
            r,
            source: source.to_string(),
            cols: Columns::default(),
            axes: Vec::new(),
            lineno: 0,
            line: Vec::new(),
            prev_t: None,
            n: 0,
            done: false,
        };
        if !me.next_line()? {
            bail!("{source}: empty file, expected a header row (t_s,fx,fy,fz)");
        }
        let header = me.line_str()?.to_string();
        me.parse_header(&header)?;
        me.cols.full_scale_n = DEFAULT_FULL_SCALE_N;
        Ok(me)
    }

    /// Refuse force values beyond ±`full_scale_n` (N) instead of
    /// [`DEFAULT_FULL_SCALE_N`]; `f64::INFINITY` checks only that they are
    /// finite.
    pub fn with_full_scale(mut self, full_scale_n: f64) -> Self {
        self.cols.full_scale_n = full_scale_n;
        self
    }

    fn parse_header(&mut self, header: &str) -> Result<()> {
        let source = &self.source;
        self.cols.names = header.split(',').map(|s| s.trim().trim_matches('"').to_ascii_lowercase()).collect();
        for (col, name) in self.cols.names.iter().enumerate() {
            if IGNORED_COLUMNS.contains(&name.as_str()) {
                self.cols.slot_of.push(None);
                continue;
            }
            self.cols.slot_of.push(column_axis(name).map(|_| self.axes.len()));
            if name == "t_s" {
                if col != 0 {
                    bail!("{source}: line {}, column {}: `t_s` must be the first column", self.lineno, col + 1);
                }
                self.cols.has_time = true;
            } else if let Some(axis) = column_axis(name) {
                if self.axes.contains(&axis) {
                    bail!("{source}: line {}, column {}: duplicate column `{name}`", self.lineno, col + 1);
                }
                if let Some(&last) = self.axes.last() {
                    if axis < last {
                        bail!(
                            "{source}: line {}, column {}: columns must be in the order fx, fy, fz",
                            self.lineno,
                            col + 1
                        );
                    }
                }
                self.axes.push(axis);
            } else {
                bail!(
                    "{source}: line {}, column {}: unknown column `{}` (expected t_s, fx, fy, fz)",
                    self.lineno,
                    col + 1,
                    one_line(name)
                );
            }
        }
        if self.axes.is_empty() {
            bail!("{source}: line {}: no force column (expected at least one of fx, fy, fz)", self.lineno);
        }
        Ok(())
    }

    /// Next non-blank line into `self.line` (without its line end); false at
    /// the end of the file. A line longer than [`MAX_LINE_BYTES`] is an error.
    fn next_line(&mut self) -> Result<bool> {
        loop {
            self.line.clear();
            let got = (&mut self.r)
                .take(MAX_LINE_BYTES as u64 + 1)
                .read_until(b'\n', &mut self.line)
                .with_context(|| format!("{}: read failed after line {}", self.source, self.lineno))?;
            if got == 0 {
                return Ok(false);
            }
            self.lineno += 1;
            if got > MAX_LINE_BYTES && self.line.last() != Some(&b'\n') {
                bail!("{}: line {} is longer than {MAX_LINE_BYTES} bytes: not a signal CSV", self.source, self.lineno);
            }
            if self.line.last() == Some(&b'\n') {
                self.line.pop();
                if self.line.last() == Some(&b'\r') {
                    self.line.pop();
                }
            }
            if !is_blank(&self.line) {
                return Ok(true);
            }
        }
    }

    fn line_str(&self) -> Result<&str> {
        std::str::from_utf8(&self.line)
            .map_err(|_| anyhow!("{}: line {}: not valid UTF-8 text", self.source, self.lineno))
    }

    /// Parse the current line (`self.line`) into `blk`.
    fn parse_line(&mut self, blk: &mut Block) -> Result<()> {
        parse_row(&self.line, &self.cols, &mut self.prev_t, blk, &self.source, self.lineno)
    }
}

/// A line of only blanks (skipped wherever it is, by both line paths).
fn is_blank(line: &[u8]) -> bool {
    line.iter().all(u8::is_ascii_whitespace)
}

/// Parse one data row (`line`, without its line end) into `blk`: one pass
/// over its bytes, each field parsed in place ([`decimal::parse_f64`]).
/// Any problem is diagnosed by [`row_error`], which checks the row in the
/// order the messages promise (text, field count, then field by field).
fn parse_row(
    line: &[u8],
    cols: &Columns,
    prev_t: &mut Option<f64>,
    blk: &mut Block,
    source: &str,
    lineno: usize,
) -> Result<()> {
    let Columns { names, slot_of, has_time, full_scale_n } = cols;
    let t_before = *prev_t;
    let mut col = 0;
    let mut ok = true;
    for field in line.split(|&b| b == b',') {
        let Some(v) = (col < names.len()).then(|| decimal::parse_f64(field)).flatten().filter(|v| v.is_finite()) else {
            ok = false;
            break;
        };
        if *has_time && col == 0 {
            if prev_t.is_some_and(|p| v <= p) {
                ok = false;
                break;
            }
            *prev_t = Some(v);
            blk.t_s.push(v);
        } else if let Some(slot) = slot_of[col] {
            if !plausible(v, *full_scale_n) {
                ok = false;
                break;
            }
            blk.channels[slot].push(v);
        }
        col += 1;
    }
    if ok && col == names.len() {
        return Ok(());
    }
    Err(row_error(line, cols, t_before, source, lineno))
}

/// Why `line` is not a valid data row (the first problem, in the order: not
/// UTF-8, field count, then each field: not a number, not finite, time not
/// increasing after `prev_t`, force beyond the full scale).
fn row_error(line: &[u8], cols: &Columns, prev_t: Option<f64>, source: &str, lineno: usize) -> anyhow::Error {
    let Columns { names, has_time, slot_of, full_scale_n } = cols;
    let Ok(line) = std::str::from_utf8(line) else {
        return anyhow!("{source}: line {lineno}: not valid UTF-8 text");
    };
    let n_fields = line.split(',').count();
    if n_fields != names.len() {
        return anyhow!("{source}: line {lineno}: {n_fields} fields, header has {}", names.len());
    }
    for (col, field) in line.split(',').enumerate() {
        let field = field.trim();
        let Ok(v) = field.parse::<f64>() else {
            return anyhow!(
                "{source}: line {lineno}, column {} (`{}`): `{}` is not a number",
                col + 1,
                names[col],
                one_line(field)
            );
        };
        if !v.is_finite() {
            return anyhow!("{source}: line {lineno}, column {} (`{}`): value is not finite", col + 1, names[col]);
        }
        if *has_time && col == 0 {
            if let Some(prev) = prev_t.filter(|p| v <= *p) {
                return anyhow!(
                    "{source}: line {lineno}, column 1 (`t_s`): time {v} does not increase (previous {prev})"
                );
            }
        } else if slot_of[col].is_some() && !plausible(v, *full_scale_n) {
            return implausible(
                source,
                &format!("line {lineno}, column {} (`{}`)", col + 1, names[col]),
                v,
                *full_scale_n,
            );
        }
    }
    anyhow!("{source}: line {lineno}: internal error: the row reads back valid")
}

impl<R: BufRead + Send> SignalReader for CsvReader<R> {
    fn axes(&self) -> &[usize] {
        &self.axes
    }

    fn has_time(&self) -> bool {
        self.cols.has_time
    }

    fn read_block(&mut self, blk: &mut Block, max: usize) -> Result<usize> {
        blk.clear();
        blk.channels.resize(self.axes.len(), Vec::new());
        while !self.done && blk.len() < max {
            // A whole line in the reader's buffer is parsed in place; one
            // that runs past the buffer's end is copied out (`next_line`).
            let buf = self
                .r
                .fill_buf()
                .with_context(|| format!("{}: read failed after line {}", self.source, self.lineno))?;
            if let Some(end) = memchr::memchr(b'\n', buf) {
                self.lineno += 1;
                let line = buf[..end].strip_suffix(b"\r").unwrap_or(&buf[..end]);
                if !is_blank(line) {
                    parse_row(line, &self.cols, &mut self.prev_t, blk, &self.source, self.lineno)?;
                }
                self.r.consume(end + 1);
                continue;
            }
            if !self.next_line()? {
                self.done = true;
                break;
            }
            self.parse_line(blk)?;
        }
        self.n += blk.len() as u64;
        if self.done && self.n == 0 {
            bail!("{}: no samples after the header", self.source);
        }
        Ok(blk.len())
    }
}

/// A signal CSV written block by block: a header row, then one row per
/// sample, every value in the shortest decimal form that reads back as the
/// same f64 (so f32 outputs of the kernel, held as f64, read back
/// bit-identical). Formatting is most of the cost of a CSV output (ryu,
/// ~35 ns a value), so a large block is formatted in two halves on two
/// threads into two reused buffers, written in order.
pub struct CsvWriter<'w> {
    w: &'w mut dyn Write,
    halves: [Vec<u8>; 2],
    n_channels: usize,
    has_time: bool,
}

/// Rows below which a block is formatted on the calling thread alone (a
/// thread costs tens of microseconds, about 300 rows' formatting).
const SPLIT_ROWS: usize = 2048;

impl<'w> CsvWriter<'w> {
    /// Write the header for `axes` (and `t_s` first if `has_time`).
    pub fn new(w: &'w mut dyn Write, axes: &[usize], has_time: bool) -> Result<Self> {
        let mut header: Vec<String> = Vec::new();
        if has_time {
            header.push("t_s".into());
        }
        header.extend(axes.iter().map(|a| format!("f{}", axis_name(*a))));
        writeln!(w, "{}", header.join(","))?;
        Ok(CsvWriter { w, halves: [Vec::new(), Vec::new()], n_channels: axes.len(), has_time })
    }
}

/// Append rows `rows` of the block (`t_s` first, if any) to `out`.
fn format_rows(out: &mut Vec<u8>, t_s: Option<&[f64]>, channels: &[&[f64]], rows: std::ops::Range<usize>) {
    let mut fmt = ryu::Buffer::new();
    out.clear();
    for k in rows {
        let mut first = true;
        if let Some(t) = t_s {
            push_f64(out, &mut fmt, t[k]);
            first = false;
        }
        for c in channels {
            if !first {
                out.push(b',');
            }
            first = false;
            push_f64(out, &mut fmt, c[k]);
        }
        out.push(b'\n');
    }
}

impl SignalWriter for CsvWriter<'_> {
    fn write_block(&mut self, t_s: Option<&[f64]>, channels: &[&[f64]]) -> Result<()> {
        let n = channels.first().map_or(0, |c| c.len());
        if channels.len() != self.n_channels
            || channels.iter().any(|c| c.len() != n)
            || t_s.is_some() != self.has_time
            || t_s.is_some_and(|t| t.len() != n)
        {
            bail!("internal error: a block does not match the output's columns");
        }
        let [first, second] = &mut self.halves;
        if n < SPLIT_ROWS {
            format_rows(first, t_s, channels, 0..n);
            second.clear();
        } else {
            let mid = n / 2;
            std::thread::scope(|s| {
                s.spawn(|| format_rows(second, t_s, channels, mid..n));
                format_rows(first, t_s, channels, 0..mid);
            });
        }
        self.w.write_all(first)?;
        self.w.write_all(second)?;
        Ok(())
    }

    fn finish(&mut self) -> Result<()> {
        Ok(())
    }
}

/// Append `v` in its shortest round-trip decimal form (ryu: the same
/// digits as `{}` formatting, about 3x faster; large and small magnitudes
/// in exponent form, e.g. `1.953125e-5`). Non-finite values (never written:
/// the readers and the kernel's check refuse them) would read `NaN`/`inf`.
fn push_f64(line: &mut Vec<u8>, buf: &mut ryu::Buffer, v: f64) {
    line.extend_from_slice(buf.format(v).as_bytes());
}

/// Write a force record to `path` atomically (columns t_s?, fx?, fy?, fz?).
///
/// Values are written with enough digits to round-trip f64 exactly (so a
/// compensated output read back is bit-identical to what the kernel produced).
pub fn write_signal_csv(path: &Path, rec: &SignalRecord) -> Result<()> {
    let n = rec.len();
    if rec.channels.iter().any(|c| c.1.len() != n) || rec.t_s.as_ref().is_some_and(|t| t.len() != n) {
        bail!("{}: internal error: channels of different lengths", path.display());
    }
    let axes: Vec<usize> = rec.channels.iter().map(|c| c.0).collect();
    write_atomic(path, |w| {
        let mut cw = CsvWriter::new(w, &axes, rec.t_s.is_some())?;
        let chans: Vec<&[f64]> = rec.channels.iter().map(|c| c.1.as_slice()).collect();
        cw.write_block(rec.t_s.as_deref(), &chans)?;
        cw.finish()
    })
}
