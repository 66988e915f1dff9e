//! Scenes shared by the contact tests of both schemes (`contact.rs`, `stiff_contact.rs`).

use cosserat_backend_cpu::{CpuRod, EndCondition, MeshContactSettings, PrescribedMotion};
use cosserat_collide::{MeshCollider, TriMesh};
use cosserat_constraints::Friction;
use cosserat_model::rod::{RodSpec, build_rod};
use cosserat_model::{Material, Vec3};
use std::sync::Arc;

/// A square of side `2 half` centred at `centre`, spanned by the unit vectors `u`, `v`, with its
/// normal `u × v` on the side the rod is.
pub fn square(centre: Vec3<f64>, u: Vec3<f64>, v: Vec3<f64>, half: f64) -> Arc<MeshCollider> {
    let corners = [
        centre - u * half - v * half,
        centre + u * half - v * half,
        centre + u * half + v * half,
        centre - u * half + v * half,
    ];
    let vertices: Vec<[f64; 3]> = corners.iter().map(|c| [c.x, c.y, c.z]).collect();
    let (mesh, _) = TriMesh::new(vertices, vec![[0, 1, 2], [0, 2, 3]], "square").unwrap();
    let collider = MeshCollider::new(mesh);
    // The normal of the first face must point to the rod's side.
    assert!((Vec3::from(collider.mesh().face_normal(0)) - u.cross(&v)).norm() < 1e-12);
    Arc::new(collider)
}

/// Contact with `collider`: Coulomb friction `mu_s`, `mu_k`, margin 0.1 mm.
pub fn contact(collider: Arc<MeshCollider>, mu_s: f64, mu_k: f64) -> MeshContactSettings {
    MeshContactSettings {
        collider,
        friction: Friction {
            static_coefficient: mu_s,
            kinetic_coefficient: mu_k,
        },
        margin: 1e-4,
    }
}

/// The soft test material (E 1 MPa, ρ 1100 kg/m³) of radius `r`.
pub fn soft(r: f64) -> Material {
    Material::new(1e6, 1e6 / 3.0, 1100.0, r)
}

/// A soft wire of radius `r` (40 elements over 0.19 m along x, bent by 1 mm in y so that the
/// buckling direction is defined), its base clamped and pushed at 0.2 m/s towards a wall at
/// x = 0.2 facing −x (friction 0.1).
pub fn wire_pushed_at_a_wall(r: f64) -> CpuRod<f64> {
    let wall = square(Vec3::new(0.2, 0.0, 0.0), Vec3::z(), Vec3::y(), 0.5);
    let push = PrescribedMotion::push(Vec3::new(0.2, 0.0, 0.0));
    let spec = RodSpec::new(soft(r));
    let pts: Vec<[f64; 3]> = (0..=40)
        .map(|i| {
            let s = i as f64 / 40.0;
            [0.19 * s, 1e-3 * (std::f64::consts::PI * s).sin(), 0.0]
        })
        .collect();
    let (state, params) = build_rod::<f64>(&pts, &spec).unwrap();
    CpuRod::new(
        state,
        params,
        [EndCondition::clamped().driven(push), EndCondition::free()],
        vec![],
    )
    .with_mesh(contact(wall, 0.1, 0.1))
}
