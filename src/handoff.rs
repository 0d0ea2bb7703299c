//! Switching the sample path to a new coefficient image at a sample
//! boundary, without a lock the interrupt could wait on.
//!
//! The firmware keeps two image buffers (`[CoeffImage; 2]`, or `Option`s).
//! The sample interrupt reads only `buffers[active]`; the USB task writes
//! only the other one. [`ImageHandoff`] holds the two indices as atomics
//! (load/store only: no read-modify-write, so it works on any Cortex-M):
//!
//! * **USB task** (after [`crate::store::Store::commit`]):
//!   1. `let i = handoff.writable()?` — the spare buffer, or `None` while a
//!      previous switch is still pending (retry after one sample period);
//!   2. fill `buffers[i]` with [`crate::store::Store::load_active`];
//!   3. `handoff.publish(i)` (Release: the buffer writes happen before).
//! * **Sample interrupt**, first thing in every sample:
//!   `if let Some(i) = handoff.take() { active = i; state.reset_filters(); }`
//!   (Acquire: sees the complete buffer). The switch therefore happens
//!   between two samples; the filter memory of the old image is cleared
//!   because it means nothing to the new one.
//!
//! The buffer accesses themselves are the firmware's (`unsafe` with this
//! protocol as the safety argument, or a `critical_section::Mutex` per
//! buffer). The protocol guarantees that the task never writes the buffer
//! the interrupt reads: `writable` returns the spare index only when no
//! switch is pending, and the interrupt changes `active` before it clears
//! `pending`.

use core::sync::atomic::{AtomicU8, Ordering};

/// "No switch pending".
const NONE: u8 = 0xFF;

/// Index handoff between the USB task (producer) and the sample interrupt
/// (consumer) for double-buffered coefficient images.
#[derive(Debug)]
pub struct ImageHandoff {
    active: AtomicU8,
    pending: AtomicU8,
}

impl ImageHandoff {
    /// Start with buffer `active` (0 or 1) in use and nothing pending.
    pub const fn new(active: u8) -> Self {
        ImageHandoff { active: AtomicU8::new(active & 1), pending: AtomicU8::new(NONE) }
    }

    /// Task: the buffer it may write now, or `None` while a switch is pending.
    pub fn writable(&self) -> Option<usize> {
        if self.pending.load(Ordering::Acquire) != NONE {
            return None;
        }
        Some(1 - usize::from(self.active.load(Ordering::Acquire) & 1))
    }

    /// Task: hand buffer `i` (from [`writable`](Self::writable), now fully
    /// written) to the interrupt. Returns `false` (and does nothing) if `i`
    /// is not the writable buffer.
    pub fn publish(&self, i: usize) -> bool {
        if self.writable() != Some(i) {
            return false;
        }
        self.pending.store(i as u8, Ordering::Release);
        true
    }

    /// Interrupt, at a sample boundary: the buffer to switch to, if a switch
    /// is pending; it becomes the active one.
    pub fn take(&self) -> Option<usize> {
        let p = self.pending.load(Ordering::Acquire);
        if p == NONE {
            return None;
        }
        self.active.store(p & 1, Ordering::Release);
        self.pending.store(NONE, Ordering::Release);
        Some(usize::from(p & 1))
    }

    /// The buffer the interrupt uses.
    pub fn active(&self) -> usize {
        usize::from(self.active.load(Ordering::Acquire) & 1)
    }
}
