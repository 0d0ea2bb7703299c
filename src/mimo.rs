//! The 3x3 compensator: one modal realization whose modes are shared by the
//! three force estimates (DESIGN.md, "Signal chain": the dynamometer as one
//! 3x3 system).
//!
//! The filter maps the three measured forces `u = (u_x, u_y, u_z)` (N) to
//! the three estimates `y` (N). As in [`crate::kernel`], every 2x2 block is
//! stored as `Δ = A − I` in f32 and is a normal-form conjugate pair or
//! diagonal; each block now has an input row per state (`b`, 2x3) and an
//! output column per estimate (`c`, 3x2). Per sample, in this order:
//!
//! ```text
//! y_i  = Σ_j d_ij·u_j                                   (j = x, y, z in turn)
//! pair:  y_i += c_i1·x₁ ;  y_i += c_i2·x₂               (i = x, y, z; x of sample k)
//!        x₁ ← x₁ + ((σ·x₁ + ω·x₂) + ((b₁x·u_x + b₁y·u_y) + b₁z·u_z))
//!        x₂ ← x₂ + ((σ·x₂ − ω·x₁) + ((b₂x·u_x + b₂y·u_y) + b₂z·u_z))
//! real:  y_i += c_i·x ;  x ← x + (σ·x + ((b_x·u_x + b_y·u_y) + b_z·u_z))
//! FIR:   y_i += Σ_j h_m,ij·u_j[k−m]                     (m = 1, 2, …; j in turn)
//! ```
//!
//! Sections run in their order (pairs and reals interleaved as given), so
//! the result is the same to the bit on the host, the box and under QEMU:
//! no product is fused (Rust never contracts `a·b + c`). On the Cortex-M4F
//! the step is one block of assembly with the same operations in the same
//! order (`mimo_m4.rs`).
//!
//! Configuration ([`MimoFilter`]) is apart from state ([`MimoState`]).

use crate::kernel::{FilterError, Section, RUNAWAY_LIMIT_N};

// `MimoFilter::step` in assembly for the Cortex-M4F (one `vldm` per
// section's coefficients, multiply-adds as `vmul` + `vadd`); every other
// target runs the Rust loops.
#[cfg(all(target_arch = "arm", target_os = "none", target_abi = "eabihf"))]
#[allow(unsafe_code)]
#[path = "mimo_m4.rs"]
mod m4;

/// Inputs and outputs of the 3x3 filter: the axes x, y, z.
pub const MIMO_AXES: usize = 3;

/// Most 2x2 sections of a 3x3 filter (order ≤ 96): the plant's shared modes
/// and the compensator's own slow poles.
pub const MAX_MIMO_SECTIONS: usize = 48;

/// Most FIR taps (delays 1..=24 samples) of a 3x3 filter, each a 3x3 matrix.
pub const MAX_MIMO_FIR: usize = 24;

/// One 2x2 block of the 3x3 realization.
///
/// Units: `u` and `y` in N; the states carry no physical unit.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct MimoSection {
    /// `A − I` of this block, row-major `[Δ11, Δ12, Δ21, Δ22]`.
    pub delta: [f32; 4],
    /// Input rows: `b[s][j]` is state `s`'s gain from input `j`.
    pub b: [[f32; MIMO_AXES]; 2],
    /// Output columns: `c[i][s]` is output `i`'s gain on state `s`.
    pub c: [[f32; 2]; MIMO_AXES],
}

impl MimoSection {
    /// Whether every coefficient is finite.
    pub fn is_finite(&self) -> bool {
        self.delta.iter().chain(self.b.iter().flatten()).chain(self.c.iter().flatten()).all(|v| v.is_finite())
    }

    /// The 2x2 block alone (input and output gains left out), for its
    /// stability test ([`Section::poles_within`]).
    pub fn block(&self) -> Section {
        Section { delta: self.delta, b: [0.0; 2], c: [0.0; 2] }
    }

    /// A normal-form pair (`Δ11 = Δ22`, `Δ21 = −Δ12 ≠ 0`).
    pub fn is_pair(&self) -> bool {
        let [d11, d12, d21, d22] = self.delta;
        d11 == d22 && d21 == -d12 && d12 != 0.0
    }

    /// Diagonal (`Δ12 = Δ21 = 0`): up to two real poles.
    fn is_diagonal(&self) -> bool {
        self.delta[1] == 0.0 && self.delta[2] == 0.0
    }
}

/// A 3x3 matrix of forces, row `i` = output, column `j` = input (N/N).
pub type Matrix3 = [[f32; MIMO_AXES]; MIMO_AXES];

/// The coefficients of the 3x3 compensator (configuration, no state).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MimoFilter {
    sections: [MimoSection; MAX_MIMO_SECTIONS],
    len: usize,
    d: Matrix3,
    fir: [Matrix3; MAX_MIMO_FIR],
    fir_len: usize,
}

impl MimoFilter {
    /// Build a filter from its sections, direct term `d` and FIR taps
    /// `fir[m−1]` (delay m samples). Every coefficient must be finite, every
    /// block stable and a normal-form pair or diagonal. The errors name the
    /// section or tap as [`FilterError`] does (`NonFinite(MAX_MIMO_SECTIONS)`
    /// for `d`).
    pub fn new(sections: &[MimoSection], d: Matrix3, fir: &[Matrix3]) -> Result<Self, FilterError> {
        if sections.len() > MAX_MIMO_SECTIONS {
            return Err(FilterError::TooManySections);
        }
        if fir.len() > MAX_MIMO_FIR {
            return Err(FilterError::TooManyTaps);
        }
        if !d.iter().flatten().all(|v| v.is_finite()) {
            return Err(FilterError::NonFinite(MAX_MIMO_SECTIONS));
        }
        let mut taps = [[[0.0; MIMO_AXES]; MIMO_AXES]; MAX_MIMO_FIR];
        for (m, (dst, h)) in taps.iter_mut().zip(fir).enumerate() {
            if !h.iter().flatten().all(|v| v.is_finite()) {
                return Err(FilterError::NonFiniteTap(m));
            }
            *dst = *h;
        }
        let mut all = [MimoSection::default(); MAX_MIMO_SECTIONS];
        for (i, (dst, s)) in all.iter_mut().zip(sections).enumerate() {
            if !s.is_finite() {
                return Err(FilterError::NonFinite(i));
            }
            if !s.block().is_stable() {
                return Err(FilterError::Unstable(i));
            }
            if !(s.is_pair() || s.is_diagonal()) {
                return Err(FilterError::NotModal(i));
            }
            *dst = *s;
        }
        Ok(MimoFilter { sections: all, len: sections.len(), d, fir: taps, fir_len: fir.len() })
    }

    /// The sections, in the order the kernel runs them.
    pub fn sections(&self) -> &[MimoSection] {
        self.sections.get(..self.len).unwrap_or(&[])
    }

    /// The direct term `d` (output × input).
    pub fn d(&self) -> &Matrix3 {
        &self.d
    }

    /// FIR taps `h_1..h_m` (delays 1..m samples), each output × input.
    pub fn fir(&self) -> &[Matrix3] {
        self.fir.get(..self.fir_len).unwrap_or(&[])
    }

    /// (pole pairs, diagonal sections): what the kernel runs per sample.
    pub fn kernel_counts(&self) -> (usize, usize) {
        let pairs = self.sections().iter().filter(|s| s.is_pair()).count();
        (pairs, self.len - pairs)
    }

    /// Bound on the ℓ1 norm of output `row`'s impulse response, summed over
    /// the three inputs (N/N): for |u_j| ≤ U on every input, |y_row| never
    /// exceeds this times U (exact arithmetic). Per section, the bound of
    /// [`Section::gain_bound`] with `b` the row sums of |B| and `c` the
    /// magnitudes of the row's output gains (for a pair:
    /// `2·‖c_row‖₁·Σ_j ‖b_j‖₁ / (1 − ρ²)`), plus `Σ_j |d_row,j|` and the
    /// taps' `Σ_m Σ_j |h_m,row,j|`. `∞` for an unstable section; 0 for a
    /// row outside 0..3. Computed in f64 from the stored f32 values.
    pub fn row_gain_bound(&self, row: usize) -> f64 {
        let Some(d) = self.d.get(row) else { return 0.0 };
        let abs_sum = |v: &[f32]| v.iter().map(|x| f64::from(x.abs())).sum::<f64>();
        let mut bound = abs_sum(d);
        for h in self.fir() {
            bound += h.get(row).map_or(0.0, |r| abs_sum(r));
        }
        for s in self.sections() {
            let c = s.c.get(row).copied().unwrap_or([0.0; 2]);
            let folded = Section {
                delta: s.delta,
                b: [abs_sum(&s.b[0]) as f32, abs_sum(&s.b[1]) as f32],
                c: [c[0].abs(), c[1].abs()],
            };
            // The f32 row sums round to nearest: make the bound an upper
            // bound again by one relative ulp.
            bound += folded.gain_bound() * (1.0 + f64::from(f32::EPSILON));
        }
        bound
    }

    /// The DC gain matrix `H(1)` (N/N; row = output, column = input):
    /// `d + Σ_m h_m + Σ_sections C·(−Δ)⁻¹·B`, the filter's response to a
    /// constant force. Non-finite entries when a section has a pole at
    /// z = 1. Computed in f64 from the stored f32 values.
    pub fn dc_gain(&self) -> [[f64; MIMO_AXES]; MIMO_AXES] {
        let mut g = [[0.0f64; MIMO_AXES]; MIMO_AXES];
        for (i, gi) in g.iter_mut().enumerate() {
            for (j, gij) in gi.iter_mut().enumerate() {
                let mut v = f64::from(self.d[i][j]);
                for h in self.fir() {
                    v += f64::from(h[i][j]);
                }
                for s in self.sections() {
                    let sec = Section { delta: s.delta, b: [s.b[0][j], s.b[1][j]], c: s.c[i] };
                    v += sec.dc_gain();
                }
                *gij = v;
            }
        }
        g
    }

    /// One sample: the three estimates `y[k]` (N) from the three measured
    /// forces `u[k]` (N), advancing the state (module equation). No
    /// allocation, no panics, O(sections + 9·taps).
    #[inline]
    pub fn step(&self, state: &mut MimoState, u: [f32; MIMO_AXES]) -> [f32; MIMO_AXES] {
        // Cortex-M4F: the whole step in one block of hand-scheduled
        // assembly, bit-identical (mimo_m4.rs).
        #[cfg(all(target_arch = "arm", target_os = "none", target_abi = "eabihf"))]
        {
            m4::step(self, state, u)
        }
        #[cfg(not(all(target_arch = "arm", target_os = "none", target_abi = "eabihf")))]
        {
            self.step_rust(state, u)
        }
    }

    /// [`step`](Self::step) in Rust: the definition the Cortex-M4F's
    /// assembly (`mimo_m4.rs`) matches bit for bit.
    #[cfg(not(all(target_arch = "arm", target_os = "none", target_abi = "eabihf")))]
    #[inline]
    fn step_rust(&self, state: &mut MimoState, u: [f32; MIMO_AXES]) -> [f32; MIMO_AXES] {
        let mut y = [0.0f32; MIMO_AXES];
        for (yi, di) in y.iter_mut().zip(&self.d) {
            *yi = di[0] * u[0];
            *yi += di[1] * u[1];
            *yi += di[2] * u[2];
        }
        for (s, x) in self.sections().iter().zip(state.x.iter_mut()) {
            *x = section_update(s, *x, u, &mut y);
        }
        // hist[m] holds u[k−1−m]: accumulate h_{m+1}·u[k−1−m] in ascending
        // m and shift u[k] in (each slot takes its predecessor's old value).
        let m = self.fir_len.min(MAX_MIMO_FIR);
        let mut carry = u;
        for (h, past) in self.fir[..m].iter().zip(state.hist[..m].iter_mut()) {
            let old = *past;
            for (yi, hi) in y.iter_mut().zip(h) {
                *yi += hi[0] * old[0];
                *yi += hi[1] * old[1];
                *yi += hi[2] * old[2];
            }
            *past = carry;
            carry = old;
        }
        y
    }

    /// [`step`](Self::step) with the runaway guard of
    /// [`crate::kernel::AxisFilter::step_guarded`]: if any estimate is
    /// non-finite or beyond [`RUNAWAY_LIMIT_N`], the state is reset, the reset
    /// counted, and `None` returned.
    #[inline]
    pub fn step_guarded(&self, state: &mut MimoState, u: [f32; MIMO_AXES]) -> Option<[f32; MIMO_AXES]> {
        let y = self.step(state, u);
        // `!(a <= b)` is also true for NaN.
        if y.iter().any(|v| !(v.abs() <= RUNAWAY_LIMIT_N)) {
            state.reset();
            state.nonfinite_resets = state.nonfinite_resets.wrapping_add(1);
            None
        } else {
            Some(y)
        }
    }

    /// Filter a block of samples: `output[k] = step(input[k])` for the common
    /// length of the slices.
    pub fn process(&self, state: &mut MimoState, input: &[[f32; MIMO_AXES]], output: &mut [[f32; MIMO_AXES]]) {
        for (u, y) in input.iter().zip(output.iter_mut()) {
            *y = self.step(state, *u);
        }
    }
}

/// `b·u` for one state's input row, in the module's order.
#[cfg(not(all(target_arch = "arm", target_os = "none", target_abi = "eabihf")))]
#[inline(always)]
fn input_term(b: &[f32; MIMO_AXES], u: &[f32; MIMO_AXES]) -> f32 {
    (b[0] * u[0] + b[1] * u[1]) + b[2] * u[2]
}

/// One sample of a section (module equation): adds its outputs to `y` and
/// returns the next state.
#[cfg(not(all(target_arch = "arm", target_os = "none", target_abi = "eabihf")))]
#[inline(always)]
fn section_update(s: &MimoSection, [x1, x2]: [f32; 2], u: [f32; MIMO_AXES], y: &mut [f32; MIMO_AXES]) -> [f32; 2] {
    for (yi, ci) in y.iter_mut().zip(&s.c) {
        *yi += ci[0] * x1;
        *yi += ci[1] * x2;
    }
    let [d11, d12, d21, d22] = s.delta;
    let (u1, u2) = (input_term(&s.b[0], &u), input_term(&s.b[1], &u));
    if d12 == 0.0 && d21 == 0.0 {
        [x1 + (d11 * x1 + u1), x2 + (d22 * x2 + u2)]
    } else {
        // Normal form: σ = Δ11 = Δ22, ω = Δ12 = −Δ21.
        [x1 + ((d11 * x1 + d12 * x2) + u1), x2 + ((d22 * x2 + d21 * x1) + u2)]
    }
}

/// The memory of the 3x3 filter (state, no configuration).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MimoState {
    /// The states `[x₁, x₂]` of each section, in section order.
    pub x: [[f32; 2]; MAX_MIMO_SECTIONS],
    /// Past inputs of the FIR part: `hist[m] = u[k−1−m]`.
    pub hist: [[f32; MIMO_AXES]; MAX_MIMO_FIR],
    /// How many times the runaway guard has reset this state.
    pub nonfinite_resets: u32,
}

impl Default for MimoState {
    fn default() -> Self {
        MimoState { x: [[0.0; 2]; MAX_MIMO_SECTIONS], hist: [[0.0; MIMO_AXES]; MAX_MIMO_FIR], nonfinite_resets: 0 }
    }
}

impl MimoState {
    /// Zero the filter memory (the reset counter is kept).
    pub fn reset(&mut self) {
        self.x = [[0.0; 2]; MAX_MIMO_SECTIONS];
        self.hist = [[0.0; MIMO_AXES]; MAX_MIMO_FIR];
    }
}
