//! Which latency round's compensator goes into the image, and in what form:
//! the rule's choice, its reduction, the next round, or the per-axis rows
//! ([`realize_chosen`]). The choice is kept apart from the work it orders
//! (realizing, reducing, pricing a filter: [`Realizing`]), so that every
//! branch is tested on rounds whose outcomes are set by hand.

use anyhow::{Context, Result};

use super::reduce::{self, LoadAt, ReductionFigures};
use super::{
    percent_xyz, realize_round, refuse_unless_better_than_raw, rule_prefers, Criteria, Realized, Round, RowSource,
};
use crate::numeric::lti::MimoStateSpace;

/// A reduction that is used (the reduced realization, its figures and the
/// full compensator), or the figures that say why none is (`None` without
/// a 3x3 block).
pub(super) type Reduced<R, F> = std::result::Result<(R, ReductionFigures, F), Option<ReductionFigures>>;

/// The work [`realize_chosen`] orders on a round.
pub(super) trait Realizing {
    /// A compensator realized and verified in f32.
    type Realized;
    /// The full compensator a reduction was made from.
    type Full;
    /// `rd`'s compensator, realized and verified in f32 ([`realize_round`]).
    fn realize(&self, rd: &Round) -> Result<Self::Realized>;
    /// `rd`'s 3x3 block reduced to what goes into an image within `at`
    /// ([`reduce::reduce_to_realize`]); `why` the full one does not.
    fn reduce(&self, rd: &mut Round, at: LoadAt, why: String) -> Result<Reduced<Self::Realized, Self::Full>>;
    /// The box load of a realized filter (‰ of the sample period, high estimate).
    fn load(&self, r: &Self::Realized) -> u32;
}

/// The design's own work: realized and verified in f32 up to `at.f_band`,
/// reduced by balancing on `crits`, priced by the box's cost model.
pub(super) struct InF32<'a> {
    pub crits: &'a Criteria,
    pub fs: f64,
    pub f_band: f64,
}

impl Realizing for InF32<'_> {
    type Realized = Realized;
    type Full = MimoStateSpace;

    fn realize(&self, rd: &Round) -> Result<Realized> {
        realize_round(rd, self.fs, self.f_band)
    }

    fn reduce(&self, rd: &mut Round, at: LoadAt, why: String) -> Result<Reduced<Realized, MimoStateSpace>> {
        reduce::reduce_to_realize(rd, self.crits, at, why)
    }

    fn load(&self, r: &Realized) -> u32 {
        reduce::filter_load(&r.1 .1, self.fs)
    }
}

/// The round chosen and its realization ([`realize_chosen`]).
pub(super) struct Chosen<R, F> {
    pub round: Round,
    pub realized: R,
    /// Why the 3x3 rows were dropped, where they were.
    pub dropped: Option<String>,
    /// Where the full compensator of the rule's choice cannot go into an
    /// image but a reduction of its 3x3 block can: the reduction's figures
    /// and the full compensator (`realized` is the reduced one).
    pub reduced: Option<(ReductionFigures, F)>,
}

/// The first of the `ranked` rounds ([`super::rank_rounds`]) whose
/// compensator is realized and verified in f32, never an unverified one:
/// 1. the rule's choice;
/// 2. where its 3x3 rows do not verify (or need more sections than the
///    kernel holds), the rule's choice with its 3x3 block reduced by
///    balancing ([`reduce::reduce_to_realize`]), where every 3x3 row still
///    beats its per-axis row, within the box's load limit;
/// 3. else the next round (latency) by the rule whose 3x3 rows verify and
///    that beats no compensation, with a note, where the box runs it;
///    where it is over the load limit too (the image is offline-only at
///    any latency), the rule's choice reduced to the highest order that
///    verifies, unless the latency rule prefers the next round's filter to
///    that reduction ([`rule_prefers`], on their predictions);
/// 4. else the choice with every axis on its per-axis row, with a note,
///    and why the 3x3 rows were dropped.
pub(super) fn realize_chosen<Z: Realizing>(
    z: &Z,
    ranked: Vec<Round>,
    notes: &mut Vec<String>,
    at: LoadAt,
) -> Result<Chosen<Z::Realized, Z::Full>> {
    let mut ranked = ranked.into_iter();
    let mut rd = ranked.next().context("no latency round")?;
    let err = match z.realize(&rd) {
        Ok(realized) => return Ok(Chosen { round: rd, realized, dropped: None, reduced: None }),
        Err(e) if rd.rows.contains(&RowSource::Matrix) => e,
        Err(e) => return Err(e),
    };
    let boxed = match z.reduce(&mut rd, at, format!("{err:#}"))? {
        Ok((realized, fig, full)) => {
            return Ok(Chosen { round: rd, realized, dropped: None, reduced: Some((fig, full)) });
        }
        Err(fig) => fig,
    };
    let alt = ranked
        .filter(|a| a.rows.contains(&RowSource::Matrix) && refuse_unless_better_than_raw(a).is_ok())
        .find_map(|a| z.realize(&a).ok().map(|r| (a, r)));
    let alt_on_the_box = alt.as_ref().is_some_and(|(_, r)| z.load(r) <= at.limit);
    let mut reduced_lost = None;
    if let Some(boxed) = boxed.as_ref().filter(|_| !alt_on_the_box && at.limit < u32::MAX) {
        // The image is offline-only whichever latency it holds: the rule's
        // choice reduced to the highest order that verifies (`compensate`),
        // where the latency rule prefers it to the next latency's filter.
        let offline = LoadAt { limit: u32::MAX, ..at };
        if let Ok((realized, fig, full)) = z.reduce(&mut rd, offline, format!("{err:#}"))? {
            let three = |rd: &Round| percent_xyz(&rd.predicted());
            let reduced = format!(
                "latency {}'s 3x3 block reduced to {} states for an offline-only image predicts {} %",
                rd.lag,
                fig.states,
                three(&rd)
            );
            match &alt {
                Some((a, _)) if rule_prefers(a, &rd) => {
                    reduced_lost = Some(format!("{reduced}, latency {} {} %", a.lag, three(a)));
                }
                _ => {
                    // No order at all within the limit leaves no figures to
                    // compare: say what the limit leaves instead.
                    let why_not = match boxed.states {
                        0 => format!("none fits the load limit of {:.1} %", f64::from(at.limit) / 10.0),
                        n => format!("{n} states: {} %", percent_xyz(&boxed.predicted)),
                    };
                    notes.push(format!(
                        "the box runs no reduction of latency {}'s 3x3 block that beats the alternatives ({why_not}){}: \
                         the image, offline-only, holds the highest-order reduction that verifies in f32",
                        rd.lag,
                        alt.as_ref().map_or(String::new(), |(a, _)| format!(
                            "; latency {}'s filter, over the load limit too, predicts {} % against {} % by the \
                             latency rule",
                            a.lag,
                            three(a),
                            three(&rd)
                        ))
                    ));
                    return Ok(Chosen { round: rd, realized, dropped: None, reduced: Some((fig, full)) });
                }
            }
        }
    }
    notes.extend(boxed.map(|f| f.line()));
    if let Some((alt, r)) = alt {
        notes.push(format!(
            "latency {}: {err:#}; latency {} is used instead, the next by the latency rule whose 3x3 rows verify{}",
            rd.lag,
            alt.lag,
            reduced_lost.map_or(String::new(), |r| format!(" (by the same rule: {r})"))
        ));
        return Ok(Chosen { round: alt, realized: r, dropped: None, reduced: None });
    }
    if !rd.per_axis.iter().all(Option::is_some) {
        return Err(err);
    }
    notes.push(format!("the 3x3 rows were not used: {err:#}; every axis is designed per axis"));
    for (a, d) in rd.axes.iter_mut().zip(&rd.per_axis) {
        if a.source == RowSource::Matrix {
            a.noise_gain = d.as_ref().map_or(f64::NAN, |d| d.noise_gain);
            a.source = RowSource::PerAxis;
            a.chosen = a.per_axis.expect("per-axis design present");
            a.reason = "per-axis row: the 3x3 compensator does not verify in f32".to_string();
        }
    }
    rd.rows = [RowSource::PerAxis; 3];
    let realized = z.realize(&rd)?;
    Ok(Chosen { round: rd, realized, dropped: Some(format!("{err:#}")), reduced: None })
}

#[cfg(test)]
mod tests {
    use std::collections::HashMap;

    use anyhow::bail;

    use super::*;
    use crate::design::mimo::tests::round_predicting;
    use crate::numeric::balanced::Reduction;

    const BOX: LoadAt = LoadAt { fs: 51_200.0, limit: 600, f_band: 4000.0 };

    /// What realizing a round at each latency gives: `Ok(load ‰)` or the
    /// reason it does not verify; and what its 3x3 block's reduction gives
    /// for the box (`box_reduced`) and for an offline-only image
    /// (`offline_reduced`): the reduced states and the error (%) each axis
    /// then predicts, where one is used.
    #[derive(Default)]
    struct Outcomes {
        realize: HashMap<usize, std::result::Result<u32, &'static str>>,
        box_reduced: HashMap<usize, (usize, f64)>,
        offline_reduced: HashMap<usize, (usize, f64)>,
        /// Where the box gets no reduction: whether no order at all is
        /// within the load limit (else a 24-state one is worse than per axis).
        box_fits_no_order: bool,
    }

    fn figures(states: usize, used: bool) -> ReductionFigures {
        ReductionFigures {
            used,
            reason: if used { "reduced".into() } else { "worse than per axis".into() },
            full_states: 60,
            states,
            method: Reduction::SingularPerturbation,
            hankel_bound: 0.1,
            full_load_permille: 0,
            load_permille: 550,
            full_predicted: [0.003; 3],
            predicted: [0.004; 3],
            full_not_realized: Some("too many sections".into()),
        }
    }

    /// Realized: (latency, load ‰); full compensator: its latency.
    impl Realizing for Outcomes {
        type Realized = (usize, u32);
        type Full = usize;

        fn realize(&self, rd: &Round) -> Result<(usize, u32)> {
            match self.realize.get(&rd.lag) {
                Some(Ok(load)) => Ok((rd.lag, *load)),
                Some(Err(why)) => bail!("{why}"),
                None => bail!("latency {} not set", rd.lag),
            }
        }

        fn reduce(&self, rd: &mut Round, at: LoadAt, _why: String) -> Result<Reduced<(usize, u32), usize>> {
            let table = if at.limit == u32::MAX { &self.offline_reduced } else { &self.box_reduced };
            Ok(match table.get(&rd.lag) {
                Some(&(states, percent)) => {
                    // As the reduction does: the axes take its predictions.
                    for a in &mut rd.axes {
                        a.chosen.error = percent / 100.0;
                    }
                    Ok(((rd.lag, 550), figures(states, true), rd.lag))
                }
                None => Err(Some(figures(if self.box_fits_no_order { 0 } else { 24 }, false))),
            })
        }

        fn load(&self, r: &(usize, u32)) -> u32 {
            r.1
        }
    }

    /// The choice the fake's outcomes lead to: (latency, load ‰) realized.
    type FakeChosen = Chosen<(usize, u32), usize>;

    fn choose(z: &Outcomes, rounds: Vec<Round>) -> (Result<FakeChosen>, Vec<String>) {
        let mut notes = Vec::new();
        let chosen = realize_chosen(z, rounds, &mut notes, BOX);
        (chosen, notes)
    }

    /// The rule's choice, latency 8, and the next by the latency rule,
    /// latency 6, which predicts 1.33x more error.
    fn eight_then_six() -> Vec<Round> {
        vec![round_predicting(8, [0.30, 0.30, 0.30]), round_predicting(6, [0.40, 0.40, 0.40])]
    }

    const FAILS: std::result::Result<u32, &str> = Err("the 3x3 rows do not verify in f32");

    #[test]
    fn the_rules_choice_is_kept_where_it_verifies() {
        let z = Outcomes { realize: HashMap::from([(8, Ok(400)), (6, Ok(300))]), ..Default::default() };
        let (c, notes) = choose(&z, eight_then_six());
        let c = c.unwrap();
        assert_eq!((c.round.lag, c.realized, c.reduced.is_none()), (8, (8, 400), true));
        assert!(notes.is_empty(), "{notes:?}");
    }

    #[test]
    fn a_reduction_for_the_box_comes_before_another_latency() {
        let z = Outcomes {
            realize: HashMap::from([(8, FAILS), (6, Ok(300))]),
            box_reduced: HashMap::from([(8, (40, 0.32))]),
            ..Default::default()
        };
        let (c, _) = choose(&z, eight_then_six());
        let c = c.unwrap();
        assert_eq!(c.round.lag, 8);
        assert_eq!(c.reduced.map(|(f, full)| (f.states, full)), Some((40, 8)));
    }

    /// The path the box runs when the rule's choice cannot go into an image
    /// in any form that fits: the next latency, with a note that names both.
    #[test]
    fn the_next_latency_is_used_instead_where_the_box_runs_it() {
        // Latency 8 reduced for an offline-only image would predict less
        // error, but the box runs latency 6 and not that.
        let z = Outcomes {
            realize: HashMap::from([(8, FAILS), (6, Ok(450))]),
            offline_reduced: HashMap::from([(8, (70, 0.33))]),
            ..Default::default()
        };
        let (c, notes) = choose(&z, eight_then_six());
        let c = c.unwrap();
        assert_eq!((c.round.lag, c.realized, c.dropped, c.reduced.is_none()), (6, (6, 450), None, true));
        let used = notes.iter().find(|n| n.contains("is used instead")).expect("a note on the latency used");
        assert!(used.starts_with("latency 8: the 3x3 rows do not verify in f32; latency 6 is used instead"), "{used}");
        assert!(!used.contains("by the same rule"), "{used}");
        // The box reduction's figures say why it was not used.
        assert!(
            notes.iter().any(|n| n.starts_with("not reduced for the image") && n.contains("24 states")),
            "{notes:?}"
        );
    }

    /// Control: a next latency that does not beat no compensation is passed
    /// over for the one after it; with none left, the design fails with the
    /// rule's choice's own error (no per-axis rows to fall back on here).
    #[test]
    fn a_next_latency_worse_than_raw_is_never_used_instead() {
        let rounds = || {
            let mut r = eight_then_six();
            r[1] = round_predicting(6, [0.31, 60.0, 0.31]); // raw is 50 %
            r.push(round_predicting(4, [0.45, 0.45, 0.45]));
            r
        };
        let z = Outcomes { realize: HashMap::from([(8, FAILS), (6, Ok(300)), (4, Ok(200))]), ..Default::default() };
        let (c, notes) = choose(&z, rounds());
        assert_eq!(c.unwrap().round.lag, 4);
        assert!(notes.iter().any(|n| n.contains("latency 4 is used instead")), "{notes:?}");

        let z = Outcomes { realize: HashMap::from([(8, FAILS), (6, Ok(300)), (4, FAILS)]), ..Default::default() };
        let (c, _) = choose(&z, rounds());
        let e = c.err().expect("no round to use");
        assert_eq!(format!("{e:#}"), "the 3x3 rows do not verify in f32");
    }

    /// Where the next latency is over the load limit too, the image is
    /// offline-only either way: the rule's choice reduced, unless the
    /// latency rule prefers the next latency's full filter to it.
    #[test]
    fn offline_only_either_way_the_latency_rule_decides() {
        let z = |reduced_percent: f64| Outcomes {
            realize: HashMap::from([(8, FAILS), (6, Ok(700))]),
            offline_reduced: HashMap::from([(8, (70, reduced_percent))]),
            ..Default::default()
        };
        // Reduced, latency 8 predicts 0.33 %: latency 6's 0.40 % is 1.21x
        // that, over the rule's 1.1x, so the reduction goes into the image.
        let (c, notes) = choose(&z(0.33), eight_then_six());
        let c = c.unwrap();
        assert_eq!((c.round.lag, c.reduced.as_ref().map(|r| r.0.states)), (8, Some(70)));
        assert!(c.round.predicted().iter().all(|&e| e == 0.0033));
        let n = notes.iter().find(|n| n.starts_with("the box runs no reduction")).expect("offline-only note");
        assert!(n.contains("latency 6's filter, over the load limit too, predicts 0.400 / 0.400 / 0.400 %"), "{n}");
        assert!(!notes.iter().any(|n| n.contains("is used instead")), "{notes:?}");
        assert!(n.contains("beats the alternatives (24 states: 0.400 / 0.400 / 0.400 %)"), "{n}");
        // Where no order of the block is within the limit, the note says so
        // (it gave "0 states: NaN / NaN / NaN %").
        let (_, notes) = choose(&Outcomes { box_fits_no_order: true, ..z(0.33) }, eight_then_six());
        let n = notes.iter().find(|n| n.starts_with("the box runs no reduction")).expect("offline-only note");
        assert!(n.contains("beats the alternatives (none fits the load limit of 60.0 %)"), "{n}");

        // Control: reduced, latency 8 predicts 0.60 %: latency 6 is used, and
        // the note says the rule preferred it to the reduction.
        let (c, notes) = choose(&z(0.60), eight_then_six());
        let c = c.unwrap();
        assert_eq!((c.round.lag, c.realized, c.reduced.is_none()), (6, (6, 700), true));
        let used = notes.iter().find(|n| n.contains("is used instead")).expect("a note on the latency used");
        assert!(
            used.contains(
                "(by the same rule: latency 8's 3x3 block reduced to 70 states for an offline-only image predicts \
                 0.600 / 0.600 / 0.600 %, latency 6 0.400 / 0.400 / 0.400 %)"
            ),
            "{used}"
        );
    }

    /// Without a load limit (`--max-load` not given) the next latency that
    /// verifies is used, whatever its load.
    #[test]
    fn without_a_load_limit_the_next_latency_is_used() {
        let z = Outcomes {
            realize: HashMap::from([(8, FAILS), (6, Ok(900))]),
            offline_reduced: HashMap::from([(8, (70, 0.33))]),
            ..Default::default()
        };
        let mut notes = Vec::new();
        let c = realize_chosen(&z, eight_then_six(), &mut notes, LoadAt { limit: u32::MAX, ..BOX }).unwrap();
        // The unlimited "box" reduction is the offline one, used first.
        assert_eq!((c.round.lag, c.reduced.map(|r| r.0.states)), (8, Some(70)));
        let z = Outcomes { realize: HashMap::from([(8, FAILS), (6, Ok(900))]), ..Default::default() };
        let c = realize_chosen(&z, eight_then_six(), &mut notes, LoadAt { limit: u32::MAX, ..BOX }).unwrap();
        assert_eq!(c.round.lag, 6);
    }

    /// A round without 3x3 rows that does not verify is an error as it is.
    #[test]
    fn per_axis_rows_that_do_not_verify_fail_the_design() {
        let mut r = eight_then_six();
        r[0].rows = [RowSource::PerAxis; 3];
        let z = Outcomes { realize: HashMap::from([(8, FAILS), (6, Ok(300))]), ..Default::default() };
        let (c, notes) = choose(&z, r);
        assert!(c.is_err() && notes.is_empty());
    }
}
