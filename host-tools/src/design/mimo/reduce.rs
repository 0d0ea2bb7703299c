//! A 3x3 compensator reduced to what the box runs in time:
//! where the chosen compensator's f32 filter is over the load limit at the
//! design's rate, its balanced reduction ([`crate::numeric::balanced`]) of
//! the highest order whose filter fits, with its predicted error on the same
//! criterion as the full one. It is used only where every row still beats
//! the per-axis row and no compensation (never silently worse); the offline
//! smoother keeps the full model either way (it runs the plant model, not
//! this filter).

use anyhow::Result;
use dynocomp_core::budget::MimoShape;
use dynocomp_core::mimo::MimoFilter;
use serde::{Deserialize, Serialize};

use super::criterion::RowError;
use super::{blocks_of, percent_xyz, Criteria, Realized, Round, RowSource};
use crate::numeric::balanced::{balance, Balanced, Reduction};
use crate::numeric::lti::MimoStateSpace;
use crate::numeric::parallel::map_on_threads;
use crate::realize::mimo::{block_sum, realize_blocks_by, shape_load, Prefer};

/// What the reduction did, for the summary, `--json`, and the model
/// sidecar of an image that holds the reduced filter (read by `inspect`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReductionFigures {
    /// Whether the reduced filter is the one in the image.
    pub used: bool,
    /// Why (or why not).
    pub reason: String,
    /// States of the full compensator.
    pub full_states: usize,
    /// States of the reduced one.
    pub states: usize,
    /// Truncation or singular perturbation (exact at DC).
    pub method: Reduction,
    /// Bound 2 Σσ on the largest error of the transfer matrix (N/N).
    pub hankel_bound: f64,
    /// Predicted box load of the full filter (‰ of the sample period, high
    /// estimate).
    pub full_load_permille: u32,
    /// Predicted box load of the reduced filter (‰).
    pub load_permille: u32,
    /// Predicted in-band error per output axis of the full filter (√J,
    /// fraction of the force's RMS, crosstalk counted).
    pub full_predicted: [f64; 3],
    /// The same for the reduced filter.
    pub predicted: [f64; 3],
    /// Why the full filter cannot go into an image at all (it needs more
    /// sections or taps than the kernel holds, or does not verify in f32),
    /// where that, not the load, is what the reduction is for; its load
    /// is then unknown (`full_load_permille` 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub full_not_realized: Option<String>,
}

/// Predicted load (‰, high estimate) of `filter` at `fs_hz`.
pub fn filter_load(filter: &MimoFilter, fs_hz: f64) -> u32 {
    shape_load(MimoShape::of(filter), fs_hz)
}

impl ReductionFigures {
    /// One line of what the reduction to the box's load limit did, with its
    /// cost in predicted in-band error.
    pub fn line(&self) -> String {
        let method = match self.method {
            Reduction::SingularPerturbation => "balanced singular perturbation, exact at DC",
            Reduction::Truncation => "balanced truncation",
        };
        let purpose = match &self.full_not_realized {
            None => "for the box".to_string(),
            Some(why) => format!("for the image (the full filter: {why})"),
        };
        if self.states == 0 {
            return format!("not reduced {purpose}: {}", self.reason);
        }
        let load = match &self.full_not_realized {
            None => format!(
                "load {:.1} -> {:.1} %",
                f64::from(self.full_load_permille) / 10.0,
                f64::from(self.load_permille) / 10.0
            ),
            Some(_) => format!("load {:.1} %", f64::from(self.load_permille) / 10.0),
        };
        let what = format!(
            "3x3 block {} -> {} states ({method}; {load}); predicted in-band error x / y / z {} % full -> {} % reduced",
            self.full_states,
            self.states,
            percent_xyz(&self.full_predicted),
            percent_xyz(&self.predicted)
        );
        match self.used {
            true => format!("reduced {purpose}: {what}; compensate --offline keeps the full model"),
            false => format!("not reduced {purpose}: {what}: {}", self.reason),
        }
    }
}

/// One reduced candidate that fits.
struct Candidate {
    realized: Realized,
    states: usize,
    method: Reduction,
    load: u32,
    errors: Vec<RowError>,
    judged: Vec<RowError>,
}

/// The reductions of the 3x3 block `bal` of the highest order whose
/// filter, with the `other` blocks unchanged, is realized, verified and
/// within the load limit. The load grows with the order, but not strictly
/// (a realization may take FIR taps for its fast poles), so: bisection on
/// the singular perturbation's order for the highest that fits, then that
/// order and the next [`ABOVE`] above it by both reductions, every one that
/// fits returned (realized for the least load, [`Prefer::Load`]).
fn fitting(bal: &Balanced, other: &[MimoStateSpace], lag: usize, crits: &Criteria, at: LoadAt) -> Vec<Candidate> {
    let freqs = crits.model.all_freqs();
    let try_one = |states: usize, method: Reduction| -> Option<Candidate> {
        let block = bal.reduce(states, method).ok()?;
        let blocks: Vec<MimoStateSpace> = std::iter::once(block).chain(other.iter().cloned()).collect();
        let realized = realize_blocks_by(&blocks, at.fs, at.f_band, Prefer::LoadWithin(at.limit)).ok()?;
        let load = filter_load(&realized.1, at.fs);
        if load > at.limit {
            return None;
        }
        let system = block_sum(&blocks);
        let h = system.freq_responses(&freqs, at.fs);
        let errors = (0..3).map(|i| crits.model.row_error(i, lag, &h)).collect();
        let judged = (0..3).map(|i| crits.judge.row_error(i, lag, &h)).collect();
        Some(Candidate { realized: (system, realized), states, method, load, errors, judged })
    };
    // Invariant: `lo` fits (0: nothing found yet), `hi` does not.
    let (mut lo, mut hi) = (0, bal.hankel.len().min(2 * max_sections(at) + 1).min(bal.trusted + 1));
    while hi - lo > 1 {
        let mid = (lo + hi) / 2;
        match try_one(mid, Reduction::SingularPerturbation) {
            Some(_) => lo = mid,
            None => hi = mid,
        }
    }
    if lo == 0 {
        return Vec::new();
    }
    let top = (lo + ABOVE).min(bal.hankel.len() - 1).min(bal.trusted);
    let tries: Vec<(usize, Reduction)> = (lo..=top)
        .flat_map(|states| [Reduction::SingularPerturbation, Reduction::Truncation].map(|m| (states, m)))
        .collect();
    map_on_threads(&tries, |(states, m)| try_one(*states, *m)).into_iter().flatten().collect()
}

/// Most sections (of the cheapest kind, diagonal: two states each) a 3x3
/// filter without taps may have within the load limit: twice this, plus
/// one, is the top of the bisection (a higher order could fit only with
/// many of its poles as FIR taps; the bisection does not look there).
fn max_sections(at: LoadAt) -> usize {
    let fits = |k: u32| shape_load(MimoShape { pairs: 0, diagonals: k, taps: 0 }, at.fs) <= at.limit;
    (0..=dynocomp_core::mimo::MAX_MIMO_SECTIONS as u32).take_while(|k| fits(*k)).last().map_or(0, |k| k as usize)
}

/// Orders above the bisection's result also tried ([`fitting`]): the load
/// is not monotone in the order (seed 6 of the seed study at 25.6 kHz: 47
/// states need 57 % of the period with 24 FIR taps, 50 states 49 % without).
const ABOVE: usize = 6;

/// Where the filter must fit: rate (Hz), load limit (‰) and the band the
/// f32 filter is verified over (Hz).
#[derive(Clone, Copy)]
pub(super) struct LoadAt {
    pub fs: f64,
    pub limit: u32,
    pub f_band: f64,
}

/// The chosen round `rd`'s compensator `realized`, whose filter needs
/// `full_load` ‰, over the load limit, reduced to it: its 3x3 rows' block
/// (`rd` has one) by balancing, the per-axis rows' blocks unchanged
/// ([`reduce_block`]). Where the reduction is used, the returned
/// realization replaces the full one, which is returned beside it;
/// otherwise the figures say why and `realized` is returned unchanged.
pub(super) fn reduce_to_load(
    realized: Realized,
    full_load: u32,
    rd: &mut Round,
    crits: &Criteria,
    at: LoadAt,
) -> Result<(Realized, Option<ReductionFigures>, Option<MimoStateSpace>)> {
    Ok(match reduce_block(rd, crits, at, full_load, None)? {
        None => (realized, None, None),
        Some((fig, Some(reduced), _)) => (reduced, Some(fig), Some(realized.0)),
        Some((fig, None, _)) => (realized, Some(fig), None),
    })
}

/// The chosen round `rd`, whose full compensator cannot go into an image
/// (`why`: it needs more sections or taps than the kernel holds, or does
/// not verify), reduced by balancing its 3x3 rows' block to the highest
/// order that is realized, verified and within the load limit, on the same
/// terms as [`reduce_to_load`]. `Ok(Err(figures))` where no reduction is
/// used (the figures say why; `None` without a 3x3 block); otherwise the
/// reduced realization, the figures and the full compensator.
pub(super) fn reduce_to_realize(
    rd: &mut Round,
    crits: &Criteria,
    at: LoadAt,
    why: String,
) -> Result<std::result::Result<(Realized, ReductionFigures, MimoStateSpace), Option<ReductionFigures>>> {
    Ok(match reduce_block(rd, crits, at, 0, Some(why))? {
        Some((fig, Some(reduced), full)) => Ok((reduced, fig, full)),
        Some((fig, None, _)) => Err(Some(fig)),
        None => Err(None),
    })
}

/// The figures of the balanced reduction of `rd`'s 3x3 rows' block that
/// fits `at`, the reduction where it is used, and `rd`'s full compensator
/// (`None` where `rd` has no 3x3 block). The reduction is used (and
/// `rd.axes` take its predictions) only where every 3x3 row still beats
/// the per-axis row and every row beats no compensation, as the judge sees
/// them; otherwise the figures say why.
fn reduce_block(
    rd: &mut Round,
    crits: &Criteria,
    at: LoadAt,
    full_load: u32,
    full_not_realized: Option<String>,
) -> Result<Option<(ReductionFigures, Option<Realized>, MimoStateSpace)>> {
    let (blocks, full) = blocks_of(rd)?;
    let Some((matrix_block, other)) = blocks.split_first() else { return Ok(None) };
    let for_image = full_not_realized.is_some();
    let full_predicted = rd.predicted();
    let mut fig = ReductionFigures {
        used: false,
        reason: String::new(),
        full_states: matrix_block.a.nrows(),
        states: 0,
        method: Reduction::SingularPerturbation,
        hankel_bound: f64::NAN,
        full_load_permille: full_load,
        load_permille: 0,
        full_predicted,
        predicted: [f64::NAN; 3],
        full_not_realized,
    };
    let bal = match balance(matrix_block) {
        Ok(b) => b,
        Err(e) => {
            fig.reason = format!("{e:#}");
            return Ok(Some((fig, None, full)));
        }
    };
    let worst = |c: &Candidate| (0..3).map(|i| c.errors[i].error / full_predicted[i]).fold(0.0, f64::max);
    let best = fitting(&bal, other, rd.lag, crits, at).into_iter().min_by(|a, b| worst(a).total_cmp(&worst(b)));
    let Some(c) = best else {
        fig.reason = format!(
            "no balanced reduction of the {}-state 3x3 block is realized within the load limit",
            matrix_block.a.nrows()
        );
        return Ok(Some((fig, None, full)));
    };
    (fig.states, fig.method, fig.load_permille) = (c.states, c.method, c.load);
    fig.hankel_bound = bal.error_bound(c.states);
    fig.predicted = std::array::from_fn(|i| c.errors[i].error);
    let worse: Vec<String> = rd
        .axes
        .iter()
        .enumerate()
        .filter_map(|(i, a)| {
            let j = c.judged[i].error;
            let per_axis = a.per_axis_judged.map_or(f64::INFINITY, |p| p.error);
            if !(j < a.raw.error) {
                Some(format!("{} {:.3} % against {:.3} % uncompensated", a.axis, 100.0 * j, 100.0 * a.raw.error))
            } else if a.source == RowSource::Matrix && !(j < per_axis) {
                Some(format!("{} {:.3} % against {:.3} % per axis", a.axis, 100.0 * j, 100.0 * per_axis))
            } else {
                None
            }
        })
        .collect();
    if !worse.is_empty() {
        fig.reason = format!(
            "the {}-state reduction that fits the box is worse than the alternatives on {} (judged on the per-axis \
             fits); {}",
            c.states,
            worse.join(", "),
            if for_image { "the 3x3 rows are not used" } else { "the full filter is kept" }
        );
        return Ok(Some((fig, None, full)));
    }
    fig.used = true;
    let purpose = if for_image { "to go into an image" } else { "to fit the box" };
    fig.reason = format!(
        "the 3x3 block is reduced from {} to {} states {purpose}; every 3x3 row still beats its per-axis row",
        fig.full_states, c.states
    );
    let noise_gains = c.realized.0.white_noise_gains();
    for (i, a) in rd.axes.iter_mut().enumerate() {
        if a.source != RowSource::Matrix {
            continue;
        }
        a.chosen = c.errors[i];
        if let Some(ng) = &noise_gains {
            a.noise_gain = ng[i];
        }
        a.reason.push_str(&format!(
            "; reduced to {} states {}: {:.3} % (full filter {:.3} %)",
            c.states,
            if for_image { "for the image" } else { "for the box" },
            100.0 * c.errors[i].error,
            100.0 * full_predicted[i]
        ));
    }
    Ok(Some((fig, Some(c.realized), full)))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn figures(full_not_realized: Option<String>) -> ReductionFigures {
        ReductionFigures {
            used: true,
            reason: "fits".into(),
            full_states: 108,
            states: 30,
            method: Reduction::SingularPerturbation,
            hankel_bound: 0.01,
            full_load_permille: if full_not_realized.is_some() { 0 } else { 1023 },
            load_permille: 595,
            full_predicted: [0.0968, 0.0978, 0.0284],
            predicted: [0.0968, 0.0978, 0.0284],
            full_not_realized,
        }
    }

    /// A reduction made because the full filter does not go into an image
    /// says so and why, without a load the full filter never had; and it
    /// reads back from a sidecar. Control: the load reduction's line.
    #[test]
    fn a_reduction_for_the_kernel_says_why_the_full_filter_does_not_go_into_an_image() {
        let why = "the 3x3 compensator needs 53 sections and 24 FIR taps, the kernel holds 48 and 24".to_string();
        let line = figures(Some(why.clone())).line();
        assert!(line.starts_with("reduced for the image (the full filter: "), "{line}");
        assert!(line.contains(&why) && line.contains("load 59.5 %") && !line.contains("0.0 ->"), "{line}");
        let text = serde_json::to_string(&figures(Some(why.clone()))).unwrap();
        assert_eq!(serde_json::from_str::<ReductionFigures>(&text).unwrap(), figures(Some(why)));
        let control = figures(None).line();
        assert!(control.starts_with("reduced for the box: ") && control.contains("load 102.3 -> 59.5 %"), "{control}");
        // A sidecar written before the key existed reads as a load reduction.
        let old = serde_json::to_string(&figures(None)).unwrap();
        assert!(!old.contains("full_not_realized"), "{old}");
        assert_eq!(serde_json::from_str::<ReductionFigures>(&old).unwrap(), figures(None));
    }
}
