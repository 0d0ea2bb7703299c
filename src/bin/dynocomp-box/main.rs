//! dynocomp box firmware (STM32G474RE, Nucleo-G474RE): samples Fx, Fy, Fz
//! from the charge amplifiers, runs the compensator of the coefficient image
//! in flash and outputs the compensated forces on three DACs.
//!
//! * Boot: 170 MHz from the 24 MHz HSE crystal (48 MHz USB clock from
//!   HSI48, trimmed by the CRS from the host's start-of-frame); open the A/B
//!   coefficient store on the internal flash (`dynocomp_core::store`): the
//!   newest valid slot wins, none valid = bypass; say over defmt why the box
//!   is in bypass if it is.
//! * Sample path (`sampler.rs`): TIM2 → ADC1/2/3 (hardware oversampling) →
//!   DMA rings → TIM2 interrupt (highest priority) → `process_sample` → DAC1
//!   CH1/CH2, DAC2 CH1; offset auto-zero, image switch at a sample boundary,
//!   stream queue.
//! * Thread-mode tasks: status (defmt every second, LED, watchdog), the
//!   user button (toggles bypass) and USB CDC (`usb.rs`: status, stream,
//!   bypass, auto-zero, coefficient upload).
//!
//! See docs/firmware.md for pins, wiring, build and run.
#![no_std]
#![no_main]

mod ccm;
mod sampler;
mod slots;
mod usb;

use defmt::{error, info, warn};
use dynocomp_core::sample::{select_stored_mode, BypassReason, Mode};
use dynocomp_core::shell::{
    box_sample_rate, led_on, led_state, LedState, Slot, BOX_CORE_CLOCK_HZ, DEFAULT_FS_HZ, LED_PATTERN_TICKS,
};
use dynocomp_core::store::{Layout, Store};
use embassy_executor::Spawner;
use embassy_stm32::exti::{self, ExtiInput};
use embassy_stm32::flash::Flash;
use embassy_stm32::gpio::{Level, Output, Pull, Speed};
use embassy_stm32::interrupt::{self, InterruptExt, Priority};
use embassy_stm32::time::Hertz;
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_stm32::{bind_interrupts, peripherals, Config, Peri};
use embassy_time::{Duration, Ticker, Timer};
use sampler::{Hardware, Sampler, Snapshot, STREAM_QUEUE, TELEMETRY, USER_BYPASS};
use {defmt_rtt as _, panic_probe as _};

bind_interrupts!(struct Irqs {
    EXTI15_10 => exti::InterruptHandler<interrupt::typelevel::EXTI15_10>;
    USB_LP => embassy_stm32::usb::InterruptHandler<peripherals::USB>;
});

/// Status LED period and pattern resolution.
const TICK: Duration = Duration::from_millis(100);
/// Ticks per status report (1 s) = one LED pattern.
const TICKS_PER_REPORT: u32 = LED_PATTERN_TICKS;
/// Watchdog timeout: the status task pets it only while samples flow.
const WATCHDOG_TIMEOUT_US: u32 = 1_000_000;
/// Button debounce time.
const DEBOUNCE: Duration = Duration::from_millis(30);

/// What the box decided at boot, for the status reports.
#[derive(Clone, Copy, defmt::Format)]
struct BootInfo {
    /// Why the box is in bypass without the user asking (None = image runs).
    reason: Option<BypassReason>,
    /// Slot of the image or of the reported error.
    slot: Option<Slot>,
    /// Sample rate (Hz, as requested; the timer's exact rate is logged at boot).
    fs_hz: u32,
}

fn clock_config() -> Config {
    use embassy_stm32::rcc::{
        AHBPrescaler, APBPrescaler, Hse, HseMode, Pll, PllMul, PllPreDiv, PllRDiv, PllSource, Sysclk,
    };
    let mut config = Config::default();
    // Nucleo-G474RE: 24 MHz crystal X3 on HSE. 24 / 6 * 85 / 2 = 170 MHz.
    config.rcc.hse = Some(Hse { freq: Hertz(24_000_000), mode: HseMode::Oscillator });
    config.rcc.pll = Some(Pll {
        source: PllSource::HSE,
        prediv: PllPreDiv::DIV6,
        mul: PllMul::MUL85,
        divp: None,
        divq: None,
        divr: Some(PllRDiv::DIV2),
    });
    config.rcc.sys = Sysclk::PLL1_R;
    // Range 1 boost mode, required above 150 MHz.
    config.rcc.boost = true;
    // APB1 = APB2 = HCLK = 170 MHz, so TIM2 counts at 170 MHz
    // (dynocomp_core::shell::BOX_TIMER_CLOCK_HZ).
    config.rcc.ahb_pre = AHBPrescaler::DIV1;
    config.rcc.apb1_pre = APBPrescaler::DIV1;
    config.rcc.apb2_pre = APBPrescaler::DIV1;
    // USB: 48 MHz from HSI48, kept on frequency by the CRS from the host's
    // 1 kHz start-of-frame packets (RM0440 §7.2.4, §8).
    config.rcc.hsi48 = Some(embassy_stm32::rcc::Hsi48Config { sync_from_usb: true });
    config.rcc.mux.clk48sel = embassy_stm32::rcc::mux::Clk48sel::HSI48;
    // Nothing of embassy's own DMA use may compete with the sample interrupt.
    config.bdma_interrupt_priority = Priority::P6;
    config
}

#[embassy_executor::main]
async fn main(spawner: Spawner) {
    let p = embassy_stm32::init(clock_config());
    // The sample interrupt (TIM2) alone runs at P0; embassy's time driver
    // (TIM3) and the button (EXTI15_10) below it.
    interrupt::TIM3.set_priority(Priority::P4);
    interrupt::EXTI15_10.set_priority(Priority::P6);
    interrupt::USB_LP.set_priority(Priority::P6);
    info!("dynocomp box {} starting", env!("CARGO_PKG_VERSION"));

    // ---- coefficient store and mode
    let flash = Flash::new_blocking(p.FLASH);
    let mut store = if slots::memory_x_matches_store() {
        match Store::open(flash, Layout::STM32G474RE) {
            Ok(st) => Some(st),
            Err(e) => {
                error!("coefficient store: flash geometry refused: {}", e);
                None
            }
        }
    } else {
        error!("memory.x slot symbols disagree with dynocomp_core::store; store not opened");
        None
    };
    let (image, slot) = match store.as_mut() {
        Some(st) => {
            let boot = st.boot();
            (boot.image, boot.active.map(|a| a.slot))
        }
        None => (Err(BypassReason::NoImage), None),
    };
    let ecc = slots::FLASH_ECC_ERRORS.load(core::sync::atomic::Ordering::Relaxed);
    if ecc != 0 {
        warn!("{} flash double-ECC error(s) while scanning the slots (torn write); that slot is ignored", ecc);
    }
    let boot_mode = select_stored_mode(&image, false);
    let reason = match boot_mode {
        Mode::Compensate(img) => {
            info!(
                "compensating: slot {}, image {=u32:#010x} (format {}), fs = {} Hz, latency {} samples",
                slot,
                img.id(),
                img.format_version(),
                img.fs_hz(),
                img.latency_samples()
            );
            None
        }
        Mode::Bypass(r) => {
            warn!("BYPASS (raw forces out): {}", r);
            Some(r)
        }
    };
    let fs_hz = box_sample_rate(&boot_mode);

    // ---- sample path
    let timing = match sampler::timing_for(fs_hz) {
        Ok(t) => t,
        Err(e) => {
            error!("no timer setting for {} Hz ({}); using {} Hz", fs_hz, e, DEFAULT_FS_HZ);
            defmt::unwrap!(sampler::timing_for(DEFAULT_FS_HZ))
        }
    };
    info!(
        "sampling at {} Hz: TIM2 PSC={} ARR={}, actual {=u64} mHz ({=i64} ppm), IRQ at tick {}; ADC oversampling {}x",
        timing.fs_hz,
        timing.divider.psc,
        timing.divider.arr,
        timing.actual_fs_millihz,
        timing.error_ppm,
        timing.irq_at_tick,
        timing.oversampling.ratio
    );
    let hw = Hardware {
        adc1: p.ADC1,
        adc2: p.ADC2,
        adc3: p.ADC3,
        dac1: p.DAC1,
        dac2: p.DAC2,
        tim2: p.TIM2,
        dma_x: p.DMA1_CH1,
        dma_y: p.DMA1_CH2,
        dma_z: p.DMA1_CH3,
        fx_in: p.PA0,
        fy_in: p.PA1,
        fz_in: p.PB0,
        fx_out: p.PA4,
        fy_out: p.PA5,
        fz_out: p.PA6,
    };
    // DWT cycle counter: the sample interrupt measures its own cost with it
    // (status `isr_cycles_*`, docs/firmware.md). Nothing else in the
    // firmware or embassy takes the cortex-m core peripherals.
    let cycle_counter = match cortex_m::Peripherals::take() {
        Some(mut cp) => sampler::enable_cycle_counter(&mut cp.DCB, &mut cp.DWT),
        None => false,
    };
    if cycle_counter {
        info!("DWT cycle counter on: sample interrupt cost in cycles of {} Hz", BOX_CORE_CLOCK_HZ);
    } else {
        warn!("DWT cycle counter not available: the sample interrupt's cost is not measured (0)");
    }
    let (producer, consumer) = defmt::unwrap!(STREAM_QUEUE.split());
    let usb_image = image;
    let started = match sampler::start(hw, &timing, image, Sampler::new(producer)) {
        Ok(()) => {
            info!("sample path running");
            true
        }
        Err(e) => {
            error!("sample path failed to start: {}; outputs are not driven", e);
            false
        }
    };

    let boot = BootInfo { reason, slot, fs_hz: timing.fs_hz };

    // ---- lower-priority tasks
    // Status LED on PB5 (Arduino D4): LD2 sits on PA5, which is DAC1_OUT2.
    let led = Output::new(p.PB5, Level::Low, Speed::Low);
    let watchdog = if started {
        let mut wd = IndependentWatchdog::new(p.IWDG, WATCHDOG_TIMEOUT_US);
        wd.unleash();
        Some(wd)
    } else {
        None
    };
    spawner.spawn(defmt::unwrap!(status_task(boot, led, watchdog, started)));
    spawner.spawn(defmt::unwrap!(button_task(p.PC13, p.EXTI13)));

    // ---- USB (needs the store; without it the box still samples)
    if let Some(store) = store {
        let driver = embassy_stm32::usb::Driver::new(p.USB, Irqs, p.PA12, p.PA11);
        // In a static, not in the task's future (the store holds a 3 KiB
        // read-back buffer, the image copy another 3 KiB).
        let link = defmt::unwrap!(cortex_m::singleton!(: usb::Link = usb::Link {
            store,
            image: usb_image,
            fs_hz: timing.fs_hz,
            stream: consumer,
        }));
        spawner.spawn(defmt::unwrap!(usb::usb_task(driver, link)));
    }
}

/// Every 100 ms: LED pattern and watchdog (only while samples flow).
/// Every second: counters over defmt.
#[embassy_executor::task]
async fn status_task(
    boot: BootInfo,
    mut led_pin: Output<'static>,
    mut watchdog: Option<IndependentWatchdog<'static, peripherals::IWDG>>,
    started: bool,
) {
    let mut ticker = Ticker::every(TICK);
    let mut tick = 0u32;
    let mut last = Snapshot::default();
    let mut last_tick_samples = 0u32;
    let mut adc_ovr = [0u32; 3];
    let mut shown = led_state(started, false, false, false);
    loop {
        ticker.next().await;
        let now = TELEMETRY.snapshot();

        // Pet the watchdog only if the sample interrupt made progress: a
        // hung sample path resets the box.
        if now.samples != last_tick_samples {
            if let Some(wd) = watchdog.as_mut() {
                wd.pet();
            }
        }
        last_tick_samples = now.samples;

        tick += 1;
        if tick >= TICKS_PER_REPORT {
            tick = 0;
            for (count, ovr) in adc_ovr.iter_mut().zip(sampler::take_adc_overruns()) {
                *count = count.wrapping_add(u32::from(ovr));
            }
            let faults = now.overruns != last.overruns
                || now.late != last.late
                || now.dma_faults != last.dma_faults
                || now.resets != last.resets;
            let saturated = now.saturated != last.saturated;
            shown = led_state(started, faults, saturated, now.compensating);
            let mode_reason = if now.compensating {
                None
            } else if USER_BYPASS.load(core::sync::atomic::Ordering::Relaxed) {
                Some(BypassReason::User)
            } else {
                boot.reason
            };
            match mode_reason {
                None => info!(
                    "compensating (slot {}) | {} samples/s @ {} Hz | overruns {} late {} dma {} | sat {} | resets {} | adc ovr {} | isr cycles mean {} max {}",
                    boot.slot,
                    now.samples.wrapping_sub(last.samples),
                    boot.fs_hz,
                    now.overruns,
                    now.late,
                    now.dma_faults,
                    now.saturated,
                    now.resets,
                    adc_ovr,
                    now.isr_cycles_mean,
                    now.isr_cycles_max
                ),
                Some(r) => info!(
                    "bypass ({}) | {} samples/s @ {} Hz | overruns {} late {} dma {} | sat {} | adc ovr {} | isr cycles mean {} max {}",
                    r,
                    now.samples.wrapping_sub(last.samples),
                    boot.fs_hz,
                    now.overruns,
                    now.late,
                    now.dma_faults,
                    now.saturated,
                    adc_ovr,
                    now.isr_cycles_mean,
                    now.isr_cycles_max
                ),
            }
            if matches!(shown, LedState::Fault | LedState::Saturated) {
                warn!("in the last second: {}", shown);
            }
            last = now;
        }
        if led_on(shown, tick) {
            led_pin.set_high();
        } else {
            led_pin.set_low();
        }
    }
}

/// User button B1 (PC13) toggles bypass. The pin's idle level is read at
/// start, so the board's button polarity does not matter.
#[embassy_executor::task]
async fn button_task(pin: Peri<'static, peripherals::PC13>, ch: Peri<'static, peripherals::EXTI13>) {
    // The Nucleo has its own pull resistor on B1.
    let mut button = ExtiInput::new(pin, ch, Pull::None, Irqs);
    Timer::after(DEBOUNCE).await;
    let idle_high = button.is_high();
    loop {
        button.wait_for_any_edge().await;
        Timer::after(DEBOUNCE).await;
        if button.is_high() == idle_high {
            continue; // bounce or glitch
        }
        let bypass = !USER_BYPASS.load(core::sync::atomic::Ordering::Relaxed);
        USER_BYPASS.store(bypass, core::sync::atomic::Ordering::Relaxed);
        info!("button: user bypass {}", if bypass { "ON" } else { "OFF" });
        // Wait for release.
        while button.is_high() != idle_high {
            button.wait_for_any_edge().await;
            Timer::after(DEBOUNCE).await;
        }
    }
}
