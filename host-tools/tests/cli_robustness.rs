//! The command line as a careless or hostile user meets it: interrupted
//! runs, outputs that are inputs, image and sidecar written as a pair,
//! implausible values, bad parameters. Each test runs the built binary.

use crate::cli_common;

use cli_common::{dynocomp, example, tmp};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Temporary files of the tool's naming left in `dir`.
fn temporaries(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with(".dynocomp-"))
        .collect()
}

/// A fresh folder `name` for one test.
fn fresh_dir(name: &str) -> PathBuf {
    let d = tmp("robust", name);
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A default-method image of the bundled example designed into `dir`.
fn example_image(dir: &Path) -> PathBuf {
    let img = dir.join("ex.dcimg");
    let (ok, _, err) = dynocomp(&[
        "design",
        "--frf",
        &example("frf.csv"),
        "--fs",
        "51200",
        "--idle",
        &example("idle.csv"),
        "--out",
        s(&img),
    ]);
    assert!(ok, "design failed: {err}");
    img
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// SIGTERM in the middle of a compensation removes its temporary output
/// file (a record read from a pipe that is still open keeps the run busy).
/// Negative control: SIGKILL, which no process can handle, leaves it.
#[test]
fn sigterm_removes_the_temporary_output() {
    let img = example_image(&fresh_dir("sig-image"));
    for (sig, cleaned) in [("-TERM", true), ("-INT", true), ("-KILL", false)] {
        let dir = fresh_dir(&format!("sig{sig}"));
        let out = dir.join("out.csv");
        let mut child = Command::new(env!("CARGO_BIN_EXE_dynocomp"))
            .args(["compensate", "--coeffs", s(&img), "--input", "-", "--output", s(&out)])
            .stdin(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let mut stdin = child.stdin.take().unwrap();
        let mut text = String::from("t_s,fx\n");
        for k in 0..20_000 {
            text.push_str(&format!("{},{}\n", k as f64 / 51200.0, (k as f64 * 0.01).sin()));
        }
        std::io::Write::write_all(&mut stdin, text.as_bytes()).unwrap();
        let t0 = Instant::now();
        while temporaries(&dir).is_empty() && t0.elapsed() < Duration::from_secs(20) {
            std::thread::sleep(Duration::from_millis(20));
        }
        assert!(!temporaries(&dir).is_empty(), "no temporary output appeared");
        std::thread::sleep(Duration::from_millis(200));
        let killed = Command::new("kill").args([sig, &child.id().to_string()]).status().unwrap();
        assert!(killed.success());
        let status = child.wait().unwrap();
        drop(stdin);
        assert!(!status.success());
        assert_eq!(temporaries(&dir).is_empty(), cleaned, "{sig}: temporaries {:?}", temporaries(&dir));
        assert!(!out.exists(), "{sig}: an output was written");
    }
}

/// `design` writes the image and its sidecar together: when the sidecar
/// cannot be written (a directory in its place) the old image is left as
/// it was. Control: without the obstacle the same run replaces both.
#[test]
fn design_keeps_the_old_image_when_the_sidecar_cannot_be_written() {
    let dir = fresh_dir("pair");
    let img = dir.join("ex.dcimg");
    std::fs::write(&img, b"old image").unwrap();
    let side = dir.join("ex.dcimg.model.json");
    std::fs::create_dir(&side).unwrap();
    let args =
        ["design", "--frf", &example("frf.csv"), "--fs", "51200", "--idle", &example("idle.csv"), "--out", s(&img)];
    let (ok, _, err) = dynocomp(&args);
    assert!(!ok, "design succeeded with a directory in the sidecar's place");
    assert!(err.contains("model.json"), "{err}");
    assert_eq!(std::fs::read(&img).unwrap(), b"old image", "the old image was replaced");
    assert!(temporaries(&dir).is_empty());
    std::fs::remove_dir(&side).unwrap();
    let (ok, _, err) = dynocomp(&args);
    assert!(ok, "{err}");
    assert_ne!(std::fs::read(&img).unwrap(), b"old image");
    assert!(side.is_file());
}

/// An image without a sidecar (parallel elaboration) removes the sidecar
/// of the image it replaces. Control: a file that is not its sidecar stays.
#[test]
fn design_without_sidecar_removes_the_stale_one() {
    let dir = fresh_dir("stale");
    let img = dir.join("par.dcimg");
    let side = dir.join("par.dcimg.model.json");
    let other = dir.join("par.model.json");
    std::fs::write(&side, b"{}").unwrap();
    std::fs::write(&other, b"{}").unwrap();
    let (ok, _, err) = dynocomp(&[
        "design",
        "--frf",
        &example("frf.csv"),
        "--fs",
        "51200",
        "--idle",
        &example("idle.csv"),
        "--out",
        s(&img),
        "--parallel",
        "--spindle-rpm",
        "16500",
        "--teeth",
        "4",
    ]);
    assert!(ok, "{err}");
    assert!(img.is_file());
    assert!(!side.exists(), "the old sidecar is still there");
    assert!(other.exists());
}

/// Runs `args` and expects a refusal that names `flags` and leaves `kept`
/// with the bytes it had.
fn refused_keeping(args: &[&str], flags: &[&str], kept: &Path) {
    let before = std::fs::read(kept).unwrap();
    let (ok, _, err) = dynocomp(args);
    assert!(!ok, "{args:?} succeeded");
    for f in flags {
        assert!(err.contains(f), "{args:?}: the message does not name {f}: {err}");
    }
    assert!(err.contains("same file"), "{err}");
    assert_eq!(std::fs::read(kept).unwrap(), before, "{args:?}: {} was changed", kept.display());
}

/// An output that is one of the inputs is refused, naming both flags, and
/// the input is left as it was: compensate, design (its image and its
/// sidecar), compare's folder and stream. Controls: the same runs with
/// another output succeed (compensate, design) or fail for another reason.
#[test]
fn an_output_that_is_an_input_is_refused() {
    let dir = fresh_dir("same");
    let img = example_image(&dir);
    let rec = dir.join("rec.csv");
    std::fs::copy(example("measured.csv"), &rec).unwrap();
    let truth = dir.join("truth.csv");
    std::fs::copy(example("true_force.csv"), &truth).unwrap();
    let (i, r, t) = (s(&img), s(&rec), s(&truth));
    refused_keeping(&["compensate", "--coeffs", i, "--input", r, "--output", r], &["--output", "--input"], &rec);
    let dot = format!("{}/./rec.csv", dir.display());
    refused_keeping(&["compensate", "--coeffs", i, "--input", r, "--output", &dot], &["--output", "--input"], &rec);
    refused_keeping(&["compensate", "--coeffs", i, "--input", r, "--output", i], &["--output", "--coeffs"], &img);
    let side = format!("{i}.model.json");
    refused_keeping(
        &["compensate", "--coeffs", i, "--input", r, "--output", &side, "--offline"],
        &["--output", "sidecar"],
        Path::new(&side),
    );
    let rep = dir.join("rep");
    let rp = s(&rep);
    refused_keeping(
        &["compensate", "--coeffs", i, "--input", r, "--output", t, "--report", rp, "--truth", t],
        &["--output", "--truth"],
        &truth,
    );
    // A hard link is the same file under another name.
    let link = dir.join("link.csv");
    std::fs::hard_link(&rec, &link).unwrap();
    refused_keeping(&["compensate", "--coeffs", i, "--input", r, "--output", s(&link)], &["--output", "--input"], &rec);
    let (ok, _, err) = dynocomp(&["compensate", "--coeffs", i, "--input", r, "--output", s(&dir.join("out.csv"))]);
    assert!(ok, "control: {err}");

    let frf = dir.join("frf.csv");
    std::fs::copy(example("frf.csv"), &frf).unwrap();
    let idle = dir.join("idle.csv");
    std::fs::copy(example("idle.csv"), &idle).unwrap();
    let (f, id) = (s(&frf), s(&idle));
    refused_keeping(&["design", "--frf", f, "--fs", "51200", "--idle", id, "--out", f], &["--out", "--frf"], &frf);
    refused_keeping(&["design", "--frf", f, "--fs", "51200", "--idle", id, "--out", id], &["--out", "--idle"], &idle);
    let idle_side = dir.join("i.dcimg.model.json");
    std::fs::copy(example("idle.csv"), &idle_side).unwrap();
    let i2 = dir.join("i.dcimg");
    refused_keeping(
        &["design", "--frf", f, "--fs", "51200", "--idle", s(&idle_side), "--out", s(&i2)],
        &["sidecar", "--idle"],
        &idle_side,
    );
    assert!(!i2.exists());
    refused_keeping(
        &[
            "design",
            "--frf",
            f,
            "--fs",
            "51200",
            "--idle",
            id,
            "--out",
            r,
            "--force-prior",
            "spectrum",
            "--force-record",
            r,
        ],
        &["--out", "--force-record"],
        &rec,
    );
    refused_keeping(
        &[
            "design",
            "--frf",
            f,
            "--fs",
            "51200",
            "--idle",
            id,
            "--out",
            r,
            "--spindle-rpm",
            "16500",
            "--teeth",
            "4",
            "--bands-from",
            r,
        ],
        &["--out", "--bands-from"],
        &rec,
    );

    let cmp = dir.join("cmp");
    std::fs::create_dir_all(&cmp).unwrap();
    let cidle = cmp.join("compare.txt");
    std::fs::copy(example("idle.csv"), &cidle).unwrap();
    refused_keeping(
        &["compare", "--frf", f, "--fs", "51200", "--idle", s(&cidle), "--out-dir", s(&cmp)],
        &["--out-dir", "--idle"],
        &cidle,
    );

    let port = dir.join("port");
    std::fs::write(&port, b"not a port").unwrap();
    refused_keeping(
        &["stream", "--serial", s(&port), "--output", s(&port), "--samples", "10"],
        &["--output", "--serial"],
        &port,
    );
}

/// Runs `dynocomp args`: (success, stdout bytes, stderr).
fn dynocomp_bytes(args: &[&str]) -> (bool, Vec<u8>, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_dynocomp")).args(args).output().expect("run dynocomp");
    (out.status.success(), out.stdout, String::from_utf8_lossy(&out.stderr).into_owned())
}

/// `compensate --output -` writes the record to standard output, the same
/// bytes as a file output, in every mode that holds the output differently
/// (streamed box filter, whole-record smoother); no file named `-` is made.
#[test]
fn compensate_writes_standard_output() {
    let dir = fresh_dir("stdout");
    let img = example_image(&dir);
    let measured = example("measured.csv");
    for extra in [&[][..], &["--offline"][..], &["--output-format", "tdms"][..]] {
        let file = dir.join("file.out");
        let mut args = vec!["compensate", "--coeffs", s(&img), "--input", &measured];
        args.extend_from_slice(extra);
        let (ok, _, err) = dynocomp_bytes(&[&args[..], &["--output", s(&file)]].concat());
        assert!(ok, "{err}");
        let (ok, piped, err) = dynocomp_bytes(&[&args[..], &["--output", "-"]].concat());
        assert!(ok, "{extra:?}: {err}");
        assert_eq!(piped, std::fs::read(&file).unwrap(), "{extra:?}: standard output differs from the file");
        assert!(piped.len() > 100_000);
    }
    assert!(!dir.join("-").exists());
}

/// Copy of the example's measured record with line `line` (1-based, the
/// header is line 1) given the force `fx` (N).
fn record_with(dir: &Path, name: &str, src: &str, line: usize, fx: &str) -> PathBuf {
    let text = std::fs::read_to_string(example(src)).unwrap();
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    let mut cols: Vec<String> = lines[line - 1].split(',').map(String::from).collect();
    cols[1] = fx.to_string();
    lines[line - 1] = cols.join(",");
    let p = dir.join(name);
    std::fs::write(&p, lines.join("\n") + "\n").unwrap();
    p
}

/// A record value beyond the full scale (`--max-force`, 100 kN by default)
/// is refused, naming the file and the line, by compensate (input and true
/// force) and design (--idle, --force-record); a larger --max-force takes
/// it, and a --max-force that is not a positive force is refused.
#[test]
fn implausible_forces_are_refused_and_max_force_sets_the_bound() {
    let dir = fresh_dir("maxforce");
    let img = example_image(&dir);
    let i = s(&img);
    let big = record_with(&dir, "big.csv", "measured.csv", 100, "2.5e5");
    let (ok, _, err) = dynocomp(&["compensate", "--coeffs", i, "--input", s(&big), "--output", s(&dir.join("o.csv"))]);
    assert!(!ok);
    assert!(err.contains("big.csv") && err.contains("line 100"), "{err}");
    let (ok, _, err) = dynocomp(&[
        "compensate",
        "--coeffs",
        i,
        "--input",
        s(&big),
        "--output",
        s(&dir.join("o.csv")),
        "--max-force",
        "3e5",
    ]);
    assert!(ok, "{err}");
    let (ok, _, err) = dynocomp(&[
        "compensate",
        "--coeffs",
        i,
        "--input",
        &example("measured.csv"),
        "--output",
        s(&dir.join("o2.csv")),
        "--report",
        s(&dir.join("rep")),
        "--truth",
        s(&big),
    ]);
    assert!(!ok && err.contains("big.csv"), "{err}");
    for bad in ["0", "-5", "nan"] {
        let (ok, _, err) = dynocomp(&[
            "compensate",
            "--coeffs",
            i,
            "--input",
            s(&big),
            "--output",
            s(&dir.join("o.csv")),
            &format!("--max-force={bad}"),
        ]);
        assert!(!ok && err.contains("--max-force"), "{bad}: {err}");
    }

    let idle = record_with(&dir, "idle.csv", "idle.csv", 50, "1e30");
    let (frf, d) = (example("frf.csv"), dir.join("d.dcimg"));
    let base = ["design", "--frf", &frf, "--fs", "51200", "--out", s(&d)];
    let (ok, _, err) = dynocomp(&[&base[..], &["--idle", s(&idle)]].concat());
    assert!(!ok && err.contains("idle.csv") && err.contains("line 50"), "{err}");
    // A lower full scale reaches the idle record too (its noise is ~1 N);
    // control: the default takes it.
    let (ok, _, err) = dynocomp(&[&base[..], &["--idle", &example("idle.csv"), "--max-force", "0.3"]].concat());
    assert!(!ok && err.contains("idle.csv") && err.contains("line"), "{err}");
    let (ok, _, err) = dynocomp(&[&base[..], &["--idle", &example("idle.csv")]].concat());
    assert!(ok, "{err}");
    let (ok, _, err) = dynocomp(
        &[&base[..], &["--idle", &example("idle.csv"), "--force-prior", "level", "--force-record", s(&big)]].concat(),
    );
    assert!(!ok && err.contains("big.csv") && err.contains("line 100"), "{err}");
}

/// An idle record sampled at another rate than --fs gives another R: it is
/// refused, naming the file and both rates. Control: the right rate works.
#[test]
fn design_refuses_an_idle_record_at_another_rate() {
    let dir = fresh_dir("idlerate");
    let out = dir.join("d.dcimg");
    let (ok, _, err) = dynocomp(&[
        "design",
        "--frf",
        &example("frf.csv"),
        "--fs",
        "25600",
        "--idle",
        &example("idle.csv"),
        "--out",
        s(&out),
    ]);
    assert!(!ok);
    assert!(err.contains("idle.csv") && err.contains("51200") && err.contains("25600"), "{err}");
    assert!(!out.exists());
    let (ok, _, err) = dynocomp(&[
        "design",
        "--frf",
        &example("frf.csv"),
        "--fs",
        "51200",
        "--idle",
        &example("idle.csv"),
        "--out",
        s(&out),
    ]);
    assert!(ok, "{err}");
}

/// `flash` names what is wrong with an image in words, not as Rust's
/// debug form (`Image(BadCrc { stored: … })`).
#[test]
fn flash_errors_read_as_words() {
    let dir = fresh_dir("flash");
    let img = example_image(&dir);
    let mut bytes = std::fs::read(&img).unwrap();
    bytes[100] ^= 1;
    let bad = dir.join("bad.dcimg");
    std::fs::write(&bad, &bytes).unwrap();
    let (ok, _, err) = dynocomp(&["flash", s(&bad), "--probe", "--dry-run"]);
    assert!(!ok);
    assert!(err.contains("bad.dcimg") && err.contains("CRC"), "{err}");
    assert!(!err.contains("BadCrc") && !err.contains('{'), "{err}");
}

/// Runs `dynocomp args` and gives up after `secs` seconds (killing it):
/// (finished in time, success, stderr).
fn dynocomp_within(args: &[&str], secs: u64) -> (bool, bool, String) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_dynocomp"))
        .args(args)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let t0 = Instant::now();
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            let mut err = String::new();
            std::io::Read::read_to_string(child.stderr.as_mut().unwrap(), &mut err).unwrap();
            return (true, status.success(), err);
        }
        if t0.elapsed() > Duration::from_secs(secs) {
            let _ = child.kill();
            let _ = child.wait();
            return (false, false, String::new());
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Out-of-range parameters are refused at once with a message naming the
/// parameter and its range, instead of running for hours (`--teeth
/// 100000`), aborting on a failed allocation (`--duration 1e9`), taking a
/// negative number for a flag, or designing with a non-positive force.
/// Control: the same flags with sensible values run.
#[test]
fn out_of_range_parameters_are_refused_at_once() {
    let dir = fresh_dir("range");
    let out = s(&dir.join("sim")).to_string();
    let refused = [
        (&["--teeth", "100000"][..], "teeth"),
        (&["--duration", "1e9"][..], "duration"),
        (&["--fs", "-51200"][..], "fs"),
        (&["--spindle-rpm", "0"][..], "spindle"),
        (&["--frf-lines", "100000000"][..], "lines"),
        (&["--drift-percent", "3", "--preset", "cut-2"][..], "--preset"),
    ];
    for (extra, word) in refused {
        let (done, ok, err) = dynocomp_within(&[&["simulate", "--out", &out][..], extra].concat(), 20);
        assert!(done, "{extra:?} did not finish");
        assert!(!ok && err.contains(word) && !err.contains("panicked") && err.lines().count() == 1, "{extra:?}: {err}");
    }
    let (done, ok, err) = dynocomp_within(
        &["simulate", "--out", &out, "--duration", "0.05", "--idle-duration", "0.05", "--teeth", "8"],
        120,
    );
    assert!(done && ok, "control: {err}");

    let (frf, idle, img) = (example("frf.csv"), example("idle.csv"), dir.join("d.dcimg"));
    let base = ["design", "--frf", &frf, "--idle", &idle, "--out", s(&img)];
    let refused = [
        (&["--fs", "51200", "--force-rms", "0"][..], "--force-rms 0"),
        (&["--fs", "51200", "--force-rms", "-5"][..], "--force-rms -5"),
        (&["--fs", "51200", "--force-rms=-5"][..], "--force-rms -5"),
        (&["--fs", "-51200"][..], "--fs -51200"),
        // Used to design for seconds, then fail to encode the image.
        (&["--fs", "51200", "--full-scale", "0"][..], "--full-scale 0"),
        (&["--fs", "51200", "--full-scale=-5000"][..], "--full-scale -5000"),
        (&["--fs", "51200", "--full-scale", "NaN"][..], "--full-scale NaN"),
        (&["--fs", "51200", "--full-scale", "1e30"][..], "--full-scale 1000000000000000000000000000000"),
        (&["--fs", "51200", "--frf", &frf, "--full-scale", "0"][..], "--full-scale 0"),
        (&["--fs", "51200", "--spindle-rpm", "0", "--teeth", "4"][..], "--spindle-rpm 0"),
        (&["--fs", "51200", "--spindle-rpm", "5000", "--teeth", "0"][..], "--teeth 0"),
        (
            &[
                "--fs",
                "51200",
                "--spindle-rpm",
                "0",
                "--teeth",
                "4",
                "--force-prior",
                "harmonics",
                "--force-record",
                &idle,
            ][..],
            "--spindle-rpm 0",
        ),
    ];
    for (extra, want) in refused {
        let (done, ok, err) = dynocomp_within(&[&base[..], extra].concat(), 20);
        assert!(done, "{extra:?} did not finish");
        assert!(!ok && err.contains(want), "{extra:?}: {err}");
        assert!(!img.exists(), "{extra:?} wrote an image");
    }
    // Control: a full scale within the range designs.
    let (done, ok, err) = dynocomp_within(&[&base[..], &["--fs", "51200", "--full-scale", "20000"][..]].concat(), 120);
    assert!(done && ok && img.exists(), "control: {err}");
}

/// Random `simulate` arguments from a fixed seed (values in and far out of
/// range, negative, non-finite): every run ends within its time with
/// success or a one-line error, never a panic, an abort or a hang.
#[test]
fn random_simulate_arguments_never_panic_or_hang() {
    use rand::{RngExt, SeedableRng};
    let dir = fresh_dir("simfuzz");
    let out = s(&dir.join("sim")).to_string();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(31);
    let flags = [
        "--fs",
        "--duration",
        "--idle-duration",
        "--oversample",
        "--spindle-rpm",
        "--teeth",
        "--diameter",
        "--helix",
        "--axial-depth",
        "--radial-depth",
        "--feed-per-tooth",
        "--runout-um",
        "--noise-variance",
        "--adc-bits",
        "--adc-range",
        "--frf-lines",
        "--frf-df",
        "--impacts",
        "--hammer-cutoff",
        "--chatter-hz",
        "--ramp-in-revs",
    ];
    let values = ["0", "-1", "1e9", "-1e300", "nan", "inf", "3", "0.5", "100000", "1e-300", "18446744073709551616"];
    for _ in 0..40 {
        let mut args = vec![
            "simulate".to_string(),
            "--out".into(),
            out.clone(),
            "--duration".into(),
            "0.02".into(),
            "--idle-duration".into(),
            "0.02".into(),
            "--frf-lines".into(),
            "200".into(),
        ];
        for _ in 0..rng.random_range(1..4) {
            args.push(flags[rng.random_range(0..flags.len())].to_string());
            args.push(values[rng.random_range(0..values.len())].to_string());
        }
        let a: Vec<&str> = args.iter().map(String::as_str).collect();
        let (done, ok, err) = dynocomp_within(&a, 120);
        assert!(done, "{a:?} did not finish");
        assert!(ok || (err.starts_with("error") && !err.contains("panicked")), "{a:?}: {err}");
    }
}

/// The output's format follows --output-format, else its extension, else
/// the input's: a TDMS record compensated into `x.csv` gives CSV (it gave
/// TDMS bytes), and --output-format that contradicts the extension is an
/// error that writes nothing. Control: a format that fits the name works.
#[test]
fn output_format_and_extension_agree() {
    let dir = fresh_dir("format");
    let img = example_image(&dir);
    let i = s(&img);
    let tdms = dir.join("rec.tdms");
    let (ok, _, err) = dynocomp(&[
        "compensate",
        "--coeffs",
        i,
        "--input",
        &example("measured.csv"),
        "--output",
        s(&tdms),
        "--raw-timing",
    ]);
    assert!(ok, "{err}");
    assert_eq!(&std::fs::read(&tdms).unwrap()[..4], b"TDSm");
    let csv = dir.join("x.csv");
    let (ok, _, err) = dynocomp(&["compensate", "--coeffs", i, "--input", s(&tdms), "--output", s(&csv)]);
    assert!(ok, "{err}");
    let text = std::fs::read(&csv).unwrap();
    assert!(text.starts_with(b"t_s,fx") || text.starts_with(b"fx"), "{:?}", String::from_utf8_lossy(&text[..20]));
    let bad = dir.join("y.csv");
    let (ok, _, err) =
        dynocomp(&["compensate", "--coeffs", i, "--input", s(&tdms), "--output", s(&bad), "--output-format", "tdms"]);
    assert!(!ok && err.contains("y.csv") && err.contains("tdms"), "{err}");
    assert!(!bad.exists());
    let good = dir.join("y.tdms");
    let (ok, _, err) = dynocomp(&[
        "compensate",
        "--coeffs",
        i,
        "--input",
        &example("measured.csv"),
        "--output",
        s(&good),
        "--output-format",
        "tdms",
    ]);
    assert!(ok, "{err}");
}

/// `design` on the first 1 to 100 lines of a valid FRF (8-64 lines made
/// the fit panic on a non-square matrix): an image or a one-line error,
/// never a panic or a hang.
#[test]
fn design_on_a_few_frf_lines_never_panics() {
    let dir = fresh_dir("fewlines");
    let text = std::fs::read_to_string(example("frf.csv")).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    let idle = example("idle.csv");
    for n in [1usize, 2, 3, 5, 8, 9, 12, 16, 24, 33, 48, 64, 100] {
        let frf = dir.join(format!("f{n}.csv"));
        std::fs::write(&frf, lines[..=n].join("\n") + "\n").unwrap();
        let out = dir.join(format!("f{n}.dcimg"));
        let (done, ok, err) =
            dynocomp_within(&["design", "--frf", s(&frf), "--fs", "51200", "--idle", &idle, "--out", s(&out)], 300);
        assert!(done, "{n} lines: no answer");
        let last = err.lines().last().unwrap_or("");
        assert!(ok || (last.starts_with("error: ") && !err.contains("panicked")), "{n} lines: {err}");
        assert_eq!(ok, out.exists(), "{n} lines");
    }
}

/// With the latency removed, the last L outputs have no measured
/// look-ahead: the summary says a predicted one stands in. Against the
/// simulator's true force, their error stays within 3x the record's RMS
/// error (it was 5-70x with the last value held); control: with
/// --raw-timing nothing is extrapolated and nothing is said.
#[test]
fn the_tail_with_a_predicted_look_ahead_is_announced_and_accurate() {
    let dir = fresh_dir("tail");
    let img = example_image(&dir);
    let out = dir.join("c.csv");
    let (ok, _, err) =
        dynocomp(&["compensate", "--coeffs", s(&img), "--input", &example("measured.csv"), "--output", s(&out)]);
    assert!(ok, "{err}");
    // The image's latency L, from the message "the last L samples use a
    // predicted look-ahead".
    let latency: usize = err
        .split("the last ")
        .filter_map(|t| t.split_once(" samples use a predicted look-ahead"))
        .find_map(|(n, _)| n.parse().ok())
        .unwrap_or_else(|| panic!("no predicted look-ahead announced: {err}"));
    let column = |p: &Path, k: usize| -> Vec<f64> {
        std::fs::read_to_string(p)
            .unwrap()
            .lines()
            .skip(1)
            .map(|l| l.split(',').nth(k).unwrap().parse().unwrap())
            .collect()
    };
    let truth = std::path::PathBuf::from(example("true_force.csv"));
    let worst_ratio = (1..=3)
        .map(|k| {
            let (y, t) = (column(&out, k), column(&truth, k));
            let n = y.len();
            assert_eq!(n, t.len());
            let interior = ((100..n - 100).map(|i| (y[i] - t[i]).powi(2)).sum::<f64>() / (n - 200) as f64).sqrt();
            let tail = (n - latency..n).map(|i| (y[i] - t[i]).abs()).fold(0.0, f64::max);
            tail / interior
        })
        .fold(0.0, f64::max);
    eprintln!("worst |tail error| / interior RMS error: {worst_ratio:.2}");
    assert!(worst_ratio < 3.0, "the tail's error is {worst_ratio:.1} times the interior's RMS error");
    let (ok, _, err) = dynocomp(&[
        "compensate",
        "--coeffs",
        s(&img),
        "--input",
        &example("measured.csv"),
        "--output",
        s(&out),
        "--raw-timing",
    ]);
    assert!(ok && !err.contains("look-ahead"), "{err}");
}

/// `simulate` says what it is about to compute before it starts, and when
/// it writes: the announced sample count is the written record's.
#[test]
fn simulate_announces_its_work_before_doing_it() {
    let dir = fresh_dir("sim_progress");
    let out = dir.join("sim");
    let (ok, _, err) = dynocomp(&["simulate", "--out", s(&out), "--duration", "0.1", "--frf-lines", "513"]);
    assert!(ok, "{err}");
    let lines: Vec<&str> = err.lines().collect();
    let at = |what: &str| lines.iter().position(|l| l.contains(what)).unwrap_or_else(|| panic!("no {what:?} in {err}"));
    let (start, writing, wrote) = (at("samples × 3 axes at"), at("simulate: writing"), at("wrote "));
    assert!(start == 0 && start < writing && writing < wrote, "{err}");
    let announced: usize = lines[start].trim_start_matches("simulate: ").split(' ').next().unwrap().parse().unwrap();
    let rows = std::fs::read_to_string(out.join("measured.csv")).unwrap().lines().count() - 1;
    assert_eq!(announced, rows, "{}", lines[start]);
}
