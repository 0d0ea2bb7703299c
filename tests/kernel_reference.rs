//! The f32 delta-form kernel against independent f64 references.

mod common;
use common::*;
use dynocomp_core::kernel::{AxisFilter, AxisState, FilterError, Section, RUNAWAY_LIMIT_N};

/// Dense f64 state-space recursion x[k+1] = A x[k] + B u[k], y = C x + D u of
/// the block-diagonal filter, in standard (not delta) form.
fn reference_f64(blocks: &[Block64], d: f64, input: &[f64]) -> Vec<f64> {
    let n = 2 * blocks.len();
    let mut a = vec![0.0; n * n];
    let mut b = vec![0.0; n];
    let mut c = vec![0.0; n];
    for (i, blk) in blocks.iter().enumerate() {
        for r in 0..2 {
            for q in 0..2 {
                a[(2 * i + r) * n + 2 * i + q] = blk.a[r][q];
            }
            b[2 * i + r] = blk.b[r];
            c[2 * i + r] = blk.c[r];
        }
    }
    let mut x = vec![0.0; n];
    let mut xn = vec![0.0; n];
    input
        .iter()
        .map(|&u| {
            let y: f64 = c.iter().zip(&x).map(|(ci, xi)| ci * xi).sum::<f64>() + d * u;
            for r in 0..n {
                xn[r] = (0..n).map(|q| a[r * n + q] * x[q]).sum::<f64>() + b[r] * u;
            }
            std::mem::swap(&mut x, &mut xn);
            y
        })
        .collect()
}

fn run_kernel(filter: &AxisFilter, input: &[f64]) -> Vec<f64> {
    let mut st = AxisState::default();
    input.iter().map(|&u| f64::from(filter.step(&mut st, u as f32))).collect()
}

fn max_rel_err(got: &[f64], want: &[f64]) -> (f64, usize) {
    let peak = want.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let (k, e) = got.iter().zip(want).map(|(g, w)| (g - w).abs()).enumerate().fold((0, 0.0f64), |(bk, be), (k, e)| {
        if e > be {
            (k, e)
        } else {
            (bk, be)
        }
    });
    (e / peak, k)
}

const FS: f64 = 51_200.0;
const N: usize = 100_000;

#[test]
fn impulse_response_24_sections_matches_f64_reference() {
    let (blocks, d) = filter_24(FS);
    let filter = kernel_filter(&blocks, d);
    assert_eq!(filter.sections().len(), 24);
    let mut input = vec![0.0; N];
    input[0] = 1.0;
    let want = reference_f64(&blocks, d, &input);
    let got = run_kernel(&filter, &input);
    let (err, k) = max_rel_err(&got, &want);
    eprintln!("impulse rel err {err:.3e}");
    assert!(err < 1e-5, "impulse: max error {err:.3e} of peak at sample {k}");
    // The slow 100 Hz mode must still ring at the end of the record in the
    // reference; otherwise the test would not exercise long-term accuracy.
    let tail = want[N - 2000..].iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(tail > 1e-8, "reference decayed completely ({tail:e})");
}

#[test]
fn step_response_24_sections_matches_f64_reference() {
    let (blocks, d) = filter_24(FS);
    let filter = kernel_filter(&blocks, d);
    let input = vec![1.0; N];
    let want = reference_f64(&blocks, d, &input);
    let got = run_kernel(&filter, &input);
    let (err, k) = max_rel_err(&got, &want);
    eprintln!("step rel err {err:.3e}");
    assert!(err < 1e-5, "step: max error {err:.3e} of peak at sample {k}");
}

/// Pairs and real poles in any section order (diagonal sections first,
/// between pairs, last; one with a dropped state): the kernel keeps both
/// kinds in one packed array, so a pair that arrives after real poles must
/// move them, not overwrite them. Against the f64 recursion of the same
/// blocks, for an impulse and a step.
#[test]
fn pairs_and_real_poles_in_any_order_match_f64_reference() {
    let diag = |p1: f64, p2: f64, b: [f64; 2], c: [f64; 2]| Block64 { a: [[p1, 0.0], [0.0, p2]], b, c };
    let (modes, d) = filter_24(FS);
    let blocks = vec![
        diag(0.9, 0.5, [1.0, 0.7], [0.3, -0.2]),
        modes[0],
        modes[5],
        diag(0.99, -0.3, [1.0, 1.0], [-0.4, 0.25]),
        modes[9],
        diag(0.7, 0.2, [1.0, 0.0], [0.6, 0.9]), // second state dropped (b = 0)
        modes[14],
        modes[20],
        diag(0.995, 0.8, [0.5, 2.0], [0.1, -0.05]),
    ];
    let filter = kernel_filter(&blocks, d);
    for (name, input) in
        [("impulse", (0..N).map(|k| if k == 0 { 1.0 } else { 0.0 }).collect::<Vec<f64>>()), ("step", vec![1.0; N])]
    {
        let want = reference_f64(&blocks, d, &input);
        let got = run_kernel(&filter, &input);
        let (err, k) = max_rel_err(&got, &want);
        eprintln!("mixed order {name} rel err {err:.3e}");
        assert!(err < 1e-5, "{name}: max error {err:.3e} of peak at sample {k}");
    }
}

#[test]
fn single_mode_impulse_response_matches_analytic_formula() {
    // h[0] = d, h[k] = c·A^(k−1)·b with A = r·R(θ): for b = [g, 0],
    // h[k] = g·r^(k−1)·(c1·cos((k−1)θ) − c2·sin((k−1)θ)).
    let (f, zeta) = (100.0, 0.01);
    let c = [0.7, -0.4];
    let blk = mode_block(f, zeta, FS, c);
    let filter = kernel_filter(&[blk], 0.0);
    let w = 2.0 * std::f64::consts::PI * f;
    let r = (-zeta * w / FS).exp();
    let th = w * (1.0 - zeta * zeta).sqrt() / FS;
    let g = blk.b[0];
    let mut input = vec![0.0; N];
    input[0] = 1.0;
    let want: Vec<f64> = (0..N)
        .map(|k| {
            if k == 0 {
                0.0
            } else {
                let m = (k - 1) as f64;
                g * r.powf(m) * (c[0] * (m * th).cos() - c[1] * (m * th).sin())
            }
        })
        .collect();
    let got = run_kernel(&filter, &input);
    let (err, k) = max_rel_err(&got, &want);
    eprintln!("analytic rel err {err:.3e}");
    assert!(err < 1e-5, "analytic single mode: max error {err:.3e} of peak at sample {k}");
}

#[test]
fn delta_form_keeps_slow_pole_where_plain_f32_would_not() {
    // Why the kernel stores A − I: for a 100 Hz, 1 % mode at 51.2 kHz the pole
    // radius 1 − 1.2e-4 rounds in f32 on A's diagonal with a relative error of
    // the damping ~ 5e-4, but in delta form the damping keeps f32 precision.
    let blk = mode_block(100.0, 0.01, FS, [1.0, 0.0]);
    let sec = to_section(&blk);
    let decay_true = 1.0 - blk.a[0][0];
    let decay_delta = -f64::from(sec.delta[0]);
    let decay_plain = 1.0 - f64::from(blk.a[0][0] as f32);
    let err_delta = ((decay_delta - decay_true) / decay_true).abs();
    let err_plain = ((decay_plain - decay_true) / decay_true).abs();
    assert!(err_delta < 1e-6, "delta-form error {err_delta:e}");
    assert!(err_plain > 10.0 * err_delta, "plain f32 error {err_plain:e} vs delta {err_delta:e}");
}

#[test]
fn process_slice_matches_step_by_step_and_state_resets() {
    let (blocks, d) = filter_24(FS);
    let filter = kernel_filter(&blocks, d);
    let input: Vec<f32> = (0..4096).map(|k| ((k as f32) * 0.37).sin() * 100.0).collect();
    let mut out = vec![0.0f32; input.len()];
    let mut st = AxisState::default();
    filter.process(&mut st, &input, &mut out);
    let want: Vec<f64> = reference_f64(&blocks, d, &input.iter().map(|&v| f64::from(v)).collect::<Vec<_>>());
    let (err, _) = max_rel_err(&out.iter().map(|&v| f64::from(v)).collect::<Vec<_>>(), &want);
    assert!(err < 1e-5, "slice processing error {err:e}");
    st.reset();
    assert_eq!(st, AxisState::default());
}

#[test]
fn guard_resets_nonfinite_and_runaway_state_and_counts_it() {
    let (blocks, d) = filter_24(FS);
    let filter = kernel_filter(&blocks, d);
    let mut st = AxisState::default();
    assert!(filter.step_guarded(&mut st, 1.0).is_some());
    st.x[0][0] = f32::NAN;
    assert_eq!(filter.step_guarded(&mut st, 1.0), None);
    assert_eq!(st.nonfinite_resets, 1);
    assert!(st.x.iter().all(|x| x[0] == 0.0 && x[1] == 0.0) && st.x_real.iter().all(|x| *x == 0.0), "state not reset");
    st.x[3][1] = 1.0e12; // runaway (finite but absurd)
    assert_eq!(filter.step_guarded(&mut st, 1.0), None);
    assert_eq!(st.nonfinite_resets, 2);
    // after the reset the filter works again
    assert!(filter.step_guarded(&mut st, 1.0).unwrap().abs() < RUNAWAY_LIMIT_N);
}

#[test]
fn unstable_or_nonfinite_sections_are_refused() {
    let stable = Section::first_order(0.999, 1.0, 1.0);
    assert!(AxisFilter::new(&[stable], 0.0).is_ok());
    let on_circle = Section::first_order(1.0, 1.0, 1.0);
    assert!(AxisFilter::new(&[stable, on_circle], 0.0).is_err());
    let outside = Section { delta: [0.0, 0.1, -0.1, 0.0], b: [1.0, 0.0], c: [1.0, 0.0] }; // |z| = sqrt(1.01)
    assert!(AxisFilter::new(&[outside], 0.0).is_err());
    let nan = Section { delta: [f32::NAN, 0.0, 0.0, -1.0], ..stable };
    assert!(AxisFilter::new(&[nan], 0.0).is_err());
    assert!(AxisFilter::new(&[stable], f32::INFINITY).is_err());
    assert!(AxisFilter::new(&[stable; 25], 0.0).is_err());
    // a slow pole just inside the circle is accepted: 1 − 1e-7 in delta form
    let slow = Section::first_order(1.0 - 1e-7, 1.0, 1.0);
    assert!(slow.is_stable());
    assert!(!slow.poles_within(1.0 - 1e-6));
}

#[test]
fn sections_the_kernel_does_not_run_are_refused() {
    let pair = Section { delta: [-0.01, 0.05, -0.05, -0.01], b: [1.0, 0.0], c: [1.0, 0.5] };
    let diagonal = Section { delta: [-0.01, 0.0, 0.0, -0.2], b: [1.0, 2.0], c: [1.0, 0.5] };
    assert!(AxisFilter::new(&[pair, diagonal], 0.0).is_ok());
    let triangular = Section { delta: [-0.01, 0.3, 0.0, -0.2], ..diagonal };
    let skewed = Section { delta: [-0.01, 0.05, -0.04, -0.01], ..pair };
    let unequal_sigma = Section { delta: [-0.01, 0.05, -0.05, -0.02], ..pair };
    let input_on_both = Section { b: [1.0, 0.1], ..pair };
    for bad in [triangular, skewed, unequal_sigma, input_on_both] {
        assert!(bad.is_stable() && bad.is_finite());
        assert_eq!(AxisFilter::new(&[pair, bad], 0.0), Err(FilterError::NotModal(1)), "{bad:?}");
    }
}

#[test]
fn fir_part_delays_and_weights_past_inputs() {
    // y[k] = 0.5·u[k] + 2·u[k−1] − 1·u[k−3]: an impulse gives exactly the taps
    let f = AxisFilter::with_fir(&[], 0.5, &[2.0, 0.0, -1.0]).unwrap();
    let mut st = AxisState::default();
    let mut input = vec![0.0f32; 8];
    input[0] = 1.0;
    let mut out = vec![0.0f32; 8];
    f.process(&mut st, &input, &mut out);
    assert_eq!(out, vec![0.5, 2.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0]);
    // the FIR history is state: reset clears it
    f.step(&mut st, 3.0);
    st.reset();
    assert_eq!(f.step(&mut st, 0.0), 0.0);
    assert!(AxisFilter::with_fir(&[], 0.0, &[0.0; dynocomp_core::kernel::MAX_FIR + 1]).is_err());
    assert!(AxisFilter::with_fir(&[], 0.0, &[f32::NAN]).is_err());
}
