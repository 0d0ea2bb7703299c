//! Rigid bodies in small motion: mass, centre of mass, inertia, and the
//! kinematics of a point on the body.
//!
//! Coordinates (m): origin at the centre of the sensor plane (the centroid of
//! the four sensors), z up. A body's motion is q = [u; θ], the translation u
//! (m) of its centre of mass c and a small rotation θ (rad) about it; a
//! material point at r moves by u + θ × (r − c) = T(r − c)·q with
//! T(d) = [I₃, −[d]×] (3x6). A force F (N) at r does the generalized force
//! T(r − c)ᵀF = [F; (r − c) × F] on the body.

use nalgebra::{Matrix3, SMatrix, Vector3};
use serde::{Deserialize, Serialize};

/// Mass properties of a rigid body.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct RigidBody {
    /// Mass (kg).
    pub mass_kg: f64,
    /// Centre of mass (m).
    pub com_m: [f64; 3],
    /// Inertia tensor about the centre of mass (kg·m²), symmetric.
    pub inertia_kg_m2: [[f64; 3]; 3],
}

impl RigidBody {
    /// A uniform solid cuboid of `mass_kg`, edges `size_m` along x, y, z,
    /// centred at `centre_m`: I = m/12·diag(ly² + lz², lx² + lz², lx² + ly²).
    pub fn cuboid(mass_kg: f64, size_m: [f64; 3], centre_m: [f64; 3]) -> Self {
        let [lx, ly, lz] = size_m;
        let k = mass_kg / 12.0;
        Self {
            mass_kg,
            com_m: centre_m,
            inertia_kg_m2: [
                [k * (ly * ly + lz * lz), 0.0, 0.0],
                [0.0, k * (lx * lx + lz * lz), 0.0],
                [0.0, 0.0, k * (lx * lx + ly * ly)],
            ],
        }
    }

    /// Two bodies joined rigidly: masses add, the centre of mass is the
    /// mass-weighted mean, and each inertia moves to it by the parallel-axis
    /// theorem, I + m(|d|²I₃ − d dᵀ), d = cₖ − c.
    pub fn join(&self, other: &Self) -> Self {
        let m = self.mass_kg + other.mass_kg;
        let c = (self.com() * self.mass_kg + other.com() * other.mass_kg) / m;
        let moved = |b: &Self| {
            let d = b.com() - c;
            b.inertia() + (Matrix3::identity() * d.norm_squared() - d * d.transpose()) * b.mass_kg
        };
        let i = moved(self) + moved(other);
        Self { mass_kg: m, com_m: [c.x, c.y, c.z], inertia_kg_m2: to_rows(&i) }
    }

    /// Centre of mass as a vector (m).
    pub fn com(&self) -> Vector3<f64> {
        Vector3::from(self.com_m)
    }

    /// Inertia tensor about the centre of mass (kg·m²).
    pub fn inertia(&self) -> Matrix3<f64> {
        Matrix3::from_fn(|i, j| self.inertia_kg_m2[i][j])
    }

    /// The 6x6 mass matrix in q = [u; θ]: diag(m·I₃, I).
    pub fn mass_matrix(&self) -> SMatrix<f64, 6, 6> {
        let mut m = SMatrix::<f64, 6, 6>::zeros();
        for k in 0..3 {
            m[(k, k)] = self.mass_kg;
        }
        m.fixed_view_mut::<3, 3>(3, 3).copy_from(&self.inertia());
        m
    }

    /// T(r − c): displacement of the material point at `r_m` per unit q.
    pub fn point(&self, r_m: [f64; 3]) -> SMatrix<f64, 3, 6> {
        point_map(&(Vector3::from(r_m) - self.com()))
    }
}

/// T(d) = [I₃, −[d]×]: u + θ × d = u − d × θ.
pub fn point_map(d: &Vector3<f64>) -> SMatrix<f64, 3, 6> {
    let mut t = SMatrix::<f64, 3, 6>::zeros();
    t.fixed_view_mut::<3, 3>(0, 0).copy_from(&Matrix3::identity());
    t.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-d.cross_matrix()));
    t
}

fn to_rows(m: &Matrix3<f64>) -> [[f64; 3]; 3] {
    [[m[(0, 0)], m[(0, 1)], m[(0, 2)]], [m[(1, 0)], m[(1, 1)], m[(1, 2)]], [m[(2, 0)], m[(2, 1)], m[(2, 2)]]]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn joining_two_cubes_side_by_side_is_the_long_cuboid() {
        // Two 1 kg cubes of 0.1 m side at x = ±0.05: one 2 kg cuboid 0.2 x 0.1 x 0.1.
        let a = RigidBody::cuboid(1.0, [0.1; 3], [-0.05, 0.0, 0.0]);
        let b = RigidBody::cuboid(1.0, [0.1; 3], [0.05, 0.0, 0.0]);
        let j = a.join(&b);
        let want = RigidBody::cuboid(2.0, [0.2, 0.1, 0.1], [0.0; 3]);
        assert!((j.mass_kg - 2.0).abs() < 1e-15);
        for r in 0..3 {
            for c in 0..3 {
                assert!((j.inertia_kg_m2[r][c] - want.inertia_kg_m2[r][c]).abs() < 1e-15, "{j:?}");
            }
        }
        // Negative control: a 1 mm shift of one cube changes Iyy.
        let off = RigidBody::cuboid(1.0, [0.1; 3], [0.051, 0.0, 0.0]);
        assert!((a.join(&off).inertia_kg_m2[1][1] - want.inertia_kg_m2[1][1]).abs() > 1e-5);
    }

    #[test]
    fn a_point_above_the_centre_moves_with_the_rotation() {
        let body = RigidBody::cuboid(1.0, [0.1; 3], [0.0, 0.0, 0.0]);
        // Rotation θy = 0.01 rad: the point 0.1 m above moves by +0.001 m in x.
        let q = SMatrix::<f64, 6, 1>::from_column_slice(&[0.0, 0.0, 0.0, 0.0, 0.01, 0.0]);
        let u = body.point([0.0, 0.0, 0.1]) * q;
        assert!((u[0] - 0.001).abs() < 1e-15 && u[1].abs() < 1e-15 && u[2].abs() < 1e-15, "{u}");
    }
}
