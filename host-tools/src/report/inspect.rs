//! `dynocomp inspect`: what an image holds, for people and for scripts.

use anyhow::Result;
use dynocomp_core::image::{
    AxisImage, AxisScaling, AxisSummary, BoxImage, CoeffImage, DesignMethod, MatrixImage, ParallelImage, RowDesign,
    PARALLEL_FORMAT_VERSION,
};
use serde::Serialize;
use std::fmt::Write;

use dynocomp_core::kernel::Section;

use crate::frf::axis_name;
use crate::offline::sidecar::ModelSidecar;

/// Per-axis part of the inspection report.
#[derive(Debug, Serialize)]
pub struct AxisReport {
    /// Axis letter.
    pub axis: &'static str,
    /// Number of 2x2 sections in the compensator.
    pub sections: usize,
    /// Compensator order (states).
    pub filter_order: usize,
    /// Order of the fitted sensor model.
    pub model_order: u16,
    /// ADC code at 0 N.
    pub adc_offset_code: f32,
    /// N per ADC code.
    pub newton_per_code: f32,
    /// DAC codes per N.
    pub dac_code_per_newton: f32,
    /// DAC code at 0 N.
    pub dac_offset_code: f32,
    /// Normalized RMS fit error (fraction).
    pub fit_nrmse: f32,
    /// Flat band (Hz).
    pub flat_band_hz: [f32; 2],
    /// White-noise gain (ratio).
    pub noise_gain: f32,
    /// Process noise intensity Q.
    pub q: f64,
    /// Measurement noise variance R (N²).
    pub r: f64,
    /// Largest pole radius of the compensator (z-plane).
    pub max_pole_radius: f64,
    /// 3x3 image only: how this axis's output row was designed, `3x3`
    /// (crosstalk compensated) or `per-axis` (direct FRF only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub row_design: Option<&'static str>,
}

/// The shared filter of a 3x3 image (format 3).
#[derive(Debug, Serialize)]
pub struct MatrixReport {
    /// 2x2 sections shared by the three outputs.
    pub sections: usize,
    /// Of which normal-form pole pairs.
    pub pairs: usize,
    /// Of which diagonal (real-pole) sections.
    pub diagonals: usize,
    /// Filter order (states).
    pub filter_order: usize,
    /// FIR taps, each a 3x3 matrix.
    pub fir_taps: usize,
    /// Largest pole radius (z-plane).
    pub max_pole_radius: f64,
    /// DC gain, output row × input column (N/N); near the identity for a
    /// calibrated compensator.
    pub dc_gain: [[f64; 3]; 3],
    /// Bound on each output row's gain for bounded forces (ℓ1 norm of its
    /// impulse response over the three inputs, N/N).
    pub row_gain_bound: [f64; 3],
}

/// Inspection report of a whole image.
#[derive(Debug, Serialize)]
pub struct InspectReport {
    /// Image format version.
    pub format_version: u16,
    /// Image id (its CRC-32).
    pub image_id: String,
    /// Sample rate (Hz).
    pub fs_hz: u32,
    /// Declared latency (samples).
    pub latency_samples: u16,
    /// Whether the image is offline-only (the box never runs it).
    pub offline_only: bool,
    /// Whether the box would run it inline.
    pub runs_in_box: bool,
    /// Design method.
    pub method: &'static str,
    /// SHA-256 of the source FRF file.
    pub source_sha256: String,
    /// Creation time (Unix seconds).
    pub created_unix_s: u64,
    /// Why the box never runs it, when it is offline only, e.g.
    /// `parallel elaboration, 3 bands: 900-1300 Hz, …`.
    pub offline_reason: Option<String>,
    /// Axes (of a box image; empty for a parallel image, see `bands`).
    pub axes: Vec<AxisReport>,
    /// Bands of a parallel-elaboration image (empty otherwise), lowest first.
    pub bands: Vec<BandReport>,
    /// Predicted CPU load of the box's sample interrupt at `fs_hz`
    /// (`dynocomp_core::budget`); `null` for a parallel image.
    pub box_load: Option<crate::realize::load::LoadReport>,
    /// The shared 3x3 filter of a 3x3 image (absent otherwise).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub matrix: Option<MatrixReport>,
    /// Whether a 3x3 image's filter was reduced to fit the box, by its model
    /// sidecar (absent for other images).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub box_reduction: Option<ReductionReport>,
}

/// What a 3x3 image's model sidecar says of its filter's reduction for the
/// box ([`crate::design::mimo::reduce`]).
#[derive(Debug, Serialize)]
pub struct ReductionReport {
    /// The sidecar read.
    pub sidecar: String,
    /// The reduction, where the image holds a reduced filter; `null` where
    /// it holds the full one or the sidecar cannot tell.
    pub reduction: Option<crate::design::mimo::reduce::ReductionFigures>,
    /// The same in words.
    pub line: String,
}

/// [`ReductionReport`] of a 3x3 image from what its model sidecar
/// (`sidecar`, as shown) gave: the sidecar that belongs to the image, or why
/// there is none. Reduced (with the figures), full, or not known.
pub fn reduction_report(sidecar: String, read: Result<ModelSidecar, String>) -> ReductionReport {
    const UNKNOWN: &str = "whether the 3x3 filter was reduced for the box is not known";
    let (reduction, line) = match read {
        Ok(s) => match s.matrix.and_then(|m| m.box_reduction) {
            Some(Some(r)) => {
                let line = r.line();
                (Some(r), line)
            }
            Some(None) => (None, "the full 3x3 filter: not reduced for the box".to_string()),
            None => (
                None,
                format!(
                    "{UNKNOWN}: its model sidecar predates the record of reductions (re-run `dynocomp design` to \
                     write both)"
                ),
            ),
        },
        Err(why) => (None, format!("{UNKNOWN}: {why}")),
    };
    ReductionReport { sidecar, reduction, line }
}

/// One band of a parallel-elaboration image.
#[derive(Debug, Serialize)]
pub struct BandReport {
    /// Band edges the compensators were designed for (Hz).
    pub band_hz: [f32; 2],
    /// Zero-phase split of `compensate`: the band's share of the record
    /// runs from `split_hz[0]` to `split_hz[1]` (crossovers, Hz; 0 and
    /// Nyquist at the ends).
    pub split_hz: [f64; 2],
    /// Per-axis compensators of the band.
    pub axes: Vec<AxisReport>,
}

fn method_name(m: DesignMethod) -> &'static str {
    match m {
        DesignMethod::Manual => "manual",
        DesignMethod::VectorFitting => "vf",
        DesignMethod::Paper => "paper",
    }
}

/// Largest pole radius over all sections (eigenvalues of I + Δ, in f64).
pub fn max_pole_radius(sections: &[Section]) -> f64 {
    sections
        .iter()
        .flat_map(|s| crate::realize::modal::section_poles(s.delta.map(f64::from)))
        .map(|p| p.norm())
        .fold(0.0, f64::max)
}

/// One axis's row of the table: its scaling and design summary, and the
/// filter it runs (its own, or the shared 3x3 one).
fn axis_report(
    axis: u8,
    scaling: &AxisScaling,
    summary: &AxisSummary,
    sections: &[Section],
    order: usize,
) -> AxisReport {
    AxisReport {
        axis: axis_name(axis as usize),
        sections: sections.len(),
        filter_order: order,
        model_order: summary.model_order,
        adc_offset_code: scaling.adc_offset_code,
        newton_per_code: scaling.newton_per_code,
        dac_code_per_newton: scaling.dac_code_per_newton,
        dac_offset_code: scaling.dac_offset_code,
        fit_nrmse: summary.fit_nrmse,
        flat_band_hz: [summary.flat_lo_hz, summary.flat_hi_hz],
        noise_gain: summary.noise_gain,
        q: summary.q,
        r: summary.r,
        max_pole_radius: max_pole_radius(sections),
        row_design: None,
    }
}

fn axis_reports(axes: &[Option<AxisImage>]) -> Vec<AxisReport> {
    axes.iter()
        .flatten()
        .map(|a| axis_report(a.axis, &a.scaling, &a.summary, a.filter.sections(), a.filter.order()))
        .collect()
}

/// The report of an image the box runs (format 1 or 3), with its axes and,
/// for a 3x3 image, its shared filter.
fn box_report(image: BoxImage, axes: Vec<AxisReport>, matrix: Option<MatrixReport>) -> InspectReport {
    let (source_sha256, created_unix_s) = match &image {
        BoxImage::PerAxis(i) => (i.source_sha256, i.created_unix_s),
        BoxImage::Matrix(m) => (m.source_sha256, m.created_unix_s),
    };
    let loaded = Ok(image);
    let box_mode = dynocomp_core::sample::select_mode(Some(&loaded), false);
    InspectReport {
        format_version: image.format_version(),
        image_id: format!("{:08x}", image.id()),
        fs_hz: image.fs_hz(),
        latency_samples: image.latency_samples(),
        offline_only: image.is_offline_only(),
        runs_in_box: matches!(box_mode, dynocomp_core::sample::Mode::Compensate(_)),
        method: method_name(image.method()),
        source_sha256: source_sha256.iter().map(|b| format!("{b:02x}")).collect(),
        created_unix_s,
        offline_reason: image.is_offline_only().then(|| "marked offline only (flag 0x01)".to_string()),
        axes,
        bands: Vec::new(),
        box_load: Some(crate::realize::load::report(&image, dynocomp_core::budget::BOX_LOAD_LIMIT_PERMILLE)),
        matrix,
        box_reduction: None,
    }
}

/// Build the report of a box image (format 1).
pub fn report(image: &CoeffImage) -> InspectReport {
    box_report((*image).into(), axis_reports(&image.axes), None)
}

/// Build the report of a 3x3 image (format 3): the shared filter's shape,
/// each axis's scaling, summary and row design, and the box's predicted
/// cost per sample against its budget.
pub fn report_matrix(image: &MatrixImage) -> InspectReport {
    let f = &image.filter;
    let blocks: Vec<Section> = f.sections().iter().map(|s| s.block()).collect();
    let (pairs, diagonals) = f.kernel_counts();
    let order = 2 * pairs + 2 * diagonals;
    let axes = image
        .axes
        .iter()
        .zip(image.rows)
        .map(|(a, row)| AxisReport {
            row_design: Some(match row {
                RowDesign::Matrix => "3x3",
                RowDesign::PerAxis => "per-axis",
            }),
            ..axis_report(a.axis, &a.scaling, &a.summary, &blocks, order)
        })
        .collect();
    let matrix = MatrixReport {
        sections: f.sections().len(),
        pairs,
        diagonals,
        filter_order: order,
        fir_taps: f.fir().len(),
        max_pole_radius: max_pole_radius(&blocks),
        dc_gain: f.dc_gain(),
        row_gain_bound: std::array::from_fn(|i| f.row_gain_bound(i)),
    };
    box_report((*image).into(), axes, Some(matrix))
}

/// Build the report of a parallel-elaboration image (format 2): offline
/// only, with its bands and the zero-phase split `compensate` uses.
pub fn report_parallel(image: &ParallelImage) -> Result<InspectReport> {
    let edges: Vec<(f64, f64)> = image.bands().iter().map(|b| (f64::from(b.lo_hz), f64::from(b.hi_hz))).collect();
    let cross = crate::design::bands::crossovers(&edges)?;
    let nyquist = f64::from(image.fs_hz) / 2.0;
    let bands: Vec<BandReport> = image
        .bands()
        .iter()
        .enumerate()
        .map(|(k, b)| BandReport {
            band_hz: [b.lo_hz, b.hi_hz],
            split_hz: [if k == 0 { 0.0 } else { cross[k - 1] }, cross.get(k).copied().unwrap_or(nyquist)],
            axes: axis_reports(&b.axes),
        })
        .collect();
    let list =
        bands.iter().map(|b| format!("{:.0}-{:.0} Hz", b.band_hz[0], b.band_hz[1])).collect::<Vec<_>>().join(", ");
    Ok(InspectReport {
        format_version: PARALLEL_FORMAT_VERSION,
        image_id: format!("{:08x}", image.id()),
        fs_hz: image.fs_hz,
        latency_samples: image.latency_samples,
        offline_only: true,
        runs_in_box: false,
        method: method_name(image.method),
        source_sha256: image.source_sha256.iter().map(|b| format!("{b:02x}")).collect(),
        created_unix_s: image.created_unix_s,
        offline_reason: Some(format!("parallel elaboration, {} bands: {list}", bands.len())),
        axes: Vec::new(),
        bands,
        box_load: None,
        matrix: None,
        box_reduction: None,
    })
}

/// Human-readable rendering of the report.
pub fn render(r: &InspectReport) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "image {}  format v{}  method {}", r.image_id, r.format_version, r.method);
    let _ = writeln!(
        s,
        "fs {} Hz  latency {} samples ({:.1} µs)",
        r.fs_hz,
        r.latency_samples,
        f64::from(r.latency_samples) * 1e6 / f64::from(r.fs_hz)
    );
    if r.offline_only {
        let why = r.offline_reason.as_deref().unwrap_or("marked offline only");
        let _ = writeln!(s, "offline only: {why}");
        let _ = writeln!(
            s,
            "this image is for `dynocomp compensate`; the box never runs it (it stays in bypass, reason OfflineOnly)"
        );
    } else if r.box_load.as_ref().is_some_and(|l| !l.fits) {
        let _ = writeln!(s, "the box cannot run this image inline: its predicted CPU load exceeds the limit (it stays in bypass, reason OverBudget)");
    } else if !r.runs_in_box {
        let _ = writeln!(s, "the box cannot run this image inline (sample rate outside its 10-200 kHz range)");
    }
    if let Some(l) = &r.box_load {
        let _ = writeln!(s, "{}", crate::realize::load::describe(l, r.fs_hz));
    }
    let _ = writeln!(s, "source sha256 {}", r.source_sha256);
    if let Some(m) = &r.matrix {
        render_matrix(&mut s, m, &r.axes);
    }
    if let Some(b) = &r.box_reduction {
        let _ = writeln!(s, "{}", b.line);
    }
    if r.bands.is_empty() {
        render_axes(&mut s, &r.axes);
    }
    for (k, b) in r.bands.iter().enumerate() {
        let _ = writeln!(
            s,
            "band {k}: designed for {:.0}-{:.0} Hz, zero-phase split {:.0}-{:.0} Hz",
            b.band_hz[0], b.band_hz[1], b.split_hz[0], b.split_hz[1]
        );
        render_axes(&mut s, &b.axes);
    }
    s
}

/// The shared filter of a 3x3 image: its shape, which rows compensate
/// crosstalk, and its DC gain matrix.
fn render_matrix(s: &mut String, m: &MatrixReport, axes: &[AxisReport]) {
    let _ = writeln!(
        s,
        "3x3 filter (shared by x, y, z): {} sections ({} pole pairs, {} diagonal), order {}, {} FIR taps (3x3 each), \
         max |p| {:.7}",
        m.sections, m.pairs, m.diagonals, m.filter_order, m.fir_taps, m.max_pole_radius
    );
    let rows: Vec<String> = axes.iter().map(|a| format!("{} {}", a.axis, a.row_design.unwrap_or("?"))).collect();
    let _ = writeln!(s, "output rows: {} (3x3 = crosstalk compensated, per-axis = direct FRF only)", rows.join(", "));
    for (i, row) in m.dc_gain.iter().enumerate() {
        let _ = writeln!(
            s,
            "DC gain {} <- (x, y, z): {:>9.4} {:>9.4} {:>9.4}   gain bound {:.3}",
            axis_name(i),
            row[0],
            row[1],
            row[2],
            m.row_gain_bound[i]
        );
    }
}

fn render_axes(s: &mut String, axes: &[AxisReport]) {
    let _ = writeln!(
        s,
        "{:<4} {:>4} {:>5} {:>6} {:>8} {:>17} {:>6} {:>10} {:>10} {:>10}",
        "axis", "sec", "order", "model", "fit err", "flat band (Hz)", "noise", "Q", "R (N²)", "max |p|"
    );
    for a in axes {
        let _ = writeln!(
            s,
            "{:<4} {:>4} {:>5} {:>6} {:>7.2}% {:>8.0}-{:<8.0} {:>6.2} {:>10.3e} {:>10.3e} {:>10.7}",
            a.axis,
            a.sections,
            a.filter_order,
            a.model_order,
            a.fit_nrmse * 100.0,
            a.flat_band_hz[0],
            a.flat_band_hz[1],
            a.noise_gain,
            a.q,
            a.r,
            a.max_pole_radius
        );
        // `design` writes an axis it could not compensate as a pure delay
        // with no model and q = 0 (crate::design::pass_through).
        if a.model_order == 0 && a.q == 0.0 && a.sections == 0 {
            let _ = writeln!(s, "     axis {}: NOT COMPENSATED, passed through raw (delayed by the latency)", a.axis);
        }
    }
}
