//! The physical set-up of a plate dynamometer on the machine table and its
//! 12-DOF model M q̈ + C q̇ + K q = B(p)·F.
//! ([`PlateSetup`], its bounds, and the matrices [`PlateMatrices`]).

use anyhow::{bail, Result};
use nalgebra::{DMatrix, Matrix3, SMatrix, Vector3};
use serde::{Deserialize, Serialize};

use super::body::RigidBody;

/// Number of degrees of freedom: plate 6 + base 6.
pub const DOF: usize = 12;

/// A plate dynamometer with its workpiece on the machine table.
///
/// Coordinates as in [`super::body`]: origin at the centre of the sensor
/// plane, z up. Bodies:
/// - the top plate (a cuboid whose underside lies on the sensor plane, centred
///   over the sensors) with the workpiece (a cuboid standing on the plate)
///   clamped to it: one rigid body, q_p = [u_p; θ_p] about its centre of mass;
/// - the base (a cuboid under the sensor plane, centred): the dynamometer's
///   housing together with the effective (modal) mass of the machine table
///   under it, q_b = [u_b; θ_b] about its centre of mass.
///
/// Four 3-component sensors at (±a, ±b, 0) join the plate to the base, each
/// a spring diag(kx, ky, kz) (N/m) on the relative displacement
/// δ = u_p(s) − u_b(s) of the two bodies at the sensor. Four mounts at the
/// base's bottom corners hold it on the (rigid) table, each diag(kx, ky, kz).
/// The measured channels are the sums of the four sensors' forces Σ K_s δ_k
/// (what a multi-component dynamometer outputs), through a static crosstalk
/// matrix S = I + E: y = S·Cd·q plus the sensors' damping force
/// ([`super::modal`]). A force F at p acts on the plate only, so statically
/// the sensors carry all of it and G(0) = S.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PlateSetup {
    /// Mass of the top plate (kg).
    pub plate_mass_kg: f64,
    /// Top plate edges x, y and thickness z (m); its underside on the sensor plane.
    pub plate_size_m: [f64; 3],
    /// Mass of the workpiece clamped on the plate (kg); 0 = none.
    pub workpiece_mass_kg: f64,
    /// Workpiece edges x, y, z (m), standing on the plate's top face.
    pub workpiece_size_m: [f64; 3],
    /// Centre of the workpiece's footprint in the plane (m).
    pub workpiece_xy_m: [f64; 2],
    /// Half spacing (a, b) of the sensors at (±a, ±b, 0) (m).
    pub sensor_half_spacing_m: [f64; 2],
    /// Stiffness of one sensor in x, y, z (N/m).
    pub sensor_stiffness_n_per_m: [f64; 3],
    /// Mass of the base: housing plus the effective mass of the table (kg).
    pub base_mass_kg: f64,
    /// Base edges x, y, z (m); its top face on the sensor plane, centred.
    pub base_size_m: [f64; 3],
    /// Stiffness of one of the four table mounts (base bottom corners) in x, y, z (N/m).
    pub table_stiffness_n_per_m: [f64; 3],
    /// Damping ratio of each mode, ascending by natural frequency (12 values).
    pub zeta: Vec<f64>,
    /// Static crosstalk E of S = I + E: channel i reads (S·F)_i statically.
    /// Diagonal zero (gain errors belong to calibration).
    pub crosstalk: [[f64; 3]; 3],
    /// Where the force acts in the impact test (the impact point) (m).
    pub force_point_m: [f64; 3],
}

/// Physical bounds of every parameter, checked by [`PlateSetup::validate`]:
/// (lower, upper), inclusive, in the unit each names.
pub mod bounds {
    /// Top plate mass (kg).
    pub const PLATE_MASS_KG: (f64, f64) = (0.2, 50.0);
    /// Top plate edges in the plane (m).
    pub const PLATE_EDGE_M: (f64, f64) = (0.03, 1.0);
    /// Top plate thickness (m).
    pub const PLATE_THICKNESS_M: (f64, f64) = (0.003, 0.15);
    /// Workpiece mass (kg); 0 = none.
    pub const WORKPIECE_MASS_KG: (f64, f64) = (0.0, 100.0);
    /// Workpiece edges (m).
    pub const WORKPIECE_EDGE_M: (f64, f64) = (0.001, 0.6);
    /// Density of plate and workpiece (kg/m³): plastics to tungsten.
    pub const DENSITY_KG_M3: (f64, f64) = (500.0, 20_000.0);
    /// Sensor half spacing (m).
    pub const SENSOR_HALF_SPACING_M: (f64, f64) = (0.005, 0.5);
    /// Stiffness of one sensor (N/m).
    pub const SENSOR_STIFFNESS_N_PER_M: (f64, f64) = (1e7, 1e10);
    /// Base mass incl. the table's effective mass (kg).
    pub const BASE_MASS_KG: (f64, f64) = (0.5, 2000.0);
    /// Base edges (m).
    pub const BASE_EDGE_M: (f64, f64) = (0.02, 3.0);
    /// Stiffness of one table mount (N/m).
    pub const TABLE_STIFFNESS_N_PER_M: (f64, f64) = (1e5, 1e10);
    /// Modal damping ratio.
    pub const ZETA: (f64, f64) = (0.001, 0.2);
    /// |E_ij| of the static crosstalk (datasheets give < 0.02).
    pub const CROSSTALK: f64 = 0.05;
    /// |x|, |y| of a force point (m).
    pub const POINT_XY_M: f64 = 0.5;
    /// z of a force point (m): on or above the sensor plane.
    pub const POINT_Z_M: (f64, f64) = (0.0, 0.5);
}

fn in_range(name: &str, v: f64, (lo, hi): (f64, f64), unit: &str) -> Result<()> {
    if !(v.is_finite() && v >= lo && v <= hi) {
        bail!("plate dynamometer: {name} = {v} {unit} is outside the physical range {lo}..={hi} {unit}");
    }
    Ok(())
}

/// Check a force application point against [`bounds`]; `name` says which.
pub fn check_point(name: &str, p: [f64; 3]) -> Result<()> {
    let xy = (-bounds::POINT_XY_M, bounds::POINT_XY_M);
    in_range(&format!("{name} x"), p[0], xy, "m")?;
    in_range(&format!("{name} y"), p[1], xy, "m")?;
    in_range(&format!("{name} z"), p[2], bounds::POINT_Z_M, "m")
}

/// The model's matrices, for a force at one point.
#[derive(Clone, Debug)]
pub struct PlateMatrices {
    /// Mass matrix (12x12): kg for translations, kg·m² for rotations.
    pub m: DMatrix<f64>,
    /// Stiffness matrix (12x12), sensors and table mounts.
    pub k: DMatrix<f64>,
    /// Input matrix (12x3): generalized force per newton of F at the point.
    pub b: DMatrix<f64>,
    /// Sensor force sum per unit q (3x12, N/m): Σ K_s·L_k with δ_k = L_k q.
    pub cd: DMatrix<f64>,
    /// Static crosstalk S = I + E (3x3).
    pub s: Matrix3<f64>,
}

impl PlateSetup {
    /// Check every parameter against its physical range ([`bounds`]); the
    /// error names the parameter, its value and the range.
    pub fn validate(&self) -> Result<()> {
        use bounds::*;
        in_range("plate mass", self.plate_mass_kg, PLATE_MASS_KG, "kg")?;
        for (k, ax) in ["x", "y"].iter().enumerate() {
            in_range(&format!("plate edge {ax}"), self.plate_size_m[k], PLATE_EDGE_M, "m")?;
        }
        in_range("plate thickness", self.plate_size_m[2], PLATE_THICKNESS_M, "m")?;
        let vol = |s: [f64; 3]| s[0] * s[1] * s[2];
        let rho = self.plate_mass_kg / vol(self.plate_size_m);
        in_range("plate density (mass / volume)", rho, DENSITY_KG_M3, "kg/m³")?;
        in_range("workpiece mass", self.workpiece_mass_kg, WORKPIECE_MASS_KG, "kg")?;
        if self.workpiece_mass_kg > 0.0 {
            for (k, ax) in ["x", "y", "z"].iter().enumerate() {
                in_range(&format!("workpiece edge {ax}"), self.workpiece_size_m[k], WORKPIECE_EDGE_M, "m")?;
            }
            let rho = self.workpiece_mass_kg / vol(self.workpiece_size_m);
            in_range("workpiece density (mass / volume)", rho, DENSITY_KG_M3, "kg/m³")?;
            for (k, ax) in ["x", "y"].iter().enumerate() {
                let half = self.plate_size_m[k] / 2.0;
                in_range(&format!("workpiece centre {ax} (on the plate)"), self.workpiece_xy_m[k], (-half, half), "m")?;
            }
        }
        for (k, ax) in ["a (x)", "b (y)"].iter().enumerate() {
            let v = self.sensor_half_spacing_m[k];
            in_range(&format!("sensor half spacing {ax}"), v, SENSOR_HALF_SPACING_M, "m")?;
            let half = self.plate_size_m[k] / 2.0;
            if v > half {
                bail!(
                    "plate dynamometer: sensor half spacing {ax} = {v} m puts the sensors outside the plate \
                     (half edge {half} m)"
                );
            }
        }
        for (k, ax) in ["x", "y", "z"].iter().enumerate() {
            let (ks, kt) = (self.sensor_stiffness_n_per_m[k], self.table_stiffness_n_per_m[k]);
            in_range(&format!("sensor stiffness {ax}"), ks, SENSOR_STIFFNESS_N_PER_M, "N/m")?;
            in_range(&format!("table stiffness {ax}"), kt, TABLE_STIFFNESS_N_PER_M, "N/m")?;
            in_range(&format!("base edge {ax}"), self.base_size_m[k], BASE_EDGE_M, "m")?;
        }
        in_range("base mass", self.base_mass_kg, BASE_MASS_KG, "kg")?;
        if self.zeta.len() != DOF {
            bail!("plate dynamometer: {} damping ratios given, one per mode is needed ({DOF})", self.zeta.len());
        }
        for (r, &z) in self.zeta.iter().enumerate() {
            in_range(&format!("damping ratio of mode {}", r + 1), z, ZETA, "")?;
        }
        for i in 0..3 {
            for j in 0..3 {
                let e = self.crosstalk[i][j];
                if i == j && e != 0.0 {
                    bail!(
                        "plate dynamometer: static crosstalk E[{i}][{j}] = {e} must be 0 (a gain error is calibration)"
                    );
                }
                in_range(&format!("static crosstalk E[{i}][{j}]"), e, (-CROSSTALK, CROSSTALK), "")?;
            }
        }
        check_point("force point", self.force_point_m)
    }

    /// The top plate and workpiece as one rigid body.
    pub fn top(&self) -> RigidBody {
        let [_, _, t] = self.plate_size_m;
        let plate = RigidBody::cuboid(self.plate_mass_kg, self.plate_size_m, [0.0, 0.0, t / 2.0]);
        if self.workpiece_mass_kg > 0.0 {
            let [x, y] = self.workpiece_xy_m;
            let w = self.workpiece_size_m;
            plate.join(&RigidBody::cuboid(self.workpiece_mass_kg, w, [x, y, t + w[2] / 2.0]))
        } else {
            plate
        }
    }

    /// The base (housing and effective table mass).
    pub fn base(&self) -> RigidBody {
        RigidBody::cuboid(self.base_mass_kg, self.base_size_m, [0.0, 0.0, -self.base_size_m[2] / 2.0])
    }

    /// Positions of the four sensors (m).
    pub fn sensors(&self) -> [[f64; 3]; 4] {
        let [a, b] = self.sensor_half_spacing_m;
        [[a, b, 0.0], [-a, b, 0.0], [-a, -b, 0.0], [a, -b, 0.0]]
    }

    /// Positions of the four table mounts: the base's bottom corners (m).
    pub fn mounts(&self) -> [[f64; 3]; 4] {
        let [x, y, z] = self.base_size_m;
        [[x / 2.0, y / 2.0, -z], [-x / 2.0, y / 2.0, -z], [-x / 2.0, -y / 2.0, -z], [x / 2.0, -y / 2.0, -z]]
    }

    /// Height of the workpiece's top face (or the plate's) above the sensor plane (m).
    pub fn top_height_m(&self) -> f64 {
        self.plate_size_m[2] + if self.workpiece_mass_kg > 0.0 { self.workpiece_size_m[2] } else { 0.0 }
    }

    /// M, K, B(point), Cd and S for a force at `point_m`.
    pub fn matrices(&self, point_m: [f64; 3]) -> PlateMatrices {
        let (top, base) = (self.top(), self.base());
        let mut m = DMatrix::zeros(DOF, DOF);
        m.view_mut((0, 0), (6, 6)).copy_from(&top.mass_matrix());
        m.view_mut((6, 6), (6, 6)).copy_from(&base.mass_matrix());
        let mut k = DMatrix::zeros(DOF, DOF);
        let mut cd = DMatrix::zeros(3, DOF);
        let ks = Matrix3::from_diagonal(&Vector3::from(self.sensor_stiffness_n_per_m));
        for s in self.sensors() {
            // δ = u_p(s) − u_b(s) = L q.
            let mut l = DMatrix::zeros(3, DOF);
            l.view_mut((0, 0), (3, 6)).copy_from(&top.point(s));
            l.view_mut((0, 6), (3, 6)).copy_from(&(-base.point(s)));
            let ksl = DMatrix::from_fn(3, 3, |i, j| ks[(i, j)]) * &l;
            k += l.transpose() * &ksl;
            cd += ksl;
        }
        let kt = Matrix3::from_diagonal(&Vector3::from(self.table_stiffness_n_per_m));
        for t in self.mounts() {
            let lt: SMatrix<f64, 3, 6> = base.point(t);
            let kb = lt.transpose() * kt * lt;
            let mut view = k.view_mut((6, 6), (6, 6));
            view += kb;
        }
        let mut b = DMatrix::zeros(DOF, 3);
        b.view_mut((0, 0), (6, 3)).copy_from(&top.point(point_m).transpose());
        let s = Matrix3::identity() + Matrix3::from_fn(|i, j| self.crosstalk[i][j]);
        PlateMatrices { m, k, b, cd, s }
    }
}
