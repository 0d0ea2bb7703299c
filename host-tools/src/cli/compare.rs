//! `dynocomp compare`: the seed paper's method beside the default on one FRF,
//! as tables (text or JSON) and, with `--out-dir`, plots.

use anyhow::{Context, Result};
use clap::Args;
use std::path::{Path, PathBuf};

use crate::cli::design_args::{BandArgs, DesignInputArgs, PaperArgs};
use crate::design::axis::DesignOptions;
use crate::eval::compare::{compare, CompareInputs};
use crate::frf::Frf;
use crate::report::compare::{plot_axis, render};

/// Arguments of `dynocomp compare`.
#[derive(Args, Debug, Clone)]
pub struct CompareArgs {
    /// The FRF, sample rate, noise and Q-criterion inputs (as for `design`).
    #[command(flatten)]
    pub input: DesignInputArgs,
    /// Latency L of the default method (samples).
    #[arg(long, default_value_t = 4)]
    pub latency: usize,
    /// Options of the paper's method.
    #[command(flatten)]
    pub paper: PaperArgs,
    /// Fitting bands.
    #[command(flatten)]
    pub bands: BandArgs,
    /// Write the plots (one SVG per axis), compare.txt (the printed table)
    /// and compare.json into this directory.
    #[arg(long)]
    pub out_dir: Option<PathBuf>,
    /// Print the comparison as JSON on stdout.
    #[arg(long)]
    pub json: bool,
}

/// The comparison's inputs from `args`, validated, for `frf`.
fn inputs(args: &CompareArgs, frf: &Frf) -> Result<CompareInputs> {
    args.input.check_values(&args.bands)?;
    let r = args.input.noise_variances(frf)?;
    let bands = args
        .bands
        .resolve(frf, args.input.fs, args.input.max_force)
        .with_context(|| format!("{}", args.input.frf().display()))?;
    let base = DesignOptions {
        fs_hz: args.input.fs,
        lag: args.latency,
        force_rms: args.input.force_rms,
        max_noise_gain: args.input.max_noise_gain,
        discretization: args.input.discretization.into(),
        paper_orders_auto: args.paper.auto(),
        order_search_progress: Some(crate::design::progress::Progress::stderr()),
        ..Default::default()
    };
    let paper = args.paper.method(args.bands.tooth_passing_hz(), args.input.fs)?;
    let progress = crate::design::progress::Progress::stderr();
    Ok(CompareInputs { frf_name: args.input.frf().display().to_string(), r, bands, base, paper, progress })
}

/// Refuse to write a file of `--out-dir` (the pages of [`run`]) over one
/// of the inputs.
fn check_pages_are_not_inputs(args: &CompareArgs, dir: &Path) -> Result<()> {
    let names = ["compare.json", "compare.txt", "x_compare.svg", "y_compare.svg", "z_compare.svg"];
    let files: Vec<PathBuf> = names.iter().map(|n| dir.join(n)).collect();
    let outputs: Vec<(&str, &Path)> = files.iter().map(|f| ("a file of --out-dir", f.as_path())).collect();
    let mut inputs: Vec<(&str, &Path)> = args.input.frf.iter().map(|p| ("--frf", p.as_path())).collect();
    inputs.extend(args.input.idle.as_deref().map(|p| ("--idle", p)));
    inputs.extend(args.bands.bands_from.as_deref().map(|p| ("--bands-from", p)));
    crate::io::atomic::ensure_not_an_input(&outputs, &inputs)
}

/// Run `dynocomp compare`.
pub fn run(args: &CompareArgs) -> Result<()> {
    if args.input.frf.len() != 1 {
        anyhow::bail!("compare: --frf given {} times; compare takes one FRF", args.input.frf.len());
    }
    if let Some(dir) = &args.out_dir {
        check_pages_are_not_inputs(args, dir)?;
    }
    let frf = crate::io::read_frf(args.input.frf())?;
    let c = compare(&frf, &inputs(args, &frf)?);
    let text = render(&c);
    let json = serde_json::to_string_pretty(&c)?;
    if let Some(dir) = &args.out_dir {
        let mut pages = Vec::new();
        for ax in &c.axes {
            pages.push(crate::report::page::Page {
                name: format!("{}_compare.svg", ax.axis),
                content: plot_axis(&frf.freq_hz, ax, &c.bands)
                    .with_context(|| format!("compare: axis {} plot", ax.axis))?,
            });
        }
        pages.push(crate::report::page::Page { name: "compare.json".into(), content: json.clone() });
        pages.push(crate::report::page::Page { name: "compare.txt".into(), content: text.clone() });
        let files = crate::report::page::write_pages(dir, &pages)?;
        eprintln!("compare: {} files in {}", files.len(), dir.display());
    }
    if args.json {
        println!("{json}");
    } else {
        print!("{text}");
    }
    Ok(())
}
