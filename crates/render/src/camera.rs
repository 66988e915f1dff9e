//! Cameras that frame a scene by themselves.
//!
//! A run's rods move through a vessel that may be anywhere and of any size, so nobody should
//! have to look up coordinates to see it. A [`Camera`] is built from the [`Bounds`] of
//! everything drawn (every frame's rods and the mesh, so that the camera stays still while the
//! video plays), a [`View`] direction and a [`Projection`], and fits the box into the picture
//! with a small margin. For views given by angles, world "up" is `+z` (the scenes' gravity
//! points along `-z`), except when looking along `z`, where it is `+y`; the automatic view
//! turns the scene so that its longest extent runs across the (wide) picture.
//!
//! The matrices follow wgpu's clip space (depth from 0 to 1) and are handed to WGSL column by
//! column.

use crate::RenderError;

/// An axis-aligned box; [`Bounds::EMPTY`] grows with [`Bounds::include`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bounds {
    /// Smallest coordinates.
    pub min: [f64; 3],
    /// Largest coordinates.
    pub max: [f64; 3],
}

impl Bounds {
    /// A box holding nothing: including a point makes it that point.
    pub const EMPTY: Self = Self {
        min: [f64::INFINITY; 3],
        max: [f64::NEG_INFINITY; 3],
    };

    /// Grows the box to hold `p` (non-finite points are ignored).
    pub fn include(&mut self, p: [f64; 3]) {
        if p.iter().all(|x| x.is_finite()) {
            for k in 0..3 {
                self.min[k] = self.min[k].min(p[k]);
                self.max[k] = self.max[k].max(p[k]);
            }
        }
    }

    /// Grows the box to hold `p` and a ball of radius `r` around it.
    pub fn include_ball(&mut self, p: [f64; 3], r: f64) {
        self.include([p[0] - r, p[1] - r, p[2] - r]);
        self.include([p[0] + r, p[1] + r, p[2] + r]);
    }

    /// Whether nothing was included.
    pub fn is_empty(&self) -> bool {
        self.min[0] > self.max[0]
    }

    fn centre(&self) -> [f64; 3] {
        std::array::from_fn(|k| 0.5 * (self.min[k] + self.max[k]))
    }

    fn corners(&self) -> [[f64; 3]; 8] {
        std::array::from_fn(|i| {
            [
                if i & 1 == 0 { self.min[0] } else { self.max[0] },
                if i & 2 == 0 { self.min[1] } else { self.max[1] },
                if i & 4 == 0 { self.min[2] } else { self.max[2] },
            ]
        })
    }
}

/// How the picture is projected.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Projection {
    /// Parallel rays: sizes do not shrink with distance, so lengths can be compared across
    /// the picture (the default).
    Orthographic,
    /// A pinhole camera with this vertical field of view in degrees.
    Perspective {
        /// Vertical field of view [degrees], between 1 and 150.
        fov_y_degrees: f64,
    },
}

impl Projection {
    /// The perspective projection with the field of view used when none is given (35°).
    pub const PERSPECTIVE: Self = Self::Perspective {
        fov_y_degrees: 35.0,
    };

    /// Parses `ortho`/`orthographic` or `perspective`/`persp`.
    pub fn parse(text: &str) -> Result<Self, RenderError> {
        match text {
            "ortho" | "orthographic" => Ok(Self::Orthographic),
            "perspective" | "persp" => Ok(Self::PERSPECTIVE),
            other => Err(RenderError::Option {
                option: "camera",
                value: other.to_string(),
                expected: "ortho or perspective",
            }),
        }
    }
}

/// Where the camera looks from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum View {
    /// Along the box's thinnest axis, so the scene's two largest extents fill the picture (a
    /// vessel tree that spreads in a plane is seen face on), with the longest across.
    Auto,
    /// From a direction given as azimuth (degrees about `+z`, 0 looking along `+y` from the
    /// `-y` side) and elevation (degrees above the horizontal plane, 90 looking down).
    Angles {
        /// Degrees about `+z`.
        azimuth: f64,
        /// Degrees above the `xy` plane.
        elevation: f64,
    },
}

impl View {
    /// Parses `auto`, `front` (from `-y`), `back`, `left` (from `-x`), `right`, `top` (from
    /// `+z`), `bottom`, `iso` (azimuth 35°, elevation 30°), or `AZIMUTH,ELEVATION` in degrees.
    pub fn parse(text: &str) -> Result<Self, RenderError> {
        let angles = |azimuth, elevation| Ok(Self::Angles { azimuth, elevation });
        match text {
            "auto" => Ok(Self::Auto),
            "front" => angles(0.0, 0.0),
            "back" => angles(180.0, 0.0),
            "left" => angles(-90.0, 0.0),
            "right" => angles(90.0, 0.0),
            "top" => angles(0.0, 90.0),
            "bottom" => angles(0.0, -90.0),
            "iso" => angles(35.0, 30.0),
            other => {
                let bad = || RenderError::Option {
                    option: "view",
                    value: other.to_string(),
                    expected: "auto, front, back, left, right, top, bottom, iso or AZIMUTH,ELEVATION in degrees",
                };
                let (a, e) = other.split_once(',').ok_or_else(bad)?;
                let a: f64 = a.trim().parse().map_err(|_| bad())?;
                let e: f64 = e.trim().parse().map_err(|_| bad())?;
                if !(a.is_finite() && e.is_finite() && e.abs() <= 90.0) {
                    return Err(bad());
                }
                angles(a, e)
            }
        }
    }

    /// Unit vector from the scene towards the camera, and the direction that is up in the
    /// picture (before it is made perpendicular to the first).
    fn axes(self, bounds: &Bounds) -> ([f64; 3], [f64; 3]) {
        match self {
            Self::Auto => {
                let ext: [f64; 3] = std::array::from_fn(|k| bounds.max[k] - bounds.min[k]);
                // Look along the thinnest axis; the longest of the other two runs across the
                // picture (which is wider than tall), the third up. Ties keep the order z, y, x
                // for the view and x, y, z across.
                let mut order = [2usize, 1, 0];
                order.sort_by(|&a, &b| ext[a].total_cmp(&ext[b]));
                let (thin, up, across) = (order[0], order[1], order[2]);
                let (mut back, mut upward) = ([0.0; 3], [0.0; 3]);
                upward[up] = 1.0;
                // The sign that makes `across` point right: right = up × back.
                back[thin] = if (up + 1) % 3 == thin && (thin + 1) % 3 == across {
                    1.0
                } else {
                    -1.0
                };
                (back, upward)
            }
            Self::Angles { azimuth, elevation } => {
                let (a, e) = (azimuth.to_radians(), elevation.to_radians());
                let back = [-a.sin() * e.cos(), -a.cos() * e.cos(), e.sin()];
                let up = if back[2].abs() > 0.999 {
                    [0.0, 1.0, 0.0]
                } else {
                    [0.0, 0.0, 1.0]
                };
                (back, up)
            }
        }
    }
}

/// A camera fixed on a scene: the matrix from world to clip space and where it looks from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// World → clip space, column-major (as WGSL's `mat4x4<f32>` reads it).
    pub view_projection: [[f32; 4]; 4],
    /// Unit vector from the scene towards the camera (the headlight comes from there).
    pub towards_camera: [f32; 3],
    /// The eye, for a perspective camera (lighting and sizes follow it); `None` when
    /// orthographic.
    pub eye: Option<[f32; 3]>,
    /// World length of one pixel at the centre of the scene (the thinnest tube drawn is a
    /// few of them wide).
    pub pixel_size: f64,
}

/// Margin around the framed box, as a fraction of its projected size on each side.
const MARGIN: f64 = 0.04;

impl Camera {
    /// Frames `bounds` in a `width × height` picture, looking from `view` with `projection`.
    ///
    /// # Errors
    /// [`RenderError::Option`] for an empty box or a field of view outside 1–150°.
    pub fn framing(
        bounds: &Bounds,
        view: View,
        projection: Projection,
        width: u32,
        height: u32,
    ) -> Result<Self, RenderError> {
        if bounds.is_empty() {
            return Err(RenderError::Option {
                option: "camera",
                value: "an empty scene".into(),
                expected: "something to frame (a rod or a mesh)",
            });
        }
        let (back, up_hint) = view.axes(bounds);
        let right = normalize(cross(up_hint, back));
        let up = cross(back, right);
        let centre = bounds.centre();
        // Extents of the box in the camera's axes, around the centre.
        let (mut half_w, mut half_h, mut half_d) = (0.0f64, 0.0f64, 0.0f64);
        for c in bounds.corners() {
            let r = sub(c, centre);
            half_w = half_w.max(dot(r, right).abs());
            half_h = half_h.max(dot(r, up).abs());
            half_d = half_d.max(dot(r, back).abs());
        }
        let size = half_w.max(half_h).max(half_d).max(1e-9);
        let (half_w, half_h) = ((half_w + MARGIN * size), (half_h + MARGIN * size));
        let aspect = f64::from(width) / f64::from(height.max(1));
        // Widen whichever side is short of the picture's aspect ratio.
        let (half_w, half_h) = if half_w / half_h > aspect {
            (half_w, half_w / aspect)
        } else {
            (half_h * aspect, half_h)
        };
        match projection {
            Projection::Orthographic => {
                let distance = 2.0 * half_d + size;
                let eye = add(centre, scale(back, distance));
                let view = look(eye, right, up, back);
                let (near, far) = (
                    distance - half_d - 0.01 * size,
                    distance + half_d + 0.01 * size,
                );
                let proj = [
                    [1.0 / half_w, 0.0, 0.0, 0.0],
                    [0.0, 1.0 / half_h, 0.0, 0.0],
                    [0.0, 0.0, -1.0 / (far - near), 0.0],
                    [0.0, 0.0, -near / (far - near), 1.0],
                ];
                Ok(Self {
                    view_projection: to_f32(mul(&proj, &view)),
                    towards_camera: back.map(|x| x as f32),
                    eye: None,
                    pixel_size: 2.0 * half_h / f64::from(height.max(1)),
                })
            }
            Projection::Perspective { fov_y_degrees } => {
                if !(1.0..=150.0).contains(&fov_y_degrees) {
                    return Err(RenderError::Option {
                        option: "fov",
                        value: fov_y_degrees.to_string(),
                        expected: "a vertical field of view between 1 and 150 degrees",
                    });
                }
                let tan = (0.5 * fov_y_degrees.to_radians()).tan();
                // Far enough that the box's nearest face fits the field of view.
                let distance = half_h / tan + half_d;
                let eye = add(centre, scale(back, distance));
                let view = look(eye, right, up, back);
                let near = (distance - 1.5 * half_d).max(1e-3 * distance);
                let far = distance + 1.5 * half_d + 0.01 * size;
                let f = 1.0 / tan;
                let proj = [
                    [f / aspect, 0.0, 0.0, 0.0],
                    [0.0, f, 0.0, 0.0],
                    [0.0, 0.0, far / (near - far), -1.0],
                    [0.0, 0.0, near * far / (near - far), 0.0],
                ];
                Ok(Self {
                    view_projection: to_f32(mul(&proj, &view)),
                    towards_camera: back.map(|x| x as f32),
                    eye: Some(eye.map(|x| x as f32)),
                    pixel_size: 2.0 * distance * tan / f64::from(height.max(1)),
                })
            }
        }
    }
}

impl Camera {
    /// The same camera with the picture magnified `factor` times about its centre (a wheel's
    /// zoom): clip-space `x` and `y` are scaled, depth is not, so nothing framed is clipped
    /// away in depth.
    #[must_use]
    pub fn zoomed(mut self, factor: f64) -> Self {
        let f = factor as f32;
        for column in &mut self.view_projection {
            column[0] *= f;
            column[1] *= f;
        }
        self.pixel_size /= factor;
        self
    }
}

impl View {
    /// The angles of a view whose unit vector from the scene towards the camera is `back`
    /// (the inverse of the direction [`View::Angles`] looks from), for orbiting from a
    /// camera's [`Camera::towards_camera`].
    pub fn looking_from(back: [f32; 3]) -> Self {
        let [x, y, z] = back.map(f64::from);
        Self::Angles {
            azimuth: (-x).atan2(-y).to_degrees(),
            elevation: z.clamp(-1.0, 1.0).asin().to_degrees(),
        }
    }
}

type Mat4 = [[f64; 4]; 4];

/// World → camera space for an eye with axes `right`, `up` and `back` (column-major).
fn look(eye: [f64; 3], right: [f64; 3], up: [f64; 3], back: [f64; 3]) -> Mat4 {
    [
        [right[0], up[0], back[0], 0.0],
        [right[1], up[1], back[1], 0.0],
        [right[2], up[2], back[2], 0.0],
        [-dot(right, eye), -dot(up, eye), -dot(back, eye), 1.0],
    ]
}

/// `a · b` for column-major matrices.
fn mul(a: &Mat4, b: &Mat4) -> Mat4 {
    std::array::from_fn(|col| {
        std::array::from_fn(|row| (0..4).map(|k| a[k][row] * b[col][k]).sum())
    })
}

fn to_f32(m: Mat4) -> [[f32; 4]; 4] {
    m.map(|c| c.map(|x| x as f32))
}

pub(crate) fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn add(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
fn scale(a: [f64; 3], s: f64) -> [f64; 3] {
    a.map(|x| x * s)
}
pub(crate) fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
pub(crate) fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
pub(crate) fn normalize(a: [f64; 3]) -> [f64; 3] {
    let n = dot(a, a).sqrt();
    if n > 0.0 { scale(a, 1.0 / n) } else { a }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn clip(m: &[[f32; 4]; 4], p: [f64; 3]) -> [f64; 3] {
        let v = [p[0], p[1], p[2], 1.0];
        let c: [f64; 4] = std::array::from_fn(|r| (0..4).map(|k| f64::from(m[k][r]) * v[k]).sum());
        [c[0] / c[3], c[1] / c[3], c[2] / c[3]]
    }

    fn unit_box() -> Bounds {
        let mut b = Bounds::EMPTY;
        b.include([1.0, 2.0, 3.0]);
        b.include([3.0, 3.0, 3.5]);
        b
    }

    /// Every corner of the framed box lands inside the picture and the depth range, and the
    /// box touches the picture's edge (up to the margin) on at least one axis.
    #[test]
    fn both_projections_fit_the_box_into_the_picture() {
        let b = unit_box();
        for projection in [Projection::Orthographic, Projection::PERSPECTIVE] {
            for view in ["auto", "front", "top", "iso", "20,-40"] {
                let cam =
                    Camera::framing(&b, View::parse(view).unwrap(), projection, 160, 90).unwrap();
                let mut reach = 0.0f64;
                for c in b.corners() {
                    let p = clip(&cam.view_projection, c);
                    assert!(
                        p[0].abs() <= 1.0 && p[1].abs() <= 1.0,
                        "{view} {projection:?} {p:?}"
                    );
                    assert!(
                        (0.0..=1.0).contains(&p[2]),
                        "{view} {projection:?} depth {p:?}"
                    );
                    reach = reach.max(p[0].abs()).max(p[1].abs());
                }
                assert!(
                    reach > 0.8,
                    "{view} {projection:?}: the box fills only {reach}"
                );
            }
        }
    }

    /// Zooming keeps the centre and depth, and scales the rest of the picture.
    #[test]
    fn zoom_magnifies_about_the_centre() {
        let b = unit_box();
        let cam = Camera::framing(&b, View::Auto, Projection::Orthographic, 160, 90).unwrap();
        let zoomed = cam.zoomed(2.0);
        let corner = clip(&cam.view_projection, b.min);
        let near = clip(&zoomed.view_projection, b.min);
        assert!(
            (near[0] - 2.0 * corner[0]).abs() < 1e-5 && (near[1] - 2.0 * corner[1]).abs() < 1e-5
        );
        assert!((near[2] - corner[2]).abs() < 1e-6);
        assert!((zoomed.pixel_size - cam.pixel_size / 2.0).abs() < 1e-12);
    }

    /// The angles read back from a camera give the camera's direction again.
    #[test]
    fn orbiting_starts_from_where_the_camera_is() {
        let b = unit_box();
        for view in ["iso", "20,-40", "front"] {
            let cam = Camera::framing(
                &b,
                View::parse(view).unwrap(),
                Projection::Orthographic,
                16,
                9,
            )
            .unwrap();
            let again = Camera::framing(
                &b,
                View::looking_from(cam.towards_camera),
                Projection::Orthographic,
                16,
                9,
            )
            .unwrap();
            for k in 0..3 {
                assert!(
                    (cam.towards_camera[k] - again.towards_camera[k]).abs() < 1e-5,
                    "{view}"
                );
            }
        }
    }

    #[test]
    fn auto_looks_along_the_thinnest_axis() {
        let cam =
            Camera::framing(&unit_box(), View::Auto, Projection::Orthographic, 10, 10).unwrap();
        assert_eq!(cam.towards_camera, [0.0, 0.0, 1.0]);
    }

    #[test]
    fn bad_options_name_themselves() {
        let e = View::parse("sideways").unwrap_err().to_string();
        assert!(e.contains("view") && e.contains("sideways"), "{e}");
        assert!(View::parse("10,95").is_err());
        let e = Projection::parse("fisheye").unwrap_err().to_string();
        assert!(e.contains("fisheye"), "{e}");
        assert!(
            Camera::framing(&Bounds::EMPTY, View::Auto, Projection::Orthographic, 8, 8).is_err()
        );
    }
}
