//! The seed paper's qualitative findings (§3.1–3.3), reproduced on simulated
//! impact tests whose true dynamometer is known. Every error below is
//! measured against the simulator's true G (not the measured lines, not the
//! design's own model):
//!
//! - a high-order whole-band fit by the paper's method breaks down (rank
//!   loss / ill-conditioning) or is inaccurate, while the same code on a
//!   narrow band is well conditioned and accurate;
//! - band-fitting restores accuracy inside the bands;
//! - parallel elaboration is accurate across the bands;
//! - the default method matches or beats them over the whole band.

use dynocomp::design::axis::{
    coherent_band, design_axis, fitted_response, probe_paper_fit, AxisDesign, DesignOptions, FitMethod, MAX_FIT_ERROR,
};
use dynocomp::design::bands::{from_tooth_passing, validate, Band};
use dynocomp::eval::compare::{design_parallel, CompareSetup};
use dynocomp::fit::rfp::RfpOptions;
use dynocomp::metrics::sample_variance;
use dynocomp::simulate::{simulate, SimOutput, SimParams};
use num_complex::Complex64;
use std::f64::consts::PI;

const FS: f64 = 51_200.0;
/// Tooth-passing frequency of the simulated cut (Hz): 16 500 rpm, 4 teeth.
const TPF: f64 = 1100.0;

fn sim(seed: u64) -> SimOutput {
    let p = SimParams { duration_s: 0.05, idle_duration_s: 0.2, ..Default::default() };
    simulate(seed, &p).expect("simulate")
}

fn paper(nb: usize, na: usize) -> FitMethod {
    FitMethod::Paper { rfp: RfpOptions { nb, na, ..Default::default() }, prewarp_hz: None }
}

/// TPF and its 2nd and 3rd harmonic (±10 %) plus the static band.
fn tpf_bands(f_max: f64) -> Vec<Band> {
    let mut b = from_tooth_passing(TPF * 60.0 / 4.0, 4, 3, 0.1, f_max).unwrap();
    b.push(Band { lo_hz: 0.0, hi_hz: 0.25 * 0.9 * TPF, label: "static".into() });
    validate(b, f_max, 5.0).unwrap()
}

/// Relative RMS error of `model` against the true G over lines `f` in `keep`.
fn truth_error(s: &SimOutput, axis: usize, model: impl Fn(f64) -> Complex64, keep: impl Fn(f64) -> bool) -> f64 {
    let g = s.dyno.axis(axis);
    let v: Vec<f64> =
        s.frf.freq_hz.iter().filter(|f| keep(**f)).map(|f| ((model(*f) - g.frf(*f)) / g.frf(*f)).norm_sqr()).collect();
    (v.iter().sum::<f64>() / v.len() as f64).sqrt()
}

/// RMS of |H·G_true·e^{j2πfL/fs} − 1| over lines in `keep`.
fn compensated_error(
    s: &SimOutput,
    axis: usize,
    h: impl Fn(f64) -> Complex64,
    lag: usize,
    keep: impl Fn(f64) -> bool,
) -> f64 {
    let g = s.dyno.axis(axis);
    let v: Vec<f64> = s
        .frf
        .freq_hz
        .iter()
        .filter(|f| keep(**f))
        .map(|f| (h(*f) * g.frf(*f) * Complex64::from_polar(1.0, 2.0 * PI * f * lag as f64 / FS) - 1.0).norm_sqr())
        .collect();
    (v.iter().sum::<f64>() / v.len() as f64).sqrt()
}

fn design(s: &SimOutput, axis: usize, method: FitMethod, bands: Vec<Band>) -> anyhow::Result<AxisDesign> {
    let opts = DesignOptions { fs_hz: FS, method, bands, ..Default::default() };
    design_axis(&s.frf.freq_hz, s.frf.axis(axis).unwrap(), sample_variance(&s.idle[axis]), &opts)
}

fn coherent(s: &SimOutput, axis: usize) -> (f64, f64) {
    coherent_band(&s.frf.freq_hz, s.frf.axis(axis).unwrap(), 0.9)
}

#[test]
fn whole_band_high_order_paper_fit_breaks_down_where_a_narrow_band_fit_does_not() {
    for seed in [23u64, 24] {
        let s = sim(seed);
        let axis = 0;
        let band = coherent(&s, axis);
        // whole band, high order (the paper's Fig. 4 situation): the
        // companion form loses observability rank in floating point
        // (the design now refuses a fit beyond MAX_FIT_ERROR before the
        // Kalman step; the probe runs the fit and the observability check
        // without that limit, so the breakdown itself is what is tested)
        let opts = DesignOptions { fs_hz: FS, method: paper(14, 16), ..Default::default() };
        match probe_paper_fit(&s.frf.freq_hz, s.frf.axis(axis).unwrap(), &opts) {
            Ok((fit, p)) => {
                // observable, but then the fit itself misses the FRF
                assert!(
                    fit > MAX_FIT_ERROR,
                    "seed {seed}: a 16th-order whole-band fit neither lost rank ({p:?}) nor missed the FRF (fit {fit})"
                );
                eprintln!(
                    "seed {seed}: whole band 14:16: observable (condition {:.1e}) but fit error {:.1} %",
                    p.observability_condition,
                    100.0 * fit
                );
            }
            Err(e) => {
                let msg = format!("{e:#}");
                eprintln!("seed {seed}: whole band 14:16: {msg}");
                // "rank R of 17", "ill-conditioned (observability condition C", or an unstable fit
                assert!(
                    msg.contains("of 17") || msg.contains("ill-conditioned") || msg.contains("unstable"),
                    "seed {seed}: {msg}"
                );
            }
        }

        // the same code, order 4:6, on the narrow bands around the TPF harmonics
        let bands = tpf_bands(band.1);
        let d =
            design(&s, axis, paper(4, 6), bands.clone()).unwrap_or_else(|e| panic!("seed {seed}: narrow bands: {e:#}"));
        let p = &d.paper.as_ref().unwrap().1;
        let e = truth_error(
            &s,
            axis,
            |f| d.fitted_frf(f),
            |f| bands.iter().any(|b| b.contains(f)) && f >= band.0 && f <= band.1,
        );
        eprintln!(
            "seed {seed}: bands 4:6: truth error {e:.4}, cond RFP {:.2e}, obs {:.2e}, rank {}/{}",
            p.rfp_condition, p.observability_condition, p.observability_rank, p.observability_dim
        );
        assert_eq!(p.observability_rank, p.observability_dim);
        assert!(p.rfp_condition < 1e5 && p.observability_condition < 1e8, "seed {seed}: {p:?}");
        assert!(e < 0.01, "seed {seed}: band-fitted error {e} against the true G");
    }
}

#[test]
fn band_fitting_restores_accuracy_inside_the_bands() {
    // (seed, axis, orders): cases where the whole-band fit at that order
    // misses the bands by several per cent
    for (seed, axis, nb, na) in [(21u64, 1usize, 6usize, 8usize), (23, 0, 6, 8), (24, 0, 4, 6)] {
        let s = sim(seed);
        let band = coherent(&s, axis);
        let bands = tpf_bands(band.1);
        let in_bands = |f: f64| bands.iter().any(|b| b.contains(f)) && f >= band.0 && f <= band.1;
        // the whole-band fit itself (the design would now refuse most of
        // them on the fit-error limit, which is the point)
        let whole_opts = DesignOptions { fs_hz: FS, method: paper(nb, na), ..Default::default() };
        let whole = fitted_response(&s.frf.freq_hz, s.frf.axis(axis).unwrap(), &whole_opts)
            .unwrap_or_else(|e| panic!("seed {seed}: whole band: {e:#}"));
        let whole_err = truth_error(&s, axis, whole, in_bands);
        let d = design(&s, axis, paper(nb, na), bands.clone())
            .unwrap_or_else(|e| panic!("seed {seed}: band-fitted: {e:#}"));
        let band_err = truth_error(&s, axis, |f| d.fitted_frf(f), in_bands);
        eprintln!("seed {seed} axis {axis} {nb}:{na}: in-band truth error: whole band {whole_err:.4}, band-fitted {band_err:.4}");
        assert!(band_err < 0.01, "seed {seed}: band-fitted error {band_err}");
        assert!(
            band_err < 0.2 * whole_err,
            "seed {seed}: band fitting must cut the in-band error five-fold ({band_err} vs {whole_err})"
        );
    }
}

#[test]
fn parallel_elaboration_is_accurate_across_bands_and_the_default_method_matches_or_beats_all() {
    for seed in [21u64, 24] {
        let s = sim(seed);
        let axis = 0;
        let band = coherent(&s, axis);
        let whole = |f: f64| f >= band.0 && f <= band.1;
        let bands = tpf_bands(band.1);
        let a = s.frf.axis(axis).unwrap();
        let r = sample_variance(&s.idle[axis]);
        let setup = CompareSetup {
            freq_hz: &s.frf.freq_hz,
            base: DesignOptions { fs_hz: FS, ..Default::default() },
            paper: paper(6, 8),
            bands: bands.clone(),
        };
        let par = design_parallel(&setup, a, r).unwrap_or_else(|e| panic!("seed {seed}: parallel: {e:#}"));
        // accuracy across the tooth-passing bands (the static segment is the
        // weak one, as the paper notes for the low-frequency range)
        let harmonic = |f: f64| bands.iter().any(|b| b.label.starts_with("TPF") && b.contains(f)) && whole(f);
        let par_bands = truth_error(&s, axis, |f| par.fitted_frf(f), harmonic);
        let par_fit = truth_error(&s, axis, |f| par.fitted_frf(f), whole);
        let par_comp = compensated_error(&s, axis, |f| par.response(f), 0, whole);
        // parallel vs a single whole-band paper fit of the same (largest) order
        let single = match design(&s, axis, paper(6, 8), Vec::new()) {
            Ok(d) => truth_error(&s, axis, |f| d.fitted_frf(f), harmonic),
            Err(_) => f64::INFINITY,
        };
        let vf = design(&s, axis, FitMethod::Vf, Vec::new()).unwrap();
        let vf_fit = truth_error(&s, axis, |f| vf.fitted_frf(f), whole);
        let vf_comp = compensated_error(
            &s,
            axis,
            |f| dynocomp::realize::quantize::filter_response(&vf.filter, f, FS),
            vf.kalman.lag,
            whole,
        );
        let pb = design(&s, axis, paper(6, 8), bands.clone()).ok();
        let pb_comp = pb.as_ref().map_or(f64::INFINITY, |d| {
            compensated_error(&s, axis, |f| dynocomp::realize::quantize::filter_response(&d.filter, f, FS), 0, whole)
        });
        eprintln!(
            "seed {seed}: truth fit error: parallel {par_bands:.4} in the TPF bands, {par_fit:.4} whole band ({} segments, order {}); single paper 6:8 {single:.4} in the TPF bands; vf {vf_fit:.4} whole band; compensated error (whole band): parallel {par_comp:.4}, paper band-fitted {pb_comp:.4}, vf {vf_comp:.4}",
            par.segments.len(),
            par.order()
        );
        assert!(par_bands < 0.01, "seed {seed}: parallel elaboration fit error across the TPF bands {par_bands}");
        assert!(
            par_bands < single,
            "seed {seed}: parallel ({par_bands}) must beat one whole-band paper fit ({single}) in the bands"
        );
        // the default method: fit at least as good, compensation better
        assert!(vf_fit <= 1.1 * par_fit, "seed {seed}: vf fit {vf_fit} vs parallel {par_fit}");
        assert!(
            vf_comp < par_comp && vf_comp < pb_comp,
            "seed {seed}: vf compensated {vf_comp} vs parallel {par_comp}, band-fitted {pb_comp}"
        );
        assert!(vf_comp < 0.05, "seed {seed}: vf compensated error {vf_comp}");
    }
}
