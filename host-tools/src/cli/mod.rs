//! The command line: one module per command, each parse → validate into
//! options → library calls → render (the contract is DESIGN.md's "CLI
//! contract"). Nothing below imports it.

pub mod compare;
pub mod compensate;
pub mod design;
pub mod design_args;
pub mod design_matrix;
pub mod design_parallel;
pub mod design_two_state;
pub mod flash;
pub mod inspect;
pub mod simulate;
pub mod stream;
pub mod virtual_box;

use anyhow::Result;
use clap::{Parser, Subcommand};

/// `dynocomp`'s arguments.
#[derive(Parser)]
#[command(name = "dynocomp", version, about = "Dynamic compensation of piezoelectric cutting-force dynamometers")]
pub struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Design a compensator from a measured FRF and write its coefficient image.
    #[command(allow_negative_numbers = true)]
    Design(design_args::DesignArgs),
    /// Compare the seed paper's method (whole band, band-fitted, parallel)
    /// with the default method on the same FRF: tables and plots.
    #[command(allow_negative_numbers = true)]
    Compare(compare::CompareArgs),
    /// Show what a coefficient image holds.
    Inspect(inspect::InspectArgs),
    /// Compensate a recorded force file offline: bit-exact with the box, or
    /// band by band for a parallel-elaboration image, or with the zero-lag
    /// fixed-interval smoother (`--offline`).
    #[command(allow_negative_numbers = true)]
    Compensate(compensate::CompensateArgs),
    /// Simulate a dynamometer, an impact test and a milling record with known
    /// true force (for demos and tests).
    #[command(allow_negative_numbers = true)]
    Simulate(simulate::SimulateArgs),
    /// Write a coefficient image into the box: through a debug probe
    /// (--probe) or over the box's USB port (--serial PORT).
    Flash(flash::FlashArgs),
    /// Record the box's stream of raw and compensated forces to CSV.
    Stream(stream::StreamArgs),
    /// A simulated box on a pseudo-terminal (tests and demos): the box's
    /// protocol handler and coefficient store on a simulated flash.
    #[command(hide = true)]
    VirtualBox(virtual_box::VirtualBoxArgs),
}

/// Run the command; returns the process's exit status.
pub fn run(cli: Cli) -> Result<u8> {
    match cli.command {
        Command::Inspect(args) => inspect::run(&args)?,
        Command::Compensate(args) => compensate::run(&args)?,
        Command::Simulate(args) => simulate::run(&args)?,
        Command::Design(args) => design::run(&args)?,
        Command::Flash(args) => flash::run(&args)?,
        Command::Stream(args) => {
            stream::run(&args)?;
        }
        Command::VirtualBox(args) => return Ok(virtual_box::run(&args)? as u8),
        Command::Compare(args) => compare::run(&args)?,
    }
    Ok(0)
}
