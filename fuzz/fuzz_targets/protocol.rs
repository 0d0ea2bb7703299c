//! USB protocol frame decoder and message decoding (`src/protocol.rs`).
//!
//! Byte 0 of the input is a mode. Mode bit 0 clear: the rest is a raw byte
//! stream from the wire. Set: the rest is a message payload, framed here
//! (CRC-32 + COBS + 0x00), so the fuzzer reaches the postcard decoding of
//! `RequestFrame` and `BoxMessage` without solving the CRC.
//!
//! Checks: never panics; the stream gives one result per non-empty
//! delimited segment, the same however the stream is split into reads;
//! a segment longer than the buffer is `Oversized`; an accepted frame
//! re-framed decodes to the same bytes; a well-formed frame of a payload
//! that fits always decodes to that payload; a decoded message re-encodes
//! and decodes to the same message, bit for bit (encode → decode).
#![no_main]

use dynocomp_core::image::CRC32;
use dynocomp_core::protocol::*;
use libfuzzer_sys::fuzz_target;

type Out = Vec<Result<Vec<u8>, FrameError>>;

fn decode_stream(chunks: &[&[u8]]) -> Out {
    let mut dec = FrameDecoder::new();
    let mut out = Vec::new();
    for c in chunks {
        dec.push(c, |r| out.push(r.map(<[u8]>::to_vec)));
    }
    out
}

/// Frame `payload` (payload + CRC-32, COBS, 0x00) independently of `encode_frame`.
fn frame(payload: &[u8]) -> Vec<u8> {
    let mut body = payload.to_vec();
    body.extend_from_slice(&CRC32.checksum(payload).to_le_bytes());
    let mut out = vec![0u8; cobs::max_encoding_length(body.len()) + 1];
    let n = cobs::encode(&body, &mut out);
    out.truncate(n);
    out.push(0);
    out
}

/// encode → decode of a message decoded as `$t` from `$bytes` gives it back:
/// compared as its re-encoded frame, bit for bit (a NaN is not equal to
/// itself, its bits are).
macro_rules! roundtrip {
    ($t:ty, $bytes:expr) => {
        if let Some(msg) = decode_message::<$t>($bytes) {
            let mut buf = [0u8; MAX_FRAME];
            let n = encode_frame(&msg, &mut buf).expect("a decoded message fits a frame");
            assert_eq!(buf[n - 1], 0, "a frame ends with its delimiter");
            let first = buf[..n].to_vec();
            let body = decode_frame(&mut buf[..n - 1]).expect("an encoded frame decodes");
            let again = decode_message::<$t>(body).expect("an encoded message decodes");
            let mut buf2 = [0u8; MAX_FRAME];
            let n2 = encode_frame(&again, &mut buf2).expect("fits");
            assert_eq!(&buf2[..n2], &first[..], "encode → decode changed the message: {msg:?} vs {again:?}");
        }
    };
}

fn check_message(bytes: &[u8]) {
    roundtrip!(RequestFrame<'_>, bytes);
    roundtrip!(BoxMessage, bytes);
    let _ = status_protocol_version(bytes);
}

fuzz_target!(|data: &[u8]| {
    let Some((&mode, rest)) = data.split_first() else { return };
    if mode & 1 == 1 {
        let wire = frame(rest);
        let out = decode_stream(&[&wire]);
        if rest.len() + 4 <= MAX_PAYLOAD && !rest.is_empty() {
            assert_eq!(out, vec![Ok(rest.to_vec())], "a well-formed frame did not decode to its payload");
            check_message(rest);
        } else {
            assert_eq!(out.len(), 1);
        }
        return;
    }
    let whole = decode_stream(&[rest]);
    let cut = usize::from(mode >> 1) % (rest.len() + 1);
    let (a, b) = rest.split_at(cut);
    assert_eq!(decode_stream(&[a, b]), whole, "result depends on how the stream is split");
    // One result per non-empty segment closed by a delimiter.
    let mut segments: Vec<&[u8]> = rest.split(|&x| x == 0).collect();
    segments.pop(); // the unterminated tail
    segments.retain(|s| !s.is_empty());
    assert_eq!(whole.len(), segments.len());
    for (seg, r) in segments.iter().zip(&whole) {
        if seg.len() > MAX_FRAME {
            assert_eq!(r, &Err(FrameError::Oversized));
        }
        if let Ok(msg) = r {
            assert!(msg.len() + 4 <= MAX_PAYLOAD && !msg.is_empty());
            assert_eq!(decode_stream(&[&frame(msg)]), vec![Ok(msg.clone())]);
            check_message(msg);
        }
    }
});
