//! The design report's look-ahead figure: the predicted in-band error of
//! the box filter and of longer fixed-lag smoothers against their
//! look-ahead, beside `compensate --offline`'s ([`crate::design::look_ahead`]).

use crate::design::look_ahead::LookAhead;
use crate::frf::axis_name;
use crate::report::plot::{build_chart, draw_line, legend_off_data, log_pct_tick, mesh, perr, FONT};

const C_BOX: plotters::style::RGBColor = plotters::style::RGBColor(214, 39, 40);
const C_OFFLINE: plotters::style::RGBColor = plotters::style::RGBColor(44, 160, 44);
const C_GUIDE: plotters::style::RGBColor = plotters::style::RGBColor(127, 127, 127);
const C_LIMIT: plotters::style::RGBColor = plotters::style::RGBColor(31, 119, 180);

/// Caption of the report's look-ahead plot of `l` at `fs_hz`.
pub fn plot_caption(l: &LookAhead, fs_hz: f64) -> String {
    format!(
        "Predicted in-band error for the record's force spectrum (the fit's uncertainty counted) of the box filter at \
         its latency and of fixed-lag smoothers of the same model looking further ahead, which the box cannot run \
         (right of the dotted line at {} samples). Dashed: half the box filter's error, and compensate --offline's \
         (the whole record, no look-ahead limit). {}.",
        l.box_longest,
        crate::report::page::sentence_case(
            crate::design::look_ahead::note(l, fs_hz).split_once(": ").map_or("", |(_, rest)| rest)
        )
    )
}

/// The report's SVG: predicted error (%, log scale) against the look-ahead
/// (samples): the box filter's, each longer one tried, `--offline`'s and
/// half the box's as dashed lines, and the box's limit.
pub fn plot(l: &LookAhead, fs_hz: f64) -> anyhow::Result<String> {
    use plotters::prelude::*;
    let lg = |e: f64| (100.0 * e).max(1e-6).log10();
    let mut pts = vec![(l.box_latency as f64, lg(l.box_predicted))];
    pts.extend(l.tried.iter().filter_map(|(n, e)| e.map(|e| (*n as f64, lg(e)))));
    let longest = l.tried.last().map_or(l.box_latency, |t| t.0) as f64;
    let xr = (0.0, 1.08 * longest);
    let values = pts.iter().map(|p| p.1).chain([lg(l.offline_predicted)]);
    let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| (a.min(v), b.max(v)));
    let yr = if lo.is_finite() && hi.is_finite() { (lo - 0.2, hi + 0.5) } else { (-2.0, 2.0) };
    let mut buf = String::new();
    {
        let root = SVGBackend::with_string(&mut buf, (1100, 440)).into_drawing_area();
        root.fill(&WHITE).map_err(perr)?;
        let title = format!(
            "Axis {} — predicted error against look-ahead: box {:.2} % at {} samples ({:.2} ms), compensate --offline {:.2} %",
            axis_name(l.axis),
            100.0 * l.box_predicted,
            l.box_latency,
            1e3 * l.box_latency as f64 / fs_hz,
            100.0 * l.offline_predicted
        );
        let root = root.titled(&title, (FONT, 16)).map_err(perr)?;
        let mut c = build_chart(&root, "Predicted in-band RMS error (% of the force's std, log scale)", xr, yr)?;
        let ms = |v: &f64| format!("{v:.0} ({:.2} ms)", 1e3 * v / fs_hz);
        mesh(&mut c, "Look-ahead L (samples)", "Predicted error (%)", &ms, &log_pct_tick, 8)?;
        let labels = [
            "fixed-lag smoother, predicted",
            "compensate --offline, predicted",
            "half the box filter's error",
            "the box's longest look-ahead",
        ];
        draw_line(&mut c, &pts, yr, f64::INFINITY, C_BOX, 2, false, labels[0])?;
        c.draw_series(pts.iter().map(|p| Circle::new(*p, 4, C_BOX.filled()))).map_err(perr)?;
        let offline = [(xr.0, lg(l.offline_predicted)), (xr.1, lg(l.offline_predicted))];
        draw_line(&mut c, &offline, yr, f64::INFINITY, C_OFFLINE, 2, true, labels[1])?;
        let half = [(xr.0, lg(0.5 * l.box_predicted)), (xr.1, lg(0.5 * l.box_predicted))];
        draw_line(&mut c, &half, yr, f64::INFINITY, C_GUIDE, 1, true, labels[2])?;
        let limit = [(l.box_longest as f64, yr.0), (l.box_longest as f64, yr.1)];
        draw_line(&mut c, &limit, yr, f64::INFINITY, C_LIMIT, 1, true, labels[3])?;
        let data: Vec<&[(f64, f64)]> = vec![&pts, &offline, &half, &limit];
        legend_off_data(&mut c, SeriesLabelPosition::UpperRight, &labels, &data)?;
        root.present().map_err(perr)?;
    }
    Ok(buf)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_plot_draws_every_look_ahead_tried_and_the_offline_level() {
        let l = LookAhead {
            axis: 0,
            box_latency: 6,
            box_longest: 8,
            box_predicted: 0.1716,
            offline_predicted: 0.0119,
            tried: vec![(16, Some(0.1243)), (32, Some(0.0713)), (64, None)],
            designs: Vec::new(),
        };
        let svg = plot(&l, 10_240.0).unwrap();
        assert!(svg.contains("box 17.16 % at 6 samples (0.59 ms), compensate --offline 1.19 %"), "title");
        // One marker per design with a figure: the box and two of three tried.
        assert_eq!(svg.matches("<circle").count(), 3, "markers");
        let cap = plot_caption(&l, 10_240.0);
        assert!(cap.contains("is 32 samples (3.12 ms)") && cap.contains("no design at 64"), "{cap}");
    }
}
