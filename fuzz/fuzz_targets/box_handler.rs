//! The box's request handler (`src/link.rs` over the store, run as the host's
//! virtual box does, `host-tools/src/virtual_box.rs`) under a fuzzed
//! sequence of raw wire bytes, well-formed requests and whole uploads
//! (of the project's own images, optionally corrupted).
//!
//! Checks: never panics; every frame the box sends is valid; every frame it
//! receives gets exactly one reply, in order, with the request's id, or id 0
//! and an error if the frame is unreadable (predicted by an independent
//! decoder fed the same bytes); `StartStream { 0 }` is refused and
//! `GetStatus` reports this protocol version; a clean upload of a box image
//! is acked and runs, a corrupted or offline-only one is refused at commit
//! and the running image is unchanged; after every step the running image is
//! the one a fresh boot of the flash would run.
#![no_main]

use dynocomp::link::sim_flash::SimFlash;
use dynocomp::link::virtual_box::VirtualBox;
use dynocomp_core::image::{BoxImage, CRC32};
use dynocomp_core::protocol::*;
use dynocomp_core::store::{Layout, Store};
use dynocomp_fuzz::{box_runnable, IMAGES};
use libfuzzer_sys::arbitrary::{self, Arbitrary};
use libfuzzer_sys::fuzz_target;

#[derive(Arbitrary, Debug)]
enum Req {
    GetStatus,
    SetBypass(bool),
    StartStream(u16),
    StopStream,
    AutoZero,
    UploadBegin { len: u32, crc: u32 },
    UploadChunk { offset: u32, bytes: Vec<u8> },
    UploadCommit,
}

#[derive(Arbitrary, Debug)]
enum Op {
    /// Bytes on the wire, as they come.
    Raw(Vec<u8>),
    /// One well-formed request.
    Request(Req),
    /// A whole upload: begin, chunks (`upload_chunks`: the first `chunk`
    /// bytes long), commit.
    Upload { image: u8, chunk: u8, corrupt: Option<(u16, u8)>, commit: bool },
}

struct Harness {
    vbox: VirtualBox,
    /// Decoder fed the same bytes as the box: predicts its replies.
    shadow: FrameDecoder,
    next_id: u16,
    /// Flash operation count at the last fresh boot, and what it ran.
    booted: Option<(u64, Option<BoxImage>)>,
}

impl Harness {
    /// Send `bytes`; returns the replies (stream frames dropped), checked
    /// against the frames the shadow decoder sees.
    fn send(&mut self, bytes: &[u8]) -> Vec<(u16, Reply)> {
        let mut expected: Vec<u16> = Vec::new();
        self.shadow.push(bytes, |r| {
            expected.push(match r.ok().and_then(decode_message::<RequestFrame<'_>>) {
                Some(f) => f.id,
                None => 0,
            })
        });
        let wire = self.vbox.receive(bytes);
        let mut dec = FrameDecoder::new();
        let mut replies = Vec::new();
        dec.push(&wire, |r| {
            let bytes = r.expect("the box sends valid frames");
            match decode_message::<BoxMessage>(bytes).expect("the box's frames decode") {
                BoxMessage::Reply { id, reply } => replies.push((id, reply)),
                BoxMessage::Stream(_) => {}
            }
        });
        assert_eq!(dec.pending(), 0, "the box sent an unterminated frame");
        assert_eq!(replies.len(), expected.len(), "one reply per received frame");
        for ((id, reply), want) in replies.iter().zip(&expected) {
            assert_eq!(id, want, "reply id");
            if *id == 0 {
                assert!(matches!(reply, Reply::Error(_)), "an unreadable frame got {reply:?}");
            }
        }
        replies
    }

    /// Send one request (after a delimiter that closes any partial frame).
    fn request(&mut self, request: Request<'_>) -> Reply {
        self.next_id = self.next_id.wrapping_add(1).max(1);
        let id = self.next_id;
        let mut buf = [0u8; MAX_FRAME + 1];
        let n = encode_frame(&RequestFrame { id, request }, &mut buf[1..]).expect("request fits a frame");
        let replies = self.send(&buf[..n + 1]);
        let (rid, reply) = *replies.last().expect("a request gets a reply");
        assert_eq!(rid, id);
        reply
    }

    /// The running image is what a fresh boot of the flash runs. The boot
    /// is redone only when the flash was erased or written since the last
    /// check (boot is a function of the flash contents); the comparison
    /// with the running image is made every time.
    fn consistent(&mut self) {
        let ops = self.vbox.flash_ops();
        if self.booted.as_ref().is_none_or(|(at, _)| *at != ops) {
            let mut store = Store::open(self.vbox.flash_copy(), Layout::STM32G474RE).expect("layout");
            self.booted = Some((ops, store.boot().image.ok()));
        }
        let boot = self.booted.as_ref().and_then(|(_, img)| img.as_ref());
        assert_eq!(boot, self.vbox.running(), "running image differs from a fresh boot of the flash");
    }
}

/// Most chunks an [`Op::Upload`] sends, and most whole uploads per input
/// (enough for A → B → A slot alternation and a refused upload between).
/// Byte-sized chunks of every image (up to 1 476 requests per upload, up to
/// 32 uploads per input) made this target run at 300 exec/s, with no
/// coverage that a few dozen chunks do not reach.
const MAX_UPLOAD_CHUNKS: usize = 12;
const MAX_UPLOADS: usize = 4;

/// The (offset, bytes) chunks of an upload: the first is `first` bytes
/// (1..=MAX_CHUNK, any alignment: every later offset inherits it), the rest
/// are as long as `first` but at least `len / MAX_UPLOAD_CHUNKS`.
/// Single-byte and odd chunks throughout a transfer remain reachable through
/// `Req::UploadChunk`.
fn upload_chunks(bytes: &[u8], first: u8) -> Vec<(u32, &[u8])> {
    let first = usize::from(first).clamp(1, MAX_CHUNK);
    let rest = first.max(bytes.len().div_ceil(MAX_UPLOAD_CHUNKS)).min(MAX_CHUNK);
    let mut out = Vec::new();
    let mut at = 0;
    while at < bytes.len() {
        let n = if at == 0 { first } else { rest }.min(bytes.len() - at);
        out.push((at as u32, &bytes[at..at + n]));
        at += n;
    }
    out
}

fuzz_target!(|ops: Vec<Op>| {
    let mut h = Harness {
        vbox: VirtualBox::boot(SimFlash::g474_slots(), []).expect("boot"),
        shadow: FrameDecoder::new(),
        next_id: 0,
        booted: None,
    };
    let mut uploads = 0;
    for op in ops.into_iter().take(32) {
        match op {
            Op::Raw(bytes) => {
                h.send(&bytes);
            }
            Op::Request(req) => {
                let reply = match &req {
                    Req::GetStatus => h.request(Request::GetStatus),
                    Req::SetBypass(on) => h.request(Request::SetBypass(*on)),
                    Req::StartStream(d) => h.request(Request::StartStream { decimation: *d }),
                    Req::StopStream => h.request(Request::StopStream),
                    Req::AutoZero => h.request(Request::AutoZero),
                    Req::UploadBegin { len, crc } => h.request(Request::UploadBegin { len: *len, crc: *crc }),
                    // A host cannot send a chunk too long for one frame (the
                    // encoder refuses it): such a chunk is sent as long as fits.
                    // Longer-than-MAX_CHUNK chunks that do fit still reach the box.
                    Req::UploadChunk { offset, bytes } => {
                        let fits = (0..=bytes.len().min(MAX_PAYLOAD))
                            .rev()
                            .find(|&n| {
                                let frame = RequestFrame {
                                    id: u16::MAX,
                                    request: Request::UploadChunk { offset: *offset, bytes: &bytes[..n] },
                                };
                                encode_frame(&frame, &mut [0u8; MAX_FRAME]).is_ok()
                            })
                            .unwrap_or(0);
                        h.request(Request::UploadChunk { offset: *offset, bytes: &bytes[..fits] })
                    }
                    Req::UploadCommit => h.request(Request::UploadCommit),
                };
                match req {
                    Req::StartStream(0) => assert_eq!(reply, Reply::Error(LinkError::BadDecimation)),
                    Req::GetStatus => match reply {
                        Reply::Status(s) => assert_eq!(s.protocol, PROTOCOL_VERSION),
                        other => panic!("GetStatus answered {other:?}"),
                    },
                    _ => {}
                }
            }
            Op::Upload { .. } if uploads == MAX_UPLOADS => continue,
            Op::Upload { image, chunk, corrupt, commit } => {
                uploads += 1;
                let src = IMAGES[usize::from(image) % IMAGES.len()];
                let mut bytes = src.to_vec();
                let crc = CRC32.checksum(&bytes);
                let mut changed = false;
                if let Some((at, x)) = corrupt {
                    let at = usize::from(at) % bytes.len();
                    changed = x != 0;
                    bytes[at] ^= x;
                }
                let before = h.vbox.running().copied();
                assert_eq!(h.request(Request::UploadBegin { len: bytes.len() as u32, crc }), Reply::Ack);
                for (offset, c) in upload_chunks(&bytes, chunk) {
                    assert_eq!(h.request(Request::UploadChunk { offset, bytes: c }), Reply::Ack, "chunk at {offset}");
                }
                if commit {
                    let reply = h.request(Request::UploadCommit);
                    match BoxImage::parse(src) {
                        Ok(img) if !changed && box_runnable(&img) => {
                            assert_eq!(reply, Reply::Ack, "a clean upload of a box image");
                            assert_eq!(h.vbox.running(), Some(&img));
                        }
                        _ => {
                            let refused = matches!(reply, Reply::Error(_));
                            assert!(refused, "corrupted, offline-only or over-budget upload committed: {reply:?}");
                            assert_eq!(h.vbox.running().copied(), before);
                        }
                    }
                }
            }
        }
        h.consistent();
    }
});
