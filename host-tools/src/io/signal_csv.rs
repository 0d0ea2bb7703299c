//! Force records as CSV (DESIGN.md, CLI contract "Signal CSV").
//!
//! Header row; columns `fx`, `fy`, `fz` (any subset, in N); an optional first
//! column `t_s` (seconds). Output files use the same layout.

use anyhow::{anyhow, bail, Context, Result};
use std::path::Path;

use crate::frf::axis_name;
use crate::io::atomic::write_atomic;

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

/// Read a force record from `path`.
pub fn read_signal_csv(path: &Path) -> Result<SignalRecord> {
    let text = std::fs::read_to_string(path).with_context(|| format!("{}: cannot read", path.display()))?;
    parse_signal_csv(&text, &path.display().to_string())
}

/// Parse a force record from CSV text; `source` names the input in errors.
pub fn parse_signal_csv(text: &str, source: &str) -> Result<SignalRecord> {
    let mut lines = text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty());
    let (_, header) = lines.next().ok_or_else(|| anyhow!("{source}: empty file, expected a header row (t_s,fx,fy,fz)"))?;
    let names: Vec<String> = header.split(',').map(|s| s.trim().trim_matches('"').to_ascii_lowercase()).collect();
    let mut has_time = false;
    let mut axes = Vec::new();
    // Data column of each CSV column (None: time or an ignored column).
    let mut slot_of: Vec<Option<usize>> = Vec::with_capacity(names.len());
    for (col, name) in names.iter().enumerate() {
        if IGNORED_COLUMNS.contains(&name.as_str()) {
            slot_of.push(None);
            continue;
        }
        slot_of.push(column_axis(name).map(|_| axes.len()));
        if name == "t_s" {
            if col != 0 {
                bail!("{source}: line 1, column {}: `t_s` must be the first column", col + 1);
            }
            has_time = true;
        } else if let Some(axis) = column_axis(name) {
            if axes.contains(&axis) {
                bail!("{source}: line 1, column {}: duplicate column `{name}`", col + 1);
            }
            if let Some(&last) = axes.last() {
                if axis < last {
                    bail!("{source}: line 1, column {}: columns must be in the order fx, fy, fz", col + 1);
                }
            }
            axes.push(axis);
        } else {
            bail!("{source}: line 1, column {}: unknown column `{name}` (expected t_s, fx, fy, fz)", col + 1);
        }
    }
    if axes.is_empty() {
        bail!("{source}: line 1: no force column (expected at least one of fx, fy, fz)");
    }
    let mut t_s = Vec::new();
    let mut data: Vec<Vec<f64>> = vec![Vec::new(); axes.len()];
    for (idx, line) in lines {
        let lineno = idx + 1;
        let fields: Vec<&str> = line.split(',').collect();
        if fields.len() != names.len() {
            bail!("{source}: line {lineno}: {} fields, header has {}", fields.len(), names.len());
        }
        for (col, field) in fields.iter().enumerate() {
            let v: f64 = field
                .trim()
                .parse()
                .map_err(|_| anyhow!("{source}: line {lineno}, column {} (`{}`): `{}` is not a number", col + 1, names[col], field.trim()))?;
            if !v.is_finite() {
                bail!("{source}: line {lineno}, column {} (`{}`): value is not finite", col + 1, names[col]);
            }
            if has_time && col == 0 {
                if let Some(&prev) = t_s.last() {
                    if v <= prev {
                        bail!("{source}: line {lineno}, column 1 (`t_s`): time {v} does not increase (previous {prev})");
                    }
                }
                t_s.push(v);
            } else if let Some(slot) = slot_of[col] {
                data[slot].push(v);
            }
        }
    }
    if data[0].is_empty() {
        bail!("{source}: no samples after the header");
    }
    Ok(SignalRecord {
        t_s: has_time.then_some(t_s),
        channels: axes.into_iter().zip(data).collect(),
    })
}

/// Write a force record to `path` atomically (columns t_s?, fx?, fy?, fz?).
///
/// Values are written with enough digits to round-trip f32 exactly (so a
/// compensated output read back is bit-identical to what the kernel produced).
pub fn write_signal_csv(path: &Path, rec: &SignalRecord) -> Result<()> {
    let n = rec.len();
    if rec.channels.iter().any(|c| c.1.len() != n) || rec.t_s.as_ref().is_some_and(|t| t.len() != n) {
        bail!("{}: internal error: channels of different lengths", path.display());
    }
    write_atomic(path, |w| {
        let mut header: Vec<&str> = Vec::new();
        if rec.t_s.is_some() {
            header.push("t_s");
        }
        let names: Vec<String> = rec.channels.iter().map(|c| format!("f{}", axis_name(c.0))).collect();
        header.extend(names.iter().map(String::as_str));
        writeln!(w, "{}", header.join(","))?;
        let mut line = String::new();
        for k in 0..n {
            line.clear();
            if let Some(t) = &rec.t_s {
                line.push_str(&format!("{}", t[k]));
            }
            for c in &rec.channels {
                if !line.is_empty() {
                    line.push(',');
                }
                line.push_str(&format!("{}", c.1[k]));
            }
            writeln!(w, "{line}")?;
        }
        Ok(())
    })
}
