//! The two-state design's figure: each candidate's predicted error over
//! the range between the two measured states.

use anyhow::Result;

use crate::design::two_state::range::{RangeDesign, RANGE_STATES};

/// Caption of the report's range plot.
pub fn range_caption(rd: &RangeDesign) -> String {
    let shared = shared_modes_hz(rd);
    format!(
        "Predicted in-band error (the design's criterion, flat force spectrum) of each candidate image at the states s = 0, ¼, ½, ¾, 1 \
         of the range (joined by straight lines; 0 = the first FRF, 1 = the second, in between the model interpolated with 1/f² \
         linear). The image is the candidate \
         with the least worst case (thick); the first and second FRF's own designs are the candidates at s = 0 and 1. \
         Machine modes shared by both states: {} Hz.{} A fixed image cannot follow a drift of a few %: \
         `compensate --offline --drift START:END` follows it with both states.",
        if shared.is_empty() { "none".to_string() } else { shared.join(", ") },
        match rd.above_band.first() {
            Some(m) if m.joint => format!(
                " Sensor modes above the compensated band, fitted to both FRFs at once: {} Hz.",
                rd.above_band.iter().map(|m| format!("{:.0}→{:.0}", m.joint_fn_hz.0, m.joint_fn_hz.1)).collect::<Vec<_>>().join(", ")
            ),
            Some(_) => " Sensor modes above the compensated band: each FRF's own fit (the FRFs disagree on their static gain).".to_string(),
            None => String::new(),
        }
    )
}

/// The report's SVG: each candidate's predicted error (%) against the state s.
pub fn plot_range(axis: &str, rd: &RangeDesign) -> Result<String> {
    use crate::report::plot::{build_chart, draw_line, legend, mesh, perr, FONT};
    use plotters::prelude::*;
    let top = rd.candidates.iter().flat_map(|c| c.errors.iter()).fold(0.0f64, |a, e| a.max(100.0 * e));
    let yr = (0.0, if top.is_finite() && top > 0.0 { 1.1 * top } else { 1.0 });
    let chosen = &rd.candidates[rd.best];
    let (first, last) = (&rd.candidates[0], &rd.candidates[rd.candidates.len() - 1]);
    let mut buf = String::new();
    {
        let root = SVGBackend::with_string(&mut buf, (1100, 420)).into_drawing_area();
        root.fill(&WHITE).map_err(perr)?;
        let title = format!(
            "Axis {axis} — image designed at s = {:.2}: worst case {:.2} % over the range (first / second FRF's design alone: {:.2} / {:.2} %)",
            chosen.s,
            100.0 * chosen.worst,
            100.0 * first.worst,
            100.0 * last.worst
        );
        let root = root.titled(&title, (FONT, 16)).map_err(perr)?;
        let mut c = build_chart(&root, "Predicted in-band RMS error (% of the force's std)", (0.0, 1.0), yr)?;
        mesh(&mut c, "State s (0 = first FRF, 1 = second FRF)", "Predicted error (%)", &|v| format!("{v:.2}"), &|v| format!("{v:.1}"), 8)?;
        const PALETTE: [RGBColor; 5] = [RGBColor(31, 119, 180), RGBColor(44, 160, 44), RGBColor(148, 103, 189), RGBColor(140, 86, 75), RGBColor(255, 127, 14)];
        for (i, cand) in rd.candidates.iter().enumerate() {
            let pts: Vec<(f64, f64)> = RANGE_STATES.iter().zip(&cand.errors).map(|(s, e)| (*s, 100.0 * e)).collect();
            let (color, width) = if i == rd.best { (RGBColor(214, 39, 40), 3) } else { (PALETTE[i % PALETTE.len()], 1) };
            let label = format!("designed at s = {:.2}{}", cand.s, if i == rd.best { " (the image)" } else { "" });
            draw_line(&mut c, &pts, yr, f64::INFINITY, color, width, i != rd.best, &label)?;
        }
        legend(&mut c, SeriesLabelPosition::UpperMiddle)?;
        root.present().map_err(perr)?;
    }
    Ok(buf)
}

/// The shared machine modes' frequencies (Hz, mean of the two states).
pub fn shared_modes_hz(rd: &RangeDesign) -> Vec<String> {
    rd.machine.iter().filter(|m| m.shared).map(|m| format!("{:.0}", 0.5 * (m.fn_hz.0 + m.fn_hz.1))).collect()
}
