//! A force record's values are plausible forces, or reading fails naming
//! the file, the place and the column: beyond the full scale of a charge
//! amplifier (default 10⁵ N), NaN or ∞. Input text quoted in an error is
//! capped; `-` reads standard input as CSV.

use dynocomp::io::signal::{read_all, DEFAULT_FULL_SCALE_N};
use dynocomp::io::signal_file::{open_signal, open_signal_checked, writer_for, SignalFormat};
use std::io::Write;
use std::path::Path;

fn csv(dir: &Path, name: &str, text: &str) -> std::path::PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

/// Read the whole record of `p` (full scale `fs`), or the error message.
fn read(p: &Path, fs: f64) -> Result<Vec<Vec<f64>>, String> {
    open_signal_checked(p, None, fs)
        .and_then(|(mut r, _)| read_all(&mut *r))
        .map(|(_, c)| c)
        .map_err(|e| format!("{e:#}"))
}

#[test]
fn a_csv_value_beyond_the_full_scale_is_an_error_naming_file_line_and_column() {
    let dir = tempfile::tempdir().unwrap();
    let rows = "t_s,fx,fy\n0,1,2\n0.00002,3,4\n0.00004,5,1e30\n0.00006,7,8\n";
    let p = csv(dir.path(), "rec.csv", rows);
    let e = read(&p, DEFAULT_FULL_SCALE_N).unwrap_err();
    assert!(
        e.contains("rec.csv") && e.contains("line 4") && e.contains("column 3 (`fy`)") && e.contains("full scale"),
        "{e}"
    );
    // At the bound and just beyond it; a larger full scale takes 1e30's
    // neighbours that are below it.
    let edge = csv(dir.path(), "edge.csv", "fx\n100000\n-100000\n");
    assert_eq!(read(&edge, DEFAULT_FULL_SCALE_N).unwrap(), vec![vec![1e5, -1e5]]);
    let over = csv(dir.path(), "over.csv", "fx\n100000\n-100000.5\n");
    assert!(read(&over, DEFAULT_FULL_SCALE_N).unwrap_err().contains("line 3"));
    assert_eq!(read(&over, 2e5).unwrap(), vec![vec![1e5, -100000.5]]);
    // Non-finite values, and the time column (not a force) is not bounded.
    for bad in ["nan", "inf", "-inf"] {
        let p = csv(dir.path(), "nf.csv", &format!("fx\n1\n{bad}\n"));
        let e = read(&p, DEFAULT_FULL_SCALE_N).unwrap_err();
        assert!(e.contains("line 3") && e.contains("finite"), "{bad}: {e}");
    }
    let late = csv(dir.path(), "late.csv", "t_s,fx\n1e6,1\n2e6,2\n");
    assert_eq!(read(&late, DEFAULT_FULL_SCALE_N).unwrap(), vec![vec![1.0, 2.0]]);
    // The default reader applies the default full scale.
    let (mut r, _) = open_signal(&p, None).unwrap();
    assert!(read_all(&mut *r).is_err());
}

#[test]
fn tdms_and_uff_values_beyond_the_full_scale_name_the_sample_and_channel() {
    let dir = tempfile::tempdir().unwrap();
    for (fmt, ext) in [(SignalFormat::Tdms, "tdms"), (SignalFormat::Uff, "uff"), (SignalFormat::Uff58b, "uff")] {
        let path = dir.path().join(format!("rec.{ext}"));
        let mut bytes = Vec::new();
        {
            let mut w = writer_for(fmt, &mut bytes, None, &[0, 2], false, None, 1000.0, &path).unwrap();
            w.write_block(None, &[&[1.0, 2.0, 3.0, 4.0], &[5.0, 6.0, 3e19, 8.0]]).unwrap();
            w.finish().unwrap();
        }
        std::fs::File::create(&path).unwrap().write_all(&bytes).unwrap();
        let e = read(&path, DEFAULT_FULL_SCALE_N).unwrap_err();
        assert!(
            e.contains(&format!("rec.{ext}")) && e.contains("sample 3 of fz") && e.contains("full scale"),
            "{fmt:?}: {e}"
        );
        // Within a full scale that allows it, the record reads.
        assert_eq!(read(&path, 1e20).unwrap()[1][2], 3e19, "{fmt:?}");
    }
}

#[test]
fn input_text_in_an_error_is_capped() {
    let dir = tempfile::tempdir().unwrap();
    // One 4 MB line: refused by its length, never echoed.
    let long = csv(dir.path(), "long.csv", &"x".repeat(4 << 20));
    let e = read(&long, DEFAULT_FULL_SCALE_N).unwrap_err();
    assert!(e.contains("longer than") && e.len() < 300, "{} bytes: {}", e.len(), &e[..e.len().min(300)]);
    // A long header name and a long field are quoted in part.
    let name = csv(dir.path(), "name.csv", &format!("fx,{}\n1,2\n", "y".repeat(100_000)));
    let e = read(&name, DEFAULT_FULL_SCALE_N).unwrap_err();
    assert!(e.contains("bytes in all") && e.len() < 400, "{} bytes", e.len());
    let field = csv(dir.path(), "field.csv", &format!("fx\n{}\n", "z".repeat(100_000)));
    let e = read(&field, DEFAULT_FULL_SCALE_N).unwrap_err();
    assert!(e.contains("line 2") && e.contains("bytes in all") && e.len() < 400, "{} bytes", e.len());
    assert_eq!(dynocomp::io::one_line("a\tb"), "a\\tb");
}

/// `-` reads standard input as CSV (a child of this test binary reads what
/// the test pipes to it); a TDMS or UFF record cannot come from a pipe.
#[test]
fn a_dash_reads_standard_input_as_csv() {
    if std::env::var_os("DYNOCOMP_STDIN_CHILD").is_some() {
        let (mut r, fmt) = open_signal(Path::new("-"), None).unwrap();
        let (t, c) = read_all(&mut *r).unwrap();
        println!("CHILD {fmt:?} {} {:?} {:?}", r.axes().len(), t, c);
        return;
    }
    // This test's name in the harness: its module path without the crate's.
    let name = format!("{}::a_dash_reads_standard_input_as_csv", module_path!().split_once("::").unwrap().1);
    let mut child = std::process::Command::new(std::env::current_exe().unwrap())
        .args(["--exact", &name, "--nocapture", "--quiet"])
        .env("DYNOCOMP_STDIN_CHILD", "1")
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    child.stdin.take().unwrap().write_all(b"t_s,fx,fz\n0,1.5,-2\n0.001,2.5,3\n").unwrap();
    let out = child.wait_with_output().unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("CHILD Csv 2 Some([0.0, 0.001]) [[1.5, 2.5], [-2.0, 3.0]]"), "{text}");
    let map = dynocomp::io::signal::ChannelMap::parse("fx=A").unwrap();
    assert!(open_signal(Path::new("-"), Some(&map)).is_err());
}
