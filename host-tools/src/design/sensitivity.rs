//! How sensitive a designed compensator is to its sensor modes moving
//! ([`predict`]): the workpiece loses mass during the cut, the FRF was
//! measured once, and near a lightly damped resonance a 1 % shift is most of
//! a half-power bandwidth. The shift at which the predicted error has doubled
//! is what a user acts on: re-measure the FRF when the modes may have moved
//! by more than that.

use num_complex::Complex64;
use serde::Serialize;

use crate::design::axis::{AxisDesign, DesignOptions};
use crate::design::criterion::{criterion_grid, criterion_j_weighted, criterion_ranges, noise_term};
use crate::fit::modes::sensor_mode_indices;
use crate::fit::{PoleResidueModel, Term};

/// The absolute error level of the second figure of [`Sensitivity`]: 1 %.
pub const ONE_PERCENT: f64 = 0.01;

/// Relative shifts of the sensor modes (%) at which the error is predicted:
/// −5 … +5 % in steps of 0.25 %.
pub const SHIFTS_PCT: [f64; 41] = {
    let mut a = [0.0; 41];
    let mut i = 0;
    while i < 41 {
        a[i] = -5.0 + 0.25 * i as f64;
        i += 1;
    }
    a
};

/// Predicted in-band error against shifted sensor modes, one axis.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Sensitivity {
    /// Natural frequencies (Hz) of the fitted modes treated as sensor modes.
    pub sensor_modes_hz: Vec<f64>,
    /// (δ in %, predicted in-band relative error √J) at every δ of [`SHIFTS_PCT`].
    pub points: Vec<(f64, f64)>,
    /// Predicted error with no shift (equals the design's predicted error).
    pub nominal: f64,
    /// Smallest downward shift (%, negative) at which the predicted error
    /// reaches twice the nominal; `None` if it does not within −5 %.
    pub doubles_below_pct: Option<f64>,
    /// Smallest upward shift (%) at which it reaches twice the nominal;
    /// `None` if it does not within +5 %.
    pub doubles_above_pct: Option<f64>,
    /// Smallest downward shift (%) at which the predicted error reaches
    /// 1 % (or twice the nominal, if that is more); `None` within −5 %.
    pub one_percent_below_pct: Option<f64>,
    /// The same upward.
    pub one_percent_above_pct: Option<f64>,
    /// Line spacing of the measured FRF (Hz), for the advice in Hz
    /// ([`set_line_spacing`]); `None` until set.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub frf_line_spacing_hz: Option<f64>,
}

/// Record the FRF's line spacing (the median step of `freq_hz`) in every
/// sensitivity, for the advice in Hz ([`Sensitivity::advice`]).
pub fn set_line_spacing(sensitivities: &mut [Option<Sensitivity>], freq_hz: &[f64]) {
    let mut steps: Vec<f64> = freq_hz.windows(2).map(|w| w[1] - w[0]).filter(|d| *d > 0.0).collect();
    steps.sort_by(f64::total_cmp);
    let spacing = steps.get(steps.len() / 2).copied();
    for s in sensitivities.iter_mut().flatten() {
        s.frf_line_spacing_hz = spacing;
    }
}

impl Sensitivity {
    /// Predicted error at the shift `pct` (one of [`SHIFTS_PCT`]).
    pub fn at(&self, pct: f64) -> Option<f64> {
        self.points.iter().find(|p| (p.0 - pct).abs() < 1e-9).map(|p| p.1)
    }

    /// The shift (%, magnitude) beyond which the FRF should be re-measured:
    /// the smaller of the two doubling shifts; `None` when the error does not
    /// double within ±5 %.
    pub fn remeasure_pct(&self) -> Option<f64> {
        smaller(self.doubles_below_pct, self.doubles_above_pct)
    }

    /// The shift (%, magnitude) beyond which the predicted error exceeds
    /// 1 % (or twice the nominal), either way; `None` within ±5 %.
    pub fn one_percent_pct(&self) -> Option<f64> {
        smaller(self.one_percent_below_pct, self.one_percent_above_pct)
    }

    /// The shift of `pct` % in quantities a user acts on: Hz at the lowest
    /// sensor mode against the FRF's line spacing, and the change of the
    /// workpiece's mass that causes it. **Assumption (stated):** the mode
    /// is loaded by the workpiece's mass at constant stiffness, f ∝ 1/√m,
    /// so Δm/m ≈ −2·Δf/f.
    fn in_units(&self, pct: f64) -> String {
        let Some(f) = self.sensor_modes_hz.iter().copied().reduce(f64::min) else { return String::new() };
        let hz = f * pct / 100.0;
        let lines = match self.frf_line_spacing_hz {
            Some(df) if hz < df => format!(
                ", below the FRF's line spacing of {df:.3} Hz: a shift the FRF cannot resolve costs that much; \
                 design for both states (`--frf BEFORE --frf AFTER`) or follow the change offline (`compensate --offline --drift`)"
            ),
            Some(df) => format!(", {:.1} lines of the FRF ({df:.3} Hz)", hz / df),
            None => String::new(),
        };
        format!(
            ": {hz:.2} Hz at the {f:.0} Hz mode{lines}; a workpiece mass change of about {:.2} % (Δm/m ≈ −2·Δf/f for a mode loaded by its mass)",
            2.0 * pct
        )
    }

    /// The sentence a user acts on.
    pub fn advice(&self) -> String {
        let one = match self.one_percent_pct() {
            Some(x) => {
                format!("; it exceeds {:.0} % beyond {}", 100.0 * ONE_PERCENT.max(2.0 * self.nominal), fmt_mag(x))
            }
            None => String::new(),
        };
        match self.remeasure_pct() {
            Some(x) => format!(
                "re-measure the FRF when the sensor modes may have moved by more than {} (predicted error doubles, to {:.2} %, at {} / {}){}{one}",
                fmt_mag(x),
                200.0 * self.nominal,
                fmt_pct(self.doubles_below_pct),
                fmt_pct(self.doubles_above_pct),
                self.in_units(x)
            ),
            None => "the predicted error does not double for sensor-mode shifts within ±5 %".to_string(),
        }
    }
}

/// One line of `design`'s text summary for axis `name`.
pub fn summary_line(name: &str, s: &Sensitivity) -> String {
    let at = |p: f64| s.at(p).map_or("-".to_string(), |e| format!("{:.2}", 100.0 * e));
    let modes: Vec<String> = s.sensor_modes_hz.iter().map(|f| format!("{f:.0}")).collect();
    format!(
        "{name} sensor modes moved (modes {} Hz): pred. error {} / {} / {} / {} / {} % at −3 / −1 / 0 / +1 / +3 %; {}",
        modes.join(", "),
        at(-3.0),
        at(-1.0),
        at(0.0),
        at(1.0),
        at(3.0),
        s.advice()
    )
}

fn smaller(a: Option<f64>, b: Option<f64>) -> Option<f64> {
    [a.map(f64::abs), b.map(f64::abs)].into_iter().flatten().reduce(f64::min)
}

/// A shift magnitude in %, with two significant digits below 1 %.
fn fmt_mag(x: f64) -> String {
    if x < 1.0 {
        format!("{x:.2} %")
    } else {
        format!("{x:.1} %")
    }
}

fn fmt_pct(v: Option<f64>) -> String {
    match v {
        Some(v) if v.abs() < 1.0 => format!("{v:+.2} %"),
        Some(v) => format!("{v:+.1} %"),
        None => "beyond ±5 %".to_string(),
    }
}

/// `model` with the terms at `indices` moved by the relative shift `delta`:
/// pole and residue times (1 + δ).
///
/// A sensor mode moved by δ is the same mode on a frequency axis scaled by
/// (1 + δ): its term r/(s − p) becomes r/(s/(1+δ) − p) = r(1+δ)/(s − p(1+δ)),
/// so ω scales by (1 + δ), the damping ratio and the mode's static share stay
/// (a change of mass at constant stiffness moves ω and keeps the static
/// compliance).
pub fn shifted_model(model: &PoleResidueModel, indices: &[usize], delta: f64) -> PoleResidueModel {
    let mut m = model.clone();
    for &i in indices {
        if let Term::Pair { pole, residue } = m.terms[i] {
            m.terms[i] = Term::Pair { pole: pole * (1.0 + delta), residue: residue * (1.0 + delta) };
        }
    }
    m
}

/// Σ over `indices` of the terms' response at `f_hz` (Hz).
fn terms_frf(model: &PoleResidueModel, indices: &[usize], f_hz: f64) -> Complex64 {
    let part = PoleResidueModel { terms: indices.iter().map(|&i| model.terms[i]).collect(), d: 0.0 };
    part.frf(f_hz)
}

/// The first shift along `points` (ordered away from 0) where the error
/// reaches `limit`, refined by bisection on `err` (error at a shift in %)
/// between the bracketing points; `None` if it never does.
fn crossing<'a>(mut points: impl Iterator<Item = &'a (f64, f64)>, limit: f64, err: &dyn Fn(f64) -> f64) -> Option<f64> {
    let mut prev = *points.next()?;
    if prev.1 >= limit {
        return Some(prev.0);
    }
    for &p in points {
        if p.1 >= limit {
            let (mut lo, mut hi) = (prev.0, p.0);
            for _ in 0..40 {
                let mid = 0.5 * (lo + hi);
                if err(mid) >= limit {
                    hi = mid;
                } else {
                    lo = mid;
                }
            }
            return Some(hi);
        }
        prev = p;
    }
    None
}

/// [`predict`] for each of `designs`.
pub fn predict_all(designs: &[AxisDesign], opts: &DesignOptions) -> Vec<Option<Sensitivity>> {
    designs.iter().map(|d| predict(d, opts)).collect()
}

/// Predict the in-band error of the designed filter of `d` when its sensor
/// modes shift, with the design's own criterion and `opts` (sample rate,
/// force RMS). `None` when the model has no pair.
///
/// **Sensor modes (stated rule).** The dynamometer's main mode is the fitted
/// pair with the largest modal share 2|ρ|/|p| (the static gain a pair
/// r/(s − p) + c.c. contributes, for light damping); the sensor modes are the
/// fitted pairs whose natural frequency is at least
/// [`crate::fit::modes::SENSOR_FRACTION`] × the main mode's
/// ([`sensor_mode_indices`]). Machine-structure modes (a few hundred Hz on a
/// 9257-class set-up, sensor modes 2-6 kHz) stay below that line and do not
/// move; real poles do not move either.
///
/// **Prediction.** The plant met by the filter is G_δ = Ĝ + Σ_sensor
/// (term_δ − term) ([`shifted_model`]), so G_0 is the design's Ĝ. The designed
/// filter H (f64, the one the q search chose) is scored against G_δ by the
/// design's own criterion J ([`crate::design::criterion::criterion_j`]: model
/// error |H·G_δ·e^{j2πfL/fs} − 1|² plus amplified noise, flat force spectrum
/// of `force_rms` in the criterion's bands); √J at each δ of [`SHIFTS_PCT`],
/// and the shifts at which it has doubled (interpolated between the points).
pub fn predict(d: &AxisDesign, opts: &DesignOptions) -> Option<Sensitivity> {
    let idx = sensor_mode_indices(&d.model);
    if idx.is_empty() {
        return None;
    }
    let fs = opts.fs_hz;
    let ranges = criterion_ranges(&d.bands, d.compensated_band_hz);
    let width: f64 = ranges.iter().map(|b| b.1 - b.0).sum();
    let freqs = criterion_grid(&ranges);
    let h = d.kalman.compensator.freq_responses(&freqs, fs);
    let base: Vec<(Complex64, Complex64)> =
        freqs.iter().map(|f| (d.fitted_frf(*f), terms_frf(&d.model, &idx, *f))).collect();
    // The design's own force spectrum: flat of `force_rms`, or the record's.
    let force = d.force_spectrum.as_ref();
    let noise = noise_term(d.kalman.r, fs, width, force.map_or(opts.force_rms, |s| s.force_rms_n));
    let err = |pct: f64| -> f64 {
        let m = shifted_model(&d.model, &idx, pct / 100.0);
        let grid: Vec<(f64, Complex64)> =
            freqs.iter().zip(&base).map(|(f, (g, part))| (*f, g + terms_frf(&m, &idx, *f) - part)).collect();
        criterion_j_weighted(&grid, &h, force.map(|s| s.weights.as_slice()), d.kalman.lag, fs, noise).sqrt()
    };
    let points: Vec<(f64, f64)> = SHIFTS_PCT.iter().map(|&pct| (pct, err(pct))).collect();
    let nominal = points.iter().find(|p| p.0 == 0.0).map(|p| p.1).unwrap_or(f64::NAN);
    let mid = points.iter().position(|p| p.0 == 0.0).unwrap_or(0);
    let sensor_modes_hz = idx
        .iter()
        .filter_map(|&i| match d.model.terms[i] {
            Term::Pair { pole, .. } => Some(pole.norm() / (2.0 * std::f64::consts::PI)),
            Term::Real { .. } => None,
        })
        .collect();
    let twice = 2.0 * nominal;
    let one = ONE_PERCENT.max(twice);
    Some(Sensitivity {
        sensor_modes_hz,
        doubles_below_pct: crossing(points[..=mid].iter().rev(), twice, &err),
        doubles_above_pct: crossing(points[mid..].iter(), twice, &err),
        one_percent_below_pct: crossing(points[..=mid].iter().rev(), one, &err),
        one_percent_above_pct: crossing(points[mid..].iter(), one, &err),
        points,
        nominal,
        frf_line_spacing_hz: None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shift_scales_the_frequency_axis_of_the_sensor_modes_only() {
        // machine mode 400 Hz (share 0.1), sensor modes 2.3 kHz (0.8) and 4 kHz (0.1)
        let m = PoleResidueModel::from_modes(&[(400.0, 0.03, 0.1), (2300.0, 0.02, 0.8), (4000.0, 0.03, 0.1)]);
        let idx = sensor_mode_indices(&m);
        assert_eq!(idx, vec![1, 2]);
        let s = shifted_model(&m, &idx, 0.03);
        // Independent truth: the same modes built at 1.03 × f.
        let truth =
            PoleResidueModel::from_modes(&[(400.0, 0.03, 0.1), (2300.0 * 1.03, 0.02, 0.8), (4000.0 * 1.03, 0.03, 0.1)]);
        for f in [0.0, 100.0, 1000.0, 2300.0, 2369.0, 3000.0, 4120.0] {
            assert!((s.frf(f) - truth.frf(f)).norm() < 1e-9 * truth.frf(f).norm().max(1.0), "f {f}");
        }
        // Negative control: the machine mode did not move.
        let wrong =
            PoleResidueModel::from_modes(&[(412.0, 0.03, 0.1), (2300.0 * 1.03, 0.02, 0.8), (4000.0 * 1.03, 0.03, 0.1)]);
        assert!((s.frf(412.0) - wrong.frf(412.0)).norm() > 0.1);
    }

    #[test]
    fn crossing_bisects_and_reports_none() {
        // err(x) = 1 + x²/2: reaches 2 at x = √2 (independent of the points).
        let err = |x: f64| 1.0 + 0.5 * x * x;
        let pts: Vec<(f64, f64)> = [0.0, 1.0, 2.0, 3.0].iter().map(|&x| (x, err(x))).collect();
        assert!((crossing(pts.iter(), 2.0, &err).unwrap() - 2f64.sqrt()).abs() < 1e-9);
        assert_eq!(crossing(pts.iter(), 6.0, &err), None);
    }
}
