//! `dynocomp design --parallel`: one compensator per fitting band, in one
//! offline-only image.

use anyhow::{Context, Result};

use crate::cli::design_args::{DesignArgs, DesignSetup};
use crate::design::bands::Band;
use crate::design::image::build_parallel_image;
use crate::design::parallel::{design_parallel, design_regions};
use crate::frf::axis_name;

/// `dynocomp design --parallel`: design per band, write the parallel image
/// atomically; returns the summary per band (text or JSON) for stdout.
pub fn run(args: &DesignArgs, setup: &DesignSetup) -> Result<String> {
    let DesignSetup { frf, r, opts, bands, latency, sha, .. } = setup;
    let (latency, sha) = (*latency, *sha);
    let t0 = std::time::Instant::now();
    let per_band = design_parallel(frf, r, opts, bands).with_context(|| format!("{}", args.input.frf().display()))?;
    let image = build_parallel_image(&per_band, bands, args.input.fs as u32, latency, args.full_scale, sha)?;
    crate::io::image_file::write_parallel_image(&args.out, &image)?;
    crate::offline::sidecar::remove_stale_sidecar(&args.out)?;
    let id = image.id();
    let method = args.method.name();
    let shown = args.out.display().to_string();
    if args.json {
        return parallel_json(args, setup, &per_band, id, t0.elapsed().as_secs_f64());
    }
    let mut out = format!(
        "parallel-elaboration image {shown} (id {id:08x}), OFFLINE ONLY (the box never runs it), {} bands:\n",
        bands.len()
    );
    for (k, (b, ds)) in bands.iter().zip(&per_band).enumerate() {
        out.push_str(&format!("band {k}: {:.0}-{:.0} Hz ({})\n", b.lo_hz, b.hi_hz, b.label));
        let sensitivities = crate::design::sensitivity::predict_all(ds, opts);
        let fs = args.input.fs;
        out.push_str(&crate::report::summary::render_summary(
            ds,
            &sensitivities,
            fs,
            latency,
            &shown,
            id,
            method,
            None,
        ));
    }
    eprintln!("designed in {:.0} ms", t0.elapsed().as_secs_f64() * 1e3);
    Ok(out)
}

/// The `--json` summary of a parallel design: per band its region and each
/// axis's figures; `seconds`: the design time.
fn parallel_json(
    args: &DesignArgs,
    setup: &DesignSetup,
    per_band: &[Vec<crate::design::axis::AxisDesign>],
    id: u32,
    seconds: f64,
) -> Result<String> {
    let DesignSetup { frf, bands, latency, .. } = setup;
    let (method, shown) = (args.method.name(), args.out.display().to_string());
    #[derive(serde::Serialize)]
    struct AxisJson {
        axis: &'static str,
        model_order: usize,
        fit_nrmse: f64,
        q: f64,
        flat_band_hz: (f64, f64),
        noise_gain: f64,
    }
    #[derive(serde::Serialize)]
    struct BandJson<'a> {
        band: &'a Band,
        design_region_hz: (f64, f64),
        axes: Vec<AxisJson>,
    }
    let n = frf.freq_hz.len();
    let regions = design_regions(bands, frf.freq_hz[0], frf.freq_hz[n - 1])?;
    let j: Vec<BandJson> = bands
        .iter()
        .zip(&regions)
        .zip(per_band)
        .map(|((b, reg), ds)| BandJson {
            band: b,
            design_region_hz: (reg.lo_hz, reg.hi_hz),
            axes: ds
                .iter()
                .map(|d| AxisJson {
                    axis: axis_name(d.axis),
                    model_order: d.model.order(),
                    fit_nrmse: d.fit_nrmse,
                    q: d.kalman.q,
                    flat_band_hz: d.flat_band_hz,
                    noise_gain: d.noise_gain,
                })
                .collect(),
        })
        .collect();
    let doc = serde_json::json!({
        "image": shown,
        "image_id": format!("{id:08x}"),
        "offline_only": true,
        "parallel_bands": j,
        "fs_hz": args.input.fs,
        "latency_samples": latency,
        "method": method,
        "design_time_s": seconds,
    });
    Ok(format!("{}\n", serde_json::to_string_pretty(&doc)?))
}
