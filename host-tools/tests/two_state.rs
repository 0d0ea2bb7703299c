//! Issue #15, items 2-3 (library level): pairing and interpolating two
//! states of a set-up, and the time-varying smoother that follows a drift,
//! against the simulator's band-limited truth.
//!
//! Target (issue): for cuts whose sensor modes drift by up to ±5 % across the
//! record, the smoother with the two end-state FRFs is within 1.5x of the
//! same smoother with the exact model at every instant; today's single-FRF
//! smoother is shown beside it (and is the negative control).

use crate::sim_common;

use dynocomp::design::axis::{design_axis, DesignOptions};
use dynocomp::design::discretize::fit_with_structure;
use dynocomp::design::discretize::{discretize, Discretization};
use dynocomp::design::kalman::{augmented_plant, solve_filter_dare};
use dynocomp::design::two_state::model::{pair, TwoState};
use dynocomp::design::two_state::range::{
    design_or_hold, pair_second_state, two_state_options, RangeCandidate, RangeDesign, RANGE_STATES,
};
use dynocomp::fit::PoleResidueModel;
use dynocomp::metrics::{accuracy, sample_variance};
use dynocomp::offline::drift::{
    drift_log_likelihood, smooth_drifting, smooth_drifting_in_segments, state_at, DriftSmoothing, S_LEVELS,
};
use dynocomp::offline::smoother::Smoother;
use dynocomp::simulate::drift::{measure_drifting, shift_sensor_modes, simulate_drifting, Drift};
use dynocomp::simulate::MultiAxisDynamometer;
use nalgebra::DVector;

use dynocomp::design::two_state::joint::JOINT_TOLERANCE;
use dynocomp::simulate::impact::impact_test_axis;
use sim_common::FS;
/// Issue target: two-state within 1.5x of the exact model. Met on all 9
/// axes below (worst 1.32x, seed 4 y; figures in BENCHMARKS.md): seed 4 x
/// was 1.66x before the machine modes were shared, seed 4 y 1.64x before
/// its above-band sensor mode was fitted to both FRFs at once.
const TARGET: f64 = 1.5;

#[test]
fn pairing_fails_clearly_and_interpolation_follows_the_stated_rule() {
    let before = PoleResidueModel::from_modes(&[(400.0, 0.03, 0.1), (2300.0, 0.02, 0.8), (4000.0, 0.03, 0.1)]);
    let after = PoleResidueModel::from_modes(&[(400.0, 0.04, 0.1), (2400.0, 0.03, 0.8), (4100.0, 0.03, 0.1)]);
    let ts = pair("x", &before, &after).unwrap();
    // s = 0 and 1 are the two states; in between 1/f² is linear, ζ linear.
    for (s, m) in [(0.0, &before), (1.0, &after)] {
        for f in [100.0, 2300.0, 3000.0] {
            assert!((ts.at(s).frf(f) - m.frf(f)).norm() < 1e-9 * m.frf(f).norm(), "s {s} f {f}");
        }
    }
    let mid = ts.at(0.5).modes();
    let f_mid = 1.0 / (0.5 / (2300f64 * 2300.0) + 0.5 / (2400f64 * 2400.0)).sqrt();
    assert!((mid[1].0 - f_mid).abs() < 1e-6 && (mid[1].1 - 0.025).abs() < 1e-12, "{mid:?}");
    assert!((mid[1].0 - 2350.0).abs() > 0.1, "1/f² interpolation, not linear in f");
    // A missing mode and a mode too far away fail, naming axis and modes.
    let fewer = PoleResidueModel::from_modes(&[(400.0, 0.03, 0.1), (2300.0, 0.02, 0.9)]);
    let e = pair("y", &before, &fewer).unwrap_err().to_string();
    assert!(e.contains("axis y") && e.contains("400, 2300, 4000 Hz") && e.contains("400, 2300 Hz"), "{e}");
    let far = PoleResidueModel::from_modes(&[(400.0, 0.03, 0.1), (2300.0, 0.02, 0.8), (5000.0, 0.03, 0.1)]);
    let e = pair("z", &before, &far).unwrap_err().to_string();
    assert!(e.contains("axis z") && e.contains("4000 Hz") && e.contains("5000 Hz"), "{e}");
}

#[test]
fn with_a_constant_model_the_time_varying_smoother_is_the_stationary_one() {
    let m = PoleResidueModel::from_modes(&[(400.0, 0.03, 0.1), (2300.0, 0.02, 0.9)]);
    let band = (0.0, 4000.0);
    let (dm, _) = discretize(&m, FS, Discretization::Fit, band).unwrap();
    let y: Vec<f64> = (0..4000).map(|k| (k as f64 * 0.01).sin() * 50.0 + ((k * 7919) % 13) as f64).collect();
    let (q, r) = (10.0, 0.05);
    let reference = Smoother::new(&dm, q, r).unwrap().smooth(&y);
    let ts = TwoState { before: m.clone(), after: m.clone() };
    let tv = smooth_drifting(
        &y,
        &|s| ts.at(s),
        &DriftSmoothing {
            fs_hz: FS,
            interval_s: (0.01, 0.05),
            band_hz: band,
            structure: (dm.fir.len(), dm.advance),
            q,
            r,
        },
    )
    .unwrap();
    let scale = reference.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    let err = tv.iter().zip(&reference).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
    assert!(err < 1e-9 * scale, "{err:e}");
    // Negative control: a model that really moves gives another estimate.
    let moved =
        TwoState { before: m.clone(), after: PoleResidueModel::from_modes(&[(400.0, 0.03, 0.1), (2400.0, 0.02, 0.9)]) };
    let tv2 = smooth_drifting(
        &y,
        &|s| moved.at(s),
        &DriftSmoothing {
            fs_hz: FS,
            interval_s: (0.01, 0.05),
            band_hz: band,
            structure: (dm.fir.len(), dm.advance),
            q,
            r,
        },
    )
    .unwrap();
    assert!(tv2.iter().zip(&reference).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max) > 1e-3 * scale);
}

/// A plain dense reference of the time-varying smoother: the Kalman filter
/// with every step's covariance kept, and the Bryson–Frazier backward pass,
/// straight from the module doc's definition (no checkpoints, no held
/// covariance, dense A).
fn dense_reference(y: &[f64], ts: &TwoState, o: &DriftSmoothing) -> Vec<f64> {
    let (taps, adv) = o.structure;
    // Step k's model: that of its drift level, fitted once per level (the
    // fit is a function of the level alone).
    let mut fitted = std::collections::HashMap::new();
    let mut plant = |k: usize| {
        let level = (state_at(k as f64 / o.fs_hz, o.interval_s.0, o.interval_s.1) * S_LEVELS as f64).round();
        let fit = || fit_with_structure(&ts.at(level / S_LEVELS as f64), o.fs_hz, o.band_hz, taps, adv).unwrap();
        fitted.entry(level as i64).or_insert_with(|| augmented_plant(&fit(), 0)).clone()
    };
    let p0 = plant(0);
    let f = p0.n_plant;
    let qm = &p0.g * p0.g.transpose() * o.q;
    let mut p = solve_filter_dare(&p0.a, &p0.c, &qm, o.r).unwrap().p;
    let yt: Vec<f64> = std::iter::repeat_n(y[0], adv).chain(y.iter().copied()).collect();
    let plants: Vec<_> = (0..yt.len()).map(&mut plant).collect();
    let mut x = DVector::zeros(p.nrows());
    let mut steps = Vec::new();
    for (k, &yk) in yt.iter().enumerate() {
        let pl = &plants[k];
        let pc = &p * &pl.c;
        let s = pl.c.dot(&pc) + o.r;
        let kg = &pc / s;
        let e = yk - pl.c.dot(&x);
        steps.push((x[f], p.row(f).transpose(), kg.clone(), s, e));
        x = &pl.a * (&x + &kg * e);
        p = &pl.a * (&p - &kg * pc.transpose()) * pl.a.transpose() + &qm;
        p = (&p + p.transpose()) * 0.5;
    }
    let mut lambda = DVector::zeros(p.nrows());
    let mut out = vec![0.0; yt.len()];
    for k in (0..yt.len()).rev() {
        let (xf, prow, kg, s, e) = &steps[k];
        let lt = &lambda - &plants[k].c * (e / s + kg.dot(&lambda));
        out[k] = xf - prow.dot(&lt);
        if k > 0 {
            lambda = plants[k - 1].a.tr_mul(&lt);
        }
    }
    // Step k carries F_k; the last D steps carry forces after the record.
    out.truncate(y.len());
    out
}

/// A sensor mode moving 2300 → 2420 Hz over `interval_s`, a record of
/// `len` samples (two tones and a little deterministic noise), and the
/// smoother's settings for it.
fn drift_fixture(len: usize, interval_s: (f64, f64)) -> (TwoState, Vec<f64>, DriftSmoothing) {
    let before = PoleResidueModel::from_modes(&[(400.0, 0.03, 0.1), (2300.0, 0.02, 0.9)]);
    let after = PoleResidueModel::from_modes(&[(400.0, 0.03, 0.1), (2420.0, 0.02, 0.9)]);
    let ts = TwoState { before, after };
    let band = (0.0, 4000.0);
    let (dm, _) = discretize(&ts.before, FS, Discretization::Fit, band).unwrap();
    let y: Vec<f64> = (0..len)
        .map(|k| (k as f64 * 0.013).sin() * 50.0 + (k as f64 * 0.71).sin() * 9.0 + ((k * 7919) % 13) as f64)
        .collect();
    let opts = DriftSmoothing {
        fs_hz: FS,
        interval_s,
        band_hz: band,
        structure: (dm.fir.len(), dm.advance),
        q: 10.0,
        r: 0.05,
    };
    (ts, y, opts)
}

/// The smoother keeps only checkpoints of the covariance and holds it where
/// it has converged and the model stays; neither may change the estimate.
/// Any segment length gives the dense reference's estimate to 1e-10 of the
/// record's peak, on a record whose drift leaves stationary stretches before
/// and after it.
#[test]
fn checkpointed_smoother_equals_the_dense_reference_for_any_segment_length() {
    let (ts, y, opts) = drift_fixture(3000, (0.012, 0.041));
    let advance = opts.structure.1;
    let reference = dense_reference(&y, &ts, &opts);
    let scale = reference.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    let dev = |e: &[f64]| e.iter().zip(&reference).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
    for seg in [1, 7, 500, 4096] {
        let done = std::cell::Cell::new(0u64);
        let est = smooth_drifting_in_segments(&y, &|s| ts.at(s), &opts, seg, &|m| done.set(done.get() + m)).unwrap();
        eprintln!("segment {seg}: {:e} of {scale}", dev(&est));
        assert!(dev(&est) < 1e-10 * scale, "segment {seg}: {:e} of {scale}", dev(&est));
        assert_eq!(done.get(), 2 * (y.len() + advance) as u64, "progress counts both passes");
    }
    // Negative control: the drift's timing moved by one sample (one level
    // switch earlier) is resolved by the tolerance.
    let shifted = DriftSmoothing { interval_s: (0.012 - 1.0 / FS, 0.041 - 1.0 / FS), ..opts };
    let moved = dense_reference(&y, &ts, &shifted);
    eprintln!("one sample earlier: {:e}", dev(&moved));
    assert!(dev(&moved) > 1e3 * 1e-10 * scale, "{:e}", dev(&moved));
}

/// `compensate --offline --drift` on a file: the forward pass and the
/// covariance checkpoints spilled to temporary files, the record pushed in
/// blocks of any size. Against the dense reference on a record of several
/// spill segments, with the drift crossing a segment boundary.
#[test]
fn spilled_drift_smoother_equals_the_dense_reference() {
    use dynocomp::offline::drift::{SpilledDriftForward, SPILLED_SEGMENT};
    use dynocomp::offline::smoother::SpilledPass;
    let len = 2 * SPILLED_SEGMENT + 777;
    // The drift runs from 0.05 s to 0.12 s, across the boundary at 4096 samples (0.08 s).
    let (ts, y, opts) = drift_fixture(len, (0.05, 0.12));
    let reference = dense_reference(&y, &ts, &opts);
    let scale = reference.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    let model_at = |s: f64| ts.at(s);
    let dir = std::env::temp_dir();
    let run = |blocks: &[usize], opts: &DriftSmoothing| {
        let mut pass = Box::new(SpilledDriftForward::new(&model_at, opts, &dir).unwrap());
        let mut at = 0;
        for &b in blocks.iter().chain(std::iter::once(&usize::MAX)) {
            let hi = at + b.min(len - at);
            pass.push(&y[at..hi]).unwrap();
            at = hi;
        }
        let done = std::cell::Cell::new(0u64);
        let mut est = pass.backward(&dir, "fx", "test", &|m| done.set(done.get() + m)).unwrap();
        assert_eq!(done.get(), len as u64, "the backward pass reports every sample");
        let mut out = Vec::new();
        est.read(len, &mut out).unwrap();
        assert_eq!(est.left(), 0);
        out
    };
    let dev = |e: &[f64]| e.iter().zip(&reference).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
    let whole = run(&[len], &opts);
    let pieces = run(&[1, 1000, 333, 4096, 7], &opts);
    eprintln!("spilled: {:e} of {scale}", dev(&whole));
    assert!(dev(&whole) < 1e-10 * scale, "{:e} of {scale}", dev(&whole));
    assert_eq!(whole, pieces, "the block sizes must not matter");
    // The in-memory smoother with the same segment length: the same bits.
    let in_memory = smooth_drifting_in_segments(&y, &model_at, &opts, SPILLED_SEGMENT, &|_| {}).unwrap();
    assert_eq!(whole, in_memory);
    // Negative control: the drift one sample earlier is resolved.
    let shifted = DriftSmoothing { interval_s: (0.05 - 1.0 / FS, 0.12 - 1.0 / FS), ..opts };
    let moved = run(&[len], &shifted);
    assert!(dev(&moved) > 1e3 * 1e-10 * scale, "{:e}", dev(&moved));
}

/// (single-FRF, two-state, exact) NRMSE of every axis for a drift of
/// `delta` over the whole record.
fn drift_case(seed: u64, rpm: f64, delta: f64) -> Vec<(f64, f64, f64)> {
    let p = sim_common::params(rpm, 4);
    let dyno = MultiAxisDynamometer::random(dynocomp::simulate::sub_seed(seed, 1), &p);
    let drift = Drift { delta, start_s: 0.0, end_s: p.duration_s };
    let out = simulate_drifting(seed, &p, dyno, drift).unwrap();
    let s = &out.sim;
    let opts = two_state_options(&DesignOptions { fs_hz: FS, lag: 4, ..Default::default() });
    let mut rows = Vec::new();
    for a in 0..3 {
        let r = sample_variance(&s.idle[a]);
        let d = design_axis(&s.frf.freq_hz, s.frf.axis(a).unwrap(), r, &opts).unwrap();
        let band = d.compensated_band_hz;
        let f_max = band.1;
        let (dm, _) = d.discrete.clone().unwrap();
        let structure = (dm.fir.len(), dm.advance);
        let (q, rr) = (d.kalman.q, d.kalman.r);
        let y = &s.measured[a];
        // Today: one FRF (before), stationary smoother.
        let single = Smoother::new(&dm, q, rr).unwrap().smooth(y);
        // Two states: the after FRF fitted at the before model's order,
        // paired, machine modes measured alike shared (what `design` does).
        let paired = pair_second_state(
            &s.frf.freq_hz,
            s.frf.axis(a).unwrap(),
            &d,
            out.frf_after.axis(a).unwrap(),
            &two_state_options(&DesignOptions::default()).vf,
        )
        .unwrap();
        let (ts, machine) = (paired.states, paired.machine);
        let shared: Vec<String> = machine.iter().filter(|m| m.shared).map(|m| format!("{:.0}", m.fn_hz.0)).collect();
        eprintln!(
            "seed {seed} axis {a}: machine modes shared {} Hz, {} kept apart",
            shared.join(", "),
            machine.len() - shared.len()
        );
        let two = smooth_drifting(
            y,
            &|s| ts.at(s),
            &DriftSmoothing { fs_hz: FS, interval_s: (0.0, p.duration_s), band_hz: band, structure, q, r: rr },
        )
        .unwrap();
        // Exact: the true set-up at every instant (the simulator's modes).
        let true_axis = s.dyno.axis(a).clone();
        let exact_at = |sv: f64| {
            // The simulator's law: mass linear in time (1/f² linear in s).
            let m = shift_sensor_modes(&true_axis, drift.shift_at(sv * p.duration_s));
            PoleResidueModel::from_modes(&m.modes.iter().map(|m| (m.fn_hz, m.zeta, m.residue)).collect::<Vec<_>>())
        };
        let exact_dm = discretize(&exact_at(0.0), FS, Discretization::Fit, band).unwrap().0;
        let exact = smooth_drifting(
            y,
            &exact_at,
            &DriftSmoothing {
                fs_hz: FS,
                interval_s: (0.0, p.duration_s),
                band_hz: band,
                structure: (exact_dm.fir.len(), exact_dm.advance),
                q,
                r: rr,
            },
        )
        .unwrap();
        let score = |x: &[f64]| accuracy(x, &s.truth[a], FS, f_max).nrmse;
        // The interpolation rule with the TRUE end states reproduces the
        // exact model (the simulator's mass-linear drift): what separates
        // two-state from exact is the fit of the two FRFs, not the rule.
        let true_states = pair("true", &exact_at(0.0), &exact_at(1.0)).unwrap();
        let rule = smooth_drifting(
            y,
            &|s| true_states.at(s),
            &DriftSmoothing {
                fs_hz: FS,
                interval_s: (0.0, p.duration_s),
                band_hz: band,
                structure: (exact_dm.fir.len(), exact_dm.advance),
                q,
                r: rr,
            },
        )
        .unwrap();
        let row = (score(&single), score(&two), score(&exact));
        let e_rule = score(&rule);
        assert!(
            (e_rule / row.2 - 1.0).abs() < 0.02,
            "axis {a}: rule with true end states {e_rule:.5} vs exact {:.5}",
            row.2
        );
        eprintln!(
            "seed {seed} drift {:+.0} % axis {a}: single-FRF {:.3} %, two-state {:.3} %, exact {:.3} % (two/exact {:.2})",
            100.0 * delta,
            100.0 * row.0,
            100.0 * row.1,
            100.0 * row.2,
            row.1 / row.2
        );
        rows.push(row);
    }
    rows
}

#[test]
#[ignore = "diagnostic: the fit error's share without drift (BENCHMARKS.md)"]
fn no_drift_reference() {
    drift_case(4, 6_000.0, 0.0);
    drift_case(3, 20_000.0, 0.0);
}

#[test]
fn two_state_smoother_follows_a_drift_within_1_5x_of_the_exact_model() {
    let mut rows = Vec::new();
    for (seed, rpm, delta) in [(3, 20_000.0, -0.05), (4, 6_000.0, 0.05), (5, 12_000.0, -0.03)] {
        rows.extend(drift_case(seed, rpm, delta));
    }
    let mut ratios: Vec<f64> = rows.iter().map(|r| r.1 / r.2).collect();
    ratios.sort_by(f64::total_cmp);
    let median = ratios[ratios.len() / 2];
    eprintln!("two-state / exact: median {median:.2}, worst {:.2}", ratios[ratios.len() - 1]);
    assert!(median <= TARGET, "median ratio {median:.2}");
    // All 9 within the target; 7 with the machine modes kept apart and the
    // above-band modes fitted separately.
    for (i, &(single, two, exact)) in rows.iter().enumerate() {
        assert!(two <= TARGET * exact, "row {i}: two-state {two:.4} vs exact {exact:.4}");
        // Negative control: today's single-FRF smoother misses the target.
        assert!(single > TARGET * exact, "row {i}: single {single:.4} vs exact {exact:.4}");
    }
}

#[test]
fn box_image_for_the_range_beats_either_single_state_design() {
    // A +4 % drift (modal mass linear in time); both impact tests.
    let p = sim_common::params(20_000.0, 4);
    let dyno = MultiAxisDynamometer::random(dynocomp::simulate::sub_seed(3, 1), &p);
    let drift = Drift { delta: 0.04, start_s: 0.0, end_s: 1.0 };
    let out = simulate_drifting(3, &p, dyno, drift).unwrap();
    let s = &out.sim;
    let opts = DesignOptions { fs_hz: FS, lag: 4, ..Default::default() };
    let fine_len = p.anti_alias.fine_len(p.n_samples(), p.oversample);
    let f_fine = FS * p.oversample as f64;
    for a in [0, 1] {
        let r = sample_variance(&s.idle[a]);
        let outcome = design_or_hold(
            &s.frf.freq_hz,
            s.frf.axis(a).unwrap(),
            out.frf_after.axis(a).unwrap(),
            r,
            &opts,
            &[0.0, 0.25, 0.5, 0.75, 1.0],
        )
        .unwrap();
        let RangeDesign { candidates: cands, best, .. } = outcome.range().expect("states paired");
        let best = *best;
        let single = [&cands[0], &cands[cands.len() - 1]];
        let chosen = &cands[best];
        // A design at an interpolated state reports the measured states'
        // fit error, not that of the model response it was fitted to (which
        // is zero by construction: the control, below 1e-6).
        for c in cands.iter().filter(|c| c.s > 0.0 && c.s < 1.0) {
            let e = c.design.fit_nrmse;
            assert!(e >= cands[0].design.fit_nrmse && e > 1e-6, "axis {a} s = {}: fit error {e:.2e}", c.s);
        }
        // Measured worst case over the range: flat force, true set-up at each state.
        let flat = sim_common::flat_force(fine_len, f_fine, chosen.design.compensated_band_hz.1, 100.0, 55);
        let measured_worst = |c: &RangeCandidate| {
            RANGE_STATES
                .iter()
                .map(|&sv| sim_common::measured_shifted(s, &c.design, &flat, 100.0 * drift.shift_at(sv)))
                .fold(0.0, f64::max)
        };
        let m: Vec<f64> = cands.iter().map(measured_worst).collect();
        for (c, mw) in cands.iter().zip(&m) {
            eprintln!(
                "axis {a} candidate s = {:.2}: predicted worst {:.2} % ({:?}), measured worst {:.2} %",
                c.s,
                100.0 * c.worst,
                c.errors.iter().map(|e| (1e4 * e).round() / 100.0).collect::<Vec<_>>(),
                100.0 * mw
            );
        }
        eprintln!("axis {a}: chosen s = {:.2}", chosen.s);
        for (i, sd) in single.iter().enumerate() {
            assert!(
                chosen.worst < sd.worst,
                "axis {a}: predicted worst case {} not below single state {i}'s {}",
                chosen.worst,
                sd.worst
            );
        }
        let (m0, m1, mc) = (m[0], m[cands.len() - 1], m[best]);
        assert!(mc < m0 && mc < m1, "axis {a}: measured worst case {mc:.4} vs single-state {m0:.4} / {m1:.4}");
    }
}

/// Issue #15, item 4 (an investigation, not a shipped feature: BENCHMARKS.md,
/// `examples/drift_from_record.rs`): the likelihood itself, with the exact
/// two-state model (the true end states, no FRF fit in between) and a
/// broadband force, over candidate end states c (model path s ↦ state s·c).
/// A record whose modes drifted by the full −5 % prefers a drift (best c ≥
/// 0.5, at least 100 nats above c = 0); a record without drift prefers
/// c = 0 (negative control). Measured, and why nothing ships: even here the
/// maximum is biased low (c = 0.75 for the true 1; c = 0 for the true 0.48),
/// since the filter's force model (q, flat) is not the record's force.
#[test]
fn drift_likelihood_tells_drift_from_none_with_the_exact_model() {
    let p = sim_common::params(20_000.0, 4);
    let dyno = MultiAxisDynamometer::random(dynocomp::simulate::sub_seed(3, 1), &p);
    let delta = -0.05;
    let drift = Drift { delta, start_s: 0.0, end_s: p.duration_s };
    let out = simulate_drifting(3, &p, dyno, drift).unwrap();
    let s = &out.sim;
    let a = 1;
    let opts = DesignOptions { fs_hz: FS, lag: 4, ..Default::default() };
    let d = design_axis(&s.frf.freq_hz, s.frf.axis(a).unwrap(), sample_variance(&s.idle[a]), &opts).unwrap();
    let band = d.compensated_band_hz;
    let true_axis = s.dyno.axis(a).clone();
    let exact_at = |sv: f64| {
        let m = shift_sensor_modes(&true_axis, drift.shift_at(sv * p.duration_s));
        PoleResidueModel::from_modes(&m.modes.iter().map(|m| (m.fn_hz, m.zeta, m.residue)).collect::<Vec<_>>())
    };
    let exact_dm = discretize(&exact_at(0.0), FS, Discretization::Fit, band).unwrap().0;
    let ts = pair("true", &exact_at(0.0), &exact_at(1.0)).unwrap();
    let smoothing = DriftSmoothing {
        fs_hz: FS,
        interval_s: (0.0, p.duration_s),
        band_hz: band,
        structure: (exact_dm.fir.len(), exact_dm.advance),
        q: d.kalman.q,
        r: d.kalman.r,
    };
    let (n, os) = (p.n_samples(), p.oversample.max(1));
    let f_fine = FS * os as f64;
    let force = sim_common::flat_force(p.anti_alias.fine_len(n, os), f_fine, band.1, 100.0, 77);
    let grid = [0.0, 0.25, 0.5, 0.75, 1.0, 1.25];
    let best_c = |actual: f64| -> (f64, f64) {
        let y_fine =
            measure_drifting(&true_axis, &Drift { delta: actual, start_s: 0.0, end_s: p.duration_s }, &force, f_fine);
        let (_, clean) = p.anti_alias.acquire_response(&force, &y_fine, FS, os, n);
        let y = p.measurement.apply(&clean, 91);
        let l: Vec<f64> =
            grid.iter().map(|&c| drift_log_likelihood(&y, &|sv| ts.at(sv * c), &smoothing).unwrap()).collect();
        let best = (0..grid.len()).max_by(|&i, &j| l[i].total_cmp(&l[j])).unwrap();
        eprintln!(
            "shift {:+.1} %: log-likelihood − max over c = {:?}",
            100.0 * actual,
            grid.iter().zip(&l).map(|(c, v)| (*c, (v - l[best]).round())).collect::<Vec<_>>()
        );
        (grid[best], l[best] - l[0])
    };
    let (c_full, gain_full) = best_c(delta);
    assert!(c_full >= 0.5 && gain_full >= 100.0, "full drift: best c {c_full}, {gain_full:.0} nats above c = 0");
    let (c_none, _) = best_c(0.0);
    assert_eq!(c_none, 0.0, "no drift (negative control)");
}

/// Seed 4's set-up (TPF 400 Hz), axis `axis` before any change: its true
/// model, an impact test of it (seed 41) and the default design from that.
struct ImpactFixture {
    before: dynocomp::simulate::Dynamometer,
    p: dynocomp::simulate::SimParams,
    freq: Vec<f64>,
    d0: (dynocomp::design::axis::AxisDesign, dynocomp::frf::AxisFrf),
}

fn impact_fixture(axis: usize) -> ImpactFixture {
    let p = sim_common::params(6_000.0, 4);
    let dyno = MultiAxisDynamometer::random(dynocomp::simulate::sub_seed(4, 1), &p);
    let before = dyno.axis(axis).clone();
    let ip = &p.impact;
    let freq = dynocomp::simulate::impact::impact_freqs(ip.n_lines, ip.df_hz);
    let frf0 = impact_test_axis(&before, axis, ip.n_lines, ip.df_hz, 41, ip);
    let opts = two_state_options(&DesignOptions { fs_hz: FS, lag: 4, ..Default::default() });
    let d0 = design_axis(&freq, &frf0, 0.05, &opts).unwrap();
    ImpactFixture { before, p, freq, d0: (d0, frf0) }
}

/// Machine-structure modes are shared between the states only where both
/// impact tests measured them alike (`share_machine_modes`): with the
/// sensor modes alone moved every machine mode is shared; a machine mode
/// that moved too is kept apart in each state (negative control).
#[test]
fn machine_modes_are_shared_only_where_both_frfs_measured_them_alike() {
    let ImpactFixture { before, p, freq, d0 } = impact_fixture(0);
    let frf0 = &d0.1;
    let (d0, ip) = (&d0.0, &p.impact);
    let sensors_moved = shift_sensor_modes(&before, 0.05);
    // The machine mode nearest 413 Hz (ζ ≈ 0.017) moved as well.
    let m = sensors_moved
        .modes
        .iter()
        .enumerate()
        .filter(|(_, m)| m.fn_hz < 1000.0)
        .min_by(|a, b| (a.1.fn_hz - 413.0).abs().total_cmp(&(b.1.fn_hz - 413.0).abs()))
        .unwrap()
        .0;
    let f_m = sensors_moved.modes[m].fn_hz;
    let run = |after: &dynocomp::simulate::Dynamometer| {
        let frf1 = impact_test_axis(after, 0, ip.n_lines, ip.df_hz, 42, ip);
        let p = pair_second_state(&freq, frf0, d0, &frf1, &two_state_options(&DesignOptions::default()).vf).unwrap();
        (p.states, p.machine)
    };
    let (ts, machine) = run(&sensors_moved);
    eprintln!("sensor modes moved: {machine:?}");
    assert!(machine.len() >= 2 && machine.iter().all(|x| x.shared), "{machine:?}");
    let sensors = dynocomp::fit::modes::sensor_mode_indices(&ts.before);
    for (i, (a, b)) in ts.before.terms.iter().zip(&ts.after.terms).enumerate() {
        // Shared modes are one mode in both states; sensor modes keep their shift.
        assert_eq!(
            a == b,
            !sensors.contains(&i) && matches!(a, dynocomp::fit::Term::Pair { .. }),
            "term {i}: {a:?} / {b:?}"
        );
    }
    for shift in [0.002, 0.005, 0.01] {
        let mut moved = sensors_moved.clone();
        moved.modes[m].fn_hz *= 1.0 + shift;
        let (_, machine) = run(&moved);
        let near = machine.iter().find(|x| (x.fn_hz.0 - f_m).abs() < 5.0).unwrap();
        eprintln!("machine mode {f_m:.1} Hz also moved {:+.1} %: {near:?}", 100.0 * shift);
        // Even 0.2 % (an eighth of the mode's half-power bandwidth) is seen.
        assert!(!near.shared && near.misfit_growth.0.min(near.misfit_growth.1) > 1.5, "{near:?}");
        assert!(machine.iter().filter(|x| x.shared).count() == machine.len() - 1, "{machine:?}");
    }
}

/// Sensor modes above the compensated band are fitted to both FRFs at once
/// (`two_state_joint`): on seed 4 y (true 4396 → 4616 Hz, +5 %, the band
/// ending near 3.7 kHz) the joint fit lands closer to the true frequencies
/// than the two separate fits. Negative control: when the second state's
/// mode also changed its static gain (stiffness, not mass), the two FRFs
/// disagree and each keeps its own fit.
#[test]
fn above_band_modes_are_fitted_jointly_only_where_the_frfs_agree_on_their_static_gain() {
    let ImpactFixture { before, p, freq, d0 } = impact_fixture(1);
    let frf0 = &d0.1;
    let (d0, ip) = (&d0.0, &p.impact);
    let after = shift_sensor_modes(&before, 0.05);
    let top = |d: &dynocomp::simulate::Dynamometer| d.modes.last().unwrap().fn_hz;
    assert!(top(&before) > d0.compensated_band_hz.1, "the fixture needs a sensor mode above the band");
    let run_seeded = |after: &dynocomp::simulate::Dynamometer, seed: u64| {
        let frf1 = impact_test_axis(after, 1, ip.n_lines, ip.df_hz, seed, ip);
        pair_second_state(&freq, frf0, d0, &frf1, &two_state_options(&DesignOptions::default()).vf).unwrap()
    };
    let run = |after: &dynocomp::simulate::Dynamometer| run_seeded(after, 42);
    let p = run(&after);
    eprintln!("sensor modes moved: {:?}", p.above_band);
    let [m] = &p.above_band[..] else { panic!("one above-band mode expected: {:?}", p.above_band) };
    assert!(m.joint, "{m:?}");
    let miss = |f: (f64, f64)| ((f.0 / top(&before) - 1.0).abs()).max((f.1 / top(&after) - 1.0).abs());
    eprintln!(
        "largest frequency error: separate {:.2} %, joint {:.2} %",
        100.0 * miss(m.fn_hz),
        100.0 * miss(m.joint_fn_hz)
    );
    assert!(miss(m.joint_fn_hz) < 0.5 * miss(m.fn_hz), "{m:?}");
    // The states carry the joint fit: one modal share and one d.
    assert_eq!(p.states.before.d, p.states.after.d);
    // Null: other impact tests of the after-state (noise draws).
    let mut null = vec![m.misfit_growth];
    for seed in [43, 44, 45] {
        let q = run_seeded(&after, seed);
        let [m] = &q.above_band[..] else { panic!("{:?}", q.above_band) };
        assert!(m.joint, "null seed {seed}: {m:?}");
        null.push(m.misfit_growth);
    }
    eprintln!("misfit growth, mass change only: {null:?}");
    // Negative control: the second state's mode also changed its static
    // gain (stiffness, not mass) by −10 %, +10 %, +30 %.
    for g in [0.9, 1.1, 1.3] {
        let mut changed = after.clone();
        changed.modes.last_mut().unwrap().residue *= g;
        let q = run(&changed);
        eprintln!("static gain ×{g} too: {:?}", q.above_band);
        let [m] = &q.above_band[..] else { panic!("{:?}", q.above_band) };
        assert!(!m.joint && m.misfit_growth > 1.0 + JOINT_TOLERANCE, "×{g}: {m:?}");
        assert_ne!(q.states.before.d, q.states.after.d, "each state keeps its own fit");
    }
}

/// Background terms of one fit (a heavily damped pair, real poles far
/// outside the band) are not paired: each state keeps its own and carries
/// the other's with a zero residue, so both states are reproduced exactly
/// and in between one background fades into the other. A physical mode
/// that only one fit holds still refuses the pairing, naming the modes
/// (negative control: the rule does not pair everything).
#[test]
fn background_terms_of_one_fit_are_not_paired_but_physical_modes_must_match() {
    use dynocomp::fit::Term;
    let real = |f: f64, share: f64| Term::Real {
        pole: -std::f64::consts::TAU * f,
        residue: std::f64::consts::TAU * f * share,
    };
    let modes0 = PoleResidueModel::from_modes(&[(260.0, 0.03, 0.05), (1988.0, 0.5, -0.0065), (3450.0, 0.02, 0.45)]);
    let modes1 = PoleResidueModel::from_modes(&[(260.0, 0.03, 0.05), (3536.0, 0.02, 0.45)]);
    let before = PoleResidueModel { terms: [modes0.terms, vec![real(118e3, 0.48), real(3.8, 0.01)]].concat(), d: 0.0 };
    let after =
        PoleResidueModel { terms: [modes1.terms, vec![real(88.7e3, 0.5), real(122.0, 0.002)]].concat(), d: 0.0 };
    let ts = pair("z", &before, &after).unwrap();
    for (s, m) in [(0.0, &before), (1.0, &after)] {
        for f in [1.0, 100.0, 1988.0, 3450.0, 4000.0] {
            assert!((ts.at(s).frf(f) - m.frf(f)).norm() < 1e-9 * m.frf(f).norm(), "s {s} f {f}");
        }
    }
    let physical: Vec<usize> = (0..ts.before.terms.len()).filter(|&i| !ts.is_background(i)).collect();
    assert_eq!(physical.len(), 2, "{ts:?}");
    // The sidecar's check accepts what pair() made.
    TwoState::checked("z", ts.before.clone(), ts.after.clone()).unwrap();
    // A lightly damped mode of real weight in one fit only is refused.
    let extra = PoleResidueModel::from_modes(&[(260.0, 0.03, 0.05), (1988.0, 0.05, 0.05), (3450.0, 0.02, 0.45)]);
    let e = pair("z", &extra, &modes1_only()).unwrap_err().to_string();
    assert!(e.contains("axis z") && e.contains("260, 1988, 3450 Hz") && e.contains("260, 3536 Hz"), "{e}");
}

fn modes1_only() -> PoleResidueModel {
    PoleResidueModel::from_modes(&[(260.0, 0.03, 0.05), (3536.0, 0.02, 0.45)])
}

/// Modes one fit resolved and the other did not (drift sweep seed 8 x: the
/// first fit holds 190, 269, 2503 Hz, the second 118, 190, 2569 Hz). Paired
/// in order, 190 would meet 118 (−38 %) and the axis was refused. The most
/// partners within ±15 % are matched instead (190 ↔ 190, 2503 ↔ 2569), and
/// a mode left alone fades between the states where the caller allows it:
/// both states are reproduced exactly. Negative controls: without fading,
/// and with fading allowed only below 200 Hz, the lone 269 Hz is refused by
/// name.
#[test]
fn modes_without_a_partner_fade_where_allowed_and_are_refused_elsewhere() {
    use dynocomp::design::two_state::model::pair_fading;
    let before = PoleResidueModel::from_modes(&[(190.0, 0.03, 0.05), (269.0, 0.03, 0.04), (2503.0, 0.02, 0.8)]);
    let after = PoleResidueModel::from_modes(&[(118.0, 0.04, 0.03), (190.0, 0.03, 0.05), (2569.0, 0.02, 0.8)]);
    let ts = pair_fading("x", &before, &after, &|f| f < 1000.0, f64::INFINITY).unwrap();
    for (s, m) in [(0.0, &before), (1.0, &after)] {
        for f in [10.0, 118.0, 190.0, 269.0, 2503.0, 2569.0, 4000.0] {
            assert!((ts.at(s).frf(f) - m.frf(f)).norm() < 1e-9 * m.frf(f).norm(), "s {s} f {f}");
        }
    }
    let partners: Vec<(f64, f64)> = (0..ts.before.terms.len())
        .filter(|&i| !ts.is_background(i))
        .filter_map(|i| match (ts.before.terms[i], ts.after.terms[i]) {
            (dynocomp::fit::Term::Pair { pole: p0, .. }, dynocomp::fit::Term::Pair { pole: p1, .. }) => {
                Some((p0.norm() / std::f64::consts::TAU, p1.norm() / std::f64::consts::TAU))
            }
            _ => None,
        })
        .collect();
    assert_eq!(partners.len(), 2, "{partners:?}");
    assert!((partners[0].0 - 190.0).abs() < 1.0 && (partners[0].1 - 190.0).abs() < 1.0, "{partners:?}");
    assert!((partners[1].0 - 2503.0).abs() < 5.0 && (partners[1].1 - 2569.0).abs() < 5.0, "{partners:?}");
    TwoState::checked("x", ts.before.clone(), ts.after.clone()).unwrap();
    let e = pair("x", &before, &after).unwrap_err().to_string();
    assert!(e.contains("axis x") && e.contains("269 Hz has no partner") && e.contains("118 Hz has no partner"), "{e}");
    let e = pair_fading("x", &before, &after, &|f| f < 200.0, f64::INFINITY).unwrap_err().to_string();
    assert!(e.contains("269 Hz has no partner") && !e.contains("118 Hz has no partner"), "{e}");
    // A mode that crosses fs/2 between the states (5000 → 5200 Hz at 10.24
    // kHz, drift sweep seed 19) is no pair: the discrete models would hold
    // it as a state in one state and in the FIR taps in the other. Both
    // fade where allowed (above the band); without the Nyquist rule they
    // pair (the control).
    let before = PoleResidueModel::from_modes(&[(2503.0, 0.02, 0.8), (5000.0, 0.02, 0.1)]);
    let after = PoleResidueModel::from_modes(&[(2569.0, 0.02, 0.8), (5200.0, 0.02, 0.1)]);
    let ts = pair_fading("z", &before, &after, &|f| f > 4000.0, 5120.0).unwrap();
    let lone = (0..ts.before.terms.len()).filter(|&i| ts.is_background(i)).count();
    assert_eq!(lone, 2, "{ts:?}");
    for (s, m) in [(0.0, &before), (1.0, &after)] {
        assert!((ts.at(s).frf(3000.0) - m.frf(3000.0)).norm() < 1e-9 * m.frf(3000.0).norm(), "s {s}");
    }
    let paired = pair_fading("z", &before, &after, &|f| f > 4000.0, f64::INFINITY).unwrap();
    assert_eq!((0..paired.before.terms.len()).filter(|&i| paired.is_background(i)).count(), 0, "{paired:?}");
}
