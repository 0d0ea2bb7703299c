//! `dynocomp simulate --dyno plate`: the files it writes read back to the
//! simulation (all nine FRFs with coherence, the records, truth.json with the
//! model and the crosstalk figure), the per-axis model stays the default,
//! and the plate flags are refused where they mean nothing.

use clap::Parser;
use dynocomp::cli::simulate::SimulateArgs;
use dynocomp::frf::MatrixKind;
use dynocomp::simulate::plate::{simulate_plate, PlateModal, PlateSetup, PlateSim};

#[derive(Parser)]
struct Cli {
    #[command(flatten)]
    args: SimulateArgs,
}

fn parse(extra: &[&str], out: &std::path::Path) -> SimulateArgs {
    let mut argv = vec!["simulate", "--out", out.to_str().unwrap(), "--seed", "4", "--duration", "0.1"];
    argv.extend_from_slice(&["--idle-duration", "0.05", "--frf-lines", "513", "--frf-df", "8"]);
    argv.extend_from_slice(extra);
    Cli::try_parse_from(argv).map_err(|e| e.to_string()).unwrap().args
}

#[test]
fn plate_files_hold_the_nine_frfs_the_records_and_the_model() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("sim");
    let args = parse(&["--dyno", "plate", "--dyno-preset", "tall", "--cut-offset", "20:-10:0"], &out);
    dynocomp::cli::simulate::run(&args).unwrap();
    let setup = PlateSetup::preset("tall").unwrap();
    let plate = PlateSim { setup: setup.clone(), cut_offset_m: [0.02, -0.01, 0.0] };
    let sim = simulate_plate(4, &args.params().unwrap(), &plate).unwrap();
    for f in ["frf.uff", "frf.csv"] {
        let frf = dynocomp::io::read_frf(&out.join(f)).unwrap();
        assert_eq!(frf.matrix_status().kind(), MatrixKind::Complete, "{f}");
        assert_eq!(frf.freq_hz.len(), 513);
        for (a, b) in frf.entries().zip(sim.frf.entries()) {
            assert_eq!((a.channel, a.direction), (b.channel, b.direction));
            let err = a.frf.iter().zip(b.frf).map(|(x, y)| (x - y).norm() / y.norm().max(1e-3)).fold(0.0, f64::max);
            assert!(err < 1e-10, "{f}: entry {}{} differs by {err}", a.channel, a.direction);
            assert!(a.coherence.is_some(), "{f}: coherence of {}{} lost", a.channel, a.direction);
        }
    }
    let rd = |f: &str| dynocomp::io::signal_csv::read_signal_csv(&out.join(f)).unwrap();
    let (m, t) = (rd("measured.csv"), rd("true_force.csv"));
    for a in 0..3 {
        assert_eq!(m.channel(a).unwrap(), &sim.measured[a][..], "measured axis {a}");
        assert_eq!(t.channel(a).unwrap(), &sim.truth[a][..], "truth axis {a}");
    }
    let j: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(out.join("truth.json")).unwrap()).unwrap();
    assert_eq!(j["dynamometer"], "plate");
    assert_eq!(j["dyno_preset"], "tall");
    assert_eq!(j["modes"].as_array().unwrap().len(), 12);
    let back: PlateSetup = serde_json::from_value(j["plate"].clone()).unwrap();
    assert_eq!(back, setup);
    let cut: Vec<f64> = serde_json::from_value(j["cut_point_m"].clone()).unwrap();
    assert!((cut[0] - 0.045).abs() < 1e-12 && (cut[1] - 0.0).abs() < 1e-12 && (cut[2] - 0.09).abs() < 1e-12);
    // The crosstalk figure is the model's over the FRF's lines.
    let xt: [[f64; 3]; 3] = serde_json::from_value(j["crosstalk_peak"].clone()).unwrap();
    let want = PlateModal::new(&setup, setup.force_point_m).unwrap().crosstalk_peak(&sim.frf.freq_hz);
    for i in 0..3 {
        for k in 0..3 {
            assert!((xt[i][k] - want[i][k]).abs() <= 1e-12 * want[i][k], "crosstalk {i}{k}");
        }
    }
    let band: Vec<f64> = serde_json::from_value(j["crosstalk_band_hz"].clone()).unwrap();
    assert_eq!(band, vec![0.0, 4096.0]);
    // The static gain recorded is S.
    let g0: [[f64; 3]; 3] = serde_json::from_value(j["static_gain"].clone()).unwrap();
    assert!((g0[0][1] - (setup.crosstalk[0][1])).abs() < 1e-9);
}

#[test]
fn the_per_axis_model_writes_the_direct_frfs_and_plate_flags_need_the_plate() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("d");
    let args = parse(&["--dyno", "diagonal"], &out);
    dynocomp::cli::simulate::run(&args).unwrap();
    let frf = dynocomp::io::read_frf(&out.join("frf.csv")).unwrap();
    assert_eq!(frf.matrix_status().kind(), MatrixKind::DirectOnly);
    let j: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(out.join("truth.json")).unwrap()).unwrap();
    assert_eq!(j["version"], 1);
    assert!(j.get("dynamometer").is_none());
    let err = |extra: &[&str]| {
        format!("{:#}", dynocomp::cli::simulate::run(&parse(extra, &dir.path().join("x"))).unwrap_err())
    };
    assert!(err(&["--dyno", "diagonal", "--dyno-preset", "tall"]).contains("not --dyno diagonal"));
    assert!(err(&["--dyno", "diagonal", "--cut-offset", "10:0:0"]).contains("not --dyno diagonal"));
    assert!(err(&["--dyno", "plate", "--preset", "cut-1"]).contains("use --dyno-preset"));
    assert!(err(&["--preset", "cut-1", "--dyno-preset", "flat"]).contains("use --dyno-preset"));
    assert!(err(&["--drift-percent", "3", "--cut-offset", "10:0:0"]).contains("add --dyno diagonal"));
    assert!(err(&["--dyno", "plate", "--drift-percent", "3"]).contains("not simulated yet"));
    assert!(err(&["--dyno", "plate", "--dyno-preset", "cube"]).contains("flat, offcentre, tall"));
    assert!(
        err(&["--dyno", "plate", "--dyno-preset", "flat", "--cut-offset", "150:0:0"]).contains("cut offset x = 0.15 m")
    );
    assert!(!dir.path().join("x").exists(), "no output after an error");
    let bad = Cli::try_parse_from(["simulate", "--out", "o", "--dyno", "plate", "--cut-offset", "1:2"]);
    assert!(bad.err().unwrap().to_string().contains("DX:DY:DZ"));
    // A random plate from the seed, also without --dyno: the default.
    for (flags, name) in [(&["--dyno", "plate"][..], "r"), (&[][..], "default")] {
        let r = dir.path().join(name);
        dynocomp::cli::simulate::run(&parse(flags, &r)).unwrap();
        let j: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(r.join("truth.json")).unwrap()).unwrap();
        assert!(j.get("dyno_preset").is_none());
        assert_eq!(dynocomp::io::read_frf(&r.join("frf.uff")).unwrap().entries().count(), 9, "{flags:?}");
    }
}

/// Without --dyno, `simulate` is the plate, as a real dynamometer has
/// crosstalk; a paper preset or a drift keeps its per-axis dynamometer, and
/// --dyno diagonal asks for it (its files: the test above).
#[test]
fn the_plate_is_the_default_and_the_per_axis_dynamometer_a_choice() {
    use dynocomp::cli::simulate::DynoModel::{Diagonal, Plate};
    let dir = tempfile::tempdir().unwrap();
    let o = dir.path();
    assert_eq!(parse(&[], o).dyno_model(), Plate);
    assert_eq!(parse(&["--dyno-preset", "flat"], o).dyno_model(), Plate);
    assert_eq!(parse(&["--preset", "cut-1"], o).dyno_model(), Diagonal);
    assert_eq!(parse(&["--drift-percent", "3"], o).dyno_model(), Diagonal);
    assert_eq!(parse(&["--dyno", "plate", "--drift-percent", "3"], o).dyno_model(), Plate);
    assert_eq!(parse(&["--dyno", "diagonal"], o).dyno_model(), Diagonal);
}
