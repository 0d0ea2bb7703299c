//! The last L samples of a latency-removed output (the fixed-lag smoother's
//! estimates with no measured look-ahead) against the simulator's true
//! force: fed the record's predicted continuation, they are about as
//! accurate as the rest; fed the last value held (the control), they are
//! not.

use dynocomp::io::signal_csv::{read_signal_csv, SignalRecord};
use dynocomp::numeric::predict::predict_after;
use dynocomp::offline::compensate::{compensate_record, look_ahead};
use dynocomp_core::image::CoeffImage;

fn root() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn prefix(rec: &SignalRecord, n: usize) -> SignalRecord {
    SignalRecord { t_s: None, channels: rec.channels.iter().map(|(a, x)| (*a, x[..n].to_vec())).collect() }
}

/// RMS over the record's ends of (the last L outputs − truth) per axis, and
/// RMS of the error over the body (the samples before the last L of the
/// longest prefix, after the filter's start-up), for records cut at `ends`.
/// `hold`: the control, the record's last value held as its look-ahead
/// (done by appending L copies and taking the raw-timing output).
fn tail_and_body(
    img: &CoeffImage,
    meas: &SignalRecord,
    truth: &SignalRecord,
    ends: &[usize],
    hold: bool,
) -> Vec<(f64, f64)> {
    let l = usize::from(img.latency_samples);
    let mut tail = [0.0f64; 3];
    let mut count = 0usize;
    let mut body = [0.0f64; 3];
    let mut body_n = 0usize;
    for (i, &n) in ends.iter().enumerate() {
        let out = if hold {
            let held = SignalRecord {
                t_s: None,
                channels: meas
                    .channels
                    .iter()
                    .map(|(a, x)| {
                        let mut v = x[..n].to_vec();
                        v.extend(std::iter::repeat_n(x[n - 1], l));
                        (*a, v[..].to_vec())
                    })
                    .collect(),
            };
            let raw = compensate_record(img, &held, true, "test").unwrap();
            SignalRecord { t_s: None, channels: raw.channels.into_iter().map(|(a, y)| (a, y[l..].to_vec())).collect() }
        } else {
            compensate_record(img, &prefix(meas, n), false, "test").unwrap()
        };
        for (c, (_, y)) in out.channels.iter().enumerate() {
            let t = &truth.channels[c].1;
            for k in n - l..n {
                tail[c] += (y[k] - t[k]).powi(2);
            }
            if i == ends.len() - 1 {
                for k in 5000..n - l {
                    body[c] += (y[k] - t[k]).powi(2);
                }
            }
        }
        count += l;
        if i == ends.len() - 1 {
            body_n = n - l - 5000;
        }
    }
    (0..3).map(|c| ((tail[c] / count as f64).sqrt(), (body[c] / body_n as f64).sqrt())).collect()
}

/// The bundled example (a simulated 9257-class dynamometer at 51.2 kHz,
/// latency 4) cut at 24 places in its steady cut: the last L outputs are
/// within 2x the body's RMS error (N) on every axis with the predicted
/// look-ahead, and over 3x on some axis with the last value held.
#[test]
fn the_last_samples_are_as_good_as_the_rest() {
    let img = CoeffImage::parse(&std::fs::read(root().join("fuzz/images/example.dcimg")).unwrap()).unwrap();
    assert!(img.latency_samples >= 2);
    let meas = read_signal_csv(&root().join("data/example/measured.csv")).unwrap();
    let truth = read_signal_csv(&root().join("data/example/true_force.csv")).unwrap();
    let ends: Vec<usize> = (0..24).map(|i| 8000 + 733 * i).collect();
    let predicted = tail_and_body(&img, &meas, &truth, &ends, false);
    let held = tail_and_body(&img, &meas, &truth, &ends, true);
    for (c, ((pt, pb), (ht, _))) in predicted.iter().zip(&held).enumerate() {
        eprintln!("axis {c}: body {pb:.2} N, last L predicted {pt:.2} N, held {ht:.2} N");
    }
    for (c, (pt, pb)) in predicted.iter().enumerate() {
        assert!(pt < &(2.0 * pb), "axis {c}: the last samples are off by {pt:.2} N RMS against {pb:.2} N in the body");
    }
    assert!(
        held.iter().zip(&predicted).any(|((ht, _), (_, pb))| *ht > 3.0 * pb),
        "control: holding the last value should spoil the last samples"
    );
}

/// The look-ahead is the predicted continuation, in f32 as the kernel takes
/// it; a record too short to fit a model gets its last value held.
#[test]
fn look_ahead_is_the_prediction_or_a_hold_for_short_records() {
    let hist: Vec<f32> = (0..500).map(|k| (k as f32 * 0.2).sin() * 50.0 + 10.0).collect();
    let want = predict_after(&hist.iter().map(|&v| f64::from(v)).collect::<Vec<_>>(), 6).unwrap();
    let got = look_ahead(&hist, 6);
    assert_eq!(got, want.iter().map(|&v| v as f32).collect::<Vec<_>>());
    let truth: Vec<f32> = (500..506).map(|k| (k as f32 * 0.2).sin() * 50.0 + 10.0).collect();
    assert!(got.iter().zip(&truth).all(|(g, t)| (g - t).abs() < 0.05), "{got:?} vs {truth:?}");
    assert_eq!(look_ahead(&[3.0; 10], 3), vec![3.0; 3]);
    assert!(look_ahead(&hist, 0).is_empty());
}
