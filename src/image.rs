//! The coefficient image: one versioned, position-independent, CRC-protected
//! binary blob per box (DESIGN.md, "The coefficient image").
//!
//! The byte layout is documented in `docs/image-format.md`; this module is its
//! only implementation. All multi-byte fields are little-endian.
//!
//! Parsing never panics on any input: every read goes through bounds-checked
//! accessors, and every failure is a typed [`ImageError`]. Validation order:
//! length → magic → version → declared length → CRC → per-axis structure
//! (counts, reserved bytes, finiteness and stability of each section) →
//! header and scaling ranges. A single flipped bit anywhere is caught by the
//! CRC-32. `docs/image-format.md` lists every step.
//!
//! Two kinds of image share the envelope (magic, header, CRC):
//! * version 1, [`CoeffImage`]: one compensator per axis, what the box runs;
//! * version 2, [`ParallelImage`]: parallel elaboration (paper §3.3), one
//!   compensator per band and axis plus the band edges. **Offline only**:
//!   [`CoeffImage::parse`] and [`CoeffImage::parse_prefix`] refuse it from its
//!   version field ([`ImageError::ParallelOfflineOnly`]), so the box never
//!   runs any part of it, and it always carries [`FLAG_OFFLINE_ONLY`];
//! * version 3, [`MatrixImage`]: one 3-input, 3-output compensator
//!   ([`MimoFilter`]) whose modes are shared by the three force estimates
//!   (crosstalk compensation). The box runs it like version 1.
//!
//! [`BoxImage`] is what the box runs: a version-1 or a version-3 image
//! ([`BoxImage::parse`] chooses by the version field).

use crate::kernel::{AxisFilter, FilterError, Section, MAX_FIR, MAX_SECTIONS};
use crate::mimo::{Matrix3, MimoFilter, MimoSection, MAX_MIMO_FIR, MAX_MIMO_SECTIONS, MIMO_AXES};
use crate::AXES;

/// Magic bytes at offset 0.
pub const MAGIC: [u8; 4] = *b"DCIM";
/// The format version this code writes and reads.
pub const FORMAT_VERSION: u16 = 1;
/// Size of the fixed header (bytes before the first axis block).
pub const HEADER_LEN: usize = 64;
/// Size of an axis block without its sections and FIR taps.
pub const AXIS_HEADER_LEN: usize = 60;
/// Size of one FIR tap (f32).
pub const TAP_LEN: usize = 4;
/// Size of one section record (8 × f32).
pub const SECTION_LEN: usize = 32;
/// Size of the trailing CRC.
pub const CRC_LEN: usize = 4;
/// Largest possible image (3 axes × 24 sections × 24 FIR taps).
pub const MAX_IMAGE_LEN: usize =
    HEADER_LEN + AXES * (AXIS_HEADER_LEN + MAX_SECTIONS * SECTION_LEN + MAX_FIR * TAP_LEN) + CRC_LEN;
/// Smallest valid image (1 axis, 0 sections, no taps).
pub const MIN_IMAGE_LEN: usize = HEADER_LEN + AXIS_HEADER_LEN + CRC_LEN;

/// Format version of a parallel-elaboration image ([`ParallelImage`]):
/// several band compensators per axis, offline only.
pub const PARALLEL_FORMAT_VERSION: u16 = 2;
/// Most bands in a parallel-elaboration image.
pub const MAX_BANDS: usize = 8;
/// Size of one band record of a parallel image (lo_hz, hi_hz as f32).
pub const BAND_RECORD_LEN: usize = 8;
/// Largest possible parallel image ([`MAX_BANDS`] bands × 3 full axes). It
/// is larger than a flash slot: parallel images only live in files.
pub const MAX_PARALLEL_IMAGE_LEN: usize = HEADER_LEN
    + MAX_BANDS * (BAND_RECORD_LEN + AXES * (AXIS_HEADER_LEN + MAX_SECTIONS * SECTION_LEN + MAX_FIR * TAP_LEN))
    + CRC_LEN;

/// Accepted sample-rate range of an image (Hz). The box itself narrows this
/// to what its hardware supports.
pub const FS_RANGE_HZ: core::ops::RangeInclusive<u32> = 1_000..=1_000_000;
/// Largest declared output latency (samples).
pub const MAX_LATENCY_SAMPLES: u16 = 1024;

/// Largest magnitude of any filter coefficient (Δ, b, c, d, FIR taps), N/N
/// or dimensionless. The host scales every section state to unit input gain
/// (b = 1), so c, d and the taps are gains of a force/force filter, and
/// stable Δ entries are below 2: designs use magnitudes of 10⁻⁶…10². The
/// bound is four orders of magnitude above that and far below what a flipped
/// high exponent bit makes of a coefficient (a factor of 2⁶⁴ or more).
pub const MAX_COEFFICIENT: f32 = 1.0e6;
/// Smallest distance of every section pole from the unit circle: pole
/// radius ≤ 1 − `MIN_POLE_MARGIN`, the margin the host's design verifies
/// after rounding to f32 (`quantize::POLE_MARGIN`).
pub const MIN_POLE_MARGIN: f64 = 1.0e-7;
/// Largest accepted bound on the ℓ1 gain of an axis's filter
/// ([`AxisFilter::gain_bound`], N/N): for |u| ≤ U the output stays within
/// this times U. Designed compensators are at 3…1 300 (their lightly damped
/// slow modes dominate); a compensator that may amplify some bounded force
/// ten thousand times is not a force measurement, it is a wrong image.
pub const MAX_GAIN_BOUND: f64 = 1.0e4;
/// Largest magnitude of an axis's DC gain ([`AxisFilter::dc_gain`], N/N).
/// A compensator's static gain is the inverse of the dynamometer's static
/// sensitivity after calibration, ≈ 1 (band-pass compensators of a
/// parallel image: ≈ 0); beyond 100 the image does not belong to a
/// calibrated force channel.
pub const MAX_DC_GAIN: f64 = 100.0;

/// Format version of a 3x3 image ([`MatrixImage`]): one 3-input, 3-output
/// compensator for the three axes.
pub const MATRIX_FORMAT_VERSION: u16 = 3;
/// Size of one axis block of a 3x3 image: scaling and design summary, no
/// filter (bytes).
pub const MATRIX_AXIS_LEN: usize = 56;
/// Size of the 3x3 filter's header: counts, reserved, the 3x3 direct term
/// (bytes).
pub const MATRIX_FILTER_HEADER_LEN: usize = 40;
/// Size of one section record of a 3x3 image (16 × f32: Δ, B, C).
pub const MIMO_SECTION_LEN: usize = 64;
/// Size of one FIR tap of a 3x3 image (a 3x3 matrix of f32).
pub const MIMO_TAP_LEN: usize = 36;
/// Size of the row record of a 3x3 image (one byte per output row, one
/// reserved byte).
pub const ROW_RECORD_LEN: usize = 4;
/// Smallest 3x3 image (a pure 3x3 gain: no section, no tap).
pub const MIN_MATRIX_IMAGE_LEN: usize =
    HEADER_LEN + MIMO_AXES * MATRIX_AXIS_LEN + MATRIX_FILTER_HEADER_LEN + ROW_RECORD_LEN + CRC_LEN;
/// Largest 3x3 image ([`MAX_MIMO_SECTIONS`] sections, [`MAX_MIMO_FIR`] taps).
pub const MAX_MATRIX_IMAGE_LEN: usize =
    MIN_MATRIX_IMAGE_LEN + MAX_MIMO_SECTIONS * MIMO_SECTION_LEN + MAX_MIMO_FIR * MIMO_TAP_LEN;
/// Largest image the box runs (either version): what a flash slot must hold.
pub const MAX_BOX_IMAGE_LEN: usize =
    if MAX_MATRIX_IMAGE_LEN > MAX_IMAGE_LEN { MAX_MATRIX_IMAGE_LEN } else { MAX_IMAGE_LEN };
/// Largest deviation of a 3x3 filter's DC gain row from the identity row,
/// `Σ_j |H_ij(1) − δ_ij|` (N/N). A dynamometer's static matrix is the
/// identity within its calibration (sensitivity ≲ 1 %) and its static
/// crosstalk (≲ 2 % per pair of axes, datasheets of the 9257 class): the
/// rigid top plate passes a static force to the sensors whatever its point
/// of application. So a compensator's static gain row is the identity row
/// within a few per cent. 0.5 leaves an order of magnitude for the fit's
/// extrapolation to DC (impact tests are poor below ≈ 50 Hz) and refuses a
/// row that turns a static force into 1.5 times itself, or reads half of
/// another axis's static force: not a calibrated force/force compensator.
pub const MAX_DC_ROW_DEVIATION: f64 = 0.5;

/// Image flag: the image holds an offline-only design (e.g. parallel
/// elaboration); the box must never run it.
pub const FLAG_OFFLINE_ONLY: u8 = 0x01;
const KNOWN_FLAGS: u8 = FLAG_OFFLINE_ONLY;

/// The CRC used: CRC-32/ISO-HDLC (the zlib/PNG/Ethernet CRC-32).
pub const CRC32: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

/// How the compensator was designed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum DesignMethod {
    /// Not produced by the design pipeline (hand-made, test or placeholder).
    Manual = 0,
    /// Vector fitting + ZOH + discrete Riccati (the default).
    VectorFitting = 1,
    /// The seed paper's RFP + damped Gauss-Newton + continuous Riccati + Tustin.
    Paper = 2,
}

impl DesignMethod {
    fn from_u8(v: u8) -> Option<Self> {
        match v {
            0 => Some(Self::Manual),
            1 => Some(Self::VectorFitting),
            2 => Some(Self::Paper),
            _ => None,
        }
    }
}

/// Conversion between converter codes and newtons for one axis.
///
/// `force_n = (adc_code − adc_offset_code) · newton_per_code` and
/// `dac_code = dac_offset_code + force_n · dac_code_per_newton`.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct AxisScaling {
    /// ADC code that corresponds to 0 N (codes).
    pub adc_offset_code: f32,
    /// Input gain (N per ADC code).
    pub newton_per_code: f32,
    /// Output gain (DAC codes per N).
    pub dac_code_per_newton: f32,
    /// DAC code that represents 0 N (codes).
    pub dac_offset_code: f32,
}

impl AxisScaling {
    /// ADC code → force (N).
    #[inline]
    pub fn code_to_newton(&self, code: u16) -> f32 {
        (f32::from(code) - self.adc_offset_code) * self.newton_per_code
    }
}

/// Design summary of one axis, carried for `inspect` and the box's status.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct AxisSummary {
    /// Order of the fitted sensor model G(s).
    pub model_order: u16,
    /// Normalized RMS fit error of G over the coherent band (fraction, 0.01 = 1 %).
    pub fit_nrmse: f32,
    /// Lower edge of the achieved flat band (|H·G| within ±5 %, ±5°), Hz.
    pub flat_lo_hz: f32,
    /// Upper edge of the achieved flat band, Hz.
    pub flat_hi_hz: f32,
    /// Noise gain: output noise RMS / input noise RMS for white noise (ratio).
    pub noise_gain: f32,
    /// Process-noise intensity Q of the force random walk (N²/sample).
    pub q: f64,
    /// Measurement-noise variance R (N²).
    pub r: f64,
}

/// One axis of an image: which axis, its scaling, filter and summary.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AxisImage {
    /// Axis index (0 = x, 1 = y, 2 = z).
    pub axis: u8,
    /// Code ↔ newton conversion.
    pub scaling: AxisScaling,
    /// The compensator.
    pub filter: AxisFilter,
    /// Design summary.
    pub summary: AxisSummary,
}

/// A decoded, validated coefficient image.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CoeffImage {
    /// Sample rate the filters were designed for (Hz).
    pub fs_hz: u32,
    /// Declared output latency of the compensated force (samples).
    pub latency_samples: u16,
    /// Flags (`FLAG_*`).
    pub flags: u8,
    /// Design method.
    pub method: DesignMethod,
    /// SHA-256 of the FRF file the design came from (zeros if none).
    pub source_sha256: [u8; 32],
    /// Creation time, seconds since the Unix epoch (0 if unknown).
    pub created_unix_s: u64,
    /// Per-axis content; `None` for an axis the image does not cover.
    pub axes: [Option<AxisImage>; AXES],
}

/// Why an image was rejected.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ImageError {
    /// Fewer bytes than the smallest image or than the declared length.
    Truncated {
        /// Bytes needed.
        needed: u32,
        /// Bytes present.
        have: u32,
    },
    /// The magic bytes are wrong (erased flash, not an image).
    BadMagic,
    /// A format version this code does not read.
    UnsupportedVersion(u16),
    /// The declared header length is not [`HEADER_LEN`].
    BadHeaderLength(u16),
    /// The declared total length is out of range or disagrees with the contents.
    BadLength(u32),
    /// CRC mismatch.
    BadCrc {
        /// CRC stored in the image.
        stored: u32,
        /// CRC computed over the image.
        computed: u32,
    },
    /// Sample rate outside [`FS_RANGE_HZ`].
    SampleRateOutOfRange(u32),
    /// Latency above [`MAX_LATENCY_SAMPLES`].
    LatencyOutOfRange(u16),
    /// No axis, or unknown axis bits set.
    BadAxisMask(u8),
    /// Unknown flag bits set.
    UnknownFlags(u8),
    /// Unknown design method code.
    UnknownMethod(u8),
    /// Reserved bytes are not zero.
    ReservedNotZero,
    /// An axis block names a different axis than expected from the mask.
    AxisMismatch {
        /// Expected axis index.
        expected: u8,
        /// Axis index found.
        found: u8,
    },
    /// More than [`MAX_FIR`] FIR taps on an axis.
    TooManyTaps {
        /// Axis index.
        axis: u8,
        /// Declared count.
        count: u8,
    },
    /// An FIR tap is non-finite.
    NonFiniteTap {
        /// Axis index.
        axis: u8,
        /// Tap index (0 = delay 1).
        tap: u8,
    },
    /// More than [`MAX_SECTIONS`] sections on an axis.
    TooManySections {
        /// Axis index.
        axis: u8,
        /// Declared count.
        count: u8,
    },
    /// A scaling value is non-finite or zero where it must not be.
    BadScaling {
        /// Axis index.
        axis: u8,
    },
    /// A summary value is non-finite or negative.
    BadSummary {
        /// Axis index.
        axis: u8,
    },
    /// A filter coefficient is non-finite (section index; 255 for `d`).
    NonFiniteCoefficient {
        /// Axis index.
        axis: u8,
        /// Section index.
        section: u8,
    },
    /// A section has a pole on or outside the unit circle.
    UnstableSection {
        /// Axis index.
        axis: u8,
        /// Section index.
        section: u8,
    },
    /// Output buffer too small (encoding only).
    BufferTooSmall {
        /// Bytes needed.
        needed: u32,
    },
    /// A parallel-elaboration image (format version 2) where a box-runnable
    /// image (version 1) is expected: it is offline only, the box never runs it.
    ParallelOfflineOnly,
    /// A parallel image without [`FLAG_OFFLINE_ONLY`].
    ParallelNotOfflineOnly,
    /// A parallel image with 0 or more than [`MAX_BANDS`] bands.
    BadBandCount(u8),
    /// A band's edges are non-finite, empty, above Nyquist, or not above the
    /// previous band's upper edge.
    BadBand {
        /// Band index (0 = lowest).
        band: u8,
    },
    /// A band covers different axes than the first band.
    BandAxesDiffer {
        /// Band index.
        band: u8,
    },
    /// A section is neither a conjugate pair in real normal form nor
    /// diagonal, the shapes the kernel runs (`FilterError::NotModal`).
    /// Last on purpose: the variant index is on the USB wire.
    NotModalSection {
        /// Axis index.
        axis: u8,
        /// Section index.
        section: u8,
    },
    /// A coefficient's magnitude exceeds [`MAX_COEFFICIENT`] (section index;
    /// 255 for `d`).
    CoefficientOutOfRange {
        /// Axis index.
        axis: u8,
        /// Section index (255: `d`).
        section: u8,
    },
    /// An FIR tap's magnitude exceeds [`MAX_COEFFICIENT`].
    TapOutOfRange {
        /// Axis index.
        axis: u8,
        /// Tap index (0 = delay 1).
        tap: u8,
    },
    /// A section has a pole within [`MIN_POLE_MARGIN`] of the unit circle.
    PoleMarginTooSmall {
        /// Axis index.
        axis: u8,
        /// Section index.
        section: u8,
    },
    /// The bound on the axis filter's ℓ1 gain exceeds [`MAX_GAIN_BOUND`] or
    /// is not finite.
    GainBoundTooLarge {
        /// Axis index.
        axis: u8,
        /// The bound, rounded to an integer (N/N; `u32::MAX` if larger or
        /// not finite).
        bound: u32,
    },
    /// The axis filter's DC gain is not finite or exceeds [`MAX_DC_GAIN`].
    DcGainOutOfRange {
        /// Axis index.
        axis: u8,
    },
    /// A 3x3 image (format version 3) where a per-axis image (version 1) is
    /// expected: read it with [`BoxImage::parse`] or [`MatrixImage::parse`].
    NotPerAxisImage,
    /// A 3x3 image's row record holds an unknown design code.
    BadRowDesign {
        /// Output row (axis index).
        row: u8,
        /// The code found.
        code: u8,
    },
    /// A 3x3 filter with more than [`MAX_MIMO_SECTIONS`] sections.
    MatrixTooManySections(u8),
    /// A 3x3 filter with more than [`MAX_MIMO_FIR`] FIR taps.
    MatrixTooManyTaps(u8),
    /// A 3x3 filter coefficient is non-finite (section index; 255 for `d`).
    MatrixNonFinite {
        /// Section index (255: the direct term).
        section: u8,
    },
    /// A 3x3 FIR tap is non-finite.
    MatrixNonFiniteTap {
        /// Tap index (0 = delay 1).
        tap: u8,
    },
    /// A 3x3 section has a pole on or outside the unit circle.
    MatrixUnstableSection {
        /// Section index.
        section: u8,
    },
    /// A 3x3 section is neither a normal-form pair nor diagonal.
    MatrixNotModalSection {
        /// Section index.
        section: u8,
    },
    /// A 3x3 filter coefficient's magnitude exceeds [`MAX_COEFFICIENT`]
    /// (section index; 255 for `d`).
    MatrixCoefficientOutOfRange {
        /// Section index (255: the direct term).
        section: u8,
    },
    /// A 3x3 FIR tap entry's magnitude exceeds [`MAX_COEFFICIENT`].
    MatrixTapOutOfRange {
        /// Tap index (0 = delay 1).
        tap: u8,
    },
    /// A 3x3 section has a pole within [`MIN_POLE_MARGIN`] of the unit circle.
    MatrixPoleMarginTooSmall {
        /// Section index.
        section: u8,
    },
    /// The bound on an output row's ℓ1 gain exceeds [`MAX_GAIN_BOUND`] or is
    /// not finite.
    MatrixGainBoundTooLarge {
        /// Output row (axis index).
        row: u8,
        /// The bound, rounded (N/N; `u32::MAX` if larger or not finite).
        bound: u32,
    },
    /// An output row's DC gain is not finite or deviates from the identity
    /// row by more than [`MAX_DC_ROW_DEVIATION`].
    MatrixDcGainOutOfRange {
        /// Output row (axis index).
        row: u8,
    },
}

impl core::fmt::Display for ImageError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        use ImageError::*;
        match *self {
            Truncated { needed, have } => write!(f, "image truncated: {have} bytes, need {needed}"),
            BadMagic => write!(f, "not a dynocomp coefficient image (bad magic)"),
            UnsupportedVersion(v) => {
                write!(f, "unsupported image format version {v} (this build reads {FORMAT_VERSION} to {MATRIX_FORMAT_VERSION})")
            }
            BadHeaderLength(l) => write!(f, "bad header length {l} (expected {HEADER_LEN})"),
            BadLength(l) => write!(f, "declared image length {l} is inconsistent with its contents"),
            BadCrc { stored, computed } => write!(f, "CRC mismatch: stored {stored:#010x}, computed {computed:#010x} (image corrupted)"),
            SampleRateOutOfRange(fs) => write!(f, "sample rate {fs} Hz outside {}..={} Hz", FS_RANGE_HZ.start(), FS_RANGE_HZ.end()),
            LatencyOutOfRange(l) => write!(f, "declared latency {l} samples exceeds {MAX_LATENCY_SAMPLES}"),
            BadAxisMask(m) => write!(f, "bad axis mask {m:#04x}"),
            UnknownFlags(fl) => write!(f, "unknown flag bits {fl:#04x}"),
            UnknownMethod(m) => write!(f, "unknown design method code {m}"),
            ReservedNotZero => write!(f, "reserved bytes (header or axis block) are not zero"),
            AxisMismatch { expected, found } => write!(f, "axis block for axis {found} where axis {expected} was expected"),
            TooManyTaps { axis, count } => write!(f, "axis {axis}: {count} FIR taps exceeds the maximum {MAX_FIR}"),
            NonFiniteTap { axis, tap } => write!(f, "axis {axis}: FIR tap {tap} is non-finite"),
            TooManySections { axis, count } => write!(f, "axis {axis}: {count} sections exceeds the maximum {MAX_SECTIONS}"),
            BadScaling { axis } => write!(f, "axis {axis}: scaling values non-finite or zero gain"),
            BadSummary { axis } => write!(f, "axis {axis}: design summary has non-finite or negative values"),
            NonFiniteCoefficient { axis, section } => write!(f, "axis {axis}: section {section} has a non-finite coefficient"),
            UnstableSection { axis, section } => write!(f, "axis {axis}: section {section} has a pole on or outside the unit circle"),
            NotModalSection { axis, section } => write!(
                f,
                "axis {axis}: section {section} is neither a normal-form pole pair (Δ11 = Δ22, Δ21 = −Δ12, b2 = 0) nor diagonal"
            ),
            BufferTooSmall { needed } => write!(f, "output buffer too small, need {needed} bytes"),
            ParallelOfflineOnly => write!(
                f,
                "parallel-elaboration image (format {PARALLEL_FORMAT_VERSION}): offline only, run it with `dynocomp compensate`; the box never runs it"
            ),
            ParallelNotOfflineOnly => write!(f, "parallel-elaboration image without the offline-only flag"),
            CoefficientOutOfRange { axis, section: 255 } => {
                write!(f, "axis {axis}: direct term d is beyond ±{MAX_COEFFICIENT:e} (image corrupted or not a force compensator)")
            }
            CoefficientOutOfRange { axis, section } => {
                write!(f, "axis {axis}: section {section} has a coefficient beyond ±{MAX_COEFFICIENT:e} (image corrupted)")
            }
            TapOutOfRange { axis, tap } => write!(f, "axis {axis}: FIR tap {tap} is beyond ±{MAX_COEFFICIENT:e} (image corrupted)"),
            PoleMarginTooSmall { axis, section } => {
                write!(f, "axis {axis}: section {section} has a pole within {MIN_POLE_MARGIN:e} of the unit circle")
            }
            GainBoundTooLarge { axis, bound } => write!(
                f,
                "axis {axis}: the filter may amplify a bounded force up to {bound} times (limit {MAX_GAIN_BOUND:e}): image corrupted or unstable"
            ),
            DcGainOutOfRange { axis } => write!(
                f,
                "axis {axis}: DC gain is not finite or beyond ±{MAX_DC_GAIN} (not a calibrated force/force compensator)"
            ),
            BadBandCount(n) => write!(f, "parallel image with {n} bands (allowed 1..={MAX_BANDS})"),
            BadBand { band } => write!(f, "band {band}: edges non-finite, empty, above Nyquist or overlapping the previous band"),
            BandAxesDiffer { band } => write!(f, "band {band} covers other axes than band 0"),
            NotPerAxisImage => write!(
                f,
                "3x3 image (format {MATRIX_FORMAT_VERSION}) where a per-axis image (format {FORMAT_VERSION}) is expected"
            ),
            BadRowDesign { row, code } => write!(f, "3x3 image: row {row} has unknown design code {code} (0 per-axis, 1 3x3)"),
            MatrixTooManySections(n) => write!(f, "3x3 filter: {n} sections exceeds the maximum {MAX_MIMO_SECTIONS}"),
            MatrixTooManyTaps(n) => write!(f, "3x3 filter: {n} FIR taps exceeds the maximum {MAX_MIMO_FIR}"),
            MatrixNonFinite { section: 255 } => write!(f, "3x3 filter: the direct term d has a non-finite entry"),
            MatrixNonFinite { section } => write!(f, "3x3 filter: section {section} has a non-finite coefficient"),
            MatrixNonFiniteTap { tap } => write!(f, "3x3 filter: FIR tap {tap} has a non-finite entry"),
            MatrixUnstableSection { section } => {
                write!(f, "3x3 filter: section {section} has a pole on or outside the unit circle")
            }
            MatrixNotModalSection { section } => write!(
                f,
                "3x3 filter: section {section} is neither a normal-form pole pair (Δ11 = Δ22, Δ21 = −Δ12) nor diagonal"
            ),
            MatrixCoefficientOutOfRange { section: 255 } => {
                write!(f, "3x3 filter: the direct term d has an entry beyond ±{MAX_COEFFICIENT:e} (image corrupted)")
            }
            MatrixCoefficientOutOfRange { section } => {
                write!(f, "3x3 filter: section {section} has a coefficient beyond ±{MAX_COEFFICIENT:e} (image corrupted)")
            }
            MatrixTapOutOfRange { tap } => {
                write!(f, "3x3 filter: FIR tap {tap} has an entry beyond ±{MAX_COEFFICIENT:e} (image corrupted)")
            }
            MatrixPoleMarginTooSmall { section } => {
                write!(f, "3x3 filter: section {section} has a pole within {MIN_POLE_MARGIN:e} of the unit circle")
            }
            MatrixGainBoundTooLarge { row, bound } => write!(
                f,
                "3x3 filter: row {row} may amplify bounded forces up to {bound} times (limit {MAX_GAIN_BOUND:e}): image corrupted or unstable"
            ),
            MatrixDcGainOutOfRange { row } => write!(
                f,
                "3x3 filter: row {row}'s DC gain is not finite or deviates from the identity row by more than {MAX_DC_ROW_DEVIATION} \
                 (not a calibrated force/force compensator)"
            ),
        }
    }
}

/// Bounds-checked little-endian reader; every read returns `None` past the end.
struct Reader<'a> {
    buf: &'a [u8],
    pos: usize,
}

impl<'a> Reader<'a> {
    fn bytes<const N: usize>(&mut self) -> Option<[u8; N]> {
        let end = self.pos.checked_add(N)?;
        let out: [u8; N] = self.buf.get(self.pos..end)?.try_into().ok()?;
        self.pos = end;
        Some(out)
    }
    fn u8(&mut self) -> Option<u8> {
        self.bytes::<1>().map(|b| b[0])
    }
    fn u16(&mut self) -> Option<u16> {
        self.bytes().map(u16::from_le_bytes)
    }
    fn u32(&mut self) -> Option<u32> {
        self.bytes().map(u32::from_le_bytes)
    }
    fn u64(&mut self) -> Option<u64> {
        self.bytes().map(u64::from_le_bytes)
    }
    fn f32(&mut self) -> Option<f32> {
        self.bytes().map(f32::from_le_bytes)
    }
    fn f64(&mut self) -> Option<f64> {
        self.bytes().map(f64::from_le_bytes)
    }
}

/// Bounds-checked little-endian writer.
struct Writer<'a> {
    buf: &'a mut [u8],
    pos: usize,
}

impl Writer<'_> {
    fn put(&mut self, bytes: &[u8]) {
        // Callers check the total length first; out-of-range writes are dropped
        // rather than panicking.
        if let Some(dst) = self.buf.get_mut(self.pos..self.pos + bytes.len()) {
            dst.copy_from_slice(bytes);
        }
        self.pos += bytes.len();
    }
}

/// Length of one axis block with its sections and taps (bytes).
fn axis_block_len(a: &AxisImage) -> usize {
    AXIS_HEADER_LEN + a.filter.sections().len() * SECTION_LEN + a.filter.fir().len() * TAP_LEN
}

/// Total image length of an image (header, axis blocks, sections, taps, CRC).
pub fn encoded_len(image: &CoeffImage) -> usize {
    HEADER_LEN + image.axes.iter().flatten().map(axis_block_len).sum::<usize>() + CRC_LEN
}

/// Read the declared total length from an image header without validating
/// the rest (used to find an image's end inside a flash slot).
pub fn declared_len(bytes: &[u8]) -> Option<usize> {
    let mut r = Reader { buf: bytes, pos: 8 };
    r.u32().map(|v| v as usize)
}

/// Read the format version (bytes 4..6) of something that starts with the
/// image magic; `None` if it does not.
pub fn peek_version(bytes: &[u8]) -> Option<u16> {
    if bytes.get(..4) != Some(&MAGIC[..]) {
        return None;
    }
    Reader { buf: bytes, pos: 4 }.u16()
}

/// The fields of the 64-byte header after `total_len` (offsets 12..64).
struct Header {
    fs_hz: u32,
    latency_samples: u16,
    mask: u8,
    flags: u8,
    method_code: u8,
    /// Bytes 21..24: reserved (zero) in version 1; byte 21 is the band count
    /// in version 2.
    extra: [u8; 3],
    source_sha256: [u8; 32],
    created_unix_s: u64,
}

/// Check everything up to and including the CRC (steps 1-8 of
/// `docs/image-format.md` §8) and return the body (all bytes before the CRC).
fn envelope(bytes: &[u8], version: u16, min_len: usize, max_len: usize) -> Result<&[u8], ImageError> {
    let have = bytes.len() as u32;
    if bytes.len() < MIN_IMAGE_LEN {
        return Err(ImageError::Truncated { needed: MIN_IMAGE_LEN as u32, have });
    }
    let mut r = Reader { buf: bytes, pos: 0 };
    let truncated = ImageError::Truncated { needed: MIN_IMAGE_LEN as u32, have };
    if r.bytes::<4>() != Some(MAGIC) {
        return Err(ImageError::BadMagic);
    }
    let v = r.u16().ok_or(truncated)?;
    if v != version {
        return Err(match v {
            PARALLEL_FORMAT_VERSION => ImageError::ParallelOfflineOnly,
            MATRIX_FORMAT_VERSION => ImageError::NotPerAxisImage,
            _ => ImageError::UnsupportedVersion(v),
        });
    }
    let header_len = r.u16().ok_or(truncated)?;
    if usize::from(header_len) != HEADER_LEN {
        return Err(ImageError::BadHeaderLength(header_len));
    }
    let total = r.u32().ok_or(truncated)?;
    if (total as usize) < min_len || total as usize > max_len {
        return Err(ImageError::BadLength(total));
    }
    if bytes.len() < total as usize {
        return Err(ImageError::Truncated { needed: total, have });
    }
    if bytes.len() > total as usize {
        return Err(ImageError::BadLength(total));
    }
    let body_len = total as usize - CRC_LEN;
    let body = bytes.get(..body_len).ok_or(truncated)?;
    let stored = Reader { buf: bytes, pos: body_len }.u32().ok_or(truncated)?;
    let computed = CRC32.checksum(body);
    if stored != computed {
        return Err(ImageError::BadCrc { stored, computed });
    }
    Ok(body)
}

/// Read header bytes 12..64 (the envelope has been checked).
fn read_header(r: &mut Reader<'_>, bad_len: ImageError) -> Result<Header, ImageError> {
    Ok(Header {
        fs_hz: r.u32().ok_or(bad_len)?,
        latency_samples: r.u16().ok_or(bad_len)?,
        mask: r.u8().ok_or(bad_len)?,
        flags: r.u8().ok_or(bad_len)?,
        method_code: r.u8().ok_or(bad_len)?,
        extra: r.bytes::<3>().ok_or(bad_len)?,
        source_sha256: r.bytes::<32>().ok_or(bad_len)?,
        created_unix_s: r.u64().ok_or(bad_len)?,
    })
}

/// Write the 64-byte header.
fn write_header(w: &mut Writer<'_>, version: u16, len: usize, h: &Header) {
    w.put(&MAGIC);
    w.put(&version.to_le_bytes());
    w.put(&(HEADER_LEN as u16).to_le_bytes());
    w.put(&(len as u32).to_le_bytes());
    w.put(&h.fs_hz.to_le_bytes());
    w.put(&h.latency_samples.to_le_bytes());
    w.put(&[h.mask, h.flags, h.method_code]);
    w.put(&h.extra);
    w.put(&h.source_sha256);
    w.put(&h.created_unix_s.to_le_bytes());
}

/// The CRC stored at the end of the `n` encoded bytes in `buf` (0 if the
/// encoding failed): the image id.
fn stored_crc(buf: &[u8], n: Result<usize, ImageError>) -> u32 {
    n.ok().and_then(|n| Reader { buf, pos: n.checked_sub(CRC_LEN)? }.u32()).unwrap_or(0)
}

/// Append the CRC of everything written so far; returns the total length.
fn finish_crc(w: &mut Writer<'_>) -> usize {
    let crc = CRC32.checksum(w.buf.get(..w.pos).unwrap_or(&[]));
    w.put(&crc.to_le_bytes());
    w.pos
}

/// Write one axis block (header, sections, taps).
fn write_axis(w: &mut Writer<'_>, a: &AxisImage) {
    let secs = a.filter.sections();
    let taps = a.filter.fir();
    w.put(&[a.axis, secs.len() as u8, taps.len() as u8, 0]);
    w.put(&a.summary.model_order.to_le_bytes());
    w.put(&[0, 0]);
    let s = &a.scaling;
    for v in [s.adc_offset_code, s.newton_per_code, s.dac_code_per_newton, s.dac_offset_code, a.filter.d()] {
        w.put(&v.to_le_bytes());
    }
    let m = &a.summary;
    for v in [m.fit_nrmse, m.flat_lo_hz, m.flat_hi_hz, m.noise_gain] {
        w.put(&v.to_le_bytes());
    }
    w.put(&m.q.to_le_bytes());
    w.put(&m.r.to_le_bytes());
    for sec in secs {
        for v in sec.delta.iter().chain(&sec.b).chain(&sec.c) {
            w.put(&v.to_le_bytes());
        }
    }
    for h in taps {
        w.put(&h.to_le_bytes());
    }
}

/// Read one axis block that must belong to axis `expected` (checks 12a-12g).
fn read_axis(r: &mut Reader<'_>, expected: u8, bad_len: ImageError) -> Result<AxisImage, ImageError> {
    let axis = r.u8().ok_or(bad_len)?;
    if axis != expected {
        return Err(ImageError::AxisMismatch { expected, found: axis });
    }
    let count = r.u8().ok_or(bad_len)?;
    if usize::from(count) > MAX_SECTIONS {
        return Err(ImageError::TooManySections { axis, count });
    }
    let n_taps = r.u8().ok_or(bad_len)?;
    if usize::from(n_taps) > MAX_FIR {
        return Err(ImageError::TooManyTaps { axis, count: n_taps });
    }
    if r.u8().ok_or(bad_len)? != 0 {
        return Err(ImageError::ReservedNotZero);
    }
    let model_order = r.u16().ok_or(bad_len)?;
    if r.u16().ok_or(bad_len)? != 0 {
        return Err(ImageError::ReservedNotZero);
    }
    let scaling = AxisScaling {
        adc_offset_code: r.f32().ok_or(bad_len)?,
        newton_per_code: r.f32().ok_or(bad_len)?,
        dac_code_per_newton: r.f32().ok_or(bad_len)?,
        dac_offset_code: r.f32().ok_or(bad_len)?,
    };
    let d = r.f32().ok_or(bad_len)?;
    let summary = AxisSummary {
        model_order,
        fit_nrmse: r.f32().ok_or(bad_len)?,
        flat_lo_hz: r.f32().ok_or(bad_len)?,
        flat_hi_hz: r.f32().ok_or(bad_len)?,
        noise_gain: r.f32().ok_or(bad_len)?,
        q: r.f64().ok_or(bad_len)?,
        r: r.f64().ok_or(bad_len)?,
    };
    let mut sections = [Section::default(); MAX_SECTIONS];
    for sec in sections.iter_mut().take(usize::from(count)) {
        let mut v = [0f32; 8];
        for x in v.iter_mut() {
            *x = r.f32().ok_or(bad_len)?;
        }
        *sec = Section { delta: [v[0], v[1], v[2], v[3]], b: [v[4], v[5]], c: [v[6], v[7]] };
    }
    let mut taps = [0f32; MAX_FIR];
    for h in taps.iter_mut().take(usize::from(n_taps)) {
        *h = r.f32().ok_or(bad_len)?;
    }
    let secs = sections.get(..usize::from(count)).unwrap_or(&[]);
    let fir = taps.get(..usize::from(n_taps)).unwrap_or(&[]);
    let filter = AxisFilter::with_fir(secs, d, fir).map_err(|e| match e {
        FilterError::TooManySections => ImageError::TooManySections { axis, count },
        FilterError::NonFinite(s) => {
            ImageError::NonFiniteCoefficient { axis, section: if s >= MAX_SECTIONS { 255 } else { s as u8 } }
        }
        FilterError::Unstable(s) => ImageError::UnstableSection { axis, section: s as u8 },
        FilterError::TooManyTaps => ImageError::TooManyTaps { axis, count: n_taps },
        FilterError::NonFiniteTap(t) => ImageError::NonFiniteTap { axis, tap: t as u8 },
        FilterError::NotModal(s) => ImageError::NotModalSection { axis, section: s as u8 },
    })?;
    Ok(AxisImage { axis, scaling, filter, summary })
}

/// Read the axis blocks of `mask` (x, then y, then z).
fn read_axes(r: &mut Reader<'_>, mask: u8, bad_len: ImageError) -> Result<[Option<AxisImage>; AXES], ImageError> {
    let mut axes: [Option<AxisImage>; AXES] = [None; AXES];
    for (i, slot) in axes.iter_mut().enumerate() {
        if mask & (1 << i) != 0 {
            *slot = Some(read_axis(r, i as u8, bad_len)?);
        }
    }
    Ok(axes)
}

/// Axis mask of an axis array: bit i set when axis i is present.
fn mask_of(axes: &[Option<AxisImage>; AXES]) -> u8 {
    axes.iter().enumerate().filter(|(_, a)| a.is_some()).fold(0, |m, (i, _)| m | (1 << i))
}

/// Header checks shared by both versions (steps 14-16).
fn validate_header(fs_hz: u32, latency_samples: u16, flags: u8) -> Result<(), ImageError> {
    if !FS_RANGE_HZ.contains(&fs_hz) {
        return Err(ImageError::SampleRateOutOfRange(fs_hz));
    }
    if latency_samples > MAX_LATENCY_SAMPLES {
        return Err(ImageError::LatencyOutOfRange(latency_samples));
    }
    if flags & !KNOWN_FLAGS != 0 {
        return Err(ImageError::UnknownFlags(flags));
    }
    Ok(())
}

/// Scaling finite with non-zero gains, then summary finite and ≥ 0
/// (steps 17-18 of version 1; the same for every axis of version 3).
fn validate_channel(axis: u8, s: &AxisScaling, m: &AxisSummary) -> Result<(), ImageError> {
    let finite =
        [s.adc_offset_code, s.newton_per_code, s.dac_code_per_newton, s.dac_offset_code].iter().all(|v| v.is_finite());
    if !finite || s.newton_per_code == 0.0 || s.dac_code_per_newton == 0.0 {
        return Err(ImageError::BadScaling { axis });
    }
    let ok = [m.fit_nrmse, m.flat_lo_hz, m.flat_hi_hz, m.noise_gain].iter().all(|v| v.is_finite() && *v >= 0.0)
        && m.q.is_finite()
        && m.q >= 0.0
        && m.r.is_finite()
        && m.r >= 0.0;
    if !ok {
        return Err(ImageError::BadSummary { axis });
    }
    Ok(())
}

/// Per-axis semantic checks (steps 17-18 plus the repeated structural ones).
fn validate_axes(axes: &[Option<AxisImage>; AXES]) -> Result<(), ImageError> {
    if mask_of(axes) == 0 {
        return Err(ImageError::BadAxisMask(0));
    }
    for (i, a) in axes.iter().enumerate() {
        let Some(a) = a else { continue };
        let axis = i as u8;
        if a.axis != axis {
            return Err(ImageError::AxisMismatch { expected: axis, found: a.axis });
        }
        validate_channel(axis, &a.scaling, &a.summary)?;
        if !a.filter.d().is_finite() {
            return Err(ImageError::NonFiniteCoefficient { axis, section: 255 });
        }
        if let Some(tap) = a.filter.fir().iter().position(|h| !h.is_finite()) {
            return Err(ImageError::NonFiniteTap { axis, tap: tap as u8 });
        }
        for (j, sec) in a.filter.sections().iter().enumerate() {
            let section = j as u8;
            if !sec.is_finite() {
                return Err(ImageError::NonFiniteCoefficient { axis, section });
            }
            if !sec.is_stable() {
                return Err(ImageError::UnstableSection { axis, section });
            }
        }
        validate_filter(axis, &a.filter)?;
    }
    Ok(())
}

/// Whether `v` lies within ±[`MAX_COEFFICIENT`] (false for NaN).
fn in_range(v: f32) -> bool {
    v.abs() <= MAX_COEFFICIENT
}

/// What the design verified, checked again on what will run (steps 19-22
/// of `docs/image-format.md` §8): coefficients bounded, pole margin, ℓ1
/// gain bound and DC gain. The filter's structure (finite, stable, modal)
/// has been checked. Public so that the design applies the same check to
/// every realization it may choose (its errors then name `axis`).
// `!(x <= limit)` on purpose: a NaN bound or gain must fail the check.
#[allow(clippy::neg_cmp_op_on_partial_ord)]
pub fn validate_filter(axis: u8, filter: &AxisFilter) -> Result<(), ImageError> {
    if !in_range(filter.d()) {
        return Err(ImageError::CoefficientOutOfRange { axis, section: 255 });
    }
    if let Some(tap) = filter.fir().iter().position(|h| !in_range(*h)) {
        return Err(ImageError::TapOutOfRange { axis, tap: tap as u8 });
    }
    for (j, sec) in filter.sections().iter().enumerate() {
        let section = j as u8;
        if !sec.delta.iter().chain(&sec.b).chain(&sec.c).all(|v| in_range(*v)) {
            return Err(ImageError::CoefficientOutOfRange { axis, section });
        }
        if !sec.poles_within(1.0 - MIN_POLE_MARGIN) {
            return Err(ImageError::PoleMarginTooSmall { axis, section });
        }
    }
    let bound = filter.gain_bound();
    if !(bound <= MAX_GAIN_BOUND) {
        let rounded = if bound < u32::MAX as f64 { bound as u32 } else { u32::MAX };
        return Err(ImageError::GainBoundTooLarge { axis, bound: rounded });
    }
    if !(filter.dc_gain().abs() <= MAX_DC_GAIN) {
        return Err(ImageError::DcGainOutOfRange { axis });
    }
    Ok(())
}

impl CoeffImage {
    /// Axis mask: bit i set when axis i is present.
    pub fn axis_mask(&self) -> u8 {
        mask_of(&self.axes)
    }

    /// Whether the image is marked offline-only (never run in the box).
    pub fn is_offline_only(&self) -> bool {
        self.flags & FLAG_OFFLINE_ONLY != 0
    }

    /// An identifier of the image's content: its CRC-32.
    pub fn id(&self) -> u32 {
        let mut buf = [0u8; MAX_IMAGE_LEN];
        let n = self.encode(&mut buf);
        stored_crc(&buf, n)
    }

    fn header(&self) -> Header {
        Header {
            fs_hz: self.fs_hz,
            latency_samples: self.latency_samples,
            mask: self.axis_mask(),
            flags: self.flags,
            method_code: self.method as u8,
            extra: [0; 3],
            source_sha256: self.source_sha256,
            created_unix_s: self.created_unix_s,
        }
    }

    /// Encode into `buf`; returns the number of bytes written.
    ///
    /// The image is validated first (the same checks as [`parse`](Self::parse)),
    /// so an encoded image always parses back to an equal value.
    pub fn encode(&self, buf: &mut [u8]) -> Result<usize, ImageError> {
        self.validate()?;
        let len = encoded_len(self);
        if buf.len() < len {
            return Err(ImageError::BufferTooSmall { needed: len as u32 });
        }
        let mut w = Writer { buf, pos: 0 };
        write_header(&mut w, FORMAT_VERSION, len, &self.header());
        for a in self.axes.iter().flatten() {
            write_axis(&mut w, a);
        }
        Ok(finish_crc(&mut w))
    }

    /// Check the semantic rules every image must satisfy.
    fn validate(&self) -> Result<(), ImageError> {
        validate_header(self.fs_hz, self.latency_samples, self.flags)?;
        validate_axes(&self.axes)
    }

    /// Parse and validate an image that occupies exactly `bytes`.
    ///
    /// A parallel-elaboration image (format version 2) is refused with
    /// [`ImageError::ParallelOfflineOnly`]: read it with
    /// [`ParallelImage::parse`].
    pub fn parse(bytes: &[u8]) -> Result<CoeffImage, ImageError> {
        let body = envelope(bytes, FORMAT_VERSION, MIN_IMAGE_LEN, MAX_IMAGE_LEN)?;
        // From here on the bytes are exactly what an encoder wrote; what
        // remains are structural and semantic checks.
        let bad_len = ImageError::BadLength(bytes.len() as u32);
        let mut r = Reader { buf: body, pos: 12 };
        let h = read_header(&mut r, bad_len)?;
        if h.extra != [0; 3] {
            return Err(ImageError::ReservedNotZero);
        }
        if h.mask == 0 || h.mask & !0b111 != 0 {
            return Err(ImageError::BadAxisMask(h.mask));
        }
        let method = DesignMethod::from_u8(h.method_code).ok_or(ImageError::UnknownMethod(h.method_code))?;
        let axes = read_axes(&mut r, h.mask, bad_len)?;
        if r.pos != body.len() {
            return Err(bad_len);
        }
        let image = CoeffImage {
            fs_hz: h.fs_hz,
            latency_samples: h.latency_samples,
            flags: h.flags,
            method,
            source_sha256: h.source_sha256,
            created_unix_s: h.created_unix_s,
            axes,
        };
        image.validate()?;
        Ok(image)
    }

    /// Parse an image stored at the start of a larger region (a flash slot):
    /// the declared length selects the prefix, the rest is ignored.
    ///
    /// A parallel-elaboration image (version 2) gives
    /// [`ImageError::ParallelOfflineOnly`] from its version field alone,
    /// before its length or anything else is read: the box never runs any
    /// part of it.
    pub fn parse_prefix(region: &[u8]) -> Result<CoeffImage, ImageError> {
        parse_prefix_with(region, MIN_IMAGE_LEN, MAX_IMAGE_LEN, Self::parse)
    }
}

/// One band of a parallel-elaboration image: the band's edges and, per axis,
/// the compensator designed for that band (paper §3.3).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BandImage {
    /// Lower edge of the band the compensator was designed for (Hz).
    pub lo_hz: f32,
    /// Upper edge (Hz).
    pub hi_hz: f32,
    /// Per-axis compensator of this band; every band covers the same axes.
    pub axes: [Option<AxisImage>; AXES],
}

/// A parallel-elaboration image (format version 2, paper §3.3): one
/// compensator per band and axis. **Offline only**: `dynocomp compensate`
/// splits a record into the bands with zero-phase filters, runs each band
/// through its own compensator and sums. The box never runs it: the core
/// refuses version 2 in [`CoeffImage::parse`] and
/// [`CoeffImage::parse_prefix`] ([`ImageError::ParallelOfflineOnly`]), and the
/// flag [`FLAG_OFFLINE_ONLY`] is mandatory.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ParallelImage {
    /// Sample rate the filters were designed for (Hz).
    pub fs_hz: u32,
    /// Declared output latency of every band's compensator (samples).
    pub latency_samples: u16,
    /// Flags (`FLAG_*`); always contains [`FLAG_OFFLINE_ONLY`].
    pub flags: u8,
    /// Design method of the band compensators.
    pub method: DesignMethod,
    /// SHA-256 of the FRF file the design came from (zeros if none).
    pub source_sha256: [u8; 32],
    /// Creation time, seconds since the Unix epoch (0 if unknown).
    pub created_unix_s: u64,
    bands: [BandImage; MAX_BANDS],
    n_bands: usize,
}

/// Total length of a parallel image (bytes).
pub fn parallel_encoded_len(image: &ParallelImage) -> usize {
    HEADER_LEN
        + image
            .bands()
            .iter()
            .map(|b| BAND_RECORD_LEN + b.axes.iter().flatten().map(axis_block_len).sum::<usize>())
            .sum::<usize>()
        + CRC_LEN
}

impl ParallelImage {
    /// Build and validate a parallel image from its bands (ascending, not
    /// overlapping, 1..=[`MAX_BANDS`], all with the same axes). The flag
    /// [`FLAG_OFFLINE_ONLY`] is set.
    pub fn new(
        fs_hz: u32,
        latency_samples: u16,
        method: DesignMethod,
        source_sha256: [u8; 32],
        created_unix_s: u64,
        bands: &[BandImage],
    ) -> Result<Self, ImageError> {
        if bands.is_empty() || bands.len() > MAX_BANDS {
            return Err(ImageError::BadBandCount(bands.len().min(255) as u8));
        }
        let empty = BandImage { lo_hz: 0.0, hi_hz: 0.0, axes: [None; AXES] };
        let mut all = [empty; MAX_BANDS];
        for (dst, b) in all.iter_mut().zip(bands) {
            *dst = *b;
        }
        let img = ParallelImage {
            fs_hz,
            latency_samples,
            flags: FLAG_OFFLINE_ONLY,
            method,
            source_sha256,
            created_unix_s,
            bands: all,
            n_bands: bands.len(),
        };
        img.validate()?;
        Ok(img)
    }

    /// The bands, lowest first.
    pub fn bands(&self) -> &[BandImage] {
        self.bands.get(..self.n_bands).unwrap_or(&[])
    }

    /// Axis mask (the same for every band).
    pub fn axis_mask(&self) -> u8 {
        self.bands().first().map(|b| mask_of(&b.axes)).unwrap_or(0)
    }

    /// Band `k` as a stand-alone version-1 image value (with
    /// [`FLAG_OFFLINE_ONLY`] set), e.g. to run it through the same offline
    /// code as any other image.
    pub fn band_image(&self, k: usize) -> Option<CoeffImage> {
        self.bands().get(k).map(|b| CoeffImage {
            fs_hz: self.fs_hz,
            latency_samples: self.latency_samples,
            flags: self.flags | FLAG_OFFLINE_ONLY,
            method: self.method,
            source_sha256: self.source_sha256,
            created_unix_s: self.created_unix_s,
            axes: b.axes,
        })
    }

    /// An identifier of the image's content: its CRC-32.
    pub fn id(&self) -> u32 {
        let mut buf = [0u8; MAX_PARALLEL_IMAGE_LEN];
        let n = self.encode(&mut buf);
        stored_crc(&buf, n)
    }

    fn validate(&self) -> Result<(), ImageError> {
        validate_header(self.fs_hz, self.latency_samples, self.flags)?;
        if self.flags & FLAG_OFFLINE_ONLY == 0 {
            return Err(ImageError::ParallelNotOfflineOnly);
        }
        if self.n_bands == 0 || self.n_bands > MAX_BANDS {
            return Err(ImageError::BadBandCount(self.n_bands.min(255) as u8));
        }
        let mask = self.axis_mask();
        let nyquist = self.fs_hz as f32 / 2.0;
        let mut prev_hi = 0.0f32;
        for (k, b) in self.bands().iter().enumerate() {
            let band = k as u8;
            let edges_ok = b.lo_hz.is_finite()
                && b.hi_hz.is_finite()
                && b.lo_hz >= prev_hi
                && b.hi_hz > b.lo_hz
                && b.hi_hz <= nyquist;
            if !edges_ok {
                return Err(ImageError::BadBand { band });
            }
            prev_hi = b.hi_hz;
            if mask_of(&b.axes) != mask {
                return Err(ImageError::BandAxesDiffer { band });
            }
            validate_axes(&b.axes)?;
        }
        Ok(())
    }

    /// Encode into `buf`; returns the number of bytes written. Validated
    /// first, so an encoded image always parses back to an equal value.
    pub fn encode(&self, buf: &mut [u8]) -> Result<usize, ImageError> {
        self.validate()?;
        let len = parallel_encoded_len(self);
        if buf.len() < len {
            return Err(ImageError::BufferTooSmall { needed: len as u32 });
        }
        let mut w = Writer { buf, pos: 0 };
        let h = Header {
            fs_hz: self.fs_hz,
            latency_samples: self.latency_samples,
            mask: self.axis_mask(),
            flags: self.flags,
            method_code: self.method as u8,
            extra: [self.n_bands as u8, 0, 0],
            source_sha256: self.source_sha256,
            created_unix_s: self.created_unix_s,
        };
        write_header(&mut w, PARALLEL_FORMAT_VERSION, len, &h);
        for b in self.bands() {
            w.put(&b.lo_hz.to_le_bytes());
            w.put(&b.hi_hz.to_le_bytes());
        }
        for b in self.bands() {
            for a in b.axes.iter().flatten() {
                write_axis(&mut w, a);
            }
        }
        Ok(finish_crc(&mut w))
    }

    /// Parse and validate a parallel image that occupies exactly `bytes`
    /// (`docs/image-format.md` §12). Never panics.
    pub fn parse(bytes: &[u8]) -> Result<ParallelImage, ImageError> {
        let body = envelope(bytes, PARALLEL_FORMAT_VERSION, MIN_IMAGE_LEN, MAX_PARALLEL_IMAGE_LEN)?;
        let bad_len = ImageError::BadLength(bytes.len() as u32);
        let mut r = Reader { buf: body, pos: 12 };
        let h = read_header(&mut r, bad_len)?;
        let n_bands = usize::from(h.extra[0]);
        if h.extra[1..] != [0, 0] {
            return Err(ImageError::ReservedNotZero);
        }
        if n_bands == 0 || n_bands > MAX_BANDS {
            return Err(ImageError::BadBandCount(h.extra[0]));
        }
        if h.mask == 0 || h.mask & !0b111 != 0 {
            return Err(ImageError::BadAxisMask(h.mask));
        }
        let method = DesignMethod::from_u8(h.method_code).ok_or(ImageError::UnknownMethod(h.method_code))?;
        let empty = BandImage { lo_hz: 0.0, hi_hz: 0.0, axes: [None; AXES] };
        let mut bands = [empty; MAX_BANDS];
        for b in bands.iter_mut().take(n_bands) {
            b.lo_hz = r.f32().ok_or(bad_len)?;
            b.hi_hz = r.f32().ok_or(bad_len)?;
        }
        for b in bands.iter_mut().take(n_bands) {
            b.axes = read_axes(&mut r, h.mask, bad_len)?;
        }
        if r.pos != body.len() {
            return Err(bad_len);
        }
        let image = ParallelImage {
            fs_hz: h.fs_hz,
            latency_samples: h.latency_samples,
            flags: h.flags,
            method,
            source_sha256: h.source_sha256,
            created_unix_s: h.created_unix_s,
            bands,
            n_bands,
        };
        image.validate()?;
        Ok(image)
    }
}

/// [`CoeffImage::parse_prefix`] and [`MatrixImage::parse_prefix`]: an image
/// of `min_len..=max_len` bytes at the start of `region`, read by `parse`.
fn parse_prefix_with<T>(
    region: &[u8],
    min_len: usize,
    max_len: usize,
    parse: impl Fn(&[u8]) -> Result<T, ImageError>,
) -> Result<T, ImageError> {
    let have = region.len() as u32;
    if region.len() < MIN_IMAGE_LEN {
        return Err(ImageError::Truncated { needed: MIN_IMAGE_LEN as u32, have });
    }
    if region.get(..4) != Some(&MAGIC[..]) {
        return Err(ImageError::BadMagic);
    }
    let len = declared_len(region).unwrap_or(0);
    if !(min_len..=max_len).contains(&len) {
        // Let `parse` report version/header problems first.
        return parse(region.get(..MIN_IMAGE_LEN).unwrap_or(region)).and(Err(ImageError::BadLength(len as u32)));
    }
    match region.get(..len) {
        Some(prefix) => parse(prefix),
        None => Err(ImageError::Truncated { needed: len as u32, have }),
    }
}

// ---------------------------------------------------- version 3: the 3x3 --

/// How one output row of a 3x3 image was designed (its byte in the row
/// record). It tells `inspect` and the status what the row compensates; the
/// filter runs the same either way.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum RowDesign {
    /// Code 0: designed per axis, from the direct FRF alone (crosstalk not
    /// compensated on this axis; the 3x3 design predicted no gain here).
    PerAxis = 0,
    /// Code 1: designed on the 3x3 model (crosstalk compensated).
    Matrix = 1,
}

impl RowDesign {
    fn from_u8(v: u8) -> Option<Self> {
        match v {
            0 => Some(Self::PerAxis),
            1 => Some(Self::Matrix),
            _ => None,
        }
    }
}

/// One axis of a 3x3 image: its converters' scaling and the design summary
/// of its output row. The filter is shared ([`MatrixImage::filter`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AxisChannel {
    /// Axis index (0 = x, 1 = y, 2 = z); must equal its position.
    pub axis: u8,
    /// Code ↔ newton conversion of this axis's ADC input and DAC output.
    pub scaling: AxisScaling,
    /// Design summary of this axis's output row.
    pub summary: AxisSummary,
}

/// A decoded, validated 3x3 image (format version 3): one 3-input,
/// 3-output compensator whose modes are shared by the three force
/// estimates, and the three axes' scaling. Always covers x, y and z.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MatrixImage {
    /// Sample rate the filter was designed for (Hz).
    pub fs_hz: u32,
    /// Declared output latency of the compensated forces (samples).
    pub latency_samples: u16,
    /// Flags (`FLAG_*`).
    pub flags: u8,
    /// Design method.
    pub method: DesignMethod,
    /// SHA-256 of the FRF file the design came from (zeros if none).
    pub source_sha256: [u8; 32],
    /// Creation time, seconds since the Unix epoch (0 if unknown).
    pub created_unix_s: u64,
    /// Scaling and design summary of x, y, z.
    pub axes: [AxisChannel; MIMO_AXES],
    /// The 3x3 compensator (N → N).
    pub filter: MimoFilter,
    /// How each output row was designed.
    pub rows: [RowDesign; MIMO_AXES],
}

/// Total length of a 3x3 image (bytes).
pub fn matrix_encoded_len(image: &MatrixImage) -> usize {
    MIN_MATRIX_IMAGE_LEN + image.filter.sections().len() * MIMO_SECTION_LEN + image.filter.fir().len() * MIMO_TAP_LEN
}

/// Write the 56-byte axis block of a 3x3 image.
fn write_channel(w: &mut Writer<'_>, a: &AxisChannel) {
    w.put(&[a.axis, 0, 0, 0]);
    w.put(&a.summary.model_order.to_le_bytes());
    w.put(&[0, 0]);
    let s = &a.scaling;
    let m = &a.summary;
    for v in [s.adc_offset_code, s.newton_per_code, s.dac_code_per_newton, s.dac_offset_code] {
        w.put(&v.to_le_bytes());
    }
    for v in [m.fit_nrmse, m.flat_lo_hz, m.flat_hi_hz, m.noise_gain] {
        w.put(&v.to_le_bytes());
    }
    w.put(&m.q.to_le_bytes());
    w.put(&m.r.to_le_bytes());
}

/// Read the axis block of a 3x3 image that must belong to axis `expected`.
fn read_channel(r: &mut Reader<'_>, expected: u8, bad_len: ImageError) -> Result<AxisChannel, ImageError> {
    let axis = r.u8().ok_or(bad_len)?;
    if axis != expected {
        return Err(ImageError::AxisMismatch { expected, found: axis });
    }
    if r.bytes::<3>().ok_or(bad_len)? != [0; 3] {
        return Err(ImageError::ReservedNotZero);
    }
    let model_order = r.u16().ok_or(bad_len)?;
    if r.u16().ok_or(bad_len)? != 0 {
        return Err(ImageError::ReservedNotZero);
    }
    let scaling = AxisScaling {
        adc_offset_code: r.f32().ok_or(bad_len)?,
        newton_per_code: r.f32().ok_or(bad_len)?,
        dac_code_per_newton: r.f32().ok_or(bad_len)?,
        dac_offset_code: r.f32().ok_or(bad_len)?,
    };
    let summary = AxisSummary {
        model_order,
        fit_nrmse: r.f32().ok_or(bad_len)?,
        flat_lo_hz: r.f32().ok_or(bad_len)?,
        flat_hi_hz: r.f32().ok_or(bad_len)?,
        noise_gain: r.f32().ok_or(bad_len)?,
        q: r.f64().ok_or(bad_len)?,
        r: r.f64().ok_or(bad_len)?,
    };
    Ok(AxisChannel { axis, scaling, summary })
}

/// `N` f32 values in a row.
fn read_f32s<const N: usize>(r: &mut Reader<'_>, bad_len: ImageError) -> Result<[f32; N], ImageError> {
    let mut v = [0f32; N];
    for x in v.iter_mut() {
        *x = r.f32().ok_or(bad_len)?;
    }
    Ok(v)
}

/// A 3x3 matrix stored row-major.
fn read_matrix3(r: &mut Reader<'_>, bad_len: ImageError) -> Result<Matrix3, ImageError> {
    let v = read_f32s::<9>(r, bad_len)?;
    Ok([[v[0], v[1], v[2]], [v[3], v[4], v[5]], [v[6], v[7], v[8]]])
}

/// What the design verified, checked again on the 3x3 filter that will run
/// (steps 18-22 of `docs/image-format.md` §13.5): coefficients bounded,
/// pole margin, ℓ1 gain bound per output row, DC gain rows near the
/// identity. The structure (finite, stable, modal) holds for every
/// [`MimoFilter`].
///
/// Public so that the design holds every whole filter it may choose to the
/// same check before an image is built from it.
// `!(x <= limit)` on purpose: a NaN bound or gain must fail the check.
#[allow(clippy::neg_cmp_op_on_partial_ord)]
pub fn validate_mimo(filter: &MimoFilter) -> Result<(), ImageError> {
    if !filter.d().iter().flatten().all(|v| in_range(*v)) {
        return Err(ImageError::MatrixCoefficientOutOfRange { section: 255 });
    }
    if let Some(tap) = filter.fir().iter().position(|h| !h.iter().flatten().all(|v| in_range(*v))) {
        return Err(ImageError::MatrixTapOutOfRange { tap: tap as u8 });
    }
    for (j, s) in filter.sections().iter().enumerate() {
        let section = j as u8;
        if !s.delta.iter().chain(s.b.iter().flatten()).chain(s.c.iter().flatten()).all(|v| in_range(*v)) {
            return Err(ImageError::MatrixCoefficientOutOfRange { section });
        }
        if !s.block().poles_within(1.0 - MIN_POLE_MARGIN) {
            return Err(ImageError::MatrixPoleMarginTooSmall { section });
        }
    }
    for row in 0..MIMO_AXES {
        let bound = filter.row_gain_bound(row);
        if !(bound <= MAX_GAIN_BOUND) {
            let rounded = if bound < u32::MAX as f64 { bound as u32 } else { u32::MAX };
            return Err(ImageError::MatrixGainBoundTooLarge { row: row as u8, bound: rounded });
        }
    }
    for (i, g) in filter.dc_gain().iter().enumerate() {
        let deviation: f64 = g.iter().enumerate().map(|(j, v)| (v - if i == j { 1.0 } else { 0.0 }).abs()).sum();
        if !(deviation <= MAX_DC_ROW_DEVIATION) {
            return Err(ImageError::MatrixDcGainOutOfRange { row: i as u8 });
        }
    }
    Ok(())
}

impl MatrixImage {
    /// Whether the image is marked offline-only (never run in the box).
    pub fn is_offline_only(&self) -> bool {
        self.flags & FLAG_OFFLINE_ONLY != 0
    }

    /// An identifier of the image's content: its CRC-32.
    pub fn id(&self) -> u32 {
        let mut buf = [0u8; MAX_MATRIX_IMAGE_LEN];
        let n = self.encode(&mut buf);
        stored_crc(&buf, n)
    }

    /// Check the semantic rules every 3x3 image must satisfy (steps 16-22
    /// of `docs/image-format.md` §13.5).
    fn validate(&self) -> Result<(), ImageError> {
        validate_header(self.fs_hz, self.latency_samples, self.flags)?;
        for (i, a) in self.axes.iter().enumerate() {
            let axis = i as u8;
            if a.axis != axis {
                return Err(ImageError::AxisMismatch { expected: axis, found: a.axis });
            }
            validate_channel(axis, &a.scaling, &a.summary)?;
        }
        validate_mimo(&self.filter)
    }

    /// Encode into `buf`; returns the number of bytes written. Validated
    /// first, so an encoded image always parses back to an equal value.
    pub fn encode(&self, buf: &mut [u8]) -> Result<usize, ImageError> {
        self.validate()?;
        let len = matrix_encoded_len(self);
        if buf.len() < len {
            return Err(ImageError::BufferTooSmall { needed: len as u32 });
        }
        let mut w = Writer { buf, pos: 0 };
        let h = Header {
            fs_hz: self.fs_hz,
            latency_samples: self.latency_samples,
            mask: 0b111,
            flags: self.flags,
            method_code: self.method as u8,
            extra: [0; 3],
            source_sha256: self.source_sha256,
            created_unix_s: self.created_unix_s,
        };
        write_header(&mut w, MATRIX_FORMAT_VERSION, len, &h);
        for a in &self.axes {
            write_channel(&mut w, a);
        }
        let f = &self.filter;
        w.put(&[f.sections().len() as u8, f.fir().len() as u8, 0, 0]);
        for v in f.d().iter().flatten() {
            w.put(&v.to_le_bytes());
        }
        for s in f.sections() {
            for v in s.delta.iter().chain(s.b.iter().flatten()).chain(s.c.iter().flatten()) {
                w.put(&v.to_le_bytes());
            }
        }
        for v in f.fir().iter().flatten().flatten() {
            w.put(&v.to_le_bytes());
        }
        w.put(&[self.rows[0] as u8, self.rows[1] as u8, self.rows[2] as u8, 0]);
        Ok(finish_crc(&mut w))
    }

    /// Parse and validate a 3x3 image that occupies exactly `bytes`
    /// (`docs/image-format.md` §13). Never panics.
    pub fn parse(bytes: &[u8]) -> Result<MatrixImage, ImageError> {
        let body = envelope(bytes, MATRIX_FORMAT_VERSION, MIN_MATRIX_IMAGE_LEN, MAX_MATRIX_IMAGE_LEN)?;
        let bad_len = ImageError::BadLength(bytes.len() as u32);
        let mut r = Reader { buf: body, pos: 12 };
        let h = read_header(&mut r, bad_len)?;
        if h.extra != [0; 3] {
            return Err(ImageError::ReservedNotZero);
        }
        if h.mask != 0b111 {
            return Err(ImageError::BadAxisMask(h.mask));
        }
        let method = DesignMethod::from_u8(h.method_code).ok_or(ImageError::UnknownMethod(h.method_code))?;
        let axes =
            [read_channel(&mut r, 0, bad_len)?, read_channel(&mut r, 1, bad_len)?, read_channel(&mut r, 2, bad_len)?];
        let n_sections = r.u8().ok_or(bad_len)?;
        if usize::from(n_sections) > MAX_MIMO_SECTIONS {
            return Err(ImageError::MatrixTooManySections(n_sections));
        }
        let n_taps = r.u8().ok_or(bad_len)?;
        if usize::from(n_taps) > MAX_MIMO_FIR {
            return Err(ImageError::MatrixTooManyTaps(n_taps));
        }
        if r.u16().ok_or(bad_len)? != 0 {
            return Err(ImageError::ReservedNotZero);
        }
        let d = read_matrix3(&mut r, bad_len)?;
        let mut sections = [MimoSection::default(); MAX_MIMO_SECTIONS];
        for s in sections.iter_mut().take(usize::from(n_sections)) {
            let v = read_f32s::<16>(&mut r, bad_len)?;
            *s = MimoSection {
                delta: [v[0], v[1], v[2], v[3]],
                b: [[v[4], v[5], v[6]], [v[7], v[8], v[9]]],
                c: [[v[10], v[11]], [v[12], v[13]], [v[14], v[15]]],
            };
        }
        let mut taps = [[[0f32; MIMO_AXES]; MIMO_AXES]; MAX_MIMO_FIR];
        for h in taps.iter_mut().take(usize::from(n_taps)) {
            *h = read_matrix3(&mut r, bad_len)?;
        }
        let record = r.bytes::<ROW_RECORD_LEN>().ok_or(bad_len)?;
        let mut rows = [RowDesign::PerAxis; MIMO_AXES];
        for (row, (dst, &code)) in rows.iter_mut().zip(&record).enumerate() {
            *dst = RowDesign::from_u8(code).ok_or(ImageError::BadRowDesign { row: row as u8, code })?;
        }
        if record[3] != 0 {
            return Err(ImageError::ReservedNotZero);
        }
        if r.pos != body.len() {
            return Err(bad_len);
        }
        let secs = sections.get(..usize::from(n_sections)).unwrap_or(&[]);
        let fir = taps.get(..usize::from(n_taps)).unwrap_or(&[]);
        let filter = MimoFilter::new(secs, d, fir).map_err(|e| match e {
            FilterError::TooManySections => ImageError::MatrixTooManySections(n_sections),
            FilterError::TooManyTaps => ImageError::MatrixTooManyTaps(n_taps),
            FilterError::NonFinite(s) => {
                ImageError::MatrixNonFinite { section: if s >= MAX_MIMO_SECTIONS { 255 } else { s as u8 } }
            }
            FilterError::NonFiniteTap(t) => ImageError::MatrixNonFiniteTap { tap: t as u8 },
            FilterError::Unstable(s) => ImageError::MatrixUnstableSection { section: s as u8 },
            FilterError::NotModal(s) => ImageError::MatrixNotModalSection { section: s as u8 },
        })?;
        let image = MatrixImage {
            fs_hz: h.fs_hz,
            latency_samples: h.latency_samples,
            flags: h.flags,
            method,
            source_sha256: h.source_sha256,
            created_unix_s: h.created_unix_s,
            axes,
            filter,
            rows,
        };
        image.validate()?;
        Ok(image)
    }

    /// Parse a 3x3 image stored at the start of a larger region (a flash
    /// slot): the declared length selects the prefix, the rest is ignored.
    pub fn parse_prefix(region: &[u8]) -> Result<MatrixImage, ImageError> {
        parse_prefix_with(region, MIN_MATRIX_IMAGE_LEN, MAX_MATRIX_IMAGE_LEN, Self::parse)
    }
}

// ------------------------------------------------- what the box runs --

/// An image the box runs: per-axis (version 1) or 3x3 (version 3). The
/// store, the sample path, the status and the host match on it.
// The variants are the same size within 5 % (≈ 4 KiB each).
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum BoxImage {
    /// One compensator per axis (format version 1).
    PerAxis(CoeffImage),
    /// One 3x3 compensator (format version 3).
    Matrix(MatrixImage),
}

impl From<CoeffImage> for BoxImage {
    fn from(i: CoeffImage) -> Self {
        BoxImage::PerAxis(i)
    }
}

impl From<MatrixImage> for BoxImage {
    fn from(i: MatrixImage) -> Self {
        BoxImage::Matrix(i)
    }
}

/// A borrowed image the box runs, for what reads either version (the cost
/// model): `From` a `&CoeffImage`, `&MatrixImage` or `&BoxImage`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ImageRef<'a> {
    /// A per-axis image (version 1).
    PerAxis(&'a CoeffImage),
    /// A 3x3 image (version 3).
    Matrix(&'a MatrixImage),
}

impl<'a> From<&'a CoeffImage> for ImageRef<'a> {
    fn from(i: &'a CoeffImage) -> Self {
        ImageRef::PerAxis(i)
    }
}

impl<'a> From<&'a MatrixImage> for ImageRef<'a> {
    fn from(i: &'a MatrixImage) -> Self {
        ImageRef::Matrix(i)
    }
}

impl<'a> From<&'a BoxImage> for ImageRef<'a> {
    fn from(i: &'a BoxImage) -> Self {
        match i {
            BoxImage::PerAxis(p) => ImageRef::PerAxis(p),
            BoxImage::Matrix(m) => ImageRef::Matrix(m),
        }
    }
}

impl ImageRef<'_> {
    /// Sample rate (Hz).
    pub fn fs_hz(&self) -> u32 {
        match self {
            ImageRef::PerAxis(i) => i.fs_hz,
            ImageRef::Matrix(m) => m.fs_hz,
        }
    }
}

impl BoxImage {
    /// Parse and validate an image that occupies exactly `bytes`: version 3
    /// as [`MatrixImage`], anything else as [`CoeffImage::parse`] does
    /// (version 1; version 2 gives [`ImageError::ParallelOfflineOnly`]).
    pub fn parse(bytes: &[u8]) -> Result<BoxImage, ImageError> {
        if peek_version(bytes) == Some(MATRIX_FORMAT_VERSION) {
            MatrixImage::parse(bytes).map(BoxImage::Matrix)
        } else {
            CoeffImage::parse(bytes).map(BoxImage::PerAxis)
        }
    }

    /// Parse an image at the start of a larger region (a flash slot), as
    /// [`CoeffImage::parse_prefix`] / [`MatrixImage::parse_prefix`].
    pub fn parse_prefix(region: &[u8]) -> Result<BoxImage, ImageError> {
        if peek_version(region) == Some(MATRIX_FORMAT_VERSION) {
            MatrixImage::parse_prefix(region).map(BoxImage::Matrix)
        } else {
            CoeffImage::parse_prefix(region).map(BoxImage::PerAxis)
        }
    }

    /// Encode into `buf` (at most [`MAX_BOX_IMAGE_LEN`] bytes); returns the
    /// number of bytes written.
    pub fn encode(&self, buf: &mut [u8]) -> Result<usize, ImageError> {
        match self {
            BoxImage::PerAxis(i) => i.encode(buf),
            BoxImage::Matrix(m) => m.encode(buf),
        }
    }

    /// An identifier of the image's content: its CRC-32.
    pub fn id(&self) -> u32 {
        match self {
            BoxImage::PerAxis(i) => i.id(),
            BoxImage::Matrix(m) => m.id(),
        }
    }

    /// The format version (1 or 3).
    pub fn format_version(&self) -> u16 {
        match self {
            BoxImage::PerAxis(_) => FORMAT_VERSION,
            BoxImage::Matrix(_) => MATRIX_FORMAT_VERSION,
        }
    }

    /// Sample rate the filters were designed for (Hz).
    pub fn fs_hz(&self) -> u32 {
        ImageRef::from(self).fs_hz()
    }

    /// Declared output latency (samples).
    pub fn latency_samples(&self) -> u16 {
        match self {
            BoxImage::PerAxis(i) => i.latency_samples,
            BoxImage::Matrix(m) => m.latency_samples,
        }
    }

    /// Design method.
    pub fn method(&self) -> DesignMethod {
        match self {
            BoxImage::PerAxis(i) => i.method,
            BoxImage::Matrix(m) => m.method,
        }
    }

    /// Whether the image is marked offline-only (never run in the box).
    pub fn is_offline_only(&self) -> bool {
        match self {
            BoxImage::PerAxis(i) => i.is_offline_only(),
            BoxImage::Matrix(m) => m.is_offline_only(),
        }
    }

    /// Scaling of each axis (`None` for an axis a per-axis image does not
    /// cover).
    pub fn scaling(&self) -> [Option<AxisScaling>; AXES] {
        match self {
            BoxImage::PerAxis(i) => i.axes.map(|a| a.map(|a| a.scaling)),
            BoxImage::Matrix(m) => m.axes.map(|a| Some(a.scaling)),
        }
    }

    /// Design summary of each axis (output row).
    pub fn summaries(&self) -> [Option<AxisSummary>; AXES] {
        match self {
            BoxImage::PerAxis(i) => i.axes.map(|a| a.map(|a| a.summary)),
            BoxImage::Matrix(m) => m.axes.map(|a| Some(a.summary)),
        }
    }

    /// How each output row was designed: `None` for a per-axis image.
    pub fn rows(&self) -> Option<[RowDesign; AXES]> {
        match self {
            BoxImage::PerAxis(_) => None,
            BoxImage::Matrix(m) => Some(m.rows),
        }
    }

    /// Set the ADC offset (code of 0 N) of every axis the image covers;
    /// returns the mask of axes changed (bit i = axis i). Inlined: the
    /// sample interrupt calls it (auto-zero), and its code must stay in
    /// CCM SRAM with the interrupt.
    #[inline(always)]
    pub fn set_adc_offsets(&mut self, offsets: [f32; AXES]) -> u8 {
        let mut mask = 0u8;
        match self {
            BoxImage::PerAxis(img) => {
                for (i, (axis, &off)) in img.axes.iter_mut().zip(offsets.iter()).enumerate() {
                    if let Some(a) = axis {
                        a.scaling.adc_offset_code = off;
                        mask |= 1 << i;
                    }
                }
            }
            BoxImage::Matrix(m) => {
                for (i, (a, &off)) in m.axes.iter_mut().zip(offsets.iter()).enumerate() {
                    a.scaling.adc_offset_code = off;
                    mask |= 1 << i;
                }
            }
        }
        mask
    }
}
