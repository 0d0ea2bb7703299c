//! The design report's sensitivity figure: predicted in-band error of a
//! design against the shift of its sensor modes.

use crate::design::sensitivity::{Sensitivity, SHIFTS_PCT};
use crate::fit::modes::SENSOR_FRACTION;
use crate::report::plot::{build_chart, draw_line, legend_off_data, log_pct_tick, mesh, perr, FONT};

/// Caption of the report's sensitivity plot.
pub fn plot_caption(s: &Sensitivity) -> String {
    let modes: Vec<String> = s.sensor_modes_hz.iter().map(|f| format!("{f:.0}")).collect();
    format!(
        "Predicted in-band error (the design's criterion: model error of this filter against the shifted plant plus noise, \
         flat force spectrum) when the sensor modes ({} Hz; fitted pairs at or above {:.0} % of the main mode's frequency) \
         move by δ, ω scaled by 1 + δ, damping and static share kept. Dashed: twice the nominal error. {}.",
        modes.join(", "),
        100.0 * SENSOR_FRACTION,
        crate::report::page::sentence_case(&s.advice())
    )
}

/// The report's SVG: predicted error (%) against the shift δ (%), the
/// error on a log scale so that the nominal error, twice it and the shifts
/// where it doubles (dotted) can be read beside errors of tens of %.
pub fn plot(axis: &str, s: &Sensitivity) -> anyhow::Result<String> {
    use plotters::prelude::*;
    let lg = |pct: f64| pct.max(1e-6).log10();
    let pts: Vec<(f64, f64)> = s.points.iter().map(|p| (p.0, lg(100.0 * p.1))).collect();
    let nominal = 100.0 * s.nominal;
    let top = s.points.iter().map(|p| 100.0 * p.1).fold(2.0 * nominal, f64::max);
    let yr = if top.is_finite() && nominal > 0.0 { (lg(0.5 * nominal), lg(1.5 * top)) } else { (-2.0, 2.0) };
    let xr = (SHIFTS_PCT[0], SHIFTS_PCT[SHIFTS_PCT.len() - 1]);
    let mut buf = String::new();
    {
        let root = SVGBackend::with_string(&mut buf, (1100, 440)).into_drawing_area();
        root.fill(&WHITE).map_err(perr)?;
        let title = format!(
            "Axis {axis} — predicted in-band error vs sensor-mode shift: {:.2} % nominal, {:.2} / {:.2} % at ±1 %, {:.2} / {:.2} % at ±3 %",
            nominal,
            100.0 * s.at(-1.0).unwrap_or(f64::NAN),
            100.0 * s.at(1.0).unwrap_or(f64::NAN),
            100.0 * s.at(-3.0).unwrap_or(f64::NAN),
            100.0 * s.at(3.0).unwrap_or(f64::NAN)
        );
        let root = root.titled(&title, (FONT, 16)).map_err(perr)?;
        let mut c = build_chart(&root, "Predicted in-band RMS error (% of the force's std, log scale)", xr, yr)?;
        mesh(&mut c, "Sensor-mode shift δ (%)", "Predicted error (%)", &|v| format!("{v:+.1}"), &log_pct_tick, 8)?;
        draw_line(&mut c, &pts, yr, f64::INFINITY, RGBColor(214, 39, 40), 2, false, "predicted error, this filter")?;
        let twice = [(xr.0, lg(2.0 * nominal)), (xr.1, lg(2.0 * nominal))];
        draw_line(&mut c, &twice, yr, f64::INFINITY, RGBColor(127, 127, 127), 1, true, "twice the nominal error")?;
        let doubling: Vec<[(f64, f64); 2]> =
            [s.doubles_below_pct, s.doubles_above_pct].into_iter().flatten().map(|x| [(x, yr.0), (x, yr.1)]).collect();
        for (k, line) in doubling.iter().enumerate() {
            let label = if k == 0 { "where the error doubles" } else { "" };
            draw_line(&mut c, line, yr, f64::INFINITY, RGBColor(31, 119, 180), 1, true, label)?;
        }
        let labels = ["predicted error, this filter", "twice the nominal error", "where the error doubles"];
        let mut data: Vec<&[(f64, f64)]> = vec![&pts, &twice];
        data.extend(doubling.iter().map(|l| l.as_slice()));
        legend_off_data(&mut c, SeriesLabelPosition::UpperMiddle, &labels[..2 + doubling.len().min(1)], &data)?;
        root.present().map_err(perr)?;
    }
    Ok(buf)
}
