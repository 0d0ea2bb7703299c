//! The conjugate-pair loop of [`AxisFilter::step`](super::AxisFilter::step)
//! for the Cortex-M4F (bare-metal ARM with hardware float, `eabihf`), in
//! hand-scheduled assembly. Every other target runs [`pair_update`](super::pair_update) in Rust.
//!
//! LLVM computes the pairs with one `vldr` per coefficient and per state and
//! one `vstr` per state (6 + 2 per pair, 18.25 instructions per pair with its
//! loop overhead): its post-allocation load/store optimizer only merges
//! `vldr`s into a `vldm` when the registers happen to be consecutive and
//! ascending, which the register allocator does not aim for (no reordering
//! or layout of the Rust source made it do so). Here two pairs per
//! iteration take one `vldmia` for their 8 coefficients ([`PairCoeffs`] is
//! `[σ, ω, c1, c2]`, and the pairs are contiguous), one `vldmia`
//! for their 4 states (`[[f32; 2]]` is contiguous) and one `vstmia` for the
//! 4 new states; `y` stays in `s0` and `u` in `s1` throughout:
//!
//! ```text
//!     vmov    s0,  y            (y and u arrive in core registers)
//!     vmov    s1,  u
//!     lsrs    k,   n,   #1      k = number of pairs of pairs
//!     beq     3f
//! 2:  vldmia  cp!, {s8-s15}     σa ωa c1a c2a σb ωb c1b c2b
//!     vldmia  xp,  {s4-s7}      x1a x2a x1b x2b
//!     vmla    s0,  s10, s4      y   += c1a·x1a
//!     vmul    s2,  s8,  s4      t1a  = σa·x1a
//!     vmul    s3,  s8,  s5      t2a  = σa·x2a
//!     vmla    s0,  s11, s5      y   += c2a·x2a
//!     vmla    s2,  s9,  s5      t1a  = t1a + ωa·x2a
//!     vmls    s3,  s9,  s4      d2a  = t2a − ωa·x1a
//!     vmla    s0,  s14, s6      y   += c1b·x1b
//!     vadd    s2,  s2,  s1      d1a  = t1a + u
//!     vmul    s10, s12, s6      t1b  = σb·x1b
//!     vmul    s11, s12, s7      t2b  = σb·x2b
//!     vmla    s0,  s15, s7      y   += c2b·x2b
//!     vadd    s4,  s4,  s2      x1a' = x1a + d1a
//!     vadd    s5,  s5,  s3      x2a' = x2a + d2a
//!     vmla    s10, s13, s7      t1b  = t1b + ωb·x2b
//!     vmls    s11, s13, s6      d2b  = t2b − ωb·x1b
//!     vadd    s10, s10, s1      d1b  = t1b + u
//!     vadd    s6,  s6,  s10     x1b' = x1b + d1b
//!     vadd    s7,  s7,  s11     x2b' = x2b + d2b
//!     vstmia  xp!, {s4-s7}
//!     subs    k,   k,   #1
//!     bne     2b
//! 3:  lsls    n,   n,   #31     odd n: the last pair alone
//!     beq     4f
//!     vldmia  cp,  {s8-s11}     σ ω c1 c2
//!     vldmia  xp,  {s4-s5}      x1 x2
//!     (the 9 operations of pair a above)
//!     vstmia  xp,  {s4-s5}
//! 4:  vmov    y,   s0
//! ```
//!
//! 23 instructions per two pairs in the loop (11.5 per pair, 5.75 per
//! state), 12 for an odd last pair, 7 per call around them (plus the
//! compiler's moves of `y` and `u` between S and core registers).
//!
//! **Bit-identical to [`pair_update`](super::pair_update)** (the kernel's definition: `y += c1·x1;
//! y += c2·x2; d1 = (σ·x1 + ω·x2) + u; d2 = σ·x2 − ω·x1; x1 += d1; x2 += d2`,
//! f32, round to nearest even), operation by operation, with the same
//! operands in the same order:
//!
//! * `VMLA.F32 Sd, Sn, Sm` is *not* fused: the ARMv7-M Architecture Reference
//!   Manual (ARM DDI 0403E, the instruction "VMLA, VMLS") defines it as
//!   `FPAdd(S[d], FPMul(S[n], S[m]))`, the product rounded to f32 first, so
//!   it equals Rust's `d + n * m` (rustc never fuses `*` and `+`; the fused
//!   instruction is `VFMA` ("VFMA, VFMS"), not used here). LLVM itself emits
//!   `vmla` for [`pair_update`](super::pair_update) on this target.
//! * `VMLS.F32 Sd, Sn, Sm` is `FPAdd(S[d], FPNeg(FPMul(S[n], S[m])))`; IEEE
//!   754 defines `a − b` as `a + (−b)` and round-to-nearest is symmetric, so
//!   it equals Rust's `d − n * m` (`σ·x2 − ω·x1`), signed zeros included.
//! * The first operand of each addition is the one `pair_update` writes
//!   first (`y`, `σ·x1`, `σ·x2`, `… + u`, `x1 + d1`, `x2 + d2`); `y`
//!   accumulates pair by pair in section order, c1 before c2.
//! * `vmov` between core and S registers copies the 32 bits unchanged.
//! * FPSCR: the code does not change the rounding mode or flush-to-zero (it
//!   sets the cumulative exception flags, as the compiled code does).
//!
//! `tests/qemu_bit_exact.rs` compares this code on an emulated Cortex-M4F
//! against the Rust kernel on the host, bit for bit.
//!
//! The loop count depends only on the number of pairs (configuration), never
//! on the signal.
//!
//! `y` and `u` pass through core registers because rustc (as of 1.95)
//! accepts S-register operands only with its `vfp2` target feature, which
//! implies double precision and is off for the single-precision M4F
//! (relaxed upstream by rust-lang/rust#159988, after 1.95); the S registers
//! are named explicitly instead.

use super::{AxisFilter, AxisState, KernelForm, MAX_FIR, MAX_SECTIONS};
use core::mem::offset_of;

/// Byte offsets the assembly reads the filter and the state at.
const OFF_D: usize = offset_of!(AxisFilter, d);
const OFF_COEFFS: usize = offset_of!(AxisFilter, form) + offset_of!(KernelForm, coeffs);
const OFF_COEFFS_END: usize = OFF_COEFFS + 4 * 4 * MAX_SECTIONS;
const OFF_NPAIRS: usize = offset_of!(AxisFilter, form) + offset_of!(KernelForm, n_pairs);
const OFF_NREALS: usize = offset_of!(AxisFilter, form) + offset_of!(KernelForm, n_reals);
const OFF_FIR: usize = offset_of!(AxisFilter, fir);
const OFF_FIRLEN: usize = offset_of!(AxisFilter, fir_len);
const OFF_X: usize = offset_of!(AxisState, x);
const OFF_XREAL: usize = offset_of!(AxisState, x_real);
const OFF_HIST: usize = offset_of!(AxisState, fir_hist);
// The immediates below are Thumb-2 12-bit offsets.
const _: () = assert!(OFF_D < 4096 && OFF_COEFFS_END < 4096 && OFF_NPAIRS < 4096 && OFF_NREALS < 4096);
const _: () = assert!(OFF_FIR < 4096 && OFF_FIRLEN < 4096 && OFF_X < 4096 && OFF_XREAL < 4096 && OFF_HIST < 4096);
const _: () = assert!(MAX_SECTIONS == 24 && MAX_FIR == 24);

/// One sample of `f` ([`AxisFilter::step`]'s module equation, in its
/// order): `y = d·u`, every pair, every live real pole, every FIR tap, in
/// one block, so `y` stays in `s0` and `u` in `s1` from the first
/// operation to the last (two separate blocks moved them between core and
/// S registers four times per axis).
///
/// * pairs: two per pass as documented above (`vldmia` of 8 coefficients
///   and 4 states, 18 float operations, `vstmia`), the odd last pair alone;
///   count clamped to [`MAX_SECTIONS`];
/// * real poles (`x += σ·x + u`, `y += c·x`): one per pass, from where the
///   pairs' coefficients end (the kernel form packs them there), count
///   clamped to what is left of the coefficient array; skipped when there
///   is none;
/// * FIR taps: four per pass (`vldmia` of 4 coefficients and 4 history
///   values, 4 `vmul` + 4 `vadd` in tap order, `vstmia` of the shifted
///   history, the fourth value carried in `s3`), then the rest one by one;
///   count clamped to [`MAX_FIR`]. `vmul` + `vadd` rounds as `vmla` does
///   (two roundings), in 2 cycles instead of 3 by the Cortex-M4 TRM; the
///   pair loop keeps `vmla` for its instruction count.
///
/// **Bit-identical to the Rust loops** (`pair_update`, `real_update`, the
/// FIR loop of `step`): the same operations on the same operands in the
/// same order (above, and: `y += c·x` is `vmla s0, c, x`; `σ·x + u` is
/// `vmul` then `vadd`; `x + (…)` is `vadd x, x, t`). `tests/qemu_bit_exact.rs`
/// compares it with the host's Rust kernel on axes with an odd pair count,
/// one and two real poles, and 24, 23 and 5 taps.
#[inline(always)]
pub(super) fn step(f: &AxisFilter, state: &mut AxisState, u: f32) -> f32 {
    let y: f32;
    // SAFETY: the asm reads `f` and reads and writes `state` only, at the
    // field offsets above (computed by `offset_of!`), and no other memory:
    // * `d`, `n_pairs`, `n_reals`, `fir_len`: one word each;
    // * pairs: `n ≤ MAX_SECTIONS` (clamped in the asm), `4n` f32 of
    //   `form.coeffs` (`4·MAX_SECTIONS` long), `2n` of `state.x`
    //   (`MAX_SECTIONS` pairs);
    // * real poles: `r` clamped to the pairs left of `form.coeffs` after the
    //   pairs' `4n` (so `4n + 2r ≤ 4·MAX_SECTIONS`), `2r` f32 of it and `r`
    //   of `state.x_real` (`2·MAX_SECTIONS ≥ r` long);
    // * taps: `m ≤ MAX_FIR` (clamped), `m` f32 of `fir` and of
    //   `state.fir_hist` (both `MAX_FIR` long);
    // all ascending, 4-byte aligned (f32/usize fields; VLDM/VSTM need word
    // alignment). `state` is a unique borrow, `f` a shared one: no overlap.
    // The pointers and counters are scratch outputs allocated apart from
    // the inputs (`f`, `state` and `u` are not written); every S register
    // written (`s0`-`s15`) is a declared clobber; the flags change (no
    // `preserves_flags`); no stack use. FPSCR's rounding and flush-to-zero
    // modes are left unchanged.
    unsafe {
        core::arch::asm!(
            "vmov s1, {u}",
            "add {k}, {f}, #{off_d}",
            "vldr s0, [{k}]",
            "vmul.f32 s0, s0, s1",
            // ---- pairs
            "ldr {n}, [{f}, #{off_np}]",
            "cmp {n}, #24",
            "it hi",
            "movhi {n}, #24",
            "add {cp}, {f}, #{off_coeffs}",
            "add {xp}, {st}, #{off_x}",
            "lsrs {k}, {n}, #1",
            "beq 3f",
            "2:",
            "vldmia {cp}!, {{s8-s15}}",
            "vldmia {xp}, {{s4-s7}}",
            "vmla.f32 s0, s10, s4",
            "vmul.f32 s2, s8, s4",
            "vmul.f32 s3, s8, s5",
            "vmla.f32 s0, s11, s5",
            "vmla.f32 s2, s9, s5",
            "vmls.f32 s3, s9, s4",
            "vmla.f32 s0, s14, s6",
            "vadd.f32 s2, s2, s1",
            "vmul.f32 s10, s12, s6",
            "vmul.f32 s11, s12, s7",
            "vmla.f32 s0, s15, s7",
            "vadd.f32 s4, s4, s2",
            "vadd.f32 s5, s5, s3",
            "vmla.f32 s10, s13, s7",
            "vmls.f32 s11, s13, s6",
            "vadd.f32 s10, s10, s1",
            "vadd.f32 s6, s6, s10",
            "vadd.f32 s7, s7, s11",
            "vstmia {xp}!, {{s4-s7}}",
            "subs {k}, {k}, #1",
            "bne 2b",
            "3:",
            "lsls {n}, {n}, #31",
            "beq 4f",
            "vldmia {cp}!, {{s8-s11}}",
            "vldmia {xp}, {{s4-s5}}",
            "vmla.f32 s0, s10, s4",
            "vmul.f32 s2, s8, s4",
            "vmul.f32 s3, s8, s5",
            "vmla.f32 s0, s11, s5",
            "vmla.f32 s2, s9, s5",
            "vmls.f32 s3, s9, s4",
            "vadd.f32 s2, s2, s1",
            "vadd.f32 s4, s4, s2",
            "vadd.f32 s5, s5, s3",
            "vstmia {xp}, {{s4-s5}}",
            "4:",
            // ---- real poles: {cp} is where the pairs' coefficients end
            "ldr {n}, [{f}, #{off_nr}]",
            "cmp {n}, #0",
            "beq 6f",
            "add {k}, {f}, #{off_coeffs_end}",
            "sub {k}, {k}, {cp}",
            "lsrs {k}, {k}, #3",
            "cmp {n}, {k}",
            "it hi",
            "movhi {n}, {k}",
            "cmp {n}, #0",
            "beq 6f",
            "add {xp}, {st}, #{off_xreal}",
            "5:",
            "vldmia {cp}!, {{s8-s9}}",
            "vldr s4, [{xp}]",
            "vmla.f32 s0, s9, s4",
            "vmul.f32 s5, s8, s4",
            "vadd.f32 s5, s5, s1",
            "vadd.f32 s4, s4, s5",
            "vstmia {xp}!, {{s4}}",
            "subs {n}, {n}, #1",
            "bne 5b",
            "6:",
            // ---- FIR taps
            "ldr {n}, [{f}, #{off_fl}]",
            "cmp {n}, #24",
            "it hi",
            "movhi {n}, #24",
            "add {cp}, {f}, #{off_fir}",
            "add {xp}, {st}, #{off_hist}",
            "vmov.f32 s3, s1",
            "lsrs {k}, {n}, #2",
            "beq 8f",
            "7:",
            "vldmia {cp}!, {{s8-s11}}",
            "vldmia {xp}, {{s4-s7}}",
            "vmul.f32 s12, s8, s4",
            "vmul.f32 s13, s9, s5",
            "vadd.f32 s0, s0, s12",
            "vmul.f32 s14, s10, s6",
            "vadd.f32 s0, s0, s13",
            "vmul.f32 s15, s11, s7",
            "vadd.f32 s0, s0, s14",
            "vstmia {xp}!, {{s3-s6}}",
            "vadd.f32 s0, s0, s15",
            "vmov.f32 s3, s7",
            "subs {k}, {k}, #1",
            "bne 7b",
            "8:",
            "ands {n}, {n}, #3",
            "beq 10f",
            "9:",
            "vldmia {cp}!, {{s8}}",
            "vldmia {xp}, {{s4}}",
            "vmul.f32 s12, s8, s4",
            "vadd.f32 s0, s0, s12",
            "vstmia {xp}!, {{s3}}",
            "vmov.f32 s3, s4",
            "subs {n}, {n}, #1",
            "bne 9b",
            "10:",
            "vmov {y}, s0",
            f = in(reg) f as *const AxisFilter,
            st = in(reg) state as *mut AxisState,
            u = in(reg) u,
            y = lateout(reg) y,
            cp = out(reg) _,
            xp = out(reg) _,
            n = out(reg) _,
            k = out(reg) _,
            off_d = const OFF_D,
            off_np = const OFF_NPAIRS,
            off_nr = const OFF_NREALS,
            off_coeffs = const OFF_COEFFS,
            off_coeffs_end = const OFF_COEFFS_END,
            off_fir = const OFF_FIR,
            off_fl = const OFF_FIRLEN,
            off_x = const OFF_X,
            off_xreal = const OFF_XREAL,
            off_hist = const OFF_HIST,
            out("s0") _,
            out("s1") _,
            out("s2") _,
            out("s3") _,
            out("s4") _,
            out("s5") _,
            out("s6") _,
            out("s7") _,
            out("s8") _,
            out("s9") _,
            out("s10") _,
            out("s11") _,
            out("s12") _,
            out("s13") _,
            out("s14") _,
            out("s15") _,
            options(nostack),
        );
    }
    y
}
