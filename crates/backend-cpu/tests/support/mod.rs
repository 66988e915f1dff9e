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
    MeshContactSettings::mesh(
        collider,
        Friction {
            static_coefficient: mu_s,
            kinetic_coefficient: mu_k,
        },
        1e-4,
    )
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

/// A roof: a ridge along y at x = z = 0 with faces falling away at 45° on either side to
/// z = −1, normals upwards.
pub fn roof() -> Arc<MeshCollider> {
    let v = vec![
        [0.0, -1.0, 0.0],
        [0.0, 1.0, 0.0],
        [1.0, -1.0, -1.0],
        [1.0, 1.0, -1.0],
        [-1.0, -1.0, -1.0],
        [-1.0, 1.0, -1.0],
    ];
    let (mesh, _) =
        TriMesh::new(v, vec![[0, 2, 3], [0, 3, 1], [0, 1, 5], [0, 5, 4]], "roof").unwrap();
    let collider = MeshCollider::new(mesh);
    assert!(collider.mesh().face_normal(0)[2] > 0.0 && collider.mesh().face_normal(2)[2] > 0.0);
    Arc::new(collider)
}

/// Two elements of 0.1 m along x (points at x = −0.15, −0.05, 0.05), radius `r`, `gap` above
/// the ridge of [`roof`]: the ridge lies under the middle of the second element, where neither
/// of its points' spheres reaches (each is 3.5 cm from its face).
pub fn rod_over_a_ridge(material: Material, gap: f64) -> CpuRod<f64> {
    let r = material.radius;
    let spec = RodSpec::new(material);
    let pts: Vec<[f64; 3]> = (0..3)
        .map(|i| [-0.15 + 0.1 * i as f64, 0.0, r + gap])
        .collect();
    let (state, params) = build_rod::<f64>(&pts, &spec).unwrap();
    CpuRod::new(
        state,
        params,
        [EndCondition::free(), EndCondition::free()],
        vec![],
    )
}

/// How far the rod of [`rod_over_a_ridge`] reaches into the roof, less its radius (positive:
/// into it): its elements' distances from the ridge and its points' from the faces, in the
/// xz-plane (the roof does not change along y).
pub fn into_the_roof(rod: &CpuRod<f64>) -> f64 {
    let r = rod.params.radius;
    let p = &rod.state.positions;
    let mut deepest = f64::NEG_INFINITY;
    for w in p.windows(2) {
        let (a, b) = (
            Vec3::new(w[0].x, 0.0, w[0].z),
            Vec3::new(w[1].x, 0.0, w[1].z),
        );
        let d = b - a;
        let s = (-a.dot(&d) / d.norm_squared()).clamp(0.0, 1.0);
        deepest = deepest.max(r - (a + d * s).norm());
    }
    for q in p {
        // The face under the point: z = −|x|, normal (±1, 0, 1)/√2.
        let above = (q.z + q.x.abs()) / 2.0_f64.sqrt();
        deepest = deepest.max(r - above);
    }
    deepest
}
