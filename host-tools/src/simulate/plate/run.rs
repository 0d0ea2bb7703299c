//! A whole simulation on the plate dynamometer: the impact tests of all nine
//! FRFs at the impact point, the cutting (or shaker) force acting at the cut
//! point, the acquisition chain, noise and the idle record, exactly as
//! [`crate::simulate::simulate_with`] does for the per-axis model: the true
//! force goes through the same anti-aliasing filter as the measurement.

use anyhow::{bail, Result};
use serde::{Deserialize, Serialize};

use super::impact::impact_test_matrix;
use super::modal::PlateModal;
use super::setup::{check_point, PlateSetup};
use crate::frf::Frf;
use crate::simulate::{sub_seed, SimParams, TAG_IDLE, TAG_IMPACT, TAG_NOISE};

/// Largest |component| of the cut point's offset from the impact point (m).
pub const MAX_CUT_OFFSET_M: f64 = 0.1;

/// The plate dynamometer of a simulation and where the force acts.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PlateSim {
    /// The set-up; its `force_point_m` is the impact point.
    pub setup: PlateSetup,
    /// Where the cutting force acts, from the impact point (m): the tool
    /// moves over the part while the FRF was measured at one point.
    pub cut_offset_m: [f64; 3],
}

impl PlateSim {
    /// The impact point (m).
    pub fn impact_point_m(&self) -> [f64; 3] {
        self.setup.force_point_m
    }

    /// The cut point: impact point + offset (m).
    pub fn cut_point_m(&self) -> [f64; 3] {
        std::array::from_fn(|k| self.setup.force_point_m[k] + self.cut_offset_m[k])
    }

    /// Check the set-up, the offset (|each| ≤ [`MAX_CUT_OFFSET_M`]) and the cut point.
    pub fn validate(&self) -> Result<()> {
        self.setup.validate()?;
        for (k, ax) in ["x", "y", "z"].iter().enumerate() {
            let d = self.cut_offset_m[k];
            if !(d.is_finite() && d.abs() <= MAX_CUT_OFFSET_M) {
                bail!(
                    "plate dynamometer: cut offset {ax} = {d} m is outside ±{MAX_CUT_OFFSET_M} m of the impact point"
                );
            }
        }
        check_point("cut point (impact point + offset)", self.cut_point_m())
    }
}

/// All simulated data of a plate simulation, on `t_s[k] = k/fs_hz`.
#[derive(Clone, Debug)]
pub struct PlateSimOutput {
    /// Seed that produced it.
    pub seed: u64,
    /// Parameters that produced it.
    pub params: SimParams,
    /// The dynamometer and the force points.
    pub plate: PlateSim,
    /// The modal form for a force at the impact point (what the FRF measures).
    pub impact_modal: PlateModal,
    /// The modal form for a force at the cut point (what the record saw).
    pub cut_modal: PlateModal,
    /// Impact tests: all nine entries with coherence.
    pub frf: Frf,
    /// Sample times (s).
    pub t_s: Vec<f64>,
    /// True applied force through the anti-aliasing filter (N), x/y/z.
    pub truth: [Vec<f64>; 3],
    /// Noise-free channels (N), x/y/z.
    pub clean: [Vec<f64>; 3],
    /// Measured channels: clean + noise, quantized (N), x/y/z.
    pub measured: [Vec<f64>; 3],
    /// Idle record (noise and quantization only), x/y/z.
    pub idle: [Vec<f64>; 3],
}

/// Simulate `plate` with `params` from `seed`: random streams as
/// [`crate::simulate::simulate_with`] (impact test, noise and idle per axis),
/// the hammer directions of the impact test each with their own stream.
pub fn simulate_plate(seed: u64, params: &SimParams, plate: &PlateSim) -> Result<PlateSimOutput> {
    params.validate()?;
    plate.validate()?;
    let impact_modal = PlateModal::new(&plate.setup, plate.impact_point_m())?;
    let cut_modal = PlateModal::new(&plate.setup, plate.cut_point_m())?;
    let chain = &params.anti_alias;
    let ip = &params.impact;
    let analog = |f: f64| chain.analog_frf(f);
    let frf = impact_test_matrix(&impact_modal, &analog, ip.n_lines, ip.df_hz, sub_seed(seed, TAG_IMPACT), ip);
    let n = params.n_samples();
    let os = params.oversample;
    let fine = params.applied_force(chain.fine_len(n, os));
    let f_fine = params.fs_hz * os as f64;
    let force = [fine[0].as_slice(), fine[1].as_slice(), fine[2].as_slice()];
    let y = match chain.analog() {
        None => cut_modal.measure(force, f_fine),
        Some(b) => cut_modal.measure_through(b, force, f_fine)?,
    };
    let mut truth: [Vec<f64>; 3] = Default::default();
    let mut clean: [Vec<f64>; 3] = Default::default();
    let mut measured: [Vec<f64>; 3] = Default::default();
    let mut idle: [Vec<f64>; 3] = Default::default();
    for a in 0..3 {
        let (t, c) = chain.acquire_response(&fine[a], &y[a], params.fs_hz, os, n);
        measured[a] = params.measurement.apply(&c, sub_seed(seed, TAG_NOISE + a as u64));
        idle[a] = params.measurement.idle(params.n_idle_samples(), sub_seed(seed, TAG_IDLE + a as u64));
        truth[a] = t;
        clean[a] = c;
    }
    let t_s = (0..n).map(|k| k as f64 / params.fs_hz).collect();
    let (params, plate) = (params.clone(), plate.clone());
    Ok(PlateSimOutput { seed, params, plate, impact_modal, cut_modal, frf, t_s, truth, clean, measured, idle })
}
