//! The signal CSV reader (issue #14, "CSV at disk speed"): lines parsed in
//! place in the reader's buffer must give exactly what an independent,
//! line-by-line `str::parse` reading gives, whatever the buffer size (lines
//! cut by the buffer's end take the copying path), and every malformed row
//! the same one-line error naming line and column.

use std::io::BufReader;

use dynocomp::io::signal::{read_all, SignalReader, WholeRecord};
use dynocomp::io::signal_csv::CsvReader;
use proptest::prelude::*;

/// Buffer sizes: one that holds the whole text, and ones that cut lines.
const CAPACITIES: [usize; 4] = [1 << 20, 64, 7, 1];

fn read(text: &[u8], cap: usize) -> anyhow::Result<WholeRecord> {
    // Any finite value: these tests are about the parser, not plausibility.
    let mut r = CsvReader::new(BufReader::with_capacity(cap, text), "rec.csv")?.with_full_scale(f64::INFINITY);
    read_all(&mut r as &mut dyn SignalReader)
}

/// The reference: split into lines, skip blank ones, split fields, trim,
/// `str::parse::<f64>` (header t_s,fx,fy,fz).
fn reference(text: &str) -> (Vec<f64>, Vec<Vec<f64>>) {
    let mut t = Vec::new();
    let mut ch = vec![Vec::new(); 3];
    for line in text.lines().skip(1).filter(|l| !l.trim().is_empty()) {
        let v: Vec<f64> = line.split(',').map(|f| f.trim().parse().unwrap()).collect();
        t.push(v[0]);
        for a in 0..3 {
            ch[a].push(v[a + 1]);
        }
    }
    (t, ch)
}

fn bits(v: &[f64]) -> Vec<u64> {
    v.iter().map(|x| x.to_bits()).collect()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// Values written every way a DAQ or a script writes them, with CRLF and
    /// blank lines mixed in: the same bits as the reference, at every
    /// buffer size.
    #[test]
    fn rows_read_in_place_equal_the_reference(
        rows in prop::collection::vec((any::<u64>(), -1e6f64..1e6, -1e-3f64..1e-3, 0usize..6, 0usize..4), 1..60),
    ) {
        let mut text = String::from("t_s,fx,fy,fz\n");
        for (k, (b, x, y, style, end)) in rows.iter().enumerate() {
            let big = f64::from_bits(*b);
            let big = if big.is_finite() { big } else { 1.5 };
            let z = match style {
                0 => format!("{x}"),
                1 => format!("{x:.6}"),
                2 => format!("{y:e}"),
                3 => format!(" {big} "),
                4 => format!("{big:E}"),
                _ => format!("{:.3}", x.round()),
            };
            text.push_str(&format!("{:.9},{x:.6},{y},{z}", k as f64 * 1.953125e-5));
            text.push_str(["\n", "\r\n", "\n\n", "\n \t\n"][*end]);
        }
        let (t_ref, ch_ref) = reference(&text);
        for cap in CAPACITIES {
            let (t, ch) = read(text.as_bytes(), cap).unwrap();
            prop_assert_eq!(bits(&t.unwrap()), bits(&t_ref), "t_s, buffer {}", cap);
            for a in 0..3 {
                prop_assert_eq!(bits(&ch[a]), bits(&ch_ref[a]), "axis {}, buffer {}", a, cap);
            }
        }
    }
}

#[test]
fn a_last_line_without_line_end_and_blank_lines_are_read() {
    for cap in CAPACITIES {
        let (t, ch) = read(b"t_s,fx\r\n\r\n0,1.5\n  \n1e-3,-2.25e1", cap).unwrap();
        assert_eq!(t.unwrap(), vec![0.0, 1e-3], "buffer {cap}");
        assert_eq!(ch, vec![vec![1.5, -22.5]], "buffer {cap}");
    }
}

#[test]
fn malformed_rows_are_named_by_line_and_column() {
    let cases: [(&[u8], &str); 9] = [
        (b"t_s,fx\n0,1\n1,abc\n", "rec.csv: line 3, column 2 (`fx`): `abc` is not a number"),
        (b"t_s,fx\n0,1\n\n1\n", "rec.csv: line 4: 1 fields, header has 2"),
        (b"t_s,fx\n0,1,2\n", "rec.csv: line 2: 3 fields, header has 2"),
        (b"t_s,fx\n0,1\n1,\xff2\n", "rec.csv: line 3: not valid UTF-8 text"),
        // UTF-8 is checked before the field count, the count before the values.
        (b"t_s,fx\n0,\xff,x\n", "rec.csv: line 2: not valid UTF-8 text"),
        (b"t_s,fx\nx,1,2\n", "rec.csv: line 2: 3 fields, header has 2"),
        (b"t_s,fx\n0,inf\n", "rec.csv: line 2, column 2 (`fx`): value is not finite"),
        (
            b"t_s,fx\r\n0,1\r\n0.5,1\r\n0.5,2\r\n",
            "rec.csv: line 4, column 1 (`t_s`): time 0.5 does not increase (previous 0.5)",
        ),
        (b"t_s,fx\n0,1\n1,1e400\n", "rec.csv: line 3, column 2 (`fx`): value is not finite"),
    ];
    for (text, want) in cases {
        for cap in CAPACITIES {
            let e = format!("{:#}", read(text, cap).unwrap_err());
            assert_eq!(e, want, "buffer {cap}, input {:?}", String::from_utf8_lossy(text));
        }
    }
    // Control: the same rows, well formed, are read.
    for text in [&b"t_s,fx\n0,1\n1,2\n"[..], b"t_s,fx\n0,1\n\n1,2\n", b"t_s,fx\r\n0,1\r\n0.5,1\r\n0.6,2\r\n"] {
        for cap in CAPACITIES {
            assert!(read(text, cap).is_ok(), "buffer {cap}");
        }
    }
}

/// The writer formats a large block in two halves on two threads: rows come
/// back in order and bit-identical, for blocks on either side of the split
/// size and for a block size that is odd.
#[test]
fn written_rows_read_back_in_order_and_bit_identical() {
    use dynocomp::io::signal::SignalWriter;
    use dynocomp::io::signal_csv::CsvWriter;
    for n in [1usize, 2047, 2048, 8191] {
        let t: Vec<f64> = (0..n).map(|k| k as f64 / 51_200.0).collect();
        let x: Vec<f64> = (0..n).map(|k| ((k as f64) * 0.37).sin() as f32 as f64 * 1e3).collect();
        let z: Vec<f64> = (0..n)
            .map(|k| f64::from_bits(0x3ff0_0000_0000_0000 ^ (k as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15) >> 12))
            .collect();
        let mut out = Vec::new();
        let mut w = CsvWriter::new(&mut out, &[0, 2], true).unwrap();
        w.write_block(Some(&t), &[&x, &z]).unwrap();
        w.write_block(Some(&[t[n - 1] + 1.0]), &[&[-0.0], &[1e-300]]).unwrap();
        w.finish().unwrap();
        let mut r = CsvReader::new(&out[..], "out.csv").unwrap();
        assert_eq!(r.axes(), &[0, 2]);
        let (tt, ch) = read_all(&mut r as &mut dyn SignalReader).unwrap();
        let tt = tt.unwrap();
        assert_eq!(tt.len(), n + 1, "rows, block of {n}");
        assert_eq!(bits(&tt[..n]), bits(&t), "t_s, block of {n}");
        assert_eq!(bits(&ch[0][..n]), bits(&x), "fx, block of {n}");
        assert_eq!(bits(&ch[1][..n]), bits(&z), "fz, block of {n}");
        assert_eq!((ch[0][n].to_bits(), ch[1][n]), ((-0.0f64).to_bits(), 1e-300), "second block, block of {n}");
    }
}
