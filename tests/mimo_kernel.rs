//! The 3x3 kernel against independent references: a dense f64 state-space
//! recursion of the same filter, and three per-axis kernels when the 3x3
//! filter is their diagonal embedding.

use dynocomp_core::kernel::{AxisFilter, AxisState, FilterError, Section};
use dynocomp_core::mimo::{Matrix3, MimoFilter, MimoSection, MimoState, MAX_MIMO_FIR, MAX_MIMO_SECTIONS};

/// A small deterministic generator (xorshift), so the test needs no crate.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    }
}

/// A random stable 3x3 filter: `pairs` normal-form pairs (poles of radius
/// 0.9-0.999), one diagonal section, dense `b`, `c`, `d` and `taps` FIR taps.
fn random_filter(rng: &mut Rng, pairs: usize, taps: usize) -> (Vec<MimoSection>, Matrix3, Vec<Matrix3>) {
    let mut sections = Vec::new();
    let m3 = |rng: &mut Rng, s: f64| -> Matrix3 {
        core::array::from_fn(|_| core::array::from_fn(|_| (s * rng.next()) as f32))
    };
    for _ in 0..pairs {
        let r = 0.9 + 0.0495 * (rng.next() + 1.0);
        let th = 0.5 * (rng.next() + 1.0) + 0.01;
        let (sigma, omega) = ((r * th.cos() - 1.0) as f32, (r * th.sin()) as f32);
        let b = m3(rng, 0.1);
        let c = m3(rng, 1.0);
        sections.push(MimoSection {
            delta: [sigma, omega, -omega, sigma],
            b: [b[0], b[1]],
            c: [[c[0][0], c[0][1]], [c[1][0], c[1][1]], [c[2][0], c[2][1]]],
        });
    }
    let b = m3(rng, 0.1);
    let c = m3(rng, 1.0);
    sections.push(MimoSection {
        delta: [-0.01, 0.0, 0.0, -0.3],
        b: [b[0], b[1]],
        c: [[c[0][0], c[0][1]], [c[1][0], c[1][1]], [c[2][0], c[2][1]]],
    });
    let d = m3(rng, 1.0);
    let fir = (0..taps).map(|_| m3(rng, 0.2)).collect();
    (sections, d, fir)
}

/// The same filter as a dense f64 recursion in standard form (A = I + Δ).
fn reference_f64(sections: &[MimoSection], d: &Matrix3, fir: &[Matrix3], input: &[[f64; 3]]) -> Vec<[f64; 3]> {
    let n = 2 * sections.len();
    let mut x = vec![0.0f64; n];
    let mut hist: Vec<[f64; 3]> = vec![[0.0; 3]; fir.len()];
    input
        .iter()
        .map(|u| {
            let mut y = [0.0f64; 3];
            for i in 0..3 {
                y[i] = (0..3).map(|j| f64::from(d[i][j]) * u[j]).sum::<f64>();
                for (k, s) in sections.iter().enumerate() {
                    y[i] += f64::from(s.c[i][0]) * x[2 * k] + f64::from(s.c[i][1]) * x[2 * k + 1];
                }
                for (m, h) in fir.iter().enumerate() {
                    y[i] += (0..3).map(|j| f64::from(h[i][j]) * hist[m][j]).sum::<f64>();
                }
            }
            let mut xn = vec![0.0; n];
            for (k, s) in sections.iter().enumerate() {
                let dl = s.delta.map(f64::from);
                let (x1, x2) = (x[2 * k], x[2 * k + 1]);
                let bu = |r: usize| (0..3).map(|j| f64::from(s.b[r][j]) * u[j]).sum::<f64>();
                xn[2 * k] = x1 + dl[0] * x1 + dl[1] * x2 + bu(0);
                xn[2 * k + 1] = x2 + dl[2] * x1 + dl[3] * x2 + bu(1);
            }
            x = xn;
            if !hist.is_empty() {
                hist.rotate_right(1);
                hist[0] = *u;
            }
            y
        })
        .collect()
}

fn input(rng: &mut Rng, n: usize) -> Vec<[f64; 3]> {
    (0..n)
        .map(|k| [100.0 * rng.next(), 50.0 * (k as f64 * 0.01).sin(), if k == 10 { 300.0 } else { 20.0 * rng.next() }])
        .collect()
}

#[test]
fn a_random_3x3_filter_matches_the_f64_recursion() {
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    let (sections, d, fir) = random_filter(&mut rng, 12, 6);
    let f = MimoFilter::new(&sections, d, &fir).unwrap();
    let u = input(&mut rng, 20_000);
    let want = reference_f64(&sections, &d, &fir, &u);
    let mut st = MimoState::default();
    let peak = want.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
    let mut worst = 0.0f64;
    for (u, w) in u.iter().zip(&want) {
        let y = f.step(&mut st, u.map(|v| v as f32));
        for i in 0..3 {
            worst = worst.max((f64::from(y[i]) - w[i]).abs());
        }
    }
    assert!(worst / peak < 1e-5, "f32 kernel {:.2e} of the peak from the f64 recursion", worst / peak);
    // Negative control: one coupling coefficient changed by 1 % is seen.
    let mut wrong = sections.clone();
    wrong[3].c[2][1] *= 1.01;
    let g = MimoFilter::new(&wrong, d, &fir).unwrap();
    let mut st = MimoState::default();
    let mut seen = 0.0f64;
    for (u, w) in u.iter().zip(&want) {
        let y = g.step(&mut st, u.map(|v| v as f32));
        seen = seen.max((f64::from(y[2]) - w[2]).abs());
    }
    assert!(seen / peak > 1e-4, "a 1 % coupling error is invisible ({:.1e})", seen / peak);
}

/// The per-axis kernel's section of a 3x3 section's own-axis part.
fn siso(s: &MimoSection, axis: usize) -> Section {
    Section { delta: s.delta, b: [s.b[0][axis], s.b[1][axis]], c: [s.c[axis][0], s.c[axis][1]] }
}

#[test]
fn the_diagonal_embedding_of_three_axis_filters_is_bit_exact_with_them() {
    let mut rng = Rng(42);
    // Per axis: pairs with b = [1, 0] (the host's normal form) then a real pole.
    let mut per_axis: Vec<(Vec<MimoSection>, f32, Vec<f32>)> = Vec::new();
    for axis in 0..3 {
        let mut secs = Vec::new();
        for k in 0..(4 + axis) {
            let r = 0.95 + 0.01 * k as f64;
            let th = 0.1 + 0.2 * k as f64;
            let (sigma, omega) = ((r * th.cos() - 1.0) as f32, (r * th.sin()) as f32);
            let mut s = MimoSection { delta: [sigma, omega, -omega, sigma], ..Default::default() };
            s.b[0][axis] = 1.0;
            s.c[axis] = [rng.next() as f32, rng.next() as f32];
            secs.push(s);
        }
        let mut s = MimoSection { delta: [-0.02, 0.0, 0.0, -0.5], ..Default::default() };
        s.b[0][axis] = 1.0;
        s.b[1][axis] = 1.0;
        s.c[axis] = [rng.next() as f32, rng.next() as f32];
        secs.push(s);
        let taps: Vec<f32> = (0..5).map(|_| 0.1 * rng.next() as f32).collect();
        per_axis.push((secs, 0.9 + 0.1 * rng.next() as f32, taps));
    }
    let sections: Vec<MimoSection> = per_axis.iter().flat_map(|p| p.0.clone()).collect();
    let mut d = [[0.0f32; 3]; 3];
    let mut fir = vec![[[0.0f32; 3]; 3]; 5];
    for (axis, (_, dd, taps)) in per_axis.iter().enumerate() {
        d[axis][axis] = *dd;
        for (m, h) in taps.iter().enumerate() {
            fir[m][axis][axis] = *h;
        }
    }
    let mimo = MimoFilter::new(&sections, d, &fir).unwrap();
    let axes: Vec<AxisFilter> = per_axis
        .iter()
        .enumerate()
        .map(|(axis, (secs, dd, taps))| {
            AxisFilter::with_fir(&secs.iter().map(|s| siso(s, axis)).collect::<Vec<_>>(), *dd, taps).unwrap()
        })
        .collect();
    let mut ms = MimoState::default();
    let mut ss = [AxisState::default(); 3];
    for u in input(&mut rng, 5_000) {
        let u = u.map(|v| v as f32);
        let y = mimo.step(&mut ms, u);
        for axis in 0..3 {
            let want = axes[axis].step(&mut ss[axis], u[axis]);
            assert!(y[axis] == want, "axis {axis}: {} against the per-axis kernel's {want}", y[axis]);
        }
    }
}

#[test]
fn bad_filters_are_refused_with_the_place() {
    let mut rng = Rng(7);
    let (mut sections, d, fir) = random_filter(&mut rng, 3, 2);
    assert!(MimoFilter::new(&sections, d, &fir).is_ok());
    let mut nan_d = d;
    nan_d[1][2] = f32::NAN;
    assert_eq!(MimoFilter::new(&sections, nan_d, &fir), Err(FilterError::NonFinite(MAX_MIMO_SECTIONS)));
    let mut bad_fir = fir.clone();
    bad_fir[1][0][0] = f32::INFINITY;
    assert_eq!(MimoFilter::new(&sections, d, &bad_fir), Err(FilterError::NonFiniteTap(1)));
    let too_many = vec![fir[0]; MAX_MIMO_FIR + 1];
    assert_eq!(MimoFilter::new(&sections, d, &too_many), Err(FilterError::TooManyTaps));
    let keep = sections.clone();
    sections[1].delta = [0.01, 0.1, -0.1, 0.01]; // |pole| > 1
    assert_eq!(MimoFilter::new(&sections, d, &fir), Err(FilterError::Unstable(1)));
    sections = keep.clone();
    sections[2].delta[2] *= 0.5; // stable, but neither normal form nor diagonal
    assert_eq!(MimoFilter::new(&sections, d, &fir), Err(FilterError::NotModal(2)));
    sections = keep.clone();
    sections[0].b[1][2] = f32::NAN;
    assert_eq!(MimoFilter::new(&sections, d, &fir), Err(FilterError::NonFinite(0)));
    let many = vec![keep[0]; MAX_MIMO_SECTIONS + 1];
    assert_eq!(MimoFilter::new(&many, d, &fir), Err(FilterError::TooManySections));
}

#[test]
fn the_runaway_guard_resets_and_counts() {
    let mut rng = Rng(3);
    let (sections, d, fir) = random_filter(&mut rng, 2, 1);
    let f = MimoFilter::new(&sections, d, &fir).unwrap();
    let mut st = MimoState::default();
    assert!(f.step_guarded(&mut st, [1.0, 2.0, 3.0]).is_some());
    assert!(f.step_guarded(&mut st, [f32::NAN, 0.0, 0.0]).is_none());
    assert_eq!(st.nonfinite_resets, 1);
    assert_eq!(st, MimoState { nonfinite_resets: 1, ..MimoState::default() });
    // After the reset it runs on from zero state, as a fresh one would.
    let mut fresh = MimoState::default();
    assert_eq!(f.step(&mut st, [4.0, 5.0, 6.0]), f.step(&mut fresh, [4.0, 5.0, 6.0]));
}
