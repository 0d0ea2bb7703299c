//! The filter DARE on a plant whose time scales spread over five decades
//! (a slow real pole next to z = 1, a real pole beyond Nyquist fitted by its
//! tail, a lightly damped mode and a heavily damped one, a random-walk
//! force): the solution is checked against the Riccati recursion run to its
//! fixed point (an independent computation), and the residual check
//! rejects a wrong P.

use dynocomp::design::discretize::{discretize, Discretization};
use dynocomp::design::kalman::{augmented_plant, dare_residual, solve_filter_dare, DARE_TOLERANCE};
use dynocomp::fit::{PoleResidueModel, Term};
use nalgebra::DMatrix;
use num_complex::Complex64;
use std::f64::consts::TAU;

fn pair(f: f64, zeta: f64, share: f64) -> Term {
    let w = TAU * f;
    let pole = Complex64::new(-zeta * w, w * (1.0 - zeta * zeta).sqrt());
    Term::Pair { pole, residue: Complex64::new(share, 0.0) * pole.norm_sqr() / (2.0 * Complex64::i() * pole.im) }
}

#[test]
fn dare_on_spread_time_scales_matches_the_recursion_and_rejects_a_wrong_p() {
    for (slow_hz, q, r) in [(3.8, 18.2, 0.053), (0.5, 1e-3, 1.0), (0.5, 1e4, 1e-4), (3.8, 1e6, 1e-5)] {
        check(slow_hz, q, r);
    }
}

fn check(slow_hz: f64, q: f64, r: f64) {
    let fs = 25_600.0;
    let m = PoleResidueModel {
        terms: vec![
            Term::Real { pole: -TAU * slow_hz, residue: TAU * slow_hz * 0.02 },
            Term::Real { pole: -TAU * 118e3, residue: TAU * 118e3 * 0.48 },
            pair(260.0, 0.03, 0.05),
            pair(1988.0, 0.5, -0.0065),
            pair(3450.0, 0.02, 0.45),
        ],
        d: 0.0,
    };
    let (dm, _) = discretize(&m, fs, Discretization::Fit, (0.0, 4096.0)).unwrap();
    let plant = augmented_plant(&dm, 0);
    let qm = &plant.g * plant.g.transpose() * q;
    let sol = solve_filter_dare(&plant.a, &plant.c, &qm, r).unwrap();
    let ric = |p: &DMatrix<f64>| {
        let s = (plant.c.transpose() * p * &plant.c)[(0, 0)] + r;
        let apc = &plant.a * p * &plant.c;
        &plant.a * p * plant.a.transpose() - &apc * apc.transpose() / s + &qm
    };
    let plain = (&sol.p - ric(&sol.p)).norm() / sol.p.norm();
    eprintln!(
        "slow {slow_hz} Hz, q {q:e}, R {r:e}: n {}, residual {:.2e} (over ‖P‖ alone {:.2e}), {} doubling steps",
        plant.a.nrows(),
        sol.residual,
        plain,
        sol.iterations
    );
    assert!(sol.residual < DARE_TOLERANCE);
    // Independent: the Riccati recursion from P = Q to its fixed point.
    let mut p = qm.clone();
    for _ in 0..2_000_000 {
        let next = ric(&p);
        let done = (&next - &p).norm() <= 1e-15 * next.norm();
        p = (&next + next.transpose()) * 0.5;
        if done {
            break;
        }
    }
    let diff = (&p - &sol.p).norm() / p.norm();
    assert!(diff < 1e-7, "doubling + Newton vs recursion: relative difference {diff:.2e}");
    // Negative controls: a P off by 1e-6 or for another q is rejected.
    let off = &sol.p * (1.0 + 1e-6);
    assert!(dare_residual(&plant.a, &plant.c, &qm, r, &off) > DARE_TOLERANCE);
    let other = solve_filter_dare(&plant.a, &plant.c, &(&qm * 1.1), r).unwrap().p;
    assert!(dare_residual(&plant.a, &plant.c, &qm, r, &other) > DARE_TOLERANCE);
}
