//! Instruction counts per sample on the emulated Cortex-M4F (issue #6).
//!
//! Run under `qemu-system-arm -M mps2-an386 -icount shift=0` (see
//! `scripts/qemu_icount.sh`). Why the count is exact: with `-icount shift=0`
//! QEMU's virtual clock advances exactly 1 ns per executed guest instruction
//! (and with icount, reads of a timer are made precise to the instruction:
//! QEMU ends the translation block at the I/O access). SysTick counts that
//! virtual clock at the board's 25 MHz core clock, 1 tick per 40 ns = 40
//! instructions. Each case runs `SAMPLES` samples between two SysTick reads,
//! so the quantization error of the mean is ≤ 2·40/`SAMPLES` = 0.02
//! instructions per sample; the code paths have no data-dependent branches,
//! so the true per-sample count is an integer and rounding the mean gives it
//! exactly. The calibration case (two functions that differ only by 100
//! NOPs) must differ by exactly 100.00, which checks the 40 ns tick.
//!
//! Every case calls a `#[inline(never)]` function per sample, as the
//! interrupt handler would; the "empty" case (same loop, a function that
//! only returns its input) is subtracted to give the net count of the body.
//!
//! Cases, all f32, same code generation as the box firmware (opt-level 3,
//! fat LTO):
//! * `kernel Sxx`: `dynocomp_core::kernel::AxisFilter::step` with xx 2x2
//!   sections, no FIR (filter order n = 2·xx).
//! * `dense Sxx`: the dense (n+1)x(n+1) state-space update of the seed
//!   paper's eq. (6) form, [x'; y] = [A B; C D]·[x; u], for the same order:
//!   every one of the (n+1)² products is computed (the matrix is the
//!   block-diagonal [A B; C D] of the same sections; a dense update does not
//!   know its zeros, so values do not change the count).
//! * `idsp df1 Sxx`: QUARTIQ `idsp` 0.23 `Cascade<[Biquad<f32>; xx]>` (direct
//!   form I cascade, shared delay lines) — xx biquads = the same order.
//! * `idsp df2t Sxx`: xx `idsp` `Biquad<f32>`s in transposed direct form II,
//!   applied in a loop.
//! * `kernel S24+F24`: the box's full axis (24 sections + 24 FIR taps).
//! * `process_sample 3x(S24+F24)`: `dynocomp_core::sample::process_sample`,
//!   the pure body of the sample interrupt: 3 ADC codes → N, three full
//!   axes with the runaway guard, → DAC codes, flags and counters; and the
//!   same with 3 sections + 19 taps, the size `dynocomp design` chose for the
//!   bundled example.
//! * `model P R T A`: `SamplePath::tick` (the sample interrupt's decisions
//!   around `process_sample`, compensating) over A axes, each with P pole
//!   pairs, R real poles and T FIR taps, printed as one machine-readable line
//!   `model P R T A <instructions per call> <net>` (no `empty` subtraction
//!   in the first figure); `tick-minus-process_sample …` is what the
//!   decisions add to `process_sample` alone.
//! * `shell P R T A`: a replica of the firmware's sample interrupt
//!   (`sampler::TIM2` → `on_tick`: handoff, ring cursor, ring reads,
//!   auto-zero request, `SamplePath::tick`, telemetry stores, stream push,
//!   cycle statistics) without its register accesses, not streaming and
//!   streaming every sample; `shell` and `streaming` are its instructions
//!   beyond `SamplePath::tick` (`budget::SHELL_INSNS`). `tests/qemu_cost_model.rs` checks the core's
//!   cost model (`dynocomp_core::budget`) against these lines.
#![no_std]
#![no_main]

use core::hint::black_box;
use core::sync::atomic::{AtomicBool, AtomicU32, Ordering::Relaxed};
use cortex_m_rt::entry;
use cortex_m_semihosting::hprintln;
use dsp_process::SplitProcess;
use dynocomp_core::cycles::IsrCycles;
use dynocomp_core::handoff::ImageHandoff;
use dynocomp_core::image::{
    AxisChannel, AxisImage, AxisScaling, AxisSummary, BoxImage, CoeffImage, DesignMethod, MatrixImage, RowDesign,
};
use dynocomp_core::kernel::{AxisFilter, AxisState, Section};
use dynocomp_core::mimo::{MimoFilter, MimoSection, MimoState};
use dynocomp_core::protocol::StreamSample;
use dynocomp_core::sample::{process_sample, Mode, SampleState};
use dynocomp_core::shell::{ActiveImage, RingCursor, SamplePath};
use dynocomp_core::stream_queue::{Consumer, Producer, StreamItem, StreamQueue};
use dynocomp_core::AXES;
use dynocomp_qemu::{success, Ticks};
use idsp::iir::{Biquad, Cascade, DirectForm, DirectForm2Transposed};

/// Samples per case.
const SAMPLES: u32 = 4096;
/// Instructions per SysTick tick: 40 ns at 25 MHz, 1 ns per instruction.
const INSNS_PER_TICK: u32 = 40;

/// A stable 2x2 section (poles 0.99 ± 0.05j·k); the values do not change
/// the instruction count (no data-dependent branches), only keep it stable.
fn section(i: usize) -> Section {
    let w = 0.001 + 0.0015 * i as f32;
    Section { delta: [-0.002, w, -w, -0.002], b: [0.1, 0.0], c: [0.5, -0.2] }
}

fn kernel_filter(sections: usize, taps: usize) -> AxisFilter {
    let mut secs = [Section::default(); 24];
    for (i, s) in secs.iter_mut().enumerate() {
        *s = section(i);
    }
    let mut fir = [0.0f32; 24];
    for (j, h) in fir.iter_mut().enumerate() {
        *h = 0.1 / (j as f32 + 1.0);
    }
    match AxisFilter::with_fir(&secs[..sections], 0.25, &fir[..taps]) {
        Ok(f) => f,
        Err(_) => dynocomp_qemu::fail("icount: test filter rejected"),
    }
}

/// Input sample k (varied, finite, well inside the runaway limit).
#[inline(always)]
fn input(k: u32) -> f32 {
    ((k.wrapping_mul(2_654_435_761) >> 20) as f32) - 2048.0
}

/// Run `body` once per sample between two SysTick reads; instructions per sample.
#[inline(always)]
fn measure(ticks: &Ticks, mut body: impl FnMut(f32) -> f32) -> f32 {
    let mut acc = 0.0f32;
    let t0 = ticks.now();
    for k in 0..SAMPLES {
        acc += body(input(k));
    }
    let t1 = ticks.now();
    black_box(acc);
    (Ticks::elapsed(t0, t1) * INSNS_PER_TICK) as f32 / SAMPLES as f32
}

#[inline(never)]
fn empty_call(u: f32) -> f32 {
    black_box(u)
}

#[inline(never)]
fn nop100(u: f32) -> f32 {
    // SAFETY: 100 NOPs, no memory or register effects.
    unsafe { core::arch::asm!(".rept 100", "nop", ".endr", options(nomem, nostack, preserves_flags)) };
    black_box(u)
}

#[inline(never)]
fn nop200(u: f32) -> f32 {
    // SAFETY: 200 NOPs, no memory or register effects.
    unsafe { core::arch::asm!(".rept 200", "nop", ".endr", options(nomem, nostack, preserves_flags)) };
    black_box(u)
}

#[inline(never)]
fn kernel_step(f: &AxisFilter, st: &mut AxisState, u: f32) -> f32 {
    f.step(st, u)
}

#[inline(never)]
fn kernel_step_guarded(f: &AxisFilter, st: &mut AxisState, u: f32) -> f32 {
    f.step_guarded(st, u).unwrap_or(u)
}

/// Dense eq. (6) update with N1 = n + 1: `z = [x; u]`, `[x'; y] = M z`.
#[inline(never)]
fn dense_step<const N1: usize>(m: &[[f32; N1]; N1], x: &mut [f32; N1], u: f32) -> f32 {
    x[N1 - 1] = u;
    let mut out = [0.0f32; N1];
    for (o, row) in out.iter_mut().zip(m.iter()) {
        let mut s = 0.0f32;
        for (a, z) in row.iter().zip(x.iter()) {
            s += a * z;
        }
        *o = s;
    }
    x[..N1 - 1].copy_from_slice(&out[..N1 - 1]);
    out[N1 - 1]
}

/// The block-diagonal [I+Δ b; c d] of `kernel_filter`'s sections, dense.
fn dense_matrix<const N1: usize>() -> [[f32; N1]; N1] {
    let n = N1 - 1;
    let mut m = [[0.0f32; N1]; N1];
    for i in 0..n / 2 {
        let s = section(i);
        let (r0, r1) = (2 * i, 2 * i + 1);
        m[r0][r0] = 1.0 + s.delta[0];
        m[r0][r1] = s.delta[1];
        m[r1][r0] = s.delta[2];
        m[r1][r1] = 1.0 + s.delta[3];
        m[r0][n] = s.b[0];
        m[r1][n] = s.b[1];
        m[n][r0] = s.c[0];
        m[n][r1] = s.c[1];
    }
    m[n][n] = 0.25;
    m
}

fn measure_dense<const N1: usize>(ticks: &Ticks) -> f32 {
    let m = dense_matrix::<N1>();
    let mut x = [0.0f32; N1];
    measure(ticks, |u| dense_step(black_box(&m), &mut x, u))
}

/// A stable biquad: poles of z² − 1.6 z + 0.8 (|z| = 0.89).
const BIQUAD: [f32; 5] = [0.1, 0.2, 0.1, 1.6, -0.8];

#[inline(never)]
fn idsp_df1<const S: usize>(c: &Cascade<[Biquad<f32>; S]>, st: &mut DirectForm<f32, S>, u: f32) -> f32 {
    c.process(st, u)
}

fn measure_idsp_df1<const S: usize>(ticks: &Ticks) -> f32 {
    let c = Cascade(core::array::from_fn::<_, S, _>(|_| Biquad { ba: BIQUAD }));
    let mut st = DirectForm::<f32, S> { x: [0.0; 2], y: [[0.0; 2]; S] };
    measure(ticks, |u| idsp_df1(black_box(&c), &mut st, u))
}

#[inline(never)]
fn idsp_df2t<const S: usize>(c: &[Biquad<f32>; S], st: &mut [DirectForm2Transposed<f32>; S], u: f32) -> f32 {
    c.iter().zip(st.iter_mut()).fold(u, |x, (b, s)| b.process(s, x))
}

fn measure_idsp_df2t<const S: usize>(ticks: &Ticks) -> f32 {
    let c: [Biquad<f32>; S] = core::array::from_fn(|_| Biquad { ba: BIQUAD });
    let mut st: [DirectForm2Transposed<f32>; S] = core::array::from_fn(|_| DirectForm2Transposed::default());
    measure(ticks, |u| idsp_df2t(black_box(&c), &mut st, u))
}

/// A filter with `pairs` pole pairs, `reals` real poles (two per diagonal
/// section, the last one alone when `reals` is odd) and `taps` FIR taps.
fn mixed_filter(pairs: usize, reals: usize, taps: usize) -> AxisFilter {
    let mut secs = [Section::default(); 24];
    let mut n = 0;
    for (i, s) in secs.iter_mut().take(pairs).enumerate() {
        *s = section(i);
        n += 1;
    }
    let mut left = reals;
    while left > 0 && n < 24 {
        let p1 = 0.9 - 0.01 * left as f32;
        secs[n] = if left >= 2 {
            Section { delta: [p1 - 1.0, 0.0, 0.0, p1 - 1.02], b: [0.1, 0.2], c: [0.3, -0.1] }
        } else {
            Section::first_order(p1, 0.1, 0.3)
        };
        left = left.saturating_sub(2);
        n += 1;
    }
    let mut fir = [0.0f32; 24];
    for (j, h) in fir.iter_mut().enumerate() {
        *h = 0.1 / (j as f32 + 1.0);
    }
    match AxisFilter::with_fir(&secs[..n], 0.25, &fir[..taps]) {
        Ok(f) => f,
        Err(_) => dynocomp_qemu::fail("icount: mixed test filter rejected"),
    }
}

fn box_image(sections: usize, taps: usize) -> BoxImage {
    image_of(kernel_filter(sections, taps), AXES).into()
}

/// A 3x3 filter with `pairs` normal-form pairs, `diagonals` diagonal
/// sections and `taps` FIR taps, every B and C entry non-zero (dense).
fn mimo_filter(pairs: usize, diagonals: usize, taps: usize) -> MimoFilter {
    let mut secs = [MimoSection::default(); 48];
    let n = (pairs + diagonals).min(48);
    for (i, s) in secs.iter_mut().take(n).enumerate() {
        let k = i as f32;
        let b = [[0.1, -0.02 * k, 0.03], [0.01, 0.05, -0.04]];
        let c = [[0.5, -0.2], [0.03, 0.1 + 0.001 * k], [-0.02, 0.04]];
        *s = if i < pairs {
            let w = 0.001 + 0.0015 * k;
            MimoSection { delta: [-0.002, w, -w, -0.002], b, c }
        } else {
            MimoSection { delta: [-0.1 - 0.01 * k, 0.0, 0.0, -0.3], b, c }
        };
    }
    let mut fir = [[[0.0f32; 3]; 3]; 24];
    for (m, h) in fir.iter_mut().enumerate() {
        *h = [[0.01, 0.002, -0.003], [0.001, 0.01, 0.002], [-0.002, 0.001, 0.01]]
            .map(|r| r.map(|v| v / (m as f32 + 1.0)));
    }
    let d = [[1.0, 0.01, -0.02], [0.015, 1.0, 0.01], [-0.01, 0.02, 1.0]];
    match MimoFilter::new(&secs[..n], d, &fir[..taps]) {
        Ok(f) => f,
        Err(_) => dynocomp_qemu::fail("icount: 3x3 test filter rejected"),
    }
}

/// A 3x3 image of `filter` at 10 kHz (every shape of the grid fits the
/// box's budget there), scaling as [`image_of`].
fn matrix_image(filter: MimoFilter) -> BoxImage {
    let scaling = AxisScaling {
        adc_offset_code: 2048.0,
        newton_per_code: 2.5,
        dac_code_per_newton: 0.4,
        dac_offset_code: 2048.0,
    };
    let ch = |axis: u8| AxisChannel { axis, scaling, summary: AxisSummary::default() };
    BoxImage::Matrix(MatrixImage {
        fs_hz: 10_000,
        latency_samples: 4,
        flags: 0,
        method: DesignMethod::Manual,
        source_sha256: [0; 32],
        created_unix_s: 0,
        axes: [ch(0), ch(1), ch(2)],
        filter,
        rows: [RowDesign::Matrix; 3],
    })
}

#[inline(never)]
fn mimo_step(f: &MimoFilter, st: &mut MimoState, u: f32) -> f32 {
    let y = f.step(st, [u, 0.5 * u, -0.25 * u]);
    y[0] + y[1] + y[2]
}

fn image_of(filter: AxisFilter, n_axes: usize) -> CoeffImage {
    let mut img = CoeffImage {
        fs_hz: 100_000,
        latency_samples: 4,
        flags: 0,
        method: DesignMethod::Manual,
        source_sha256: [0; 32],
        created_unix_s: 0,
        axes: [None; AXES],
    };
    for (a, slot) in img.axes.iter_mut().enumerate().take(n_axes) {
        *slot = Some(AxisImage {
            axis: a as u8,
            scaling: AxisScaling {
                adc_offset_code: 2048.0,
                newton_per_code: 2.5,
                dac_code_per_newton: 0.4,
                dac_offset_code: 2048.0,
            },
            filter,
            summary: AxisSummary::default(),
        });
    }
    img
}

#[inline(never)]
fn sample_isr_body(img: &BoxImage, st: &mut SampleState, code: u16) -> u16 {
    let (dac, flags) = process_sample([code, code ^ 0x155, code ^ 0x2AA], Mode::Compensate(img), st);
    dac[0] ^ dac[1] ^ dac[2] ^ u16::from(flags.0)
}

/// The sample interrupt's decisions around `process_sample`
/// (`SamplePath::tick`: auto-zero feed, mode, filter resets), compensating.
#[inline(never)]
fn tick_body(path: &mut SamplePath, stored: &mut ActiveImage, code: u16) -> u16 {
    let out = path.tick([code, code ^ 0x155, code ^ 0x2AA], stored, false);
    out.dac[0] ^ out.dac[1] ^ out.dac[2] ^ u16::from(out.flags.0)
}

// ---- the interrupt's software shell (a replica of the firmware's
// `sampler::Sampler::on_tick` and `TIM2` without their register accesses)

/// Entries per DMA ring, as the firmware's `sampler::RING_LEN`.
const RING_LEN: u16 = 32;
/// Stream queue length, as the firmware's `sampler::STREAM_QUEUE_LEN`.
const QLEN: usize = 128;

/// The firmware's per-sample telemetry stores (`sampler::Telemetry`).
struct Telemetry {
    samples: AtomicU32,
    overruns: AtomicU32,
    saturated: [AtomicU32; AXES],
    resets: [AtomicU32; AXES],
    stream_dropped: AtomicU32,
    compensating: AtomicBool,
    auto_zero_done: AtomicU32,
    auto_zero_failed: AtomicU32,
    isr_cycles_last: AtomicU32,
    isr_cycles_max: AtomicU32,
    isr_cycles_mean: AtomicU32,
}
static TELEMETRY: Telemetry = Telemetry {
    samples: AtomicU32::new(0),
    overruns: AtomicU32::new(0),
    saturated: [AtomicU32::new(0), AtomicU32::new(0), AtomicU32::new(0)],
    resets: [AtomicU32::new(0), AtomicU32::new(0), AtomicU32::new(0)],
    stream_dropped: AtomicU32::new(0),
    compensating: AtomicBool::new(false),
    auto_zero_done: AtomicU32::new(0),
    auto_zero_failed: AtomicU32::new(0),
    isr_cycles_last: AtomicU32::new(0),
    isr_cycles_max: AtomicU32::new(0),
    isr_cycles_mean: AtomicU32::new(0),
};
static USER_BYPASS: AtomicBool = AtomicBool::new(false);
static AUTO_ZERO_REQUEST: AtomicU32 = AtomicU32::new(0);
static STREAM_DECIMATION: AtomicU32 = AtomicU32::new(0);
static HANDOFF: ImageHandoff = ImageHandoff::new(0);
static QUEUE: StreamQueue<QLEN> = StreamQueue::new();

/// What the sample interrupt owns (`sampler::Sampler`).
struct Shell {
    path: SamplePath,
    cursor: RingCursor,
    stream: Producer<'static, QLEN>,
    cycles: IsrCycles,
}

/// One sample interrupt's software, step by step as the firmware's
/// `TIM2` → `on_tick` (same core calls, same atomics, same order), with
/// each register access replaced: the three `DMA_CNDTR` reads by `ndtr`,
/// the ring reads by `ring` (volatile, as the firmware), the DAC writes by
/// a `black_box`, the two DWT readings by `t0`/`t0 + 1 000`, the TIM2
/// status write and read left out. What is left out is the hardware part
/// of the shell's estimate (BENCHMARKS.md, "Cost model of the
/// sample interrupt").
#[inline(never)]
fn isr_software(
    sh: &mut Shell,
    stored: &mut ActiveImage,
    ring: &[[u16; RING_LEN as usize]; AXES],
    ndtr: [u16; AXES],
    t0: u32,
) -> u16 {
    if HANDOFF.take().is_some() {
        sh.path.on_image_switch();
    }
    black_box(HANDOFF.active());
    let Some(step) = sh.cursor.advance(&ndtr) else {
        TELEMETRY.stream_dropped.fetch_add(1, Relaxed);
        return 0;
    };
    if step.available == 0 {
        TELEMETRY.stream_dropped.fetch_add(1, Relaxed);
        return 0;
    }
    sh.path.state.note_overruns(step.missed());
    let i = usize::from(step.newest) % RING_LEN as usize;
    let mut codes = [0u16; AXES];
    for (c, r) in codes.iter_mut().zip(ring) {
        // SAFETY: `i < RING_LEN`, a read of an element of `r`.
        *c = unsafe { core::ptr::read_volatile(r.as_ptr().add(i)) } & 0x0FFF;
    }
    let request = AUTO_ZERO_REQUEST.swap(0, Relaxed);
    if request != 0 && sh.path.request_auto_zero(request).is_err() {
        TELEMETRY.auto_zero_failed.fetch_add(1, Relaxed);
    }
    let out = sh.path.tick(codes, stored, USER_BYPASS.load(Relaxed));
    black_box(out.dac);
    let c = &sh.path.state.counters;
    TELEMETRY.samples.store(c.samples, Relaxed);
    TELEMETRY.overruns.store(c.overruns, Relaxed);
    for (dst, &src) in TELEMETRY.saturated.iter().zip(c.saturated.iter()) {
        dst.store(src, Relaxed);
    }
    for (dst, n) in TELEMETRY.resets.iter().zip(sh.path.state.nonfinite_resets()) {
        dst.store(n, Relaxed);
    }
    TELEMETRY.compensating.store(out.compensating, Relaxed);
    match out.auto_zero {
        Some(Ok(_)) => {
            TELEMETRY.auto_zero_done.fetch_add(1, Relaxed);
        }
        Some(Err(_)) => {
            TELEMETRY.auto_zero_failed.fetch_add(1, Relaxed);
        }
        None => {}
    }
    let decimation = STREAM_DECIMATION.load(Relaxed);
    let index = sh.path.state.counters.samples;
    if decimation != 0 && index.is_multiple_of(decimation) {
        let item = StreamItem {
            index,
            step: decimation,
            sample: StreamSample { raw: codes, out: out.dac, flags: out.flags.0 },
        };
        if sh.stream.push(&item).is_err() {
            TELEMETRY.stream_dropped.fetch_add(1, Relaxed);
        }
    }
    sh.cycles.record(t0, t0.wrapping_add(1_000));
    TELEMETRY.isr_cycles_last.store(sh.cycles.last(), Relaxed);
    TELEMETRY.isr_cycles_max.store(sh.cycles.max(), Relaxed);
    TELEMETRY.isr_cycles_mean.store(sh.cycles.mean(), Relaxed);
    out.dac[0] ^ out.dac[1] ^ out.dac[2] ^ u16::from(out.flags.0)
}

/// Instructions per call of [`isr_software`] for one image, streaming
/// every sample (`stream` = the USB task's end, emptied by the harness
/// after each call, whose cost is measured apart and subtracted) or not.
fn measure_shell(
    ticks: &Ticks,
    img: CoeffImage,
    streaming: bool,
    consumer: &mut Consumer<'static, QLEN>,
    producer: Producer<'static, QLEN>,
) -> (f32, Producer<'static, QLEN>) {
    let mut stored = ActiveImage::new(Ok(CoeffImage { fs_hz: 20_000, ..img }.into()));
    let mut sh = Shell {
        path: SamplePath::new(),
        cursor: RingCursor::new(RING_LEN),
        stream: producer,
        cycles: IsrCycles::new(),
    };
    let ring = [[2048u16; RING_LEN as usize]; AXES];
    STREAM_DECIMATION.store(u32::from(streaming), Relaxed);
    let mut written = 0u32;
    let per_call = measure(ticks, |u| {
        written = written.wrapping_add(1);
        let n = RING_LEN - (written % u32::from(RING_LEN)) as u16;
        let out = isr_software(&mut sh, black_box(&mut stored), black_box(&ring), [n, n, n], (u as i32) as u32);
        if streaming {
            black_box(consumer.pop());
        }
        f32::from(out)
    });
    STREAM_DECIMATION.store(0, Relaxed);
    (per_call, sh.stream)
}

fn report(name: &str, per_sample: f32, empty: f32, states: u32) {
    let net = per_sample - empty;
    if states > 0 {
        hprintln!(
            "{:<28} {:>8.2} per call  {:>8.2} net  {:>6.2} net/state",
            name,
            per_sample,
            net,
            net / states as f32
        );
    } else {
        hprintln!("{:<28} {:>8.2} per call  {:>8.2} net", name, per_sample, net);
    }
}

#[entry]
fn main() -> ! {
    let cp = match cortex_m::Peripherals::take() {
        Some(p) => p,
        None => dynocomp_qemu::fail("icount: peripherals taken"),
    };
    let ticks = Ticks::start(cp.SYST);
    hprintln!("instructions per sample, mean of {} samples (QEMU -icount shift=0, SysTick 40 insn/tick)", SAMPLES);

    let empty = measure(&ticks, empty_call);
    report("empty call (loop overhead)", empty, empty, 0);
    // Two functions that differ only by 100 NOPs: must differ by exactly 100.
    let nops = measure(&ticks, nop200) - measure(&ticks, nop100);
    hprintln!("{:<28} {:>8.2} (must be 100.00)", "calibration: 200-100 NOPs", nops);
    if (nops - 100.0).abs() > 0.05 {
        dynocomp_qemu::fail(
            "icount: calibration failed, SysTick is not 40 instructions per tick (run with -icount shift=0)",
        );
    }

    for &s in &[8usize, 16, 24] {
        let f = kernel_filter(s, 0);
        let mut st = AxisState::default();
        let k = measure(&ticks, |u| kernel_step(black_box(&f), &mut st, u));
        let name = match s {
            8 => "kernel S8 (n=16)",
            16 => "kernel S16 (n=32)",
            _ => "kernel S24 (n=48)",
        };
        report(name, k, empty, 2 * s as u32);
    }
    report("dense eq.(6) S8 (17x17)", measure_dense::<17>(&ticks), empty, 16);
    report("dense eq.(6) S16 (33x33)", measure_dense::<33>(&ticks), empty, 32);
    report("dense eq.(6) S24 (49x49)", measure_dense::<49>(&ticks), empty, 48);
    report("idsp df1 cascade S8", measure_idsp_df1::<8>(&ticks), empty, 16);
    report("idsp df1 cascade S16", measure_idsp_df1::<16>(&ticks), empty, 32);
    report("idsp df1 cascade S24", measure_idsp_df1::<24>(&ticks), empty, 48);
    report("idsp df2t loop S8", measure_idsp_df2t::<8>(&ticks), empty, 16);
    report("idsp df2t loop S16", measure_idsp_df2t::<16>(&ticks), empty, 32);
    report("idsp df2t loop S24", measure_idsp_df2t::<24>(&ticks), empty, 48);

    let full = kernel_filter(24, 24);
    let mut st = AxisState::default();
    report("kernel S24+F24 (n=72)", measure(&ticks, |u| kernel_step(black_box(&full), &mut st, u)), empty, 72);
    let mut st = AxisState::default();
    report("kernel S24+F24 guarded", measure(&ticks, |u| kernel_step_guarded(black_box(&full), &mut st, u)), empty, 72);
    for (name, sections, taps) in [("process_sample 3x(S24+F24)", 24, 24), ("process_sample 3x(S3+F19)", 3, 19)] {
        let img = box_image(sections, taps);
        let mut sst = SampleState::default();
        report(
            name,
            measure(&ticks, |u| f32::from(sample_isr_body(black_box(&img), &mut sst, (u as i32 + 2048) as u16))),
            empty,
            0,
        );
    }
    let f = kernel_filter(3, 19);
    let mut st = AxisState::default();
    report("kernel S3+F19 (n=25)", measure(&ticks, |u| kernel_step(black_box(&f), &mut st, u)), empty, 25);

    // Calibration grid of the cost model (dynocomp_core::budget):
    // (pairs, real poles, taps, axes).
    for (p, r, t, a) in [
        (0usize, 0usize, 0usize, 3usize),
        (1, 0, 0, 3),
        (2, 0, 0, 3),
        (3, 0, 19, 3),
        (8, 0, 0, 3),
        (16, 0, 0, 3),
        (24, 0, 0, 3),
        (24, 0, 24, 3),
        (23, 1, 24, 3),
        (0, 0, 24, 3),
        (0, 4, 0, 3),
        (0, 1, 0, 3),
        (5, 2, 10, 3),
        (12, 0, 12, 3),
        (11, 3, 6, 3),
        (7, 0, 1, 3),
        (24, 0, 24, 1),
        (24, 0, 24, 2),
        (6, 1, 9, 1),
        (3, 0, 13, 3),
        (2, 0, 14, 3),
        (1, 0, 15, 3),
        (4, 0, 5, 3),
    ] {
        let img = image_of(mixed_filter(p, r, t), a).into();
        let mut sst = SampleState::default();
        let body = measure(&ticks, |u| f32::from(sample_isr_body(black_box(&img), &mut sst, (u as i32 + 2048) as u16)));
        // The same shape through `SamplePath::tick` (what the interrupt
        // calls: `process_sample` and the decisions around it), at 20 kHz,
        // where every shape of the grid is within the box's budget. The
        // `model` line's count is the tick's; `tick` minus `process_sample`
        // is printed on its own line.
        let mut stored =
            ActiveImage::new(Ok(CoeffImage { fs_hz: 20_000, ..image_of(mixed_filter(p, r, t), a) }.into()));
        if stored.refused().is_some() {
            dynocomp_qemu::fail("icount: a calibration shape is refused at 20 kHz");
        }
        let mut path = SamplePath::new();
        let per_call =
            measure(&ticks, |u| f32::from(tick_body(&mut path, black_box(&mut stored), (u as i32 + 2048) as u16)));
        hprintln!("model {} {} {} {} {:.2} {:.2}", p, r, t, a, per_call, per_call - empty);
        hprintln!("tick-minus-process_sample {} {} {} {} {:.2}", p, r, t, a, per_call - body);
    }

    // The 3x3 kernel alone (`MimoFilter::step`), and its calibration grid
    // through `SamplePath::tick` with a 3x3 image: (pairs, diagonal
    // sections, taps). `mimo P D T <per call> <net>` lines.
    for (p, dg, t) in [(20usize, 2usize, 8usize), (40, 0, 24), (10, 0, 8)] {
        let f = mimo_filter(p, dg, t);
        let mut st = MimoState::default();
        let k = measure(&ticks, |u| mimo_step(black_box(&f), &mut st, u));
        hprintln!("kernel3x3 {} {} {} {:.2} {:.2}", p, dg, t, k, k - empty);
    }
    for (p, dg, t) in [
        (0usize, 0usize, 0usize),
        (1, 0, 0),
        (2, 0, 0),
        (10, 0, 0),
        (20, 0, 0),
        (40, 0, 0),
        (0, 1, 0),
        (0, 4, 0),
        (0, 0, 1),
        (0, 0, 8),
        (0, 0, 24),
        (10, 0, 8),
        (20, 2, 8),
        (30, 0, 24),
        (40, 0, 8),
        (40, 8, 24),
        (13, 3, 5),
    ] {
        let mut stored = ActiveImage::new(Ok(matrix_image(mimo_filter(p, dg, t))));
        if stored.refused().is_some() {
            dynocomp_qemu::fail("icount: a 3x3 calibration shape is refused at 10 kHz");
        }
        let mut path = SamplePath::new();
        let per_call =
            measure(&ticks, |u| f32::from(tick_body(&mut path, black_box(&mut stored), (u as i32 + 2048) as u16)));
        hprintln!("mimo {} {} {} {:.2} {:.2}", p, dg, t, per_call, per_call - empty);
    }

    // The interrupt's software shell around `SamplePath::tick`: the same
    // tick inside a replica of the firmware's handler, minus the tick
    // alone, each measured in the same loop (its ring-counter arithmetic
    // for the replica's `ndtr` input, ≈ 6 instructions, is counted too).
    let (mut producer, mut consumer) = match QUEUE.split() {
        Some(ends) => ends,
        None => dynocomp_qemu::fail("icount: queue split twice"),
    };
    // The harness's own `pop` per sample when streaming, measured alone.
    let mut pop_only = {
        let mut sh_prod = producer;
        let pop = measure(&ticks, |u| {
            let _ = sh_prod.push(&StreamItem {
                index: u as u32,
                step: 1,
                sample: StreamSample { raw: [1, 2, 3], out: [4, 5, 6], flags: 0 },
            });
            black_box(consumer.pop()).map_or(0.0, |i| i.index as f32)
        });
        producer = sh_prod;
        pop
    };
    let push_only = {
        let mut sh_prod = producer;
        let push = measure(&ticks, |u| {
            let r = sh_prod.push(&StreamItem {
                index: u as u32,
                step: 1,
                sample: StreamSample { raw: [1, 2, 3], out: [4, 5, 6], flags: 0 },
            });
            black_box(r.is_ok());
            black_box(consumer.pop()).map_or(0.0, |i| i.index as f32) * 0.0
        });
        producer = sh_prod;
        push
    };
    // pop_only and push_only are the same loop: report their mean as the
    // harness's push + pop, the pop alone is not separable here.
    pop_only = 0.5 * (pop_only + push_only);
    for (p, r, t, a) in [(0usize, 0usize, 0usize, 3usize), (3, 0, 13, 3), (24, 0, 24, 3)] {
        let img = image_of(mixed_filter(p, r, t), a);
        let mut stored = ActiveImage::new(Ok(CoeffImage { fs_hz: 20_000, ..img }.into()));
        let mut path = SamplePath::new();
        let tick =
            measure(&ticks, |u| f32::from(tick_body(&mut path, black_box(&mut stored), (u as i32 + 2048) as u16)));
        let (quiet, prod) = measure_shell(&ticks, img, false, &mut consumer, producer);
        let (streaming, prod) = measure_shell(&ticks, img, true, &mut consumer, prod);
        producer = prod;
        hprintln!(
            "shell {} {} {} {} tick {:.2} isr {:.2} isr+stream+pop {:.2} (push+pop alone {:.2}): shell {:.2}, streaming {:.2}",
            p, r, t, a, tick, quiet, streaming, pop_only, quiet - tick, streaming - tick
        );
    }
    success()
}
