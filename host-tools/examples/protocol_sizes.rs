//! RAM the box's protocol and store objects take, and worst-case frame
//! sizes: `cargo run -p dynocomp --example protocol_sizes`.
//! (Sizes of these types are the same on thumbv7em: they are byte arrays,
//! u16/u32 and f32 fields.)

use dynocomp::link::sim_flash::SimFlash;
use dynocomp_core::image::CoeffImage;
use dynocomp_core::link::BoxLink;
use dynocomp_core::protocol::*;
use dynocomp_core::store::Store;
use std::mem::size_of;

fn main() {
    println!(
        "MAX_PAYLOAD {} B, MAX_FRAME {} B, MAX_CHUNK {} B, STREAM_BATCH {}",
        MAX_PAYLOAD, MAX_FRAME, MAX_CHUNK, STREAM_BATCH
    );
    println!("FrameDecoder      {:5} B", size_of::<FrameDecoder>());
    println!("Store (w/o flash) {:5} B", size_of::<Store<SimFlash>>() - size_of::<SimFlash>());
    println!("BoxLink           {:5} B", size_of::<BoxLink>());
    println!("StreamBatcher     {:5} B", size_of::<StreamBatcher>());
    println!("CoeffImage        {:5} B (x2 for the handoff buffers)", size_of::<CoeffImage>());
    let mut buf = [0u8; MAX_FRAME];
    let s = StreamFrame {
        seq: 1_000_000,
        first_sample: 1_000_000_000,
        step: 1,
        n: STREAM_BATCH as u8,
        samples: [StreamSample { raw: [2048, 3000, 1000], out: [2100, 2900, 1100], flags: 0 }; STREAM_BATCH],
    };
    let n = encode_frame(&BoxMessage::Stream(s), &mut buf).unwrap();
    println!("typical stream frame: {n} B for {STREAM_BATCH} samples ({:.1} B/sample)", n as f64 / STREAM_BATCH as f64);
}
