//! The box's CPU budget: a cost model of the sample interrupt, and the check
//! that keeps an image the box cannot run at its sample rate off the box
//! (issue #16).
//!
//! **Model.** The sample interrupt costs, per sample,
//!
//! ```text
//! cycles = FIXED + Σ_axes ( AXIS + PAIR·pairs + ODD·(pairs mod 2)
//!                            + REAL·reals + REAL_SETUP·(reals > 0)
//!                            + TAP·taps + FIR_SETUP·(taps > 0)
//!                            + TAP_REM·(taps mod 4) )
//! ```
//!
//! with each coefficient a range (low, high) of Cortex-M4 cycles
//! ([`CostModel::CORTEX_M4`]). The same form, in instructions
//! ([`CostModel::QEMU_INSNS`]), is calibrated against the instruction counts
//! of `shell::SamplePath::tick` (the interrupt's decisions around
//! `process_sample`) measured under QEMU (`scripts/qemu_icount.sh`, the
//! `model …` lines; `tests/qemu_cost_model.rs` fails if they drift apart
//! by more than [`INSN_TOLERANCE`]). Instructions become cycles with the
//! Cortex-M4 TRM timings of each part's instruction mix (BENCHMARKS.md,
//! "Interrupt budget and box load"); FIXED also holds the interrupt shell around
//! `SamplePath::tick` (exception entry/exit, lazy FP stacking, the ADC ring
//! reads, the DAC writes, the stream push and the cycle statistics).
//!
//! **Check.** The box refuses to run an image whose *high* estimate exceeds
//! [`BOX_LOAD_LIMIT_PERMILLE`] of the sample period at
//! [`BOX_CORE_CLOCK_HZ`] ([`check_load`], called by
//! `sample::select_mode`, once per image: `shell::ActiveImage`).
//! Everything here is integer arithmetic: no
//! allocation, no panics, no floating point.

use crate::image::{CoeffImage, ImageRef};
use crate::kernel::AxisFilter;
use crate::mimo::MimoFilter;
use crate::shell::BOX_CORE_CLOCK_HZ;

/// The box's hard limit on the predicted interrupt load (high estimate), in
/// thousandths of the sample period: 600 = 60 %. The rest of the period is
/// the USB, stream and watchdog tasks' and the margin for what the model
/// does not see (flash stalls if the code left CCM SRAM, bus contention).
pub const BOX_LOAD_LIMIT_PERMILLE: u32 = 600;

/// Largest relative deviation (per mille) of the instruction model from a
/// QEMU-measured count that `tests/qemu_cost_model.rs` accepts, plus the
/// absolute [`INSN_TOLERANCE_ABS`]. The fit's largest residual over the 23
/// calibration shapes is 3 instructions (3 axes × 24 pairs + 24 taps on
/// two axes); between builds the counts moved by up to 15 (LLVM allocates the
/// shared code differently, e.g. 4 real poles); the tolerance is kept from
/// the earlier fit, whose largest residual was 14.8 (the compiled tap
/// loop's remainder).
pub const INSN_TOLERANCE: u32 = 20;
/// Absolute part of the tolerance (instructions): LLVM's register
/// allocation moves the shared loop code by ±2 instructions between builds.
pub const INSN_TOLERANCE_ABS: u32 = 6;

/// Instructions of the sample interrupt's software around
/// `SamplePath::tick` (the handoff, the ring cursor, the ADC ring reads,
/// the auto-zero request, the telemetry stores, the stream push when
/// streaming every sample, the cycle statistics): measured under QEMU on a
/// replica of the firmware's handler without its register accesses (the
/// `shell … streaming` figure of `scripts/qemu_icount.sh`;
/// `tests/qemu_cost_model.rs` checks it within [`INSN_TOLERANCE`]). The
/// replica is compiled apart from the firmware, so its count moves with
/// the code around it: 223 with the kernel in two assembly blocks, 192 with
/// one (the same source).
pub const SHELL_INSNS: u32 = 192;

/// Cycles of the sample interrupt's hardware part, hundredths (low, high):
/// exception entry and exit (12 + 12), lazy stacking of the FP context
/// (17), and the register accesses the QEMU replica leaves out: the TIM2
/// status write (1-2) and read (3-6, APB1), 3 DMA `CNDTR` reads (2-4 each,
/// AHB), 3 DAC writes (1-2 each, write buffer), 2 DWT `CYCCNT` reads (1-2
/// each), with their address set-up (10-20): 66-91, taken as 70-110.
pub const SHELL_HW_CYCLES: Cost = Cost::new(7_000, 11_000);

/// A cost in cycles (or instructions), as a range.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Cost {
    /// Optimistic estimate.
    pub low: u32,
    /// Pessimistic estimate (the one every check uses).
    pub high: u32,
}

impl Cost {
    const fn new(low: u32, high: u32) -> Self {
        Cost { low, high }
    }

    fn add_scaled(self, c: Cost, k: u32) -> Cost {
        Cost {
            low: self.low.saturating_add(c.low.saturating_mul(k)),
            high: self.high.saturating_add(c.high.saturating_mul(k)),
        }
    }
}

/// Coefficients of the cost model, in hundredths of a cycle (or of an
/// instruction) so that fractional costs (11.5 instructions per pair) stay
/// exact in integers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CostModel {
    /// Per sample, whatever the image: `process_sample`'s own work and the
    /// interrupt shell.
    pub fixed: Cost,
    /// Per axis present in the image (the call, scaling, guard, DAC code).
    pub axis: Cost,
    /// Per pole pair.
    pub pair: Cost,
    /// Extra for an odd pair count (the last pair runs alone).
    pub odd_pair: Cost,
    /// Per live real pole.
    pub real: Cost,
    /// Per axis with at least one real pole (entering the real-pole loop).
    pub real_setup: Cost,
    /// Per FIR tap.
    pub tap: Cost,
    /// Per axis with at least one FIR tap (entering the tap loop).
    pub fir_setup: Cost,
    /// Extra per tap after the last full block of four (the assembly tap
    /// loop runs four taps per pass, then the rest one by one).
    pub tap_rem: Cost,
}

/// Shape of one axis's filter as the kernel runs it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct AxisShape {
    /// Pole pairs.
    pub pairs: u32,
    /// Live real poles.
    pub reals: u32,
    /// FIR taps.
    pub taps: u32,
}

impl AxisShape {
    /// The shape of a built filter.
    pub fn of(f: &AxisFilter) -> Self {
        let (pairs, reals) = f.kernel_counts();
        AxisShape { pairs: pairs as u32, reals: reals as u32, taps: f.fir().len() as u32 }
    }
}

impl CostModel {
    /// Instructions per call of `SamplePath::tick` (`process_sample` and
    /// the decisions around it) on the Cortex-M4F (no interrupt shell),
    /// fitted to the QEMU counts (`model …` lines of
    /// `scripts/qemu_icount.sh`; BENCHMARKS.md, "Cost model of
    /// the sample interrupt"). low = high: the count is exact per shape.
    pub const QEMU_INSNS: CostModel = CostModel {
        fixed: Cost::new(8_737, 8_737),
        axis: Cost::new(6_428, 6_428),
        pair: Cost::new(1_150, 1_150),
        odd_pair: Cost::new(51, 51),
        real: Cost::new(896, 896),
        real_setup: Cost::new(913, 913),
        tap: Cost::new(349, 349),
        fir_setup: Cost::new(3, 3),
        tap_rem: Cost::new(451, 451),
    };

    /// Cycles of the whole sample interrupt on the STM32G474 at 170 MHz,
    /// code in CCM SRAM (0 wait states): the instruction model's parts
    /// converted with the Cortex-M4 TRM timings of their instruction mix
    /// (BENCHMARKS.md), plus the interrupt shell in `fixed`.
    ///
    /// * pair: 28-29 cycles (two pairs per loop pass: `vldmia` 8 + 4,
    ///   `vstmia` 4, 8 `vmla`/`vmls` at 3, 10 `vmul`/`vadd` at 1, `subs` +
    ///   `bne`); odd pair: the lone last pair's 12 instructions cost 30-32
    ///   cycles, 3.5-7 more than a pair in the loop;
    /// * real pole (assembly): `vldmia` of σ, c (3), `vldr` x (2), `vmla`
    ///   (3), `vmul`, 2 `vadd`, `vstmia` (2), `subs`, `bne` 2-4: 16-18
    ///   cycles;
    /// * tap (assembly, four per pass: two 4-register `vldmia`, 4 `vmul`,
    ///   4 `vadd`, a 4-register `vstmia`, `vmov`, `subs`, `bne`: 5 + 5 + 4 +
    ///   4 + 5 + 1 + 1 + 2-4 = 27-29 cycles): 6.75-7.25 per tap; a remainder
    ///   tap (one-register `vldmia`/`vstmia`, 2 each, `vmul`, `vadd`, `vmov`,
    ///   `subs`, `bne` 2-4: 12-14 cycles) costs 5.25-6.75 more;
    /// * scalar and set-up code (fixed, axis, loop set-ups): 1.0-1.35 cycles
    ///   per instruction (loads at 2, branches at 2-4, the rest at 1);
    /// * interrupt shell, in `fixed`: its software ([`SHELL_INSNS`], measured
    ///   under QEMU on a replica of the handler, streaming every sample) at
    ///   the same 1.0-1.35 cycles per instruction, plus the hardware
    ///   ([`SHELL_HW_CYCLES`]: exception entry and exit 24, lazy FP stacking
    ///   17, the TIM2 flag write and read, 3 DMA NDTR reads, 3 DAC writes, 2
    ///   DWT reads on the peripheral buses).
    pub const CORTEX_M4: CostModel = CostModel {
        fixed: Cost::new(
            8_737 + 100 * SHELL_INSNS + SHELL_HW_CYCLES.low,
            (8_737 + 100 * SHELL_INSNS) * 135 / 100 + SHELL_HW_CYCLES.high,
        ),
        axis: Cost::new(6_428, 8_678),
        pair: Cost::new(2_800, 2_900),
        odd_pair: Cost::new(350, 700),
        real: Cost::new(1_600, 1_800),
        real_setup: Cost::new(913, 1_233),
        tap: Cost::new(675, 725),
        fir_setup: Cost::new(3, 5),
        tap_rem: Cost::new(525, 675),
    };

    /// Cost of one axis of shape `s` (whole cycles, rounded up).
    pub fn axis_cost(&self, s: AxisShape) -> Cost {
        let c = self.axis_cost_hundredths(s);
        Cost { low: c.low.div_ceil(100), high: c.high.div_ceil(100) }
    }

    /// Cost of one axis of shape `s` (hundredths).
    fn axis_cost_hundredths(&self, s: AxisShape) -> Cost {
        Cost::default()
            .add_scaled(self.axis, 1)
            .add_scaled(self.pair, s.pairs)
            .add_scaled(self.odd_pair, s.pairs & 1)
            .add_scaled(self.real, s.reals)
            .add_scaled(self.real_setup, u32::from(s.reals > 0))
            .add_scaled(self.tap, s.taps)
            .add_scaled(self.fir_setup, u32::from(s.taps > 0))
            .add_scaled(self.tap_rem, s.taps % 4)
    }

    /// Cost of one sample with these axes, rounded up to whole cycles
    /// (instructions).
    pub fn sample_cost(&self, axes: &[AxisShape]) -> Cost {
        let sum = axes.iter().fold(self.fixed, |acc, s| {
            let a = self.axis_cost_hundredths(*s);
            Cost { low: acc.low.saturating_add(a.low), high: acc.high.saturating_add(a.high) }
        });
        Cost { low: sum.low.div_ceil(100), high: sum.high.div_ceil(100) }
    }

    /// Cost of one sample of `image`.
    pub fn image_cost(&self, image: &CoeffImage) -> Cost {
        let mut shapes = [AxisShape::default(); crate::AXES];
        let mut n = 0;
        for a in image.axes.iter().flatten() {
            if let Some(s) = shapes.get_mut(n) {
                *s = AxisShape::of(&a.filter);
                n += 1;
            }
        }
        self.sample_cost(shapes.get(..n).unwrap_or(&[]))
    }
}

/// Cycles per sample period at `fs_hz` on the box's core clock (0 for
/// fs = 0).
pub fn period_cycles(fs_hz: u32) -> u32 {
    BOX_CORE_CLOCK_HZ.checked_div(fs_hz).unwrap_or(0)
}

/// Load of `cycles` per sample at `fs_hz`, in thousandths of the sample
/// period (rounded up; `u32::MAX` when the period is 0).
pub fn load_permille(cycles: u32, fs_hz: u32) -> u32 {
    let num = u64::from(cycles) * u64::from(fs_hz) * 1000;
    let den = u64::from(BOX_CORE_CLOCK_HZ);
    u32::try_from(num.div_ceil(den)).unwrap_or(u32::MAX)
}

/// The highest sample rate (Hz) at which `cycles` per sample stay within
/// `limit_permille` of the period (0 when `cycles` is 0: no limit).
pub fn max_fs_hz(cycles: u32, limit_permille: u32) -> u32 {
    let num = u64::from(BOX_CORE_CLOCK_HZ) * u64::from(limit_permille);
    u32::try_from(num.checked_div(u64::from(cycles) * 1000).unwrap_or(0)).unwrap_or(u32::MAX)
}

/// Cycles each of `n_axes` axes may cost (high estimate of
/// [`CostModel::CORTEX_M4`]) for the whole interrupt to stay within
/// `limit_permille` of the period at `fs_hz` (0 if not even the fixed part
/// fits).
pub fn axis_budget(fs_hz: u32, limit_permille: u32, n_axes: u32) -> u32 {
    let total = u64::from(period_cycles(fs_hz)) * u64::from(limit_permille) / 1000;
    let fixed = u64::from(CostModel::CORTEX_M4.fixed.high.div_ceil(100));
    let per_axis = total.saturating_sub(fixed).checked_div(u64::from(n_axes)).unwrap_or(0);
    u32::try_from(per_axis).unwrap_or(u32::MAX)
}

/// The predicted interrupt load of an image at its own sample rate.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Load {
    /// Predicted cycles per sample, high estimate.
    pub cycles: u32,
    /// The same as thousandths of the sample period.
    pub permille: u32,
}

/// Shape of a 3x3 filter as the kernel runs it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MimoShape {
    /// Normal-form pole pairs.
    pub pairs: u32,
    /// Diagonal sections (two real poles each, both always run).
    pub diagonals: u32,
    /// FIR taps (each a 3x3 matrix).
    pub taps: u32,
}

impl MimoShape {
    /// The shape of a built 3x3 filter.
    pub fn of(f: &MimoFilter) -> Self {
        let (pairs, diagonals) = f.kernel_counts();
        MimoShape { pairs: pairs as u32, diagonals: diagonals as u32, taps: f.fir().len() as u32 }
    }
}

/// Coefficients of the cost of a sample with a 3x3 image, in hundredths of
/// a cycle (or of an instruction), in the form
///
/// ```text
/// cost = FIXED + MATRIX + PAIR·pairs + DIAGONAL·diagonals
///        + SECTION_SETUP·(sections > 0) + EVEN_SECTIONS·(sections > 0 and even)
///        + TAP·taps + FIR_SETUP·(taps > 0) + EVEN_TAPS·(taps > 0 and even)
/// ```
///
/// `fixed` is [`CostModel::fixed`] (the same interrupt around either kind
/// of image); `matrix` is the 3x3 path's own work per sample (three
/// scalings, the 3x3 direct term, the runaway guard, three DAC codes). A
/// loop that runs two sections (taps) per pass shows in the even/odd
/// terms; the assembly step (`mimo_m4.rs`) runs one section per pass and
/// its odd last tap costs a tap, so its are 0.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MimoCostModel {
    /// Per sample, whatever the image (as [`CostModel::fixed`]).
    pub fixed: Cost,
    /// Per sample with a 3x3 image.
    pub matrix: Cost,
    /// Per normal-form pair.
    pub pair: Cost,
    /// Per diagonal section.
    pub diagonal: Cost,
    /// Once when the filter has sections.
    pub section_setup: Cost,
    /// Once more when the section count is even (and not 0).
    pub even_sections: Cost,
    /// Per FIR tap (a 3x3 matrix).
    pub tap: Cost,
    /// Once when the filter has FIR taps.
    pub fir_setup: Cost,
    /// Once more when the tap count is even (and not 0).
    pub even_taps: Cost,
}

impl MimoCostModel {
    /// Instructions per call of `SamplePath::tick` with a 3x3 image on the
    /// Cortex-M4F, fitted to the QEMU counts (`mimo P D T …` lines of
    /// `scripts/qemu_icount.sh`; `tests/qemu_cost_model.rs`) of the assembly
    /// step (`mimo_m4.rs`): 42 per pair (2 `vldmia`, 2 `vmov`, 16 `vmul`,
    /// 16 `vadd`, the pair/diagonal test on the bits, `vstmia`, the loop),
    /// 39 per diagonal section (4 float operations fewer, 2 branches more),
    /// 22 per tap (two per pass: `vldmia` of 9 coefficients and 3 past
    /// inputs, `vstmia` of 3, 9 `vmul` + 9 `vadd`; an odd last tap is one
    /// instruction fewer, which the model does not subtract). The sections
    /// run one per pass and the taps' odd remainder costs what a tap does,
    /// so the even/odd terms are 0. low = high: the count is exact per
    /// shape.
    pub const QEMU_INSNS: MimoCostModel = MimoCostModel {
        fixed: CostModel::QEMU_INSNS.fixed,
        matrix: Cost::new(11_185, 11_185),
        pair: Cost::new(4_200, 4_200),
        diagonal: Cost::new(3_900, 3_900),
        section_setup: Cost::new(300, 300),
        even_sections: Cost::new(0, 0),
        tap: Cost::new(2_200, 2_200),
        fir_setup: Cost::new(0, 0),
        even_taps: Cost::new(0, 0),
    };

    /// Cycles on the STM32G474 at 170 MHz, code in CCM SRAM: each part's
    /// instruction mix at the Cortex-M4 TRM timings (`vldm`/`vstm` of N
    /// registers 1 + N, `vmul`/`vadd`/`vmov` 1, integer ALU 1, branches 1
    /// not taken and 2-4 taken), plus the interrupt shell in `fixed`
    /// ([`CostModel::CORTEX_M4`]).
    ///
    /// * pair: `vldmia` of 16 (17) and of 2 (3), 2 `vmov` (2), 32
    ///   `vmul`/`vadd` (32), the test (3), `vstmia` of 2 (3), loop (3-5):
    ///   63-65 by the table; high 72 for stalls the table does not show;
    /// * diagonal section: 4 float operations fewer, two taken branches more:
    ///   62-68, high 72;
    /// * tap, per two: 2 × (`vldmia` of 9 (10) and of 3 (4), `vstmia` of 3
    ///   (4), 18 `vmul`/`vadd`) and the loop (3-5): 37.5-38.5 per tap, high
    ///   42;
    /// * the 3x3 path's scalar part and set-ups: 1.0-1.5 cycles per
    ///   instruction, plus 31 for the multi-register transfers one
    ///   instruction each does not count (`vldmia` of `d`, of `u`, `vstmia`
    ///   of `y`, and the saving and restoring of `s16-s23`).
    pub const CORTEX_M4: MimoCostModel = MimoCostModel {
        fixed: CostModel::CORTEX_M4.fixed,
        matrix: Cost::new(14_285, 19_878),
        pair: Cost::new(6_300, 7_200),
        diagonal: Cost::new(6_200, 7_200),
        section_setup: Cost::new(300, 450),
        even_sections: Cost::new(0, 0),
        tap: Cost::new(3_750, 4_200),
        fir_setup: Cost::new(0, 0),
        even_taps: Cost::new(0, 0),
    };

    /// Cost of one sample with a 3x3 filter of shape `s`, rounded up to
    /// whole cycles (instructions).
    pub fn sample_cost(&self, s: MimoShape) -> Cost {
        let sections = s.pairs + s.diagonals;
        let c = self
            .fixed
            .add_scaled(self.matrix, 1)
            .add_scaled(self.pair, s.pairs)
            .add_scaled(self.diagonal, s.diagonals)
            .add_scaled(self.section_setup, u32::from(sections > 0))
            .add_scaled(self.even_sections, u32::from(sections > 0 && sections.is_multiple_of(2)))
            .add_scaled(self.tap, s.taps)
            .add_scaled(self.fir_setup, u32::from(s.taps > 0))
            .add_scaled(self.even_taps, u32::from(s.taps > 0 && s.taps.is_multiple_of(2)));
        Cost { low: c.low.div_ceil(100), high: c.high.div_ceil(100) }
    }
}

/// Cost of one sample of any image the box runs, in cycles
/// ([`CostModel::CORTEX_M4`] / [`MimoCostModel::CORTEX_M4`]).
pub fn image_cycles<'a>(image: impl Into<ImageRef<'a>>) -> Cost {
    match image.into() {
        ImageRef::PerAxis(i) => CostModel::CORTEX_M4.image_cost(i),
        ImageRef::Matrix(m) => MimoCostModel::CORTEX_M4.sample_cost(MimoShape::of(&m.filter)),
    }
}

/// Predicted load of `image` (per-axis or 3x3) at its sample rate (high
/// estimate of the Cortex-M4 cost models).
pub fn image_load<'a>(image: impl Into<ImageRef<'a>>) -> Load {
    let image = image.into();
    let cycles = image_cycles(image).high;
    Load { cycles, permille: load_permille(cycles, image.fs_hz()) }
}

/// `Err` with the predicted load when the image's high estimate exceeds
/// `limit_permille` of its sample period.
pub fn check_load<'a>(image: impl Into<ImageRef<'a>>, limit_permille: u32) -> Result<Load, Load> {
    let l = image_load(image);
    if l.permille > limit_permille {
        Err(l)
    } else {
        Ok(l)
    }
}

/// Whether the instruction model's prediction `model` is within the stated
/// uncertainty ([`INSN_TOLERANCE`], [`INSN_TOLERANCE_ABS`]) of a measured
/// count `measured` (instructions per call).
pub fn insns_agree(model: u32, measured: u32) -> bool {
    let tol = (u64::from(measured) * u64::from(INSN_TOLERANCE)).div_ceil(1000) + u64::from(INSN_TOLERANCE_ABS);
    u64::from(model.abs_diff(measured)) <= tol
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shape(pairs: u32, reals: u32, taps: u32) -> AxisShape {
        AxisShape { pairs, reals, taps }
    }

    #[test]
    fn cost_grows_with_every_part_and_low_never_exceeds_high() {
        let m = CostModel::CORTEX_M4;
        let base = m.sample_cost(&[shape(4, 0, 0)]);
        for more in [shape(6, 0, 0), shape(4, 1, 0), shape(4, 0, 1)] {
            let c = m.sample_cost(&[more]);
            assert!(c.low > base.low && c.high > base.high, "{more:?}: {c:?} vs {base:?}");
        }
        for s in [shape(0, 0, 0), shape(24, 0, 24), shape(3, 1, 19)] {
            let c = m.sample_cost(&[s, s, s]);
            assert!(c.low < c.high, "{s:?}: {c:?}");
        }
    }

    #[test]
    fn axes_within_the_axis_budget_fit_the_limit_and_one_cycle_more_does_not() {
        let m = CostModel::CORTEX_M4;
        for (fs, n) in [(51_200u32, 3u32), (25_600, 3), (51_200, 1), (102_400, 2)] {
            let per_axis = axis_budget(fs, 600, n);
            let total = m.fixed.high.div_ceil(100) + n * per_axis;
            assert!(load_permille(total, fs) <= 600, "fs {fs} n {n}");
            assert!(
                load_permille(total + n + 4, fs) > 600 || load_permille(total + 2 * n + 4, fs) > 600,
                "fs {fs} n {n}: budget not tight"
            );
        }
        assert_eq!(axis_budget(1_000_000, 100, 3), 0);
    }

    #[test]
    fn load_and_max_fs_are_inverse() {
        // 1 700 cycles at 51.2 kHz: 1700·51200/170e6 = 0.512 → 512 ‰.
        assert_eq!(load_permille(1_700, 51_200), 512);
        // and the highest rate at 60 % is 170e6·0.6/1700 = 60 kHz.
        assert_eq!(max_fs_hz(1_700, 600), 60_000);
        assert_eq!(period_cycles(51_200), 3_320);
        assert_eq!(max_fs_hz(0, 600), 0);
        assert_eq!(period_cycles(0), 0);
    }

    #[test]
    fn mimo_cost_grows_with_every_part_and_low_never_exceeds_high() {
        let m = MimoCostModel::CORTEX_M4;
        let s = |pairs, diagonals, taps| MimoShape { pairs, diagonals, taps };
        let base = m.sample_cost(s(10, 0, 8));
        for more in [s(11, 0, 8), s(10, 1, 8), s(10, 0, 9)] {
            let c = m.sample_cost(more);
            assert!(c.low > base.low && c.high > base.high, "{more:?}: {c:?} vs {base:?}");
        }
        for shape in [s(0, 0, 0), s(40, 8, 24), s(13, 3, 5)] {
            let c = m.sample_cost(shape);
            assert!(c.low < c.high, "{shape:?}: {c:?}");
        }
        // A 3x3 filter costs more than the per-axis filters of the same
        // section count on one axis (dense B and C).
        let per_axis = CostModel::CORTEX_M4.sample_cost(&[AxisShape { pairs: 10, reals: 0, taps: 8 }]);
        assert!(base.low > per_axis.high);
    }

    #[test]
    fn tolerance_accepts_the_stated_band_and_rejects_beyond() {
        assert!(insns_agree(1_000 + 26, 1_000));
        assert!(!insns_agree(1_000 + 27, 1_000));
        assert!(insns_agree(1_000 - 26, 1_000));
        assert!(!insns_agree(0, 1_000));
        // 523 · 2 % = 10.5 → 11, + 6: 17.
        assert!(insns_agree(523 + 17, 523));
        assert!(!insns_agree(523 + 18, 523));
    }
}
