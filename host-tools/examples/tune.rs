//! Design-tuning experiment on simulated dynamometers (not part of the CLI).
use dynocomp::design::axis::{design_axis, DesignOptions};
use dynocomp::metrics::accuracy;
use dynocomp::simulate::{simulate, SimParams};
use dynocomp_core::kernel::AxisState;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let lag: usize = args.get(1).map_or(4, |s| s.parse().unwrap());
    let force_rms: f64 = args.get(2).map_or(100.0, |s| s.parse().unwrap());
    let rpm: f64 = args.get(3).map_or(4125.0, |s| s.parse().unwrap());
    for seed in 1..=3u64 {
        let mut p = SimParams::default();
        p.milling.spindle_rpm = rpm;
        let sim = simulate(seed, &p)?;
        let fs = p.fs_hz;
        for ax in 0..3 {
            let frf = sim.frf.axis(ax).unwrap();
            let r = dynocomp::metrics::sample_variance(&sim.idle[ax]);
            let opts = DesignOptions { lag, force_rms, fs_hz: fs, ..Default::default() };
            let t0 = std::time::Instant::now();
            let d = match design_axis(&sim.frf.freq_hz, frf, r, &opts) {
                Ok(d) => d,
                Err(e) => {
                    println!("seed {seed} axis {ax}: {e:#}");
                    continue;
                }
            };
            let dt = t0.elapsed();
            let mut st = AxisState::default();
            let meas = &sim.measured[ax];
            let mut out: Vec<f64> = meas.iter().map(|u| f64::from(d.filter.step(&mut st, *u as f32))).collect();
            out.drain(..lag);
            let truth = &sim.truth[ax][..out.len()];
            let a = accuracy(&out, truth, fs, 4000.0);
            let raw = accuracy(meas, &sim.truth[ax], fs, 4000.0);
            println!(
                "seed {seed} ax {ax} fn {:.0} order {} secs {} fir {} q {:.2e} R {:.3} ng {:.1} flat {:.0}-{:.0} pred {:.3}% | nrmse {:.3}% (p2p {:.3}%) raw {:.2}% | {:?} fit {:.2}%",
                sim.dyno.axis(ax).main_mode().fn_hz, d.model.order(), d.filter.sections().len(), d.filter.fir().len(),
                d.kalman.q, r, d.noise_gain, d.flat_band_hz.0, d.flat_band_hz.1, d.predicted_error*100.0,
                a.nrmse*100.0, a.nrmse_p2p*100.0, raw.nrmse*100.0, dt, d.fit_nrmse*100.0
            );
        }
    }
    Ok(())
}
