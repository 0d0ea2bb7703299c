//! `dynocomp stream`: record the box's stream of raw and compensated forces.

use anyhow::{bail, Result};
use std::path::PathBuf;

use crate::link::serial::Link;
use crate::link::stream::{record, StreamReport};

/// Options of `dynocomp stream`.
#[derive(clap::Args, Debug, Clone)]
pub struct StreamArgs {
    /// Serial port of the box (e.g. /dev/ttyACM0).
    #[arg(long)]
    pub serial: String,
    /// Output CSV (t_s, fx, fy, fz, raw_fx, raw_fy, raw_fz for the axes of
    /// the image), written atomically.
    #[arg(long)]
    pub output: PathBuf,
    /// Record this long (seconds).
    #[arg(long, conflicts_with = "samples")]
    pub duration: Option<f64>,
    /// Record this many samples.
    #[arg(long)]
    pub samples: Option<usize>,
    /// Keep one sample out of N (default: the smallest N that keeps the
    /// stream at or below 20 000 samples/s, what USB full speed carries).
    #[arg(long)]
    pub decimation: Option<u16>,
}

/// `dynocomp stream`.
pub fn run(args: &StreamArgs) -> Result<StreamReport> {
    if args.duration.is_none() && args.samples.is_none() {
        bail!("give --duration S or --samples N");
    }
    if let Some(d) = args.duration {
        if !(d > 0.0 && d.is_finite()) {
            bail!("--duration {d}: must be a positive number of seconds");
        }
    }
    let port = std::path::Path::new(&args.serial);
    crate::io::atomic::ensure_not_an_input(&[("--output", &args.output)], &[("--serial", port)])?;
    let mut link = Link::open(&args.serial)?;
    let (dur, n) = (args.duration, args.samples);
    let report = record(&mut link, args.decimation, &args.output, n, |got, t| {
        n.is_some_and(|n| got >= n) || dur.is_some_and(|d| t.as_secs_f64() >= d)
    })?;
    eprintln!("{} -> {}", report.summary(), args.output.display());
    for line in report.box_load.summary() {
        eprintln!("{line}");
    }
    Ok(report)
}
