//! The files `dynocomp simulate` writes: the impact test (frf.uff, frf.csv),
//! the records (measured.csv, true_force.csv, idle.csv) and truth.json.

use anyhow::{Context, Result};
use serde::Serialize;
use std::path::Path;

use super::{Mode, SimOutput, SimParams};
use crate::frf::axis_name;
use crate::io::frf_csv::write_frf_csv;
use crate::io::signal_csv::{write_signal_csv, SignalRecord};
use crate::io::uff::write_uff58;

/// One axis of `truth.json`.
#[derive(Serialize)]
struct TruthAxis {
    axis: &'static str,
    dc_gain: f64,
    main_fn_hz: f64,
    modes: Vec<Mode>,
}

/// Content of `truth.json`.
#[derive(Serialize)]
struct Truth<'a> {
    format: &'static str,
    version: u32,
    seed: u64,
    /// The paper preset (`--preset`), if any.
    #[serde(skip_serializing_if = "Option::is_none")]
    preset: Option<&'a str>,
    /// The band-fitting flags of `design --method paper` for the preset.
    #[serde(skip_serializing_if = "Option::is_none")]
    preset_design_flags: Option<&'a [String]>,
    fs_hz: f64,
    n_samples: usize,
    n_idle_samples: usize,
    /// The force and, for a milling cut, its tooth-passing and spindle
    /// frequencies (Hz).
    #[serde(flatten)]
    force: super::ForceLines,
    /// How the model sees the force between fine samples.
    hold: &'static str,
    /// Acquisition chain: `ideal`, `none` or `butterworth:ORDER:FC_HZ`.
    anti_alias: String,
    /// Cutoff of the brick wall that band-limits truth and measurement (Hz).
    brick_wall_hz: Option<f64>,
    noise_variance_n2: f64,
    adc_lsb_n: f64,
    expected_idle_variance_n2: f64,
    axes: Vec<TruthAxis>,
    params: &'a SimParams,
    files: [&'static str; 6],
}

fn truth_json(out: &SimOutput, preset: Option<&super::presets::Preset>) -> Result<String> {
    let p = &out.params;
    let t = Truth {
        format: "dynocomp-simulate-truth",
        version: 1,
        seed: out.seed,
        preset: preset.map(|p| p.name),
        preset_design_flags: preset.map(|p| p.design_flags.as_slice()),
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
        axes: (0..3)
            .map(|a| {
                let d = out.dyno.axis(a);
                TruthAxis {
                    axis: axis_name(a),
                    dc_gain: d.dc_gain(),
                    main_fn_hz: d.main_mode().fn_hz,
                    modes: d.modes.clone(),
                }
            })
            .collect(),
        params: p,
        files: ["frf.uff", "frf.csv", "measured.csv", "true_force.csv", "idle.csv", "truth.json"],
    };
    Ok(serde_json::to_string_pretty(&t)?)
}

fn record(t_s: Option<&[f64]>, ch: &[Vec<f64>; 3]) -> SignalRecord {
    SignalRecord { t_s: t_s.map(|t| t.to_vec()), channels: (0..3).map(|a| (a, ch[a].clone())).collect() }
}

/// Write the files every model writes into `dir` (created if missing): the
/// impact test `frf` (frf.uff, frf.csv), the records `[measured, truth,
/// idle]` at `fs_hz` (measured.csv, true_force.csv, idle.csv; the first two
/// on `t_s`) and `truth_json` (truth.json).
pub(crate) fn write_records(
    dir: &Path,
    frf: &crate::frf::Frf,
    fs_hz: f64,
    t_s: &[f64],
    [measured, truth, idle]: [&[Vec<f64>; 3]; 3],
    truth_json: &str,
) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("{}: cannot create output directory", dir.display()))?;
    let t_idle: Vec<f64> = (0..idle[0].len()).map(|k| k as f64 / fs_hz).collect();
    write_uff58(&dir.join("frf.uff"), frf, false)?;
    write_frf_csv(&dir.join("frf.csv"), frf)?;
    write_signal_csv(&dir.join("measured.csv"), &record(Some(t_s), measured))?;
    write_signal_csv(&dir.join("true_force.csv"), &record(Some(t_s), truth))?;
    write_signal_csv(&dir.join("idle.csv"), &record(Some(&t_idle), idle))?;
    crate::io::atomic::write_bytes_atomic(&dir.join("truth.json"), format!("{truth_json}\n").as_bytes())?;
    Ok(())
}

/// Write the output files of `out` into `dir` (created if missing).
pub fn write_outputs(dir: &Path, out: &SimOutput) -> Result<()> {
    write_outputs_of(dir, out, None)
}

/// [`write_outputs`], recording the preset that produced `out` in truth.json.
pub fn write_outputs_of(dir: &Path, out: &SimOutput, preset: Option<&super::presets::Preset>) -> Result<()> {
    let json = truth_json(out, preset)?;
    write_records(dir, &out.frf, out.params.fs_hz, &out.t_s, [&out.measured, &out.truth, &out.idle], &json)
}
