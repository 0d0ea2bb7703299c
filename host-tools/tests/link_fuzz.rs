//! The box's request handler (dynocomp_core::link, run by the virtual box
//! in-process) under arbitrary input: random bytes and random request
//! sequences never panic, every unreadable frame gets an error reply with
//! id 0, every request exactly one reply with its id, and the running image
//! is always the one a fresh boot of the flash would run.

use crate::common;

use dynocomp::link::sim_flash::SimFlash;
use dynocomp::link::virtual_box::VirtualBox;
use dynocomp_core::image::CRC32;
use dynocomp_core::protocol::*;
use dynocomp_core::store::{Layout, Store};
use proptest::prelude::*;

fn replies(bytes: &[u8]) -> Vec<BoxMessage> {
    let mut dec = FrameDecoder::new();
    let mut out = vec![];
    dec.push(bytes, |r| {
        out.push(decode_message::<BoxMessage>(r.expect("the box sends valid frames")).expect("decodes"))
    });
    out
}

fn frame(id: u16, request: Request<'_>) -> Vec<u8> {
    let mut buf = [0u8; MAX_FRAME];
    let n = encode_frame(&RequestFrame { id, request }, &mut buf).unwrap();
    buf[..n].to_vec()
}

/// The running image agrees with an independent boot of the flash.
fn consistent(vbox: &mut VirtualBox) -> Result<(), TestCaseError> {
    let mut store = Store::open(vbox.flash_copy(), Layout::STM32G474RE).unwrap();
    let boot = store.boot().image.ok();
    prop_assert_eq!(boot.as_ref(), vbox.running());
    Ok(())
}

#[derive(Clone, Debug)]
enum Op {
    Garbage(Vec<u8>),
    Request(u8, u32, u32, u16, Vec<u8>),
    GoodUpload(u32),
}

fn arb_op() -> impl Strategy<Value = Op> {
    prop_oneof![
        proptest::collection::vec(any::<u8>(), 0..400).prop_map(Op::Garbage),
        (0u8..8, any::<u32>(), 0u32..400, any::<u16>(), proptest::collection::vec(any::<u8>(), 0..=MAX_CHUNK + 8))
            .prop_map(|(k, a, b, d, v)| Op::Request(k, a, b, d, v)),
        (1u32..4).prop_map(Op::GoodUpload),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 96, ..ProptestConfig::default() })]

    #[test]
    fn arbitrary_input_never_breaks_the_box(ops in proptest::collection::vec(arb_op(), 1..12)) {
        let mut vbox = VirtualBox::boot(SimFlash::g474_slots(), []).unwrap();
        let mut id = 1u16;
        for op in ops {
            match op {
                Op::Garbage(mut g) => {
                    g.push(0);
                    for m in replies(&vbox.receive(&g)) {
                        // Garbage is answered (if at all) with id-0 errors.
                        match m {
                            BoxMessage::Reply { id: 0, reply: Reply::Error(_) } => {}
                            other => prop_assert!(false, "reply to garbage: {:?}", other),
                        }
                    }
                }
                Op::Request(kind, a, b, d, data) => {
                    let req = match kind {
                        0 => Request::GetStatus,
                        1 => Request::SetBypass(a & 1 == 1),
                        2 => Request::StartStream { decimation: d },
                        3 => Request::StopStream,
                        4 => Request::UploadBegin { len: b, crc: a },
                        5 => Request::UploadChunk { offset: b, bytes: &data },
                        6 => Request::UploadCommit,
                        _ => Request::AutoZero,
                    };
                    id = id.wrapping_add(1).max(1);
                    let got: Vec<_> = replies(&vbox.receive(&frame(id, req)))
                        .into_iter()
                        .filter(|m| matches!(m, BoxMessage::Reply { .. }))
                        .collect();
                    prop_assert_eq!(got.len(), 1, "{:?}", got);
                    let BoxMessage::Reply { id: rid, .. } = got[0] else { unreachable!() };
                    prop_assert_eq!(rid, id);
                }
                Op::GoodUpload(v) => {
                    let img = common::good(v);
                    let mut reqs = vec![frame(1, Request::UploadBegin { len: img.len() as u32, crc: CRC32.checksum(&img) })];
                    for (i, c) in img.chunks(MAX_CHUNK).enumerate() {
                        reqs.push(frame(2, Request::UploadChunk { offset: (i * MAX_CHUNK) as u32, bytes: c }));
                    }
                    reqs.push(frame(3, Request::UploadCommit));
                    let all: Vec<u8> = reqs.concat();
                    let got = replies(&vbox.receive(&all));
                    prop_assert!(got.iter().all(|m| !matches!(m, BoxMessage::Reply { reply: Reply::Error(_), .. })), "{:?}", got);
                    prop_assert_eq!(vbox.running().map(|i| i.id()), Some(common::id(&img)));
                }
            }
            consistent(&mut vbox)?;
        }
        // Still answers.
        let got = replies(&vbox.receive(&frame(9, Request::GetStatus)));
        let has_status = got.iter().any(|m| matches!(m, BoxMessage::Reply { id: 9, reply: Reply::Status(_) }));
        prop_assert!(has_status);
    }
}

/// Each request's effect on the sample path comes out as `Actions`, and
/// nothing else changes it.
#[test]
fn requests_map_to_actions() {
    use dynocomp_core::link::{Actions, BoxLink, Telemetry};
    let mut store = Store::open(SimFlash::g474_slots(), Layout::STM32G474RE).unwrap();
    let mut link = BoxLink::new();
    let counters = StatusCounters {
        overruns: 2,
        isr_cycles_last: 1_100,
        isr_cycles_max: 3_000,
        isr_cycles_mean: 1_234,
        ..Default::default()
    };
    let tel = Telemetry {
        firmware: [1, 2, 3],
        fs_hz: 51_200,
        core_clock_hz: 170_000_000,
        bypass: None,
        image: None,
        counters,
        stream_next_seq: 7,
    };
    let run = |req: Request<'_>, link: &mut BoxLink, store: &mut Store<SimFlash>| {
        let mut act = Actions::default();
        let reply = link.handle(req, store, &tel, &mut act);
        (reply, act)
    };
    assert_eq!(
        run(Request::SetBypass(true), &mut link, &mut store),
        (Reply::Ack, Actions { bypass: Some(true), ..Default::default() })
    );
    assert_eq!(
        run(Request::AutoZero, &mut link, &mut store),
        (Reply::Ack, Actions { auto_zero: true, ..Default::default() })
    );
    assert_eq!(
        run(Request::StartStream { decimation: 0 }, &mut link, &mut store),
        (Reply::Error(LinkError::BadDecimation), Actions::default())
    );
    assert_eq!(
        run(Request::StartStream { decimation: 4 }, &mut link, &mut store),
        (Reply::Ack, Actions { stream: Some(Some(4)), ..Default::default() })
    );
    match run(Request::GetStatus, &mut link, &mut store) {
        (Reply::Status(s), act) => {
            assert_eq!(act, Actions::default());
            assert_eq!(
                (s.firmware, s.fs_hz, s.stream_decimation, s.stream_next_seq, s.active),
                ([1, 2, 3], 51_200, Some(4), 7, None)
            );
            assert_eq!((s.protocol, s.core_clock_hz, s.counters), (PROTOCOL_VERSION, 170_000_000, counters));
        }
        other => panic!("{other:?}"),
    }
    assert_eq!(
        run(Request::StopStream, &mut link, &mut store),
        (Reply::Ack, Actions { stream: Some(None), ..Default::default() })
    );
    let img = common::good(5);
    assert_eq!(
        run(Request::UploadBegin { len: img.len() as u32, crc: CRC32.checksum(&img) }, &mut link, &mut store).1,
        Actions::default()
    );
    for (i, c) in img.chunks(MAX_CHUNK).enumerate() {
        assert_eq!(
            run(Request::UploadChunk { offset: (i * MAX_CHUNK) as u32, bytes: c }, &mut link, &mut store).0,
            Reply::Ack
        );
    }
    assert_eq!(
        run(Request::UploadCommit, &mut link, &mut store),
        (Reply::Ack, Actions { switch_image: true, ..Default::default() })
    );
    assert_eq!(store.active().map(|a| a.image_id), Some(common::id(&img)));
}
