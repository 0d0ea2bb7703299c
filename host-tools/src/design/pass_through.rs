//! An axis the design cannot compensate, passed through raw (#34): the image
//! still carries the axes that can be compensated, and this one outputs its
//! measured force delayed by the image's declared latency L, so that the
//! three outputs stay aligned in time. The design says so loudly and gives
//! the reason; `design --strict` refuses the image instead.

use anyhow::{Context, Result};
use nalgebra::{DMatrix, DVector};

use crate::design::axis::{AxisDesign, DesignOptions};
use crate::design::kalman::KalmanDesign;
use crate::fit::PoleResidueModel;
use crate::frf::AxisFrf;
use crate::numeric::lti::StateSpace;
use crate::realize::modal::ModalRealization;
use crate::realize::quantize::{quantize, Reference};

/// The pure delay z^−L (L = `lag` samples) as a state space: a shift
/// register, or the identity for L = 0.
pub fn delay(lag: usize) -> StateSpace {
    if lag == 0 {
        return StateSpace { a: DMatrix::zeros(1, 1), b: DVector::zeros(1), c: DVector::zeros(1), d: 1.0 };
    }
    let mut a = DMatrix::zeros(lag, lag);
    for i in 1..lag {
        a[(i, i - 1)] = 1.0;
    }
    let mut b = DVector::zeros(lag);
    b[0] = 1.0;
    let mut c = DVector::zeros(lag);
    c[lag - 1] = 1.0;
    StateSpace { a, b, c, d: 0.0 }
}

/// The design of `frf`'s axis as a pass-through: the compensator is the
/// pure delay of `opts.lag` samples (realized and verified in f32 as any
/// other), the model Ĝ = 1, no q; `reason` (why the axis cannot be
/// compensated) is kept for the summary, `--json`, the report and the
/// sidecar. Measurement noise variance R (N²) as given.
pub fn pass_through(frf: &AxisFrf, r: f64, opts: &DesignOptions, reason: String) -> Result<AxisDesign> {
    let compensator = delay(opts.lag);
    // Realized as what it is, one FIR tap of 1 at h_L (or D = 1): exact in
    // f32, and verified against the delay as any other filter.
    let mut fir = vec![0.0; opts.lag];
    if let Some(last) = fir.last_mut() {
        *last = 1.0;
    }
    let realization = ModalRealization {
        sections: Vec::new(),
        d: if opts.lag == 0 { 1.0 } else { 0.0 },
        fir,
        poles: Vec::new(),
        modal_condition: 1.0,
        decoupling_norm: 1.0,
        fir_truncation: 0.0,
    };
    let reference = Reference::of(&compensator, opts.fs_hz, 0.45 * opts.fs_hz);
    let (filter, verification) =
        quantize(&realization, &reference).context("the pass-through of an axis that cannot be compensated")?;
    let kalman = KalmanDesign {
        compensator,
        kalman_gain: DVector::zeros(0),
        dare_residual: 0.0,
        closed_loop_radius: 0.0,
        lag: opts.lag,
        q: 0.0,
        r,
        force_shape: None,
    };
    Ok(AxisDesign {
        axis: frf.axis,
        model: PoleResidueModel { terms: Vec::new(), d: 1.0 },
        order_trace: Vec::new(),
        fit_nrmse: f64::NAN,
        coherent_band_hz: (0.0, 0.0),
        kalman,
        realization,
        filter,
        verification,
        flat_band_hz: (0.0, 0.0),
        noise_gain: 1.0,
        predicted_error: f64::NAN,
        fit_uncertainty: f64::NAN,
        predicted_distortion: f64::NAN,
        predicted_criterion: f64::NAN,
        q_trace: Vec::new(),
        bands: Vec::new(),
        fit_nrmse_out_of_band: f64::NAN,
        paper: None,
        discrete: None,
        model_match: f64::NAN,
        raw_predicted_error: f64::NAN,
        compensated_band_hz: (0.0, 0.0),
        notes: Vec::new(),
        seeded_hz: Vec::new(),
        force_spectrum: None,
        pass_through: Some(reason),
        phase_limits: Vec::new(),
        offline_predicted: (f64::NAN, f64::NAN),
    })
}

/// [`pass_through`], saying so loudly on stderr first: the axis, the
/// latency its measured force is delayed by, the reason, and that
/// `--strict` refuses the image instead.
pub fn pass_through_warned(frf: &AxisFrf, r: f64, opts: &DesignOptions, reason: String) -> Result<AxisDesign> {
    eprintln!(
        "WARNING: axis {} is NOT COMPENSATED: passed through raw (delayed by {} samples): {reason} \
         (--strict refuses the image instead)",
        crate::frf::axis_name(frf.axis),
        opts.lag
    );
    pass_through(frf, r, opts, reason)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The delay's f32 filter outputs the input L samples later, exactly
    /// (a single FIR tap of 1); control: another latency is another delay.
    #[test]
    fn the_pass_through_filter_is_the_exact_delay() {
        let frf = AxisFrf { axis: 2, frf: Vec::new(), coherence: None };
        for lag in [0usize, 1, 4, 8] {
            let opts = DesignOptions { fs_hz: 51_200.0, lag, ..Default::default() };
            let d = pass_through(&frf, 0.01, &opts, "test".into()).unwrap();
            let mut st = dynocomp_core::kernel::AxisState::default();
            let x: Vec<f32> = (0..64).map(|k| ((k * 37 % 11) as f32 - 5.0) * 1.7).collect();
            let y: Vec<f32> = x.iter().map(|v| d.filter.step(&mut st, *v)).collect();
            for k in lag..x.len() {
                assert_eq!(y[k], x[k - lag], "lag {lag}, sample {k}");
            }
            assert!(y[..lag].iter().all(|v| *v == 0.0));
            if lag > 0 {
                assert_ne!(y, x, "control: a delay is not the identity");
            }
        }
    }
}
