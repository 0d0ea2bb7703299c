//! Issue #15, item 5: the simulator's drifting sensor modes
//! (`simulate::drift`), against independent references: a fine-step RK4
//! integration of one mode whose ω moves continuously, the constant model
//! (bit for bit), the shifted constant model once the drift is over, and the
//! CLI's files.

use dynocomp::simulate::drift::{measure_drifting, sensor_modes, shift_sensor_modes, simulate_drifting, Drift};
use dynocomp::simulate::{Dynamometer, Mode, MultiAxisDynamometer, SimParams};
use std::f64::consts::PI;

use crate::cli_common;

const F_FINE: f64 = 409_600.0;

/// A smooth, broadband force: a few sines plus a chirp (N), at `F_FINE`.
fn force(n: usize) -> Vec<f64> {
    (0..n)
        .map(|k| {
            let t = k as f64 / F_FINE;
            50.0 + 30.0 * (2.0 * PI * 800.0 * t).sin()
                + 20.0 * (2.0 * PI * 2330.0 * t).sin()
                + 10.0 * (2.0 * PI * (500.0 + 20_000.0 * t) * t).sin()
        })
        .collect()
}

/// RK4 integration of ẍ + 2ζω(t)ẋ + ω(t)²x = rω(t)²u(t), u linear between
/// the samples, ω(t) = ω0·(1 + drift(t)) continuous in time, `sub` RK4 steps
/// per sample; x at each sample.
fn rk4(m: &Mode, drift: &Drift, u: &[f64], sub: usize) -> Vec<f64> {
    let h = 1.0 / F_FINE / sub as f64;
    let w0 = 2.0 * PI * m.fn_hz;
    let f = |t: f64, x: f64, v: f64, uu: f64| -> (f64, f64) {
        let w = w0 * (1.0 + drift.shift_at(t));
        (v, m.residue * w * w * uu - 2.0 * m.zeta * w * v - w * w * x)
    };
    let mut y = vec![0.0; u.len()];
    let (mut x, mut v) = (0.0, 0.0);
    for k in 1..u.len() {
        for s in 0..sub {
            let t = ((k - 1) as f64 + s as f64 / sub as f64) / F_FINE;
            let ua = |frac: f64| u[k - 1] + (u[k] - u[k - 1]) * frac;
            let (fa, fb, fc) = (s as f64 / sub as f64, (s as f64 + 0.5) / sub as f64, (s as f64 + 1.0) / sub as f64);
            let k1 = f(t, x, v, ua(fa));
            let k2 = f(t + h / 2.0, x + h / 2.0 * k1.0, v + h / 2.0 * k1.1, ua(fb));
            let k3 = f(t + h / 2.0, x + h / 2.0 * k2.0, v + h / 2.0 * k2.1, ua(fb));
            let k4 = f(t + h, x + h * k3.0, v + h * k3.1, ua(fc));
            x += h / 6.0 * (k1.0 + 2.0 * k2.0 + 2.0 * k3.0 + k4.0);
            v += h / 6.0 * (k1.1 + 2.0 * k2.1 + 2.0 * k3.1 + k4.1);
        }
        y[k] = x;
    }
    y
}

fn rel_rms(a: &[f64], b: &[f64]) -> f64 {
    let e: f64 = a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum();
    let s: f64 = b.iter().map(|y| y * y).sum();
    (e / s).sqrt()
}

/// Largest relative error of the block-wise drifting model against the RK4
/// reference of a continuously drifting mode: the per-block ω (at the block's
/// middle) is a midpoint rule on a linear ω(t), so this is far below the
/// drift's own effect (negative control below).
const RK4_TOL: f64 = 1e-4;

#[test]
fn one_drifting_mode_matches_a_fine_step_ode_integration() {
    let mode = Mode { fn_hz: 2400.0, zeta: 0.02, residue: 1.0 };
    let dyn_ = Dynamometer::from_modes(vec![mode]).unwrap();
    let u = force(40_960); // 0.1 s
    let drift = Drift { delta: 0.05, start_s: 0.02, end_s: 0.08 };
    let sim = measure_drifting(&dyn_, &drift, &u, F_FINE);
    let reference = rk4(&mode, &drift, &u, 4);
    let err = rel_rms(&sim, &reference);
    eprintln!("drifting mode vs RK4: relative RMS error {err:.2e}");
    assert!(err < RK4_TOL, "{err:.3e}");
    // RK4 itself is converged: halving its step changes it far less.
    let finer = rk4(&mode, &drift, &u, 8);
    assert!(rel_rms(&reference, &finer) < 0.1 * RK4_TOL);
    // Negative controls: the same mode without drift, and the drift applied
    // with a state reset at every block boundary (x, ẋ not kept), are far
    // from the reference.
    let constant = dyn_.measure(&u, F_FINE);
    let e_const = rel_rms(&constant, &reference);
    assert!(e_const > 100.0 * RK4_TOL, "{e_const:.3e}");
    let (mut reset, mut x0) = (vec![0.0; u.len()], 0usize);
    while x0 < u.len() {
        let end = (x0 + 4096).min(u.len());
        let t_mid = (x0 + end) as f64 / 2.0 / F_FINE;
        let m = Mode { fn_hz: mode.fn_hz * (1.0 + drift.shift_at(t_mid)), ..mode };
        let part = Dynamometer::from_modes(vec![m]).unwrap().measure(&u[x0..end], F_FINE);
        reset[x0..end].copy_from_slice(&part);
        x0 = end;
    }
    assert!(rel_rms(&reset, &reference) > 100.0 * RK4_TOL);
}

fn axis() -> Dynamometer {
    Dynamometer::from_modes(vec![
        Mode { fn_hz: 300.0, zeta: 0.03, residue: 0.1 },
        Mode { fn_hz: 2300.0, zeta: 0.02, residue: 0.8 },
        Mode { fn_hz: 4100.0, zeta: 0.03, residue: 0.1 },
    ])
    .unwrap()
}

#[test]
fn without_drift_the_record_is_unchanged_bit_for_bit() {
    let d = axis();
    let u = force(20_000);
    let plain = d.measure(&u, F_FINE);
    for drift in [Drift { delta: 0.0, start_s: 0.0, end_s: 0.01 }, Drift { delta: 0.04, start_s: 1.0, end_s: 2.0 }] {
        assert_eq!(measure_drifting(&d, &drift, &u, F_FINE), plain, "{drift:?}");
    }
    // Before the drift starts the record is the constant model's, bit for bit;
    // after it ends it becomes the shifted model's once the sensor modes'
    // different histories have decayed (slowest sensor mode: 1/(ζω) = 3.5 ms).
    let u = force(81_920); // 0.2 s
    let drift = Drift { delta: -0.04, start_s: 0.05, end_s: 0.1 };
    let y = measure_drifting(&d, &drift, &u, F_FINE);
    let before = d.measure(&u, F_FINE);
    let k_start = (0.05 * F_FINE) as usize - 64;
    assert_eq!(y[..k_start], before[..k_start]);
    assert_ne!(y[k_start + 128], before[k_start + 128], "the drift has started");
    let after = shift_sensor_modes(&d, -0.04).measure(&u, F_FINE);
    let k_end = (0.15 * F_FINE) as usize;
    let e = rel_rms(&y[k_end..], &after[k_end..]);
    assert!(e < 1e-5, "{e:.3e}");
    assert!(rel_rms(&y[k_end..], &before[k_end..]) > 1e-2, "negative control: not the unshifted model");
}

#[test]
fn sensor_modes_rule_and_shift() {
    let d = axis();
    assert_eq!(sensor_modes(&d), vec![1, 2]);
    let s = shift_sensor_modes(&d, 0.03);
    let f: Vec<f64> = s.modes.iter().map(|m| m.fn_hz).collect();
    assert_eq!(f[0], 300.0);
    assert!((f[1] - 2369.0).abs() < 1e-9 && (f[2] - 4223.0).abs() < 1e-9, "{f:?}");
    assert_eq!(
        s.modes.iter().map(|m| m.residue).collect::<Vec<_>>(),
        d.modes.iter().map(|m| m.residue).collect::<Vec<_>>()
    );
}

#[test]
fn drifting_simulation_writes_both_end_states() {
    let p = SimParams { duration_s: 0.1, idle_duration_s: 0.05, ..Default::default() };
    let dyno = MultiAxisDynamometer { axes: [axis(), axis(), axis()] };
    let drift = Drift { delta: 0.03, start_s: 0.02, end_s: 0.06 };
    let out = simulate_drifting(5, &p, dyno.clone(), drift).unwrap();
    let plain = dynocomp::simulate::simulate_with(5, &p, dyno).unwrap();
    // The truth and the before-FRF do not depend on the drift; the record does.
    assert_eq!(out.sim.truth, plain.truth);
    assert_eq!(out.sim.frf.axes[0].frf, plain.frf.axes[0].frf);
    assert_ne!(out.sim.measured[0], plain.measured[0]);
    // The after-FRF peaks 3 % higher (main mode 2300 → 2369 Hz).
    let peak = |frf: &dynocomp::frf::Frf| {
        let a = &frf.axes[0];
        let i = (0..a.frf.len())
            .filter(|&i| frf.freq_hz[i] > 1500.0 && frf.freq_hz[i] < 3000.0)
            .max_by(|&i, &j| a.frf[i].norm().total_cmp(&a.frf[j].norm()))
            .unwrap();
        frf.freq_hz[i]
    };
    let (b, a) = (peak(&out.sim.frf), peak(&out.frf_after));
    assert!((b - 2300.0).abs() < 15.0 && (a - 2369.0).abs() < 15.0, "peaks {b} → {a} Hz");
}

#[test]
fn cli_writes_before_and_after_frfs_and_refuses_bad_drift() {
    let dir = cli_common::tmp("drift-sim", "out");
    let _ = std::fs::remove_dir_all(&dir);
    let d = dir.to_str().unwrap();
    let (ok, _, err) = cli_common::dynocomp(&[
        "simulate",
        "--out",
        d,
        "--duration",
        "0.1",
        "--idle-duration",
        "0.05",
        "--drift-percent",
        "-3",
        "--drift-end",
        "0.08",
    ]);
    assert!(ok, "{err}");
    for f in ["frf.uff", "frf_after.uff", "frf_after.csv", "drift.json", "measured.csv", "true_force.csv", "truth.json"]
    {
        assert!(dir.join(f).is_file(), "{f} missing: {err}");
    }
    let j: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(dir.join("drift.json")).unwrap()).unwrap();
    assert_eq!(j["delta"].as_f64().unwrap(), -0.03);
    assert_eq!(j["end_s"].as_f64().unwrap(), 0.08);
    let (b, a) =
        (j["sensor_modes_before_hz"][0][0].as_f64().unwrap(), j["sensor_modes_after_hz"][0][0].as_f64().unwrap());
    assert!((a / b - 0.97).abs() < 1e-12, "{b} → {a}");
    // Bad drifts: one-line error naming the flag, nothing written.
    let bad = cli_common::tmp("drift-sim", "bad");
    let _ = std::fs::remove_dir_all(&bad);
    for args in
        [vec!["--drift-percent", "80"], vec!["--drift-percent", "2", "--drift-start", "0.5", "--drift-end", "0.2"]]
    {
        let mut a = vec!["simulate", "--out", bad.to_str().unwrap(), "--duration", "0.1"];
        a.extend(args.iter());
        let (ok, _, err) = cli_common::dynocomp(&a);
        assert!(!ok && err.contains("--drift"), "{err}");
        assert!(!bad.exists(), "output written for {args:?}");
    }
}
