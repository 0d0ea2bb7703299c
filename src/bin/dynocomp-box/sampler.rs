//! The hard-real-time sample path, at register level (RM0440 names).
//!
//! ```text
//!  TIM2 update ──TRGO──► ADC1 (PA0, IN1,  Fx) ──DMA1 CH1 (DMAMUX req 5)──► ring X ┐
//!     │                  ADC2 (PA1, IN2,  Fy) ──DMA1 CH2 (DMAMUX req 36)─► ring Y ├─► TIM2 IRQ
//!     │                  ADC3 (PB0, IN12, Fz) ──DMA1 CH3 (DMAMUX req 37)─► ring Z ┘   (CC1, P0)
//!     └─ CC1 match, Oversampling::irq_delay_ns after the update ──────────────────────────┘
//!  TIM2 IRQ: read newest codes ─► dynocomp_core::sample::process_sample ─► DAC1 CH1 (PA4),
//!            DAC1 CH2 (PA5), DAC2 CH1 (PA6)
//! ```
//!
//! * One 32-bit timer (TIM2, 170 MHz, no prescaler) overflows at fs. Its
//!   update event is TRGO (`TIMx_CR2.MMS = 010`), which starts one regular
//!   conversion on all three ADCs at once (`ADC_CFGR.EXTSEL = 11` =
//!   `tim2_trgo` for ADC1/2 and ADC3/4/5, `EXTEN = 01` rising edge). The ADCs
//!   run from HCLK/4 = 42.5 MHz in synchronous mode (`ADCx_CCR.CKMODE = 11`),
//!   so the trigger-to-sample latency is fixed (no clock-domain jitter).
//! * Each ADC's DMA request (`ADC_CFGR.DMAEN = 1`, `DMACFG = 1` circular)
//!   moves its 12-bit result into its own circular ring of [`RING_LEN`]
//!   half-words (`DMA_CCRx.CIRC = 1`, `MINC = 1`). No DMA interrupts.
//! * The same timer's capture/compare 1 event fires `Oversampling::irq_delay_ns`
//!   after the update, when the three conversions and transfers are done,
//!   and raises the TIM2 interrupt at the highest priority (P0). The handler
//!   is the thin shell of DESIGN.md: it reads the three DMA counters
//!   (`DMA_CNDTRx`), lets [`RingCursor`] say which ring entry is the newest
//!   complete sample and how many were skipped, calls
//!   [`process_sample`], and writes the three DAC holding registers
//!   (`DAC_DHR12Rx`, no DAC trigger: the output follows one APB cycle later).
//! * Missed deadlines are counted in [`SampleState::note_overruns`], from two
//!   sources: samples the rings show were skipped, and a compare event that
//!   arrived while the handler was still running (`TIMx_SR.CC1IF` set again
//!   at exit).
//! * The handler's cost: the DWT cycle counter (`DWT_CYCCNT`, enabled at
//!   boot by [`enable_cycle_counter`]) is read as the handler's first step
//!   and after the sample is output; `dynocomp_core::cycles::IsrCycles`
//!   keeps last/max/mean, published in [`TELEMETRY`] for the USB status.
//!
//! Why not the embassy-stm32 ADC/DAC drivers: they are async and wake a task
//! from the DMA interrupt; this path has to run to completion in an interrupt
//! at a fixed time after each trigger, on three ADCs started by one event.
//! embassy still does clocks, RCC enables, GPIO/EXTI, the watchdog and time.
//!
//! * ADC hardware oversampling (`ADC_CFGR2`), the interrupt delay and the
//!   timer setting come from pure core functions (`shell::adc_oversampling`,
//!   `timer_divider`, `compare_offset_ticks`); the per-sample decisions
//!   (mode, filter resets on leaving bypass or on an image switch, auto-zero)
//!   are `shell::SamplePath::tick` around `sample::process_sample`, and the
//!   switch itself is `handoff::ImageHandoff`. The handler only moves data
//!   between them, the registers and the atomics.
//!
//! All `unsafe` of the firmware is in this module, each use with its
//! justification (plus the NMI handler in `slots.rs`, an `unsafe fn` by
//! cortex-m-rt's rule, with a safe body).

use core::cell::UnsafeCell;
use core::mem::MaybeUninit;
use core::sync::atomic::{
    compiler_fence, AtomicBool, AtomicU32,
    Ordering::{Acquire, Relaxed, Release, SeqCst},
};

use cortex_m::peripheral::{DCB, DWT};
use dynocomp_core::cycles::IsrCycles;
use dynocomp_core::handoff::ImageHandoff;
use dynocomp_core::image::BoxImage;
use dynocomp_core::protocol::{StatusCounters, StreamSample};
use dynocomp_core::sample::{BypassReason, SampleState};
use dynocomp_core::shell::{
    adc_oversampling, compare_offset_ticks, timer_divider, ActiveImage, Oversampling, RingCursor, SamplePath,
    TimerDivider, ARR_MAX_32, BOX_ADC_CLOCK_HZ, BOX_SAMPLE_HALF_CYCLES, BOX_TIMER_CLOCK_HZ,
};
use dynocomp_core::stream_queue::{Producer, StreamItem, StreamQueue};
use dynocomp_core::AXES;
use embassy_stm32::interrupt;
use embassy_stm32::interrupt::{InterruptExt, Priority};
use embassy_stm32::pac;
use embassy_stm32::pac::adc::vals::{Adcaldif, Dmacfg, Dmaen, Exten, Ovrmod, Res, SampleTime, Trovs};
use embassy_stm32::pac::adccommon::vals::Ckmode;
use embassy_stm32::pac::bdma::vals::{Dir, Pl, Size};
use embassy_stm32::pac::dac::vals::Mode as DacMode;
use embassy_stm32::pac::gpio::vals::{Moder, Pupdr};
use embassy_stm32::pac::timer::vals::Mms;
use embassy_stm32::{peripherals, rcc, Peri};

/// Entries per DMA ring. The interrupt may be held off (critical sections of
/// the lower-priority code, debugger) for up to `RING_LEN - 1` samples
/// before skipped samples stop being counted exactly: 155 µs at 200 kHz.
pub const RING_LEN: u16 = 32;
const RING: usize = RING_LEN as usize;

/// ADC sampling time (`ADC_SMPRx.SMPy`): 24.5 cycles = 0.58 µs, enough for a
/// low-impedance (op-amp) front end; see docs/firmware.md. Must agree with
/// `dynocomp_core::shell::BOX_SAMPLE_HALF_CYCLES` (49 half cycles), from
/// which the oversampling ratio and the interrupt delay are computed.
const SAMPLE_TIME: SampleTime = SampleTime::CYCLES24_5;
const _: () = assert!(BOX_SAMPLE_HALF_CYCLES == 49);

/// Streamed samples the interrupt can queue for the USB task (a power of
/// two).
pub const STREAM_QUEUE_LEN: usize = 128;

/// The queue of streamed samples from the interrupt to the USB task
/// (`dynocomp_core::stream_queue`: no panic path in `push`).
pub static STREAM_QUEUE: StreamQueue<STREAM_QUEUE_LEN> = StreamQueue::new();
/// `ADC_CFGR.EXTSEL` of `tim2_trgo` (adc_ext_trg11) for ADC1..ADC5 (RM0440
/// "ADC1/ADC2/ADC3/ADC4/ADC5 - External triggers for regular channels").
const EXTSEL_TIM2_TRGO: u8 = 11;
/// DMAMUX1 request IDs (RM0440 "DMAMUX: assignment of multiplexer inputs to resources").
const DMAREQ_ADC1: u8 = 5;
const DMAREQ_ADC2: u8 = 36;
const DMAREQ_ADC3: u8 = 37;
/// DMA1 channels (0-based index = channel number - 1 = DMAMUX1 channel).
const DMA_CH: [usize; AXES] = [0, 1, 2];
/// `DAC_MCR.HFSEL = 10`: AHB clock above 160 MHz (RM0440 DAC_MCR).
const DAC_HFSEL_ABOVE_160MHZ: u8 = 0b10;
/// First DAC value (mid-scale) until the first sample.
const DAC_MIDSCALE: u16 = 2048;
/// Bound of the busy-waits on hardware flags during start-up.
const SPIN_LIMIT: u32 = 1_000_000;

/// Peripherals the sample path owns (taken from embassy's singletons so no
/// other code can claim them).
#[allow(dead_code)] // held for ownership only
pub struct Hardware {
    pub adc1: Peri<'static, peripherals::ADC1>,
    pub adc2: Peri<'static, peripherals::ADC2>,
    pub adc3: Peri<'static, peripherals::ADC3>,
    pub dac1: Peri<'static, peripherals::DAC1>,
    pub dac2: Peri<'static, peripherals::DAC2>,
    pub tim2: Peri<'static, peripherals::TIM2>,
    pub dma_x: Peri<'static, peripherals::DMA1_CH1>,
    pub dma_y: Peri<'static, peripherals::DMA1_CH2>,
    pub dma_z: Peri<'static, peripherals::DMA1_CH3>,
    /// Fx in (ADC1_IN1, Arduino A0).
    pub fx_in: Peri<'static, peripherals::PA0>,
    /// Fy in (ADC2_IN2, Arduino A1).
    pub fy_in: Peri<'static, peripherals::PA1>,
    /// Fz in (ADC3_IN12, Arduino A3).
    pub fz_in: Peri<'static, peripherals::PB0>,
    /// Fx out (DAC1_OUT1, Arduino A2).
    pub fx_out: Peri<'static, peripherals::PA4>,
    /// Fy out (DAC1_OUT2, Arduino D13, also LD2).
    pub fy_out: Peri<'static, peripherals::PA5>,
    /// Fz out (DAC2_OUT1, Arduino D12).
    pub fz_out: Peri<'static, peripherals::PA6>,
}

/// Why the sample path could not start.
#[derive(Clone, Copy, Debug, defmt::Format)]
pub enum StartError {
    /// No timer setting for this rate.
    Rate(u32),
    /// An ADC did not finish calibration / become ready (ADC number).
    Adc(u8),
    /// A DAC channel did not become ready (DAC number, channel 1/2).
    Dac(u8, u8),
    /// The DMA rings were linked into CCM SRAM, which the DMA cannot reach.
    RingsNotDmaReachable(u32),
    /// `start` was called twice.
    AlreadyRunning,
}

/// Timing the sample path runs with.
#[derive(Clone, Copy, Debug, defmt::Format)]
pub struct Timing {
    /// Requested rate (Hz).
    pub fs_hz: u32,
    /// TIM2 prescaler / auto-reload.
    pub divider: TimerDivider,
    /// Counter value of the sample interrupt (TIM2_CCR1).
    pub irq_at_tick: u32,
    /// ADC hardware oversampling and the trigger-to-interrupt delay.
    pub oversampling: Oversampling,
    /// Rate obtained (mHz).
    pub actual_fs_millihz: u64,
    /// Rate error (ppm).
    pub error_ppm: i64,
}

/// Timer and ADC setting for `fs_hz` on the 170 MHz TIM2 and the 42.5 MHz
/// ADCs: oversampling ratio and interrupt delay from
/// `dynocomp_core::shell::adc_oversampling`.
pub fn timing_for(fs_hz: u32) -> Result<Timing, StartError> {
    let divider = timer_divider(BOX_TIMER_CLOCK_HZ, fs_hz, ARR_MAX_32).ok_or(StartError::Rate(fs_hz))?;
    let oversampling =
        adc_oversampling(fs_hz, BOX_ADC_CLOCK_HZ, BOX_SAMPLE_HALF_CYCLES).ok_or(StartError::Rate(fs_hz))?;
    let irq_at_tick =
        compare_offset_ticks(&divider, BOX_TIMER_CLOCK_HZ, oversampling.irq_delay_ns).ok_or(StartError::Rate(fs_hz))?;
    Ok(Timing {
        fs_hz,
        divider,
        irq_at_tick,
        oversampling,
        actual_fs_millihz: divider.actual_fs_millihz(BOX_TIMER_CLOCK_HZ),
        error_ppm: divider.error_ppm(BOX_TIMER_CLOCK_HZ, fs_hz),
    })
}

// ------------------------------------------------------------ telemetry --

/// Set by the button task and the USB `SetBypass` request: force bypass.
pub static USER_BYPASS: AtomicBool = AtomicBool::new(false);

/// Set by the USB task (`AutoZero` request): average this many samples for
/// an offset auto-zero (0 = no request). Taken by the interrupt.
pub static AUTO_ZERO_REQUEST: AtomicU32 = AtomicU32::new(0);

/// Streaming decimation the USB task asks for (0 = not streaming): the
/// interrupt queues every sample whose index is a multiple of it.
pub static STREAM_DECIMATION: AtomicU32 = AtomicU32::new(0);

/// Counters the interrupt publishes for the status and USB tasks (relaxed
/// atomics: single-word stores, no locking on the sample path).
pub struct Telemetry {
    /// Samples processed.
    pub samples: AtomicU32,
    /// Missed deadlines (skipped samples + handler overran the next event).
    pub overruns: AtomicU32,
    /// Interrupts that found no complete conversion (trigger/ADC timing fault).
    pub late: AtomicU32,
    /// Interrupts that found an impossible DMA counter (DMA stopped).
    pub dma_faults: AtomicU32,
    /// Samples with the ADC at a rail, per axis.
    pub saturated: [AtomicU32; AXES],
    /// Runaway-guard state resets, per axis.
    pub resets: [AtomicU32; AXES],
    /// Streamed samples dropped because the USB queue was full.
    pub stream_dropped: AtomicU32,
    /// Whether the last sample ran the compensator.
    pub compensating: AtomicBool,
    /// Completed auto-zeros (the offsets below belong to the latest).
    pub auto_zero_done: AtomicU32,
    /// Refused or failed auto-zeros (busy, input at a rail).
    pub auto_zero_failed: AtomicU32,
    /// ADC offsets (code of 0 N, f32 bits) of the latest auto-zero.
    pub auto_zero_offsets: [AtomicU32; AXES],
    /// Core clock cycles of the last sample interrupt's body (DWT CYCCNT;
    /// 0 = counter not running).
    pub isr_cycles_last: AtomicU32,
    /// Most cycles of any sample interrupt's body since boot.
    pub isr_cycles_max: AtomicU32,
    /// Mean cycles over the last complete window of
    /// `dynocomp_core::cycles::MEAN_WINDOW` samples.
    pub isr_cycles_mean: AtomicU32,
}

/// The published counters.
pub static TELEMETRY: Telemetry = Telemetry {
    samples: AtomicU32::new(0),
    overruns: AtomicU32::new(0),
    late: AtomicU32::new(0),
    dma_faults: AtomicU32::new(0),
    saturated: [AtomicU32::new(0), AtomicU32::new(0), AtomicU32::new(0)],
    resets: [AtomicU32::new(0), AtomicU32::new(0), AtomicU32::new(0)],
    stream_dropped: AtomicU32::new(0),
    compensating: AtomicBool::new(false),
    auto_zero_done: AtomicU32::new(0),
    auto_zero_failed: AtomicU32::new(0),
    auto_zero_offsets: [AtomicU32::new(0), AtomicU32::new(0), AtomicU32::new(0)],
    isr_cycles_last: AtomicU32::new(0),
    isr_cycles_max: AtomicU32::new(0),
    isr_cycles_mean: AtomicU32::new(0),
};

/// A copy of [`TELEMETRY`] at one instant (fields read one by one).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, defmt::Format)]
pub struct Snapshot {
    pub samples: u32,
    pub overruns: u32,
    pub late: u32,
    pub dma_faults: u32,
    pub saturated: [u32; AXES],
    pub resets: [u32; AXES],
    pub stream_dropped: u32,
    pub compensating: bool,
    pub auto_zero_done: u32,
    pub auto_zero_failed: u32,
    pub isr_cycles_last: u32,
    pub isr_cycles_max: u32,
    pub isr_cycles_mean: u32,
}

fn load3(a: &[AtomicU32; AXES]) -> [u32; AXES] {
    let [x, y, z] = a;
    [x.load(Relaxed), y.load(Relaxed), z.load(Relaxed)]
}

impl Telemetry {
    /// Read all counters.
    pub fn snapshot(&self) -> Snapshot {
        Snapshot {
            samples: self.samples.load(Relaxed),
            overruns: self.overruns.load(Relaxed),
            late: self.late.load(Relaxed),
            dma_faults: self.dma_faults.load(Relaxed),
            saturated: load3(&self.saturated),
            resets: load3(&self.resets),
            stream_dropped: self.stream_dropped.load(Relaxed),
            compensating: self.compensating.load(Relaxed),
            auto_zero_done: self.auto_zero_done.load(Relaxed),
            auto_zero_failed: self.auto_zero_failed.load(Relaxed),
            isr_cycles_last: self.isr_cycles_last.load(Relaxed),
            isr_cycles_max: self.isr_cycles_max.load(Relaxed),
            isr_cycles_mean: self.isr_cycles_mean.load(Relaxed),
        }
    }

    /// ADC offsets of the latest auto-zero (codes).
    pub fn auto_zero_offsets(&self) -> [f32; AXES] {
        load3(&self.auto_zero_offsets).map(f32::from_bits)
    }

    fn publish(&self, st: &SampleState, compensating: bool) {
        let c = &st.counters;
        self.samples.store(c.samples, Relaxed);
        self.overruns.store(c.overruns, Relaxed);
        for (dst, &src) in self.saturated.iter().zip(c.saturated.iter()) {
            dst.store(src, Relaxed);
        }
        for (dst, n) in self.resets.iter().zip(st.nonfinite_resets()) {
            dst.store(n, Relaxed);
        }
        self.compensating.store(compensating, Relaxed);
    }

    #[inline(always)]
    fn publish_cycles(&self, c: &IsrCycles) {
        self.isr_cycles_last.store(c.last(), Relaxed);
        self.isr_cycles_max.store(c.max(), Relaxed);
        self.isr_cycles_mean.store(c.mean(), Relaxed);
    }
}

impl Snapshot {
    /// The counters of the USB status reply.
    pub fn status_counters(&self) -> StatusCounters {
        StatusCounters {
            samples: self.samples,
            overruns: self.overruns,
            saturated: self.saturated,
            nonfinite_resets: self.resets,
            stream_dropped: self.stream_dropped,
            isr_cycles_last: self.isr_cycles_last,
            isr_cycles_max: self.isr_cycles_max,
            isr_cycles_mean: self.isr_cycles_mean,
        }
    }
}

// ------------------------------------------------------- image buffers --

/// What the store gave: a verified image, or why the box is in bypass.
pub type Stored = Result<BoxImage, BypassReason>;

/// The two coefficient-image buffers of `dynocomp_core::handoff`: the
/// interrupt uses `[HANDOFF.active()]`, the USB task fills the other one.
/// Each holds an `ActiveImage`: the image checks (offline-only, rate, CPU
/// budget) run when it is written (`start`, `hand_over`, outside the
/// interrupt), and the interrupt reads their stored verdict.
struct ImageBuffers([UnsafeCell<MaybeUninit<ActiveImage>>; 2]);
// SAFETY: accesses follow the ImageHandoff protocol (see `hand_over` and
// `Sampler::on_tick`): the USB task writes only the buffer `writable()`
// returns, which the interrupt does not use, and the interrupt reads (and,
// for an auto-zero, writes) only the active one.
unsafe impl Sync for ImageBuffers {}
static IMAGES: ImageBuffers =
    ImageBuffers([UnsafeCell::new(MaybeUninit::uninit()), UnsafeCell::new(MaybeUninit::uninit())]);
/// Which buffer the interrupt uses; a new image is switched in between two
/// samples.
static HANDOFF: ImageHandoff = ImageHandoff::new(0);

/// USB task: hand a verified image to the sample interrupt, which switches
/// to it at the next sample boundary (and resets the filter state). Returns
/// `false` if the previous switch is still pending (retry after a sample
/// period) or the sample path is not running.
pub fn hand_over(image: BoxImage) -> bool {
    if !SAMPLER_READY.load(Acquire) {
        return false;
    }
    let Some(i) = HANDOFF.writable() else {
        return false;
    };
    let Some(buf) = IMAGES.0.get(i) else {
        return false;
    };
    // SAFETY: `i` is the spare buffer: no switch is pending, so the
    // interrupt uses the other one and will not look at this one until
    // `publish` (Release) below. Only this task calls `hand_over`.
    unsafe { (*buf.get()).write(ActiveImage::new(Ok(image))) };
    HANDOFF.publish(i)
}

// ---------------------------------------------------- interrupt context --

/// Everything the sample interrupt owns.
pub struct Sampler {
    path: SamplePath,
    cursor: RingCursor,
    stream: Producer<'static, STREAM_QUEUE_LEN>,
    cycles: IsrCycles,
}

impl Sampler {
    /// The sample path; streamed samples go to `stream`.
    pub fn new(stream: Producer<'static, STREAM_QUEUE_LEN>) -> Self {
        Sampler { path: SamplePath::new(), cursor: RingCursor::new(RING_LEN), stream, cycles: IsrCycles::new() }
    }

    /// One sample interrupt, given the three DMA counters; returns whether
    /// a sample was output. Never panics.
    /// The decisions are `dynocomp_core::shell::SamplePath`'s (host-tested);
    /// this only moves data between it, the registers and the atomics.
    #[inline(always)]
    fn on_tick(&mut self, ndtr: [u16; AXES]) -> bool {
        // A new image: switch between two samples.
        if HANDOFF.take().is_some() {
            self.path.on_image_switch();
        }
        let Some(buf) = IMAGES.0.get(HANDOFF.active()) else {
            return false;
        };
        // SAFETY: the active buffer was initialised (by `start` or by
        // `hand_over` before its publish), and only this handler, which
        // cannot preempt itself, accesses it until a later switch.
        let stored = unsafe { (*buf.get()).assume_init_mut() };

        let Some(step) = self.cursor.advance(&ndtr) else {
            TELEMETRY.dma_faults.fetch_add(1, Relaxed);
            return false;
        };
        if step.available == 0 {
            // Conversion not complete yet: nothing to output; the sample is
            // picked up (and the skip counted) at the next interrupt.
            TELEMETRY.late.fetch_add(1, Relaxed);
            return false;
        }
        self.path.state.note_overruns(step.missed());
        let codes = read_codes(step.newest);

        let request = AUTO_ZERO_REQUEST.swap(0, Relaxed);
        if request != 0 && self.path.request_auto_zero(request).is_err() {
            TELEMETRY.auto_zero_failed.fetch_add(1, Relaxed);
        }
        let out = self.path.tick(codes, stored, USER_BYPASS.load(Relaxed));
        write_dacs(out.dac);
        TELEMETRY.publish(&self.path.state, out.compensating);
        match out.auto_zero {
            Some(Ok(offsets)) => {
                for (dst, o) in TELEMETRY.auto_zero_offsets.iter().zip(offsets) {
                    dst.store(o.to_bits(), Relaxed);
                }
                TELEMETRY.auto_zero_done.fetch_add(1, Relaxed);
            }
            Some(Err(_)) => {
                TELEMETRY.auto_zero_failed.fetch_add(1, Relaxed);
            }
            None => {}
        }

        // Stream every `decimation`-th sample; a full queue is counted.
        let decimation = STREAM_DECIMATION.load(Relaxed);
        let index = self.path.state.counters.samples;
        if decimation != 0 && index.is_multiple_of(decimation) {
            let item = StreamItem {
                index,
                step: decimation,
                sample: StreamSample { raw: codes, out: out.dac, flags: out.flags.0 },
            };
            if self.stream.push(&item).is_err() {
                TELEMETRY.stream_dropped.fetch_add(1, Relaxed);
            }
        }
        true
    }
}

/// Storage that only the TIM2 interrupt touches once the sampler is running.
/// Uninitialised (in .bss/.uninit, not a `.data` copy in flash) until
/// `start` writes it and sets `SAMPLER_READY`.
struct IsrOwned(UnsafeCell<MaybeUninit<Sampler>>);
// SAFETY: written once by `start` before the TIM2 interrupt is enabled, then
// accessed only from the TIM2 handler, which cannot preempt itself.
unsafe impl Sync for IsrOwned {}
static SAMPLER: IsrOwned = IsrOwned(UnsafeCell::new(MaybeUninit::uninit()));
static SAMPLER_READY: AtomicBool = AtomicBool::new(false);

/// The DMA rings: `[axis][entry]`, written by DMA1 CH1..3.
#[repr(C, align(4))]
struct Rings(UnsafeCell<[[u16; RING]; AXES]>);
// SAFETY: written only by the DMA; the CPU only reads with volatile loads.
unsafe impl Sync for Rings {}
static RINGS: Rings = Rings(UnsafeCell::new([[0; RING]; AXES]));

fn ring_addr(axis: usize) -> u32 {
    // Address arithmetic only; no reference to DMA-written memory is formed.
    (RINGS.0.get() as *const u16).wrapping_add(axis * RING) as u32
}

/// The three 12-bit codes at ring index `idx`.
#[inline(always)]
fn read_codes(idx: u16) -> [u16; AXES] {
    let i = usize::from(idx) % RING;
    let base = RINGS.0.get() as *const u16;
    let mut codes = [0u16; AXES];
    for (axis, c) in codes.iter_mut().enumerate() {
        // SAFETY: axis < AXES and i < RING, so the element is inside RINGS;
        // volatile because the DMA writes it behind the compiler's back
        // (half-word DMA writes are single bus transfers, never torn).
        *c = unsafe { core::ptr::read_volatile(base.add(axis * RING + i)) } & 0x0FFF;
    }
    codes
}

/// Write the three DAC holding registers (12-bit right aligned).
#[inline(always)]
fn write_dacs(dac: [u16; AXES]) {
    let [x, y, z] = dac;
    pac::DAC1.dhr12r(0).write(|w| w.set_dhr(x));
    pac::DAC1.dhr12r(1).write(|w| w.set_dhr(y));
    pac::DAC2.dhr12r(0).write(|w| w.set_dhr(z));
}

/// The sample interrupt. Runs from CCM SRAM (`.ccmram_text`, memory.x;
/// copied there at reset by `ccm.rs`): everything on the sample path is
/// inlined into it (the handler, `Sampler::on_tick`, `SamplePath::tick`,
/// `process_sample`, the kernel), and what it still calls is linked into
/// CCM SRAM too (tests/firmware_layout.rs checks both in the ELF).
#[interrupt]
#[link_section = ".ccmram_text.TIM2"]
fn TIM2() {
    // Cycle counter at the start of the body (exception entry and the
    // prologue's register saves come before it; docs/firmware.md, "Reading
    // the sample interrupt's cost"). The fences keep the compiler from
    // moving the handler's memory accesses across the two readings.
    let start = DWT::cycle_count();
    compiler_fence(SeqCst);
    let tim = pac::TIM2;
    // Acknowledge CC1 (TIMx_SR flags are rc_w0: writing 1 leaves a flag alone).
    let mut ack = pac::timer::regs::SrGp16(0xFFFF_FFFF);
    ack.set_ccif(0, false);
    tim.sr().write_value(ack);

    let ndtr = DMA_CH.map(|ch| pac::DMA1.ch(ch).ndtr().read().ndt());

    if !SAMPLER_READY.load(Acquire) {
        return;
    }
    // SAFETY: SAMPLER_READY is set only after `start` initialised SAMPLER,
    // and from then on this handler (which cannot preempt itself) is its
    // only accessor, so this is the one live reference.
    let sampler = unsafe { (*SAMPLER.0.get()).assume_init_mut() };
    if sampler.on_tick(ndtr) {
        // Cost of this sample: start of the handler to the sample output
        // and published (interrupts that output no sample are not counted).
        compiler_fence(SeqCst);
        let end = DWT::cycle_count();
        sampler.cycles.record(start, end);
        TELEMETRY.publish_cycles(&sampler.cycles);
    }

    // The next compare event came while this one was being handled: that
    // sample's deadline is missed (it is processed late, or skipped and then
    // also counted by the ring cursor as a separate sample).
    if tim.sr().read().ccif(0) {
        sampler.path.state.note_overruns(1);
        TELEMETRY.overruns.store(sampler.path.state.counters.overruns, Relaxed);
    }
}

// ------------------------------------------------------------- start-up --

/// Start the DWT cycle counter (`DEMCR.TRCENA`, then `DWT_CTRL.CYCCNTENA`),
/// which the sample interrupt reads (`DWT::cycle_count`, a read-only
/// register access) to measure its own cost. Returns whether it runs; if
/// not, every `isr_cycles_*` figure stays 0 ("not measured").
pub fn enable_cycle_counter(dcb: &mut DCB, dwt: &mut DWT) -> bool {
    if !DWT::has_cycle_counter() {
        return false;
    }
    dcb.enable_trace();
    dwt.enable_cycle_counter();
    DWT::cycle_counter_enabled()
}

fn spin_until(mut done: impl FnMut() -> bool) -> bool {
    for _ in 0..SPIN_LIMIT {
        if done() {
            return true;
        }
    }
    false
}

fn set_analog(port: pac::gpio::Gpio, pin: usize) {
    port.pupdr().modify(|w| w.set_pupdr(pin, Pupdr::FLOATING));
    port.moder().modify(|w| w.set_moder(pin, Moder::ANALOG));
}

/// RM0440 §21.4.6-21.4.9: leave deep power-down, start the regulator.
fn adc_wake(adc: pac::adc::Adc) {
    adc.cr().modify(|w| w.set_deeppwd(false));
    adc.cr().modify(|w| w.set_advregen(true));
}

/// Calibrate (single-ended), enable, and configure one channel, triggered by
/// TIM2 TRGO, with hardware oversampling `os`, results to circular DMA.
fn adc_setup(adc: pac::adc::Adc, n: u8, channel: u8, os: &Oversampling) -> Result<(), StartError> {
    adc.cr().modify(|w| {
        w.set_adcaldif(Adcaldif::SINGLE_ENDED);
        w.set_adcal(true);
    });
    if !spin_until(|| !adc.cr().read().adcal()) {
        return Err(StartError::Adc(n));
    }
    // ADEN may be set only 4 ADC clock cycles after ADCAL cleared.
    cortex_m::asm::delay(200);
    adc.isr().write(|w| w.set_adrdy(true));
    adc.cr().modify(|w| w.set_aden(true));
    if !spin_until(|| adc.isr().read().adrdy()) {
        return Err(StartError::Adc(n));
    }
    adc.isr().write(|w| w.set_adrdy(true));

    let ch = usize::from(channel);
    if ch < 10 {
        adc.smpr().modify(|w| w.set_smp(ch, SAMPLE_TIME));
    } else {
        adc.smpr2().modify(|w| w.set_smp(ch - 10, SAMPLE_TIME));
    }
    adc.sqr1().write(|w| {
        w.set_l(0); // one conversion
        w.set_sq(0, channel);
    });
    adc.cfgr().modify(|w| {
        w.set_res(Res::BITS12);
        w.set_align(false);
        w.set_cont(false);
        w.set_extsel(EXTSEL_TIM2_TRGO);
        w.set_exten(Exten::RISING_EDGE);
        w.set_dmaen(Dmaen::ENABLE);
        w.set_dmacfg(Dmacfg::CIRCULAR);
        w.set_ovrmod(Ovrmod::OVERWRITE);
    });
    // Regular oversampling (RM0440 §21.4.30): `ratio` conversions back to
    // back per trigger (TROVS = 0), sum >> shift = their 12-bit mean; one
    // DMA request per oversampled result.
    adc.cfgr2().write(|w| {
        w.set_rovse(os.enabled());
        w.set_ovsr(os.ovsr);
        w.set_ovss(os.shift);
        w.set_trovs(Trovs::AUTOMATIC);
    });
    Ok(())
}

/// DMA1 channel `ch` (0-based) moves `adc`'s data register into ring `axis`.
fn dma_setup(ch: usize, request: u8, adc: pac::adc::Adc, axis: usize) {
    let c = pac::DMA1.ch(ch);
    c.cr().write(|w| w.set_en(false));
    pac::DMAMUX1.ccr(ch).write(|w| w.set_dmareq_id(request));
    c.par().write_value(adc.dr().as_ptr() as u32);
    c.mar().write_value(ring_addr(axis));
    c.ndtr().write(|w| w.set_ndt(RING_LEN));
    c.cr().write(|w| {
        w.set_dir(Dir::FROM_PERIPHERAL);
        w.set_circ(true);
        w.set_minc(true);
        w.set_pinc(false);
        w.set_psize(Size::BITS16);
        w.set_msize(Size::BITS16);
        w.set_pl(Pl::VERY_HIGH);
        w.set_en(true);
    });
}

/// Bring up DACs, ADCs, DMA and TIM2 and start sampling at `timing` with
/// the store's boot result `image` (a verified image or the bypass reason).
pub fn start(_hw: Hardware, timing: &Timing, image: Stored, sampler: Sampler) -> Result<(), StartError> {
    // The DMA cannot reach CCM SRAM (0x2001_8000.., RM0440 §2.1 bus matrix).
    let rings = ring_addr(0);
    if rings >= 0x2001_8000 {
        return Err(StartError::RingsNotDmaReachable(rings));
    }

    // Clocks (RCC_AHB2ENR.ADC12EN/ADC345EN/DAC1EN/DAC2EN, RCC_APB1ENR1.TIM2EN).
    // ADC1 and ADC2 share one enable/reset bit: enable both before any setup.
    rcc::enable_and_reset::<peripherals::ADC1>();
    rcc::enable_and_reset::<peripherals::ADC2>();
    rcc::enable_and_reset::<peripherals::ADC3>();
    rcc::enable_and_reset::<peripherals::DAC1>();
    rcc::enable_and_reset::<peripherals::DAC2>();
    rcc::enable_and_reset::<peripherals::TIM2>();

    // Pins: analog mode, no pull (GPIOx_MODER = 11, GPIOx_PUPDR = 00).
    for (port, pin) in
        [(pac::GPIOA, 0), (pac::GPIOA, 1), (pac::GPIOB, 0), (pac::GPIOA, 4), (pac::GPIOA, 5), (pac::GPIOA, 6)]
    {
        set_analog(port, pin);
    }

    // DACs: high-frequency interface mode for HCLK > 160 MHz, normal mode
    // with output buffer to the pin, mid-scale until the first sample.
    for dac in [pac::DAC1, pac::DAC2] {
        dac.mcr().modify(|w| w.set_hfsel(DAC_HFSEL_ABOVE_160MHZ));
    }
    pac::DAC1.mcr().modify(|w| {
        w.set_mode(0, DacMode::NORMAL_EXT_BUFEN);
        w.set_mode(1, DacMode::NORMAL_EXT_BUFEN);
    });
    pac::DAC2.mcr().modify(|w| w.set_mode(0, DacMode::NORMAL_EXT_BUFEN));
    write_dacs([DAC_MIDSCALE; AXES]);
    pac::DAC1.cr().modify(|w| {
        w.set_en(0, true);
        w.set_en(1, true);
    });
    pac::DAC2.cr().modify(|w| w.set_en(0, true));
    for (dac, n, ch) in [(pac::DAC1, 1u8, 0usize), (pac::DAC1, 1, 1), (pac::DAC2, 2, 0)] {
        if !spin_until(|| dac.sr().read().dacrdy(ch)) {
            return Err(StartError::Dac(n, ch as u8 + 1));
        }
    }

    // ADC clock: synchronous HCLK/4 = 42.5 MHz (ADC12_CCR / ADC345_CCR.CKMODE = 11).
    for common in [pac::ADC12_COMMON, pac::ADC345_COMMON] {
        common.ccr().modify(|w| w.set_ckmode(Ckmode::SYNC_DIV4));
    }
    let adcs = [pac::ADC1, pac::ADC2, pac::ADC3];
    for adc in adcs {
        adc_wake(adc);
    }
    // t_ADCVREG_STUP = 20 µs (datasheet); 25 µs at 170 MHz.
    cortex_m::asm::delay(170 * 25);
    let os = &timing.oversampling;
    adc_setup(pac::ADC1, 1, 1, os)?; // PA0 = ADC1_IN1
    adc_setup(pac::ADC2, 2, 2, os)?; // PA1 = ADC2_IN2
    adc_setup(pac::ADC3, 3, 12, os)?; // PB0 = ADC3_IN12

    dma_setup(DMA_CH[0], DMAREQ_ADC1, pac::ADC1, 0);
    dma_setup(DMA_CH[1], DMAREQ_ADC2, pac::ADC2, 1);
    dma_setup(DMA_CH[2], DMAREQ_ADC3, pac::ADC3, 2);

    // TIM2: update -> TRGO (conversions), CC1 -> interrupt after the conversions.
    let tim = pac::TIM2;
    tim.cr1().write(|w| w.set_cen(false));
    tim.psc().write_value(timing.divider.psc);
    tim.arr().write_value(timing.divider.arr);
    tim.ccr(0).write_value(timing.irq_at_tick);
    tim.cr2().modify(|w| w.set_mms(Mms::UPDATE));
    // Load PSC/ARR now. Its TRGO pulse is ignored: the ADCs are not armed yet.
    tim.egr().write(|w| w.set_ug(true));
    tim.sr().write_value(pac::timer::regs::SrGp16(0));
    // Start just past the compare point so the first event is a trigger.
    tim.cnt().write_value(timing.irq_at_tick + 1);
    tim.dier().write(|w| w.set_ccie(0, true));
    // Freeze TIM2 (and the IWDG) while a debugger halts the core.
    pac::DBGMCU.apb1lfzr().modify(|w| {
        w.set_tim2(true);
        w.set_iwdg(true);
    });

    if SAMPLER_READY.load(Acquire) {
        // `start` consumed `Hardware`, which exists once: cannot happen.
        return Err(StartError::AlreadyRunning);
    }
    let Some(first) = IMAGES.0.get(HANDOFF.active()) else {
        return Err(StartError::AlreadyRunning);
    };
    // SAFETY: SAMPLER_READY is false and the TIM2 interrupt is not enabled,
    // so nothing else accesses SAMPLER or the image buffers (`hand_over`
    // refuses until SAMPLER_READY); after the flag only the handler uses
    // SAMPLER and the active buffer.
    unsafe {
        (*first.get()).write(ActiveImage::new(image));
        (*SAMPLER.0.get()).write(sampler);
    }
    SAMPLER_READY.store(true, Release);

    // Arm the ADCs: each now converts on every TIM2 TRGO rising edge.
    for adc in adcs {
        adc.cr().modify(|w| w.set_adstart(true));
    }

    interrupt::TIM2.set_priority(Priority::P0);
    interrupt::TIM2.unpend();
    // SAFETY: the handler above is defined and its state initialised.
    unsafe { interrupt::TIM2.enable() };
    tim.cr1().modify(|w| w.set_cen(true));
    Ok(())
}

/// ADC overrun flags (`ADC_ISR.OVR`) since the last call, cleared on read.
/// With circular DMA an overrun means the DMA missed a conversion result.
pub fn take_adc_overruns() -> [bool; AXES] {
    [pac::ADC1, pac::ADC2, pac::ADC3].map(|adc| {
        let ovr = adc.isr().read().ovr();
        if ovr {
            adc.isr().write(|w| w.set_ovr(true));
        }
        ovr
    })
}
