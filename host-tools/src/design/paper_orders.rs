//! The paper method's orders NB:NA chosen per axis (`design --method paper`
//! without `--paper-orders`, [`design_axis_auto`]). The paper chose its orders
//! by hand for its own FRF (§3.1); here they are the highest that pass every
//! check of the full design among the best-fitting workable pairs, and the
//! reason is reported.

use anyhow::{bail, Result};

use crate::design::axis::{self, probe_paper_fit, AxisDesign, DesignOptions, FitMethod};
use crate::frf::{axis_name, AxisFrf};

/// Highest denominator order tried.
pub const MAX_AUTO_NA: usize = 14;
/// Fits whose errors differ by less than this (relative) rank as equal; the
/// higher orders go first among them.
pub const FIT_TIE: f64 = 0.02;
/// Full designs tried at most, best-ranked first.
pub const MAX_FULL_TRIALS: usize = 4;

/// Design one axis: by the paper's method at orders chosen by
/// [`design_axis_auto`] when `opts.paper_orders_auto` asks for it, else as
/// [`crate::design::axis::design_axis`] does.
pub fn design_axis(freq_hz: &[f64], frf: &AxisFrf, r: f64, opts: &DesignOptions) -> Result<AxisDesign> {
    if opts.paper_orders_auto && matches!(opts.method, FitMethod::Paper { .. }) {
        return design_axis_auto(freq_hz, frf, r, &DesignOptions { paper_orders_auto: false, ..opts.clone() });
    }
    axis::design_axis(freq_hz, frf, r, opts)
}

/// The candidate order pairs (NB, NA), lowest first.
pub fn candidates() -> Vec<(usize, usize)> {
    (2..=MAX_AUTO_NA).flat_map(|na| (na.saturating_sub(2)..=na).map(move |nb| (nb, na))).collect()
}

/// Design `frf` by the paper's method at orders it chooses. `opts.method`
/// must be [`FitMethod::Paper`] (its orders are ignored). The reason for the
/// choice is the first of the design's notes.
///
/// Every pair with 2 ≤ NA ≤ [`MAX_AUTO_NA`] and NA − 2 ≤ NB ≤ NA is first
/// probed cheaply ([`crate::design::axis::probe_paper_fit`]): the
/// RFP/Gauss–Newton fit must be stable with a plausible static gain, and the
/// augmented system of eq. (4) observable and well-conditioned in floating
/// point ([`crate::design::paper::MAX_OBSERVABILITY_CONDITION`]). The workable
/// pairs are ranked by their in-band fit error (relative RMS against the
/// coherent measured lines in the bands), the higher orders first among equal
/// fits (within [`FIT_TIE`]), and designed in that order; the first that
/// passes every check of the full design (Q search, the fit-error limit,
/// never worse than raw, f32 verification) is taken.
pub fn design_axis_auto(freq_hz: &[f64], frf: &AxisFrf, r: f64, opts: &DesignOptions) -> Result<AxisDesign> {
    let name = axis_name(frf.axis);
    let FitMethod::Paper { rfp, prewarp_hz } = &opts.method else {
        bail!("automatic orders need the paper's method");
    };
    let with = |nb: usize, na: usize| {
        let mut o = opts.clone();
        o.method =
            FitMethod::Paper { rfp: crate::fit::rfp::RfpOptions { nb, na, ..rfp.clone() }, prewarp_hz: *prewarp_hz };
        o
    };
    let say = |line: String| {
        if let Some(p) = &opts.order_search_progress {
            p.say(&line);
        }
    };
    say(format!("axis {name}: probing {} paper-method order pairs NB:NA…", candidates().len()));
    let mut workable: Vec<(usize, usize, f64)> = Vec::new();
    let mut refused = 0usize;
    for (nb, na) in candidates() {
        match probe_paper_fit(freq_hz, frf, &with(nb, na)) {
            Ok((e, _)) if e.is_finite() => workable.push((nb, na, e)),
            _ => refused += 1,
        }
    }
    if workable.is_empty() {
        bail!(
            "axis {name}: no paper-method orders NB:NA with NA ≤ {MAX_AUTO_NA} give a stable fit with an observable, well-conditioned augmented system; fit narrower bands (--band, --spindle-rpm/--teeth) or use the default method (--method vf)"
        );
    }
    let best = workable.iter().map(|w| w.2).fold(f64::INFINITY, f64::min);
    // rank: fit error in tie classes of FIT_TIE, higher orders first within a class
    workable.sort_by(|a, b| {
        let class = |e: f64| ((e / best).ln() / (1.0 + FIT_TIE).ln()).floor() as i64;
        class(a.2).cmp(&class(b.2)).then(b.1.cmp(&a.1)).then(b.0.cmp(&a.0)).then(a.2.total_cmp(&b.2))
    });
    let mut failures = Vec::new();
    let trials = workable.len().min(MAX_FULL_TRIALS);
    say(format!("axis {name}: {} workable pairs; designing the best-fitting, at most {trials}", workable.len()));
    for (k, &(nb, na, fit)) in workable.iter().take(MAX_FULL_TRIALS).enumerate() {
        say(format!("axis {name}: orders {nb}:{na} ({} of at most {trials}): full design…", k + 1));
        match axis::design_axis(freq_hz, frf, r, &with(nb, na)) {
            Ok(mut d) => {
                let skipped = if failures.is_empty() {
                    String::new()
                } else {
                    format!("; better-fitting pairs failed the design: {}", failures.join("; "))
                };
                d.notes.insert(
                    0,
                    format!(
                        "axis {name}: paper orders {nb}:{na} chosen automatically: in-band fit error {:.2} % (best of {} workable pairs: {:.2} %), the highest orders among the best fits; {refused} of {} pairs refused (unstable fit, or augmented system not observable or ill-conditioned in floating point){skipped}",
                        100.0 * fit,
                        workable.len(),
                        100.0 * best,
                        candidates().len()
                    ),
                );
                return Ok(d);
            }
            Err(e) => failures.push(format!("{nb}:{na} ({})", last_clause(&e).chars().take(160).collect::<String>())),
        }
    }
    bail!(
        "axis {name}: none of the {} best-fitting paper-method order pairs gives a usable compensator: {}; fit narrower bands (--band, --spindle-rpm/--teeth) or use the default method (--method vf)",
        failures.len(),
        failures.join("; ")
    )
}

/// The last clause of an error chain (`{e:#}` joins the contexts with ": "),
/// without the axis and file prefixes.
pub fn last_clause(e: &anyhow::Error) -> String {
    let full = format!("{e:#}");
    full.rsplit(": ").next().unwrap_or(&full).to_string()
}
