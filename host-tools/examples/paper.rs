//! The seed paper's claims against what dynocomp measures on the paper's
//! own experiments (issue #13; the figures of `docs/paper.md`).
//!
//!     cargo run --release -p dynocomp --example paper [-- --quick]
//!
//! Every record figure is an NRMSE against the simulator's true force
//! (DESIGN.md): RMS error / std of the truth, below 4 kHz ("0-4 kHz") or
//! restricted to the preset's fitting bands ("bands"). `--quick` simulates
//! shorter records (the designs are the same).

use dynocomp::eval::reproduce::{
    evaluate, local_error_single_vs_parallel, preset_bands, simulate_preset, AxisOutcome, Method,
};
use dynocomp::simulate::presets::{dynamometer_9257a, preset, NAMES};
use std::time::Instant;

const AXES: [&str; 3] = ["x", "y", "z"];

fn pct(v: f64) -> String {
    format!("{:.1} %", 100.0 * v)
}

fn row(preset: &str, method: &Method, out: &[AxisOutcome]) {
    for o in out {
        match &o.result {
            Ok(s) => println!(
                "| {preset} | {} | {} | {} | {} | {} | {} | {} | {} |",
                method.label(),
                AXES[o.axis],
                s.orders,
                pct(s.fit_error),
                pct(s.raw_in_bands),
                pct(s.comp_in_bands),
                pct(s.raw_full),
                pct(s.comp_full)
            ),
            Err(e) => {
                let e: String = e.replace('|', "/").chars().take(220).collect();
                println!("| {preset} | {} | {} | refused: {e} | | | | | |", method.label(), AXES[o.axis])
            }
        }
    }
}

fn main() -> anyhow::Result<()> {
    let quick = std::env::args().any(|a| a == "--quick");
    let t0 = Instant::now();
    println!("### Claim 1: only forces below 200 Hz are measurable uncompensated\n");
    println!("First line where the true |G(f) − 1| of the preset set-up exceeds 5 % (the usable-range rule of the paper's Fig. 1):\n");
    let d = dynamometer_9257a();
    for (a, name) in AXES.iter().enumerate() {
        let g = d.axis(a);
        let f5 = (1..4096).map(|f| f as f64).find(|f| (g.frf(*f) - 1.0).norm() > 0.05).unwrap_or(f64::NAN);
        println!(
            "- axis {name}: {f5:.0} Hz (|G − 1| at 83 Hz: {}, at 277 Hz: {})",
            pct((g.frf(83.3) - 1.0).norm()),
            pct((g.frf(276.7) - 1.0).norm())
        );
    }
    println!("\n### Every preset: raw and compensated NRMSE against the true force\n");
    println!(
        "| preset | method | axis | orders | fit err | raw (bands) | comp. (bands) | raw (0-4 kHz) | comp. (0-4 kHz) |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    let mut chirp1300 = None;
    for name in NAMES {
        let p = preset(name)?;
        let duration = if quick { Some(if p.params.excitation.is_some() { 0.3 } else { 0.25 }) } else { None };
        let s = simulate_preset(&p, 1, duration)?;
        let bands = preset_bands(&p, &s.frf)?;
        let mut methods = vec![Method::PaperBandFitted, Method::Default];
        if name == "chirp-1300" {
            methods.insert(1, Method::PaperWholeBandAt(6, 8));
            methods.insert(1, Method::PaperWholeBand);
        }
        for m in &methods {
            let t = Instant::now();
            row(name, m, &evaluate(&s, &bands, m));
            eprintln!("{name} {}: {:.1} s", m.label(), t.elapsed().as_secs_f64());
        }
        if name == "chirp-1300" {
            chirp1300 = Some((s, bands));
        }
    }
    let (s, bands) = chirp1300.expect("chirp-1300 is a preset");
    println!("\n### Parallel elaboration around 300 Hz (chirp 10-1300 Hz)\n");
    println!("RMS of |H(f)·G(f) − 1| over 250-350 Hz with the simulator's true G: one band-fitted design over 10-1300 Hz against parallel elaboration over 10-430, 470-880, 920-1300 Hz:\n");
    println!("| axis | single band-fitted | parallel |\n|---|---|---|");
    let t = Instant::now();
    for (a, axis) in AXES.iter().enumerate() {
        let (single, parallel) = local_error_single_vs_parallel(
            &s,
            a,
            &bands,
            &[(10.0, 430.0), (470.0, 880.0), (920.0, 1300.0)],
            (250.0, 350.0),
        );
        let show = |r: Result<f64, String>| {
            r.map(pct).unwrap_or_else(|e| format!("refused: {}", e.chars().take(120).collect::<String>()))
        };
        println!("| {} | {} | {} |", axis, show(single), show(parallel));
    }
    eprintln!("parallel: {:.1} s", t.elapsed().as_secs_f64());
    println!("\n(run time {:.0} s)", t0.elapsed().as_secs_f64());
    Ok(())
}
