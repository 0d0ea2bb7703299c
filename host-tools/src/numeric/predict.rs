//! Linear prediction of a sampled signal past its last sample: an
//! autoregressive model fitted by Burg's method (maximum-entropy, its
//! reflection coefficients |k_m| ≤ 1, so the prediction filter is minimum
//! phase) to the end of the record, then run forward on its own output.
//!
//! The offline compensators use it to give the last L samples of a record
//! the look-ahead the fixed-lag smoother needs (L samples of measurement
//! past the record's end), instead of holding the last value, which is a
//! kink the dynamometer's model reads as a large force.

/// Samples at the end of a record the model is fitted on (at most).
pub const WINDOW: usize = 4096;
/// Model order (at most; an eighth of a shorter window).
pub const ORDER: usize = 256;

/// The `count` samples that follow `history` (its last [`WINDOW`] samples
/// matter), predicted by an AR model of order ≤ [`ORDER`] fitted to them
/// with their mean removed. `None` when the history is too short to fit
/// (fewer than 16 samples) or a prediction is not finite; the caller then
/// needs another way to finish.
pub fn predict_after(history: &[f64], count: usize) -> Option<Vec<f64>> {
    let x = &history[history.len().saturating_sub(WINDOW)..];
    if x.len() < 16 {
        return None;
    }
    let mean = x.iter().sum::<f64>() / x.len() as f64;
    let centred: Vec<f64> = x.iter().map(|v| v - mean).collect();
    let a = burg(&centred, ORDER.min(x.len() / 8));
    let mut ext = centred;
    let n0 = ext.len();
    for _ in 0..count {
        let n = ext.len();
        let next = -a.iter().enumerate().map(|(k, ak)| ak * ext[n - 1 - k]).sum::<f64>();
        ext.push(next);
    }
    let out: Vec<f64> = ext[n0..].iter().map(|v| v + mean).collect();
    out.iter().all(|v| v.is_finite()).then_some(out)
}

/// Burg's method: the coefficients a_1..a_p of x_n + Σ a_k x_{n−k} = e_n
/// (returned as `a[k − 1]`). Stops early, with a shorter model, when the
/// remaining prediction error has no energy left.
pub fn burg(x: &[f64], order: usize) -> Vec<f64> {
    let n = x.len();
    let mut f = x.to_vec();
    let mut b = x.to_vec();
    let mut a: Vec<f64> = Vec::with_capacity(order);
    let energy: f64 = x.iter().map(|v| v * v).sum();
    for m in 1..=order.min(n.saturating_sub(1)) {
        // f[i]: forward error of order m−1 at i; b[i−1]: backward error at i−1.
        let (mut num, mut den) = (0.0, 0.0);
        for i in m..n {
            num += f[i] * b[i - 1];
            den += f[i] * f[i] + b[i - 1] * b[i - 1];
        }
        if !(den > 1e-24 * energy.max(f64::MIN_POSITIVE)) {
            break;
        }
        let k = -2.0 * num / den;
        for i in (m..n).rev() {
            let (fi, bi) = (f[i], b[i - 1]);
            f[i] = fi + k * bi;
            b[i] = bi + k * fi;
        }
        // Levinson update: a_j ← a_j + k·a_{m−j}, a_m = k.
        let prev = a.clone();
        for j in 0..prev.len() {
            a[j] += k * prev[prev.len() - 1 - j];
        }
        a.push(k);
    }
    a
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A sum of sinusoids is an AR process of twice their count: the
    /// prediction continues it (checked against the true continuation),
    /// and holding the last value (the control) does not.
    #[test]
    fn continues_sinusoids_and_beats_a_hold() {
        let s = |k: usize| {
            let t = k as f64 / 51_200.0;
            80.0 + 30.0 * (2.0 * std::f64::consts::PI * 1100.0 * t).sin()
                + 12.0 * (2.0 * std::f64::consts::PI * 2200.0 * t + 0.4).sin()
                + 3.0 * (2.0 * std::f64::consts::PI * 3300.0 * t + 1.1).sin()
        };
        let hist: Vec<f64> = (0..3000).map(s).collect();
        let pred = predict_after(&hist, 8).unwrap();
        let hold = *hist.last().unwrap();
        let (mut e_pred, mut e_hold) = (0.0f64, 0.0f64);
        for (m, p) in pred.iter().enumerate() {
            let truth = s(3000 + m);
            e_pred = e_pred.max((p - truth).abs());
            e_hold = e_hold.max((hold - truth).abs());
        }
        assert!(e_pred < 1e-3, "prediction error {e_pred}");
        assert!(e_hold > 5.0, "control: holding is off by {e_hold}");
    }

    /// The reflection coefficients of an AR(1) x_n = 0.9 x_{n−1} + e_n are
    /// found (a_1 ≈ −0.9), and a constant or short history does not fail.
    #[test]
    fn fits_an_ar1_and_survives_degenerate_histories() {
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut rnd = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let mut x = vec![0.0f64; 20_000];
        for i in 1..x.len() {
            x[i] = 0.9 * x[i - 1] + rnd();
        }
        let a = burg(&x, 1);
        assert!((a[0] + 0.9).abs() < 0.01, "a1 = {}", a[0]);
        assert_eq!(predict_after(&[5.0; 100], 4), Some(vec![5.0; 4]));
        assert_eq!(predict_after(&[1.0; 15], 4), None);
    }
}
