//! The harmonic force prior (issue #12, optional part) against the default,
//! on the cases of `dynocomp::eval::rates`, scored against the
//! simulator's band-limited truth, with its negative controls.
//!
//! usage: cargo run --release -p dynocomp --example prior -- [--case NAME]... [--fs HZ]... [--width HZ]
//!
//! Per case, rate and axis (NRMSE %, DESIGN.md convention):
//! - raw; box = the default image (latency 4 removed); smooth = the default
//!   offline smoother; prior = the offline smoother with the harmonic prior,
//!   tuned from a second record of the same cut with other noise (the
//!   "representative record"); floor = the exact inverse's noise floor;
//!   pred = the design's predicted error with the prior (steady cut);
//! - entry: the same two estimates (default / prior) scored on the tool-entry
//!   window only (the ramp-in's revolutions after the scored start);
//! - rpm+2%: the same cut run 2 % faster, compensated with the prior tuned
//!   at the nominal speed (default / prior), and whether `compensate
//!   --offline` accepts that record (`force_prior::check_record`);
//! - chatter: the same cut with regenerative chatter at 1710 Hz from mid
//!   record (0.02 mm), same prior (default / prior), and the check's verdict;
//! - t.off: the steady cut with a prior tuned at a spindle speed 2 % off
//!   (the design's checks skipped: `design` refuses it).
use anyhow::{bail, Context, Result};
use dynocomp::eval::rates::{cases, design_options, noise_floor, RunOptions, RATES_HZ};
use dynocomp::frf::axis_name;
use dynocomp::metrics::{accuracy, lowpass, sample_variance, scoring_band_hz};
use dynocomp::offline::force_prior::{build_axis_prior, check_record, PriorOptions};
use dynocomp::offline::smoother::Smoother;
use dynocomp::simulate::{simulate_with, Chatter};

fn main() -> Result<()> {
    let (mut names, mut rates, mut width) = (Vec::new(), Vec::new(), None);
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--case" => names.push(args.next().context("--case needs a name")?),
            "--fs" => rates.push(args.next().context("--fs needs Hz")?.parse::<f64>().context("--fs: not a number")?),
            "--width" => {
                width = Some(args.next().context("--width needs Hz")?.parse::<f64>().context("--width: not a number")?)
            }
            _ => bail!("prior: unknown argument {a:?} (usage: prior [--case NAME]... [--fs HZ]... [--width HZ])"),
        }
    }
    if rates.is_empty() {
        rates = RATES_HZ.to_vec();
    }
    let list: Vec<_> = cases().into_iter().filter(|c| names.is_empty() || names.iter().any(|n| n == c.name)).collect();
    println!("NRMSE % against the band-limited truth, band min(4 kHz, 0.4 fs); columns: see examples/prior.rs");
    println!(
        "{:>6} {:<14} {:>2} {:>7} {:>6} {:>6} {:>6} {:>6} {:>6} {:<7} | {:>6} {:>6} | {:>6} {:>6} {:<7} | {:>6} {:>6} {:<7} | {:>6} | {:>5} {:>5}",
        "fs", "case", "ax", "raw", "box", "smooth", "prior", "floor", "pred", "check", "entry", "e.pri", "rpm2%", "r.pri", "check", "chat", "c.pri", "check", "t.off", "lines", "s"
    );
    for &fs in &rates {
        for case in &list {
            let params = case.sim_params(fs);
            let dyno = case.dynamometer(&params)?;
            let s = simulate_with(case.seed, &params, dyno.clone())?;
            // The representative record: the same cut, other noise.
            let tune = simulate_with(case.seed + 1000, &params, dyno.clone())?;
            let mut fast = params.clone();
            fast.milling.spindle_rpm *= 1.02;
            let s_fast = simulate_with(case.seed, &fast, dyno.clone())?;
            let mut chat = params.clone();
            chat.milling.chatter = Some(Chatter { freq_hz: 1710.0, amplitude_mm: 0.02, onset_s: 0.2, growth_s: 0.02 });
            let s_chat = simulate_with(case.seed, &chat, dyno)?;
            let band = scoring_band_hz(fs);
            let opts = design_options(fs, &RunOptions::default());
            let n = s.truth[0].len();
            let entry_lo = n / 20;
            let entry_hi =
                ((params.milling.ramp_in_revs * 60.0 / case.spindle_rpm * fs) as usize).max(entry_lo + 64).min(n);
            for a in 0..3 {
                let raw = accuracy(&s.measured[a], &s.truth[a], fs, band);
                let std_truth = raw.rms_error_n / raw.nrmse;
                let chain = s.params.anti_alias;
                let floor = noise_floor(
                    |f| s.dyno.axis(a).frf(f) * chain.analog_frf(f),
                    s.params.measurement.expected_idle_variance(),
                    fs,
                    band,
                    std_truth,
                );
                let r = sample_variance(&s.idle[a]);
                let frf = s.frf.axis(a).context("axis")?;
                let d = match dynocomp::design::axis::design_axis(&s.frf.freq_hz, frf, r, &opts) {
                    Ok(d) => d,
                    Err(e) => {
                        println!("{fs:>6} {:<14} {:>2} design failed: {e:#}", case.name, axis_name(a));
                        continue;
                    }
                };
                let img =
                    dynocomp::design::image::build_image(std::slice::from_ref(&d), fs as u32, 4, 5000.0, [0; 32])?;
                let rec =
                    dynocomp::io::signal_csv::SignalRecord { t_s: None, channels: vec![(a, s.measured[a].clone())] };
                let boxed = dynocomp::offline::compensate::compensate_record(&img, &rec, false, "prior")?;
                let box_nrmse = accuracy(boxed.channel(a).context("channel")?, &s.truth[a], fs, band).nrmse;
                let dm = &d.discrete.as_ref().context("discrete model")?.0;
                let default = Smoother::new(dm, d.kalman.q, r)?;
                let g = |f: f64| d.model.frf(f);
                let t0 = std::time::Instant::now();
                let popts = PriorOptions {
                    spindle_rpm: case.spindle_rpm,
                    teeth: case.teeth as u32,
                    line_width_hz: width,
                    unchecked: false,
                };
                let built =
                    match build_axis_prior(&popts, dm, &g, r, d.kalman.q, d.compensated_band_hz, &tune.measured[a]) {
                        Ok(b) => b,
                        Err(e) => {
                            println!("{fs:>6} {:<14} {:>2} prior refused: {e:#}", case.name, axis_name(a));
                            continue;
                        }
                    };
                if std::env::var("PRIOR_DEBUG").is_ok() {
                    eprintln!(
                        "q_default {:.3e} q_bb {:.3e} r {r:.3e} lines {:?}",
                        d.kalman.q,
                        built.prior.q_broadband,
                        built.prior.lines.iter().map(|l| (l.freq_hz, l.power_n2)).collect::<Vec<_>>()
                    );
                }
                let with_prior = match Smoother::with_force_prior(dm, &built.prior, r) {
                    Ok(w) => w,
                    Err(e) => {
                        println!("{fs:>6} {:<14} {:>2} smoother with the prior failed: {e:#}", case.name, axis_name(a));
                        continue;
                    }
                };
                let est = with_prior.smooth(&s.measured[a]);
                let secs = t0.elapsed().as_secs_f64();
                let sm = default.smooth(&s.measured[a]);
                let score = |x: &[f64], truth: &[f64]| 100.0 * accuracy(x, truth, fs, band).nrmse;
                let entry = |x: &[f64]| -> f64 {
                    let (e, t) = (lowpass(x, fs, band), lowpass(&s.truth[a], fs, band));
                    let m = (entry_hi - entry_lo) as f64;
                    100.0
                        * (e[entry_lo..entry_hi]
                            .iter()
                            .zip(&t[entry_lo..entry_hi])
                            .map(|(a, b)| (a - b).powi(2))
                            .sum::<f64>()
                            / m)
                            .sqrt()
                        / std_truth
                };
                // A prior tuned at a spindle speed 2 % off (checks skipped).
                let off_opts = PriorOptions { spindle_rpm: case.spindle_rpm * 1.02, unchecked: true, ..popts.clone() };
                let tuned_off =
                    build_axis_prior(&off_opts, dm, &g, r, d.kalman.q, d.compensated_band_hz, &tune.measured[a])
                        .and_then(|b| Smoother::with_force_prior(dm, &b.prior, r))
                        .map(|sm| score(&sm.smooth(&s.measured[a]), &s.truth[a]))
                        .unwrap_or(f64::NAN);
                let verdict = |y: &[f64]| match check_record(&built.prior, y, &g, r) {
                    Ok(rs) => format!("ok {:.0e}", rs.off_line_share),
                    Err(_) => "REFUSE".to_string(),
                };
                println!(
                    "{fs:>6} {:<14} {:>2} {:>7.3} {:>6.3} {:>6.3} {:>6.3} {:>6.3} {:>6.3} {:<7} | {:>6.3} {:>6.3} | {:>6.3} {:>6.3} {:<7} | {:>6.3} {:>6.3} {:<7} | {:>6.3} | {:>5} {:>5.1}",
                    case.name,
                    axis_name(a),
                    100.0 * raw.nrmse,
                    100.0 * box_nrmse,
                    score(&sm, &s.truth[a]),
                    score(&est, &s.truth[a]),
                    100.0 * floor,
                    100.0 * built.prediction.with_prior,
                    verdict(&s.measured[a]),
                    entry(&sm),
                    entry(&est),
                    score(&default.smooth(&s_fast.measured[a]), &s_fast.truth[a]),
                    score(&with_prior.smooth(&s_fast.measured[a]), &s_fast.truth[a]),
                    verdict(&s_fast.measured[a]),
                    score(&default.smooth(&s_chat.measured[a]), &s_chat.truth[a]),
                    score(&with_prior.smooth(&s_chat.measured[a]), &s_chat.truth[a]),
                    verdict(&s_chat.measured[a]),
                    tuned_off,
                    built.prior.lines.len(),
                    secs,
                );
            }
        }
    }
    Ok(())
}
