//! `compensate` warns when the record was clipped (plateaus at its extremes,
//! [`dynocomp::io::clipping`]) and still writes its output; so does `design`
//! of a clipped `--force-record`. The bundled example's record, within its
//! rails, gets no such warning (the negative control).

use crate::cli_common;
use cli_common::{design, dynocomp, example, tmp};

#[test]
fn a_clipped_record_is_compensated_with_a_warning_naming_channel_and_sample() {
    let dir = tmp("clipping", "cli");
    std::fs::create_dir_all(&dir).unwrap();
    let p = |n: &str| dir.join(n).display().to_string();
    let (ok, _, err) = design(&example("frf.uff"), &example("idle.csv"), "51200", &p("c.dcimg"), &[]);
    assert!(ok, "{err}");
    // fx of the example clipped at 80 % of its largest value, as an ADC
    // with that range would hold it.
    let text = std::fs::read_to_string(example("measured.csv")).unwrap();
    let rows: Vec<Vec<f64>> =
        text.lines().skip(1).map(|l| l.split(',').map(|v| v.parse().unwrap()).collect()).collect();
    let rail = 0.8 * rows.iter().map(|r| r[1]).fold(f64::NEG_INFINITY, f64::max);
    let first = rows.iter().position(|r| r[1] >= rail).unwrap() + 1;
    let mut clipped = String::from("t_s,fx,fy,fz\n");
    for r in &rows {
        clipped.push_str(&format!("{},{},{},{}\n", r[0], r[1].min(rail), r[2], r[3]));
    }
    std::fs::write(p("clipped.csv"), clipped).unwrap();
    // With a report beside the output: the overview of the clipped axis
    // marks the rail, and its caption says where and what to do.
    let run = |input: &str, out: &str| {
        let report = format!("{out}.report");
        dynocomp(&["compensate", "--coeffs", &p("c.dcimg"), "--input", input, "--output", out, "--report", &report])
    };
    let marked = |out: &str, axis: &str| {
        let svg = std::fs::read_to_string(format!("{out}.report/{axis}_overview.svg")).unwrap();
        let index = std::fs::read_to_string(format!("{out}.report/index.html")).unwrap();
        (svg.contains("clipped (measured)"), index.contains("Clipped: the measured force holds"))
    };
    let (ok, _, err) = run(&p("clipped.csv"), &p("out.csv"));
    assert!(ok, "{err}");
    let warning = err.lines().find(|l| l.contains("clipped")).unwrap_or_else(|| panic!("no warning: {err}"));
    assert!(
        warning.starts_with("warning: ")
            && warning.contains("clipped.csv")
            && warning.contains("fx holds its maximum")
            && warning.contains(&format!("the first at sample {first})")),
        "{warning}"
    );
    assert_eq!(err.matches("clipped there").count(), 1, "only fx, only its maximum: {err}");
    assert!(std::path::Path::new(&p("out.csv")).exists(), "the output is written all the same");
    assert_eq!(marked(&p("out.csv"), "x"), (true, true));
    let index = std::fs::read_to_string(p("out.csv.report/index.html")).unwrap();
    assert!(index.contains(&format!("its maximum {rail} N")), "the caption names the rail");
    assert_eq!(marked(&p("out.csv"), "y"), (false, true), "fy is not clipped: only fx's overview is marked");
    // The record as measured: no warning, no mark.
    let (ok, _, err) = run(&example("measured.csv"), &p("out2.csv"));
    assert!(ok && !err.contains("clipped"), "{err}");
    assert_eq!(marked(&p("out2.csv"), "x"), (false, false));
    // A clipped representative record for a force prior.
    let prior = |rec: &str, out: &str| {
        let extra = ["--force-prior", "level", "--force-record", rec];
        design(&example("frf.uff"), &example("idle.csv"), "51200", &p(out), &extra)
    };
    let (ok, _, err) = prior(&p("clipped.csv"), "l.dcimg");
    assert!(ok, "{err}");
    assert!(err.contains("fx holds its maximum") && err.contains("the force spectrum taken from it"), "{err}");
    let (ok, _, err) = prior(&example("measured.csv"), "l2.dcimg");
    assert!(ok && !err.contains("clipped"), "{err}");
}
