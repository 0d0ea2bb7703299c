//! The offline-only modes through the binary on the bundled example:
//! `design` writes the model sidecar, `compensate --offline` needs it and
//! refuses a missing one without leaving output; `design --parallel` writes
//! a format-2 image that `inspect` reports as offline only and `compensate`
//! runs band by band.

use std::path::PathBuf;

use crate::cli_common;
use cli_common::{dynocomp, dynocomp_piped, example};

fn tmp(name: &str) -> PathBuf {
    cli_common::tmp("offline-cli", name)
}

#[test]
fn offline_smoother_needs_the_sidecar_of_its_image() {
    let img = tmp("box.dcimg");
    let (frf, idle, measured) = (example("frf.uff"), example("idle.csv"), example("measured.csv"));
    let (ok, _, err) =
        dynocomp(&["design", "--frf", &frf, "--fs", "51200", "--idle", &idle, "--out", img.to_str().unwrap()]);
    assert!(ok, "{err}");
    let sidecar = tmp("box.dcimg.model.json");
    assert!(sidecar.exists(), "design must write the model sidecar");
    let out = tmp("smoothed.csv");
    let (ok, _, err) = dynocomp(&[
        "compensate",
        "--coeffs",
        img.to_str().unwrap(),
        "--input",
        &measured,
        "--output",
        out.to_str().unwrap(),
        "--offline",
    ]);
    assert!(ok, "{err}");
    assert!(err.contains("fixed-interval smoother"), "{err}");
    let text = std::fs::read_to_string(&out).unwrap();
    assert_eq!(text.lines().count(), std::fs::read_to_string(&measured).unwrap().lines().count());
    // A file is smoothed with its forward pass spilled to disk (memory
    // independent of the record's length) and read twice; a pipe, which
    // cannot be read twice, is kept in a temporary file during its first
    // reading. Same output, byte for byte, and both with a report against
    // the true force.
    assert!(err.contains("forward pass spilled"), "{err}");
    let (report_file, report_pipe, out_pipe) = (tmp("rep-file"), tmp("rep-pipe"), tmp("smoothed-pipe.csv"));
    let truth = example("true_force.csv");
    let (ok, _, err_file) = dynocomp(&[
        "compensate",
        "--coeffs",
        img.to_str().unwrap(),
        "--input",
        &measured,
        "--output",
        out.to_str().unwrap(),
        "--offline",
        "--truth",
        &truth,
        "--report",
        report_file.to_str().unwrap(),
    ]);
    assert!(ok, "{err_file}");
    let bytes = std::fs::read(&measured).unwrap();
    let (ok, err_pipe, fed) = dynocomp_piped(
        &[
            "compensate",
            "--coeffs",
            img.to_str().unwrap(),
            "--input",
            "/dev/stdin",
            "--output",
            out_pipe.to_str().unwrap(),
            "--offline",
            "--truth",
            &truth,
            "--report",
            report_pipe.to_str().unwrap(),
        ],
        bytes.clone(),
    );
    assert!(ok && fed, "{err_pipe}");
    assert!(err_pipe.contains("with the input (a pipe) for its second reading"), "{err_pipe}");
    assert!(!err_file.contains("(a pipe)"), "{err_file}");
    assert_eq!(
        std::fs::read(&out).unwrap(),
        std::fs::read(&out_pipe).unwrap(),
        "a file and a pipe smoothed differently"
    );
    let nrmse = |e: &str| e.lines().filter(|l| l.contains("NRMSE")).map(str::to_string).collect::<Vec<_>>();
    assert!(!nrmse(&err_file).is_empty(), "{err_file}");
    assert_eq!(nrmse(&err_file), nrmse(&err_pipe), "the reports' scores differ");

    // A malformed row deep in a piped record (beyond the first blocks
    // spooled): a one-line error naming the input and its line, and
    // nothing left in the output's folder, neither the output nor the
    // temporary copy of the input.
    let text = String::from_utf8(bytes).unwrap();
    let bad_line = 20_000;
    let spoil =
        |l: &str| l.split(',').enumerate().map(|(j, v)| if j == 2 { "oops" } else { v }).collect::<Vec<_>>().join(",");
    let broken: String = text
        .lines()
        .enumerate()
        .map(|(k, l)| if k + 1 == bad_line { format!("{}\n", spoil(l)) } else { format!("{l}\n") })
        .collect();
    let folder = tmp("bad-pipe");
    std::fs::create_dir_all(&folder).unwrap();
    let out_bad = folder.join("smoothed.csv");
    let (ok, err, _) = dynocomp_piped(
        &[
            "compensate",
            "--coeffs",
            img.to_str().unwrap(),
            "--input",
            "/dev/stdin",
            "--output",
            out_bad.to_str().unwrap(),
            "--offline",
        ],
        broken.into_bytes(),
    );
    assert!(!ok, "{err}");
    assert!(
        err.contains("/dev/stdin")
            && err.contains(&format!("line {bad_line}"))
            && err.contains("oops")
            && err.trim().lines().count() == 1,
        "{err}"
    );
    assert_eq!(std::fs::read_dir(&folder).unwrap().count(), 0, "no output and no temporary file may be left behind");

    // without the sidecar: a one-line error naming it, and no output file
    std::fs::remove_file(&sidecar).unwrap();
    let out2 = tmp("smoothed2.csv");
    let (ok, _, err) = dynocomp(&[
        "compensate",
        "--coeffs",
        img.to_str().unwrap(),
        "--input",
        &measured,
        "--output",
        out2.to_str().unwrap(),
        "--offline",
    ]);
    assert!(!ok);
    assert!(err.contains("box.dcimg.model.json") && err.trim().lines().count() == 1, "{err}");
    assert!(!out2.exists(), "no output may be left behind");
    // --offline and --raw-timing exclude each other
    let (ok, _, _) = dynocomp(&[
        "compensate",
        "--coeffs",
        img.to_str().unwrap(),
        "--input",
        &measured,
        "--output",
        out2.to_str().unwrap(),
        "--offline",
        "--raw-timing",
    ]);
    assert!(!ok);
}

#[test]
fn parallel_design_is_offline_only_and_runs_in_compensate() {
    let img = tmp("par.dcimg");
    let (frf, idle, measured) = (example("frf.uff"), example("idle.csv"), example("measured.csv"));
    let (ok, stdout, err) = dynocomp(&[
        "design",
        "--frf",
        &frf,
        "--fs",
        "51200",
        "--idle",
        &idle,
        "--out",
        img.to_str().unwrap(),
        "--parallel",
        "--spindle-rpm",
        "16500",
        "--teeth",
        "4",
        "--harmonics",
        "2",
    ]);
    assert!(ok, "{err}");
    assert!(stdout.contains("OFFLINE ONLY"), "{stdout}");
    let (ok, text, err) = dynocomp(&["inspect", img.to_str().unwrap()]);
    assert!(ok, "{err}");
    assert!(
        text.contains("format v2")
            && text.contains("offline only: parallel elaboration, 3 bands: 0-248 Hz, 990-1210 Hz, 1980-2420 Hz"),
        "{text}"
    );
    let (ok, json, _) = dynocomp(&["inspect", img.to_str().unwrap(), "--json"]);
    assert!(ok);
    let j: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert_eq!((j["offline_only"].as_bool(), j["runs_in_box"].as_bool()), (Some(true), Some(false)));
    assert_eq!(j["bands"].as_array().unwrap().len(), 3);
    let out = tmp("par.csv");
    let (ok, _, err) = dynocomp(&[
        "compensate",
        "--coeffs",
        img.to_str().unwrap(),
        "--input",
        &measured,
        "--output",
        out.to_str().unwrap(),
    ]);
    assert!(ok && err.contains("parallel elaboration, 3 bands"), "{err}");
    // the smoother needs a box image
    let out2 = tmp("par2.csv");
    let (ok, _, err) = dynocomp(&[
        "compensate",
        "--coeffs",
        img.to_str().unwrap(),
        "--input",
        &measured,
        "--output",
        out2.to_str().unwrap(),
        "--offline",
    ]);
    assert!(!ok && err.contains("parallel-elaboration image"), "{err}");
    assert!(!out2.exists());
    // --parallel without bands is refused
    let (ok, _, err) = dynocomp(&[
        "design",
        "--frf",
        &frf,
        "--fs",
        "51200",
        "--idle",
        &idle,
        "--out",
        tmp("nob.dcimg").to_str().unwrap(),
        "--parallel",
    ]);
    assert!(!ok && err.contains("--parallel needs bands"), "{err}");
    assert!(!tmp("nob.dcimg").exists());
}
