//! The output-as-written figures (DESIGN.md, "Accuracy") against analytic
//! signals: a 1 kHz tone of amplitude 1 plus an 8 kHz tone of amplitude 0.3
//! above a 4 kHz band, sampled at 51.2 kHz on whole cycles, so every figure
//! has a closed form.

use dynocomp::metrics::{accuracy, accuracy_as_written};
use std::f64::consts::PI;

const FS: f64 = 51_200.0;
const BAND: f64 = 4_000.0;
const N: usize = 5_120;

fn tone(f: f64, a: f64) -> Vec<f64> {
    (0..N).map(|k| a * (2.0 * PI * f * k as f64 / FS).sin()).collect()
}

fn add(a: &[f64], b: &[f64]) -> Vec<f64> {
    a.iter().zip(b).map(|(x, y)| x + y).collect()
}

#[test]
fn as_written_figures_match_their_closed_forms() {
    let in_band = tone(1_000.0, 1.0);
    let truth = add(&in_band, &tone(8_000.0, 0.3));
    let std_truth = ((1.0 + 0.09) / 2.0f64).sqrt();
    let above = 0.3 / 2f64.sqrt();

    // A perfect band-limited estimate misses exactly the 8 kHz tone.
    let perfect = accuracy_as_written(&in_band, &truth, FS, BAND);
    assert!((perfect.perfect.nrmse - above / std_truth).abs() < 1e-9, "{perfect:?}");
    assert!((perfect.output.nrmse - perfect.perfect.nrmse).abs() < 1e-9, "{perfect:?}");

    // The truth itself as the estimate: no error as written.
    assert!(accuracy_as_written(&truth, &truth, FS, BAND).output.nrmse < 1e-12);

    // Control: the band-limited estimate plus 0.3 of noise at 10 kHz is
    // perfect in the band, but √2 worse than the perfect estimate as
    // written (two uncorrelated tones of 0.3 above the band).
    let noisy = add(&in_band, &tone(10_000.0, 0.3));
    assert!(accuracy(&noisy, &truth, FS, BAND).nrmse < 1e-9, "the band-limited figure cannot see it");
    let w = accuracy_as_written(&noisy, &truth, FS, BAND);
    let want = (2.0 * above * above).sqrt() / std_truth;
    assert!((w.output.nrmse - want).abs() < 1e-9, "{w:?}, want {want}");
    assert!(w.output.nrmse / w.perfect.nrmse > 1.41, "{w:?}");
}
