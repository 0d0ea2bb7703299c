//! The design report's force-spectrum figure: where the record's force is,
//! against where the filter is accurate (`--force-prior spectrum`).

use anyhow::Result;

use crate::design::force_spectrum::AxisForceSpectrum;
use crate::report::plot::{build_chart, draw_line, legend, mesh, perr, FONT};

/// The design report's plot of an axis designed on a record's force
/// spectrum: on the criterion's lines, the record's force power per line
/// relative to a flat spectrum (dB; the flat share β shows as its floor,
/// −30 dB) and this filter's distortion |H·Ĝ·e^{j2πfL/fs} − 1| (dB), so that
/// one sees where the filter gives accuracy up and that the force is weak
/// there. `None` for an axis designed on a flat spectrum (also at a
/// record's level, `--force-prior level`).
pub fn plot(d: &crate::design::axis::AxisDesign, fs_hz: f64) -> Result<Option<String>> {
    use plotters::prelude::*;
    let Some(s) = d.force_spectrum.as_ref().filter(|s| !s.level_only) else { return Ok(None) };
    let ranges = crate::design::criterion::criterion_ranges(&d.bands, d.compensated_band_hz);
    let freqs = crate::design::criterion::criterion_grid(&ranges);
    let n = freqs.len() as f64;
    let force: Vec<(f64, f64)> =
        freqs.iter().zip(&s.weights).map(|(f, w)| (*f, 10.0 * (w * n).max(1e-12).log10())).collect();
    let lag = d.kalman.lag;
    let h = d.kalman.compensator.freq_responses(&freqs, fs_hz);
    let dist: Vec<(f64, f64)> = freqs
        .iter()
        .zip(h)
        .map(|(f, h)| {
            let e = crate::design::criterion::distortion(*f, d.fitted_frf(*f), h, lag, fs_hz);
            (*f, 20.0 * e.norm().max(1e-12).log10())
        })
        .collect();
    let all = force.iter().chain(&dist).map(|p| p.1);
    let (lo, hi) = crate::report::plot::finite_range(all).unwrap_or((-60.0, 20.0));
    let yr = (lo.max(-120.0) - 3.0, hi + 3.0);
    let xr = (0.0, freqs.last().copied().unwrap_or(1.0) * 1.02);
    let name = crate::frf::axis_name(d.axis);
    let mut buf = String::new();
    {
        let root = SVGBackend::with_string(&mut buf, (1100, 420)).into_drawing_area();
        root.fill(&WHITE).map_err(perr)?;
        let title = format!(
            "Axis {name} — q for the record's force spectrum ({:.2} N RMS): predicted {:.3} % for it, {:.3} % for a flat spectrum",
            s.force_rms_n,
            100.0 * s.predicted_error,
            100.0 * s.flat_predicted_error
        );
        let root = root.titled(&title, (FONT, 16)).map_err(perr)?;
        let mut c = build_chart(&root, "Where the force is, and where the filter is accurate", xr, yr)?;
        mesh(&mut c, "Frequency (Hz)", "dB", &crate::report::plot::hz, &|v| format!("{v:.0}"), 8)?;
        draw_line(
            &mut c,
            &force,
            yr,
            f64::INFINITY,
            RGBColor(31, 119, 180),
            2,
            false,
            "record's force power per line, dB re a flat spectrum",
        )?;
        draw_line(
            &mut c,
            &dist,
            yr,
            f64::INFINITY,
            RGBColor(214, 39, 40),
            2,
            false,
            "distortion |H·Ĝ·e^{jωL} − 1| of this filter, dB",
        )?;
        legend(&mut c, SeriesLabelPosition::LowerRight)?;
        root.present().map_err(perr)?;
    }
    Ok(Some(buf))
}

/// The caption of [`plot`].
pub fn plot_caption(s: &AxisForceSpectrum) -> String {
    format!(
        "q of this axis was chosen for the force spectrum of --force-record ({:.2} N RMS in the band) instead of a flat one: \
         blue, the record's force power on each line of the criterion relative to a flat spectrum of the same power \
         (noise removed; its floor, −30 dB, is the 0.1 % of the weight kept flat); red, the distortion of this filter. \
         Where the force is weak the filter may give accuracy up to carry less noise: a force there that the record did \
         not have (chatter) is compensated less well ({:.3} % predicted for a flat spectrum against {:.3} % for the record's).",
        s.force_rms_n,
        100.0 * s.flat_predicted_error,
        100.0 * s.predicted_error
    )
}
