//! Mechanistic milling forces (Altintas, *Manufacturing Automation*, ch. 2):
//! linear edge-force model integrated along the axial depth in slices
//! ([`milling_force`]).

use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// Up (conventional) or down (climb) milling.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum MillingMode {
    /// Up milling: the tooth enters at φ = 0 (zero chip) and exits at arccos(1 − 2ae/D).
    Up,
    /// Down milling: the tooth enters at arccos(2ae/D − 1) and exits at π (zero chip).
    Down,
}

/// Regenerative chatter: a tool vibration at a non-harmonic frequency whose
/// amplitude grows (logistic) during the cut.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Chatter {
    /// Chatter frequency (Hz).
    pub freq_hz: f64,
    /// Final vibration amplitude (mm) in x; y has 0.8 of it, a quarter period later.
    pub amplitude_mm: f64,
    /// Time at which the amplitude reaches half its final value (s).
    pub onset_s: f64,
    /// Growth time constant of the logistic amplitude (s).
    pub growth_s: f64,
}

impl Chatter {
    fn amplitude(&self, t: f64) -> f64 {
        self.amplitude_mm / (1.0 + (-(t - self.onset_s) / self.growth_s.max(1e-9)).exp())
    }

    /// Tool displacement (x, y) at time t (mm).
    fn displacement(&self, t: f64) -> (f64, f64) {
        let a = self.amplitude(t);
        let w = 2.0 * PI * self.freq_hz;
        (a * (w * t).sin(), 0.8 * a * (w * t - PI / 2.0).sin())
    }
}

/// Cutting conditions and coefficients.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MillingParams {
    /// Spindle speed (rev/min).
    pub spindle_rpm: f64,
    /// Number of teeth Z.
    pub teeth: usize,
    /// Tool diameter D (mm).
    pub diameter_mm: f64,
    /// Helix angle β (degrees; 0 = straight teeth).
    pub helix_deg: f64,
    /// Axial depth of cut ap (mm).
    pub axial_depth_mm: f64,
    /// Radial depth of cut (immersion) ae (mm); ae = D is a slot.
    pub radial_depth_mm: f64,
    /// Up or down milling.
    pub mode: MillingMode,
    /// Feed per tooth c (mm).
    pub feed_per_tooth_mm: f64,
    /// Tangential cutting coefficient Kt (N/mm²).
    pub kt: f64,
    /// Radial cutting coefficient Kr (N/mm²).
    pub kr: f64,
    /// Axial cutting coefficient Ka (N/mm²).
    pub ka: f64,
    /// Tangential edge coefficient Kte (N/mm).
    pub kte: f64,
    /// Radial edge coefficient Kre (N/mm).
    pub kre: f64,
    /// Axial edge coefficient Kae (N/mm).
    pub kae: f64,
    /// Runout: radial offset amplitude ρ (mm) of the tool axis.
    pub runout_mm: f64,
    /// Runout: angle λ (degrees) of the offset relative to tooth 0.
    pub runout_angle_deg: f64,
    /// Revolutions over which engagement ramps from 0 to full (smoothstep); 0 = none.
    pub ramp_in_revs: f64,
    /// Axial slices for the helix integration (1 is exact for straight teeth).
    pub axial_slices: usize,
    /// Optional regenerative chatter.
    pub chatter: Option<Chatter>,
}

impl Default for MillingParams {
    /// Down milling of steel with a 10 mm, 4-tooth, 30° helix end mill at
    /// 4125 rpm (TPF 275 Hz, the paper's faster test), ap 2 mm, ae 3 mm,
    /// 0.05 mm/tooth, 5 µm runout.
    fn default() -> Self {
        Self {
            spindle_rpm: 4125.0,
            teeth: 4,
            diameter_mm: 10.0,
            helix_deg: 30.0,
            axial_depth_mm: 2.0,
            radial_depth_mm: 3.0,
            mode: MillingMode::Down,
            feed_per_tooth_mm: 0.05,
            kt: 2000.0,
            kr: 800.0,
            ka: 300.0,
            kte: 25.0,
            kre: 30.0,
            kae: 3.0,
            runout_mm: 0.005,
            runout_angle_deg: 0.0,
            ramp_in_revs: 2.0,
            axial_slices: 32,
            chatter: None,
        }
    }
}

impl MillingParams {
    /// Spindle frequency rpm/60 (Hz).
    pub fn spindle_hz(&self) -> f64 {
        self.spindle_rpm / 60.0
    }

    /// Tooth-passing frequency rpm/60·Z (Hz).
    pub fn tooth_passing_hz(&self) -> f64 {
        self.spindle_hz() * self.teeth as f64
    }

    /// Engagement window (φ_st, φ_ex) in radians.
    pub fn engagement(&self) -> (f64, f64) {
        let ratio = (self.radial_depth_mm / self.diameter_mm).clamp(0.0, 1.0);
        match self.mode {
            MillingMode::Up => (0.0, (1.0 - 2.0 * ratio).acos()),
            MillingMode::Down => ((2.0 * ratio - 1.0).acos(), PI),
        }
    }

    /// Check the parameters; names the offending one.
    pub fn validate(&self) -> anyhow::Result<()> {
        let pos = |v: f64, name: &str| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(anyhow::anyhow!("milling parameter {name} = {v} must be finite and > 0"))
            }
        };
        pos(self.spindle_rpm, "spindle_rpm")?;
        pos(self.diameter_mm, "diameter_mm")?;
        pos(self.axial_depth_mm, "axial_depth_mm")?;
        pos(self.radial_depth_mm, "radial_depth_mm")?;
        pos(self.feed_per_tooth_mm, "feed_per_tooth_mm")?;
        if self.teeth == 0 || self.teeth > super::MAX_TEETH {
            anyhow::bail!("milling parameter teeth = {} must be in 1..={}", self.teeth, super::MAX_TEETH);
        }
        if self.spindle_rpm > super::MAX_SPINDLE_RPM {
            let max = super::MAX_SPINDLE_RPM;
            anyhow::bail!("milling parameter spindle_rpm = {} must be at most {max}", self.spindle_rpm);
        }
        if self.axial_slices == 0 {
            anyhow::bail!("milling parameter axial_slices must be ≥ 1");
        }
        if self.radial_depth_mm > self.diameter_mm {
            anyhow::bail!(
                "milling parameter radial_depth_mm = {} exceeds the diameter {}",
                self.radial_depth_mm,
                self.diameter_mm
            );
        }
        if self.helix_deg.is_nan() || self.helix_deg.abs() >= 89.0 {
            anyhow::bail!("milling parameter helix_deg = {} must be within ±89°", self.helix_deg);
        }
        if let Some(c) = &self.chatter {
            pos(c.freq_hz, "chatter.freq_hz")?;
            if !(c.amplitude_mm.is_finite() && c.amplitude_mm >= 0.0) {
                anyhow::bail!("milling parameter chatter.amplitude_mm = {} must be ≥ 0", c.amplitude_mm);
            }
        }
        Ok(())
    }
}

/// Cutting forces (Fx, Fy, Fz) in N at `n` samples `t_k = k/fs_hz` from t = 0
/// (tooth 0 at φ = 0 at t = 0).
///
/// Conventions (Altintas): feed along +x, the tool turns clockwise seen from
/// the spindle, the immersion angle φ is measured clockwise from +y. Tooth j at
/// height z has φ_j(z,t) = Ω·t + j·2π/Z − k_β·z with k_β = 2·tan β / D. In the
/// engagement window φ_st ≤ φ ≤ φ_ex, with chip thickness h > 0:
/// ```text
/// dFt = (Kt·h + Kte)·dz   dFr = (Kr·h + Kre)·dz   dFa = (Ka·h + Kae)·dz
/// dFx = −dFt·cos φ − dFr·sin φ
/// dFy = +dFt·sin φ − dFr·cos φ
/// dFz = +dFa
/// ```
/// Chip thickness `h = c·sin φ + (ρ_j − ρ_{j+1}) + Δh_chatter`: ρ_j is tooth j's
/// radial offset from runout, ρ_j = ρ·cos(λ − j·2π/Z) (tooth j+1 is the one that
/// cut the surface before tooth j), and chatter adds the regenerative term
/// `[x(t−T) − x(t)]·sin φ + [y(t−T) − y(t)]·cos φ` of a tool vibration at the
/// chatter frequency with a logistic growing amplitude (T = tooth period).
/// A tooth with h ≤ 0 is out of the cut (no force, no edge force). Ramp-in
/// scales the whole force by a smoothstep over the first revolutions.
pub fn milling_force(p: &MillingParams, fs_hz: f64, n: usize) -> [Vec<f64>; 3] {
    let z_teeth = p.teeth.max(1);
    let pitch = 2.0 * PI / z_teeth as f64;
    let omega = 2.0 * PI * p.spindle_hz();
    let kb = 2.0 * p.helix_deg.to_radians().tan() / p.diameter_mm;
    let slices = if p.helix_deg == 0.0 { 1 } else { p.axial_slices.max(1) };
    let dz = p.axial_depth_mm / slices as f64;
    let (phi_st, phi_ex) = p.engagement();
    let c = p.feed_per_tooth_mm;
    let lambda = p.runout_angle_deg.to_radians();
    let rho: Vec<f64> = (0..z_teeth).map(|j| p.runout_mm * (lambda - j as f64 * pitch).cos()).collect();
    let d_runout: Vec<f64> = (0..z_teeth).map(|j| rho[j] - rho[(j + 1) % z_teeth]).collect();
    let tooth_period = 1.0 / p.tooth_passing_hz();
    let ramp_s = p.ramp_in_revs.max(0.0) / p.spindle_hz();
    let mut fx = vec![0.0; n];
    let mut fy = vec![0.0; n];
    let mut fz = vec![0.0; n];
    for k in 0..n {
        let t = k as f64 / fs_hz;
        let (dxc, dyc) = match &p.chatter {
            Some(ch) => {
                let (x0, y0) = ch.displacement(t);
                let (x1, y1) = ch.displacement(t - tooth_period);
                (x1 - x0, y1 - y0)
            }
            None => (0.0, 0.0),
        };
        let (mut sx, mut sy, mut sz) = (0.0, 0.0, 0.0);
        for (j, d_ro) in d_runout.iter().enumerate() {
            let phi_j = omega * t + j as f64 * pitch;
            for i in 0..slices {
                let z = (i as f64 + 0.5) * dz;
                let phi = (phi_j - kb * z).rem_euclid(2.0 * PI);
                if phi < phi_st || phi > phi_ex {
                    continue;
                }
                let (s, co) = phi.sin_cos();
                let h = c * s + d_ro + dxc * s + dyc * co;
                if h <= 0.0 {
                    continue;
                }
                let ft = (p.kt * h + p.kte) * dz;
                let fr = (p.kr * h + p.kre) * dz;
                let fa = (p.ka * h + p.kae) * dz;
                sx += -ft * co - fr * s;
                sy += ft * s - fr * co;
                sz += fa;
            }
        }
        let ramp = if ramp_s > 0.0 && t < ramp_s {
            let x = t / ramp_s;
            x * x * (3.0 - 2.0 * x)
        } else {
            1.0
        };
        fx[k] = ramp * sx;
        fy[k] = ramp * sy;
        fz[k] = ramp * sz;
    }
    [fx, fy, fz]
}
