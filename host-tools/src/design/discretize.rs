//! The sampled-data relation (DESIGN.md, signal chain step 3): a discrete
//! model Ĝ_d(z) of the fitted sensor model Ĝ(s) for the Kalman design.
//!
//! A real acquisition chain band-limits before it samples, and the impact
//! test measures the FRF through that chain: for band-limited signals the
//! sampled force and measurement are then related exactly by Ĝ(j2πf) below
//! the band limit. A model with Ĝ_d(e^{j2πf/fs}) = Ĝ(j2πf) there
//! ([`Discretization::Fit`]) lets the Kalman filter invert the sensor exactly;
//! the hold equivalents assume a force constant or linear between samples and
//! err as (f/fs)².

use anyhow::{bail, Result};
use nalgebra::{DMatrix, DVector};
use num_complex::Complex64;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

use crate::fit::{PoleResidueModel, Term};

/// Upper edge of the band in which the discrete model must match Ĝ, as a
/// fraction of fs: the pass band of a sigma-delta DAQ's anti-aliasing filter.
pub const MATCH_BAND_FRACTION: f64 = 0.45;

/// Upper edge of the alternative fit grid, as a fraction of fs: just below
/// Nyquist (a real-coefficient model's response is real at fs/2 itself).
/// With a sensor mode above Nyquist, matching Ĝ over the whole unit circle
/// instead of leaving 0.45-0.5 fs free can give a model whose inverse the
/// fixed-lag smoother approximates far better (high-mode z axis at 10.24 kHz:
/// predicted 7.4 → 1.4 %, measured 2.65 → 2.02 %); for a mode inside that
/// stretch it is worse. [`crate::design::latency`] tries it where the default falls
/// short and keeps, per axis, whichever predicts the smaller error.
pub const NYQUIST_FIT_FRACTION: f64 = 0.499;

/// How the continuous model becomes the discrete model of the Kalman design.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum Discretization {
    /// Fit on the unit circle to the sampled-data relation, from 0 to 0.45 fs:
    ///
    /// Ĝ_d(z) = d + Σ_real ρ/(z − ζ) + Σ_pairs [ρ/(z − ζ) + ρ̄/(z − ζ̄)] + Σ_{m=1..M} h_m z^{−m}
    ///
    /// with the poles mapped exactly, ζ = e^{pT} (the free response of a mode is
    /// sampled exactly by any chain), for every pair whose frequency |Im p|/2π
    /// and every real pole whose corner |p|/2π lies below fs/2; a pole beyond
    /// Nyquist has no discrete counterpart inside the band, and its in-band
    /// tail is carried by the other terms. The
    /// residues ρ, the direct term d and M FIR taps h_m are the least-squares
    /// solution of the relative error (Ĝ_d − Ĝ)/Ĝ on a dense grid, under the one
    /// linear constraint Ĝ_d(1) = Ĝ(0) (the static gain exact, [`StaticGain`]): a
    /// linear problem, solved with column scaling, its condition number and
    /// residual checked. Zero- and first-order holds are special cases of the
    /// same form (same poles, fixed residues) that keep the static gain too, so
    /// the fit is never worse than either on its grid.
    #[default]
    Fit,
    /// First-order hold: force linear between samples (its error grows as
    /// (f/fs)²: a 2.5 kHz mode at 25.6 kHz is 2 % off at 2 kHz). Selectable
    /// to show the difference, as is [`Discretization::Zoh`].
    Foh,
    /// Zero-order hold: force constant over each sample.
    Zoh,
}

impl Discretization {
    /// Lower-case name, as on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Discretization::Fit => "fit",
            Discretization::Foh => "foh",
            Discretization::Zoh => "zoh",
        }
    }

    /// The discretization of a lower-case name (`fit`, `foh`, `zoh`).
    pub fn from_name(name: &str) -> Option<Self> {
        [Discretization::Fit, Discretization::Foh, Discretization::Zoh].into_iter().find(|d| d.name() == name)
    }
}

/// One term of a discrete pole-residue model (z-domain).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum DTerm {
    /// ρ/(z − ζ), ζ and ρ real.
    Real {
        /// Pole ζ (|ζ| < 1).
        pole: f64,
        /// Residue ρ.
        residue: f64,
    },
    /// ρ/(z − ζ) + ρ̄/(z − ζ̄), represented by the pole with Im ζ > 0.
    Pair {
        /// Pole ζ (re, im), Im ζ > 0.
        pole: (f64, f64),
        /// Residue ρ of ζ (re, im).
        residue: (f64, f64),
    },
}

/// A discrete SISO model of the sensor ([`Discretization`]), input F_k (N),
/// output y_k (N).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DiscreteModel {
    /// Sample rate (Hz).
    pub fs_hz: f64,
    /// How it was obtained.
    pub method: Discretization,
    /// Pole-residue terms.
    pub terms: Vec<DTerm>,
    /// Direct term d (N/N).
    pub d: f64,
    /// FIR taps h_1..h_M (N/N) on F_{k−1}..F_{k−M}.
    pub fir: Vec<f64>,
    /// Advance D (samples): Ĝ_d(z) = z^D·M(z) with M(z) the causal part
    /// above ([`Discretization::Fit`]); 0 for the hold equivalents.
    #[serde(default)]
    pub advance: usize,
}

/// max |g/t − 1| over the pairs (g, t): a model's match to its truth.
fn largest_relative_error(pairs: impl Iterator<Item = (Complex64, Complex64)>) -> f64 {
    pairs.map(|(g, t)| (g / t - 1.0).norm()).fold(0.0, f64::max)
}

fn c(v: (f64, f64)) -> Complex64 {
    Complex64::new(v.0, v.1)
}

impl DiscreteModel {
    /// Ĝ_d(z) at a complex point z.
    pub fn eval_z(&self, z: Complex64) -> Complex64 {
        let mut g = Complex64::new(self.d, 0.0);
        for t in &self.terms {
            match *t {
                DTerm::Real { pole, residue } => g += residue / (z - pole),
                DTerm::Pair { pole, residue } => {
                    let (p, r) = (c(pole), c(residue));
                    g += r / (z - p) + r.conj() / (z - p.conj());
                }
            }
        }
        let zi = z.inv();
        let mut zm = zi;
        for h in &self.fir {
            g += zm * h;
            zm *= zi;
        }
        g * z.powi(self.advance as i32)
    }

    /// Ĝ_d(e^{j2πf/fs}) at frequency `f_hz` (Hz).
    pub fn frf(&self, f_hz: f64) -> Complex64 {
        self.eval_z(Complex64::from_polar(1.0, 2.0 * PI * f_hz / self.fs_hz))
    }

    /// Number of states of the pole part (a pair counts two).
    pub fn order(&self) -> usize {
        self.terms.iter().map(|t| if matches!(t, DTerm::Real { .. }) { 1 } else { 2 }).sum()
    }

    /// The sum of the gains its terms reach on the unit circle, each alone:
    /// |ρ|/(1 − |ζ|) per real pole, 2|ρ|/(1 − |ζ|) per pair, |d| and |h_m|.
    /// Where it is many times the largest |Ĝ_d|, the terms cancel each other
    /// ([`MAX_TERM_GAIN_RATIO`]).
    pub fn term_gain_sum(&self) -> f64 {
        let poles: f64 = self
            .terms
            .iter()
            .map(|t| match *t {
                DTerm::Real { pole, residue } => residue.abs() / (1.0 - pole.abs()).max(f64::MIN_POSITIVE),
                DTerm::Pair { pole, residue } => {
                    2.0 * c(residue).norm() / (1.0 - c(pole).norm()).max(f64::MIN_POSITIVE)
                }
            })
            .sum();
        poles + self.d.abs() + self.fir.iter().map(|h| h.abs()).sum::<f64>()
    }

    /// Largest pole modulus (0 without poles).
    pub fn pole_radius(&self) -> f64 {
        self.terms
            .iter()
            .map(|t| match *t {
                DTerm::Real { pole, .. } => pole.abs(),
                DTerm::Pair { pole, .. } => c(pole).norm(),
            })
            .fold(0.0, f64::max)
    }

    /// Model match: max over `freqs_hz` of |Ĝ_d/Ĝ − 1| against `truth`.
    pub fn match_error(&self, freqs_hz: &[f64], truth: impl Fn(f64) -> Complex64) -> f64 {
        largest_relative_error(freqs_hz.iter().map(|f| (self.frf(*f), truth(*f))))
    }
}

/// Diagnostics of the unit-circle fit.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct FitDiagnostics {
    /// Condition number of the column-scaled least-squares matrix.
    pub condition: f64,
    /// Weighted RMS relative residual on the grid.
    pub residual: f64,
    /// Number of FIR taps chosen.
    pub fir_taps: usize,
    /// Advance D chosen (samples).
    pub advance: usize,
    /// Modes dropped because they lie above fs/2 (their tail is fitted).
    pub modes_above_nyquist: usize,
}

/// Discrete model by `method` for the fitted Ĝ(s) at `fs_hz`. `band_hz` is
/// the band where the compensator must be exact (weighted fully); the rest
/// of 0..0.45 fs is matched with a lower weight ([`Discretization::Fit`]).
pub fn discretize(
    model: &PoleResidueModel,
    fs_hz: f64,
    method: Discretization,
    band_hz: (f64, f64),
) -> Result<(DiscreteModel, FitDiagnostics)> {
    discretize_to(model, fs_hz, method, band_hz, MATCH_BAND_FRACTION, StaticGain::Exact)
}

/// The static gain of the unit-circle fit.
///
/// A cutting force's mean is 1-1.5x its standard deviation, so a static
/// gain error of the discrete model is an error of that size on its own.
/// Fitted like any other line, the least-squares fit spreads its error
/// evenly and left the models of stiff axes 0.03-0.06 % off at f = 0: as
/// large as those axes' noise floors (0.05-0.1 %), which put them 1.3-2.2x
/// above the floor with an exact FRF (BENCHMARKS.md, "The static gain of
/// the discrete model").
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StaticGain {
    /// Ĝ_d(1) = Ĝ(0) exactly: the least-squares fit under that one linear
    /// equality constraint (the default).
    Exact,
    /// The static line weighted like the others (the fit before; for
    /// side-by-side runs and the tests' negative control).
    Fitted,
}

/// [`discretize`] with the fit's grid running up to `top_fraction`·fs
/// ([`MATCH_BAND_FRACTION`] or [`NYQUIST_FIT_FRACTION`]); the hold
/// equivalents ignore it and `static_gain`).
pub fn discretize_to(
    model: &PoleResidueModel,
    fs_hz: f64,
    method: Discretization,
    band_hz: (f64, f64),
    top_fraction: f64,
    static_gain: StaticGain,
) -> Result<(DiscreteModel, FitDiagnostics)> {
    match method {
        Discretization::Foh => Ok((hold(model, fs_hz, true), FitDiagnostics::default())),
        Discretization::Zoh => Ok((hold(model, fs_hz, false), FitDiagnostics::default())),
        Discretization::Fit => fit_unit_circle(model, fs_hz, band_hz, top_fraction, static_gain),
    }
}

/// Hold equivalents in pole-residue form. Per continuous term r/(s − p), with
/// ζ = e^{pT}: ZOH gives r(ζ − 1)/p /(z − ζ); FOH (force linear between
/// samples) gives x[k+1] = ζ x[k] + γ0 F_k + γ1 F_{k+1}, i.e.
/// r(γ0 + γ1 ζ)/(z − ζ) + r γ1, with γ0 = I1/T, γ1 = I0 − I1/T,
/// I0 = ∫₀ᵀ e^{pu} du, I1 = ∫₀ᵀ u e^{pu} du.
fn hold(model: &PoleResidueModel, fs_hz: f64, first_order: bool) -> DiscreteModel {
    let t = 1.0 / fs_hz;
    let mut d = model.d;
    let mut terms = Vec::with_capacity(model.terms.len());
    let map = |p: Complex64, r: Complex64| -> (Complex64, Complex64, Complex64) {
        let (zeta, g0, g1) = hold_weights(p, t);
        if first_order {
            (zeta, r * (g0 + g1 * zeta), r * g1)
        } else {
            (zeta, r * (g0 + g1), Complex64::new(0.0, 0.0))
        }
    };
    for term in &model.terms {
        match *term {
            Term::Real { pole, residue } => {
                let (z, rho, direct) = map(Complex64::new(pole, 0.0), Complex64::new(residue, 0.0));
                terms.push(DTerm::Real { pole: z.re, residue: rho.re });
                d += direct.re;
            }
            Term::Pair { pole, residue } => {
                let (z, rho, direct) = map(pole, residue);
                terms.push(DTerm::Pair { pole: (z.re, z.im), residue: (rho.re, rho.im) });
                d += 2.0 * direct.re;
            }
        }
    }
    DiscreteModel {
        fs_hz,
        method: if first_order { Discretization::Foh } else { Discretization::Zoh },
        terms,
        d,
        fir: Vec::new(),
        advance: 0,
    }
}

/// (e^{pT}, γ0, γ1) of the first-order hold for ẋ = p x + F(t); γ0 + γ1 is
/// the zero-order hold's input weight (e^{pT} − 1)/p.
fn hold_weights(p: Complex64, t: f64) -> (Complex64, Complex64, Complex64) {
    let x = p * t;
    let e = x.exp();
    let (i0, i1) = if x.norm() < 1e-4 {
        // series: I0 = T(1 + x/2 + x²/6), I1 = T²(1/2 + x/3 + x²/8)
        (t * (1.0 + x / 2.0 + x * x / 6.0), t * t * (0.5 + x / 3.0 + x * x / 8.0))
    } else {
        ((e - 1.0) / p, (e * (x - 1.0) + 1.0) / (p * p))
    };
    (e, i1 / t, i0 - i1 / t)
}

/// Weight of grid lines outside the compensated band, relative to those inside.
pub(crate) const OUT_OF_BAND_WEIGHT: f64 = 0.2;
/// Most FIR taps tried.
pub(crate) const MAX_FIR_TAPS: usize = 12;
/// Largest advance D tried (samples).
pub(crate) const MAX_ADVANCE: usize = 6;
/// In-band match error max|Ĝ_d/Ĝ − 1| that is good enough: well below the
/// distortion budget of the compensated force (0.5 % NRMSE).
pub const MATCH_TARGET: f64 = 1e-3;
/// Above the target, the least complex model within this factor of the best.
pub(crate) const MATCH_SLACK: f64 = 1.5;
/// Largest condition number of the scaled least-squares matrix accepted.
pub(crate) const MAX_CONDITION: f64 = 1e12;
/// Largest ratio of a fit's [`DiscreteModel::term_gain_sum`] to its largest
/// |Ĝ_d| on the band's grid. Beyond it the least squares cancels huge terms
/// against each other: a fast real pole (ζ near 0) is nearly a FIR tap, and
/// the two columns can take residues of 10⁵ of opposite sign. The response
/// is right, but the Kalman design's augmented plant then measures a small
/// difference of huge states, and its Riccati equation has no usable
/// solution for any q. Random-sweep seed 19 z, fitted with its poles
/// relocated on every line: 1.3e5 times its peak, a residue of −1.0e5 on a
/// pole at z = 0.065; the fit chosen in its place, 270 times.
pub const MAX_TERM_GAIN_RATIO: f64 = 1e3;

/// The dense frequency grid of the fit: uniform over 0..`top_fraction`·fs
/// (0.45 fs by default), plus fine points around every mapped mode below
/// that (± 8 half-power bandwidths).
pub(crate) fn fit_grid(model: &PoleResidueModel, fs_hz: f64, band_hz: (f64, f64), top_fraction: f64) -> Vec<f64> {
    let f_hi = top_fraction * fs_hz;
    let mut g: Vec<f64> = (0..=1200).map(|i| f_hi * i as f64 / 1200.0).collect();
    // The compensated band gets its own uniform grid (it may be narrow at high fs).
    let (b0, b1) = (band_hz.0.max(0.0), band_hz.1.min(f_hi));
    if b1 > b0 {
        g.extend((0..=600).map(|i| b0 + (b1 - b0) * i as f64 / 600.0));
    }
    for t in &model.terms {
        if let Term::Pair { pole, .. } = *t {
            let fn_hz = pole.im / (2.0 * PI);
            let hw = (-pole.re / (2.0 * PI)).max(1e-3);
            if fn_hz < f_hi {
                g.extend((-32..=32).map(|k| fn_hz + 0.25 * k as f64 * hw).filter(|f| *f >= 0.0 && *f <= f_hi));
            }
        }
    }
    g.sort_by(f64::total_cmp);
    g.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
    g
}

/// The unit-circle fit of `model` with a given structure: `taps` FIR taps
/// and advance `advance` (e.g. those [`discretize`] chose for a neighbouring
/// model), so that models of a set-up that changes share one state layout
/// (the time-varying smoother of [`crate::design::two_state`]).
pub fn fit_with_structure(
    model: &PoleResidueModel,
    fs_hz: f64,
    band_hz: (f64, f64),
    taps: usize,
    advance: usize,
) -> Result<DiscreteModel> {
    if taps > MAX_FIR_TAPS || advance > MAX_ADVANCE {
        bail!("discrete model: {taps} FIR taps / advance {advance} exceed the fit's limits ({MAX_FIR_TAPS} / {MAX_ADVANCE})");
    }
    let (ls, _, _) = unit_circle_problem(model, fs_hz, band_hz, MATCH_BAND_FRACTION, StaticGain::Exact)?;
    ls.solve(taps, advance).map(|x| x.0).ok_or_else(|| {
        anyhow::anyhow!("discrete model: the fit with {taps} taps and advance {advance} is ill-conditioned")
    })
}

/// The least-squares problem of the unit-circle fit of `model`, its grid's
/// lines in the band, and the number of modes above Nyquist.
fn unit_circle_problem(
    model: &PoleResidueModel,
    fs_hz: f64,
    band_hz: (f64, f64),
    top_fraction: f64,
    static_gain: StaticGain,
) -> Result<(LeastSquares, Vec<f64>, usize)> {
    let t = 1.0 / fs_hz;
    let nyq = PI * fs_hz; // rad/s
    let kept: Vec<(Complex64, bool)> = model
        .terms
        .iter()
        .filter_map(|term| match *term {
            Term::Real { pole, .. } if pole.abs() < nyq => Some((Complex64::new(pole, 0.0), false)),
            Term::Real { .. } => None,
            Term::Pair { pole, .. } if pole.im < nyq => Some((pole, true)),
            Term::Pair { .. } => None,
        })
        .collect();
    let above = model.terms.len() - kept.len();
    let grid = fit_grid(model, fs_hz, band_hz, top_fraction);
    let band_grid: Vec<f64> = grid.iter().copied().filter(|f| *f >= band_hz.0 && *f <= band_hz.1).collect();
    let truth: Vec<Complex64> = grid.iter().map(|f| model.frf(*f)).collect();
    if let Some(i) = truth.iter().position(|g| !(g.norm() > 0.0 && g.norm().is_finite())) {
        bail!("discrete model: the fitted model is zero or not finite at {:.1} Hz; refit the FRF", grid[i]);
    }
    let exact_static = (static_gain == StaticGain::Exact).then(|| model.frf(0.0).re);
    let ls = LeastSquares::new(&kept, fs_hz, t, &grid, &truth, band_hz, exact_static);
    Ok((ls, band_grid, above))
}

/// The unit-circle least-squares fit ([`Discretization::Fit`]); the number of FIR taps
/// is raised while each tap lowers the in-band match error enough.
fn fit_unit_circle(
    model: &PoleResidueModel,
    fs_hz: f64,
    band_hz: (f64, f64),
    top_fraction: f64,
    static_gain: StaticGain,
) -> Result<(DiscreteModel, FitDiagnostics)> {
    let (ls, band_grid, above) = unit_circle_problem(model, fs_hz, band_hz, top_fraction, static_gain)?;
    // Every (advance, taps) pair, then the least complex one whose in-band
    // match error is within reach of the best: below MATCH_TARGET, or within
    // MATCH_SLACK of the best error when that is above the target.
    let mut tried: Vec<(DiscreteModel, FitDiagnostics, f64)> = Vec::new();
    let mut cancelling = 0;
    let truth: Vec<Complex64> = band_grid.iter().map(|f| model.frf(*f)).collect();
    for advance in 0..=MAX_ADVANCE {
        for taps in advance.saturating_sub(1)..=MAX_FIR_TAPS {
            let Some((dm, diag)) = ls.solve(taps, advance) else { continue };
            let response: Vec<Complex64> = band_grid.iter().map(|f| dm.frf(*f)).collect();
            let peak = response.iter().map(|g| g.norm()).fold(0.0, f64::max);
            if !(dm.term_gain_sum() <= MAX_TERM_GAIN_RATIO * peak) {
                cancelling += 1;
                continue;
            }
            let err = largest_relative_error(response.into_iter().zip(truth.iter().copied()));
            tried.push((dm, FitDiagnostics { modes_above_nyquist: above, ..diag }, err));
        }
    }
    let best_err = tried.iter().map(|t| t.2).fold(f64::INFINITY, f64::min);
    if !best_err.is_finite() && cancelling > 0 {
        bail!("discrete model: every well-conditioned unit-circle fit cancels terms of more than {MAX_TERM_GAIN_RATIO:.0e} times its response against each other (a fast pole against the FIR taps); lower --max-order or use --discretization foh");
    }
    if !best_err.is_finite() {
        bail!("discrete model: every unit-circle fit was ill-conditioned (condition > {MAX_CONDITION:.0e}); two fitted modes may coincide: lower --max-order or use --discretization foh");
    }
    let good_enough = MATCH_TARGET.max(MATCH_SLACK * best_err);
    let best = tried.into_iter().filter(|t| t.2 <= good_enough).min_by(|a, b| {
        let cost = |t: &(DiscreteModel, FitDiagnostics, f64)| t.0.advance + t.0.fir.len();
        cost(a).cmp(&cost(b)).then(a.2.total_cmp(&b.2))
    });
    let (dm, diag, _) = best.expect("at least one fit");
    Ok((dm, diag))
}

/// The weighted least-squares problem of the fit, built once for the most
/// FIR taps and every advance: the matrix A does not depend on the advance
/// (only the right-hand side z^{−D}·Ĝ does), and fewer taps is a leading
/// block of its columns. A is column-scaled (the 1/(z − ζ) columns of lightly
/// damped modes are orders of magnitude larger than the FIR columns) and the
/// small normal equations of each candidate are solved by Cholesky, their
/// condition checked by a symmetric eigen-decomposition.
struct LeastSquares {
    poles: Vec<(Complex64, bool)>,
    fs_hz: f64,
    /// Column scales of A.
    scale: Vec<f64>,
    /// Scaled Gram matrix AᵀA.
    gram: DMatrix<f64>,
    /// Aᵀ b_D for D = 0..=MAX_ADVANCE, and b_Dᵀ b_D.
    rhs: Vec<(DVector<f64>, f64)>,
    /// Columns of the pole part and the direct term.
    base_cols: usize,
    /// The exact static gain constraint, if any: the (scaled) columns' values
    /// at z = 1 and Ĝ(0) (the same for every advance, z^{−D} = 1 there).
    static_gain: Option<(DVector<f64>, f64)>,
}

/// The columns of the fit at z ([`Discretization::Fit`]): per mapped pole 1/(z − ζ)
/// (a pair: the real and imaginary part of its residue), the direct term,
/// then z^{−1}..z^{−MAX_FIR_TAPS}.
pub(crate) fn columns_at(poles: &[(Complex64, bool)], z: Complex64) -> Vec<Complex64> {
    let mut v = Vec::with_capacity(2 * poles.len() + 1 + MAX_FIR_TAPS);
    for (zeta, pair) in poles {
        let u = (z - zeta).inv();
        if *pair {
            let w = (z - zeta.conj()).inv();
            v.push(u + w); // ρ_re
            v.push((u - w) * Complex64::i()); // ρ_im
        } else {
            v.push(u);
        }
    }
    v.push(Complex64::new(1.0, 0.0));
    let zi = z.inv();
    let mut zm = zi;
    for _ in 0..MAX_FIR_TAPS {
        v.push(zm);
        zm *= zi;
    }
    v
}

impl LeastSquares {
    fn new(
        kept: &[(Complex64, bool)],
        fs_hz: f64,
        t: f64,
        grid: &[f64],
        truth: &[Complex64],
        band_hz: (f64, f64),
        static_gain: Option<f64>,
    ) -> Self {
        let poles: Vec<(Complex64, bool)> = kept.iter().map(|(p, pair)| ((p * t).exp(), *pair)).collect();
        let base_cols = poles.iter().map(|(_, pair)| if *pair { 2 } else { 1 }).sum::<usize>() + 1;
        let ncol = base_cols + MAX_FIR_TAPS;
        let nrow = 2 * grid.len();
        let mut a = DMatrix::<f64>::zeros(nrow, ncol);
        let mut b = DMatrix::<f64>::zeros(nrow, MAX_ADVANCE + 1);
        for (i, (f, g)) in grid.iter().zip(truth).enumerate() {
            let z = Complex64::from_polar(1.0, 2.0 * PI * f / fs_hz);
            let inside = *f >= band_hz.0 && *f <= band_hz.1;
            let w = if inside { 1.0 } else { OUT_OF_BAND_WEIGHT } / g.norm();
            for (col, v) in columns_at(&poles, z).into_iter().enumerate() {
                a[(2 * i, col)] = w * v.re;
                a[(2 * i + 1, col)] = w * v.im;
            }
            let zi = z.inv();
            // M(z) = z^{−D}·Ĝ: the causal part of the advanced relation.
            let mut gm = g * w;
            for d in 0..=MAX_ADVANCE {
                b[(2 * i, d)] = gm.re;
                b[(2 * i + 1, d)] = gm.im;
                gm *= zi;
            }
        }
        let scale: Vec<f64> = (0..ncol).map(|j| a.column(j).norm().max(f64::MIN_POSITIVE)).collect();
        for (j, s) in scale.iter().enumerate() {
            a.column_mut(j).scale_mut(1.0 / s);
        }
        let gram = a.tr_mul(&a);
        let atb = a.tr_mul(&b);
        let rhs = (0..=MAX_ADVANCE).map(|d| (atb.column(d).into_owned(), b.column(d).norm_squared())).collect();
        let static_gain = static_gain.map(|g0| {
            let at_one = columns_at(&poles, Complex64::new(1.0, 0.0));
            (DVector::from_iterator(ncol, at_one.iter().zip(&scale).map(|(v, s)| v.re / s)), g0)
        });
        LeastSquares { poles, fs_hz, scale, gram, rhs, base_cols, static_gain }
    }

    /// The fit with `taps` FIR taps and advance `advance`; `None` when its
    /// normal equations are ill-conditioned.
    fn solve(&self, taps: usize, advance: usize) -> Option<(DiscreteModel, FitDiagnostics)> {
        let n = self.base_cols + taps;
        let g = self.gram.view((0, 0), (n, n)).into_owned();
        let (atb, btb) = &self.rhs[advance];
        let atb = atb.rows(0, n).into_owned();
        // No convergence within the iteration limit: not a usable fit.
        let eig = crate::fit::linalg::symmetric_eigenvalues(&g, "the normal equations of the discrete fit").ok()?;
        let (lmin, lmax) = (eig.min(), eig.max());
        // cond(A) = sqrt(cond(AᵀA)).
        let condition = (lmax / lmin).sqrt();
        if !(lmin > 0.0 && condition < MAX_CONDITION) {
            return None;
        }
        let chol = g.clone().cholesky()?;
        let mut x = chol.solve(&atb);
        if let Some((at_one, g0)) = &self.static_gain {
            // min ‖Ax − b‖ subject to vᵀx = Ĝ(0): from the unconstrained
            // solution, x − G⁻¹v·(vᵀx − Ĝ(0))/(vᵀG⁻¹v) (G = AᵀA).
            let v = at_one.rows(0, n).into_owned();
            let gv = chol.solve(&v);
            let denom = v.dot(&gv);
            if !(denom > 0.0) {
                return None;
            }
            x -= gv * ((v.dot(&x) - g0) / denom);
        }
        // ‖Ax − b‖² = bᵀb − 2xᵀAᵀb + xᵀAᵀAx, relative to ‖b‖.
        let r2 = (btb - 2.0 * x.dot(&atb) + x.dot(&(&g * &x))).max(0.0);
        let residual = (r2 / btb.max(f64::MIN_POSITIVE)).sqrt();
        let coef: Vec<f64> = x.iter().zip(&self.scale).map(|(v, s)| v / s).collect();
        if !coef.iter().all(|v| v.is_finite()) {
            return None;
        }
        let mut terms = Vec::with_capacity(self.poles.len());
        let mut j = 0;
        for (zeta, pair) in &self.poles {
            if *pair {
                terms.push(DTerm::Pair { pole: (zeta.re, zeta.im), residue: (coef[j], coef[j + 1]) });
                j += 2;
            } else {
                terms.push(DTerm::Real { pole: zeta.re, residue: coef[j] });
                j += 1;
            }
        }
        let d = coef[j];
        let fir = coef[j + 1..].to_vec();
        Some((
            DiscreteModel { fs_hz: self.fs_hz, method: Discretization::Fit, terms, d, fir, advance },
            FitDiagnostics { condition, residual, fir_taps: taps, advance, modes_above_nyquist: 0 },
        ))
    }
}
