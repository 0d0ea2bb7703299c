//! Force records as NI TDMS files, read ([`TdmsReader`]) and written
//! ([`TdmsWriter`]) in a stream: memory does not grow with the record. A leaf
//! of the chain, behind the `io` signal traits.
//!
//! Format: NI's "TDMS File Format Internal Structure" (public); no NI or
//! third-party code.

use anyhow::{anyhow, bail, Context, Result};
use std::collections::HashMap;
use std::fs::File;
use std::io::{BufReader, Read, Write};
use std::path::Path;

use super::signal::ChannelMap;
use super::signal::{newton_per_unit, Block, SignalReader, SignalWriter};
use crate::frf::axis_name;

/// The lead-in's tag.
pub const TAG: &[u8; 4] = b"TDSm";
const LEAD_IN: u64 = 28;
const TOC_META: u32 = 1 << 1;
const TOC_NEW_OBJ_LIST: u32 = 1 << 2;
const TOC_RAW: u32 = 1 << 3;
const TOC_INTERLEAVED: u32 = 1 << 5;
const TOC_BIG_ENDIAN: u32 = 1 << 6;
const TOC_DAQMX: u32 = 1 << 7;
/// A next-segment offset of all ones: LabVIEW stopped writing this segment.
const INCOMPLETE: u64 = u64::MAX;
const TY_F64: u32 = 10;
const TY_STRING: u32 = 0x20;

/// Whether `head` (the first bytes of a file) is a TDMS file.
pub fn looks_like_tdms(head: &[u8]) -> bool {
    head.starts_with(TAG)
}

/// Size in bytes of a value of TDMS data type `ty` (None: variable, i.e. a
/// string, or unknown).
fn type_size(ty: u32) -> Option<u64> {
    Some(match ty {
        1 | 5 | 0x21 => 1,
        2 | 6 => 2,
        3 | 7 | 9 | 0x19 => 4,
        4 | 8 | 10 | 0x1A | 0x08_000C => 8,
        11 | 0x44 | 0x10_000D => 16,
        _ => return None,
    })
}

/// Whether `ty` is a real number type that a force channel can have.
fn is_real(ty: u32) -> bool {
    matches!(ty, 1..=10 | 0x19 | 0x1A)
}

fn type_name(ty: u32) -> String {
    match ty {
        1 => "i8".into(),
        2 => "i16".into(),
        3 => "i32".into(),
        4 => "i64".into(),
        5 => "u8".into(),
        6 => "u16".into(),
        7 => "u32".into(),
        8 => "u64".into(),
        9 | 0x19 => "f32".into(),
        10 | 0x1A => "f64".into(),
        11 => "extended float".into(),
        0x20 => "string".into(),
        0x21 => "boolean".into(),
        0x44 => "timestamp".into(),
        0x08_000C | 0x10_000D => "complex".into(),
        0xFFFF_FFFF => "DAQmx raw data".into(),
        t => format!("type 0x{t:X}"),
    }
}

/// Decode one value of real type `ty` from `b` (its size).
fn decode(ty: u32, big: bool, b: &[u8]) -> f64 {
    macro_rules! num {
        ($t:ty) => {{
            let mut a = [0u8; std::mem::size_of::<$t>()];
            let k = a.len();
            a.copy_from_slice(&b[..k]);
            (if big { <$t>::from_be_bytes(a) } else { <$t>::from_le_bytes(a) }) as f64
        }};
    }
    match ty {
        1 => num!(i8),
        2 => num!(i16),
        3 => num!(i32),
        4 => num!(i64),
        5 => num!(u8),
        6 => num!(u16),
        7 => num!(u32),
        8 => num!(u64),
        9 | 0x19 => num!(f32),
        _ => num!(f64),
    }
}

/// A property value, as far as this reader needs it.
#[derive(Clone, Debug, PartialEq)]
pub enum Prop {
    /// Any real or integer value.
    Num(f64),
    /// A string.
    Str(String),
    /// Anything else (timestamp, boolean, complex).
    Other,
}

/// An object's raw-data index in the current segment.
#[derive(Clone, Copy, Debug, PartialEq)]
struct RawIndex {
    ty: u32,
    /// Values per chunk.
    n: u64,
    /// Bytes per chunk.
    bytes: u64,
}

/// A file object (root, group or channel) as the metadata so far left it.
#[derive(Clone, Debug, Default)]
struct Object {
    path: String,
    /// The last raw-data index seen (for "same as before" indices).
    index: Option<RawIndex>,
    /// The object's data is DAQmx raw data.
    daqmx: bool,
    props: HashMap<String, Prop>,
    /// Values in the file so far.
    total: u64,
}

/// An object as a segment's metadata gives it: path, raw-data index (None:
/// no data; Some(None): as before; Some(Some): new), DAQmx, properties.
type FoundObject = (String, Option<Option<RawIndex>>, bool, Vec<(String, Prop)>);

/// One segment's layout, with its metadata applied.
#[derive(Clone, Debug, Default)]
struct Segment {
    /// 1-based number and file offset of the lead-in.
    no: usize,
    data_start: u64,
    data_end: u64,
    interleaved: bool,
    big: bool,
    /// Objects with raw data in this segment, in order, with their index.
    list: Vec<(usize, RawIndex)>,
    chunk_bytes: u64,
    chunks: u64,
}

/// A read position in a file, with relative seeks within the buffer.
struct Src {
    r: BufReader<File>,
    pos: u64,
    len: u64,
    source: String,
}

impl Src {
    fn open(path: &Path, source: &str) -> Result<Src> {
        let f = File::open(path).with_context(|| format!("{source}: cannot read"))?;
        let len = f.metadata().with_context(|| format!("{source}: cannot read"))?.len();
        Ok(Src { r: BufReader::with_capacity(1 << 18, f), pos: 0, len, source: source.to_string() })
    }

    fn seek(&mut self, to: u64) -> Result<()> {
        if to != self.pos {
            let d = i64::try_from(i128::from(to) - i128::from(self.pos))
                .map_err(|_| anyhow!("{}: offset {to}: seek out of range", self.source))?;
            self.r.seek_relative(d).with_context(|| format!("{}: offset {to}: seek failed", self.source))?;
            self.pos = to;
        }
        Ok(())
    }

    /// Read `buf.len()` bytes at the current position; `what` says what
    /// was being read when the file ends.
    fn read(&mut self, buf: &mut [u8], what: &dyn Fn() -> String) -> Result<()> {
        let at = self.pos;
        if at.saturating_add(buf.len() as u64) > self.len {
            bail!("{}: offset {at}: the file ends inside {} (truncated?)", self.source, what());
        }
        self.r.read_exact(buf).with_context(|| format!("{}: offset {at}: read failed in {}", self.source, what()))?;
        self.pos += buf.len() as u64;
        Ok(())
    }
}

/// Walks the segments of a file, applying their metadata.
///
/// The subset that DAQ software (NI-DAQmx logging, LabVIEW's TDMS Write,
/// npTDMS, DIAdem exports) writes for analog channels: segments of a
/// 28-byte lead-in (`TDSm`, ToC mask, version 4712/4713, next-segment and
/// raw-data offsets), metadata (objects by path, raw-data indices, typed
/// properties) and raw data; contiguous or interleaved; little- or
/// big-endian; incremental metadata (an object list carried over from the
/// previous segment, a raw-data index "same as before", properties added in
/// later segments); raw data repeated in several chunks per segment.
struct Walker {
    src: Src,
    next: u64,
    no: usize,
    objects: Vec<Object>,
    by_path: HashMap<String, usize>,
    /// The previous segment's layout (for segments without metadata and
    /// object lists carried over).
    prev: Segment,
    /// Apply properties (the index pass) or skip them (the data passes).
    keep_props: bool,
}

/// Little helper: read numbers in the segment's byte order.
struct Meta<'a> {
    src: &'a mut Src,
    big: bool,
    seg: usize,
    end: u64,
}

impl Meta<'_> {
    fn bytes(&mut self, n: u64, what: &str) -> Result<Vec<u8>> {
        if self.src.pos.saturating_add(n) > self.end {
            bail!(
                "{}: segment {}, offset {}: {what} of {n} bytes runs past the segment's metadata",
                self.src.source,
                self.seg,
                self.src.pos
            );
        }
        let mut b = vec![0u8; n as usize];
        let seg = self.seg;
        self.src.read(&mut b, &|| format!("segment {seg}'s metadata ({what})"))?;
        Ok(b)
    }
    fn u32(&mut self, what: &str) -> Result<u32> {
        let b = self.bytes(4, what)?;
        let a = [b[0], b[1], b[2], b[3]];
        Ok(if self.big { u32::from_be_bytes(a) } else { u32::from_le_bytes(a) })
    }
    fn u64(&mut self, what: &str) -> Result<u64> {
        let b = self.bytes(8, what)?;
        let mut a = [0u8; 8];
        a.copy_from_slice(&b);
        Ok(if self.big { u64::from_be_bytes(a) } else { u64::from_le_bytes(a) })
    }
    fn string(&mut self, what: &str) -> Result<String> {
        let at = self.src.pos;
        let n = self.u32(what)?;
        let b = self.bytes(u64::from(n), what)?;
        String::from_utf8(b)
            .map_err(|_| anyhow!("{}: segment {}, offset {at}: {what} is not UTF-8", self.src.source, self.seg))
    }
}

impl Walker {
    fn open(path: &Path, source: &str, keep_props: bool) -> Result<Walker> {
        Ok(Walker {
            src: Src::open(path, source)?,
            next: 0,
            no: 0,
            objects: Vec::new(),
            by_path: HashMap::new(),
            prev: Segment::default(),
            keep_props,
        })
    }

    fn object(&mut self, path: String) -> usize {
        if let Some(&i) = self.by_path.get(&path) {
            return i;
        }
        self.objects.push(Object { path: path.clone(), ..Object::default() });
        self.by_path.insert(path, self.objects.len() - 1);
        self.objects.len() - 1
    }

    /// The next segment, None at the end of the file: its lead-in, then its
    /// metadata (or the previous segment's object list), then the layout of
    /// its raw data.
    fn next_segment(&mut self) -> Result<Option<Segment>> {
        if self.next >= self.src.len {
            return Ok(None);
        }
        self.no += 1;
        let lead = self.lead_in()?;
        let mut seg = Segment {
            no: lead.no,
            data_start: lead.body + lead.raw_off,
            data_end: lead.body + lead.next_off,
            interleaved: lead.toc & TOC_INTERLEAVED != 0,
            big: lead.big,
            ..Segment::default()
        };
        seg.list = if lead.toc & TOC_META != 0 { self.metadata(&lead)? } else { self.prev.list.clone() };
        self.prev = Segment { list: seg.list.clone(), ..Segment::default() };
        if lead.toc & TOC_RAW == 0 {
            seg.list.clear();
        }
        if lead.toc & TOC_DAQMX != 0 {
            // DAQmx raw buffers: not laid out here; their channels are
            // refused if selected, the others of the segment too.
            for e in &seg.list {
                self.objects[e.0].daqmx = true;
            }
            seg.list.clear();
            return Ok(Some(seg));
        }
        self.lay_out(&mut seg, lead.at)?;
        Ok(Some(seg))
    }

    /// Read and check the 28-byte lead-in at the next segment's offset
    /// (tag, ToC mask, version, next-segment and raw-data offsets); moves
    /// the next segment's offset past this one.
    fn lead_in(&mut self) -> Result<LeadIn> {
        let (at, no) = (self.next, self.no);
        let source = self.src.source.clone();
        self.src.seek(at)?;
        let mut lead = [0u8; LEAD_IN as usize];
        self.src.read(&mut lead, &|| format!("the lead-in of segment {no}"))?;
        if &lead[..4] != TAG {
            bail!(
                "{source}: segment {no}, offset {at}: no TDMS lead-in (tag {:?}, expected \"TDSm\")",
                String::from_utf8_lossy(&lead[..4])
            );
        }
        let toc = u32::from_le_bytes([lead[4], lead[5], lead[6], lead[7]]);
        let big = toc & TOC_BIG_ENDIAN != 0;
        let version = u32_in(&lead[8..12], big);
        if version != 4712 && version != 4713 {
            bail!("{source}: segment {no}, offset {at}: TDMS version {version} (this reader knows 4712 and 4713)");
        }
        let next_off = u64_in(&lead[12..20], big);
        let raw_off = u64_in(&lead[20..28], big);
        let body = at + LEAD_IN;
        let left = self.src.len - body;
        if next_off == INCOMPLETE {
            bail!(
                "{source}: segment {no}, offset {at}: the segment was never finished (next-segment offset unset: \
                 the writer stopped); the record is incomplete"
            );
        }
        if next_off > left {
            bail!(
                "{source}: segment {no}, offset {at}: the segment declares {next_off} bytes after its lead-in, \
                 the file has {left}: the file is truncated"
            );
        }
        if raw_off > next_off {
            bail!(
                "{source}: segment {no}, offset {at}: raw data offset {raw_off} is beyond the segment's end \
                 ({next_off})"
            );
        }
        self.next = body + next_off;
        Ok(LeadIn { at, no, toc, big, body, next_off, raw_off })
    }

    /// Read the segment's metadata and apply it to the objects; returns the
    /// objects with raw data in this segment, in order, with their index.
    fn metadata(&mut self, lead: &LeadIn) -> Result<Vec<(usize, RawIndex)>> {
        let mut list = if lead.toc & TOC_NEW_OBJ_LIST != 0 { Vec::new() } else { self.prev.list.clone() };
        let keep_props = self.keep_props;
        let mut m = Meta { src: &mut self.src, big: lead.big, seg: lead.no, end: lead.body + lead.raw_off };
        let n_obj = m.u32("the number of objects")?;
        let mut found: Vec<FoundObject> = Vec::new();
        for _ in 0..n_obj {
            let path = m.string("an object path")?;
            let (index, daqmx) = raw_index(&mut m, &path)?;
            let props = properties(&mut m, &path, keep_props)?;
            found.push((path, index, daqmx, props));
        }
        for (path, index, daqmx, props) in found {
            let i = self.object(path);
            let o = &mut self.objects[i];
            for (k, v) in props {
                o.props.insert(k, v);
            }
            let ri = match index {
                None => {
                    // No data in this segment: off the list.
                    list.retain(|e| e.0 != i);
                    continue;
                }
                Some(Some(ri)) => {
                    o.daqmx = daqmx;
                    ri
                }
                Some(None) => o.index.ok_or_else(|| {
                    anyhow!(
                        "{}: segment {}: object {}: raw data index \"same as before\", but it had none",
                        self.src.source,
                        lead.no,
                        shown(&o.path)
                    )
                })?,
            };
            o.index = Some(ri);
            match list.iter_mut().find(|e| e.0 == i) {
                Some(e) => e.1 = ri,
                None => list.push((i, ri)),
            }
        }
        Ok(list)
    }

    /// Lay out the raw data of `seg` (lead-in at offset `at`): drop objects
    /// without values, count the chunks, check an interleaved segment's
    /// rows, add the values to the objects' totals.
    fn lay_out(&mut self, seg: &mut Segment, at: u64) -> Result<()> {
        let (source, no) = (&self.src.source, seg.no);
        let raw = seg.data_end - seg.data_start;
        seg.list.retain(|e| e.1.n > 0);
        seg.chunk_bytes = seg
            .list
            .iter()
            .try_fold(0u64, |s, e| s.checked_add(e.1.bytes))
            .ok_or_else(|| anyhow!("{source}: segment {no}, offset {at}: raw data sizes overflow"))?;
        if seg.chunk_bytes == 0 {
            seg.list.clear();
            seg.chunks = 0;
            return Ok(());
        }
        if !raw.is_multiple_of(seg.chunk_bytes) {
            bail!(
                "{source}: segment {no}, offset {at}: {raw} bytes of raw data are not a whole number of chunks of {} \
                 bytes (the metadata's channels)",
                seg.chunk_bytes
            );
        }
        seg.chunks = raw / seg.chunk_bytes;
        if seg.interleaved {
            let n0 = seg.list[0].1.n;
            if let Some(e) = seg.list.iter().find(|e| e.1.n != n0 || type_size(e.1.ty).is_none()) {
                bail!(
                    "{source}: segment {no}, offset {at}: interleaved data, but object {} has {} {} values where the \
                     first has {n0}",
                    shown(&self.objects[e.0].path),
                    e.1.n,
                    type_name(e.1.ty)
                );
            }
        }
        for e in &seg.list {
            let o = &mut self.objects[e.0];
            o.total = o.total.saturating_add(e.1.n.saturating_mul(seg.chunks));
        }
        Ok(())
    }
}

/// A segment's lead-in, checked.
struct LeadIn {
    /// File offset and 1-based number of the segment.
    at: u64,
    no: usize,
    /// Table of contents mask.
    toc: u32,
    big: bool,
    /// Offset of the metadata (after the lead-in).
    body: u64,
    /// Next segment and raw data, in bytes from `body`.
    next_off: u64,
    raw_off: u64,
}

/// A u32 from the 4 bytes `b` in the given byte order.
fn u32_in(b: &[u8], big: bool) -> u32 {
    let a = [b[0], b[1], b[2], b[3]];
    if big {
        u32::from_be_bytes(a)
    } else {
        u32::from_le_bytes(a)
    }
}

/// A u64 from the 8 bytes `b` in the given byte order.
fn u64_in(b: &[u8], big: bool) -> u64 {
    let mut a = [0u8; 8];
    a.copy_from_slice(b);
    if big {
        u64::from_be_bytes(a)
    } else {
        u64::from_le_bytes(a)
    }
}

/// An object's raw-data index in the metadata (None: no data; Some(None):
/// as before; Some(Some): new) and whether it is DAQmx raw data, whose
/// scaler description is skipped.
fn raw_index(m: &mut Meta, path: &str) -> Result<(Option<Option<RawIndex>>, bool)> {
    let (source, no) = (m.src.source.clone(), m.seg);
    let at_idx = m.src.pos;
    let idx_len = m.u32("a raw data index")?;
    Ok(match idx_len {
        0xFFFF_FFFF => (None, false),
        0 => (Some(None), false),
        0x6912_0000..=0x6913_FFFF => {
            // DAQmx format-changing scaler / digital line scaler: skip its description.
            let ty = m.u32("a DAQmx index")?;
            let _dim = m.u32("a DAQmx index")?;
            let n = m.u64("a DAQmx index")?;
            let n_scalers = m.u32("a DAQmx index")?;
            let sz = if idx_len >> 16 == 0x6912 { 17u64 } else { 9 };
            m.bytes(u64::from(n_scalers).saturating_mul(sz), "DAQmx scalers")?;
            let n_widths = m.u32("a DAQmx index")?;
            let widths = m.bytes(u64::from(n_widths).saturating_mul(4), "DAQmx raw data widths")?;
            let w: u64 = widths.chunks_exact(4).map(|c| u64::from(u32_in(c, m.big))).sum();
            (Some(Some(RawIndex { ty, n, bytes: n.saturating_mul(w) })), true)
        }
        l => {
            let ty = m.u32("a raw data index")?;
            let dim = m.u32("a raw data index")?;
            let n = m.u64("a raw data index")?;
            let here = || format!("{source}: segment {no}, offset {at_idx}: object {}", shown(path));
            if dim != 1 {
                bail!("{}: array dimension {dim} (TDMS allows 1)", here());
            }
            let bytes = match type_size(ty) {
                Some(s) if l == 20 => n.checked_mul(s),
                None if ty == TY_STRING && l == 28 => Some(m.u64("a raw data index")?),
                _ => bail!("{}: raw data index of {l} bytes for {} values", here(), type_name(ty)),
            }
            .ok_or_else(|| anyhow!("{}: {n} values overflow", here()))?;
            (Some(Some(RawIndex { ty, n, bytes })), false)
        }
    })
}

/// An object's properties in the metadata; real values kept as numbers,
/// strings as strings. Returned only if `keep` (else read past).
fn properties(m: &mut Meta, path: &str, keep: bool) -> Result<Vec<(String, Prop)>> {
    let n_props = m.u32("the number of properties")?;
    let mut props = Vec::new();
    for _ in 0..n_props {
        let name = m.string("a property name")?;
        let at_p = m.src.pos;
        let ty = m.u32("a property type")?;
        let v = match ty {
            TY_STRING => Prop::Str(m.string("a string property")?),
            t if is_real(t) => {
                let sz = type_size(t).unwrap_or(8);
                let b = m.bytes(sz, "a property value")?;
                Prop::Num(decode(t, m.big, &b))
            }
            t => match type_size(t) {
                Some(sz) => {
                    m.bytes(sz, "a property value")?;
                    Prop::Other
                }
                None => bail!(
                    "{}: segment {}, offset {at_p}: property {name:?} of {}: unknown data type 0x{t:X}",
                    m.src.source,
                    m.seg,
                    shown(path)
                ),
            },
        };
        if keep {
            props.push((name, v));
        }
    }
    Ok(props)
}

/// A name or path from the file as shown in a one-line message.
use super::one_line as shown;

/// `/'group'/'channel'` → (group, channel); None for the root and groups.
fn split_path(p: &str) -> Option<(String, String)> {
    let mut parts = Vec::new();
    let mut cur = String::new();
    let mut chars = p.chars().peekable();
    while let Some(c) = chars.next() {
        match c {
            '/' if cur.is_empty() => {
                if chars.next() != Some('\'') {
                    return None;
                }
                loop {
                    match chars.next() {
                        Some('\'') if chars.peek() == Some(&'\'') => {
                            chars.next();
                            cur.push('\'');
                        }
                        Some('\'') => break,
                        Some(c) => cur.push(c),
                        None => return None,
                    }
                }
                parts.push(std::mem::take(&mut cur));
            }
            _ => return None,
        }
    }
    match <[String; 2]>::try_from(parts) {
        Ok([g, c]) => Some((g, c)),
        Err(_) => None,
    }
}

/// `group`/`channel` as a TDMS path.
fn make_path(group: &str, channel: Option<&str>) -> String {
    let q = |s: &str| format!("/'{}'", s.replace('\'', "''"));
    match channel {
        Some(c) => format!("{}{}", q(group), q(c)),
        None => q(group),
    }
}

/// The axis a channel name says: `Fx`, `F_x`, `Force X`, `force-y`, `X`
/// (case-insensitive, spaces, `_` and `-` ignored).
pub fn axis_from_name(name: &str) -> Option<usize> {
    let n: String = name.chars().filter(|c| !matches!(c, ' ' | '_' | '-' | '.')).flat_map(char::to_lowercase).collect();
    let axis = n.strip_prefix("force").or_else(|| n.strip_prefix('f')).unwrap_or(&n);
    match axis {
        "x" => Some(0),
        "y" => Some(1),
        "z" => Some(2),
        _ => None,
    }
}

/// One selected channel's read cursor (its own file handle and walk).
struct Cursor {
    walker: Walker,
    obj: usize,
    seg: Option<Segment>,
    /// Position in the current segment: chunk number.
    chunk: u64,
    /// Current run: next value's offset, values left, stride.
    off: u64,
    left: u64,
    stride: u64,
    ty: u32,
    big: bool,
    buf: Vec<u8>,
}

impl Cursor {
    /// Start the next run of this channel's values; false at the end.
    fn next_run(&mut self) -> Result<bool> {
        loop {
            if let Some(seg) = &self.seg {
                if self.chunk < seg.chunks {
                    let k = seg.list.iter().position(|e| e.0 == self.obj);
                    if let Some(k) = k {
                        let ri = seg.list[k].1;
                        let size = type_size(ri.ty).unwrap_or(8);
                        if seg.interleaved {
                            let col: u64 = seg.list[..k].iter().map(|e| type_size(e.1.ty).unwrap_or(0)).sum();
                            let row: u64 = seg.list.iter().map(|e| type_size(e.1.ty).unwrap_or(0)).sum();
                            self.off = seg.data_start + col;
                            self.left = ri.n * seg.chunks;
                            self.stride = row;
                            self.chunk = seg.chunks;
                        } else {
                            let before: u64 = seg.list[..k].iter().map(|e| e.1.bytes).sum();
                            self.off = seg.data_start + self.chunk * seg.chunk_bytes + before;
                            self.left = ri.n;
                            self.stride = size;
                            self.chunk += 1;
                        }
                        self.ty = ri.ty;
                        self.big = seg.big;
                        return Ok(true);
                    }
                }
            }
            match self.walker.next_segment()? {
                Some(s) => {
                    self.seg = Some(s);
                    self.chunk = 0;
                }
                None => return Ok(false),
            }
        }
    }

    /// Append the next `m` values of the current run (`m` ≤ its values
    /// left), in N (times `scale`), to `out`.
    fn take(&mut self, m: usize, scale: f64, out: &mut Vec<f64>) -> Result<()> {
        let size = type_size(self.ty).unwrap_or(8) as usize;
        let stride = self.stride as usize;
        let span = (m - 1) * stride + size;
        self.buf.resize(span, 0);
        self.walker.src.seek(self.off)?;
        let no = self.seg.as_ref().map_or(0, |s| s.no);
        let mut buf = std::mem::take(&mut self.buf);
        self.walker.src.read(&mut buf, &|| format!("the raw data of segment {no}"))?;
        let (ty, big) = (self.ty, self.big);
        out.extend(buf.chunks(stride).take(m).map(|b| scale * decode(ty, big, &b[..size])));
        self.buf = buf;
        self.advance(m);
        Ok(())
    }

    fn advance(&mut self, m: usize) {
        self.off += m as u64 * self.stride;
        self.left -= m as u64;
    }

    /// The segment of the current run, if it is interleaved.
    fn interleaved_segment(&self) -> Option<usize> {
        self.seg.as_ref().filter(|s| s.interleaved && self.left > 0).map(|s| s.no)
    }
}

/// Read the next `m` values of every cursor, all in the same interleaved
/// segment, with one read of the rows through the first cursor's handle.
fn take_rows(cursors: &mut [Cursor], m: usize, scale: &[f64], outs: &mut [Vec<f64>]) -> Result<()> {
    let stride = cursors[0].stride;
    let base = cursors.iter().map(|c| c.off).min().unwrap_or(0);
    let span = cursors
        .iter()
        .map(|c| c.off - base + (m as u64 - 1) * stride + type_size(c.ty).unwrap_or(8))
        .max()
        .unwrap_or(0);
    let (first, _) = cursors.split_at_mut(1);
    let c0 = &mut first[0];
    let mut buf = std::mem::take(&mut c0.buf);
    buf.resize(span as usize, 0);
    c0.walker.src.seek(base)?;
    let no = c0.seg.as_ref().map_or(0, |s| s.no);
    c0.walker.src.read(&mut buf, &|| format!("the raw data of segment {no}"))?;
    let stride = stride as usize;
    for ((c, out), k) in cursors.iter_mut().zip(outs.iter_mut()).zip(scale) {
        let size = type_size(c.ty).unwrap_or(8) as usize;
        let at = (c.off - base) as usize;
        let (ty, big) = (c.ty, c.big);
        out.extend(buf[at..].chunks(stride).take(m).map(|b| k * decode(ty, big, &b[..size])));
        c.advance(m);
    }
    cursors[0].buf = buf;
    Ok(())
}

/// The channels of the file: (object, group, name).
fn channels(w: &Walker) -> Vec<(usize, String, String)> {
    w.objects.iter().enumerate().filter_map(|(i, o)| split_path(&o.path).map(|(g, c)| (i, g, c))).collect()
}

/// The channels of the file as `group/name`, for messages.
fn channel_list(chans: &[(usize, String, String)]) -> String {
    chans.iter().map(|c| shown(&format!("{}/{}", c.1, c.2))).collect::<Vec<_>>().join(", ")
}

/// (axis, object) of each channel `--channels` names, by name or GROUP/NAME.
fn pick_by_map(w: &Walker, source: &str, m: &ChannelMap) -> Result<Vec<(usize, usize)>> {
    let chans = channels(w);
    let mut picked = Vec::new();
    for (axis, want) in &m.pairs {
        let hits: Vec<&(usize, String, String)> = chans
            .iter()
            .filter(|(_, g, c)| c.eq_ignore_ascii_case(want) || format!("{g}/{c}").eq_ignore_ascii_case(want))
            .collect();
        match hits.as_slice() {
            [one] => picked.push((*axis, one.0)),
            [] => bail!(
                "{source}: --channels f{}={want}: no such channel (channels: {})",
                axis_name(*axis),
                channel_list(&chans)
            ),
            _ => bail!("{source}: --channels f{}={want}: several groups have it; give GROUP/NAME", axis_name(*axis)),
        }
    }
    Ok(picked)
}

/// (axis, object) of each channel whose name says a force axis ([`axis_from_name`]), one per axis.
fn pick_by_name(w: &Walker, source: &str) -> Result<Vec<(usize, usize)>> {
    let chans = channels(w);
    let label = |g: &str, c: &str| shown(&format!("{g}/{c}"));
    // (axis, object, `group/name`) of each channel picked so far.
    let mut picked: Vec<(usize, usize, String)> = Vec::new();
    for (i, g, c) in &chans {
        if let Some(axis) = axis_from_name(c) {
            if let Some(other) = picked.iter().find(|p| p.0 == axis) {
                bail!(
                    "{source}: channels {} and {} are both axis {}; pick one with --channels f{}=GROUP/NAME",
                    other.2,
                    label(g, c),
                    axis_name(axis),
                    axis_name(axis)
                );
            }
            picked.push((axis, *i, label(g, c)));
        }
    }
    if picked.is_empty() {
        bail!(
            "{source}: no channel named for a force axis (Fx, Force X, ...); channels: {}; give --channels fx=NAME,...",
            if chans.is_empty() { "none".to_string() } else { channel_list(&chans) }
        );
    }
    Ok(picked.into_iter().map(|(axis, object, _)| (axis, object)).collect())
}

/// The picked channels as one record: names, scale to N, sampling interval
/// (s, from `wf_increment`) and length.
struct Record {
    names: Vec<String>,
    scale: Vec<f64>,
    dt: Option<f64>,
    n: u64,
}

/// Check the picked channels (axis, object): scaled real data, a force
/// unit, one sampling interval and one length for all.
fn check_channels(w: &Walker, source: &str, picked: &[(usize, usize)]) -> Result<Record> {
    let mut names = Vec::new();
    let mut scale = Vec::new();
    let mut dt: Option<(f64, String)> = None;
    let mut n: Option<(u64, String)> = None;
    for &(axis, i) in picked {
        let o = &w.objects[i];
        let (g, c) = split_path(&o.path).unwrap_or_default();
        let name = shown(&format!("{g}/{c}"));
        let here = format!("{source}: channel {name} (f{})", axis_name(axis));
        let k = channel_scale(o, &here)?;
        check_rate(o, &here, &name, &mut dt)?;
        match &n {
            Some((n0, c0)) if *n0 != o.total => {
                bail!("{here}: {} samples, but channel {c0} has {n0}: channels must have the same length", o.total)
            }
            Some(_) => {}
            None => n = Some((o.total, name.clone())),
        }
        names.push(name);
        scale.push(k);
    }
    Ok(Record { names, scale, dt: dt.map(|x| x.0), n: n.map_or(0, |x| x.0) })
}

/// A channel's data must be scaled real numbers; returns N per unit of its
/// `unit_string` (N, kN, mN; 1 without one). `here` names the channel.
///
/// The channels read must be real numbers (i8…i64, u8…u64, f32, f64, with or
/// without unit), unscaled by DAQmx: DAQmx raw data (the `NI_Scaling`
/// properties, ADC codes to be scaled) is refused with a message saying so.
/// Other channels of the file (strings, timestamps, DAQmx) are skipped.
fn channel_scale(o: &Object, here: &str) -> Result<f64> {
    if o.daqmx {
        bail!(
            "{here}: DAQmx raw data (ADC codes with NI_Scaling properties) is not supported; log scaled data or \
             convert the file"
        );
    }
    if matches!(o.props.get("NI_Scaling_Status"), Some(Prop::Str(s)) if s.eq_ignore_ascii_case("unscaled")) {
        bail!("{here}: NI_Scaling_Status is \"unscaled\" (raw values needing NI scaling); log scaled data");
    }
    let ty = o.index.map_or(0, |r| r.ty);
    if o.total == 0 {
        bail!("{here}: no data");
    }
    if !is_real(ty) {
        bail!("{here}: {} values; a force channel must be real numbers", type_name(ty));
    }
    Ok(match o.props.get("unit_string") {
        Some(Prop::Str(u)) => {
            newton_per_unit(u).ok_or_else(|| anyhow!("{here}: unit {u:?}; expected N (kN and mN are scaled)"))?
        }
        _ => 1.0,
    })
}

/// A channel's `wf_increment` (s), if any, must be a positive sampling
/// interval, the same as the first channel's (`dt`: interval and channel
/// name); its `wf_start_offset`, if a number, finite.
fn check_rate(o: &Object, here: &str, name: &str, dt: &mut Option<(f64, String)>) -> Result<()> {
    match o.props.get("wf_increment") {
        Some(Prop::Num(d)) => {
            if !(d.is_finite() && *d > 0.0) {
                bail!("{here}: property wf_increment = {d} s is not a positive sampling interval");
            }
            match &dt {
                Some((d0, c0)) if ((d - d0) / d0).abs() > 1e-6 => {
                    bail!("{here}: wf_increment {d} s, but channel {c0} has {d0} s: channels must share a rate")
                }
                Some(_) => {}
                None => *dt = Some((*d, name.to_string())),
            }
        }
        Some(_) => bail!("{here}: property wf_increment is not a number"),
        None => {}
    }
    match o.props.get("wf_start_offset") {
        Some(Prop::Num(t)) if !t.is_finite() => bail!("{here}: property wf_start_offset = {t} s is not finite"),
        // Another type (none in NI's writers) is ignored: times start at 0.
        _ => {}
    }
    Ok(())
}

/// A reader of the force channels of a TDMS file.
///
/// Axis by channel name (`Fx`, `Force X`, `force_y`, … case-insensitive,
/// or `--channels fx=NAME` / `fx=GROUP/NAME`); sample rate from the
/// channel's `wf_increment`; `unit_string` N, kN or mN (scaled to N).
///
/// Why not a crate (checked 2026-11): `tdms` 0.3 reads raw data only as bytes
/// and cannot write; `tedium` 0.2 (early stage, by its README) re-plans a read
/// over every data block of the file on each offset read (quadratic when
/// streaming a long record in blocks), must be told each channel's storage
/// type, and reports errors without a place; `tdms-rs` 2.0 ends silently at a
/// truncated segment and reads raw data in the machine's byte order only.
pub struct TdmsReader {
    source: String,
    axes: Vec<usize>,
    names: Vec<String>,
    cursors: Vec<Cursor>,
    scale: Vec<f64>,
    n: u64,
    done: u64,
    dt: Option<f64>,
    start: Option<f64>,
}

impl TdmsReader {
    /// Index `path` and pick the force channels (by name, or by `map`).
    pub fn open(path: &Path, map: Option<&ChannelMap>) -> Result<TdmsReader> {
        let source = path.display().to_string();
        let mut w = Walker::open(path, &source, true)?;
        let mut n_seg = 0;
        while w.next_segment()?.is_some() {
            n_seg += 1;
        }
        if n_seg == 0 {
            bail!("{source}: empty file (no TDMS segment)");
        }
        let mut picked = match map {
            Some(m) => pick_by_map(&w, &source, m)?,
            None => pick_by_name(&w, &source)?,
        };
        picked.sort_by_key(|p| p.0);
        let rec = check_channels(&w, &source, &picked)?;
        let mut cursors = Vec::new();
        for &(_, i) in &picked {
            cursors.push(Cursor {
                walker: Walker::open(path, &source, false)?,
                obj: i,
                seg: None,
                chunk: 0,
                off: 0,
                left: 0,
                stride: 8,
                ty: TY_F64,
                big: false,
                buf: Vec::new(),
            });
        }
        Ok(TdmsReader {
            source,
            axes: picked.iter().map(|p| p.0).collect(),
            names: rec.names,
            cursors,
            scale: rec.scale,
            n: rec.n,
            done: 0,
            dt: rec.dt,
            start: picked.first().and_then(|p| match w.objects[p.1].props.get("wf_start_offset") {
                Some(Prop::Num(v)) => Some(*v),
                _ => None,
            }),
        })
    }

    /// The first channel's `wf_start_offset` (s), if it has one.
    pub fn start_offset_s(&self) -> Option<f64> {
        self.start
    }

    /// The channels read, as `group/name`, in axis order.
    pub fn channel_names(&self) -> &[String] {
        &self.names
    }
}

impl SignalReader for TdmsReader {
    fn axes(&self) -> &[usize] {
        &self.axes
    }

    /// Times from the channels' waveform properties (`wf_start_offset`, 0
    /// if absent, and `wf_increment`), when they have them.
    fn has_time(&self) -> bool {
        self.dt.is_some()
    }

    fn declared_fs_hz(&self) -> Option<f64> {
        self.dt.map(|d| 1.0 / d)
    }

    fn len_hint(&self) -> Option<u64> {
        Some(self.n)
    }

    fn read_block(&mut self, blk: &mut Block, max: usize) -> Result<usize> {
        blk.clear();
        blk.channels.resize(self.cursors.len(), Vec::new());
        let left = usize::try_from(self.n - self.done).unwrap_or(usize::MAX).min(max);
        let mut got = 0usize;
        while got < left {
            for c in &mut self.cursors {
                if c.left == 0 && !c.next_run()? {
                    bail!("{}: a channel ends early (internal error: the index pass counted more values)", self.source);
                }
            }
            let m = self
                .cursors
                .iter()
                .map(|c| c.left)
                .min()
                .map_or(0, |l| usize::try_from(l).unwrap_or(usize::MAX))
                .min(left - got);
            let seg0 = self.cursors[0].interleaved_segment();
            if seg0.is_some()
                && self.cursors.iter().all(|c| c.interleaved_segment() == seg0 && c.stride == self.cursors[0].stride)
            {
                // Interleaved rows: one read for all channels.
                take_rows(&mut self.cursors, m, &self.scale, &mut blk.channels)?;
            } else {
                for (i, c) in self.cursors.iter_mut().enumerate() {
                    c.take(m, self.scale[i], &mut blk.channels[i])?;
                }
            }
            got += m;
        }
        for i in 0..self.cursors.len() {
            if let Some(k) = blk.channels[i].iter().position(|v| !v.is_finite()) {
                bail!(
                    "{}: channel {}: value {} (sample {}) is not finite; values must be finite",
                    self.source,
                    self.names[i],
                    blk.channels[i][k],
                    self.done + k as u64
                );
            }
        }
        if let Some(dt) = self.dt {
            blk.push_even_times(self.start.unwrap_or(0.0), dt, self.done, left);
        }
        self.done += left as u64;
        Ok(left)
    }
}

/// A writer of a TDMS file: group `dynocomp`, one f64 channel per axis
/// named `Fx`/`Fy`/`Fz`, with `wf_increment` = 1/fs, `wf_start_offset`
/// (the first sample's time if the blocks carry times, else `t0_s`),
/// `wf_samples` and `unit_string` N; interleaved segments, one per block.
///
/// Little-endian; full metadata in the first segment and whenever the block length changes
/// (the last block), a bare lead-in otherwise.
pub struct TdmsWriter<'w> {
    w: &'w mut dyn Write,
    axes: Vec<usize>,
    dt: f64,
    t0: f64,
    prev_n: Option<usize>,
    any: bool,
    buf: Vec<u8>,
}

impl<'w> TdmsWriter<'w> {
    /// A writer for `axes` at `fs_hz`; `t0_s` is the time of the first
    /// sample (`wf_start_offset`).
    pub fn new(w: &'w mut dyn Write, axes: &[usize], fs_hz: f64, t0_s: f64) -> Result<Self> {
        Ok(TdmsWriter { w, axes: axes.to_vec(), dt: 1.0 / fs_hz, t0: t0_s, prev_n: None, any: false, buf: Vec::new() })
    }

    /// Metadata for blocks of `n` samples (properties on the first).
    fn metadata(&self, n: usize, first: bool) -> Vec<u8> {
        let mut m = Vec::new();
        let s = |m: &mut Vec<u8>, v: &str| {
            m.extend_from_slice(&(v.len() as u32).to_le_bytes());
            m.extend_from_slice(v.as_bytes());
        };
        let objs = if first { 2 + self.axes.len() } else { self.axes.len() };
        m.extend_from_slice(&(objs as u32).to_le_bytes());
        if first {
            s(&mut m, "/");
            m.extend_from_slice(&u32::MAX.to_le_bytes());
            m.extend_from_slice(&1u32.to_le_bytes());
            s(&mut m, "name");
            m.extend_from_slice(&TY_STRING.to_le_bytes());
            s(&mut m, "dynocomp compensated forces");
            s(&mut m, &make_path("dynocomp", None));
            m.extend_from_slice(&u32::MAX.to_le_bytes());
            m.extend_from_slice(&0u32.to_le_bytes());
        }
        for &a in &self.axes {
            s(&mut m, &make_path("dynocomp", Some(&format!("F{}", axis_name(a)))));
            m.extend_from_slice(&20u32.to_le_bytes());
            m.extend_from_slice(&TY_F64.to_le_bytes());
            m.extend_from_slice(&1u32.to_le_bytes());
            m.extend_from_slice(&(n as u64).to_le_bytes());
            if first {
                m.extend_from_slice(&4u32.to_le_bytes());
                for (k, v) in [("wf_increment", self.dt), ("wf_start_offset", self.t0)] {
                    s(&mut m, k);
                    m.extend_from_slice(&TY_F64.to_le_bytes());
                    m.extend_from_slice(&v.to_le_bytes());
                }
                s(&mut m, "wf_samples");
                m.extend_from_slice(&3u32.to_le_bytes());
                m.extend_from_slice(&(n.min(i32::MAX as usize) as i32).to_le_bytes());
                s(&mut m, "unit_string");
                m.extend_from_slice(&TY_STRING.to_le_bytes());
                s(&mut m, "N");
            } else {
                m.extend_from_slice(&0u32.to_le_bytes());
            }
        }
        m
    }

    fn segment(&mut self, toc: u32, meta: &[u8], raw: &[u8]) -> Result<()> {
        let mut lead = Vec::with_capacity(LEAD_IN as usize);
        lead.extend_from_slice(TAG);
        lead.extend_from_slice(&toc.to_le_bytes());
        lead.extend_from_slice(&4713u32.to_le_bytes());
        lead.extend_from_slice(&((meta.len() + raw.len()) as u64).to_le_bytes());
        lead.extend_from_slice(&(meta.len() as u64).to_le_bytes());
        self.w.write_all(&lead)?;
        self.w.write_all(meta)?;
        self.w.write_all(raw)?;
        Ok(())
    }
}

impl SignalWriter for TdmsWriter<'_> {
    fn write_block(&mut self, t_s: Option<&[f64]>, channels: &[&[f64]]) -> Result<()> {
        if !self.any {
            // The input's time base, if it has times (a CSV's t_s).
            if let Some(&t) = t_s.and_then(|t| t.first()) {
                self.t0 = t;
            }
        }
        let n = channels.first().map_or(0, |c| c.len());
        if channels.len() != self.axes.len() || channels.iter().any(|c| c.len() != n) {
            bail!("internal error: a block does not match the output's channels");
        }
        if n == 0 {
            return Ok(());
        }
        let mut buf = std::mem::take(&mut self.buf);
        buf.clear();
        for k in 0..n {
            for c in channels {
                buf.extend_from_slice(&c[k].to_le_bytes());
            }
        }
        let r = if self.prev_n == Some(n) {
            self.segment(TOC_RAW | TOC_INTERLEAVED, &[], &buf)
        } else {
            let meta = self.metadata(n, !self.any);
            let toc = TOC_META | TOC_RAW | TOC_INTERLEAVED | if self.any { 0 } else { TOC_NEW_OBJ_LIST };
            self.segment(toc, &meta, &buf)
        };
        self.buf = buf;
        self.prev_n = Some(n);
        self.any = true;
        r
    }

    fn finish(&mut self) -> Result<()> {
        if !self.any {
            let meta = self.metadata(0, true);
            self.segment(TOC_META | TOC_NEW_OBJ_LIST, &meta, &[])?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_say_the_axis() {
        for (n, a) in [
            ("Fx", Some(0)),
            ("Force Y", Some(1)),
            ("force_z", Some(2)),
            ("F-X", Some(0)),
            ("Z", Some(2)),
            ("Fxy", None),
            ("Torque", None),
            ("", None),
        ] {
            assert_eq!(axis_from_name(n), a, "{n}");
        }
    }

    #[test]
    fn paths_split_and_quote() {
        assert_eq!(split_path("/'Group'/'Force X'"), Some(("Group".into(), "Force X".into())));
        assert_eq!(split_path(&make_path("it's", Some("a/b"))), Some(("it's".into(), "a/b".into())));
        assert_eq!(split_path("/'Group'"), None);
        assert_eq!(split_path("/"), None);
        assert_eq!(split_path("/'a'/'b"), None);
    }
}
