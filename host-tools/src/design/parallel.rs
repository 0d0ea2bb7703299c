//! Parallel elaboration (paper §3.3): one compensator per band, in one
//! offline-only image (`design --parallel`, [`design_parallel`]), run by
//! `compensate` through the zero-phase split of [`crate::offline::bandsplit`].
//! The image stores the bands themselves (they define the crossovers).

use anyhow::{bail, Context, Result};
use dynocomp_core::image::MAX_BANDS;

use crate::design::axis::{AxisDesign, DesignOptions};
use crate::design::bands::crossovers;
use crate::design::bands::Band;
use crate::design::paper_orders::design_axis;
use crate::frf::{axis_name, Frf};

/// Ratio by which a design region extends past each crossover
/// ([`design_regions`]).
pub const REGION_MARGIN: f64 = 1.25;

/// The design region of each band (Hz): the band's share of the zero-phase
/// split, widened by [`REGION_MARGIN`], within `[f_first, f_last]`.
///
/// `compensate` hands band k everything between the crossovers `f_c,k` and
/// `f_c,k+1` (the middle of the gaps between the bands; DC for the first
/// band, Nyquist for the last). So band k's compensator is designed with the
/// band-fitting of [`crate::design::axis`] (fit weighted to, Q criterion and
/// flat band evaluated on its band lines) over its **region**
/// `[f_c,k / 1.25, 1.25·f_c,k+1]`, clipped to the FRF: where the split passes
/// more than ≈ 5 % of the signal (`L_c(1.25·f_c) = 0.028`), the filter that
/// receives it was designed for it.
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

/// Design every axis of `frf` once per band over its region
/// ([`design_regions`]); `r[axis]` is R
/// (N²). Returns the designs per band, then per axis.
pub fn design_parallel(
    frf: &Frf,
    r: &[Option<f64>; 3],
    opts: &DesignOptions,
    bands: &[Band],
) -> Result<Vec<Vec<AxisDesign>>> {
    if bands.is_empty() {
        bail!("--parallel needs bands: give --spindle-rpm and --teeth, --band LO:HI or --bands-from RECORD");
    }
    if bands.len() > MAX_BANDS {
        bail!(
            "--parallel: {} bands, a parallel image holds at most {MAX_BANDS}; use fewer --harmonics or bands",
            bands.len()
        );
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
                format!(
                    "band {k} ({:.0}-{:.0} Hz, {}; designed over {:.0}-{:.0} Hz)",
                    band.lo_hz, band.hi_hz, band.label, region.lo_hz, region.hi_hz
                )
            })?;
            per_axis.push(d);
        }
        out.push(per_axis);
    }
    Ok(out)
}
