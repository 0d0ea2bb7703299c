//! The box's predicted CPU load of an image, for people and scripts
//! (`design`, `inspect`): the core's cost model (`dynocomp_core::budget`)
//! at the image's sample rate on the 170 MHz STM32G474.

use dynocomp_core::budget::{
    image_cycles, image_load, load_permille, max_fs_hz, period_cycles, BOX_LOAD_LIMIT_PERMILLE,
};
use dynocomp_core::image::ImageRef;
use serde::Serialize;

/// Predicted interrupt load of an image at its sample rate.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct LoadReport {
    /// Predicted cycles per sample, optimistic and pessimistic.
    pub cycles: [u32; 2],
    /// Cycles in one sample period at 170 MHz.
    pub period_cycles: u32,
    /// Predicted load (% of the period), optimistic and pessimistic.
    pub load_pct: [f64; 2],
    /// The limit the pessimistic load is held to (%).
    pub limit_pct: f64,
    /// Whether the pessimistic load is within the limit.
    pub fits: bool,
    /// Highest sample rate at which the pessimistic load stays within the
    /// limit (Hz).
    pub max_fs_hz: u32,
}

/// The load report of `image` (per-axis or 3x3: `&CoeffImage`,
/// `&MatrixImage` or `&BoxImage`) against `limit_permille` (the box's own
/// limit is [`BOX_LOAD_LIMIT_PERMILLE`]).
pub fn report<'a>(image: impl Into<ImageRef<'a>>, limit_permille: u32) -> LoadReport {
    let image = image.into();
    let fs_hz = image.fs_hz();
    let c = image_cycles(image);
    let high = image_load(image);
    let limit = limit_permille.min(BOX_LOAD_LIMIT_PERMILLE);
    LoadReport {
        cycles: [c.low, c.high],
        period_cycles: period_cycles(fs_hz),
        load_pct: [f64::from(load_permille(c.low, fs_hz)) / 10.0, f64::from(high.permille) / 10.0],
        limit_pct: f64::from(limit) / 10.0,
        fits: high.permille <= limit,
        max_fs_hz: max_fs_hz(c.high, limit),
    }
}

/// One line: `box CPU load at 51200 Hz: 1020-1283 cycles per sample of 3320 = 30.8-38.7 % (limit 60 %)`.
pub fn describe(r: &LoadReport, fs_hz: u32) -> String {
    format!(
        "box CPU load at {fs_hz} Hz: {}-{} cycles per sample of {} = {:.1}-{:.1} % (limit {:.0} %, predicted; the box runs it up to {} Hz)",
        r.cycles[0], r.cycles[1], r.period_cycles, r.load_pct[0], r.load_pct[1], r.limit_pct, r.max_fs_hz
    )
}

/// The warning for an image marked offline-only, over the load limit at
/// `fs_hz` (per-axis and 3x3 images alike).
pub fn offline_only_warning(load: &LoadReport, fs_hz: u32) -> String {
    format!(
        "WARNING: OFFLINE-ONLY IMAGE: predicted box CPU load {:.1} % ({} cycles per sample) at {fs_hz} Hz exceeds the limit of {:.0} %; \
         the box could run it up to {} Hz. Written for `dynocomp compensate` only: `flash` refuses it and the box would stay in bypass.",
        load.load_pct[1],
        load.cycles[1],
        load.limit_pct,
        load.max_fs_hz
    )
}
