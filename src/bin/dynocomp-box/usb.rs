//! USB CDC-ACM link of the box (embassy-usb on the G474's USB FS device,
//! PA12 = D+, PA11 = D−), in a thread-mode task below every interrupt:
//!
//! * received bytes → `protocol::FrameDecoder` → `link::BoxLink::on_frame`
//!   (status, bypass, stream on/off, auto-zero, upload through the A/B
//!   `store::Store` on the internal flash) → reply frame;
//! * the `link::Actions` of a request are applied here: user bypass, the
//!   auto-zero request to the interrupt, stream decimation, and after a
//!   commit the new image is loaded from flash and handed to the sample
//!   interrupt (`sampler::hand_over`, switched between two samples), or, if
//!   its sample rate differs, the box reboots into it;
//! * streamed samples: the interrupt queues them (lock-free SPSC, drops
//!   counted), this task packs them into `StreamFrame`s with sequence
//!   numbers (`protocol::StreamBatcher`).
//!
//! Flash erase/program run here and block this task only: the slots are in
//! bank 2, the code in bank 1 (read-while-write), and embassy-stm32's
//! `Flash` (not its region API) programs without a critical section, so the
//! sample interrupt keeps running.

use defmt::{info, warn};
use dynocomp_core::image::BoxImage;
use dynocomp_core::link::{Actions, BoxLink, Telemetry};
use dynocomp_core::protocol::{encode_frame, BoxMessage, FrameDecoder, StreamBatcher, MAX_FRAME};
use dynocomp_core::sample::{select_stored_mode, Mode};
use dynocomp_core::shell::{apply_adc_offsets, image_switch, parse_version, ImageSwitch, BOX_CORE_CLOCK_HZ};
use dynocomp_core::store::Store;
use dynocomp_core::stream_queue::Consumer;
use embassy_futures::join::join;
use embassy_futures::select::{select, Either};
use embassy_stm32::flash::{Blocking, Flash};
use embassy_stm32::peripherals::USB;
use embassy_stm32::usb::Driver;
use embassy_time::{Duration, Timer};
use embassy_usb::class::cdc_acm::{CdcAcmClass, State};
use embassy_usb::driver::EndpointError;

use crate::sampler::{
    hand_over, Stored, AUTO_ZERO_REQUEST, STREAM_DECIMATION, STREAM_QUEUE_LEN, TELEMETRY, USER_BYPASS,
};

/// USB IDs: pid.codes test VID/PID (0x1209/0x0001), for development only;
/// a product needs its own.
const USB_VID: u16 = 0x1209;
const USB_PID: u16 = 0x0001;
/// Full-speed bulk packet size.
const PACKET: usize = 64;
/// How often the task looks at the stream queue when no request comes.
const STREAM_POLL: Duration = Duration::from_millis(2);
/// Most queued samples packed per poll, so requests are still served
/// while streaming.
const STREAM_ITEMS_PER_POLL: usize = 64;
/// Auto-zero averaging time (samples = fs / this), 100 ms.
const AUTO_ZERO_PER_SECOND: u32 = 10;
/// Firmware version for the status reply.
const FIRMWARE: [u8; 3] = parse_version(env!("CARGO_PKG_VERSION"));

/// The internal flash through embassy-stm32's blocking driver (NOR-flash
/// traits, offsets from 0x0800_0000, 8-byte writes, 2 KiB pages).
pub type BoxFlash = Flash<'static, Blocking>;

/// What the USB task owns.
pub struct Link {
    /// The A/B coefficient store (after `Store::boot`).
    pub store: Store<BoxFlash>,
    /// This task's copy of the image the sample path runs (for the status).
    pub image: Stored,
    /// Sample rate the sample path runs at (Hz).
    pub fs_hz: u32,
    /// Streamed samples from the interrupt.
    pub stream: Consumer<'static, STREAM_QUEUE_LEN>,
}

/// The USB device and the protocol loop.
#[embassy_executor::task]
pub async fn usb_task(driver: Driver<'static, USB>, link: &'static mut Link) {
    let mut config = embassy_usb::Config::new(USB_VID, USB_PID);
    config.manufacturer = Some("dynocomp");
    config.product = Some("dynocomp compensator box");
    config.serial_number = None;
    config.max_power = 100;
    config.max_packet_size_0 = PACKET as u8;

    // The USB stack borrows its buffers for the driver's 'static lifetime.
    let config_descriptor = defmt::unwrap!(cortex_m::singleton!(: [u8; 128] = [0; 128]));
    let bos_descriptor = defmt::unwrap!(cortex_m::singleton!(: [u8; 32] = [0; 32]));
    let msos_descriptor = defmt::unwrap!(cortex_m::singleton!(: [u8; 0] = [0; 0]));
    let control_buf = defmt::unwrap!(cortex_m::singleton!(: [u8; 64] = [0; 64]));
    let state = defmt::unwrap!(cortex_m::singleton!(: State<'static> = State::new()));
    let mut builder =
        embassy_usb::Builder::new(driver, config, config_descriptor, bos_descriptor, msos_descriptor, control_buf);
    let mut class = CdcAcmClass::new(&mut builder, state, PACKET as u16);
    let mut device = builder.build();
    join(device.run(), serve(&mut class, link)).await;
}

type Class = CdcAcmClass<'static, Driver<'static, USB>>;

/// Send one encoded frame in packets (a zero-length packet ends a frame
/// that fills its last packet, so the host sees it at once).
async fn send(class: &mut Class, frame: &[u8]) -> Result<(), EndpointError> {
    for chunk in frame.chunks(PACKET) {
        class.write_packet(chunk).await?;
    }
    if frame.len().is_multiple_of(PACKET) {
        class.write_packet(&[]).await?;
    }
    Ok(())
}

async fn send_message(class: &mut Class, msg: &BoxMessage) -> Result<(), EndpointError> {
    let mut tx = [0u8; MAX_FRAME];
    match encode_frame(msg, &mut tx) {
        Ok(n) => send(class, tx.get(..n).unwrap_or(&[])).await,
        Err(e) => {
            // Every message type fits MAX_PAYLOAD (protocol tests); log if not.
            warn!("USB: reply not encodable: {}", defmt::Debug2Format(&e));
            Ok(())
        }
    }
}

/// The status the link handler reports.
fn telemetry(image: &Stored, fs_hz: u32, stream_next_seq: u32) -> Telemetry<'_> {
    let bypass = match select_stored_mode(image, USER_BYPASS.load(core::sync::atomic::Ordering::Relaxed)) {
        Mode::Compensate(_) => None,
        Mode::Bypass(r) => Some(r),
    };
    Telemetry {
        firmware: FIRMWARE,
        fs_hz,
        core_clock_hz: BOX_CORE_CLOCK_HZ,
        bypass,
        image: image.as_ref().ok(),
        counters: TELEMETRY.snapshot().status_counters(),
        stream_next_seq,
    }
}

/// Apply what a request asked of the sample path.
async fn apply(act: Actions, link: &mut Link) {
    use core::sync::atomic::Ordering::Relaxed;
    if let Some(on) = act.bypass {
        USER_BYPASS.store(on, Relaxed);
        info!("USB: user bypass {}", if on { "ON" } else { "OFF" });
    }
    if act.auto_zero {
        let n = (link.fs_hz / AUTO_ZERO_PER_SECOND).clamp(1, dynocomp_core::shell::AUTO_ZERO_MAX_SAMPLES);
        AUTO_ZERO_REQUEST.store(n, Relaxed);
        info!("USB: auto-zero over {} samples", n);
    }
    if let Some(stream) = act.stream {
        // (A stop was already handled before the reply.)
        STREAM_DECIMATION.store(stream.map_or(0, u32::from), Relaxed);
    }
    if act.switch_image {
        switch_image(link).await;
    }
}

/// Pack up to `max` queued samples into stream frames and send the full
/// ones; returns how many samples were taken from the queue.
async fn pump_stream(
    link: &mut Link,
    batcher: &mut StreamBatcher,
    class: &mut Class,
    max: usize,
) -> Result<usize, EndpointError> {
    let mut packed = 0;
    while packed < max {
        let Some(item) = link.stream.pop() else {
            break;
        };
        packed += 1;
        // The step of the samples in the queue is the index difference the
        // interrupt used; a change of decimation closes the frame.
        let step = u16::try_from(item.step).unwrap_or(u16::MAX);
        if let Some(frame) = batcher.push(item.index, step, item.sample) {
            send_message(class, &BoxMessage::Stream(frame)).await?;
        }
    }
    Ok(packed)
}

/// After a commit: run the new image.
async fn switch_image(link: &mut Link) {
    let img: BoxImage = match link.store.load_active() {
        Ok(img) => img,
        Err(r) => {
            // The store verified it before committing; keep running the old one.
            warn!("USB: committed image does not load ({}); sample path unchanged", r);
            return;
        }
    };
    match image_switch(link.fs_hz, &img) {
        ImageSwitch::AtSampleBoundary => {
            // A previous switch may be pending for one sample period.
            for _ in 0..100 {
                if hand_over(img) {
                    info!("USB: new image {=u32:#010x} handed to the sample path", img.id());
                    link.image = Ok(img);
                    return;
                }
                Timer::after_micros(100).await;
            }
            warn!("USB: sample path did not take the new image; it runs after a reset");
        }
        ImageSwitch::Reboot { from_hz, to_hz } => {
            info!("USB: new image runs at {} Hz (now {} Hz): rebooting", to_hz, from_hz);
            // Let the commit's Ack leave before the reset.
            Timer::after_millis(50).await;
            cortex_m::peripheral::SCB::sys_reset();
        }
    }
}

/// Serve one host connection after another.
async fn serve(class: &mut Class, link: &mut Link) -> ! {
    use core::sync::atomic::Ordering::Relaxed;
    let mut rx = [0u8; PACKET];
    let mut seen_auto_zero = TELEMETRY.snapshot().auto_zero_done;
    loop {
        class.wait_connection().await;
        info!("USB: host connected");
        let mut handler = BoxLink::new();
        let mut decoder = FrameDecoder::new();
        let mut batcher = StreamBatcher::new();
        STREAM_DECIMATION.store(0, Relaxed);
        let result: Result<(), EndpointError> = async {
            loop {
                // The latest auto-zero shows in this task's image copy too.
                let done = TELEMETRY.snapshot().auto_zero_done;
                if done != seen_auto_zero {
                    seen_auto_zero = done;
                    let offsets = TELEMETRY.auto_zero_offsets();
                    if let Ok(img) = link.image.as_mut() {
                        apply_adc_offsets(img, offsets);
                    }
                    info!("auto-zero: ADC offsets {} codes", offsets);
                }

                match select(class.read_packet(&mut rx), Timer::after(STREAM_POLL)).await {
                    Either::First(n) => {
                        let n = n?;
                        for &b in rx.get(..n).unwrap_or(&[]) {
                            let Some(frame) = decoder.push_byte(b) else {
                                continue;
                            };
                            let mut act = Actions::default();
                            // `tel` in its own scope: not kept in the task's
                            // future across the awaits below (static RAM).
                            let msg = {
                                let tel = telemetry(&link.image, link.fs_hz, batcher.next_seq());
                                handler.on_frame(frame, &mut link.store, &tel, &mut act)
                            };
                            if act.stream == Some(None) {
                                // Stop: the last frames go out before the Ack.
                                STREAM_DECIMATION.store(0, Relaxed);
                                pump_stream(link, &mut batcher, class, usize::MAX).await?;
                                if let Some(f) = batcher.flush() {
                                    send_message(class, &BoxMessage::Stream(f)).await?;
                                }
                            }
                            send_message(class, &msg).await?;
                            apply(act, link).await;
                        }
                    }
                    Either::Second(()) => {}
                }

                if STREAM_DECIMATION.load(Relaxed) == 0 {
                    // Not streaming: drop what the interrupt queued before.
                    while link.stream.pop().is_some() {}
                    continue;
                }
                let packed = pump_stream(link, &mut batcher, class, STREAM_ITEMS_PER_POLL).await?;
                if packed == 0 {
                    // Queue empty: send the partial frame rather than hold it.
                    if let Some(frame) = batcher.flush() {
                        send_message(class, &BoxMessage::Stream(frame)).await?;
                    }
                }
            }
        }
        .await;
        if let Err(e) = result {
            info!("USB: host gone ({})", defmt::Debug2Format(&e));
        }
        STREAM_DECIMATION.store(0, Relaxed);
    }
}
