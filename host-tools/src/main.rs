//! `dynocomp`: design, inspect, flash and apply dynamometer compensators
//! (the commands are in `dynocomp::cli`).
#![forbid(unsafe_code)]

use clap::Parser;
use std::process::ExitCode;

fn main() -> ExitCode {
    // Temporary output files are removed on SIGINT and SIGTERM.
    if let Err(e) = dynocomp::io::atomic::install_signal_cleanup() {
        eprintln!("warning: {e:#}; an interrupted run may leave a temporary file, which the next run removes");
    }
    match dynocomp::cli::run(dynocomp::cli::Cli::parse()) {
        Ok(status) => ExitCode::from(status),
        Err(e) => {
            // One line: the context chain joined, outermost first.
            let msg: Vec<String> = e.chain().map(|c| c.to_string()).collect();
            eprintln!("error: {}", msg.join(": "));
            ExitCode::FAILURE
        }
    }
}
