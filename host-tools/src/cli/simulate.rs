//! `dynocomp simulate`: a synthetic dynamometer, impact test and milling
//! record with known true force, written as the files `design` and
//! `compensate` read.

use anyhow::{Context, Result};
use std::path::PathBuf;

use crate::frf::axis_name;
use crate::simulate::files::{write_outputs, write_outputs_of};
use crate::simulate::presets::Preset;
use crate::simulate::{simulate, AntiAlias, Chatter, MillingMode, SimOutput, SimParams};

/// Arguments of `dynocomp simulate`. Every option left out takes its value
/// from [`SimParams::default`].
#[derive(clap::Args, Clone, Debug)]
pub struct SimulateArgs {
    /// Output directory (created if missing): frf.uff, frf.csv, measured.csv,
    /// true_force.csv, idle.csv, truth.json.
    #[arg(long)]
    pub out: PathBuf,
    /// Seed of every random choice (dynamometer, impact test, noise).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// One of the seed paper's experiments on its 9257A-like set-up:
    /// sine-1185, chirp-650, chirp-1300 (shaker, Figs. 8-9), cut-1, cut-2,
    /// cut-3 (Table 2). The other options still override its values; the
    /// dynamometer is the preset's, not a random one.
    #[arg(long, value_name = "NAME")]
    pub preset: Option<String>,
    /// Sample rate (Hz), 1000..=1000000 [default: 51200].
    #[arg(long)]
    pub fs: Option<f64>,
    /// Length of the cutting record (s) [default: 1]. At most 2.5e7
    /// internal samples (duration × fs × oversample: 60 s at 51.2 kHz).
    #[arg(long)]
    pub duration: Option<f64>,
    /// Length of the idle record (s) [default: 1].
    #[arg(long)]
    pub idle_duration: Option<f64>,
    /// Internal oversampling of force and model [default: 8].
    #[arg(long)]
    pub oversample: Option<usize>,
    /// Anti-aliasing chain before sampling: `ideal` (the DAQ's zero-phase
    /// brick wall at 0.45 fs), `none` (plain decimation, aliases kept) or
    /// `butterworth:ORDER:FC_HZ` (an analog Butterworth front end, e.g. the
    /// box's butterworth:4:12000, in front of the brick wall; the impact test
    /// sees it too).
    #[arg(long, default_value = "ideal", value_parser = clap::value_parser!(AntiAlias))]
    pub anti_alias: AntiAlias,
    /// Spindle speed (rpm), at most 200000 [default: 4125].
    #[arg(long)]
    pub spindle_rpm: Option<f64>,
    /// Number of teeth, 1..=100 [default: 4].
    #[arg(long)]
    pub teeth: Option<usize>,
    /// Tool diameter (mm) [default: 10].
    #[arg(long)]
    pub diameter: Option<f64>,
    /// Helix angle (degrees) [default: 30].
    #[arg(long)]
    pub helix: Option<f64>,
    /// Axial depth of cut ap (mm) [default: 2].
    #[arg(long)]
    pub axial_depth: Option<f64>,
    /// Radial depth of cut ae (mm) [default: 3].
    #[arg(long)]
    pub radial_depth: Option<f64>,
    /// Feed per tooth (mm) [default: 0.05].
    #[arg(long)]
    pub feed_per_tooth: Option<f64>,
    /// Up milling instead of down milling.
    #[arg(long)]
    pub up_milling: bool,
    /// Runout: radial offset of the tool axis (µm) [default: 5].
    #[arg(long)]
    pub runout_um: Option<f64>,
    /// Revolutions of ramp-in [default: 2].
    #[arg(long)]
    pub ramp_in_revs: Option<f64>,
    /// Add regenerative chatter at this frequency (Hz).
    #[arg(long)]
    pub chatter_hz: Option<f64>,
    /// Final chatter vibration amplitude (mm) [default: 0.01].
    #[arg(long)]
    pub chatter_amplitude: Option<f64>,
    /// Time at which chatter reaches half its amplitude (s) [default: duration/2].
    #[arg(long)]
    pub chatter_onset: Option<f64>,
    /// Instead of a milling cut, a force with a flat spectrum from 10 Hz to
    /// the scoring band's top, min(4 kHz, 0.4 fs), of this RMS (N) on each
    /// axis, the axes independent: the force `design`'s predicted error is
    /// for (with `--force-rms` the same). Its response at the sensor modes
    /// is several times the force: where it reaches --adc-range, raise that
    /// (`compensate` warns of a clipped record).
    #[arg(long, value_name = "N", conflicts_with_all = ["drift_percent", "chatter_hz"])]
    pub flat_force: Option<f64>,
    /// Measurement noise variance R (N²) [default: 0.05].
    #[arg(long)]
    pub noise_variance: Option<f64>,
    /// ADC resolution (bits, 0 = none) [default: 16].
    #[arg(long)]
    pub adc_bits: Option<u32>,
    /// ADC full scale ±N [default: 2000].
    #[arg(long)]
    pub adc_range: Option<f64>,
    /// Impact test: number of frequency lines from 0 Hz, at most 1048576 [default: 4097].
    #[arg(long)]
    pub frf_lines: Option<usize>,
    /// Impact test: line spacing (Hz) [default: 1].
    #[arg(long)]
    pub frf_df: Option<f64>,
    /// Impact test: number of averaged impacts, at most 1000 [default: 7].
    #[arg(long)]
    pub impacts: Option<usize>,
    /// Impact test: hammer spectrum cutoff (Hz) [default: 3000].
    #[arg(long)]
    pub hammer_cutoff: Option<f64>,
    /// Let the sensor modes drift during the cutting record by this many
    /// percent (e.g. +3: the workpiece's mass loss moves them up), from
    /// --drift-start to --drift-end with the modal mass linear in time (1/f²
    /// linear); frf.uff is then the set-up before
    /// the drift and frf_after.uff/.csv after it, drift.json describes it.
    #[arg(long, allow_hyphen_values = true, value_name = "PCT")]
    pub drift_percent: Option<f64>,
    /// Start of the drift (s) [default: 0].
    #[arg(long, requires = "drift_percent")]
    pub drift_start: Option<f64>,
    /// End of the drift (s) [default: the end of the record].
    #[arg(long, requires = "drift_percent")]
    pub drift_end: Option<f64>,
    /// The dynamometer model: `plate` (a rigid plate and workpiece on four
    /// 3-component sensors and a base on the table: every channel responds
    /// to every force direction, as on a real dynamometer; the impact tests
    /// measure all nine FRFs) or `diagonal` (one independent modal model per
    /// axis, no crosstalk) [default: plate; diagonal with --preset or
    /// --drift-percent, which simulate per-axis set-ups].
    #[arg(long, value_enum)]
    pub dyno: Option<DynoModel>,
    /// With the plate: a named set-up instead of a random one: `flat`
    /// (flat centred plate), `offcentre` (block off the centre), `tall`
    /// (tall part, force 90 mm above the sensors).
    #[arg(long, value_name = "NAME")]
    pub dyno_preset: Option<String>,
    /// With the plate: where the cutting force acts, from the impact point,
    /// as DX:DY:DZ in mm (e.g. 20:0:0); the FRF is measured at the impact point.
    #[arg(long, value_name = "DX:DY:DZ", allow_hyphen_values = true, value_parser = parse_offset_mm)]
    pub cut_offset: Option<[f64; 3]>,
}

/// The dynamometer model of `dynocomp simulate`.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum DynoModel {
    /// One independent modal model per axis (no crosstalk).
    Diagonal,
    /// The physical 3x3 plate dynamometer (crosstalk).
    Plate,
}

/// `DX:DY:DZ` in mm → metres.
fn parse_offset_mm(s: &str) -> Result<[f64; 3]> {
    let parts: Vec<&str> = s.split(':').collect();
    let [x, y, z] = parts.as_slice() else {
        anyhow::bail!("--cut-offset {s}: expected DX:DY:DZ in mm, e.g. 20:0:0");
    };
    let mm = |v: &str| -> Result<f64> {
        let x: f64 = v.trim().parse().with_context(|| format!("--cut-offset {s}: {v:?} is not a number of mm"))?;
        anyhow::ensure!(x.is_finite(), "--cut-offset {s}: {v:?} is not finite");
        Ok(x * 1e-3)
    };
    Ok([mm(x)?, mm(y)?, mm(z)?])
}

impl SimulateArgs {
    /// The dynamometer simulated: `--dyno`; without it the plate, except
    /// that a paper `--preset` brings its own per-axis dynamometer and
    /// `--drift-percent` drifts only the per-axis one.
    pub fn dyno_model(&self) -> DynoModel {
        let plate_options = self.dyno_preset.is_some() || self.cut_offset.is_some();
        match self.dyno {
            Some(m) => m,
            None if !plate_options && (self.preset.is_some() || self.drift_percent.is_some()) => DynoModel::Diagonal,
            None => DynoModel::Plate,
        }
    }

    /// The simulation parameters these arguments select (from the
    /// preset's, or [`SimParams::default`]).
    pub fn params(&self) -> Result<SimParams> {
        Ok(self.params_over(match &self.preset {
            Some(name) => crate::simulate::presets::preset(name)?.params,
            None => SimParams::default(),
        }))
    }

    /// `base` with the options given on the command line applied.
    fn params_over(&self, base: SimParams) -> SimParams {
        let mut p = base;
        let set = |dst: &mut f64, v: Option<f64>| {
            if let Some(v) = v {
                *dst = v;
            }
        };
        set(&mut p.fs_hz, self.fs);
        set(&mut p.duration_s, self.duration);
        set(&mut p.idle_duration_s, self.idle_duration);
        if let Some(v) = self.oversample {
            p.oversample = v;
        }
        p.anti_alias = self.anti_alias;
        let m = &mut p.milling;
        set(&mut m.spindle_rpm, self.spindle_rpm);
        if let Some(v) = self.teeth {
            m.teeth = v;
        }
        set(&mut m.diameter_mm, self.diameter);
        set(&mut m.helix_deg, self.helix);
        set(&mut m.axial_depth_mm, self.axial_depth);
        set(&mut m.radial_depth_mm, self.radial_depth);
        set(&mut m.feed_per_tooth_mm, self.feed_per_tooth);
        if self.up_milling {
            m.mode = MillingMode::Up;
        }
        if let Some(v) = self.runout_um {
            m.runout_mm = v * 1e-3;
        }
        set(&mut m.ramp_in_revs, self.ramp_in_revs);
        if let Some(f) = self.chatter_hz {
            let duration = p.duration_s;
            m.chatter = Some(Chatter {
                freq_hz: f,
                amplitude_mm: self.chatter_amplitude.unwrap_or(0.01),
                onset_s: self.chatter_onset.unwrap_or(duration / 2.0),
                growth_s: duration / 20.0,
            });
        }
        set(&mut p.measurement.noise_variance_n2, self.noise_variance);
        if let Some(v) = self.adc_bits {
            p.measurement.adc_bits = v;
        }
        set(&mut p.measurement.adc_range_n, self.adc_range);
        if let Some(v) = self.frf_lines {
            p.impact.n_lines = v;
        }
        set(&mut p.impact.df_hz, self.frf_df);
        if let Some(v) = self.impacts {
            p.impact.n_impacts = v;
        }
        set(&mut p.impact.hammer_cutoff_hz, self.hammer_cutoff);
        if let Some(rms_n) = self.flat_force {
            let seed = crate::simulate::sub_seed(self.seed, crate::simulate::TAG_FLAT_FORCE);
            p.excitation = Some(crate::simulate::shaker::Excitation::flat_force(p.fs_hz, rms_n, seed));
        }
        p
    }
}

/// What the simulation is about to compute, on stderr before it starts (a
/// long record takes a while and says nothing until it is written); out
/// of range parameters are refused first, with nothing printed.
fn announce(p: &SimParams, what: &str) -> Result<()> {
    p.validate()?;
    let n = (p.duration_s * p.fs_hz).round();
    eprintln!(
        "simulate: {n:.0} samples × 3 axes at {} Hz ({} s, oversample {}), {} s idle, an impact test of {} lines{what}…",
        p.fs_hz, p.duration_s, p.oversample, p.idle_duration_s, p.impact.n_lines
    );
    Ok(())
}

/// `dynocomp simulate`: simulate and write the files into `args.out`; a
/// summary goes to stderr.
pub fn run(args: &SimulateArgs) -> Result<()> {
    if args.dyno_model() == DynoModel::Plate {
        return run_plate(args);
    }
    let options = DiagonalOptions::new(args)?;
    if args.dyno.is_none() {
        let why = if args.preset.is_some() { "--preset" } else { "--drift-percent" };
        eprintln!(
            "simulate: {why} simulates the per-axis dynamometer (no crosstalk), not the default plate \
             (same as --dyno diagonal)"
        );
    }
    let out = simulate_and_write(&options)?;
    for line in summary(&out, options.preset(), &options.out) {
        eprintln!("{line}");
    }
    Ok(())
}

/// What `dynocomp simulate` of the per-axis dynamometer makes, checked.
struct DiagonalOptions {
    seed: u64,
    params: SimParams,
    dyno: DiagonalDyno,
    /// Output directory.
    out: PathBuf,
}

/// The per-axis dynamometer simulated.
enum DiagonalDyno {
    /// A random one from the seed.
    Random,
    /// A paper preset's.
    Preset(Box<Preset>),
    /// A random one whose sensor modes drift during the record.
    Drifting(crate::simulate::drift::Drift),
}

impl DiagonalOptions {
    /// The options `args` select; plate-only options, and a drift with a
    /// paper preset, are refused.
    fn new(args: &SimulateArgs) -> Result<Self> {
        if args.dyno_preset.is_some() || args.cut_offset.is_some() {
            anyhow::bail!("--dyno-preset and --cut-offset describe the plate dynamometer, not --dyno diagonal");
        }
        let params = args.params()?;
        let preset = args.preset.as_deref().map(crate::simulate::presets::preset).transpose()?;
        let dyno = match (args.drift_percent, preset) {
            (Some(_), Some(_)) => anyhow::bail!(
                "--drift-percent with --preset: a drifting paper preset is not supported; simulate the drift \
                 without --preset"
            ),
            (Some(pct), None) => DiagonalDyno::Drifting(crate::simulate::drift::Drift {
                delta: pct / 100.0,
                start_s: args.drift_start.unwrap_or(0.0),
                end_s: args.drift_end.unwrap_or(params.duration_s),
            }),
            (None, Some(pr)) => DiagonalDyno::Preset(Box::new(pr)),
            (None, None) => DiagonalDyno::Random,
        };
        Ok(DiagonalOptions { seed: args.seed, params, dyno, out: args.out.clone() })
    }

    /// The paper preset simulated, if any.
    fn preset(&self) -> Option<&Preset> {
        match &self.dyno {
            DiagonalDyno::Preset(p) => Some(p.as_ref()),
            _ => None,
        }
    }
}

/// Announce, simulate and write the files.
fn simulate_and_write(o: &DiagonalOptions) -> Result<SimOutput> {
    announce(&o.params, "")?;
    let writing = || eprintln!("simulate: writing {}", o.out.display());
    Ok(match &o.dyno {
        DiagonalDyno::Drifting(drift) => crate::simulate::drift::run(o.seed, &o.params, *drift, &o.out)?,
        DiagonalDyno::Preset(pr) => {
            let out = crate::simulate::simulate_with(o.seed, &o.params, pr.dyno.clone())?;
            writing();
            write_outputs_of(&o.out, &out, Some(pr.as_ref()))?;
            out
        }
        DiagonalDyno::Random => {
            let out = simulate(o.seed, &o.params)?;
            writing();
            write_outputs(&o.out, &out)?;
            out
        }
    })
}

/// What was simulated and written into `dir`, line by line.
fn summary(out: &SimOutput, preset: Option<&Preset>, dir: &std::path::Path) -> Vec<String> {
    let p = &out.params;
    let mut lines = Vec::new();
    if let Some(pr) = preset {
        lines.push(format!("simulate: preset {}: {}", pr.name, pr.description));
    }
    lines.push(format!(
        "simulate: seed {}, fs {} Hz, {} samples ({} s), oversample {}, anti-alias {}",
        out.seed,
        p.fs_hz,
        out.t_s.len(),
        p.duration_s,
        p.oversample,
        p.anti_alias
    ));
    lines.push(excitation_line(p));
    for a in 0..3 {
        let modes: Vec<String> = out
            .dyno
            .axis(a)
            .modes
            .iter()
            .map(|md| format!("{:.0} Hz ζ {:.3} r {:+.3}", md.fn_hz, md.zeta, md.residue))
            .collect();
        let peak = out.truth[a].iter().fold(0.0f64, |acc, v| acc.max(v.abs()));
        lines.push(format!("  axis {}: peak true force {:.1} N; modes: {}", axis_name(a), peak, modes.join(", ")));
    }
    lines.push(format!(
        "  noise R {} N², ADC {} bits ±{} N (LSB {:.4} N); impact test {} lines × {} Hz, {} impacts",
        p.measurement.noise_variance_n2,
        p.measurement.adc_bits,
        p.measurement.adc_range_n,
        p.measurement.lsb_n(),
        p.impact.n_lines,
        p.impact.df_hz,
        p.impact.n_impacts
    ));
    let d = dir.display();
    lines.push(format!("  wrote {d}/{{frf.uff, frf.csv, measured.csv, true_force.csv, idle.csv, truth.json}}"));
    lines.push(next_steps(dir, p.fs_hz));
    if let Some(pr) = preset {
        lines.push(format!(
            "  design as the paper did: dynocomp design --frf {d}/frf.uff --idle {d}/idle.csv --fs {} --method paper \
             {} --out {d}/paper.dcimg",
            p.fs_hz,
            pr.design_flags.join(" ")
        ));
    }
    lines
}

/// The force: the shaker's, or the milling cut's.
fn excitation_line(p: &SimParams) -> String {
    if let Some(crate::simulate::shaker::Excitation::Noise { lo_hz, hi_hz, rms_n, .. }) = &p.excitation {
        return format!(
            "  flat force: {rms_n} N RMS per axis, flat spectrum {lo_hz}-{hi_hz} Hz, the axes independent \
             (what design's predicted error assumes with --force-rms {rms_n})"
        );
    }
    if let Some(e) = &p.excitation {
        return format!("  shaker: {e:?} (the same force on x, y and z)");
    }
    let m = &p.milling;
    format!(
        "  milling: {} rpm, {} teeth, tooth_passing_hz {:.2} Hz (spindle {:.2} Hz), ap {} mm, ae {} mm, {:?}, \
         runout {} µm{}",
        m.spindle_rpm,
        m.teeth,
        m.tooth_passing_hz(),
        m.spindle_hz(),
        m.axial_depth_mm,
        m.radial_depth_mm,
        m.mode,
        m.runout_mm * 1e3,
        m.chatter.as_ref().map(|c| format!(", chatter {} Hz", c.freq_hz)).unwrap_or_default()
    )
}

/// `dynocomp simulate --dyno plate`: the physical 3x3 dynamometer, random
/// from the seed or a `--dyno-preset`, cut at `--cut-offset` from the impact point.
fn run_plate(args: &SimulateArgs) -> Result<()> {
    use crate::simulate::plate::{output, simulate_plate, PlateSetup, PlateSim};
    if args.preset.is_some() {
        anyhow::bail!(
            "--preset with the plate dynamometer (--dyno plate, --dyno-preset, --cut-offset): the paper presets \
             bring their own per-axis dynamometer; use --dyno-preset for a plate set-up"
        );
    }
    if args.drift_percent.is_some() {
        anyhow::bail!(
            "--drift-percent with the plate dynamometer: a drifting plate is not simulated yet; add --dyno diagonal \
             for a drifting per-axis dynamometer"
        );
    }
    let params = args.params()?;
    let setup = match &args.dyno_preset {
        Some(name) => PlateSetup::preset(name)?,
        None => PlateSetup::random(crate::simulate::sub_seed(args.seed, crate::simulate::TAG_DYNO))?,
    };
    let plate = PlateSim { setup, cut_offset_m: args.cut_offset.unwrap_or([0.0; 3]) };
    announce(&params, ", plate dynamometer (impact tests in x, y and z)")?;
    let out = simulate_plate(args.seed, &params, &plate)?;
    eprintln!("simulate: writing {}", args.out.display());
    output::write_plate_outputs(&args.out, &out, args.dyno_preset.as_deref())?;
    let p = &out.params;
    eprintln!(
        "simulate: seed {}, fs {} Hz, {} samples ({} s), oversample {}, anti-alias {}, plate dynamometer{}",
        out.seed,
        p.fs_hz,
        out.t_s.len(),
        p.duration_s,
        p.oversample,
        p.anti_alias,
        args.dyno_preset.as_deref().map(|n| format!(" (preset {n})")).unwrap_or_default()
    );
    for line in output::summary(&out) {
        eprintln!("{line}");
    }
    if p.excitation.is_some() {
        eprintln!("{}", excitation_line(p));
    }
    eprintln!(
        "  noise R {} N², ADC {} bits ±{} N; impact tests in x, y, z: {} lines × {} Hz, {} impacts, all nine FRFs",
        p.measurement.noise_variance_n2,
        p.measurement.adc_bits,
        p.measurement.adc_range_n,
        p.impact.n_lines,
        p.impact.df_hz,
        p.impact.n_impacts
    );
    let files = "frf.uff, frf.csv, measured.csv, true_force.csv, idle.csv, truth.json";
    eprintln!("  wrote {}/{{{files}}}", args.out.display());
    eprintln!("{}", next_steps(&args.out, p.fs_hz));
    Ok(())
}

/// The commands that design a compensator for the files written into
/// `dir` and score it against the true force.
fn next_steps(dir: &std::path::Path, fs_hz: f64) -> String {
    let d = dir.display();
    format!(
        "  next: dynocomp design --frf {d}/frf.uff --idle {d}/idle.csv --fs {fs_hz} --out {d}/box.dcimg && \
         dynocomp compensate --coeffs {d}/box.dcimg --input {d}/measured.csv --output {d}/compensated.csv \
         --truth {d}/true_force.csv"
    )
}
