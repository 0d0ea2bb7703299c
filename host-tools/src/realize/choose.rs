//! Choose the realization the box runs: among the valid modal realizations
//! of a compensator (and their shortened FIR tails), the cheapest on the box
//! that verifies in f32 as accurately as the best.

use anyhow::{Context, Result};
use dynocomp_core::kernel::AxisFilter;

use crate::numeric::lti::StateSpace;
use crate::realize::modal::{self, ModalRealization};
use crate::realize::quantize::{self, Verification};

/// Realize the compensator `ss` and round it to f32, with no CPU budget:
/// [`choose_realization_within`] with `axis_budget = None`.
pub fn choose_realization(
    ss: &StateSpace,
    fs_hz: f64,
    f_band_hz: f64,
) -> Result<(ModalRealization, AxisFilter, Verification)> {
    choose_realization_within(ss, fs_hz, f_band_hz, None)
}

/// Largest verification score ([`Verification::score`]) a shortened FIR may
/// reach: a tenth of the verification limits, or 10x the full FIR's score
/// when that is larger.
const TRIM_SCORE_FLOOR: f64 = 1e-5;

/// A cheaper candidate may not be scaled worse than this or than the most
/// accurate candidate (`Verification::term_growth`: no part of the kernel's
/// sum beyond 2x the output).
const MAX_CHOICE_TERM_GROWTH: f64 = 2.0;

/// Realize the compensator `ss` and round it to f32.
///
/// Candidates: the valid realizations (one per fast/slow pole split,
/// `modal::realize_candidates`), each fully verified by `quantize` over
/// 0..`f_band_hz`, and for each one with FIR taps its shortest FIR that
/// still verifies with a score ≤ max(10x its own, `TRIM_SCORE_FLOOR`)
/// (taps bought for nothing: the kernel's cost falls, the verification
/// limits hold). Only candidates scaled no worse than the most accurate one
/// or `MAX_CHOICE_TERM_GROWTH` are considered. Choice, the cheapest (ties:
/// the most accurate) of the first non-empty of: within `axis_budget`
/// (cycles per sample this axis may cost, high estimate of
/// `dynocomp_core::budget::CostModel::CORTEX_M4`) and within the score
/// bound max(10x the best score, `TRIM_SCORE_FLOOR`); within the budget;
/// within the score bound (so the box's cost is never paid for rounding).
pub fn choose_realization_within(
    ss: &StateSpace,
    fs_hz: f64,
    f_band_hz: f64,
    axis_budget: Option<u32>,
) -> Result<(ModalRealization, AxisFilter, Verification)> {
    use dynocomp_core::budget::{AxisShape, CostModel};
    let candidates = modal::realize_candidates(ss).context("realization")?;
    let reference = quantize::Reference::of(ss, fs_hz, f_band_hz);
    let mut verified: Vec<(ModalRealization, AxisFilter, Verification)> = Vec::new();
    let mut last_err = None;
    for r in candidates {
        match quantize::quantize(&r, &reference) {
            Ok((f, v)) => {
                if let Some(t) = shortest_fir(&r, &v, &reference) {
                    verified.push(t);
                }
                verified.push((r, f, v));
            }
            Err(e) => last_err = Some(e),
        }
    }
    let cost = |f: &AxisFilter| CostModel::CORTEX_M4.axis_cost(AxisShape::of(f)).high;
    // Well-scaled realizations first: when any verified one keeps every term
    // of the kernel's sum within MAX_CHOICE_TERM_GROWTH of the output, the
    // choice is made among those only (the most accurate candidate can be a
    // badly scaled one, e.g. a fast pair split from a long delay chain).
    if verified.iter().any(|c| c.2.term_growth <= MAX_CHOICE_TERM_GROWTH) {
        verified.retain(|c| c.2.term_growth <= MAX_CHOICE_TERM_GROWTH);
    }
    let Some(best) = verified.iter().min_by(|a, b| a.2.score().total_cmp(&b.2.score())) else {
        return Err(last_err.unwrap_or_else(|| anyhow::anyhow!("no realization")).context("quantization"));
    };
    let bound = (10.0 * best.2.score()).max(TRIM_SCORE_FLOOR);
    let growth = best.2.term_growth.max(MAX_CHOICE_TERM_GROWTH);
    type Cand = (ModalRealization, AxisFilter, Verification);
    let fits = |c: &Cand| axis_budget.is_some_and(|b| cost(&c.1) <= b);
    let accurate = |c: &Cand| c.2.score() <= bound && c.2.term_growth <= growth;
    let well_scaled = |c: &Cand| c.2.term_growth <= growth;
    // Most preferred first: within budget and as accurate as the best; within
    // budget; as accurate as the best (the best itself always is).
    let pools: [&dyn Fn(&Cand) -> bool; 3] = [&|c| fits(c) && accurate(c), &|c| fits(c) && well_scaled(c), &accurate];
    let chosen = pools.iter().find_map(|keep| {
        verified
            .iter()
            .filter(|c| keep(c))
            .min_by(|a, b| cost(&a.1).cmp(&cost(&b.1)).then(a.2.score().total_cmp(&b.2.score())))
            .cloned()
    });
    chosen.ok_or_else(|| last_err.unwrap_or_else(|| anyhow::anyhow!("no realization")).context("quantization"))
}

/// The realization `r` (verified as `v`) with the fewest FIR taps that still
/// passes `quantize` with a score ≤ max(10·v.score(), `TRIM_SCORE_FLOOR`);
/// `None` if no shorter FIR does.
fn shortest_fir(
    r: &ModalRealization,
    v: &Verification,
    reference: &quantize::Reference,
) -> Option<(ModalRealization, AxisFilter, Verification)> {
    let bound = (10.0 * v.score()).max(TRIM_SCORE_FLOOR);
    let total: f64 = r.fir.iter().map(|h| h.abs()).sum::<f64>();
    (0..r.fir.len()).find_map(|len| {
        let mut t = r.clone();
        t.fir.truncate(len);
        let dropped: f64 = r.fir[len..].iter().map(|h| h.abs()).sum();
        t.fir_truncation = r.fir_truncation + dropped / total.max(f64::MIN_POSITIVE);
        let (f, tv) = quantize::quantize(&t, reference).ok()?;
        (tv.score() <= bound).then_some((t, f, tv))
    })
}
