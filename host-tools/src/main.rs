//! `dynocomp`: design, inspect, flash and apply dynamometer compensators.
//! The command-line contract is in DESIGN.md ("CLI contract").
#![forbid(unsafe_code)]

use anyhow::Result;
use clap::{Parser, Subcommand};
use std::path::PathBuf;
use std::process::ExitCode;

use dynocomp::{inspect, io};

#[derive(Parser)]
#[command(name = "dynocomp", version, about = "Dynamic compensation of piezoelectric cutting-force dynamometers")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Design a compensator from a measured FRF and write its coefficient image.
    Design(dynocomp::design_cmd::DesignArgs),
    /// Compare the seed paper's method (whole band, band-fitted, parallel)
    /// with the default method on the same FRF: tables and plots.
    Compare(dynocomp::compare::CompareArgs),
    /// Show what a coefficient image holds.
    Inspect {
        /// Coefficient image (.dcimg).
        image: PathBuf,
        /// Machine-readable output.
        #[arg(long)]
        json: bool,
    },
    /// Compensate a recorded force file offline: bit-exact with the box, or
    /// band by band for a parallel-elaboration image, or with the zero-lag
    /// fixed-interval smoother (`--offline`).
    Compensate(dynocomp::compensate_cmd::CompensateArgs),
    /// Simulate a dynamometer, an impact test and a milling record with known
    /// true force (for demos and tests).
    Simulate(dynocomp::simulate::SimulateArgs),
    /// Write a coefficient image into the box: through a debug probe
    /// (--probe) or over the box's USB port (--serial PORT).
    Flash(FlashArgs),
    /// Record the box's stream of raw and compensated forces to CSV.
    Stream(dynocomp::stream::StreamArgs),
    /// A simulated box on a pseudo-terminal (tests and demos): the box's
    /// protocol handler and coefficient store on a simulated flash.
    #[command(hide = true)]
    VirtualBox(dynocomp::virtual_box::VirtualBoxArgs),
}

/// `dynocomp flash IMAGE [--probe [--chip CHIP] [--slot S] | --serial PORT] [--dry-run]`.
#[derive(clap::Args)]
struct FlashArgs {
    /// Coefficient image (.dcimg).
    image: PathBuf,
    /// Write through a debug probe (probe-rs), with verify.
    #[arg(long, conflicts_with = "serial")]
    probe: bool,
    /// Upload over the box's USB serial port (e.g. /dev/ttyACM0).
    #[arg(long, value_name = "PORT")]
    serial: Option<String>,
    /// probe-rs chip name (with --probe).
    #[arg(long, default_value = dynocomp::flash_probe::DEFAULT_CHIP)]
    chip: String,
    /// Slot to write (with --probe).
    #[arg(long, value_enum, default_value = "auto")]
    slot: dynocomp::flash_probe::SlotArg,
    /// With --probe: plan the write against a simulated probe, touch no
    /// hardware.
    #[arg(long, conflicts_with = "serial")]
    dry_run: bool,
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Inspect { image, json } => {
            let report = match io::image_file::read_any_image(&image)? {
                io::image_file::AnyImage::Inline(img) => inspect::report(&img),
                io::image_file::AnyImage::Parallel(p) => inspect::report_parallel(&p)?,
            };
            if json {
                println!("{}", serde_json::to_string_pretty(&report)?);
            } else {
                print!("{}", inspect::render(&report));
            }
        }
        Command::Compensate(args) => dynocomp::compensate_cmd::run(&args)?,
        Command::Simulate(args) => dynocomp::simulate::run(&args)?,
        Command::Design(args) => dynocomp::design_cmd::run(&args)?,
        Command::Flash(a) => match (&a.serial, a.probe || a.dry_run) {
            (Some(port), _) => dynocomp::flash_serial::run(&a.image, port)?,
            #[cfg(feature = "probe")]
            (None, true) => dynocomp::flash_probe::run(&a.image, &a.chip, a.slot, a.dry_run)?,
            #[cfg(not(feature = "probe"))]
            (None, true) => anyhow::bail!("flash --probe: this dynocomp was built without the `probe` feature (probe-rs); rebuild with default features"),
            (None, false) => anyhow::bail!("flash: give --probe (debug probe) or --serial PORT (USB)"),
        },
        Command::Stream(args) => {
            dynocomp::stream::run(&args)?;
        }
        Command::VirtualBox(args) => {
            let code = dynocomp::virtual_box::run(&args)?;
            std::process::exit(code);
        }
        Command::Compare(args) => dynocomp::compare::run(&args)?,
    }
    Ok(())
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // One line: the context chain joined, outermost first.
            let msg: Vec<String> = e.chain().map(|c| c.to_string()).collect();
            eprintln!("error: {}", msg.join(": "));
            ExitCode::FAILURE
        }
    }
}
