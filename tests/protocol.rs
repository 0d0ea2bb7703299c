//! USB protocol framing and messages (src/protocol.rs): round trip of every
//! message through frames split at arbitrary points, worst-case sizes,
//! corruption, truncation, oversize, resynchronisation, and arbitrary bytes
//! (no panic, only errors or valid messages).

use dynocomp_core::image::{DesignMethod, ImageError};
use dynocomp_core::protocol::*;
use dynocomp_core::sample::BypassReason;
use dynocomp_core::shell::Slot;
use proptest::prelude::*;

/// Decode every frame in `stream` fed in pieces of the given sizes.
fn feed_all(stream: &[u8], cuts: &[usize]) -> Vec<Result<Vec<u8>, FrameError>> {
    let mut dec = FrameDecoder::new();
    let mut out = vec![];
    let mut rest = stream;
    let mut i = 0;
    while !rest.is_empty() {
        let n = cuts.get(i).copied().unwrap_or(rest.len()).clamp(1, rest.len());
        i += 1;
        let (head, tail) = rest.split_at(n);
        dec.push(head, |r| out.push(r.map(|b| b.to_vec())));
        rest = tail;
    }
    out
}

fn frame<T: serde::Serialize>(msg: &T) -> Vec<u8> {
    let mut buf = [0u8; MAX_FRAME];
    let n = encode_frame(msg, &mut buf).expect("message fits a frame");
    buf[..n].to_vec()
}

fn arb_request(data: Vec<u8>) -> impl Strategy<Value = (u16, u8, u32, u32, bool, u16)> {
    let _ = data;
    (any::<u16>(), 0u8..8, any::<u32>(), any::<u32>(), any::<bool>(), any::<u16>())
}

fn make_request(kind: u8, a: u32, b: u32, flag: bool, d: u16, data: &[u8]) -> Request<'_> {
    match kind {
        0 => Request::GetStatus,
        1 => Request::SetBypass(flag),
        2 => Request::StartStream { decimation: d },
        3 => Request::StopStream,
        4 => Request::UploadBegin { len: a, crc: b },
        5 => Request::UploadChunk { offset: a, bytes: data },
        6 => Request::UploadCommit,
        _ => Request::AutoZero,
    }
}

fn max_status() -> Status {
    let axis = AxisSummaryWire {
        adc_offset_code: f32::MAX,
        newton_per_code: f32::MIN,
        dac_code_per_newton: f32::MAX,
        dac_offset_code: f32::MIN,
        model_order: u16::MAX,
        flat_lo_hz: f32::MAX,
        flat_hi_hz: f32::MAX,
        noise_gain: f32::MAX,
    };
    Status {
        protocol: u16::MAX,
        firmware: [255; 3],
        fs_hz: u32::MAX,
        core_clock_hz: u32::MAX,
        bypass: Some(BypassReason::InvalidImage(ImageError::BadCrc { stored: u32::MAX, computed: u32::MAX })),
        active: Some(SlotInfo { slot: Slot::B, seq: u32::MAX, image_id: u32::MAX }),
        image: Some(ImageSummary {
            id: u32::MAX,
            fs_hz: u32::MAX,
            latency_samples: u16::MAX,
            method: DesignMethod::Paper,
            axes: [Some(axis); 3],
            rows: Some([dynocomp_core::image::RowDesign::Matrix; 3]),
        }),
        counters: StatusCounters {
            samples: u32::MAX,
            overruns: u32::MAX,
            saturated: [u32::MAX; 3],
            nonfinite_resets: [u32::MAX; 3],
            stream_dropped: u32::MAX,
            isr_cycles_last: u32::MAX,
            isr_cycles_max: u32::MAX,
            isr_cycles_mean: u32::MAX,
        },
        stream_decimation: Some(u16::MAX),
        stream_next_seq: u32::MAX,
    }
}

fn max_stream() -> StreamFrame {
    StreamFrame {
        seq: u32::MAX,
        first_sample: u32::MAX,
        step: u16::MAX,
        n: STREAM_BATCH as u8,
        samples: [StreamSample { raw: [u16::MAX; 3], out: [u16::MAX; 3], flags: 0xFF }; STREAM_BATCH],
    }
}

#[test]
fn worst_case_messages_fit_a_frame() {
    let chunk = [0xFFu8; MAX_CHUNK];
    let req = RequestFrame { id: u16::MAX, request: Request::UploadChunk { offset: u32::MAX, bytes: &chunk } };
    let msgs: Vec<Vec<u8>> = vec![
        frame(&req),
        frame(&BoxMessage::Reply { id: u16::MAX, reply: Reply::Status(max_status()) }),
        frame(&BoxMessage::Stream(max_stream())),
        frame(&BoxMessage::Reply {
            id: u16::MAX,
            reply: Reply::Error(LinkError::Image(ImageError::Truncated { needed: u32::MAX, have: u32::MAX })),
        }),
    ];
    for f in &msgs {
        assert!(f.len() <= MAX_FRAME);
        assert_eq!(f.iter().filter(|&&b| b == 0).count(), 1, "only the delimiter is 0");
        assert_eq!(*f.last().unwrap(), 0);
    }
    // A chunk one byte longer than MAX_CHUNK still encodes (the box refuses
    // it by length), but a much longer one does not fit.
    let big = [0xFFu8; MAX_PAYLOAD];
    let req = RequestFrame { id: 1, request: Request::UploadChunk { offset: 0, bytes: &big } };
    let mut buf = [0u8; MAX_FRAME];
    assert_eq!(encode_frame(&req, &mut buf), Err(FrameError::TooLarge));
    // Output buffer too small.
    let mut small = [0u8; 4];
    assert_eq!(
        encode_frame(&BoxMessage::Reply { id: 1, reply: Reply::Status(max_status()) }, &mut small),
        Err(FrameError::TooLarge)
    );
}

#[test]
fn status_and_stream_round_trip() {
    for msg in [BoxMessage::Reply { id: 7, reply: Reply::Status(max_status()) }, BoxMessage::Stream(max_stream())] {
        let f = frame(&msg);
        let got = feed_all(&f, &[3, 1, 50]);
        assert_eq!(got.len(), 1);
        let bytes = got[0].clone().unwrap();
        assert_eq!(decode_message::<BoxMessage>(&bytes), Some(msg));
    }
}

/// `Status` as protocol version 1 sent it (no core clock, no interrupt
/// cycle counts): the wire form of an older firmware.
#[derive(serde::Serialize)]
struct StatusV1 {
    protocol: u16,
    firmware: [u8; 3],
    fs_hz: u32,
    bypass: Option<BypassReason>,
    active: Option<SlotInfo>,
    image: Option<ImageSummary>,
    counters: (u32, u32, [u32; 3], [u32; 3], u32),
    stream_decimation: Option<u16>,
    stream_next_seq: u32,
}

// Unboxed like `Reply` (same allow there): the wire form of a no-heap
// firmware, and the core crate's serde has no `alloc` to serialize a `Box`.
#[allow(clippy::large_enum_variant)]
#[derive(serde::Serialize)]
enum ReplyV1 {
    #[allow(dead_code)]
    Ack,
    Status(StatusV1),
}

#[derive(serde::Serialize)]
enum BoxMessageV1 {
    Reply { id: u16, reply: ReplyV1 },
}

#[test]
fn the_status_reply_of_any_protocol_version_reveals_its_version() {
    // This version's status reply.
    let now = BoxMessage::Reply { id: 7, reply: Reply::Status(Status { protocol: PROTOCOL_VERSION, ..max_status() }) };
    let bytes = feed_all(&frame(&now), &[]).remove(0).unwrap();
    assert_eq!(status_protocol_version(&bytes), Some(PROTOCOL_VERSION));
    assert_eq!(PROTOCOL_VERSION, 3, "the 3x3 image's row record in the status is version 3");

    // A version-1 box's status reply: it does not decode as this version's
    // message (it would be dropped as unreadable), but its version shows.
    let m = max_status();
    let c = m.counters;
    let old = BoxMessageV1::Reply {
        id: 9,
        reply: ReplyV1::Status(StatusV1 {
            protocol: 1,
            firmware: [0, 1, 0],
            fs_hz: 51_200,
            bypass: None,
            active: m.active,
            image: m.image,
            counters: (c.samples, c.overruns, c.saturated, c.nonfinite_resets, c.stream_dropped),
            stream_decimation: None,
            stream_next_seq: 12,
        }),
    };
    let bytes = feed_all(&frame(&old), &[]).remove(0).unwrap();
    assert_eq!(decode_message::<BoxMessage>(&bytes), None);
    assert_eq!(status_protocol_version(&bytes), Some(1));

    // Other messages are not status replies.
    for other in [
        BoxMessage::Reply { id: 1, reply: Reply::Ack },
        BoxMessage::Reply { id: 1, reply: Reply::Error(LinkError::Malformed) },
        BoxMessage::Stream(max_stream()),
    ] {
        let bytes = feed_all(&frame(&other), &[]).remove(0).unwrap();
        assert_eq!(status_protocol_version(&bytes), None, "{other:?}");
    }
    let req = feed_all(&frame(&RequestFrame { id: 0, request: Request::GetStatus }), &[]).remove(0).unwrap();
    assert_eq!(status_protocol_version(&req), None);
    assert_eq!(status_protocol_version(&[]), None);
}

#[test]
fn garbage_oversize_and_truncation_yield_errors_then_resync() {
    let good = RequestFrame { id: 9, request: Request::GetStatus };
    let f = frame(&good);
    let mut stream = vec![];
    // 1: garbage that is not COBS (a code byte pointing past the frame).
    stream.extend_from_slice(&[0x40, 1, 2, 0]);
    // 2: oversize: MAX_FRAME + 5 non-zero bytes.
    stream.extend(std::iter::repeat_n(0x11u8, MAX_FRAME + 5));
    stream.push(0);
    // 3: truncated frame: first half of a valid frame.
    stream.extend_from_slice(&f[..f.len() / 2]);
    stream.push(0);
    // 4: empty frames are skipped.
    stream.extend_from_slice(&[0, 0]);
    // 5: a valid frame.
    stream.extend_from_slice(&f);
    let got = feed_all(&stream, &[5, 7, 300, 2]);
    assert_eq!(got.len(), 4, "{got:?}");
    assert!(got[0].is_err());
    assert_eq!(got[1], Err(FrameError::Oversized));
    assert!(matches!(got[2], Err(FrameError::BadCrc | FrameError::Cobs | FrameError::Truncated)));
    let bytes = got[3].clone().unwrap();
    assert_eq!(decode_message::<RequestFrame>(&bytes), Some(good));
}

#[test]
fn a_frame_too_short_for_its_crc_is_truncated() {
    // COBS of [1, 2, 3] = [4, 1, 2, 3].
    let got = feed_all(&[4, 1, 2, 3, 0], &[]);
    assert_eq!(got, vec![Err(FrameError::Truncated)]);
}

#[test]
fn stream_batcher_numbers_frames_and_splits_at_gaps() {
    let mut b = StreamBatcher::new();
    let s = |i: u16| StreamSample { raw: [i; 3], out: [i + 1; 3], flags: 0 };
    let mut frames = vec![];
    // 8 contiguous samples (step 2): one full frame.
    for k in 0..8u32 {
        frames.extend(b.push(100 + 2 * k, 2, s(k as u16)));
    }
    assert_eq!(frames.len(), 1);
    assert_eq!((frames[0].seq, frames[0].first_sample, frames[0].n), (0, 100, 8));
    // 3 samples, then a gap (sample 122 lost): the frame closes early.
    for k in [116u32, 118, 120, 124] {
        frames.extend(b.push(k, 2, s(k as u16)));
    }
    assert_eq!(frames.len(), 2);
    assert_eq!((frames[1].seq, frames[1].first_sample, frames[1].n), (1, 116, 3));
    assert_eq!(frames[1].valid().len(), 3);
    let last = b.flush().unwrap();
    assert_eq!((last.seq, last.first_sample, last.n), (2, 124, 1));
    assert_eq!(b.flush(), None);
    assert_eq!(b.next_seq(), 3);
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 512, ..ProptestConfig::default() })]

    #[test]
    fn every_request_round_trips(
        (id, kind, a, b, flag, d) in arb_request(vec![]),
        data in proptest::collection::vec(any::<u8>(), 0..=MAX_CHUNK),
        cuts in proptest::collection::vec(1usize..40, 0..10),
    ) {
        let req = RequestFrame { id, request: make_request(kind, a, b, flag, d, &data) };
        let f = frame(&req);
        let got = feed_all(&f, &cuts);
        prop_assert_eq!(got.len(), 1);
        let bytes = got[0].clone().unwrap();
        prop_assert_eq!(decode_message::<RequestFrame>(&bytes), Some(req));
    }

    #[test]
    fn every_reply_round_trips(id in any::<u16>(), kind in 0u8..6, v in any::<u32>(), w in any::<u32>()) {
        let reply = match kind {
            0 => Reply::Ack,
            1 => Reply::Status(Status {
                fs_hz: v,
                core_clock_hz: w,
                counters: StatusCounters { overruns: w, isr_cycles_last: v, isr_cycles_max: w, isr_cycles_mean: v / 2, ..Default::default() },
                ..max_status()
            }),
            2 => Reply::Error(LinkError::OutOfOrder { expected: v, got: w }),
            3 => Reply::Error(LinkError::CrcMismatch { declared: v, computed: w }),
            4 => Reply::Error(LinkError::NotRunnable(BypassReason::UnsupportedSampleRate(v))),
            _ => Reply::Error(LinkError::Frame(FrameError::BadCrc)),
        };
        let msg = BoxMessage::Reply { id, reply };
        let bytes = feed_all(&frame(&msg), &[]).remove(0).unwrap();
        prop_assert_eq!(decode_message::<BoxMessage>(&bytes), Some(msg));
    }

    #[test]
    fn arbitrary_bytes_never_panic_and_resync(
        garbage in proptest::collection::vec(any::<u8>(), 0..2000),
        cuts in proptest::collection::vec(1usize..300, 0..20),
    ) {
        // Garbage, a delimiter, then a valid frame: the valid frame is
        // always the last result, whatever came before.
        let good = RequestFrame { id: 42, request: Request::SetBypass(true) };
        let mut stream = garbage.clone();
        stream.push(0);
        stream.extend_from_slice(&frame(&good));
        let got = feed_all(&stream, &cuts);
        let last = got.last().cloned().unwrap().unwrap();
        prop_assert_eq!(decode_message::<RequestFrame>(&last), Some(good));
        // Any frame decoded from garbage is CRC-checked bytes; decoding them
        // as a message must not panic either.
        for r in got.iter().flatten() {
            let _ = decode_message::<RequestFrame>(r);
            let _ = decode_message::<BoxMessage>(r);
        }
    }

    #[test]
    fn one_corrupted_byte_is_always_detected(
        pos in any::<prop::sample::Index>(),
        flip in 1u8..=255,
        offset in any::<u32>(),
        data in proptest::collection::vec(any::<u8>(), 1..=MAX_CHUNK),
    ) {
        let req = RequestFrame { id: 3, request: Request::UploadChunk { offset, bytes: &data } };
        let mut f = frame(&req);
        let body = f.len() - 1; // do not touch the delimiter
        let i = pos.index(body);
        f[i] ^= flip;
        let got = feed_all(&f, &[]);
        // A corrupted byte may become 0 (splitting the frame) but no piece
        // may decode as a valid frame.
        prop_assert!(!got.is_empty());
        for r in &got {
            prop_assert!(r.is_err(), "corruption at {} not detected: {:?}", i, r);
        }
    }
}
