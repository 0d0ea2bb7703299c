//! Plate dynamometers from a seed, within physical ranges, and three named
//! set-ups (`simulate --dyno plate --dyno-preset NAME`).

use anyhow::{bail, Result};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::modal::PlateModal;
use super::setup::{PlateSetup, DOF};

/// Band of the six machine modes (Hz).
pub const MACHINE_HZ: (f64, f64) = (100.0, 900.0);
/// Band of the six sensor and rocking modes (Hz).
pub const SENSOR_HZ: (f64, f64) = (2000.0, 6000.0);

/// Names of the presets.
pub const PRESETS: [&str; 3] = ["flat", "offcentre", "tall"];

/// Whether the modes of `setup` (at its force point) lie in the machine and
/// sensor bands; `Err` says which mode does not.
pub fn check_mode_bands(modal: &PlateModal) -> Result<()> {
    for (r, m) in modal.modes.iter().enumerate() {
        let (band, what) = if r < DOF / 2 { (MACHINE_HZ, "machine") } else { (SENSOR_HZ, "sensor/rocking") };
        if !(m.fn_hz >= band.0 && m.fn_hz <= band.1) {
            bail!("mode {} at {:.0} Hz is outside the {what} band {}-{} Hz", r + 1, m.fn_hz, band.0, band.1);
        }
    }
    Ok(())
}

fn uni(rng: &mut ChaCha8Rng, (lo, hi): (f64, f64)) -> f64 {
    if hi > lo {
        rng.random_range(lo..hi)
    } else {
        lo
    }
}

/// One draw of the ranges of [`PlateSetup::random`] (not yet checked).
fn draw(rng: &mut ChaCha8Rng) -> PlateSetup {
    const AL_STEEL: (f64, f64) = (2700.0, 7850.0);
    let plate = [uni(rng, (0.12, 0.2)), uni(rng, (0.08, 0.16)), uni(rng, (0.02, 0.035))];
    let plate_mass = uni(rng, AL_STEEL) * plate[0] * plate[1] * plate[2];
    let margin = [uni(rng, (0.01, 0.025)), uni(rng, (0.01, 0.025))];
    let a = [plate[0] / 2.0 - margin[0], plate[1] / 2.0 - margin[1]];
    let kxy = uni(rng, (2e8, 6e8));
    let k = [kxy, kxy * uni(rng, (0.9, 1.1)), kxy * uni(rng, (1.5, 2.5))];
    let with_workpiece = rng.random_bool(0.85);
    let (wp_mass, wp_size, wp_xy) = if with_workpiece {
        let size = [plate[0] * uni(rng, (0.3, 0.9)), plate[1] * uni(rng, (0.3, 0.9)), uni(rng, (0.01, 0.09))];
        let rho = uni(rng, AL_STEEL);
        let xy =
            [uni(rng, (-1.0, 1.0)) * (plate[0] - size[0]) / 2.0, uni(rng, (-1.0, 1.0)) * (plate[1] - size[1]) / 2.0];
        (rho * size[0] * size[1] * size[2], size, xy)
    } else {
        (0.0, [0.0; 3], [0.0; 2])
    };
    let base = [uni(rng, (0.3, 0.6)), uni(rng, (0.25, 0.5)), uni(rng, (0.05, 0.15))];
    let base_mass = uni(rng, (20.0, 120.0));
    let kt = [uni(rng, (5e6, 1e8)), uni(rng, (5e6, 1e8)), uni(rng, (1e7, 2e8))];
    let zeta = (0..DOF).map(|_| uni(rng, (0.01, 0.06))).collect();
    let mut crosstalk = [[0.0; 3]; 3];
    for (i, row) in crosstalk.iter_mut().enumerate() {
        for (j, e) in row.iter_mut().enumerate() {
            if i != j {
                *e = uni(rng, (-0.01, 0.01));
            }
        }
    }
    let top = plate[2] + if with_workpiece { wp_size[2] } else { 0.0 };
    let (cx, cy, hx, hy, h) = if with_workpiece {
        (wp_xy[0], wp_xy[1], wp_size[0] / 2.0, wp_size[1] / 2.0, wp_size[2])
    } else {
        (0.0, 0.0, plate[0] / 2.0, plate[1] / 2.0, plate[2])
    };
    // The tool engages somewhere on the top, or on a side near the top.
    let point = [cx + uni(rng, (-1.0, 1.0)) * hx, cy + uni(rng, (-1.0, 1.0)) * hy, top - uni(rng, (0.0, 0.3)) * h];
    PlateSetup {
        plate_mass_kg: plate_mass,
        plate_size_m: plate,
        workpiece_mass_kg: wp_mass,
        workpiece_size_m: wp_size,
        workpiece_xy_m: wp_xy,
        sensor_half_spacing_m: a,
        sensor_stiffness_n_per_m: k,
        base_mass_kg: base_mass,
        base_size_m: base,
        table_stiffness_n_per_m: kt,
        zeta,
        crosstalk,
        force_point_m: point,
    }
}

impl PlateSetup {
    /// A random set-up from `seed`: draws are repeated, on the seed's own
    /// stream, until the modes lie in their bands.
    ///
    /// The ranges describe a Kistler 9257-class table dynamometer: a steel or
    /// aluminium top plate of 120-200 x 80-160 mm on four 3-component sensors of
    /// 2-6·10⁸ N/m in shear (x, y) and 1.5-2.5 times that in z, a workpiece of
    /// aluminium or steel up to 90 mm tall anywhere on the plate, and a base of
    /// 20-120 kg (housing plus the table's effective mass) on the table through
    /// mounts of 5·10⁶-2·10⁸ N/m. A draw is kept only when its six lowest modes
    /// (the whole dynamometer on the table: machine modes) lie in 100-900 Hz and
    /// its six highest (the plate on the sensors: translations and rocking) in
    /// 2-6 kHz, so a seed always gives a set-up of that kind.
    pub fn random(seed: u64) -> Result<Self> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut last = String::new();
        for _ in 0..1000 {
            let s = draw(&mut rng);
            let checked = PlateModal::new(&s, s.force_point_m).and_then(|m| check_mode_bands(&m));
            match checked {
                Ok(()) => return Ok(s),
                Err(e) => last = format!("{e:#}"),
            }
        }
        bail!("plate dynamometer: no set-up of seed {seed} in 1000 draws has its modes in band (last: {last})")
    }

    /// The named set-up ([`PRESETS`]), on one 9257-like dynamometer (steel
    /// top plate 170 x 100 x 25 mm, 3.3 kg; sensors at ±70, ±35 mm; 60 kg of
    /// base and table):
    /// - `flat`: a flat aluminium plate 140 x 80 x 15 mm centred, struck at
    ///   the centre of its top (40 mm): symmetric, so only the static
    ///   crosstalk couples the channels;
    /// - `offcentre`: a steel block 80 x 60 x 50 mm centred at (20, 10) mm,
    ///   struck on its top at (50, 30, 75) mm: the centre of mass off the
    ///   sensors' centre couples every mode into every channel;
    /// - `tall`: a steel part 50 x 50 x 75 mm centred, struck on its side at
    ///   (25, 10, 90) mm: the force 90 mm above the sensors drives the plate's
    ///   rocking modes.
    pub fn preset(name: &str) -> Result<Self> {
        let plate = [0.17, 0.10, 0.025];
        let base = PlateSetup {
            plate_mass_kg: 7850.0 * plate[0] * plate[1] * plate[2],
            plate_size_m: plate,
            workpiece_mass_kg: 0.0,
            workpiece_size_m: [0.0; 3],
            workpiece_xy_m: [0.0; 2],
            sensor_half_spacing_m: [0.07, 0.035],
            sensor_stiffness_n_per_m: [3e8, 3e8, 6e8],
            base_mass_kg: 60.0,
            base_size_m: [0.5, 0.4, 0.1],
            table_stiffness_n_per_m: [3e7, 3e7, 6e7],
            zeta: vec![0.04, 0.035, 0.05, 0.03, 0.045, 0.04, 0.02, 0.025, 0.02, 0.03, 0.025, 0.03],
            crosstalk: [[0.0, 0.004, -0.003], [0.005, 0.0, 0.002], [-0.004, 0.006, 0.0]],
            force_point_m: [0.0, 0.0, 0.0],
        };
        let block = |rho: f64, size: [f64; 3], xy: [f64; 2], point: [f64; 3]| PlateSetup {
            workpiece_mass_kg: rho * size[0] * size[1] * size[2],
            workpiece_size_m: size,
            workpiece_xy_m: xy,
            force_point_m: point,
            ..base.clone()
        };
        let s = match name {
            "flat" => block(2700.0, [0.14, 0.08, 0.015], [0.0, 0.0], [0.0, 0.0, 0.04]),
            "offcentre" => block(7850.0, [0.08, 0.06, 0.05], [0.02, 0.01], [0.05, 0.03, 0.075]),
            "tall" => block(7850.0, [0.05, 0.05, 0.075], [0.0, 0.0], [0.025, 0.01, 0.09]),
            other => bail!("--dyno-preset {other}: unknown; the presets are {}", PRESETS.join(", ")),
        };
        s.validate()?;
        Ok(s)
    }
}
