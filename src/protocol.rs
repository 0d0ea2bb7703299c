//! The USB CDC protocol between the host (`dynocomp flash --serial`,
//! `dynocomp stream`) and the box: message types and framing, shared by both
//! sides. The byte-level specification is `docs/protocol.md`.
//!
//! # Frame
//!
//! `COBS( postcard(message) ‖ CRC-32(postcard(message)) as LE u32 ) ‖ 0x00`
//!
//! * postcard: compact serde encoding (varints), no allocation.
//! * CRC-32/ISO-HDLC ([`crate::image::CRC32`]) over the postcard bytes.
//! * COBS removes every 0x00 from the body, so 0x00 delimits frames and a
//!   receiver resynchronises at the next 0x00 after garbage or a lost byte.
//! * A decoded body is at most [`MAX_PAYLOAD`] bytes (message + CRC); an
//!   encoded frame at most [`MAX_FRAME`] bytes including the delimiter.
//!
//! Host → box: [`RequestFrame`] (a request id chosen by the host and a
//! [`Request`]). Box → host: [`BoxMessage`]: either a [`BoxMessage::Reply`]
//! echoing the request id (0 when the request could not be decoded) or an
//! unsolicited [`BoxMessage::Stream`] frame with its own sequence number.
//!
//! # How the firmware calls this (API note for the box)
//!
//! * **USB task only** (thread mode, embassy task that owns the CDC class):
//!   feed every received USB packet into a [`FrameDecoder`] with
//!   [`FrameDecoder::push`]; each complete frame (or framing error) goes to
//!   [`crate::link::BoxLink::on_frame`], which returns the [`BoxMessage`] to
//!   send; encode it with [`encode_frame`] into a `[u8; MAX_FRAME]` and write
//!   it to the CDC class (in 64-byte packets). Stream frames are built by
//!   [`StreamBatcher`] in the same task from samples the interrupt queued.
//! * **Sample interrupt:** nothing in this module. The interrupt only pushes
//!   [`StreamSample`]s into a lock-free single-producer queue
//!   ([`crate::stream_queue`]) when streaming is on, and never blocks on USB; a full
//!   queue drops the sample (the host sees the gap in
//!   [`StreamFrame::first_sample`]).
//!
//! Nothing here panics on any input, allocates, or uses `unsafe`.

use serde::{Deserialize, Serialize};

use crate::image::{DesignMethod, ImageError, RowDesign, CRC32};
use crate::sample::BypassReason;
use crate::shell::Slot;
use crate::AXES;

/// Protocol version carried in [`Status::protocol`]; bumped on any
/// incompatible change of the message types.
///
/// * 1: first version.
/// * 2: [`Status::core_clock_hz`] and the sample interrupt's cycle counts
///   in [`StatusCounters`] (`isr_cycles_last`, `isr_cycles_max`,
///   `isr_cycles_mean`).
/// * 3: [`ImageSummary::rows`] (a 3x3 image, format version 3, and how each
///   of its output rows was designed); new [`ImageError`] variants of the
///   3x3 image at the end of the enum.
pub const PROTOCOL_VERSION: u16 = 3;
/// Largest decoded frame body: postcard message + 4-byte CRC.
pub const MAX_PAYLOAD: usize = 320;
/// Largest encoded frame: COBS overhead + the 0x00 delimiter.
pub const MAX_FRAME: usize = cobs::max_encoding_length(MAX_PAYLOAD) + 1;
/// Largest data field of one [`Request::UploadChunk`], bytes.
pub const MAX_CHUNK: usize = 128;
/// Samples per [`StreamFrame`].
pub const STREAM_BATCH: usize = 8;
/// CRC trailer length.
const CRC_BYTES: usize = 4;

/// A request from the host, with the host's request id (echoed in the reply).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct RequestFrame<'a> {
    /// Request id chosen by the host (any value; the host uses 1, 2, …).
    pub id: u16,
    /// The request.
    #[serde(borrow)]
    pub request: Request<'a>,
}

/// Host → box requests.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Request<'a> {
    /// Reply with [`Reply::Status`].
    GetStatus,
    /// Force bypass on (`true`) or release the user bypass (`false`).
    SetBypass(bool),
    /// Start streaming every `decimation`-th sample (1 = all; 0 is refused).
    StartStream {
        /// Keep one sample out of `decimation`.
        decimation: u16,
    },
    /// Stop streaming.
    StopStream,
    /// Start an upload of an image of `len` bytes whose CRC-32/ISO-HDLC is
    /// `crc`; erases the inactive slot.
    UploadBegin {
        /// Image length, bytes.
        len: u32,
        /// CRC-32/ISO-HDLC of the whole image.
        crc: u32,
    },
    /// Image bytes at `offset`. Chunks must arrive in order (`offset` = bytes
    /// received so far); at most [`MAX_CHUNK`] bytes.
    UploadChunk {
        /// Offset of the first byte in the image.
        offset: u32,
        /// The bytes.
        #[serde(borrow)]
        bytes: &'a [u8],
    },
    /// Verify the uploaded image and, if it is valid and runnable, make it
    /// the active slot and switch the sample path to it.
    UploadCommit,
    /// Measure the ADC offset of each axis at zero force; the sample path
    /// then uses it as the code of 0 N (`shell::AutoZero`).
    AutoZero,
}

/// Box → host messages.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum BoxMessage {
    /// Reply to the request with this id (0 if the request was unreadable).
    Reply {
        /// Request id being answered.
        id: u16,
        /// The reply.
        reply: Reply,
    },
    /// A batch of streamed samples.
    Stream(StreamFrame),
}

/// Reply to one request.
// The box has no heap to box the status in, and a reply lives only until it
// is encoded into its frame: the size difference costs a few stack bytes.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum Reply {
    /// Request done.
    Ack,
    /// Status of the box.
    Status(Status),
    /// The request was refused or failed; the box state is unchanged except
    /// as documented for the error.
    Error(LinkError),
}

/// Why a request failed (the `Error` reply).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum LinkError {
    /// The frame failed to decode (framing layer).
    Frame(FrameError),
    /// The frame decoded but is not a valid message.
    Malformed,
    /// A request that makes no sense now (e.g. a chunk without an upload).
    NoUpload,
    /// `StartStream { decimation: 0 }`.
    BadDecimation,
    /// Declared upload length is 0 or larger than the slot's image area.
    UploadTooLarge {
        /// Declared length.
        len: u32,
        /// Largest accepted length.
        max: u32,
    },
    /// A chunk did not start where the previous one ended (nothing written).
    OutOfOrder {
        /// Offset the box expects next.
        expected: u32,
        /// Offset received.
        got: u32,
    },
    /// A chunk reaches past the declared length, or is larger than
    /// [`MAX_CHUNK`] (nothing written).
    ChunkTooLong {
        /// Declared image length.
        len: u32,
    },
    /// Commit before all bytes arrived.
    Incomplete {
        /// Bytes received.
        received: u32,
        /// Declared length.
        len: u32,
    },
    /// The bytes read back from flash do not have the declared CRC.
    CrcMismatch {
        /// CRC declared in `UploadBegin`.
        declared: u32,
        /// CRC of the bytes read back.
        computed: u32,
    },
    /// The image does not parse (version, ranges, stability, …).
    Image(ImageError),
    /// The image is valid but the box cannot run it (offline-only, or its
    /// sample rate is outside the box's range).
    NotRunnable(BypassReason),
    /// The flash driver failed.
    Flash(FlashFault),
    /// The upload was abandoned by a new `UploadBegin` or failed earlier;
    /// start again.
    UploadAborted,
}

/// Flash driver failure classes (`embedded_storage::nor_flash::NorFlashErrorKind`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FlashFault {
    /// Offset or length not aligned to the flash's granularity.
    NotAligned,
    /// Outside the flash.
    OutOfBounds,
    /// Any other driver error.
    Other,
    /// Bytes read back differ from the bytes written.
    Verify,
}

/// Framing-layer failures ([`FrameDecoder`], [`decode_frame`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FrameError {
    /// The bytes between two delimiters are not valid COBS.
    Cobs,
    /// The frame is longer than [`MAX_FRAME`]; its bytes were discarded up
    /// to the next delimiter.
    Oversized,
    /// The decoded body is too short to hold a CRC.
    Truncated,
    /// CRC mismatch.
    BadCrc,
    /// The message does not fit [`MAX_PAYLOAD`] (encoding only).
    TooLarge,
}

impl core::fmt::Display for FrameError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            FrameError::Cobs => "frame is not valid COBS",
            FrameError::Oversized => "frame longer than the largest frame, discarded",
            FrameError::Truncated => "frame too short to hold its CRC",
            FrameError::BadCrc => "frame CRC mismatch (corrupted on the link)",
            FrameError::TooLarge => "message too large for one frame",
        })
    }
}

impl core::fmt::Display for FlashFault {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            FlashFault::NotAligned => "flash access not aligned to the flash's granularity",
            FlashFault::OutOfBounds => "flash access outside the flash",
            FlashFault::Other => "flash driver error",
            FlashFault::Verify => "flash read-back differs from what was written",
        })
    }
}

impl core::fmt::Display for LinkError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            LinkError::Frame(e) => write!(f, "the box could not read the frame: {e}"),
            LinkError::Malformed => f.write_str("the box could not decode the message (protocol version mismatch?)"),
            LinkError::NoUpload => f.write_str("no upload in progress"),
            LinkError::BadDecimation => f.write_str("stream decimation must be at least 1"),
            LinkError::UploadTooLarge { len, max } => {
                write!(f, "image of {len} bytes does not fit a slot (at most {max})")
            }
            LinkError::OutOfOrder { expected, got } => {
                write!(f, "upload chunk at offset {got}, the box expected {expected}")
            }
            LinkError::ChunkTooLong { len } => {
                write!(f, "upload chunk reaches past the declared length {len} or is too long")
            }
            LinkError::Incomplete { received, len } => write!(f, "commit after {received} of {len} bytes"),
            LinkError::CrcMismatch { declared, computed } => {
                write!(f, "image corrupted in transfer: CRC {computed:#010x} read back, {declared:#010x} declared")
            }
            LinkError::Image(e) => write!(f, "invalid image: {e}"),
            LinkError::NotRunnable(r) => write!(f, "the box cannot run this image: {r}"),
            LinkError::Flash(e) => write!(f, "flash write failed: {e}"),
            LinkError::UploadAborted => f.write_str("the upload was aborted; start again"),
        }
    }
}

/// Box state for the host (`GetStatus`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Status {
    /// [`PROTOCOL_VERSION`] of the firmware.
    pub protocol: u16,
    /// Firmware version (major, minor, patch).
    pub firmware: [u8; 3],
    /// Sample rate the sample path runs at, Hz.
    pub fs_hz: u32,
    /// CPU core clock, Hz: the unit of the `isr_cycles_*` counters
    /// (a sample period is `core_clock_hz / fs_hz` cycles). 0 = unknown
    /// (the virtual box).
    pub core_clock_hz: u32,
    /// `None` when compensating, else why the box is in bypass.
    pub bypass: Option<BypassReason>,
    /// The store's active slot and its sequence number (None: no valid slot).
    pub active: Option<SlotInfo>,
    /// The image the sample path runs (None in bypass without an image).
    pub image: Option<ImageSummary>,
    /// Sample-path counters.
    pub counters: StatusCounters,
    /// Whether streaming is on, and its decimation.
    pub stream_decimation: Option<u16>,
    /// Sequence number the next stream frame will get: after `StopStream`
    /// the host compares it with the last frame it received to count frames
    /// lost at the end of a recording.
    pub stream_next_seq: u32,
}

/// A committed slot.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SlotInfo {
    /// Which slot.
    pub slot: Slot,
    /// Its sequence number (newest wins, wrapping comparison).
    pub seq: u32,
    /// Id of the image in the slot ([`crate::image::BoxImage::id`]: the
    /// image's own trailing CRC-32, as `dynocomp inspect` shows it).
    pub image_id: u32,
}

/// Design summary of the running image (what `dynocomp inspect` shows).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ImageSummary {
    /// Image id: its CRC-32 ([`crate::image::BoxImage::id`]).
    pub id: u32,
    /// Design sample rate, Hz.
    pub fs_hz: u32,
    /// Declared latency, samples.
    pub latency_samples: u16,
    /// Design method.
    pub method: DesignMethod,
    /// Per axis (x, y, z): scaling and design figures, None if absent.
    pub axes: [Option<AxisSummaryWire>; AXES],
    /// `None` for a per-axis image (format version 1); for a 3x3 image
    /// (version 3), how each output row was designed.
    pub rows: Option<[RowDesign; AXES]>,
}

/// One axis of [`ImageSummary`]: what the host needs to convert streamed
/// codes to newtons, and the design figures.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct AxisSummaryWire {
    /// ADC code at 0 N.
    pub adc_offset_code: f32,
    /// N per ADC code.
    pub newton_per_code: f32,
    /// DAC codes per N.
    pub dac_code_per_newton: f32,
    /// DAC code at 0 N.
    pub dac_offset_code: f32,
    /// Model order of the fitted sensor model.
    pub model_order: u16,
    /// Lower edge of the flat band, Hz.
    pub flat_lo_hz: f32,
    /// Upper edge of the flat band, Hz.
    pub flat_hi_hz: f32,
    /// Noise gain (ratio).
    pub noise_gain: f32,
}

/// Counters of the sample path (see [`crate::sample::Counters`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct StatusCounters {
    /// Samples processed (wrapping).
    pub samples: u32,
    /// Missed deadlines.
    pub overruns: u32,
    /// Samples at an ADC rail, per axis.
    pub saturated: [u32; AXES],
    /// Runaway-guard resets of the filter state, per axis.
    pub nonfinite_resets: [u32; AXES],
    /// Streamed samples dropped because the USB queue was full.
    pub stream_dropped: u32,
    /// Core clock cycles of the most recent sample interrupt's body
    /// ([`crate::cycles::IsrCycles::last`]); 0 = not measured.
    pub isr_cycles_last: u32,
    /// Most cycles of any sample interrupt's body since boot, including
    /// the first samples after boot and after image switches
    /// ([`crate::cycles::IsrCycles::max`]); 0 = not measured.
    pub isr_cycles_max: u32,
    /// Mean cycles of the sample interrupt's body over the last complete
    /// window of [`crate::cycles::MEAN_WINDOW`] samples
    /// ([`crate::cycles::IsrCycles::mean`]); 0 = not measured (yet).
    pub isr_cycles_mean: u32,
}

/// One streamed sample: ADC codes in, DAC codes out, flags.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct StreamSample {
    /// ADC codes (x, y, z).
    pub raw: [u16; AXES],
    /// DAC codes written (x, y, z).
    pub out: [u16; AXES],
    /// [`crate::sample::SampleFlags`] bits.
    pub flags: u8,
}

/// A batch of streamed samples.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct StreamFrame {
    /// Frame sequence number, +1 (wrapping) per frame the box sends: a gap
    /// on the host is a lost frame.
    pub seq: u32,
    /// Sample index (the sample path's sample counter) of `samples[0]`.
    pub first_sample: u32,
    /// Index step between consecutive samples (the decimation).
    pub step: u16,
    /// Number of valid entries in `samples` (1..=[`STREAM_BATCH`]).
    pub n: u8,
    /// The samples; entries at `n..` are zero.
    pub samples: [StreamSample; STREAM_BATCH],
}

impl StreamFrame {
    /// The valid samples.
    pub fn valid(&self) -> &[StreamSample] {
        self.samples.get(..usize::from(self.n)).unwrap_or(&self.samples)
    }
}

/// Builds [`StreamFrame`]s from decimated samples (USB task).
///
/// Samples whose index does not follow the previous one by `step` (dropped
/// in the queue) close the current frame early, so every frame describes
/// evenly spaced samples.
#[derive(Clone, Copy, Debug)]
pub struct StreamBatcher {
    next_seq: u32,
    frame: Option<StreamFrame>,
}

impl Default for StreamBatcher {
    fn default() -> Self {
        Self::new()
    }
}

impl StreamBatcher {
    /// A batcher whose first frame has sequence number 0.
    pub const fn new() -> Self {
        StreamBatcher { next_seq: 0, frame: None }
    }

    /// Add the sample with sample index `index`; `step` is the decimation.
    /// Returns up to one completed frame to send (a frame completes when
    /// full, or when this sample does not continue it).
    pub fn push(&mut self, index: u32, step: u16, sample: StreamSample) -> Option<StreamFrame> {
        let mut done = None;
        if let Some(f) = &self.frame {
            let expected = f.first_sample.wrapping_add(u32::from(f.n) * u32::from(f.step));
            if expected != index || f.step != step {
                done = self.flush();
            }
        }
        let seq = self.next_seq;
        let f = self.frame.get_or_insert(StreamFrame {
            seq,
            first_sample: index,
            step,
            n: 0,
            samples: [StreamSample::default(); STREAM_BATCH],
        });
        if let Some(s) = f.samples.get_mut(usize::from(f.n)) {
            *s = sample;
            f.n += 1;
        }
        if usize::from(f.n) >= STREAM_BATCH {
            // `done` is None here unless the previous frame was flushed
            // above, and a new frame cannot be full after one sample
            // (STREAM_BATCH > 1), so nothing is lost.
            return done.or_else(|| self.flush());
        }
        done
    }

    /// Close the current frame (e.g. when streaming stops or a timer fires)
    /// and return it; each returned frame consumes one sequence number.
    pub fn flush(&mut self) -> Option<StreamFrame> {
        let f = self.frame.take()?;
        self.next_seq = self.next_seq.wrapping_add(1);
        Some(f)
    }

    /// Sequence number of the next frame.
    pub fn next_seq(&self) -> u32 {
        self.next_seq
    }
}

/// Encode `msg` as one frame (COBS body + 0x00) into `out`; returns the
/// frame length. `out` of [`MAX_FRAME`] bytes always suffices for messages
/// whose postcard encoding fits [`MAX_PAYLOAD`] − 4.
pub fn encode_frame<T: Serialize>(msg: &T, out: &mut [u8]) -> Result<usize, FrameError> {
    let mut body = [0u8; MAX_PAYLOAD];
    let n = {
        let (msg_area, _) = body.split_at_mut(MAX_PAYLOAD - CRC_BYTES);
        postcard::to_slice(msg, msg_area).map_err(|_| FrameError::TooLarge)?.len()
    };
    let crc = CRC32.checksum(body.get(..n).ok_or(FrameError::TooLarge)?);
    body.get_mut(n..n + CRC_BYTES).ok_or(FrameError::TooLarge)?.copy_from_slice(&crc.to_le_bytes());
    let src = body.get(..n + CRC_BYTES).ok_or(FrameError::TooLarge)?;
    let len = cobs::try_encode(src, out).map_err(|_| FrameError::TooLarge)?;
    *out.get_mut(len).ok_or(FrameError::TooLarge)? = 0;
    Ok(len + 1)
}

/// Decode one frame body in place: `buf` holds the COBS bytes between two
/// delimiters (without the 0x00). Returns the postcard message bytes (CRC
/// checked and removed).
pub fn decode_frame(buf: &mut [u8]) -> Result<&[u8], FrameError> {
    if buf.len() > MAX_FRAME {
        return Err(FrameError::Oversized);
    }
    let n = cobs::decode_in_place(buf).map_err(|_| FrameError::Cobs)?;
    if n > MAX_PAYLOAD {
        return Err(FrameError::Oversized);
    }
    let body = buf.get(..n).ok_or(FrameError::Cobs)?;
    if n < CRC_BYTES + 1 {
        return Err(FrameError::Truncated);
    }
    let (msg, crc) = body.split_at(n - CRC_BYTES);
    let stored = u32::from_le_bytes([crc[0], crc[1], crc[2], crc[3]]);
    if CRC32.checksum(msg) != stored {
        return Err(FrameError::BadCrc);
    }
    Ok(msg)
}

/// Decode the message bytes returned by [`decode_frame`] (or
/// [`FrameDecoder::push`]) as a `T`; `None` if they are not a valid `T` or
/// have trailing bytes.
pub fn decode_message<'a, T: Deserialize<'a>>(bytes: &'a [u8]) -> Option<T> {
    match postcard::take_from_bytes::<T>(bytes) {
        Ok((v, [])) => Some(v),
        _ => None,
    }
}

/// The protocol version of a status reply in message bytes (from
/// [`decode_frame`]) that may be of another protocol version, e.g. bytes
/// that do not decode as this version's [`BoxMessage`]: the start of a
/// status reply, `BoxMessage::Reply { id, reply: Reply::Status(Status {
/// protocol, .. }) }` (variant 0, varint id, variant 1, varint version), is
/// the same in every version. `None` if the bytes do not start like a
/// status reply.
pub fn status_protocol_version(bytes: &[u8]) -> Option<u16> {
    match postcard::take_from_bytes::<(u32, u16, u32, u16)>(bytes) {
        Ok(((0, _id, 1, version), _rest)) => Some(version),
        _ => None,
    }
}

/// Accumulates a byte stream (arbitrary partial reads) into frames, with a
/// fixed buffer of [`MAX_FRAME`] bytes.
///
/// Empty frames (consecutive delimiters) are skipped. A frame longer than
/// the buffer is discarded up to the next delimiter and reported once as
/// [`FrameError::Oversized`]. Garbage yields a framing error and the decoder
/// resynchronises at the next 0x00.
#[derive(Clone, Debug)]
pub struct FrameDecoder {
    buf: [u8; MAX_FRAME],
    len: usize,
    overflow: bool,
}

impl Default for FrameDecoder {
    fn default() -> Self {
        Self::new()
    }
}

impl FrameDecoder {
    /// An empty decoder.
    pub const fn new() -> Self {
        FrameDecoder { buf: [0; MAX_FRAME], len: 0, overflow: false }
    }

    /// Feed one byte; returns a frame's message bytes (or its framing error)
    /// when `byte` is the delimiter that ends a non-empty frame.
    pub fn push_byte(&mut self, byte: u8) -> Option<Result<&[u8], FrameError>> {
        if byte != 0 {
            match self.buf.get_mut(self.len) {
                Some(slot) if !self.overflow => {
                    *slot = byte;
                    self.len += 1;
                }
                _ => self.overflow = true,
            }
            return None;
        }
        let len = core::mem::take(&mut self.len);
        if core::mem::take(&mut self.overflow) {
            return Some(Err(FrameError::Oversized));
        }
        if len == 0 {
            return None;
        }
        let frame = self.buf.get_mut(..len)?;
        Some(decode_frame(frame))
    }

    /// Feed a chunk of received bytes; `on_frame` is called for every frame
    /// or framing error it completes, in order.
    pub fn push(&mut self, bytes: &[u8], mut on_frame: impl FnMut(Result<&[u8], FrameError>)) {
        for &b in bytes {
            if let Some(r) = self.push_byte(b) {
                on_frame(r);
            }
        }
    }

    /// Bytes of the partial frame held so far.
    pub fn pending(&self) -> usize {
        self.len
    }
}
