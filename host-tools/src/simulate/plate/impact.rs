//! Impact tests of all nine FRFs: the hammer strikes the impact point in x,
//! then y, then z, and each test records all three channels, so test j
//! measures column j of G (H1 and coherence per channel, as in
//! [`crate::simulate::impact`]: the three channels of one test share the
//! impacts and the hammer's load-cell noise, each has its own output noise).

use num_complex::Complex64;

use super::modal::PlateModal;
use crate::frf::{AxisFrf, CrossFrf, Frf};
use crate::simulate::impact::{impact_freqs, impact_test_channels, ImpactParams};
use crate::simulate::sub_seed;

/// Seed tag of hammer direction j's test: `TAG + j`.
const TAG_DIRECTION: u64 = 40;

/// Impact tests in x, y and z at the modal form's point, `n_lines` lines at
/// `df_hz`, through `analog(f)` (the acquisition chain's analog front end,
/// 1 without one): all nine entries with coherence.
pub fn impact_test_matrix(
    modal: &PlateModal,
    analog: &dyn Fn(f64) -> Complex64,
    n_lines: usize,
    df_hz: f64,
    seed: u64,
    params: &ImpactParams,
) -> Frf {
    let mut frf = Frf::direct(impact_freqs(n_lines, df_hz), Vec::new());
    for j in 0..3 {
        let g = |f: f64, out: &mut [Complex64]| {
            let gm = modal.frf(f);
            let a = analog(f);
            for (i, o) in out.iter_mut().enumerate() {
                *o = gm[(i, j)] * a;
            }
        };
        let column = impact_test_channels(&g, 3, n_lines, df_hz, sub_seed(seed, TAG_DIRECTION + j as u64), params);
        for (i, (h1, coh)) in column.into_iter().enumerate() {
            if i == j {
                frf.axes.push(AxisFrf { axis: i, frf: h1, coherence: Some(coh) });
            } else {
                frf.cross.push(CrossFrf { channel: i, direction: j, frf: h1, coherence: Some(coh) });
            }
        }
    }
    frf.axes.sort_by_key(|a| a.axis);
    frf.cross.sort_by_key(|c| (c.channel, c.direction));
    frf
}
