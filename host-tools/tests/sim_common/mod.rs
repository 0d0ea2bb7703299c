//! Shared fixtures of the host tests against simulated truth.
#![allow(dead_code)]

use dynocomp::design::{design_axis, AxisDesign, DesignOptions};
use dynocomp::metrics::sample_variance;
use dynocomp::simulate::{simulate, MillingParams, SimOutput, SimParams};

/// Sample rate of the simulated records (Hz).
pub const FS: f64 = 51_200.0;
/// Upper edge of the scored band (Hz): the FRF bandwidth.
pub const F_MAX: f64 = 4_000.0;

/// The parameters of a 0.4 s milling record (0.3 s idle) at `FS`.
pub fn params(rpm: f64, teeth: usize) -> SimParams {
    SimParams {
        fs_hz: FS,
        duration_s: 0.4,
        idle_duration_s: 0.3,
        milling: MillingParams { spindle_rpm: rpm, teeth, ..Default::default() },
        ..Default::default()
    }
}

/// A 0.4 s milling record (0.3 s idle) of a random dynamometer.
pub fn sim(seed: u64, rpm: f64, teeth: usize) -> SimOutput {
    simulate(seed, &params(rpm, teeth)).expect("simulate")
}

/// Default (whole-band vf) designs of the three axes with lag `lag`.
pub fn design_all(s: &SimOutput, lag: usize) -> Vec<AxisDesign> {
    let opts = DesignOptions { lag, fs_hz: FS, ..Default::default() };
    (0..3)
        .map(|ax| design_axis(&s.frf.freq_hz, s.frf.axis(ax).unwrap(), sample_variance(&s.idle[ax]), &opts).unwrap_or_else(|e| panic!("axis {ax}: {e:#}")))
        .collect()
}
