//! For scripts/bench_scipy.sh (issue #6): export an image's compensators as
//! second-order transfer functions for scipy, and time `compensate` on a
//! record in memory (no CSV I/O), in the same run as scipy.
//!
//! usage: sos_export IMAGE INPUT.csv OUT.json [REPEATS]
//!
//! Per axis the JSON holds `d`, `fir` (h_1..h_m, delays 1..m) and `sections`:
//! each 2x2 delta-form section (A = I + Δ, b, c) of the kernel as
//! `[b0, b1, b2, a0, a1, a2]` of c·(zI − A)⁻¹·b =
//! (n1 z⁻¹ + n2 z⁻²) / (1 − tr(A) z⁻¹ + det(A) z⁻²), computed in f64 from the
//! image's f32 values, plus `A`, `B`, `C`, `D` of the block-diagonal state
//! space. The kernel's filter is d + Σ sections + FIR (parallel form).
//! Prints `compensate_samples_per_s <axes> <value>` (best of REPEATS, default 200: the first runs after start-up are up to 1.4x slower).
use anyhow::{ensure, Context, Result};
use dynocomp::io::image_file::read_image;
use dynocomp::io::signal_csv::{read_signal_csv, SignalRecord};
use dynocomp::offline::compensate::compensate_record;
use serde_json::json;
use std::path::Path;
use std::time::Instant;

fn main() -> Result<()> {
    let a: Vec<String> = std::env::args().collect();
    ensure!(a.len() >= 4, "usage: sos_export IMAGE INPUT.csv OUT.json [REPEATS]");
    let image = read_image(Path::new(&a[1]))?;
    let rec = read_signal_csv(Path::new(&a[2]))?;
    let repeats: usize = a.get(4).map_or(Ok(200), |s| s.parse()).context("REPEATS")?;

    let mut axes = Vec::new();
    for ax in image.axes.iter().flatten() {
        let f = &ax.filter;
        let n = 2 * f.sections().len();
        let mut am = vec![vec![0.0f64; n]; n];
        let mut bm = vec![0.0f64; n];
        let mut cm = vec![0.0f64; n];
        let mut sos = Vec::new();
        for (i, s) in f.sections().iter().enumerate() {
            let [d11, d12, d21, d22] = s.delta.map(f64::from);
            let (a11, a12, a21, a22) = (1.0 + d11, d12, d21, 1.0 + d22);
            let [b1, b2] = s.b.map(f64::from);
            let [c1, c2] = s.c.map(f64::from);
            // c·adj(zI − A)·b with adj = [[z − a22, a12], [a21, z − a11]].
            let n1 = c1 * b1 + c2 * b2;
            let n2 = -a22 * c1 * b1 + a12 * c1 * b2 + a21 * c2 * b1 - a11 * c2 * b2;
            let tr = a11 + a22;
            let det = a11 * a22 - a12 * a21;
            sos.push([0.0, n1, n2, 1.0, -tr, det]);
            let (r0, r1) = (2 * i, 2 * i + 1);
            am[r0][r0] = a11;
            am[r0][r1] = a12;
            am[r1][r0] = a21;
            am[r1][r1] = a22;
            bm[r0] = b1;
            bm[r1] = b2;
            cm[r0] = c1;
            cm[r1] = c2;
        }
        axes.push(json!({
            "axis": ax.axis,
            "d": f64::from(f.d()),
            "fir": f.fir().iter().map(|&h| f64::from(h)).collect::<Vec<_>>(),
            "sections": sos,
            "A": am, "B": bm, "C": cm,
        }));
    }
    let out = json!({ "fs_hz": image.fs_hz, "axes": axes });
    std::fs::write(&a[3], serde_json::to_string(&out)?).with_context(|| format!("{}: cannot write", a[3]))?;

    for n_axes in [1usize, 3] {
        let sub = SignalRecord { t_s: None, channels: rec.channels[..n_axes.min(rec.channels.len())].to_vec() };
        let mut best = f64::INFINITY;
        for _ in 0..repeats {
            let t = Instant::now();
            let r = compensate_record(&image, &sub, true, "bench")?;
            std::hint::black_box(&r);
            best = best.min(t.elapsed().as_secs_f64());
        }
        let samples = (sub.len() * sub.channels.len()) as f64;
        println!("compensate_samples_per_s {} {:.6e}", sub.channels.len(), samples / best);
    }

    // The box's path for comparison: `step` per sample, the three axes
    // interleaved sample by sample; same kernel, same results per axis.
    let filters: Vec<_> =
        rec.channels.iter().filter_map(|(a, _)| image.axes.get(*a).copied().flatten().map(|ai| ai.filter)).collect();
    let inputs: Vec<Vec<f32>> = rec.channels.iter().map(|(_, v)| v.iter().map(|&x| x as f32).collect()).collect();
    ensure!(filters.len() == inputs.len(), "every column needs a compensator in the image");
    let n = rec.len();
    let mut outs = vec![vec![0.0f32; n]; inputs.len()];
    let mut best = f64::INFINITY;
    for _ in 0..repeats {
        let mut states = vec![dynocomp_core::kernel::AxisState::default(); filters.len()];
        let t = Instant::now();
        for k in 0..n {
            for ((f, st), (inp, out)) in filters.iter().zip(states.iter_mut()).zip(inputs.iter().zip(outs.iter_mut())) {
                out[k] = f.step(st, inp[k]);
            }
        }
        std::hint::black_box(&outs);
        best = best.min(t.elapsed().as_secs_f64());
    }
    println!("step_kernel_samples_per_s {} {:.6e}", inputs.len(), (n * inputs.len()) as f64 / best);
    Ok(())
}
