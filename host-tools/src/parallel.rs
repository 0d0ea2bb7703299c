//! Parallel elaboration (paper §3.3): one compensator per band, in one
//! offline-only image (`design --parallel`), run by `compensate` through the
//! zero-phase split of [`crate::bandsplit`].
//!
//! **Design regions.** `compensate` hands band k everything between the
//! crossovers `f_c,k` and `f_c,k+1` (the middle of the gaps between the bands;
//! DC for the first band, Nyquist for the last). So band k's compensator is
//! designed with the band-fitting of [`crate::design`] (fit weighted to, Q
//! criterion and flat band evaluated on its band lines) over its **region**
//! `[f_c,k / 1.25, 1.25·f_c,k+1]`, clipped to the FRF: where the split
//! passes more than ≈ 5 % of the signal (`L_c(1.25·f_c) = 0.028`), the filter
//! that receives it was designed for it. The image stores the bands
//! themselves (they define the crossovers).

use anyhow::{bail, Context, Result};
use dynocomp_core::image::{BandImage, DesignMethod, ParallelImage, MAX_BANDS};

use crate::bands::Band;
use crate::bandsplit::crossovers;
use crate::design::{design_axis, AxisDesign, DesignOptions};
use crate::design_cmd::build_image;
use crate::frf::{axis_name, Frf};

/// Ratio by which a design region extends past each crossover (module doc).
pub const REGION_MARGIN: f64 = 1.25;

/// The design region of each band (Hz; module doc): the band's share of the
/// zero-phase split, widened by [`REGION_MARGIN`], within `[f_first, f_last]`.
pub fn design_regions(bands: &[Band], f_first: f64, f_last: f64) -> Result<Vec<Band>> {
    let edges: Vec<(f64, f64)> = bands.iter().map(|b| (b.lo_hz, b.hi_hz)).collect();
    let c = crossovers(&edges)?;
    Ok(bands
        .iter()
        .enumerate()
        .map(|(k, b)| {
            let lo = if k == 0 { f_first } else { (c[k - 1] / REGION_MARGIN).max(f_first) };
            let hi = c.get(k).map_or(f_last, |x| (x * REGION_MARGIN).min(f_last));
            Band { lo_hz: lo, hi_hz: hi, label: format!("region of {}", b.label) }
        })
        .collect())
}

/// Design every axis of `frf` once per band (module doc); `r[axis]` is R
/// (N²). Returns the designs per band, then per axis.
pub fn design_parallel(frf: &Frf, r: &[Option<f64>; 3], opts: &DesignOptions, bands: &[Band]) -> Result<Vec<Vec<AxisDesign>>> {
    if bands.is_empty() {
        bail!("--parallel needs bands: give --spindle-rpm and --teeth, --band LO:HI or --bands-from RECORD");
    }
    if bands.len() > MAX_BANDS {
        bail!("--parallel: {} bands, a parallel image holds at most {MAX_BANDS}; use fewer --harmonics or bands", bands.len());
    }
    let n = frf.freq_hz.len();
    let regions = design_regions(bands, frf.freq_hz[0], frf.freq_hz[n - 1])?;
    let mut out = Vec::with_capacity(bands.len());
    for (k, (band, region)) in bands.iter().zip(&regions).enumerate() {
        let band_opts = DesignOptions { bands: vec![region.clone()], ..opts.clone() };
        let mut per_axis = Vec::with_capacity(frf.axes.len());
        for a in &frf.axes {
            let rv = r[a.axis].ok_or_else(|| anyhow::anyhow!("no R for axis {}", axis_name(a.axis)))?;
            let d = design_axis(&frf.freq_hz, a, rv, &band_opts).with_context(|| {
                format!("band {k} ({:.0}-{:.0} Hz, {}; designed over {:.0}-{:.0} Hz)", band.lo_hz, band.hi_hz, band.label, region.lo_hz, region.hi_hz)
            })?;
            per_axis.push(d);
        }
        out.push(per_axis);
    }
    Ok(out)
}

/// The parallel image of per-band designs (each band's filters verified by
/// the design's quantize/verify step), with the bands' edges.
pub fn build_parallel_image(
    per_band: &[Vec<AxisDesign>],
    bands: &[Band],
    fs_hz: u32,
    latency: usize,
    full_scale_n: f64,
    source_sha256: [u8; 32],
) -> Result<ParallelImage> {
    let mut images = Vec::with_capacity(per_band.len());
    let mut method = DesignMethod::VectorFitting;
    let mut created = 0;
    for (designs, band) in per_band.iter().zip(bands) {
        let img = build_image(designs, fs_hz, latency, full_scale_n, source_sha256)?;
        method = img.method;
        created = img.created_unix_s;
        images.push(BandImage { lo_hz: band.lo_hz as f32, hi_hz: band.hi_hz as f32, axes: img.axes });
    }
    let latency = u16::try_from(latency).context("latency too large")?;
    ParallelImage::new(fs_hz, latency, method, source_sha256, created, &images).map_err(|e| anyhow::anyhow!("parallel image: {e}"))
}

/// `dynocomp design --parallel`: design per band, write the parallel image
/// atomically, print a summary per band.
#[allow(clippy::too_many_arguments)]
pub fn run(
    args: &crate::design_cmd::DesignArgs,
    frf: &Frf,
    r: &[Option<f64>; 3],
    opts: &DesignOptions,
    bands: &[Band],
    latency: usize,
    sha: [u8; 32],
) -> Result<()> {
    let t0 = std::time::Instant::now();
    let per_band = design_parallel(frf, r, opts, bands).with_context(|| format!("{}", args.input.frf().display()))?;
    let image = build_parallel_image(&per_band, bands, args.input.fs as u32, latency, args.full_scale, sha)?;
    crate::io::image_file::write_parallel_image(&args.out, &image)?;
    let id = image.id();
    let method = if args.method == "paper" { "paper" } else { "vf" };
    let shown = args.out.display().to_string();
    if args.json {
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
            .zip(&per_band)
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
            "design_time_s": t0.elapsed().as_secs_f64(),
        });
        println!("{}", serde_json::to_string_pretty(&doc)?);
    } else {
        println!("parallel-elaboration image {shown} (id {id:08x}), OFFLINE ONLY (the box never runs it), {} bands:", bands.len());
        for (k, (b, ds)) in bands.iter().zip(&per_band).enumerate() {
            println!("band {k}: {:.0}-{:.0} Hz ({})", b.lo_hz, b.hi_hz, b.label);
            print!("{}", crate::design_cmd::render_summary(ds, args.input.fs, latency, &shown, id, method));
        }
        eprintln!("designed in {:.0} ms", t0.elapsed().as_secs_f64() * 1e3);
    }
    Ok(())
}
