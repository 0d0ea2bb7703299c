//! Multi-rate accuracy benchmark (issue #12): every case of
//! `dynocomp::eval::rates` at fs ∈ {10.24, 25.6, 51.2, 102.4} kHz,
//! simulated with the ideal anti-aliasing chain, designed, compensated and
//! scored against the band-limited truth.
//!
//! usage: cargo run --release -p dynocomp --example rates -- [--quick] [--lag L] [--discretization fit|foh|zoh] [--exact-frf] [--force-spectrum | --force-level] [--chatter HZ] [--fitted-static-gain] [--flat-force] [--above-band-inverse]
//!
//! `--above-band-inverse`: the design of `design --above-band inverse`.
//!
//! `--flat-force`: the scored record's force is the one the default
//! prediction assumes instead of the cut: Gaussian noise, flat from 10 Hz to
//! the scoring band's top, `force_rms` (100 N) per axis, the axes
//! independent; the ADC's range raised to ±32 000 N at 20 bits (the same
//! LSB) so that the resonant response does not clip.
//!
//! `--fitted-static-gain`: the discrete model's static gain fitted like any
//! other line (the fit before), not held exact (`discretize::StaticGain`).
//!
//! `--force-spectrum`: q chosen for the force spectrum of a representative
//! record (the same steady cut, other noise), as `design --force-prior
//! spectrum` does; `--force-level`: q for a flat spectrum at that
//! record's level, as `design --force-prior level` does. `--chatter HZ`: the scored cut chatters at HZ (0.02 mm
//! from 0.2 s) while a representative record stays the steady cut (the
//! negative control of `--force-spectrum`).
//!
//! Per case and axis: raw and compensated NRMSE (RMS error / std of the
//! truth, below min(4 kHz, 0.4 fs), latency removed), the exact-inverse noise
//! floor from the true G, the design's predicted error and flat band; then per
//! fs the median and worst compensated NRMSE and the axes worse than raw.
use anyhow::{bail, Context, Result};
use dynocomp::eval::rates::{cases, quick_cases, run_case_on, summarize, RunOptions, RATES_HZ};
use dynocomp::frf::axis_name;
use dynocomp::simulate::Chatter;
use dynocomp_core::budget::BOX_LOAD_LIMIT_PERMILLE;
use std::time::Instant;

fn main() -> Result<()> {
    let mut quick = false;
    let mut chatter_hz: Option<f64> = None;
    let mut flat_force = false;
    let mut run = RunOptions::default();
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--quick" => quick = true,
            "--exact-frf" => run.exact_frf = true,
            "--no-refine" => run.refine_fit = false,
            "--flat-force" => flat_force = true,
            "--above-band-inverse" => run.above_band = dynocomp::design::above_band::AboveBand::Inverse,
            "--force-spectrum" => run.force_spectrum = true,
            "--force-level" => (run.force_spectrum, run.force_level_only) = (true, true),
            "--chatter" => chatter_hz = Some(args.next().context("--chatter needs Hz")?.parse().context("--chatter: not a number")?),
            "--fitted-static-gain" => run.static_gain = dynocomp::design::discretize::StaticGain::Fitted,
            "--lag" => run.lag = Some(args.next().context("--lag needs a value")?.parse().context("--lag: not a number of samples")?),
            "--discretization" => {
                let v = args.next().context("--discretization needs fit, foh or zoh")?;
                run.discretization = dynocomp::design::discretize::Discretization::from_name(&v)
                    .ok_or_else(|| anyhow::anyhow!("--discretization {v}: expected fit, foh or zoh"))?;
            }
            _ => bail!("rates: unknown argument {a:?} (usage: rates [--quick] [--lag L] [--discretization fit|foh|zoh] [--exact-frf] [--force-spectrum | --force-level] [--chatter HZ] [--fitted-static-gain] [--no-refine] [--flat-force] [--above-band-inverse])"),
        }
    }
    let list = if quick { quick_cases() } else { cases() };
    let t_all = Instant::now();
    println!("NRMSE = RMS error / std of the band-limited truth, band min(4 kHz, 0.4 fs), declared latency {} removed, discretization {} (static gain {:?}){}", run.lag.map_or("chosen as `design` does (4, or 6/8 where the flat band falls short)".to_string(), |l| l.to_string()), run.discretization.name(), run.static_gain, if run.exact_frf { ", exact (noise-free) impact-test FRF" } else { "" });
    if run.force_spectrum {
        match run.force_level_only {
            true => println!("q chosen for a flat force spectrum at the level of a representative record (the steady cut, seed + 1000), as design --force-prior level"),
            false => println!("q chosen for the force spectrum of a representative record (the steady cut, seed + 1000), as design --force-prior spectrum"),
        }
    }
    if flat_force {
        println!("scored force: flat noise from 10 Hz to the scoring band's top, 100 N RMS per axis (the default prediction's force); ADC ±32000 N, 20 bits");
    }
    if let Some(f) = chatter_hz {
        println!("scored cut chatters at {f} Hz (0.02 mm from 0.2 s); any representative record is the steady cut");
    }
    println!("floor = exact-inverse noise floor sqrt(R·(2/fs)·∫|1/G|² df)/std(truth) with the true G");
    println!("written = the unfiltered output against the anti-aliased truth; perfect = the truth band-limited, the same way");
    println!(
        "{:>7} {:<15} {:>5} {:>4} {:>4} {:>9} {:>9} {:>8} {:>9} {:>8} {:>7} {:>15} {:>8} {:>9} {:>9}",
        "fs",
        "case",
        "TPF",
        "df",
        "axis",
        "raw %",
        "comp %",
        "floor %",
        "comp/flr",
        "pred %",
        "+fit %",
        "flat band Hz",
        "design s",
        "written %",
        "perfect %"
    );
    let mut results = Vec::new();
    for &fs in &RATES_HZ {
        for case in &list {
            let mut params = case.sim_params(fs);
            if let Some(f) = chatter_hz {
                params.milling.chatter = Some(Chatter { freq_hz: f, amplitude_mm: 0.02, onset_s: 0.2, growth_s: 0.02 });
            }
            if flat_force {
                let rms_n = dynocomp::design::axis::DesignOptions::default().force_rms;
                params.excitation = Some(dynocomp::simulate::shaker::Excitation::flat_force(fs, rms_n, 11));
                params.measurement.adc_range_n = 32_000.0;
                params.measurement.adc_bits = 20;
            }
            match run_case_on(case, &params, &run) {
                Err(e) => println!("{fs:>7} {:<15} simulation failed: {e:#}", case.name),
                Ok(r) => {
                    for a in &r.axes {
                        let head = format!(
                            "{fs:>7} {:<15} {:>5.0} {:>4} {:>4}",
                            case.name,
                            case.tpf_hz(),
                            case.frf_df_hz,
                            axis_name(a.axis)
                        );
                        match &a.comp_nrmse {
                            Ok(c) => println!(
                                "{head} {:>9.3} {:>9.3} {:>8.3} {:>9.2} {:>8.2} {:>7.2} {:>6.0}-{:<8.0} {:>8.3} {:>9.2} {:>9.2}{}",
                                a.raw_nrmse * 100.0,
                                c * 100.0,
                                a.noise_floor * 100.0,
                                c / a.noise_floor,
                                a.predicted_error * 100.0,
                                a.predicted_with_fit * 100.0,
                                a.flat_band_hz.0,
                                a.flat_band_hz.1,
                                a.design_s,
                                a.as_written.map_or(f64::NAN, |w| w.output.nrmse * 100.0),
                                a.as_written.map_or(f64::NAN, |w| w.perfect.nrmse * 100.0),
                                if *c >= a.raw_nrmse { "  WORSE THAN RAW" } else { "" }
                            ),
                            Err(e) => println!("{head} {:>9.3} design failed: {e}", a.raw_nrmse * 100.0),
                        }
                    }
                    match r.box_load() {
                        Some((c, lo, hi)) => {
                            let shapes: Vec<String> = r
                                .axes
                                .iter()
                                .filter_map(|a| a.shape)
                                .map(|s| format!("{}+{}r+{}", s.pairs, s.reals, s.taps))
                                .collect();
                            // This benchmark builds its images without `design`, which
                            // marks an image over the box's limit offline-only: say so here.
                            let offline = if hi > BOX_LOAD_LIMIT_PERMILLE {
                                format!(
                                    "  OFFLINE-ONLY: over the box's {} % limit, the box would refuse it",
                                    BOX_LOAD_LIMIT_PERMILLE / 10
                                )
                            } else {
                                String::new()
                            };
                            println!("{fs:>7} {:<15} latency {}, box load {:.1}-{:.1} % ({}-{} cycles; pairs+real poles+taps per axis: {}){offline}", case.name, r.latency, f64::from(lo) / 10.0, f64::from(hi) / 10.0, c.low, c.high, shapes.join(", "));
                        }
                        None => println!("{fs:>7} {:<15} box load: a design failed", case.name),
                    }
                    results.push(r);
                }
            }
        }
    }
    println!();
    println!("{:>7} {:>9} {:>9}  worse than raw / failed designs", "fs", "median %", "worst %");
    for s in summarize(&results) {
        println!(
            "{:>7} {:>9.3} {:>9.3}  {} / {}",
            s.fs_hz,
            s.median * 100.0,
            s.worst * 100.0,
            if s.worse_than_raw.is_empty() { "none".to_string() } else { s.worse_than_raw.join(", ") },
            if s.failed.is_empty() { "none".to_string() } else { s.failed.join(", ") }
        );
    }
    println!();
    // Predicted against measured in-band error, with and without the fit's
    // uncertainty (AxisDesign::predicted_error_with_fit).
    let ratios = |with_fit: bool| -> Vec<f64> {
        results
            .iter()
            .flat_map(|r| &r.axes)
            .filter_map(|a| {
                let c = a.comp_nrmse.as_ref().ok()?;
                let p = if with_fit { a.predicted_with_fit } else { a.predicted_error };
                (p.is_finite() && *c > 0.0).then_some(p / c)
            })
            .collect()
    };
    for (what, r) in [("model alone", ratios(false)), ("with the fit's uncertainty", ratios(true))] {
        let within = r.iter().filter(|x| (1.0 / 1.5..=1.5).contains(*x)).count();
        let (lo, hi) = r.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), x| (lo.min(*x), hi.max(*x)));
        println!(
            "predicted / measured, {what}: {within} of {} axes within 0.67-1.5x (range {lo:.2}-{hi:.2}x)",
            r.len()
        );
    }
    println!();
    println!("predicted box load (budget::CostModel::CORTEX_M4, 170 MHz), median over the cases' designs");
    println!(
        "{:>7} {:>13} {:>13} {:>6}  offline-only (high > {} %: the box refuses them)",
        "fs",
        "median low %",
        "median high %",
        "cases",
        BOX_LOAD_LIMIT_PERMILLE / 10
    );
    for &fs in &RATES_HZ {
        let loads: Vec<(u32, u32)> =
            results.iter().filter(|r| r.fs_hz == fs).filter_map(|r| r.box_load()).map(|(_, lo, hi)| (lo, hi)).collect();
        if loads.is_empty() {
            continue;
        }
        let median = |mut v: Vec<u32>| {
            v.sort_unstable();
            let n = v.len();
            if n % 2 == 1 {
                f64::from(v[n / 2])
            } else {
                (f64::from(v[n / 2 - 1]) + f64::from(v[n / 2])) / 2.0
            }
        };
        let (lo, hi) = (median(loads.iter().map(|l| l.0).collect()), median(loads.iter().map(|l| l.1).collect()));
        let offline = loads.iter().filter(|l| l.1 > BOX_LOAD_LIMIT_PERMILLE).count();
        println!("{fs:>7} {:>13.1} {:>13.1} {:>6}  {offline}", lo / 10.0, hi / 10.0, loads.len());
    }
    println!("total run time {:.1} s", t_all.elapsed().as_secs_f64());
    Ok(())
}
