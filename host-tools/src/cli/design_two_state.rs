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
use crate::design::two_state::range::{design_axes_over_range, RangeOutcome, RANGE_STATES};
use crate::frf::{axis_name, Frf};
use crate::io;
use crate::offline::sidecar::TwoStateJson;
use crate::report::summary::{render_summary, RangeFigures};
use crate::report::two_state::{describe, describe_held, HeldAxisJson, RangeAxisEntry, RangeAxisJson, RangeJson};

/// Run `design` with two FRFs; returns the summary (text or JSON) for stdout.
pub fn run(args: &DesignArgs) -> Result<String> {
    let latency = check_args(args)?;
    let frfs = TwoFrfs::read(args)?;
    let r = args.input.noise_variances(&frfs.before)?;
    let opts = args.base_options(latency);
    let axes = design_ranges(args, &frfs, &r, &opts)?;
    let designs: Vec<AxisDesign> = axes.iter().map(|a| a.design.clone()).collect();
    let image = build_image(&designs, args.input.fs as u32, latency, args.full_scale, frfs.sha)?;
    write_image_and_sidecar(args, &image, &axes)?;
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

/// One axis of a design from two FRFs, with what the sidecar keeps of it.
struct RangeAxis {
    axis: usize,
    /// The range design or the first FRF's design held over it; `None`
    /// for an axis passed through raw (its first FRF cannot be designed).
    outcome: Option<RangeOutcome>,
    /// The design the image carries.
    design: AxisDesign,
}

/// Every axis designed for the range between the two states. An axis whose
/// two states cannot be paired holds the first FRF's design, and one whose
/// first FRF cannot be designed is passed through raw, each with a loud
/// warning; `--strict` refuses the image instead, and so does a set-up
/// where no axis can be compensated.
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
    let compensated = results.iter().filter(|x| x.is_ok()).count();
    let mut axes = Vec::new();
    for (a, res) in f0.axes.iter().zip(results) {
        let name = axis_name(a.axis);
        let outcome = match res {
            Ok(o) => o,
            Err(e) if args.strict || compensated == 0 => {
                return Err(e.context(format!("{p0}: axis {name}: no image written")))
            }
            Err(e) => {
                let rv = r[a.axis].expect("R set for every FRF axis");
                let reason = format!("first FRF {p0}: {e:#}");
                let design = crate::design::pass_through::pass_through_warned(a, rv, opts, reason)?;
                axes.push(RangeAxis { axis: a.axis, outcome: None, design });
                continue;
            }
        };
        if let RangeOutcome::Held(h) = &outcome {
            if args.strict {
                bail!("{p0} / {p1}: axis {name}: no image written: {}", h.why);
            }
            eprintln!(
                "WARNING: axis {name} does NOT FOLLOW the change between the two FRFs: {}; the image and \
                 `compensate --offline --drift` hold the first FRF's design for it (--strict refuses the image instead)",
                h.why
            );
        }
        let design = outcome.chosen().clone();
        for p in &design.phase_limits {
            eprintln!("{}", crate::design::phase_limit::note(name, p, opts.lag, opts.fs_hz));
        }
        axes.push(RangeAxis { axis: a.axis, outcome: Some(outcome), design });
    }
    Ok(axes)
}

/// Write the image and its model sidecar, with both states of every axis
/// designed for the range (for `compensate --offline --drift`), and why any
/// other axis holds the first state.
fn write_image_and_sidecar(args: &DesignArgs, image: &CoeffImage, axes: &[RangeAxis]) -> Result<()> {
    let designs: Vec<AxisDesign> = axes.iter().map(|a| a.design.clone()).collect();
    let mut sidecar = crate::offline::sidecar::ModelSidecar::of_designs(image, &designs);
    for a in axes {
        let name = axis_name(a.axis);
        let Some(m) = sidecar.axes.iter_mut().find(|m| m.axis == name) else { continue };
        match &a.outcome {
            Some(RangeOutcome::Range(rd)) => {
                let first = &rd.candidates[0].design;
                let (dm0, _) =
                    first.discrete.as_ref().ok_or_else(|| anyhow::anyhow!("axis {name}: no discrete model"))?;
                m.two_state = Some(TwoStateJson::new(&rd.states, first.compensated_band_hz, dm0));
            }
            Some(RangeOutcome::Held(h)) => m.holds_first_state = Some(h.why.clone()),
            None => {}
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
        .map(|a| match &a.outcome {
            Some(RangeOutcome::Range(rd)) => {
                let c = &rd.candidates[rd.best];
                RangeFigures { worst: c.worst, s: c.s }
            }
            Some(RangeOutcome::Held(h)) => RangeFigures { worst: h.worst(), s: 0.0 },
            None => RangeFigures { worst: f64::NAN, s: 0.0 },
        })
        .collect();
    let mut summary =
        render_summary(designs, sensitivities, args.input.fs, latency, &shown, image.id(), "vf", Some(&range));
    for a in axes {
        match &a.outcome {
            Some(RangeOutcome::Range(rd)) => summary.push_str(&describe(axis_name(a.axis), rd)),
            Some(RangeOutcome::Held(h)) => summary.push_str(&describe_held(axis_name(a.axis), h)),
            None => {}
        }
    }
    let _ = writeln!(
        summary,
        "criterion: least worst-case predicted in-band error over s ∈ {{0, 0.25, 0.5, 0.75, 1}} (1/f² interpolated between the two FRFs' models) among designs for those states; `compensate --offline --drift START:END` follows the change with both states"
    );
    if let Some(dir) = &args.report {
        let extra = |axis: usize| -> Result<Vec<crate::report::design::Plot>> {
            let name = axis_name(axis);
            let (Some(first), Some(second)) = (frfs.before.axis(axis), frfs.after.axis(axis)) else {
                bail!("report: axis {name}: missing from one of the two FRFs")
            };
            let rd = match axes.iter().find(|a| a.axis == axis).and_then(|a| a.outcome.as_ref()) {
                Some(RangeOutcome::Range(rd)) => rd,
                Some(RangeOutcome::Held(h)) => {
                    return Ok(vec![(
                        format!("{name}_held.svg"),
                        format!("Axis {name}: NOT FOLLOWED, both measured FRFs against the first FRF's model"),
                        crate::report::two_state::held_frfs_caption(h),
                        crate::report::two_state::plot_held_frfs(&frfs.before.freq_hz, first, second, h)
                            .with_context(|| format!("report: axis {name}: held FRF plot"))?,
                    )])
                }
                None => return Ok(Vec::new()),
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
            .map(|(a, s)| {
                let name = axis_name(a.axis);
                match &a.outcome {
                    Some(RangeOutcome::Range(rd)) => RangeAxisEntry::Designed(RangeAxisJson::new(name, rd, s.clone())),
                    Some(RangeOutcome::Held(h)) => RangeAxisEntry::Held(HeldAxisJson::new(name, h, s.clone())),
                    None => RangeAxisEntry::PassedThrough {
                        axis: name,
                        reason: a.design.pass_through.clone().unwrap_or_default(),
                    },
                }
            })
            .collect(),
    };
    Ok(format!("{}\n", serde_json::to_string_pretty(&j)?))
}
