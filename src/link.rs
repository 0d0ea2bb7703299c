//! The box side of the USB protocol: a pure request handler over the
//! coefficient store. It never touches the sample path; what the sample
//! path must do (bypass, auto-zero, switch image, stream on/off) comes out
//! as [`Actions`] for the firmware to apply.
//!
//! # How the firmware calls this (API note for the box)
//!
//! In the **USB task** only:
//!
//! ```text
//! decoder.push(&usb_packet, |frame| {
//!     let mut act = Actions::default();
//!     let msg = link.on_frame(frame, &mut store, &telemetry_snapshot(), &mut act);
//!     send(encode_frame(&msg));
//!     apply(act);   // see Actions
//! });
//! ```
//!
//! `telemetry_snapshot()` copies the counters the interrupt publishes
//! (atomics or a critical section around a `Copy` struct). The same handler
//! runs in the host's virtual box (`dynocomp virtual-box`), which is how the
//! host tests exercise it.

use embedded_storage::nor_flash::NorFlash;

use crate::image::BoxImage;
use crate::protocol::{
    decode_message, AxisSummaryWire, BoxMessage, FrameError, ImageSummary, LinkError, Reply, Request, RequestFrame,
    Status, StatusCounters, PROTOCOL_VERSION,
};
use crate::sample::BypassReason;
use crate::store::Store;

/// What the sample path is doing, as the USB task sees it (a snapshot).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Telemetry<'a> {
    /// Firmware version (major, minor, patch).
    pub firmware: [u8; 3],
    /// Sample rate the sample path runs at, Hz.
    pub fs_hz: u32,
    /// CPU core clock, Hz (unit of the `isr_cycles_*` counters; 0 = unknown).
    pub core_clock_hz: u32,
    /// `None` when compensating, else why the box is in bypass.
    pub bypass: Option<BypassReason>,
    /// The image the sample path runs (None if there is none).
    pub image: Option<&'a BoxImage>,
    /// Counters.
    pub counters: StatusCounters,
    /// [`StreamBatcher::next_seq`](crate::protocol::StreamBatcher::next_seq)
    /// of the stream batcher.
    pub stream_next_seq: u32,
}

/// What the firmware must do after a request (all fields default to "nothing").
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Actions {
    /// Set (`Some(true)`) or release (`Some(false)`) the user bypass.
    pub bypass: Option<bool>,
    /// Start an offset auto-zero.
    pub auto_zero: bool,
    /// A new image was committed: load it with
    /// [`Store::load_active`](crate::store::Store::load_active) and hand it
    /// to the interrupt ([`crate::handoff::ImageHandoff`]).
    pub switch_image: bool,
    /// Start (`Some(Some(decimation))`) or stop (`Some(None)`) streaming.
    pub stream: Option<Option<u16>>,
}

/// The request handler (state: streaming on/off; the upload state lives in
/// the store).
#[derive(Clone, Copy, Debug, Default)]
pub struct BoxLink {
    stream: Option<u16>,
}

/// Design summary of `img` for [`Status`].
pub fn image_summary(img: &BoxImage) -> ImageSummary {
    let (scaling, summaries) = (img.scaling(), img.summaries());
    let axes = core::array::from_fn(|i| match (scaling[i], summaries[i]) {
        (Some(s), Some(m)) => Some(AxisSummaryWire {
            adc_offset_code: s.adc_offset_code,
            newton_per_code: s.newton_per_code,
            dac_code_per_newton: s.dac_code_per_newton,
            dac_offset_code: s.dac_offset_code,
            model_order: m.model_order,
            flat_lo_hz: m.flat_lo_hz,
            flat_hi_hz: m.flat_hi_hz,
            noise_gain: m.noise_gain,
        }),
        _ => None,
    });
    ImageSummary {
        id: img.id(),
        fs_hz: img.fs_hz(),
        latency_samples: img.latency_samples(),
        method: img.method(),
        axes,
        rows: img.rows(),
    }
}

impl BoxLink {
    /// A handler with streaming off.
    pub const fn new() -> Self {
        BoxLink { stream: None }
    }

    /// Streaming decimation, if streaming is on.
    pub fn streaming(&self) -> Option<u16> {
        self.stream
    }

    /// Handle one received frame (the output of
    /// [`FrameDecoder`](crate::protocol::FrameDecoder)): a framing error or
    /// an undecodable message gets an `Error` reply with id 0; a request
    /// gets its reply.
    pub fn on_frame<F: NorFlash>(
        &mut self,
        frame: Result<&[u8], FrameError>,
        store: &mut Store<F>,
        tel: &Telemetry<'_>,
        act: &mut Actions,
    ) -> BoxMessage {
        let bytes = match frame {
            Ok(b) => b,
            Err(e) => return BoxMessage::Reply { id: 0, reply: Reply::Error(LinkError::Frame(e)) },
        };
        match decode_message::<RequestFrame<'_>>(bytes) {
            Some(f) => BoxMessage::Reply { id: f.id, reply: self.handle(f.request, store, tel, act) },
            None => BoxMessage::Reply { id: 0, reply: Reply::Error(LinkError::Malformed) },
        }
    }

    /// Handle one request.
    pub fn handle<F: NorFlash>(
        &mut self,
        req: Request<'_>,
        store: &mut Store<F>,
        tel: &Telemetry<'_>,
        act: &mut Actions,
    ) -> Reply {
        let done = |r: Result<(), LinkError>| match r {
            Ok(()) => Reply::Ack,
            Err(e) => Reply::Error(e),
        };
        match req {
            Request::GetStatus => Reply::Status(Status {
                protocol: PROTOCOL_VERSION,
                firmware: tel.firmware,
                fs_hz: tel.fs_hz,
                core_clock_hz: tel.core_clock_hz,
                bypass: tel.bypass,
                active: store.active(),
                image: tel.image.map(image_summary),
                counters: tel.counters,
                stream_decimation: self.stream,
                stream_next_seq: tel.stream_next_seq,
            }),
            Request::SetBypass(on) => {
                act.bypass = Some(on);
                Reply::Ack
            }
            Request::StartStream { decimation: 0 } => Reply::Error(LinkError::BadDecimation),
            Request::StartStream { decimation } => {
                self.stream = Some(decimation);
                act.stream = Some(Some(decimation));
                Reply::Ack
            }
            Request::StopStream => {
                self.stream = None;
                act.stream = Some(None);
                Reply::Ack
            }
            Request::AutoZero => {
                act.auto_zero = true;
                Reply::Ack
            }
            Request::UploadBegin { len, crc } => done(store.begin_upload(len, crc)),
            Request::UploadChunk { offset, bytes } => done(store.write_chunk(offset, bytes)),
            Request::UploadCommit => match store.commit() {
                Ok(_) => {
                    act.switch_image = true;
                    Reply::Ack
                }
                Err(e) => Reply::Error(e),
            },
        }
    }
}
