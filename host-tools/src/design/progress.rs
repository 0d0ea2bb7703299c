//! Where a long design reports its stages: one line each, e.g. to a
//! terminal (`design` prints them on stderr). Axes are designed on parallel
//! threads, so the lines of different axes may interleave.

use std::sync::Arc;

/// A sink for stage lines ("axis y (2/3): fitting 4097 FRF lines…").
#[derive(Clone)]
pub struct Progress(pub Arc<dyn Fn(&str) + Send + Sync>);

impl Progress {
    /// Lines go nowhere.
    pub fn none() -> Self {
        Progress(Arc::new(|_| {}))
    }

    /// Lines on stderr, indented by two spaces (under a command's own line).
    pub fn stderr() -> Self {
        Progress(Arc::new(|line| eprintln!("  {line}")))
    }

    /// Report one stage line.
    pub fn say(&self, line: &str) {
        (self.0)(line)
    }
}

impl std::fmt::Debug for Progress {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Progress")
    }
}
