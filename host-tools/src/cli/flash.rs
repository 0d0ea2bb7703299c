//! `dynocomp flash`: write a coefficient image into the box, through a debug
//! probe or over its USB port.

use anyhow::{bail, Result};
use std::path::PathBuf;

use crate::link::flash_probe::SlotArg;

/// `dynocomp flash IMAGE [--probe [--chip CHIP] [--slot S] | --serial PORT] [--dry-run]`.
#[derive(clap::Args, Debug, Clone)]
pub struct FlashArgs {
    /// Coefficient image (.dcimg).
    pub image: PathBuf,
    /// Write through a debug probe (probe-rs), with verify.
    #[arg(long, conflicts_with = "serial")]
    pub probe: bool,
    /// Upload over the box's USB serial port (e.g. /dev/ttyACM0).
    #[arg(long, value_name = "PORT")]
    pub serial: Option<String>,
    /// probe-rs chip name (with --probe).
    #[arg(long, default_value = crate::link::flash_probe::DEFAULT_CHIP)]
    pub chip: String,
    /// Slot to write (with --probe).
    #[arg(long, value_enum, default_value = "auto")]
    pub slot: SlotChoice,
    /// With --probe: plan the write against a simulated probe, touch no
    /// hardware.
    #[arg(long, conflicts_with = "serial")]
    pub dry_run: bool,
    /// Show the probe's register traces (with --dry-run, the simulated
    /// probe's); by default flash prints only what it does.
    #[arg(short, long)]
    pub verbose: bool,
}

/// Which slot `--slot` asks for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum SlotChoice {
    /// Slot A (0x0807_C000).
    A,
    /// Slot B (0x0807_E000).
    B,
    /// The slot that does not hold the newest valid record.
    Auto,
}

impl From<SlotChoice> for SlotArg {
    fn from(s: SlotChoice) -> Self {
        match s {
            SlotChoice::A => SlotArg::A,
            SlotChoice::B => SlotArg::B,
            SlotChoice::Auto => SlotArg::Auto,
        }
    }
}

/// Run `dynocomp flash`.
pub fn run(a: &FlashArgs) -> Result<()> {
    match (&a.serial, a.probe || a.dry_run) {
        (Some(port), _) => crate::link::flash_serial::run(&a.image, port),
        #[cfg(feature = "probe")]
        (None, true) => crate::link::flash_probe::run(&a.image, &a.chip, a.slot.into(), a.dry_run, a.verbose),
        #[cfg(not(feature = "probe"))]
        (None, true) => bail!("flash --probe: this dynocomp was built without the `probe` feature (probe-rs); rebuild with default features"),
        (None, false) => bail!("flash: give --probe (debug probe) or --serial PORT (USB)"),
    }
}
