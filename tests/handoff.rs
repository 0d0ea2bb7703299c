//! The image handoff between the USB task and the sample interrupt
//! (src/handoff.rs): the task never gets the buffer the interrupt reads, a
//! switch is taken exactly once, and under a real concurrent reader every
//! "sample" sees a completely written buffer.

use dynocomp_core::handoff::ImageHandoff;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;

#[test]
fn spare_buffer_publish_and_take() {
    let h = ImageHandoff::new(0);
    assert_eq!(h.active(), 0);
    assert_eq!(h.take(), None);
    assert_eq!(h.writable(), Some(1));
    assert!(!h.publish(0), "the active buffer cannot be published");
    assert!(h.publish(1));
    // Pending: the task may write nothing until the interrupt took it.
    assert_eq!(h.writable(), None);
    assert!(!h.publish(1));
    assert_eq!(h.active(), 0);
    assert_eq!(h.take(), Some(1));
    assert_eq!(h.take(), None);
    assert_eq!(h.active(), 1);
    assert_eq!(h.writable(), Some(0));
}

/// Two "image buffers" of 64 words each; the writer fills the spare buffer
/// with one generation number in every word and publishes it; the reader
/// (the "interrupt") checks on every step that its active buffer is
/// uniform. A torn buffer would show two different values.
#[test]
fn concurrent_reader_never_sees_a_partly_written_buffer() {
    let h = Arc::new(ImageHandoff::new(0));
    let bufs: Arc<[Vec<AtomicU64>; 2]> =
        Arc::new([(0..64).map(|_| AtomicU64::new(0)).collect(), (0..64).map(|_| AtomicU64::new(0)).collect()]);
    let done = Arc::new(AtomicBool::new(false));
    let reader = {
        let (h, bufs, done) = (h.clone(), bufs.clone(), done.clone());
        std::thread::spawn(move || {
            let mut switches = 0u64;
            let mut last = 0u64;
            let mut active = h.active();
            while !done.load(Ordering::Acquire) {
                if let Some(i) = h.take() {
                    active = i;
                    switches += 1;
                }
                let b = &bufs[active];
                let first = b[0].load(Ordering::Relaxed);
                for w in b.iter() {
                    assert_eq!(w.load(Ordering::Relaxed), first, "torn buffer");
                }
                assert!(first >= last, "went back to an older image");
                last = first;
            }
            switches
        })
    };
    let mut published = 0u64;
    for gen in 1..=2000u64 {
        let i = loop {
            if let Some(i) = h.writable() {
                break i;
            }
            std::thread::yield_now();
        };
        for w in bufs[i].iter() {
            w.store(gen, Ordering::Relaxed);
        }
        assert!(h.publish(i));
        published += 1;
    }
    // Let the reader take the last one.
    while h.writable().is_none() {
        std::thread::yield_now();
    }
    done.store(true, Ordering::Release);
    let switches = reader.join().unwrap();
    assert_eq!(switches, published);
}
