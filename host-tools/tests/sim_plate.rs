//! The physical 3x3 plate dynamometer of the simulator: every expectation is
//! computed independently of the code under test (a direct solve of the
//! 12-DOF equations, closed-form two-mass frequencies, symmetry, Fourier
//! phasors of the time response, analytic noise-floor integrals), and each
//! threshold has a negative control that would fail it.

#![allow(clippy::needless_range_loop)] // channel/direction indices index several arrays at once

use dynocomp::frf::MatrixKind;
use dynocomp::simulate::plate::{
    check_mode_bands, impact_test_matrix, inverse_noise_floor, per_axis_noise_floor, simulate_plate, FloorSpec,
    PlateModal, PlateSetup, PlateSim, DOF, PRESETS,
};
use dynocomp::simulate::{h1_random_error, simulate, AntiAlias, Butterworth, Excitation, ImpactParams, SimParams};
use nalgebra::{DMatrix, Matrix3, SymmetricEigen};
use num_complex::Complex64;
use std::f64::consts::PI;

type CMatrix = DMatrix<Complex64>;

fn preset(name: &str) -> PlateSetup {
    PlateSetup::preset(name).unwrap()
}

fn rel(a: &Matrix3<Complex64>, b: &Matrix3<Complex64>) -> f64 {
    (a - b).norm() / b.norm()
}

// ---------------------------------------------------------------- an independent direct solve

/// Modal damping built here from this test's own eigen decomposition (via
/// the eigenvectors of M, not a Cholesky factor): C = MΦ diag(2ζω) ΦᵀM and
/// the sensors' damping output Cv = S·Cd·Φ diag(2ζ/ω) ΦᵀM, with the modes
/// ascending and ζ from the set-up.
fn damping(setup: &PlateSetup, point: [f64; 3]) -> (DMatrix<f64>, DMatrix<f64>) {
    let m = setup.matrices(point);
    let em = SymmetricEigen::new(m.m.clone());
    let m_inv_half = &em.eigenvectors
        * DMatrix::from_diagonal(&em.eigenvalues.map(|v| 1.0 / v.sqrt()))
        * em.eigenvectors.transpose();
    let a = &m_inv_half * &m.k * &m_inv_half;
    let ea = SymmetricEigen::new((&a + a.transpose()) * 0.5);
    let mut idx: Vec<usize> = (0..DOF).collect();
    idx.sort_by(|&i, &j| ea.eigenvalues[i].total_cmp(&ea.eigenvalues[j]));
    let phi = DMatrix::from_fn(DOF, DOF, |r, c| (&m_inv_half * ea.eigenvectors.column(idx[c]))[r]);
    let w: Vec<f64> = idx.iter().map(|&i| ea.eigenvalues[i].sqrt()).collect();
    let d_c = DMatrix::from_fn(DOF, DOF, |r, c| if r == c { 2.0 * setup.zeta[r] * w[r] } else { 0.0 });
    let d_v = DMatrix::from_fn(DOF, DOF, |r, c| if r == c { 2.0 * setup.zeta[r] / w[r] } else { 0.0 });
    let c = &m.m * &phi * d_c * phi.transpose() * &m.m;
    let s = DMatrix::from_fn(3, 3, |i, j| m.s[(i, j)]);
    let cv = s * &m.cd * &phi * d_v * phi.transpose() * &m.m;
    (c, cv)
}

/// G(j2πf) by solving (K − ω²M + jωC) x = B, then y = (S·Cd + jω·Cv) x.
fn direct_frf(setup: &PlateSetup, point: [f64; 3], f_hz: f64, damped: bool) -> Matrix3<Complex64> {
    let m = setup.matrices(point);
    let w = 2.0 * PI * f_hz;
    let (c, cv) = if damped { damping(setup, point) } else { (DMatrix::zeros(DOF, DOF), DMatrix::zeros(3, DOF)) };
    let cplx = |a: &DMatrix<f64>| a.map(|v| Complex64::new(v, 0.0));
    let j = Complex64::new(0.0, 1.0);
    let dyn_stiff: CMatrix = cplx(&m.k) - cplx(&m.m) * Complex64::new(w * w, 0.0) + cplx(&c) * (j * w);
    let lu = dyn_stiff.clone().lu();
    let x = lu.solve(&cplx(&m.b)).expect("dynamic stiffness is regular off resonance");
    // Check the solve: residual against the right-hand side.
    let res = (&dyn_stiff * &x - cplx(&m.b)).norm() / cplx(&m.b).norm();
    assert!(res < 1e-9, "direct solve residual {res}");
    let s = cplx(&DMatrix::from_fn(3, 3, |i, j| m.s[(i, j)]));
    let y = s * cplx(&m.cd) * &x + cplx(&cv) * &x * (j * w);
    Matrix3::from_fn(|r, c| y[(r, c)])
}

const FREQS: [f64; 8] = [0.5, 150.0, 333.3, 777.0, 1500.0, 2345.6, 3456.7, 5555.0];

#[test]
fn the_modal_frf_matrix_equals_a_direct_solve_of_the_12_dof_equations() {
    for name in PRESETS {
        let s = preset(name);
        let modal = PlateModal::new(&s, s.force_point_m).unwrap();
        for f in FREQS {
            let d = direct_frf(&s, s.force_point_m, f, true);
            let e = rel(&modal.frf(f), &d);
            assert!(e < 1e-10, "{name} at {f} Hz: modal vs direct {e:e}");
        }
        // Undamped, the direct solve uses M, K, B, Cd only: no modes at all.
        let mut undamped = modal.clone();
        undamped.modes.iter_mut().for_each(|m| m.zeta = 0.0);
        for f in [1.0, 50.0, 1200.0, 3000.0] {
            let e = rel(&undamped.frf(f), &direct_frf(&s, s.force_point_m, f, false));
            assert!(e < 1e-10, "{name} undamped at {f} Hz: {e:e}");
        }
    }
    // Negative controls: the force 1 mm away, or one mode's input row off by
    // 1e-6, miss the direct solve by far more than the tolerance.
    let s = preset("offcentre");
    let modal = PlateModal::new(&s, s.force_point_m).unwrap();
    let moved = [s.force_point_m[0] + 1e-3, s.force_point_m[1], s.force_point_m[2]];
    let e = rel(&modal.frf(2345.6), &direct_frf(&s, moved, 2345.6, true));
    assert!(e > 1e-6, "1 mm away: {e:e}");
    let mut bent = modal.clone();
    bent.modes[7].input[0] *= 1.0 + 1e-6;
    let e = rel(&bent.frf(2345.6), &direct_frf(&s, s.force_point_m, 2345.6, true));
    assert!(e > 1e-8, "perturbed input row: {e:e}");
}

#[test]
fn the_static_gain_is_the_static_crosstalk_matrix() {
    let mut setups: Vec<PlateSetup> = PRESETS.iter().map(|n| preset(n)).collect();
    setups.extend((0..10).map(|seed| PlateSetup::random(seed).unwrap()));
    for s in &setups {
        let modal = PlateModal::new(s, s.force_point_m).unwrap();
        let want = Matrix3::from_fn(|i, j| Complex64::new(if i == j { 1.0 } else { 0.0 } + s.crosstalk[i][j], 0.0));
        let g0 = modal.frf(0.0);
        assert!((g0 - want).norm() < 1e-9, "G(0) = {g0}, S = {want}");
        let sum = modal.static_gain();
        assert!((sum.map(|v| Complex64::new(v, 0.0)) - want).norm() < 1e-9, "Σ residues = {sum}");
        // The same at any force point: all load passes through the sensors.
        let elsewhere = PlateModal::new(s, [0.03, -0.02, 0.06]).unwrap();
        assert!((elsewhere.frf(0.0) - want).norm() < 1e-9);
        // Negative control: 1 Hz is already measurably dynamic (machine modes).
        assert!((modal.frf(1.0) - want).norm() > 1e-7, "G(1 Hz) indistinguishable from S");
    }
}

#[test]
fn a_centred_symmetric_plate_couples_nothing_and_its_vertical_modes_are_the_two_mass_ones() {
    let mut s = preset("flat");
    s.crosstalk = [[0.0; 3]; 3];
    let modal = PlateModal::new(&s, s.force_point_m).unwrap();
    let grid: Vec<f64> = (0..=600).map(|k| 10.0 * k as f64).collect();
    for &f in &grid {
        let g = modal.frf(f);
        for (i, j) in [(0, 1), (0, 2), (1, 0), (1, 2), (2, 0), (2, 1)] {
            assert!(g[(i, j)].norm() < 1e-12 * g[(i, i)].norm().max(1.0), "G_{i}{j}({f} Hz) = {}", g[(i, j)]);
        }
    }
    // Vertical: the top (m) on 4kz over the base (M) on 4kt,z, decoupled by
    // symmetry: det [[k1 − ω²m, −k1], [−k1, k1 + k2 − ω²M]] = 0.
    let (m, mb) = (s.top().mass_kg, s.base_mass_kg);
    let (k1, k2) = (4.0 * s.sensor_stiffness_n_per_m[2], 4.0 * s.table_stiffness_n_per_m[2]);
    let two_mass = |k1: f64| {
        let (a, b, c) = (m * mb, -(k1 * mb + (k1 + k2) * m), k1 * k2);
        let d = (b * b - 4.0 * a * c).sqrt();
        [(-b - d) / (2.0 * a), (-b + d) / (2.0 * a)].map(|w2: f64| w2.sqrt() / (2.0 * PI))
    };
    let near = |f: f64| modal.modes.iter().map(|md| (md.fn_hz - f).abs() / f).fold(f64::INFINITY, f64::min);
    for f in two_mass(k1) {
        assert!(
            near(f) < 1e-9,
            "vertical mode {f} Hz not among {:?}",
            modal.modes.iter().map(|m| m.fn_hz).collect::<Vec<_>>()
        );
    }
    // ... and only they show in G_zz (a vertical force excites nothing else).
    let zz: Vec<f64> = modal.modes.iter().map(|md| md.residue()[2][2].abs()).collect();
    let big = zz.iter().filter(|&&r| r > 1e-12).count();
    assert_eq!(big, 2, "G_zz residues {zz:?}");
    // Negative controls: 0.1 % stiffer sensors miss the upper (sensor) mode;
    // 5 mm of workpiece offset couples x and z.
    assert!(near(two_mass(k1 * 1.001)[1]) > 1e-4);
    let mut off = s.clone();
    off.workpiece_xy_m = [0.005, 0.0];
    let om = PlateModal::new(&off, off.force_point_m).unwrap();
    let peak = grid.iter().map(|&f| om.frf(f)[(0, 2)].norm()).fold(0.0, f64::max);
    assert!(peak > 1e-3, "5 mm offset: |G_xz| peak {peak}");
}

// ---------------------------------------------------------------- time response

/// A·e^{jφ} of A·sin(2πf t + φ) in `x` (rate `fs`) over whole periods from `k0`.
fn phasor(x: &[f64], fs: f64, f: f64, k0: usize, n: usize) -> Complex64 {
    let w = 2.0 * PI * f / fs;
    let s: Complex64 = (k0..k0 + n).map(|k| x[k] * Complex64::from_polar(1.0, -w * k as f64)).sum();
    s * (2.0 / n as f64) * Complex64::new(0.0, 1.0)
}

#[test]
fn the_time_response_to_a_sine_is_the_frf_in_amplitude_and_phase() {
    let s = preset("offcentre");
    let modal = PlateModal::new(&s, s.force_point_m).unwrap();
    let fs = 409_600.0;
    let n = 204_800; // 0.5 s: the slowest mode (≈ 210 Hz, ζ 0.035) has decayed by e^-20
    let amp = [3.0, -2.0, 5.0];
    let bw = Butterworth { order: 4, fc_hz: 6000.0 };
    // Whole periods in the second half (102400 samples): f a multiple of 4 Hz.
    for f in [732.0, 2400.0, 3600.0] {
        let force: [Vec<f64>; 3] = amp.map(|a| (0..n).map(|k| a * (2.0 * PI * f * k as f64 / fs).sin()).collect());
        let fr = [force[0].as_slice(), force[1].as_slice(), force[2].as_slice()];
        // The model sees the linear interpolant of the samples: its
        // fundamental is the sine's × sinc²(πf/fs).
        let x = PI * f / fs;
        let sinc2 = (x.sin() / x).powi(2);
        let (k0, len) = (n / 2, n / 2);
        let g = modal.frf(f);
        let y = modal.measure(fr, fs);
        let yb = modal.measure_through(&bw, fr, fs).unwrap();
        for i in 0..3 {
            let want: Complex64 = (0..3).map(|j| g[(i, j)] * amp[j]).sum::<Complex64>() * sinc2;
            let got = phasor(&y[i], fs, f, k0, len);
            let e = (got - want).norm() / want.norm();
            assert!(e < 1e-6, "channel {i} at {f} Hz: {got} vs {want} ({e:e})");
            // Negative control: without the velocity term of the sensors'
            // damping the response is off by far more.
            let no_vel: Complex64 = modal
                .modes
                .iter()
                .map(|md| {
                    let (w, z) = (md.omega(), md.zeta);
                    let s = Complex64::new(0.0, 2.0 * PI * f);
                    let b: f64 = (0..3).map(|j| md.input[j] * amp[j]).sum();
                    md.output[i] * b / (s * s + 2.0 * z * w * s + w * w)
                })
                .sum::<Complex64>()
                * sinc2;
            assert!((got - no_vel).norm() / want.norm() > 1e-3, "velocity term invisible at {f} Hz");
            // Through the analog front end: B(j2πf)·G.
            let wantb = want * bw.frf(f);
            let gotb = phasor(&yb[i], fs, f, k0, len);
            let eb = (gotb - wantb).norm() / wantb.norm();
            assert!(eb < 1e-6, "channel {i} at {f} Hz through the front end: {gotb} vs {wantb} ({eb:e})");
        }
        // Negative control: half a sample of delay (what a zero-order hold
        // does) is a phase error far above the tolerance.
        let delayed: Complex64 =
            (0..3).map(|j| g[(0, j)] * amp[j]).sum::<Complex64>() * sinc2 * Complex64::from_polar(1.0, -x);
        let got = phasor(&y[0], fs, f, k0, len);
        assert!((got - delayed).norm() / delayed.norm() > 1e-3);
    }
}

// ---------------------------------------------------------------- crosstalk of the presets

/// Largest off-diagonal peak |G_ij|/|G_ii| over 0-4096 Hz at 1 Hz.
fn max_crosstalk(s: &PlateSetup) -> f64 {
    let modal = PlateModal::new(s, s.force_point_m).unwrap();
    let freqs: Vec<f64> = (0..=4096).map(f64::from).collect();
    let xt = modal.crosstalk_peak(&freqs);
    (0..9).filter(|k| k / 3 != k % 3).map(|k| xt[k / 3][k % 3]).fold(0.0, f64::max)
}

#[test]
fn presets_span_little_to_strong_crosstalk_and_modes_sit_in_their_bands() {
    let flat = max_crosstalk(&preset("flat"));
    let off = max_crosstalk(&preset("offcentre"));
    let tall = max_crosstalk(&preset("tall"));
    assert!(flat < 0.10, "flat: {flat}");
    assert!((0.10..=0.30).contains(&tall), "tall: {tall}");
    assert!(off > 0.30, "offcentre: {off}");
    // The flat plate's figure is its static crosstalk, amplified near the
    // modes: without it, nothing.
    let mut clean = preset("flat");
    clean.crosstalk = [[0.0; 3]; 3];
    assert!(max_crosstalk(&clean) < 1e-10);
    // Negative control: the flat plate's workpiece 10 mm off centre.
    let mut moved = preset("flat");
    moved.workpiece_xy_m = [0.01, 0.005];
    assert!(max_crosstalk(&moved) > 0.10, "moved: {}", max_crosstalk(&moved));
    for name in PRESETS {
        let s = preset(name);
        check_mode_bands(&PlateModal::new(&s, s.force_point_m).unwrap()).unwrap_or_else(|e| panic!("{name}: {e:#}"));
    }
}

#[test]
fn random_setups_are_reproducible_physical_and_in_band() {
    for seed in 0..40u64 {
        let s = PlateSetup::random(seed).unwrap();
        assert_eq!(PlateSetup::random(seed).unwrap(), s, "seed {seed} not reproducible");
        s.validate().unwrap();
        let modal = PlateModal::new(&s, s.force_point_m).unwrap();
        check_mode_bands(&modal).unwrap();
        for m in &modal.modes {
            assert!((0.01..=0.06).contains(&m.zeta), "seed {seed}: ζ {}", m.zeta);
        }
        let top = s.top_height_m();
        assert!(s.force_point_m[2] <= top + 1e-12 && s.force_point_m[2] > 0.0, "seed {seed}: point above the part");
    }
    assert_ne!(PlateSetup::random(1).unwrap(), PlateSetup::random(2).unwrap());
    // Negative control: the band check refuses a set-up whose sensors are 10x softer.
    let mut soft = preset("flat");
    soft.sensor_stiffness_n_per_m = soft.sensor_stiffness_n_per_m.map(|k| k / 10.0);
    let e = check_mode_bands(&PlateModal::new(&soft, soft.force_point_m).unwrap()).unwrap_err();
    assert!(format!("{e}").contains("sensor/rocking band"), "{e}");
}

// ---------------------------------------------------------------- impact tests

#[test]
fn impact_tests_measure_all_nine_entries_within_their_random_error() {
    let s = preset("offcentre");
    let modal = PlateModal::new(&s, s.force_point_m).unwrap();
    let p = ImpactParams::default();
    let frf = impact_test_matrix(&modal, &|_| Complex64::new(1.0, 0.0), 4097, 1.0, 5, &p);
    assert_eq!(frf.matrix_status().kind(), MatrixKind::Complete);
    let mut wrong_entry_outside = 0usize;
    for i in 0..3 {
        for j in 0..3 {
            let e = frf.entry(i, j).unwrap();
            let coh = e.coherence.unwrap();
            let (mut checked, mut outside) = (0usize, 0usize);
            for k in 1..4097 {
                if coh[k] > 0.9 {
                    let g = modal.frf(k as f64)[(i, j)];
                    checked += 1;
                    let bound = 5.0 * h1_random_error(coh[k], p.n_impacts);
                    if (e.frf[k] - g).norm() / g.norm() > bound {
                        outside += 1;
                    }
                    // Negative control: the transposed entry is another FRF.
                    let gt = modal.frf(k as f64)[(j, i)];
                    if i != j && (e.frf[k] - gt).norm() / g.norm() > bound {
                        wrong_entry_outside += 1;
                    }
                }
            }
            assert!(checked > 300, "entry {i}{j}: only {checked} coherent lines");
            // Bendat's error is asymptotic in the number of averages: with 7
            // and γ² down to 0.9 the tails are a little heavier than Gaussian.
            assert!((outside as f64) < 0.01 * checked as f64, "entry {i}{j}: {outside} of {checked} outside 5σ");
        }
    }
    assert!(wrong_entry_outside > 1000, "G_ji passes for G_ij ({wrong_entry_outside})");
    // Without noise H1 is G and the coherence 1, in every entry.
    let quiet = ImpactParams { output_noise_rel: 0.0, input_noise_rel: 0.0, ..p.clone() };
    let q = impact_test_matrix(&modal, &|_| Complex64::new(1.0, 0.0), 513, 8.0, 5, &quiet);
    for k in 0..513 {
        let g = modal.frf(8.0 * k as f64);
        for e in q.entries() {
            let want = g[(e.channel, e.direction)];
            assert!((e.frf[k] - want).norm() <= 1e-12 * want.norm().max(1e-3));
            assert!((e.coherence.unwrap()[k] - 1.0).abs() < 1e-12);
        }
    }
    // One test per hammer direction: its three channels share the impacts
    // and the load cell, so with input noise only every channel's H1 is off
    // by the same factor.
    let input_only = ImpactParams { output_noise_rel: 0.0, input_noise_rel: 0.05, ..p.clone() };
    let t = impact_test_matrix(&modal, &|_| Complex64::new(1.0, 0.0), 65, 16.0, 9, &input_only);
    for k in 1..65 {
        let g = modal.frf(16.0 * k as f64);
        for j in 0..3 {
            let r: Vec<Complex64> = (0..3).map(|i| t.entry(i, j).unwrap().frf[k] / g[(i, j)]).collect();
            assert!((r[0] - r[1]).norm() < 1e-9 && (r[0] - r[2]).norm() < 1e-9, "line {k} direction {j}: {r:?}");
        }
    }
}

// ---------------------------------------------------------------- noise floor

fn spec(r: [f64; 3], band: (f64, f64)) -> FloorSpec {
    FloorSpec { r_n2: r, fs_hz: 51_200.0, band_hz: band, std_truth_n: [10.0, 20.0, 40.0] }
}

#[test]
fn the_noise_floor_of_a_constant_matrix_is_its_inverse_rows() {
    // A = [[1, 0.2, 0], [0, 1, 0.1], [0, 0, 1]]: A⁻¹ = [[1, -0.2, 0.02], [0, 1, -0.1], [0, 0, 1]].
    let a = Matrix3::new(1.0, 0.2, 0.0, 0.0, 1.0, 0.1, 0.0, 0.0, 1.0).map(|v| Complex64::new(v, 0.0));
    let inv = [[1.0, -0.2, 0.02], [0.0, 1.0, -0.1], [0.0, 0.0, 1.0]];
    let r = [0.05, 0.2, 0.5];
    let band = (100.0, 4100.0);
    let sp = spec(r, band);
    let got = inverse_noise_floor(&|_| a, &sp).unwrap();
    let per = per_axis_noise_floor(&|_| a, &sp).unwrap();
    for i in 0..3 {
        let s2: f64 = (0..3).map(|j| r[j] * inv[i][j] * inv[i][j]).sum();
        let want = (2.0 / sp.fs_hz * (band.1 - band.0) * s2).sqrt() / sp.std_truth_n[i];
        assert!((got[i] - want).abs() < 1e-12 * want, "axis {i}: {} vs {want}", got[i]);
        let want_per = (2.0 / sp.fs_hz * (band.1 - band.0) * r[i]).sqrt() / sp.std_truth_n[i];
        assert!((per[i] - want_per).abs() < 1e-12 * want_per);
    }
    // Negative control: the per-axis floor misses the 3x3 one where the
    // inverse has off-diagonal terms (x: 1 + 0.04·4 + 0.0004·10 in R units).
    assert!((per[0] - got[0]).abs() > 0.01 * got[0]);
    assert!((per[2] - got[2]).abs() < 1e-15 * got[2], "z has no off-diagonal inverse terms");
}

#[test]
fn the_noise_floor_of_first_order_axes_is_the_closed_form_integral() {
    // G_ii = 1/(1 + jf/fc_i): |1/G_ii|² = 1 + (f/fc)², ∫ = Δf + (hi³ − lo³)/(3fc²).
    let fc = [1000.0, 2000.0, 3000.0];
    let g = |f: f64| {
        Matrix3::from_fn(|i, j| if i == j { 1.0 / Complex64::new(1.0, f / fc[i]) } else { Complex64::new(0.0, 0.0) })
    };
    let r = [0.05, 0.05, 0.1];
    let band = (0.0, 4000.0);
    let sp = spec(r, band);
    let got = inverse_noise_floor(&g, &sp).unwrap();
    let per = per_axis_noise_floor(&g, &sp).unwrap();
    for i in 0..3 {
        let integral = (band.1 - band.0) + (band.1.powi(3) - band.0.powi(3)) / (3.0 * fc[i] * fc[i]);
        let want = (r[i] * 2.0 / sp.fs_hz * integral).sqrt() / sp.std_truth_n[i];
        assert!((got[i] - want).abs() < 1e-7 * want, "axis {i}: {} vs {want}", got[i]);
        assert!((per[i] - got[i]).abs() < 1e-12 * want, "diagonal G: per-axis = 3x3");
        // Negative control: a 1 % wrong cutoff moves the floor by more than the tolerance.
        let off = (band.1 - band.0) + (band.1.powi(3) - band.0.powi(3)) / (3.0 * (1.01 * fc[i]).powi(2));
        assert!(((r[i] * 2.0 / sp.fs_hz * off).sqrt() / sp.std_truth_n[i] - got[i]).abs() > 1e-4 * want);
    }
}

#[test]
fn the_noise_floor_refuses_a_singular_matrix_and_a_bad_band() {
    let singular = Matrix3::new(1.0, 1.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0, 1.0).map(|v| Complex64::new(v, 0.0));
    let e = inverse_noise_floor(&|_| singular, &spec([0.1; 3], (0.0, 100.0))).unwrap_err();
    assert!(format!("{e}").contains("singular at 0 Hz"), "{e}");
    let id = Matrix3::identity();
    for band in [(100.0, 50.0), (0.0, 30_000.0), (-1.0, 10.0)] {
        let e = inverse_noise_floor(&|_| id, &spec([0.1; 3], band)).unwrap_err();
        assert!(format!("{e}").contains("band"), "{e}");
    }
    // The plate model's G is invertible over the band; its 3x3 floor and
    // per-axis floor are close where the crosstalk is small.
    let s = preset("flat");
    let modal = PlateModal::new(&s, s.force_point_m).unwrap();
    let sp = spec([0.05; 3], (0.0, 4000.0));
    let full = inverse_noise_floor(&|f| modal.frf(f), &sp).unwrap();
    let per = per_axis_noise_floor(&|f| modal.frf(f), &sp).unwrap();
    for i in 0..3 {
        assert!((full[i] / per[i] - 1.0).abs() < 0.05, "axis {i}: {} vs {}", full[i], per[i]);
    }
}

// ---------------------------------------------------------------- whole simulation

fn sine_params(f: f64) -> SimParams {
    let mut p = SimParams { duration_s: 0.5, idle_duration_s: 0.1, ..Default::default() };
    p.excitation = Some(Excitation::Sine { freq_hz: f, amplitude_n: 10.0, taper_s: 0.05 });
    p.measurement.adc_bits = 0;
    p.impact.n_lines = 513;
    p.impact.df_hz = 8.0;
    p
}

#[test]
fn a_plate_simulation_measures_the_cut_point_through_the_same_chain_as_the_truth() {
    let f = 2400.0;
    let params = sine_params(f);
    let plate = PlateSim { setup: preset("offcentre"), cut_offset_m: [0.02, 0.0, 0.0] };
    let out = simulate_plate(3, &params, &plate).unwrap();
    assert_eq!(out.frf.matrix_status().kind(), MatrixKind::Complete);
    assert!(out.frf.entries().all(|e| e.coherence.is_some()));
    // The truth is the per-axis simulator's: the same force through the same
    // anti-aliasing filter, bit for bit.
    let diag = simulate(3, &params).unwrap();
    assert_eq!(out.truth, diag.truth);
    // Noise: measured − clean has variance R.
    let d: Vec<f64> = out.measured[0].iter().zip(&out.clean[0]).map(|(m, c)| m - c).collect();
    let var = d.iter().map(|v| v * v).sum::<f64>() / d.len() as f64;
    assert!((var / params.measurement.noise_variance_n2 - 1.0).abs() < 0.05, "noise variance {var}");
    // In steady state clean_i = Σ_j G_ij(cut point) truth_j (all truth_j equal here).
    let fs = params.fs_hz;
    let n = out.t_s.len();
    // The middle half, 0.125-0.375 s: 600 whole periods.
    let (k0, len) = (n / 4, n / 2);
    let t = phasor(&out.truth[0], fs, f, k0, len);
    let g_cut = out.cut_modal.frf(f);
    let g_imp = out.impact_modal.frf(f);
    for i in 0..3 {
        let got = phasor(&out.clean[i], fs, f, k0, len) / t;
        let want: Complex64 = (0..3).map(|j| g_cut[(i, j)]).sum();
        let e = (got - want).norm() / want.norm();
        assert!(e < 1e-6, "channel {i}: {got} vs {want} ({e:e})");
        // Negative control: the impact point's G is another system.
        let other: Complex64 = (0..3).map(|j| g_imp[(i, j)]).sum();
        assert!((got - other).norm() / other.norm() > 1e-2, "channel {i}: cut point indistinguishable");
    }
    // The impact test was at the impact point.
    assert_eq!(out.impact_modal.point_m, plate.setup.force_point_m);
    // Through an analog front end the truth stays the same, the channels get B.
    let mut pb = params.clone();
    pb.anti_alias = AntiAlias::Butterworth(Butterworth { order: 4, fc_hz: 12_000.0 });
    let ob = simulate_plate(3, &pb, &plate).unwrap();
    assert_eq!(ob.truth, out.truth);
    let b = Butterworth { order: 4, fc_hz: 12_000.0 }.frf(f);
    for i in 0..3 {
        let got = phasor(&ob.clean[i], fs, f, k0, len) / t;
        let want: Complex64 = (0..3).map(|j| g_cut[(i, j)]).sum::<Complex64>() * b;
        assert!((got - want).norm() / want.norm() < 1e-6, "channel {i} through B");
    }
}

#[test]
fn set_up_parameters_outside_their_physical_range_are_refused_by_name() {
    let ok = preset("flat");
    type Change = Box<dyn Fn(&mut PlateSetup)>;
    let cases: Vec<(Change, &str)> = vec![
        (Box::new(|s| s.plate_mass_kg = 0.0), "plate mass = 0 kg"),
        (Box::new(|s| s.plate_mass_kg = 40.0), "plate density"),
        (Box::new(|s| s.workpiece_mass_kg = 500.0), "workpiece mass"),
        (Box::new(|s| s.workpiece_xy_m = [0.2, 0.0]), "workpiece centre x (on the plate)"),
        (Box::new(|s| s.sensor_half_spacing_m = [0.1, 0.035]), "outside the plate"),
        (Box::new(|s| s.sensor_stiffness_n_per_m[2] = 1e12), "sensor stiffness z"),
        (Box::new(|s| s.table_stiffness_n_per_m[0] = f64::NAN), "table stiffness x"),
        (Box::new(|s| s.base_mass_kg = -1.0), "base mass"),
        (Box::new(|s| s.zeta.truncate(11)), "11 damping ratios"),
        (Box::new(|s| s.zeta[3] = 0.5), "damping ratio of mode 4"),
        (Box::new(|s| s.crosstalk[0][0] = 0.01), "E[0][0] = 0.01 must be 0"),
        (Box::new(|s| s.crosstalk[1][2] = 0.1), "static crosstalk E[1][2]"),
        (Box::new(|s| s.force_point_m[2] = -0.01), "force point z"),
    ];
    for (change, want) in cases {
        let mut s = ok.clone();
        change(&mut s);
        let e = format!("{:#}", s.validate().unwrap_err());
        assert!(e.contains(want) && e.starts_with("plate dynamometer: "), "{e:?} should contain {want:?}");
        assert!(PlateModal::new(&s, ok.force_point_m).is_err());
    }
    ok.validate().unwrap();
    let far = PlateSim { setup: ok.clone(), cut_offset_m: [0.15, 0.0, 0.0] };
    let e = format!("{:#}", far.validate().unwrap_err());
    assert!(e.contains("cut offset x = 0.15 m"), "{e}");
    let below = PlateSim { setup: ok.clone(), cut_offset_m: [0.0, 0.0, -0.05] };
    assert!(format!("{:#}", below.validate().unwrap_err()).contains("cut point"));
    assert!(PlateSetup::preset("round").unwrap_err().to_string().contains("flat, offcentre, tall"));
}
