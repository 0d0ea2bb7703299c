//! Score compensated (and raw) force records against a true-force record:
//! NRMSE below a cut-off, as defined in `dynocomp::metrics`.
//!
//! usage: score TRUE.csv COMPENSATED.csv RAW.csv FS_HZ [F_MAX_HZ]
use anyhow::{Context, Result};
use dynocomp::io::signal_csv::read_signal_csv;
use dynocomp::metrics::{accuracy, accuracy_as_written};
use std::path::Path;

fn main() -> Result<()> {
    let a: Vec<String> = std::env::args().collect();
    anyhow::ensure!(a.len() >= 5, "usage: score TRUE.csv COMPENSATED.csv RAW.csv FS_HZ [F_MAX_HZ]");
    let truth = read_signal_csv(Path::new(&a[1]))?;
    let comp = read_signal_csv(Path::new(&a[2]))?;
    let raw = read_signal_csv(Path::new(&a[3]))?;
    let fs: f64 = a[4].parse().context("FS_HZ")?;
    let fmax: f64 = a.get(5).map_or(Ok(4000.0), |s| s.parse()).context("F_MAX_HZ")?;
    println!("accuracy against the true force below {fmax} Hz (NRMSE = RMS error / std of the band-limited truth;");
    println!("p2p: RMS error / peak-to-peak of the truth, a second figure for comparison only;");
    println!("as written: the unfiltered output against the truth through the anti-aliasing filter alone,");
    println!("beside what a perfect estimate band-limited to {fmax} Hz reaches against that truth):");
    println!(
        "{:<5} {:>12} {:>12} {:>12} {:>16} {:>16} {:>12} {:>12}",
        "axis", "raw", "compensated", "improvement", "raw (p2p)", "comp. (p2p)", "as written", "perfect"
    );
    for (axis, t) in &truth.channels {
        let (Some(c), Some(r)) = (comp.channel(*axis), raw.channel(*axis)) else { continue };
        let ac = accuracy(c, t, fs, fmax);
        let ar = accuracy(r, t, fs, fmax);
        let aw = accuracy_as_written(c, t, fs, fmax);
        println!(
            "f{:<4} {:>11.2}% {:>11.3}% {:>11.0}x {:>15.2}% {:>15.3}% {:>11.2}% {:>11.2}%",
            dynocomp::frf::axis_name(*axis),
            ar.nrmse * 100.0,
            ac.nrmse * 100.0,
            ar.nrmse / ac.nrmse,
            ar.nrmse_p2p * 100.0,
            ac.nrmse_p2p * 100.0,
            aw.output.nrmse * 100.0,
            aw.perfect.nrmse * 100.0
        );
    }
    Ok(())
}
