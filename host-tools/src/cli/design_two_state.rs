//! `dynocomp design --frf BEFORE --frf AFTER` (issue #15, item 2): a set-up
//! measured in two states. Per axis the two fitted models are paired and
//! interpolated ([`crate::design::two_state`]), the machine-structure modes both
//! FRFs measured alike shared ([`crate::design::two_state::range::share_machine_modes`]),
//! the sensor modes above the compensated band fitted to both FRFs at once
//! ([`crate::design::two_state::joint`]);
//! the box image is the candidate with
//! the least worst-case predicted error over the range
//! ([`crate::design::two_state::range::design_over_range`], candidates at s = 0, ¼, ½, ¾, 1);
//! the model sidecar keeps both states for `compensate --offline --drift`.
//! Default method only, without fitting bands or parallel elaboration.

use anyhow::{bail, Context, Result};
use sha2::{Digest, Sha256};
use std::fmt::Write as _;

use crate::cli::design_args::{DesignArgs, Method};
use crate::report::summary::render_summary;
use crate::design::image::build_image;
use crate::frf::axis_name;
use crate::io;
use crate::offline::sidecar::TwoStateJson;
use crate::design::two_state::range::{design_over_range, RANGE_STATES};

/// Run `design` with two FRFs.
pub fn run(args: &DesignArgs) -> Result<()> {
    if args.method != Method::Vf || args.parallel || args.bands.spindle_rpm.is_some() || !args.bands.band.is_empty() || args.bands.bands_from.is_some() {
        bail!("--frf given twice (a set-up in two states): only the default method, without fitting bands or --parallel");
    }
    let latency = args.latency.unwrap_or(crate::design::latency::DEFAULT_LATENCY);
    if latency > 16 {
        bail!("--latency {latency}: at most 16 samples");
    }
    args.input.check_fs()?;
    let (p0, p1) = (&args.input.frf[0], &args.input.frf[1]);
    let b0 = std::fs::read(p0).with_context(|| format!("{}: cannot read", p0.display()))?;
    let b1 = std::fs::read(p1).with_context(|| format!("{}: cannot read", p1.display()))?;
    let f0 = io::parse_frf(p0, &b0)?;
    let f1 = io::parse_frf(p1, &b1)?;
    if f0.freq_hz != f1.freq_hz || f0.axes.iter().map(|a| a.axis).ne(f1.axes.iter().map(|a| a.axis)) {
        bail!("{}: the second FRF must have the same frequency lines and axes as the first ({})", p1.display(), p0.display());
    }
    let sha: [u8; 32] = Sha256::digest([b0, b1].concat()).into();
    let r = args.input.noise_variances(&f0)?;
    let opts = args.base_options(latency);
    eprintln!("designing {} axes for the range between two states ({} candidates each)…", f0.axes.len(), RANGE_STATES.len());
    let results: Vec<_> = std::thread::scope(|scope| {
        let handles: Vec<_> = f0
            .axes
            .iter()
            .zip(&f1.axes)
            .map(|(a0, a1)| {
                let (opts, freq) = (&opts, &f0.freq_hz);
                let rv = r[a0.axis].expect("R set for every FRF axis");
                scope.spawn(move || design_over_range(freq, a0, a1, rv, opts, &RANGE_STATES))
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap_or_else(|p| std::panic::resume_unwind(p))).collect()
    });
    let mut designs = Vec::new();
    let mut entries = Vec::new();
    let mut axes_json = Vec::new();
    let mut lines = String::new();
    let mut ranges = Vec::new();
    for (a, res) in f0.axes.iter().zip(results) {
        let name = axis_name(a.axis);
        let rd = res.with_context(|| format!("{} / {}: axis {name}", p0.display(), p1.display()))?;
        let (ts, cands, best) = (&rd.states, &rd.candidates, rd.best);
        let c = &cands[best];
        let (first, last) = (&cands[0], &cands[cands.len() - 1]);
        let moved: Vec<String> =
            ts.before.modes().iter().zip(ts.after.modes()).map(|(m0, m1)| format!("{:.0}→{:.0}", m0.0, m1.0)).collect();
        let _ = writeln!(
            lines,
            "{name} two states: modes paired {} Hz; image for the range designed at s = {:.2}: worst-case predicted error {:.2} % over s ∈ [0, 1] (designs for the first / second FRF alone: {:.2} / {:.2} %)",
            moved.join(", "),
            c.s,
            100.0 * c.worst,
            100.0 * first.worst,
            100.0 * last.worst
        );
        let shared = crate::report::two_state::shared_modes_hz(&rd);
        let apart: Vec<String> = rd
            .machine
            .iter()
            .filter(|m| !m.shared)
            .map(|m| format!("{:.0}→{:.0} Hz (misfit ×{:.1} / ×{:.1} if shared)", m.fn_hz.0, m.fn_hz.1, m.misfit_growth.0, m.misfit_growth.1))
            .collect();
        if !rd.machine.is_empty() {
            let _ = writeln!(
                lines,
                "{name} machine modes measured alike in both FRFs, averaged: {} Hz; kept apart: {}",
                if shared.is_empty() { "none".to_string() } else { shared.join(", ") },
                if apart.is_empty() { "none".to_string() } else { apart.join(", ") }
            );
        }
        if let Some(m0) = rd.above_band.first() {
            let modes: Vec<String> = rd
                .above_band
                .iter()
                .map(|m| if m.joint {
                    format!("{:.0}→{:.0} Hz (separately {:.0}→{:.0} Hz)", m.joint_fn_hz.0, m.joint_fn_hz.1, m.fn_hz.0, m.fn_hz.1)
                } else {
                    format!("{:.0}→{:.0} Hz", m.fn_hz.0, m.fn_hz.1)
                })
                .collect();
            let growth = 100.0 * (m0.misfit_growth - 1.0);
            let how = if m0.joint {
                format!("fitted to both FRFs at once, modal shares and direct term common (misfit {growth:+.2} %)")
            } else {
                format!("each FRF's own fit kept: fitted at once with a common static gain the misfit grows {growth:+.1} %, more than {:.0} %", 100.0 * crate::design::two_state::joint::JOINT_TOLERANCE)
            };
            let _ = writeln!(lines, "{name} sensor modes above the compensated band {how}: {}", modes.join(", "));
        }
        let dm0 = first.design.discrete.as_ref().map(|x| x.0.clone()).ok_or_else(|| anyhow::anyhow!("axis {name}: no discrete model"))?;
        entries.push((a.axis, TwoStateJson::new(ts, first.design.compensated_band_hz, &dm0)));
        axes_json.push(RangeAxisJson {
            axis: name,
            modes_before: ts.before.modes(),
            modes_after: ts.after.modes(),
            machine_modes: rd.machine.clone(),
            above_band_modes: rd.above_band.clone(),
            chosen_state: c.s,
            worst_case_error: c.worst,
            single_state_worst_case: (first.worst, last.worst),
            candidates: cands.iter().map(|c| (c.s, c.worst, c.errors.clone())).collect(),
            predicted_error: c.design.predicted_error,
            sensitivity: crate::design::sensitivity::predict(&c.design, &opts),
        });
        designs.push(c.design.clone());
        ranges.push((a.axis, rd));
    }
    let image = build_image(&designs, args.input.fs as u32, latency, args.full_scale, sha)?;
    io::image_file::write_image(&args.out, &image)?;
    let models: Vec<_> = designs.iter().map(|d| (d.axis, &d.model, d.discrete.as_ref().map(|x| &x.0))).collect();
    let mut sidecar = crate::offline::sidecar::ModelSidecar::new(&image, &models);
    for (axis, e) in entries {
        if let Some(m) = sidecar.axes.iter_mut().find(|m| m.axis == axis_name(axis)) {
            m.two_state = Some(e);
        }
    }
    crate::offline::sidecar::write_sidecar(&args.out, &sidecar)?;
    let sensitivities = crate::design::sensitivity::predict_all(&designs, &opts);
    let mut summary = render_summary(&designs, &sensitivities, args.input.fs, latency, &args.out.display().to_string(), image.id(), "vf");
    summary.push_str(&lines);
    let _ = writeln!(
        summary,
        "criterion: least worst-case predicted in-band error over s ∈ {{0, 0.25, 0.5, 0.75, 1}} (1/f² interpolated between the two FRFs' models) among designs for those states; `compensate --offline --drift START:END` follows the change with both states"
    );
    if let Some(dir) = &args.report {
        let extra = |axis: usize| -> Result<Vec<crate::report::design::Plot>> {
            let Some(rd) = ranges.iter().find(|(a, _)| *a == axis).map(|(_, rd)| rd) else { return Ok(Vec::new()) };
            let name = axis_name(axis);
            Ok(vec![(
                format!("{name}_range.svg"),
                format!("Axis {name}: the box image over the range between the two states"),
                crate::report::two_state::range_caption(rd),
                crate::report::two_state::plot_range(name, rd).with_context(|| format!("report: axis {name}: range plot"))?,
            )])
        };
        crate::report::design::write_report_with(dir, &f0, &designs, &sensitivities, args.input.fs, &summary, &extra)?;
    }
    if args.json {
        let j = RangeJson {
            image: args.out.display().to_string(),
            image_id: format!("{:08x}", image.id()),
            fs_hz: args.input.fs,
            latency_samples: latency,
            criterion: "least worst-case predicted in-band error over the range states",
            range_states: RANGE_STATES,
            axes: axes_json,
        };
        println!("{}", serde_json::to_string_pretty(&j)?);
    } else {
        print!("{summary}");
    }
    Ok(())
}

/// `--json` of a two-state design.
#[derive(serde::Serialize)]
struct RangeJson {
    image: String,
    image_id: String,
    fs_hz: f64,
    latency_samples: usize,
    criterion: &'static str,
    range_states: [f64; 5],
    axes: Vec<RangeAxisJson>,
}

/// One axis of [`RangeJson`].
#[derive(serde::Serialize)]
struct RangeAxisJson {
    axis: &'static str,
    /// (Hz, ζ) of the paired modes in each state.
    modes_before: Vec<(f64, f64)>,
    modes_after: Vec<(f64, f64)>,
    /// Machine-structure modes: shared between the states or kept apart.
    machine_modes: Vec<crate::design::two_state::range::MachineMode>,
    /// Sensor modes above the compensated band: fitted to both FRFs at once
    /// or each FRF's own fit kept.
    above_band_modes: Vec<crate::design::two_state::joint::AboveBandMode>,
    /// Model state the image was designed for.
    chosen_state: f64,
    /// Its worst-case predicted in-band error over the range.
    worst_case_error: f64,
    /// The same for the designs from the first and the second FRF alone.
    single_state_worst_case: (f64, f64),
    /// (state, worst case, error at each range state) of every candidate.
    candidates: Vec<(f64, f64, Vec<f64>)>,
    /// The image's predicted error at its own state.
    predicted_error: f64,
    /// Its sensitivity to shifted sensor modes.
    sensitivity: Option<crate::design::sensitivity::Sensitivity>,
}
