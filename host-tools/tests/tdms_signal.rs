//! Issue #14: force records as NI TDMS files: written and read back, read
//! from files built here byte by byte after NI's published layout
//! (interleaved and contiguous raw data, several segments and chunks,
//! incremental metadata, big-endian, integer and f32 channels), through
//! `compensate`, and refused with a message naming the file, segment or
//! channel when they are wrong.

use dynocomp::io::signal::ChannelMap;
use dynocomp::io::signal::{read_all, SignalWriter};
use dynocomp::io::signal_csv::read_signal_csv;
use dynocomp::io::signal_file::{open_signal, SignalFormat};
use dynocomp::io::tdms::TdmsWriter;
use dynocomp::offline::compensate::compensate_record;
use std::path::{Path, PathBuf};

use crate::cli_common;
use crate::common;
use cli_common::{dynocomp, example, tmp};

// ---- an independent builder of TDMS bytes (test side) ----

const META: u32 = 1 << 1;
const NEW_LIST: u32 = 1 << 2;
const RAW: u32 = 1 << 3;
const INTERLEAVED: u32 = 1 << 5;
const BIG: u32 = 1 << 6;
const DAQMX: u32 = 1 << 7;

/// Bytes in a segment's byte order.
struct Bytes {
    big: bool,
    b: Vec<u8>,
}

impl Bytes {
    fn u32(&mut self, v: u32) -> &mut Self {
        self.b.extend_from_slice(&if self.big { v.to_be_bytes() } else { v.to_le_bytes() });
        self
    }
    fn u64(&mut self, v: u64) -> &mut Self {
        self.b.extend_from_slice(&if self.big { v.to_be_bytes() } else { v.to_le_bytes() });
        self
    }
    fn f64(&mut self, v: f64) -> &mut Self {
        self.b.extend_from_slice(&if self.big { v.to_be_bytes() } else { v.to_le_bytes() });
        self
    }
    fn str(&mut self, s: &str) -> &mut Self {
        self.u32(s.len() as u32);
        self.b.extend_from_slice(s.as_bytes());
        self
    }
}

/// An object of a segment's metadata.
enum Index {
    None,
    Same,
    Daqmx,
    /// (type, values per chunk)
    New(u32, u64),
}

enum P {
    F64(f64),
    Str(&'static str),
}

struct Obj {
    path: String,
    index: Index,
    props: Vec<(&'static str, P)>,
}

fn ch(name: &str, index: Index, props: Vec<(&'static str, P)>) -> Obj {
    Obj { path: format!("/'Cut 1'/'{name}'"), index, props }
}

/// One segment: lead-in, metadata (if `objs` is Some), raw bytes.
fn segment(toc: u32, objs: Option<&[Obj]>, raw: &[u8]) -> Vec<u8> {
    let big = toc & BIG != 0;
    let mut m = Bytes { big, b: Vec::new() };
    if let Some(objs) = objs {
        m.u32(objs.len() as u32);
        for o in objs {
            m.str(&o.path);
            match o.index {
                Index::None => m.u32(0xFFFF_FFFF),
                Index::Same => m.u32(0),
                Index::Daqmx => m
                    .u32(0x6912_0000)
                    .u32(0xFFFF_FFFF)
                    .u32(1)
                    .u64(4)
                    .u32(1)
                    .u32(3)
                    .u32(0)
                    .u32(0)
                    .b(0)
                    .u32(0)
                    .u32(1)
                    .u32(2),
                Index::New(ty, n) => m.u32(20).u32(ty).u32(1).u64(n),
            };
            m.u32(o.props.len() as u32);
            for (k, v) in &o.props {
                m.str(k);
                match v {
                    P::F64(x) => m.u32(10).f64(*x),
                    P::Str(s) => m.u32(0x20).str(s),
                };
            }
        }
    }
    let mut s = Bytes { big, b: Vec::new() };
    s.b.extend_from_slice(b"TDSm");
    s.b.extend_from_slice(&toc.to_le_bytes());
    s.u32(4713).u64((m.b.len() + raw.len()) as u64).u64(m.b.len() as u64);
    s.b.extend_from_slice(&m.b);
    s.b.extend_from_slice(raw);
    s.b
}

impl Bytes {
    fn b(&mut self, v: u8) -> &mut Self {
        self.b.push(v);
        self
    }
}

/// (axes, declared rate, channels) of a TDMS record, or the error.
type Read = (Vec<usize>, Option<f64>, Vec<Vec<f64>>);

fn read(p: &Path, m: Option<&ChannelMap>) -> Result<Read, String> {
    let (mut r, fmt) = open_signal(p, m).map_err(|e| format!("{e:#}"))?;
    assert_eq!(fmt, SignalFormat::Tdms);
    let axes = r.axes().to_vec();
    let fs = r.declared_fs_hz();
    let (_, c) = read_all(&mut *r).map_err(|e| format!("{e:#}"))?;
    Ok((axes, fs, c))
}

fn signals(n: usize) -> Vec<Vec<f64>> {
    (0..3).map(|a| (0..n).map(|k| (((k * (a + 1)) as f64 * 0.01).sin() * 100.0) as f32 as f64).collect()).collect()
}

fn write_tdms(path: &Path, chans: &[Vec<f64>], fs: f64, block: usize) {
    let mut bytes = Vec::new();
    {
        let axes: Vec<usize> = (0..chans.len()).collect();
        let mut w = TdmsWriter::new(&mut bytes, &axes, fs, 0.0).unwrap();
        let n = chans[0].len();
        for s in (0..n).step_by(block) {
            let e = (s + block).min(n);
            let sl: Vec<&[f64]> = chans.iter().map(|c| &c[s..e]).collect();
            w.write_block(None, &sl).unwrap();
        }
        w.finish().unwrap();
    }
    std::fs::write(path, bytes).unwrap();
}

/// The writer's file reads back bit for bit, with the rate it declares,
/// across segments with and without metadata (blocks of 1000, last 7).
#[test]
fn tdms_round_trip() {
    let x = signals(10_007);
    let p = tmp("tdmsrt", "rt.tdms");
    write_tdms(&p, &x, 51200.0, 1000);
    let (axes, fs, got) = read(&p, None).unwrap();
    assert_eq!(axes, vec![0, 1, 2]);
    assert!((fs.unwrap() - 51200.0).abs() < 1e-6);
    for (g, w) in got.iter().zip(&x) {
        assert_eq!(g.len(), w.len());
        assert!(g.iter().zip(w).all(|(a, b)| a.to_bits() == b.to_bits()));
    }
    // By content, without the extension.
    let q = tmp("tdmsrt", "rt.bin");
    std::fs::copy(&p, &q).unwrap();
    assert_eq!(read(&q, None).unwrap().2[1], x[1]);
}

/// A file built byte by byte: contiguous f64 segment of two chunks with a
/// string channel between the forces; a segment without metadata (the
/// same layout again); incremental metadata ("same index as before", a
/// unit added: Fz in kN, scaled); then a big-endian interleaved segment of
/// i16, i32 and f32 channels. Every value is known by construction.
#[test]
fn hand_built_segments_read_as_built() {
    let wf = |fs: f64| vec![("wf_increment", P::F64(1.0 / fs)), ("unit_string", P::Str("N"))];
    let mut file = Vec::new();
    let mut want: [Vec<f64>; 3] = Default::default();
    // Segment 1: Force X, Force Y, a string channel, Force Z; 2 values per chunk, 2 chunks.
    let objs = [
        Obj { path: "/".into(), index: Index::None, props: vec![("name", P::Str("test"))] },
        Obj { path: "/'Cut 1'".into(), index: Index::None, props: vec![] },
        ch("Force X", Index::New(10, 2), wf(25600.0)),
        ch("Force Y", Index::New(10, 2), wf(25600.0)),
        Obj { path: "/'Cut 1'/'note'".into(), index: Index::None, props: vec![] },
        ch("Force Z", Index::New(10, 2), vec![("wf_increment", P::F64(1.0 / 25600.0))]),
    ];
    let mut raw = Bytes { big: false, b: Vec::new() };
    let mut v = 0.0;
    for _chunk in 0..2 {
        for w in want.iter_mut() {
            for _ in 0..2 {
                v += 1.5;
                raw.f64(v);
                w.push(v);
            }
        }
    }
    file.extend(segment(META | NEW_LIST | RAW, Some(&objs), &raw.b));
    // Segment 2: no metadata, one chunk of the same layout.
    let mut raw = Bytes { big: false, b: Vec::new() };
    for w in want.iter_mut() {
        for _ in 0..2 {
            v -= 0.25;
            raw.f64(v);
            w.push(v);
        }
    }
    file.extend(segment(RAW, None, &raw.b));
    // Segment 3: incremental metadata: Fz gets a unit (kN) and keeps its index.
    let objs = [ch("Force Z", Index::Same, vec![("unit_string", P::Str("kN"))])];
    let mut raw = Bytes { big: false, b: Vec::new() };
    for (a, w) in want.iter_mut().enumerate() {
        for _ in 0..2 {
            v += 2.0;
            raw.f64(v);
            w.push(if a == 2 { v * 1000.0 } else { v });
        }
    }
    // From here on, every Fz value read is in kN: fix the earlier ones after the fact
    // (a property applies to the channel, whichever segment sets it).
    file.extend(segment(META | RAW, Some(&objs), &raw.b));
    for x in want[2].iter_mut().take(6) {
        *x *= 1000.0;
    }
    // Segment 4: big-endian, interleaved, new object list: i16, i32, f32.
    let objs = [
        ch("Force X", Index::New(2, 3), vec![]),
        ch("Force Y", Index::New(3, 3), vec![]),
        ch("Force Z", Index::New(9, 3), vec![]),
    ];
    let mut raw = Vec::new();
    for k in 0..3i32 {
        raw.extend_from_slice(&(-300 - k as i16).to_be_bytes());
        raw.extend_from_slice(&(70_000 + k).to_be_bytes());
        raw.extend_from_slice(&(0.5f32 + k as f32).to_be_bytes());
        want[0].push(f64::from(-300 - k as i16));
        want[1].push(f64::from(70_000 + k));
        want[2].push(f64::from(0.5f32 + k as f32) * 1000.0);
    }
    file.extend(segment(META | NEW_LIST | RAW | INTERLEAVED | BIG, Some(&objs), &raw));
    let p = tmp("tdmshand", "hand.tdms");
    std::fs::write(&p, &file).unwrap();
    let (axes, fs, got) = read(&p, None).unwrap();
    assert_eq!(axes, vec![0, 1, 2]);
    assert!((fs.unwrap() - 25600.0).abs() < 1e-6);
    for (a, (g, w)) in got.iter().zip(&want).enumerate() {
        assert_eq!(g, w, "axis {a}");
    }
    // Negative control: the same file with segment 4 marked little-endian reads other values.
    let mut le = file.clone();
    let s4 = le.windows(4).rposition(|w| w == b"TDSm").unwrap();
    assert_eq!(&le[s4..s4 + 4], b"TDSm");
    le[s4 + 4] &= !(BIG as u8);
    std::fs::write(&p, &le).unwrap();
    assert!(read(&p, None).map_or(true, |(_, _, g)| g != want));
    // --channels by name and by GROUP/NAME; a missing name lists the channels.
    std::fs::write(&p, &file).unwrap();
    let m = ChannelMap::parse("fz=force x,fx=Cut 1/Force Z").unwrap();
    let (axes, _, got) = read(&p, Some(&m)).unwrap();
    assert_eq!(axes, vec![0, 2]);
    assert_eq!(got[0], want[2]);
    assert_eq!(got[1], want[0]);
    let e = read(&p, Some(&ChannelMap::parse("fx=Kraft").unwrap())).unwrap_err();
    assert!(e.contains("hand.tdms") && e.contains("Kraft") && e.contains("Cut 1/Force Y"), "{e}");
}

/// Broken and unsupported files name the file and the segment, offset or
/// channel: truncated, an unfinished segment, NaN, a foreign unit, DAQmx
/// data, no force channel, channels of different lengths.
#[test]
fn bad_tdms_records_are_refused_clearly() {
    let x = signals(3000);
    let p = tmp("tdmsbad", "bad.tdms");
    write_tdms(&p, &x, 51200.0, 1000);
    let good = std::fs::read(&p).unwrap();
    assert!(read(&p, None).is_ok());
    // truncated in the last segment's raw data
    std::fs::write(&p, &good[..good.len() - 100]).unwrap();
    let e = read(&p, None).unwrap_err();
    assert!(e.contains("bad.tdms") && e.contains("segment 3") && e.contains("truncated"), "{e}");
    // truncated inside a lead-in
    let seg = 28 + 1000 * 24;
    let first = good.len() - 2 * seg;
    std::fs::write(&p, &good[..first + 10]).unwrap();
    let e = read(&p, None).unwrap_err();
    assert!(
        e.contains("bad.tdms") && e.contains(&format!("offset {first}")) && e.contains("lead-in of segment 2"),
        "{e}"
    );
    // an unfinished segment (next-segment offset all ones)
    let mut b = good.clone();
    b[first + 12..first + 20].copy_from_slice(&u64::MAX.to_le_bytes());
    std::fs::write(&p, &b).unwrap();
    let e = read(&p, None).unwrap_err();
    assert!(e.contains("segment 2") && e.contains("never finished"), "{e}");
    // NaN in fy, sample 1500 (segment 2, row 500)
    let mut b = good.clone();
    let at = first + 28 + 500 * 24 + 8;
    b[at..at + 8].copy_from_slice(&f64::NAN.to_le_bytes());
    std::fs::write(&p, &b).unwrap();
    let e = read(&p, None).unwrap_err();
    assert!(e.contains("dynocomp/Fy") && e.contains("sample 1500") && e.contains("not finite"), "{e}");
    // a unit that is not a force in N
    let file = segment(
        META | NEW_LIST | RAW,
        Some(&[ch("Fx", Index::New(10, 1), vec![("unit_string", P::Str("lbf"))])]),
        &1.0f64.to_le_bytes(),
    );
    std::fs::write(&p, file).unwrap();
    let e = read(&p, None).unwrap_err();
    assert!(e.contains("Cut 1/Fx") && e.contains("lbf"), "{e}");
    // a start time that is not finite; control: a finite one reads
    let file = segment(
        META | NEW_LIST | RAW,
        Some(&[ch("Fx", Index::New(10, 1), vec![("wf_start_offset", P::F64(f64::INFINITY))])]),
        &1.0f64.to_le_bytes(),
    );
    std::fs::write(&p, file).unwrap();
    let e = read(&p, None).unwrap_err();
    assert!(e.contains("Cut 1/Fx") && e.contains("wf_start_offset") && e.contains("not finite"), "{e}");
    let file = segment(
        META | NEW_LIST | RAW,
        Some(&[ch("Fx", Index::New(10, 1), vec![("wf_start_offset", P::F64(2.5))])]),
        &1.0f64.to_le_bytes(),
    );
    std::fs::write(&p, file).unwrap();
    assert!(read(&p, None).is_ok());
    // DAQmx raw data
    let file = segment(META | NEW_LIST | RAW | DAQMX, Some(&[ch("Fx", Index::Daqmx, vec![])]), &[0u8; 8]);
    std::fs::write(&p, file).unwrap();
    let e = read(&p, None).unwrap_err();
    assert!(e.contains("Cut 1/Fx") && e.contains("DAQmx"), "{e}");
    // no force channel
    let file = segment(META | NEW_LIST | RAW, Some(&[ch("Torque", Index::New(10, 1), vec![])]), &1.0f64.to_le_bytes());
    std::fs::write(&p, file).unwrap();
    let e = read(&p, None).unwrap_err();
    assert!(e.contains("no channel named for a force axis") && e.contains("Cut 1/Torque"), "{e}");
    // a name with a newline (found by the fuzzer): the message stays one line
    let file = segment(META | NEW_LIST | RAW, Some(&[ch("F\nx", Index::New(10, 1), vec![])]), &1.0f64.to_le_bytes());
    std::fs::write(&p, file).unwrap();
    let e = read(&p, None).unwrap_err();
    assert!(e.contains("Cut 1/F\\nx") && e.lines().count() == 1, "{e}");
    // different lengths
    let mut raw = Vec::new();
    for v in [1.0f64, 2.0, 3.0] {
        raw.extend_from_slice(&v.to_le_bytes());
    }
    let file = segment(
        META | NEW_LIST | RAW,
        Some(&[ch("Fx", Index::New(10, 2), vec![]), ch("Fy", Index::New(10, 1), vec![])]),
        &raw,
    );
    std::fs::write(&p, file).unwrap();
    let e = read(&p, None).unwrap_err();
    assert!(e.contains("Cut 1/Fy") && e.contains("same length"), "{e}");
    // raw data not a whole number of chunks
    let file = segment(META | NEW_LIST | RAW, Some(&[ch("Fx", Index::New(10, 2), vec![])]), &raw);
    std::fs::write(&p, file).unwrap();
    let e = read(&p, None).unwrap_err();
    assert!(e.contains("segment 1") && e.contains("whole number of chunks"), "{e}");
}

/// `compensate` on the example as TDMS: the output is TDMS (format follows
/// the input) with the very values of the CSV path; `--output-format tdms`
/// from CSV; a record at 48 kHz is refused naming the file and
/// wf_increment's rate, and leaves no output.
#[test]
fn compensate_reads_and_writes_tdms() {
    let img_path = tmp("tdmscli", "img.dcimg");
    let mut img = common::image(1, 51200, 0);
    img.latency_samples = 2;
    std::fs::write(&img_path, common::bytes(&img)).unwrap();
    let rec = read_signal_csv(Path::new(&example("measured.csv"))).unwrap();
    let chans: Vec<Vec<f64>> = rec.channels.iter().map(|c| c.1.clone()).collect();
    let inp = tmp("tdmscli", "measured.tdms");
    write_tdms(&inp, &chans, 51200.0, 4096);
    let run = |inp: &PathBuf, out: &PathBuf, extra: &[&str]| {
        let mut args = vec![
            "compensate",
            "--coeffs",
            img_path.to_str().unwrap(),
            "--input",
            inp.to_str().unwrap(),
            "--output",
            out.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        dynocomp(&args)
    };
    let want = compensate_record(&img, &rec, false, "x").unwrap();
    let out = tmp("tdmscli", "out.tdms");
    let (ok, _, err) = run(&inp, &out, &[]);
    assert!(ok, "{err}");
    let (axes, fs, got) = read(&out, None).unwrap();
    assert_eq!(axes, vec![0, 1, 2]);
    assert!((fs.unwrap() - 51200.0).abs() < 1e-6);
    for (a, g) in got.iter().enumerate() {
        let w = want.channel(a).unwrap();
        assert!(g.len() == w.len() && g.iter().zip(w).all(|(x, y)| x.to_bits() == y.to_bits()), "axis {a}");
    }
    let out2 = tmp("tdmscli", "from_csv.out");
    let (ok, _, err) = run(&PathBuf::from(example("measured.csv")), &out2, &["--output-format", "tdms"]);
    assert!(ok, "{err}");
    assert_eq!(read(&out2, None).unwrap().2[2], want.channel(2).unwrap());
    // 48 kHz record against a 51.2 kHz image
    let slow = tmp("tdmscli", "slow.tdms");
    write_tdms(&slow, &chans, 48000.0, 4096);
    let out3 = tmp("tdmscli", "out3.tdms");
    let (ok, _, err) = run(&slow, &out3, &[]);
    assert!(!ok);
    assert!(err.contains("slow.tdms") && err.contains("48000") && err.contains("51200"), "{err}");
    assert!(!out3.exists());
    // a truncated input leaves no output either
    let b = std::fs::read(&inp).unwrap();
    let cut = tmp("tdmscli", "cut.tdms");
    std::fs::write(&cut, &b[..b.len() / 2]).unwrap();
    let (ok, _, err) = run(&cut, &out3, &[]);
    assert!(!ok && err.contains("cut.tdms") && err.contains("truncated"), "{err}");
    assert!(!out3.exists());
}

/// A file written by another implementation (npTDMS 1.13, see
/// `fixtures/tdms/make_nptdms_fixture.py`): two segments, f64, f32 and i16
/// force channels (Fz in kN) and a string channel; its values, saved by
/// numpy as CSV in N, are read exactly, and the rate from wf_increment.
#[test]
fn a_file_written_by_nptdms_reads_as_written() {
    let dir = format!("{}/tests/fixtures/tdms", env!("CARGO_MANIFEST_DIR"));
    // Its test values reach 852 kN, beyond the default full scale.
    let csv = Path::new(&format!("{dir}/nptdms_two_segments.csv")).to_path_buf();
    let want = dynocomp::io::signal_csv::read_signal_csv_checked(&csv, f64::INFINITY).unwrap();
    let tdms = Path::new(&format!("{dir}/nptdms_two_segments.tdms")).to_path_buf();
    let (mut r, _) = dynocomp::io::signal_file::open_signal_checked(&tdms, None, f64::INFINITY).unwrap();
    let (axes, fs) = (r.axes().to_vec(), r.declared_fs_hz());
    let (_, got) = read_all(&mut *r).unwrap();
    assert_eq!(axes, vec![0, 1, 2]);
    assert!((fs.unwrap() - 10240.0).abs() < 1e-6);
    for (a, g) in got.iter().enumerate() {
        assert_eq!(g.len(), 1000);
        assert_eq!(g.as_slice(), want.channel(a).unwrap(), "axis {a}");
    }
}

/// The output keeps the input's time base: a CSV whose t_s starts at
/// 1.25 s gives TDMS `wf_start_offset` 1.25 and a UFF abscissa starting at
/// 1.25 s (record 7); without times, both start at 0 (negative control).
#[test]
fn outputs_keep_the_time_base() {
    let img_path = tmp("tdmst0", "img.dcimg");
    std::fs::write(&img_path, common::bytes(&common::image(1, 51200, 0))).unwrap();
    let inp = tmp("tdmst0", "in.csv");
    let text: String = std::iter::once("t_s,fx\n".to_string())
        .chain((0..5000).map(|k| format!("{},{}\n", 1.25 + k as f64 / 51200.0, k % 7)))
        .collect();
    std::fs::write(&inp, text).unwrap();
    let notime = tmp("tdmst0", "notime.csv");
    std::fs::write(&notime, "fx\n1\n2\n3\n4\n").unwrap();
    for (input, t0) in [(&inp, 1.25), (&notime, 0.0)] {
        let out = tmp("tdmst0", "out.tdms");
        let (ok, _, err) = dynocomp(&[
            "compensate",
            "--coeffs",
            img_path.to_str().unwrap(),
            "--input",
            input.to_str().unwrap(),
            "--output",
            out.to_str().unwrap(),
            "--output-format",
            "tdms",
        ]);
        assert!(ok, "{err}");
        let r = dynocomp::io::tdms::TdmsReader::open(&out, None).unwrap();
        assert_eq!(r.start_offset_s(), Some(t0));
        let uff = tmp("tdmst0", "out.uff");
        let (ok, _, err) = dynocomp(&[
            "compensate",
            "--coeffs",
            img_path.to_str().unwrap(),
            "--input",
            input.to_str().unwrap(),
            "--output",
            uff.to_str().unwrap(),
            "--output-format",
            "uff",
        ]);
        assert!(ok, "{err}");
        let text = std::fs::read_to_string(&uff).unwrap();
        let rec7 = text.lines().nth(8).unwrap();
        let x0: f64 = rec7.split_whitespace().nth(3).unwrap().parse().unwrap();
        assert!((x0 - t0).abs() < 1e-5, "record 7 `{rec7}`: x0 {x0}, want {t0}");
    }
    // A TDMS or UFF input's time base goes on too: to a CSV output as its
    // t_s column (from the start and the increment), to TDMS as its start.
    let run = |input: &std::path::Path, out: &std::path::Path, fmt: &str| {
        let (ok, _, err) = dynocomp(&[
            "compensate",
            "--coeffs",
            img_path.to_str().unwrap(),
            "--input",
            input.to_str().unwrap(),
            "--output",
            out.to_str().unwrap(),
            "--output-format",
            fmt,
        ]);
        assert!(ok, "{err}");
    };
    let (tdms_in, uff_in) = (tmp("tdmst0", "timed.tdms"), tmp("tdmst0", "timed.uff"));
    run(&inp, &tdms_in, "tdms");
    run(&inp, &uff_in, "uff58b");
    for from in [&tdms_in, &uff_in] {
        let csv = tmp("tdmst0", "back.csv");
        run(from, &csv, "csv");
        let rec = dynocomp::io::signal_csv::read_signal_csv(&csv).unwrap();
        let t = rec.t_s.as_ref().unwrap_or_else(|| panic!("{}: no t_s column in the CSV output", from.display()));
        assert_eq!(t.len(), 5000);
        for (k, tk) in t.iter().enumerate() {
            assert!((tk - (1.25 + k as f64 / 51200.0)).abs() < 1e-9, "{}: t_s[{k}] = {tk}", from.display());
        }
        let again = tmp("tdmst0", "again.tdms");
        run(from, &again, "tdms");
        assert_eq!(
            dynocomp::io::tdms::TdmsReader::open(&again, None).unwrap().start_offset_s(),
            Some(1.25),
            "{}",
            from.display()
        );
    }
}

/// Every refusal of the segment walk (lead-in, metadata, raw-data layout) and
/// of the channel pick, word for word: the messages name the file, segment,
/// offset or channel as they always have.
#[test]
fn tdms_refusals_word_for_word() {
    let p = tmp("tdmsexact", "e.tdms");
    let s = p.display().to_string();
    let one = |objs: &[Obj], raw: &[u8]| segment(META | NEW_LIST | RAW, Some(objs), raw);
    let f1 = 1.0f64.to_le_bytes();
    let f2 = [1.0f64.to_le_bytes(), 2.0f64.to_le_bytes()].concat();
    let fx = || one(&[ch("Fx", Index::New(10, 1), vec![])], &f1);
    let patch = |mut b: Vec<u8>, at: usize, v: &[u8]| {
        b[at..at + v.len()].copy_from_slice(v);
        b
    };
    // Offsets in `fx()`: lead-in 0..28, object count 28, path 32..49, index length 49,
    // type 53, dimension 57, values 61, property count 69.
    let with_prop = one(&[ch("Fx", Index::New(10, 1), vec![("a", P::F64(1.0))])], &f1);
    let wf = |d: f64| vec![("wf_increment", P::F64(d))];
    let g = |grp: &str, name: &str, index: Index| Obj { path: format!("/'{grp}'/'{name}'"), index, props: vec![] };
    let fx_map = ChannelMap::parse("fx=Fx").unwrap();
    let kraft = ChannelMap::parse("fx=Kraft").unwrap();
    let cases: Vec<(Vec<u8>, Option<&ChannelMap>, &str)> = vec![
        (Vec::new(), None, "{s}: empty file (no TDMS segment)"),
        (patch(fx(), 0, b"XDSm"), None, "{s}: segment 1, offset 0: no TDMS lead-in (tag \"XDSm\", expected \"TDSm\")"),
        (
            patch(fx(), 8, &4711u32.to_le_bytes()),
            None,
            "{s}: segment 1, offset 0: TDMS version 4711 (this reader knows 4712 and 4713)",
        ),
        (
            patch(fx(), 12, &(1u64 << 40).to_le_bytes()),
            None,
            "{s}: segment 1, offset 0: the segment declares 1099511627776 bytes after its lead-in, \
                the file has 53: the file is truncated",
        ),
        (
            patch(fx(), 20, &1000u64.to_le_bytes()),
            None,
            "{s}: segment 1, offset 0: raw data offset 1000 is beyond the segment's end (53)",
        ),
        (
            patch(fx(), 57, &2u32.to_le_bytes()),
            None,
            "{s}: segment 1, offset 49: object /'Cut 1'/'Fx': array dimension 2 (TDMS allows 1)",
        ),
        (
            patch(fx(), 49, &24u32.to_le_bytes()),
            None,
            "{s}: segment 1, offset 49: object /'Cut 1'/'Fx': raw data index of 24 bytes for f64 values",
        ),
        (
            one(&[ch("Fx", Index::New(10, u64::MAX), vec![])], &f1),
            None,
            "{s}: segment 1, offset 49: object /'Cut 1'/'Fx': 18446744073709551615 values overflow",
        ),
        (
            patch(with_prop, 78, &0x99u32.to_le_bytes()),
            None,
            "{s}: segment 1, offset 78: property \"a\" of /'Cut 1'/'Fx': unknown data type 0x99",
        ),
        (
            one(&[ch("Fx", Index::Same, vec![])], &f1),
            None,
            "{s}: segment 1: object /'Cut 1'/'Fx': raw data index \"same as before\", but it had none",
        ),
        (
            one(&[ch("Fx", Index::New(10, u64::MAX / 8), vec![]), ch("Fy", Index::New(10, u64::MAX / 8), vec![])], &f1),
            None,
            "{s}: segment 1, offset 0: raw data sizes overflow",
        ),
        (
            one(&[ch("Fx", Index::New(10, 2), vec![])], &[f2.clone(), f1.to_vec()].concat()),
            None,
            "{s}: segment 1, offset 0: 24 bytes of raw data are not a whole number of chunks of 16 \
                bytes (the metadata's channels)",
        ),
        (
            segment(
                META | NEW_LIST | RAW | INTERLEAVED,
                Some(&[ch("Fx", Index::New(10, 2), vec![]), ch("Fy", Index::New(10, 1), vec![])]),
                &[f2.clone(), f1.to_vec()].concat(),
            ),
            None,
            "{s}: segment 1, offset 0: interleaved data, but object /'Cut 1'/'Fy' has 1 f64 values \
                where the first has 2",
        ),
        (fx(), Some(&kraft), "{s}: --channels fx=Kraft: no such channel (channels: Cut 1/Fx)"),
        (
            one(&[g("A", "Fx", Index::New(10, 1)), g("B", "Fx", Index::New(10, 1))], &f2),
            Some(&fx_map),
            "{s}: --channels fx=Fx: several groups have it; give GROUP/NAME",
        ),
        (
            one(&[ch("Fx", Index::New(10, 1), vec![]), ch("Force X", Index::New(10, 1), vec![])], &f2),
            None,
            "{s}: channels Cut 1/Fx and Cut 1/Force X are both axis x; pick one with --channels \
                fx=GROUP/NAME",
        ),
        (
            one(&[ch("Torque", Index::New(10, 1), vec![])], &f1),
            None,
            "{s}: no channel named for a force axis (Fx, Force X, ...); channels: Cut 1/Torque; give \
                --channels fx=NAME,...",
        ),
        (
            segment(META | NEW_LIST | RAW | DAQMX, Some(&[ch("Fx", Index::Daqmx, vec![])]), &[0u8; 8]),
            None,
            "{s}: channel Cut 1/Fx (fx): DAQmx raw data (ADC codes with NI_Scaling properties) is \
                not supported; log scaled data or convert the file",
        ),
        (
            one(&[ch("Fx", Index::New(10, 1), vec![("NI_Scaling_Status", P::Str("unscaled"))])], &f1),
            None,
            "{s}: channel Cut 1/Fx (fx): NI_Scaling_Status is \"unscaled\" (raw values needing NI \
                scaling); log scaled data",
        ),
        (one(&[ch("Fx", Index::None, vec![])], &[]), None, "{s}: channel Cut 1/Fx (fx): no data"),
        (
            one(&[ch("Fx", Index::New(0x21, 1), vec![])], &[1u8]),
            None,
            "{s}: channel Cut 1/Fx (fx): boolean values; a force channel must be real numbers",
        ),
        (
            one(&[ch("Fx", Index::New(10, 1), vec![("unit_string", P::Str("lbf"))])], &f1),
            None,
            "{s}: channel Cut 1/Fx (fx): unit \"lbf\"; expected N (kN and mN are scaled)",
        ),
        (
            one(&[ch("Fx", Index::New(10, 1), wf(-1.0))], &f1),
            None,
            "{s}: channel Cut 1/Fx (fx): property wf_increment = -1 s is not a positive sampling interval",
        ),
        (
            one(&[ch("Fx", Index::New(10, 1), wf(1e-4)), ch("Fy", Index::New(10, 1), wf(2e-4))], &f2),
            None,
            "{s}: channel Cut 1/Fy (fy): wf_increment 0.0002 s, but channel Cut 1/Fx has 0.0001 s: \
                channels must share a rate",
        ),
        (
            one(&[ch("Fx", Index::New(10, 1), vec![("wf_increment", P::Str("x"))])], &f1),
            None,
            "{s}: channel Cut 1/Fx (fx): property wf_increment is not a number",
        ),
        (
            one(&[ch("Fx", Index::New(10, 1), vec![("wf_start_offset", P::F64(f64::NAN))])], &f1),
            None,
            "{s}: channel Cut 1/Fx (fx): property wf_start_offset = NaN s is not finite",
        ),
        (
            one(
                &[ch("Fx", Index::New(10, 2), vec![]), ch("Fy", Index::New(10, 1), vec![])],
                &[f2.clone(), f1.to_vec()].concat(),
            ),
            None,
            "{s}: channel Cut 1/Fy (fy): 1 samples, but channel Cut 1/Fx has 2: channels must have \
                the same length",
        ),
    ];
    let mut bad = Vec::new();
    for (k, (bytes, map, want)) in cases.iter().enumerate() {
        std::fs::write(&p, bytes).unwrap();
        let got = read(&p, *map).map(|_| "accepted".to_string()).unwrap_or_else(|e| e);
        let want = want.replace("{s}", &s);
        if got != want {
            bad.push(format!("case {k}: {:?}", got.replace(&s, "{s}")));
        }
    }
    assert!(bad.is_empty(), "\n{}", bad.join("\n"));
}
