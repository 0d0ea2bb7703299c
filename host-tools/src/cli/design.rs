//! `dynocomp design`: FRF → per-axis design (with progress) → image and
//! model sidecar → summary (text or JSON) and optional report.
//! Two FRFs go to [`crate::cli::design_two_state`], `--parallel` to
//! [`crate::cli::design_parallel`].

use anyhow::{bail, Result};
use std::time::Instant;

use dynocomp_core::image::CoeffImage;

use crate::cli::design_args::{
    check_outputs_are_not_inputs, check_prior_flags, read_force_record, DesignArgs, DesignSetup, ForcePrior, Method,
};
use crate::cli::design_matrix::MatrixOutcome;
use crate::design::axis::AxisDesign;
use crate::design::image::build_image;
use crate::design::latency::{LatencyChoice, LONGEST_LATENCY};
use crate::design::progress::Progress;
use crate::design::versus_default::VersusDefault;
use crate::frf::axis_name;
use crate::offline::force_prior::{AxisPrior, PriorOptions};
use crate::offline::smoother::build_priors;
use crate::realize::load::LoadReport;
use crate::report::summary::{prior_line, render_summary, spectrum_line, AxisJson, DesignJson};

/// Run `dynocomp design`: the summary (text or JSON) on stdout.
pub fn run(args: &DesignArgs) -> Result<()> {
    print!("{}", design(args)?);
    Ok(())
}

/// Everything `dynocomp design` does (image, sidecar, report; progress on
/// stderr) except printing: returns the summary, text or with `--json` the
/// JSON document, that it prints on stdout. Other front ends (the Python
/// package) call this with the same arguments.
pub fn design(args: &DesignArgs) -> Result<String> {
    check_prior_flags(args)?;
    check_outputs_are_not_inputs(args)?;
    match args.input.frf.len() {
        1 => {}
        2 => return crate::cli::design_two_state::run(args),
        n => bail!("--frf given {n} times: give one FRF, or two (before and after) for a set-up in two states"),
    }
    let t0 = Instant::now();
    let setup = DesignSetup::new(args)?;
    let mut crosstalk = String::new();
    let matrix = crate::cli::design_matrix::wanted(args, &setup.frf)?;
    if args.full_order && !matrix {
        eprintln!("note: --full-order applies to the 3x3 design only; this design is per axis");
    }
    if args.free_residues && !matrix {
        eprintln!("note: --free-residues applies to the 3x3 design only; this design is per axis");
    }
    if matrix {
        match crate::cli::design_matrix::run(args, &setup, t0)? {
            MatrixOutcome::Written(summary) => return Ok(summary),
            MatrixOutcome::PerAxis(lines) => {
                eprint!("{lines}");
                crosstalk = lines;
            }
        }
    }
    if args.parallel {
        return crate::cli::design_parallel::run(args, &setup);
    }
    let designed = design_axes(args, &setup)?;
    // The prior is built and checked before anything is written.
    let priors = harmonic_priors(args, &designed.designs, &setup.r)?;
    let (image, box_load) = image_within_load(args, &setup, &designed)?;
    write_image_and_sidecar(args, &image, &designed.designs, &priors)?;
    let summary = render(args, &setup, &designed, &priors, &image, box_load, t0)?;
    Ok(if args.json { summary } else { summary + &crosstalk })
}

/// Every axis designed, in axis order.
struct Designed {
    designs: Vec<AxisDesign>,
    /// Design time of each axis (s).
    times: Vec<f64>,
    /// How the latency was chosen (`None`: given).
    latency_choice: Option<LatencyChoice>,
    /// The declared latency (samples).
    latency: usize,
    /// Band-fitted or paper-method axes beside the default design, and
    /// whether the default replaced them.
    versus: Vec<(VersusDefault, bool)>,
}

/// Design the axes on parallel threads (the box has three, the host at
/// least two cores), choosing the latency where it is not given.
fn design_axes(args: &DesignArgs, s: &DesignSetup) -> Result<Designed> {
    let frf = &s.frf;
    eprintln!("designing {} axes ({} lines each)…", frf.axes.len(), frf.freq_hz.len());
    let rv: Vec<f64> = frf.axes.iter().map(|a| s.r[a.axis].expect("R set for every FRF axis")).collect();
    let progress = Progress::stderr();
    let (results, mut latency_choice) = if s.auto_latency {
        let (d, c) = crate::design::latency::design_axes_choosing_latency(
            &frf.freq_hz,
            &frf.axes,
            &rv,
            &s.opts,
            Some(s.limit_permille),
            &progress,
        );
        (d, Some(c))
    } else {
        (crate::design::latency::design_axes_reporting(&frf.freq_hz, &frf.axes, &rv, &s.opts, &progress), None)
    };
    let latency = latency_choice.as_ref().map_or(s.latency, |c| c.chosen);
    let mut designs = Vec::new();
    let mut times = Vec::new();
    let compensated = results.iter().filter(|r| r.0.is_ok()).count();
    for ((a, (d, dt)), r) in frf.axes.iter().zip(results).zip(&rv) {
        let d = match d {
            Ok(d) => d,
            // No axis compensated: nothing worth an image. The explicit
            // methods and priors keep their refusals (their messages say what
            // to drop), and so does `--strict`.
            Err(e) if args.strict || compensated == 0 || !default_design(args, s) => {
                let e = beyond_the_chosen_latencies(e, s);
                return Err(e.context(format!("{}: no image written", args.input.frf().display())));
            }
            Err(e) => {
                let e = beyond_the_chosen_latencies(e, s);
                let opts = crate::design::axis::DesignOptions { lag: latency, ..s.opts.clone() };
                crate::design::pass_through::pass_through_warned(a, *r, &opts, format!("{e:#}"))?
            }
        };
        if d.pass_through.is_none() {
            eprintln!(
                "  axis {}: order {}, q {:.3e}, {:.0} ms",
                axis_name(a.axis),
                d.model.order(),
                d.kalman.q,
                dt * 1e3
            );
        }
        for p in &d.phase_limits {
            eprintln!("{}", crate::design::phase_limit::note(axis_name(a.axis), p, latency, s.opts.fs_hz));
        }
        times.push(dt);
        designs.push(d);
    }
    let versus = against_default(args, s, &mut designs, latency, &rv);
    if let Some(c) = latency_choice.as_mut() {
        let replaced: Vec<usize> = designs
            .iter()
            .filter(|d| versus.iter().any(|(v, replaced)| *replaced && v.axis == axis_name(d.axis)))
            .map(|d| d.axis)
            .collect();
        crate::design::look_ahead::retain_current(&mut c.look_ahead, &replaced);
    }
    Ok(Designed { designs, times, latency_choice, latency, versus })
}

/// Whether this is the default design (vector fitting on the whole band,
/// no force prior): the only one whose failed axes are passed through raw
/// ([`crate::design::pass_through`]).
fn default_design(args: &DesignArgs, s: &DesignSetup) -> bool {
    args.method == Method::Vf && s.bands.is_empty() && args.prior.force_prior == ForcePrior::Default
}

/// A band-fitted or paper-method design beside the default design of the
/// same FRF ([`crate::design::versus_default`]), at the image's latency
/// (band-fitted) or the default latency (paper method, latency 0).
/// Where the default predicts less error, a band-fitted axis is replaced by
/// it (the image then says so); a paper-method axis is kept (the method
/// exists to reproduce the paper) with a warning naming the better command.
/// Returns each axis's comparison and whether it was replaced; empty for
/// the default design.
fn against_default(
    args: &DesignArgs,
    s: &DesignSetup,
    designs: &mut [AxisDesign],
    latency: usize,
    rv: &[f64],
) -> Vec<(VersusDefault, bool)> {
    let paper = args.method == Method::Paper;
    if s.bands.is_empty() && !paper {
        return Vec::new();
    }
    let opts = crate::design::axis::DesignOptions {
        method: crate::design::axis::FitMethod::Vf,
        bands: Vec::new(),
        paper_orders_auto: false,
        // The paper's filter has no lag; the default command it is judged
        // against has the default latency (a paper axis is only warned about).
        lag: if paper { crate::design::latency::DEFAULT_LATENCY } else { latency },
        ..s.opts.clone()
    };
    let frf = &s.frf;
    crate::design::progress::Progress::stderr().say(&format!(
        "designing the default method (vf, whole band, latency {}) on the same FRF, to compare…",
        opts.lag
    ));
    let defaults = crate::design::latency::design_axes(&frf.freq_hz, &frf.axes, rv, &opts);
    let mut out = Vec::new();
    for (d, (def, _)) in designs.iter_mut().zip(defaults) {
        let Ok(def) = def else {
            // No default design to prefer: the asked-for one stands.
            continue;
        };
        let oob = s.opts.above_band.out_of_band_weight();
        let v = crate::design::versus_default::compare(d, &def, s.opts.force_rms, args.input.fs, oob);
        let replace = v.default_better && !paper;
        if replace {
            *d = def;
        }
        out.push((v, replace));
    }
    out
}

/// The harmonic force prior of each axis (`--force-prior harmonics`), or none.
fn harmonic_priors(args: &DesignArgs, designs: &[AxisDesign], r: &[Option<f64>; 3]) -> Result<Vec<Option<AxisPrior>>> {
    if args.prior.force_prior != ForcePrior::Harmonics {
        return Ok(designs.iter().map(|_| None).collect());
    }
    let path = args.prior.force_record.as_ref().expect("checked by check_prior_flags");
    let rec = read_force_record(path, args.input.fs, args.input.max_force)?;
    let opts = PriorOptions {
        spindle_rpm: args.bands.spindle_rpm.expect("checked"),
        teeth: args.bands.teeth.expect("checked"),
        line_width_hz: args.prior.line_width,
        unchecked: false,
    };
    build_priors(&opts, &rec, &path.display().to_string(), designs, r)
}

/// The image of the designs, marked offline-only (loudly) when the box could
/// not run it within its load limit.
fn image_within_load(args: &DesignArgs, s: &DesignSetup, d: &Designed) -> Result<(CoeffImage, LoadReport)> {
    let mut image = build_image(&d.designs, args.input.fs as u32, d.latency, args.full_scale, s.sha)?;
    let box_load = crate::realize::load::report(&image, s.limit_permille);
    if !box_load.fits {
        image.flags |= dynocomp_core::image::FLAG_OFFLINE_ONLY;
        eprintln!("{}", crate::realize::load::offline_only_warning(&box_load, image.fs_hz));
    }
    Ok((image, box_load))
}

/// Write the image and, for the default method, the model sidecar of
/// `compensate --offline` ([`crate::offline::sidecar`]).
fn write_image_and_sidecar(
    args: &DesignArgs,
    image: &CoeffImage,
    designs: &[AxisDesign],
    priors: &[Option<AxisPrior>],
) -> Result<()> {
    if args.method == Method::Paper {
        return crate::offline::sidecar::write_image_and_sidecar(&args.out, image, None);
    }
    let mut sidecar = crate::offline::sidecar::ModelSidecar::of_designs(image, designs);
    let record = args.prior.force_record.as_ref().map(|p| p.display().to_string()).unwrap_or_default();
    for ((m, p), d) in sidecar.axes.iter_mut().zip(priors).zip(designs) {
        m.force_prior = p.as_ref().map(|p| p.prior.clone());
        // A flat spectrum at the record's level is as safe as the default:
        // no note for `compensate`.
        m.force_spectrum = d.force_spectrum.as_ref().filter(|s| !s.level_only).map(|s| s.provenance(record.clone()));
    }
    crate::offline::sidecar::write_image_and_sidecar(&args.out, image, Some(&sidecar))
}

/// The summary (text or JSON) and the report.
fn render(
    args: &DesignArgs,
    s: &DesignSetup,
    d: &Designed,
    priors: &[Option<AxisPrior>],
    image: &CoeffImage,
    box_load: LoadReport,
    t0: Instant,
) -> Result<String> {
    let mut sensitivities = crate::design::sensitivity::predict_all(&d.designs, &s.opts);
    crate::design::sensitivity::set_line_spacing(&mut sensitivities, &s.frf.freq_hz);
    let summary = summary_text(args, d, priors, image, &box_load, &sensitivities);
    if let Some(dir) = &args.report {
        let fs = args.input.fs;
        let look_ahead = d.latency_choice.as_ref().map_or(&[][..], |c| c.look_ahead.as_slice());
        let extra = |axis: usize| -> Result<Vec<crate::report::design::Plot>> {
            look_ahead
                .iter()
                .filter(|l| l.axis == axis)
                .map(|l| {
                    let name = axis_name(axis);
                    Ok((
                        format!("{name}_look_ahead.svg"),
                        format!("Axis {name}: what a longer look-ahead would reach"),
                        crate::report::look_ahead::plot_caption(l, fs),
                        crate::report::look_ahead::plot(l, fs)?,
                    ))
                })
                .collect()
        };
        let files =
            crate::report::design::write_report_with(dir, &s.frf, &d.designs, &sensitivities, fs, &summary, &extra)?;
        eprintln!("report: {} files in {} (open index.html)", files.len(), dir.display());
    }
    if !args.json {
        eprintln!("designed in {:.0} ms", t0.elapsed().as_secs_f64() * 1e3);
        return Ok(summary);
    }
    let axes = (0..d.designs.len())
        .map(|i| AxisJson::new(&d.designs[i], d.times[i], priors[i].as_ref(), &sensitivities[i]))
        .collect();
    let j = design_json(args, s, d, image, box_load, axes, t0);
    Ok(format!("{}\n", serde_json::to_string_pretty(&j)?))
}

/// The text summary: the table of the axes ([`render_summary`]), how the
/// latency was chosen, the force prior and spectrum of each axis, each axis
/// against the default design, and the box's load.
fn summary_text(
    args: &DesignArgs,
    d: &Designed,
    priors: &[Option<AxisPrior>],
    image: &CoeffImage,
    box_load: &LoadReport,
    sensitivities: &[Option<crate::design::sensitivity::Sensitivity>],
) -> String {
    let designs = &d.designs;
    let out = args.out.display().to_string();
    let mut summary =
        render_summary(designs, sensitivities, args.input.fs, d.latency, &out, image.id(), args.method.name(), None);
    if let Some(c) = &d.latency_choice {
        let names: Vec<&str> = designs.iter().map(|d| axis_name(d.axis)).collect();
        summary.push_str(&crate::design::latency::describe(c, &names));
        summary.push('\n');
        for l in &c.look_ahead {
            summary.push_str(&crate::design::look_ahead::note(l, args.input.fs));
            summary.push('\n');
        }
    }
    for (d, p) in designs.iter().zip(priors) {
        if let Some(p) = p {
            summary.push_str(&prior_line(d.axis, p));
        }
        if let Some(s) = &d.force_spectrum {
            summary.push_str(&spectrum_line(d.axis, s, args.input.force_rms));
        }
    }
    summary.push_str(&versus_lines(args, d));
    let shapes: Vec<_> = designs.iter().map(|d| (axis_name(d.axis), d.kalman.force_shape)).collect();
    summary.push_str(&crate::design::above_band::describe(&shapes));
    summary.push_str(&crate::realize::load::describe(box_load, image.fs_hz));
    summary.push_str(if box_load.fits { "\n" } else { "  OVER THE LIMIT: offline-only image\n" });
    summary
}

/// Each axis against the default design; the lines where the default is
/// better also go to stderr at once.
fn versus_lines(args: &DesignArgs, d: &Designed) -> String {
    let better = if args.method == Method::Paper {
        "the default method is better: drop --method paper"
    } else {
        "the design without fitting bands: drop --spindle-rpm/--teeth, --band and --bands-from"
    };
    let mut lines = String::new();
    for (v, replaced) in &d.versus {
        let line = crate::design::versus_default::describe(v, *replaced, better);
        if v.default_better {
            eprint!("{line}");
        }
        lines.push_str(&line);
    }
    lines
}

/// The `--json` document of the design with the summaries `axes` of its axes.
fn design_json(
    args: &DesignArgs,
    s: &DesignSetup,
    d: &Designed,
    image: &CoeffImage,
    box_load: LoadReport,
    axes: Vec<AxisJson>,
    t0: Instant,
) -> DesignJson {
    DesignJson {
        image: args.out.display().to_string(),
        image_id: format!("{:08x}", image.id()),
        fs_hz: args.input.fs,
        latency_samples: d.latency,
        method: args.method.name(),
        bands: s.bands.clone(),
        design_time_s: t0.elapsed().as_secs_f64(),
        offline_only: image.is_offline_only(),
        latency_choice: d.latency_choice.clone(),
        versus_default: d
            .versus
            .iter()
            .map(|(v, replaced)| crate::report::summary::VersusDefaultJson {
                comparison: v.clone(),
                replaced_by_default: *replaced,
            })
            .collect(),
        box_load,
        axes,
    }
}

/// An axis's refusal at a declared latency above the longest the design
/// chooses by itself ([`LONGEST_LATENCY`]), where its compensator does not
/// verify in f32 (a longer smoother lag has more states to round): the
/// error with what to do instead.
fn beyond_the_chosen_latencies(e: anyhow::Error, s: &DesignSetup) -> anyhow::Error {
    let longest = LONGEST_LATENCY;
    if s.auto_latency || s.latency <= longest || !format!("{e:#}").contains("quantization") {
        return e;
    }
    e.context(format!(
        "--latency {}: above the {longest} samples the design chooses by itself, this axis's compensator does not \
         verify in f32; omit --latency or give {longest} or less",
        s.latency
    ))
}
