//! Model match of the discrete model on the unit circle, side by side for the
//! three discretizations: max |Ĝ_d(e^{j2πf/fs})/Ĝ(j2πf) − 1| over the
//! scoring band 0..min(4 kHz, 0.4 fs) and over 0..0.45 fs, for exact modal
//! models of 9257-class dynamometers (no fit error involved).
//!
//! usage: cargo run --release -p dynocomp --example discretize_match
use dynocomp::design::discretize::{discretize, Discretization};
use dynocomp::fit::PoleResidueModel;

/// Modes of a model: (f_n Hz, ζ, share of the static gain) each.
type Modes = Vec<(f64, f64, f64)>;

fn main() -> anyhow::Result<()> {
    // (label, fs, modes (f_n Hz, ζ, share of the static gain))
    let cases: Vec<(&str, f64, Modes)> = vec![
        ("2.5 kHz sensor, 300 Hz machine", 25_600.0, vec![(300.0, 0.03, 0.1), (2500.0, 0.02, 0.9)]),
        ("2.5 kHz sensor", 10_240.0, vec![(300.0, 0.03, 0.1), (2500.0, 0.02, 0.9)]),
        ("4.8 kHz sensor (near Nyquist)", 10_240.0, vec![(200.0, 0.03, 0.1), (4800.0, 0.03, 0.9)]),
        ("6 kHz sensor (above Nyquist)", 10_240.0, vec![(150.0, 0.03, 0.1), (1800.0, 0.02, 0.3), (6000.0, 0.03, 0.6)]),
        ("close pair 2.9/3.1 kHz", 25_600.0, vec![(500.0, 0.02, 0.1), (2900.0, 0.015, 0.5), (3100.0, 0.015, 0.4)]),
        ("3.3 kHz sensor", 51_200.0, vec![(276.0, 0.03, 0.05), (600.0, 0.02, 0.05), (3300.0, 0.02, 0.9)]),
        ("100 Hz machine, 2 kHz sensor", 102_400.0, vec![(100.0, 0.01, 0.1), (2000.0, 0.02, 0.9)]),
    ];
    println!(
        "{:<34} {:>8} | {:>9} {:>9} {:>9} | {:>9} {:>9} {:>9} | D taps cond",
        "case", "fs", "foh band", "zoh band", "fit band", "foh .45fs", "zoh .45fs", "fit .45fs"
    );
    for (label, fs, modes) in cases {
        let model = PoleResidueModel::from_modes(&modes);
        let band = (0.0, (0.4 * fs).min(4000.0));
        let grid = |hi: f64| (0..=2000).map(move |i| hi * i as f64 / 2000.0).collect::<Vec<_>>();
        let (gb, gw) = (grid(band.1), grid(0.45 * fs));
        let mut row = Vec::new();
        let mut diag = None;
        for m in [Discretization::Foh, Discretization::Zoh, Discretization::Fit] {
            let (dm, dg) = discretize(&model, fs, m, band)?;
            row.push((dm.match_error(&gb, |f| model.frf(f)), dm.match_error(&gw, |f| model.frf(f))));
            if m == Discretization::Fit {
                diag = Some(dg);
            }
        }
        let dg = diag.unwrap();
        println!(
            "{label:<34} {fs:>8.0} | {:>8.3}% {:>8.3}% {:>8.4}% | {:>8.2}% {:>8.2}% {:>8.3}% | {} {} {:.1e}",
            row[0].0 * 100.0,
            row[1].0 * 100.0,
            row[2].0 * 100.0,
            row[0].1 * 100.0,
            row[1].1 * 100.0,
            row[2].1 * 100.0,
            dg.advance,
            dg.fir_taps,
            dg.condition
        );
    }
    Ok(())
}
