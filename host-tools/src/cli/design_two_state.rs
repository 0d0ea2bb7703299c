//! `dynocomp design --frf BEFORE --frf AFTER`: a set-up measured in two
//! states, designed per axis for the range between them
//! ([`crate::design::two_state::range::design_axes_over_range`]); the model
//! sidecar keeps both states for `compensate --offline --drift`. Default
//! method only, without fitting bands or parallel elaboration.

use anyhow::{bail, Context, Result};
use sha2::{Digest, Sha256};
use std::fmt::Write as _;

use dynocomp_core::image::CoeffImage;

use crate::cli::design_args::{DesignArgs, Method};
use crate::design::axis::{AxisDesign, DesignOptions};
use crate::design::image::build_image;
use crate::design::sensitivity::Sensitivity;
use crate::design::two_state::range::{design_axes_over_range, RangeDesign, RANGE_STATES};
use crate::frf::{axis_name, Frf};
use crate::io;
use crate::offline::sidecar::TwoStateJson;
use crate::report::summary::{render_summary, RangeFigures};
use crate::report::two_state::{RangeAxisJson, RangeJson};

/// Run `design` with two FRFs; returns the summary (text or JSON) for stdout.
pub fn run(args: &DesignArgs) -> Result<String> {
    let latency = check_args(args)?;
    let frfs = TwoFrfs::read(args)?;
    let r = args.input.noise_variances(&frfs.before)?;
    let opts = args.base_options(latency);
    let axes = design_ranges(args, &frfs, &r, &opts)?;
    let designs: Vec<AxisDesign> = axes.iter().map(|a| a.range.candidates[a.range.best].design.clone()).collect();
    let image = build_image(&designs, args.input.fs as u32, latency, args.full_scale, frfs.sha)?;
    write_image_and_sidecar(args, &image, &designs, &axes)?;
    let mut sensitivities = crate::design::sensitivity::predict_all(&designs, &opts);
    crate::design::sensitivity::set_line_spacing(&mut sensitivities, &frfs.before.freq_hz);
    render(args, &frfs, &axes, &designs, &sensitivities, &image, latency)
}

/// The options two FRFs allow; the declared latency (samples).
fn check_args(args: &DesignArgs) -> Result<usize> {
    let bands = &args.bands;
    if args.method != Method::Vf
        || args.parallel
        || bands.spindle_rpm.is_some()
        || !bands.band.is_empty()
        || bands.bands_from.is_some()
    {
        bail!(
            "--frf given twice (a set-up in two states): only the default method, without fitting bands or --parallel"
        );
    }
    let latency = args.latency.unwrap_or(crate::design::latency::DEFAULT_LATENCY);
    if latency > 16 {
        bail!("--latency {latency}: at most 16 samples");
    }
    args.input.check_values(&args.bands)?;
    Ok(latency)
}

/// The two FRFs, on the same lines and axes, and the SHA-256 of both
/// files' bytes.
struct TwoFrfs {
    before: Frf,
    after: Frf,
    sha: [u8; 32],
}

impl TwoFrfs {
    fn read(args: &DesignArgs) -> Result<Self> {
        let (p0, p1) = (&args.input.frf[0], &args.input.frf[1]);
        let b0 = std::fs::read(p0).with_context(|| format!("{}: cannot read", p0.display()))?;
        let b1 = std::fs::read(p1).with_context(|| format!("{}: cannot read", p1.display()))?;
        let f0 = io::parse_frf(p0, &b0)?;
        let f1 = io::parse_frf(p1, &b1)?;
        if (f0.has_cross() || f1.has_cross()) && !args.per_axis {
            bail!(
                "{}: holds cross FRFs, and the two-state design is per axis (it cannot take the 3x3 model); \
                 add --per-axis to design each axis from its direct FRFs, crosstalk not compensated",
                if f0.has_cross() { p0.display() } else { p1.display() }
            );
        }
        if f0.freq_hz != f1.freq_hz || f0.axes.iter().map(|a| a.axis).ne(f1.axes.iter().map(|a| a.axis)) {
            bail!(
                "{}: the second FRF must have the same frequency lines and axes as the first ({})",
                p1.display(),
                p0.display()
            );
        }
        let sha: [u8; 32] = Sha256::digest([b0, b1].concat()).into();
        Ok(TwoFrfs { before: f0, after: f1, sha })
    }
}

/// One axis designed for the range, with what the sidecar keeps of it.
struct RangeAxis {
    axis: usize,
    range: RangeDesign,
    sidecar: TwoStateJson,
}

/// Every axis designed for the range between the two states.
fn design_ranges(
    args: &DesignArgs,
    frfs: &TwoFrfs,
    r: &[Option<f64>; 3],
    opts: &DesignOptions,
) -> Result<Vec<RangeAxis>> {
    let (f0, f1) = (&frfs.before, &frfs.after);
    eprintln!(
        "designing {} axes for the range between two states ({} candidates each)…",
        f0.axes.len(),
        RANGE_STATES.len()
    );
    let results = design_axes_over_range(&f0.freq_hz, &f0.axes, &f1.axes, r, opts);
    let (p0, p1) = (args.input.frf[0].display(), args.input.frf[1].display());
    let mut axes = Vec::new();
    for (a, res) in f0.axes.iter().zip(results) {
        let name = axis_name(a.axis);
        let range = res.with_context(|| format!("{p0} / {p1}: axis {name}"))?;
        let first = &range.candidates[0].design;
        let dm0 = first
            .discrete
            .as_ref()
            .map(|x| x.0.clone())
            .ok_or_else(|| anyhow::anyhow!("axis {name}: no discrete model"))?;
        let sidecar = TwoStateJson::new(&range.states, first.compensated_band_hz, &dm0);
        axes.push(RangeAxis { axis: a.axis, range, sidecar });
    }
    Ok(axes)
}

/// Write the image and its model sidecar, with both states of every axis.
fn write_image_and_sidecar(
    args: &DesignArgs,
    image: &CoeffImage,
    designs: &[AxisDesign],
    axes: &[RangeAxis],
) -> Result<()> {
    let models: Vec<_> = designs.iter().map(|d| (d.axis, &d.model, d.discrete.as_ref().map(|x| &x.0))).collect();
    let mut sidecar = crate::offline::sidecar::ModelSidecar::new(image, &models);
    for a in axes {
        if let Some(m) = sidecar.axes.iter_mut().find(|m| m.axis == axis_name(a.axis)) {
            m.two_state = Some(a.sidecar.clone());
        }
    }
    crate::offline::sidecar::write_image_and_sidecar(&args.out, image, Some(&sidecar))
}

/// The summary (text or JSON) and the report, with each axis's range plot.
fn render(
    args: &DesignArgs,
    frfs: &TwoFrfs,
    axes: &[RangeAxis],
    designs: &[AxisDesign],
    sensitivities: &[Option<Sensitivity>],
    image: &CoeffImage,
    latency: usize,
) -> Result<String> {
    let shown = args.out.display().to_string();
    let range: Vec<RangeFigures> = axes
        .iter()
        .map(|a| {
            let c = &a.range.candidates[a.range.best];
            RangeFigures { worst: c.worst, s: c.s }
        })
        .collect();
    let mut summary =
        render_summary(designs, sensitivities, args.input.fs, latency, &shown, image.id(), "vf", Some(&range));
    for a in axes {
        summary.push_str(&crate::report::two_state::describe(axis_name(a.axis), &a.range));
    }
    let _ = writeln!(
        summary,
        "criterion: least worst-case predicted in-band error over s ∈ {{0, 0.25, 0.5, 0.75, 1}} (1/f² interpolated between the two FRFs' models) among designs for those states; `compensate --offline --drift START:END` follows the change with both states"
    );
    if let Some(dir) = &args.report {
        let extra = |axis: usize| -> Result<Vec<crate::report::design::Plot>> {
            let Some(rd) = axes.iter().find(|a| a.axis == axis).map(|a| &a.range) else { return Ok(Vec::new()) };
            let name = axis_name(axis);
            let (Some(first), Some(second)) = (frfs.before.axis(axis), frfs.after.axis(axis)) else {
                bail!("report: axis {name}: missing from one of the two FRFs")
            };
            let fits = crate::report::two_state::plot_frf_fits(&frfs.before.freq_hz, first, second, rd)
                .with_context(|| format!("report: axis {name}: FRF plot"))?;
            Ok(vec![
                (
                    format!("{name}_frf_fit.svg"),
                    format!("Axis {name}: both measured FRFs and the model at each state"),
                    crate::report::two_state::frf_fits_caption(rd),
                    fits,
                ),
                (
                    format!("{name}_range.svg"),
                    format!("Axis {name}: the box image over the range between the two states"),
                    crate::report::two_state::range_caption(rd),
                    crate::report::two_state::plot_range(name, rd)
                        .with_context(|| format!("report: axis {name}: range plot"))?,
                ),
            ])
        };
        crate::report::design::write_report_with(
            dir,
            &frfs.before,
            designs,
            sensitivities,
            args.input.fs,
            &summary,
            &extra,
        )?;
    }
    if !args.json {
        return Ok(summary);
    }
    let j = RangeJson {
        image: shown,
        image_id: format!("{:08x}", image.id()),
        fs_hz: args.input.fs,
        latency_samples: latency,
        criterion: "least worst-case predicted in-band error over the range states",
        range_states: RANGE_STATES,
        axes: axes
            .iter()
            .zip(sensitivities)
            .map(|(a, s)| RangeAxisJson::new(axis_name(a.axis), &a.range, s.clone()))
            .collect(),
    };
    Ok(format!("{}\n", serde_json::to_string_pretty(&j)?))
}
