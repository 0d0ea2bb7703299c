//! What a look-ahead longer than the box's would reach, for an axis the box
//! filter leaves far behind `compensate --offline`.
//!
//! The box runs fixed-lag smoothers of at most 8 samples
//! (`crate::design::latency::LONGEST_LATENCY`): past
//! that the realization does not verify in f32 (BENCHMARKS.md, "Past 8
//! samples"). The zero-lag smoother of `--offline` has no such limit. Between
//! the two lie the fixed-lag smoothers of 16-64 samples, which the design can
//! predict but not ship. Where, for the force record's spectrum, the box's
//! predicted error is over 1 % and twice `--offline`'s, the summary says
//! which of them would close the gap, so that a user who needs the force in
//! real time knows what delay it costs and whether any does.
//!
//! Not for a flat force (the default) nor `--force-prior level`: on the
//! random-set-up sweep the flat predictions of a longer look-ahead were
//! 0.07-10x what it measured on the cut, against 0.95-1.08x for the cut's
//! spectrum (BENCHMARKS.md, "Longer look-aheads than the box's").

use serde::Serialize;

use crate::design::axis::{predict_prepared, AxisDesign, DesignOptions, PreparedAxis};
use crate::design::criterion::OFFLINE_MUCH_BETTER;
use crate::design::kalman::KalmanDesign;
use crate::frf::axis_name;

/// The look-aheads predicted beyond the box's (samples).
pub const LOOK_AHEADS: [usize; 3] = [16, 32, 64];
/// A box prediction (with the fit's uncertainty) under this (fraction) is
/// not worth a longer look-ahead, whatever `--offline` reaches.
pub const BOX_FALLS_SHORT: f64 = 0.01;
/// A look-ahead whose prediction is within this factor of `--offline`'s
/// leaves nothing for a longer one: the search stops there.
pub const CLOSE_TO_OFFLINE: f64 = 1.25;

/// One axis's predictions beyond the box's look-ahead.
#[derive(Clone, Debug, Serialize)]
pub struct LookAhead {
    /// Axis index (0 = x).
    pub axis: usize,
    /// The box image's latency (samples).
    pub box_latency: usize,
    /// The longest latency the box runs (samples).
    pub box_longest: usize,
    /// The box filter's predicted in-band error (fraction, the fit's
    /// uncertainty counted).
    pub box_predicted: f64,
    /// `compensate --offline`'s (same terms).
    pub offline_predicted: f64,
    /// Each longer latency tried (samples) and its predicted error (same
    /// terms; `None` where no q gave a design).
    pub tried: Vec<(usize, Option<f64>)>,
    /// The design at each latency of `tried` (f64, never realized: for
    /// scoring against a truth, `crate::eval::rates`).
    #[serde(skip)]
    pub designs: Vec<Option<KalmanDesign>>,
}

impl LookAhead {
    /// The shortest latency tried whose prediction is under half the box's
    /// ([`OFFLINE_MUCH_BETTER`]), with it.
    pub fn enough(&self) -> Option<(usize, f64)> {
        self.tried
            .iter()
            .find_map(|(l, e)| e.filter(|e| *e < OFFLINE_MUCH_BETTER * self.box_predicted).map(|e| (*l, e)))
    }
}

/// Whether `d`, the box's design with `opts`, falls short enough of
/// `--offline` for longer look-aheads to be predicted: designed for a force
/// record's spectrum, its prediction over [`BOX_FALLS_SHORT`] and over
/// 1/[`OFFLINE_MUCH_BETTER`] times `--offline`'s (both with the fit's
/// uncertainty).
pub fn wanted(d: &AxisDesign, opts: &DesignOptions) -> bool {
    if !opts.look_ahead_every_axis.is_empty() {
        return d.pass_through.is_none();
    }
    let (rt, off) = (d.predicted_error_with_fit(), d.offline_predicted_with_fit());
    let for_the_cut = opts.force_record.is_some() && !opts.force_record_level_only && d.force_spectrum.is_some();
    for_the_cut && d.pass_through.is_none() && rt > BOX_FALLS_SHORT && off < OFFLINE_MUCH_BETTER * rt
}

/// The predictions of `p` at each of [`LOOK_AHEADS`] beside `d`, its box
/// design at `opts.lag`, on a box that runs at most `box_longest` samples
/// (`None` unless [`wanted`]). Stops at the first
/// within [`CLOSE_TO_OFFLINE`] of `--offline`. With
/// `opts.look_ahead_every_axis`, each of those instead, to the last.
pub fn look_ahead(p: &PreparedAxis, opts: &DesignOptions, d: &AxisDesign, box_longest: usize) -> Option<LookAhead> {
    if !wanted(d, opts) {
        return None;
    }
    let offline = d.offline_predicted_with_fit();
    let (mut tried, mut designs) = (Vec::new(), Vec::new());
    let study = !opts.look_ahead_every_axis.is_empty();
    let lags = if study { opts.look_ahead_every_axis.as_slice() } else { &LOOK_AHEADS[..] };
    for &lag in lags {
        let (e, k) = predict_prepared(p, &DesignOptions { lag, ..opts.clone() }).ok().unzip();
        tried.push((lag, e));
        designs.push(k);
        if !study && e.is_some_and(|e| e <= CLOSE_TO_OFFLINE * offline) {
            break;
        }
    }
    Some(LookAhead {
        axis: d.axis,
        box_latency: opts.lag,
        box_longest,
        box_predicted: d.predicted_error_with_fit(),
        offline_predicted: offline,
        tried,
        designs,
    })
}

/// The summary's line on `l` at `fs_hz`: "axis x: the box filter (latency
/// 6, 0.59 ms) predicts 17.16 % and compensate --offline 1.19 %; a longer
/// look-ahead would predict 12.43 % at 16, 7.13 % at 32, 2.44 % at 64
/// samples; the shortest under half the box's error is 32 samples (3.12 ms),
/// past the 8 the box runs, so only compensate --offline gets there" (the
/// random sweep's seed 26), or that none up to the longest tried halves it.
pub fn note(l: &LookAhead, fs_hz: f64) -> String {
    let ms = |n: usize| 1e3 * n as f64 / fs_hz;
    let pct = |e: f64| format!("{:.2} %", 100.0 * e);
    let tried: Vec<String> = l
        .tried
        .iter()
        .map(|(n, e)| match e {
            Some(e) => format!("{} at {n}", pct(*e)),
            None => format!("no design at {n}"),
        })
        .collect();
    let verdict = match l.enough() {
        Some((n, _)) => format!(
            "the shortest under half the box's error is {n} samples ({:.2} ms), past the {} the box runs, so only \
             compensate --offline gets there",
            ms(n),
            l.box_longest
        ),
        None => {
            let n = l.tried.last().map_or(0, |t| t.0);
            format!(
                "no look-ahead up to {n} samples ({:.2} ms) halves the box's error; compensate --offline, which sees \
             the whole record, does",
                ms(n)
            )
        }
    };
    format!(
        "axis {}: the box filter (latency {}, {:.2} ms) predicts {} and compensate --offline {}; a longer look-ahead \
         would predict {} samples; {verdict}",
        axis_name(l.axis),
        l.box_latency,
        ms(l.box_latency),
        pct(l.box_predicted),
        pct(l.offline_predicted),
        tried.join(", ")
    )
}

/// Keep only the look-aheads of axes whose box design is still the one
/// they were predicted beside: an axis replaced after the latency choice
/// (a band-fitted axis by the default design,
/// `crate::design::versus_default`) is in `replaced`, and its
/// look-ahead, predicted beside the design it no longer has, goes.
pub fn retain_current(look_ahead: &mut Vec<LookAhead>, replaced: &[usize]) {
    look_ahead.retain(|l| !replaced.contains(&l.axis));
}

#[cfg(test)]
mod tests {
    use super::*;

    fn l(tried: Vec<(usize, Option<f64>)>) -> LookAhead {
        LookAhead {
            axis: 1,
            box_latency: 8,
            box_longest: 8,
            box_predicted: 0.137,
            offline_predicted: 0.0014,
            tried,
            designs: Vec::new(),
        }
    }

    #[test]
    fn the_note_names_the_shortest_look_ahead_that_halves_the_box_error() {
        let a = l(vec![(16, Some(0.09)), (32, Some(0.05)), (64, Some(0.0016))]);
        assert_eq!(a.enough(), Some((32, 0.05)));
        let n = note(&a, 25_600.0);
        assert!(
            n.contains("axis y: the box filter (latency 8, 0.31 ms) predicts 13.70 % and compensate --offline 0.14 %"),
            "{n}"
        );
        assert!(n.contains("9.00 % at 16, 5.00 % at 32, 0.16 % at 64 samples"), "{n}");
        assert!(n.contains("is 32 samples (1.25 ms)"), "{n}");
        // Control: none under half (6.85 %): said so, with the longest tried.
        let b = l(vec![(16, Some(0.12)), (32, None), (64, Some(0.07))]);
        assert_eq!(b.enough(), None);
        let n = note(&b, 25_600.0);
        assert!(n.contains("no design at 32"), "{n}");
        assert!(n.contains("no look-ahead up to 64 samples (2.50 ms) halves"), "{n}");
    }

    #[test]
    fn a_replaced_axis_loses_the_look_ahead_of_the_design_it_no_longer_has() {
        let mut all = vec![LookAhead { axis: 0, ..l(Vec::new()) }, l(Vec::new())];
        retain_current(&mut all, &[0]);
        assert_eq!(all.iter().map(|l| l.axis).collect::<Vec<_>>(), [1]);
        // Control: nothing replaced, nothing dropped.
        let mut all = vec![LookAhead { axis: 0, ..l(Vec::new()) }, l(Vec::new())];
        retain_current(&mut all, &[]);
        assert_eq!(all.len(), 2);
    }
}
