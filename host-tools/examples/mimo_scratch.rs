use dynocomp::design::mimo::{design_matrix, MatrixOptions};
use dynocomp::design::axis::DesignOptions;
use dynocomp::metrics::{accuracy, lowpass, sample_variance, scoring_band_hz};
use dynocomp::simulate::plate::{inverse_noise_floor, per_axis_noise_floor, simulate_plate, FloorSpec, PlateSetup, PlateSim};
use dynocomp::simulate::SimParams;
use dynocomp_core::mimo::MimoState;
use dynocomp_core::kernel::AxisState;
use std::time::Instant;

fn std_mid(x: &[f64]) -> f64 {
    let n = x.len(); let s = n / 20; let v = &x[s..n - s];
    let m = v.iter().sum::<f64>() / v.len() as f64;
    (v.iter().map(|a| (a - m).powi(2)).sum::<f64>() / v.len() as f64).sqrt()
}

fn main() {
    let fs: f64 = std::env::var("FS").map(|v| v.parse().unwrap()).unwrap_or(51200.0);
    let names: Vec<String> = std::env::args().skip(1).collect();
    for name in names {
        let setup = if let Ok(seed) = name.parse::<u64>() { PlateSetup::random(seed).unwrap() } else { PlateSetup::preset(&name).unwrap() };
        let params = SimParams { fs_hz: fs, duration_s: 0.4, idle_duration_s: 0.3, ..Default::default() };
        let out = simulate_plate(7, &params, &PlateSim { setup, cut_offset_m: [0.0; 3] }).unwrap();
        let r: [f64; 3] = std::array::from_fn(|i| sample_variance(&out.idle[i]));
        let mut opts = MatrixOptions { design: DesignOptions { fs_hz: fs, ..Default::default() }, ..Default::default() }; let mut vf = dynocomp::fit::vf::VfOptions { max_order: 40, ..Default::default() }; if let Ok(t) = std::env::var("TOL") { vf.improvement_tol = t.parse().unwrap(); } if let Ok(m) = std::env::var("MAXO") { vf.max_order = m.parse().unwrap(); } if let Ok(m) = std::env::var("IT") { vf.iterations = m.parse().unwrap(); } if let Ok(m) = std::env::var("DEC") { vf.decimate = m.parse().unwrap(); } opts.matrix_vf = Some(vf);
        let t = Instant::now();
        let exact = {
            use dynocomp::fit::{PoleResidueModel, Term};
            use num_complex::Complex64;
            let entries = (0..9).map(|e| {
                let (i, j) = (e / 3, e % 3);
                let terms = out.impact_modal.modes.iter().map(|m| {
                    let p = m.pole();
                    let w = m.omega();
                    let res = (Complex64::new(1.0, 0.0) + p * (2.0 * m.zeta / w)) / Complex64::new(0.0, 2.0 * p.im) * (m.output[i] * m.input[j]);
                    Term::Pair { pole: p, residue: res }
                }).collect();
                PoleResidueModel { terms, d: 0.0 }
            }).collect();
            dynocomp::fit::matrix::MatrixModel { entries }
        };
        let union = || {
            use dynocomp::fit::vf::{coherence_weights, vector_fit, VfOptions};
            use dynocomp::fit::Term;
            use dynocomp::fit::matrix::{fit_matrix_from, MatrixData};
            let ents: Vec<_> = (0..9).map(|e| out.frf.entry(e / 3, e % 3).unwrap()).collect();
            let w: Vec<Vec<f64>> = ents.iter().map(|e| coherence_weights(e.frf, e.coherence)).collect();
            let mut poles: Vec<(num_complex::Complex64, bool)> = Vec::new();
            for (e, ent) in ents.iter().enumerate() {
                let Ok(f) = vector_fit(&out.frf.freq_hz, ent.frf, &w[e], &VfOptions::default()) else { continue };
                for t in &f.model.terms {
                    let (p, pair) = match *t { Term::Pair { pole, .. } => (pole, true), Term::Real { pole, .. } => (num_complex::Complex64::new(pole, 0.0), false) };
                    if !poles.iter().any(|(q, qp)| *qp == pair && (q - p).norm() < 0.3 * p.re.abs().max(q.re.abs())) { poles.push((p, pair)); }
                }
            }
            poles.sort_by(|a, b| a.0.im.total_cmp(&b.0.im));
            println!("union poles: {:?}", poles.iter().map(|p| ((p.0.norm() / 6.283).round(), (-p.0.re / p.0.norm() * 1e3).round() / 1e3)).collect::<Vec<_>>());
            let data = MatrixData { freq_hz: &out.frf.freq_hz, h: std::array::from_fn(|e| ents[e].frf), w: std::array::from_fn(|e| w[e].as_slice()) };
            let it = std::env::var("UIT").map(|v| v.parse().unwrap()).unwrap_or(0);
            let m = fit_matrix_from(&data, &poles, &VfOptions { iterations: it, ..Default::default() }).unwrap();
            println!("union fit: wrms {:.5} modes {:?}", data.weighted_rms(&m), m.modes().iter().map(|m| (m.0.round(), (m.1*1e3).round()/1e3)).collect::<Vec<_>>());
            m
        };
        let res = if std::env::var("UNION").is_ok() { dynocomp::design::mimo::design_matrix_with_model(&out.frf, union(), r, &opts) } else if std::env::var("EXACT").is_ok() { dynocomp::design::mimo::design_matrix_with_model(&out.frf, exact, r, &opts) } else { design_matrix(&out.frf, r, &opts) };
        let md = match res { Ok(m) => m, Err(e) => { println!("{name}: design failed: {e:#}"); continue; } };
        let dt = t.elapsed().as_secs_f64();
        if let Some(m) = &md.model {
            let tpf = 4125.0 / 60.0 * 4.0;
            let mut line = String::new();
            for k in 1..=14 {
                let f = tpf * k as f64;
                let g = out.impact_modal.frf(f);
                let gh = m.frf(f);
                let e = gh.try_inverse().unwrap() * (g - gh);
                line += &format!(" {:.0}:{:.2}/{:.2}/{:.2}", f, 100.0 * e.row(0).norm(), 100.0 * e.row(1).norm(), 100.0 * e.row(2).norm());
            }
            println!("model force error at harmonics (%, rows x/y/z):{line}");
            let mut l2 = String::new();
            for k in 1..=14 {
                let f = tpf * k as f64;
                let g = out.impact_modal.frf(f);
                let gh = m.frf(f);
                let siso: Vec<f64> = (0..3).map(|i| md.per_axis[i].as_ref().map_or(f64::NAN, |a| (a.model.frf(f) / g[(i, i)] - 1.0).norm())).collect();
                l2 += &format!(" {:.0}: m {:.2}/{:.2}/{:.2} s {:.2}/{:.2}/{:.2}", f, 100.0 * (gh[(0,0)]/g[(0,0)]-1.0).norm(), 100.0 * (gh[(1,1)]/g[(1,1)]-1.0).norm(), 100.0 * (gh[(2,2)]/g[(2,2)]-1.0).norm(), 100.0*siso[0], 100.0*siso[1], 100.0*siso[2]);
            }
            println!("direct entry rel error, matrix vs siso:{l2}");
        }
        let s = &md.summary;
        println!("== {name} fs {fs}: {dt:.2} s, L {} rows {:?}", s.latency, md.rows);
        if let Some(f) = &s.fit { println!("fit order {} wrms {:.4} entry err {:?}\ntrace {:?}\nmodes {:?}", f.order, f.weighted_rms, f.entry_error.map(|r| r.map(|v| (v*1e4).round()/1e4)), f.order_trace.iter().map(|t| (t.0, (t.1*1e5).round()/1e5)).collect::<Vec<_>>(), f.modes.iter().map(|m| (m.0.round(), (m.1*1e3).round()/1e3)).collect::<Vec<_>>()); }
        if let Some(d) = &s.discrete { println!("discrete match {:.2e} taps {} adv {} cond {:.1e}", d.matrix, d.fir_taps, d.advance, d.condition); }
        if let Some(p) = &s.plant { println!("plant states {} ranks {:?} dropped {:.1e} realerr {:.1e}", p.states, p.ranks, p.dropped_bound, p.realization_error); }
        if let Some(k) = &s.kalman { println!("kalman q {:?} order {} dare res {:.1e} it {} innov cond {:.1e} radius {:.6} ng {:?} search passes {} evals {} last step {:.3} last change {:.4}", k.q.map(|v| format!("{v:.2e}")), k.order, k.dare_residual, k.dare_iterations, k.innovation_condition, k.closed_loop_radius, k.noise_gains, k.q_search.passes, k.q_search.evaluations, k.q_search.last_step_decades, k.q_search.last_change); }
        println!("realization: pairs {} diag {} fir {} modal cond {:.1e} score {:.1e}", s.realization.pairs, s.realization.diagonal, s.realization.fir_taps, s.realization.modal_condition, s.realization.verification.score());
        for n in &s.notes { println!("note: {n}"); }
        let band = scoring_band_hz(fs);
        let n = out.measured[0].len();
        let l = s.latency;
        // 3x3 filter
        let mut st = MimoState::default();
        let est: Vec<[f32; 3]> = (0..n).map(|k| md.filter.step(&mut st, [0, 1, 2].map(|i| out.measured[i][k] as f32))).collect();
        let truth_std: [f64; 3] = std::array::from_fn(|i| std_mid(&lowpass(&out.truth[i], fs, band)));
        let spec = FloorSpec { r_n2: r, fs_hz: fs, band_hz: (0.0, band), std_truth_n: truth_std };
        let floor = inverse_noise_floor(&|f| out.cut_modal.frf(f), &spec).unwrap();
        let pfloor = per_axis_noise_floor(&|f| out.cut_modal.frf(f), &spec).unwrap();
        for i in 0..3 {
            let e: Vec<f64> = est[l..].iter().map(|y| y[i] as f64).collect();
            let comb = accuracy(&e, &out.truth[i][..n - l], fs, band).nrmse;
            let raw = accuracy(&out.measured[i], &out.truth[i], fs, band).nrmse;
            let per = md.per_axis[i].as_ref().map(|a| {
                let mut st = AxisState::default();
                let y: Vec<f64> = out.measured[i].iter().map(|u| a.filter.step(&mut st, *u as f32) as f64).collect();
                accuracy(&y[l..], &out.truth[i][..n - l], fs, band).nrmse
            });
            let a = &s.axes[i];
            println!(
                "  {}: raw {:.3}% (pred {:.3}%) | per-axis {:?}% (pred {:?}, self-pred {:?}) | 3x3 pred {:?} | chosen {:?} meas {:.3}% pred {:.3}% | floor {:.3}% ({:.2}x) per-axis floor {:.3}%",
                a.axis, 100.0 * raw, 100.0 * a.raw.error,
                per.map(|v| (v * 1e5).round() / 1e3), a.per_axis.map(|p| (p.error * 1e5).round() / 1e3), a.per_axis_direct_only.map(|p| (p * 1e5).round() / 1e3),
                a.matrix.map(|p| (p.error * 1e5).round() / 1e3), a.source, 100.0 * comb, 100.0 * a.chosen.error,
                100.0 * floor[i], comb / floor[i], 100.0 * pfloor[i]
            );
        }
    }
}
