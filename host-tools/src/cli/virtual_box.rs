//! `dynocomp virtual-box` (hidden): a simulated box on a pseudo-terminal, for
//! tests and demos.

use anyhow::Result;

use crate::link::virtual_box::VirtualBoxOptions;

/// Options of `dynocomp virtual-box`.
#[derive(clap::Args, Debug, Clone)]
pub struct VirtualBoxArgs {
    /// File holding the simulated flash (created erased if missing); the
    /// slots survive restarts of the virtual box.
    #[arg(long)]
    pub flash: Option<std::path::PathBuf>,
    /// Cut the simulated power at this flash operation (page erase or
    /// double-word write, counted from 0 after boot): the process exits
    /// with status 3 at once, as a box would lose power.
    #[arg(long)]
    pub power_cut_at_op: Option<u64>,
    /// Never send the stream frames with these sequence numbers
    /// (comma-separated): simulated loss on the link.
    #[arg(long, value_delimiter = ',')]
    pub drop_frames: Vec<u32>,
}

/// Run the virtual box; returns its exit status.
pub fn run(args: &VirtualBoxArgs) -> Result<i32> {
    crate::link::virtual_box::run(&VirtualBoxOptions {
        flash: args.flash.clone(),
        power_cut_at_op: args.power_cut_at_op,
        drop_frames: args.drop_frames.clone(),
    })
}
