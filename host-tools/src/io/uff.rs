//! Universal File Format dataset 58 ("function at nodal DOF") FRF import/export,
//! ASCII (58) and binary (58b), as exported by LMS Testlab / Simcenter, m+p,
//! B&K and pyuff (DESIGN.md, "CLI contract"). A leaf of the chain: it reads and
//! writes [`Frf`] and imports only `frf` and its `io` siblings.
//!
//! Every error is one line naming the file, the line, the dataset and record,
//! and the problem. Parsers never panic, whatever the input.

use std::io::Write;
use std::path::Path;

use anyhow::{anyhow, bail, Context, Result};
use num_complex::Complex64;

use super::frf_csv::{validate_frf, COHERENCE_SLACK};
use crate::frf::{axis_name, entry_name, AxisFrf, CrossFrf, Frf};

/// Read an FRF (+ coherence) from a UFF file with datasets 58/58b.
pub fn read_uff58(path: &Path) -> Result<Frf> {
    let bytes = std::fs::read(path).with_context(|| format!("{}: cannot read", path.display()))?;
    parse_uff58(&bytes, &path.display().to_string())
}

/// True if the first non-blank line of `bytes` is a UFF block delimiter `-1`.
pub fn looks_like_uff(bytes: &[u8]) -> bool {
    let mut cur = Cursor { data: bytes, pos: 0 };
    while let Some((_, line)) = cur.next_line() {
        let t = trim(line);
        if !t.is_empty() {
            return t == b"-1";
        }
    }
    false
}

// ---------------------------------------------------------------------------
// Reading

struct Cursor<'a> {
    data: &'a [u8],
    pos: usize,
}

impl<'a> Cursor<'a> {
    /// Next line (without `\n` / `\r\n`) and the offset of its first byte.
    fn next_line(&mut self) -> Option<(usize, &'a [u8])> {
        if self.pos >= self.data.len() {
            return None;
        }
        let start = self.pos;
        let rest = &self.data[start..];
        let (line, adv) = match rest.iter().position(|&b| b == b'\n') {
            Some(i) => (&rest[..i], i + 1),
            None => (rest, rest.len()),
        };
        self.pos += adv;
        Some((start, line.strip_suffix(b"\r").unwrap_or(line)))
    }
}

/// 1-based line number of byte offset `off`.
fn line_of(data: &[u8], off: usize) -> usize {
    1 + data[..off.min(data.len())].iter().filter(|&&b| b == b'\n').count()
}

fn is_blank(b: u8) -> bool {
    b.is_ascii_whitespace() || b == 0 || b == 0x1a
}

pub(super) fn trim(mut b: &[u8]) -> &[u8] {
    while let [first, rest @ ..] = b {
        if is_blank(*first) {
            b = rest;
        } else {
            break;
        }
    }
    while let [rest @ .., last] = b {
        if is_blank(*last) {
            b = rest;
        } else {
            break;
        }
    }
    b
}

/// A short printable rendering of a line for error messages.
pub(super) fn show(line: &[u8]) -> String {
    let s = String::from_utf8_lossy(line);
    let s = s.trim();
    let mut out: String = s.chars().take(40).map(|c| if c.is_control() { '?' } else { c }).collect();
    if s.chars().count() > 40 {
        out.push('…');
    }
    format!("{out:?}")
}

/// The fixed-width field `[start, start + width)` of a record, trimmed.
pub(super) fn field(line: &[u8], start: usize, width: usize) -> Option<&str> {
    let end = (start + width).min(line.len());
    let bytes = line.get(start..end)?;
    std::str::from_utf8(bytes).ok().map(str::trim)
}

pub(super) fn parse_int(s: &str) -> Option<i64> {
    s.trim().parse().ok()
}

/// A Fortran-style real: `1.5E+03`, `1.5e3`, `1.5D+03`, `15`.
pub(super) fn parse_real(s: &str) -> Option<f64> {
    let s = s.trim();
    if s.is_empty() {
        return None;
    }
    if s.contains(['D', 'd']) {
        s.replace(['D', 'd'], "e").parse().ok()
    } else {
        s.parse().ok()
    }
}

pub(super) fn tokens(line: &[u8]) -> Vec<&str> {
    std::str::from_utf8(line).map(|s| s.split_whitespace().collect()).unwrap_or_default()
}

/// Where we are, for error messages.
pub(super) struct Ctx<'a> {
    pub(super) source: &'a str,
    pub(super) data: &'a [u8],
    pub(super) no: usize,
    pub(super) line: usize,
}

impl Ctx<'_> {
    /// `file: line L: dataset #k (58 at line S), <what>`
    fn at(&self, off: usize, what: &str) -> String {
        format!(
            "{}: line {}: dataset #{} (58, starting line {}), {what}",
            self.source,
            line_of(self.data, off),
            self.no,
            self.line
        )
    }
}

#[derive(Clone, Copy)]
pub(super) struct BinHeader {
    pub(super) big_endian: bool,
    pub(super) n_ascii_lines: usize,
    pub(super) n_bytes: Option<u64>,
}

/// Parse the fields after `58b` (format I6,I6,I12,I12,...; blanks as fallback).
pub(super) fn parse_bin_header(rest: &[u8], ctx: &Ctx, off: usize) -> Result<BinHeader> {
    let fixed = (
        field(rest, 0, 6).and_then(parse_int),
        field(rest, 6, 6).and_then(parse_int),
        field(rest, 12, 12).and_then(parse_int),
        field(rest, 24, 12).and_then(parse_int),
    );
    let (bo, fp, nl, nb) = match fixed {
        (Some(a), Some(b), Some(c), d) => (a, b, c, d),
        _ => {
            let t = tokens(rest);
            let get = |i: usize| t.get(i).and_then(|s| parse_int(s));
            match (get(0), get(1), get(2)) {
                (Some(a), Some(b), Some(c)) => (a, b, c, get(3)),
                _ => bail!(
                    "{}: cannot read byte order, floating point format and number of ASCII lines \
                     from the 58b header {}",
                    ctx.at(off, "binary header"),
                    show(rest)
                ),
            }
        }
    };
    let big_endian = match bo {
        1 => false,
        2 => true,
        _ => bail!("{}: byte order {bo} unknown (1 = little endian, 2 = big endian)", ctx.at(off, "binary header")),
    };
    if fp != 2 {
        bail!(
            "{}: floating point format {fp} not supported (only 2 = IEEE 754; 1 = DEC VMS, 3 = IBM 370)",
            ctx.at(off, "binary header")
        );
    }
    if !(11..=1000).contains(&nl) {
        bail!("{}: {nl} ASCII lines declared, dataset 58 has 11 (records 1 to 11)", ctx.at(off, "binary header"));
    }
    Ok(BinHeader { big_endian, n_ascii_lines: nl as usize, n_bytes: nb.and_then(|v| u64::try_from(v).ok()) })
}

/// Find a closing `-1` at `pos` (after optional blanks / line breaks); return
/// the offset after its line.
pub(super) fn closing_at(data: &[u8], mut pos: usize) -> Option<usize> {
    while pos < data.len() && matches!(data[pos], b' ' | b'\r' | b'\n') {
        pos += 1;
    }
    if data.get(pos..pos + 2)? != b"-1" {
        return None;
    }
    pos += 2;
    while pos < data.len() && data[pos] != b'\n' {
        if !is_blank(data[pos]) {
            return None;
        }
        pos += 1;
    }
    Some((pos + 1).min(data.len()))
}

/// Skip a dataset other than 58 up to and including its closing `-1`.
fn skip_other(cur: &mut Cursor, ctx: &Ctx, num: u64, binary: bool, rest: &[u8], id_off: usize) -> Result<()> {
    if binary {
        // Another binary dataset: n_ascii_lines ASCII lines, then n_bytes.
        if let Ok(h) = parse_bin_header(rest, ctx, id_off) {
            if let Some(nb) = h.n_bytes {
                for _ in 0..h.n_ascii_lines {
                    if cur.next_line().is_none() {
                        break;
                    }
                }
                let end = usize::try_from(nb).ok().and_then(|nb| cur.pos.checked_add(nb));
                if let Some(next) = end.and_then(|e| closing_at(cur.data, e)) {
                    cur.pos = next;
                    return Ok(());
                }
            }
        }
        // Fall back to looking for the closing line.
    }
    while let Some((_, line)) = cur.next_line() {
        if trim(line) == b"-1" {
            return Ok(());
        }
    }
    bail!(
        "{}: line {}: dataset #{} (type {num}) is not closed by a '    -1' line before the end of the file",
        ctx.source,
        ctx.line,
        ctx.no
    )
}

pub(super) fn spec_type_name(t: i64) -> &'static str {
    match t {
        0 => "unknown",
        1 => "general",
        2 => "stress",
        3 => "strain",
        5 => "temperature",
        6 => "heat flux",
        8 => "displacement",
        9 => "reaction force",
        11 => "velocity",
        12 => "acceleration",
        13 => "excitation force",
        15 => "pressure",
        16 => "mass",
        17 => "time",
        18 => "frequency",
        19 => "rpm",
        20 => "order",
        _ => "an unlisted quantity",
    }
}

pub(super) fn function_type_name(t: i64) -> &'static str {
    match t {
        0 => "general",
        1 => "time response",
        2 => "auto spectrum",
        3 => "cross spectrum",
        4 => "FRF",
        5 => "transmissibility",
        6 => "coherence",
        7 => "auto correlation",
        8 => "cross correlation",
        9 => "PSD",
        12 => "spectrum",
        18 => "mode indicator function",
        26 => "multiple coherence",
        _ => "other",
    }
}

/// Units labels that are obviously not a force (FRF ordinate must be N/N).
fn obviously_not_force(label: &str) -> bool {
    let l = label.trim().to_ascii_lowercase();
    if l.is_empty() || l == "none" {
        return false;
    }
    const NOT: [&str; 12] = ["m/s", "mm", "µm", "um", "in/", "/s", "s^2", "pa", "mv", "v/", "g/", "m/n"];
    NOT.iter().any(|p| l.contains(p)) || ["g", "m", "v", "in", "s", "rad"].contains(&l.as_str())
}

/// A units label as exported (trimmed), or `None` when it is blank or `NONE`.
fn units_label(label: &str) -> Option<String> {
    let t = label.trim();
    (!t.is_empty() && !t.eq_ignore_ascii_case("none")).then(|| t.to_string())
}

/// Data characteristics record (8 to 11): specific data type and units label.
pub(super) fn data_characteristics(line: &[u8]) -> (Option<i64>, String) {
    let spec = field(line, 0, 10).and_then(parse_int).or_else(|| tokens(line).first().and_then(|t| parse_int(t)));
    let units = field(line, 46, 21).unwrap_or("").to_string();
    (spec, units)
}

enum Found58 {
    Skipped(String),
    Frf { entry: usize, freq: Vec<f64>, frf: Vec<Complex64>, units: Option<String> },
    Coh { entry: usize, freq: Vec<f64>, coh: Vec<f64> },
}

/// Record 6 (DOF identification, Format(2(I5,I10),2(1X,10A1,I10,I4))):
/// function type, response direction, reference direction.
pub(super) fn record6(r6: &[u8]) -> Option<(i64, i64, i64)> {
    let fixed6 = (
        field(r6, 0, 5).and_then(parse_int),
        field(r6, 51, 4).and_then(parse_int),
        field(r6, 76, 4).and_then(parse_int),
    );
    match fixed6 {
        (Some(f), Some(d), Some(r)) => Some((f, d, r)),
        _ => {
            let t = tokens(r6);
            let get = |i: usize| t.get(i).and_then(|s| parse_int(s));
            match (get(0), get(6), get(9)) {
                (Some(f), Some(d), Some(r)) if t.len() == 10 => Some((f, d, r)),
                _ => None,
            }
        }
    }
}

/// Record 7 (data form, Format(3I10,3E13.5)): ordinate data type, number
/// of points, spacing (1 = even), abscissa minimum and increment.
pub(super) fn record7(r7: &[u8]) -> Option<(i64, i64, i64, f64, f64)> {
    let fixed7 = (
        field(r7, 0, 10).and_then(parse_int),
        field(r7, 10, 10).and_then(parse_int),
        field(r7, 20, 10).and_then(parse_int),
        field(r7, 30, 13).and_then(parse_real),
        field(r7, 43, 13).and_then(parse_real),
    );
    match fixed7 {
        (Some(a), Some(b), Some(c), Some(d), Some(e)) => Some((a, b, c, d, e)),
        _ => {
            let t = tokens(r7);
            let gi = |i: usize| t.get(i).and_then(|s| parse_int(s));
            let gr = |i: usize| t.get(i).and_then(|s| parse_real(s));
            match (gi(0), gi(1), gi(2), gr(3), gr(4)) {
                (Some(a), Some(b), Some(c), Some(d), Some(e)) => Some((a, b, c, d, e)),
                _ => None,
            }
        }
    }
}

/// Parse one dataset 58 whose id line was just read: header records 1 to 11,
/// data (record 12), then the checks of units, values and abscissa.
fn parse58(cur: &mut Cursor, ctx: &Ctx, bin: Option<BinHeader>) -> Result<Found58> {
    let recs = header_records(cur, ctx, bin)?;
    let dof = dof_id(ctx, recs[5])?;
    let form = data_form(ctx, recs[6])?;
    let target = target(ctx, &dof);
    let keep = matches!(target, Target::Entry(_));
    let values = match bin {
        Some(h) => binary_values(cur, ctx, &form, h, keep)?,
        None => ascii_values(cur, ctx, &form, keep)?,
    };
    let entry = match target {
        Target::Entry(entry) => entry,
        Target::Skip(note) => return Ok(Found58::Skipped(note)),
    };
    check_abscissa(ctx, recs[7])?;
    let units = if dof.func_type == 4 { frf_units(ctx, &recs)? } else { None };
    check_finite(ctx, &values, bin.is_some())?;
    let freq = frequencies(ctx, &form, &values)?;
    if dof.func_type == 4 {
        Ok(frf_found(&form, &dof, &values, entry, freq, units))
    } else {
        coherence_found(ctx, &form, &values, entry, freq)
    }
}

/// Header lines of a dataset 58, each with the offset of its line: records
/// 1 to 11 (58b: the first 11 of its ASCII lines).
type Records<'a> = Vec<(usize, &'a [u8])>;

/// Read the header lines of a dataset 58 (11, or the 58b header's count).
fn header_records<'a>(cur: &mut Cursor<'a>, ctx: &Ctx, bin: Option<BinHeader>) -> Result<Records<'a>> {
    let data = cur.data;
    let n_ascii = bin.map_or(11, |b| b.n_ascii_lines);
    let mut recs: Records<'a> = Vec::with_capacity(11);
    for r in 0..n_ascii {
        let Some((off, line)) = cur.next_line() else {
            bail!(
                "{}: line {}: dataset #{} (58, starting line {}), record {}: the file ends inside the dataset header",
                ctx.source,
                line_of(data, data.len()),
                ctx.no,
                ctx.line,
                r + 1
            );
        };
        if bin.is_none() && trim(line) == b"-1" {
            bail!(
                "{}: the dataset ends ('-1') before its 11 header records",
                ctx.at(off, &format!("record {}", r + 1))
            );
        }
        if r < 11 {
            recs.push((off, line));
        }
    }
    Ok(recs)
}

/// Record 6 (DOF identification): function type, response and reference
/// direction (1/2/3 = +X/+Y/+Z, negative: reversed).
struct DofId {
    func_type: i64,
    rsp_dir: i64,
    ref_dir: i64,
}

/// Read record 6, Format(2(I5,I10),2(1X,10A1,I10,I4)).
fn dof_id(ctx: &Ctx, (off6, r6): (usize, &[u8])) -> Result<DofId> {
    let Some((func_type, rsp_dir, ref_dir)) = record6(r6) else {
        bail!(
            "{}: cannot read function type, response direction and reference direction from {}",
            ctx.at(off6, "record 6"),
            show(r6)
        );
    };
    Ok(DofId { func_type, rsp_dir, ref_dir })
}

/// Record 7 (data form), checked: the layout of the values of record 12.
struct DataForm {
    /// Offset of the record's line, for messages.
    off: usize,
    num_pts: i64,
    complex: bool,
    double: bool,
    /// Even abscissa (minimum + i·increment, Hz); uneven: stored with every point.
    even: bool,
    x_min: f64,
    x_inc: f64,
    /// Values per point: the abscissa if uneven, then re (and im if complex).
    per_point: usize,
    /// Values in record 12.
    total: usize,
}

impl DataForm {
    /// Number of points (frequency lines).
    fn points(&self) -> usize {
        self.total / self.per_point
    }

    /// Ordinate part `j` (0 = re, 1 = im) of point `k`.
    fn ord(&self, vals: &[f64], k: usize, j: usize) -> f64 {
        vals[k * self.per_point + usize::from(!self.even) + j]
    }
}

/// Read and check record 7, Format(3I10,3E13.5): a supported ordinate data
/// type and spacing, and no more values than the file can hold.
///
/// Ordinate data types 2/4 (real single/double) and 5/6 (complex
/// single/double); even abscissa (min + i·increment) or uneven (abscissa stored
/// with every value).
fn data_form(ctx: &Ctx, (off7, r7): (usize, &[u8])) -> Result<DataForm> {
    let Some((ord_type, num_pts, spacing, x_min, x_inc)) = record7(r7) else {
        bail!(
            "{}: cannot read ordinate data type, number of points, spacing, abscissa minimum \
             and increment from {}",
            ctx.at(off7, "record 7"),
            show(r7)
        );
    };
    let (complex, double) = match ord_type {
        2 => (false, false),
        4 => (false, true),
        5 => (true, false),
        6 => (true, true),
        _ => bail!(
            "{}: ordinate data type {ord_type} not supported (2/4 = real single/double, 5/6 = complex single/double)",
            ctx.at(off7, "record 7")
        ),
    };
    let even = match spacing {
        1 => true,
        0 => false,
        _ => bail!("{}: abscissa spacing {spacing} is neither 0 (uneven) nor 1 (even)", ctx.at(off7, "record 7")),
    };
    if num_pts < 1 {
        bail!("{}: number of data points is {num_pts}: no data", ctx.at(off7, "record 7"));
    }
    let per_point = usize::from(!even) + if complex { 2 } else { 1 };
    let total = usize::try_from(num_pts)
        .ok()
        .and_then(|n| n.checked_mul(per_point))
        .filter(|&t| t <= ctx.data.len())
        .ok_or_else(|| {
        anyhow!("{}: {num_pts} data points declared, more than the file can hold", ctx.at(off7, "record 7"))
    })?;
    Ok(DataForm { off: off7, num_pts, complex, double, even, x_min, x_inc, per_point, total })
}

/// What a dataset 58 is used for.
enum Target {
    /// Entry 3·i + j of the FRF matrix: response (channel) i, reference (force) j.
    Entry(usize),
    /// Not used, with the note saying why.
    Skip(String),
}

/// The entry of an FRF or coherence with translational directions; an
/// unknown reference direction (0) is taken as the direct FRF.
///
/// Function type 4 (FRF) and 6 (coherence) are used, others are skipped. Entry
/// G_ij of the FRF matrix: the channel i comes from the response direction, the
/// force (hammer) direction j from the reference direction (record 6),
/// 1/2/3 = +X/+Y/+Z. Equal directions give [`Frf::axes`], different ones
/// [`Frf::cross`]; rotational directions (±4/±5/±6) are skipped.
fn target(ctx: &Ctx, dof: &DofId) -> Target {
    let DofId { func_type, rsp_dir, ref_dir } = *dof;
    let axis = match rsp_dir.abs() {
        d @ 1..=3 => Some((d - 1) as usize),
        _ => None,
    };
    let direction = match ref_dir.abs() {
        0 => axis,
        d @ 1..=3 => Some((d - 1) as usize),
        _ => None,
    };
    match (axis, direction) {
        _ if func_type != 4 && func_type != 6 => Target::Skip(format!(
            "dataset #{} at line {}: function type {func_type} ({})",
            ctx.no,
            ctx.line,
            function_type_name(func_type)
        )),
        (None, _) => Target::Skip(format!(
            "dataset #{} at line {}: response direction {rsp_dir} is not a translation (±1/±2/±3)",
            ctx.no, ctx.line
        )),
        (Some(_), None) => Target::Skip(format!(
            "dataset #{} at line {}: reference direction {ref_dir} is not a translation (±1/±2/±3)",
            ctx.no, ctx.line
        )),
        (Some(i), Some(j)) => Target::Entry(3 * i + j),
    }
}

/// The values of record 12, each with the offset of its line (ASCII) or of
/// the value itself (binary), for messages.
struct Values {
    vals: Vec<f64>,
    offs: Vec<usize>,
}

impl Values {
    fn with_capacity(total: usize) -> Values {
        Values { vals: Vec::with_capacity(total.min(1 << 20)), offs: Vec::with_capacity(total.min(1 << 20)) }
    }
}

/// Record 12 of a 58b dataset: the raw values of record 7's size, then the
/// closing `-1`; the values are decoded only if `keep`.
///
/// The 58b header line `58b byte_order fp_format n_ascii_lines n_bytes 0 0 0 0`
/// is followed by the 11 ASCII records and then the raw values (byte order
/// 1 = little, 2 = big endian; IEEE 754 only). The data size is computed from
/// record 7 (some writers, pyuff among them, put a wrong `n_bytes`), and the
/// closing `-1` may follow directly or after a line break. With an uneven
/// abscissa the abscissa values have the precision of the ordinate (pyuff's
/// convention).
fn binary_values(cur: &mut Cursor, ctx: &Ctx, form: &DataForm, h: BinHeader, keep: bool) -> Result<Values> {
    let data = cur.data;
    let (num_pts, total, double) = (form.num_pts, form.total, form.double);
    let mut v = Values::with_capacity(total);
    let elem = if double { 8 } else { 4 };
    let start = cur.pos;
    let need = total * elem; // total <= data.len(), no overflow
    let avail = data.len() - start;
    if avail < need {
        bail!(
            "{}: record 7 declares {num_pts} points, {need} bytes of binary data, but only {avail} bytes follow",
            ctx.at(start, "record 12")
        );
    }
    let Some(next) = closing_at(data, start + need) else {
        bail!(
            "{}: no closing '    -1' after the {need} bytes of binary data declared by record 7 \
             (the 58b header says {} bytes)",
            ctx.at(start + need, "record 12"),
            h.n_bytes.map_or("?".to_string(), |b| b.to_string())
        );
    };
    if keep {
        for (i, chunk) in data[start..start + need].chunks_exact(elem).enumerate() {
            let x = match (double, h.big_endian) {
                (true, false) => chunk.try_into().map(f64::from_le_bytes).unwrap_or(f64::NAN),
                (true, true) => chunk.try_into().map(f64::from_be_bytes).unwrap_or(f64::NAN),
                (false, false) => chunk.try_into().map(f32::from_le_bytes).map_or(f64::NAN, f64::from),
                (false, true) => chunk.try_into().map(f32::from_be_bytes).map_or(f64::NAN, f64::from),
            };
            v.vals.push(x);
            v.offs.push(start + i * elem);
        }
    }
    cur.pos = next;
    Ok(v)
}

/// Record 12 of an ASCII dataset: numbers up to the closing `-1`, exactly
/// as many as record 7 declares; read only if `keep`.
fn ascii_values(cur: &mut Cursor, ctx: &Ctx, form: &DataForm, keep: bool) -> Result<Values> {
    let (num_pts, total) = (form.num_pts, form.total);
    let mut v = Values::with_capacity(total);
    let widths: &[usize] = match (form.double, form.even, form.complex) {
        (false, _, _) => &[13],
        (true, true, _) => &[20],
        (true, false, false) => &[13, 20],
        (true, false, true) => &[13, 20, 20],
    };
    let mut closed = false;
    while let Some((off, line)) = cur.next_line() {
        let t = trim(line);
        if t == b"-1" {
            closed = true;
            break;
        }
        if !keep || t.is_empty() {
            continue;
        }
        read_numbers(line, widths, &mut v.vals)
            .map_err(|tok| anyhow!("{}: cannot read {} as a number", ctx.at(off, "record 12"), show(tok.as_bytes())))?;
        v.offs.resize(v.vals.len(), off);
        if v.vals.len() > total {
            bail!(
                "{}: more values than the {num_pts} points declared in record 7 ({total} values)",
                ctx.at(off, "record 12")
            );
        }
    }
    if !closed {
        bail!(
            "{}: the dataset is not closed by a '    -1' line before the end of the file",
            ctx.at(cur.data.len(), "record 12")
        );
    }
    if keep && v.vals.len() < total {
        bail!(
            "{}: {} values, but record 7 declares {num_pts} points ({total} values)",
            ctx.at(v.offs.last().copied().unwrap_or(form.off), "record 12"),
            v.vals.len()
        );
    }
    Ok(v)
}

/// Record 8: the abscissa must be frequency (specific data type 18, or
/// unknown/general), in Hz if labelled.
fn check_abscissa(ctx: &Ctx, (off8, r8): (usize, &[u8])) -> Result<()> {
    let (abs_type, abs_units) = data_characteristics(r8);
    if let Some(t) = abs_type.filter(|t| ![0, 1, 18].contains(t)) {
        bail!(
            "{}: the abscissa is {} (specific data type {t}), not frequency",
            ctx.at(off8, "record 8"),
            spec_type_name(t)
        );
    }
    let au = abs_units.to_ascii_lowercase();
    if !au.is_empty() && au != "none" && !au.contains("hz") {
        bail!("{}: abscissa units {abs_units:?} are not Hz", ctx.at(off8, "record 8"));
    }
    Ok(())
}

/// Records 9 and 10 of an FRF: numerator and denominator must be forces
/// (force over force, N/N). Returns the units as labelled, e.g. "N/N";
/// None when either is unlabelled.
///
/// Reaction or excitation force, or unknown/general, are accepted; anything else
/// (e.g. an accelerance) is refused with a message saying so.
fn frf_units(ctx: &Ctx, recs: &Records) -> Result<Option<String>> {
    let mut labels = Vec::new();
    for (r, part) in [(8usize, "numerator"), (9, "denominator")] {
        let (off, line) = recs[r];
        let (t, units) = data_characteristics(line);
        if let Some(t) = t.filter(|t| ![0, 1, 9, 13].contains(t)) {
            bail!(
                "{}: the FRF {part} is {} (specific data type {t}), not a force: \
                 dynocomp needs the dynamometer's force/force FRF (N/N)",
                ctx.at(off, &format!("record {}", r + 1)),
                spec_type_name(t)
            );
        }
        if obviously_not_force(&units) {
            bail!(
                "{}: the FRF {part} units {units:?} are not a force: \
                 dynocomp needs the dynamometer's force/force FRF (N/N)",
                ctx.at(off, &format!("record {}", r + 1))
            );
        }
        labels.push(units_label(&units));
    }
    Ok(match labels.as_slice() {
        [Some(n), Some(d)] => Some(format!("{n}/{d}")),
        _ => None,
    })
}

/// Every value of record 12 finite; a binary value is named by its byte offset.
fn check_finite(ctx: &Ctx, v: &Values, binary: bool) -> Result<()> {
    if let Some(i) = v.vals.iter().position(|x| !x.is_finite()) {
        let what = if binary {
            format!("record 12 (binary value {} at byte offset {})", i + 1, v.offs[i])
        } else {
            "record 12".to_string()
        };
        bail!("{}: value {} is {} (values must be finite)", ctx.at(v.offs[i], &what), i + 1, v.vals[i]);
    }
    Ok(())
}

/// The frequency lines (Hz): from record 7's minimum and increment when even,
/// else the abscissa of every point of record 12; non-negative, strictly
/// ascending.
fn frequencies(ctx: &Ctx, form: &DataForm, v: &Values) -> Result<Vec<f64>> {
    let (n, x_min, x_inc) = (form.points(), form.x_min, form.x_inc);
    if form.even {
        if x_min < 0.0 || !x_min.is_finite() {
            bail!("{}: abscissa minimum {x_min} Hz is not a non-negative frequency", ctx.at(form.off, "record 7"));
        }
        if n > 1 && !(x_inc > 0.0 && x_inc.is_finite()) {
            bail!(
                "{}: abscissa increment {x_inc} Hz must be positive (frequencies strictly ascending)",
                ctx.at(form.off, "record 7")
            );
        }
        return Ok((0..n).map(|i| x_min + i as f64 * x_inc).collect());
    }
    let f: Vec<f64> = v.vals.iter().step_by(form.per_point).copied().collect();
    for i in 0..f.len() {
        let o = v.offs[i * form.per_point];
        if f[i] < 0.0 {
            bail!("{}: negative frequency {} Hz", ctx.at(o, "record 12"), f[i]);
        }
        if i > 0 && f[i] <= f[i - 1] {
            bail!(
                "{}: frequency {} Hz is not greater than the previous point's {} Hz \
                 (frequencies must be strictly ascending)",
                ctx.at(o, "record 12"),
                f[i],
                f[i - 1]
            );
        }
    }
    Ok(f)
}

/// An FRF dataset: H = (s_rsp · response) / (s_ref · force), the direction
/// signs undone.
///
/// A negative direction (-1/-2/-3) flips the sign of the FRF (not of the
/// coherence), so the FRF returned is always the +i response over the +j force.
fn frf_found(form: &DataForm, dof: &DofId, v: &Values, entry: usize, freq: Vec<f64>, units: Option<String>) -> Found58 {
    let sign = dof.rsp_dir.signum() * if dof.ref_dir < 0 { -1 } else { 1 };
    let s = sign as f64;
    let frf = (0..form.points())
        .map(|k| {
            let re = form.ord(&v.vals, k, 0);
            let x = if form.complex { Complex64::new(re, form.ord(&v.vals, k, 1)) } else { Complex64::new(re, 0.0) };
            x * s
        })
        .collect();
    Found58::Frf { entry, freq, frf, units }
}

/// A coherence dataset: real, within [0, 1] up to [`COHERENCE_SLACK`] (clamped).
fn coherence_found(ctx: &Ctx, form: &DataForm, v: &Values, entry: usize, freq: Vec<f64>) -> Result<Found58> {
    let mut coh = Vec::with_capacity(freq.len());
    for (k, f) in freq.iter().enumerate() {
        let o = v.offs[k * form.per_point];
        let c = form.ord(&v.vals, k, 0);
        if form.complex && form.ord(&v.vals, k, 1) != 0.0 {
            bail!(
                "{}: coherence at point {} has a non-zero imaginary part {}",
                ctx.at(o, "record 12"),
                k + 1,
                form.ord(&v.vals, k, 1)
            );
        }
        if !(-COHERENCE_SLACK..=1.0 + COHERENCE_SLACK).contains(&c) {
            bail!("{}: coherence {c} at point {} ({} Hz) outside [0, 1]", ctx.at(o, "record 12"), k + 1, f);
        }
        coh.push(c.clamp(0.0, 1.0));
    }
    Ok(Found58::Coh { entry, freq, coh })
}

/// Numbers of one ASCII data line: split at blanks; if a token does not
/// parse (fields touching), the line is cut at the fixed Fortran widths.
/// On failure returns the offending token.
///
/// The Fortran widths are those of the ASCII records (E13.5 / E20.12).
pub(super) fn read_numbers(line: &[u8], widths: &[usize], out: &mut Vec<f64>) -> std::result::Result<(), String> {
    let Ok(text) = std::str::from_utf8(line) else {
        return Err(String::from_utf8_lossy(line).into_owned());
    };
    let mut tmp = Vec::new();
    let mut bad = None;
    for t in text.split_whitespace() {
        match parse_real(t) {
            Some(v) => tmp.push(v),
            None => {
                bad = Some(t.to_string());
                break;
            }
        }
    }
    if bad.is_none() {
        out.extend(tmp);
        return Ok(());
    }
    // Fixed widths.
    tmp.clear();
    let b = text.as_bytes();
    let mut pos = 0;
    let mut k = 0;
    while pos < b.len() {
        let w = widths[k % widths.len()];
        let end = (pos + w).min(b.len());
        let f = text.get(pos..end).unwrap_or("");
        if !f.trim().is_empty() {
            match parse_real(f) {
                Some(v) => tmp.push(v),
                None => return Err(bad.unwrap_or_else(|| f.trim().to_string())),
            }
        }
        pos = end;
        k += 1;
    }
    out.extend(tmp);
    Ok(())
}

/// Parse a UFF file (ASCII and/or binary datasets) from memory; `source`
/// names the input in error messages.
pub fn parse_uff58(bytes: &[u8], source: &str) -> Result<Frf> {
    parse_uff58_units(bytes, source).map(|(frf, _)| frf)
}

/// What one FRF or coherence dataset of a file is, for error messages.
struct Item {
    no: usize,
    line: usize,
    entry: usize,
    freq: Vec<f64>,
    what: &'static str,
}

impl Item {
    /// "axis x" for a direct entry, "entry xy (channel x, force y)" otherwise.
    fn name(&self) -> String {
        entry_label(self.entry)
    }
}

/// "axis x" for the direct entry xx, "entry xy (channel x, force y)" for a cross one.
fn entry_label(entry: usize) -> String {
    let (i, j) = (entry / 3, entry % 3);
    if i == j {
        format!("axis {}", axis_name(i))
    } else {
        format!("entry {} (channel {}, force {})", entry_name(i, j), axis_name(i), axis_name(j))
    }
}

/// [`parse_uff58`], also returning the FRFs' force units as labelled in
/// records 9 and 10 (e.g. `"N/N"`), or `None` when no FRF labels both. FRFs
/// of one file labelled with different units are refused.
pub fn parse_uff58_units(bytes: &[u8], source: &str) -> Result<(Frf, Option<String>)> {
    if trim(bytes).is_empty() {
        bail!("{source}: empty file");
    }
    let mut cur = Cursor { data: bytes, pos: 0 };
    let mut sets = Datasets::default();
    while let Some(id) = next_dataset(&mut cur, source)? {
        sets.count += 1;
        let ctx = Ctx { source, data: bytes, no: sets.count, line: id.line };
        if id.num != 58 {
            skip_other(&mut cur, &ctx, id.num, id.binary, id.rest, id.off)?;
            sets.skipped.push(format!("dataset #{} at line {}: type {}", ctx.no, ctx.line, id.num));
            continue;
        }
        let bin = if id.binary { Some(parse_bin_header(id.rest, &ctx, id.off)?) } else { None };
        sets.add(parse58(&mut cur, &ctx, bin)?, &ctx)?;
    }
    if sets.count == 0 {
        bail!("{source}: no UFF dataset found");
    }
    sets.into_frf(source)
}

/// The opening `-1` and the dataset number line of a block.
struct DatasetId<'a> {
    /// Line of the opening `-1`.
    line: usize,
    /// Offset of the dataset number line.
    off: usize,
    num: u64,
    /// `58b`-style binary dataset.
    binary: bool,
    /// The rest of the number line (the binary header's fields).
    rest: &'a [u8],
}

/// Read the next block's `-1` and dataset number; None at the end of the file.
///
/// A UFF file is a sequence of blocks, each between two `    -1` lines; the
/// line after the opening `-1` holds the dataset number (`58`, or `58b ...` for
/// binary). Datasets other than 58 (151 header, 164 units, geometry, ...) are
/// skipped.
fn next_dataset<'a>(cur: &mut Cursor<'a>, source: &str) -> Result<Option<DatasetId<'a>>> {
    let bytes = cur.data;
    let (off, t) = loop {
        match cur.next_line() {
            Some((off, line)) if !trim(line).is_empty() => break (off, trim(line)),
            Some(_) => continue,
            None => return Ok(None),
        }
    };
    let start_line = line_of(bytes, off);
    if t != b"-1" {
        bail!("{source}: line {start_line}: expected '    -1' opening a UFF dataset, found {}", show(t));
    }
    // The dataset number line; a lone trailing "-1" ends the file.
    let (id_off, id) = loop {
        match cur.next_line() {
            Some((o, l)) if !trim(l).is_empty() => break (o, l),
            Some(_) => continue,
            None => bail!("{source}: line {start_line}: the file ends after '-1' (dataset number missing)"),
        }
    };
    let idt = trim(id);
    let digits = idt.iter().take_while(|b| b.is_ascii_digit()).count();
    let num: Option<u64> = std::str::from_utf8(&idt[..digits]).ok().and_then(|s| s.parse().ok());
    let Some(num) = num.filter(|_| digits <= 6) else {
        bail!("{source}: line {}: expected a dataset number after '-1', found {}", line_of(bytes, id_off), show(idt));
    };
    let rest = &idt[digits..];
    let binary = matches!(rest.first(), Some(b'b' | b'B'));
    let rest = if binary { &rest[1..] } else { rest };
    Ok(Some(DatasetId { line: start_line, off: id_off, num, binary, rest }))
}

/// The datasets of a file so far: FRFs and coherences by entry, notes on
/// those skipped, and the first FRF's units label.
#[derive(Default)]
struct Datasets {
    /// Datasets read (of any type).
    count: usize,
    skipped: Vec<String>,
    frfs: [Option<(Item, Vec<Complex64>)>; 9],
    cohs: [Option<(Item, Vec<f64>)>; 9],
    /// The first units label, with its dataset number and line.
    units: Option<(String, usize, usize)>,
}

impl Datasets {
    /// Add the dataset 58 of `ctx`: refuse a second FRF or coherence of an
    /// entry, and FRFs labelled in other units than the first.
    fn add(&mut self, found: Found58, ctx: &Ctx) -> Result<()> {
        let item =
            |entry: usize, freq: Vec<f64>, what: &'static str| Item { no: ctx.no, line: ctx.line, entry, freq, what };
        match found {
            Found58::Skipped(note) => self.skipped.push(note),
            Found58::Frf { entry, freq, frf, units } => {
                if let Some(u) = units {
                    self.check_units(u, entry, ctx)?;
                }
                store(&mut self.frfs[entry], (item(entry, freq, "FRF"), frf), ctx.source)?
            }
            Found58::Coh { entry, freq, coh } => {
                store(&mut self.cohs[entry], (item(entry, freq, "coherence"), coh), ctx.source)?
            }
        }
        Ok(())
    }

    /// Units `u` of the FRF of `entry` must be the first FRF's, if labelled.
    fn check_units(&mut self, u: String, entry: usize, ctx: &Ctx) -> Result<()> {
        match &self.units {
            Some((first, no, line)) if !first.eq_ignore_ascii_case(&u) => bail!(
                "{}: line {}: dataset #{} ({}) is in units {}, but dataset #{no} \
                 (line {line}) in {}: export every FRF of the file in the same units (N/N)",
                ctx.source,
                ctx.line,
                ctx.no,
                entry_label(entry),
                super::one_line(&u),
                super::one_line(first)
            ),
            Some(_) => {}
            None => self.units = Some((u, ctx.no, ctx.line)),
        }
        Ok(())
    }

    /// The FRF matrix: every dataset on the first FRF's frequency lines,
    /// every coherence with its FRF.
    fn into_frf(mut self, source: &str) -> Result<(Frf, Option<String>)> {
        // The reference frequency lines: the first FRF in the file.
        let Some(reference) = self.frfs.iter().flatten().map(|(it, _)| it).min_by_key(|it| it.no) else {
            bail!(no_frf_message(source, &self.skipped));
        };
        self.check_lines(source, reference)?;
        let freq_hz = reference.freq.clone();
        let mut axes = Vec::new();
        let mut cross = Vec::new();
        for entry in 0..9 {
            if let Some((_, frf)) = self.frfs[entry].take() {
                let coherence = self.cohs[entry].take().map(|(_, c)| c);
                let (i, j) = (entry / 3, entry % 3);
                if i == j {
                    axes.push(AxisFrf { axis: i, frf, coherence });
                } else {
                    cross.push(CrossFrf { channel: i, direction: j, frf, coherence });
                }
            }
        }
        Ok((Frf { freq_hz, axes, cross }, self.units.map(|(u, _, _)| u)))
    }

    /// Every FRF and coherence on the lines of `reference`; no coherence
    /// without the FRF of its entry.
    fn check_lines(&self, source: &str, reference: &Item) -> Result<()> {
        for entry in 0..9 {
            if let Some((it, _)) = &self.frfs[entry] {
                same_lines(source, reference, it)?;
            }
            if let Some((it, _)) = &self.cohs[entry] {
                if self.frfs[entry].is_none() {
                    let (i, j) = (entry / 3, entry % 3);
                    let what = match i == j {
                        true => format!("axis {}", axis_name(i)),
                        false => format!("entry {}", entry_name(i, j)),
                    };
                    bail!(
                        "{source}: line {}: dataset #{} is a coherence for {} but the file has no FRF for {}",
                        it.line,
                        it.no,
                        it.name(),
                        what
                    );
                }
                same_lines(source, reference, it)?;
            }
        }
        Ok(())
    }
}

/// Store a dataset for its entry, refusing a second one of the same kind.
fn store<T>(slot: &mut Option<(Item, T)>, new: (Item, T), source: &str) -> Result<()> {
    if let Some((p, _)) = slot {
        let n = &new.0;
        let dup = if n.entry / 3 == n.entry % 3 { "duplicate axis" } else { "duplicate entry" };
        bail!(
            "{source}: line {}: dataset #{} is a second {} for {} \
             (the first is dataset #{} at line {}): {dup}",
            n.line,
            n.no,
            n.what,
            n.name(),
            p.no,
            p.line
        );
    }
    *slot = Some(new);
    Ok(())
}

/// The message for a file without FRF, listing up to four datasets skipped.
fn no_frf_message(source: &str, skipped: &[String]) -> String {
    let mut msg =
        format!("{source}: no FRF found (dataset 58 with function type 4 and response direction ±1, ±2 or ±3)");
    if !skipped.is_empty() {
        let shown: Vec<&str> = skipped.iter().take(4).map(String::as_str).collect();
        msg.push_str(&format!("; skipped {}", shown.join("; ")));
        if skipped.len() > 4 {
            msg.push_str(&format!("; and {} more", skipped.len() - 4));
        }
    }
    msg
}

/// Dataset `it` has the frequency lines of `reference` (to 1e-6 of the highest).
fn same_lines(source: &str, reference: &Item, it: &Item) -> Result<()> {
    let (a, b) = (&reference.freq, &it.freq);
    let head = || format!("{source}: line {}: dataset #{} ({} {})", it.line, it.no, it.what, short(it.entry));
    if a.len() != b.len() {
        bail!(
            "{}: {} frequency lines, but dataset #{} (FRF {}, line {}) has {}: \
             all datasets must share the same frequency lines",
            head(),
            b.len(),
            reference.no,
            short(reference.entry),
            reference.line,
            a.len()
        );
    }
    let scale = a.last().copied().unwrap_or(0.0).abs().max(b.last().copied().unwrap_or(0.0).abs());
    if let Some(i) = (0..a.len()).find(|&i| (a[i] - b[i]).abs() > 1e-6 * scale) {
        bail!(
            "{}: frequency line {} is {} Hz, but {} Hz in dataset #{} (FRF {}, line {}): \
             all datasets must share the same frequency lines",
            head(),
            i + 1,
            b[i],
            a[i],
            reference.no,
            short(reference.entry),
            reference.line
        );
    }
    Ok(())
}

/// The short name of an entry in messages: `x` for the direct entry xx (as
/// before the matrix existed), `xy` for a cross entry.
fn short(entry: usize) -> String {
    let (i, j) = (entry / 3, entry % 3);
    if i == j {
        axis_name(i).to_string()
    } else {
        entry_name(i, j)
    }
}

// ---------------------------------------------------------------------------
// Writing

/// Write `frf` as UFF datasets 58 (ASCII) or 58b (binary, little endian,
/// IEEE 754 double), atomically: per entry G_ij, row by row, an FRF (function
/// type 4, complex double) and, if present, its coherence (function type 6,
/// real double); response direction i + 1, reference direction j + 1 (+X/+Y/+Z),
/// node 1. The frequency lines must
/// be evenly spaced (the abscissa is written as minimum and increment, with 7
/// significant digits).
pub fn write_uff58(path: &Path, frf: &Frf, binary: bool) -> Result<()> {
    let bytes = uff58_to_bytes(frf, binary).map_err(|e| anyhow!("{}: not written: {e:#}", path.display()))?;
    super::atomic::write_atomic(path, |w: &mut dyn Write| {
        w.write_all(&bytes)?;
        Ok(())
    })
}

/// The bytes [`write_uff58`] writes.
pub fn uff58_to_bytes(frf: &Frf, binary: bool) -> Result<Vec<u8>> {
    validate_frf(frf)?;
    let f = &frf.freq_hz;
    let n = f.len();
    let f0 = f[0];
    let df = if n > 1 { (f[n - 1] - f0) / (n - 1) as f64 } else { 1.0 };
    if let Some(i) = (0..n).find(|&i| (f[i] - (f0 + i as f64 * df)).abs() > 1e-6 * df) {
        bail!(
            "UFF 58 export requires evenly spaced frequency lines, but line {} is {} Hz where a spacing of \
             {df} Hz from {f0} Hz puts {} Hz (use the CSV format for uneven lines)",
            i + 1,
            f[i],
            f0 + i as f64 * df
        );
    }
    let mut out = Vec::new();
    let mut func_id = 0;
    for e in frf.entries() {
        let entry = (e.channel, e.direction);
        func_id += 1;
        let vals: Vec<f64> = e.frf.iter().flat_map(|v| [v.re, v.im]).collect();
        write_dataset(&mut out, 4, func_id, entry, 6, n, f0, df, &vals, binary);
        if let Some(c) = e.coherence {
            func_id += 1;
            write_dataset(&mut out, 6, func_id, entry, 4, n, f0, df, c, binary);
        }
    }
    Ok(out)
}

/// Fortran `Ew.d`: `d` decimals, two- (or three-) digit exponent, right-aligned in `w`.
pub(super) fn fmt_e(x: f64, decimals: usize, width: usize) -> String {
    let mut out = String::with_capacity(width);
    push_e(&mut out, &mut String::new(), x, decimals, width);
    out
}

/// [`fmt_e`], appended to `out` (`scratch`: a reusable buffer), without
/// allocating once the buffers have grown: the time-history writer formats
/// millions of values.
pub(super) fn push_e(out: &mut String, scratch: &mut String, x: f64, decimals: usize, width: usize) {
    use std::fmt::Write as _;
    scratch.clear();
    let _ = write!(scratch, "{x:.decimals$e}");
    let (mant, exp) = scratch.split_once('e').unwrap_or((scratch.as_str(), "0"));
    let exp: i32 = exp.parse().unwrap_or(0);
    // Exponent: sign and at least two digits (Fortran E format).
    let digits = if exp.abs() >= 100 { 3 } else { 2 };
    let len = mant.len() + 2 + digits;
    for _ in len..width {
        out.push(' ');
    }
    let _ = write!(out, "{mant}e{}{:02}", if exp < 0 { '-' } else { '+' }, exp.abs());
}

/// The `-1` line, id line and the 11 header records of a dataset 58:
/// (function type, function id, direction, ID line 1), (ordinate data type,
/// points, abscissa minimum, increment), records 8-11 as (specific data
/// type, label, units), and for 58b the number of data bytes.
pub(super) fn dataset_header(
    (func_type, func_id, dir, id1): (i64, i64, i64, &str),
    (ord_type, n, x0, dx): (i64, usize, f64, f64),
    recs: [(i64, &str, &str); 4],
    binary_bytes: Option<usize>,
) -> String {
    dataset_header_ref((func_type, func_id, (dir, dir), id1), (ord_type, n, x0, dx), recs, binary_bytes)
}

/// [`dataset_header`] with a response and a reference direction of their own
/// (record 6): an FRF G_ij has response direction i + 1, reference j + 1.
pub(super) fn dataset_header_ref(
    (func_type, func_id, (dir, ref_dir), id1): (i64, i64, (i64, i64), &str),
    (ord_type, n, x0, dx): (i64, usize, f64, f64),
    recs: [(i64, &str, &str); 4],
    binary_bytes: Option<usize>,
) -> String {
    let mut s = String::new();
    s.push_str(&format!("{:>6}\n", -1));
    match binary_bytes {
        Some(nb) => {
            s.push_str(&format!("{:>6}b{:>6}{:>6}{:>12}{:>12}{:>6}{:>6}{:>12}{:>12}\n", 58, 1, 2, 11, nb, 0, 0, 0, 0))
        }
        None => s.push_str(&format!("{:>6}{:74}\n", 58, "")),
    }
    for id in [id1, "NONE", "NONE", "NONE", "NONE"] {
        s.push_str(&format!("{id:<80}\n"));
    }
    s.push_str(&format!(
        "{:>5}{:>10}{:>5}{:>10} {:>10}{:>10}{:>4} {:>10}{:>10}{:>4}\n",
        func_type, func_id, 0, 0, "DYN", 1, dir, "HAMMER", 1, ref_dir
    ));
    s.push_str(&format!(
        "{:>10}{:>10}{:>10}{}{}{}\n",
        ord_type,
        n,
        1,
        fmt_e(x0, 6, 13),
        fmt_e(dx, 6, 13),
        fmt_e(0.0, 6, 13)
    ));
    for (spec, label, units) in recs {
        s.push_str(&format!("{:>10}{:>5}{:>5}{:>5} {:<20} {:<20}\n", spec, 0, 0, 0, label, units));
    }
    s
}

#[allow(clippy::too_many_arguments)]
fn write_dataset(
    out: &mut Vec<u8>,
    func_type: i64,
    func_id: i64,
    (channel, direction): (usize, usize),
    ord_type: i64,
    n: usize,
    f0: f64,
    df: f64,
    vals: &[f64],
    binary: bool,
) {
    let (what, num, den) = if func_type == 4 {
        ("FRF", (9, "Force", "N"), (13, "Force", "N"))
    } else {
        ("coherence", (0, "Coherence", "NONE"), (0, "NONE", "NONE"))
    };
    // A direct entry keeps the one-letter name of the files written before
    // the matrix existed.
    let name = if channel == direction { axis_name(channel).to_string() } else { entry_name(channel, direction) };
    let id1 = format!("dynocomp {what} {name}");
    let dirs = (channel as i64 + 1, direction as i64 + 1);
    let s = dataset_header_ref(
        (func_type, func_id, dirs, &id1),
        (ord_type, n, f0, df),
        [(18, "Frequency", "Hz"), num, den, (0, "NONE", "NONE")],
        binary.then_some(vals.len() * 8),
    );
    out.extend_from_slice(s.as_bytes());
    if binary {
        for v in vals {
            out.extend_from_slice(&v.to_le_bytes());
        }
    } else {
        let mut line = String::new();
        for chunk in vals.chunks(4) {
            line.clear();
            for v in chunk {
                line.push_str(&fmt_e(*v, 12, 20));
            }
            line.push('\n');
            out.extend_from_slice(line.as_bytes());
        }
    }
    out.extend_from_slice(format!("{:>6}\n", -1).as_bytes());
}
