//! End to end at the sample rates DAQs use (issue #12): simulate with a real
//! acquisition chain (brick wall at 0.45 fs, band-limited truth), design,
//! compensate through a coefficient image and score against the truth (NRMSE
//! = RMS error / std of the band-limited truth, band min(4 kHz, 0.4 fs),
//! latency removed). Cases: `simulate::rates::quick_cases()` (the default
//! dynamometer, and sensor modes at 4.5-6 kHz with an FRF to 8 kHz, above
//! Nyquist at 10.24 kHz). The full case list runs in the benchmark
//! (`cargo run --release -p dynocomp --example rates`, BENCHMARKS.md).

use dynocomp::design::discretize::{Discretization, StaticGain};
use dynocomp::design::latency::DEFAULT_LATENCY;
use dynocomp::eval::rates::{quick_cases, run_case, CaseResult, RunOptions, RATES_HZ};

/// Issue #12 targets, met at 25.6, 51.2 and 102.4 kHz.
const MEDIAN: f64 = 0.005;
const WORST: f64 = 0.02;
/// At 10.24 kHz the targets are NOT met (BENCHMARKS.md, "The declared
/// latency, chosen"): with the main sensor mode at and above Nyquist the
/// design chooses latency 8 (and z's discrete model fitted up to Nyquist)
/// and the compensated error is 1.1-2.0 % on that case's three axes
/// (3.2-4.6 % at the old fixed latency 4), half of this
/// subset. These are regression guards just above the measured level, not
/// targets.
const MEDIAN_10K: f64 = 0.015;
const WORST_10K: f64 = 0.03;
/// The high-mode z axis at 10.24 kHz with its discrete model fitted up to
/// Nyquist (measured 2.02 %; 2.64 % with the 0.45 fs fit at the same latency).
const Z_NYQUIST_FIT: f64 = 0.023;

fn run(fs: f64, opts: &RunOptions) -> Vec<CaseResult> {
    quick_cases()
        .iter()
        .map(|c| run_case(c, fs, opts).unwrap_or_else(|e| panic!("{} at {fs} Hz: {e:#}", c.name)))
        .collect()
}

/// (compensated, raw) NRMSE of every axis; panics on a failed design.
fn scores(results: &[CaseResult]) -> Vec<(f64, f64)> {
    let mut v = Vec::new();
    for r in results {
        for a in &r.axes {
            let c = a
                .comp_nrmse
                .as_ref()
                .unwrap_or_else(|e| panic!("{} at {} Hz axis {}: design failed: {e}", r.case, r.fs_hz, a.axis));
            eprintln!(
                "{:>6} Hz {:<11} axis {}: comp {:.3} %, raw {:.2} %, floor {:.3} %",
                r.fs_hz,
                r.case,
                a.axis,
                c * 100.0,
                a.raw_nrmse * 100.0,
                a.noise_floor * 100.0
            );
            v.push((*c, a.raw_nrmse));
        }
    }
    v
}

fn median_worst(s: &[(f64, f64)]) -> (f64, f64) {
    let mut c: Vec<f64> = s.iter().map(|x| x.0).collect();
    c.sort_by(f64::total_cmp);
    (c[c.len() / 2], c[c.len() - 1])
}

fn limits(fs: f64) -> (f64, f64) {
    if fs < 20_000.0 {
        (MEDIAN_10K, WORST_10K)
    } else {
        (MEDIAN, WORST)
    }
}

#[test]
fn accurate_at_every_daq_rate_and_never_worse_than_raw() {
    for fs in RATES_HZ {
        let s = scores(&run(fs, &RunOptions::default()));
        for (c, r) in &s {
            assert!(c < r, "{fs} Hz: an axis is worse than uncompensated ({:.3} % vs {:.3} %)", c * 100.0, r * 100.0);
        }
        let (median, worst) = median_worst(&s);
        let (lm, lw) = limits(fs);
        eprintln!("{fs} Hz: median {:.3} %, worst {:.3} %", median * 100.0, worst * 100.0);
        assert!(median <= lm, "{fs} Hz: median {:.3} % > {:.2} %", median * 100.0, lm * 100.0);
        assert!(worst <= lw, "{fs} Hz: worst {:.3} % > {:.2} %", worst * 100.0, lw * 100.0);
    }
}

#[test]
fn the_first_order_hold_fails_the_same_limits() {
    // Negative control: the same cases designed on the first-order-hold
    // model (the design before issue #12) miss the limits above at the two
    // lowest rates.
    let foh = RunOptions { discretization: Discretization::Foh, ..Default::default() };
    for fs in [RATES_HZ[0], RATES_HZ[1]] {
        let results = run(fs, &foh);
        // A design refused outright (e.g. predicted above design's 50 %
        // limit) misses the limits too.
        if let Some(e) = results.iter().flat_map(|r| &r.axes).find_map(|a| a.comp_nrmse.as_ref().err()) {
            eprintln!("FOH {fs} Hz: a design is refused: {e}");
            continue;
        }
        let (median, worst) = median_worst(&scores(&results));
        let (lm, lw) = limits(fs);
        eprintln!("FOH {fs} Hz: median {:.3} %, worst {:.3} %", median * 100.0, worst * 100.0);
        assert!(
            median > lm || worst > lw,
            "{fs} Hz: FOH met the limits (median {:.3} %, worst {:.3} %)",
            median * 100.0,
            worst * 100.0
        );
    }
}

#[test]
fn distortion_stays_near_the_noise_floor_when_the_frf_is_exact() {
    // With a noise-free impact test only the discrete model and the filter
    // can push the error above the exact inverse filter's noise floor
    // sqrt(R·(2/fs)·∫|1/G|² df)/std(truth). Target: within 1.3x, checked at
    // the rates where it holds on this case (BENCHMARKS.md lists every rate
    // and case).
    let exact = RunOptions { exact_frf: true, ..Default::default() };
    let case = &quick_cases()[0];
    let ratios = |r: &CaseResult, run: &RunOptions| -> Vec<f64> {
        r.axes
            .iter()
            .map(|a| {
                let c = *a.comp_nrmse.as_ref().unwrap();
                eprintln!(
                    "exact FRF {} Hz axis {} ({:?}, static gain {:?}): {:.3} % vs floor {:.3} % ({:.2}x)",
                    r.fs_hz,
                    a.axis,
                    run.discretization,
                    run.static_gain,
                    c * 100.0,
                    a.noise_floor * 100.0,
                    c / a.noise_floor
                );
                c / a.noise_floor
            })
            .collect()
    };
    for fs in [RATES_HZ[1], RATES_HZ[2], RATES_HZ[3]] {
        let r = run_case(case, fs, &exact).unwrap();
        for (axis, ratio) in ratios(&r, &exact).into_iter().enumerate() {
            assert!(ratio <= 1.3, "{fs} Hz axis {axis}: {ratio:.2}x the noise floor (limit 1.3x)");
        }
    }
    // Negative controls on the same exact FRF: the first-order hold at
    // 25.6 kHz, and at 102.4 kHz the discrete model's static gain fitted
    // like any other line instead of held exact (the y axis, whose floor is 0.07 %, was
    // 1.40x: its model's static gain was 0.06 % off and the force's mean is
    // 1.4x its std). The second control designs with the in-band criterion
    // alone (`--above-band inverse`): the default quiet design's lower q
    // hides that static-gain error (1.05x), so only there does the check
    // show it can fail on a wrong discrete model.
    let foh = RunOptions { discretization: Discretization::Foh, ..exact.clone() };
    let worst = ratios(&run_case(case, RATES_HZ[1], &foh).unwrap(), &foh).into_iter().fold(0.0, f64::max);
    assert!(worst > 1.3, "FOH stayed within 1.3x of the floor ({worst:.2}x)");
    let fitted = RunOptions {
        static_gain: StaticGain::Fitted,
        above_band: dynocomp::design::above_band::AboveBand::Inverse,
        ..exact
    };
    let worst = ratios(&run_case(case, RATES_HZ[3], &fitted).unwrap(), &fitted).into_iter().fold(0.0, f64::max);
    assert!(worst > 1.3, "the fitted static gain stayed within 1.3x of the floor at 102.4 kHz ({worst:.2}x)");
}

#[test]
fn a_longer_latency_is_chosen_only_where_the_flat_band_falls_short() {
    // The high-mode case at 10.24 kHz (sensor modes 4.5-6 kHz, Nyquist
    // 5.12 kHz): latency 4 leaves the flat band at 2-3.3 kHz of 4.1 kHz.
    // Without --latency the design looks further ahead and the error falls
    // under the guard; the same case at the fixed latency 4 stays above it
    // (negative control).
    let case = quick_cases().into_iter().find(|c| c.name == "high-modes").unwrap();
    let fs = RATES_HZ[0];
    let worst = |r: &CaseResult| r.axes.iter().map(|a| *a.comp_nrmse.as_ref().unwrap()).fold(0.0, f64::max);
    let chosen = run_case(&case, fs, &RunOptions::default()).unwrap();
    let fixed = run_case(&case, fs, &RunOptions { lag: Some(DEFAULT_LATENCY), ..Default::default() }).unwrap();
    eprintln!(
        "high-modes at {fs} Hz: latency {} worst {:.3} %, latency 4 worst {:.3} %",
        chosen.latency,
        100.0 * worst(&chosen),
        100.0 * worst(&fixed)
    );
    assert!(chosen.latency > DEFAULT_LATENCY, "latency {} chosen", chosen.latency);
    assert!(
        worst(&chosen) <= WORST_10K,
        "chosen latency: worst {:.3} % > {:.1} %",
        100.0 * worst(&chosen),
        100.0 * WORST_10K
    );
    assert!(
        worst(&fixed) > WORST_10K,
        "latency 4 met the guard ({:.3} %): the choice is not what made the difference",
        100.0 * worst(&fixed)
    );
    // The z axis (main mode 5.4-6 kHz, above Nyquist) gains from its discrete
    // model fitted up to Nyquist (measured 2.02 %); the same latency without
    // that choice leaves it at 2.64 % (negative control).
    let z = |r: &CaseResult| *r.axes[2].comp_nrmse.as_ref().unwrap();
    let at8 = run_case(&case, fs, &RunOptions { lag: Some(chosen.latency), ..Default::default() }).unwrap();
    eprintln!(
        "high-modes z: {:.3} % chosen, {:.3} % at latency {} with the 0.45 fs fit only",
        100.0 * z(&chosen),
        100.0 * z(&at8),
        chosen.latency
    );
    assert!(z(&chosen) <= Z_NYQUIST_FIT, "z {:.3} % > {:.1} %", 100.0 * z(&chosen), 100.0 * Z_NYQUIST_FIT);
    assert!(
        z(&at8) > Z_NYQUIST_FIT,
        "z met {:.1} % without the fit to Nyquist ({:.3} %)",
        100.0 * Z_NYQUIST_FIT,
        100.0 * z(&at8)
    );
    // Where latency 4 is flat to the band's top, it stays: the default
    // dynamometer at 51.2 kHz with the exact inverse above the band (the
    // quiet default looks further for the noise it writes above the band:
    // `tests/sweep_cases.rs`, seed 52).
    let inverse = RunOptions { above_band: dynocomp::design::above_band::AboveBand::Inverse, ..Default::default() };
    let default = run_case(&quick_cases()[0], RATES_HZ[2], &inverse).unwrap();
    assert_eq!(default.latency, DEFAULT_LATENCY);
}

#[test]
fn a_longer_latency_is_chosen_where_a_design_predicts_missing_the_target() {
    // The close-pair dynamometer at 10.24 kHz: latency 4 is flat to the
    // band's top on every axis but predicts 0.8-1.2 % of distortion
    // (> 0.5 %, `latency::PREDICTED_SHORT`); its stiff y
    // axis, with an exact FRF, was 2.2x its noise floor there. Without
    // --latency the design now looks further ahead and y comes within 1.3x
    // of its floor; the same case at the fixed latency 4 stays above
    // (negative control). The default case at 51.2 kHz, whose predicted
    // distortion is under 0.5 %, keeps 4 (the previous test).
    use dynocomp::eval::rates::cases;
    let case = cases().into_iter().find(|c| c.name == "close-pair").unwrap();
    let exact = RunOptions { exact_frf: true, ..Default::default() };
    let fs = RATES_HZ[0];
    let y = |r: &CaseResult| r.axes[1].comp_nrmse.as_ref().unwrap() / r.axes[1].noise_floor;
    let chosen = run_case(&case, fs, &exact).unwrap();
    let fixed = run_case(&case, fs, &RunOptions { lag: Some(DEFAULT_LATENCY), ..exact }).unwrap();
    eprintln!(
        "close-pair y at {fs} Hz, exact FRF: latency {} {:.2}x the floor, latency 4 {:.2}x",
        chosen.latency,
        y(&chosen),
        y(&fixed)
    );
    assert!(chosen.latency > DEFAULT_LATENCY, "latency {} chosen", chosen.latency);
    assert!(y(&chosen) <= 1.3, "chosen latency {}: y {:.2}x its floor", chosen.latency, y(&chosen));
    assert!(y(&fixed) > 1.3, "latency 4 already had y within 1.3x ({:.2}x)", y(&fixed));
    // No axis pays for it.
    for (a, (c, f)) in chosen.axes.iter().zip(&fixed.axes).enumerate() {
        let (c, f) = (c.comp_nrmse.as_ref().unwrap(), f.comp_nrmse.as_ref().unwrap());
        assert!(c <= &(1.03 * f), "axis {a}: {:.3} % at the chosen latency, {:.3} % at 4", 100.0 * c, 100.0 * f);
    }
}

/// The output as written (DESIGN.md, "Accuracy"): the unfiltered output
/// against the truth through the anti-aliasing filter alone, over the best
/// an estimate with this band-limited error can reach there,
/// √(band-limited² + perfect²) (a perfect band-limited estimate's figure
/// combined with the in-band error): its median over the axes, and the
/// median band-limited NRMSE.
fn written_excess(results: &[CaseResult]) -> (f64, f64) {
    let (mut excess, mut band) = (Vec::new(), Vec::new());
    for r in results {
        for a in &r.axes {
            let c = *a.comp_nrmse.as_ref().unwrap_or_else(|e| panic!("{} axis {}: {e}", r.case, a.axis));
            let w = a.as_written.unwrap_or_else(|| panic!("{} axis {}: no as-written figure", r.case, a.axis));
            let best = c.hypot(w.perfect.nrmse);
            eprintln!(
                "{:>6} Hz {:<11} axis {}: band-limited {:.3} %, as written {:.2} % (perfect {:.2} %, best {:.2} %)",
                r.fs_hz,
                r.case,
                a.axis,
                100.0 * c,
                100.0 * w.output.nrmse,
                100.0 * w.perfect.nrmse,
                100.0 * best
            );
            excess.push(w.output.nrmse / best);
            band.push(c);
        }
    }
    let median = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    (median(excess), median(band))
}

/// Issue #34 item 4: above its band the default ("quiet") design writes
/// little more than its in-band error. At 51.2 kHz on the quick cases its
/// output as written is within 1.5x (median) of √(band-limited² + perfect²),
/// at an unchanged median band-limited error (at most 5 % above). Negative
/// control: the exact inverse continued above the band (`--above-band
/// inverse`, the design before) is more than 3x from it.
#[test]
fn the_output_as_written_carries_little_noise_above_the_band() {
    let fs = 51_200.0;
    let quiet = written_excess(&run(fs, &RunOptions::default()));
    let inverse_opts =
        RunOptions { above_band: dynocomp::design::above_band::AboveBand::Inverse, ..Default::default() };
    let inverse = written_excess(&run(fs, &inverse_opts));
    eprintln!("as written over its best, median: quiet {:.2}x, inverse {:.2}x", quiet.0, inverse.0);
    eprintln!("band-limited median: quiet {:.3} %, inverse {:.3} %", 100.0 * quiet.1, 100.0 * inverse.1);
    assert!(quiet.0 < 1.5, "quiet: as written {:.2}x its best (median)", quiet.0);
    assert!(inverse.0 > 3.0, "control: the inverse above the band is only {:.2}x its best", inverse.0);
    assert!(
        quiet.1 <= 1.05 * inverse.1,
        "band-limited median regressed: {:.3} % vs {:.3} %",
        100.0 * quiet.1,
        100.0 * inverse.1
    );
}
