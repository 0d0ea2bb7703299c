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

use super::{MAX_FIR, MAX_SECTIONS};

/// The first `n_pairs` pairs of one sample: for each pair `i < n_pairs` in
/// order, `x[i] = pair_update(pair i of coeffs, x[i], u, y)`, pair `i`
/// being `coeffs[4i..4i + 4]` (the kernel form's layout: the pairs first);
/// `n_pairs` is clamped to what both arrays hold (module documentation).
/// Fixed-size arrays and one clamp, so the call's set-up is a compare, not
/// the bounds of two slices.
#[inline(always)]
pub(super) fn pairs_step(
    coeffs: &[f32; 4 * MAX_SECTIONS],
    n_pairs: usize,
    x: &mut [[f32; 2]; MAX_SECTIONS],
    u: f32,
    y: &mut f32,
) {
    let n = n_pairs.min(MAX_SECTIONS);
    let mut acc = *y;
    // SAFETY: the asm reads `4 * n` f32 starting at `coeffs.as_ptr()` and
    // reads and writes `2 * n` f32 starting at `x.as_mut_ptr()`, ascending,
    // and no other memory. `n ≤ MAX_SECTIONS`, `coeffs` holds
    // `4 * MAX_SECTIONS` f32 and `x` `MAX_SECTIONS` contiguous `[f32; 2]`
    // (8 bytes, no padding); so every
    // access is in bounds and 4-byte aligned (VLDM/VSTM need word
    // alignment). `x` is a unique borrow (writable) and `coeffs` a shared
    // one, so the two ranges do not overlap. The pointers and `n` are
    // `inout` and discarded (post-increment writeback, shifts); `k` is a
    // scratch output, allocated apart from the inputs; every S register the
    // code writes (`s0`-`s15`) is a declared clobber; `subs`/`lsrs`/`lsls`
    // change the flags, so no `preserves_flags`; no stack use (`nostack`).
    // FPSCR's rounding and flush-to-zero modes are left unchanged.
    unsafe {
        core::arch::asm!(
            "vmov s0, {y}",
            "vmov s1, {u}",
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
            "vldmia {cp}, {{s8-s11}}",
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
            "vmov {y}, s0",
            cp = inout(reg) coeffs.as_ptr() => _,
            xp = inout(reg) x.as_mut_ptr() => _,
            n = inout(reg) n => _,
            k = out(reg) _,
            y = inout(reg) acc,
            u = in(reg) u,
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
    *y = acc;
}

/// The FIR part of one sample (the loop of `AxisFilter::step` on every
/// other target): for each tap `j < m` in ascending order, `y += h[j] ·
/// hist[j]`, and the history moves on by one (`hist[0] = u`, `hist[j] =`
/// the old `hist[j − 1]`), with `m = fir_len` clamped to [`MAX_FIR`].
///
/// Four taps per pass: one `vldmia` for their coefficients, one for their
/// history, four products (`vmul`) added to `y` in tap order (`vadd`,
/// interleaved with the next product), one `vstmia` of the shifted history
/// (the carried-in value, then the first three loaded), a `vmov` of the
/// fourth as the next carry: 14 instructions per four taps (the Rust loop:
/// 4.5-5.4 per tap, with one `vldr`/`vstr` per value); the remaining
/// `m mod 4` taps one at a time (7 instructions each). `y` stays in `s0`,
/// the carry in `s3`.
///
/// `vmul` + `vadd` rather than `vmla`: the same two roundings (`vmla` is
/// `FPAdd(y, FPMul(h, x))`, not fused: [`pairs_step`]'s argument), so the
/// same bits, in 2 cycles instead of 3 by the Cortex-M4 TRM (VMLA 3, VMUL 1,
/// VADD 1); a block of four: `vldmia` 5 + 5, 4 + 4, `vstmia` 5, `vmov`,
/// `subs`, `bne` 2-4 = 27-29 cycles, 6.75-7.25 per tap (8 per tap with
/// `vmla`). Which is faster on the silicon is for the DWT cycle counter to
/// confirm (the pair loop keeps `vmla`, for its instruction count).
///
/// **Bit-identical to the Rust loop:** the same products, added to `y` in
/// the same order, and the same values stored (copies, no arithmetic).
/// `tests/qemu_bit_exact.rs` runs it against the host's Rust loop.
#[inline(always)]
pub(super) fn fir_step(h: &[f32; MAX_FIR], fir_len: usize, hist: &mut [f32; MAX_FIR], u: f32, y: &mut f32) {
    let m = fir_len.min(MAX_FIR);
    let mut acc = *y;
    // SAFETY: the asm reads `m` f32 starting at `h.as_ptr()` and reads and
    // writes `m` f32 starting at `hist.as_mut_ptr()`, ascending (the blocks
    // of four first, then the rest one by one), and no other memory.
    // `m ≤ MAX_FIR`, the length of both arrays, so every access is in
    // bounds and 4-byte aligned (VLDM/VSTM need word alignment). `hist` is
    // a unique borrow and `h` a shared one, so they do not overlap. The
    // pointers and `m` are `inout` and discarded; `k` is a scratch output
    // allocated apart from the inputs; every S register written (`s0`,
    // `s3`-`s15`) is a declared clobber; `lsrs`/`ands`/`subs` change the
    // flags; no stack use. FPSCR's modes are left unchanged.
    unsafe {
        core::arch::asm!(
            "vmov s0, {y}",
            "vmov s3, {u}",
            "lsrs {k}, {m}, #2",
            "beq 3f",
            "2:",
            "vldmia {hp}!, {{s8-s11}}",
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
            "bne 2b",
            "3:",
            "ands {m}, {m}, #3",
            "beq 5f",
            "4:",
            "vldmia {hp}!, {{s8}}",
            "vldmia {xp}, {{s4}}",
            "vmul.f32 s12, s8, s4",
            "vadd.f32 s0, s0, s12",
            "vstmia {xp}!, {{s3}}",
            "vmov.f32 s3, s4",
            "subs {m}, {m}, #1",
            "bne 4b",
            "5:",
            "vmov {y}, s0",
            hp = inout(reg) h.as_ptr() => _,
            xp = inout(reg) hist.as_mut_ptr() => _,
            m = inout(reg) m => _,
            k = out(reg) _,
            y = inout(reg) acc,
            u = in(reg) u,
            out("s0") _,
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
    *y = acc;
}
