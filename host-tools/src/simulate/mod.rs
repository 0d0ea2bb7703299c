//! Synthetic dynamometers, impact tests and milling forces with known truth:
//! the project's ground truth, computed in f64 and independent of the
//! compensator (it never calls `dynocomp_core`'s kernel, and imports only the
//! leaves of the chain). [`dynamometer`] and [`plate`] give the plants,
//! [`impact`] the hammer tests, [`milling`] the forces, [`chain`] and
//! [`measurement`] the acquisition; [`simulate`] runs all of it from one seed
//! and [`run`] writes the files of `dynocomp simulate`.

pub mod chain;
pub mod drift;
pub mod dynamometer;
pub mod files;
pub mod impact;
pub mod measurement;
pub mod milling;
pub mod plate;
pub mod presets;

pub mod shaker;

pub use chain::{AntiAlias, Butterworth, BRICK_WALL_FRACTION};
pub use dynamometer::{Dynamometer, Hold, Mode, ModeRanges, ModeStep, MultiAxisDynamometer};
pub use impact::{
    h1_random_error, impact_freqs, impact_test, impact_test_all, impact_test_all_with, impact_test_axis, ImpactParams,
};
pub use measurement::MeasurementParams;
pub use milling::{milling_force, Chatter, MillingMode, MillingParams};
pub use shaker::Excitation;

use anyhow::{bail, Result};
use serde::{Deserialize, Serialize};

use crate::frf::Frf;

/// Everything the simulator needs besides the seed.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SimParams {
    /// Output sample rate (Hz).
    pub fs_hz: f64,
    /// Length of the cutting record (s).
    pub duration_s: f64,
    /// Length of the idle (no engagement) record (s).
    pub idle_duration_s: f64,
    /// Internal oversampling of the true force and the model (≥ 1).
    pub oversample: usize,
    /// Anti-aliasing chain in front of the sampler (default: the DAQ's ideal
    /// brick wall at 0.45 fs).
    #[serde(default)]
    pub anti_alias: AntiAlias,
    /// Measurement noise and ADC (after the anti-aliasing filter).
    pub measurement: MeasurementParams,
    /// Ranges of the random dynamometer modes.
    pub modes: ModeRanges,
    /// Impact test.
    pub impact: ImpactParams,
    /// Cutting conditions.
    pub milling: MillingParams,
    /// A shaker force applied instead of the cutting force (the paper's
    /// validation tests, [`shaker`]); `None` = milling.
    #[serde(default)]
    pub excitation: Option<Excitation>,
}

impl Default for SimParams {
    fn default() -> Self {
        Self {
            fs_hz: 51_200.0,
            duration_s: 1.0,
            idle_duration_s: 1.0,
            oversample: 8,
            anti_alias: AntiAlias::default(),
            measurement: MeasurementParams::default(),
            modes: ModeRanges::default(),
            impact: ImpactParams::default(),
            milling: MillingParams::default(),
            excitation: None,
        }
    }
}

/// Most samples at the internal rate fs·oversample of one simulated record
/// (cutting and idle): about 110 bytes each are held, so 2.5·10⁷ (60 s at
/// 51.2 kHz with the default oversampling of 8) stay near 3 GB.
pub const MAX_FINE_SAMPLES: f64 = 2.5e7;

/// Sample rates the simulator takes (Hz): the box's and `design`'s range.
pub const FS_RANGE_HZ: (f64, f64) = (1.0e3, 1.0e6);

/// Most teeth of a cutter (face mills have up to about 30).
pub const MAX_TEETH: usize = 100;

/// Fastest spindle (rev/min): high-speed spindles reach 60 000-100 000.
pub const MAX_SPINDLE_RPM: f64 = 200_000.0;

/// Most impact-test lines and impacts.
pub const MAX_FRF_LINES: usize = 1 << 20;
/// Most averaged impacts.
pub const MAX_IMPACTS: usize = 1000;

/// The force of a simulation as truth.json states it: what it is, and the
/// cut's tooth-passing and spindle frequencies (Hz) when it is a milling cut
/// (absent for a shaker or flat force, which have none).
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct ForceLines {
    /// `milling`, or the excitation's name ([`shaker::Excitation::name`]).
    pub force: &'static str,
    /// The cut's tooth-passing frequency (Hz).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tooth_passing_hz: Option<f64>,
    /// The cut's spindle frequency (Hz).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub spindle_hz: Option<f64>,
}

impl SimParams {
    /// What drives the simulated dynamometer, for truth.json.
    pub fn force_lines(&self) -> ForceLines {
        match &self.excitation {
            Some(e) => ForceLines { force: e.name(), tooth_passing_hz: None, spindle_hz: None },
            None => ForceLines {
                force: "milling",
                tooth_passing_hz: Some(self.milling.tooth_passing_hz()),
                spindle_hz: Some(self.milling.spindle_hz()),
            },
        }
    }

    /// Check the parameters against their physical ranges (and the memory
    /// of [`MAX_FINE_SAMPLES`]); the error names the offending one.
    pub fn validate(&self) -> Result<()> {
        let (fs_lo, fs_hi) = FS_RANGE_HZ;
        if !(self.fs_hz.is_finite() && self.fs_hz >= fs_lo && self.fs_hz <= fs_hi) {
            bail!("simulate: sample rate fs = {} Hz must be within {fs_lo}..={fs_hi} Hz", self.fs_hz);
        }
        if !(self.duration_s.is_finite() && self.duration_s > 0.0) {
            bail!("simulate: duration = {} s must be > 0", self.duration_s);
        }
        if !(self.idle_duration_s.is_finite() && self.idle_duration_s >= 0.0) {
            bail!("simulate: idle duration = {} s must be ≥ 0", self.idle_duration_s);
        }
        if self.oversample == 0 || self.oversample > 64 {
            bail!("simulate: oversample = {} must be in 1..=64", self.oversample);
        }
        for (what, d) in [("duration", self.duration_s), ("idle duration", self.idle_duration_s)] {
            let fine = d * self.fs_hz * self.oversample as f64;
            if fine > MAX_FINE_SAMPLES {
                bail!(
                    "simulate: {what} = {d} s at {} Hz with oversample {} needs {fine:.3e} internal samples, more than the limit of \
                     {MAX_FINE_SAMPLES:.1e} (at most {:.1} s at this rate)",
                    self.fs_hz,
                    self.oversample,
                    MAX_FINE_SAMPLES / (self.fs_hz * self.oversample as f64)
                );
            }
        }
        self.anti_alias.validate()?;
        let m = &self.measurement;
        if !(m.noise_variance_n2.is_finite() && m.noise_variance_n2 >= 0.0) {
            bail!("simulate: noise variance = {} N² must be ≥ 0", m.noise_variance_n2);
        }
        if m.adc_bits > 32 || (m.adc_bits > 0 && !(m.adc_range_n.is_finite() && m.adc_range_n > 0.0)) {
            bail!("simulate: ADC {} bits over ±{} N is not valid (bits ≤ 32, range > 0)", m.adc_bits, m.adc_range_n);
        }
        let i = &self.impact;
        if i.n_lines > MAX_FRF_LINES || i.n_impacts > MAX_IMPACTS {
            bail!("simulate: impact test of {} lines and {} impacts: at most {MAX_FRF_LINES} lines and {MAX_IMPACTS} impacts", i.n_lines, i.n_impacts);
        }
        if i.n_lines < 2 || !(i.df_hz.is_finite() && i.df_hz > 0.0) || i.n_impacts == 0 {
            bail!(
                "simulate: impact test needs ≥ 2 lines, df > 0 and ≥ 1 impact (got {} lines, df {} Hz, {} impacts)",
                i.n_lines,
                i.df_hz,
                i.n_impacts
            );
        }
        if !(i.hammer_cutoff_hz.is_finite() && i.hammer_cutoff_hz > 0.0) {
            bail!("simulate: hammer cutoff = {} Hz must be > 0", i.hammer_cutoff_hz);
        }
        self.milling.validate()?;
        if let Some(e) = &self.excitation {
            e.validate(self.fs_hz)?;
        }
        if let Some(ch) = &self.milling.chatter {
            if ch.freq_hz >= self.fs_hz / 2.0 {
                bail!("simulate: chatter frequency {} Hz is not below fs/2 = {} Hz", ch.freq_hz, self.fs_hz / 2.0);
            }
        }
        Ok(())
    }

    /// The applied force at `fs·oversample` (N), `n_fine` samples: the
    /// shaker's if one is set, else the milling force.
    pub fn applied_force(&self, n_fine: usize) -> [Vec<f64>; 3] {
        let fs_fine = self.fs_hz * self.oversample as f64;
        match &self.excitation {
            Some(e) => e.force(fs_fine, n_fine, self.duration_s),
            None => milling_force(&self.milling, fs_fine, n_fine),
        }
    }

    /// Number of output samples of the cutting record.
    pub fn n_samples(&self) -> usize {
        (self.duration_s * self.fs_hz).round().max(1.0) as usize
    }

    /// Number of output samples of the idle record.
    pub fn n_idle_samples(&self) -> usize {
        (self.idle_duration_s * self.fs_hz).round() as usize
    }
}

/// All simulated data, on a common time base `t_s[k] = k/fs_hz`.
#[derive(Clone, Debug)]
pub struct SimOutput {
    /// Seed that produced it.
    pub seed: u64,
    /// Parameters that produced it.
    pub params: SimParams,
    /// The true dynamometer.
    pub dyno: MultiAxisDynamometer,
    /// Simulated impact test of the three axes (H1 and coherence).
    pub frf: Frf,
    /// Sample times (s).
    pub t_s: Vec<f64>,
    /// True applied force (N), x/y/z.
    pub truth: [Vec<f64>; 3],
    /// Noise-free dynamometer output (N), x/y/z.
    pub clean: [Vec<f64>; 3],
    /// Measured force: dynamometer output + noise, quantized (N), x/y/z.
    pub measured: [Vec<f64>; 3],
    /// Idle record (noise and quantization only), x/y/z.
    pub idle: [Vec<f64>; 3],
}

/// Independent stream seeds derived from the user's seed (splitmix64 of seed ⊕ tag),
/// so that each part of the simulation has its own reproducible randomness.
pub fn sub_seed(seed: u64, tag: u64) -> u64 {
    let mut z = seed ^ tag.wrapping_mul(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

pub(crate) const TAG_DYNO: u64 = 1;
pub(crate) const TAG_IMPACT: u64 = 2;
pub(crate) const TAG_NOISE: u64 = 10; // + axis
pub(crate) const TAG_IDLE: u64 = 20; // + axis
/// The seed of `simulate --flat-force`'s noise (+ axis inside it).
pub(crate) const TAG_FLAT_FORCE: u64 = 50;

/// Measure `force_fine` (defined at `fs·oversample`, at least
/// `chain.fine_len(n, oversample)` samples) with `dyn_` through the
/// acquisition `chain`: returns (band-limited truth, clean output), `n`
/// samples at fs. With [`AntiAlias::None`] this keeps every `oversample`-th
/// sample of the force and of the model's response.
pub fn measure_decimated(
    dyn_: &Dynamometer,
    chain: &AntiAlias,
    force_fine: &[f64],
    fs_hz: f64,
    oversample: usize,
    n: usize,
) -> (Vec<f64>, Vec<f64>) {
    chain.acquire(dyn_, force_fine, fs_hz, oversample, n)
}

/// Run the whole simulation for `seed`: a random three-axis dynamometer, its
/// impact test, the milling force, the measured and idle records.
pub fn simulate(seed: u64, params: &SimParams) -> Result<SimOutput> {
    params.validate()?;
    let dyno = MultiAxisDynamometer::random(sub_seed(seed, TAG_DYNO), params);
    simulate_with(seed, params, dyno)
}

/// As [`simulate`], with a given dynamometer.
///
/// Time records: the true force is generated at `fs·oversample`, passed through
/// each axis's model at that rate (exact for a force linear between the fine
/// samples) and the analog front end if any, then both the force and the
/// dynamometer output go through the DAQ's zero-phase brick wall at 0.45 fs and
/// are taken every `oversample`-th sample: `measured[k]` is the band-limited
/// response at `t_k = k/fs` and `true[k]` the applied force through the same
/// band limit at the same instant (DESIGN.md, "Accuracy, stated one way
/// everywhere"). Noise and quantization are added after the filter.
pub fn simulate_with(seed: u64, params: &SimParams, dyno: MultiAxisDynamometer) -> Result<SimOutput> {
    params.validate()?;
    let ip = &params.impact;
    // The impact test runs through the same analog front end.
    let chain = &params.anti_alias;
    let frf = impact_test_all_with(
        &|a, f| dyno.axis(a).frf(f) * chain.analog_frf(f),
        ip.n_lines,
        ip.df_hz,
        sub_seed(seed, TAG_IMPACT),
        ip,
    );
    let n = params.n_samples();
    let os = params.oversample;
    let fine = params.applied_force(chain.fine_len(n, os));
    let mut truth: [Vec<f64>; 3] = Default::default();
    let mut clean: [Vec<f64>; 3] = Default::default();
    let mut measured: [Vec<f64>; 3] = Default::default();
    let mut idle: [Vec<f64>; 3] = Default::default();
    for a in 0..3 {
        let (t, c) = measure_decimated(dyno.axis(a), chain, &fine[a], params.fs_hz, os, n);
        measured[a] = params.measurement.apply(&c, sub_seed(seed, TAG_NOISE + a as u64));
        idle[a] = params.measurement.idle(params.n_idle_samples(), sub_seed(seed, TAG_IDLE + a as u64));
        truth[a] = t;
        clean[a] = c;
    }
    let t_s = (0..n).map(|k| k as f64 / params.fs_hz).collect();
    Ok(SimOutput { seed, params: params.clone(), dyno, frf, t_s, truth, clean, measured, idle })
}
