//! The kernel's FIR part (delays 1..=m) against an independent f64
//! convolution, for every length that the one-pass accumulate-and-shift
//! loop of `AxisFilter::step` treats differently (1, odd, MAX_FIR − 1, MAX_FIR).
use dynocomp_core::kernel::{AxisFilter, AxisState, MAX_FIR};

fn noise(seed: &mut u64) -> f32 {
    *seed ^= *seed << 13;
    *seed ^= *seed >> 7;
    *seed ^= *seed << 17;
    ((*seed >> 40) as f32 / (1u64 << 24) as f32 - 0.5) * 200.0
}

#[test]
fn fir_part_matches_a_direct_convolution() {
    let mut seed = 0x2545_F491_4F6C_DD1Du64;
    for m in [1usize, 2, 5, 13, MAX_FIR - 1, MAX_FIR] {
        let taps: Vec<f32> = (0..m).map(|_| noise(&mut seed) / 50.0).collect();
        let d = 0.3f32;
        let f = AxisFilter::with_fir(&[], d, &taps).unwrap();
        let input: Vec<f32> = (0..600).map(|_| noise(&mut seed)).collect();
        let mut st = AxisState::default();
        for (k, &u) in input.iter().enumerate() {
            let y = f.step(&mut st, u);
            // f64 reference: y[k] = d·u[k] + Σ_{j=1..m} h_j·u[k−j], u[<0] = 0.
            let mut y_ref = f64::from(d) * f64::from(u);
            let mut scale = y_ref.abs();
            for (j, h) in taps.iter().enumerate() {
                if let Some(&past) = k.checked_sub(j + 1).and_then(|i| input.get(i)) {
                    let t = f64::from(*h) * f64::from(past);
                    y_ref += t;
                    scale += t.abs();
                }
            }
            // Rounding of an (m+1)-term f32 sum: ≤ (m+1)·2⁻²⁴·Σ|terms|.
            let bound = (m + 1) as f64 * f64::from(f32::EPSILON) / 2.0 * scale;
            assert!(
                (f64::from(y) - y_ref).abs() <= bound,
                "m = {m}, sample {k}: kernel {y}, f64 convolution {y_ref} (bound {bound:e})"
            );
            // The history holds the last m inputs, newest first.
            for j in 0..m {
                let want = k.checked_sub(j).map_or(0.0, |i| input[i]);
                assert_eq!(st.fir_hist[j].to_bits(), want.to_bits(), "m = {m}, sample {k}, history slot {j}");
            }
        }
    }
}
