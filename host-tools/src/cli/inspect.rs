//! `dynocomp inspect`: what a coefficient image holds.

use anyhow::Result;
use std::path::PathBuf;

use crate::io::image_file::{read_any_image, AnyImage};
use crate::report::inspect;

/// `dynocomp inspect IMAGE [--json]`.
#[derive(clap::Args, Debug, Clone)]
pub struct InspectArgs {
    /// Coefficient image (.dcimg).
    pub image: PathBuf,
    /// Machine-readable output.
    #[arg(long)]
    pub json: bool,
}

/// Run `dynocomp inspect`.
pub fn run(args: &InspectArgs) -> Result<()> {
    let report = match read_any_image(&args.image)? {
        AnyImage::Inline(img) => inspect::report(&img),
        AnyImage::Parallel(p) => inspect::report_parallel(&p)?,
        AnyImage::Matrix(m) => {
            let mut report = inspect::report_matrix(&m);
            report.box_reduction = Some(inspect::reduction_report(&args.image, &m));
            report
        }
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{}", inspect::render(&report));
    }
    Ok(())
}
