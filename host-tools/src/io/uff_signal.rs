//! Force records as UFF dataset 58/58b time histories, one dataset per
//! channel: read by [`UffReader`] and written by [`UffWriter`] in a stream, so
//! memory does not grow with the record. A leaf of the chain, behind the `io`
//! signal traits; the dataset records are those of [`super::uff`].

use anyhow::{anyhow, bail, Context, Result};
use std::collections::VecDeque;
use std::fs::File;
use std::io::{BufRead, BufReader, Read, Seek, SeekFrom, Write};
use std::path::Path;

use super::signal::ChannelMap;
use super::signal::{newton_per_unit, Block, SignalReader, SignalWriter};
use super::uff::{data_characteristics, dataset_header, read_numbers, record6, record7, spec_type_name, tokens, trim};
use crate::frf::axis_name;

/// One time-history dataset found by the index pass.
#[derive(Clone, Debug)]
struct Channel {
    axis: usize,
    sign: f64,
    /// Dataset number in the file (1-based) and its first line.
    no: usize,
    line: usize,
    n: u64,
    dt: f64,
    /// Abscissa of the first sample (s, record 7).
    t0: f64,
    double: bool,
    /// 58b: Some(big endian).
    binary: Option<bool>,
    data_off: u64,
    data_line: usize,
}

/// The index pass: every dataset of the file in turn, the time histories
/// kept as channels (checked to form one record, in axis order).
fn index(path: &Path, source: &str, map: Option<&ChannelMap>) -> Result<Vec<Channel>> {
    let f = File::open(path).with_context(|| format!("{source}: cannot read"))?;
    let mut lines = Lines { r: BufReader::with_capacity(1 << 20, f), line: Vec::new(), off: 0, lineno: 0, source };
    let mut found: Vec<Channel> = Vec::new();
    let mut skipped: Vec<String> = Vec::new();
    let mut no = 0usize;
    while lines.next()? {
        if trim(&lines.line) != b"-1" {
            if trim(&lines.line).is_empty() {
                continue;
            }
            bail!(
                "{source}: line {}: expected a '    -1' line opening a dataset, found {}",
                lines.lineno,
                super::uff::show(&lines.line)
            );
        }
        let start_line = lines.lineno;
        if !lines.next()? {
            break;
        }
        no += 1;
        let ds = Dataset { source, no, line: start_line };
        let NumberLine::Uff58 { binary } = dataset_kind(&mut lines, &ds)? else {
            continue;
        };
        match time_history(&mut lines, &ds, binary, map)? {
            Indexed::Channel(ch) => found.push(ch),
            Indexed::Skipped(note) => skipped.push(note),
        }
    }
    one_record(source, found, &skipped, map)
}

/// Lines of the file read in turn, with the offset after the current line
/// and its 1-based number.
struct Lines<'a> {
    r: BufReader<File>,
    /// The current line, without its line break.
    line: Vec<u8>,
    off: u64,
    lineno: usize,
    source: &'a str,
}

impl Lines<'_> {
    /// Read the next line; false at the end of the file.
    fn next(&mut self) -> Result<bool> {
        self.line.clear();
        let n = self.r.read_until(b'\n', &mut self.line).with_context(|| format!("{}: read failed", self.source))?;
        self.off += n as u64;
        self.lineno += 1;
        while matches!(self.line.last(), Some(b'\n' | b'\r')) {
            self.line.pop();
        }
        Ok(n > 0)
    }

    /// Skip `n` bytes.
    fn skip(&mut self, n: i64) -> Result<()> {
        self.r.seek_relative(n).with_context(|| format!("{}: seek failed", self.source))
    }
}

/// The dataset being indexed, for messages.
struct Dataset<'a> {
    source: &'a str,
    /// Number in the file (1-based) and line of its opening `-1`.
    no: usize,
    line: usize,
}

impl Dataset<'_> {
    /// `file: line L: dataset #k (58, starting line S), <what>`
    fn at(&self, what: &str, l: usize) -> String {
        format!("{}: line {l}: dataset #{} (58, starting line {}), {what}", self.source, self.no, self.line)
    }
}

/// What a dataset number line says.
enum NumberLine {
    /// A dataset 58; 58b: Some(big endian).
    Uff58 { binary: Option<bool> },
    /// Another dataset, skipped.
    Other,
}

/// The dataset number line just read: a dataset 58 or a supported 58b;
/// another dataset is skipped up to its closing `-1` (binary ones by their
/// byte count).
fn dataset_kind(lines: &mut Lines, ds: &Dataset) -> Result<NumberLine> {
    let id = String::from_utf8_lossy(trim(&lines.line)).to_string();
    let t: Vec<String> = tokens(&lines.line).into_iter().map(str::to_string).collect();
    let head = t.first().cloned().unwrap_or_default();
    match head.as_str() {
        "58" => Ok(NumberLine::Uff58 { binary: None }),
        "58b" => {
            let g = |i: usize| t.get(i).and_then(|s| s.parse::<i64>().ok());
            match (g(1), g(2), g(3)) {
                (Some(bo @ 1..=2), Some(2), Some(11)) => Ok(NumberLine::Uff58 { binary: Some(bo == 2) }),
                _ => bail!(
                    "{}: unsupported 58b header {:?} (need byte order 1/2, IEEE 754, 11 ASCII lines)",
                    ds.at("binary header", lines.lineno),
                    id
                ),
            }
        }
        _ => {
            skip_other(lines, ds, &head, &t)?;
            Ok(NumberLine::Other)
        }
    }
}

/// Skip a dataset other than 58 (number line `head`, fields `t`) up to and
/// including its closing `-1`: a binary one first by its header line count
/// and byte count.
fn skip_other(lines: &mut Lines, ds: &Dataset, head: &str, t: &[String]) -> Result<()> {
    let (source, no, start_line) = (ds.source, ds.no, ds.line);
    let nb = if head.ends_with('b') { t.get(4).and_then(|s| s.parse::<u64>().ok()) } else { None };
    if let Some(nb) = nb {
        let nl = t.get(3).and_then(|s| s.parse::<usize>().ok()).unwrap_or(0);
        let here = || format!("{source}: line {start_line}: dataset #{no} ({head})");
        for _ in 0..nl {
            // A declared line count past the end of the file ends the skip.
            if !lines.next()? {
                bail!("{}: the file ends inside its {nl} header lines", here());
            }
        }
        // A byte count above i64::MAX would seek backwards (and loop).
        let skip = i64::try_from(nb).map_err(|_| anyhow!("{}: binary byte count {nb} out of range", here()))?;
        lines.skip(skip)?;
        lines.off += nb;
    }
    loop {
        if !lines.next()? {
            bail!("{source}: line {start_line}: dataset #{no} ({head}) is not closed by a '    -1' line");
        }
        if trim(&lines.line) == b"-1" {
            return Ok(());
        }
    }
}

/// Records 1 to 11 of a dataset 58, each with its line number.
fn header_records(lines: &mut Lines, ds: &Dataset) -> Result<Vec<(usize, Vec<u8>)>> {
    let mut recs = Vec::with_capacity(11);
    for k in 0..11 {
        if !lines.next()? {
            bail!("{}: the file ends inside the dataset header", ds.at(&format!("record {}", k + 1), lines.lineno));
        }
        recs.push((lines.lineno, lines.line.clone()));
    }
    Ok(recs)
}

/// Records 6 and 7 of a dataset 58 as far as the index needs them.
struct DataForm {
    /// Function type (1 = time response) and response direction (record 6).
    func: i64,
    rsp_dir: i64,
    /// Response node number (record 6), for `--channels`.
    node: Option<i64>,
    /// Record 7's line, ordinate data type, points, spacing (1 = even),
    /// abscissa start and increment (s).
    line: usize,
    ord: i64,
    n: u64,
    spacing: i64,
    x0: f64,
    dx: f64,
    double: bool,
    complex: bool,
    /// Bytes per point in a 58b dataset.
    elem: u64,
}

/// Read records 6 (DOF identification) and 7 (data form).
fn data_form(recs: &[(usize, Vec<u8>)], ds: &Dataset) -> Result<DataForm> {
    let (l6, r6) = (recs[5].0, &recs[5].1);
    let (func, rsp_dir, _) =
        record6(r6).ok_or_else(|| anyhow!("{}: cannot read function type and directions", ds.at("record 6", l6)))?;
    let node = super::uff::field(r6, 41, 10)
        .and_then(super::uff::parse_int)
        .or_else(|| tokens(r6).get(5).and_then(|s| s.parse().ok()));
    let (l7, r7) = (recs[6].0, &recs[6].1);
    let (ord, num, spacing, x0, dx) =
        record7(r7).ok_or_else(|| anyhow!("{}: cannot read data form", ds.at("record 7", l7)))?;
    let double = match ord {
        2 | 5 => false,
        4 | 6 => true,
        _ if func != 1 => false,
        _ => bail!(
            "{}: ordinate data type {ord}: a time history must be real (2 = single, 4 = double precision)",
            ds.at("record 7", l7)
        ),
    };
    let complex = matches!(ord, 5 | 6);
    let elem =
        if matches!(ord, 4 | 6) { 8 } else { 4 } * if complex { 2 } else { 1 } * if spacing == 0 { 2 } else { 1 };
    let n = u64::try_from(num).map_err(|_| anyhow!("{}: {num} data points", ds.at("record 7", l7)))?;
    Ok(DataForm { func, rsp_dir, node, line: l7, ord, n, spacing, x0, dx, double, complex, elem })
}

/// Skip the data (record 12) up to the closing `-1`: a 58b dataset's by
/// its byte count.
fn skip_data(lines: &mut Lines, ds: &Dataset, binary: bool, form: &DataForm) -> Result<()> {
    let Some(bytes) = form.n.checked_mul(form.elem).filter(|b| i64::try_from(*b).is_ok()) else {
        bail!(
            "{}: {} data points of {} bytes: more than any file holds",
            ds.at("record 7", form.line),
            form.n,
            form.elem
        );
    };
    if binary {
        lines.skip(bytes as i64)?;
        lines.off += bytes;
    }
    loop {
        if !lines.next()? {
            bail!(
                "{}: the dataset is not closed by a '    -1' line before the end of the file",
                ds.at("record 12", lines.lineno)
            );
        }
        if trim(&lines.line) == b"-1" {
            return Ok(());
        }
        if binary && !trim(&lines.line).is_empty() {
            bail!(
                "{}: no closing '    -1' after the {} bytes of binary data record 7 declares",
                ds.at("record 12", lines.lineno),
                bytes
            );
        }
    }
}

/// A dataset 58 as the index pass found it.
enum Indexed {
    /// A time history of a force axis.
    Channel(Channel),
    /// Another function type or direction: the note saying so.
    Skipped(String),
}

/// Index one dataset 58 whose number line was just read (`binary`: Some(big
/// endian) for 58b).
fn time_history(lines: &mut Lines, ds: &Dataset, binary: Option<bool>, map: Option<&ChannelMap>) -> Result<Indexed> {
    let recs = header_records(lines, ds)?;
    let form = data_form(&recs, ds)?;
    let data_off = lines.off;
    let data_line = lines.lineno + 1;
    skip_data(lines, ds, binary.is_some(), &form)?;
    if form.func == 1 && form.complex {
        bail!(
            "{}: ordinate data type {}: a time history must be real (2 = single, 4 = double precision)",
            ds.at("record 7", form.line),
            form.ord
        );
    }
    if form.func != 1 {
        return Ok(Indexed::Skipped(format!("dataset #{}: function type {}", ds.no, form.func)));
    }
    check_time_axis(&recs, ds, &form)?;
    let name = String::from_utf8_lossy(trim(&recs[0].1)).to_string();
    let Some(axis) = channel_axis(map, &name, form.node, form.rsp_dir) else {
        return Ok(Indexed::Skipped(format!("dataset #{} ({name:?}): response direction {}", ds.no, form.rsp_dir)));
    };
    let sign = if map.is_some() || form.rsp_dir >= 0 { 1.0 } else { -1.0 };
    Ok(Indexed::Channel(Channel {
        axis,
        sign: sign * newtons(&recs, ds)?,
        no: ds.no,
        line: ds.line,
        n: form.n,
        dt: form.dx,
        t0: form.x0,
        double: form.double,
        binary,
        data_off,
        data_line,
    }))
}

/// The abscissa of a time history: evenly spaced (record 7), time in seconds
/// (record 8).
fn check_time_axis(recs: &[(usize, Vec<u8>)], ds: &Dataset, form: &DataForm) -> Result<()> {
    let (l7, n, x0, dx) = (form.line, form.n, form.x0, form.dx);
    if form.spacing != 1 {
        bail!("{}: uneven abscissa: a time history needs evenly spaced samples", ds.at("record 7", l7));
    }
    if n == 0 {
        bail!("{}: no data points", ds.at("record 7", l7));
    }
    if !(dx > 0.0 && dx.is_finite()) {
        bail!("{}: abscissa increment {dx} s must be positive", ds.at("record 7", l7));
    }
    if !x0.is_finite() {
        bail!("{}: abscissa start {x0} s is not finite", ds.at("record 7", l7));
    }
    let (l8, r8) = (recs[7].0, &recs[7].1);
    let (spec, units) = data_characteristics(r8);
    if let Some(t) = spec.filter(|t| ![0, 1, 17].contains(t)) {
        bail!("{}: the abscissa is {} (specific data type {t}), not time", ds.at("record 8", l8), spec_type_name(t));
    }
    let u = units.trim().to_ascii_lowercase();
    if !(u.is_empty() || u == "none" || u == "s" || u.starts_with("sec")) {
        bail!("{}: abscissa units {units:?} are not seconds", ds.at("record 8", l8));
    }
    Ok(())
}

/// The axis of a channel: by `--channels` (ID line 1 `name` or response
/// `node`), else by the response direction (±1/±2/±3).
fn channel_axis(map: Option<&ChannelMap>, name: &str, node: Option<i64>, rsp_dir: i64) -> Option<usize> {
    match map {
        Some(m) => {
            m.pairs.iter().find(|(_, v)| *v == name || node.is_some_and(|nd| v.parse::<i64>() == Ok(nd))).map(|p| p.0)
        }
        None => match rsp_dir.abs() {
            d @ 1..=3 => Some((d - 1) as usize),
            _ => None,
        },
    }
}

/// Newtons per unit of the ordinate (record 9): N, kN or mN; NONE/blank read as N.
fn newtons(recs: &[(usize, Vec<u8>)], ds: &Dataset) -> Result<f64> {
    let (l9, r9) = (recs[8].0, &recs[8].1);
    let (_, ounits) = data_characteristics(r9);
    let ou = ounits.trim();
    if ou.eq_ignore_ascii_case("none") {
        return Ok(1.0);
    }
    newton_per_unit(ou).ok_or_else(|| {
        anyhow!("{}: ordinate units {ou:?} are not a force in N (kN and mN are scaled)", ds.at("record 9", l9))
    })
}

/// The channels found as one record, in axis order: at least one, one per
/// axis, all of the same length and sampling interval.
fn one_record(
    source: &str,
    mut found: Vec<Channel>,
    skipped: &[String],
    map: Option<&ChannelMap>,
) -> Result<Vec<Channel>> {
    if found.is_empty() {
        bail!(
            "{source}: no time history (dataset 58, function type 1) for fx, fy or fz{}{}",
            if skipped.is_empty() { String::new() } else { format!("; skipped: {}", skipped.join(", ")) },
            if map.is_none() {
                " (give --channels fx=NAME,... if the response directions do not say the axis)"
            } else {
                ""
            }
        );
    }
    found.sort_by_key(|c| c.axis);
    for w in found.windows(2) {
        if w[0].axis == w[1].axis {
            bail!(
                "{source}: datasets #{} and #{} are both axis {}; pick one with --channels",
                w[0].no,
                w[1].no,
                axis_name(w[0].axis)
            );
        }
    }
    let c0 = &found[0];
    for c in &found[1..] {
        if c.n != c0.n || ((c.dt - c0.dt) / c0.dt).abs() > 1e-6 {
            bail!(
                "{source}: dataset #{} (f{}) has {} points every {} s, dataset #{} (f{}) {} points every {} s: \
                 channels must match",
                c0.no,
                axis_name(c0.axis),
                c0.n,
                c0.dt,
                c.no,
                axis_name(c.axis),
                c.n,
                c.dt
            );
        }
    }
    Ok(found)
}

/// A reader of the time histories of a UFF file.
///
/// Function type 1 (time response), real ordinate (data types 2/4), even
/// abscissa in seconds (record 8 specific data type 17 "time", or
/// unknown/general). The axis comes from the response direction as for FRFs
/// (±1/±2/±3, a negative direction flips the sign), or from `--channels` (by
/// the dataset's ID line 1 or response node number). Datasets of other
/// function types (and other dataset numbers) are skipped.
///
/// Streaming: a first pass indexes the datasets (binary data is skipped by
/// its length, ASCII data line by line, nothing kept); then every channel is
/// read through its own file handle from its own data offset, block by block.
pub struct UffReader {
    source: String,
    chans: Vec<Channel>,
    axes: Vec<usize>,
    readers: Vec<BufReader<File>>,
    pending: Vec<VecDeque<f64>>,
    lines: Vec<usize>,
    done: Vec<u64>,
    text: String,
    raw: Vec<u8>,
    nums: Vec<f64>,
}

impl UffReader {
    /// Whether the channels are binary (58b) datasets.
    pub fn is_binary(&self) -> bool {
        self.chans.iter().any(|c| c.binary.is_some())
    }

    /// Index the time histories of `path` and open one handle per channel.
    pub fn open(path: &Path, map: Option<&ChannelMap>) -> Result<UffReader> {
        let source = path.display().to_string();
        let chans = index(path, &source, map)?;
        let mut readers = Vec::new();
        for c in &chans {
            let mut f = File::open(path).with_context(|| format!("{source}: cannot read"))?;
            f.seek(SeekFrom::Start(c.data_off)).with_context(|| format!("{source}: seek failed"))?;
            readers.push(BufReader::with_capacity(1 << 18, f));
        }
        let n = chans.len();
        Ok(UffReader {
            source,
            axes: chans.iter().map(|c| c.axis).collect(),
            lines: chans.iter().map(|c| c.data_line).collect(),
            chans,
            readers,
            pending: vec![VecDeque::new(); n],
            done: vec![0; n],
            text: String::new(),
            raw: Vec::new(),
            nums: Vec::new(),
        })
    }

    /// Read up to `want` values of channel `i` into `out`.
    fn fill(&mut self, i: usize, want: usize, out: &mut Vec<f64>) -> Result<()> {
        let c = &self.chans[i];
        let at = |l: usize, what: &str| {
            format!("{}: line {l}: dataset #{} (58, starting line {}), record 12, {what}", self.source, c.no, c.line)
        };
        match c.binary {
            Some(big) => {
                let elem = if c.double { 8 } else { 4 };
                self.raw.resize(want * elem, 0);
                self.readers[i].read_exact(&mut self.raw).with_context(|| at(c.data_line, "binary data ends early"))?;
                for (k, b) in self.raw.chunks_exact(elem).enumerate() {
                    let v = match (c.double, big) {
                        (true, false) => f64::from_le_bytes(b.try_into().unwrap_or([0; 8])),
                        (true, true) => f64::from_be_bytes(b.try_into().unwrap_or([0; 8])),
                        (false, false) => f64::from(f32::from_le_bytes(b.try_into().unwrap_or([0; 4]))),
                        (false, true) => f64::from(f32::from_be_bytes(b.try_into().unwrap_or([0; 4]))),
                    };
                    if !v.is_finite() {
                        bail!(
                            "{}",
                            at(
                                c.data_line,
                                &format!("value {} is {v} (values must be finite)", self.done[i] + k as u64 + 1)
                            )
                        );
                    }
                    out.push(c.sign * v);
                }
            }
            None => {
                let widths: &[usize] = if c.double { &[20] } else { &[13] };
                while self.pending[i].len() < want {
                    self.text.clear();
                    let n = self.readers[i]
                        .read_line(&mut self.text)
                        .with_context(|| at(self.lines[i], "read failed (not text?)"))?;
                    if n == 0 || trim(self.text.as_bytes()) == b"-1" {
                        bail!(
                            "{}",
                            at(
                                self.lines[i],
                                &format!(
                                    "{} values, but record 7 declares {}",
                                    self.done[i] + self.pending[i].len() as u64,
                                    c.n
                                )
                            )
                        );
                    }
                    self.nums.clear();
                    read_numbers(self.text.trim_end().as_bytes(), widths, &mut self.nums)
                        .map_err(|tok| anyhow!("{}", at(self.lines[i], &format!("cannot read {tok:?} as a number"))))?;
                    if let Some(v) = self.nums.iter().find(|v| !v.is_finite()) {
                        bail!("{}", at(self.lines[i], &format!("value {v} (values must be finite)")));
                    }
                    self.pending[i].extend(self.nums.iter().map(|v| c.sign * v));
                    self.lines[i] += 1;
                }
                out.extend(self.pending[i].drain(..want));
            }
        }
        self.done[i] += want as u64;
        Ok(())
    }
}

impl SignalReader for UffReader {
    fn axes(&self) -> &[usize] {
        &self.axes
    }

    /// Times from the first dataset's abscissa (record 7: start and
    /// increment), so a CSV output gets its `t_s` column and a UFF or TDMS
    /// output its start time.
    fn has_time(&self) -> bool {
        true
    }

    fn declared_fs_hz(&self) -> Option<f64> {
        Some(1.0 / self.chans[0].dt)
    }

    fn len_hint(&self) -> Option<u64> {
        Some(self.chans[0].n)
    }

    fn read_block(&mut self, blk: &mut Block, max: usize) -> Result<usize> {
        blk.clear();
        blk.channels.resize(self.chans.len(), Vec::new());
        let left = (self.chans[0].n - self.done[0]).min(max as u64) as usize;
        blk.push_even_times(self.chans[0].t0, self.chans[0].dt, self.done[0], left);
        for i in 0..self.chans.len() {
            let mut v = std::mem::take(&mut blk.channels[i]);
            self.fill(i, left, &mut v)?;
            blk.channels[i] = v;
        }
        Ok(left)
    }
}

/// Characters of one ASCII value (E20.12) and of a full data line (four
/// values and the newline): every value has the same width, so the place of
/// sample `i` in a dataset is known before it is written.
const ASCII_VALUE: u64 = 20;
const ASCII_LINE: u64 = 4 * ASCII_VALUE + 1;
/// The line that ends a dataset (`{:>6}` of -1 and a newline).
const END_LINE: u64 = 7;

/// A writer of UFF 58 (ASCII, double precision, 4E20.12 per line) or 58b
/// (binary little-endian doubles) time histories: one dataset per axis,
/// abscissa every 1/fs s from the first sample's time (0 s when the input
/// has no times).
///
/// The datasets follow one another and each header gives its number of
/// points, while the samples of all axes arrive together. When the output
/// is a file and the number of samples is known ([`UffWriter::placed`]),
/// every dataset's place in the file is fixed from the start and each block
/// is written at its offset; otherwise each channel is spilled to a
/// temporary file and the datasets are written one after the other at the
/// end (the data then goes through the disk twice).
pub struct UffWriter<'w> {
    sink: Sink<'w>,
    axes: Vec<usize>,
    n: u64,
    dt: f64,
    t0: Option<f64>,
    binary: bool,
    /// [`Sink::Placed`]: the offset of dataset k's first data byte, fixed
    /// when the first block fixes the headers' length (the first sample's
    /// time is in the header); empty until then.
    data_at: Vec<u64>,
    /// Formatting buffers (ASCII) and the bytes of one block of a channel.
    text: String,
    scratch: String,
    bytes: Vec<u8>,
}

enum Sink<'w> {
    Spilled {
        w: &'w mut dyn Write,
        spill: Vec<std::io::BufWriter<File>>,
    },
    /// `len` samples per dataset, each at its place in `file`.
    Placed {
        file: &'w File,
        len: u64,
    },
    /// After [`SignalWriter::finish`].
    Done,
}

impl<'w> UffWriter<'w> {
    /// A writer for `axes` at `fs_hz` into `w`, spilling to the system's
    /// temporary folder.
    pub fn new(w: &'w mut dyn Write, axes: &[usize], fs_hz: f64, binary: bool) -> Result<Self> {
        Self::new_in(w, axes, fs_hz, binary, &std::env::temp_dir())
    }

    /// [`UffWriter::new`], spilling each channel (8 bytes per sample) to an
    /// unnamed temporary file in `spill_dir` until [`SignalWriter::finish`]
    /// writes the datasets: `compensate` passes the output's folder, the
    /// disk chosen for a large output (the system's temporary folder is
    /// often a small RAM disk).
    pub fn new_in(w: &'w mut dyn Write, axes: &[usize], fs_hz: f64, binary: bool, spill_dir: &Path) -> Result<Self> {
        let spill = axes
            .iter()
            .map(|_| {
                tempfile::tempfile_in(spill_dir)
                    .map(std::io::BufWriter::new)
                    .with_context(|| format!("{}: cannot create a temporary spill file", spill_dir.display()))
            })
            .collect::<Result<_>>()?;
        Ok(Self::with_sink(Sink::Spilled { w, spill }, axes, fs_hz, binary))
    }

    /// A writer of a record of exactly `len` samples per axis into the empty
    /// `file`, each block written at its place (positioned writes; the
    /// file's cursor is not used): no spill. Writing more than `len`
    /// samples, or finishing with fewer, is an error.
    pub fn placed(file: &'w File, len: u64, axes: &[usize], fs_hz: f64, binary: bool) -> Result<Self> {
        Ok(Self::with_sink(Sink::Placed { file, len }, axes, fs_hz, binary))
    }

    fn with_sink(sink: Sink<'w>, axes: &[usize], fs_hz: f64, binary: bool) -> Self {
        UffWriter {
            sink,
            axes: axes.to_vec(),
            n: 0,
            dt: 1.0 / fs_hz,
            t0: None,
            binary,
            data_at: Vec::new(),
            text: String::new(),
            scratch: String::new(),
            bytes: Vec::new(),
        }
    }

    /// Header of dataset `k` (of `n` points).
    fn header(&self, k: usize, n: usize) -> String {
        let axis = self.axes[k];
        let id1 = format!("dynocomp compensated f{}", axis_name(axis));
        dataset_header(
            (1, k as i64 + 1, axis as i64 + 1, &id1),
            (4, n, self.t0.unwrap_or(0.0), self.dt),
            [(17, "Time", "s"), (9, "Force", "N"), (0, "NONE", "NONE"), (0, "NONE", "NONE")],
            self.binary.then_some(n * 8),
        )
    }

    /// Offset of each dataset's first data byte in a file of `len` samples
    /// per dataset, and the file's length.
    fn layout(&self, len: u64) -> Result<(Vec<u64>, u64)> {
        let n = usize::try_from(len)?;
        let mut at = 0;
        let mut data_at = Vec::with_capacity(self.axes.len());
        for k in 0..self.axes.len() {
            at += self.header(k, n).len() as u64;
            data_at.push(at);
            at += self.data_bytes(len) + END_LINE;
        }
        Ok((data_at, at))
    }

    /// What follows a dataset's `n` values: the newline of a short last
    /// ASCII line, and the line that ends the dataset.
    fn data_end(&self, n: u64) -> &'static [u8] {
        if !self.binary && !n.is_multiple_of(4) {
            b"\n    -1\n"
        } else {
            b"    -1\n"
        }
    }

    /// Bytes of `n` samples of data (58b: doubles; 58: lines of four values,
    /// the last one shorter).
    fn data_bytes(&self, n: u64) -> u64 {
        if self.binary {
            8 * n
        } else {
            n / 4 * ASCII_LINE + if n.is_multiple_of(4) { 0 } else { n % 4 * ASCII_VALUE + 1 }
        }
    }

    /// Offset of sample `i` from the start of a dataset's data.
    fn sample_at(&self, i: u64) -> u64 {
        if self.binary {
            8 * i
        } else {
            i / 4 * ASCII_LINE + i % 4 * ASCII_VALUE
        }
    }

    /// Encode `values` (samples `first`, `first + 1`, … of a channel) into
    /// `self.bytes` as they appear in the data section.
    fn encode(&mut self, first: u64, values: &[f64]) {
        self.bytes.clear();
        if self.binary {
            for v in values {
                self.bytes.extend_from_slice(&v.to_le_bytes());
            }
        } else {
            self.text.clear();
            for (i, v) in (first..).zip(values) {
                super::uff::push_e(&mut self.text, &mut self.scratch, *v, 12, 20);
                if i % 4 == 3 {
                    self.text.push('\n');
                }
            }
            self.bytes.extend_from_slice(self.text.as_bytes());
        }
    }
}

impl SignalWriter for UffWriter<'_> {
    fn write_block(&mut self, t_s: Option<&[f64]>, channels: &[&[f64]]) -> Result<()> {
        if self.t0.is_none() {
            self.t0 = t_s.and_then(|t| t.first().copied());
        }
        let m = channels.first().map_or(0, |c| c.len()) as u64;
        let first = self.n;
        match &mut self.sink {
            Sink::Spilled { spill, .. } => {
                for (s, c) in spill.iter_mut().zip(channels) {
                    for v in *c {
                        s.write_all(&v.to_le_bytes())?;
                    }
                }
            }
            Sink::Placed { file, len } => {
                let (file, len) = (*file, *len);
                if first + m > len {
                    bail!("the record has more than the {len} samples announced for the UFF datasets' headers");
                }
                if self.data_at.is_empty() {
                    let (data_at, end) = self.layout(len)?;
                    // The file's final size, set now, so no write below
                    // extends it: 74 MB of 58b to ext4 took 0.32-0.36 s
                    // without, 0.21-0.23 s with (the writes go to three
                    // regions, the later ones past the end; an appended
                    // TDMS output did not gain from the same).
                    file.set_len(end)?;
                    self.data_at = data_at;
                }
                let off = self.sample_at(first);
                for (k, c) in channels.iter().enumerate() {
                    self.encode(first, c);
                    write_at(file, &self.bytes, self.data_at[k] + off)?;
                }
            }
            Sink::Done => bail!("UFF writer: a block after the end"),
        }
        self.n += m;
        Ok(())
    }

    fn finish(&mut self) -> Result<()> {
        let n = usize::try_from(self.n)?;
        match std::mem::replace(&mut self.sink, Sink::Done) {
            Sink::Done => bail!("UFF writer: finished twice"),
            Sink::Placed { file, len } => {
                if self.n != len {
                    bail!(
                        "the record ended after {} of the {len} samples announced for the UFF datasets' headers",
                        self.n
                    );
                }
                // An empty record: no block fixed the layout.
                let data_at =
                    if self.data_at.is_empty() { self.layout(len)?.0 } else { std::mem::take(&mut self.data_at) };
                for (k, at) in data_at.iter().enumerate() {
                    let head = self.header(k, n);
                    write_at(file, head.as_bytes(), at - head.len() as u64)?;
                    write_at(file, self.data_end(len), at + self.sample_at(len))?;
                }
            }
            Sink::Spilled { w, spill } => {
                for (k, s) in spill.into_iter().enumerate() {
                    w.write_all(self.header(k, n).as_bytes())?;
                    let mut f = s.into_inner().map_err(|e| anyhow!("spill file: {}", e.error()))?;
                    f.seek(SeekFrom::Start(0))?;
                    let mut r = BufReader::with_capacity(1 << 18, f);
                    if self.binary {
                        let copied = std::io::copy(&mut r, w)?;
                        if copied != 8 * self.n {
                            bail!("spill file: {copied} bytes read back for {} samples", self.n);
                        }
                    } else {
                        let mut b = [0u8; 8];
                        let mut i = 0u64;
                        let mut chunk = Vec::with_capacity(4096);
                        // Exactly n values back from the spill file: a
                        // short read is an error, not a shorter dataset.
                        while i < self.n {
                            chunk.clear();
                            while chunk.len() < 4096 && i + (chunk.len() as u64) < self.n {
                                r.read_exact(&mut b).context("spill file: read back")?;
                                chunk.push(f64::from_le_bytes(b));
                            }
                            self.encode(i, &chunk);
                            w.write_all(&self.bytes)?;
                            i += chunk.len() as u64;
                        }
                    }
                    w.write_all(self.data_end(self.n))?;
                }
            }
        }
        Ok(())
    }
}

/// Write all of `bytes` at `offset` of `file` (positioned: the file's
/// cursor does not move, nothing else is shared).
fn write_at(file: &File, bytes: &[u8], offset: u64) -> Result<()> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileExt;
        file.write_all_at(bytes, offset)?;
    }
    #[cfg(not(unix))]
    {
        let mut f = file;
        f.seek(SeekFrom::Start(offset))?;
        f.write_all(bytes)?;
    }
    Ok(())
}
