//! [`MimoFilter::step`](super::MimoFilter::step) for the Cortex-M4F
//! (bare-metal ARM with hardware float, `eabihf`), in hand-scheduled
//! assembly. Every other target runs the Rust loops of `step`.
//!
//! LLVM compiles a 3x3 section with one `vldr` per coefficient and state
//! (18), `vmla` for its twelve multiply-adds (3 cycles each by the
//! Cortex-M4 TRM) and a floating-point compare for the pair/diagonal test:
//! 49.5 instructions per pair under QEMU. Here a section takes
//!
//! * one `vldmia` for its 16 coefficients ([`MimoSection`](super::MimoSection)
//!   is `Δ[4], b[2][3], c[3][2]`, and the sections are contiguous) and one
//!   for its two states, one `vstmia` for the new states;
//! * each multiply-add as `vmul` + `vadd` (two roundings, as `vmla` and as
//!   Rust's `a + b * c`: 2 cycles instead of 3 by the TRM);
//! * the pair/diagonal test on the bits of `Δ12` and `Δ21` in core
//!   registers (`(Δ12 | Δ21) << 1 == 0`: both ±0, which is what `== 0.0`
//!   tests), the diagonal path out of line.
//!
//! The direct term is one `vldmia` of `d` (9) and the FIR two taps per pass
//! (one `vldmia` of a tap's 9 coefficients, one of its 3 past inputs, one
//! `vstmia` of the 3 shifted in; the carried inputs alternate between
//! `s3-s5` and `s17-s19`, so nothing is moved), the odd last tap alone.
//! `u` comes from and `y` goes to memory (one `vldmia` / `vstmia` each).
//!
//! Registers: `y` in `s0-s2`, `u` in `s3-s5` (then the FIR's carry), a
//! section's states in `s6-s7`, its coefficients in `s8-s23`, whose
//! registers take the products once a coefficient is used.
//!
//! **Bit-identical to the Rust `step`** (module equation of
//! [`super`]): the same operations on the same operands in the same order.
//! Each `y_i` accumulates in `s0 + i`: `d_i0·u0`, `+ d_i1·u1`, `+ d_i2·u2`,
//! then each section's `c_i1·x1` and `c_i2·x2` in section order, then each
//! tap's `h_i0·u0[k−m]`, `h_i1·…`, `h_i2·…` in tap order. The three
//! accumulators never mix, so interleaving their operations changes no
//! bit. A state's input term is `(b0·u0 + b1·u1) + b2·u2`; a pair's
//! `x1 + ((Δ11·x1 + Δ12·x2) + ub1)` and `x2 + ((Δ22·x2 + Δ21·x1) + ub2)`, a
//! diagonal's `x1 + (Δ11·x1 + ub1)` and `x2 + (Δ22·x2 + ub2)`. `vmul`
//! then `vadd` is `FPAdd(a, FPMul(b, c))`, as Rust's `a + b * c` (rustc never
//! fuses); the first operand of every addition is the one Rust writes
//! first. FPSCR's rounding and flush-to-zero modes are left unchanged.
//! `tests/qemu_bit_exact.rs` compares it with the host's Rust kernel, bit
//! for bit, on pairs and diagonal sections interleaved, and on even and
//! odd tap counts.
//!
//! The loop counts depend only on the configuration (sections, taps),
//! never on the signal; the sections' branch only on their kind.

use super::{MimoFilter, MimoState, MAX_MIMO_FIR, MAX_MIMO_SECTIONS, MIMO_AXES};
use core::mem::offset_of;

/// Byte offsets the assembly reads the filter and the state at.
const OFF_SECTIONS: usize = offset_of!(MimoFilter, sections);
const OFF_LEN: usize = offset_of!(MimoFilter, len);
const OFF_D: usize = offset_of!(MimoFilter, d);
const OFF_FIR: usize = offset_of!(MimoFilter, fir);
const OFF_FIRLEN: usize = offset_of!(MimoFilter, fir_len);
const OFF_X: usize = offset_of!(MimoState, x);
const OFF_HIST: usize = offset_of!(MimoState, hist);
// The immediates below are Thumb-2 12-bit offsets; the loops' strides are
// the types' sizes.
const _: () = assert!(OFF_SECTIONS < 4096 && OFF_LEN < 4096 && OFF_D < 4096 && OFF_FIR < 4096 && OFF_FIRLEN < 4096);
const _: () = assert!(OFF_X < 4096 && OFF_HIST < 4096);
const _: () = assert!(MAX_MIMO_SECTIONS == 48 && MAX_MIMO_FIR == 24 && MIMO_AXES == 3);
const _: () = assert!(core::mem::size_of::<super::MimoSection>() == 64);
// A section's coefficients in the order the registers take them.
const _: () = assert!(
    offset_of!(super::MimoSection, delta) == 0
        && offset_of!(super::MimoSection, b) == 16
        && offset_of!(super::MimoSection, c) == 40
);
const _: () = assert!(core::mem::size_of::<super::Matrix3>() == 36);

/// One FIR tap's 18 float operations (module equation, FIR line): the
/// tap's coefficients `h_ij` in `s8-s16` (row-major) times the past inputs
/// in the three registers given, added to `y` in `s0-s2`, each `y_i` in
/// `j` order; the products overwrite the coefficients.
macro_rules! tap {
    ($o0:literal, $o1:literal, $o2:literal) => {
        concat!(
            "vmul.f32 s8, s8, ",
            $o0,
            "\n",
            "vmul.f32 s11, s11, ",
            $o0,
            "\n",
            "vmul.f32 s14, s14, ",
            $o0,
            "\n",
            "vadd.f32 s0, s0, s8\n",
            "vmul.f32 s9, s9, ",
            $o1,
            "\n",
            "vadd.f32 s1, s1, s11\n",
            "vmul.f32 s12, s12, ",
            $o1,
            "\n",
            "vadd.f32 s2, s2, s14\n",
            "vmul.f32 s15, s15, ",
            $o1,
            "\n",
            "vadd.f32 s0, s0, s9\n",
            "vmul.f32 s10, s10, ",
            $o2,
            "\n",
            "vadd.f32 s1, s1, s12\n",
            "vmul.f32 s13, s13, ",
            $o2,
            "\n",
            "vadd.f32 s2, s2, s15\n",
            "vmul.f32 s16, s16, ",
            $o2,
            "\n",
            "vadd.f32 s0, s0, s10\n",
            "vadd.f32 s1, s1, s13\n",
            "vadd.f32 s2, s2, s16",
        )
    };
}

/// One sample of `f` (the module equation of [`super`], in its order).
#[inline(always)]
pub(super) fn step(f: &MimoFilter, state: &mut MimoState, u: [f32; MIMO_AXES]) -> [f32; MIMO_AXES] {
    let mut y = [0.0f32; MIMO_AXES];
    // SAFETY: the asm reads `f` and `u`, reads and writes `state`, and
    // writes `y`, at the field offsets above (computed by `offset_of!`), and
    // no other memory:
    // * `len`, `fir_len`: one word each; `d`: 9 f32; `u`, `y`: 3 f32 each;
    // * sections: `n ≤ MAX_MIMO_SECTIONS` (clamped in the asm), `16n` f32
    //   of `sections` and `2n` of `state.x` (`MAX_MIMO_SECTIONS` pairs);
    // * taps: `m ≤ MAX_MIMO_FIR` (clamped), `9m` f32 of `fir` and `3m` of
    //   `state.hist` (both `MAX_MIMO_FIR` long);
    // all ascending, 4-byte aligned (f32/usize fields; VLDM/VSTM need word
    // alignment). `state` and `y` are unique borrows, `f` and `u` shared:
    // no overlap. The pointers and counters are scratch outputs allocated
    // apart from the inputs (no input register is written); every S
    // register written (`s0`-`s23`) is a declared clobber, so the compiler
    // saves the callee-saved `s16`-`s23`; the flags change (no
    // `preserves_flags`); no stack use by the asm itself.
    unsafe {
        core::arch::asm!(
            "vldmia {up}, {{s3-s5}}",
            // ---- direct term: y_i = (d_i0·u0 + d_i1·u1) + d_i2·u2
            "add {cp}, {f}, #{off_d}",
            "vldmia {cp}, {{s8-s16}}",
            "vmul.f32 s0, s8, s3",
            "vmul.f32 s9, s9, s4",
            "vmul.f32 s1, s11, s3",
            "vmul.f32 s12, s12, s4",
            "vmul.f32 s2, s14, s3",
            "vmul.f32 s15, s15, s4",
            "vadd.f32 s0, s0, s9",
            "vmul.f32 s10, s10, s5",
            "vadd.f32 s1, s1, s12",
            "vmul.f32 s13, s13, s5",
            "vadd.f32 s2, s2, s15",
            "vmul.f32 s16, s16, s5",
            "vadd.f32 s0, s0, s10",
            "vadd.f32 s1, s1, s13",
            "vadd.f32 s2, s2, s16",
            // ---- sections
            "ldr {n}, [{f}, #{off_len}]",
            "cmp {n}, #48",
            "it hi",
            "movhi {n}, #48",
            "cmp {n}, #0",
            "beq 7f",
            "add {cp}, {f}, #{off_sections}",
            "add {xp}, {st}, #{off_x}",
            "2:",
            // s8-s11 Δ11 Δ12 Δ21 Δ22, s12-s14 b1, s15-s17 b2,
            // s18-s19 c_x, s20-s21 c_y, s22-s23 c_z
            "vldmia {cp}!, {{s8-s23}}",
            "vldmia {xp}, {{s6-s7}}",
            "vmov {ra}, s9",
            "vmov {rb}, s10",
            "vmul.f32 s18, s18, s6",
            "vmul.f32 s19, s19, s7",
            "vmul.f32 s20, s20, s6",
            "vmul.f32 s21, s21, s7",
            "vadd.f32 s0, s0, s18",
            "vmul.f32 s22, s22, s6",
            "vadd.f32 s1, s1, s20",
            "vmul.f32 s23, s23, s7",
            "vadd.f32 s2, s2, s22",
            "vmul.f32 s12, s12, s3",
            "vadd.f32 s0, s0, s19",
            "vmul.f32 s13, s13, s4",
            "vadd.f32 s1, s1, s21",
            "vmul.f32 s14, s14, s5",
            "vadd.f32 s2, s2, s23",
            "vmul.f32 s15, s15, s3",
            "vadd.f32 s12, s12, s13",
            "vmul.f32 s16, s16, s4",
            "vmul.f32 s17, s17, s5",
            "vadd.f32 s15, s15, s16",
            "vadd.f32 s12, s12, s14",
            "vadd.f32 s15, s15, s17",
            "orr {ra}, {ra}, {rb}",
            "lsls {ra}, {ra}, #1",
            "beq 5f",
            // pair: t1 = (Δ11·x1 + Δ12·x2) + ub1, t2 = (Δ22·x2 + Δ21·x1) + ub2
            "vmul.f32 s18, s8, s6",
            "vmul.f32 s9, s9, s7",
            "vmul.f32 s19, s11, s7",
            "vmul.f32 s10, s10, s6",
            "vadd.f32 s18, s18, s9",
            "vadd.f32 s19, s19, s10",
            "vadd.f32 s18, s18, s12",
            "vadd.f32 s19, s19, s15",
            "3:",
            "vadd.f32 s6, s6, s18",
            "vadd.f32 s7, s7, s19",
            "vstmia {xp}!, {{s6-s7}}",
            "subs {n}, {n}, #1",
            "bne 2b",
            "b 7f",
            // diagonal: t1 = Δ11·x1 + ub1, t2 = Δ22·x2 + ub2
            "5:",
            "vmul.f32 s18, s8, s6",
            "vmul.f32 s19, s11, s7",
            "vadd.f32 s18, s18, s12",
            "vadd.f32 s19, s19, s15",
            "b 3b",
            // ---- FIR taps: hist[m] = u[k−1−m]; carry (u[k] first) in
            // s3-s5, then s17-s19, alternately
            "7:",
            "ldr {n}, [{f}, #{off_fl}]",
            "cmp {n}, #24",
            "it hi",
            "movhi {n}, #24",
            "add {cp}, {f}, #{off_fir}",
            "add {xp}, {st}, #{off_hist}",
            "lsrs {ra}, {n}, #1",
            "beq 9f",
            "8:",
            "vldmia {cp}!, {{s8-s16}}",
            "vldmia {xp}, {{s17-s19}}",
            "vstmia {xp}!, {{s3-s5}}",
            tap!("s17", "s18", "s19"),
            "vldmia {cp}!, {{s8-s16}}",
            "vldmia {xp}, {{s3-s5}}",
            "vstmia {xp}!, {{s17-s19}}",
            tap!("s3", "s4", "s5"),
            "subs {ra}, {ra}, #1",
            "bne 8b",
            "9:",
            "lsls {n}, {n}, #31",
            "beq 10f",
            "vldmia {cp}, {{s8-s16}}",
            "vldmia {xp}, {{s17-s19}}",
            "vstmia {xp}, {{s3-s5}}",
            tap!("s17", "s18", "s19"),
            "10:",
            "vstmia {yp}, {{s0-s2}}",
            f = in(reg) f as *const MimoFilter,
            st = in(reg) state as *mut MimoState,
            up = in(reg) u.as_ptr(),
            yp = in(reg) y.as_mut_ptr(),
            cp = out(reg) _,
            xp = out(reg) _,
            n = out(reg) _,
            ra = out(reg) _,
            rb = out(reg) _,
            off_d = const OFF_D,
            off_len = const OFF_LEN,
            off_sections = const OFF_SECTIONS,
            off_fl = const OFF_FIRLEN,
            off_fir = const OFF_FIR,
            off_x = const OFF_X,
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
            out("s16") _,
            out("s17") _,
            out("s18") _,
            out("s19") _,
            out("s20") _,
            out("s21") _,
            out("s22") _,
            out("s23") _,
            options(nostack),
        );
    }
    y
}
