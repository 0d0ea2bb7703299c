//! Rounding a realization to the kernel's f32 coefficients and verifying the
//! result before it may be written (DESIGN.md step 7, [`quantize`]).

use anyhow::{bail, Result};
use dynocomp_core::kernel::{AxisFilter, AxisState, Section};
use num_complex::Complex64;

use crate::numeric::lti::StateSpace;
use crate::realize::modal::{section_poles, section_response, ModalRealization};

/// Required distance of every f32 pole from the unit circle.
pub const POLE_MARGIN: f64 = 1e-7;
/// Largest accepted relative frequency-response error of the f32 filter.
pub const MAX_FREQ_ERROR: f64 = 1e-4;
/// Largest accepted relative time-domain error of the f32 kernel.
pub const MAX_TIME_ERROR: f64 = 1e-4;
/// Largest accepted pole displacement relative to |1 − λ|.
pub const MAX_POLE_SHIFT: f64 = 1e-4;

/// Verification figures of a quantized filter.
#[derive(Clone, Debug)]
pub struct Verification {
    /// Largest pole radius of the f32 sections.
    pub max_pole_radius: f64,
    /// Largest relative pole displacement by rounding.
    pub max_pole_shift: f64,
    /// Largest |H32 − H64| / max|H64| over the checked band.
    pub freq_error: f64,
    /// Largest |y32 − y64| / rms(y64) of the time-domain run.
    pub time_error: f64,
    /// Scaling of the realization: the largest ℓ1 norm of the impulse
    /// response of one part (a section's c_i·x_i, the FIR sum, or d) over
    /// the ℓ1 norm of the whole filter's impulse response (see
    /// [`term_growth`]).
    pub term_growth: f64,
}

impl Verification {
    /// The figure candidates are ranked by: the larger of the frequency
    /// error (coefficient rounding) and the time error (coefficient and
    /// arithmetic rounding through the real kernel).
    pub fn score(&self) -> f64 {
        self.freq_error.max(self.time_error)
    }
}

/// How much larger than the output a part of the kernel's sum can get:
/// max_part ‖g_part‖₁ / ‖h‖₁, with g_part the impulse response of one part
/// of the module equation of `dynocomp_core::kernel` (a section's c_i·x_i,
/// the FIR taps, or d) and h = d + Σ parts that of the filter (each
/// ‖·‖₁ is the largest output of that part for |u| ≤ 1). The kernel's f32
/// rounding error is ≈ ε_f32 times the sum of the parts' magnitudes, so
/// this factor multiplies it; 1 means no part exceeds the output.
/// Evaluated in f64 from the f32 coefficients, until every section's state
/// has decayed by 10⁻¹⁴ (at most [`TERM_GROWTH_MAX_LEN`] samples).
pub fn term_growth(f: &AxisFilter) -> f64 {
    let secs = f.sections();
    let mut x: Vec<[f64; 2]> = secs.iter().map(|s| s.b.map(f64::from)).collect();
    let x0: f64 = x.iter().map(|v| v[0].abs() + v[1].abs()).fold(0.0, f64::max);
    let mut l1_parts: Vec<f64> = vec![0.0; secs.len()];
    let fir = f.fir();
    let mut l1_total = f64::from(f.d()).abs();
    for j in 1..=TERM_GROWTH_MAX_LEN {
        // h_j = Σ_i c_i A_i^{j−1} b_i + h_fir_j
        let mut h = fir.get(j - 1).map_or(0.0, |v| f64::from(*v));
        let mut alive = 0.0f64;
        for ((s, xi), l1) in secs.iter().zip(x.iter_mut()).zip(l1_parts.iter_mut()) {
            let [c1, c2] = s.c.map(f64::from);
            let g = c1 * xi[0] + c2 * xi[1];
            *l1 += g.abs();
            h += g;
            let [d11, d12, d21, d22] = s.delta.map(f64::from);
            *xi = [xi[0] + d11 * xi[0] + d12 * xi[1], xi[1] + d21 * xi[0] + d22 * xi[1]];
            alive = alive.max(xi[0].abs() + xi[1].abs());
        }
        l1_total += h.abs();
        if j > fir.len() && alive <= 1e-14 * x0 {
            break;
        }
    }
    let l1_fir: f64 = fir.iter().map(|v| f64::from(*v).abs()).sum();
    let worst = l1_parts.iter().copied().fold(l1_fir.max(f64::from(f.d()).abs()), f64::max);
    worst / l1_total.max(f64::MIN_POSITIVE)
}

/// Longest impulse response evaluated by [`term_growth`] (samples).
pub const TERM_GROWTH_MAX_LEN: usize = 1 << 20;

fn round_section(s: &crate::realize::modal::Section64) -> Section {
    Section { delta: s.delta.map(|v| v as f32), b: s.b.map(|v| v as f32), c: s.c.map(|v| v as f32) }
}

/// Frequency response of the f32 filter, evaluated in f64 from its
/// coefficients.
pub fn filter_response(f: &AxisFilter, f_hz: f64, fs_hz: f64) -> Complex64 {
    let z = Complex64::from_polar(1.0, 2.0 * std::f64::consts::PI * f_hz / fs_hz);
    let mut h = Complex64::new(f64::from(f.d()), 0.0);
    for s in f.sections() {
        h += section_response(s.delta.map(f64::from), s.b.map(f64::from), s.c.map(f64::from), z);
    }
    let mut zp = 1.0 / z;
    for tap in f.fir() {
        h += zp * f64::from(*tap);
        zp /= z;
    }
    h
}

/// A deterministic broadband test signal: a log chirp over the band plus a
/// pseudo-random sequence, unit RMS scale (N).
pub fn test_signal(n: usize, fs_hz: f64, f_hi: f64) -> Vec<f64> {
    let mut state: u64 = 0x2545_F491_4F6C_DD1D;
    let f_lo = 10.0f64;
    let dur = n as f64 / fs_hz;
    (0..n)
        .map(|k| {
            let t = k as f64 / fs_hz;
            let ratio = (f_hi / f_lo).max(1.0001);
            let phase = 2.0 * std::f64::consts::PI * f_lo * dur / ratio.ln() * (ratio.powf(t / dur) - 1.0);
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            let noise = (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5;
            phase.sin() + noise
        })
        .collect()
}

/// What a quantized filter is checked against: the f64 design's frequency
/// response on the check grid and its output for the time-domain test
/// signal. It depends on the design `ss` only, so [`quantize`]
/// shares it between every realization and FIR length of one compensator
/// (the f64 simulation was most of a check's cost).
pub struct Reference {
    fs_hz: f64,
    /// (f (Hz), H64(f)) on `VERIFY_GRID` + 1 points over 0..f_band.
    grid: Vec<(f64, Complex64)>,
    /// max |H64| on the grid.
    peak: f64,
    /// The test signal ([`test_signal`]) and the design's output for it.
    u: Vec<f64>,
    y64: Vec<f64>,
    /// RMS of `y64`.
    rms: f64,
}

/// Points of the frequency check over the band (plus one).
pub(crate) const VERIFY_GRID: usize = 400;
/// Samples of the time-domain check.
pub(crate) const VERIFY_SAMPLES: usize = 20_000;

impl Reference {
    /// The f64 design `ss`'s responses over 0..`f_band_hz` at `fs_hz`.
    pub fn of(ss: &StateSpace, fs_hz: f64, f_band_hz: f64) -> Self {
        let freqs: Vec<f64> = (0..=VERIFY_GRID).map(|i| f_band_hz * i as f64 / VERIFY_GRID as f64).collect();
        let grid: Vec<(f64, Complex64)> = freqs.iter().copied().zip(ss.freq_responses(&freqs, fs_hz)).collect();
        let peak = grid.iter().map(|g| g.1.norm()).fold(0.0, f64::max);
        let u = test_signal(VERIFY_SAMPLES, fs_hz, f_band_hz);
        let y64 = ss.simulate(&u);
        let rms = (y64.iter().map(|v| v * v).sum::<f64>() / y64.len() as f64).sqrt();
        Reference { fs_hz, grid, peak, u, y64, rms }
    }
}

/// Round to f32 and verify against the f64 design, whose responses
/// `reference` holds ([`Reference::of`] the design `ss` over 0..`f_band_hz`).
///
/// Checks, each with a reason on failure:
/// * every f32 section stable with margin (pole radius ≤ 1 − [`POLE_MARGIN`]);
/// * pole displacement by rounding, relative to the pole's distance from
///   z = 1 (what sets a mode's frequency and damping);
/// * frequency response of the f32 filter against the f64 design over the
///   band (relative to the design's peak response);
/// * a time-domain run of the real f32 core kernel against an f64 simulation
///   of the design (relative to the design's output RMS).
pub fn quantize(real: &ModalRealization, reference: &Reference) -> Result<(AxisFilter, Verification)> {
    let Reference { fs_hz, grid, peak, u, y64, rms } = reference;
    let (fs_hz, peak, rms) = (*fs_hz, *peak, *rms);
    let sections: Vec<Section> = real.sections.iter().map(round_section).collect();
    let fir: Vec<f32> = real.fir.iter().map(|v| *v as f32).collect();
    let filter = AxisFilter::with_fir(&sections, real.d as f32, &fir)
        .map_err(|e| anyhow::anyhow!("the f32 compensator is invalid ({e}); its poles do not survive rounding"))?;
    // stability margin and pole displacement
    let mut max_radius = 0.0f64;
    let mut max_shift = 0.0f64;
    for (s64, s32) in real.sections.iter().zip(filter.sections()) {
        let e64 = section_poles(s64.delta);
        let e32 = section_poles(s32.delta.map(f64::from));
        for p32 in &e32 {
            max_radius = max_radius.max(p32.norm());
        }
        for p64 in &e64 {
            let shift =
                e32.iter().map(|q| (q - p64).norm()).fold(f64::INFINITY, f64::min) / (1.0 - p64).norm().max(1e-300);
            max_shift = max_shift.max(shift);
        }
        if !s32.poles_within(1.0 - POLE_MARGIN) {
            bail!("quantized compensator has a pole within {POLE_MARGIN:e} of the unit circle; refusing to write it");
        }
    }
    if !(max_shift <= MAX_POLE_SHIFT) {
        bail!("rounding to f32 moves a compensator pole by {max_shift:.1e} of its distance from z = 1 (limit {MAX_POLE_SHIFT:e})");
    }
    // frequency response over the band (and a little beyond)
    let worst = grid.iter().map(|(f, h64)| (filter_response(&filter, *f, fs_hz) - h64).norm()).fold(0.0, f64::max);
    let freq_error = worst / peak;
    if !(freq_error <= MAX_FREQ_ERROR) {
        bail!("f32 compensator deviates from the f64 design by {freq_error:.1e} of its peak response (limit {MAX_FREQ_ERROR:e})");
    }
    // time domain through the real kernel
    let mut st = AxisState::default();
    let time_error =
        u.iter().zip(y64).map(|(u, y)| (f64::from(filter.step(&mut st, *u as f32)) - y).abs()).fold(0.0, f64::max)
            / rms;
    if !(time_error <= MAX_TIME_ERROR) {
        bail!(
            "f32 kernel output deviates from the f64 design by {time_error:.1e} of its RMS (limit {MAX_TIME_ERROR:e})"
        );
    }
    // The checks the box repeats on the image it runs (coefficients bounded,
    // the gain bound, the DC gain): a realization that matches its design
    // but fails them is never chosen, rather than refused when the image is
    // written. The axis is not known here; the caller's context names it.
    if let Err(e) = dynocomp_core::image::validate_filter(0, &filter) {
        let e = super::image_check_refusal(&e);
        bail!("the f32 compensator fails the box's image check: {}", e.strip_prefix("axis 0: ").unwrap_or(&e));
    }
    Ok((
        filter,
        Verification {
            max_pole_radius: max_radius,
            max_pole_shift: max_shift,
            freq_error,
            time_error,
            term_growth: term_growth(&filter),
        },
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::realize::modal::Section64;
    use nalgebra::{DMatrix, DVector};

    /// One real pole at 0.5, output gain 0.25, direct term `d`: DC gain
    /// `d + 0.5`. Its realization and the f64 compensator it realizes.
    fn first_order(d: f64) -> (ModalRealization, StateSpace) {
        let real = ModalRealization {
            sections: vec![Section64 { delta: [-0.5, 0.0, 0.0, -1.0], b: [1.0, 0.0], c: [0.25, 0.0] }],
            d,
            fir: Vec::new(),
            poles: vec![Complex64::new(0.5, 0.0)],
            modal_condition: 1.0,
            decoupling_norm: 1.0,
            fir_truncation: 0.0,
        };
        let ss = StateSpace {
            a: DMatrix::from_element(1, 1, 0.5),
            b: DVector::from_element(1, 1.0),
            c: DVector::from_element(1, 0.25),
            d,
        };
        (real, ss)
    }

    /// A realization that matches its design in f32 but whose DC gain the
    /// box's image check refuses (200.5, limit ±100) is refused at
    /// verification; the calibrated one (DC gain 1, the control) verifies.
    #[test]
    fn a_filter_the_image_check_refuses_does_not_verify() {
        let (real, ss) = first_order(0.5);
        let (filter, v) = quantize(&real, &Reference::of(&ss, 51_200.0, 4000.0)).unwrap();
        assert!(v.freq_error < 1e-6 && (filter.dc_gain() - 1.0).abs() < 1e-6, "{v:?}");

        let (real, ss) = first_order(200.0);
        let e = format!("{:#}", quantize(&real, &Reference::of(&ss, 51_200.0, 4000.0)).unwrap_err());
        assert!(e.starts_with("the f32 compensator fails the box's image check: DC gain"), "{e}");
    }
}
