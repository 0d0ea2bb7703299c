//! Set-ups whose sensor modes move (issue #15): the workpiece loses mass
//! while it is machined, so the dynamometer's modes drift during the cut.
//!
//! **Sensor modes of a simulated axis** (the same rule as the design's,
//! [`crate::sensitivity`], applied to the true modes): the main mode is the
//! one with the largest residue, the sensor modes are those whose natural
//! frequency is at least [`crate::sensitivity::SENSOR_FRACTION`] × the main
//! mode's; machine-structure modes stay put. A shift by the relative δ
//! multiplies their natural frequencies by (1 + δ) and keeps their damping
//! ratio and residue (static share): a change of mass at constant stiffness.
//!
//! **Drifting record** ([`measure_drifting`]): the shift goes linearly in time
//! from 0 at `start_s` to δ at `end_s` and is constant outside. Each mode is
//! integrated as its own 2x2 system `ẍ + 2ζωẋ + ω²x = rω²u` (the simulator's
//! exact first-order-hold step, [`ModeStep`]), its ω and ζ updated per block
//! of [`DRIFT_BLOCK`] fine samples (ω taken at the block's middle); across a
//! block boundary the state (x, ẋ) is kept, so displacement and velocity are
//! continuous, and only the step matrices are derived again. A constant
//! model (no drift) reproduces [`Dynamometer::measure`] bit for bit.

use super::dynamometer::{Dynamometer, Hold, Mode, ModeStep};
use crate::sensitivity::SENSOR_FRACTION;

/// Fine samples per block of constant modal parameters in a drifting record.
pub const DRIFT_BLOCK: usize = 64;

/// Indices of the sensor modes of `dyn_` (module doc).
pub fn sensor_modes(dyn_: &Dynamometer) -> Vec<usize> {
    let main = dyn_.main_mode();
    dyn_.modes.iter().enumerate().filter(|(_, m)| m.fn_hz >= SENSOR_FRACTION * main.fn_hz).map(|(i, _)| i).collect()
}

/// `dyn_` with its sensor modes moved by the relative shift `delta`
/// (module doc); the modes stay sorted by frequency.
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
    /// Relative shift at time `t_s`.
    pub fn shift_at(&self, t_s: f64) -> f64 {
        if t_s <= self.start_s {
            0.0
        } else if t_s >= self.end_s {
            self.delta
        } else {
            self.delta * (t_s - self.start_s) / (self.end_s - self.start_s)
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
/// rest) while its sensor modes drift by `drift` (module doc). Mode k's
/// parameters on the step from sample j to j + 1 are those of the block
/// containing j, at the time of the block's middle.
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
