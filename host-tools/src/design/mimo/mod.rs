//! The 3x3 design: from the full FRF matrix to one verified 3-in, 3-out
//! compensator that counts the crosstalk (DESIGN.md, "Signal chain": the
//! dynamometer as one 3x3 system). [`design_matrix`] runs the per-axis chain
//! on the matrix with [`discrete`], [`kalman`] and [`criterion`], and hands
//! the result to [`crate::realize::mimo`] for the f32 kernel.

#![allow(clippy::needless_range_loop)] // axis indices index several per-axis arrays at once

mod choose;
pub mod combine;
pub mod criterion;
pub mod discrete;
pub mod image;
pub mod kalman;
pub mod reduce;
pub mod response;
pub mod worse_than_raw;

use anyhow::{bail, Context, Result};
use dynocomp_core::mimo::MimoFilter;
use num_complex::Complex64;
use serde::Serialize;

use self::choose::{realize_chosen, Chosen, InF32};
use self::combine::combine;
pub use self::combine::RowSource;
use self::criterion::{choose_q, ForceWeights, MatrixCriterion, QSearch, RowError};
use self::discrete::{discretize_matrix, plant_states, CMatrix3, DiscreteMatch, DiscreteMatrixModel, PlantStates};
use self::kalman::{augmented_plant, augmented_plant_shaped, MatrixAugmentedPlant, MatrixKalman};
use self::response::PlantResolvent;
use crate::design::above_band::AboveBand;
use crate::design::axis::{
    coherent_band, design_prepared, prepare_axis, AxisDesign, DesignOptions, FitMethod, PreparedAxis, MAX_FIT_ERROR,
    MAX_PREDICTED_ERROR,
};
use crate::design::discretize::{Discretization, MATCH_BAND_FRACTION};
use crate::design::kalman::ForceShape;
use crate::design::latency::{DEFAULT_LATENCY, GAIN_NOT_WORTH, LONGER_LATENCIES, LONGEST_LATENCY, PREDICTED_SHORT};
pub use crate::fit::line_noise::LineWeights;
use crate::fit::matrix::{matrix_fit_stages, MatrixData, MatrixFitStages, MatrixModel};
use crate::fit::refine::FitCovariance;
use crate::fit::relative_rms_error;
use crate::fit::vf::{coherence_weights, VfOptions};
use crate::frf::{axis_name, entry_name, Frf};
use crate::numeric::lti::MimoStateSpace;
use crate::numeric::parallel::map_on_threads;
use crate::realize::mimo::{realize_blocks, MimoRealization, MimoVerification};

/// Where the 3x3 design reports its stages (it takes up to a minute).
pub use crate::design::progress::Progress;

/// Options of the 3x3 design.
#[derive(Clone, Debug, Default)]
pub struct MatrixOptions {
    /// Where the stages are reported (`None`: nowhere).
    pub progress: Option<Progress>,
    /// The per-axis design's options: rate, force RMS, noise-gain limit,
    /// coherence threshold, fit options, q override. Fitting bands, the
    /// paper's method, hold discretizations and force records are not
    /// supported by the 3x3 design yet (refused).
    pub design: DesignOptions,
    /// Declared latency L (samples); `None`: chosen by the latency rule
    /// ([`design_matrix`]).
    pub latency: Option<usize>,
    /// In-band force RMS per axis F_j (N) of the criterion; `None`:
    /// `design.force_rms` on every axis.
    pub force_rms_axes: Option<[f64; 3]>,
    /// Options of the matrix fit; `None`: `design.vf` (the per-axis fits')
    /// with the highest order [`MATRIX_MAX_ORDER`].
    pub matrix_vf: Option<VfOptions>,
    /// The box's load limit (‰ of the sample period) the filter is reduced
    /// to where it is over it ([`reduce`]); `None`: never reduced.
    pub load_limit_permille: Option<u32>,
    /// Design on the refined fit alone, without the retry on the fit
    /// without the refinement where a 3x3 row loses to its per-axis row
    /// ([`retry_unrefined`]); for controls.
    pub refined_only: bool,
}

/// Highest order of the matrix fit by default: every mode of the set-up is
/// in the one model (a per-axis fit sees only those of its entry).
pub const MATRIX_MAX_ORDER: usize = 40;
/// Pole-relocation iterations per order of the matrix fit by default. The
/// plate dynamometer's rocking modes come in close pairs (e.g. 211 and
/// 213 Hz of the off-centre preset) that 8 iterations merge into one pole,
/// leaving 1-2 % model error at the tooth-passing harmonics next to them;
/// 20 separate them (measured on the presets at 25.6 kHz).
pub const MATRIX_ITERATIONS: usize = 20;
/// Largest condition number of the measured FRF matrix on a coherent line
/// of the compensated band: beyond it the three channels do not see three
/// independent forces and no 3x3 inverse exists.
pub const MAX_MATRIX_CONDITION: f64 = 1e6;

/// The fit of the matrix, for the summary.
#[derive(Clone, Debug, Serialize)]
pub struct MatrixFitFigures {
    /// Model order (poles, a pair counting two).
    pub order: usize,
    /// Weighted RMS residual over all entries.
    pub weighted_rms: f64,
    /// `(order, weighted_rms)` of every order tried.
    pub order_trace: Vec<(usize, f64)>,
    /// Per entry the relative RMS error on its coherent lines in its row's
    /// compensated band (`[i][j]`; NaN without such lines).
    pub entry_error: [[f64; 3]; 3],
    /// Natural frequencies (Hz) and damping ratios of the pairs.
    pub modes: Vec<(f64, f64)>,
    /// Natural frequencies (Hz) of the pairs the fit dropped because the
    /// lines do not support them ([`crate::fit::matrix::drop_unsupported_pairs`]).
    pub dropped_hz: Vec<f64>,
    /// Frequencies (Hz) where the fit added a pair because its residual
    /// exceeded the noise there ([`crate::fit::matrix::MatrixFit::seeded_hz`]).
    pub seeded_hz: Vec<f64>,
    /// Pairs whose residues are one mode shape, c·bᵀ
    /// ([`crate::fit::rank_one`]; σ₂/σ₁ of the residue under 10⁻⁹).
    pub rank_one_pairs: usize,
}

/// The peak crosstalk |G_ij|/|G_ii| over the compensated band (coherent
/// lines of both entries), per entry.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct Crosstalk {
    /// Peak |G_ij|/|G_ii| (`[i][j]`; 1 on the diagonal, NaN without lines).
    pub peak: [[f64; 3]; 3],
    /// Where it peaks (Hz).
    pub at_hz: [[f64; 3]; 3],
}

/// One output axis's predictions (√J, fractions of the force's RMS, with
/// the crosstalk counted, on the 3x3 model) and which row was used: the one
/// with the smaller error on the measured matrix ([`Criteria`]).
#[derive(Clone, Debug, Serialize)]
pub struct AxisPrediction {
    /// Axis letter.
    pub axis: &'static str,
    /// Compensated band (Hz).
    pub band_hz: (f64, f64),
    /// No compensation.
    pub raw: RowError,
    /// The per-axis design (`None` where it failed).
    pub per_axis: Option<RowError>,
    /// What the per-axis design predicts for itself, ignoring the crosstalk.
    pub per_axis_direct_only: Option<f64>,
    /// The 3x3 design's row (`None` where it failed).
    pub matrix: Option<RowError>,
    /// The per-axis design's error as the judge of the choice sees it
    /// ([`Criteria`]; `None` where it failed).
    pub per_axis_judged: Option<RowError>,
    /// The 3x3 row's error as the judge sees it.
    pub matrix_judged: Option<RowError>,
    /// The row used.
    pub source: RowSource,
    /// Its prediction.
    pub chosen: RowError,
    /// Why that row.
    pub reason: String,
    /// White-noise gain of the row used (RMS ratio for unit noise on every input).
    pub noise_gain: f64,
    /// What `compensate --offline` on the image predicts for the 3x3 row
    /// ([`offline_prediction`]; `None` where there is no 3x3 design).
    pub offline: Option<RowError>,
}

/// The 3x3 Kalman design's figures.
#[derive(Clone, Debug, Serialize)]
pub struct KalmanFigures {
    /// q per force axis (N²/sample).
    pub q: [f64; 3],
    /// Measurement noise per channel (N²).
    pub r: [f64; 3],
    /// Compensator order (states).
    pub order: usize,
    /// DARE residual relative to its terms.
    pub dare_residual: f64,
    /// Doubling steps.
    pub dare_iterations: usize,
    /// Condition number of the innovation covariance.
    pub innovation_condition: f64,
    /// Spectral radius of the compensator.
    pub closed_loop_radius: f64,
    /// White-noise gain per output.
    pub noise_gains: [f64; 3],
    /// The q search.
    pub q_search: QSearch,
    /// The band-limited force model per force direction
    /// ([`crate::design::above_band`]); `None`: the random walk (the exact
    /// inverse continues above the band).
    pub force_shape: [Option<ForceShape>; 3],
}

/// The plant realization's figures.
#[derive(Clone, Debug, Serialize)]
pub struct PlantFigures {
    /// Plant states.
    pub states: usize,
    /// Rank kept of each discrete pole's residue.
    pub ranks: Vec<usize>,
    /// Force-error bound of the dropped rank.
    pub dropped_bound: f64,
    /// Realization against the pole-residue form.
    pub realization_error: f64,
}

/// The realization's figures: what the box runs.
#[derive(Clone, Debug, Serialize)]
pub struct RealizationFigures {
    /// Upper end of the band the f32 filter is verified over (Hz).
    pub verified_to_hz: f64,
    /// Pole-pair sections.
    pub pairs: usize,
    /// Diagonal sections (two real poles each).
    pub diagonal: usize,
    /// FIR taps (3x3 each).
    pub fir_taps: usize,
    /// Largest modal-transform condition number.
    pub modal_condition: f64,
    /// Largest cluster-decoupling norm.
    pub decoupling_norm: f64,
    /// Largest truncated FIR tail (relative).
    pub fir_truncation: f64,
    /// The f32 verification.
    pub verification: MimoVerification,
}

/// One latency designed: each axis's chosen predicted error (`None` where
/// neither design worked).
#[derive(Clone, Debug, Serialize)]
pub struct LatencyRound {
    /// Latency (samples).
    pub latency: usize,
    /// Chosen √J per axis.
    pub predicted: [Option<f64>; 3],
}

/// Every figure of a 3x3 design (serializable, for the summary and `--json`).
#[derive(Clone, Debug, Serialize)]
pub struct MatrixSummary {
    /// Sample rate (Hz).
    pub fs_hz: f64,
    /// Declared latency L (samples).
    pub latency: usize,
    /// The latencies designed.
    pub latency_rounds: Vec<LatencyRound>,
    /// The fit (`None` where it failed; the notes say why).
    pub fit: Option<MatrixFitFigures>,
    /// The discrete model's match.
    pub discrete: Option<DiscreteMatch>,
    /// The plant's realization.
    pub plant: Option<PlantFigures>,
    /// The 3x3 Kalman design at the chosen latency.
    pub kalman: Option<KalmanFigures>,
    /// Per output axis.
    pub axes: Vec<AxisPrediction>,
    /// The crosstalk in the measured FRFs.
    pub crosstalk: Crosstalk,
    /// The realization the box runs.
    pub realization: RealizationFigures,
    /// Output rows whose lines the image's filter leaves further from the
    /// force than raw ([`worse_than_raw`]).
    pub worse_than_raw: Vec<worse_than_raw::RowWorse>,
    /// The reduction to the box's load limit, where the full filter is over
    /// it ([`reduce`]).
    pub reduction: Option<reduce::ReductionFigures>,
    /// The forces the predictions are for: "a flat force", or the
    /// record's spectrum or level with its mean force.
    pub forces: String,
    /// Whether the predictions are for a flat force (`forces` is
    /// [`FLAT_FORCE`]), not a record's.
    pub flat_force: bool,
    /// Notes for the user.
    pub notes: Vec<String>,
}

/// Everything the 3x3 design made.
#[derive(Clone, Debug)]
pub struct MatrixDesign {
    /// The figures.
    pub summary: MatrixSummary,
    /// The fitted model Ĝ (`None` where the fit failed).
    pub model: Option<MatrixModel>,
    /// The discrete model and its plant states.
    pub discrete: Option<(DiscreteMatrixModel, PlantStates)>,
    /// The 3x3 Kalman design at the chosen latency.
    pub kalman: Option<MatrixKalman>,
    /// The per-axis designs at the chosen latency.
    pub per_axis: Vec<Option<AxisDesign>>,
    /// Which row each output axis uses.
    pub rows: [RowSource; 3],
    /// The combined compensator y → F̂[k−L] (f64).
    pub compensator: MimoStateSpace,
    /// Its realization (f64).
    pub realization: MimoRealization,
    /// The f32 filter the box runs.
    pub filter: MimoFilter,
    /// The full compensator where the image holds its reduction to the
    /// box's load limit ([`reduce`]; `None`: not reduced).
    pub full_compensator: Option<MimoStateSpace>,
}

impl MatrixDesign {
    /// The augmented plant of the 3x3 model at latency `lag`: the model of
    /// an offline smoother (`None` where the 3x3 model failed).
    pub fn augmented_plant(&self, lag: usize) -> Option<MatrixAugmentedPlant> {
        self.discrete.as_ref().map(|(dm, plant)| augmented_plant(dm, plant, lag))
    }
}

/// The 3x3 model's part that does not depend on the latency.
struct MatrixPrep {
    fit: MatrixFitFigures,
    model: MatrixModel,
    dm: DiscreteMatrixModel,
    matching: DiscreteMatch,
    plant: PlantStates,
    /// Where `model` has close modes split ([`crate::fit::matrix::MatrixFit::splits`]),
    /// the order search's own model, for a design its 3x3 rows cannot use.
    unsplit: Option<GivenModel>,
    /// Where `model` is the refined fit, what finishes the same fit without
    /// the refinement, for a design whose 3x3 rows lose to per-axis rows on
    /// the refined one ([`retry_unrefined`]).
    plain: Option<Unrefined>,
    /// How the fit weighted its lines, for its covariance.
    line_weights: LineWeights,
}

/// The order search of a refined 3x3 fit, kept to finish it without the
/// refinement (vector fitting's own model) only where a design needs it.
struct Unrefined {
    stages: MatrixFitStages,
    /// The refined fit's options.
    vf: VfOptions,
    /// Whether the refined design took the model with close modes split.
    split: bool,
}

impl Unrefined {
    /// The fit without its refinement, split or not as the refined model
    /// was taken.
    fn model(&self, frf: &Frf) -> Result<GivenModel> {
        let plain = VfOptions { refine: false, ..self.vf.clone() };
        let (split, unsplit) = finished_models(frf, &self.stages, &plain)?;
        Ok(match unsplit {
            Some(u) if !self.split => u,
            _ => split,
        })
    }
}

/// A 3x3 model the design takes instead of fitting one: with the figures of
/// its fit (NaN and none for a model from elsewhere).
struct GivenModel {
    model: MatrixModel,
    weighted_rms: f64,
    order_trace: Vec<(usize, f64)>,
    dropped_hz: Vec<f64>,
    seeded_hz: Vec<f64>,
    /// How its fit weighted the lines, for its covariance.
    line_weights: LineWeights,
}

/// One latency's designs.
struct Round {
    lag: usize,
    per_axis: Vec<Option<AxisDesign>>,
    matrix: Option<(MatrixKalman, QSearch, [f64; 3])>,
    /// Why there is no 3x3 design where the model exists.
    matrix_error: Option<String>,
    axes: Vec<AxisPrediction>,
    rows: [RowSource; 3],
}

impl Round {
    /// The predicted in-band error of each axis's chosen row (fractions).
    fn predicted(&self) -> [f64; 3] {
        std::array::from_fn(|i| self.axes[i].chosen.error)
    }

    /// The largest ratio, over the axes, of this round's predicted error to
    /// `best` (the latency rule's measure).
    fn worst_ratio(&self, best: &[f64; 3]) -> f64 {
        self.predicted().iter().zip(best).map(|(e, b)| e / b).fold(0.0, f64::max)
    }
}

/// Three predicted errors as percentages, "x / y / z" to 0.001 %.
fn percent_xyz(v: &[f64; 3]) -> String {
    v.map(|e| format!("{:.3}", 100.0 * e)).join(" / ")
}

/// Design the 3x3 compensator of the complete FRF matrix `frf` for the
/// measurement noise variances `r` (N², per channel).
///
/// The chain of the per-axis design on the matrix:
/// 1. fit all nine FRFs with common poles ([`crate::fit::matrix`]);
/// 2. the discrete model of the sampled-data relation and its plant states
///    ([`discrete`]);
/// 3. the disturbance Kalman filter and fixed-lag smoother with a
///    3-component force state ([`kalman`]), q per output axis by the
///    predicted in-band error counting the crosstalk ([`criterion`]);
/// 4. beside it the per-axis design of each direct FRF
///    ([`crate::design::axis`], unchanged), its prediction now with the
///    crosstalk it leaves;
/// 5. per output axis the row with less error on the measured matrix (never
///    silently worse: the 3x3 row only where it beats the per-axis one
///    there, `Criteria`), as one block-diagonal compensator (`combine`);
/// 6. realized and verified in f32 for the one 3x3 kernel
///    ([`crate::realize::mimo`]);
/// 7. where its filter is over `opts.load_limit_permille`, its 3x3 block
///    reduced by balancing to one that fits, if every 3x3 row still beats
///    its per-axis row ([`reduce`]);
/// 8. where a 3x3 row lost to its per-axis row, all of it again on the fit
///    without its refinement, kept if its rows judge better
///    ([`retry_unrefined`]).
///
/// The latency follows the per-axis rule ([`crate::design::latency`]):
/// [`DEFAULT_LATENCY`], and [`LONGER_LATENCIES`] only where an axis's best
/// row predicts more than [`PREDICTED_SHORT`] of distortion, keeping the
/// shortest within [`GAIN_NOT_WORTH`] of each axis's best.
pub fn design_matrix(frf: &Frf, r: [f64; 3], opts: &MatrixOptions) -> Result<MatrixDesign> {
    design(frf, r, opts, None, Vec::new())
}

/// [`design_matrix`] on a given 3x3 model instead of the fit of `frf` (the
/// FRF still gives the bands, the per-axis designs and the model's error
/// against the measurement): for studies with a known model, e.g. the
/// simulator's exact one.
pub fn design_matrix_with_model(
    frf: &Frf,
    model: MatrixModel,
    r: [f64; 3],
    opts: &MatrixOptions,
) -> Result<MatrixDesign> {
    design(
        frf,
        r,
        opts,
        Some(GivenModel {
            model,
            weighted_rms: f64::NAN,
            order_trace: Vec::new(),
            dropped_hz: Vec::new(),
            seeded_hz: Vec::new(),
            line_weights: LineWeights::PerLine,
        }),
        Vec::new(),
    )
}

/// The design on the fit of `frf`, or on the `given` model, after the
/// `notes` of an earlier try.
fn design(
    frf: &Frf,
    r: [f64; 3],
    opts: &MatrixOptions,
    given: Option<GivenModel>,
    mut notes: Vec<String>,
) -> Result<MatrixDesign> {
    let d = &opts.design;
    check_options(frf, r, opts)?;
    let bands = compensated_bands(frf, d)?;
    check_invertible(frf, &bands, d.coherence_threshold)?;
    let crosstalk = crosstalk_of(frf, &bands, d.coherence_threshold);
    // The per-axis rows are fitted without seeding
    // ([`crate::fit::vf::VfOptions::seed_unfitted`]): with it, on the
    // off-centre plate at 10.24 kHz designed for its record, the rows'
    // changed predictions moved the design's choices, and the zero-lag
    // smoother's x went 0.52 → 0.72 % against the box's 0.55 %
    // (BENCHMARKS.md, "Missing modes seeded per axis").
    let per_axis_d =
        DesignOptions { vf: crate::fit::vf::VfOptions { seed_unfitted: false, ..d.vf.clone() }, ..d.clone() };
    let prepared: Vec<Result<PreparedAxis>> =
        (0..3).map(|i| prepare_axis(&frf.freq_hz, frf.axis(i).expect("complete"), r[i], &per_axis_d)).collect();
    for (i, p) in prepared.iter().enumerate() {
        if let Err(e) = p {
            notes.push(format!("axis {}: no per-axis design: {e:#}", axis_name(i)));
        }
    }
    let mut prep = fit_stage(frf, &bands, opts, given, &prepared, &mut notes);
    let plain = prep.as_mut().and_then(|p| p.plain.take());
    let (criterion, flat) = criteria(frf, &prepared, prep.as_ref(), bands, r, opts, &mut notes)?;
    let rounds = latency_rounds(&prepared, prep.as_ref(), &criterion, r, opts);
    opts.say("realizing the compensator and verifying it in f32…");
    let (ranked, latency_rounds) = rank_rounds(rounds);
    refuse_unless_better_than_raw(&ranked[0])?;
    let f_band = bands.iter().map(|b| b.1).fold(0.0, f64::max);
    let at = reduce::LoadAt { fs: d.fs_hz, limit: opts.load_limit_permille.unwrap_or(u32::MAX), f_band };
    let Chosen { round: mut chosen, realized, dropped, reduced } =
        realize_chosen(&InF32 { crits: &criterion, fs: d.fs_hz, f_band }, ranked, &mut notes, at)?;
    if let (Some(err), Some(unsplit)) = (dropped, prep.as_mut().and_then(|p| p.unsplit.take())) {
        // The 3x3 rows of the model with close modes split do not verify
        // (or do not fit the kernel): the order search's model, once.
        opts.say("the 3x3 compensator of the split model does not verify: designing on the unsplit model…");
        let note = format!(
            "the 3x3 model with close modes fitted as two pairs each gave a compensator that does not verify ({err}); \
             the order search's model (close modes as one pair) is used"
        );
        return design(frf, r, opts, Some(unsplit), vec![note]);
    }
    let full_load = reduce::filter_load(&realized.1 .1, d.fs_hz);
    let (realized, reduction, full_compensator) = match (reduced, opts.load_limit_permille) {
        // Reduced already, within the load limit, because the full filter
        // does not go into an image.
        (Some((fig, full)), _) => (realized, Some(fig), Some(full)),
        (None, Some(limit)) if full_load > limit && chosen.rows.contains(&RowSource::Matrix) => {
            opts.say(&format!(
                "the filter needs {:.1} % of the box's sample period (limit {:.1} %): reducing it…",
                f64::from(full_load) / 10.0,
                f64::from(limit) / 10.0
            ));
            reduce::reduce_to_load(realized, full_load, &mut chosen, &criterion, at)?
        }
        _ => (realized, None, None),
    };
    let offline = prep.as_ref().zip(chosen.matrix.as_ref()).and_then(|(p, (k, _, _))| {
        opts.say("predicting compensate --offline on the image…");
        offline_prediction(p, &criterion.model, k.q, r, d)
    });
    if let Some(off) = offline {
        chosen.axes.iter_mut().zip(off).for_each(|(a, o)| a.offline = Some(o));
    }
    if flat {
        notes.extend(moderate_crosstalk_caveat(&chosen.axes, &crosstalk));
    } else {
        notes.extend(offline_note(&chosen.axes, chosen.lag));
    }
    notes.extend(level_prior_caveat(d, flat));
    let shapes = force_shapes(&criterion.model, d);
    let mut md = finish(shapes, chosen, realized, prep, crosstalk, latency_rounds, notes, d.fs_hz, f_band)?;
    md.summary.reduction = reduction;
    md.summary.flat_force = flat;
    md.summary.forces = match (flat, d.force_record_level_only) {
        (true, _) => FLAT_FORCE,
        (false, true) => "the record's force level and mean force",
        (false, false) => "the record's force spectrum and mean force",
    }
    .to_string();
    md.full_compensator = full_compensator;
    md.summary.worse_than_raw = worse_than_raw::rows_worse_than_raw(&md, &frf.freq_hz);
    match plain {
        Some(plain) if !opts.refined_only => retry_unrefined(frf, r, opts, md, &plain),
        _ => Ok(md),
    }
}

/// Where a 3x3 row of the design `md` on the refined fit loses to its
/// per-axis row, the design on the same fit without the refinement
/// (`plain`), kept where its rows have less error as the rows are judged
/// ([`judged_errors`]: each model with its direct entries replaced by the
/// per-axis fits, which both share); the summary says which and why.
///
/// The refinement moves the fit's poles and residues to the likeliest ones
/// on the lines, where the lines say nothing above the band; a 3x3 model can
/// then carry a right-half-plane transmission zero just above the band that
/// no causal compensator inverts, and its rows near the band's top fail
/// (BENCHMARKS.md, "Twelve independent plates").
fn retry_unrefined(
    frf: &Frf,
    r: [f64; 3],
    opts: &MatrixOptions,
    mut md: MatrixDesign,
    plain: &Unrefined,
) -> Result<MatrixDesign> {
    let lost: Vec<&str> = md
        .summary
        .axes
        .iter()
        .filter(|a| a.source == RowSource::PerAxis && a.matrix.is_some())
        .map(|a| a.axis)
        .collect();
    if lost.is_empty() {
        return Ok(md);
    }
    opts.say("a 3x3 row loses to its per-axis row on the refined fit: designing on the fit without the refinement…");
    let before = judged_errors(&md);
    let why = format!("on the refined 3x3 fit the 3x3 row of {} lost to the per-axis row; ", lost.join(", "));
    match plain.model(frf).and_then(|m| design(frf, r, opts, Some(m), Vec::new())) {
        Ok(mut alt) => {
            let after = judged_errors(&alt);
            let sq = |e: &[f64; 3]| e.iter().map(|v| v * v).sum::<f64>();
            let show = |e: &[f64; 3]| e.map(|v| format!("{:.3}", 100.0 * v)).join(" / ");
            if sq(&after) < sq(&before) {
                alt.summary.notes.push(format!(
                    "{why}the fit without the refinement (vector fitting's own model) is used: judged on the per-axis fits, \
                     x / y / z {} % against {} % on the refined fit",
                    show(&after),
                    show(&before)
                ));
                return Ok(alt);
            }
            md.summary.notes.push(format!(
                "{why}the fit without the refinement does no better (judged on the per-axis fits, x / y / z {} % against {} %)",
                show(&after),
                show(&before)
            ));
        }
        Err(e) => md.summary.notes.push(format!("{why}the fit without the refinement gives no design: {e:#}")),
    }
    Ok(md)
}

/// Each output axis's error judged on the per-axis fits (the criterion that
/// chose its row, [`Criteria`]), of the row it uses.
fn judged_errors(md: &MatrixDesign) -> [f64; 3] {
    std::array::from_fn(|i| {
        let a = &md.summary.axes[i];
        let judged = match a.source {
            RowSource::Matrix => a.matrix_judged,
            RowSource::PerAxis => a.per_axis_judged,
        };
        judged.map_or(a.chosen.error, |j| j.error)
    })
}

impl MatrixOptions {
    /// Report a stage line, if anyone listens.
    fn say(&self, line: &str) {
        if let Some(p) = &self.progress {
            p.say(line);
        }
    }
}

/// Each output axis's compensated band: its direct FRF's coherent band,
/// below [`MATCH_BAND_FRACTION`]·fs.
fn compensated_bands(frf: &Frf, d: &DesignOptions) -> Result<[(f64, f64); 3]> {
    let f_cap = MATCH_BAND_FRACTION * d.fs_hz;
    let bands: [(f64, f64); 3] = std::array::from_fn(|i| {
        let a = frf.axis(i).expect("checked complete");
        let b = coherent_band(&frf.freq_hz, a, d.coherence_threshold);
        (b.0, b.1.min(f_cap))
    });
    for (i, b) in bands.iter().enumerate() {
        if !(b.1 > b.0) {
            bail!(
                "axis {}: no coherent band below 0.45 fs (coherence ≥ {}); repeat the impact test",
                axis_name(i),
                d.coherence_threshold
            );
        }
    }
    Ok(bands)
}

/// The common-pole fit of the matrix (or the `given` model), its discrete
/// model and plant; `None`, with a note, where it fails (every axis is then
/// designed per axis).
fn fit_stage(
    frf: &Frf,
    bands: &[(f64, f64); 3],
    opts: &MatrixOptions,
    given: Option<GivenModel>,
    prepared: &[Result<PreparedAxis>],
    notes: &mut Vec<String>,
) -> Option<MatrixPrep> {
    let d = &opts.design;
    let vf = VfOptions {
        f_ceiling_hz: crate::fit::refine::ceiling_hz(d.fs_hz),
        ..opts.matrix_vf.clone().unwrap_or(VfOptions {
            max_order: MATRIX_MAX_ORDER,
            iterations: d.vf.iterations.max(MATRIX_ITERATIONS),
            ..d.vf.clone()
        })
    };
    if given.is_none() {
        opts.say(&format!(
            "fitting the nine FRFs with common poles (order up to {}, {} iterations per order)…",
            vf.max_order, vf.iterations
        ));
    }
    let t = std::time::Instant::now();
    let prepared_model = match given {
        Some(g) => prepare_model(frf, bands, d.fs_hz, d.coherence_threshold, g),
        None => matrix_stages(frf, bands, &vf).and_then(|(stages, vf)| {
            match prepare_matrix(frf, bands, d.fs_hz, &stages, &vf, d.coherence_threshold, prepared) {
                Ok(mut p) => {
                    if vf.refine {
                        p.plain = Some(Unrefined { stages, vf, split: p.unsplit.is_some() });
                    }
                    Ok(p)
                }
                Err(e) => {
                    // The refined model (`fit::refine`) can sit where the discrete
                    // model or its realization refuses it (the off-centre plate at
                    // 51.2 kHz on 8 Hz lines: realization 3.7e-4 from the
                    // pole-residue form, limit 2e-4); vector fitting's own model
                    // then, once, and the summary says so.
                    if !vf.refine {
                        return Err(e);
                    }
                    opts.say("the refined 3x3 model gives no plant: the same fit without the refinement…");
                    let plain = VfOptions { refine: false, ..vf.clone() };
                    let p = prepare_matrix(frf, bands, d.fs_hz, &stages, &plain, d.coherence_threshold, prepared)?;
                    notes.push(format!(
                        "the 3x3 fit refined to its maximum-likelihood model gave no plant ({e:#}); vector fitting's model is used"
                    ));
                    Ok(p)
                }
            }
        }),
    };
    match prepared_model {
        Ok(p) => {
            opts.say(&format!("  fit: order {}, {:.1} s", p.fit.order, t.elapsed().as_secs_f64()));
            Some(p)
        }
        Err(e) => {
            notes.push(format!("no 3x3 design: {e:#}; every axis is designed per axis, crosstalk not compensated"));
            None
        }
    }
}

/// The criterion on the model and the judge ([`Criteria`]) for flat forces
/// or the record's (`--force-prior spectrum|level`, with a note), and
/// whether the forces are flat.
fn criteria(
    frf: &Frf,
    prepared: &[Result<PreparedAxis>],
    prep: Option<&MatrixPrep>,
    bands: [(f64, f64); 3],
    r: [f64; 3],
    opts: &MatrixOptions,
    notes: &mut Vec<String>,
) -> Result<(Criteria, bool)> {
    let d = &opts.design;
    let model_g = |f: f64| match prep {
        Some(p) => p.model.frf(f),
        None => measured_matrix_model(frf, f),
    };
    let forces = match &d.force_record {
        None => ForceWeights::Flat(opts.force_rms_axes.unwrap_or([d.force_rms; 3])),
        Some(rec) => {
            let w = ForceWeights::from_record(rec, &model_g, bands, d.fs_hz, r, d.force_record_level_only)?;
            let what = if d.force_record_level_only { "level" } else { "spectrum" };
            notes.push(format!(
                "q and the choice of rows are for the force {what} of {} (--force-prior {what}), not a flat spectrum",
                rec.source
            ));
            w
        }
    };
    // The judge: each direct entry from its own per-axis fit (independent of
    // the common-pole fit, and closer to its entry), the cross entries from
    // the common-pole fit. At 0 Hz, the line of a record's mean force, the
    // common-pole fit's static gains throughout: there the per-axis fits
    // are the less accurate (BENCHMARKS.md, "The cut's mean force").
    let judge_g = |f: f64| {
        let mut g = model_g(f);
        if f == 0.0 {
            return g;
        }
        for (i, p) in prepared.iter().enumerate() {
            if let Ok(p) = p {
                g[(i, i)] = p.model_frf(f);
            }
        }
        g
    };
    let criteria = Criteria {
        judge: MatrixCriterion::new(judge_g, bands, d.fs_hz, &forces, r),
        model: MatrixCriterion::new(model_g, bands, d.fs_hz, &forces, r)
            .quiet_above_band(if quiet_above_band(d) { d.above_band.out_of_band_weight() } else { 0.0 })
            .with_fit_covariance(|freqs| fit_covariance(frf, prep, freqs)),
    };
    Ok((criteria, matches!(forces, ForceWeights::Flat(_))))
}

/// The rounds at [`DEFAULT_LATENCY`] (or the asked-for latency), and at
/// [`LONGER_LATENCIES`] where an axis's best row predicts more than
/// [`PREDICTED_SHORT`] of distortion ([`design_matrix`]).
fn latency_rounds(
    prepared: &[Result<PreparedAxis>],
    prep: Option<&MatrixPrep>,
    criterion: &Criteria,
    r: [f64; 3],
    opts: &MatrixOptions,
) -> Vec<Round> {
    let timed_round = |l: usize| {
        opts.say(&format!("3x3 Kalman smoother and per-axis designs at latency {l}: choosing q…"));
        let t = std::time::Instant::now();
        let rd = round(l, prepared, prep, criterion, r, &opts.design);
        opts.say(&format!("  latency {l}: {:.1} s", t.elapsed().as_secs_f64()));
        rd
    };
    let mut rounds = vec![timed_round(opts.latency.unwrap_or(DEFAULT_LATENCY))];
    if opts.latency.is_none() && rounds[0].axes.iter().any(|a| a.chosen.distortion > PREDICTED_SHORT) {
        // The longer latencies are independent: on the machine's cores.
        rounds.extend(map_on_threads(&LONGER_LATENCIES, |l| timed_round(*l)));
    }
    rounds
}

/// The rounds in the latency rule's order of preference, with every round's
/// predictions. First the shortest latency within [`GAIN_NOT_WORTH`] of each
/// axis's best (as the per-axis rule, [`crate::design::latency`]), or, where
/// the axes' bests lie at different latencies and none is within it on every
/// axis, the one of least worst ratio to them; then the others by that
/// ratio (what [`realize_chosen`] falls back on).
fn rank_rounds(mut rounds: Vec<Round>) -> (Vec<Round>, Vec<LatencyRound>) {
    let latency_rounds: Vec<LatencyRound> =
        rounds.iter().map(|rd| LatencyRound { latency: rd.lag, predicted: rd.predicted().map(Some) }).collect();
    let best: [f64; 3] =
        std::array::from_fn(|i| rounds.iter().map(|rd| rd.predicted()[i]).fold(f64::INFINITY, f64::min));
    let first = rounds.iter().position(|rd| rd.worst_ratio(&best) <= GAIN_NOT_WORTH);
    let mut ranked = Vec::with_capacity(rounds.len());
    if let Some(k) = first {
        ranked.push(rounds.remove(k));
    }
    rounds.sort_by(|a, b| a.worst_ratio(&best).total_cmp(&b.worst_ratio(&best)));
    ranked.extend(rounds);
    (ranked, latency_rounds)
}

/// Whether the latency rule ([`rank_rounds`]) between rounds `a` and `b`
/// chooses `a`: the shorter latency where it is within [`GAIN_NOT_WORTH`]
/// of the better of the two on every axis, else the longer where it is,
/// else the one with the smaller worst ratio.
fn rule_prefers(a: &Round, b: &Round) -> bool {
    let (pa, pb) = (a.predicted(), b.predicted());
    let best: [f64; 3] = std::array::from_fn(|i| pa[i].min(pb[i]));
    let (short_is_a, short, long) = if a.lag <= b.lag { (true, a, b) } else { (false, b, a) };
    let (short_ratio, long_ratio) = (short.worst_ratio(&best), long.worst_ratio(&best));
    let short_wins = short_ratio <= GAIN_NOT_WORTH || (long_ratio > GAIN_NOT_WORTH && short_ratio <= long_ratio);
    short_wins == short_is_a
}

/// Never worse than no compensation: refuse the design where an axis's
/// chosen row does not beat it (or is over [`MAX_PREDICTED_ERROR`]).
fn refuse_unless_better_than_raw(chosen: &Round) -> Result<()> {
    for a in &chosen.axes {
        let worse = !(a.chosen.error < a.raw.error);
        if !worse && a.chosen.error < MAX_PREDICTED_ERROR {
            continue;
        }
        let why = match worse {
            true => "beats no compensation".to_string(),
            false => format!(
                "compensates usefully (a predicted error above {:.0} % says little more than the force's mean)",
                100.0 * MAX_PREDICTED_ERROR
            ),
        };
        bail!(
            "axis {}: neither the 3x3 nor the per-axis compensator at latency {} {why} in its band ({:.0}–{:.0} Hz): \
             predicted {:.2} % against {:.2} % uncompensated (crosstalk counted); no image written. A longer \
             --latency gives the smoother more samples (without --latency the tool chooses up to {LONGEST_LATENCY}); \
             otherwise check the FRF (coherence, units N/N, resolution)",
            a.axis,
            chosen.lag,
            a.band_hz.0,
            a.band_hz.1,
            100.0 * a.chosen.error,
            100.0 * a.raw.error
        );
    }
    Ok(())
}

/// The note for 3x3 rows chosen for flat forces where the crosstalk is
/// below [`MODERATE_CROSSTALK`]: a cut's spectrum can reverse the choice.
fn moderate_crosstalk_caveat(axes: &[AxisPrediction], crosstalk: &Crosstalk) -> Option<String> {
    let peak = (0..9).filter(|e| e / 3 != e % 3).map(|e| crosstalk.peak[e / 3][e % 3]).fold(0.0, f64::max);
    let rows: Vec<&str> = axes.iter().filter(|a| a.source == RowSource::Matrix).map(|a| a.axis).collect();
    (!rows.is_empty() && peak < MODERATE_CROSSTALK).then(|| {
        format!(
            "the crosstalk is moderate (peak {:.0} %) and the 3x3 rows ({}) were chosen for flat forces across the \
             band, where the crosstalk near the sensor modes counts fully; a cut has its power at low harmonics, where \
             a per-axis row can be better: give a record of the cut (--force-prior spectrum --force-record CUT) to \
             choose for its spectrum, or check with compensate --truth",
            100.0 * peak,
            rows.join(", ")
        )
    })
}

/// The note for a design judged for a record's force level (`--force-prior
/// level`) and quiet above the band: its predictions assume that level
/// flat up to each band's top, where the quiet rows roll off, so on a cut
/// they tend to overstate the error (median 1.54 times the error delivered
/// over the 54 axes of BENCHMARKS.md, "Quiet above the band for a record").
fn level_prior_caveat(d: &DesignOptions, flat: bool) -> Option<String> {
    (!flat && d.force_record_level_only && quiet_above_band(d)).then(|| {
        "the predictions assume the record's force level spread flat up to each band's top, where this design is \
         quiet; a cut has most of its force at lower harmonics, so they tend to overstate its error: \
         --force-prior spectrum predicts for the record's own spectrum"
            .to_string()
    })
}

/// Refuse what the 3x3 design cannot do (yet), with the reason.
fn check_options(frf: &Frf, r: [f64; 3], opts: &MatrixOptions) -> Result<()> {
    let d = &opts.design;
    let status = frf.matrix_status();
    if !status.is_complete() {
        bail!(
            "the 3x3 design needs all nine FRFs: {}; measure the missing entries (an impact test in every hammer \
             direction, every channel recorded) to compensate the crosstalk",
            status.message().unwrap_or_default()
        );
    }
    if !matches!(d.method, FitMethod::Vf) {
        bail!("the 3x3 design supports the default method only (--method vf), not the paper's");
    }
    if !d.bands.is_empty() {
        bail!("the 3x3 design does not support fitting bands (--band, --spindle-rpm) yet");
    }
    if d.discretization != Discretization::Fit {
        bail!("the 3x3 design supports only the fitted discrete model (--discretization fit)");
    }
    for (i, v) in r.iter().enumerate() {
        if !(*v > 0.0 && v.is_finite()) {
            bail!("axis {}: measurement noise variance R = {v} N² must be positive and finite", axis_name(i));
        }
    }
    Ok(())
}

/// Refuse a measured matrix that is singular (condition number above
/// [`MAX_MATRIX_CONDITION`], or not finite) on a line of the compensated
/// bands where every entry is coherent: no 3x3 compensator can separate
/// the forces there.
fn check_invertible(frf: &Frf, bands: &[(f64, f64); 3], threshold: f64) -> Result<()> {
    let lo = bands.iter().map(|b| b.0).fold(f64::INFINITY, f64::min);
    let hi = bands.iter().map(|b| b.1).fold(0.0, f64::max);
    let entries: Vec<_> = (0..9).map(|e| frf.entry(e / 3, e % 3).expect("complete")).collect();
    for (k, f) in frf.freq_hz.iter().enumerate() {
        if *f < lo || *f > hi || entries.iter().any(|e| e.coherence.is_some_and(|c| c[k] < threshold)) {
            continue;
        }
        let g = frf.matrix_at(k).expect("complete");
        let sv = g.singular_values();
        let condition = sv.max() / sv.min();
        if !(condition <= MAX_MATRIX_CONDITION) {
            bail!(
                "the measured FRF matrix is singular at {f:.1} Hz (condition number {condition:.1e}, limit {MAX_MATRIX_CONDITION:.0e}): \
                 the three channels do not see three independent forces; check the channel and hammer-direction \
                 mapping (a repeated or mislabelled file), or design per axis from the direct FRFs"
            );
        }
    }
    Ok(())
}

/// Ĝ(j2πf) by linear interpolation of the measured lines (where the 3x3
/// fit failed: the predictions then read the measurement itself).
fn measured_matrix_model(frf: &Frf, f: f64) -> CMatrix3 {
    let k = frf.freq_hz.partition_point(|x| *x < f).clamp(1, frf.freq_hz.len() - 1);
    let (f0, f1) = (frf.freq_hz[k - 1], frf.freq_hz[k]);
    let t = ((f - f0) / (f1 - f0)).clamp(0.0, 1.0);
    let (a, b) = (frf.matrix_at(k - 1).expect("complete"), frf.matrix_at(k).expect("complete"));
    a * Complex64::new(1.0 - t, 0.0) + b * Complex64::new(t, 0.0)
}

/// Peak |G_ij|/|G_ii| per entry over each row's band, on the lines where
/// both entries are coherent.
fn crosstalk_of(frf: &Frf, bands: &[(f64, f64); 3], threshold: f64) -> Crosstalk {
    let mut x = Crosstalk { peak: [[f64::NAN; 3]; 3], at_hz: [[f64::NAN; 3]; 3] };
    for i in 0..3 {
        let direct = frf.entry(i, i).expect("complete");
        for j in 0..3 {
            let e = frf.entry(i, j).expect("complete");
            for (k, f) in frf.freq_hz.iter().enumerate() {
                let coherent = |c: Option<&[f64]>| c.is_none_or(|c| c[k] >= threshold);
                if *f < bands[i].0 || *f > bands[i].1 || !coherent(e.coherence) || !coherent(direct.coherence) {
                    continue;
                }
                let v = e.frf[k].norm() / direct.frf[k].norm();
                if x.peak[i][j].is_nan() || v > x.peak[i][j] {
                    x.peak[i][j] = v;
                    x.at_hz[i][j] = *f;
                }
            }
        }
    }
    x
}

/// `use_data` on the nine entries of the matrix `frf` with their coherence
/// weights ([`coherence_weights`]), as the common-pole fit takes them by
/// default; an error naming the first entry missing.
pub fn with_weighted_matrix<R>(frf: &Frf, use_data: impl FnOnce(&MatrixData) -> R) -> Result<R> {
    with_matrix_weighted_by(frf, LineWeights::PerLine, use_data)
}

/// [`with_weighted_matrix`] with the lines weighted as `weights` says.
pub fn with_matrix_weighted_by<R>(
    frf: &Frf,
    weights: LineWeights,
    use_data: impl FnOnce(&MatrixData) -> R,
) -> Result<R> {
    let entries = (0..9)
        .map(|e| {
            let (i, j) = (e / 3, e % 3);
            frf.entry(i, j).ok_or_else(|| anyhow::anyhow!("the FRF matrix has no G_{}", entry_name(i, j)))
        })
        .collect::<Result<Vec<_>>>()?;
    let weights: Vec<Vec<f64>> =
        entries.iter().map(|e| weights.apply(&frf.freq_hz, coherence_weights(e.frf, e.coherence))).collect();
    let data = MatrixData {
        freq_hz: &frf.freq_hz,
        h: std::array::from_fn(|e| entries[e].frf),
        w: std::array::from_fn(|e| weights[e].as_slice()),
    };
    Ok(use_data(&data))
}

/// The covariance of the common-pole fit's entries (e = 3i + j for
/// Ĝ_ij) at `freqs` from the lines it was fitted to
/// ([`crate::fit::refine::fit_covariance`]); `None` without a fit of these
/// lines (no model, or a model from elsewhere).
fn fit_covariance(frf: &Frf, prep: Option<&MatrixPrep>, freqs: &[f64]) -> Option<FitCovariance> {
    let p = prep.filter(|p| p.fit.weighted_rms.is_finite())?;
    with_matrix_weighted_by(frf, p.line_weights, |data| {
        let entries: Vec<(&[Complex64], &[f64])> = (0..9).map(|e| (data.h[e], data.w[e])).collect();
        crate::fit::refine::fit_covariance(data.freq_hz, &entries, &p.model.entries, freqs)
    })
    .ok()
    .flatten()
}

/// The common-pole fit of the matrix up to its refinement
/// ([`crate::fit::matrix::matrix_fit_stages`]), and the options it was
/// fitted with.
fn matrix_stages(frf: &Frf, bands: &[(f64, f64); 3], vf: &VfOptions) -> Result<(MatrixFitStages, VfOptions)> {
    // A real pole below the first coherent line of the bands is not kept.
    let vf = VfOptions { f_identified_hz: bands.iter().map(|b| b.0).fold(f64::INFINITY, f64::min), ..vf.clone() };
    let stages = with_matrix_weighted_by(frf, vf.line_weights, |data| matrix_fit_stages(data, &vf))?
        .context("fit of the 3x3 matrix")?;
    Ok((stages, vf))
}

/// Fit, discrete model and plant of the matrix (the latency-independent
/// part): `stages` finished with `vf`, its error scored on the lines of
/// coherence ≥ `threshold`.
fn prepare_matrix(
    frf: &Frf,
    bands: &[(f64, f64); 3],
    fs: f64,
    stages: &MatrixFitStages,
    vf: &VfOptions,
    threshold: f64,
    prepared: &[Result<PreparedAxis>],
) -> Result<MatrixPrep> {
    let (split, unsplit) = finished_models(frf, stages, vf)?;
    let Some(unsplit) = unsplit else {
        return prepare_model(frf, bands, fs, threshold, split);
    };
    // The split model only where its direct entries are nearer the
    // independent per-axis fits than the unsplit model's, and the chain
    // takes it (a discrete model or realization it refuses falls back).
    let distance = |m: &MatrixModel| direct_distance(m, prepared, bands, &frf.freq_hz);
    if distance(&split.model) < distance(&unsplit.model) {
        let order_trace = split.order_trace.clone();
        if let Ok(mut prep) = prepare_model(frf, bands, fs, threshold, split) {
            prep.unsplit = Some(unsplit);
            return Ok(prep);
        }
        return prepare_model(frf, bands, fs, threshold, GivenModel { order_trace, ..unsplit });
    }
    prepare_model(frf, bands, fs, threshold, unsplit)
}

/// `stages` finished with `vf`: its model, and where close modes were split
/// the order search's own model beside it, each with its weighted error.
fn finished_models(frf: &Frf, stages: &MatrixFitStages, vf: &VfOptions) -> Result<(GivenModel, Option<GivenModel>)> {
    let fit = with_matrix_weighted_by(frf, vf.line_weights, |data| stages.finish(data, vf))?
        .context("fit of the 3x3 matrix")?;
    let split = GivenModel {
        model: fit.model,
        weighted_rms: fit.weighted_rms,
        order_trace: fit.order_trace,
        dropped_hz: fit.dropped_hz,
        seeded_hz: fit.seeded_hz,
        line_weights: vf.line_weights,
    };
    let Some(unsplit) = fit.unsplit else {
        return Ok((split, None));
    };
    let rms = with_matrix_weighted_by(frf, vf.line_weights, |data| data.weighted_rms(&unsplit))?;
    let unsplit = GivenModel {
        model: unsplit,
        weighted_rms: rms,
        order_trace: split.order_trace.clone(),
        dropped_hz: fit.unsplit_dropped_hz,
        seeded_hz: Vec::new(),
        line_weights: vf.line_weights,
    };
    Ok((split, Some(unsplit)))
}

/// Σ_i Σ_f |Ĝ_ii(j2πf) − P_i(j2πf)|²/|P_i(j2πf)|² over the lines `freq_hz`
/// in axis i's band, with P_i axis i's own per-axis fit (where it has one):
/// how far the model's direct entries are from fits that are independent of
/// the common poles.
fn direct_distance(
    model: &MatrixModel,
    prepared: &[Result<PreparedAxis>],
    bands: &[(f64, f64); 3],
    freq_hz: &[f64],
) -> f64 {
    let mut sum = 0.0;
    for (i, p) in prepared.iter().enumerate() {
        let Ok(p) = p else { continue };
        for f in freq_hz.iter().filter(|f| **f >= bands[i].0 && **f <= bands[i].1) {
            let reference = p.model_frf(*f);
            sum += (model.entry(i, i).frf(*f) - reference).norm_sqr() / reference.norm_sqr().max(f64::MIN_POSITIVE);
        }
    }
    sum
}

/// [`prepare_matrix`] from the model: its error against the measurement,
/// the discrete model and the plant.
fn prepare_model(frf: &Frf, bands: &[(f64, f64); 3], fs: f64, threshold: f64, given: GivenModel) -> Result<MatrixPrep> {
    let GivenModel { model, weighted_rms, order_trace, dropped_hz, seeded_hz, line_weights } = given;
    let entries: Vec<_> = (0..9).map(|e| frf.entry(e / 3, e % 3).expect("complete")).collect();
    let mut entry_error = [[f64::NAN; 3]; 3];
    for (e, ent) in entries.iter().enumerate() {
        let (i, j) = (e / 3, e % 3);
        let mask: Vec<bool> = frf
            .freq_hz
            .iter()
            .enumerate()
            .map(|(k, f)| *f >= bands[i].0 && *f <= bands[i].1 && ent.coherence.is_none_or(|c| c[k] >= threshold))
            .collect();
        entry_error[i][j] = relative_rms_error(|f| model.entry(i, j).frf(f), &frf.freq_hz, ent.frf, &mask);
    }
    for i in 0..3 {
        if !(entry_error[i][i] <= MAX_FIT_ERROR) {
            bail!(
                "the 3x3 model is {:.1} % (relative RMS) from the measured {} FRF on its coherent lines, above the limit of {:.0} %",
                100.0 * entry_error[i][i],
                entry_name(i, i),
                100.0 * MAX_FIT_ERROR
            );
        }
    }
    let band = (bands.iter().map(|b| b.0).fold(f64::INFINITY, f64::min), bands.iter().map(|b| b.1).fold(0.0, f64::max));
    let (dm, matching) = discretize_matrix(&model, fs, band).context("discrete 3x3 model")?;
    let grid = crate::design::criterion::criterion_grid(&[band]);
    let lines: Vec<(f64, CMatrix3)> = grid.iter().map(|f| (*f, model.frf(*f))).collect();
    let plant = plant_states(&dm, &lines).context("plant of the 3x3 model")?;
    let modes = model.modes();
    let rank_one_pairs = (0..model.terms())
        .filter(|&k| model.pole(k).1 && crate::fit::rank_one::rank_two_share(&model.residue(k)) < 1e-9)
        .count();
    let figures = MatrixFitFigures {
        order: model.order(),
        weighted_rms,
        order_trace,
        entry_error,
        modes,
        dropped_hz,
        seeded_hz,
        rank_one_pairs,
    };
    Ok(MatrixPrep { fit: figures, model, dm, matching, plant, unsplit: None, plain: None, line_weights })
}

/// The criterion on the 3x3 model Ĝ (the predictions, and the q search),
/// and the judge of the choice of row: the same criterion on Ĝ with each
/// direct entry replaced by its per-axis fit. The 3x3 design is optimal for
/// Ĝ, so on Ĝ its model error is invisible while the per-axis design's
/// disagreement with Ĝ counts against it. On the per-axis fits the 3x3
/// row's error in the direct entries shows; the per-axis row sees its own
/// model (so the judge leans towards it, the safe side) and the crosstalk
/// of Ĝ's cross entries. The measured matrix itself would judge no better:
/// its impact-test noise (2-3 % per line below 1 kHz on the plate
/// simulator) is larger than the differences between the rows there.
struct Criteria {
    model: MatrixCriterion,
    judge: MatrixCriterion,
}

/// Below this peak crosstalk |G_ij|/|G_ii| (over the band, off the
/// diagonal) a 3x3 row chosen for flat forces can be worse than the
/// per-axis row for a cut, whose power sits at low harmonics far from the
/// sensor modes where the crosstalk peaks: the summary then says so.
pub const MODERATE_CROSSTALK: f64 = 1.0;

/// The designs at latency `lag` and each axis's choice of row.
fn round(
    lag: usize,
    prepared: &[Result<PreparedAxis>],
    prep: Option<&MatrixPrep>,
    crits: &Criteria,
    r: [f64; 3],
    d: &DesignOptions,
) -> Round {
    let crit = &crits.model;
    let judge = &crits.judge;
    let opts = DesignOptions { lag, ..d.clone() };
    // Why an axis has no per-axis design at this latency (its fit's error
    // is a note of its own).
    let mut per_axis_missing: [Option<String>; 3] = Default::default();
    let per_axis: Vec<Option<AxisDesign>> = prepared
        .iter()
        .zip(&mut per_axis_missing)
        .map(|(p, why)| match p.as_ref().map(|p| design_prepared(p, &opts)) {
            Ok(Ok(a)) => Some(a),
            Ok(Err(e)) => {
                *why = Some(format!("{e:#}"));
                None
            }
            Err(_) => None,
        })
        .collect();
    let (matrix, matrix_error) = match prep.map(|p| design_3x3(p, crit, r, lag, d)) {
        Some(Ok(m)) => (Some(m), None),
        Some(Err(e)) => (None, Some(format!("no 3x3 Kalman design at latency {lag}: {e:#}"))),
        None => (None, None),
    };
    debug_assert_eq!(crit.all_freqs(), judge.all_freqs());
    let all = crit.all_freqs();
    let h_matrix = matrix.as_ref().map(|(k, _, _)| k.compensator.freq_responses(&all, d.fs_hz));
    let axes: Vec<AxisPrediction> = (0..3)
        .map(|i| {
            let per = per_axis[i].as_ref().map(|a| {
                let h = a.kalman.compensator.freq_responses(&crit.rows[i].freqs, d.fs_hz);
                (crit.per_axis(i, lag, &h), a.predicted_error, a.noise_gain, judge.per_axis(i, lag, &h))
            });
            let mat = matrix
                .as_ref()
                .zip(h_matrix.as_ref())
                .map(|((_, _, ng), h)| (crit.row_error(i, lag, h), ng[i], judge.row_error(i, lag, h)));
            axis_prediction(i, crit, per, mat, per_axis_missing[i].as_deref())
        })
        .collect();
    let rows = std::array::from_fn(|i| axes[i].source);
    Round { lag, per_axis, matrix, matrix_error, axes, rows }
}

/// Output axis i's predictions and its row: the one the judge gives less
/// error ([`Criteria`]). `per`: the per-axis row's (model error, its own
/// prediction, noise gain, judged error); `mat`: the 3x3 row's (model
/// error, noise gain, judged error); `per_axis_missing`: why the per-axis
/// design failed at this latency.
fn axis_prediction(
    i: usize,
    crit: &MatrixCriterion,
    per: Option<(RowError, f64, f64, RowError)>,
    mat: Option<(RowError, f64, RowError)>,
    per_axis_missing: Option<&str>,
) -> AxisPrediction {
    let no_per_axis = match per_axis_missing {
        Some(why) => format!("3x3 row: no per-axis design at this latency ({why})"),
        None => "3x3 row: no per-axis design".to_string(),
    };
    let (source, chosen, noise_gain, reason) = match (per, mat) {
        (Some((_, _, _, pj)), Some((m, mng, mj))) if mj.error < pj.error => (
            RowSource::Matrix,
            m,
            mng,
            format!(
                "3x3 row: {:.3} % against {:.3} % per axis (judged on the per-axis fits)",
                100.0 * mj.error,
                100.0 * pj.error
            ),
        ),
        (Some((p, _, png, pj)), Some((_, _, mj))) => (
            RowSource::PerAxis,
            p,
            png,
            format!(
                "per-axis row: {:.3} % against {:.3} % for the 3x3 row (judged on the per-axis fits)",
                100.0 * pj.error,
                100.0 * mj.error
            ),
        ),
        (Some((p, _, png, _)), None) => (RowSource::PerAxis, p, png, "per-axis row: no 3x3 design".to_string()),
        (None, Some((m, mng, _))) => (RowSource::Matrix, m, mng, no_per_axis),
        (None, None) => (
            RowSource::PerAxis,
            RowError { error: f64::INFINITY, distortion: f64::INFINITY, fit: f64::NAN },
            f64::NAN,
            "no design".to_string(),
        ),
    };
    AxisPrediction {
        axis: axis_name(i),
        band_hz: crit.rows[i].band_hz,
        raw: crit.raw(i),
        per_axis: per.map(|p| p.0),
        per_axis_direct_only: per.map(|p| p.1),
        matrix: mat.map(|m| m.0),
        per_axis_judged: per.map(|p| p.3),
        matrix_judged: mat.map(|m| m.2),
        source,
        chosen,
        reason,
        noise_gain,
        offline: None,
    }
}

/// [`MatrixSummary::forces`] for predictions on a flat force spectrum.
pub const FLAT_FORCE: &str = "a flat force";

/// What the summaries add to a flat-force offline prediction: a cut gains
/// less than it shows (BENCHMARKS.md, "What `compensate --offline` reaches
/// on a 3x3 image").
pub const OFFLINE_FLAT_CAVEAT: &str = "for a flat force: a cut, its power at low harmonics, gains less \
                                       (`--force-prior spectrum --force-record CUT.csv` predicts for it)";

pub use crate::design::criterion::OFFLINE_MUCH_BETTER;

/// The note on the 3x3 rows whose offline prediction is under
/// [`OFFLINE_MUCH_BETTER`] of the full real-time filter's at latency `lag`
/// (before any reduction for the box, which the summary states apart),
/// each with the fit's uncertainty ([`RowError::with_fit`]). Only for
/// predictions on a cut's record: for a flat force nearly every row
/// qualifies, while a cut, its power at low harmonics, gains little
/// (BENCHMARKS.md, "What `compensate --offline` reaches on a 3x3 image").
fn offline_note(axes: &[AxisPrediction], lag: usize) -> Option<String> {
    let much_better: Vec<(&str, f64, f64)> = axes
        .iter()
        .filter(|a| a.source == RowSource::Matrix)
        .filter_map(|a| Some((a.axis, a.offline?.with_fit(), a.matrix?.with_fit())))
        .filter(|(_, off, rt)| *off < OFFLINE_MUCH_BETTER * rt)
        .collect();
    if much_better.is_empty() {
        return None;
    }
    let list = |k: fn(&(&str, f64, f64)) -> f64| {
        much_better.iter().map(|a| format!("{} {:.3} %", a.0, 100.0 * k(a))).collect::<Vec<_>>().join(", ")
    };
    Some(format!(
        "for this cut, `compensate --offline` on this image predicts {} against {} for its real-time 3x3 filter at \
         latency {lag} (full model, the fit's uncertainty counted): the difference is what {lag} samples of latency \
         cost, and the zero-lag smoother is not bound by them; use it where the record can be processed after the cut",
        list(|a| a.1),
        list(|a| a.2)
    ))
}

/// What `compensate --offline` on the image predicts for each 3x3 row: the
/// fixed-interval smoother of the same model (the augmented plant at
/// latency 0, the design's force shapes) with the 3x3 design's q
/// ([`response::smoother_responses`], the smoother's steady-state response),
/// by the criterion at latency 0. A line at 0 Hz (the mean force's) is
/// taken at 10⁻⁶·fs, where the random-walk force's pole at z = 1 leaves the
/// resolvent finite. `None` where a line's response is not finite.
fn offline_prediction(
    p: &MatrixPrep,
    crit: &MatrixCriterion,
    q: [f64; 3],
    r: [f64; 3],
    d: &DesignOptions,
) -> Option<[RowError; 3]> {
    let plant = augmented_plant_shaped(&p.dm, &p.plant, 0, force_shapes(crit, d));
    let lines: Vec<f64> = crit.all_freqs().iter().map(|f| f.max(1e-6 * d.fs_hz)).collect();
    let h = response::smoother_responses(&plant, q, r, &lines, d.fs_hz);
    let rows: [RowError; 3] = std::array::from_fn(|i| crit.row_error(i, 0, &h));
    rows.iter().all(|e| e.error.is_finite()).then_some(rows)
}

/// The 3x3 Kalman design at latency `lag` with q chosen by the criterion
/// (or `d.q_override` on every axis), and its noise gains. Quiet above the
/// band by default ([`quiet_above_band`]): each force band-limited
/// ([`force_shapes`]) and q for the in-band error plus the noise written
/// above the band ([`MatrixCriterion::above_j`]); the predictions in the
/// [`QSearch`] are the in-band error alone. The chosen q is one the offline
/// smoother's Riccati equation (the same plant at latency 0) also solves.
fn design_3x3(
    p: &MatrixPrep,
    crit: &MatrixCriterion,
    r: [f64; 3],
    lag: usize,
    d: &DesignOptions,
) -> Result<(MatrixKalman, QSearch, [f64; 3])> {
    let shapes = force_shapes(crit, d);
    let aug = augmented_plant_shaped(&p.dm, &p.plant, lag, shapes);
    // `compensate --offline` solves the same equation at latency 0
    // (`offline::matrix_smoother`): a q it cannot take is not chosen.
    let smoother = (lag > 0).then(|| augmented_plant_shaped(&p.dm, &p.plant, 0, shapes));
    // Where that equation is the filter's own (the FIR taps reach past the
    // latency: the delay line has no stage more), a q whose design solved it
    // needs no second solve of the same deterministic doubling.
    let same_equation = smoother.as_ref().is_some_and(|s| s.same_riccati_equation(&aug));
    let solved = std::sync::Mutex::new(Vec::<[f64; 3]>::new());
    let offline_solves = |q: [f64; 3]| {
        smoother.as_ref().is_none_or(|s| {
            (same_equation && solved.lock().is_ok_and(|v| v.contains(&q)))
                || kalman::solve_dare_refined(s, q, r).is_ok()
        })
    };
    let in_band = crit.all_freqs();
    let lines = [in_band.clone(), crit.above_freqs()].concat();
    let resolvent = PlantResolvent::new(&aug, &lines, d.fs_hz);
    let evaluate = |q: [f64; 3]| -> Option<Candidate> {
        let k = kalman::design(&aug, q, r, lag).ok()?;
        if same_equation {
            solved.lock().ok()?.push(q);
        }
        let ng = k.compensator.white_noise_gains()?;
        let h = resolvent.responses(&k);
        let (h_in, h_above) = h.split_at(in_band.len());
        let mut in_band_error = [f64::INFINITY; 3];
        let j = std::array::from_fn(|i| {
            if ng[i] > d.max_noise_gain {
                return f64::INFINITY;
            }
            in_band_error[i] = crit.row_prediction(i, lag, h_in);
            (in_band_error[i].powi(2) + crit.above_j(i, h_above)).sqrt()
        });
        Some(Candidate { kalman: k, criterion: j, noise_gains: [ng[0], ng[1], ng[2]], in_band_error })
    };
    let search = match d.q_override {
        Some(q) => QSearch { q: [q; 3], ..Default::default() },
        None => choose_q(&|q| evaluate(q).map_or([f64::INFINITY; 3], |c| c.criterion), &offline_solves, r)?,
    };
    let Some(c) = evaluate(search.q) else {
        bail!("the 3x3 Kalman design failed at the chosen q = {:?}", search.q);
    };
    let search = QSearch { predicted: c.in_band_error, ..search };
    Ok((c.kalman, search, c.noise_gains))
}

/// One candidate q's 3x3 design ([`design_3x3`]).
struct Candidate {
    kalman: MatrixKalman,
    /// The q criterion per row: √(in-band J + weighted noise above the band).
    criterion: [f64; 3],
    /// White-noise gain per output.
    noise_gains: [f64; 3],
    /// √J per row, in band alone (∞ over the noise-gain limit).
    in_band_error: [f64; 3],
}

/// Whether the 3x3 design is quiet above its band
/// ([`crate::design::above_band`]): by default, with a force record's
/// criterion too (BENCHMARKS.md, "Quiet above the band for a record"). The
/// per-axis design's record criteria stay in-band.
fn quiet_above_band(d: &DesignOptions) -> bool {
    d.above_band == AboveBand::Quiet
}

/// The band-limited force model of each force direction j, its corner above
/// row j's band ([`AboveBand::force_shape`]), where the design is quiet.
fn force_shapes(crit: &MatrixCriterion, d: &DesignOptions) -> [Option<ForceShape>; 3] {
    std::array::from_fn(|j| match quiet_above_band(d) {
        true => d.above_band.force_shape(crit.rows[j].band_hz.1, d.fs_hz),
        false => None,
    })
}

/// A round's combined compensator and its realization, verified in f32.
type Realized = (MimoStateSpace, (MimoRealization, MimoFilter, MimoVerification));

/// The combined compensator of `rd`, realized and verified in f32 up to
/// `f_band` (Hz).
fn realize_round(rd: &Round, fs: f64, f_band: f64) -> Result<Realized> {
    let (blocks, compensator) = blocks_of(rd)?;
    Ok((compensator, realize_blocks(&blocks, fs, f_band)?))
}

/// The blocks of `rd`'s combined compensator (the 3x3 rows' block first)
/// and their sum ([`combine`]).
fn blocks_of(rd: &Round) -> Result<(Vec<MimoStateSpace>, MimoStateSpace)> {
    let per_axis_ss: [Option<&crate::numeric::lti::StateSpace>; 3] =
        std::array::from_fn(|i| rd.per_axis[i].as_ref().map(|a| &a.kalman.compensator));
    combine(rd.rows, rd.matrix.as_ref().map(|m| &m.0.compensator), per_axis_ss)
}

/// The combined compensator of the chosen round, realized and verified.
#[allow(clippy::too_many_arguments)]
fn finish(
    force_shape: [Option<ForceShape>; 3],
    rd: Round,
    realized: Realized,
    prep: Option<MatrixPrep>,
    crosstalk: Crosstalk,
    latency_rounds: Vec<LatencyRound>,
    mut notes: Vec<String>,
    fs: f64,
    f_band: f64,
) -> Result<MatrixDesign> {
    let (compensator, (realization, filter, verification)) = realized;
    notes.extend(rd.matrix_error.iter().cloned());
    let kalman_fig = rd.matrix.as_ref().map(|(k, s, ng)| KalmanFigures {
        q: k.q,
        r: k.r,
        order: k.compensator.a.nrows(),
        dare_residual: k.dare_residual,
        dare_iterations: k.dare_iterations,
        innovation_condition: k.innovation_condition,
        closed_loop_radius: k.closed_loop_radius,
        noise_gains: *ng,
        q_search: s.clone(),
        force_shape,
    });
    let summary = MatrixSummary {
        fs_hz: fs,
        latency: rd.lag,
        latency_rounds,
        fit: prep.as_ref().map(|p| p.fit.clone()),
        discrete: prep.as_ref().map(|p| p.matching),
        plant: prep.as_ref().map(|p| PlantFigures {
            states: p.plant.a.nrows(),
            ranks: p.plant.ranks.clone(),
            dropped_bound: p.plant.dropped_bound,
            realization_error: p.plant.error,
        }),
        kalman: kalman_fig,
        axes: rd.axes,
        crosstalk,
        realization: RealizationFigures {
            verified_to_hz: f_band,
            pairs: verification.pairs,
            diagonal: verification.diagonal,
            fir_taps: verification.fir_taps,
            modal_condition: realization.modal_condition,
            decoupling_norm: realization.decoupling_norm,
            fir_truncation: realization.fir_truncation,
            verification,
        },
        worse_than_raw: Vec::new(),
        reduction: None,
        forces: FLAT_FORCE.to_string(),
        flat_force: true,
        notes,
    };
    let (model, discrete) = match prep {
        Some(p) => (Some(p.model), Some((p.dm, p.plant))),
        None => (None, None),
    };
    Ok(MatrixDesign {
        summary,
        model,
        discrete,
        kalman: rd.matrix.map(|m| m.0),
        per_axis: rd.per_axis,
        rows: rd.rows,
        compensator,
        realization,
        filter,
        full_compensator: None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A round at latency `lag` whose axes predict `percent` (no designs).
    pub(super) fn round_predicting(lag: usize, percent: [f64; 3]) -> Round {
        let row = |p: f64| RowError { error: p / 100.0, distortion: p / 100.0, fit: f64::NAN };
        let axes = (0..3)
            .map(|i| AxisPrediction {
                axis: ["x", "y", "z"][i],
                band_hz: (0.0, 4000.0),
                raw: row(50.0),
                per_axis: None,
                per_axis_direct_only: None,
                matrix: Some(row(percent[i])),
                per_axis_judged: None,
                matrix_judged: None,
                source: RowSource::Matrix,
                chosen: row(percent[i]),
                reason: String::new(),
                noise_gain: 1.0,
                offline: None,
            })
            .collect();
        Round {
            lag,
            per_axis: vec![None, None, None],
            matrix: None,
            matrix_error: None,
            axes,
            rows: [RowSource::Matrix; 3],
        }
    }

    fn first_ranked(rounds: Vec<Round>) -> usize {
        rank_rounds(rounds).0[0].lag
    }

    /// The summary points to `compensate --offline` on the 3x3 rows whose
    /// offline prediction is under half the full real-time filter's (y:
    /// 0.10 against 0.30 %), not on a row at 0.6 of it (x), a per-axis row
    /// (z), nor on a row whose reduced filter alone is that far behind.
    #[test]
    fn the_offline_note_names_the_rows_the_smoother_halves() {
        let mut rd = round_predicting(8, [0.20, 0.30, 0.50]);
        let row = |p: f64| RowError { error: p / 100.0, distortion: p / 100.0, fit: f64::NAN };
        rd.axes[0].offline = Some(row(0.12));
        rd.axes[1].offline = Some(row(0.10));
        rd.axes[2].offline = Some(row(0.01));
        rd.axes[2].source = RowSource::PerAxis;
        let note = offline_note(&rd.axes, 8).expect("a note for y");
        assert!(note.contains("predicts y 0.100 % against y 0.300 %"), "{note}");
        assert!(note.contains("latency 8") && !note.contains("x 0.") && !note.contains("z 0."), "{note}");
        // Controls: at 0.6 of the full filter no note; a reduced filter
        // (chosen) far behind while the full one is close: no note.
        rd.axes[1].offline = Some(row(0.18));
        assert_eq!(offline_note(&rd.axes, 8), None);
        rd.axes[1].chosen = row(0.9);
        assert_eq!(offline_note(&rd.axes, 8), None);
        rd.axes[1].offline = Some(row(0.14));
        assert!(offline_note(&rd.axes, 8).is_some(), "0.14 against 0.30 % is under half");
    }

    /// The latency rule, on rounds whose ratios are worked out by hand
    /// (GAIN_NOT_WORTH = 1.1): the shortest latency within 1.1x of every
    /// axis's best; else the least worst ratio. `rule_prefers` on two
    /// rounds chooses as `rank_rounds` does on them, either way round.
    #[test]
    fn the_latency_rule_ranks_and_compares_rounds_alike() {
        // Latency 6 within 1.1x everywhere (1.05x on y): kept, though 8 is better.
        let r = || (round_predicting(6, [0.30, 0.42, 0.50]), round_predicting(8, [0.30, 0.40, 0.50]));
        let (a, b) = r();
        assert_eq!(first_ranked(vec![a, b]), 6);
        let (a, b) = r();
        assert!(rule_prefers(&a, &b) && !rule_prefers(&b, &a));
        // Control: 1.2x on y buys latency 8.
        let r = || (round_predicting(6, [0.30, 0.48, 0.50]), round_predicting(8, [0.30, 0.40, 0.50]));
        let (a, b) = r();
        assert_eq!(first_ranked(vec![a, b]), 8);
        let (a, b) = r();
        assert!(!rule_prefers(&a, &b) && rule_prefers(&b, &a));
        // Bests on different latencies, neither within 1.1x everywhere:
        // 6 is 1.5x off on y, 8 is 1.2x off on x, so 8.
        let r = || (round_predicting(6, [0.30, 0.60, 0.50]), round_predicting(8, [0.36, 0.40, 0.50]));
        let (a, b) = r();
        assert_eq!(first_ranked(vec![a, b]), 8);
        let (a, b) = r();
        assert!(!rule_prefers(&a, &b) && rule_prefers(&b, &a));
        // Three rounds: 6 is 1.3x off, 8 within 1.1x of 10 (1.08x): 8.
        let rounds = vec![
            round_predicting(6, [0.52, 0.40, 0.40]),
            round_predicting(8, [0.43, 0.40, 0.40]),
            round_predicting(10, [0.40, 0.40, 0.40]),
        ];
        let ranked: Vec<usize> = rank_rounds(rounds).0.iter().map(|rd| rd.lag).collect();
        assert_eq!(ranked, [8, 10, 6], "then by worst ratio");
        assert_eq!(percent_xyz(&round_predicting(8, [0.43, 0.4, 0.0126]).predicted()), "0.430 / 0.400 / 0.013");
    }

    /// A refusal says which limit the axis misses: no better than raw, or
    /// better than raw but over the 50 % any image may predict; and what
    /// to try. Control: 49 % against 614 % raw is accepted.
    #[test]
    fn a_refusal_says_whether_the_filter_is_worse_than_raw_or_of_no_use() {
        let with_raw = |lag, y: f64, raw: f64| {
            let mut r = round_predicting(lag, [0.3, y, 0.3]);
            r.axes[1].raw.error = raw / 100.0;
            r
        };
        let e = format!("{:#}", refuse_unless_better_than_raw(&with_raw(0, 71.0, 614.0)).unwrap_err());
        assert!(
            e.starts_with("axis y: neither the 3x3 nor the per-axis compensator at latency 0 compensates usefully"),
            "{e}"
        );
        assert!(e.contains("predicted 71.00 % against 614.00 % uncompensated"), "{e}");
        assert!(e.contains("A longer --latency") && e.contains("chooses up to 8"), "{e}");
        let e = format!("{:#}", refuse_unless_better_than_raw(&with_raw(8, 30.0, 25.0)).unwrap_err());
        assert!(
            e.starts_with("axis y: neither the 3x3 nor the per-axis compensator at latency 8 beats no compensation"),
            "{e}"
        );
        assert!(refuse_unless_better_than_raw(&with_raw(0, 49.0, 614.0)).is_ok());
    }

    /// The level prior's caveat: for `--force-prior level` quiet above the
    /// band only; not for a record's spectrum, a flat force, or a design
    /// that is the inverse above the band.
    #[test]
    fn the_level_prior_s_caveat_goes_with_quiet_rows_only() {
        let level = DesignOptions { force_record_level_only: true, ..Default::default() };
        assert!(quiet_above_band(&level));
        assert!(level_prior_caveat(&level, false).is_some_and(|n| n.contains("--force-prior spectrum")));
        assert_eq!(level_prior_caveat(&level, true), None, "a flat force");
        assert_eq!(level_prior_caveat(&DesignOptions::default(), false), None, "the record's spectrum");
        let inverse = DesignOptions { above_band: AboveBand::Inverse, ..level };
        assert_eq!(level_prior_caveat(&inverse, false), None, "inverse above the band");
    }
}
