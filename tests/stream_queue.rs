//! The stream queue between the sample interrupt and the USB task: FIFO
//! order, a full queue refuses, items survive whole (word packing), the
//! free-running counters wrap, the ends are handed out once, and under a
//! real concurrent producer and consumer nothing is torn, reordered or
//! lost without being refused. The concurrent test is a smoke test of the
//! protocol: on x86-64 (total store order) it cannot show a missing
//! `Release`/`Acquire`, and a publish-before-write bug shows only if the
//! consumer happens to read inside a window of a few stores (in three runs
//! with that bug planted it did not); the orderings rest on the argument in
//! `src/stream_queue.rs`. A wrong capacity check fails it every time.

use dynocomp_core::protocol::StreamSample;
use dynocomp_core::stream_queue::{QueueFull, StreamItem, StreamQueue};
use proptest::prelude::*;

/// An item whose every field is derived from `k`, so a torn or mixed item
/// is detectable.
fn item(k: u32) -> StreamItem {
    let c = |j: u32| (k.wrapping_mul(2_654_435_761).rotate_left(j * 5) & 0xffff) as u16;
    StreamItem {
        index: k,
        step: k ^ 0xa5a5_5a5a,
        sample: StreamSample { raw: [c(0), c(1), c(2)], out: [c(3), c(4), c(5)], flags: (k % 251) as u8 },
    }
}

proptest! {
    #[test]
    fn words_round_trip(index: u32, step: u32, raw: [u16; 3], out: [u16; 3], flags: u8) {
        let it = StreamItem { index, step, sample: StreamSample { raw, out, flags } };
        prop_assert_eq!(StreamItem::from_words(it.to_words()), it);
    }
}

#[test]
fn fifo_full_refuses_and_counters_wrap() {
    for start in [0u32, u32::MAX - 5, u32::MAX] {
        let q: StreamQueue<8> = StreamQueue::starting_at(start);
        let (mut p, mut c) = q.split().unwrap();
        assert!(c.pop().is_none() && q.is_empty());
        let mut next_in = 0u32;
        let mut next_out = 0u32;
        // Several fill/drain rounds across the counters' wrap.
        for round in 0..5 {
            for _ in 0..8 {
                assert_eq!(p.push(&item(next_in)), Ok(()), "start {start}, round {round}");
                next_in += 1;
            }
            assert_eq!(q.len(), 8);
            assert_eq!(p.push(&item(999)), Err(QueueFull), "a full queue must refuse");
            for _ in 0..5 {
                assert_eq!(c.pop(), Some(item(next_out)));
                next_out += 1;
            }
            for _ in 0..3 {
                assert_eq!(p.push(&item(next_in)), Ok(()));
                next_in += 1;
            }
            while let Some(it) = c.pop() {
                assert_eq!(it, item(next_out), "start {start}, round {round}");
                next_out += 1;
            }
        }
        assert_eq!(next_in, next_out);
    }
}

#[test]
fn the_ends_are_handed_out_once() {
    let q: StreamQueue<4> = StreamQueue::new();
    assert!(q.split().is_some());
    assert!(q.split().is_none());
}

#[test]
fn concurrent_producer_and_consumer_lose_nothing_unreported() {
    static Q: StreamQueue<16> = StreamQueue::starting_at(u32::MAX - 1000);
    const ITEMS: u32 = 400_000;
    let (mut p, mut c) = Q.split().unwrap();
    let producer = std::thread::spawn(move || {
        let mut refused = Vec::new();
        for k in 0..ITEMS {
            if p.push(&item(k)).is_err() {
                refused.push(k);
            }
        }
        refused
    });
    let mut got = Vec::new();
    loop {
        match c.pop() {
            Some(it) => got.push(it),
            None if producer.is_finished() && Q.is_empty() => break,
            None => std::hint::spin_loop(),
        }
    }
    let refused = producer.join().unwrap();
    // Every popped item is whole and they come in order.
    for w in got.windows(2) {
        assert!(w[0].index < w[1].index, "out of order: {} then {}", w[0].index, w[1].index);
    }
    for it in &got {
        assert_eq!(*it, item(it.index), "torn item {}", it.index);
    }
    // Popped + refused = pushed, each exactly once.
    let mut all: Vec<u32> = got.iter().map(|i| i.index).chain(refused.iter().copied()).collect();
    all.sort_unstable();
    assert_eq!(all, (0..ITEMS).collect::<Vec<_>>());
    assert!(!got.is_empty());
}
