//! The model sidecar `<image>.model.json` that `dynocomp design` writes
//! next to the image: the fitted Ĝ(s) and the discrete model of the design
//! (a sidecar without the discrete model, from an older version, gets the
//! first-order hold of Ĝ(s), which that version used), the two states of a
//! two-state design, the force priors and the 3x3 model of a 3x3 image
//! ([`crate::offline::matrix_model`]), tied to the image by its id
//! (CRC-32) and the source FRF's SHA-256; `compensate --offline` refuses a
//! missing or foreign sidecar. Only the default method (vf) writes one;
//! `--method paper` images (continuous Q, Tustin) are refused by `--offline`
//! with a message saying so.

use anyhow::{bail, Context, Result};
use num_complex::Complex64;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

use dynocomp_core::image::{CoeffImage, DesignMethod, MatrixImage};

use crate::design::axis::AxisDesign;
use crate::design::discretize::{discretize, DiscreteModel, Discretization};
use crate::design::two_state::model::TwoState;
use crate::fit::{PoleResidueModel, Term};
use crate::frf::axis_name;
use crate::io::one_line;

/// Format tag of the model sidecar.
pub const SIDECAR_FORMAT: &str = "dynocomp-model/1";

/// One pole-residue term of a sidecar model (rad/s).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum TermJson {
    /// Real pole p (rad/s) with real residue r (rad/s).
    Real {
        /// Pole (rad/s).
        pole: f64,
        /// Residue (rad/s).
        residue: f64,
    },
    /// Complex pair: the pole with Im > 0 and its residue, as [re, im] (rad/s).
    Pair {
        /// Pole [re, im] (rad/s).
        pole: [f64; 2],
        /// Residue [re, im] (rad/s).
        residue: [f64; 2],
    },
}

/// The fitted sensor model G(s) of one axis.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AxisModelJson {
    /// Axis letter (x, y, z).
    pub axis: String,
    /// Direct term d (N/N).
    pub d: f64,
    /// Pole-residue terms.
    pub terms: Vec<TermJson>,
    /// The discrete model of the design (absent in older sidecars: FOH).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub discrete: Option<DiscreteModel>,
    /// Both states of a design from two FRFs (`design --frf A --frf B`;
    /// absent otherwise and in older sidecars).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub two_state: Option<crate::offline::sidecar::TwoStateJson>,
    /// The harmonic force prior of `compensate --offline` (`design
    /// --force-prior harmonics`; absent otherwise and in older sidecars).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub force_prior: Option<crate::offline::force_prior::HarmonicPrior>,
    /// The record's force spectrum q was chosen for (`design --force-prior
    /// spectrum`; absent otherwise and in older sidecars).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub force_spectrum: Option<crate::design::force_spectrum::SpectrumProvenance>,
    /// The band-limited force model of the design (`design --above-band
    /// quiet`, the default; absent for the random walk and in older
    /// sidecars): the offline smoother uses it too.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub force_shape: Option<crate::design::kalman::ForceShape>,
    /// Why the axis is passed through raw (`design` could not compensate
    /// it; absent otherwise and in older sidecars): `compensate --offline`
    /// outputs its measured force unchanged.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub passed_through_raw: Option<String>,
    /// Why the axis holds the first FRF's state in a design from two FRFs
    /// (`design --frf A --frf B` could not pair its two states; absent
    /// otherwise and in older sidecars): `compensate --offline --drift`
    /// smooths it with the first state's model, not following the drift.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub holds_first_state: Option<String>,
    /// Non-minimum-phase zeros of the model where the box output is worse
    /// than raw ([`crate::design::phase_limit`]; absent where there are none
    /// and in older sidecars): `compensate` with the box filter says so.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub phase_limits: Vec<crate::design::phase_limit::PhaseLimit>,
}

/// The sidecar's terms of a pole-residue model.
pub fn terms_to_json(m: &PoleResidueModel) -> Vec<TermJson> {
    m.terms
        .iter()
        .map(|t| match *t {
            Term::Real { pole, residue } => TermJson::Real { pole, residue },
            Term::Pair { pole, residue } => {
                TermJson::Pair { pole: [pole.re, pole.im], residue: [residue.re, residue.im] }
            }
        })
        .collect()
}

/// The pole-residue model of sidecar terms, validated (finite, stable poles
/// with Im > 0); the error names `source` and axis `name`.
pub fn model_from_json(d: f64, terms: &[TermJson], source: &str, name: &str) -> Result<PoleResidueModel> {
    let model = PoleResidueModel {
        terms: terms
            .iter()
            .map(|t| match t {
                TermJson::Real { pole, residue } => Term::Real { pole: *pole, residue: *residue },
                TermJson::Pair { pole, residue } => Term::Pair {
                    pole: Complex64::new(pole[0], pole[1]),
                    residue: Complex64::new(residue[0], residue[1]),
                },
            })
            .collect(),
        d,
    };
    let finite = d.is_finite()
        && terms.iter().all(|t| match t {
            TermJson::Real { pole, residue } => pole.is_finite() && residue.is_finite(),
            TermJson::Pair { pole, residue } => pole.iter().chain(residue).all(|v| v.is_finite()) && pole[1] > 0.0,
        });
    if !finite || !model.is_stable() {
        bail!("{source}: axis {name}: the model has non-finite values or unstable poles; re-run `dynocomp design`");
    }
    Ok(model)
}

/// The sidecar `<image>.model.json` written by `dynocomp design`: the fitted
/// model per axis, tied to one image.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModelSidecar {
    /// Always [`SIDECAR_FORMAT`].
    pub format: String,
    /// Id (CRC-32, 8 hex digits) of the image this model belongs to.
    pub image_id: String,
    /// SHA-256 of the source FRF file (hex), as in the image.
    pub source_sha256: String,
    /// Sample rate of the image (Hz).
    pub fs_hz: f64,
    /// Models per axis: every axis of a box image (format 1); the rows
    /// designed per axis of a 3x3 image (format 3).
    pub axes: Vec<AxisModelJson>,
    /// The 3x3 model of a 3x3 image (format 3; absent otherwise and in
    /// older sidecars): `compensate --offline` smooths its 3x3 rows with it
    /// ([`crate::offline::matrix_smoother`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub matrix: Option<crate::offline::matrix_model::MatrixModelJson>,
}

/// An image a sidecar can belong to: what ties the two together.
pub trait SidecarOwner {
    /// The image's id (CRC-32).
    fn image_id(&self) -> u32;
    /// SHA-256 of the FRF file it was designed from.
    fn source_sha256(&self) -> &[u8; 32];
    /// Its sample rate (Hz).
    fn fs_hz(&self) -> u32;
    /// Its design method.
    fn method(&self) -> DesignMethod;
}

/// Both box image formats that `design` writes a sidecar for.
macro_rules! sidecar_owner {
    ($($image:ty),*) => {$(
        impl SidecarOwner for $image {
            fn image_id(&self) -> u32 {
                self.id()
            }
            fn source_sha256(&self) -> &[u8; 32] {
                &self.source_sha256
            }
            fn fs_hz(&self) -> u32 {
                self.fs_hz
            }
            fn method(&self) -> DesignMethod {
                self.method
            }
        }
    )*};
}
sidecar_owner!(CoeffImage, MatrixImage);

/// Path of the model sidecar of an image: `<image>.model.json`.
pub fn sidecar_path(image: &Path) -> PathBuf {
    let mut s = image.as_os_str().to_owned();
    s.push(".model.json");
    PathBuf::from(s)
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

impl ModelSidecar {
    /// Sidecar for `image` with the given per-axis models `(axis, model)`.
    pub fn new(image: &impl SidecarOwner, models: &[(usize, &PoleResidueModel, Option<&DiscreteModel>)]) -> Self {
        let axes = models
            .iter()
            .map(|(axis, m, dm)| AxisModelJson {
                discrete: dm.cloned(),
                axis: axis_name(*axis).to_string(),
                d: m.d,
                terms: terms_to_json(m),
                two_state: None,
                force_prior: None,
                force_spectrum: None,
                force_shape: None,
                passed_through_raw: None,
                holds_first_state: None,
                phase_limits: Vec::new(),
            })
            .collect();
        ModelSidecar {
            format: SIDECAR_FORMAT.into(),
            image_id: format!("{:08x}", image.image_id()),
            source_sha256: hex(image.source_sha256()),
            fs_hz: f64::from(image.fs_hz()),
            axes,
            matrix: None,
        }
    }

    /// Sidecar for `image` with the models of `designs`, each with its
    /// force shape and, for an axis passed through raw, why.
    pub fn of_designs<D: std::borrow::Borrow<AxisDesign>>(image: &impl SidecarOwner, designs: &[D]) -> Self {
        let designs: Vec<&AxisDesign> = designs.iter().map(|d| d.borrow()).collect();
        let models: Vec<_> = designs.iter().map(|d| (d.axis, &d.model, d.discrete.as_ref().map(|x| &x.0))).collect();
        let mut sidecar = ModelSidecar::new(image, &models);
        for (m, d) in sidecar.axes.iter_mut().zip(designs) {
            m.force_shape = d.kalman.force_shape;
            m.passed_through_raw = d.pass_through.clone();
            m.phase_limits = d.phase_limits.clone();
        }
        sidecar
    }

    /// The model of `axis`, validated (finite, stable poles with Im ≥ 0).
    pub fn model(&self, axis: usize, source: &str) -> Result<PoleResidueModel> {
        let name = axis_name(axis);
        let Some(a) = self.axes.iter().find(|a| a.axis == name) else {
            bail!("{source}: no model for axis {name}; re-run `dynocomp design` for this axis");
        };
        model_from_json(a.d, &a.terms, source, name)
    }

    /// The discrete model of `axis` for the smoother: the stored one,
    /// validated (finite, poles inside the unit circle, a short advance), or
    /// the first-order hold of Ĝ(s) for a sidecar that has none.
    pub fn discrete_model(&self, axis: usize, source: &str) -> Result<DiscreteModel> {
        let model = self.model(axis, source)?;
        let name = axis_name(axis);
        let stored = self.axes.iter().find(|a| a.axis == name).and_then(|a| a.discrete.clone());
        let Some(dm) = stored else {
            return Ok(discretize(&model, self.fs_hz, Discretization::Foh, (0.0, 0.0))?.0);
        };
        let finite = dm.d.is_finite()
            && dm.fir.iter().all(|v| v.is_finite())
            && dm.terms.iter().all(|t| match *t {
                crate::design::discretize::DTerm::Real { pole, residue } => pole.is_finite() && residue.is_finite(),
                crate::design::discretize::DTerm::Pair { pole, residue } => {
                    [pole.0, pole.1, residue.0, residue.1].iter().all(|v| v.is_finite())
                }
            });
        if !finite || !(dm.pole_radius() < 1.0) || dm.fs_hz != self.fs_hz || dm.advance > 64 || dm.fir.len() > 64 {
            bail!("{source}: axis {name}: the discrete model is not valid (non-finite, unstable, another rate, or too long); re-run `dynocomp design`");
        }
        Ok(dm)
    }

    /// Why `axis` holds the first FRF's state in a design from two FRFs;
    /// `None` where it follows both states or the design had one FRF.
    pub fn holds_first_state(&self, axis: usize) -> Option<&str> {
        let name = axis_name(axis);
        self.axes.iter().find(|a| a.axis == name).and_then(|a| a.holds_first_state.as_deref())
    }

    /// Why `axis` is passed through raw (`design` could not compensate it);
    /// `None` where it is compensated.
    pub fn passed_through_raw(&self, axis: usize) -> Option<&str> {
        let name = axis_name(axis);
        self.axes.iter().find(|a| a.axis == name).and_then(|a| a.passed_through_raw.as_deref())
    }

    /// The band-limited force model of `axis`, validated (a finite corner
    /// below fs/2, order 2 or 4); `None` where the design used the random walk.
    pub fn force_shape(&self, axis: usize, source: &str) -> Result<Option<crate::design::kalman::ForceShape>> {
        let name = axis_name(axis);
        let shape = self.axes.iter().find(|a| a.axis == name).and_then(|a| a.force_shape);
        if let Some(s) = shape {
            if !(s.corner_hz > 0.0 && s.corner_hz < self.fs_hz / 2.0 && matches!(s.order, 2 | 4)) {
                bail!("{source}: axis {name}: the force shape (corner {} Hz, order {}) is not valid at {} Hz; re-run `dynocomp design`", s.corner_hz, s.order, self.fs_hz);
            }
        }
        Ok(shape)
    }
}

/// Write the sidecar of the image at `image_path` alone, atomically (the
/// image already written; see [`write_image_and_sidecar`] for both).
pub fn write_sidecar(image_path: &Path, sidecar: &ModelSidecar) -> Result<()> {
    let text = serde_json::to_string_pretty(sidecar)?;
    crate::io::atomic::write_bytes_atomic(&sidecar_path(image_path), text.as_bytes())
}

/// Write `image` at `image_path` and its sidecar so that the pair changes
/// together or not at all ([`crate::io::atomic::write_bytes_pair_atomic`]).
/// With no sidecar (the paper's method) a sidecar left by an earlier design
/// is removed after the image is written: it belongs to the old image.
pub fn write_image_and_sidecar(image_path: &Path, image: &CoeffImage, sidecar: Option<&ModelSidecar>) -> Result<()> {
    let bytes = crate::io::image_file::encode_image_checked(image_path, image)?;
    write_pair(image_path, &bytes, sidecar)
}

/// [`write_image_and_sidecar`] for a 3x3 image (format 3), whose sidecar
/// holds the 3x3 model.
pub fn write_matrix_image_and_sidecar(image_path: &Path, image: &MatrixImage, sidecar: &ModelSidecar) -> Result<()> {
    let bytes = crate::io::image_file::encode_matrix_image_checked(image_path, image)?;
    write_pair(image_path, &bytes, Some(sidecar))
}

fn write_pair(image_path: &Path, bytes: &[u8], sidecar: Option<&ModelSidecar>) -> Result<()> {
    let path = sidecar_path(image_path);
    match sidecar {
        Some(s) => {
            let text = serde_json::to_string_pretty(s)?;
            crate::io::atomic::write_bytes_pair_atomic(image_path, bytes, &path, text.as_bytes())
        }
        None => {
            crate::io::atomic::write_bytes_atomic(image_path, bytes)?;
            remove_stale_sidecar(image_path)
        }
    }
}

/// Remove the sidecar beside `image_path`, if there is one: after an image
/// without a sidecar was written there, it describes another image.
pub fn remove_stale_sidecar(image_path: &Path) -> Result<()> {
    if crate::io::atomic::is_stdio(image_path) {
        return Ok(());
    }
    let path = sidecar_path(image_path);
    match std::fs::remove_file(&path) {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(e).with_context(|| {
            format!("{}: the image was written, but this sidecar of the old image could not be removed", path.display())
        }),
        _ => Ok(()),
    }
}

/// Read the sidecar of the image at `image_path` and check that it belongs
/// to `image` (id, source hash, rate).
pub fn read_sidecar(image_path: &Path, image: &impl SidecarOwner) -> Result<ModelSidecar> {
    if image.method() != DesignMethod::VectorFitting {
        bail!(
            "{}: --offline needs an image designed with the default method (vf): the smoother uses its discrete-time q and R and fitted model",
            image_path.display()
        );
    }
    let path = sidecar_path(image_path);
    let shown = path.display().to_string();
    let text = std::fs::read_to_string(&path).with_context(|| {
        format!("{shown}: cannot read the model sidecar that --offline needs (`dynocomp design` writes it next to the image)")
    })?;
    parse_sidecar(&text, &shown, image, image_path)
}

/// Parse the text of a model sidecar (shown as `shown` in errors) and check
/// that it belongs to `image`, stored at `image_path`: the pure part of
/// [`read_sidecar`].
pub fn parse_sidecar(text: &str, shown: &str, image: &impl SidecarOwner, image_path: &Path) -> Result<ModelSidecar> {
    // serde_json's message quotes the offending value (an unknown `kind`),
    // which may hold newlines and be long: escaped and capped, so the error
    // stays one line, with the place first so the cap cannot cut it off.
    let s: ModelSidecar = serde_json::from_str(text).map_err(|e| {
        let msg = e.to_string();
        let place = format!(" at line {} column {}", e.line(), e.column());
        let what = msg.strip_suffix(&place).unwrap_or(&msg);
        anyhow::anyhow!(
            "{shown}: line {} column {}: not a valid model sidecar: {}",
            e.line(),
            e.column(),
            one_line(what)
        )
    })?;
    if s.format != SIDECAR_FORMAT {
        bail!("{shown}: format `{}`, expected `{SIDECAR_FORMAT}`", one_line(&s.format));
    }
    let id = format!("{:08x}", image.image_id());
    if s.image_id != id || s.source_sha256 != hex(image.source_sha256()) || s.fs_hz != f64::from(image.fs_hz()) {
        bail!(
            "{shown}: belongs to image {} (source {}), not to {} (image {id}); re-run `dynocomp design` to write both together",
            one_line(&s.image_id),
            one_line(s.source_sha256.get(..12).unwrap_or(&s.source_sha256)),
            image_path.display()
        );
    }
    Ok(s)
}

/// Both states of one axis in the model sidecar (`design --frf A --frf B`).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TwoStateJson {
    /// Direct term of state 0.
    pub d_before: f64,
    /// Terms of state 0 (paired order).
    pub before: Vec<TermJson>,
    /// Direct term of state 1.
    pub d_after: f64,
    /// Terms of state 1 (in the order of their partners in `before`).
    pub after: Vec<TermJson>,
    /// Compensated band of the unit-circle discretization (Hz).
    pub band_hz: (f64, f64),
    /// FIR taps of state 0's discrete model.
    pub fir_taps: usize,
    /// Advance of state 0's discrete model (samples).
    pub advance: usize,
}

impl TwoStateJson {
    /// The sidecar entry for the paired states `ts`, the design band and
    /// state 0's discrete structure.
    pub fn new(ts: &TwoState, band_hz: (f64, f64), dm0: &DiscreteModel) -> Self {
        TwoStateJson {
            d_before: ts.before.d,
            before: terms_to_json(&ts.before),
            d_after: ts.after.d,
            after: terms_to_json(&ts.after),
            band_hz,
            fir_taps: dm0.fir.len(),
            advance: dm0.advance,
        }
    }

    /// The paired states, validated (the pairing is checked again,
    /// [`TwoState::checked`]).
    pub fn states(&self, source: &str, name: &str) -> Result<TwoState> {
        let b = model_from_json(self.d_before, &self.before, source, name)?;
        let a = model_from_json(self.d_after, &self.after, source, name)?;
        TwoState::checked(name, b, a).with_context(|| source.to_string())
    }
}
