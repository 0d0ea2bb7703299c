//! Set-ups whose sensor modes move: the workpiece loses mass while it is
//! machined, so the dynamometer's modes drift during the cut
//! ([`simulate_drifting`], [`measure_drifting`]).

use anyhow::{bail, Result};

use super::dynamometer::{Dynamometer, Hold, Mode, ModeStep, MultiAxisDynamometer};
use super::{impact_test_all_with, milling_force, simulate_with, sub_seed, SimOutput, SimParams, TAG_NOISE};
use crate::fit::modes::SENSOR_FRACTION;
use crate::frf::Frf;

/// Fine samples per block of constant modal parameters in a drifting record.
pub const DRIFT_BLOCK: usize = 64;

/// Indices of the sensor modes of `dyn_`.
///
/// The same rule as the design's ([`crate::design::sensitivity`]), applied
/// to the true modes: the main mode is the one with the largest residue, the
/// sensor modes are those whose natural frequency is at least
/// [`crate::fit::modes::SENSOR_FRACTION`] × the main mode's;
/// machine-structure modes stay put.
pub fn sensor_modes(dyn_: &Dynamometer) -> Vec<usize> {
    let main = dyn_.main_mode();
    dyn_.modes.iter().enumerate().filter(|(_, m)| m.fn_hz >= SENSOR_FRACTION * main.fn_hz).map(|(i, _)| i).collect()
}

/// `dyn_` with its sensor modes ([`sensor_modes`]) moved by the relative
/// shift `delta`; the modes stay sorted by frequency.
///
/// A shift by the relative δ multiplies their natural frequencies by
/// (1 + δ) and keeps their damping ratio and residue (static share): a
/// change of mass at constant stiffness.
pub fn shift_sensor_modes(dyn_: &Dynamometer, delta: f64) -> Dynamometer {
    let idx = sensor_modes(dyn_);
    let mut modes = dyn_.modes.clone();
    for i in idx {
        modes[i].fn_hz *= 1.0 + delta;
    }
    modes.sort_by(|a, b| a.fn_hz.total_cmp(&b.fn_hz));
    Dynamometer { modes }
}

/// A linear drift of the sensor modes in time.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Drift {
    /// Relative shift at and after `end_s` (e.g. 0.03 = +3 %).
    pub delta: f64,
    /// Start of the drift (s): shift 0 before.
    pub start_s: f64,
    /// End of the drift (s): shift `delta` after.
    pub end_s: f64,
}

impl Drift {
    /// Relative shift of the sensor modes at time `t_s`: 0 before
    /// `start_s`, `delta` after `end_s`, and in between the modal mass
    /// linear in time (a constant material removal rate): 1/f² moves
    /// linearly from 1/f₀² to 1/(f₀(1 + δ))².
    pub fn shift_at(&self, t_s: f64) -> f64 {
        if t_s <= self.start_s {
            0.0
        } else if t_s >= self.end_s {
            self.delta
        } else {
            let tau = (t_s - self.start_s) / (self.end_s - self.start_s);
            1.0 / ((1.0 - tau) + tau / (1.0 + self.delta).powi(2)).sqrt() - 1.0
        }
    }

    /// Check the drift; the error names the flag.
    pub fn validate(&self) -> anyhow::Result<()> {
        if !(self.delta.is_finite() && self.delta > -0.5 && self.delta < 0.5) {
            anyhow::bail!("--drift-percent {}: the drift must be finite and within ±50 %", 100.0 * self.delta);
        }
        if !(self.start_s.is_finite() && self.end_s.is_finite() && self.start_s >= 0.0 && self.end_s > self.start_s) {
            anyhow::bail!("--drift-start {} / --drift-end {}: need 0 ≤ start < end (s)", self.start_s, self.end_s);
        }
        Ok(())
    }
}

/// Response of `dyn_` to `force` (rate `fs_hz`, linear between samples, from
/// rest) while its sensor modes drift by `drift` ([`shift_sensor_modes`]).
/// Mode k's parameters on the step from sample j to j + 1 are those of the
/// block containing j, at the time of the block's middle.
///
/// The shift goes from 0 at `start_s` to δ at `end_s` with the modal mass
/// linear in time (constant material removal rate: 1/f² linear in t,
/// [`Drift::shift_at`]) and is constant outside. Each mode is integrated as
/// its own 2x2 system `ẍ + 2ζωẋ + ω²x = rω²u` (the simulator's exact
/// first-order-hold step, [`ModeStep`]), its ω and ζ updated per block of
/// [`DRIFT_BLOCK`] fine samples; across a block boundary the state (x, ẋ)
/// is kept, so displacement and velocity are continuous, and only the step
/// matrices are derived again. A constant model (no drift) reproduces
/// [`Dynamometer::measure`] bit for bit.
pub fn measure_drifting(dyn_: &Dynamometer, drift: &Drift, force: &[f64], fs_hz: f64) -> Vec<f64> {
    let sensor = sensor_modes(dyn_);
    let h = 1.0 / fs_hz;
    let mut y = vec![0.0; force.len()];
    for (k, m) in dyn_.modes.iter().enumerate() {
        let moves = sensor.contains(&k);
        let (mut x, mut v) = (0.0f64, 0.0f64);
        let mut step = ModeStep::new(m, h, Hold::Foh);
        let mut current = 0.0;
        for j in 1..force.len() {
            let i = j - 1; // the step from sample i to sample j
            if moves && i % DRIFT_BLOCK == 0 {
                let mid = (i as f64 + 0.5 * DRIFT_BLOCK as f64) * h;
                let delta = drift.shift_at(mid);
                if delta != current {
                    current = delta;
                    step = ModeStep::new(&Mode { fn_hz: m.fn_hz * (1.0 + delta), ..*m }, h, Hold::Foh);
                }
            }
            let (u0, u1) = (force[i], force[j]);
            let xn = step.phi[0][0] * x + step.phi[0][1] * v + step.g0[0] * u0 + step.g1[0] * u1;
            let vn = step.phi[1][0] * x + step.phi[1][1] * v + step.g0[1] * u0 + step.g1[1] * u1;
            x = xn;
            v = vn;
            y[j] += x;
        }
    }
    y
}

/// Tag of the second (after-drift) impact test's random stream.
const TAG_IMPACT_AFTER: u64 = 30;

/// A simulation whose sensor modes drift during the cutting record.
#[derive(Clone, Debug)]
pub struct DriftOutput {
    /// The simulation: `frf` is the impact test before the drift (the
    /// set-up at t = 0), `measured`/`clean` come from the drifting set-up,
    /// `truth` is the band-limited applied force (independent of the set-up),
    /// `idle` as without drift.
    pub sim: SimOutput,
    /// The drift.
    pub drift: Drift,
    /// The set-up after the drift (sensor modes shifted by `drift.delta`).
    pub dyno_after: MultiAxisDynamometer,
    /// Impact test of the set-up after the drift (its own noise).
    pub frf_after: Frf,
}

/// Simulate `seed` with `params` on `dyno` (the set-up before the drift)
/// while its sensor modes drift by `drift` ([`measure_drifting`]). Refused with an
/// analog front end in the chain (only the DAQ's brick wall or none).
pub fn simulate_drifting(
    seed: u64,
    params: &SimParams,
    dyno: MultiAxisDynamometer,
    drift: Drift,
) -> Result<DriftOutput> {
    drift.validate()?;
    let chain = params.anti_alias;
    if chain.analog().is_some() {
        bail!("simulate: --drift-percent with an analog front end (--anti-alias {chain}) is not supported; use ideal or none");
    }
    let mut sim = simulate_with(seed, params, dyno)?;
    let n = params.n_samples();
    let os = params.oversample.max(1);
    let f_fine = params.fs_hz * os as f64;
    let fine = milling_force(&params.milling, f_fine, chain.fine_len(n, os));
    for (a, force) in fine.iter().enumerate() {
        let y = measure_drifting(sim.dyno.axis(a), &drift, force, f_fine);
        let (_truth, clean) = chain.acquire_response(force, &y, params.fs_hz, os, n);
        sim.measured[a] = params.measurement.apply(&clean, sub_seed(seed, TAG_NOISE + a as u64));
        sim.clean[a] = clean;
    }
    let dyno_after =
        MultiAxisDynamometer { axes: [0, 1, 2].map(|a| shift_sensor_modes(sim.dyno.axis(a), drift.delta)) };
    let ip = &params.impact;
    let frf_after = impact_test_all_with(
        &|a, f| dyno_after.axis(a).frf(f),
        ip.n_lines,
        ip.df_hz,
        sub_seed(seed, TAG_IMPACT_AFTER),
        ip,
    );
    Ok(DriftOutput { sim, drift, dyno_after, frf_after })
}

/// Content of `drift.json`.
#[derive(serde::Serialize)]
struct DriftJson<'a> {
    format: &'static str,
    version: u32,
    /// Relative shift of the sensor modes at the end (e.g. 0.03).
    delta: f64,
    start_s: f64,
    end_s: f64,
    /// Fine samples per block of constant modal parameters.
    block_fine_samples: usize,
    /// Natural frequencies of the sensor modes before and after, per axis.
    sensor_modes_before_hz: Vec<Vec<f64>>,
    sensor_modes_after_hz: Vec<Vec<f64>>,
    /// Every mode of each axis after the drift.
    modes_after: Vec<&'a [Mode]>,
    files: [&'static str; 3],
}

/// `dynocomp simulate --drift-percent`: simulate the drifting record for
/// `seed` (the random set-up of [`super::simulate`]) and write the files of
/// `dynocomp simulate` plus frf_after.uff, frf_after.csv and drift.json
/// into `dir`.
pub fn run(seed: u64, params: &SimParams, drift: Drift, dir: &std::path::Path) -> Result<SimOutput> {
    drift.validate()?;
    params.validate()?;
    let dyno = MultiAxisDynamometer::random(sub_seed(seed, super::TAG_DYNO), params);
    let out = simulate_drifting(seed, params, dyno, drift)?;
    super::files::write_outputs(dir, &out.sim)?;
    crate::io::uff::write_uff58(&dir.join("frf_after.uff"), &out.frf_after, false)?;
    crate::io::frf_csv::write_frf_csv(&dir.join("frf_after.csv"), &out.frf_after)?;
    let modes_hz = |d: &Dynamometer| sensor_modes(d).iter().map(|&i| d.modes[i].fn_hz).collect::<Vec<f64>>();
    let j = DriftJson {
        format: "dynocomp-simulate-drift",
        version: 1,
        delta: drift.delta,
        start_s: drift.start_s,
        end_s: drift.end_s,
        block_fine_samples: DRIFT_BLOCK,
        sensor_modes_before_hz: (0..3).map(|a| modes_hz(out.sim.dyno.axis(a))).collect(),
        sensor_modes_after_hz: (0..3).map(|a| modes_hz(out.dyno_after.axis(a))).collect(),
        modes_after: (0..3).map(|a| out.dyno_after.axis(a).modes.as_slice()).collect(),
        files: ["frf_after.uff", "frf_after.csv", "drift.json"],
    };
    let text = serde_json::to_string_pretty(&j)?;
    crate::io::atomic::write_bytes_atomic(&dir.join("drift.json"), format!("{text}\n").as_bytes())?;
    eprintln!(
        "  drift: sensor modes {:+.2} % from {} s to {} s; frf.uff = before, frf_after.uff = after",
        100.0 * drift.delta,
        drift.start_s,
        drift.end_s
    );
    Ok(out.sim)
}
