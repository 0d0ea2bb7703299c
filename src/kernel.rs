//! The compensator kernel: a fixed-capacity LTI filter in modal block-diagonal
//! "delta" form (DESIGN.md, signal chain step 6).
//!
//! Per axis the compensator is a discrete state-space filter of order ≤ 2·[`MAX_SECTIONS`]
//! realized as independent 2x2 sections (real Schur blocks of the filter matrix),
//! each stored as `Δ_i = A_i − I`, `b_i` and `c_i` ([`Section`], the image's
//! record). The kernel runs two shapes of section, which is what the host's
//! modal realization produces:
//!
//! - a **conjugate pole pair** in real normal form, `Δ = [[σ, ω], [−ω, σ]]`,
//!   `b = [β, 0]` (ω ≠ 0);
//! - a **diagonal** section, `Δ = [[σ₁, 0], [0, σ₂]]`: up to two real poles
//!   (a state with `b_j·c_j = 0` adds exactly nothing and is dropped; the
//!   padding state of [`Section::first_order`] is one of those).
//!
//! [`AxisFilter::with_fir`] rejects any other shape ([`FilterError::NotModal`]).
//! It folds `β` into the output row (the state is scaled by `1/β`, which is
//! exact when `β` is a power of two; the host writes `β = 1`), so per sample
//!
//! ```text
//! y[k]   = d·u[k] + Σ_pairs (c₁·x₁[k] + c₂·x₂[k]) + Σ_reals c·x[k] + Σ_{j=1..m} h_j·u[k−j]
//! pair:  x₁[k+1] = x₁ + ((σ·x₁ + ω·x₂) + u)
//!        x₂[k+1] = x₂ + (σ·x₂ − ω·x₁)               (x₁, x₂ of sample k)
//! real:  x[k+1]  = x + (σ·x + u)
//! ```
//!
//! evaluated in exactly this order in f32 (`y` accumulates `d·u`, then every
//! pair's `c₁·x₁` and `c₂·x₂`, then every real pole, then the taps). Each
//! state changes by one addition of its small increment, so it is rounded
//! once per sample at its own scale; accumulating `σ·x` into the state
//! directly would round twice there and, for a slow mode driven by a steady
//! force, bias it: the 24-section step response of `tests/kernel_reference.rs`
//! then deviates 1.1·10⁻⁵ of its peak from the f64 reference instead of
//! 2.1·10⁻⁶. That is 9 float operations per pair (`vmla` is an
//! unfused multiply-add, so the M4 and x86-64 round alike); on the Cortex-M4F
//! `step` runs the pairs in assembly (`kernel_m4.rs`: one `vldm` for two
//! pairs' coefficients, one for their states, one `vstm`, 11.5 instructions
//! per pair), everywhere else in Rust. BENCHMARKS.md has the instruction
//! counts.
//!
//! The short FIR part `h_1..h_m` (m ≤ [`MAX_FIR`]) carries the compensator's
//! fast poles (|z| ≲ 0.5, including the exact poles at z = 0 of a fixed-lag
//! smoother's delay chain), whose modal split would be ill-conditioned; their
//! impulse response is exactly finite or negligible after m samples (m ≤ 24).
//! A fast pole left in a section next to that cluster has a large residue
//! that the taps cancel, and the sum's terms grow far beyond the output
//! (the host tool checks this: `quantize::term_growth`).
//!
//! [`AxisFilter::step`] is the box's per-sample path;
//! [`AxisFilter::process_block`] computes the same numbers, bit for bit,
//! with the loops interchanged for offline throughput.
//!
//! Storing `A − I` instead of `A` keeps the pole positions of slow modes
//! (e.g. 100 Hz at 51.2 kHz, where `A ≈ I`) representable in f32: σ and ω
//! are stored with full relative precision instead of being rounded against
//! 1.0, and the updates add the small terms to the state, never `1 + σ`.
//!
//! Configuration ([`AxisFilter`]) is kept apart from state ([`AxisState`]), as in
//! QUARTIQ's `idsp`: coefficients can be swapped without touching the state
//! layout, and the state can be reset alone.

// The pair loop of `AxisFilter::step` in assembly for the Cortex-M4F (one
// `vldm` for two pairs' coefficients, one for their states, one `vstm`);
// every other target runs `pair_update` in Rust.
#[cfg(all(target_arch = "arm", target_os = "none", target_abi = "eabihf"))]
#[allow(unsafe_code)]
#[path = "kernel_m4.rs"]
mod m4;

/// Maximum number of 2x2 sections per axis (filter order ≤ 48).
pub const MAX_SECTIONS: usize = 24;

/// Maximum number of FIR taps (delays 1..=24 samples) per axis.
pub const MAX_FIR: usize = 24;

/// Magnitude above which the output is treated as a runaway filter (N).
///
/// A stable filter driven by a ±full-scale dynamometer signal (≤ 2·10^4 N for a
/// 9257-class table) stays far below this; reaching it means non-finite or
/// diverging state.
pub const RUNAWAY_LIMIT_N: f32 = 1.0e7;

/// One 2x2 section of the modal realization.
///
/// Units: `u` and `y` are forces in N; the states are scaled by the host tool
/// (the host writes unit input gain, `b = [1, 0]`) and carry no physical unit.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Section {
    /// `A − I` of this block, row-major `[Δ11, Δ12, Δ21, Δ22]`.
    pub delta: [f32; 4],
    /// Input column `b` of this block.
    pub b: [f32; 2],
    /// Output row `c` of this block.
    pub c: [f32; 2],
}

impl Section {
    /// A section that holds a single real pole `p` (z-domain), input gain `b`
    /// and output gain `c`: `Δ = p − 1`, second state unused.
    pub fn first_order(pole: f32, b: f32, c: f32) -> Self {
        Section { delta: [pole - 1.0, 0.0, 0.0, -1.0], b: [b, 0.0], c: [c, 0.0] }
    }

    /// Whether every coefficient is finite.
    pub fn is_finite(&self) -> bool {
        self.delta.iter().chain(self.b.iter()).chain(self.c.iter()).all(|v| v.is_finite())
    }

    /// Whether the block's poles (eigenvalues of `I + Δ`) lie strictly inside
    /// the unit circle. See [`poles_within`](Self::poles_within).
    pub fn is_stable(&self) -> bool {
        self.poles_within(1.0)
    }

    /// Whether both poles of the block lie strictly inside the circle of
    /// radius `r` (0 < r ≤ 1), by the Jury criterion on the characteristic
    /// polynomial `P(z) = z² − tr(A)·z + det(A)` scaled to that circle:
    /// `P(r) > 0`, `P(−r) > 0` and `|det A| < r²`.
    ///
    /// Evaluated in f64 from the stored f32 values, and written in terms of
    /// `tΔ = tr Δ`, `dΔ = det Δ` and `e = r − 1` so that poles next to
    /// `z = 1` keep their precision: `P(r) = e² − tΔ·e + dΔ`,
    /// `det A = 1 + tΔ + dΔ`.
    pub fn poles_within(&self, r: f64) -> bool {
        let [d11, d12, d21, d22] = self.delta.map(f64::from);
        let t = d11 + d22;
        let d = d11 * d22 - d12 * d21;
        let e = r - 1.0;
        let p_plus = e * e - t * e + d;
        let p_minus = r * r + (2.0 + t) * r + 1.0 + t + d;
        let det_a = 1.0 + t + d;
        p_plus > 0.0 && p_minus > 0.0 && det_a.abs() < r * r
    }

    /// Bound on the ℓ1 norm of the section's impulse response from `u` to
    /// its output term `c·x` (N/N): no |c·x| exceeds it for |u| ≤ 1, in
    /// exact arithmetic. `∞` for a section with a pole on or outside the
    /// unit circle.
    ///
    /// A normal-form pair is a scaled rotation, `A = ρ·R(θ)` with
    /// `ρ = |1 + σ + jω|`, so `|c·Aᵏ·b| ≤ ‖c‖₂·‖b‖₂·ρᵏ`, and the sum over k is
    /// `‖c‖₂·‖b‖₂ / (1 − ρ)`. Without a square root (no_std): `‖·‖₂ ≤ ‖·‖₁`
    /// and `1 − ρ = (1 − ρ²)/(1 + ρ) ≥ (1 − ρ²)/2`, so the bound used is
    /// `2·‖c‖₁·‖b‖₁ / (1 − ρ²)`, at most 2√2 times the former (√2 near
    /// z = 1, where slow modes are). A diagonal section's states are separate
    /// first-order filters: `Σ_j |b_j·c_j| / (1 − |1 + Δ_jj|)` over the states
    /// with `b_j·c_j ≠ 0`. Computed in f64 from the stored f32 values, with
    /// `1 − ρ²` and `1 − |p|` formed without cancellation.
    pub fn gain_bound(&self) -> f64 {
        let [d11, d12, d21, d22] = self.delta.map(f64::from);
        let [b1, b2] = self.b.map(f64::from);
        let [c1, c2] = self.c.map(f64::from);
        if d12 == 0.0 && d21 == 0.0 {
            return real_gain_bound(d11, b1 * c1) + real_gain_bound(d22, b2 * c2);
        }
        // 1 − ρ² = −(2σ + σ² + ω²) for A = [[1 + σ, ω], [−ω, 1 + σ]].
        let one_minus_rho2 = -(2.0 * d11 + d11 * d11 + d12 * d12);
        let gain = (b1.abs() + b2.abs()) * (c1.abs() + c2.abs());
        if one_minus_rho2 > 0.0 {
            2.0 * gain / one_minus_rho2
        } else {
            f64::INFINITY
        }
    }

    /// The section's steady-state gain from `u` to `c·x` (N/N): the value
    /// of its transfer function at z = 1, `c·(−Δ)⁻¹·b`. Non-finite when Δ
    /// is singular (a pole at z = 1). For a diagonal section, states with
    /// `b_j·c_j = 0` add nothing (the kernel drops them).
    pub fn dc_gain(&self) -> f64 {
        let [d11, d12, d21, d22] = self.delta.map(f64::from);
        let [b1, b2] = self.b.map(f64::from);
        let [c1, c2] = self.c.map(f64::from);
        if d12 == 0.0 && d21 == 0.0 {
            let real = |d: f64, bc: f64| if bc == 0.0 { 0.0 } else { -bc / d };
            return real(d11, b1 * c1) + real(d22, b2 * c2);
        }
        // x = −Δ⁻¹·b, with Δ⁻¹ = [[Δ22, −Δ12], [−Δ21, Δ11]] / det Δ.
        let det = d11 * d22 - d12 * d21;
        let x1 = -(d22 * b1 - d12 * b2) / det;
        let x2 = -(-d21 * b1 + d11 * b2) / det;
        c1 * x1 + c2 * x2
    }
}

/// ℓ1 gain of one first-order state `x ← x + Δ·x + b·u`, output `c·x`:
/// `|bc| / (1 − |1 + Δ|)`, 0 when `bc = 0` (the kernel drops the state), ∞
/// when the pole is on or outside the unit circle.
fn real_gain_bound(delta: f64, bc: f64) -> f64 {
    if bc == 0.0 {
        return 0.0;
    }
    let p = 1.0 + delta;
    // 1 − |p| without cancellation: −Δ for p ≥ 0, 2 + Δ for p < 0.
    let margin = if p >= 0.0 { -delta } else { 2.0 + delta };
    if margin > 0.0 {
        bc.abs() / margin
    } else {
        f64::INFINITY
    }
}

/// Error building an [`AxisFilter`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FilterError {
    /// More sections than [`MAX_SECTIONS`].
    TooManySections,
    /// A coefficient is NaN or infinite (section index; `MAX_SECTIONS` for `d`).
    NonFinite(usize),
    /// A section has a pole on or outside the unit circle (section index).
    Unstable(usize),
    /// More FIR taps than [`MAX_FIR`].
    TooManyTaps,
    /// An FIR tap is NaN or infinite (tap index, 0 = delay 1).
    NonFiniteTap(usize),
    /// A section is neither a conjugate pair in real normal form
    /// (`Δ11 = Δ22`, `Δ21 = −Δ12 ≠ 0`, `b2 = 0`) nor diagonal
    /// (`Δ12 = Δ21 = 0`) (section index).
    NotModal(usize),
}

impl core::fmt::Display for FilterError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            FilterError::TooManySections => write!(f, "more than {MAX_SECTIONS} sections"),
            FilterError::NonFinite(s) if s >= MAX_SECTIONS => f.write_str("the direct term d is not finite"),
            FilterError::NonFinite(s) => write!(f, "section {s} has a non-finite coefficient"),
            FilterError::Unstable(s) => write!(f, "section {s} has a pole on or outside the unit circle"),
            FilterError::TooManyTaps => write!(f, "more than {MAX_FIR} FIR taps"),
            FilterError::NonFiniteTap(t) => write!(f, "FIR tap {t} is not finite"),
            FilterError::NotModal(s) => write!(f, "section {s} is neither a normal-form pole pair nor diagonal"),
        }
    }
}

/// A conjugate pole pair as the kernel computes it: a normal-form section
/// with `β` folded into the output row, `[σ, ω, β·c₁, β·c₂]`: `σ = Δ11 =
/// Δ22`, `ω = Δ12 = −Δ21` (dimensionless), `β·c` (N per state unit, the
/// state scaled to unit input gain). The Cortex-M4F pair loop
/// (`kernel_m4.rs`) loads two consecutive pairs with one `vldmia`, in this
/// order.
type PairCoeffs = [f32; 4];

/// A real pole as the kernel computes it, `[σ, b·c]`: one state of a
/// diagonal section with its `b` folded into `c`; `σ = p − 1`
/// (dimensionless), `b·c` (N/N per state unit).
type RealCoeffs = [f32; 2];

/// Most real poles per axis (two per diagonal section).
pub const MAX_REAL_POLES: usize = 2 * MAX_SECTIONS;

/// The sections in the form the kernel computes them, packed into one
/// array (a section is a pair, 4 floats, or ≤ 2 real poles, 2 floats each,
/// so 4 · [`MAX_SECTIONS`] floats always suffice): the pairs' coefficients
/// first, then the live real poles', each in section order. Half the RAM of
/// separate arrays sized for the worst case of each (the firmware holds 15
/// filters).
#[derive(Clone, Copy, Debug, PartialEq)]
struct KernelForm {
    coeffs: [f32; 4 * MAX_SECTIONS],
    n_pairs: usize,
    n_reals: usize,
}

impl KernelForm {
    const EMPTY: Self = KernelForm { coeffs: [0.0; 4 * MAX_SECTIONS], n_pairs: 0, n_reals: 0 };

    /// Append section `s`: a normal-form pair, or the states of a diagonal
    /// section with `b·c ≠ 0`. `Err` for any other shape (or, unreachable
    /// with ≤ [`MAX_SECTIONS`] sections, no room left).
    fn push(&mut self, s: &Section) -> Result<(), ()> {
        let [d11, d12, d21, d22] = s.delta;
        let (pairs_end, used) = (4 * self.n_pairs, 4 * self.n_pairs + 2 * self.n_reals);
        if d12 == 0.0 && d21 == 0.0 {
            for (sigma, (b, c)) in [d11, d22].into_iter().zip(s.b.into_iter().zip(s.c)) {
                let c = b * c;
                if c != 0.0 {
                    let at = 4 * self.n_pairs + 2 * self.n_reals;
                    self.coeffs.get_mut(at..at + 2).ok_or(())?.copy_from_slice(&[sigma, c]);
                    self.n_reals += 1;
                }
            }
            Ok(())
        } else if d11 == d22 && d21 == -d12 && s.b[1] == 0.0 {
            let beta = s.b[0];
            // The real poles move up by one pair to make room.
            if used + 4 > self.coeffs.len() {
                return Err(());
            }
            self.coeffs.copy_within(pairs_end..used, pairs_end + 4);
            self.coeffs[pairs_end..pairs_end + 4].copy_from_slice(&[d11, d12, beta * s.c[0], beta * s.c[1]]);
            self.n_pairs += 1;
            Ok(())
        } else {
            Err(())
        }
    }

    /// The pairs, in section order.
    fn pairs(&self) -> &[PairCoeffs] {
        let end = 4 * self.n_pairs;
        self.coeffs.get(..end).unwrap_or(&[]).as_chunks::<4>().0
    }

    /// The live real poles, in section order.
    fn reals(&self) -> &[RealCoeffs] {
        let start = 4 * self.n_pairs;
        self.coeffs.get(start..start + 2 * self.n_reals).unwrap_or(&[]).as_chunks::<2>().0
    }
}

/// Coefficients of one axis's compensator (configuration, no state).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AxisFilter {
    /// The sections as given (the image's records).
    sections: [Section; MAX_SECTIONS],
    len: usize,
    /// What the kernel computes from `sections`.
    form: KernelForm,
    d: f32,
    fir: [f32; MAX_FIR],
    fir_len: usize,
}

impl AxisFilter {
    /// Build a filter from its sections and direct term `d`, rejecting
    /// non-finite coefficients and unstable sections.
    pub fn new(sections: &[Section], d: f32) -> Result<Self, FilterError> {
        Self::with_fir(sections, d, &[])
    }

    /// Build a filter from sections, direct term `d` and FIR taps
    /// `fir[j−1] = h_j` (delay j samples). Each section must be a normal-form
    /// pair or diagonal (module documentation).
    pub fn with_fir(sections: &[Section], d: f32, fir: &[f32]) -> Result<Self, FilterError> {
        if fir.len() > MAX_FIR {
            return Err(FilterError::TooManyTaps);
        }
        let mut taps = [0.0; MAX_FIR];
        for (j, (dst, h)) in taps.iter_mut().zip(fir).enumerate() {
            if !h.is_finite() {
                return Err(FilterError::NonFiniteTap(j));
            }
            *dst = *h;
        }
        if sections.len() > MAX_SECTIONS {
            return Err(FilterError::TooManySections);
        }
        if !d.is_finite() {
            return Err(FilterError::NonFinite(MAX_SECTIONS));
        }
        let mut all = [Section::default(); MAX_SECTIONS];
        let mut form = KernelForm::EMPTY;
        for (i, (dst, s)) in all.iter_mut().zip(sections).enumerate() {
            if !s.is_finite() {
                return Err(FilterError::NonFinite(i));
            }
            if !s.is_stable() {
                return Err(FilterError::Unstable(i));
            }
            form.push(s).map_err(|()| FilterError::NotModal(i))?;
            *dst = *s;
        }
        Ok(AxisFilter { sections: all, len: sections.len(), form, d, fir: taps, fir_len: fir.len() })
    }

    /// Bound on the ℓ1 norm of the filter's impulse response (N/N):
    /// `|d| + Σ|h_j| + Σ_sections` [`Section::gain_bound`]. For any input
    /// with |u| ≤ U the exact output stays within this bound times U.
    pub fn gain_bound(&self) -> f64 {
        let taps: f64 = self.fir().iter().map(|h| f64::from(*h).abs()).sum();
        let secs: f64 = self.sections().iter().map(Section::gain_bound).sum();
        f64::from(self.d).abs() + taps + secs
    }

    /// Steady-state (DC) gain of the filter, its transfer function at z = 1
    /// (N/N): `d + Σ h_j + Σ_sections` [`Section::dc_gain`].
    pub fn dc_gain(&self) -> f64 {
        let taps: f64 = self.fir().iter().map(|h| f64::from(*h)).sum();
        let secs: f64 = self.sections().iter().map(Section::dc_gain).sum();
        f64::from(self.d) + taps + secs
    }

    /// A pure gain `y = d·u` (no sections).
    pub fn gain(d: f32) -> Result<Self, FilterError> {
        Self::new(&[], d)
    }

    /// The active sections.
    pub fn sections(&self) -> &[Section] {
        // `len ≤ MAX_SECTIONS` is established by `new`, the only constructor.
        self.sections.get(..self.len).unwrap_or(&[])
    }

    /// FIR taps `h_1..h_m` (delays 1..m samples).
    pub fn fir(&self) -> &[f32] {
        self.fir.get(..self.fir_len).unwrap_or(&[])
    }

    /// Direct feed-through term `d`.
    pub fn d(&self) -> f32 {
        self.d
    }

    /// How the kernel runs the sections: (pole pairs, live real poles).
    /// A diagonal section counts its poles with `b·c ≠ 0` only.
    pub fn kernel_counts(&self) -> (usize, usize) {
        (self.form.n_pairs, self.form.n_reals)
    }

    /// Filter order (number of states in use, counting padded first-order
    /// sections as two, plus the FIR delay line).
    pub fn order(&self) -> usize {
        2 * self.len + self.fir_len
    }

    /// One sample: returns `y[k]` and advances the state (the module equation).
    ///
    /// No allocation, no panics, O(sections) multiply-adds.
    #[inline]
    pub fn step(&self, state: &mut AxisState, u: f32) -> f32 {
        // Cortex-M4F: the whole step below in one block of hand-scheduled
        // assembly, bit-identical (kernel_m4.rs).
        #[cfg(all(target_arch = "arm", target_os = "none", target_abi = "eabihf"))]
        {
            m4::step(self, state, u)
        }
        #[cfg(not(all(target_arch = "arm", target_os = "none", target_abi = "eabihf")))]
        {
            let mut y = self.d * u;
            for (p, x) in self.form.pairs().iter().zip(state.x.iter_mut()) {
                *x = pair_update(p, *x, u, &mut y);
            }
            for (r, x) in self.form.reals().iter().zip(state.x_real.iter_mut()) {
                *x = real_update(r, *x, u, &mut y);
            }
            // hist[j] holds u[k−1−j]. One pass accumulates h_{j+1}·u[k−1−j]
            // in ascending j and shifts u[k] in (each slot takes its
            // predecessor's old value): the same sums as a dot product
            // followed by `rotate_right(1)`.
            let m = self.fir_len.min(MAX_FIR);
            let mut carry = u;
            for (h, past) in self.fir[..m].iter().zip(state.fir_hist[..m].iter_mut()) {
                let old = *past;
                y += h * old;
                *past = carry;
                carry = old;
            }
            y
        }
    }

    /// [`step`](Self::step) with the runaway guard: if the output is non-finite
    /// or exceeds [`RUNAWAY_LIMIT_N`], the state is reset, the reset is counted
    /// in `state.nonfinite_resets`, and `None` is returned (the caller decides
    /// what to output for that sample, e.g. the raw force).
    #[inline]
    pub fn step_guarded(&self, state: &mut AxisState, u: f32) -> Option<f32> {
        let y = self.step(state, u);
        // `!(a <= b)` is also true for NaN.
        if !(y.abs() <= RUNAWAY_LIMIT_N) {
            state.reset();
            state.nonfinite_resets = state.nonfinite_resets.wrapping_add(1);
            None
        } else {
            Some(y)
        }
    }

    /// Filter a block: `output[k] = step(input[k])` for the common length of
    /// the two slices (by [`process_block`](Self::process_block)).
    pub fn process(&self, state: &mut AxisState, input: &[f32], output: &mut [f32]) {
        self.process_block(state, input, output);
    }

    /// Filter a block, bit-identical to calling [`step`](Self::step) on each
    /// sample in turn (`output[k] = step(input[k])` for the common length of
    /// the slices; the state is left as after the last of those steps).
    ///
    /// The loops are interchanged for throughput (the module equation, same
    /// arithmetic): every output starts as `d·u[k]`; then each section runs
    /// over the whole block with its coefficients and state in registers,
    /// adding `c_i·x_i[k]` to `output[k]`; then the FIR taps `h_j·u[k−j]`
    /// are added to [`FIR_LANES`] outputs at a time held in registers (the
    /// lanes are independent, so the compiler vectorizes them). Each `output[k]` so
    /// receives exactly the additions of `step`, in the same order
    /// (d·u, section 0, 1, …, tap 1, 2, …), and no product is fused, so the
    /// result is the same to the bit (`tests/kernel_block.rs`). Sections run
    /// four at a time (independent state recurrences in flight), the block in
    /// chunks of [`BLOCK_CHUNK`] samples (the chunk stays in L1 cache).
    ///
    /// No guard: a non-finite or runaway output is returned as computed (use
    /// [`process_block_guarded`](Self::process_block_guarded) for the
    /// runaway guard of [`step_guarded`](Self::step_guarded)). No allocation,
    /// no panics.
    pub fn process_block(&self, state: &mut AxisState, input: &[f32], output: &mut [f32]) {
        let n = input.len().min(output.len());
        for (u, y) in input[..n].chunks(BLOCK_CHUNK).zip(output[..n].chunks_mut(BLOCK_CHUNK)) {
            self.process_chunk(state, u, y);
        }
    }

    /// One chunk of [`process_block`](Self::process_block); `input` and
    /// `output` have the same length.
    fn process_chunk(&self, state: &mut AxisState, input: &[f32], output: &mut [f32]) {
        self.start_chunk(input, output);
        let (pairs, reals) = (self.form.pairs(), self.form.reals());
        over_chunks(pairs, &mut state.x, input, output, pair_update);
        over_chunks(reals, &mut state.x_real, input, output, real_update);
        self.fir_chunk(state, input, output);
    }

    /// First term of every output of a chunk: `output[k] = d·u[k]`.
    fn start_chunk(&self, input: &[f32], output: &mut [f32]) {
        for (y, u) in output.iter_mut().zip(input) {
            *y = self.d * u;
        }
    }

    /// Last terms of every output of a chunk: the FIR taps `h_j·u[k−j]`
    /// (in tap order for each sample), and the FIR history moved on by the
    /// chunk; `input` and `output` have the same length.
    fn fir_chunk(&self, state: &mut AxisState, input: &[f32], output: &mut [f32]) {
        // FIR: tap h_{j+1} multiplies u[k−1−j]: for k ≤ j that is
        // fir_hist[j−k] (the previous chunk), otherwise input[k−1−j].
        let m = self.fir_len.min(MAX_FIR);
        let n = input.len();
        let taps = &self.fir[..m];
        // Samples k < m reach back into the history: tap by tap.
        let head = m.min(n);
        for (j, h) in taps.iter().enumerate() {
            let from_hist = (j + 1).min(head);
            for (y, past) in output[..from_hist].iter_mut().zip(state.fir_hist[..=j].iter().rev()) {
                *y += h * past;
            }
            for (y, past) in output[from_hist..head].iter_mut().zip(input) {
                *y += h * past;
            }
        }
        // Samples k ≥ m: FIR_LANES outputs at a time stay in registers while
        // every tap is added to them (in tap order for each sample).
        let mut lanes = output[head..].chunks_exact_mut(FIR_LANES);
        for (i, y) in (&mut lanes).enumerate() {
            let k0 = head + i * FIR_LANES;
            let mut acc = [0.0f32; FIR_LANES];
            acc.copy_from_slice(y);
            for (j, h) in taps.iter().enumerate() {
                let past = &input[k0 - 1 - j..k0 - 1 - j + FIR_LANES];
                for (a, u) in acc.iter_mut().zip(past) {
                    *a += h * u;
                }
            }
            y.copy_from_slice(&acc);
        }
        let rest = lanes.into_remainder();
        let k0 = n - rest.len();
        for (i, y) in rest.iter_mut().enumerate() {
            for (j, h) in taps.iter().enumerate() {
                *y += h * input[k0 + i - 1 - j];
            }
        }
        // fir_hist[j] ← u[n−1−j]: the newest inputs, then the older history.
        if n >= m {
            for (dst, u) in state.fir_hist[..m].iter_mut().zip(input.iter().rev()) {
                *dst = *u;
            }
        } else {
            state.fir_hist.copy_within(..m - n, n);
            for (dst, u) in state.fir_hist[..n].iter_mut().zip(input.iter().rev()) {
                *dst = *u;
            }
        }
    }

    /// [`process_block`](Self::process_block) with the runaway guard of
    /// [`step_guarded`](Self::step_guarded), with the sample path's
    /// fallback: `output[k] = step_guarded(input[k]).unwrap_or(input[k])`
    /// (the raw force where the guard reset the state). Returns the number of
    /// resets in this block (also counted in `state.nonfinite_resets`).
    ///
    /// The guard cannot act inside the interchanged loops (a reset at sample
    /// k changes every later sample of every section), so the block is run
    /// from a copy of the state and checked afterwards; if any output is
    /// non-finite or beyond [`RUNAWAY_LIMIT_N`], the copy is discarded and
    /// the block is re-run sample by sample with `step_guarded`. Either way
    /// the outputs and the final state are those of the per-sample path.
    pub fn process_block_guarded(&self, state: &mut AxisState, input: &[f32], output: &mut [f32]) -> u32 {
        let n = input.len().min(output.len());
        let mut trial = *state;
        self.process_block(&mut trial, &input[..n], &mut output[..n]);
        // `!(a <= b)` is also true for NaN.
        if output[..n].iter().all(|y| y.abs() <= RUNAWAY_LIMIT_N) {
            *state = trial;
            return 0;
        }
        let before = state.nonfinite_resets;
        for (u, y) in input[..n].iter().zip(output[..n].iter_mut()) {
            *y = self.step_guarded(state, *u).unwrap_or(*u);
        }
        state.nonfinite_resets.wrapping_sub(before)
    }

    /// Filter a block in place.
    pub fn process_in_place(&self, state: &mut AxisState, signal: &mut [f32]) {
        for v in signal.iter_mut() {
            *v = self.step(state, *v);
        }
    }
}

/// One axis's filter, state and block for [`process_blocks`].
pub struct BlockJob<'a> {
    /// The axis's compensator.
    pub filter: &'a AxisFilter,
    /// Its state, carried on from the previous block.
    pub state: &'a mut AxisState,
    /// Input forces (N).
    pub input: &'a [f32],
    /// Compensated forces (N), as many as the shorter of the two slices.
    pub output: &'a mut [f32],
}

/// Axes per lockstep pass of [`process_blocks`]: one per f32 lane of a
/// 128-bit vector.
pub const LOCKSTEP_AXES: usize = 4;

/// One sample of every axis of a lockstep pass (lane a = axis a).
type Lane = [f32; LOCKSTEP_AXES];

/// Pair i of every axis of a lockstep pass, lane a holding axis a's pair i
/// (struct of arrays, so that one vector operation serves all lanes).
///
/// A lane whose axis has fewer pairs is idle: σ = ω = 0, c₁ = c₂ = −0.0,
/// and its input is masked to +0.0 (`live` = 0), so its state stays +0.0
/// and it adds (−0.0)·(+0.0) = −0.0 to its `y`, which leaves every `y`
/// unchanged (IEEE 754: y + (−0.0) = y, also for y = −0.0). An added +0.0
/// would not: −0.0 + (+0.0) = +0.0.
#[derive(Clone, Copy)]
struct PairLanes {
    sigma: Lane,
    omega: Lane,
    c1: Lane,
    c2: Lane,
    /// Input mask: all ones for a live lane, 0 for an idle one.
    live: [u32; LOCKSTEP_AXES],
}

impl Default for PairLanes {
    fn default() -> Self {
        PairLanes { sigma: [0.0; 4], omega: [0.0; 4], c1: [-0.0; 4], c2: [-0.0; 4], live: [0; 4] }
    }
}

/// Real pole j of every axis of a lockstep pass; idle lanes as in
/// [`PairLanes`].
#[derive(Clone, Copy)]
struct RealLanes {
    sigma: Lane,
    c: Lane,
    live: [u32; LOCKSTEP_AXES],
}

impl Default for RealLanes {
    fn default() -> Self {
        RealLanes { sigma: [0.0; 4], c: [-0.0; 4], live: [0; 4] }
    }
}

/// `u` of a live lane, +0.0 in an idle one.
#[inline(always)]
fn masked(u: f32, live: u32) -> f32 {
    f32::from_bits(u.to_bits() & live)
}

/// [`pair_update`] in every lane (the same function per lane, so the same
/// roundings; the lanes are independent, so the compiler vectorizes them).
#[inline(always)]
fn pair_update_lanes(p: &PairLanes, [x1, x2]: [Lane; 2], u: Lane, y: &mut Lane) -> [Lane; 2] {
    let mut next = [[0.0; LOCKSTEP_AXES]; 2];
    for l in 0..LOCKSTEP_AXES {
        let c = [p.sigma[l], p.omega[l], p.c1[l], p.c2[l]];
        [next[0][l], next[1][l]] = pair_update(&c, [x1[l], x2[l]], masked(u[l], p.live[l]), &mut y[l]);
    }
    next
}

/// [`real_update`] in every lane.
#[inline(always)]
fn real_update_lanes(r: &RealLanes, x: Lane, u: Lane, y: &mut Lane) -> Lane {
    core::array::from_fn(|l| {
        let c = [r.sigma[l], r.c[l]];
        real_update(&c, x[l], masked(u[l], r.live[l]), &mut y[l])
    })
}

/// Several axes' blocks: each job's outputs and final state are those of
/// its own [`AxisFilter::process_block`], bit for bit (so those of stepping
/// it sample by sample), for any filters and block lengths. No allocation,
/// no panics.
///
/// Why: a pair's state recurrence is serial in time (a multiply and three
/// dependent additions per sample), and a typical design has only a few
/// pairs per axis, so one axis alone leaves most of a core idle waiting on
/// that latency. Here up to [`LOCKSTEP_AXES`] axes run in lockstep, one per
/// vector lane: lane a computes axis a's pair i exactly as
/// [`AxisFilter::step`] does (its `d·u`, then its pairs, then its real
/// poles, in order; lanes of an axis with fewer pairs are idle and add
/// exactly nothing, see [`PairLanes`]), so one vector operation advances
/// the same recurrence of every axis. The FIR taps then run per axis as in
/// `process_block`. Over the group's common length the axes run in
/// lockstep; each longer block's rest runs alone.
pub fn process_blocks(jobs: &mut [BlockJob<'_>]) {
    for group in jobs.chunks_mut(LOCKSTEP_AXES) {
        match group {
            [one] => one.filter.process_block(one.state, one.input, one.output),
            _ => lockstep(group),
        }
    }
}

/// [`process_blocks`] for ≤ [`LOCKSTEP_AXES`] jobs in lockstep.
fn lockstep(jobs: &mut [BlockJob<'_>]) {
    let k = jobs.len().min(LOCKSTEP_AXES);
    let jobs = &mut jobs[..k];
    let n = jobs.iter().map(|j| j.input.len().min(j.output.len())).min().unwrap_or(0);
    let mut pairs = [PairLanes::default(); MAX_SECTIONS];
    let mut reals = [RealLanes::default(); MAX_REAL_POLES];
    let mut x = [[[0.0; LOCKSTEP_AXES]; 2]; MAX_SECTIONS];
    let mut x_real = [[0.0; LOCKSTEP_AXES]; MAX_REAL_POLES];
    let mut d = [0.0; LOCKSTEP_AXES];
    let (mut n_pairs, mut n_reals) = (0, 0);
    for (l, job) in jobs.iter().enumerate() {
        d[l] = job.filter.d;
        let (jp, jr) = (job.filter.form.pairs(), job.filter.form.reals());
        n_pairs = n_pairs.max(jp.len());
        n_reals = n_reals.max(jr.len());
        for ((lanes, xi), (p, [x1, x2])) in pairs.iter_mut().zip(x.iter_mut()).zip(jp.iter().zip(job.state.x)) {
            [lanes.sigma[l], lanes.omega[l], lanes.c1[l], lanes.c2[l]] = *p;
            lanes.live[l] = u32::MAX;
            (xi[0][l], xi[1][l]) = (x1, x2);
        }
        for ((lanes, xj), (r, xr)) in reals.iter_mut().zip(x_real.iter_mut()).zip(jr.iter().zip(job.state.x_real)) {
            [lanes.sigma[l], lanes.c[l]] = *r;
            lanes.live[l] = u32::MAX;
            xj[l] = xr;
        }
    }
    let mut u = [[0.0; LOCKSTEP_AXES]; BLOCK_CHUNK];
    let mut y = [[0.0; LOCKSTEP_AXES]; BLOCK_CHUNK];
    let mut start = 0;
    while start < n {
        let len = (n - start).min(BLOCK_CHUNK);
        let (u, y) = (&mut u[..len], &mut y[..len]);
        for (l, job) in jobs.iter().enumerate() {
            for (lane, v) in u.iter_mut().zip(&job.input[start..start + len]) {
                lane[l] = *v;
            }
        }
        for (y, u) in y.iter_mut().zip(u.iter()) {
            *y = core::array::from_fn(|l| d[l] * u[l]);
        }
        over_chunks(&pairs[..n_pairs], &mut x, u, y, pair_update_lanes);
        over_chunks(&reals[..n_reals], &mut x_real, u, y, real_update_lanes);
        for (l, job) in jobs.iter_mut().enumerate() {
            let out = &mut job.output[start..start + len];
            for (dst, lane) in out.iter_mut().zip(y.iter()) {
                *dst = lane[l];
            }
            job.filter.fir_chunk(job.state, &job.input[start..start + len], out);
        }
        start += len;
    }
    for (l, job) in jobs.iter_mut().enumerate() {
        let (np, nr) = (job.filter.form.pairs().len(), job.filter.form.reals().len());
        for (dst, xi) in job.state.x[..np].iter_mut().zip(&x) {
            *dst = [xi[0][l], xi[1][l]];
        }
        for (dst, xj) in job.state.x_real[..nr].iter_mut().zip(&x_real) {
            *dst = xj[l];
        }
        job.filter.process_block(job.state, &job.input[n..], &mut job.output[n..]);
    }
}

/// Samples per chunk of [`AxisFilter::process_block`]: input and output of a
/// chunk (2 × 2 KiB) stay in L1 cache while every section and tap passes
/// over them.
pub const BLOCK_CHUNK: usize = 512;

/// One sample of a conjugate pair (module equation): adds `c₁·x₁`, then
/// `c₂·x₂` to `y` and returns the next state. The grouping is the kernel's
/// definition at the bit level; `+` and `*` are never fused by rustc.
#[inline(always)]
fn pair_update(&[sigma, omega, c1, c2]: &PairCoeffs, [x1, x2]: [f32; 2], u: f32, y: &mut f32) -> [f32; 2] {
    *y += c1 * x1;
    *y += c2 * x2;
    let d1 = (sigma * x1 + omega * x2) + u;
    let d2 = sigma * x2 - omega * x1;
    [x1 + d1, x2 + d2]
}

/// One sample of a real pole (module equation): adds `c·x` to `y` and
/// returns the next state.
#[inline(always)]
fn real_update(&[sigma, c]: &RealCoeffs, x: f32, u: f32, y: &mut f32) -> f32 {
    *y += c * x;
    x + (sigma * x + u)
}

/// [`over_block`] four at a time, then the remaining 1-3 together (never
/// padded: an added zero term would turn a −0.0 output into +0.0). A sample
/// `S` is one axis's f32, or a [`Lane`] of the lockstep path.
#[inline(always)]
fn over_chunks<C: Copy + Default, X: Copy + Default, S: Copy>(
    coeffs: &[C],
    states: &mut [X],
    input: &[S],
    output: &mut [S],
    update: impl Fn(&C, X, S, &mut S) -> X + Copy,
) {
    for (c, x) in coeffs.chunks(4).zip(states.chunks_mut(4)) {
        match c.len() {
            4 => over_block::<4, _, _, _>(c, x, input, output, update),
            3 => over_block::<3, _, _, _>(c, x, input, output, update),
            2 => over_block::<2, _, _, _>(c, x, input, output, update),
            _ => over_block::<1, _, _, _>(c, x, input, output, update),
        }
    }
}

/// `N` pairs or real poles (`coeffs.len() == N`) over a whole chunk:
/// `output[k]` receives each one's `update` in order, exactly as in
/// [`AxisFilter::step`] (same function, so the same roundings). Running N
/// independent recurrences per sample keeps N of them in flight.
#[inline(always)]
fn over_block<const N: usize, C: Copy + Default, X: Copy + Default, S: Copy>(
    coeffs: &[C],
    states: &mut [X],
    input: &[S],
    output: &mut [S],
    update: impl Fn(&C, X, S, &mut S) -> X,
) {
    let c: [C; N] = core::array::from_fn(|i| coeffs.get(i).copied().unwrap_or_default());
    let mut x: [X; N] = core::array::from_fn(|i| states.get(i).copied().unwrap_or_default());
    for (y, &u) in output.iter_mut().zip(input) {
        let mut acc = *y;
        for (c, x) in c.iter().zip(x.iter_mut()) {
            *x = update(c, *x, u, &mut acc);
        }
        *y = acc;
    }
    for (dst, x) in states.iter_mut().zip(x) {
        *dst = x;
    }
}

/// Outputs per register block of the FIR part in
/// [`AxisFilter::process_block`].
const FIR_LANES: usize = 8;

/// Filter memory of one axis (state, no configuration).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AxisState {
    /// States `[x₁, x₂]` of the conjugate pairs, in section order (the
    /// `i`-th pair section, counting pairs only).
    pub x: [[f32; 2]; MAX_SECTIONS],
    /// States of the live real poles, in section order.
    pub x_real: [f32; MAX_REAL_POLES],
    /// Past inputs of the FIR part: `fir_hist[j] = u[k−1−j]`.
    pub fir_hist: [f32; MAX_FIR],
    /// How many times the runaway guard has reset this state.
    pub nonfinite_resets: u32,
}

impl Default for AxisState {
    fn default() -> Self {
        AxisState {
            x: [[0.0; 2]; MAX_SECTIONS],
            x_real: [0.0; MAX_REAL_POLES],
            fir_hist: [0.0; MAX_FIR],
            nonfinite_resets: 0,
        }
    }
}

impl AxisState {
    /// Zero the filter memory (the reset counter is kept).
    pub fn reset(&mut self) {
        self.x = [[0.0; 2]; MAX_SECTIONS];
        self.x_real = [0.0; MAX_REAL_POLES];
        self.fir_hist = [0.0; MAX_FIR];
    }
}
