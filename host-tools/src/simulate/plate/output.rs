//! The files `dynocomp simulate --dyno plate` writes: the same set as the
//! per-axis model (frf.uff and frf.csv now with all nine entries and their
//! coherence, measured.csv, true_force.csv, idle.csv) and truth.json with
//! the plate's parameters, its modes and the crosstalk figure.

use anyhow::Result;
use serde::Serialize;
use std::path::Path;

use super::body::RigidBody;
use super::run::PlateSimOutput;
use super::setup::PlateSetup;
use crate::frf::axis_name;
use crate::simulate::files::write_records;
use crate::simulate::SimParams;

/// One mode in truth.json.
#[derive(Serialize)]
struct TruthMode {
    fn_hz: f64,
    zeta: f64,
    /// Input row b_r for a force at the impact point (kg^-½).
    input_impact: [f64; 3],
    /// Input row b_r for a force at the cut point (kg^-½).
    input_cut: [f64; 3],
    /// Output column c_r (N·kg^-½·m^-1).
    output: [f64; 3],
    /// c_r b_rᵀ/ω_r² at the impact point: the mode's residue in every entry.
    residue_impact: [[f64; 3]; 3],
}

/// One axis in truth.json (as the per-axis model's, without modes).
#[derive(Serialize)]
struct TruthAxis {
    axis: &'static str,
    /// G_ii(0) at the impact point.
    dc_gain: f64,
    /// The mode with the largest |residue| in G_ii at the impact point (Hz).
    main_fn_hz: f64,
}

/// Content of truth.json for the plate dynamometer.
#[derive(Serialize)]
struct PlateTruth<'a> {
    format: &'static str,
    version: u32,
    dynamometer: &'static str,
    seed: u64,
    #[serde(skip_serializing_if = "Option::is_none")]
    dyno_preset: Option<&'a str>,
    fs_hz: f64,
    n_samples: usize,
    n_idle_samples: usize,
    #[serde(flatten)]
    force: crate::simulate::ForceLines,
    hold: &'static str,
    anti_alias: String,
    brick_wall_hz: Option<f64>,
    noise_variance_n2: f64,
    adc_lsb_n: f64,
    expected_idle_variance_n2: f64,
    axes: Vec<TruthAxis>,
    plate: &'a PlateSetup,
    /// Top plate with workpiece, and base, as rigid bodies.
    top_body: RigidBody,
    base_body: RigidBody,
    impact_point_m: [f64; 3],
    cut_point_m: [f64; 3],
    cut_offset_m: [f64; 3],
    /// G(0) (the static crosstalk S).
    static_gain: [[f64; 3]; 3],
    modes: Vec<TruthMode>,
    /// Band of the crosstalk figures (Hz): the impact test's lines.
    crosstalk_band_hz: [f64; 2],
    /// Peak |G_ij|/|G_ii| over the band, force at the impact point (`[i][j]`).
    crosstalk_peak: [[f64; 3]; 3],
    /// The same for a force at the cut point.
    crosstalk_peak_cut: [[f64; 3]; 3],
    params: &'a SimParams,
    files: [&'static str; 6],
}

fn truth_json(out: &PlateSimOutput, preset: Option<&str>) -> Result<String> {
    let p = &out.params;
    let setup = &out.plate.setup;
    let (im, cm) = (&out.impact_modal, &out.cut_modal);
    let g0 = im.static_gain();
    let freqs = &out.frf.freq_hz;
    let axes = (0..3)
        .map(|a| {
            let main = im.modes.iter().max_by(|x, y| x.residue()[a][a].abs().total_cmp(&y.residue()[a][a].abs()));
            TruthAxis { axis: axis_name(a), dc_gain: g0[(a, a)], main_fn_hz: main.map_or(f64::NAN, |m| m.fn_hz) }
        })
        .collect();
    let modes = im
        .modes
        .iter()
        .zip(&cm.modes)
        .map(|(i, c)| TruthMode {
            fn_hz: i.fn_hz,
            zeta: i.zeta,
            input_impact: i.input,
            input_cut: c.input,
            output: i.output,
            residue_impact: i.residue(),
        })
        .collect();
    let t = PlateTruth {
        format: "dynocomp-simulate-truth",
        version: 2,
        dynamometer: "plate",
        seed: out.seed,
        dyno_preset: preset,
        fs_hz: p.fs_hz,
        n_samples: out.t_s.len(),
        n_idle_samples: out.idle[0].len(),
        force: p.force_lines(),
        hold: "foh",
        anti_alias: p.anti_alias.to_string(),
        brick_wall_hz: p.anti_alias.brick_wall_hz(p.fs_hz),
        noise_variance_n2: p.measurement.noise_variance_n2,
        adc_lsb_n: p.measurement.lsb_n(),
        expected_idle_variance_n2: p.measurement.expected_idle_variance(),
        axes,
        plate: setup,
        top_body: setup.top(),
        base_body: setup.base(),
        impact_point_m: out.plate.impact_point_m(),
        cut_point_m: out.plate.cut_point_m(),
        cut_offset_m: out.plate.cut_offset_m,
        static_gain: std::array::from_fn(|i| std::array::from_fn(|j| g0[(i, j)])),
        modes,
        crosstalk_band_hz: [freqs.first().copied().unwrap_or(0.0), freqs.last().copied().unwrap_or(0.0)],
        crosstalk_peak: im.crosstalk_peak(freqs),
        crosstalk_peak_cut: cm.crosstalk_peak(freqs),
        params: p,
        files: ["frf.uff", "frf.csv", "measured.csv", "true_force.csv", "idle.csv", "truth.json"],
    };
    Ok(serde_json::to_string_pretty(&t)?)
}

/// Write the files of `out` into `dir` (created if missing); `preset` names
/// the `--dyno-preset` that made the set-up, if any.
pub fn write_plate_outputs(dir: &Path, out: &PlateSimOutput, preset: Option<&str>) -> Result<()> {
    let json = truth_json(out, preset)?;
    write_records(dir, &out.frf, out.params.fs_hz, &out.t_s, [&out.measured, &out.truth, &out.idle], &json)
}

/// The lines of the stderr summary about the plate: modes and crosstalk.
pub fn summary(out: &PlateSimOutput) -> Vec<String> {
    let im = &out.impact_modal;
    let mut lines = Vec::new();
    let s = &out.plate.setup;
    lines.push(format!(
        "  plate dynamometer: top {:.2} kg (plate {:.2} kg + workpiece {:.2} kg), base {:.0} kg; impact point \
         ({:.1}, {:.1}, {:.1}) mm, cut point ({:.1}, {:.1}, {:.1}) mm",
        s.top().mass_kg,
        s.plate_mass_kg,
        s.workpiece_mass_kg,
        s.base_mass_kg,
        out.plate.impact_point_m()[0] * 1e3,
        out.plate.impact_point_m()[1] * 1e3,
        out.plate.impact_point_m()[2] * 1e3,
        out.plate.cut_point_m()[0] * 1e3,
        out.plate.cut_point_m()[1] * 1e3,
        out.plate.cut_point_m()[2] * 1e3,
    ));
    let modes: Vec<String> = im.modes.iter().map(|m| format!("{:.0} Hz ζ {:.3}", m.fn_hz, m.zeta)).collect();
    lines.push(format!("  modes: {}", modes.join(", ")));
    let xt = im.crosstalk_peak(&out.frf.freq_hz);
    let mut cells = Vec::new();
    for (i, row) in xt.iter().enumerate() {
        for (j, v) in row.iter().enumerate() {
            if i != j {
                cells.push(format!("{}{} {:.1} %", axis_name(i), axis_name(j), 100.0 * v));
            }
        }
    }
    let band = out.frf.freq_hz.last().copied().unwrap_or(0.0);
    lines.push(format!("  crosstalk, peak |G_ij|/|G_ii| over 0-{band} Hz: {}", cells.join(", ")));
    lines
}
