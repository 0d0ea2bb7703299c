//! `dynocomp inspect`: what a coefficient image holds.

use anyhow::Result;
use std::path::{Path, PathBuf};

use crate::io::image_file::{read_any_image, AnyImage};
use crate::offline::sidecar::{parse_sidecar, sidecar_path};
use crate::report::inspect;
use dynocomp_core::image::MatrixImage;

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
            report.box_reduction = Some(reduction(&args.image, &m));
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

/// Whether the 3x3 image at `image_path` was reduced for the box, as the
/// model sidecar beside it records.
fn reduction(image_path: &Path, image: &MatrixImage) -> inspect::ReductionReport {
    let path = sidecar_path(image_path);
    let shown = path.display().to_string();
    let read = match std::fs::read_to_string(&path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            Err(format!("no model sidecar beside the image ({shown}; `dynocomp design` writes it)"))
        }
        Err(e) => Err(format!("{shown}: cannot read the model sidecar: {e}")),
        Ok(text) => parse_sidecar(&text, &shown, image, image_path).map_err(|e| format!("{e:#}")),
    };
    inspect::reduction_report(shown, read)
}
