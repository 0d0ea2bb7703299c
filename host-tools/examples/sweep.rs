//! Random-set-up sweep (not run in CI): set-ups drawn from seeds 0..N fixed
//! here (never picked by looking at results), each simulated at one of the
//! four DAQ rates with an FRF resolution of 0.5-4 Hz and one of four kinds
//! (the default ranges, clustered machine modes, a close sensor-mode pair,
//! sensor modes above the compensated band); designed, compensated through
//! a box image and scored against the band-limited truth
//! ([`dynocomp::eval::rates::run_case`]). Prints the distribution: the
//! fraction of set-ups with an image, of axes within 1.3x and 2x of the
//! exact inverse's noise floor (or at most 0.3 % NRMSE), and the worst axes;
//! per axis also the output as written against the anti-aliased truth, beside
//! a perfect band-limited estimate's figure.
//!
//! usage: cargo run --release -p dynocomp --example sweep -- [N]   (default 100)
use anyhow::Result;
use dynocomp::eval::rates::{run_case, RunOptions};
use dynocomp::eval::sweep::draw;
use dynocomp::frf::axis_name;

fn main() -> Result<()> {
    let n: u64 = std::env::args().nth(1).map(|a| a.parse()).transpose()?.unwrap_or(100);
    let (mut with_image, mut axes, mut within_13, mut within_2) = (0, 0, 0, 0);
    let mut rows: Vec<(f64, String)> = Vec::new();
    for seed in 0..n {
        let (case, fs, kind) = draw(seed);
        let res = match run_case(&case, fs, &RunOptions::default()) {
            Ok(r) => r,
            Err(e) => {
                println!("seed {seed} ({kind}, {fs} Hz, {} Hz lines): simulation failed: {e:#}", case.frf_df_hz);
                continue;
            }
        };
        if res.axes.iter().all(|a| a.comp_nrmse.is_ok()) {
            with_image += 1;
        }
        for a in &res.axes {
            axes += 1;
            let (ratio, what) = match &a.comp_nrmse {
                Ok(e) => (e / a.noise_floor, format!("{:.3} % (floor {:.3} %)", 100.0 * e, 100.0 * a.noise_floor)),
                Err(why) => (f64::INFINITY, format!("no design: {why}")),
            };
            let small = a.comp_nrmse.as_ref().is_ok_and(|e| *e <= 0.003);
            within_13 += usize::from(ratio <= 1.3);
            within_2 += usize::from(ratio <= 2.0 || small);
            let written = a.as_written.map_or(String::new(), |w| {
                format!("; as written {:.2} % (perfect {:.2} %)", 100.0 * w.output.nrmse, 100.0 * w.perfect.nrmse)
            });
            let row = format!(
                "seed {seed} {} ({kind}, {fs} Hz, {} Hz lines): {what}, {ratio:.2}x{written}",
                axis_name(a.axis),
                case.frf_df_hz
            );
            println!("{row}");
            rows.push((ratio, row));
        }
    }
    let pct = |k: usize, of: usize| 100.0 * k as f64 / of.max(1) as f64;
    println!("\n{n} set-ups: {with_image} with an image on all three axes ({:.0} %)", pct(with_image, n as usize));
    println!(
        "{axes} axes: {:.0} % within 1.3x of the exact inverse's noise floor, {:.0} % within 2x or at most 0.3 %",
        pct(within_13, axes),
        pct(within_2, axes)
    );
    rows.sort_by(|a, b| b.0.total_cmp(&a.0));
    println!("worst axes:");
    for r in rows.iter().take(8) {
        println!("  {}", r.1);
    }
    Ok(())
}
