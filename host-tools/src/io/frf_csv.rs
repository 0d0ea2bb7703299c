//! FRF CSV import/export (DESIGN.md, "CLI contract"): the format is
//! [`parse_frf_csv`]'s, written by [`write_frf_csv`]. A leaf of the chain.
//! Every error names the file, the line and, for a value, the column.

use std::io::Write;
use std::path::Path;

use anyhow::{anyhow, bail, Context, Result};
use num_complex::Complex64;

use crate::frf::{axis_name, entry_name, AxisFrf, CrossFrf, Frf};

/// Coherence values this far outside [0, 1] are taken as rounding of the
/// exporting analyser and clamped; anything further out is an error.
pub(crate) const COHERENCE_SLACK: f64 = 1e-6;

/// Read an FRF CSV file.
pub fn read_frf_csv(path: &Path) -> Result<Frf> {
    let bytes = std::fs::read(path).with_context(|| format!("{}: cannot read", path.display()))?;
    parse_frf_csv_bytes(&bytes, &path.display().to_string())
}

/// Parse FRF CSV from raw bytes (must be UTF-8); `source` names the input in errors.
pub fn parse_frf_csv_bytes(bytes: &[u8], source: &str) -> Result<Frf> {
    match std::str::from_utf8(bytes) {
        Ok(text) => parse_frf_csv(text, source),
        Err(e) => {
            let off = e.valid_up_to();
            let line = 1 + bytes[..off].iter().filter(|&&b| b == b'\n').count();
            bail!("{source}: line {line}: not a text (UTF-8) CSV file (invalid byte at offset {off})")
        }
    }
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum Kind {
    Re,
    Im,
    Coh,
}

/// Parse FRF CSV text; `source` names the input (file name) in error messages.
///
/// Format: one header row, then one row per frequency line:
///
/// ```text
/// freq_hz,x_re,x_im,x_coh,y_re,y_im,z_re,z_im,z_coh
/// 0.0,1.0,0.0,0.0,...
/// ```
///
/// `freq_hz` (Hz, strictly ascending, uniform or not), then for each axis
/// present (x, y, z) `<a>_re`, `<a>_im` (the direct FRF G_aa, N/N) and
/// optionally `<a>_coh` (coherence γ², 0..=1). The 3x3 matrix adds
/// `<i><j>_re`, `<i><j>_im`, `<i><j>_coh` for channel i and force (hammer)
/// direction j (`xy` = channel x, hammer y); `x_re` means `xx_re`, and one
/// entry is spelled one way in a file. Column names are case-insensitive and
/// may be quoted; the delimiter is `,` (`;` or a tab are accepted when the
/// header uses them); blank lines are ignored.
pub fn parse_frf_csv(text: &str, source: &str) -> Result<Frf> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut lines = text.lines().enumerate().map(|(i, l)| (i + 1, l)).filter(|(_, l)| !l.trim().is_empty());
    let Some((hline, header)) = lines.next() else {
        bail!("{source}: empty file (expected a header row starting with freq_hz)");
    };
    let header = Header::parse(header, hline, source)?;
    let mut rows = Rows::default();
    for (lineno, line) in lines {
        rows.push(&header, lineno, line, source)?;
    }
    if rows.freq.is_empty() {
        bail!("{source}: no data rows after the header (line {hline})");
    }
    Ok(rows.into_frf(&header))
}

/// The header row: what each column holds.
struct Header {
    delim: char,
    /// Per column: None for freq_hz, else (entry, kind); entry = 3·channel + direction.
    cols: Vec<Option<(usize, Kind)>>,
    /// Column names as written (lower case), for messages.
    names: Vec<String>,
    /// `slot[entry][kind]`: the column of that part of the entry.
    slot: [[Option<usize>; 3]; 9],
    /// Entries with both re and im columns, in entry order.
    present: Vec<usize>,
}

impl Header {
    /// Parse the header row (line `hline`): known, unique column names,
    /// freq_hz, and re/im pairs.
    fn parse(header: &str, hline: usize, source: &str) -> Result<Header> {
        let delim = if header.contains(',') {
            ','
        } else if header.contains(';') {
            ';'
        } else if header.contains('\t') {
            '\t'
        } else {
            ','
        };
        let mut h = Header { delim, cols: Vec::new(), names: Vec::new(), slot: [[None; 3]; 9], present: Vec::new() };
        let mut freq_col: Option<usize> = None;
        // How each entry is spelled (`x` or `xx`), and its first column.
        let mut spelling: [Option<(String, usize)>; 9] = Default::default();
        for (c, raw) in header.split(delim).enumerate() {
            let name = unquote(raw).to_ascii_lowercase();
            if name == "freq_hz" {
                if let Some(prev) = freq_col {
                    bail!(
                        "{source}: line {hline}, column {}: duplicate column freq_hz (also column {})",
                        c + 1,
                        prev + 1
                    );
                }
                freq_col = Some(c);
                h.cols.push(None);
                h.names.push(name);
                continue;
            }
            let at = format!("{source}: line {hline}, column {}", c + 1);
            let (entry, kind) = h.entry_column(&at, raw, &name, c, &mut spelling)?;
            h.cols.push(Some((entry, kind)));
            h.names.push(name);
        }
        if freq_col.is_none() {
            bail!("{source}: line {hline}: missing column freq_hz in the header");
        }
        h.present = pairs(&h.slot, &spelling, &format!("{source}: line {hline}"))?;
        if h.present.is_empty() {
            bail!(
                "{source}: line {hline}: no FRF columns in the header (expected x_re/x_im, y_re/y_im or z_re/z_im, \
                 or <i><j>_re/<i><j>_im)"
            );
        }
        Ok(h)
    }

    /// Column `c` (`raw` as written, `name` lower case; `at` names it in
    /// messages) of an FRF entry: the entry and kind, given once, in one
    /// spelling per entry.
    fn entry_column(
        &mut self,
        at: &str,
        raw: &str,
        name: &str,
        c: usize,
        spelling: &mut [Option<(String, usize)>; 9],
    ) -> Result<(usize, Kind)> {
        let Some((entry, kind, spelled)) = column_entry(name) else {
            bail!(
                "{at}: unknown column name {:?} \
                 (expected freq_hz, then <a>_re, <a>_im and optionally <a>_coh for a = x, y, z, \
                 or <i><j>_re, <i><j>_im, <i><j>_coh for channel i and force direction j)",
                unquote(raw)
            );
        };
        let (i, j) = (entry / 3, entry % 3);
        match &spelling[entry] {
            Some((s, first)) if *s != spelled => bail!(
                "{at}: column {name} and column {} ({}) are the same entry {} \
                 ({}_re means {}_re): give each entry once, in one spelling",
                first + 1,
                self.names[*first],
                entry_name(i, j),
                axis_name(i),
                entry_name(i, j)
            ),
            Some(_) => {}
            None => spelling[entry] = Some((spelled.clone(), c)),
        }
        let k = kind as usize;
        if let Some(prev) = self.slot[entry][k] {
            let what = if spelled.len() == 1 {
                format!("axis {}", axis_name(i))
            } else {
                format!("entry {} (channel {}, force {})", entry_name(i, j), axis_name(i), axis_name(j))
            };
            bail!("{at}: duplicate column {name} (also column {}): {what} given twice", prev + 1);
        }
        self.slot[entry][k] = Some(c);
        Ok((entry, kind))
    }
}

/// The entries with both re and im columns; a lone re, im or coh column is
/// refused (`at` names the header line).
fn pairs(slot: &[[Option<usize>; 3]; 9], spelling: &[Option<(String, usize)>; 9], at: &str) -> Result<Vec<usize>> {
    let mut present = Vec::new();
    for (entry, s) in slot.iter().enumerate() {
        let a = spelling[entry].as_ref().map_or("?", |(s, _)| s.as_str());
        match (s[0], s[1], s[2]) {
            (None, None, None) => {}
            (Some(_), Some(_), _) => present.push(entry),
            (Some(c), None, _) => bail!("{at}: column {a}_re (column {}) has no matching {a}_im column", c + 1),
            (None, Some(c), _) => bail!("{at}: column {a}_im (column {}) has no matching {a}_re column", c + 1),
            (None, None, Some(c)) => {
                bail!("{at}: column {a}_coh (column {}) without {a}_re and {a}_im columns", c + 1)
            }
        }
    }
    Ok(present)
}

/// The data rows read so far, by column kind and entry.
#[derive(Default)]
struct Rows {
    /// Frequency lines (Hz).
    freq: Vec<f64>,
    re: [Vec<f64>; 9],
    im: [Vec<f64>; 9],
    /// Coherence γ², clamped to [0, 1].
    coh: [Vec<f64>; 9],
}

impl Rows {
    /// Read data row `line` (line `lineno`): one finite number per column,
    /// frequencies non-negative and strictly ascending, coherence in [0, 1].
    fn push(&mut self, header: &Header, lineno: usize, line: &str, source: &str) -> Result<()> {
        let ncols = header.cols.len();
        let fields: Vec<&str> = line.split(header.delim).collect();
        if fields.len() != ncols {
            bail!("{source}: line {lineno}: {} fields, but the header has {ncols} columns", fields.len());
        }
        for (c, raw) in fields.iter().enumerate() {
            let at = || format!("{source}: line {lineno}, column {} ({})", c + 1, header.names[c]);
            let tok = unquote(raw);
            if tok.is_empty() {
                bail!("{}: empty value", at());
            }
            let v: f64 = tok.parse().map_err(|_| anyhow!("{}: cannot read {:?} as a number", at(), tok))?;
            if !v.is_finite() {
                bail!("{}: value {tok} is not finite (NaN or infinite)", at());
            }
            match header.cols[c] {
                None => {
                    if v < 0.0 {
                        bail!("{}: negative frequency {v} Hz", at());
                    }
                    if let Some(&prev) = self.freq.last() {
                        if v <= prev {
                            bail!(
                                "{}: frequency {v} Hz is not greater than the previous line's {prev} Hz \
                                 (frequencies must be strictly ascending)",
                                at()
                            );
                        }
                    }
                    self.freq.push(v);
                }
                Some((e, Kind::Re)) => self.re[e].push(v),
                Some((e, Kind::Im)) => self.im[e].push(v),
                Some((e, Kind::Coh)) => {
                    if !(-COHERENCE_SLACK..=1.0 + COHERENCE_SLACK).contains(&v) {
                        bail!("{}: coherence {v} outside [0, 1]", at());
                    }
                    self.coh[e].push(v.clamp(0.0, 1.0));
                }
            }
        }
        Ok(())
    }

    /// The FRF of the entries the header has.
    fn into_frf(mut self, header: &Header) -> Frf {
        let mut axes = Vec::new();
        let mut cross = Vec::new();
        for &e in &header.present {
            let frf = self.re[e].iter().zip(&self.im[e]).map(|(&r, &i)| Complex64::new(r, i)).collect();
            let coherence = header.slot[e][Kind::Coh as usize].map(|_| std::mem::take(&mut self.coh[e]));
            let (i, j) = (e / 3, e % 3);
            if i == j {
                axes.push(AxisFrf { axis: i, frf, coherence });
            } else {
                cross.push(CrossFrf { channel: i, direction: j, frf, coherence });
            }
        }
        Frf { freq_hz: self.freq, axes, cross }
    }
}

/// The entry (3·channel + direction), kind and spelling (`x` or `xy`) of an
/// FRF column name (lower case): `x_re` is entry xx, as `xx_re` is.
fn column_entry(name: &str) -> Option<(usize, Kind, String)> {
    let (a, k) = name.split_once('_')?;
    let idx = |c: char| "xyz".find(c);
    let mut chars = a.chars();
    let entry = match (chars.next(), chars.next(), chars.next()) {
        (Some(i), None, None) => 4 * idx(i)?,
        (Some(i), Some(j), None) => 3 * idx(i)? + idx(j)?,
        _ => return None,
    };
    let kind = match k {
        "re" => Kind::Re,
        "im" => Kind::Im,
        "coh" => Kind::Coh,
        _ => return None,
    };
    Some((entry, kind, a.to_string()))
}

/// Trim blanks and one pair of surrounding double quotes.
fn unquote(s: &str) -> &str {
    let t = s.trim();
    t.strip_prefix('"').and_then(|t| t.strip_suffix('"')).map(str::trim).unwrap_or(t)
}

/// Write an FRF CSV file atomically (nothing is left behind on error).
/// Values are written in Rust's shortest round-trip form: reading the file
/// back gives bit-identical values.
///
/// Direct-only sets are spelled `x_re`, … (the files read before the
/// matrix existed) and sets with cross entries as `xx_re`, `xy_re`, …, row by
/// row.
pub fn write_frf_csv(path: &Path, frf: &Frf) -> Result<()> {
    let text = frf_csv_to_string(frf).with_context(|| format!("{}: not written", path.display()))?;
    super::atomic::write_atomic(path, |w: &mut dyn Write| {
        w.write_all(text.as_bytes())?;
        Ok(())
    })
}

/// The FRF CSV text of `frf` (validated as [`write_frf_csv`] does).
pub fn frf_csv_to_string(frf: &Frf) -> Result<String> {
    validate_frf(frf)?;
    let entries: Vec<_> = frf.entries().collect();
    // Direct-only sets keep the one-letter names; the matrix is spelled in full.
    let matrix = frf.has_cross();
    let mut s = String::from("freq_hz");
    for e in &entries {
        let n = if matrix { entry_name(e.channel, e.direction) } else { axis_name(e.channel).to_string() };
        s.push_str(&format!(",{n}_re,{n}_im"));
        if e.coherence.is_some() {
            s.push_str(&format!(",{n}_coh"));
        }
    }
    s.push('\n');
    for (i, f) in frf.freq_hz.iter().enumerate() {
        s.push_str(&format!("{f:?}"));
        for e in &entries {
            s.push_str(&format!(",{:?},{:?}", e.frf[i].re, e.frf[i].im));
            if let Some(c) = e.coherence {
                s.push_str(&format!(",{:?}", c[i]));
            }
        }
        s.push('\n');
    }
    Ok(s)
}

/// Check an [`Frf`] before writing it: at least one entry, direct axes x/y/z
/// ascending and unique, cross entries off the diagonal, ascending by
/// (channel, direction) and unique, lengths matching the frequency lines,
/// finite values, strictly ascending non-negative frequencies, coherence
/// within [0, 1].
pub(crate) fn validate_frf(frf: &Frf) -> Result<()> {
    let n = frf.freq_hz.len();
    if n == 0 {
        bail!("FRF has no frequency lines");
    }
    if frf.axes.is_empty() && frf.cross.is_empty() {
        bail!("FRF has no axis");
    }
    for (i, &f) in frf.freq_hz.iter().enumerate() {
        if !f.is_finite() || f < 0.0 {
            bail!("frequency line {i}: {f} Hz is not a finite non-negative frequency");
        }
        if i > 0 && f <= frf.freq_hz[i - 1] {
            bail!(
                "frequency line {i}: {f} Hz is not greater than line {}'s {} Hz (must be strictly ascending)",
                i - 1,
                frf.freq_hz[i - 1]
            );
        }
    }
    let mut prev: Option<usize> = None;
    for a in &frf.axes {
        if a.axis > 2 {
            bail!("axis index {} is not x, y or z", a.axis);
        }
        if let Some(p) = prev {
            if a.axis <= p {
                bail!("axes must be unique and ascending (axis {} after {})", axis_name(a.axis), axis_name(p));
            }
        }
        prev = Some(a.axis);
        check_values(&frf.freq_hz, &format!("axis {}", axis_name(a.axis)), &a.frf, a.coherence.as_deref())?;
    }
    let mut prev: Option<(usize, usize)> = None;
    for c in &frf.cross {
        if c.channel > 2 || c.direction > 2 || c.channel == c.direction {
            bail!(
                "cross FRF (channel {}, direction {}) is not an off-diagonal entry of the 3x3 matrix",
                c.channel,
                c.direction
            );
        }
        let key = (c.channel, c.direction);
        if let Some(p) = prev {
            if key <= p {
                bail!(
                    "cross FRFs must be unique and ascending by channel, then direction (entry {} after {})",
                    entry_name(key.0, key.1),
                    entry_name(p.0, p.1)
                );
            }
        }
        prev = Some(key);
        check_values(&frf.freq_hz, &format!("entry {}", entry_name(key.0, key.1)), &c.frf, c.coherence.as_deref())?;
    }
    Ok(())
}

/// Lengths, finiteness and coherence range of one entry named `name`.
fn check_values(freq_hz: &[f64], name: &str, frf: &[Complex64], coherence: Option<&[f64]>) -> Result<()> {
    let n = freq_hz.len();
    if frf.len() != n {
        bail!("{name}: {} FRF values for {n} frequency lines", frf.len());
    }
    if let Some(i) = frf.iter().position(|v| !v.re.is_finite() || !v.im.is_finite()) {
        bail!("{name}: FRF value at line {i} ({} Hz) is not finite", freq_hz[i]);
    }
    if let Some(c) = coherence {
        if c.len() != n {
            bail!("{name}: {} coherence values for {n} frequency lines", c.len());
        }
        if let Some(i) = c.iter().position(|v| !(0.0..=1.0).contains(v)) {
            bail!("{name}: coherence {} at line {i} ({} Hz) outside [0, 1]", c[i], freq_hz[i]);
        }
    }
    Ok(())
}
