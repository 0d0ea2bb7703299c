//! `dynocomp compare`: the seed paper's method (whole band, band-fitted,
//! parallel elaboration) against the default method on the same FRF.
//!
//! Per axis, each method is one row: fit error inside and outside the
//! fitting bands (relative RMS of Ĝ against the measured lines, coherent
//! lines only), compensated error inside and outside the bands (RMS of
//! |H·G·e^{j2πfL/fs} − 1| with the f32 filter and the *measured* G, the
//! same truth for every method), flat band, white-noise gain, order,
//! latency, the paper path's condition numbers and observability rank, and
//! design time. A method that fails is a row with its diagnostic.
//!
//! **Parallel elaboration** (paper §3.3) is evaluated in the frequency
//! domain: the coherent band is cut into segments at the crossovers of
//! [`crate::bandsplit`] (the middles of the gaps between the fitting bands,
//! or three equal segments without bands), each segment is designed by the
//! paper's method over the design region of `design --parallel`
//! ([`crate::parallel::design_regions`]; the
//! denominator order is chosen per segment among 2, 4, …, `--paper-orders`'s
//! by the smallest fit error on the segment's coherent lines), and the
//! compensator is `H(f) = Σ_k B_k(f)·H_k(f)` with the zero-phase band gains
//! `B_k` of the offline band split. Its "model" for the fit error is
//! `Σ_k B_k(f)·Ĝ_k(f)`.

use anyhow::{Context, Result};
use clap::Args;
use num_complex::Complex64;
use plotters::prelude::*;
use serde::Serialize;
use std::f64::consts::PI;
use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;

use crate::bands::{band_mask, Band};
use crate::design::{coherent_band, design_axis, flat_band, AxisDesign, DesignOptions, FitMethod};
use crate::design_cmd::{BandArgs, DesignInputArgs, PaperArgs};
use crate::fit::relative_rms_error;
use crate::frf::{axis_name, AxisFrf, Frf};
use crate::io;
use crate::paper::PaperDiagnostics;
use crate::quantize::filter_response;

/// Arguments of `dynocomp compare`.
#[derive(Args, Debug, Clone)]
pub struct CompareArgs {
    /// The FRF, sample rate, noise and Q-criterion inputs (as for `design`).
    #[command(flatten)]
    pub input: DesignInputArgs,
    /// Latency L of the default method (samples).
    #[arg(long, default_value_t = 4)]
    pub latency: usize,
    /// Options of the paper's method.
    #[command(flatten)]
    pub paper: PaperArgs,
    /// Fitting bands.
    #[command(flatten)]
    pub bands: BandArgs,
    /// Write the plots (one SVG per axis) and compare.json into this directory.
    #[arg(long)]
    pub out_dir: Option<PathBuf>,
    /// Print the comparison as JSON on stdout.
    #[arg(long)]
    pub json: bool,
}

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
    let band = coherent_band(setup.freq_hz, a.coherence.as_deref(), setup.base.coherence_threshold);
    let coherent: Vec<bool> = setup
        .freq_hz
        .iter()
        .enumerate()
        .map(|(k, f)| *f >= band.0 && *f <= band.1 && a.coherence.as_ref().is_none_or(|c| c[k] >= setup.base.coherence_threshold))
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

/// Segments of parallel elaboration (module doc): with bands, each band's
/// share of the zero-phase split and the design region of
/// `design --parallel` ([`crate::parallel::design_regions`]); without, three
/// equal parts of the coherent band, widened the same way.
fn parallel_segments(bands: &[Band], coherent: (f64, f64)) -> Result<Vec<Segment>> {
    let m = crate::parallel::REGION_MARGIN;
    if bands.len() >= 2 {
        let ranges: Vec<(f64, f64)> = bands.iter().map(|b| (b.lo_hz, b.hi_hz)).collect();
        let cuts = crate::bandsplit::crossovers(&ranges)?;
        let regions = crate::parallel::design_regions(bands, coherent.0, coherent.1)?;
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

/// Parallel elaboration (paper §3.3, module doc): one paper-method design
/// per segment, combined with the zero-phase band gains of the offline split.
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
            .map(|(k, (_, d))| filter_response(&d.filter, f_hz, self.fs_hz) * crate::bandsplit::band_gain(f_hz, k, &self.crossovers_hz))
            .sum()
    }

    /// Combined model Σ_k B_k(f)·Ĝ_k(f).
    pub fn fitted_frf(&self, f_hz: f64) -> Complex64 {
        self.segments.iter().enumerate().map(|(k, (_, d))| d.fitted_frf(f_hz) * crate::bandsplit::band_gain(f_hz, k, &self.crossovers_hz)).sum()
    }

    /// Total order (sum over the segments).
    pub fn order(&self) -> usize {
        self.segments.iter().map(|s| s.1.model.order()).sum()
    }
}

/// Design parallel elaboration for one axis (module doc).
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
        let seg_lines: Vec<bool> = setup.freq_hz.iter().zip(inside.iter().zip(&outside)).map(|(f, (i, o))| (*i || *o) && *f >= seg.0 && *f <= seg.1).collect();
        let mut best: Option<(f64, AxisDesign)> = None;
        let mut errors = Vec::new();
        for na in (2..=rfp.na).step_by(2) {
            let nb = na.saturating_sub(rfp.na - rfp.nb);
            let opts = DesignOptions {
                method: FitMethod::Paper { rfp: crate::fit::rfp::RfpOptions { nb, na, ..rfp.clone() }, prewarp_hz: None },
                bands: vec![Band { lo_hz: fit.0, hi_hz: fit.1, label: format!("segment {}", k + 1) }],
                // this loop is the segment's order search
                paper_orders_auto: false,
                ..setup.base.clone()
            };
            match design_axis(setup.freq_hz, a, r, &opts) {
                Ok(d) => {
                    let err = finite(relative_rms_error(|f| d.fitted_frf(f), setup.freq_hz, &a.frf, &seg_lines)).unwrap_or(f64::INFINITY);
                    if best.as_ref().is_none_or(|b| err < b.0) {
                        best = Some((err, d));
                    }
                }
                Err(e) => errors.push(format!("{nb}:{na}: {}", crate::paper_orders::last_clause(&e))),
            }
        }
        let Some((_, d)) = best else {
            anyhow::bail!("segment {} ({:.0}–{:.0} Hz), every order 2..={} failed: {}", k + 1, seg.0, seg.1, rfp.na, errors.join("; "));
        };
        designs.push((*seg, d));
    }
    Ok(ParallelDesign { segments: designs, crossovers_hz, fs_hz: setup.base.fs_hz })
}

/// Parallel elaboration row (module doc).
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
            noise_gain: Some(crate::design::noise_gain(|f| p.response(f), fs)),
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

/// Compare the methods on one axis (module doc).
pub fn compare_axis(setup: &CompareSetup, a: &AxisFrf, r: f64) -> AxisComparison {
    let (_, _, coherent) = masks(setup, a);
    let mut rows = Vec::new();
    let whole_paper = DesignOptions { method: setup.paper.clone(), bands: Vec::new(), ..setup.base.clone() };
    rows.push(run_design("paper, whole band", setup, a, r, &whole_paper));
    if setup.bands.is_empty() {
        rows.push(failed("paper, band-fitted", anyhow::anyhow!("no bands: give --spindle-rpm/--teeth, --band or --bands-from"), 0.0));
    } else {
        let banded = DesignOptions { method: setup.paper.clone(), bands: setup.bands.clone(), ..setup.base.clone() };
        rows.push(run_design("paper, band-fitted", setup, a, r, &banded));
    }
    rows.push(parallel_row(setup, a, r));
    let vf = DesignOptions { method: FitMethod::Vf, bands: Vec::new(), ..setup.base.clone() };
    rows.push(run_design("default (vf), whole band", setup, a, r, &vf));
    if !setup.bands.is_empty() {
        let vf_b = DesignOptions { method: FitMethod::Vf, bands: setup.bands.clone(), ..setup.base.clone() };
        rows.push(run_design("default (vf), band-weighted", setup, a, r, &vf_b));
    }
    AxisComparison { axis: axis_name(a.axis), coherent_band_hz: coherent, rows }
}

fn pct(v: Option<f64>) -> String {
    v.map_or("–".into(), |v| format!("{:.2}%", 100.0 * v))
}

/// The comparison as text tables, one per axis.
pub fn render(c: &Comparison) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "compare {} at fs {} Hz", c.frf, c.fs_hz);
    if c.bands.is_empty() {
        let _ = writeln!(s, "no fitting bands: \"in band\" = the coherent band");
    } else {
        let _ = writeln!(s, "fitting bands: {}", crate::bands::describe(&c.bands));
    }
    for ax in &c.axes {
        let _ = writeln!(s, "\naxis {} (coherent {:.0}–{:.0} Hz)", ax.axis, ax.coherent_band_hz.0, ax.coherent_band_hz.1);
        let _ = writeln!(
            s,
            "{:<28} {:>5} {:>8} {:>8} {:>8} {:>8} {:>13} {:>6} {:>3} {:>8} {:>8} {:>8} {:>5} {:>8}",
            "method", "order", "fit in", "fit out", "comp in", "comp out", "flat (Hz)", "noise", "L", "cond RFP", "cond GN", "cond obs", "rank", "time"
        );
        for r in &ax.rows {
            if let Some(diag) = &r.diagnostic {
                let _ = writeln!(s, "{:<28} FAILED after {:.0} ms: {diag}", r.method, r.design_time_s * 1e3);
                continue;
            }
            let (c1, c2, c3, rank) = match &r.paper {
                Some(p) => (
                    format!("{:.1e}", p.rfp_condition),
                    format!("{:.1e}", p.jacobian_condition),
                    format!("{:.1e}", p.observability_condition),
                    format!("{}/{}", p.observability_rank, p.observability_dim),
                ),
                None => ("–".into(), "–".into(), "–".into(), "–".into()),
            };
            let flat = r.flat_band_hz.map_or("–".into(), |f| format!("{:.0}-{:.0}", f.0, f.1));
            let _ = writeln!(
                s,
                "{:<28} {:>5} {:>8} {:>8} {:>8} {:>8} {:>13} {:>6.2} {:>3} {:>8} {:>8} {:>8} {:>5} {:>6.0}ms",
                r.method,
                r.order.map_or("–".into(), |o| o.to_string()),
                pct(r.fit_error_in_band),
                pct(r.fit_error_out_of_band),
                pct(r.compensated_error_in_band),
                pct(r.compensated_error_out_of_band),
                flat,
                r.noise_gain.unwrap_or(f64::NAN),
                r.latency_samples.map_or("–".into(), |l| l.to_string()),
                c1,
                c2,
                c3,
                rank,
                r.design_time_s * 1e3
            );
        }
    }
    let _ = writeln!(
        s,
        "\nfit in/out: relative RMS |Ĝ−G|/|G| on coherent lines inside/outside the bands; comp in/out: RMS |H·G·e^(j2πfL/fs) − 1| with the f32 filter and the measured G; \
         flat: |H·Ĝ| within ±5 %/±5° of the delay from the first band line; noise: white-noise gain; L: latency (samples); cond: condition numbers of the RFP least squares, \
         the Gauss–Newton Jacobian and the observability matrix; rank: observability rank of the augmented system"
    );
    s
}

const COLORS: [RGBColor; 5] = [RGBColor(214, 39, 40), RGBColor(255, 127, 14), RGBColor(148, 103, 189), RGBColor(31, 119, 180), RGBColor(44, 160, 44)];

/// SVG of one axis: |H·G·delay| and the phase of every method that produced
/// a filter, with the fitting bands shaded.
pub fn plot_axis(freq: &[f64], ax: &AxisComparison, bands: &[Band]) -> Result<String> {
    use crate::report::{build_chart, draw_line, legend, mesh, perr, shade, shade_bands, FONT};
    let xr = (freq[0], freq[freq.len() - 1].max(freq[0] + 1.0));
    let mut buf = String::new();
    {
        let root = SVGBackend::with_string(&mut buf, (1100, 760)).into_drawing_area();
        root.fill(&WHITE).map_err(perr)?;
        let root = root.titled(&format!("Axis {} — compensated response H·G of each method (measured G)", ax.axis), (FONT, 20)).map_err(perr)?;
        let (top, bot) = root.split_vertically(380);
        let yr_m = (0.5, 1.5);
        let mut c = build_chart(&top, "Magnitude |H·G| (1 = exact)", xr, yr_m)?;
        mesh(&mut c, "Frequency (Hz)", "|H·G|", &crate::report::hz, &|v| format!("{v:.1}"), 6)?;
        shade(&mut c, ax.coherent_band_hz, xr, yr_m, RGBColor(150, 150, 150), 0.10, "coherent band")?;
        shade_bands(&mut c, bands, xr, yr_m, true)?;
        let yr_p = (-45.0, 45.0);
        let mut cp = build_chart(&bot, "Phase ∠(H·G) (0 = exact)", xr, yr_p)?;
        mesh(&mut cp, "Frequency (Hz)", "Phase (°)", &crate::report::hz, &|v| format!("{v:.0}"), 7)?;
        shade_bands(&mut cp, bands, xr, yr_p, false)?;
        for (r, color) in ax.rows.iter().zip(COLORS.iter().cycle()) {
            if r.compensated.is_empty() {
                continue;
            }
            let mag: Vec<(f64, f64)> = freq.iter().zip(&r.compensated).map(|(f, h)| (*f, h.norm())).collect();
            let ph: Vec<(f64, f64)> = freq.iter().zip(&r.compensated).map(|(f, h)| (*f, h.arg().to_degrees())).collect();
            draw_line(&mut c, &mag, yr_m, 0.3, *color, 1, false, &r.method)?;
            draw_line(&mut cp, &ph, yr_p, 30.0, *color, 1, false, &r.method)?;
        }
        legend(&mut c, SeriesLabelPosition::UpperLeft)?;
        legend(&mut cp, SeriesLabelPosition::LowerLeft)?;
        root.present().map_err(perr)?;
    }
    Ok(buf)
}

/// Run the comparison (no output files).
pub fn compare(args: &CompareArgs, frf: &Frf) -> Result<Comparison> {
    args.input.check_fs()?;
    let r = args.input.noise_variances(frf)?;
    let bands = args.bands.resolve(frf, args.input.fs).with_context(|| format!("{}", args.input.frf().display()))?;
    let setup = CompareSetup {
        freq_hz: &frf.freq_hz,
        base: DesignOptions {
            fs_hz: args.input.fs,
            lag: args.latency,
            force_rms: args.input.force_rms,
            max_noise_gain: args.input.max_noise_gain,
            discretization: args.input.discretization,
            paper_orders_auto: args.paper.auto(),
            ..Default::default()
        },
        paper: args.paper.method(args.bands.tooth_passing_hz(), args.input.fs)?,
        bands: bands.clone(),
    };
    let mut axes = Vec::new();
    for a in &frf.axes {
        eprintln!("comparing axis {}…", axis_name(a.axis));
        axes.push(compare_axis(&setup, a, r[a.axis].expect("R for every FRF axis")));
    }
    Ok(Comparison { frf: args.input.frf().display().to_string(), fs_hz: args.input.fs, bands, axes })
}

/// Run `dynocomp compare`.
pub fn run(args: &CompareArgs) -> Result<()> {
    if args.input.frf.len() != 1 {
        anyhow::bail!("compare: --frf given {} times; compare takes one FRF", args.input.frf.len());
    }
    let frf = io::read_frf(args.input.frf())?;
    let c = compare(args, &frf)?;
    let text = render(&c);
    let json = serde_json::to_string_pretty(&c)?;
    if let Some(dir) = &args.out_dir {
        let mut pages = Vec::new();
        for ax in &c.axes {
            pages.push(crate::report::Page {
                name: format!("{}_compare.svg", ax.axis),
                content: plot_axis(&frf.freq_hz, ax, &c.bands).with_context(|| format!("compare: axis {} plot", ax.axis))?,
            });
        }
        pages.push(crate::report::Page { name: "compare.json".into(), content: json.clone() });
        pages.push(crate::report::Page { name: "compare.txt".into(), content: text.clone() });
        let files = crate::report::write_pages(dir, &pages)?;
        eprintln!("compare: {} files in {}", files.len(), dir.display());
    }
    if args.json {
        println!("{json}");
    } else {
        print!("{text}");
    }
    Ok(())
}
