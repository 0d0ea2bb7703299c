//! The body of the box's sample interrupt as a pure function (DESIGN.md,
//! "Firmware"): `(raw ADC codes, coefficients, state) -> (DAC codes, flags)`.
//!
//! The firmware's interrupt handler only reads the three ADC results, calls
//! [`process_sample`] and writes the three DAC registers; everything that can
//! go wrong on the sample path (saturation, runaway state, missing or invalid
//! coefficients) is decided here, where host tests exercise it.

use crate::image::{BoxImage, ImageError, MatrixImage};
use crate::kernel::AxisState;
use crate::mimo::MimoState;
use crate::AXES;

/// Largest code of the 12-bit ADC.
pub const ADC_MAX_CODE: u16 = 4095;
/// Largest code of the 12-bit DAC.
pub const DAC_MAX_CODE: u16 = 4095;
/// Sample rates the box hardware supports (Hz).
pub const BOX_FS_RANGE_HZ: core::ops::RangeInclusive<u32> = 10_000..=200_000;

/// Why the box is in bypass (raw forces out).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum BypassReason {
    /// No image in either flash slot.
    NoImage,
    /// The stored image failed validation.
    InvalidImage(ImageError),
    /// The image is offline-only: a version-1 image with `FLAG_OFFLINE_ONLY`,
    /// or a parallel-elaboration image (version 2), which the box refuses
    /// from its version field before reading anything else.
    OfflineOnly,
    /// The image's sample rate is outside [`BOX_FS_RANGE_HZ`].
    UnsupportedSampleRate(u32),
    /// Bypass requested by the user (button or USB command).
    User,
    /// The image's predicted interrupt load at its sample rate exceeds
    /// [`budget::BOX_LOAD_LIMIT_PERMILLE`](crate::budget::BOX_LOAD_LIMIT_PERMILLE)
    /// (`budget::check_load`): predicted cycles per sample and per mille of
    /// the period.
    OverBudget(crate::budget::Load),
}

impl core::fmt::Display for BypassReason {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            BypassReason::NoImage => f.write_str("no image in either flash slot"),
            BypassReason::InvalidImage(e) => write!(f, "the stored image is invalid: {e}"),
            BypassReason::OfflineOnly => f.write_str("the image is offline-only (run it with `dynocomp compensate`)"),
            BypassReason::UnsupportedSampleRate(fs) => write!(
                f,
                "sample rate {fs} Hz outside the box's {}..={} Hz",
                BOX_FS_RANGE_HZ.start(),
                BOX_FS_RANGE_HZ.end()
            ),
            BypassReason::User => f.write_str("bypass requested by the user"),
            BypassReason::OverBudget(l) => write!(
                f,
                "predicted CPU load {}.{} % ({} cycles per sample) exceeds the box's limit of {} %",
                l.permille / 10,
                l.permille % 10,
                l.cycles,
                crate::budget::BOX_LOAD_LIMIT_PERMILLE / 10
            ),
        }
    }
}

/// What the sample path does.
#[derive(Clone, Copy, Debug)]
pub enum Mode<'a> {
    /// Run the compensator of this (validated) image: per axis (version 1)
    /// or 3x3 (version 3).
    Compensate(&'a BoxImage),
    /// Copy the raw ADC codes to the DAC.
    Bypass(BypassReason),
}

/// Decide the sample path's mode from the result of loading the image and
/// the user's bypass switch. Only a validated, inline-capable image at a
/// supported rate is ever run.
pub fn select_mode(loaded: Option<&Result<BoxImage, ImageError>>, user_bypass: bool) -> Mode<'_> {
    match loaded {
        None => Mode::Bypass(BypassReason::NoImage),
        Some(Err(ImageError::ParallelOfflineOnly)) => Mode::Bypass(BypassReason::OfflineOnly),
        Some(Err(e)) => Mode::Bypass(BypassReason::InvalidImage(*e)),
        Some(Ok(img)) => image_mode(img, user_bypass),
    }
}

/// [`select_mode`] for the coefficient store's result (`Store::boot` /
/// `Store::load_active`: a verified image, or why there is none). The
/// image checks are repeated here, so an image that is not runnable still
/// never runs, whoever produced the result.
pub fn select_stored_mode(stored: &Result<BoxImage, BypassReason>, user_bypass: bool) -> Mode<'_> {
    match stored {
        Err(r) => Mode::Bypass(*r),
        Ok(img) => image_mode(img, user_bypass),
    }
}

/// The mode of a parsed image: offline-only images, out-of-range rates and
/// images over the box's CPU budget are never run; otherwise the user's bypass decides.
fn image_mode(img: &BoxImage, user_bypass: bool) -> Mode<'_> {
    if img.is_offline_only() {
        Mode::Bypass(BypassReason::OfflineOnly)
    } else if !BOX_FS_RANGE_HZ.contains(&img.fs_hz()) {
        Mode::Bypass(BypassReason::UnsupportedSampleRate(img.fs_hz()))
    } else if let Err(load) = crate::budget::check_load(img, crate::budget::BOX_LOAD_LIMIT_PERMILLE) {
        Mode::Bypass(BypassReason::OverBudget(load))
    } else if user_bypass {
        Mode::Bypass(BypassReason::User)
    } else {
        Mode::Compensate(img)
    }
}

/// Event counters of the sample path. Wrapping u32 counters (≈ 11.6 h of
/// samples at 100 kHz before the sample counter wraps).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Counters {
    /// Samples processed.
    pub samples: u32,
    /// Missed deadlines: samples that arrived before the previous one was done.
    pub overruns: u32,
    /// Samples with the ADC at a rail, per axis.
    pub saturated: [u32; AXES],
}

/// All mutable state of the sample path: filter memory per axis, of the
/// 3x3 filter, and counters. Both filter states are always there, whichever
/// image runs: an image switch never changes the state's layout.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SampleState {
    /// Filter state per axis (per-axis images; also counts runaway resets).
    pub axes: [AxisState; AXES],
    /// Filter state of a 3x3 image (also counts its runaway resets, each of
    /// which resets all three axes).
    pub matrix: MimoState,
    /// Event counters.
    pub counters: Counters,
}

impl SampleState {
    /// Record `n` missed deadlines (called by the interrupt shell).
    pub fn note_overruns(&mut self, n: u32) {
        self.counters.overruns = self.counters.overruns.wrapping_add(n);
    }

    /// Reset the filter memory of every axis (counters are kept), e.g. after a
    /// coefficient swap or when leaving bypass.
    pub fn reset_filters(&mut self) {
        for a in self.axes.iter_mut() {
            a.reset();
        }
        self.matrix.reset();
    }

    /// Runaway-guard resets per axis: the axis's own (per-axis images) plus
    /// those of the 3x3 filter, which reset every axis (wrapping).
    pub fn nonfinite_resets(&self) -> [u32; AXES] {
        self.axes.map(|a| a.nonfinite_resets.wrapping_add(self.matrix.nonfinite_resets))
    }
}

/// Per-sample flags (bit set), streamed with each sample.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SampleFlags(pub u8);

impl SampleFlags {
    /// Bit of "axis i ADC at a rail" (i = 0..3).
    pub const fn saturated(axis: usize) -> u8 {
        1 << axis
    }
    /// Bit of "axis i state was reset by the runaway guard" (i = 0..3).
    pub const fn reset(axis: usize) -> u8 {
        1 << (3 + axis)
    }
    /// Bit of "this sample was passed through in bypass".
    pub const BYPASS: u8 = 1 << 6;

    /// Whether a bit is set.
    pub fn has(&self, bit: u8) -> bool {
        self.0 & bit != 0
    }
}

/// Round a DAC value to the nearest code and clamp it to `0..=DAC_MAX_CODE`
/// (NaN maps to 0). No panics.
///
/// `(value + 0.5) as u32` truncates toward zero and saturates (NaN and
/// negatives to 0), which is one `vcvt.u32.f32` on the Cortex-M4F (its
/// conversion saturates the same way), then an integer clamp: the same codes
/// as comparing the float against 0 and `DAC_MAX_CODE` first, in a third of
/// the instructions (`tests/sample_path.rs` compares the two definitions).
#[inline]
pub fn to_dac_code(value: f32) -> u16 {
    let code = (value + 0.5) as u32;
    code.min(u32::from(DAC_MAX_CODE)) as u16
}

/// One axis of [`process_sample`] in compensate mode: the DAC code, and
/// whether the runaway guard reset the state (the raw force is output then).
#[inline(always)]
fn compensate_axis(a: &crate::image::AxisImage, state: &mut AxisState, code: u16) -> (u16, bool) {
    let force_n = a.scaling.code_to_newton(code);
    let (y, reset) = match a.filter.step_guarded(state, force_n) {
        Some(y) => (y, false),
        None => (force_n, true),
    };
    (to_dac_code(a.scaling.dac_offset_code + y * a.scaling.dac_code_per_newton), reset)
}

/// [`process_sample`] in compensate mode with a 3x3 image: the three codes
/// to N, one step of the 3x3 filter, the three estimates to DAC codes. If
/// the runaway guard fires, the 3x3 state is reset, and the raw forces are
/// output and the reset flagged on every axis.
#[inline(always)]
fn compensate_matrix(m: &MatrixImage, state: &mut MimoState, codes: [u16; AXES], out: &mut [u16; AXES]) -> u8 {
    let [sx, sy, sz] = &m.axes;
    let [cx, cy, cz] = codes;
    let u = [sx.scaling.code_to_newton(cx), sy.scaling.code_to_newton(cy), sz.scaling.code_to_newton(cz)];
    let (y, flags) = match m.filter.step_guarded(state, u) {
        Some(y) => (y, 0),
        None => (u, SampleFlags::reset(0) | SampleFlags::reset(1) | SampleFlags::reset(2)),
    };
    for ((dst, a), v) in out.iter_mut().zip(&m.axes).zip(y) {
        *dst = to_dac_code(a.scaling.dac_offset_code + v * a.scaling.dac_code_per_newton);
    }
    flags
}

/// One sample of the box: ADC codes in, DAC codes and flags out.
///
/// * Bypass: each DAC code is the ADC code (12 bit → 12 bit), i.e. the raw
///   charge-amplifier signal passes through at the front end's own scale.
/// * Compensate: per axis the code is scaled to N, filtered by the axis's
///   compensator and scaled to a DAC code. An axis absent from the image is
///   passed through raw. If the runaway guard fires, that axis's state is
///   reset, the event counted and flagged, and the raw force is output for
///   that sample.
/// * Compensate with a 3x3 image: the three codes are scaled to N, one step
///   of the 3x3 filter gives the three estimates, each scaled to its DAC
///   code. A runaway resets the 3x3 state, counts once, outputs the raw
///   forces and flags a reset on all three axes for that sample.
///
/// ADC codes at 0 or [`ADC_MAX_CODE`] are flagged and counted as saturated
/// in both modes.
///
/// Always inlined: the firmware's interrupt has it inlined (one call site),
/// and so must every harness that counts its instructions
/// (`qemu/src/bin/icount.rs`), or the counts depend on LLVM's choice.
#[inline(always)]
pub fn process_sample(codes: [u16; AXES], mode: Mode<'_>, state: &mut SampleState) -> ([u16; AXES], SampleFlags) {
    let mut flags = 0u8;
    let mut out = codes;
    state.counters.samples = state.counters.samples.wrapping_add(1);
    for (i, &code) in codes.iter().enumerate() {
        if code == 0 || code >= ADC_MAX_CODE {
            flags |= SampleFlags::saturated(i);
            state.counters.saturated[i] = state.counters.saturated[i].wrapping_add(1);
        }
    }
    match mode {
        Mode::Bypass(_) => flags |= SampleFlags::BYPASS,
        Mode::Compensate(BoxImage::Matrix(m)) => flags |= compensate_matrix(m, &mut state.matrix, codes, &mut out),
        Mode::Compensate(BoxImage::PerAxis(img)) => {
            // One straight-line copy per axis (the loop over the three
            // lanes is unrolled): no search for the next present axis.
            let lanes = img.axes.iter().zip(state.axes.iter_mut()).zip(out.iter_mut()).zip(codes);
            for (i, (((axis_img, axis_state), dac), code)) in lanes.enumerate() {
                if let Some(a) = axis_img {
                    let (code_out, reset) = compensate_axis(a, axis_state, code);
                    *dac = code_out;
                    if reset {
                        flags |= SampleFlags::reset(i);
                    }
                }
            }
        }
    }
    (out, SampleFlags(flags))
}
