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
//! a perfect band-limited estimate's figure. A set-up with a refused axis
//! beside compensated ones is also run as `design` writes its image: the
//! refused axis passed through raw ([`dynocomp::design::pass_through`]),
//! compensated through the image and scored.
//!
//! With `--exact-frf` every impact test is noise-free (the FRF is the
//! chain's G), which separates the design's misses from the impact test's.
//!
//! With `--no-refine` the fits stop at vector fitting's model (no
//! maximum-likelihood refinement, [`dynocomp::fit::refine`]), for the
//! before/after figures in one run.
//!
//! With `--no-seed` the fits add no pair where their residual exceeds the
//! noise ([`dynocomp::fit::seed`]); with `--above-band=inverse` the design
//! is the exact inverse above the band (`design --above-band inverse`); with
//! `--no-drop` the fits keep the pairs the lines do not support
//! ([`dynocomp::fit::vf::VfOptions::drop_unsupported`]).
//! `--lag=L` designs every image at latency L instead of choosing it (and
//! so without the fit up to Nyquist the choice can add); `--force-spectrum`
//! and `--force-level` choose q for a representative record's force
//! (`design --force-prior spectrum|level`).
//! `--from=K` runs seeds K..K+N (seeds 100-199 were first run to check the
//! seeding, before any result on them was seen).
//!
//! Each row ends with the image's latency, the axis's predicted in-band
//! error and its filter's shape (pairs + real poles + FIR taps); with
//! `--offline`, also `compensate --offline`'s NRMSE and the design's
//! prediction of it. Where the design predicted longer look-aheads than the
//! box's (`design::look_ahead`: a force record's spectrum, the box far
//! behind `--offline`), or on every axis with `--look-ahead=12,16`, the row
//! ends with each one's f64 fixed-lag smoother's NRMSE and its prediction.
//!
//! usage: cargo run --release -p dynocomp --example sweep -- [N] [--from=K] [--lag=L] [--exact-frf] [--no-refine] [--no-seed] [--no-drop] [--above-band=inverse] [--force-spectrum|--force-level] [--offline] [--look-ahead=12,16]   (default 100)
use anyhow::Result;
use dynocomp::design::image::build_image;
use dynocomp::eval::rates::{design_options, run_case, scoring_band_hz, CaseResult, RateCase, RunOptions};
use dynocomp::eval::sweep::draw;
use dynocomp::frf::axis_name;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let exact_frf = args.iter().any(|a| a == "--exact-frf");
    let refine_fit = !args.iter().any(|a| a == "--no-refine");
    let n: u64 = args.iter().find(|a| !a.starts_with("--")).map(|a| a.parse()).transpose()?.unwrap_or(100);
    let above_band = if args.iter().any(|a| a == "--above-band=inverse") {
        dynocomp::design::above_band::AboveBand::Inverse
    } else {
        dynocomp::design::above_band::AboveBand::Quiet
    };
    let seed_fit = !args.iter().any(|a| a == "--no-seed");
    let drop_unsupported = !args.iter().any(|a| a == "--no-drop");
    let from: u64 = args.iter().find_map(|a| a.strip_prefix("--from=")).map(|v| v.parse()).transpose()?.unwrap_or(0);
    let lag: Option<usize> = args.iter().find_map(|a| a.strip_prefix("--lag=")).map(|v| v.parse()).transpose()?;
    let force_level_only = args.iter().any(|a| a == "--force-level");
    let force_spectrum = force_level_only || args.iter().any(|a| a == "--force-spectrum");
    let run = RunOptions {
        exact_frf,
        refine_fit,
        seed_fit,
        drop_unsupported,
        above_band,
        lag,
        force_spectrum,
        force_level_only,
        score_offline: args.iter().any(|a| a == "--offline"),
        look_ahead_every_axis: match args.iter().find_map(|a| a.strip_prefix("--look-ahead=")) {
            Some(v) => v.split(',').map(str::parse).collect::<Result<_, _>>()?,
            None => Vec::new(),
        },
        ..RunOptions::default()
    };
    let (mut with_image, mut axes, mut within_13, mut within_2, mut written) = (0, 0, 0, 0, 0);
    // Axes warned of a non-minimum-phase zero (design::phase_limit), and
    // axes whose box output is worse than raw: [warned][worse].
    let mut phase = [[0usize; 2]; 2];
    // Check of the warning against the simulator's true model (not the
    // fit), its zeros by the same `phase_limit::zeros`: [warned][true zero
    // in band].
    let mut truth_check = [[0usize; 2]; 2];
    let mut rows: Vec<(f64, String)> = Vec::new();
    for seed in from..from + n {
        let (case, fs, kind) = draw(seed);
        let res = match run_case(&case, fs, &run) {
            Ok(r) => r,
            Err(e) => {
                println!("seed {seed} ({kind}, {fs} Hz, {} Hz lines): simulation failed: {e:#}", case.frf_df_hz);
                continue;
            }
        };
        if res.axes.iter().all(|a| a.comp_nrmse.is_ok()) {
            with_image += 1;
            written += 1;
        } else if res.axes.iter().any(|a| a.comp_nrmse.is_ok()) {
            for (axis, raw, through) in passed_through(&case, fs, &res, &run)? {
                println!(
                    "seed {seed} {} ({kind}, {fs} Hz): passed through raw in the image `design` writes: {:.3} % (raw {:.3} %)",
                    axis_name(axis),
                    100.0 * through,
                    100.0 * raw
                );
            }
            written += 1;
        }
        let dyno = case.dynamometer(&case.sim_params(fs))?;
        for a in &res.axes {
            axes += 1;
            let true_axis = dyno.axis(a.axis);
            let modes: Vec<(f64, f64, f64)> = true_axis.modes.iter().map(|m| (m.fn_hz, m.zeta, m.residue)).collect();
            let band = dynocomp::eval::rates::scoring_band_hz(fs);
            let true_nmp = dynocomp::design::phase_limit::zeros(&dynocomp::fit::PoleResidueModel::from_modes(&modes))
                .iter()
                .any(|z| z.re > 0.0 && z.im > 0.0 && z.im / std::f64::consts::TAU <= band);
            truth_check[usize::from(!a.phase_limits.is_empty())][usize::from(true_nmp)] += 1;
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
            let worse = a.comp_nrmse.as_ref().is_ok_and(|e| *e > a.raw_nrmse);
            phase[usize::from(!a.phase_limits.is_empty())][usize::from(worse)] += 1;
            let zeros: Vec<String> = a.phase_limits.iter().map(|p| format!("{:.0} Hz", p.zero_hz.0)).collect();
            let warned =
                if zeros.is_empty() { String::new() } else { format!("; non-minimum-phase zero {}", zeros.join(", ")) };
            // Each seeded line beside the nearest true mode (Hz, residue).
            let nearest = |f: f64| modes.iter().min_by(|a, b| (a.0 - f).abs().total_cmp(&(b.0 - f).abs()));
            let seeded: Vec<String> = a
                .seeded_hz
                .iter()
                .map(|f| match nearest(*f) {
                    Some(m) => format!("{f:.0} Hz (true mode nearest {:.0} Hz, residue {:.3})", m.0, m.2),
                    None => format!("{f:.0} Hz"),
                })
                .collect();
            let seeded = if seeded.is_empty() { String::new() } else { format!("; seeded {}", seeded.join(", ")) };
            let shape = a.shape.map_or(String::new(), |s| {
                format!(
                    "; latency {}, predicted {:.3} %, {}+{}r+{} taps",
                    res.latency,
                    100.0 * a.predicted_error,
                    s.pairs,
                    s.reals,
                    s.taps
                )
            });
            let offline = match a.offline_nrmse.is_finite() {
                true => format!(
                    "; offline {:.3} % (predicted {:.3} %)",
                    100.0 * a.offline_nrmse,
                    100.0 * a.offline_predicted
                ),
                false => String::new(),
            };
            let look: Vec<String> = a
                .look_ahead
                .iter()
                .map(|(l, p, m)| format!("{l}: {:.3} % (predicted {:.3} %)", 100.0 * m, 100.0 * p))
                .collect();
            let look = match look.is_empty() {
                true => String::new(),
                false => format!("; look-ahead: box f64 {:.3} %, {}", 100.0 * a.box_f64_nrmse, look.join(", ")),
            };
            let row = format!(
                "seed {seed} {} ({kind}, {fs} Hz, {} Hz lines): {what}, {ratio:.2}x{written}; raw {:.2} %{warned}{seeded}{shape}{offline}{look}",
                axis_name(a.axis),
                case.frf_df_hz,
                100.0 * a.raw_nrmse
            );
            println!("{row}");
            rows.push((ratio, row));
        }
    }
    let pct = |k: usize, of: usize| 100.0 * k as f64 / of.max(1) as f64;
    println!("\n{n} set-ups: {with_image} with an image on all three axes ({:.0} %)", pct(with_image, n as usize));
    println!(
        "{written} with the image `design` writes, refused axes passed through raw ({:.0} %)",
        pct(written, n as usize)
    );
    println!(
        "{axes} axes: {:.0} % within 1.3x of the exact inverse's noise floor, {:.0} % within 2x or at most 0.3 %",
        pct(within_13, axes),
        pct(within_2, axes)
    );
    println!(
        "non-minimum-phase zero warned: {} axes, {} of them worse than raw on the box; not warned and worse than raw: {}",
        phase[1][0] + phase[1][1],
        phase[1][1],
        phase[0][1]
    );
    println!(
        "the true model has a non-minimum-phase zero in the scoring band: on {} of the warned axes; on {} axes not warned",
        truth_check[1][1], truth_check[0][1]
    );
    rows.sort_by(|a, b| b.0.total_cmp(&a.0));
    println!("worst axes:");
    for r in rows.iter().take(8) {
        println!("  {}", r.1);
    }
    Ok(())
}

/// The refused axes of `res` passed through raw as `design` does: (axis, raw
/// NRMSE, NRMSE of the image's output), on the case simulated again.
fn passed_through(case: &RateCase, fs: f64, res: &CaseResult, run: &RunOptions) -> Result<Vec<(usize, f64, f64)>> {
    let mut params = case.sim_params(fs);
    if run.exact_frf {
        dynocomp::eval::rates::noise_free_impact(&mut params);
    }
    let s = dynocomp::simulate::simulate_with(case.seed, &params, case.dynamometer(&params)?)?;
    let opts = dynocomp::design::axis::DesignOptions { lag: res.latency, ..design_options(fs, run) };
    let mut out = Vec::new();
    for a in res.axes.iter().filter(|a| a.comp_nrmse.is_err()) {
        let frf = s.frf.axis(a.axis).ok_or_else(|| anyhow::anyhow!("no FRF for axis {}", a.axis))?;
        let r = dynocomp::metrics::sample_variance(&s.idle[a.axis]);
        let d = dynocomp::design::pass_through::pass_through(frf, r, &opts, a.comp_nrmse.clone().unwrap_err())?;
        let image = build_image(&[d], fs as u32, res.latency, 5000.0, [0; 32])?;
        let rec =
            dynocomp::io::signal_csv::SignalRecord { t_s: None, channels: vec![(a.axis, s.measured[a.axis].clone())] };
        let y = dynocomp::offline::compensate::compensate_record(&image, &rec, false, "sweep")?;
        let c = y.channel(a.axis).ok_or_else(|| anyhow::anyhow!("axis {} missing", a.axis))?;
        let band = scoring_band_hz(fs);
        out.push((a.axis, a.raw_nrmse, dynocomp::metrics::accuracy(c, &s.truth[a.axis], fs, band).nrmse));
    }
    Ok(out)
}
