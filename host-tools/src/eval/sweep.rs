//! The random set-ups of the sweep (`examples/sweep.rs`, #34): each seed
//! draws a DAQ rate, an FRF resolution of 0.5-4 Hz, one of four kinds of
//! dynamometer (the default ranges, clustered machine modes at 300-900 Hz, a
//! close sensor-mode pair, sensor modes above the compensated band) and a
//! cut. The seeds are fixed in the example and were never picked by looking
//! at results; the tests keep a few of its worst cases.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::eval::rates::{DynoSpec, RateCase, RATES_HZ};
use crate::simulate::dynamometer::ModeRanges;

/// The case of seed `seed`: rate, FRF resolution, kind and cut drawn from it.
pub fn draw(seed: u64) -> (RateCase, f64, &'static str) {
    let mut rng = ChaCha8Rng::seed_from_u64(0x5eed_0000 + seed);
    let fs = RATES_HZ[rng.random_range(0..4)];
    let df = [0.5, 1.0, 2.0, 4.0][rng.random_range(0..4)];
    let d = ModeRanges::default();
    let (kind, dyno, frf_max_hz) = match rng.random_range(0..4) {
        0 => ("default", DynoSpec::Random(d), 4096.0),
        1 => (
            "machine-cluster",
            DynoSpec::Random(ModeRanges {
                machine_count: (3, 5),
                machine_hz: (300.0, 900.0),
                machine_residue: (0.05, 0.15),
                ..d
            }),
            4096.0,
        ),
        2 => (
            "close-pair",
            DynoSpec::ClosePair { ranges: d, spacing: rng.random_range(0.03..0.08), share: rng.random_range(0.2..0.5) },
            4096.0,
        ),
        _ => (
            "above-band",
            DynoSpec::Random(ModeRanges {
                main_xy_hz: (3800.0, 5000.0),
                main_z_hz: (4500.0, 6000.0),
                secondary_hz: (4500.0, 6000.0),
                ..d
            }),
            8192.0,
        ),
    };
    let case = RateCase {
        name: Box::leak(format!("seed{seed}").into_boxed_str()),
        seed: 1000 + seed,
        dyno,
        frf_df_hz: df,
        frf_max_hz,
        spindle_rpm: rng.random_range(2000.0..20000.0),
        teeth: rng.random_range(2..5),
        chatter_hz: None,
    };
    (case, fs, kind)
}
