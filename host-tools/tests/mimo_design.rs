//! The 3x3 design against the plate simulator's truth: impact-test matrix →
//! `design_matrix` → the realized f32 `MimoFilter` run on the simulated
//! measurement → NRMSE against the simulator's band-limited true force per
//! axis (DESIGN.md, "Accuracy"), beside the per-axis design's f32 filters
//! on the same record, no compensation, and the noise floor of the exact
//! 3x3 inverse (`inverse_noise_floor`, computed from the simulator's exact
//! FRF at the cut point, not from anything the design made).
//!
//! Thresholds, fixed before the figures were looked at:
//! * where the crosstalk is large (offcentre, tall: peak |G_ij|/|G_ii| of
//!   0.5-1.7) the worst axis of the 3x3 filter is at most half the worst
//!   axis of the per-axis filters;
//! * on every axis the filter used is no worse than 1.25 times the per-axis
//!   filter alone (the choice is made on predictions, which carry the
//!   model's error, so a small margin);
//! * on every axis within [`FLOOR_FACTOR`] of the exact inverse's floor.
//!
//! Negative controls: the same design from a matrix whose cross entries are
//! zeroed fails the crosstalk assertion; a filter perturbed by ten times the
//! verification limit fails the f32 verification; a matrix with a missing
//! or a repeated row is refused with a message saying what to do.
//!
//! `seed_study` (ignored: run it in release) reports the figures of the
//! presets at the four user rates and of random set-ups from seeds 1..=6;
//! with `MIMO_STUDY_FORCE=flat` under the force the default prediction
//! assumes ([`flat_force`]) instead of a milling cut, and with
//! `MIMO_STUDY_NOTES` the model's error by source and by band
//! ([`model_error`]). Further knobs: `MIMO_STUDY_IMPACTS=N` impacts per
//! direction, `MIMO_STUDY_MODEL=exact|exact-below` (the design on the
//! simulator's model), `MIMO_STUDY_ABOVE=inverse`, `MIMO_ABOVE_BAND_SWAP`
//! (`VfOptions::above_band_swap`), `MIMO_NO_REFINE`, `MIMO_NO_SEED`
//! (`VfOptions::seed_unfitted` off), `MIMO_NO_RANK_ONE`
//! (`VfOptions::rank_one_residues` off), `MIMO_LINE_WEIGHTS=averaged`
//! (`VfOptions::line_weights`), `MIMO_FULL_ORDER`, `MIMO_STUDY_NOISE=own`
//! (each random set-up its own noise draw, [`noise_seed`]).

#![allow(clippy::needless_range_loop)] // axis indices index several arrays at once
#![allow(clippy::neg_cmp_op_on_partial_ord)] // a negative control asserts a bound is not met, NaN included

use dynocomp::design::above_band::AboveBand;
use dynocomp::design::axis::DesignOptions;
use dynocomp::design::force_spectrum::ForceRecord;
use dynocomp::design::mimo::criterion::RowError;
use dynocomp::design::mimo::image::build_matrix_image;
use dynocomp::design::mimo::{design_matrix, MatrixDesign, MatrixOptions, RowSource};
use dynocomp::design::mimo::{
    with_matrix_weighted_by, with_weighted_matrix, LineWeights, MATRIX_ITERATIONS, MATRIX_MAX_ORDER,
};
use dynocomp::fit::matrix::{matrix_vector_fit, refit_kept, MatrixData, MatrixModel};
use dynocomp::fit::vf::VfOptions;
use dynocomp::fit::Term;
use dynocomp::frf::Frf;
use dynocomp::io::signal_csv::SignalRecord;
use dynocomp::metrics::{accuracy, accuracy_as_written, lowpass, sample_variance, scoring_band_hz, AsWritten};
use dynocomp::numeric::lti::MimoStateSpace;
use dynocomp::offline::matrix_smoother::{matrix_sidecar, smooth_matrix_record};
use dynocomp::realize::mimo::verify_filter;
use dynocomp::simulate::plate::{inverse_noise_floor, simulate_plate, FloorSpec, PlateSetup, PlateSim, PlateSimOutput};
use dynocomp::simulate::SimParams;
use dynocomp_core::kernel::AxisState;
use dynocomp_core::mimo::{MimoFilter, MimoState};
use nalgebra::{DMatrix, DVector};
use num_complex::Complex64;
use std::f64::consts::PI;
use std::sync::{Arc, Mutex, OnceLock};

/// Largest accepted ratio of the compensated NRMSE to the exact 3x3
/// inverse's noise floor, per axis.
const FLOOR_FACTOR: f64 = 8.0;
/// Largest accepted ratio of the filter used to the per-axis filter alone.
const NO_WORSE: f64 = 1.25;
/// Where the crosstalk is large: worst 3x3 axis ≤ this × worst per-axis axis.
const CROSSTALK_GAIN: f64 = 0.5;

/// The figures of one set-up at one rate (NRMSE, fractions).
#[derive(Debug)]
struct Figures {
    raw: [f64; 3],
    per_axis: [f64; 3],
    used: [f64; 3],
    floor: [f64; 3],
    rows: [RowSource; 3],
    predicted: [f64; 3],
    /// The same with the fit's uncertainty counted (`RowError::with_fit`).
    predicted_with_fit: [f64; 3],
    peak_crosstalk: f64,
    /// The filter used, as written, against the anti-aliased truth, and a
    /// perfect band-limited estimate against the same truth (DESIGN.md).
    as_written: [f64; 3],
    perfect: [f64; 3],
    /// `compensate --offline`'s zero-lag smoother of the image's sidecar
    /// (NaN where the design has no 3x3 model).
    offline: [f64; 3],
}

impl Figures {
    fn worst(v: &[f64; 3]) -> f64 {
        v.iter().fold(0.0f64, |m, x| m.max(*x))
    }

    fn line(&self, name: &str, fs: f64) -> String {
        let p = |v: [f64; 3]| format!("{:.3}/{:.3}/{:.3}", 100.0 * v[0], 100.0 * v[1], 100.0 * v[2]);
        format!(
            "{name:>10} {:>6.2} kHz  xtalk {:>5.2}  raw {}  per-axis {}  3x3 {}  floor {}  pred {}  rows {:?}  \
             as written {}  perfect {}  offline {}",
            fs / 1e3,
            self.peak_crosstalk,
            p(self.raw),
            p(self.per_axis),
            p(self.used),
            p(self.floor),
            p(self.predicted),
            self.rows,
            p(self.as_written),
            p(self.perfect),
            p(self.offline)
        )
    }
}

fn setup(name: &str) -> PlateSetup {
    match name.parse::<u64>() {
        Ok(seed) => PlateSetup::random(seed).unwrap(),
        Err(_) => PlateSetup::preset(name).unwrap(),
    }
}

/// A 0.4 s milling record (0.3 s idle) of `name` (a preset or a seed) at `fs`.
/// With `MIMO_STUDY_FORCE=flat`, the force is instead [`flat_force`].
fn record(name: &str, fs: f64) -> PlateSimOutput {
    record_with(name, fs, std::env::var("MIMO_STUDY_FORCE").as_deref() == Ok("flat"))
}

/// [`record`], of [`flat_force`] where `flat`, else of the milling cut.
fn record_with(name: &str, fs: f64, flat: bool) -> PlateSimOutput {
    // MIMO_STUDY_IMPACTS=N: N impacts per direction (averaged), for the
    // fit's bias against its variance.
    let impacts = std::env::var("MIMO_STUDY_IMPACTS").ok().and_then(|v| v.parse().ok());
    record_drawn(name, fs, flat, impacts, noise_seed(name))
}

/// [`record_with`] from the random streams of `seed`, with `impacts` per
/// hammer direction where given (else the simulator's default, 7).
fn record_drawn(name: &str, fs: f64, flat: bool, impacts: Option<usize>, seed: u64) -> PlateSimOutput {
    let mut params = SimParams { fs_hz: fs, duration_s: 0.4, idle_duration_s: 0.3, ..Default::default() };
    if flat {
        params.excitation = Some(flat_force(fs));
        // Its response reaches 6 times the force at the sensor modes, past
        // the default ±2000 N rails: a range that holds it, at the same
        // resolution in N (the clipping would be an error no prediction has).
        params.measurement.adc_range_n = 32_000.0;
        params.measurement.adc_bits = 20;
    }
    if let Some(n) = impacts {
        params.impact.n_impacts = n;
    }
    simulate_plate(seed, &params, &PlateSim { setup: setup(name), cut_offset_m: [0.0; 3] }).unwrap()
}

/// The seed of a record's random streams (impact test, noise, idle): 7,
/// the draw every regression case here was found on; with
/// `MIMO_STUDY_NOISE=own`, a random set-up's own draw (its seed plus 10^6),
/// so that a study's set-ups do not share the impact test's noise line by
/// line.
fn noise_seed(name: &str) -> u64 {
    match (std::env::var("MIMO_STUDY_NOISE").as_deref(), name.parse::<u64>()) {
        (Ok("own"), Ok(seed)) => own_noise_seed(seed),
        _ => 7,
    }
}

/// Random set-up `seed`'s own draw of [`noise_seed`].
fn own_noise_seed(seed: u64) -> u64 {
    1_000_000 + seed
}

/// The force the default design's prediction assumes: a flat spectrum over
/// the scoring band at the default `force_rms` (100 N) on each axis, the axes
/// independent. Against it the prediction is tested alone; against a cut
/// it is tested together with the cut's likeness to a flat spectrum.
fn flat_force(fs: f64) -> dynocomp::simulate::shaker::Excitation {
    let rms_n = DesignOptions::default().force_rms;
    dynocomp::simulate::shaker::Excitation::flat_force(fs, rms_n, 11)
}

fn noise(out: &PlateSimOutput) -> [f64; 3] {
    std::array::from_fn(|i| sample_variance(&out.idle[i]))
}

fn design(frf: &Frf, out: &PlateSimOutput) -> anyhow::Result<MatrixDesign> {
    design_above(frf, out, study_above_band())
}

/// The default design's treatment above the band; with
/// MIMO_STUDY_ABOVE=inverse, the exact inverse continued above the band.
fn study_above_band() -> AboveBand {
    match std::env::var("MIMO_STUDY_ABOVE").as_deref() {
        Ok("inverse") => AboveBand::Inverse,
        _ => AboveBand::default(),
    }
}

/// `record(name, fs)` and its [`design_above`], made once in this test
/// binary for all the tests that judge the same design (they run in
/// parallel: the first to ask designs, the others wait for it).
fn shared_design(name: &str, fs: f64, above_band: AboveBand) -> Arc<(PlateSimOutput, MatrixDesign)> {
    type Slot = Arc<OnceLock<Arc<(PlateSimOutput, MatrixDesign)>>>;
    type Key = (String, u64, AboveBand);
    static SHARED: Mutex<Vec<(Key, Slot)>> = Mutex::new(Vec::new());
    let key = (name.to_string(), fs.to_bits(), above_band);
    let slot = {
        let mut shared = SHARED.lock().unwrap();
        match shared.iter().find(|(k, _)| *k == key) {
            Some((_, slot)) => slot.clone(),
            None => {
                let slot = Slot::default();
                shared.push((key, slot.clone()));
                slot
            }
        }
    };
    slot.get_or_init(|| {
        let out = record(name, fs);
        let md = design_above(&out.frf, &out, above_band).unwrap();
        Arc::new((out, md))
    })
    .clone()
}

/// The off-centre plate at 51.2 kHz designed on the free fit
/// (`VfOptions::rank_one_residues` off), once for the tests that share it:
/// its latency-8 3x3 block does not verify in f32 (1.5e-4 of its RMS against
/// 1e-4). The paths these tests check are the realization's, not the fit's.
fn free_residues_offcentre_51k() -> Arc<(PlateSimOutput, MatrixDesign)> {
    static FREE: OnceLock<Arc<(PlateSimOutput, MatrixDesign)>> = OnceLock::new();
    FREE.get_or_init(|| {
        let out = record("offcentre", 51_200.0);
        let design = DesignOptions { fs_hz: out.params.fs_hz, above_band: study_above_band(), ..Default::default() };
        let matrix_vf = Some(VfOptions { rank_one_residues: false, ..opts_vf() });
        let opts = MatrixOptions { design, load_limit_permille: box_limit(), matrix_vf, ..Default::default() };
        let md = design_matrix(&out.frf, noise(&out), &opts).unwrap();
        Arc::new((out, md))
    })
    .clone()
}

fn design_above(frf: &Frf, out: &PlateSimOutput, above_band: AboveBand) -> anyhow::Result<MatrixDesign> {
    let design = DesignOptions { fs_hz: out.params.fs_hz, above_band, ..Default::default() };
    // MIMO_NO_REFINE: the 3x3 fit without its maximum-likelihood refinement
    // (the per-axis fits keep theirs), for the studies' before-and-after.
    // MIMO_ABOVE_BAND_SWAP: the 3x3 fit with `VfOptions::above_band_swap`.
    // MIMO_NO_SEED: the 3x3 fit without `VfOptions::seed_unfitted`.
    // MIMO_NO_RANK_ONE: the 3x3 fit without `VfOptions::rank_one_residues`.
    // MIMO_LINE_WEIGHTS=averaged: `VfOptions::line_weights` averaged.
    let matrix_vf = match std::env::var_os("MIMO_ABOVE_BAND_SWAP") {
        Some(_) => Some(VfOptions { above_band_swap: true, ..opts_vf() }),
        None => (["MIMO_NO_REFINE", "MIMO_NO_SEED", "MIMO_NO_RANK_ONE", "MIMO_LINE_WEIGHTS"]
            .iter()
            .any(|v| std::env::var_os(v).is_some()))
        .then(opts_vf),
    };
    let opts = MatrixOptions { design, load_limit_permille: box_limit(), matrix_vf, ..Default::default() };
    design_matrix(frf, noise(out), &opts)
}

/// The transmission zeros of `m` (rad/s): the eigenvalues of A − B D⁻¹ C
/// of a real realization with two states per pair and input (none where
/// the direct term D is singular), for the diagnostics of [`model_error`].
fn transmission_zeros(m: &MatrixModel) -> Vec<Complex64> {
    let pairs: Vec<usize> = (0..m.terms()).filter(|&k| m.pole(k).1).collect();
    let n = 6 * pairs.len();
    let (mut a, mut b, mut c) = (DMatrix::<f64>::zeros(n, n), DMatrix::<f64>::zeros(n, 3), DMatrix::<f64>::zeros(3, n));
    for (q, &k) in pairs.iter().enumerate() {
        let p = m.pole(k).0;
        for j in 0..3 {
            let s0 = 6 * q + 2 * j;
            // x1' = x2, x2' = −|p|² x1 + 2 Re p x2 + u_j: 1/((s − p)(s − p̄)).
            a[(s0, s0 + 1)] = 1.0;
            a[(s0 + 1, s0)] = -p.norm_sqr();
            a[(s0 + 1, s0 + 1)] = 2.0 * p.re;
            b[(s0 + 1, j)] = 1.0;
            for i in 0..3 {
                let Term::Pair { residue: r, .. } = m.entry(i, j).terms[k] else { continue };
                // R/(s − p) + c.c. = (2 Re R s − 2 Re(R p̄))/((s − p)(s − p̄)).
                c[(i, s0)] = -2.0 * (r * p.conj()).re;
                c[(i, s0 + 1)] = 2.0 * r.re;
            }
        }
    }
    let d = DMatrix::from_fn(3, 3, |i, j| m.entry(i, j).d);
    let Some(d_inv) = d.try_inverse() else { return Vec::new() };
    (a - &b * d_inv * &c).complex_eigenvalues().iter().copied().collect()
}

/// The simulator's exact G at the cut point as a pole-residue model: each
/// mode's c_i b_j (1 + 2ζs/ω)/(s² + 2ζωs + ω²) as the pair R/(s − p) + c.c.
/// with R = c_i b_j (2ζp/ω + 1)/(p − p̄); the modes above `below_hz` only
/// as their share of G(0), in the direct term.
fn exact_model(out: &PlateSimOutput, below_hz: f64) -> MatrixModel {
    let entries = (0..9)
        .map(|e| {
            let (i, j) = (e / 3, e % 3);
            let above = out.cut_modal.modes.iter().filter(|m| m.fn_hz > below_hz);
            let d = above.map(|m| m.residue()[i][j]).sum::<f64>();
            let terms = out
                .cut_modal
                .modes
                .iter()
                .filter(|m| m.fn_hz <= below_hz)
                .map(|m| {
                    let (w, z) = (m.omega(), m.zeta);
                    let p = dynocomp::fit::modes::pole_at(w, z);
                    let k = m.output[i] * m.input[j];
                    Term::Pair { pole: p, residue: k * (2.0 * z * p / w + 1.0) / (p - p.conj()) }
                })
                .collect();
            dynocomp::fit::PoleResidueModel { terms, d }
        })
        .collect();
    let model = MatrixModel { entries };
    if below_hz.is_infinite() {
        for f in [0.0, 1000.0, 5000.0] {
            assert!((model.frf(f) - out.cut_modal.frf(f)).norm() < 1e-9 * out.cut_modal.frf(f).norm(), "{f} Hz");
        }
    }
    model
}

/// [`design`] on the given 3x3 `model` instead of the fit of the record's FRF.
fn design_on_model(out: &PlateSimOutput, model: MatrixModel) -> MatrixDesign {
    design_on_model_for(out, model, None)
}

/// [`design_on_model`], for the force spectrum of `rec` where given
/// ([`design_for_record`]).
fn design_on_model_for(out: &PlateSimOutput, model: MatrixModel, rec: Option<ForceRecord>) -> MatrixDesign {
    let force_record = rec.map(std::sync::Arc::new);
    let design = DesignOptions { fs_hz: out.params.fs_hz, force_record, ..Default::default() };
    let opts = MatrixOptions { design, load_limit_permille: box_limit(), ..Default::default() };
    dynocomp::design::mimo::design_matrix_with_model(&out.frf, model, noise(out), &opts).unwrap()
}

/// [`BOX_LIMIT`], or none (the full filter, as `design --full-order`) with
/// `MIMO_FULL_ORDER` set, for the studies' before-and-after figures.
fn box_limit() -> Option<u32> {
    BOX_LIMIT.filter(|_| std::env::var_os("MIMO_FULL_ORDER").is_none())
}

/// The box's load limit, as `design` passes it: images over it are reduced.
const BOX_LIMIT: Option<u32> = Some(dynocomp_core::budget::BOX_LOAD_LIMIT_PERMILLE);

/// NRMSE of `est` (delayed by `lag`) against axis i's truth.
fn score(est: &[f64], out: &PlateSimOutput, i: usize, lag: usize) -> f64 {
    let fs = out.params.fs_hz;
    let n = est.len();
    accuracy(&est[lag..], &out.truth[i][..n - lag], fs, scoring_band_hz(fs)).nrmse
}

/// Run the design's f32 filters on the record and score them (module doc).
fn evaluate(md: &MatrixDesign, out: &PlateSimOutput) -> Figures {
    let fs = out.params.fs_hz;
    let band = scoring_band_hz(fs);
    let lag = md.summary.latency;
    let n = out.measured[0].len();
    let mut st = MimoState::default();
    let est: Vec<[f32; 3]> =
        (0..n).map(|k| md.filter.step(&mut st, [0, 1, 2].map(|i| out.measured[i][k] as f32))).collect();
    let est_axis = |i: usize| est.iter().map(|y| f64::from(y[i])).collect::<Vec<_>>();
    let used = std::array::from_fn(|i| score(&est_axis(i), out, i, lag));
    let written: [AsWritten; 3] = std::array::from_fn(|i| {
        let e = est_axis(i);
        accuracy_as_written(&e[lag..], &out.truth[i][..n - lag], fs, md.summary.axes[i].band_hz.1)
    });
    let per_axis = std::array::from_fn(|i| {
        md.per_axis[i].as_ref().map_or(f64::INFINITY, |a| {
            let mut st = AxisState::default();
            let y: Vec<f64> = out.measured[i].iter().map(|u| f64::from(a.filter.step(&mut st, *u as f32))).collect();
            score(&y, out, i, lag)
        })
    });
    let raw = std::array::from_fn(|i| score(&out.measured[i], out, i, 0));
    let std_truth = std::array::from_fn(|i| {
        let t = lowpass(&out.truth[i], fs, band);
        let s = &t[t.len() / 20..t.len() - t.len() / 20];
        let m = s.iter().sum::<f64>() / s.len() as f64;
        (s.iter().map(|v| (v - m).powi(2)).sum::<f64>() / s.len() as f64).sqrt()
    });
    if std::env::var_os("MIMO_STUDY_NOTES").is_some() {
        diagnose(md, out, &est);
        model_error(md, out);
        residual_excess(md, out);
    }
    let spec = FloorSpec { r_n2: noise(out), fs_hz: fs, band_hz: (0.0, band), std_truth_n: std_truth };
    let floor = inverse_noise_floor(&|f| out.cut_modal.frf(f), &spec).unwrap();
    let x = &md.summary.crosstalk.peak;
    let peak_crosstalk = (0..9).filter(|e| e / 3 != e % 3).map(|e| x[e / 3][e % 3]).fold(0.0, f64::max);
    Figures {
        raw,
        per_axis,
        used,
        floor,
        rows: md.rows,
        predicted: std::array::from_fn(|i| md.summary.axes[i].chosen.error),
        predicted_with_fit: std::array::from_fn(|i| md.summary.axes[i].chosen.with_fit()),
        peak_crosstalk,
        as_written: written.map(|w| w.output.nrmse),
        perfect: written.map(|w| w.perfect.nrmse),
        offline: offline(md, out),
    }
}

/// NRMSE per axis of the zero-lag 3x3 smoother that `compensate --offline`
/// runs: the image and sidecar `design` would write, then the record.
fn offline(md: &MatrixDesign, out: &PlateSimOutput) -> [f64; 3] {
    let image = build_matrix_image(md, &out.frf, 2000.0, [0; 32]).unwrap();
    let sidecar = matrix_sidecar(&image, md);
    if sidecar.matrix.is_none() {
        return [f64::NAN; 3];
    }
    let rec = SignalRecord { t_s: None, channels: (0..3).map(|i| (i, out.measured[i].clone())).collect() };
    let sm = smooth_matrix_record(&image, &sidecar, &rec, "record").unwrap();
    std::array::from_fn(|i| score(&sm.channels[i].1, out, i, 0))
}

/// `seed_study`'s diagnostics (with `MIMO_STUDY_NOTES`): per axis the error
/// of the output `est` and of the raw measurement against the truth by
/// frequency band, and the filter's output on the idle record (noise alone),
/// in band and above it, all relative to the truth's std.
fn diagnose(md: &MatrixDesign, out: &PlateSimOutput, est: &[[f32; 3]]) {
    let fs = out.params.fs_hz;
    let (n, lag) = (est.len(), md.summary.latency);
    let mut st = MimoState::default();
    let idle: Vec<[f32; 3]> =
        (0..out.idle[0].len()).map(|k| md.filter.step(&mut st, [0, 1, 2].map(|i| out.idle[i][k] as f32))).collect();
    for i in 0..3 {
        let y: Vec<f64> = idle.iter().map(|v| f64::from(v[i])).collect();
        let top = md.summary.axes[i].band_hz.1;
        let below = lowpass(&y, fs, top);
        let rms =
            |v: &[f64]| (v[v.len() / 10..].iter().map(|x| x * x).sum::<f64>() / (v.len() - v.len() / 10) as f64).sqrt();
        let above: Vec<f64> = y.iter().zip(&below).map(|(a, b)| a - b).collect();
        let std_t: f64 = {
            let t = &out.truth[i];
            let m = t.iter().sum::<f64>() / t.len() as f64;
            (t.iter().map(|v| (v - m).powi(2)).sum::<f64>() / t.len() as f64).sqrt()
        };
        let e: Vec<f64> = (0..n - lag).map(|k| f64::from(est[k + lag][i]) - out.truth[i][k]).collect();
        let r: Vec<f64> = (0..n).map(|k| out.measured[i][k] - out.truth[i][k]).collect();
        let edges = [0.0, 0.5 * top, top, 1.25 * top, 1.6 * top, 2.0 * top, 3.0 * top, fs / 2.0];
        let cells: Vec<String> = edges
            .windows(2)
            .map(|w| {
                let b = [(w[0], w[1])];
                let (eb, rb) = (dynocomp::metrics::bandpass(&e, fs, &b), dynocomp::metrics::bandpass(&r, fs, &b));
                format!("{:.0}-{:.0}: {:.2}/{:.2}", w[0], w[1], 100.0 * rms(&eb) / std_t, 100.0 * rms(&rb) / std_t)
            })
            .collect();
        eprintln!("    error by band (output/raw, %): {}", cells.join("  "));
        eprintln!(
            "    idle axis {i}: output noise {:.3} % in band, {:.3} % above {:.0} Hz; raw {:.3} %",
            100.0 * rms(&below) / std_t,
            100.0 * rms(&above) / std_t,
            top,
            100.0 * rms(&out.idle[i]) / std_t
        );
    }
}

/// Where the fit leaves more than the impact test's noise
/// ([`dynocomp::fit::matrix::MatrixData::residual_excess`]), with the noise
/// scale the mean weighted residual per real data point: the six largest
/// windows, their excess in units of that scale. A mode the fit left out
/// shows as a window of large excess.
fn residual_excess(md: &MatrixDesign, out: &PlateSimOutput) {
    let Some(model) = &md.model else { return };
    let top = with_weighted_matrix(&out.frf, |data| {
        let v = data.line_residuals(model);
        let sigma2 = v.iter().map(|l| l.0).sum::<f64>() / v.iter().map(|l| l.1).sum::<usize>() as f64;
        let mut w = data.residual_excess(model, sigma2);
        w.truncate(6);
        w
    })
    .unwrap();
    let shown: Vec<String> = top.iter().map(|w| format!("{:.0} Hz: {:.0}", w.peak_hz, w.excess)).collect();
    eprintln!("    residual excess over the noise, largest windows (χ² − N): {}", shown.join(", "));
}

/// `seed_study`'s diagnostics (with `MIMO_STUDY_NOTES`): per row i the
/// distortion an exact inverse of A leaves on B, √(mean_f Σ_j
/// |[A⁻¹(B − A)]_ij|²), over the FRF's lines in the row's band and in the
/// scoring band, for (Ĝ, G) the fitted model against the true G at the cut,
/// (Gm, G) the measured matrix against it, and (Ĝ, Gm) the fit's residual.
/// For a flat force of equal level on each axis it is what the fit's error
/// adds to the row's in-band error.
fn model_error(md: &MatrixDesign, out: &PlateSimOutput) {
    use nalgebra::Matrix3;
    let Some(model) = &md.model else { return };
    let frf = &out.frf;
    let (fs, lag) = (out.params.fs_hz, md.summary.latency);
    let measured = |k: usize| Matrix3::from_fn(|i, j| frf.entry(i, j).map_or(Complex64::new(0.0, 0.0), |e| e.frf[k]));
    let top = scoring_band_hz(fs);
    // Row i of A⁻¹(B − A): Σ_j |·|².
    let inverse_error = |a: Matrix3<Complex64>, b: Matrix3<Complex64>, i: usize| {
        a.try_inverse().map(|inv| {
            let d = inv * (b - a);
            (0..3).map(|j| d[(i, j)].norm_sqr()).sum::<f64>()
        })
    };
    // Row i of the compensator `h` on `g` against the delayed identity at
    // `f`: Σ_j |(H·G)_ij·e^{j2πfL/fs} − δ_ij|².
    let distortion = |h: &nalgebra::DMatrix<Complex64>, g: Matrix3<Complex64>, i: usize, f: f64| {
        let delay = Complex64::from_polar(1.0, 2.0 * PI * f * lag as f64 / fs);
        (0..3)
            .map(|j| {
                let e = (0..3).map(|m| h[(i, m)] * g[(m, j)]).sum::<Complex64>() * delay;
                (e - if i == j { 1.0 } else { 0.0 }).norm_sqr()
            })
            .sum::<f64>()
    };
    let modes =
        |m: Vec<(f64, f64)>| m.iter().map(|(f, z)| format!("{f:.0} Hz ζ {z:.3}")).collect::<Vec<_>>().join(", ");
    eprintln!("    modes, true: {}", modes(out.cut_modal.modes.iter().map(|m| (m.fn_hz, m.zeta)).collect()));
    eprintln!("    modes, fitted: {}", modes(model.modes()));
    let rhp = |m: &MatrixModel| {
        let z = transmission_zeros(m);
        let right: Vec<String> = z
            .iter()
            .filter(|z| z.re > 0.0)
            .map(|z| format!("{:.0}{:+.0}j Hz", z.re / 2.0 / PI, z.im / 2.0 / PI))
            .collect();
        format!("{} of {} zeros in the right half-plane {right:?}", right.len(), z.len())
    };
    eprintln!("    transmission zeros, fitted: {}", rhp(model));
    eprintln!("    FRF lines {:.1}-{:.1} Hz", frf.freq_hz[0], frf.freq_hz[frf.freq_hz.len() - 1]);
    // The full f64 compensator on the record, once for every row.
    let simulated = md.kalman.as_ref().map(|k| {
        let n = out.measured[0].len();
        let input: Vec<DVector<f64>> = (0..n).map(|t| DVector::from_fn(3, |a, _| out.measured[a][t])).collect();
        k.compensator.simulate(&input)
    });
    for i in 0..3 {
        let band = md.summary.axes[i].band_hz;
        let mut cells = Vec::new();
        for (name, hi) in [("row band", band.1), ("scoring band", top)] {
            let mut acc = [0.0f64; 3];
            let mut n = 0usize;
            for (k, &f) in frf.freq_hz.iter().enumerate() {
                if f < band.0 || f > hi {
                    continue;
                }
                let (g, gm, gh) = (out.cut_modal.frf(f), measured(k), model.frf(f));
                for (a, (x, y)) in acc.iter_mut().zip([(gh, g), (gm, g), (gh, gm)]) {
                    *a += inverse_error(x, y, i).unwrap_or(0.0);
                }
                n += 1;
            }
            let r = acc.map(|a| 100.0 * (a / n.max(1) as f64).sqrt());
            cells.push(format!(
                "{name} to {hi:.0} Hz: fit/true {:.3}, measured/true {:.3}, fit/measured {:.3}",
                r[0], r[1], r[2]
            ));
        }
        // Low bands: the per-line noise of the measurement against the fit's error.
        for (lo, hi) in [(0.0f64, 30.0f64), (30.0, 100.0), (100.0, 300.0), (300.0, 1000.0)] {
            let (mut am, mut af, mut n) = (0.0, 0.0, 0usize);
            for (k, &f) in frf.freq_hz.iter().enumerate() {
                if f < lo.max(band.0) || f >= hi {
                    continue;
                }
                let g = out.cut_modal.frf(f);
                am += inverse_error(measured(k), g, i).unwrap_or(0.0);
                af += inverse_error(model.frf(f), g, i).unwrap_or(0.0);
                n += 1;
            }
            let r = |a: f64| 100.0 * (a / n.max(1) as f64).sqrt();
            cells.push(format!(
                "{lo:.0}-{hi:.0} Hz ({n} lines): measured {:.3}, /sqrt(n) {:.4}, fit {:.4}",
                r(am),
                r(am) / (n.max(1) as f64).sqrt(),
                r(af)
            ));
        }
        // The fit against the truth between the lines too: 16 points per line.
        let (mut acc, mut n) = (0.0, 0usize);
        let f0 = frf.freq_hz[0];
        let df = (frf.freq_hz[frf.freq_hz.len() - 1] - f0) / (frf.freq_hz.len() - 1) as f64 / 16.0;
        let mut f = f0;
        while f <= top {
            if f >= band.0 {
                if let Some(e) = inverse_error(model.frf(f), out.cut_modal.frf(f), i) {
                    acc += e;
                    n += 1;
                }
            }
            f += df;
        }
        cells.push(format!("fit/true on a grid of {df:.3} Hz {:.3}", 100.0 * (acc / n.max(1) as f64).sqrt()));
        // At 0 Hz, where a cut's mean force is.
        let at0 = inverse_error(model.frf(0.0), out.cut_modal.frf(0.0), i).map_or(f64::NAN, |e| 100.0 * e.sqrt());
        cells.push(format!("fit/true at 0 Hz {at0:.3}"));
        // The direct entry's static gain, the 3x3 fit's and the per-axis fit's, against the truth.
        let g0 = out.cut_modal.frf(0.0)[(i, i)];
        let m0 = (model.frf(0.0)[(i, i)] / g0 - 1.0).norm() * 100.0;
        let p0 = md.per_axis[i].as_ref().map_or(f64::NAN, |a| (a.model.frf(0.0) / g0 - 1.0).norm() * 100.0);
        cells.push(format!("G_ii(0) off the truth: 3x3 fit {m0:.3}, per-axis fit {p0:.3}"));
        let (Some(k), Some(y)) = (&md.kalman, &simulated) else {
            eprintln!("    model error row {i} (%): {}", cells.join("; "));
            continue;
        };
        // `lines` evenly over the row's band, those in [lo, hi) (Hz), and
        // the mean over all `lines` of the full compensator's distortion on
        // them against the model and against the truth (a flat force).
        let flat_distortion = |lines: usize, lo: f64, hi: f64| {
            let freqs: Vec<f64> = (0..lines)
                .map(|m| band.0 + (band.1 - band.0) * (m as f64 + 0.5) / lines as f64)
                .filter(|f| *f >= lo && *f < hi)
                .collect();
            let h = k.compensator.freq_responses(&freqs, fs);
            let (mut dm, mut dt) = (0.0, 0.0);
            for (f, h) in freqs.iter().zip(&h) {
                dm += distortion(h, model.frf(*f), i, *f);
                dt += distortion(h, out.cut_modal.frf(*f), i, *f);
            }
            [dm, dt].map(|d| 100.0 * (d / lines as f64).sqrt())
        };
        // On the criterion's 200 lines and on a grid 50 times finer.
        for lines in [200usize, 10_000] {
            let [m, t] = flat_distortion(lines, f64::NEG_INFINITY, f64::INFINITY);
            cells.push(format!("distortion on {lines} lines: model {m:.3}, true {t:.3}"));
        }
        let y: Vec<f64> = y.iter().map(|v| v[i]).collect();
        let n = out.measured[0].len();
        let e = lowpass(&y[lag..], fs, top);
        let t = lowpass(&out.truth[i][..n - lag], fs, top);
        let m = e.len();
        let mid = m / 4..3 * m / 4;
        let err: Vec<f64> = e.iter().zip(&t).map(|(p, q)| p - q).collect();
        let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
        // Every figure over the middle half, against the truth's std there.
        let sd_t = sample_variance(&t[mid.clone()]).sqrt();
        let edges = [0.0, 10.0, 100.0, 300.0, 1000.0, 2000.0, 3000.0, top];
        let by_band: Vec<String> = edges
            .windows(2)
            .map(|w| {
                let b = dynocomp::metrics::bandpass(&err, fs, &[(w[0], w[1])]);
                let [_, fd] = flat_distortion(2000, w[0], w[1]);
                format!("{:.0}-{:.0}: {:.3}/{fd:.3}", w[0], w[1], 100.0 * rms(&b[mid.clone()]) / sd_t)
            })
            .collect();
        eprintln!("    row {i} error by band, time / frequency domain (%): {}", by_band.join("  "));
        cells.push(format!(
            "full f64 filter in time: {:.3} (5 % cut), {:.3} (middle half)",
            100.0 * score(&y, out, i, lag),
            100.0 * rms(&err[mid]) / sd_t
        ));
        eprintln!("    model error row {i} (%): {}", cells.join("; "));
    }
}

/// The FRF with every cross entry zeroed (the negative control of the
/// crosstalk assertion).
fn without_crosstalk(frf: &Frf) -> Frf {
    let mut f = frf.clone();
    for c in &mut f.cross {
        c.frf.iter_mut().for_each(|v| *v = Complex64::new(0.0, 0.0));
    }
    f
}

fn check_no_worse_and_floor(fig: &Figures, what: &str) {
    for i in 0..3 {
        assert!(
            fig.used[i] <= NO_WORSE * fig.per_axis[i],
            "{what} axis {i}: the filter used ({:.3} %) is worse than the per-axis filter ({:.3} %)",
            100.0 * fig.used[i],
            100.0 * fig.per_axis[i]
        );
        assert!(
            fig.used[i] <= FLOOR_FACTOR * fig.floor[i],
            "{what} axis {i}: {:.3} % is more than {FLOOR_FACTOR} times the exact inverse's floor {:.3} %",
            100.0 * fig.used[i],
            100.0 * fig.floor[i]
        );
    }
}

fn crosstalk_compensated(fig: &Figures) -> bool {
    Figures::worst(&fig.used) <= CROSSTALK_GAIN * Figures::worst(&fig.per_axis)
}

/// Large crosstalk: the 3x3 design beats per-axis compensation, and the
/// design without the cross entries does not (negative control).
fn large_crosstalk(name: &str, fs: f64) {
    let out = record(name, fs);
    let md = design(&out.frf, &out).unwrap();
    let fig = evaluate(&md, &out);
    eprintln!("{}", fig.line(name, fs));
    assert!(fig.peak_crosstalk > 0.5, "{name}: the crosstalk should be large, peak {:.2}", fig.peak_crosstalk);
    assert!(
        crosstalk_compensated(&fig),
        "{name} at {fs} Hz: the 3x3 design does not beat per-axis compensation: {fig:?}"
    );
    check_no_worse_and_floor(&fig, name);
    let blind = design(&without_crosstalk(&out.frf), &out).unwrap();
    let blind_fig = evaluate(&blind, &out);
    eprintln!("{}", blind_fig.line(&format!("{name}-diag"), fs));
    assert!(
        !crosstalk_compensated(&blind_fig),
        "negative control: a design blind to the crosstalk passed: {blind_fig:?}"
    );
}

#[test]
#[ignore = "a minute of designs in release, by hand (CI runs the CLI offcentre test): --release -- --ignored"]
fn offcentre_10k() {
    large_crosstalk("offcentre", 10_240.0);
}

/// Largest ratio, on any axis, of the 3x3 image's output as written to a
/// perfect band-limited estimate's figure (both against the truth through
/// the anti-aliasing filter alone) that the quiet design must meet on the
/// off-centre plate at 25.6 kHz. Fixed from the design before the quiet
/// rows (inverse above the band: 6.2 / 2.6 / 6.4x) and what they reach
/// (4.5 / 0.8 / 3.0x); the issue's target, 1.1x, is not met (BENCHMARKS.md).
const AS_WRITTEN_FACTOR: f64 = 5.0;

/// The 3x3 rows are quiet above the band (`--above-band quiet`, the
/// default): on the off-centre plate at 25.6 kHz the output as written is
/// within [`AS_WRITTEN_FACTOR`] of a perfect band-limited estimate on every
/// axis, and the band-limited error is no worse than 1.05 times the
/// inverse design's. Negative control: the inverse design (the exact
/// inverse continued above the band) fails the as-written bound.
#[test]
#[ignore = "minutes in a debug build: scripts/test.sh runs it with --release --ignored"]
fn quiet_3x3_rows_above_the_band() {
    let figures = |above| {
        let shared = shared_design("offcentre", 25_600.0, above);
        let (out, md) = (&shared.0, &shared.1);
        assert!(md.rows.iter().all(|r| *r == RowSource::Matrix), "{:?}", md.rows);
        let k = md.summary.kalman.as_ref().unwrap();
        let fig = evaluate(md, out);
        eprintln!("{}  {above:?}, shapes {:?}", fig.line("offcentre", 25_600.0), k.force_shape);
        (fig, k.force_shape)
    };
    let worst_ratio = |f: &Figures| (0..3).map(|i| f.as_written[i] / f.perfect[i]).fold(0.0, f64::max);
    let (quiet, shapes) = figures(AboveBand::Quiet);
    let (inverse, no_shapes) = figures(AboveBand::Inverse);
    assert!(shapes.iter().all(Option::is_some) && no_shapes.iter().all(Option::is_none));
    assert!(
        worst_ratio(&quiet) <= AS_WRITTEN_FACTOR,
        "quiet: as written {:?} against perfect {:?}",
        quiet.as_written,
        quiet.perfect
    );
    assert!(
        !(worst_ratio(&inverse) <= AS_WRITTEN_FACTOR),
        "negative control: the inverse design passed: as written {:?} against perfect {:?}",
        inverse.as_written,
        inverse.perfect
    );
    for i in 0..3 {
        assert!(
            quiet.used[i] <= 1.05 * inverse.used[i],
            "axis {i}: band-limited {:.3} % quiet against {:.3} % inverse",
            100.0 * quiet.used[i],
            100.0 * inverse.used[i]
        );
    }
}

/// Where the latency rule's choice does not verify in f32, the design does
/// not give up the crosstalk compensation: on the off-centre plate at 51.2
/// kHz (`--free-residues`) latency 8's 3x3 block deviates by 1.5e-4 of its
/// RMS in f32 (limit 1e-4), and the image used to fall back to per-axis rows
/// (worst axis 12.8 %). Designed with a load limit of 42 % (`design
/// --max-load 42`), where neither a reduction of it that fits nor latency
/// 6's filter is on the box, the latency rule chooses, on their
/// predictions, between the next latency whose 3x3 rows verify and latency
/// 8 reduced to the highest order that verifies; the note carries that
/// comparison either way (the unit tests of `design::mimo::choose` take
/// each branch on outcomes set by hand). On this record it took latency 6
/// with the golden-section q search and takes the reduction with Brent's
/// (latency 8 reduced predicts 0.20 / 0.63 / 0.23 % against latency 6's
/// 0.36 / 0.45 / 0.16 %; measured 0.28 / 0.39 / 0.89 % against 0.26 / 0.38 / 0.93 %).
/// The control that the first choice did fail is the reduction's own
/// record of the full filter's f32 deviation. The image beats per-axis
/// compensation and stays within the floor factor. Within the box's 60 %,
/// latency 8's block reduced to fit verifies and is used
/// (`a_3x3_filter_over_the_load_limit_is_reduced_to_fit_where_it_stays_accurate`).
#[test]
#[ignore = "minutes in a debug build: scripts/test.sh runs it with --release --ignored"]
fn a_latency_that_does_not_verify_gives_way_by_the_latency_rule() {
    let shared = free_residues_offcentre_51k();
    let out = &shared.0;
    let design = DesignOptions { fs_hz: out.params.fs_hz, above_band: study_above_band(), ..Default::default() };
    let matrix_vf = Some(VfOptions { rank_one_residues: false, ..opts_vf() });
    let opts = MatrixOptions { design, load_limit_permille: Some(420), matrix_vf, ..Default::default() };
    let md = &design_matrix(&out.frf, noise(out), &opts).unwrap();
    let fig = evaluate(md, out);
    eprintln!("{}  latency {}", fig.line("offcentre", 51_200.0), md.summary.latency);
    let notes = &md.summary.notes;
    let next = notes.iter().find(|n| n.contains("is used instead"));
    let reduced = notes.iter().find(|n| n.starts_with("the box runs no reduction"));
    match (next, reduced) {
        (Some(n), None) => {
            assert!(n.starts_with("latency 8: ") && n.contains("verif") && n.contains("by the same rule"), "{n}");
        }
        (None, Some(n)) => {
            assert!(md.summary.latency == 8 && n.contains("latency 6's filter, over the load limit too"), "{n}");
            assert!(n.contains("by the latency rule"), "{n}");
            let r = md.summary.reduction.as_ref().expect("the reduction's figures");
            let why = r.full_not_realized.as_deref().unwrap_or_default();
            assert!(why.contains("deviates from the f64 design by"), "{why}");
        }
        _ => panic!("one note of the latency rule's choice: {notes:?}"),
    }
    assert!(md.rows.iter().all(|r| *r == RowSource::Matrix), "{:?}", md.rows);
    assert!(crosstalk_compensated(&fig), "{fig:?}");
    check_no_worse_and_floor(&fig, "offcentre 51.2 kHz");
}

/// Where the latency rule's choice does not verify in f32 and the box runs
/// neither a reduction of it that beats the alternatives nor the next
/// latency's filter, the image is offline-only at any latency: it holds
/// the rule's choice reduced by balancing to the highest order that
/// verifies, where the latency rule, on the predictions, prefers that to
/// the next latency's filter. `simulate --dyno-preset offcentre` at 51.2
/// kHz (0.5 s), `--free-residues`, `--max-load 20`: latency 8's 3x3 block
/// deviates by 1.5e-4 of its RMS in f32 (limit 1e-4), no order of it is
/// within 20 %, and latency 6's filter (131 %) is not either. Against the
/// simulator's true force (`compensate --truth`) the image is no worse
/// than 1.05 times the latency-6 image on any axis (they are within 3 %
/// of each other); the control is that the same comparison fails for the
/// image the box could run, `--per-axis`, which leaves the crosstalk (1.8x
/// worse on y, 5.9x on x, 9.2x on z). The f32 deviation is a property of
/// this q's realization, not of the set-up: the 102.4 kHz off-centre record this
/// test used before deviated by 1.6e-4 with the golden-section q search
/// and verifies (8.6e-5) with Brent's, at q within 0.1 %.
#[test]
#[ignore = "a 3x3 design takes seconds in release, minutes in debug: scripts/test.sh runs it with --release --ignored"]
fn cli_a_choice_that_does_not_verify_is_reduced_for_an_offline_only_image() {
    use cli_common::dynocomp;
    let dir = cli_common::tmp("mimo", "reduced-offline");
    let p = |n: &str| dir.join(n).display().to_string();
    let (ok, _, err) = cli_common::simulate_plate(&p(""), "offcentre", "51200", &["--duration", "0.5"]);
    assert!(ok, "{err}");
    let design = |image: &str, extra: &[&str]| -> (String, String) {
        let (ok, out, err) = cli_common::design(&p("frf.uff"), &p("idle.csv"), "51200", &p(image), extra);
        assert!(ok, "{err}");
        (out, err)
    };
    let nrmse = |image: &str| -> [f64; 3] {
        let c = format!("{image}.csv");
        let args = ["compensate", "--coeffs", &p(image), "--input", &p("measured.csv"), "--output", &p(&c)];
        let (ok, _, err) = dynocomp(&[&args[..], &["--truth", &p("true_force.csv")]].concat());
        assert!(ok, "{err}");
        cli_common::compensated_nrmse(&err)
    };
    let offline = ["--free-residues", "--max-load", "20"];
    let (out, err) = design("reduced.dcimg", &offline);
    assert!(out.contains("latency 8 samples") && out.contains("reduced for the image"), "{out}");
    assert!(out.contains("the box runs no reduction") && out.contains("none fits the load limit of 20.0 %"), "{out}");
    assert!(out.contains("by the latency rule") && !out.contains("NaN"), "{out}");
    assert!(err.contains("OFFLINE-ONLY IMAGE"), "{err}");
    design("latency6.dcimg", &[&offline[..], &["--latency", "6"]].concat());
    design("per_axis.dcimg", &["--per-axis"]);
    let [reduced, before, per_axis] = ["reduced.dcimg", "latency6.dcimg", "per_axis.dcimg"].map(nrmse);
    eprintln!("reduced latency 8: {reduced:?}\nlatency 6: {before:?}\nper axis: {per_axis:?}");
    for i in 0..3 {
        assert!(reduced[i] <= 1.05 * before[i], "axis {i}: {reduced:?} against {before:?}");
        assert!(!(per_axis[i] <= 1.05 * reduced[i]), "control, axis {i}: per axis {per_axis:?} against {reduced:?}");
    }
}

/// The f32 filter of a 3x3 design verifies against its f64 compensator, a
/// perturbed one does not (negative control).
#[test]
#[ignore = "minutes in a debug build: scripts/test.sh runs it with --release --ignored"]
fn flat_f32_verified() {
    let fs = 25_600.0;
    let out = record("flat", fs);
    let md = design(&out.frf, &out).unwrap();
    let f_band = md.summary.realization.verified_to_hz;
    let v = verify_filter(&md.filter, &md.compensator, fs, f_band).unwrap();
    assert!(v.score() <= 1e-4, "f32 verification score {:.1e}", v.score());
    // Perturb the direct term by ten times the limit of the frequency check
    // times the largest response of any row (computed here from the f64
    // compensator): its entry then deviates by ≥ 10× the limit of its row.
    let freqs: Vec<f64> = (0..=200).map(|k| f_band * k as f64 / 200.0).collect();
    let peak = md
        .compensator
        .freq_responses(&freqs, fs)
        .iter()
        .flat_map(|h| h.iter().map(|v| v.norm()).collect::<Vec<_>>())
        .fold(0.0, f64::max);
    let mut d = *md.filter.d();
    d[0][0] += (10.0 * 1e-4 * peak) as f32;
    let bad = MimoFilter::new(md.filter.sections(), d, md.filter.fir()).unwrap();
    let err = verify_filter(&bad, &md.compensator, fs, f_band).unwrap_err();
    assert!(format!("{err:#}").contains("deviates"), "{err:#}");
}

/// Ill-posed input: a missing cross entry, or a matrix whose y row repeats
/// its x row (a file given twice), is refused with what to do.
#[test]
#[ignore = "minutes in a debug build: scripts/test.sh runs it with --release --ignored"]
fn ill_posed_matrices_are_refused() {
    let out = record("offcentre", 10_240.0);
    let mut missing = out.frf.clone();
    missing.cross.retain(|c| !(c.channel == 1 && c.direction == 0));
    let e = format!("{:#}", design(&missing, &out).unwrap_err());
    assert!(e.contains("nine") && e.contains("yx"), "{e}");

    let mut repeated = out.frf.clone();
    let row_x: Vec<Vec<Complex64>> = (0..3).map(|j| out.frf.entry(0, j).unwrap().frf.to_vec()).collect();
    repeated.axes[1].frf = row_x[1].clone();
    for c in &mut repeated.cross {
        if c.channel == 1 {
            c.frf = row_x[c.direction].clone();
        }
    }
    let e = format!("{:#}", design(&repeated, &out).unwrap_err());
    assert!(e.contains("singular") && e.contains("mapping"), "{e}");
}

/// A representative record of the cut for `--force-prior spectrum`: the
/// measured channels of another run (seed 8) of the same set-up and cut.
fn force_record(name: &str, fs: f64) -> ForceRecord {
    let params = SimParams { fs_hz: fs, duration_s: 0.4, idle_duration_s: 0.3, ..Default::default() };
    let other = simulate_plate(8, &params, &PlateSim { setup: setup(name), cut_offset_m: [0.0; 3] }).unwrap();
    ForceRecord { source: format!("{name}-seed-8"), channels: other.measured.map(Some) }
}

fn design_for_record(frf: &Frf, out: &PlateSimOutput, rec: ForceRecord) -> anyhow::Result<MatrixDesign> {
    design_with_prior(frf, out, rec, false)
}

/// The design with `rec` as the force record: its spectrum, or with
/// `level_only` its in-band levels (`--force-prior spectrum|level`).
fn design_with_prior(
    frf: &Frf,
    out: &PlateSimOutput,
    rec: ForceRecord,
    level_only: bool,
) -> anyhow::Result<MatrixDesign> {
    design_with_prior_above(frf, out, rec, level_only, AboveBand::default())
}

/// [`design_with_prior`] with `above_band` (`--above-band`).
fn design_with_prior_above(
    frf: &Frf,
    out: &PlateSimOutput,
    rec: ForceRecord,
    level_only: bool,
    above_band: AboveBand,
) -> anyhow::Result<MatrixDesign> {
    design_with_prior_fit(frf, out, rec, level_only, above_band, None)
}

/// [`design_with_prior_above`] with the 3x3 fit's options `matrix_vf`
/// (`None`: the design's own).
fn design_with_prior_fit(
    frf: &Frf,
    out: &PlateSimOutput,
    rec: ForceRecord,
    level_only: bool,
    above_band: AboveBand,
    matrix_vf: Option<VfOptions>,
) -> anyhow::Result<MatrixDesign> {
    let d = DesignOptions {
        fs_hz: out.params.fs_hz,
        force_record: Some(std::sync::Arc::new(rec)),
        force_record_level_only: level_only,
        above_band,
        ..Default::default()
    };
    let opts = MatrixOptions { design: d, load_limit_permille: box_limit(), matrix_vf, ..Default::default() };
    design_matrix(frf, noise(out), &opts)
}

/// `compensate --offline` runs on every 3x3 image `design` writes. The
/// off-centre plate at 10.24 kHz designed for the record's force spectrum
/// (`--force-prior spectrum --above-band inverse`, where q is high) has a
/// zero-lag smoother whose Riccati doubling
/// stops at a residual of 8.4e-3 of its terms, over the limit of 1e-9
/// (1.49e-9 before the q search kept its best candidate): the smoother's
/// Newton steps
/// bring it under, and it estimates the force as well as the box's filter
/// does (within 1.1 times on every axis, against the simulator's truth).
/// Negative control: the doubling alone refuses the same equation.
#[test]
#[ignore = "a 3x3 design takes seconds in release, minutes in debug: scripts/test.sh runs it with --release --ignored"]
fn the_offline_smoother_refines_a_riccati_solution_the_doubling_leaves_over_the_limit() {
    let fs = 10_240.0;
    let out = record("offcentre", fs);
    let rec = force_record("offcentre", fs);
    let md = design_with_prior_above(&out.frf, &out, rec, false, AboveBand::Inverse).unwrap();
    let image = build_matrix_image(&md, &out.frf, 2000.0, [0; 32]).unwrap();
    let model = matrix_sidecar(&image, &md).matrix.expect("a 3x3 model in the sidecar");
    let plant = model.plant(fs, "offcentre").unwrap();
    let err = dynocomp::design::mimo::kalman::solve_dare(&plant, model.q, model.r).unwrap_err();
    eprintln!("the doubling alone: {err:#}");
    assert!(format!("{err:#}").contains("Riccati solution rejected"), "control: {err:#}");
    let box_filter = evaluate(&md, &out);
    offline_within_the_box(&box_filter);
}

/// What `design` predicts `compensate --offline` reaches on its 3x3 image
/// (the smoother's steady-state response on the fitted model, with the
/// fit's uncertainty), against the smoother's NRMSE on the simulator's
/// truth: a flat force on the off-centre plate at 25.6 kHz. The prediction
/// leans optimistic, as it cannot see what the fit missed (0.35-1.45x the
/// measured on plates 56-79, median 0.96; BENCHMARKS.md, "What `compensate
/// --offline` reaches on a 3x3 image"): here 0.48 / 0.60 / 0.81. Asserted:
/// within 0.4-1.5x on every axis. Controls: the model alone (the fit's
/// uncertainty left out) is under 0.4x on some axis, and the real-time
/// filter's error is over 1.5x the offline prediction on some axis, so a
/// prediction that copied the box's would fail the check.
#[test]
#[ignore = "a 3x3 design takes seconds in release, minutes in debug: scripts/test.sh runs it with --release --ignored"]
fn the_offline_prediction_against_the_truth() {
    let fs = 25_600.0;
    let out = record_drawn("offcentre", fs, true, None, 7);
    let md = design(&out.frf, &out).unwrap();
    let fig = evaluate(&md, &out);
    let off: [RowError; 3] = std::array::from_fn(|i| md.summary.axes[i].offline.expect("an offline prediction"));
    for i in 0..3 {
        eprintln!(
            "axis {i}: offline predicted {:.3} % (model alone {:.3} %), measured {:.3} %; real-time filter {:.3} %",
            100.0 * off[i].with_fit(),
            100.0 * off[i].error,
            100.0 * fig.offline[i],
            100.0 * fig.used[i]
        );
    }
    let within = |p: f64, m: f64| (0.4..=1.5).contains(&(p / m));
    for i in 0..3 {
        let ratio = off[i].with_fit() / fig.offline[i];
        assert!(within(off[i].with_fit(), fig.offline[i]), "axis {i}: offline predicted / measured {ratio:.2}");
    }
    assert!((0..3).any(|i| !within(off[i].error, fig.offline[i])), "control: the model alone is within 0.4-1.5x too");
    assert!(
        (0..3).any(|i| fig.used[i] > 1.5 * off[i].with_fit()),
        "control: the real-time filter's errors {:?} are all within 1.5x of the offline prediction",
        fig.used
    );
}

/// `compensate --offline` within 1.1 times the box's filter on every axis,
/// against the simulator's truth.
fn offline_within_the_box(fig: &Figures) {
    for i in 0..3 {
        eprintln!(
            "axis {i}: offline {:.3} %, box {:.3} % ({:?} row), per-axis row {:.3} %",
            100.0 * fig.offline[i],
            100.0 * fig.used[i],
            fig.rows[i],
            100.0 * fig.per_axis[i]
        );
    }
    for i in 0..3 {
        assert!(
            fig.offline[i] <= 1.1 * fig.used[i],
            "axis {i}: offline {:.3} % against the box's {:.3} %",
            100.0 * fig.offline[i],
            100.0 * fig.used[i]
        );
    }
}

/// Seed 1 at 25.6 kHz designed for its record's force spectrum.
///
/// - Quiet above the band (the default, `--above-band quiet`), the output
///   as written is within 1.1 times a perfect band-limited estimate's
///   figure on every axis, against the truth through the anti-aliasing
///   filter alone. Control: the same design with `--above-band inverse`
///   (as every record's design was before) is over 3 times it.
/// - The cut's mean force reaches y through the static crosstalk, which
///   the per-axis row leaves: the criterion counts the record's mean, so y
///   takes the 3x3 row, within 2 times its floor, and the per-axis row's
///   prediction is within 0.67-1.5 times what it delivers. Control: the
///   per-axis row delivers over 5 times the floor (without the mean the
///   judge took it, 14 times the floor, predicted at half of that).
/// - With `--above-band inverse` the criterion keeps falling up to q ≈ 1e12
///   N²/sample, where the box filter's Riccati equation (latency 4) solves
///   after the Newton polish but the offline smoother's (latency 0) does
///   not (residual 0.15 of its terms). The q search refuses those
///   candidates, so `compensate --offline` runs on the image `design`
///   writes and is no worse than the box's filter (within 1.1 times on
///   every axis against the simulator's truth). Control: the search
///   refused candidates it rated better than the one it kept (without the
///   check it ended on q = 7.5e12 / 7.8e11 / 1.9e11, and the record's
///   smoother was refused).
#[test]
#[ignore = "3x3 designs take seconds in release, minutes in debug: scripts/test.sh runs it with --release --ignored"]
fn seed_1_for_its_record_spectrum() {
    let fs = 25_600.0;
    let out = record("1", fs);
    let md = design_with_prior(&out.frf, &out, force_record("1", fs), false).unwrap();
    assert!(!md.summary.flat_force, "predicted for {}", md.summary.forces);
    let fig = evaluate(&md, &out);
    eprintln!("{}", fig.line("1-rec", fs));
    for i in 0..3 {
        let ratio = fig.as_written[i] / fig.perfect[i];
        assert!(ratio <= 1.1, "axis {i}: as written {ratio:.2} times a perfect estimate's figure");
    }
    assert!(fig.per_axis[1] > 5.0 * fig.floor[1], "control: the per-axis row on y {:.3} %", 100.0 * fig.per_axis[1]);
    assert_eq!(fig.rows[1], RowSource::Matrix, "{}", md.summary.axes[1].reason);
    assert!(
        fig.used[1] <= 2.0 * fig.floor[1],
        "y {:.3} % against a floor of {:.3} %",
        100.0 * fig.used[1],
        100.0 * fig.floor[1]
    );
    let predicted = md.summary.axes[1].per_axis.expect("a per-axis design of y").error;
    let ratio = predicted / fig.per_axis[1];
    assert!(
        (0.67..=1.5).contains(&ratio),
        "the per-axis row on y: predicted {predicted:.4} against {:.4}",
        fig.per_axis[1]
    );

    // The model this was found on: the fit without the seeded 474 Hz pair
    // (`VfOptions::seed_unfitted`), on whose seeded model the search ends at
    // q ≈ 9e11 with no candidate refused.
    let unseeded = Some(VfOptions { seed_unfitted: false, ..opts_vf() });
    let inverse =
        design_with_prior_fit(&out.frf, &out, force_record("1", fs), false, AboveBand::Inverse, unseeded).unwrap();
    let search = &inverse.summary.kalman.as_ref().expect("a 3x3 Kalman design").q_search;
    assert!(search.refused > 0, "control: no candidate was refused ({search:?})");
    let fig = evaluate(&inverse, &out);
    eprintln!("{}", fig.line("1-rec-inverse", fs));
    offline_within_the_box(&fig);
    let worst = (0..3).map(|i| fig.as_written[i] / fig.perfect[i]).fold(0.0, f64::max);
    assert!(worst > 3.0, "control: inverse above the band, as written {worst:.2} times a perfect estimate at worst");
}

/// Tall part at 25.6 kHz (crosstalk peaks near the sensor modes, where a
/// milling force has little power): with the cut's force spectrum from a
/// representative record (another run of the cut), every axis uses the row
/// that is no worse than per axis against the truth. Negative control: on
/// the model that fits the close base modes as one pair (the order
/// search's, before the split), the rows judged for flat forces take the
/// 3x3 row on y, which the truth puts at over 1.25 times the per-axis row.
///
/// On the split model x must beat 1.0 % against the truth (per axis
/// 1.98 %); the record's design on the unsplit model, the control, does not.
#[test]
#[ignore = "minutes in a debug build: scripts/test.sh runs it with --release --ignored"]
fn tall_rows_judged_for_the_cut() {
    let fs = 25_600.0;
    let out = record("tall", fs);
    let md = design_for_record(&out.frf, &out, force_record("tall", fs)).unwrap();
    let fig = evaluate(&md, &out);
    eprintln!("{}", fig.line("tall-rec", fs));
    check_no_worse_and_floor(&fig, "tall, rows judged for the record");
    assert!(md.summary.notes.iter().any(|n| n.contains("tall-seed-8")), "{:?}", md.summary.notes);
    assert!(!md.summary.notes.iter().any(|n| n.contains("order search's model")), "{:?}", md.summary.notes);
    assert!(fig.used[0] < 0.010, "x {:.3} % with the split model", 100.0 * fig.used[0]);
    // The control needs the model of the close base modes as one pair (the
    // fit's `unsplit`): the split model's 3x3 rows are good on every axis.
    let band_low = md.summary.axes.iter().map(|a| a.band_hz.0).fold(f64::INFINITY, f64::min);
    let vf = VfOptions { f_identified_hz: band_low, ..opts_vf() };
    let fit = with_weighted_matrix(&out.frf, |data| matrix_vector_fit(data, &vf)).unwrap().unwrap();
    let unsplit = fit.unsplit.expect("the tall part's fit splits its close base modes");
    // Negative control: the record's design on that model leaves x over
    // 1.0 %.
    let fallback = evaluate(&design_on_model_for(&out, unsplit.clone(), Some(force_record("tall", fs))), &out);
    eprintln!("{}", fallback.line("tall-rec-unsplit", fs));
    assert!(fallback.used[0] >= 0.010, "negative control: x {:.3} % on the unsplit model", 100.0 * fallback.used[0]);
    let one_pair = design_on_model(&out, unsplit);
    let flat = evaluate(&one_pair, &out);
    eprintln!("{}", flat.line("tall-flat", fs));
    let no_worse = (0..3).all(|i| flat.used[i] <= NO_WORSE * flat.per_axis[i]);
    assert!(!no_worse, "negative control: the flat judge was no worse on every axis: {flat:?}");
    let flat_md = design(&out.frf, &out).unwrap();
    // The flat choice says it may not suit a cut (the crosstalk is moderate);
    // the CLI offcentre test checks the note is absent where it is large.
    let caveat = flat_md.summary.notes.iter().any(|n| n.contains("moderate") && n.contains("--force-record"));
    assert!(caveat, "no note on the flat choice: {:?}", flat_md.summary.notes);
}

/// A 3x3 filter the kernel cannot hold is reduced for the image: seed 6 at
/// 25.6 kHz, designed for its record on a fit of higher order than the
/// BIC chooses (its poles and eight well-damped pairs more, every residue
/// fitted again to the nine entries), has a 3x3 block that goes into no
/// image: it needs more sections than the kernel holds (48; as measured
/// quiet above the band, 150 states and 51 sections), or no realization of
/// it verifies in f32 (141 states when the record's design was `inverse`
/// above the band). The block
/// is reduced by balancing until it goes into an image, the summary says
/// so, and against the simulator's truth every 3x3 row is within 1.2 times
/// the full filter (run in f64 offline) and no worse than per axis. Negative control: the filter reduced to a third of
/// that order misses the bound.
#[test]
#[ignore = "a 3x3 design takes seconds in release, minutes in debug: scripts/test.sh runs it with --release --ignored"]
fn a_3x3_filter_the_kernel_cannot_hold_is_reduced_for_the_image() {
    let fs = 25_600.0;
    let out = record("6", fs);
    let band_low = 8.0;
    let vf = VfOptions { f_identified_hz: band_low, ..opts_vf() };
    let fit = with_weighted_matrix(&out.frf, |data| matrix_vector_fit(data, &vf)).unwrap().unwrap();
    let mut higher = fit.model.clone();
    for f_hz in [600.0, 1100.0, 1400.0, 1700.0, 2000.0, 2400.0, 3100.0, 3700.0] {
        let w = 2.0 * PI * f_hz;
        let zeta: f64 = 0.15;
        let pole = Complex64::new(-zeta * w, w * (1.0 - zeta * zeta).sqrt());
        for e in &mut higher.entries {
            e.terms.push(Term::Pair { pole, residue: Complex64::new(0.0, 0.0) });
        }
    }
    let keep = vec![true; higher.entries[0].terms.len()];
    let higher = with_weighted_matrix(&out.frf, |data| refit_kept(data, &higher, &keep)).unwrap().unwrap();
    let md = design_on_model_for(&out, higher, Some(force_record("6", fs)));
    let reduction = md.summary.reduction.as_ref().expect("the full filter does not fit the kernel: reduced");
    eprintln!("{}", reduction.line());
    let why = reduction.full_not_realized.as_deref().unwrap_or_default();
    assert!(reduction.used && (why.contains("kernel holds") || why.contains("verifies in f32")), "{why}");
    assert!(reduction.line().starts_with("reduced for the image"), "{}", reduction.line());
    let fig = evaluate(&md, &out);
    eprintln!("{}", fig.line("6-rec", fs));
    check_no_worse_and_floor(&fig, "seed 6, reduced for the image");
    // An axis without a per-axis design at the chosen latency says why (y
    // here, as measured: its f32 filter does not verify at latency 8).
    for (a, p) in md.summary.axes.iter().zip(&md.per_axis) {
        assert!(p.is_some() || a.reason.contains("no per-axis design at this latency (axis"), "{}", a.reason);
    }
    // The full filter, in f64 (offline: the kernel cannot hold it).
    let lag = md.summary.latency;
    let full_nrmse = |c: &MimoStateSpace| -> [f64; 3] {
        let n = out.measured[0].len();
        let input: Vec<DVector<f64>> = (0..n).map(|k| DVector::from_fn(3, |i, _| out.measured[i][k])).collect();
        let y = c.simulate(&input);
        std::array::from_fn(|i| score(&y.iter().map(|v| v[i]).collect::<Vec<_>>(), &out, i, lag))
    };
    let full_compensator = md.full_compensator.as_ref().expect("the full filter beside the reduced one");
    let full = full_nrmse(full_compensator);
    eprintln!(
        "full filter (f64) x / y / z: {:.3} / {:.3} / {:.3} %",
        100.0 * full[0],
        100.0 * full[1],
        100.0 * full[2]
    );
    for i in 0..3 {
        if md.rows[i] == RowSource::Matrix {
            assert!(fig.used[i] <= 1.2 * full[i], "axis {i}: {:?} against the full filter {full:?}", fig.used);
        }
    }
    // Negative control: the whole filter reduced to a third of the 3x3
    // block's order.
    let bal = dynocomp::numeric::balanced::balance(full_compensator).unwrap();
    let third = full_nrmse(&bal.reduce(reduction.states / 3, reduction.method).unwrap());
    eprintln!("a third of the order (f64): {third:?}");
    assert!((0..3).any(|i| md.rows[i] == RowSource::Matrix && third[i] > 1.2 * full[i]), "{third:?} against {full:?}");
}

/// The rows judged under flat forces and under a record's force spectrum,
/// on the cases of `MIMO_JUDGE` ("name@fs,…"; default tall at 25.6 kHz).
#[test]
#[ignore = "minutes of designs: run with --release -- --ignored --nocapture"]
fn judge_study() {
    let list = std::env::var("MIMO_JUDGE").unwrap_or_else(|_| "tall@25600".into());
    for c in list.split(',') {
        let (name, fs) = c.split_once('@').expect("name@fs");
        let fs: f64 = fs.parse().expect("fs in Hz");
        let out = record(name, fs);
        let md_flat = design(&out.frf, &out).unwrap();
        let flat = evaluate(&md_flat, &out);
        eprintln!("{}", flat.line(&format!("{name}-flat"), fs));
        for n in md_flat.summary.notes.iter().filter(|n| n.contains("--force-record")) {
            eprintln!("   note: {n}");
        }
        let md = design_for_record(&out.frf, &out, force_record(name, fs)).unwrap();
        let rec = evaluate(&md, &out);
        eprintln!("{}", rec.line(&format!("{name}-rec"), fs));
        for a in &md.summary.axes {
            eprintln!("   {}: {}", a.axis, a.reason);
        }
    }
}

/// The 3x3 prediction (with the fit's uncertainty) is what the image
/// delivers for the force it assumes: a flat spectrum of 100 N per axis
/// over the band ([`flat_force`]), on the flat plate at 10.24 kHz, within
/// 0.67-1.5x of the measured in-band error on every axis. The negative
/// control is the same design on a milling cut: its force sits far below
/// the band's top, where the compensator's distortion lies, and y's
/// prediction is more than 1.5 times what the cut measures.
#[test]
#[ignore = "minutes in a debug build: scripts/test.sh runs it with --release --ignored"]
fn the_prediction_holds_for_the_force_it_assumes() {
    let fs = 10_240.0;
    let flat = record_with("flat", fs, true);
    let md = design(&flat.frf, &flat).unwrap();
    let ratio = |out: &PlateSimOutput| {
        let fig = evaluate(&md, out);
        std::array::from_fn::<f64, 3, _>(|i| fig.predicted_with_fit[i] / fig.used[i])
    };
    let on_flat = ratio(&flat);
    eprintln!("predicted with the fit / measured, flat force: {on_flat:.2?}");
    assert!(on_flat.iter().all(|r| (0.67..=1.5).contains(r)), "{on_flat:?}");
    let on_cut = ratio(&record_with("flat", fs, false));
    eprintln!("the same design on a milling cut: {on_cut:.2?}");
    assert!(on_cut[1] > 1.5, "{on_cut:?}");
}

/// Figures of random set-ups from seeds 1..=6 (chosen before the results)
/// at 25.6 kHz and of the presets at the four user rates; asserts the
/// no-worse and floor thresholds on every one.
#[test]
#[ignore = "minutes of designs: run with --release -- --ignored --nocapture"]
fn seed_study() {
    let mut failures = Vec::new();
    let mut cases: Vec<(String, f64)> = Vec::new();
    for seed in 1..=6u64 {
        cases.push((seed.to_string(), 25_600.0));
    }
    for fs in [10_240.0, 25_600.0, 51_200.0, 102_400.0] {
        for p in ["flat", "offcentre", "tall"] {
            cases.push((p.to_string(), fs));
        }
    }
    // MIMO_STUDY="name@fs,…" runs a subset.
    if let Ok(list) = std::env::var("MIMO_STUDY") {
        cases = list
            .split(',')
            .map(|c| {
                let (n, f) = c.split_once('@').expect("name@fs");
                (n.to_string(), f.parse().expect("fs in Hz"))
            })
            .collect();
    }
    // MIMO_STUDY_FORCE=flat: the force a flat spectrum ([`flat_force`]).
    // MIMO_STUDY_PRIOR=level|spectrum designs with `--force-prior` of that
    // name and another run of the cut as the record ([`force_record`]).
    let prior = std::env::var("MIMO_STUDY_PRIOR").ok();
    // MIMO_STUDY_MODEL=exact: the design on the simulator's exact model, to
    // tell the fit's share of the error from the design's; exact-below:
    // without the modes above 1.2 times the impact test's last line, their
    // static share in the direct term.
    let exact = std::env::var("MIMO_STUDY_MODEL").ok();
    for (name, fs) in cases {
        let out = record(&name, fs);
        let designed = match (prior.as_deref(), exact.as_deref()) {
            (None, Some("exact")) => Ok(design_on_model(&out, exact_model(&out, f64::INFINITY))),
            (None, Some("exact-below")) => {
                Ok(design_on_model(&out, exact_model(&out, 1.2 * out.frf.freq_hz[out.frf.freq_hz.len() - 1])))
            }
            (None, _) => design(&out.frf, &out),
            (Some(p), _) => design_with_prior(&out.frf, &out, force_record(&name, fs), p == "level"),
        };
        match designed {
            Ok(md) => {
                let fig = evaluate(&md, &out);
                eprintln!("{}  latency {}", fig.line(&name, fs), md.summary.latency);
                let ratio = (0..3).map(|i| format!("{:.2}", fig.predicted[i] / fig.used[i])).collect::<Vec<_>>();
                eprintln!("    predicted / measured {}", ratio.join(" / "));
                let ratio =
                    (0..3).map(|i| format!("{:.2}", fig.predicted_with_fit[i] / fig.used[i])).collect::<Vec<_>>();
                eprintln!("    predicted with the fit's uncertainty / measured {}", ratio.join(" / "));
                let off = (0..3)
                    .map(|i| match md.summary.axes[i].offline {
                        Some(o) => {
                            format!("{:.3}/{:.3}/{:.3}", 100.0 * o.error, 100.0 * o.with_fit(), 100.0 * fig.offline[i])
                        }
                        None => "-".into(),
                    })
                    .collect::<Vec<_>>();
                eprintln!("    offline predicted/with the fit's uncertainty/measured (%) {}", off.join("  "));
                for w in &md.summary.worse_than_raw {
                    eprintln!("    worse than raw: {w:?}");
                }
                let image = build_matrix_image(&md, &out.frf, 2000.0, [0; 32]).unwrap();
                let load = dynocomp::realize::load::report(&image, dynocomp_core::budget::BOX_LOAD_LIMIT_PERMILLE);
                eprintln!("    box load {:.1}-{:.1} % (fits: {})", load.load_pct[0], load.load_pct[1], load.fits);
                if let Some(r) = &md.summary.reduction {
                    eprintln!(
                        "    reduction: used {} {} -> {} states, load {} -> {} ‰, predicted {:?} -> {:?}: {}",
                        r.used,
                        r.full_states,
                        r.states,
                        r.full_load_permille,
                        r.load_permille,
                        r.full_predicted,
                        r.predicted,
                        r.reason
                    );
                    if let Some(w) = &r.full_not_realized {
                        eprintln!("    full filter not realized: {w}");
                    }
                }
                if std::env::var_os("MIMO_STUDY_NOTES").is_some() {
                    md.summary.notes.iter().for_each(|n| eprintln!("    note: {n}"));
                    if let Some(f) = &md.summary.fit {
                        eprintln!("    fit: seeded {:?} Hz, dropped {:?} Hz", f.seeded_hz, f.dropped_hz);
                    }
                    for a in &md.summary.axes {
                        eprintln!(
                            "    axis {}: band {:.0}-{:.0} Hz, per axis {:?} (own {:?}), 3x3 {:?}; {}",
                            a.axis, a.band_hz.0, a.band_hz.1, a.per_axis, a.per_axis_direct_only, a.matrix, a.reason
                        );
                    }
                    for l in &md.summary.latency_rounds {
                        eprintln!("    latency {}: {:?}", l.latency, l.predicted);
                    }
                    if let Some(k) = &md.summary.kalman {
                        eprintln!(
                            "    3x3 Kalman: q {:?}, noise gains {:.2?}, radius {:.4}, order {}, search {:?}, force shape {:?}",
                            k.q, k.noise_gains, k.closed_loop_radius, k.order, k.q_search, k.force_shape
                        );
                    }
                }
                let ok = (0..3)
                    .all(|i| fig.used[i] <= NO_WORSE * fig.per_axis[i] && fig.used[i] <= FLOOR_FACTOR * fig.floor[i]);
                if !ok {
                    failures.push(format!("{name} at {fs}"));
                }
            }
            Err(e) => {
                eprintln!("{name:>10} {:>6.2} kHz  refused: {e:#}", fs / 1e3);
                failures.push(format!("{name} at {fs}: {e:#}"));
            }
        }
    }
    assert!(failures.is_empty(), "{failures:?}");
}

mod cli_common;

/// The command line on a record with large crosstalk: `design` of the nine
/// FRFs writes a 3x3 image (format 3) whose JSON shows the crosstalk,
/// `compensate` runs it, and against the simulator's true force its worst
/// axis is at most half the per-axis image's (`design --per-axis`, the
/// negative control: it fails the same bound against the 3x3 image), no
/// axis worse than 1.25 times. `compensate --offline` smooths with the 3x3
/// model from the image's sidecar: the same half against the per-axis
/// image's smoother (reversed: the negative control), and no axis worse
/// than 1.25 times the box's 3x3 filter. What the 3x3 design or its
/// smoother cannot take is refused by name, and writes nothing.
#[test]
#[ignore = "minutes in a debug build: scripts/test.sh runs it with --release --ignored"]
fn cli_offcentre_3x3_image_beats_per_axis() {
    use cli_common::{dynocomp, tmp};
    let dir = tmp("mimo", "offcentre");
    let p = |n: &str| dir.join(n).display().to_string();
    let (ok, _, err) = cli_common::simulate_plate(&p(""), "offcentre", "10240", &["--duration", "0.5", "--seed", "1"]);
    assert!(ok, "{err}");
    let design = |out: &str, extra: &[&str]| cli_common::design(&p("frf.uff"), &p("idle.csv"), "10240", &p(out), extra);
    let rep = p("report");
    let (ok, json, err) = design("c.dcimg", &["--json", "--report", &rep]);
    assert!(ok, "{err}");
    assert!(!err.contains("OFFLINE-ONLY") && !err.contains("for an image the box can run"), "{err}");
    // The 3x3 report: its page names both plots, each a 3x3 grid of panels.
    let index = std::fs::read_to_string(dir.join("report/index.html")).unwrap();
    for svg in ["matrix_frf.svg", "matrix_rows.svg"] {
        assert!(index.contains(svg), "{svg} not on the page");
        let text = std::fs::read_to_string(dir.join("report").join(svg)).unwrap();
        let panels = ["x", "y", "z"].iter().flat_map(|i| ["x", "y", "z"].map(|j| format!("channel {i}, hammer {j}")));
        assert!(panels.into_iter().all(|c| text.contains(&c)), "{svg}: a panel is missing");
    }
    let j: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert_eq!(j["kind"], "3x3", "{json}");
    assert_eq!(j["design"]["flat_force"], true, "the default predicts for a flat force");
    let peak = j["design"]["crosstalk"]["peak"].as_array().unwrap();
    let largest = (0..9).filter(|e| e / 3 != e % 3).map(|e| peak[e / 3][e % 3].as_f64().unwrap()).fold(0.0, f64::max);
    assert!(largest > 0.5, "crosstalk peak {largest}");
    // Large crosstalk: no note that the flat choice may not suit a cut
    // (the tall library test checks it is there where the crosstalk is moderate).
    let notes = j["design"]["notes"].as_array().unwrap();
    assert!(notes.iter().all(|n| !n.as_str().unwrap().contains("moderate")), "{notes:?}");
    // Every row states the fit's own uncertainty (`RowError::fit`; its
    // accuracy is the Monte Carlo unit test of `fit_covariance`): a
    // fraction of a percent on this preset, not nothing.
    for a in j["design"]["axes"].as_array().unwrap() {
        let fit = a["chosen"]["fit"].as_f64();
        assert!(fit.is_some_and(|f| f > 1e-4 && f < 1e-2), "{a}");
    }
    let (ok, inspect, err) = dynocomp(&["inspect", &p("c.dcimg")]);
    assert!(ok && inspect.contains("format v3"), "{inspect}{err}");
    let (ok, _, err) = design("p.dcimg", &["--per-axis"]);
    assert!(ok, "{err}");
    let score = |img: &str, extra: &[&str]| {
        let args = ["compensate", "--coeffs", &p(img), "--input", &p("measured.csv"), "--output", &p("out.csv")];
        let (ok, _, err) = dynocomp(&[&args[..], &["--truth", &p("true_force.csv")], extra].concat());
        assert!(ok, "{err}");
        cli_common::compensated_nrmse(&err)
    };
    let (m, a) = (score("c.dcimg", &[]), score("p.dcimg", &[]));
    eprintln!("3x3 {m:?}  per axis {a:?}");
    assert!(Figures::worst(&m) <= CROSSTALK_GAIN * Figures::worst(&a), "3x3 {m:?} against per axis {a:?}");
    // Negative control: the same comparison the other way round fails (a
    // NaN must fail it too, hence not `>`).
    let reversed = Figures::worst(&a) <= CROSSTALK_GAIN * Figures::worst(&m);
    assert!(!reversed, "negative control");
    for i in 0..3 {
        assert!(m[i] <= NO_WORSE * a[i], "axis {i}: 3x3 {m:?} against per axis {a:?}");
    }
    let (mo, ao) = (score("c.dcimg", &["--offline"]), score("p.dcimg", &["--offline"]));
    eprintln!("offline: 3x3 {mo:?}  per axis {ao:?}");
    assert!(Figures::worst(&mo) <= CROSSTALK_GAIN * Figures::worst(&ao), "offline 3x3 {mo:?} against per axis {ao:?}");
    assert!(!(Figures::worst(&ao) <= CROSSTALK_GAIN * Figures::worst(&mo)), "negative control (offline)");
    for i in 0..3 {
        assert!(mo[i] <= NO_WORSE * m[i], "axis {i}: offline 3x3 {mo:?} against the box's 3x3 filter {m:?}");
    }
    let offline = |out: &str, extra: &[&str]| {
        let args = ["compensate", "--coeffs", &p("c.dcimg"), "--input", &p("measured.csv"), "--output", &p(out)];
        let (ok, _, err) = dynocomp(&[&args[..], &["--offline"], extra].concat());
        assert!(!ok && !dir.join(out).exists(), "{out}: {err}");
        err
    };
    let err = offline("o2.csv", &["--drift", "0.1:0.3"]);
    assert!(err.contains("--drift") && err.contains("3x3") && err.contains("two FRFs"), "{err}");
    let sidecar = dir.join("c.dcimg.model.json");
    std::fs::rename(&sidecar, dir.join("moved.json")).unwrap();
    let err = offline("o3.csv", &[]);
    assert!(err.contains("c.dcimg.model.json") && err.contains("sidecar"), "{err}");
    std::fs::rename(dir.join("moved.json"), &sidecar).unwrap();
    let (ok, _, err) = design("q.dcimg", &["--band", "100:900"]);
    assert!(!ok && err.contains("--per-axis"), "{err}");
    assert!(!dir.join("q.dcimg").exists());
    let harmonics = ["--force-prior", "harmonics", "--spindle-rpm", "9000", "--teeth", "2", "--force-record"];
    let (ok, _, err) = design("q.dcimg", &[&harmonics[..], &[&p("measured.csv")]].concat());
    assert!(!ok && err.contains("--force-prior harmonics") && err.contains("--per-axis"), "{err}");
    assert!(!dir.join("q.dcimg").exists());
}

/// Seed 9 at 51.2 kHz, a random set-up drawn after the seed study's six:
/// its impact test has a few lines of low coherence below the first
/// coherent line (7 Hz), where the matrix fit used to keep a real pole
/// (3.8 Hz). That pole bent every entry between 7 and 0 Hz, G_zx(0) to
/// 0.024 against a true 0.0064, and through the cut's mean forces (37 N on x,
/// 120 N on y) it biased z by 1.3 N: 11.1 % against a floor of 0.68 %.
/// The fit now drops a real pole below the first coherent line
/// (`VfOptions::f_identified_hz`). Checked against the simulator's true
/// G(0) and true force; negative control: the same fit with the lowest
/// line as its limit keeps the pole and misses G_zx(0) by more than half.
/// Scored on the full filter (`design --full-order`), which is the fit's:
/// the box's image is reduced to fit its load limit, and z loses 2x to that
/// (1.72 % against the full filter's 0.83 % and the floor's 0.68 %; per
/// axis 18.3 %).
#[test]
#[ignore = "minutes in a debug build: scripts/test.sh runs it with --release --ignored"]
fn a_pole_below_the_first_coherent_line_does_not_bias_the_mean_force() {
    let fs = 51_200.0;
    let out = record("9", fs);
    let full = MatrixOptions {
        design: DesignOptions { fs_hz: fs, above_band: study_above_band(), ..Default::default() },
        load_limit_permille: None,
        matrix_vf: Some(opts_vf()),
        ..Default::default()
    };
    let md = design_matrix(&out.frf, noise(&out), &full).unwrap();
    let fig = evaluate(&md, &out);
    eprintln!("{}", fig.line("9", fs));
    assert!(
        fig.used[2] <= 2.0 * fig.floor[2],
        "z: {:.3} % against a floor of {:.3} %",
        100.0 * fig.used[2],
        100.0 * fig.floor[2]
    );
    let first_coherent = md.summary.axes.iter().map(|a| a.band_hz.0).fold(f64::INFINITY, f64::min);
    let truth = out.cut_modal.frf(0.0)[(2, 0)];
    let dc_error = |data: &MatrixData, f_identified_hz: f64| {
        let opts = VfOptions {
            max_order: MATRIX_MAX_ORDER,
            iterations: MATRIX_ITERATIONS,
            f_identified_hz,
            ..VfOptions::default()
        };
        let fit = matrix_vector_fit(data, &opts).unwrap();
        (fit.model.frf(0.0)[(2, 0)] - truth).norm() / truth.norm()
    };
    let (kept, dropped) =
        with_weighted_matrix(&out.frf, |data| (dc_error(data, 0.0), dc_error(data, first_coherent))).unwrap();
    eprintln!(
        "G_zx(0) off by {:.1} % with the pole, {:.1} % without (first coherent line {first_coherent} Hz)",
        100.0 * kept,
        100.0 * dropped
    );
    assert!(dropped < 0.1, "G_zx(0) off by {:.1} %", 100.0 * dropped);
    assert!(kept > 0.5, "negative control: with the pole G_zx(0) is off by only {:.1} %", 100.0 * kept);
}

/// The base's x and y translations on the machine table are two modes
/// under a percent apart (tall part: 211.6 and 213.4 Hz, each in its own
/// channel), well inside each other's half-power bandwidth. The order
/// search fits them as one pair at every order, off by 5-6 % of the
/// channel's force at the peak, where the cut's tooth-passing harmonics
/// lie. The split (`fit::matrix::split_close_modes`) fits them as two: each
/// pole within 0.5 Hz of the true one (|p̂ − p|/2π; measured 0.10 and
/// 0.33 Hz, 0.31 and 0.18 Hz without the refinement; the half-power
/// bandwidths are 8 Hz), the model's force error at the modes under
/// 1.5 %, and against the simulator's true force x and y of the design at
/// 25.6 kHz under 0.6 %. Negative controls: the order search's own model
/// (the fit's `unsplit`) is over 4 % off at the modes and its design over
/// 0.9 % on x and y; random set-up 2 (no close modes) is not split.
#[test]
#[ignore = "minutes in a debug build: scripts/test.sh runs it with --release --ignored"]
fn close_base_modes_are_fitted_as_two() {
    let fs = 25_600.0;
    let out = record("tall", fs);
    let fit = with_weighted_matrix(&out.frf, |data| matrix_vector_fit(data, &opts_vf())).unwrap().unwrap();
    assert!(fit.splits >= 1, "no split");
    let unsplit = fit.unsplit.clone().expect("the order search's model");
    // The simulator's base modes near 212 Hz: their poles (rad/s, Im > 0).
    let truth: Vec<Complex64> =
        out.cut_modal.modes.iter().filter(|m| (m.fn_hz - 212.5).abs() < 5.0).map(|m| m.pole()).collect();
    assert_eq!(truth.len(), 2, "the tall part's two base modes: {:?}", out.cut_modal.modes);
    let pairs_near = |m: &MatrixModel, p: Complex64| {
        (0..m.terms()).filter(|&k| m.pole(k).1 && (m.pole(k).0 - p).norm() / (2.0 * PI) < 0.5).count()
    };
    for m in [&fit.model, &unsplit] {
        let near: Vec<String> = (0..m.terms())
            .map(|k| m.pole(k))
            .filter(|(p, pair)| *pair && (p.im / (2.0 * PI) - 212.5).abs() < 10.0)
            .map(|(p, _)| format!("{:.2} Hz ζ {:.2e}", p.norm() / (2.0 * PI), -p.re / p.norm()))
            .collect();
        eprintln!("pairs near the base modes: {near:?}");
    }
    for p in &truth {
        let f = p.norm() / (2.0 * PI);
        assert_eq!(pairs_near(&fit.model, *p), 1, "no pole within 0.5 Hz of the true mode's at {f:.1} Hz");
    }
    assert_eq!(
        truth.iter().map(|p| pairs_near(&unsplit, *p)).sum::<usize>(),
        0,
        "control: the unsplit model resolves them"
    );
    // The model's force error Ĝ⁻¹(Ĝ − G) per channel row, worst over
    // 200-230 Hz, against the simulator's true G.
    let row_error = |m: &MatrixModel, i: usize| {
        (0..=60)
            .map(|k| 200.0 + 0.5 * f64::from(k))
            .map(|f| {
                let g = out.cut_modal.frf(f);
                (g.try_inverse().unwrap() * (m.frf(f) - g)).row(i).norm()
            })
            .fold(0.0, f64::max)
    };
    for i in 0..2 {
        let (split, whole) = (row_error(&fit.model, i), row_error(&unsplit, i));
        eprintln!("row {i}: force error at the modes {:.2} % split, {:.2} % unsplit", 100.0 * split, 100.0 * whole);
        assert!(split < 0.015, "row {i}: {:.2} %", 100.0 * split);
        assert!(whole > 0.04, "control: row {i} unsplit is only {:.2} % off", 100.0 * whole);
    }
    let md = design(&out.frf, &out).unwrap();
    let fig = evaluate(&md, &out);
    let whole = design_on_model(&out, unsplit);
    let control = evaluate(&whole, &out);
    eprintln!("{}\n{}", fig.line("tall", fs), control.line("unsplit", fs));
    for i in 0..2 {
        assert!(fig.used[i] < 0.006, "axis {i}: {:.3} %", 100.0 * fig.used[i]);
        assert!(control.used[i] > 0.009, "control: axis {i} unsplit {:.3} %", 100.0 * control.used[i]);
    }
    let other = record("2", fs);
    let fit = with_weighted_matrix(&other.frf, |data| matrix_vector_fit(data, &opts_vf())).unwrap().unwrap();
    assert_eq!(fit.splits, 0, "random set-up 2 split");
}

/// Random plate seed 24 at 25.6 kHz (one of twelve independent plates,
/// seeds 20-31, taken in order): its refined 3x3 fit has a right-half-plane
/// transmission zero at 152 ± 4751j Hz, just above the band, and its x row
/// lost to the per-axis row (2.61 % against a floor of 0.257 %). The design
/// on the fit without the refinement is taken where it judges better: x
/// 0.59 %. The control is the same design on the refined fit alone.
#[test]
#[ignore = "3x3 designs take seconds in release, minutes in debug: scripts/test.sh runs it with --release --ignored"]
fn a_3x3_row_lost_on_the_refined_fit_is_designed_again_on_the_plain_one() {
    let out = record("24", 25_600.0);
    let opts = |refined_only| MatrixOptions {
        design: DesignOptions { fs_hz: 25_600.0, ..Default::default() },
        load_limit_permille: box_limit(),
        refined_only,
        ..Default::default()
    };
    let md = design_matrix(&out.frf, noise(&out), &opts(false)).unwrap();
    let fig = evaluate(&md, &out);
    eprintln!("{}", fig.line("24", 25_600.0));
    let note = md.summary.notes.iter().find(|n| n.contains("without the refinement"));
    assert!(note.is_some_and(|n| n.contains("is used")), "{:?}", md.summary.notes);
    assert!(md.rows.iter().all(|r| *r == RowSource::Matrix), "{:?}", md.rows);
    check_no_worse_and_floor(&fig, "seed 24");
    // x within this factor of its floor (0.59 against 0.257 %); the control
    // is 10x.
    const X_WITHIN: f64 = 3.0;
    assert!(fig.used[0] <= X_WITHIN * fig.floor[0], "{fig:?}");
    let control = design_matrix(&out.frf, noise(&out), &opts(true)).unwrap();
    let control_fig = evaluate(&control, &out);
    eprintln!("{}", control_fig.line("24-refined", 25_600.0));
    assert_eq!(control.rows[0], RowSource::PerAxis, "control: {:?}", control.rows);
    assert!(
        control_fig.used[0] > X_WITHIN * control_fig.floor[0],
        "control: the refined fit's design passed: {control_fig:?}"
    );
}

/// Random plate seed 35 at 25.6 kHz has a machine mode at 291 Hz (ζ 0.036)
/// that 7 impacts per direction barely support: the order search gave it no
/// pole at any order, and x / y were 1.69 / 0.96 % against floors of 0.291 /
/// 0.101 %. The fit's residual exceeds the noise there, and a pair seeded
/// at its peak line is kept by the BIC (`fit::matrix::seed_unfitted_modes`):
/// x / y 0.70 / 0.205 %. The control is the same design without the seeding.
#[test]
#[ignore = "3x3 designs take seconds in release, minutes in debug: scripts/test.sh runs it with --release --ignored"]
fn a_mode_the_impact_test_barely_supports_is_seeded_where_the_residual_exceeds_the_noise() {
    let fs = 25_600.0;
    let out = record("35", fs);
    let opts = |seed_unfitted| MatrixOptions {
        design: DesignOptions { fs_hz: fs, ..Default::default() },
        load_limit_permille: box_limit(),
        matrix_vf: Some(VfOptions { seed_unfitted, ..opts_vf() }),
        ..Default::default()
    };
    // x and y within these factors of their floors (0.70 against 0.291 %,
    // 0.205 against 0.101 % with the full filter, which fits the box since
    // the 3x3 step runs in assembly; 0.62 and 0.13 % reduced to the budget
    // before); the control is 5.8x and 9.5x.
    const WITHIN: [f64; 2] = [3.0, 2.5];
    let md = design_matrix(&out.frf, noise(&out), &opts(true)).unwrap();
    let fig = evaluate(&md, &out);
    eprintln!("{}", fig.line("35", fs));
    let fit = md.summary.fit.as_ref().expect("the fit's figures");
    assert!(fit.seeded_hz.iter().any(|f| (f - 291.0).abs() < 10.0), "seeded {:?}", fit.seeded_hz);
    assert!(fit.modes.iter().any(|m| (m.0 - 291.0).abs() < 5.0), "{:?}", fit.modes);
    for (i, within) in WITHIN.iter().enumerate() {
        assert!(fig.used[i] <= within * fig.floor[i], "axis {i}: {fig:?}");
    }
    let control = design_matrix(&out.frf, noise(&out), &opts(false)).unwrap();
    let control_fig = evaluate(&control, &out);
    eprintln!("{}", control_fig.line("35-unseeded", fs));
    assert!(control.summary.fit.as_ref().is_some_and(|f| f.seeded_hz.is_empty()));
    for (i, within) in WITHIN.iter().enumerate() {
        assert!(
            control_fig.used[i] > within * control_fig.floor[i],
            "control, axis {i}: the design without the seeding passed: {control_fig:?}"
        );
    }
}

/// Row `i` of Ĝ⁻¹(G − Ĝ) for the fitted `model` against the simulator's true
/// G at the cut, RMS over the FRF's lines in the scoring band: what the fit's
/// error adds to the row's in-band error under a flat force (%).
fn row_model_error(model: &MatrixModel, out: &PlateSimOutput, i: usize) -> f64 {
    let top = scoring_band_hz(out.params.fs_hz);
    let lines: Vec<f64> = out.frf.freq_hz.iter().copied().filter(|f| *f > 0.0 && *f <= top).collect();
    let sum: f64 = lines
        .iter()
        .map(|f| {
            let (gh, g) = (model.frf(*f), out.cut_modal.frf(*f));
            let d = gh.try_inverse().expect("an invertible fit") * (g - gh);
            (0..3).map(|j| d[(i, j)].norm_sqr()).sum::<f64>()
        })
        .sum();
    100.0 * (sum / lines.len() as f64).sqrt()
}

/// Random plate seed 78 (102.4 kHz; the 12 plates 68-79 were drawn in order
/// before any result): with each line weighted by its own coherence, the
/// 3x3 box filter's y was 23x its floor (1.126 against 0.049 %), because 7
/// impacts estimate a line's noise variance with 12 degrees of freedom and
/// the lines where it comes out low pull the fit. With the variance averaged
/// over neighbouring lines (`fit::line_noise`), the fit's error on row y
/// halves (0.164 against 0.333 %) and the design's y is 1.8x its floor. The control
/// is the same fit with per-line weights.
#[test]
#[ignore = "3x3 designs take seconds in release, minutes in debug: scripts/test.sh runs it with --release --ignored"]
fn the_impact_tests_noise_averaged_over_lines_weights_the_fit() {
    let out = record("78", 102_400.0);
    let fit = |w: LineWeights| {
        with_matrix_weighted_by(&out.frf, w, |data| matrix_vector_fit(data, &opts_vf())).unwrap().unwrap()
    };
    let (averaged, per_line) = (fit(LineWeights::Averaged), fit(LineWeights::PerLine));
    let errors = |m: &MatrixModel| [0, 1, 2].map(|i| row_model_error(m, &out, i));
    let (a, p) = (errors(&averaged.model), errors(&per_line.model));
    eprintln!("fit's error per row (%), lines averaged {a:.3?}, per line {p:.3?}");
    // Row y 0.164 % averaged, 0.333 % per line; x and z 0.227 / 0.097 %
    // against 0.238 / 0.106 %.
    const BOUND_Y: f64 = 0.25;
    assert!(a[1] < BOUND_Y, "row y: {a:?}");
    assert!(p[1] > BOUND_Y, "control: per-line weights fit row y to {p:?}");
    for i in [0, 2] {
        assert!(a[i] <= p[i], "row {i}: averaged {a:?} against per line {p:?}");
    }
}

/// The impact test's information, not the design, holds plate 78 at
/// 102.4 kHz (its own noise draw, `MIMO_STUDY_NOISE=own`) far from its floor.
/// With 7 impacts per direction (the simulator's default) the fit leaves out
/// the machine modes at 309 and 437 Hz (ζ = 0.052) and y is 19.9x the exact
/// inverse's floor; with 28 the fit resolves 309 Hz and y is 1.4x. The
/// control is the 7-impact design of the same set-up and draw.
#[test]
#[ignore = "3x3 designs take seconds in release, minutes in debug: scripts/test.sh runs it with --release --ignored"]
fn more_impacts_resolve_the_machine_mode_seven_leave_out() {
    let fs = 102_400.0;
    let y_over_floor = |impacts: usize| {
        let out = record_drawn("78", fs, false, Some(impacts), own_noise_seed(78));
        let md = design(&out.frf, &out).unwrap();
        let fig = evaluate(&md, &out);
        eprintln!("{} impacts: {}", impacts, fig.line("78", fs));
        let fitted = md.model.as_ref().is_some_and(|m| m.modes().iter().any(|(f, _)| (f - 309.0).abs() < 6.0));
        (fig.used[1] / fig.floor[1], fitted)
    };
    let (many, resolved) = y_over_floor(28);
    assert!(many < 2.0 && resolved, "28 impacts: y {many:.2}x the floor, 309 Hz fitted: {resolved}");
    let (few, resolved) = y_over_floor(7);
    assert!(few > 5.0 && !resolved, "control, 7 impacts: y {few:.2}x the floor, 309 Hz fitted: {resolved}");
}

fn opts_vf() -> VfOptions {
    let refine = std::env::var_os("MIMO_NO_REFINE").is_none();
    let seed_unfitted = std::env::var_os("MIMO_NO_SEED").is_none();
    let rank_one_residues = std::env::var_os("MIMO_NO_RANK_ONE").is_none();
    // MIMO_LINE_WEIGHTS=averaged: the noise variance averaged over lines.
    let line_weights = match std::env::var("MIMO_LINE_WEIGHTS").as_deref() {
        Ok("averaged") => LineWeights::Averaged,
        _ => LineWeights::PerLine,
    };
    VfOptions {
        max_order: MATRIX_MAX_ORDER,
        iterations: MATRIX_ITERATIONS,
        refine,
        seed_unfitted,
        rank_one_residues,
        line_weights,
        ..VfOptions::default()
    }
}

/// Random plate seed 1 at 25.6 kHz has modes above the impact test's last
/// line (4096 Hz). The common-pole fit parks a nearly undamped pair just
/// above the lines for them (4464 Hz, ζ = 2.4e-3), which the skim dropped as
/// spurious: x, y and z were 2.4x, 5.7x and 3.9x the exact inverse's floor.
/// A damped pair now takes its place (`vf::best_surrogate`): every axis
/// within 2x (1.8x, 1.5x, 1.4x). Checked against
/// the simulator's truth; negative control: the same model refitted without
/// that pair is further from the true static gains, where the cut's mean
/// force is.
#[test]
#[ignore = "minutes in a debug build: scripts/test.sh runs it with --release --ignored"]
fn a_mode_above_the_lines_keeps_a_surrogate_in_the_3x3_fit() {
    let fs = 25_600.0;
    let out = record("1", fs);
    let md = design(&out.frf, &out).unwrap();
    let fig = evaluate(&md, &out);
    eprintln!("{}", fig.line("1", fs));
    for i in 0..3 {
        assert!(
            fig.used[i] <= 2.0 * fig.floor[i],
            "axis {i}: {:.3} % against a floor of {:.3} %",
            100.0 * fig.used[i],
            100.0 * fig.floor[i]
        );
    }
    let model = md.model.as_ref().expect("a 3x3 model");
    let f_top = *out.frf.freq_hz.last().unwrap();
    let edge: Vec<bool> = model.entries[0]
        .terms
        .iter()
        .map(|t| matches!(t, Term::Pair { pole, .. } if pole.norm() / (2.0 * PI) > 0.97 * f_top))
        .collect();
    assert!(edge.iter().any(|e| *e), "no pair above the lines: {:?}", model.modes());
    let keep: Vec<bool> = edge.iter().map(|e| !e).collect();
    let dropped = with_weighted_matrix(&out.frf, |data| refit_kept(data, model, &keep)).unwrap().unwrap();
    let truth = out.cut_modal.frf(0.0);
    let static_error = |m: &MatrixModel| {
        let g = m.frf(0.0);
        (0..3).map(|i| (g[(i, i)] / truth[(i, i)] - 1.0).norm()).fold(0.0, f64::max)
    };
    let (kept, without) = (static_error(model), static_error(&dropped));
    eprintln!("direct static gains off by {kept:.2e} at most, {without:.2e} without the surrogate");
    assert!(kept < 2e-3 && without > 2.0 * kept, "static gains off {kept:.2e}, without the surrogate {without:.2e}");
}

/// `simulate --dyno plate --seed 26` at 25.6 kHz has a machine mode at
/// 349 Hz that its 7-impact test barely supports: the fit seeds a pair
/// there (at the 343 Hz line, within 3 % of the simulator's mode), and
/// `design` says so and advises more impacts. `compensate --truth` gives fx
/// 0.76 % (1.58 % without the seed; BENCHMARKS.md, "Missing modes seeded
/// where the residual exceeds the noise"). Control: seed 21, whose fit
/// misses no mode below 1 kHz, gets no seeded pair and no advice.
#[test]
#[ignore = "a 3x3 design takes seconds in release, minutes in debug: scripts/test.sh runs it with --release --ignored"]
fn cli_design_names_the_weak_mode_it_seeded() {
    const LINE: &str = "pole pairs added near ";
    for (seed, weak) in [("26", true), ("21", false)] {
        let dir = cli_common::tmp("mimo", &format!("seeded-{seed}"));
        let p = |n: &str| dir.join(n).display().to_string();
        let sim = ["simulate", "--out", &p(""), "--dyno", "plate", "--seed", seed, "--fs", "25600"];
        let (ok, _, err) = cli_common::dynocomp(&sim);
        assert!(ok, "{err}");
        let (ok, out, err) = cli_common::design(&p("frf.uff"), &p("idle.csv"), "25600", &p("c.dcimg"), &[]);
        assert!(ok, "{err}");
        let advice = out.contains("more impacts per direction would confirm a weak mode there");
        let seeded: Vec<f64> = out
            .lines()
            .filter_map(|l| l.split(LINE).nth(1))
            .flat_map(|rest| rest.split(" Hz").next().unwrap_or("").split(", ").map(|f| f.parse::<f64>().unwrap()))
            .collect();
        if !weak {
            assert!(seeded.is_empty() && !advice, "control, seed {seed}: seeded {seeded:?}\n{out}");
            continue;
        }
        let truth: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(p("truth.json")).unwrap()).unwrap();
        let true_hz: Vec<f64> =
            truth["modes"].as_array().unwrap().iter().map(|m| m["fn_hz"].as_f64().unwrap()).collect();
        let near_a_mode = |f: f64| true_hz.iter().any(|g| (f / g - 1.0).abs() <= 0.03);
        assert!(advice, "{out}");
        assert!(seeded.len() == 1 && near_a_mode(seeded[0]), "seeded {seeded:?}, true modes {true_hz:?}\n{out}");
    }
}

/// A short simulation of the off-centre plate at `fs` (Hz) by the CLI, in a
/// fresh folder `name`: the folder, and the path of a file in it.
fn short_offcentre(name: &str, fs: &str) -> (std::path::PathBuf, impl Fn(&str) -> String) {
    let dir = cli_common::tmp("mimo", name);
    let short = ["--duration", "0.1", "--idle-duration", "0.05", "--frf-lines", "513", "--frf-df", "8"];
    let (ok, _, err) = cli_common::simulate_plate(&dir.display().to_string(), "offcentre", fs, &short);
    assert!(ok, "{err}");
    let d = dir.clone();
    (dir, move |n: &str| d.join(n).display().to_string())
}

/// At 102.4 kHz a 3x3 image of the off-centre plate is over the box's load
/// limit: `design` writes it offline-only and says how to get an image the
/// box runs (`--per-axis`, with what each axis loses), and the highest rate
/// for this filter. Controls: the same set-up at 10.24 kHz fits and says
/// neither (`cli_offcentre_3x3_image_beats_per_axis`); at 51.2 kHz it is
/// reduced to fit (`cli_a_3x3_image_over_the_load_limit_is_reduced_to_one_the_box_runs`).
#[test]
#[ignore = "a 3x3 design takes seconds in release, minutes in debug: scripts/test.sh runs it with --release --ignored"]
fn cli_a_3x3_image_over_the_load_limit_says_how_to_get_one_the_box_runs() {
    use cli_common::dynocomp;
    let (_, p) = short_offcentre("over-limit", "102400");
    let (ok, out, err) =
        cli_common::design(&p("frf.uff"), &p("idle.csv"), "102400", &p("c.dcimg"), &["--latency", "4"]);
    assert!(ok, "{err}");
    for text in [&out, &err] {
        assert!(text.contains("for an image the box can run, design with --per-axis"), "{text}");
        assert!(text.contains("record at up to "), "{text}");
    }
    assert!(err.contains("WARNING: OFFLINE-ONLY IMAGE"), "{err}");
    // The reduction that would fit was tried and said why it is not used.
    assert!(out.contains("not reduced for the box: 3x3 block ") && out.contains("per axis"), "{out}");
    let (ok, inspect, err) = dynocomp(&["inspect", &p("c.dcimg")]);
    assert!(ok && inspect.contains("offline only"), "{inspect}{err}");
}

/// At 51.2 kHz the off-centre plate's full 3x3 filter is over the box's
/// load limit: `design` writes the reduced filter, which the box
/// runs, and says what the reduction costs; `--json` has the figures, and
/// `inspect` tells the reduced image from the full one by its sidecar.
/// Controls: `--max-load 20`, where no reduction that fits beats the
/// per-axis rows, and `--full-order` write the full filter offline-only;
/// an image copied without its sidecar is "not known".
#[test]
#[ignore = "a 3x3 design takes seconds in release, minutes in debug: scripts/test.sh runs it with --release --ignored"]
fn cli_a_3x3_image_over_the_load_limit_is_reduced_to_one_the_box_runs() {
    use cli_common::dynocomp;
    let (dir, p) = short_offcentre("reduced", "51200");
    let (ok, out, err) = cli_common::design(&p("frf.uff"), &p("idle.csv"), "51200", &p("c.dcimg"), &["--json"]);
    assert!(ok, "{err}");
    let j: serde_json::Value = serde_json::from_str(&out).expect("JSON");
    let r = &j["design"]["reduction"];
    assert_eq!(r["used"], true, "{r}");
    assert!(r["states"].as_u64().unwrap() < r["full_states"].as_u64().unwrap(), "{r}");
    assert!(r["full_load_permille"].as_u64().unwrap() > 600 && r["load_permille"].as_u64().unwrap() <= 600, "{r}");
    assert_eq!(j["offline_only"], false);
    assert!(!err.contains("OFFLINE-ONLY"), "{err}");
    let (ok, inspect, err) = dynocomp(&["inspect", &p("c.dcimg")]);
    assert!(ok && !inspect.contains("offline only"), "{inspect}{err}");
    // `inspect` tells a reduced image by its model sidecar, with the same
    // figures as the design; an image without its sidecar cannot tell.
    let states = format!("3x3 block {} -> {} states", r["full_states"], r["states"]);
    assert!(inspect.contains(&format!("reduced for the box: {states}")), "{inspect}");
    let (ok, json, _) = dynocomp(&["inspect", &p("c.dcimg"), "--json"]);
    let j: serde_json::Value = serde_json::from_str(&json).expect("inspect JSON");
    assert!(ok && j["box_reduction"]["reduction"]["states"] == r["states"], "{json}");
    std::fs::copy(p("c.dcimg"), p("alone.dcimg")).unwrap();
    let (ok, alone, _) = dynocomp(&["inspect", &p("alone.dcimg")]);
    assert!(ok && alone.contains("reduced for the box is not known") && !alone.contains(&states), "{alone}");
    assert!(alone.contains("no model sidecar beside the image") && !alone.contains("--offline"), "{alone}");
    // A sidecar written before reductions were recorded cannot tell either.
    let mut side: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(p("c.dcimg.model.json")).unwrap()).unwrap();
    assert!(side["matrix"].as_object_mut().unwrap().remove("box_reduction").is_some());
    std::fs::copy(p("c.dcimg"), p("old.dcimg")).unwrap();
    std::fs::write(p("old.dcimg.model.json"), side.to_string()).unwrap();
    let (ok, old, _) = dynocomp(&["inspect", &p("old.dcimg")]);
    assert!(ok && old.contains("predates the record of reductions"), "{old}");
    let (ok, out, err) =
        cli_common::design(&p("frf.uff"), &p("idle.csv"), "51200", &p("c.dcimg"), &["--report", &p("report")]);
    assert!(ok && out.contains("reduced for the box: 3x3 block "), "{out}{err}");
    // The report draws the full filter beside the reduced one.
    let rows = std::fs::read_to_string(dir.join("report").join("matrix_rows.svg")).unwrap();
    assert!(rows.contains("full filter (--full-order)"), "no full-filter trace in the report");

    let (ok, out, err) =
        cli_common::design(&p("frf.uff"), &p("idle.csv"), "51200", &p("low.dcimg"), &["--max-load", "20"]);
    assert!(ok, "{err}");
    assert!(out.contains("not reduced for the box") && err.contains("WARNING: OFFLINE-ONLY IMAGE"), "{out}{err}");
    let (ok, out, err) = cli_common::design(
        &p("frf.uff"),
        &p("idle.csv"),
        "51200",
        &p("full.dcimg"),
        &["--full-order", "--report", &p("full-report")],
    );
    assert!(ok && !out.contains("reduced for the box") && err.contains("WARNING: OFFLINE-ONLY IMAGE"), "{out}{err}");
    let (ok, inspect, _) = dynocomp(&["inspect", &p("full.dcimg")]);
    assert!(ok && inspect.contains("the full 3x3 filter: not reduced for the box"), "{inspect}");
    let rows = std::fs::read_to_string(dir.join("full-report").join("matrix_rows.svg")).unwrap();
    assert!(!rows.contains("full filter (--full-order)"), "a full-filter trace without a reduction");
}

/// The chosen compensator's 3x3 block reduced to `states` by `how`,
/// realized and verified: the filter the design would write at that order.
fn reduced_filter(md: &MatrixDesign, states: usize, how: dynocomp::numeric::balanced::Reduction) -> MimoFilter {
    reduced_filter_by(md, states, how, dynocomp::realize::mimo::Prefer::Load).unwrap()
}

/// [`reduced_filter`] realized as `prefer` says.
fn reduced_filter_by(
    md: &MatrixDesign,
    states: usize,
    how: dynocomp::numeric::balanced::Reduction,
    prefer: dynocomp::realize::mimo::Prefer,
) -> anyhow::Result<MimoFilter> {
    assert!(md.rows.iter().all(|r| *r == RowSource::Matrix), "one 3x3 block: {:?}", md.rows);
    let bal = dynocomp::numeric::balanced::balance(&md.compensator).unwrap();
    let f_band = md.summary.axes.iter().map(|a| a.band_hz.1).fold(0.0, f64::max);
    let block = bal.reduce(states, how).unwrap();
    Ok(dynocomp::realize::mimo::realize_blocks_by(&[block], md.summary.fs_hz, f_band, prefer)?.1)
}

/// A 3x3 filter over the box's load limit is reduced to fit where it stays
/// accurate (#30 item 4), judged against the simulator's truth:
/// * off-centre plate at 25.6 kHz: the full filter needs 81 % of the
///   period; the design's reduction fits the 60 % limit, and on every axis
///   its NRMSE is within 1.1 times the full filter's and below the per-axis
///   filters';
/// * at 51.2 kHz (on the free fit, [`free_residues_offcentre_51k`]) the
///   order that fits predicts worse than per axis, so the full filter is
///   kept (offline-only); against the truth that reduction is indeed worse
///   than the per-axis filter on some axis.
///
/// Negative control: the 25.6 kHz block reduced to a third of the design's
/// order (or the lowest order above it that makes a valid image, at most
/// half) misses the 1.1 bound on some axis.
#[test]
#[ignore = "a minute of designs in a debug build: scripts/test.sh runs it with --release --ignored"]
fn a_3x3_filter_over_the_load_limit_is_reduced_to_fit_where_it_stays_accurate() {
    use dynocomp::design::mimo::reduce::filter_load;
    let limit = BOX_LIMIT.unwrap();
    let shared = shared_design("offcentre", 25_600.0, study_above_band());
    let (out, reduced) = (&shared.0, &shared.1);
    let d = DesignOptions { fs_hz: out.params.fs_hz, ..Default::default() };
    let full = design_matrix(&out.frf, noise(out), &MatrixOptions { design: d, ..Default::default() }).unwrap();
    assert!(full.summary.reduction.is_none());
    assert!(filter_load(&full.filter, 25_600.0) > limit, "the full filter must be over the limit for this test");
    let r = reduced.summary.reduction.as_ref().expect("reduction figures");
    assert!(r.used, "{r:?}");
    assert!(filter_load(&reduced.filter, 25_600.0) <= limit && r.load_permille <= limit, "{r:?}");
    let (f_full, f_red) = (evaluate(&full, out), evaluate(reduced, out));
    eprintln!("full    {}\nreduced {}", f_full.line("offcentre", 25_600.0), f_red.line("offcentre", 25_600.0));
    for i in 0..3 {
        assert!(f_red.used[i] <= 1.1 * f_full.used[i], "axis {i}: {:?} vs {:?}", f_red.used, f_full.used);
        assert!(f_red.used[i] < f_red.per_axis[i], "axis {i}: {:?} vs per axis {:?}", f_red.used, f_red.per_axis);
    }
    // Negative control: a third of the order, or the lowest order above it
    // that the box's image checks accept (a third may not be a calibrated
    // filter at all, which the design would never write).
    let (states, filter) = (r.states / 3..r.states)
        .find_map(|n| reduced_filter_by(&full, n, r.method, dynocomp::realize::mimo::Prefer::Load).ok().map(|f| (n, f)))
        .expect("a reduction below the design's order realizes");
    assert!(states <= r.states / 2, "the control's order {states} of {}", r.states);
    let mut third = full.clone();
    third.filter = filter;
    let f_third = evaluate(&third, out);
    eprintln!("third   {} ({states} states)", f_third.line("offcentre", 25_600.0));
    assert!((0..3).any(|i| f_third.used[i] > 1.1 * f_full.used[i]), "{:?}", f_third.used);
    // A load limit only spares the verification of realizations over it:
    // within it, the cheapest that verifies is the same filter. Control: a
    // limit just below that filter's load refuses the block.
    use dynocomp::realize::mimo::Prefer;
    let coefficients = |f: &MimoFilter| format!("{:?} {:?} {:?}", f.sections(), f.d(), f.fir());
    let cheapest = reduced_filter(&full, r.states, r.method);
    let within = reduced_filter_by(&full, r.states, r.method, Prefer::LoadWithin(limit)).unwrap();
    assert_eq!(coefficients(&cheapest), coefficients(&within));
    let load = filter_load(&cheapest, 25_600.0);
    let below = reduced_filter_by(&full, r.states, r.method, Prefer::LoadWithin(load - 1));
    assert!(below.is_err_and(|e| format!("{e:#}").contains("over the limit")), "load {load}");

    // At 51.2 kHz, half the cycles per sample: the reduction that fits is
    // used too, and beats the per-axis rows (what the box ran before) on
    // every axis against the truth, within the floor factor.
    let shared = free_residues_offcentre_51k();
    let (out, md) = (&shared.0, &shared.1);
    let r = md.summary.reduction.as_ref().expect("reduction figures");
    assert!(r.used && r.states < r.full_states, "{r:?}");
    // The full filter does not go on the box: over the limit, or (here) not
    // verified in f32 at all.
    assert!(r.full_load_permille > limit || r.full_not_realized.is_some(), "{r:?}");
    assert!(filter_load(&md.filter, 51_200.0) <= limit, "{r:?}");
    let f = evaluate(md, out);
    eprintln!("51.2 kHz reduced {} ({} states)", f.line("offcentre", 51_200.0), r.states);
    for i in 0..3 {
        assert!(f.used[i] < f.per_axis[i], "axis {i}: {:?} vs per axis {:?}", f.used, f.per_axis);
    }
    check_no_worse_and_floor(&f, "offcentre 51.2 kHz, reduced");
}
