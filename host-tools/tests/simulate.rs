//! Tests of the synthetic dynamometer + milling simulator (ground truth of the
//! project): every expectation is computed independently of the simulator
//! (analytic responses, closed-form Altintas averages, Fourier series).

#![allow(clippy::needless_range_loop)] // axis/line indices index several arrays at once

use dynocomp::simulate::{
    h1_random_error, impact_test, measure_decimated, milling_force, simulate, AntiAlias, Butterworth, Chatter,
    Dynamometer, Hold, ImpactParams, MeasurementParams, MillingMode, MillingParams, Mode, MultiAxisDynamometer,
    SimParams,
};
use num_complex::Complex64;
use std::f64::consts::PI;

fn mode(fn_hz: f64, zeta: f64, residue: f64) -> Mode {
    Mode { fn_hz, zeta, residue }
}

/// Complex Fourier amplitude of `x` at `f_hz` (peak amplitude of a sinusoid);
/// exact for records spanning an integer number of periods.
fn dft_amp(x: &[f64], fs: f64, f_hz: f64) -> Complex64 {
    let n = x.len() as f64;
    let w = 2.0 * PI * f_hz / fs;
    let s: Complex64 = x.iter().enumerate().map(|(k, &v)| v * Complex64::from_polar(1.0, -w * k as f64)).sum();
    s * (2.0 / n)
}

fn mean(x: &[f64]) -> f64 {
    x.iter().sum::<f64>() / x.len() as f64
}

// ---------------------------------------------------------------- models

#[test]
fn random_models_have_unit_dc_gain_and_realistic_modes() {
    let p = SimParams::default();
    for seed in 0..200u64 {
        let d = MultiAxisDynamometer::random(seed, &p);
        for (a, ax) in d.axes.iter().enumerate() {
            let g0 = ax.frf(0.0);
            assert!((g0.re - 1.0).abs() < 1e-12 && g0.im.abs() < 1e-12, "seed {seed} axis {a}: G(0) = {g0}");
            assert!((ax.dc_gain() - 1.0).abs() < 1e-12);
            let main = ax.main_mode();
            let band = if a == 2 { (3000.0, 3500.0) } else { (2000.0, 2600.0) };
            assert!(main.fn_hz >= band.0 && main.fn_hz <= band.1, "seed {seed} axis {a}: main mode {main:?}");
            assert!(main.residue >= 0.6 - 1e-12, "seed {seed} axis {a}: main residue {}", main.residue);
            let machine: Vec<_> = ax.modes.iter().filter(|m| m.fn_hz < 1000.0).collect();
            assert!((1..=3).contains(&machine.len()), "seed {seed} axis {a}: {} machine modes", machine.len());
            for m in &ax.modes {
                assert!(m.zeta >= 0.01 && m.zeta <= 0.06, "{m:?}");
                if m.fn_hz < 1000.0 {
                    assert!(m.fn_hz >= 100.0 && m.fn_hz <= 700.0 && m.residue.abs() <= 0.15 + 1e-12, "{m:?}");
                } else {
                    assert!(m.fn_hz >= 2000.0 && m.fn_hz <= 5000.0, "{m:?}");
                }
            }
            // The time response is the sum of the modal step responses and
            // tends to the static force (unit DC gain).
            let y = ax.measure(&vec![10.0; 51_200], 51_200.0);
            let last = 51_199;
            let expect: f64 = ax.modes.iter().map(|m| 10.0 * step_analytic(m, last as f64 / 51_200.0)).sum();
            assert!((y[last] - expect).abs() < 1e-9, "seed {seed} axis {a}: step end {} vs {expect}", y[last]);
            assert!((y[last] - 10.0).abs() < 0.05, "seed {seed} axis {a}: step end {}", y[last]);
        }
    }
    // Different seeds give different models.
    assert_ne!(MultiAxisDynamometer::random(1, &p), MultiAxisDynamometer::random(2, &p));
}

#[test]
fn explicit_modes_are_checked() {
    assert!(Dynamometer::from_modes(vec![mode(2500.0, 0.03, 0.9)]).is_err(), "DC gain 0.9 accepted");
    assert!(Dynamometer::from_modes(vec![mode(2500.0, 1.2, 1.0)]).is_err(), "zeta > 1 accepted");
    assert!(Dynamometer::from_modes(vec![mode(-5.0, 0.03, 1.0)]).is_err());
    let d = Dynamometer::from_modes_normalized(vec![mode(2500.0, 0.03, 1.8), mode(300.0, 0.02, 0.2)]).unwrap();
    assert!((d.dc_gain() - 1.0).abs() < 1e-15);
    assert_eq!(d.modes[0].fn_hz, 300.0, "modes sorted by frequency");
}

/// Analytic unit-step response of r·ω²/(s²+2ζωs+ω²).
fn step_analytic(m: &Mode, t: f64) -> f64 {
    let w = 2.0 * PI * m.fn_hz;
    let wd = w * (1.0 - m.zeta * m.zeta).sqrt();
    let s = m.zeta * w;
    m.residue * (1.0 - (-s * t).exp() * ((wd * t).cos() + s / wd * (wd * t).sin()))
}

#[test]
fn step_response_matches_continuous_model() {
    // A dynamometer mode at the output rate, and a slow machine mode at a high
    // rate (small ωh: the series branch of the exponential integrals).
    for (m, fs) in
        [(mode(2500.0, 0.03, 1.0), 51_200.0), (mode(150.0, 0.02, 1.0), 409_600.0), (mode(4800.0, 0.01, 1.0), 20_000.0)]
    {
        let d = Dynamometer::from_modes(vec![m]).unwrap();
        let n = (0.05 * fs) as usize;
        let u = vec![1.0; n];
        for hold in [Hold::Foh, Hold::Zoh] {
            let y = d.measure_with(&u, fs, hold);
            let err = (0..n).map(|k| (y[k] - step_analytic(&m, k as f64 / fs)).abs()).fold(0.0, f64::max);
            assert!(err < 1e-10, "{m:?} fs {fs} {hold:?}: max step error {err}");
        }
    }
    // Two modes superpose (negative residue included).
    let ms = [mode(2300.0, 0.025, 1.1), mode(420.0, 0.04, -0.1)];
    let d = Dynamometer::from_modes(ms.to_vec()).unwrap();
    let fs = 51_200.0;
    let y = d.measure(&vec![1.0; 4096], fs);
    let err = (0..4096)
        .map(|k| (y[k] - ms.iter().map(|m| step_analytic(m, k as f64 / fs)).sum::<f64>()).abs())
        .fold(0.0, f64::max);
    assert!(err < 1e-10, "two-mode step error {err}");
}

#[test]
fn sinusoid_response_matches_frf_amplitude_and_phase() {
    let d = Dynamometer::from_modes(vec![mode(2400.0, 0.03, 0.93), mode(350.0, 0.04, 0.07)]).unwrap();
    let fs = 51_200.0;
    // fs/f0 = 51.2, 25.6, 128, 16 samples: 1280 samples hold whole periods.
    for f0 in [1000.0, 2000.0, 400.0, 3200.0] {
        let n = 51_200;
        let w = 2.0 * PI * f0;
        let u: Vec<f64> = (0..n).map(|k| (w * k as f64 / fs).sin()).collect();
        let g = d.frf(f0);
        // The model sees the samples interpolated: linear (FOH), whose spectrum
        // is the sampled one × sinc²(πf/fs), or held (ZOH): × sinc(πf/fs)·e^{-jπf/fs}.
        // Sampling the output at fs folds every image f0 + m·fs back onto f0.
        let sinc = |f: f64| {
            let x = PI * f / fs;
            if x == 0.0 {
                1.0
            } else {
                x.sin() / x
            }
        };
        let folded = |hold: Hold| -> Complex64 {
            (-400i32..=400)
                .map(|m| {
                    let f = f0 + m as f64 * fs;
                    let t = match hold {
                        Hold::Foh => Complex64::new(sinc(f).powi(2), 0.0),
                        Hold::Zoh => Complex64::from_polar(sinc(f), -PI * f / fs),
                    };
                    d.frf(f) * t
                })
                .sum()
        };
        for hold in [Hold::Foh, Hold::Zoh] {
            let y = d.measure_with(&u, fs, hold);
            // Steady state: the slowest transient (350 Hz, ζ 0.04) is e^-44 after 0.5 s.
            let tail = &y[n - 25_600..];
            let t0 = (n - 25_600) as f64 / fs;
            // sin input → y = Im(G·e^{jωt}); project on e^{jωt} starting at t0.
            let c = dft_amp(tail, fs, f0) * Complex64::from_polar(1.0, w * t0);
            // For y = A sin(ωt+φ): projection = -j·A·e^{jφ}.
            let measured = c * Complex64::new(0.0, 1.0);
            let expected = folded(hold);
            let rel = (measured - expected).norm() / expected.norm();
            assert!(rel < 1e-8, "f0 {f0} {hold:?}: measured {measured} expected {expected} (rel err {rel})");
            // And the physical claim: amplitude |G| and phase arg G within the
            // interpolation error of the sampled input.
            if hold == Hold::Foh {
                assert!((measured.norm() / g.norm() - 1.0).abs() < 0.025, "f0 {f0}: |G| mismatch");
                assert!((measured.arg() - g.arg()).abs() < 1e-5, "f0 {f0}: phase mismatch");
            }
        }
    }
}

// ---------------------------------------------------------------- impact test

fn test_dyno() -> Dynamometer {
    Dynamometer::from_modes(vec![mode(400.0, 0.03, 0.08), mode(2400.0, 0.03, 0.92)]).unwrap()
}

#[test]
fn impact_frf_equals_true_frf_within_noise_where_coherent() {
    let d = test_dyno();
    let p = ImpactParams::default();
    let a = impact_test(&d, 4097, 1.0, 7, &p);
    assert_eq!(a.frf.len(), 4097);
    let coh = a.coherence.as_ref().unwrap();
    assert!(coh.iter().all(|&c| (0.0..=1.0).contains(&c)));
    let (mut checked, mut outside) = (0usize, 0usize);
    for k in 1..4097 {
        if coh[k] > 0.99 {
            let g = d.frf(k as f64);
            let e = (a.frf[k] - g).norm() / g.norm();
            checked += 1;
            if e > 5.0 * h1_random_error(coh[k], p.n_impacts) {
                outside += 1;
            }
        }
    }
    assert!(checked > 3000, "only {checked} coherent lines");
    assert!((outside as f64) < 0.005 * checked as f64, "{outside} of {checked} coherent lines outside 5σ");
    // Flat band: sub-percent agreement.
    let rms: f64 =
        ((100..2000).map(|k| ((a.frf[k] - d.frf(k as f64)).norm() / d.frf(k as f64).norm()).powi(2)).sum::<f64>()
            / 1900.0)
            .sqrt();
    let bound = 1.5 * p.output_noise_rel / (p.n_impacts as f64).sqrt();
    assert!(rms < bound, "rms relative error {rms} > {bound}");
    // Without noise the estimate is the true FRF and the coherence is 1.
    let quiet = ImpactParams { output_noise_rel: 0.0, input_noise_rel: 0.0, ..p.clone() };
    let q = impact_test(&d, 4097, 1.0, 7, &quiet);
    for k in 0..4097 {
        assert!((q.frf[k] - d.frf(k as f64)).norm() < 1e-12 * d.frf(k as f64).norm().max(1.0));
        assert!((q.coherence.as_ref().unwrap()[k] - 1.0).abs() < 1e-12);
    }
}

#[test]
fn impact_coherence_drops_where_hammer_spectrum_falls_and_at_dc() {
    let d = test_dyno();
    // A soft tip: cutoff 1.5 kHz, 4th order, so that 3.6-4.1 kHz has partial
    // (not zero) coherence to compare with the theory.
    let p =
        ImpactParams { hammer_cutoff_hz: 1500.0, hammer_order: 4.0, output_noise_rel: 0.02, ..ImpactParams::default() };
    let a = impact_test(&d, 4097, 1.0, 11, &p);
    let coh = a.coherence.as_ref().unwrap();
    let band = |lo: usize, hi: usize| mean(&coh[lo..hi]);
    let low = band(100, 1000);
    let high = band(3600, 4097);
    assert!(low > 0.99, "coherence in the flat band {low}");
    assert!(high < 0.8, "coherence above the hammer cutoff {high}");
    // Consistent with the simulated noise: γ² = S²|G|²/(S²|G|² + σ²) (+ the
    // small-sample bias of 7 averages).
    let theory: Vec<f64> = (3600..4097)
        .map(|k| {
            let s = p.hammer_spectrum(k as f64) * d.frf(k as f64).norm();
            s * s / (s * s + p.output_noise_rel.powi(2))
        })
        .collect();
    assert!((high - mean(&theory)).abs() < 0.12, "coherence {high} vs theory {}", mean(&theory));
    // DC line and the lowest lines: charge-amplifier drift.
    assert!(coh[0] < 0.5, "DC coherence {}", coh[0]);
    assert!(mean(&coh[1..4]) < 0.9, "lowest lines coherence {}", mean(&coh[1..4]));
    // Default hammer: a milder but visible drop towards 4 kHz.
    let a = impact_test(&d, 4097, 1.0, 11, &ImpactParams::default());
    let coh = a.coherence.as_ref().unwrap();
    assert!(mean(&coh[3900..4097]) < mean(&coh[500..1500]) - 0.01);
    // Anti-resonance (negative machine residue): coherence dips there.
    let anti = Dynamometer::from_modes(vec![mode(500.0, 0.02, -0.1), mode(2400.0, 0.03, 1.1)]).unwrap();
    let kmin = (150..500).min_by(|&i, &j| anti.frf(i as f64).norm().total_cmp(&anti.frf(j as f64).norm())).unwrap();
    let a = impact_test(&anti, 4097, 1.0, 3, &ImpactParams::default());
    let coh = a.coherence.as_ref().unwrap();
    let band = mean(&coh[1500..2000]);
    assert!(1.0 - coh[kmin] > 3.0 * (1.0 - band), "no dip at the anti-resonance {kmin} Hz: {} vs {band}", coh[kmin]);
}

// ---------------------------------------------------------------- milling

fn simple_cut() -> MillingParams {
    MillingParams {
        spindle_rpm: 6000.0, // 100 rev/s: 512 samples per revolution at 51.2 kHz
        teeth: 2,
        diameter_mm: 10.0,
        helix_deg: 0.0,
        axial_depth_mm: 2.0,
        radial_depth_mm: 10.0, // slot
        mode: MillingMode::Down,
        feed_per_tooth_mm: 0.1,
        kt: 2000.0,
        kr: 800.0,
        ka: 300.0,
        kte: 25.0,
        kre: 30.0,
        kae: 3.0,
        runout_mm: 0.0,
        runout_angle_deg: 0.0,
        ramp_in_revs: 0.0,
        axial_slices: 1,
        chatter: None,
    }
}

/// Average forces per revolution, Altintas eq. (2.47).
fn altintas_mean(p: &MillingParams) -> [f64; 3] {
    let r = p.radial_depth_mm / p.diameter_mm;
    let (st, ex) = match p.mode {
        MillingMode::Up => (0.0, (1.0 - 2.0 * r).acos()),
        MillingMode::Down => ((2.0 * r - 1.0).acos(), PI),
    };
    let (z, ap, c) = (p.teeth as f64, p.axial_depth_mm, p.feed_per_tooth_mm);
    let fx = |f: f64| {
        z * ap * c / (8.0 * PI) * (p.kt * (2.0 * f).cos() - p.kr * (2.0 * f - (2.0 * f).sin()))
            + z * ap / (2.0 * PI) * (-p.kte * f.sin() + p.kre * f.cos())
    };
    let fy = |f: f64| {
        z * ap * c / (8.0 * PI) * (p.kt * (2.0 * f - (2.0 * f).sin()) + p.kr * (2.0 * f).cos())
            - z * ap / (2.0 * PI) * (p.kte * f.cos() + p.kre * f.sin())
    };
    let fz = |f: f64| z * ap / (2.0 * PI) * (-p.ka * c * f.cos() + p.kae * f);
    [fx(ex) - fx(st), fy(ex) - fy(st), fz(ex) - fz(st)]
}

#[test]
fn milling_mean_force_matches_altintas_closed_form() {
    let fs = 51_200.0;
    let n = 512 * 10; // ten revolutions
    let slot = simple_cut();
    let half_down = MillingParams { teeth: 3, radial_depth_mm: 3.0, helix_deg: 30.0, axial_slices: 64, ..simple_cut() };
    let half_up = MillingParams { mode: MillingMode::Up, teeth: 4, radial_depth_mm: 4.0, ..simple_cut() };
    for p in [slot, half_down, half_up] {
        let f = milling_force(&p, fs, n);
        let expect = altintas_mean(&p);
        let scale = expect.iter().fold(0.0f64, |a, v| a.max(v.abs()));
        for a in 0..3 {
            let m = mean(&f[a]);
            assert!(
                (m - expect[a]).abs() < 5e-3 * scale,
                "{:?} Z{} ae {}: axis {a} mean {m} expected {}",
                p.mode,
                p.teeth,
                p.radial_depth_mm,
                expect[a]
            );
        }
    }
}

#[test]
fn milling_tooth_passing_harmonics_match_closed_form() {
    // Two straight teeth in a slot, no edge forces: one tooth always engaged,
    // Fx = -(ap c/2)(Kr + Kt sin 2φ - Kr cos 2φ), Fy = (ap c/2)(Kt - Kt cos 2φ - Kr sin 2φ),
    // Fz = ap Ka c |sin φ| (a rectified sine: mean 2/π, TPF amplitude 4/(3π)).
    let p = MillingParams { kte: 0.0, kre: 0.0, kae: 0.0, ..simple_cut() };
    let fs = 51_200.0;
    let f = milling_force(&p, fs, 5120);
    let tpf = p.tooth_passing_hz();
    assert_eq!(tpf, 200.0);
    let (ap, c) = (p.axial_depth_mm, p.feed_per_tooth_mm);
    let amp_xy = ap * c / 2.0 * (p.kt.powi(2) + p.kr.powi(2)).sqrt();
    for a in 0..2 {
        let h1 = dft_amp(&f[a], fs, tpf).norm();
        assert!((h1 - amp_xy).abs() < 1e-3 * amp_xy, "axis {a}: TPF amplitude {h1}, expected {amp_xy}");
        for k in 2..6 {
            let hk = dft_amp(&f[a], fs, k as f64 * tpf).norm();
            assert!(hk < 2e-3 * amp_xy, "axis {a}: harmonic {k} = {hk}");
        }
    }
    assert!((mean(&f[0]) + ap * c * p.kr / 2.0).abs() < 1e-3 * amp_xy);
    assert!((mean(&f[1]) - ap * c * p.kt / 2.0).abs() < 1e-3 * amp_xy);
    let fz0 = ap * p.ka * c;
    assert!((mean(&f[2]) - 2.0 / PI * fz0).abs() < 1e-3 * fz0);
    assert!((dft_amp(&f[2], fs, tpf).norm() - 4.0 / (3.0 * PI) * fz0).abs() < 1e-3 * fz0);
    assert!((dft_amp(&f[2], fs, 2.0 * tpf).norm() - 4.0 / (15.0 * PI) * fz0).abs() < 1e-3 * fz0);
    // Four straight teeth in a slot: the sin 2φ terms cancel, the force is constant.
    let p4 = MillingParams { teeth: 4, ..p.clone() };
    let f4 = milling_force(&p4, fs, 5120);
    for a in 0..2 {
        assert!(dft_amp(&f4[a], fs, p4.tooth_passing_hz()).norm() < 1e-3 * amp_xy, "Z=4 slot axis {a} not constant");
    }
    // Nothing below the TPF without runout: no spindle-frequency content.
    assert!(dft_amp(&f[0], fs, p.spindle_hz()).norm() < 1e-9 * amp_xy);
}

#[test]
fn runout_creates_a_spindle_frequency_component() {
    let fs = 51_200.0;
    let base =
        MillingParams { teeth: 4, radial_depth_mm: 3.0, helix_deg: 30.0, axial_slices: 32, ..MillingParams::default() };
    let base = MillingParams { spindle_rpm: 6000.0, ramp_in_revs: 0.0, runout_mm: 0.0, ..base };
    let with = MillingParams { runout_mm: 0.01, runout_angle_deg: 20.0, ..base.clone() };
    let n = 5120;
    let f0 = milling_force(&base, fs, n);
    let f1 = milling_force(&with, fs, n);
    let sp = base.spindle_hz();
    for a in 0..3 {
        let scale = dft_amp(&f0[a], fs, base.tooth_passing_hz()).norm() + mean(&f0[a]).abs();
        let without = dft_amp(&f0[a], fs, sp).norm();
        let with_ro = dft_amp(&f1[a], fs, sp).norm();
        assert!(without < 1e-9 * scale, "axis {a}: spindle component {without} without runout");
        assert!(with_ro > 0.02 * scale, "axis {a}: spindle component {with_ro} with runout (scale {scale})");
    }
    // The mean force is (nearly) unchanged: runout redistributes the chip load.
    let e = altintas_mean(&base);
    assert!((mean(&f1[0]) - e[0]).abs() < 0.05 * e[0].abs().max(e[1].abs()));
}

#[test]
fn chatter_adds_a_non_harmonic_growing_component_and_ramp_in_starts_at_zero() {
    let fs = 51_200.0;
    let n = 51_200;
    let base = MillingParams { spindle_rpm: 6000.0, runout_mm: 0.0, ..MillingParams::default() };
    let fc = 1435.0; // not a multiple of the 400 Hz TPF; whole periods in 0.2 s windows
    let chat = MillingParams {
        chatter: Some(Chatter { freq_hz: fc, amplitude_mm: 0.01, onset_s: 0.4, growth_s: 0.05 }),
        ..base.clone()
    };
    let f0 = milling_force(&base, fs, n);
    let f1 = milling_force(&chat, fs, n);
    // Ramp-in: zero force at t = 0, full force after the ramp.
    assert_eq!(f0[0][0], 0.0);
    assert!(f0[1][..10].iter().all(|v| v.abs() < 1.0));
    let early = &f1[0][10_240..20_480]; // 0.2-0.4 s: chatter still small
    let late = &f1[0][40_960..51_200]; // 0.8-1.0 s: grown
    let a_early = dft_amp(early, fs, fc).norm();
    let a_late = dft_amp(late, fs, fc).norm();
    let a_none = dft_amp(&f0[0][40_960..51_200], fs, fc).norm();
    assert!(a_late > 5.0, "chatter component {a_late} N");
    assert!(a_late > 5.0 * a_early, "chatter does not grow: {a_early} -> {a_late}");
    assert!(a_none < 1e-6 * a_late.max(1.0), "component at the chatter frequency without chatter: {a_none}");
}

// ---------------------------------------------------------------- measurement

#[test]
fn measured_minus_true_has_variance_r_for_quasi_static_force() {
    let p = SimParams::default();
    let d = MultiAxisDynamometer::random(5, &p);
    let fs = p.fs_hz;
    let n = 102_400;
    // 100 N raised cosine at 0.5 Hz starting from rest: |G - 1| ≈ 1e-6 there.
    let force: Vec<f64> = (0..n).map(|k| 50.0 * (1.0 - (2.0 * PI * 0.5 * k as f64 / fs).cos())).collect();
    for axis in 0..3 {
        let clean = d.axis(axis).measure(&force, fs);
        let meas = p.measurement.apply(&clean, 100 + axis as u64);
        let resid: Vec<f64> = meas.iter().zip(&force).map(|(m, f)| m - f).collect();
        let mu = mean(&resid);
        let var = resid.iter().map(|r| (r - mu).powi(2)).sum::<f64>() / (n - 1) as f64;
        let expect = p.measurement.expected_idle_variance();
        assert!(mu.abs() < 0.005, "axis {axis}: mean residual {mu}");
        assert!((var / expect - 1.0).abs() < 0.03, "axis {axis}: residual variance {var}, expected {expect}");
        assert!((var / 0.05 - 1.0).abs() < 0.04, "axis {axis}: residual variance {var} vs R = 0.05");
    }
    // Quantization: values are multiples of the LSB, saturated at the rails.
    let m = MeasurementParams::default();
    let lsb = m.lsb_n();
    assert!((lsb - 4000.0 / 65536.0).abs() < 1e-15);
    for v in [0.3, -17.77, 1999.9, 2500.0, -2500.0] {
        let q = m.quantize(v);
        assert!(((q / lsb).round() - q / lsb).abs() < 1e-9);
        assert!(q <= 2000.0 - lsb + 1e-9 && q >= -2000.0);
    }
    assert_eq!(m.quantize(2500.0), (32767.0) * lsb);
}

#[test]
fn simulate_is_deterministic_and_consistent() {
    let mut p = SimParams { duration_s: 0.2, idle_duration_s: 0.5, ..SimParams::default() };
    p.impact.n_lines = 513;
    p.impact.df_hz = 8.0;
    let a = simulate(42, &p).unwrap();
    let b = simulate(42, &p).unwrap();
    let c = simulate(43, &p).unwrap();
    assert_eq!(a.dyno, b.dyno);
    assert_eq!(a.frf, b.frf);
    assert_eq!(a.truth, b.truth);
    assert_eq!(a.measured, b.measured);
    assert_eq!(a.idle, b.idle);
    assert_ne!(a.dyno, c.dyno);
    assert_ne!(a.measured, c.measured);
    assert_ne!(a.idle, c.idle);
    assert_eq!(a.truth, c.truth, "the cut does not depend on the seed");
    // Shapes and time base.
    assert_eq!(a.t_s.len(), 10_240);
    assert_eq!(a.frf.freq_hz.len(), 513);
    assert_eq!(a.frf.axes.iter().map(|x| x.axis).collect::<Vec<_>>(), vec![0, 1, 2]);
    for ax in 0..3 {
        assert_eq!(a.truth[ax].len(), 10_240);
        assert_eq!(a.measured[ax].len(), 10_240);
        assert_eq!(a.idle[ax].len(), 25_600);
        // Idle record: variance ≈ R (what a design tool estimates).
        let v = a.idle[ax].iter().map(|x| x * x).sum::<f64>() / a.idle[ax].len() as f64;
        assert!((v / p.measurement.expected_idle_variance() - 1.0).abs() < 0.05, "idle variance {v}");
        // measured - clean is the noise.
        let r: Vec<f64> = a.measured[ax].iter().zip(&a.clean[ax]).map(|(m, c)| m - c).collect();
        let v = r.iter().map(|x| x * x).sum::<f64>() / r.len() as f64;
        assert!((v / p.measurement.expected_idle_variance() - 1.0).abs() < 0.06, "measurement noise variance {v}");
    }
    // The decimated pipeline agrees with measuring the fs-rate truth directly
    // where the force is smooth at fs (low-pass content dominates): a loose check
    // that truth and measured are aligned in time.
    let direct = a.dyno.axis(0).measure(&a.truth[0], p.fs_hz);
    let diff = direct.iter().zip(&a.clean[0]).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max);
    let peak = a.truth[0].iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(diff < 0.05 * peak, "pipeline vs direct: {diff} N of {peak} N");
    // The truth has the tooth-passing content of the cut.
    let tpf = p.milling.tooth_passing_hz();
    assert!((tpf - 275.0).abs() < 1e-9);
}

// ---------------------------------------------------------------- CLI files

#[test]
fn run_writes_all_files_readable_by_the_io_layer() {
    use clap::Parser;
    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        args: dynocomp::cli::simulate::SimulateArgs,
    }
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("sim");
    let cli = Cli::parse_from([
        "simulate",
        "--dyno",
        "diagonal",
        "--out",
        out.to_str().unwrap(),
        "--seed",
        "9",
        "--duration",
        "0.1",
        "--idle-duration",
        "0.2",
        "--spindle-rpm",
        "9000",
        "--teeth",
        "3",
        "--chatter-hz",
        "1710",
        "--frf-lines",
        "1025",
        "--frf-df",
        "4",
    ]);
    dynocomp::cli::simulate::run(&cli.args).unwrap();
    for f in ["frf.uff", "frf.csv", "measured.csv", "true_force.csv", "idle.csv", "truth.json"] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    let params = cli.args.params().unwrap();
    let sim = simulate(9, &params).unwrap();
    // FRF files read back to the simulated impact test.
    for f in ["frf.uff", "frf.csv"] {
        let frf = dynocomp::io::read_frf(&out.join(f)).unwrap();
        assert_eq!(frf.freq_hz.len(), 1025, "{f}");
        assert_eq!(frf.axes.len(), 3, "{f}");
        for (a, b) in frf.axes.iter().zip(&sim.frf.axes) {
            assert_eq!(a.axis, b.axis);
            let err = a.frf.iter().zip(&b.frf).map(|(x, y)| (x - y).norm() / y.norm().max(1e-3)).fold(0.0, f64::max);
            assert!(err < 1e-4, "{f}: axis {} FRF differs by {err}", a.axis);
            assert!(a.coherence.is_some(), "{f}: coherence lost");
        }
    }
    // Signal files read back to the records.
    let rd = |f: &str| dynocomp::io::signal_csv::read_signal_csv(&out.join(f)).unwrap();
    let (m, t, i) = (rd("measured.csv"), rd("true_force.csv"), rd("idle.csv"));
    assert_eq!(m.len(), 5120);
    assert_eq!(i.len(), 10_240);
    let (fs, _) = m.sample_rate_from_time().unwrap();
    assert!((fs - 51_200.0).abs() < 1e-3 * 51_200.0);
    for a in 0..3 {
        let close = |x: &[f64], y: &[f64]| x.iter().zip(y).all(|(p, q)| (p - q).abs() <= 1e-6 * q.abs().max(1.0));
        assert!(close(m.channel(a).unwrap(), &sim.measured[a]), "measured axis {a}");
        assert!(close(t.channel(a).unwrap(), &sim.truth[a]), "truth axis {a}");
        assert!(close(i.channel(a).unwrap(), &sim.idle[a]), "idle axis {a}");
    }
    // truth.json names the seed, TPF and modes.
    let j: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(out.join("truth.json")).unwrap()).unwrap();
    assert_eq!(j["seed"], 9);
    assert!((j["tooth_passing_hz"].as_f64().unwrap() - 450.0).abs() < 1e-9);
    assert_eq!(j["axes"].as_array().unwrap().len(), 3);
    let modes: Vec<Mode> = serde_json::from_value(j["axes"][2]["modes"].clone()).unwrap();
    // (serde_json without `float_roundtrip` may parse the last ulp differently)
    assert_eq!(modes.len(), sim.dyno.axes[2].modes.len());
    for (a, b) in modes.iter().zip(&sim.dyno.axes[2].modes) {
        for (x, y) in [(a.fn_hz, b.fn_hz), (a.zeta, b.zeta), (a.residue, b.residue)] {
            assert!((x - y).abs() <= 1e-14 * y.abs(), "{a:?} vs {b:?}");
        }
    }
    let back: SimParams = serde_json::from_value(j["params"].clone()).unwrap();
    assert_eq!(back, params);
    assert!((j["params"]["milling"]["chatter"]["freq_hz"].as_f64().unwrap() - 1710.0).abs() < 1e-12);
    // The acquisition chain is recorded (default: the ideal brick wall at 0.45 fs).
    assert_eq!(j["anti_alias"], "ideal");
    assert!((j["brick_wall_hz"].as_f64().unwrap() - 0.45 * 51_200.0).abs() < 1e-9);
    assert_eq!(j["params"]["anti_alias"]["kind"], "ideal");
}

// ---------------------------------------------------------------- acquisition chain

const CHAIN_FS: f64 = 10_240.0;
const CHAIN_OS: usize = 8;
const CHAIN_N: usize = 10_240; // 1 s: the middle half holds whole periods of any even f0

/// A mode near Nyquist at the lowest DAQ rate, and a machine mode.
fn chain_dyno() -> Dynamometer {
    Dynamometer::from_modes(vec![mode(300.0, 0.04, 0.1), mode(3000.0, 0.03, 0.9)]).unwrap()
}

/// 4th-order Butterworth written from its normalized polynomial (independent of
/// the simulator's pole formula): B(s) = 1/(p⁴ + a p³ + b p² + a p + 1), p = s/ωc.
fn butterworth4(f_hz: f64, fc_hz: f64) -> Complex64 {
    let (a, b) = (2.613_125_929_752_753, 3.414_213_562_373_095); // 2cos(π/8)+2cos(3π/8), 2+√2
    let p = Complex64::new(0.0, f_hz / fc_hz);
    1.0 / (p.powi(4) + a * p.powi(3) + b * p * p + a * p + 1.0)
}

/// A unit sine at `f0` Hz, faded in over 0.1 s (no onset splatter), at
/// fs·os, through `chain`: (truth, clean) at fs.
fn sine_through(chain: AntiAlias, f0: f64) -> (Vec<f64>, Vec<f64>) {
    let ff = CHAIN_FS * CHAIN_OS as f64;
    let fine: Vec<f64> = (0..chain.fine_len(CHAIN_N, CHAIN_OS))
        .map(|k| {
            let t = k as f64 / ff;
            let env = if t < 0.1 { 0.5 * (1.0 - (PI * t / 0.1).cos()) } else { 1.0 };
            env * (2.0 * PI * f0 * t).sin()
        })
        .collect();
    measure_decimated(&chain_dyno(), &chain, &fine, CHAIN_FS, CHAIN_OS, CHAIN_N)
}

/// A·e^{jφ} of the component A·sin(2πf0·t + φ) of the middle half of `x`.
fn phasor(x: &[f64], f0: f64) -> Complex64 {
    let k0 = CHAIN_N / 4;
    let t0 = k0 as f64 / CHAIN_FS;
    dft_amp(&x[k0..k0 + CHAIN_N / 2], CHAIN_FS, f0)
        * Complex64::from_polar(1.0, 2.0 * PI * f0 * t0)
        * Complex64::new(0.0, 1.0)
}

fn rms_mid(x: &[f64]) -> f64 {
    let m = &x[CHAIN_N / 4..3 * CHAIN_N / 4];
    (m.iter().map(|v| v * v).sum::<f64>() / m.len() as f64).sqrt()
}

#[test]
fn a_sine_below_the_brick_wall_passes_with_its_analytic_response() {
    let d = chain_dyno();
    let bw = Butterworth { order: 4, fc_hz: 4000.0 };
    let ff = CHAIN_FS * CHAIN_OS as f64;
    // The continuous force is the linear interpolant of its fine samples: its
    // fundamental is the sine's × sinc²(πf0/f_fine).
    let sinc2 = |f: f64| ((PI * f / ff).sin() / (PI * f / ff)).powi(2);
    for f0 in [1000.0, 3000.0, 4400.0] {
        for (chain, b) in
            [(AntiAlias::Ideal, Complex64::new(1.0, 0.0)), (AntiAlias::Butterworth(bw), butterworth4(f0, bw.fc_hz))]
        {
            let (truth, clean) = sine_through(chain, f0);
            let t = phasor(&truth, f0);
            assert!((t - sinc2(f0)).norm() < 1e-6, "{chain} f0 {f0}: truth phasor {t}, expected {}", sinc2(f0));
            let expected = d.frf(f0) * b;
            let got = phasor(&clean, f0) / t;
            let rel = (got - expected).norm() / expected.norm();
            assert!(rel < 1e-4, "{chain} f0 {f0}: measured/true {got}, analytic G·B {expected} (rel err {rel})");
        }
        // The front end is really there: G alone misses it by far near fc.
        let (truth, clean) = sine_through(AntiAlias::Butterworth(bw), f0);
        let off = (phasor(&clean, f0) / phasor(&truth, f0) / d.frf(f0) - 1.0).norm();
        assert!(off > 0.02, "f0 {f0}: Butterworth chain indistinguishable from G ({off})");
        // Negative control: plain decimation relates truth samples and
        // measurement by G·sinc², not G, so the 1e-4 check would fail.
        let (truth, clean) = sine_through(AntiAlias::None, f0);
        let rel = (phasor(&clean, f0) / phasor(&truth, f0) / d.frf(f0) - 1.0).norm();
        if f0 > 2000.0 {
            assert!(rel > 1e-3, "f0 {f0}: undecimated chain matched G to {rel}");
        }
    }
    // The magnitude of the independent Butterworth is the textbook one.
    for f in [500.0, 4000.0, 9000.0] {
        let m2 = butterworth4(f, 4000.0).norm_sqr();
        assert!((m2 - 1.0 / (1.0 + (f / 4000.0f64).powi(8))).abs() < 1e-12);
        assert!((bw.frf(f) - butterworth4(f, 4000.0)).norm() < 1e-12, "simulator's B at {f} Hz");
    }
}

#[test]
fn a_sine_above_the_brick_wall_leaves_no_trace_but_aliases_without_it() {
    // 0.45 fs = 4608 Hz; 5000 Hz is 8.5 % above it (below Nyquist), 7000 and
    // 9000 Hz fold to 3240 and 1240 Hz without a filter.
    for f0 in [5000.0, 7000.0, 9000.0] {
        for chain in [AntiAlias::Ideal, AntiAlias::Butterworth(Butterworth { order: 4, fc_hz: 12_000.0 })] {
            let (truth, clean) = sine_through(chain, f0);
            assert!(rms_mid(&truth) < 1e-5, "{chain} f0 {f0}: truth keeps {:.2e} RMS", rms_mid(&truth));
            assert!(rms_mid(&clean) < 1e-5, "{chain} f0 {f0}: measurement keeps {:.2e} RMS", rms_mid(&clean));
        }
        // Negative control: without the filter the sine (or its alias) stays
        // in both records at full size.
        let (truth, clean) = sine_through(AntiAlias::None, f0);
        let alias = if f0 < CHAIN_FS / 2.0 { f0 } else { CHAIN_FS - f0 };
        assert!(
            (phasor(&truth, alias).norm() - 1.0).abs() < 0.05,
            "f0 {f0}: alias at {alias} Hz {}",
            phasor(&truth, alias).norm()
        );
        assert!(rms_mid(&clean) > 0.05, "f0 {f0}: measurement alias {}", rms_mid(&clean));
    }
}

#[test]
fn the_impact_test_runs_through_the_analog_front_end() {
    let d = chain_dyno();
    let bw = Butterworth { order: 4, fc_hz: 2500.0 };
    let dyno = MultiAxisDynamometer { axes: [d.clone(), d.clone(), d.clone()] };
    // An FRF to 8 kHz at fs = 10.24 kHz, as impact analyzers measure.
    let mut p = SimParams {
        fs_hz: CHAIN_FS,
        duration_s: 0.05,
        idle_duration_s: 0.0,
        anti_alias: AntiAlias::Butterworth(bw),
        ..Default::default()
    };
    p.impact.n_lines = 4001;
    p.impact.df_hz = 2.0;
    p.impact.hammer_cutoff_hz = 9000.0;
    let s = dynocomp::simulate::simulate_with(3, &p, dyno).unwrap();
    let ax = s.frf.axis(0).unwrap();
    let coh = ax.coherence.as_ref().unwrap();
    let (mut with_b, mut without_b, mut n) = (0.0, 0.0, 0usize);
    for k in 50..4001 {
        let f = s.frf.freq_hz[k];
        if coh[k] > 0.99 && (1500.0..6000.0).contains(&f) {
            let g = d.frf(f);
            let gb = g * butterworth4(f, bw.fc_hz);
            with_b += ((ax.frf[k] - gb).norm() / gb.norm()).powi(2);
            without_b += ((ax.frf[k] - g).norm() / gb.norm()).powi(2);
            n += 1;
        }
    }
    assert!(n > 500, "only {n} coherent lines in 1.5-6 kHz");
    let (with_b, without_b) = ((with_b / n as f64).sqrt(), (without_b / n as f64).sqrt());
    assert!(with_b < 0.03, "H1 vs G·B: rms relative error {with_b}");
    // Negative control: the bare G does not fit the measured FRF.
    assert!(without_b > 0.3, "H1 vs bare G: {without_b}");
}

#[test]
fn anti_alias_option_parses_and_rejects_bad_values() {
    assert_eq!("ideal".parse::<AntiAlias>().unwrap(), AntiAlias::Ideal);
    assert_eq!("none".parse::<AntiAlias>().unwrap(), AntiAlias::None);
    assert_eq!(
        "butterworth:4:12000".parse::<AntiAlias>().unwrap(),
        AntiAlias::Butterworth(Butterworth { order: 4, fc_hz: 12_000.0 })
    );
    for bad in [
        "",
        "brick",
        "butterworth:4",
        "butterworth:x:12000",
        "butterworth:0:12000",
        "butterworth:4:-1",
        "butterworth:4:nan",
    ] {
        let e = bad.parse::<AntiAlias>().unwrap_err().to_string();
        assert!(e.contains("--anti-alias") || e.contains("anti-alias"), "{bad:?}: {e}");
    }
}

// ---------------------------------------------------------------- multi-rate harness

#[test]
fn harness_noise_floor_matches_the_analytic_integral() {
    use dynocomp::eval::rates::noise_floor;
    // G = 1: sqrt(R·2·band/fs)/std.
    let (r, fs, band, std) = (0.05, 25_600.0, 4000.0, 7.0);
    let flat = noise_floor(|_| Complex64::new(1.0, 0.0), r, fs, band, std);
    let expect = (r * 2.0 * band / fs).sqrt() / std;
    assert!((flat / expect - 1.0).abs() < 1e-9, "{flat} vs {expect}");
    // G = 1/(1 + jf/fc)... inverse |1/G|² = 1 + (f/fc)²: ∫ = band + band³/(3fc²).
    let fc = 1000.0;
    let lp = noise_floor(|f| 1.0 / Complex64::new(1.0, f / fc), r, fs, band, std);
    let expect = (r * 2.0 / fs * (band + band.powi(3) / (3.0 * fc * fc))).sqrt() / std;
    assert!((lp / expect - 1.0).abs() < 1e-6, "{lp} vs {expect}");
    // Negative control: a flat G is not mistaken for the low-pass one.
    assert!(lp / flat > 2.0);
}

#[test]
fn harness_records_a_failed_design_in_its_row_and_summarizes() {
    use dynocomp::eval::rates::{cases, score_sim, summarize, RunOptions};
    let case = cases().into_iter().find(|c| c.name == "default").unwrap();
    let mut p = case.sim_params(25_600.0);
    p.duration_s = 0.2;
    let s = dynocomp::simulate::simulate_with(case.seed, &p, case.dynamometer(&p).unwrap()).unwrap();
    let mut broken = s.clone();
    for v in broken.frf.axes[1].frf.iter_mut() {
        *v = Complex64::new(0.0, 0.0);
    }
    let r = score_sim(case.name, &broken, &RunOptions::default());
    assert!(r.axes[1].comp_nrmse.is_err(), "a zero FRF was designed: {:?}", r.axes[1]);
    for a in [0, 2] {
        let c = *r.axes[a].comp_nrmse.as_ref().unwrap();
        assert!(c < r.axes[a].raw_nrmse, "axis {a}: compensated {c} vs raw {}", r.axes[a].raw_nrmse);
        assert!(
            r.axes[a].noise_floor > 0.0 && r.axes[a].noise_floor < c * 1.5,
            "axis {a}: floor {}",
            r.axes[a].noise_floor
        );
    }
    let sum = summarize(std::slice::from_ref(&r));
    assert_eq!(sum.len(), 1);
    assert_eq!(sum[0].failed, vec!["default/y".to_string()]);
    let (c0, c2) = (*r.axes[0].comp_nrmse.as_ref().unwrap(), *r.axes[2].comp_nrmse.as_ref().unwrap());
    assert!((sum[0].median - 0.5 * (c0 + c2)).abs() < 1e-15 && sum[0].worst == c0.max(c2));
    // An axis worse than raw is listed: pretend raw was perfect.
    let mut worse = r;
    worse.axes[0].raw_nrmse = 0.0;
    assert_eq!(summarize(&[worse])[0].worse_than_raw, vec!["default/x".to_string()]);
}
