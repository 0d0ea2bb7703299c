//! Band-fitted and paper-method designs beside the default design, through
//! the binary on the bundled example, judged against its true force: a
//! band-fitted axis that predicts more error than the default carries the
//! default design (the image and JSON say so), and the image as written is
//! not worse than the default image on the true force; a paper-method axis
//! is kept with a warning naming the better command.

use crate::cli_common;
use cli_common::{dynocomp, example};
use dynocomp::io::signal_csv::read_signal_csv;
use dynocomp::metrics::{accuracy, accuracy_as_written};

/// NRMSE of each axis of image `img` on the example's record against its
/// true force (band-limited, latency removed).
fn delivered(img: &str, tag: &str) -> Vec<f64> {
    delivered_both(img, tag).0
}

/// [`delivered`], and the output as written against the truth through the
/// anti-aliasing filter alone (no band limit).
fn delivered_both(img: &str, tag: &str) -> (Vec<f64>, Vec<f64>) {
    let out = cli_common::tmp("versus-default", &format!("{tag}.csv"));
    let (ok, _, err) = dynocomp(&[
        "compensate",
        "--coeffs",
        img,
        "--input",
        &example("measured.csv"),
        "--output",
        out.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    let (comp, truth) =
        (read_signal_csv(&out).unwrap(), read_signal_csv(std::path::Path::new(&example("true_force.csv"))).unwrap());
    let band = dynocomp::metrics::scoring_band_hz(51_200.0);
    let (c, t) = (|a| comp.channel(a).unwrap(), |a| truth.channel(a).unwrap());
    let limited = (0..3).map(|a| accuracy(c(a), t(a), 51_200.0, band).nrmse).collect();
    let written = (0..3).map(|a| accuracy_as_written(c(a), t(a), 51_200.0, band).output.nrmse).collect();
    (limited, written)
}

/// Every axis of `asked` within 1.5x of the default image's figure `default`.
fn within_1_5x(asked: &[f64], default: &[f64], what: &str) {
    for a in 0..3 {
        assert!(
            asked[a] <= 1.5 * default[a],
            "axis {a}: {what} {:.3} % vs default {:.3} %",
            100.0 * asked[a],
            100.0 * default[a]
        );
    }
}

#[test]
fn band_fitting_is_never_silently_worse_than_the_default() {
    let (frf, idle) = (example("frf.uff"), example("idle.csv"));
    let img = |n: &str| cli_common::tmp("versus-default", n).to_str().unwrap().to_string();
    let (def, band, paper) = (img("default.dcimg"), img("band.dcimg"), img("paper.dcimg"));
    let base = |out: &str| {
        vec![
            "design".to_string(),
            "--frf".into(),
            frf.clone(),
            "--fs".into(),
            "51200".into(),
            "--idle".into(),
            idle.clone(),
            "--out".into(),
            out.to_string(),
        ]
    };
    let run = |a: Vec<String>| {
        let a: Vec<&str> = a.iter().map(String::as_str).collect();
        let (ok, out, err) = dynocomp(&a);
        assert!(ok, "{err}");
        (out, err)
    };
    run(base(&def));
    let mut a = base(&band);
    a.extend(["--spindle-rpm", "16500", "--teeth", "4", "--json"].map(String::from));
    let (out, _) = run(a);
    let j: serde_json::Value = serde_json::from_str(&out).unwrap();
    let v = j["versus_default"].as_array().unwrap();
    assert_eq!(v.len(), 3, "{v:?}");
    for ax in v {
        let (asked, default) = (ax["asked_error"].as_f64().unwrap(), ax["default_error"].as_f64().unwrap());
        let replaced = ax["replaced_by_default"].as_bool().unwrap();
        assert_eq!(replaced, default * dynocomp::design::versus_default::MARGIN < asked, "{ax}");
    }
    let ((d_def, w_def), d_band) = (delivered_both(&def, "def"), delivered(&band, "band"));
    eprintln!("on the true force: default {d_def:?}, with --spindle-rpm 16500 --teeth 4 {d_band:?}");
    within_1_5x(&d_band, &d_def, "band-fitted image");
    // The judge counts what each design writes above the band (the default
    // is quiet there): one harmonic band, whose z design matched the
    // default in band (0.609 against 0.607 % on the true force) with
    // q = 1.3e13, was kept by an in-band judge and wrote 57 % as written
    // against the default's 5.0 %. Now no axis is much worse as written.
    let harmonic = img("harmonic.dcimg");
    let mut a = base(&harmonic);
    a.extend(["--spindle-rpm", "16500", "--teeth", "4", "--harmonics", "1"].map(String::from));
    run(a);
    let (_, w_harm) = delivered_both(&harmonic, "harmonic");
    eprintln!("as written: default {w_def:?}, one harmonic band {w_harm:?}");
    within_1_5x(&w_harm, &w_def, "one harmonic band's image as written");
    // The paper's method is kept, with a warning where the default is better;
    // the warning is right where the true force says the paper is worse.
    let mut a = base(&paper);
    a.extend(["--method", "paper"].map(String::from));
    let (_, err) = run(a);
    let d_paper = delivered(&paper, "paper");
    eprintln!("paper {d_paper:?}\n{err}");
    for (a, name) in ["x", "y", "z"].iter().enumerate() {
        if d_paper[a] > 2.0 * d_def[a] {
            assert!(
                err.contains(&format!("WARNING: {name} asked-for design")) && err.contains("drop --method paper"),
                "axis {name}: {err}"
            );
        }
    }
    // Negative control: the paper's method is worse on the true force on
    // some axis of this example, so the warning check above ran.
    assert!((0..3).any(|a| d_paper[a] > 2.0 * d_def[a]), "paper {d_paper:?} vs default {d_def:?}");
}
