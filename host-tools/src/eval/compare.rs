//! `dynocomp compare`: the seed paper's method (whole band, band-fitted,
//! parallel elaboration) against the default method on the same FRF, one row
//! per method and axis ([`compare_axis`]), every method scored against the
//! same truth: the *measured* G.

use anyhow::Result;
use num_complex::Complex64;
use serde::Serialize;
use std::f64::consts::PI;
use std::time::Instant;

use crate::design::axis::{coherent_band, AxisDesign, DesignOptions, FitMethod};
use crate::design::bands::{band_mask, Band};
use crate::design::criterion::flat_band;
use crate::design::paper::PaperDiagnostics;
use crate::design::paper_orders::design_axis;
use crate::design::progress::Progress;
use crate::fit::relative_rms_error;
use crate::frf::{axis_name, AxisFrf, Frf};
use crate::realize::quantize::filter_response;

/// One method on one axis.
#[derive(Clone, Debug, Serialize)]
pub struct CompareRow {
    /// Method name.
    pub method: String,
    /// Why the method failed (None = it produced a verified filter).
    pub diagnostic: Option<String>,
    /// Model order (sum of the segments' orders for parallel elaboration).
    pub order: Option<usize>,
    /// Relative RMS fit error on coherent lines inside the bands.
    pub fit_error_in_band: Option<f64>,
    /// The same outside the bands (None without bands).
    pub fit_error_out_of_band: Option<f64>,
    /// RMS of |H·G·delay − 1| on coherent lines inside the bands (measured G).
    pub compensated_error_in_band: Option<f64>,
    /// The same outside the bands.
    pub compensated_error_out_of_band: Option<f64>,
    /// Flat band (Hz) of H·Ĝ (±5 %, ±5°), from the first band line.
    pub flat_band_hz: Option<(f64, f64)>,
    /// White-noise gain of H.
    pub noise_gain: Option<f64>,
    /// Latency (samples).
    pub latency_samples: Option<usize>,
    /// The paper path's condition numbers and rank (worst segment for parallel).
    pub paper: Option<PaperDiagnostics>,
    /// Design time (s).
    pub design_time_s: f64,
    /// Compensated response H·G·delay at the FRF lines (for the plot).
    #[serde(skip)]
    pub compensated: Vec<Complex64>,
}

/// The comparison of one axis.
#[derive(Clone, Debug, Serialize)]
pub struct AxisComparison {
    /// Axis letter.
    pub axis: &'static str,
    /// Coherent band (Hz).
    pub coherent_band_hz: (f64, f64),
    /// Rows, one per method.
    pub rows: Vec<CompareRow>,
}

/// The whole comparison.
#[derive(Clone, Debug, Serialize)]
pub struct Comparison {
    /// FRF file.
    pub frf: String,
    /// Sample rate (Hz).
    pub fs_hz: f64,
    /// Fitting bands (empty = none given).
    pub bands: Vec<Band>,
    /// Per axis.
    pub axes: Vec<AxisComparison>,
}

/// Settings shared by every row of one comparison.
pub struct CompareSetup<'a> {
    /// FRF lines (Hz).
    pub freq_hz: &'a [f64],
    /// Base options (fs, lag, force RMS, noise-gain limit).
    pub base: DesignOptions,
    /// The paper's method with the user's orders and prewarp.
    pub paper: FitMethod,
    /// Fitting bands (may be empty).
    pub bands: Vec<Band>,
}

fn rms_error(resp: &[Complex64], mask: &[bool]) -> Option<f64> {
    let v: Vec<f64> = resp.iter().zip(mask).filter(|(_, m)| **m).map(|(h, _)| (h - 1.0).norm_sqr()).collect();
    (!v.is_empty()).then(|| (v.iter().sum::<f64>() / v.len() as f64).sqrt())
}

fn finite(v: f64) -> Option<f64> {
    v.is_finite().then_some(v)
}

fn failed(method: &str, e: anyhow::Error, t: f64) -> CompareRow {
    CompareRow {
        method: method.into(),
        diagnostic: Some(format!("{e:#}")),
        order: None,
        fit_error_in_band: None,
        fit_error_out_of_band: None,
        compensated_error_in_band: None,
        compensated_error_out_of_band: None,
        flat_band_hz: None,
        noise_gain: None,
        latency_samples: None,
        paper: None,
        design_time_s: t,
        compensated: Vec::new(),
    }
}

/// Masks (coherent ∧ in band, coherent ∧ out of band) of an axis.
fn masks(setup: &CompareSetup, a: &AxisFrf) -> (Vec<bool>, Vec<bool>, (f64, f64)) {
    let band = coherent_band(setup.freq_hz, a, setup.base.coherence_threshold);
    let coherent: Vec<bool> = setup
        .freq_hz
        .iter()
        .enumerate()
        .map(|(k, f)| {
            *f >= band.0 && *f <= band.1 && a.coherence.as_ref().is_none_or(|c| c[k] >= setup.base.coherence_threshold)
        })
        .collect();
    if setup.bands.is_empty() {
        return (coherent, vec![false; setup.freq_hz.len()], band);
    }
    let bm = band_mask(setup.freq_hz, &setup.bands);
    let inside = coherent.iter().zip(&bm).map(|(c, b)| *c && *b).collect();
    let outside = coherent.iter().zip(&bm).map(|(c, b)| *c && !*b).collect();
    (inside, outside, band)
}

/// A row from a single design.
fn row_from_design(method: &str, setup: &CompareSetup, a: &AxisFrf, d: &AxisDesign, t: f64) -> CompareRow {
    let (inside, outside, _) = masks(setup, a);
    let fs = setup.base.fs_hz;
    let lag = d.kalman.lag as f64;
    let comp: Vec<Complex64> = setup
        .freq_hz
        .iter()
        .zip(&a.frf)
        .map(|(f, g)| filter_response(&d.filter, *f, fs) * g * Complex64::from_polar(1.0, 2.0 * PI * f * lag / fs))
        .collect();
    CompareRow {
        method: method.into(),
        diagnostic: None,
        order: Some(d.model.order()),
        fit_error_in_band: finite(relative_rms_error(|f| d.fitted_frf(f), setup.freq_hz, &a.frf, &inside)),
        fit_error_out_of_band: finite(relative_rms_error(|f| d.fitted_frf(f), setup.freq_hz, &a.frf, &outside)),
        compensated_error_in_band: rms_error(&comp, &inside),
        compensated_error_out_of_band: rms_error(&comp, &outside),
        flat_band_hz: Some(d.flat_band_hz),
        noise_gain: Some(d.noise_gain),
        latency_samples: Some(d.kalman.lag),
        paper: d.paper.as_ref().map(|p| p.1.clone()),
        design_time_s: t,
        compensated: comp,
    }
}

fn run_design(method: &str, setup: &CompareSetup, a: &AxisFrf, r: f64, opts: &DesignOptions) -> CompareRow {
    let t0 = Instant::now();
    match design_axis(setup.freq_hz, a, r, opts) {
        Ok(d) => row_from_design(method, setup, a, &d, t0.elapsed().as_secs_f64()),
        Err(e) => failed(method, e, t0.elapsed().as_secs_f64()),
    }
}

/// A segment (Hz) and the range its fit uses (Hz).
type Segment = ((f64, f64), (f64, f64));

/// Segments of parallel elaboration ([`ParallelDesign`]): with bands, each band's
/// share of the zero-phase split and the design region of
/// `design --parallel` ([`crate::design::parallel::design_regions`]); without, three
/// equal parts of the coherent band, widened the same way.
fn parallel_segments(bands: &[Band], coherent: (f64, f64)) -> Result<Vec<Segment>> {
    let m = crate::design::parallel::REGION_MARGIN;
    if bands.len() >= 2 {
        let ranges: Vec<(f64, f64)> = bands.iter().map(|b| (b.lo_hz, b.hi_hz)).collect();
        let cuts = crate::design::bands::crossovers(&ranges)?;
        let regions = crate::design::parallel::design_regions(bands, coherent.0, coherent.1)?;
        return Ok(regions
            .iter()
            .enumerate()
            .map(|(k, r)| {
                let lo = if k == 0 { coherent.0 } else { cuts[k - 1] };
                let hi = cuts.get(k).copied().unwrap_or(coherent.1);
                ((lo, hi), (r.lo_hz, r.hi_hz))
            })
            .collect());
    }
    let w = (coherent.1 - coherent.0) / 3.0;
    let edges = [coherent.0, coherent.0 + w, coherent.0 + 2.0 * w, coherent.1];
    Ok(edges.windows(2).map(|e| ((e[0], e[1]), ((e[0] / m).max(coherent.0), (e[1] * m).min(coherent.1)))).collect())
}

/// Parallel elaboration (paper §3.3): one paper-method design per segment,
/// combined with the zero-phase band gains of the offline split, evaluated
/// in the frequency domain.
///
/// The coherent band is cut into segments at the crossovers of
/// [`crate::offline::bandsplit`] (the middles of the gaps between the fitting
/// bands, or three equal segments without bands), each segment is designed
/// by the paper's method over the design region of `design --parallel`
/// ([`crate::design::parallel::design_regions`]; the denominator order is
/// chosen per segment among 2, 4, …, `--paper-orders`'s by the smallest fit
/// error on the segment's coherent lines), and the compensator is
/// `H(f) = Σ_k B_k(f)·H_k(f)` with the zero-phase band gains `B_k` of the
/// offline band split. Its "model" for the fit error is `Σ_k B_k(f)·Ĝ_k(f)`.
pub struct ParallelDesign {
    /// Segments (Hz) and their designs.
    pub segments: Vec<((f64, f64), AxisDesign)>,
    /// Crossovers between the segments (Hz).
    pub crossovers_hz: Vec<f64>,
    /// Sample rate (Hz).
    pub fs_hz: f64,
}

impl ParallelDesign {
    /// Combined compensator Σ_k B_k(f)·H_k(f) (f32 filters, zero phase split).
    pub fn response(&self, f_hz: f64) -> Complex64 {
        self.segments
            .iter()
            .enumerate()
            .map(|(k, (_, d))| {
                filter_response(&d.filter, f_hz, self.fs_hz)
                    * crate::offline::bandsplit::band_gain(f_hz, k, &self.crossovers_hz)
            })
            .sum()
    }

    /// Combined model Σ_k B_k(f)·Ĝ_k(f).
    pub fn fitted_frf(&self, f_hz: f64) -> Complex64 {
        self.segments
            .iter()
            .enumerate()
            .map(|(k, (_, d))| d.fitted_frf(f_hz) * crate::offline::bandsplit::band_gain(f_hz, k, &self.crossovers_hz))
            .sum()
    }

    /// Total order (sum over the segments).
    pub fn order(&self) -> usize {
        self.segments.iter().map(|s| s.1.model.order()).sum()
    }
}

/// Design parallel elaboration for one axis ([`ParallelDesign`]).
pub fn design_parallel(setup: &CompareSetup, a: &AxisFrf, r: f64) -> Result<ParallelDesign> {
    let (inside, outside, coherent) = masks(setup, a);
    let segments = parallel_segments(&setup.bands, coherent)?;
    let crossovers_hz: Vec<f64> = segments.iter().skip(1).map(|s| s.0 .0).collect();
    let FitMethod::Paper { rfp, .. } = &setup.paper else {
        anyhow::bail!("parallel elaboration needs the paper method's options");
    };
    let mut designs = Vec::new();
    for (k, (seg, fit)) in segments.iter().enumerate() {
        // Orders na = 2, 4, …, the user's na (same na − nb): keep the one
        // with the smallest fit error on the segment's coherent lines.
        let seg_lines: Vec<bool> = setup
            .freq_hz
            .iter()
            .zip(inside.iter().zip(&outside))
            .map(|(f, (i, o))| (*i || *o) && *f >= seg.0 && *f <= seg.1)
            .collect();
        let mut best: Option<(f64, AxisDesign)> = None;
        let mut errors = Vec::new();
        for na in (2..=rfp.na).step_by(2) {
            let nb = na.saturating_sub(rfp.na - rfp.nb);
            let opts = DesignOptions {
                method: FitMethod::Paper {
                    rfp: crate::fit::rfp::RfpOptions { nb, na, ..rfp.clone() },
                    prewarp_hz: None,
                },
                bands: vec![Band { lo_hz: fit.0, hi_hz: fit.1, label: format!("segment {}", k + 1) }],
                // this loop is the segment's order search
                paper_orders_auto: false,
                ..setup.base.clone()
            };
            match design_axis(setup.freq_hz, a, r, &opts) {
                Ok(d) => {
                    let err = finite(relative_rms_error(|f| d.fitted_frf(f), setup.freq_hz, &a.frf, &seg_lines))
                        .unwrap_or(f64::INFINITY);
                    if best.as_ref().is_none_or(|b| err < b.0) {
                        best = Some((err, d));
                    }
                }
                Err(e) => errors.push(format!("{nb}:{na}: {}", crate::design::paper_orders::last_clause(&e))),
            }
        }
        let Some((_, d)) = best else {
            anyhow::bail!(
                "segment {} ({:.0}–{:.0} Hz), every order 2..={} failed: {}",
                k + 1,
                seg.0,
                seg.1,
                rfp.na,
                errors.join("; ")
            );
        };
        designs.push((*seg, d));
    }
    Ok(ParallelDesign { segments: designs, crossovers_hz, fs_hz: setup.base.fs_hz })
}

/// The row of parallel elaboration ([`ParallelDesign`]).
fn parallel_row(setup: &CompareSetup, a: &AxisFrf, r: f64) -> CompareRow {
    let method = "paper, parallel";
    let t0 = Instant::now();
    let (inside, outside, coherent) = masks(setup, a);
    let result = design_parallel(setup, a, r).map(|p| {
        let fs = setup.base.fs_hz;
        let comp: Vec<Complex64> = setup.freq_hz.iter().zip(&a.frf).map(|(f, g)| p.response(*f) * g).collect();
        let model_frf: Vec<Complex64> = setup.freq_hz.iter().map(|f| p.fitted_frf(*f)).collect();
        let eval = if setup.bands.is_empty() {
            setup.freq_hz.iter().map(|f| *f >= coherent.0 && *f <= coherent.1).collect()
        } else {
            band_mask(setup.freq_hz, &setup.bands)
        };
        let flat = flat_band(|f| p.response(f), setup.freq_hz, &model_frf, &eval, 0, fs);
        // the worst-conditioned segment's diagnostics
        let worst = p
            .segments
            .iter()
            .filter_map(|(_, d)| d.paper.as_ref().map(|x| x.1.clone()))
            .max_by(|x, y| x.observability_condition.total_cmp(&y.observability_condition));
        CompareRow {
            method: method.into(),
            diagnostic: None,
            order: Some(p.order()),
            fit_error_in_band: finite(relative_rms_error(|f| p.fitted_frf(f), setup.freq_hz, &a.frf, &inside)),
            fit_error_out_of_band: finite(relative_rms_error(|f| p.fitted_frf(f), setup.freq_hz, &a.frf, &outside)),
            compensated_error_in_band: rms_error(&comp, &inside),
            compensated_error_out_of_band: rms_error(&comp, &outside),
            flat_band_hz: Some(flat),
            noise_gain: Some(crate::design::criterion::noise_gain(|f| p.response(f), fs)),
            latency_samples: Some(0),
            paper: worst,
            design_time_s: 0.0,
            compensated: comp,
        }
    });
    let t = t0.elapsed().as_secs_f64();
    match result {
        Ok(row) => CompareRow { design_time_s: t, ..row },
        Err(e) => failed(method, e, t),
    }
}

/// Compare the methods on one axis.
///
/// Each method is one row: fit error inside and outside the fitting bands
/// (relative RMS of Ĝ against the measured lines, coherent lines only),
/// compensated error inside and outside the bands (RMS of
/// |H·G·e^{j2πfL/fs} − 1| with the f32 filter and the *measured* G, the same
/// truth for every method), flat band, white-noise gain, order, latency, the
/// paper path's condition numbers and observability rank, and design time. A
/// method that fails is a row with its diagnostic.
///
/// `progress` hears when each method starts and how it ended.
pub fn compare_axis(setup: &CompareSetup, a: &AxisFrf, r: f64, progress: &Progress) -> AxisComparison {
    let (_, _, coherent) = masks(setup, a);
    let name = axis_name(a.axis);
    let timed = |method: &str, run: &dyn Fn() -> CompareRow| {
        progress.say(&format!("axis {name}: {method}…"));
        let row = run();
        let outcome = if row.diagnostic.is_none() { "verified" } else { "failed" };
        progress.say(&format!("axis {name}: {method}: {outcome} in {:.1} s", row.design_time_s));
        row
    };
    let mut rows = Vec::new();
    let whole_paper = DesignOptions { method: setup.paper.clone(), bands: Vec::new(), ..setup.base.clone() };
    let paper_whole = "paper, whole band";
    rows.push(timed(paper_whole, &|| run_design(paper_whole, setup, a, r, &whole_paper)));
    if setup.bands.is_empty() {
        rows.push(failed(
            "paper, band-fitted",
            anyhow::anyhow!("no bands: give --spindle-rpm/--teeth, --band or --bands-from"),
            0.0,
        ));
    } else {
        let banded = DesignOptions { method: setup.paper.clone(), bands: setup.bands.clone(), ..setup.base.clone() };
        let paper_banded = "paper, band-fitted";
        rows.push(timed(paper_banded, &|| run_design(paper_banded, setup, a, r, &banded)));
    }
    rows.push(timed("paper, parallel", &|| parallel_row(setup, a, r)));
    let vf = DesignOptions { method: FitMethod::Vf, bands: Vec::new(), ..setup.base.clone() };
    let vf_whole = "default (vf), whole band";
    rows.push(timed(vf_whole, &|| run_design(vf_whole, setup, a, r, &vf)));
    if !setup.bands.is_empty() {
        let vf_b = DesignOptions { method: FitMethod::Vf, bands: setup.bands.clone(), ..setup.base.clone() };
        let vf_banded = "default (vf), band-weighted";
        rows.push(timed(vf_banded, &|| run_design(vf_banded, setup, a, r, &vf_b)));
    }
    AxisComparison { axis: name, coherent_band_hz: coherent, rows }
}

/// What one comparison needs besides the FRF.
#[derive(Clone, Debug)]
pub struct CompareInputs {
    /// The FRF's file, as shown.
    pub frf_name: String,
    /// R per axis (N²).
    pub r: [Option<f64>; 3],
    /// The fitting bands (empty: the whole coherent band).
    pub bands: Vec<Band>,
    /// The default method's options (rate, latency, criterion, orders auto).
    pub base: DesignOptions,
    /// The paper's method at its orders and prewarp.
    pub paper: FitMethod,
    /// Where each axis and method reports its start and outcome.
    pub progress: Progress,
}

/// Run the comparison on every axis of `frf` (no output files).
pub fn compare(frf: &Frf, inputs: &CompareInputs) -> Comparison {
    let setup = CompareSetup {
        freq_hz: &frf.freq_hz,
        base: inputs.base.clone(),
        paper: inputs.paper.clone(),
        bands: inputs.bands.clone(),
    };
    let mut axes = Vec::new();
    for a in &frf.axes {
        axes.push(compare_axis(&setup, a, inputs.r[a.axis].expect("R for every FRF axis"), &inputs.progress));
    }
    Comparison { frf: inputs.frf_name.clone(), fs_hz: inputs.base.fs_hz, bands: inputs.bands.clone(), axes }
}
