//! Analytic obstacles: an infinite plane (a half-space) and an infinite cylinder, with exact
//! signed distances and normals.
//!
//! A floor, a table or a wall meant to be infinite is better an analytic half-space than a
//! triangle patch: its distance is one dot product, it has no edges to fall off, no tree to
//! build or walk, and a point behind it is found at any depth. A round post or a straight tube
//! is exact as an analytic cylinder, where a mesh of `k` flat facets lies up to
//! `r (1 − cos(π/k))` inside the round surface and gives every facet edge a ridge.
//!
//! Every shape has a *free side*, the side the rods stay on, and its distance is signed
//! positive there: the half-space's free side is where its normal points; a cylinder's is its
//! inside ([`Side::Lumen`], a tube the rods stay in) or its outside ([`Side::Solid`], a post
//! the rods stay out of). The normal returned with a distance is the unit direction that moves
//! the point towards (and farther into) the free side, as the mesh's feature normals do.
//!
//! A shape can be moved rigidly ([`Shape::moved`]): rotated about its anchor point and
//! translated, which is how a kinematic obstacle follows its path.

use nalgebra::{Rotation3, Vector3};

/// Which side of a closed surface the rods stay on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    /// Inside: the surface is a lumen (a tube, a vessel) the rods stay in.
    Lumen,
    /// Outside: the surface bounds a solid (a post, a bone) the rods stay out of.
    Solid,
}

/// An analytic obstacle (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Shape {
    /// The half-space behind the plane through `point` with unit `normal`; the rods stay on
    /// the side the normal points to.
    HalfSpace {
        /// A point of the plane [m].
        point: [f64; 3],
        /// Unit normal, pointing to the free side.
        normal: [f64; 3],
    },
    /// The infinite cylinder of `radius` about the axis through `point` along the unit `axis`.
    Cylinder {
        /// A point of the axis [m].
        point: [f64; 3],
        /// Unit direction of the axis.
        axis: [f64; 3],
        /// Radius [m].
        radius: f64,
        /// Whether the rods stay inside (a lumen) or outside (a solid).
        side: Side,
    },
}

/// A signed distance from a shape (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShapeDistance {
    /// Distance from the surface, positive on the free side [m].
    pub signed_distance: f64,
    /// Unit normal of the surface at its nearest point, towards the free side.
    pub normal: [f64; 3],
}

/// `v` normalised, or an error naming what it is when it has no direction.
fn unit(v: [f64; 3], what: &str) -> Result<[f64; 3], String> {
    let n = Vector3::from(v);
    if !v.iter().all(|c| c.is_finite()) {
        return Err(format!("{what} {v:?} is not finite"));
    }
    let len = n.norm();
    if !(len > 1e-12) {
        return Err(format!("{what} {v:?} has no direction (zero length)"));
    }
    Ok((n / len).into())
}

fn finite_point(p: [f64; 3], what: &str) -> Result<[f64; 3], String> {
    if p.iter().all(|c| c.is_finite()) {
        Ok(p)
    } else {
        Err(format!("{what} {p:?} is not finite"))
    }
}

impl Shape {
    /// The half-space behind the plane through `point` facing `normal` (any length). Errors,
    /// as text naming the value, for a zero or non-finite normal or a non-finite point.
    pub fn half_space(point: [f64; 3], normal: [f64; 3]) -> Result<Self, String> {
        Ok(Shape::HalfSpace {
            point: finite_point(point, "point")?,
            normal: unit(normal, "normal")?,
        })
    }

    /// The infinite cylinder of `radius` about the axis through `point` along `axis` (any
    /// length). Errors, as text naming the value, for a radius that is not a positive number, a
    /// zero or non-finite axis or a non-finite point.
    pub fn cylinder(
        point: [f64; 3],
        axis: [f64; 3],
        radius: f64,
        side: Side,
    ) -> Result<Self, String> {
        if !(radius > 0.0 && radius.is_finite()) {
            return Err(format!("radius {radius} is not a number > 0"));
        }
        Ok(Shape::Cylinder {
            point: finite_point(point, "point")?,
            axis: unit(axis, "axis")?,
            radius,
            side,
        })
    }

    /// The point the shape turns about when it is moved ([`Shape::moved`]): the plane's or the
    /// axis's point.
    pub fn anchor(&self) -> [f64; 3] {
        match *self {
            Shape::HalfSpace { point, .. } | Shape::Cylinder { point, .. } => point,
        }
    }

    /// Whether the free side is bounded (a tube the rods stay in).
    pub fn is_lumen(&self) -> bool {
        matches!(
            self,
            Shape::Cylinder {
                side: Side::Lumen,
                ..
            }
        )
    }

    /// The shape turned by `rotation` about its anchor, then moved by `displacement`.
    #[must_use]
    pub fn moved(&self, displacement: [f64; 3], rotation: &Rotation3<f64>) -> Self {
        let d = Vector3::from(displacement);
        match *self {
            Shape::HalfSpace { point, normal } => Shape::HalfSpace {
                point: (Vector3::from(point) + d).into(),
                normal: (rotation * Vector3::from(normal)).into(),
            },
            Shape::Cylinder {
                point,
                axis,
                radius,
                side,
            } => Shape::Cylinder {
                point: (Vector3::from(point) + d).into(),
                axis: (rotation * Vector3::from(axis)).into(),
                radius,
                side,
            },
        }
    }

    /// The signed distance of `p` from the surface and the normal there (see the module docs).
    /// On a cylinder's axis, where every direction across it is nearest, the normal is one of
    /// them.
    #[inline]
    pub fn distance(&self, p: &[f64; 3]) -> ShapeDistance {
        match *self {
            Shape::HalfSpace { point, normal } => ShapeDistance {
                signed_distance: (0..3).map(|k| (p[k] - point[k]) * normal[k]).sum(),
                normal,
            },
            Shape::Cylinder {
                point,
                axis,
                radius,
                side,
            } => {
                let a = Vector3::from(axis);
                let rel = Vector3::from(*p) - Vector3::from(point);
                let across = rel - a * a.dot(&rel);
                let r = across.norm();
                let out = if r > 0.0 {
                    across / r
                } else {
                    // Any direction across the axis.
                    let helper = if a.x.abs() < 0.9 {
                        Vector3::x()
                    } else {
                        Vector3::y()
                    };
                    helper.cross(&a).normalize()
                };
                let (signed_distance, normal) = match side {
                    Side::Solid => (r - radius, out),
                    Side::Lumen => (radius - r, -out),
                };
                ShapeDistance {
                    signed_distance,
                    normal: normal.into(),
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn half_space_distance_is_signed_along_its_unit_normal() {
        let s = Shape::half_space([0.0, 0.0, 1.0], [0.0, 0.0, 2.0]).unwrap();
        let d = s.distance(&[3.0, -4.0, 1.5]);
        assert!((d.signed_distance - 0.5).abs() < 1e-15);
        assert_eq!(d.normal, [0.0, 0.0, 1.0]);
        assert!((s.distance(&[0.0, 0.0, -2.0]).signed_distance + 3.0).abs() < 1e-15);
    }

    #[test]
    fn cylinder_distance_matches_the_radial_distance_on_either_side() {
        let axis = [1.0, 1.0, 0.0];
        let solid = Shape::cylinder([0.0; 3], axis, 0.5, Side::Solid).unwrap();
        let lumen = Shape::cylinder([0.0; 3], axis, 0.5, Side::Lumen).unwrap();
        // 2 along the axis and 0.8 across it, along z.
        let s2 = std::f64::consts::SQRT_2;
        let p = [s2, s2, 0.8];
        let a = solid.distance(&p);
        assert!((a.signed_distance - 0.3).abs() < 1e-12);
        assert!((a.normal[2] - 1.0).abs() < 1e-12);
        let b = lumen.distance(&p);
        assert!((b.signed_distance + 0.3).abs() < 1e-12);
        assert!((b.normal[2] + 1.0).abs() < 1e-12);
        // On the axis: a normal across it, and the radius as the distance.
        let c = solid.distance(&[0.0; 3]);
        assert!((c.signed_distance + 0.5).abs() < 1e-15);
        let n = Vector3::from(c.normal);
        assert!(
            (n.norm() - 1.0).abs() < 1e-12 && n.dot(&Vector3::new(1.0, 1.0, 0.0)).abs() < 1e-12
        );
    }

    #[test]
    fn a_moved_shape_measures_what_the_unmoved_one_measures_at_the_moved_point() {
        let shapes = [
            Shape::half_space([0.1, 0.2, 0.3], [0.2, -0.3, 1.0]).unwrap(),
            Shape::cylinder([0.1, 0.2, 0.3], [0.0, 1.0, 0.2], 0.4, Side::Solid).unwrap(),
        ];
        let rot = Rotation3::from_scaled_axis(Vector3::new(0.3, -0.2, 0.5));
        let d = [0.5, -0.1, 0.7];
        for s in shapes {
            let m = s.moved(d, &rot);
            let p = Vector3::new(0.4, -0.6, 0.9);
            let c = Vector3::from(s.anchor());
            let q = c + Vector3::from(d) + rot * (p - c);
            let (a, b) = (s.distance(&p.into()), m.distance(&q.into()));
            assert!((a.signed_distance - b.signed_distance).abs() < 1e-12);
            let turned = rot * Vector3::from(a.normal);
            assert!((turned - Vector3::from(b.normal)).norm() < 1e-12);
        }
    }

    #[test]
    fn bad_shapes_are_refused_with_their_value() {
        let e = Shape::half_space([0.0; 3], [0.0; 3]).unwrap_err();
        assert!(e.contains("normal [0.0, 0.0, 0.0]"), "{e}");
        let e = Shape::cylinder([0.0; 3], [0.0, 0.0, 1.0], -1.0, Side::Solid).unwrap_err();
        assert!(e.contains("radius -1"), "{e}");
        let e = Shape::cylinder([0.0; 3], [f64::NAN, 0.0, 1.0], 1.0, Side::Lumen).unwrap_err();
        assert!(e.contains("axis"), "{e}");
    }
}
