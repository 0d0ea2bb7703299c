//! The box design's q chosen for a record's force spectrum (issue #12,
//! item 3; `host-tools/src/force_spectrum.rs`, `design --force-prior
//! spectrum`).
//!
//! - The estimate against known truth: sines of known amplitude through a
//!   known sensor, in white noise of known variance, on one segment and on
//!   a Welch average; the noise is removed. Records that cannot say
//!   anything are refused with what to do.
//! - Against the simulator's band-limited truth, on the rates harness's
//!   worst axis at 25.6 kHz (low-modes z, at the exact inverse's noise
//!   floor, 2.49 %): q chosen for a second record of the same cut brings it
//!   under 2 %; negative control: the flat criterion leaves it above. The
//!   other two axes stay within 5 % of the flat criterion. Its cost: on a
//!   chattering cut the record's q is worse than the flat one.
//! - Through the binary: the summary line, the `--json` field, the
//!   report's plot (control: none in a default design's report), the note
//!   `compensate` prints from the sidecar (control: none for a default
//!   image), and the refusals (no record, a record without an axis, an
//!   idle record) with no image written.

use dynocomp::design::force_spectrum::{estimate, estimate_matrix, WELCH_SEGMENT};
use dynocomp::eval::rates::{cases, run_case, run_case_on, RunOptions};
use dynocomp::simulate::Chatter;
use rustfft::num_complex::Complex64;
use std::f64::consts::PI;

use crate::cli_common;
use cli_common::{dynocomp, example};

/// White noise of variance `r` (a fixed LCG, Box–Muller).
fn white(n: usize, r: f64, seed: u64) -> Vec<f64> {
    let mut s = seed;
    let mut u = || {
        s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((s >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    };
    (0..n).map(|_| (-2.0 * u().ln()).sqrt() * (2.0 * PI * u()).cos() * r.sqrt()).collect()
}

/// Three sines (f Hz, force amplitude N) seen through a sensor of gain
/// |Ĝ| = 2 + f/1000 (real), plus white noise of variance R.
fn record(n: usize, fs: f64, r: f64) -> (Vec<f64>, [(f64, f64); 3]) {
    let lines = [(350.0, 40.0), (1550.0, 8.0), (3150.0, 2.0)];
    let noise = white(n, r, 7);
    let y = (0..n)
        .map(|k| {
            let t = k as f64 / fs;
            lines.iter().map(|(f, a)| (2.0 + f / 1000.0) * a * (2.0 * PI * f * t).sin()).sum::<f64>() + noise[k]
        })
        .collect();
    (y, lines)
}

fn sensor(f: f64) -> Complex64 {
    Complex64::new(2.0 + f / 1000.0, 0.0)
}

/// 100 Hz cells over 0-4 kHz.
fn cells() -> Vec<(f64, f64)> {
    (0..40).map(|i| (100.0 * i as f64, 100.0 * (i + 1) as f64)).collect()
}

#[test]
fn the_estimate_recovers_known_line_powers_and_removes_the_noise() {
    let fs = 10_240.0;
    let r = 4.0;
    for n in [20_480, 3 * WELCH_SEGMENT + 1234] {
        let (y, lines) = record(n, fs, r);
        let s = estimate(&y, fs, &sensor, r, &cells()).unwrap();
        for (f, a) in lines {
            let c = (f / 100.0) as usize;
            // The Hann window spreads a line over a few bins, all inside its cell
            // (each line sits mid-cell).
            let p = s.power_n2[c];
            assert!((p / (a * a / 2.0) - 1.0).abs() < 0.05, "n {n}: {f} Hz: {p:.3} N² against {:.3}", a * a / 2.0);
        }
        // Away from the lines only noise, which is removed: its residue is
        // small against the weakest line (2 N² of power) and against the
        // noise the inverse carries there.
        let off: f64 = (0..40).filter(|c| ![3, 15, 31].contains(c)).map(|c| s.power_n2[c]).sum();
        let noise: f64 = (0..40).filter(|c| ![3, 15, 31].contains(c)).map(|c| s.noise_n2[c]).sum();
        assert!(off < 0.2 && off < 0.1 * noise, "n {n}: {off:.4} N² off the lines, noise {noise:.4} N²");
        // Control: the same record with R understated tenfold leaves the
        // noise in, far above that bound.
        let under = estimate(&y, fs, &sensor, r / 10.0, &cells()).unwrap();
        let off_under: f64 = (0..40).filter(|c| ![3, 15, 31].contains(c)).map(|c| under.power_n2[c]).sum();
        assert!(off_under > 0.5 * noise, "n {n}: {off_under:.4} N² against noise {noise:.4} N²");
        // The weights: the lines' shares, 0.1 % spread flat.
        let w = s.weights();
        assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        assert!(w[3] > 0.9 && w[20] >= 1e-3 / 40.0 && w[20] < 1e-3, "{} {}", w[3], w[20]);
    }
}

/// A 3x3 sensor with 40-60 % crosstalk: G = [[2, 1, 0.5], [0.8, 3, 1], [0.6, 1.2, 2.5]]·(1 + f/4000).
fn sensor_matrix(f: f64) -> nalgebra::Matrix3<Complex64> {
    let g = nalgebra::Matrix3::new(2.0, 1.0, 0.5, 0.8, 3.0, 1.0, 0.6, 1.2, 2.5);
    g.map(|v| Complex64::new(v * (1.0 + f / 4000.0), 0.0))
}

/// Each force direction j a sine of its own (f Hz, amplitude N), all three
/// channels seeing every force through [`sensor_matrix`]: the matrix
/// estimate puts each sine's power in its own direction and cell, and
/// removes the noise. Control: the same records through the direct
/// entries alone (crosstalk ignored) leave the other forces' power in
/// every direction's cells.
#[test]
fn the_matrix_estimate_separates_the_force_directions() {
    let (fs, n, r) = (10_240.0, 20_480, [4.0, 2.0, 3.0]);
    let lines = [(350.0, 40.0), (1550.0, 20.0), (3150.0, 10.0)];
    let noise: Vec<Vec<f64>> = (0..3).map(|c| white(n, r[c], 11 + c as u64)).collect();
    let y: Vec<Vec<f64>> = (0..3)
        .map(|c| {
            (0..n)
                .map(|k| {
                    let t = k as f64 / fs;
                    let forces = lines.iter().enumerate();
                    forces.map(|(j, (f, a))| sensor_matrix(*f)[(c, j)].re * a * (2.0 * PI * f * t).sin()).sum::<f64>()
                        + noise[c][k]
                })
                .collect()
        })
        .collect();
    let ch = [y[0].as_slice(), y[1].as_slice(), y[2].as_slice()];
    let s = estimate_matrix(ch, fs, &sensor_matrix, r, &cells()).unwrap();
    for (j, (f, a)) in lines.iter().enumerate() {
        let c = (f / 100.0) as usize;
        let want = a * a / 2.0;
        assert!(
            (s[j].power_n2[c] / want - 1.0).abs() < 0.05,
            "force {j}: {:.3} N² against {want:.3}",
            s[j].power_n2[c]
        );
        for (k, other) in s.iter().enumerate().filter(|(k, _)| *k != j) {
            assert!(other.power_n2[c] < 1e-3 * want, "force {k} holds {:.4} N² of force {j}'s line", other.power_n2[c]);
        }
    }
    let diagonal = |f: f64| nalgebra::Matrix3::from_diagonal(&sensor_matrix(f).diagonal());
    let blind = estimate_matrix(ch, fs, &diagonal, r, &cells()).unwrap();
    let leaked = blind[0].power_n2[15] / (lines[1].1 * lines[1].1 / 2.0);
    assert!(leaked > 0.01, "control: force x shows only {leaked:.4} of force y's line without the crosstalk");
}

#[test]
fn records_that_cannot_tell_the_spectrum_are_refused() {
    let fs = 10_240.0;
    let r = 4.0;
    let idle = white(20_480, r, 3);
    let e = estimate(&idle, fs, &sensor, r, &cells()).unwrap_err();
    assert!(format!("{e:#}").contains("does not stand above the noise"), "{e:#}");
    let (mut y, _) = record(20_480, fs, r);
    y[777] = f64::NAN;
    let e = estimate(&y, fs, &sensor, r, &cells()).unwrap_err();
    assert!(format!("{e:#}").contains("sample 777"), "{e:#}");
    // 100 Hz cells need 50 Hz resolution: 0.02 s; 128 samples at 10.24 kHz are 0.0125 s.
    let (short, _) = record(128, fs, r);
    let e = estimate(&short, fs, &sensor, r, &cells()).unwrap_err();
    assert!(format!("{e:#}").contains("at least 0.020 s"), "{e:#}");
    // Control: 512 samples (0.05 s) suffice.
    let (ok, _) = record(512, fs, r);
    estimate(&ok, fs, &sensor, r, &cells()).unwrap();
}

fn z_error(r: &dynocomp::eval::rates::CaseResult) -> f64 {
    *r.axes[2].comp_nrmse.as_ref().unwrap()
}

#[test]
fn the_records_spectrum_brings_the_worst_axis_at_25_6_khz_under_two_percent() {
    let case = cases().into_iter().find(|c| c.name == "low-modes").unwrap();
    let fs = 25_600.0;
    let flat = run_case(&case, fs, &RunOptions::default()).unwrap();
    let spec = run_case(&case, fs, &RunOptions { force_spectrum: true, ..Default::default() }).unwrap();
    let (ef, es) = (z_error(&flat), z_error(&spec));
    eprintln!(
        "low-modes z at 25.6 kHz: flat {:.3} %, record's spectrum {:.3} %, floor {:.3} %",
        100.0 * ef,
        100.0 * es,
        100.0 * spec.axes[2].noise_floor
    );
    // Measured 1.52 % against 2.49 % (BENCHMARKS.md).
    assert!(es <= 0.02, "{:.3} %", 100.0 * es);
    // Negative control: the flat criterion leaves it above 2 %, at the floor.
    assert!(ef > 0.02, "{:.3} %", 100.0 * ef);
    // Below the exact inverse's noise floor: no unbiased inverse gets there.
    assert!(es < 0.8 * spec.axes[2].noise_floor);
    for a in 0..2 {
        let (f, s) = (flat.axes[a].comp_nrmse.as_ref().unwrap(), spec.axes[a].comp_nrmse.as_ref().unwrap());
        assert!(s / f < 1.05, "axis {a}: {:.3} % against {:.3} %", 100.0 * s, 100.0 * f);
    }
    // The cost, stated in docs/design.md: a cut that chatters where the steady
    // record had little force meets a filter tuned for less (measured
    // 4.58 % against 2.26 % with the flat criterion).
    let mut chat = case.sim_params(fs);
    chat.milling.chatter = Some(Chatter { freq_hz: 1710.0, amplitude_mm: 0.02, onset_s: 0.2, growth_s: 0.02 });
    let flat_c = run_case_on(&case, &chat, &RunOptions::default()).unwrap();
    let spec_c = run_case_on(&case, &chat, &RunOptions { force_spectrum: true, ..Default::default() }).unwrap();
    assert!(
        z_error(&spec_c) > 1.5 * z_error(&flat_c),
        "{:.3} % against {:.3} %",
        100.0 * z_error(&spec_c),
        100.0 * z_error(&flat_c)
    );
}

fn tmp(name: &str) -> std::path::PathBuf {
    cli_common::tmp("force-spectrum", name)
}

#[test]
fn design_chooses_q_for_the_records_spectrum_through_the_binary() {
    let img = tmp("box.dcimg");
    let img_s = img.to_str().unwrap();
    let (frf, idle, measured) = (example("frf.uff"), example("idle.csv"), example("measured.csv"));
    let base = ["design", "--frf", frf.as_str(), "--fs", "51200", "--idle", idle.as_str(), "--out", img_s];
    // Without its record: one line saying what is missing, no image.
    let (ok, _, err) = dynocomp(&[&base[..], &["--force-prior", "spectrum"]].concat());
    assert!(!ok && err.contains("--force-record") && err.trim().lines().count() == 1, "{err}");
    assert!(!img.exists());
    // A record without fz: the file and the axis named, no image.
    let two = tmp("xy.csv");
    let text = std::fs::read_to_string(&measured).unwrap();
    let cut: String = text.lines().map(|l| l.rsplit_once(',').unwrap().0.to_string() + "\n").collect();
    std::fs::write(&two, cut).unwrap();
    let (ok, _, err) =
        dynocomp(&[&base[..], &["--force-prior", "spectrum", "--force-record", two.to_str().unwrap()]].concat());
    assert!(!ok && err.contains("xy.csv") && err.contains("fz"), "{err}");
    assert!(!img.exists());
    // The idle record: nothing above the noise.
    let (ok, _, err) = dynocomp(&[&base[..], &["--force-prior", "spectrum", "--force-record", idle.as_str()]].concat());
    assert!(!ok && err.contains("does not stand above the noise") && err.contains("idle.csv"), "{err}");
    assert!(!img.exists());

    let (ok, json, err) =
        dynocomp(&[&base[..], &["--force-prior", "spectrum", "--force-record", measured.as_str(), "--json"]].concat());
    assert!(ok, "{err}");
    let j: serde_json::Value = serde_json::from_str(&json).unwrap();
    let (ok, flat_json, err) = dynocomp(&[&base[..], &["--json"]].concat());
    assert!(ok, "{err}");
    let flat: serde_json::Value = serde_json::from_str(&flat_json).unwrap();
    for (ax, fl) in j["axes"].as_array().unwrap().iter().zip(flat["axes"].as_array().unwrap()) {
        let fsp = &ax["force_spectrum"];
        let rms = fsp["force_rms_n"].as_f64().unwrap();
        // The example's forces are tens of newtons in the band, not 100 N.
        assert!(rms > 1.0 && rms < 100.0, "{fsp}");
        assert_eq!(fsp["predicted_error"], ax["predicted_error"]);
        assert!(fsp["flat_predicted_error"].as_f64().unwrap() > 0.0);
        assert!(fl["force_spectrum"].is_null());
    }
    // The record's shape changes the prediction (negative control for the
    // flat `level` prior's equality in design_at_the_records_level_through_the_binary):
    // y 0.127 % against 0.145 % flat.
    let shaped = j["axes"].as_array().unwrap().iter().map(|a| &a["force_spectrum"]).any(|f| {
        (f["predicted_error"].as_f64().unwrap() / f["flat_predicted_error"].as_f64().unwrap() - 1.0).abs() > 1e-3
    });
    assert!(shaped, "{json}");
    let report = tmp("report");
    let (ok, summary, err) = dynocomp(
        &[
            &base[..],
            &["--force-prior", "spectrum", "--force-record", measured.as_str(), "--report", report.to_str().unwrap()],
        ]
        .concat(),
    );
    assert!(ok, "{err}");
    let index = std::fs::read_to_string(report.join("index.html")).unwrap();
    for a in ["x", "y", "z"] {
        assert!(summary.contains(&format!("{a} q chosen for the force spectrum of --force-record")), "{summary}");
        // The report plots where the force is against where the filter is accurate.
        let svg = std::fs::read_to_string(report.join(format!("{a}_force_spectrum.svg"))).unwrap();
        assert!(
            svg.contains("record&apos;s force power per line") || svg.contains("record's force power per line"),
            "{a}"
        );
        assert!(index.contains(&format!("{a}_force_spectrum.svg")));
    }
    // Control: a default design's report has no such plot.
    let plain_report = tmp("plain-report");
    let plain_img = tmp("plain-report.dcimg");
    let (ok, _, err) = dynocomp(&[
        "design",
        "--frf",
        frf.as_str(),
        "--fs",
        "51200",
        "--idle",
        idle.as_str(),
        "--out",
        plain_img.to_str().unwrap(),
        "--report",
        plain_report.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    assert!(!plain_report.join("x_force_spectrum.svg").exists());
    // The image says so whenever it is used, from its sidecar: on the box
    // path and offline; the default image (control) does not.
    let out = tmp("comp.csv");
    for offline in [false, true] {
        let mut args =
            vec!["compensate", "--coeffs", img_s, "--input", measured.as_str(), "--output", out.to_str().unwrap()];
        if offline {
            args.push("--offline");
        }
        let (ok, _, err) = dynocomp(&args);
        assert!(ok, "{err}");
        for a in ["x", "y", "z"] {
            assert!(
                err.contains(&format!("note: axis {a}: q of this image was chosen for the force spectrum of")),
                "{err}"
            );
        }
        assert!(err.contains("measured.csv") && err.contains("chatter"), "{err}");
    }
    let plain = tmp("plain.dcimg");
    let (ok, _, err) = dynocomp(&[
        "design",
        "--frf",
        frf.as_str(),
        "--fs",
        "51200",
        "--idle",
        idle.as_str(),
        "--out",
        plain.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    let (ok, _, err) = dynocomp(&[
        "compensate",
        "--coeffs",
        plain.to_str().unwrap(),
        "--input",
        measured.as_str(),
        "--output",
        out.to_str().unwrap(),
    ]);
    assert!(ok && !err.contains("force spectrum"), "{err}");
    // --line-width belongs to the harmonic prior.
    let (ok, _, err) = dynocomp(
        &[&base[..], &["--force-prior", "spectrum", "--force-record", measured.as_str(), "--line-width", "5"]].concat(),
    );
    assert!(!ok && err.contains("--line-width"), "{err}");
}

#[test]
fn the_records_level_makes_the_predicted_error_honest() {
    // `--force-prior level`: q for a flat spectrum at the record's in-band
    // force level instead of --force-rms 100 N. The predicted error is then
    // for the cut's force, and matches the error measured against the
    // simulator's true force (low-modes at 25.6 kHz: z 2.44 % predicted,
    // 2.48 % measured; x 0.68 / 0.68 %). y's prediction is optimistic by
    // its fitted model's error, which no prediction from the model sees
    // (0.22 / 0.35 %). Negative control: the default's prediction for z
    // (0.28 %) is more than 5x optimistic. Accuracy stays that of the
    // default (the spectrum's shape is what buys accuracy, not its level).
    let case = cases().into_iter().find(|c| c.name == "low-modes").unwrap();
    let fs = 25_600.0;
    // The default's criterion at 100 N against the same criterion at the
    // record's level: both in-band (`--force-prior` designs are not quiet
    // above the band, crate::design::above_band).
    let in_band = RunOptions { above_band: dynocomp::design::above_band::AboveBand::Inverse, ..Default::default() };
    let flat = run_case(&case, fs, &in_band).unwrap();
    let level = run_case(&case, fs, &RunOptions { force_spectrum: true, force_level_only: true, ..Default::default() })
        .unwrap();
    let ratio = |a: &dynocomp::eval::rates::AxisScore| a.predicted_error / a.comp_nrmse.as_ref().unwrap();
    for (f, l) in flat.axes.iter().zip(&level.axes) {
        eprintln!(
            "axis {}: measured {:.3} %, predicted {:.3} % at the record's level, {:.3} % at 100 N",
            l.axis,
            100.0 * l.comp_nrmse.as_ref().unwrap(),
            100.0 * l.predicted_error,
            100.0 * f.predicted_error
        );
        let (cf, cl) = (f.comp_nrmse.as_ref().unwrap(), l.comp_nrmse.as_ref().unwrap());
        assert!(
            cl / cf < 1.03,
            "axis {}: {:.3} % at the record's level against {:.3} %",
            l.axis,
            100.0 * cl,
            100.0 * cf
        );
    }
    for a in [0, 2] {
        let r = ratio(&level.axes[a]);
        assert!((0.8..=1.25).contains(&r), "axis {a}: predicted/measured {r:.2}");
    }
    let r = ratio(&level.axes[1]);
    assert!((0.5..=2.0).contains(&r), "axis y: predicted/measured {r:.2}");
    let r = ratio(&flat.axes[2]);
    assert!(r < 0.2, "the default's prediction for z was honest ({r:.2})");
}

#[test]
fn design_at_the_records_level_through_the_binary() {
    let img = tmp("level.dcimg");
    let img_s = img.to_str().unwrap();
    let (frf, idle, measured) = (example("frf.uff"), example("idle.csv"), example("measured.csv"));
    let base = ["design", "--frf", frf.as_str(), "--fs", "51200", "--idle", idle.as_str(), "--out", img_s];
    // Without its record: one line naming what is missing, no image.
    let (ok, _, err) = dynocomp(&[&base[..], &["--force-prior", "level"]].concat());
    assert!(
        !ok && err.contains("--force-prior level needs --force-record") && err.trim().lines().count() == 1,
        "{err}"
    );
    assert!(!img.exists());
    let report = tmp("level-report");
    let (ok, summary, err) = dynocomp(
        &[
            &base[..],
            &["--force-prior", "level", "--force-record", measured.as_str(), "--report", report.to_str().unwrap()],
        ]
        .concat(),
    );
    assert!(ok, "{err}");
    for a in ["x", "y", "z"] {
        assert!(
            summary.contains(&format!("{a} q chosen for a flat force spectrum at the level of --force-record")),
            "{summary}"
        );
        // No spectrum plot: the criterion's spectrum is flat.
        assert!(!report.join(format!("{a}_force_spectrum.svg")).exists());
    }
    assert!(
        summary.contains("pred.: predicted in-band RMS error for a flat force spectrum at the level of --force-record"),
        "{summary}"
    );
    // z now predicts 0.61 %, above the 0.5 % that makes the latency choice
    // look further ahead, but as noise: its predicted distortion is small,
    // so the design keeps latency 4 after one round.
    assert!(summary.contains("latency 4 samples (default:"), "{summary}");
    let (ok, json, err) =
        dynocomp(&[&base[..], &["--force-prior", "level", "--force-record", measured.as_str(), "--json"]].concat());
    assert!(ok, "{err}");
    let j: serde_json::Value = serde_json::from_str(&json).unwrap();
    let (ok, flat_json, err) = dynocomp(&[
        "design",
        "--frf",
        frf.as_str(),
        "--fs",
        "51200",
        "--idle",
        idle.as_str(),
        "--out",
        tmp("level-flat.dcimg").to_str().unwrap(),
        "--above-band",
        "inverse",
        "--json",
    ]);
    assert!(ok, "{err}");
    let flat: serde_json::Value = serde_json::from_str(&flat_json).unwrap();
    for (ax, fl) in j["axes"].as_array().unwrap().iter().zip(flat["axes"].as_array().unwrap()) {
        let fsp = &ax["force_spectrum"];
        assert_eq!(fsp["level_only"], true, "{fsp}");
        // The same flat criterion, once with equal weights 1/n and once as
        // a mean: equal to rounding. (With `spectrum`, above, y differs by
        // 13 %: the check below would see a prior that is not flat.)
        let (pe, fpe) = (fsp["predicted_error"].as_f64().unwrap(), fsp["flat_predicted_error"].as_f64().unwrap());
        assert!((pe / fpe - 1.0).abs() < 1e-12, "{fsp}");
        // The example's forces are 11-86 N in the band, below the default
        // 100 N, so the honest prediction is larger than the default's.
        let (p, pf) = (ax["predicted_error"].as_f64().unwrap(), fl["predicted_error"].as_f64().unwrap());
        assert!(p > pf, "predicted {p} at the record's level, {pf} at 100 N");
    }
    // As safe for chatter as the default: no note when the image is used.
    let out = tmp("level-comp.csv");
    let (ok, _, err) =
        dynocomp(&["compensate", "--coeffs", img_s, "--input", measured.as_str(), "--output", out.to_str().unwrap()]);
    assert!(ok && !err.contains("note: axis"), "{err}");
}
