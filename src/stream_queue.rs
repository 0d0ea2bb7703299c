//! The queue of streamed samples from the sample interrupt to the USB task:
//! a lock-free single-producer, single-consumer ring in safe Rust, whose
//! `push` has no panic path and no division.
//!
//! Why not `heapless::spsc`: its 0.9 `Producer` keeps the capacity as a
//! run-time slice length and computes `(tail + 1) % capacity`, so the
//! compiler keeps a division-by-zero panic in the sample interrupt (the
//! firmware must have none there). Here the capacity `N` is a power of two
//! known at compile time, the indices are free-running `u32` counters, and
//! a slot is `index & (N − 1)`.
//!
//! A queued item is stored as [`WORDS`] `AtomicU32`s, so every access is an
//! atomic load or store (plain `ldr`/`str` on the Cortex-M4) and the queue
//! needs no `unsafe`. The producer writes the item's words, then publishes
//! `tail` with `Release`; the consumer reads `tail` with `Acquire`, then the
//! words, then publishes `head` with `Release`; the producer reads `head`
//! with `Acquire` before reusing a slot. With one producer and one consumer
//! (what [`StreamQueue::split`] hands out, once) every item is read whole
//! and in order.

use core::sync::atomic::{
    AtomicBool, AtomicU32,
    Ordering::{AcqRel, Acquire, Relaxed, Release},
};

use crate::protocol::StreamSample;

/// One streamed sample as the interrupt queues it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StreamItem {
    /// Sample index (the sample counter after this sample).
    pub index: u32,
    /// The decimation it was taken with (index step to the next one).
    pub step: u32,
    /// Codes in/out and flags.
    pub sample: StreamSample,
}

/// `u32` words per queued [`StreamItem`].
pub const WORDS: usize = 6;

impl StreamItem {
    /// The item as queue words: index, step, then the six 16-bit codes two
    /// per word (low half first), then the flags.
    pub fn to_words(&self) -> [u32; WORDS] {
        let [r0, r1, r2] = self.sample.raw.map(u32::from);
        let [o0, o1, o2] = self.sample.out.map(u32::from);
        [self.index, self.step, r0 | r1 << 16, r2 | o0 << 16, o1 | o2 << 16, u32::from(self.sample.flags)]
    }

    /// The item back from [`to_words`](Self::to_words).
    pub fn from_words(w: [u32; WORDS]) -> Self {
        let lo = |v: u32| (v & 0xffff) as u16;
        let hi = |v: u32| (v >> 16) as u16;
        StreamItem {
            index: w[0],
            step: w[1],
            sample: StreamSample {
                raw: [lo(w[2]), hi(w[2]), lo(w[3])],
                out: [hi(w[3]), lo(w[4]), hi(w[4])],
                flags: (w[5] & 0xff) as u8,
            },
        }
    }
}

/// A ring of `N` [`StreamItem`]s (`N` a power of two, 2..=2³¹).
pub struct StreamQueue<const N: usize> {
    slots: [[AtomicU32; WORDS]; N],
    /// Items taken so far (free-running, written by the consumer).
    head: AtomicU32,
    /// Items queued so far (free-running, written by the producer).
    tail: AtomicU32,
    /// Whether [`split`](Self::split) has handed out the two ends.
    split: AtomicBool,
}

impl<const N: usize> Default for StreamQueue<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> StreamQueue<N> {
    /// Compile-time check of `N`.
    const VALID: () = assert!(N.is_power_of_two() && N >= 2 && N <= 1 << 31, "N must be a power of two in 2..=2^31");

    /// An empty queue (usable in a `static`).
    pub const fn new() -> Self {
        Self::starting_at(0)
    }

    /// An empty queue whose counters start at `start` (tests of the
    /// counters wrapping around 2³²; [`new`](Self::new) starts at 0).
    pub const fn starting_at(start: u32) -> Self {
        #[allow(clippy::let_unit_value)]
        let () = Self::VALID;
        StreamQueue {
            slots: [const { [const { AtomicU32::new(0) }; WORDS] }; N],
            head: AtomicU32::new(start),
            tail: AtomicU32::new(start),
            split: AtomicBool::new(false),
        }
    }

    /// The producer and consumer ends, the first time only (`None` after
    /// that): one context pushes, one pops.
    pub fn split(&self) -> Option<(Producer<'_, N>, Consumer<'_, N>)> {
        if self.split.swap(true, AcqRel) {
            None
        } else {
            Some((Producer { q: self }, Consumer { q: self }))
        }
    }

    /// Items in the queue (0..=N).
    pub fn len(&self) -> usize {
        self.tail.load(Acquire).wrapping_sub(self.head.load(Acquire)) as usize
    }

    /// Whether the queue holds no item.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The slot of counter value `i` (always `Some`: `i & (N − 1) < N`).
    fn slot(&self, i: u32) -> Option<&[AtomicU32; WORDS]> {
        self.slots.get(i as usize & (N - 1))
    }
}

/// [`Producer::push`] found the queue full (the item was not queued).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct QueueFull;

/// The pushing end of a [`StreamQueue`] (the sample interrupt).
pub struct Producer<'a, const N: usize> {
    q: &'a StreamQueue<N>,
}

impl<const N: usize> Producer<'_, N> {
    /// Queue `item`; [`QueueFull`] if the queue is full (the item is
    /// dropped: the caller counts it). No panic, no division, no allocation.
    #[inline]
    pub fn push(&mut self, item: &StreamItem) -> Result<(), QueueFull> {
        let tail = self.q.tail.load(Relaxed);
        let head = self.q.head.load(Acquire);
        if tail.wrapping_sub(head) as usize >= N {
            return Err(QueueFull);
        }
        let slot = self.q.slot(tail).ok_or(QueueFull)?;
        for (dst, w) in slot.iter().zip(item.to_words()) {
            dst.store(w, Relaxed);
        }
        self.q.tail.store(tail.wrapping_add(1), Release);
        Ok(())
    }
}

/// The popping end of a [`StreamQueue`] (the USB task).
pub struct Consumer<'a, const N: usize> {
    q: &'a StreamQueue<N>,
}

impl<const N: usize> Consumer<'_, N> {
    /// The oldest queued item, or `None` if the queue is empty.
    #[inline]
    pub fn pop(&mut self) -> Option<StreamItem> {
        let head = self.q.head.load(Relaxed);
        let tail = self.q.tail.load(Acquire);
        if head == tail {
            return None;
        }
        let slot = self.q.slot(head)?;
        let words = core::array::from_fn(|i| slot.get(i).map_or(0, |w| w.load(Relaxed)));
        self.q.head.store(head.wrapping_add(1), Release);
        Some(StreamItem::from_words(words))
    }
}
