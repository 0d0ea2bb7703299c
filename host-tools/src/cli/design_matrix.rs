//! `dynocomp design` on a complete FRF matrix: the 3x3 design
//! ([`crate::design::mimo`], its filter reduced to the box's load limit
//! unless `--full-order`) → a 3x3 image (format 3), marked offline-only
//! over the load limit → summary (text or JSON) with the crosstalk, each
//! axis's choice of row and the reduction (README "Crosstalk").

use anyhow::{bail, Result};
use serde::Serialize;
use std::fmt::Write as _;
use std::time::Instant;

use crate::cli::design_args::{DesignArgs, DesignSetup, ForcePrior, Method};
use crate::design::mimo::image::build_matrix_image;
use crate::design::mimo::{
    design_matrix, MatrixDesign, MatrixOptions, MatrixSummary, Progress, RowSource, OFFLINE_FLAT_CAVEAT,
};
use crate::frf::{axis_name, Frf};
use crate::realize::load::LoadReport;
use crate::realize::mimo::NotVerified;

/// Whether `design` takes the 3x3 route for `frf`: a complete matrix and no
/// `--per-axis`. Options the 3x3 design cannot take are refused here, by
/// name, rather than silently designed per axis; an incomplete matrix is
/// designed per axis with a note saying which entries are missing.
pub fn wanted(args: &DesignArgs, frf: &Frf) -> Result<bool> {
    if !frf.has_cross() {
        return Ok(false);
    }
    let status = frf.matrix_status();
    if args.per_axis {
        eprintln!("note: --per-axis: the cross FRFs are not used; crosstalk is not compensated");
        return Ok(false);
    }
    if !status.is_complete() {
        eprintln!("note: {}", status.message().unwrap_or_default());
        return Ok(false);
    }
    let refuse = |what: &str| -> Result<bool> {
        bail!(
            "{what} is not available with the 3x3 design (the FRF file holds all nine entries); \
             add --per-axis to design each axis from its direct FRF, crosstalk not compensated"
        )
    };
    if args.parallel {
        return refuse("--parallel");
    }
    if args.method == Method::Paper {
        return refuse("--method paper");
    }
    // Before the bands: harmonics come with --spindle-rpm and --teeth.
    if args.prior.force_prior == ForcePrior::Harmonics {
        return refuse("--force-prior harmonics");
    }
    if args.bands.spindle_rpm.is_some() || !args.bands.band.is_empty() || args.bands.bands_from.is_some() {
        return refuse("a fitting band (--spindle-rpm/--teeth, --band, --bands-from)");
    }
    Ok(true)
}

/// What the 3x3 route did.
pub enum MatrixOutcome {
    /// A 3x3 image was written; the summary (text or JSON) `design` prints.
    Written(String),
    /// Every output row is better per axis: nothing was written, and the
    /// per-axis design goes on (its image is format 1, which every command
    /// takes). The lines say so, with the crosstalk and the predictions
    /// that count it.
    PerAxis(String),
}

/// Run the 3x3 design and write its image, unless every row is better per
/// axis ([`MatrixOutcome`]).
pub fn run(args: &DesignArgs, s: &DesignSetup, t0: Instant) -> Result<MatrixOutcome> {
    let r: [f64; 3] = std::array::from_fn(|i| s.r[i].expect("R set for every axis of a complete matrix"));
    let progress = Progress::stderr();
    let opts = MatrixOptions {
        design: s.opts.clone(),
        latency: args.latency,
        progress: Some(progress),
        load_limit_permille: (!args.full_order).then_some(s.limit_permille),
        ..Default::default()
    };
    eprintln!(
        "designing the 3x3 compensator ({} lines, nine FRFs; 10-60 s on two cores, each step below; \
         --per-axis: the direct FRFs alone, crosstalk not compensated, in under a second)…",
        s.frf.freq_hz.len()
    );
    let md = match design_matrix(&s.frf, r, &opts) {
        Ok(md) => md,
        Err(e) if e.downcast_ref::<NotVerified>().is_some() => {
            return Ok(MatrixOutcome::PerAxis(format!(
                "note: {e:#}\nno axis uses the 3x3 design: the per-axis image (format 1) is written, crosstalk not \
                 compensated\n"
            )));
        }
        Err(e) => return Err(e),
    };
    if md.rows.iter().all(|r| *r == RowSource::PerAxis) {
        let mut t = crosstalk_and_predictions(&md.summary);
        for n in &md.summary.notes {
            let _ = writeln!(t, "note: {n}");
        }
        let _ = writeln!(
            t,
            "no axis uses the 3x3 design: the per-axis image (format 1) is written, crosstalk not compensated; \
             the predictions above count the crosstalk it leaves"
        );
        return Ok(MatrixOutcome::PerAxis(t));
    }
    let mut image = build_matrix_image(&md, &s.frf, args.full_scale, s.sha)?;
    let load = crate::realize::load::report(&image, s.limit_permille);
    if !load.fits {
        image.flags |= dynocomp_core::image::FLAG_OFFLINE_ONLY;
        eprintln!("{}", crate::realize::load::offline_only_warning(&load, image.fs_hz));
        eprintln!("{}", for_the_box(&md.summary, load.max_fs_hz));
    }
    let sidecar = crate::offline::matrix_smoother::matrix_sidecar(&image, &md);
    crate::offline::sidecar::write_matrix_image_and_sidecar(&args.out, &image, &sidecar)?;
    let id = image.id();
    let text = summary_text(args, &md, id, &load, image.fs_hz);
    for w in &md.summary.worse_than_raw {
        eprintln!("{}", crate::design::mimo::worse_than_raw::warning(w));
    }
    if let Some(dir) = &args.report {
        let files = crate::report::matrix::write_matrix_report(dir, &md, &s.frf, args.input.fs, &text)?;
        eprintln!("report: {} files in {} (open index.html)", files.len(), dir.display());
    }
    if !args.json {
        eprintln!("designed in {:.1} s", t0.elapsed().as_secs_f64());
        return Ok(MatrixOutcome::Written(text));
    }
    let j = MatrixJson {
        kind: "3x3",
        image: args.out.display().to_string(),
        image_id: format!("{id:08x}"),
        fs_hz: args.input.fs,
        latency_samples: md.summary.latency,
        design_time_s: t0.elapsed().as_secs_f64(),
        offline_only: image.flags & dynocomp_core::image::FLAG_OFFLINE_ONLY != 0,
        box_load: load,
        design: &md.summary,
    };
    Ok(MatrixOutcome::Written(serde_json::to_string_pretty(&j)? + "\n"))
}

/// What to do for an image the box can run when the 3x3 image is over its
/// load limit: `--per-axis`, with what each axis loses by it (the
/// predictions that count the crosstalk).
fn for_the_box(s: &MatrixSummary, max_fs_hz: u32) -> String {
    let cells: Vec<String> = s
        .axes
        .iter()
        .map(|a| format!("{} {} against {}", a.axis, pct(a.per_axis.map(|p| p.error)), pct(Some(a.chosen.error))))
        .collect();
    format!(
        "for an image the box can run, design with --per-axis (crosstalk not compensated; predicted in-band error, \
         crosstalk counted, per axis against this image: {}), or record at up to {max_fs_hz} Hz, where the box runs a \
         3x3 filter of this size",
        cells.join(", ")
    )
}

/// `design --json` of a 3x3 design.
#[derive(Serialize)]
struct MatrixJson<'a> {
    /// `"3x3"`.
    kind: &'static str,
    image: String,
    image_id: String,
    fs_hz: f64,
    latency_samples: usize,
    design_time_s: f64,
    offline_only: bool,
    box_load: LoadReport,
    /// Every figure of the design: fit, crosstalk, per-axis predictions and
    /// choice of row, Kalman and realization figures, notes.
    design: &'a MatrixSummary,
}

/// Percent with three significant digits, or "-" for a missing figure.
fn pct(v: Option<f64>) -> String {
    match v {
        Some(v) if v.is_finite() => format!("{:.3} %", 100.0 * v),
        _ => "-".to_string(),
    }
}

/// The text summary of a 3x3 design.
fn summary_text(args: &DesignArgs, md: &MatrixDesign, id: u32, load: &LoadReport, fs_hz: u32) -> String {
    let s = &md.summary;
    let mut t = String::new();
    let _ = writeln!(
        t,
        "3x3 design at {} Hz, latency {} samples -> {} (image {id:08x}, format 3)",
        args.input.fs,
        s.latency,
        args.out.display()
    );
    if let Some(f) = &s.fit {
        let rows: Vec<String> =
            (0..3).map(|i| format!("{}{} {}", axis_name(i), axis_name(i), pct(Some(f.entry_error[i][i])))).collect();
        let _ = writeln!(
            t,
            "matrix fit: order {} ({} modes, common to all nine FRFs; {} of them one mode shape each, rank one); \
             relative RMS error of the direct FRFs: {}",
            f.order,
            f.modes.len(),
            f.rank_one_pairs,
            rows.join(", ")
        );
        if !f.seeded_hz.is_empty() {
            let hz: Vec<String> = f.seeded_hz.iter().map(|f| format!("{f:.0}")).collect();
            let _ = writeln!(
                t,
                "  pole pairs added near {} Hz, where the fit left more than the impact test's noise (BIC); \
                 more impacts per direction would confirm a weak mode there",
                hz.join(", ")
            );
        }
        if !f.dropped_hz.is_empty() {
            let hz: Vec<String> = f.dropped_hz.iter().map(|f| format!("{f:.0}")).collect();
            let _ = writeln!(
                t,
                "  pole pairs at {} Hz dropped from the fit: the nine FRFs' lines do not support them (BIC)",
                hz.join(", ")
            );
        }
    }
    t.push_str(&crosstalk_and_predictions(s));
    if let Some(k) = &s.kalman {
        let _ = writeln!(
            t,
            "3x3 Kalman: {} states, q = {:.3e} / {:.3e} / {:.3e} N²/sample, DARE residual {:.1e}, spectral radius {:.4}",
            k.order, k.q[0], k.q[1], k.q[2], k.dare_residual, k.closed_loop_radius
        );
        let shapes: Vec<(&str, _)> = (0..3).map(|j| (axis_name(j), k.force_shape[j])).collect();
        t.push_str("3x3 rows: ");
        t.push_str(&crate::design::above_band::describe(&shapes));
    }
    let rz = &s.realization;
    let _ = writeln!(
        t,
        "realized: {} pole pairs, {} diagonal sections, {} FIR taps (3x3); f32 verified to {:.0} Hz, largest error {:.2e}",
        rz.pairs,
        rz.diagonal,
        rz.fir_taps,
        rz.verified_to_hz,
        rz.verification.score()
    );
    if let Some(r) = &s.reduction {
        let _ = writeln!(t, "{}", r.line());
    }
    t.push_str(&crate::realize::load::describe(load, fs_hz));
    t.push_str(if load.fits { "\n" } else { "  OVER THE LIMIT: offline-only image\n" });
    if !load.fits {
        let _ = writeln!(t, "{}", for_the_box(s, load.max_fs_hz));
    }
    for n in &s.notes {
        let _ = writeln!(t, "note: {n}");
    }
    for w in &s.worse_than_raw {
        let _ = writeln!(t, "{}", crate::design::mimo::worse_than_raw::warning(w));
    }
    t
}

/// One cell of the crosstalk table: the peak |G_ij|/|G_ii| and where it
/// lies, or that no line of the band has both entries coherent (the peak is
/// NaN there, `null` in `--json`).
fn crosstalk_cell(peak: f64, at_hz: f64) -> String {
    match peak.is_finite() && at_hz.is_finite() {
        true => format!("{:.1} % at {:.0} Hz", 100.0 * peak, at_hz),
        false => "no coherent lines".into(),
    }
}

/// The crosstalk table and each axis's predictions (raw, per axis with the
/// crosstalk counted and as it claims without, 3x3) and choice of row.
fn crosstalk_and_predictions(s: &MatrixSummary) -> String {
    let mut t = String::new();
    let _ = writeln!(t, "crosstalk, peak |G_ij|/|G_ii| over each row's compensated band (force direction j):");
    let _ = writeln!(t, "  channel        from x            from y            from z");
    for i in 0..3 {
        let cells: Vec<String> = (0..3)
            .map(|j| {
                if i == j {
                    format!("{:<18}", "-")
                } else {
                    format!("{:<18}", crosstalk_cell(s.crosstalk.peak[i][j], s.crosstalk.at_hz[i][j]))
                }
            })
            .collect();
        let _ = writeln!(t, "  {:<14} {}", axis_name(i), cells.join(""));
    }
    let _ = writeln!(
        t,
        "predicted in-band error (√J of {}, crosstalk counted; per axis: what it claims ignoring crosstalk):",
        s.forces
    );
    let _ = writeln!(t, "  axis  band (Hz)       raw        per axis (claims)      3x3        used");
    for a in &s.axes {
        let used = match a.source {
            RowSource::Matrix => "3x3 row",
            RowSource::PerAxis => "per-axis row",
        };
        let _ = writeln!(
            t,
            "  {:<5} {:<15} {:<10} {:<22} {:<10} {used}",
            a.axis,
            format!("{:.0}-{:.0}", a.band_hz.0, a.band_hz.1),
            pct(Some(a.raw.error)),
            format!("{} ({})", pct(a.per_axis.map(|p| p.error)), pct(a.per_axis_direct_only)),
            pct(a.matrix.map(|m| m.error)),
        );
    }
    let fit: Vec<String> = s
        .axes
        .iter()
        .filter(|a| a.chosen.fit.is_finite())
        .map(|a| {
            format!("{} {} (used row with it {})", a.axis, pct(Some(a.chosen.fit)), pct(Some(a.chosen.with_fit())))
        })
        .collect();
    if !fit.is_empty() {
        let _ = writeln!(
            t,
            "  fit uncertainty (the impact tests' noise left in Ĝ, which these predictions cannot see; more impacts lower it): {}",
            fit.join(", ")
        );
    }
    let offline: Vec<String> = s
        .axes
        .iter()
        .filter(|a| a.source == RowSource::Matrix)
        .filter_map(|a| {
            a.offline.map(|o| match o.fit.is_finite() {
                true => format!(
                    "{} {} (with the fit's uncertainty {})",
                    a.axis,
                    pct(Some(o.error)),
                    pct(Some(o.with_fit()))
                ),
                false => format!("{} {}", a.axis, pct(Some(o.error))),
            })
        })
        .collect();
    if !offline.is_empty() {
        let _ = writeln!(
            t,
            "  compensate --offline on this image (zero-lag smoother of the full 3x3 model, same q): {}{}",
            offline.join(", "),
            match s.flat_force {
                true => format!("; {OFFLINE_FLAT_CAVEAT}"),
                false => String::new(),
            }
        );
    }
    for a in &s.axes {
        let _ = writeln!(t, "  {}: {}", a.axis, a.reason);
    }
    t
}

#[cfg(test)]
mod tests {
    use super::crosstalk_cell;

    /// An entry without coherent lines in the band reads as such, not as
    /// "NaN % at NaN Hz" (seen on the flat plate, seed 11, 25.6 kHz: G_xz
    /// and G_yz).
    #[test]
    fn a_crosstalk_entry_without_coherent_lines_says_so() {
        assert_eq!(crosstalk_cell(f64::NAN, f64::NAN), "no coherent lines");
        assert!(!crosstalk_cell(f64::NAN, f64::NAN).contains("NaN"));
        // Control: a measured peak prints its value and frequency.
        assert_eq!(crosstalk_cell(0.109, 2760.0), "10.9 % at 2760 Hz");
    }
}
