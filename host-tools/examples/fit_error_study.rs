//! Study (not in CI): how much of an axis's error comes from the fitted model
//! rather than the noise. For set-ups of the random sweep
//! ([`dynocomp::eval::sweep::draw`]), the model part of the compensated
//! error, F·(G/Ĝ − 1) over the scoring band (F the band-limited truth's
//! spectrum, G the simulator's true response), relative to the truth's
//! std and split into the mean (0 Hz) and the rest, for Ĝ = the design's
//! fit, for the same fit without its maximum-likelihood refinement
//! (vector fitting's poles, [`dynocomp::fit::refine`]) and for Ĝ = the true
//! poles with residues fitted to the same impact test (what the lines allow
//! when the poles are right). Before each such line, the rest as the fit's
//! own covariance predicts it ([`dynocomp::fit::refine::frf_variance`]).
//!
//! With `--orders`, also each order of the plain fit ([`fit_order`]):
//! weighted RMS against the lines, static gain and model error; with
//! `--bend`, only how far the plain fit and the design's fit move below the
//! first coherent line (the design's static check, [`static_deviation`]).
//!
//! usage: cargo run --release -p dynocomp --example fit_error_study -- [--orders|--bend] SEED{x|y|z} ...
use anyhow::{Context, Result};
use dynocomp::design::axis::static_deviation;
use dynocomp::eval::rates::{design_options, scoring_band_hz, RunOptions};
use dynocomp::eval::sweep::draw;
use dynocomp::fit::vf::{coherence_weights, fit_order, refit_kept, vector_fit, weighted_rms, VfOptions};
use dynocomp::fit::PoleResidueModel;
use num_complex::Complex64;
use rustfft::FftPlanner;

/// (mean part, rest) of the model error F·(ratio − 1) relative to the std
/// of `truth`, over 0 < f ≤ `band` Hz.
fn model_error(truth: &[f64], fs: f64, band: f64, ratio: &dyn Fn(f64) -> Complex64) -> (f64, f64) {
    let n = truth.len();
    let mean = truth.iter().sum::<f64>() / n as f64;
    let mut buf: Vec<Complex64> = truth.iter().map(|v| Complex64::new(v - mean, 0.0)).collect();
    FftPlanner::new().plan_fft_forward(n).process(&mut buf);
    let (mut var, mut err) = (0.0, 0.0);
    for (k, c) in buf.iter().enumerate().take(n / 2 + 1).skip(1) {
        let f = k as f64 * fs / n as f64;
        let p = 2.0 * c.norm_sqr() / (n as f64 * n as f64);
        var += p;
        if f <= band {
            err += p * (ratio(f) - 1.0).norm_sqr();
        }
    }
    let std = var.sqrt();
    (mean.abs() * (ratio(0.0) - 1.0).norm() / std, err.sqrt() / std)
}

/// The model error F·ΔĜ/Ĝ that the fit's own uncertainty predicts
/// ([`dynocomp::fit::refine::frf_variance`]), relative to the std of
/// `truth`, over 0 < f ≤ `band` Hz (the rest, as [`model_error`]).
fn predicted_model_error(
    truth: &[f64],
    fs: f64,
    band: f64,
    var_rel: &dyn Fn(&[f64]) -> Option<Vec<f64>>,
) -> Option<f64> {
    let n = truth.len();
    let mean = truth.iter().sum::<f64>() / n as f64;
    let mut buf: Vec<Complex64> = truth.iter().map(|v| Complex64::new(v - mean, 0.0)).collect();
    FftPlanner::new().plan_fft_forward(n).process(&mut buf);
    let (mut var, mut freqs, mut powers) = (0.0, Vec::new(), Vec::new());
    for (k, c) in buf.iter().enumerate().take(n / 2 + 1).skip(1) {
        let f = k as f64 * fs / n as f64;
        let p = 2.0 * c.norm_sqr() / (n as f64 * n as f64);
        var += p;
        if f <= band {
            freqs.push(f);
            powers.push(p);
        }
    }
    let v = var_rel(&freqs)?;
    Some(powers.iter().zip(&v).map(|(p, v)| p * v).sum::<f64>().sqrt() / var.sqrt())
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let orders = args.iter().any(|a| a == "--orders");
    let bend = args.iter().any(|a| a == "--bend");
    for arg in args.iter().filter(|a| !a.starts_with("--")) {
        let (seed, ax) = arg.split_at(arg.len() - 1);
        let seed: u64 = seed.parse().with_context(|| format!("{arg}: SEED{{x|y|z}}"))?;
        let a = "xyz".find(ax).with_context(|| format!("{arg}: axis x, y or z"))?;
        let (case, fs, kind) = draw(seed);
        let params = case.sim_params(fs);
        let s = dynocomp::simulate::simulate_with(case.seed, &params, case.dynamometer(&params)?)?;
        let band = scoring_band_hz(fs);
        let frf = s.frf.axis(a).context("no FRF")?;
        let (freq, h) = (&s.frf.freq_hz, &frf.frf);
        let truth_g = |f: f64| s.dyno.axis(a).frf(f);
        let opts = design_options(fs, &RunOptions::default());
        let fitted = dynocomp::design::axis::fitted_model(freq, frf, &opts)?;
        let w = coherence_weights(h, frf.coherence.as_deref());
        if bend {
            let coh = frf.coherence.as_deref().unwrap_or(&[]);
            let first = freq.iter().zip(coh).find(|(_, c)| **c >= 0.9).map_or(0.0, |(f, _)| *f);
            let plain = vector_fit(freq, h, &w, &VfOptions::default())?.model;
            println!(
                "seed {seed} {ax}: first coherent line {first} Hz; plain fit order {} moves {:.4} below it, the design's order {} {:.4}",
                plain.order(),
                static_deviation(|f| plain.frf(f), freq, first).0,
                fitted.order(),
                static_deviation(|f| fitted.frf(f), freq, first).0
            );
            continue;
        }
        let modes: Vec<(f64, f64, f64)> = s.dyno.axis(a).modes.iter().map(|m| (m.fn_hz, m.zeta, m.residue)).collect();
        let true_model = PoleResidueModel::from_modes(&modes);
        let oracle = refit_kept(freq, h, &w, &true_model, &vec![true; true_model.terms.len()])?;
        let mut plain_opts = opts.clone();
        plain_opts.vf.refine = false;
        let unrefined = dynocomp::design::axis::fitted_model(freq, frf, &plain_opts)?;
        let off = |m: &PoleResidueModel| (truth_g(0.0) / m.frf(0.0) - 1.0).norm();
        let (dc_fit, ac_fit) = model_error(&s.truth[a], fs, band, &|f| truth_g(f) / fitted.frf(f));
        let (dc_un, ac_un) = model_error(&s.truth[a], fs, band, &|f| truth_g(f) / unrefined.frf(f));
        let (dc_or, ac_or) = model_error(&s.truth[a], fs, band, &|f| truth_g(f) / oracle.frf(f));
        let predicted = predicted_model_error(&s.truth[a], fs, band, &|fr| {
            let v = dynocomp::fit::refine::frf_variance(freq, h, &w, &fitted, fr)?;
            Some(fr.iter().zip(v).map(|(f, v)| v / fitted.frf(*f).norm_sqr()).collect())
        });
        println!(
            "fit uncertainty, seed {seed} {ax}: model error (rest) {:.4} %, predicted by the fit's covariance {:.4} %, actual / predicted {:.2}",
            100.0 * ac_fit,
            100.0 * predicted.unwrap_or(f64::NAN),
            ac_fit / predicted.unwrap_or(f64::NAN)
        );
        println!(
            "seed {seed} {ax} ({kind}, {fs} Hz, {} Hz lines, {} true modes): fit order {} mean {:.3} % rest {:.3} % (G(0) off {:.2e}); unrefined mean {:.3} % rest {:.3} % (G(0) off {:.2e}); true poles mean {:.3} % rest {:.3} % (G(0) off {:.2e})",
            case.frf_df_hz,
            modes.len(),
            fitted.order(),
            100.0 * dc_fit,
            100.0 * ac_fit,
            off(&fitted),
            100.0 * dc_un,
            100.0 * ac_un,
            off(&unrefined),
            100.0 * dc_or,
            100.0 * ac_or,
            off(&oracle),
        );
        if orders {
            println!("  true modes (Hz, ζ, share): {modes:?}");
            println!("  fitted modes (Hz, ζ): {:?}", fitted.modes());
            println!("  fitted terms: {:?} d {:.4e}", fitted.terms, fitted.d);
            println!("  oracle terms: {:?} d {:.4e}", oracle.terms, oracle.d);
            for order in (2..=20).step_by(2) {
                match fit_order(freq, h, &w, order, &VfOptions::default()) {
                    Err(e) => println!("  order {order}: {e:#}"),
                    Ok(m) => {
                        let (dc, ac) = model_error(&s.truth[a], fs, band, &|f| truth_g(f) / m.frf(f));
                        println!(
                            "  order {order}: weighted rms {:.5}, G(0) off {:.2e}, model error mean {:.3} % rest {:.3} %",
                            weighted_rms(&m, freq, h, &w),
                            off(&m),
                            100.0 * dc,
                            100.0 * ac
                        );
                    }
                }
            }
            println!("  true poles, residues fitted: weighted rms {:.5}", weighted_rms(&oracle, freq, h, &w));
        }
    }
    Ok(())
}
