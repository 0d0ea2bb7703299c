//! Shared fixtures of the host tests against simulated truth.
#![allow(dead_code)]

use dynocomp::design::axis::{design_axis, AxisDesign, DesignOptions};
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
        .map(|ax| {
            design_axis(&s.frf.freq_hz, s.frf.axis(ax).unwrap(), sample_variance(&s.idle[ax]), &opts)
                .unwrap_or_else(|e| panic!("axis {ax}: {e:#}"))
        })
        .collect()
}

/// White force at the fine rate `f_fine`, low-passed at `f_hi`, RMS `rms` (N):
/// the flat in-band spectrum the design's criterion declares.
pub fn flat_force(len: usize, f_fine: f64, f_hi: f64, rms: f64, seed: u64) -> Vec<f64> {
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let n = Normal::new(0.0, 1.0).unwrap();
    let w: Vec<f64> = (0..len).map(|_| n.sample(&mut rng)).collect();
    let x = dynocomp::metrics::lowpass(&w, f_fine, f_hi);
    let r = (x.iter().map(|v| v * v).sum::<f64>() / len as f64).sqrt();
    x.iter().map(|v| v * rms / r).collect()
}

/// Measured NRMSE of design `d` (axis `d.axis` of `s`) through its
/// coefficient image (latency removed) on `force_fine` measured by the true
/// axis with its sensor modes shifted by `pct` %, against the band-limited
/// truth over the design's compensated band.
pub fn measured_shifted(s: &SimOutput, d: &AxisDesign, force_fine: &[f64], pct: f64) -> f64 {
    use dynocomp::io::signal_csv::SignalRecord;
    let p = &s.params;
    let a = d.axis;
    let dyn_ = dynocomp::simulate::drift::shift_sensor_modes(s.dyno.axis(a), pct / 100.0);
    let (truth, clean) = p.anti_alias.acquire(&dyn_, force_fine, p.fs_hz, p.oversample, p.n_samples());
    let meas = p.measurement.apply(&clean, 1000 + a as u64);
    let img =
        dynocomp::design::image::build_image(std::slice::from_ref(d), p.fs_hz as u32, d.kalman.lag, 5000.0, [0; 32])
            .expect("image");
    let rec = SignalRecord { t_s: None, channels: vec![(a, meas)] };
    let out =
        dynocomp::offline::compensate::compensate_record(&img, &rec, false, "measured_shifted").expect("compensate");
    dynocomp::metrics::accuracy(out.channel(a).expect("axis"), &truth, p.fs_hz, d.compensated_band_hz.1).nrmse
}
