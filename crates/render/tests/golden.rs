//! Pictures on a real adapter (lavapipe in CI): a small scene against a stored reference, what
//! each colour means, and the same bytes twice.
//!
//! The reference `tests/golden/tiny_scene.png` is compared pixel by pixel: a pixel differs when
//! any channel is off by more than [`CHANNEL_TOLERANCE`], and at most [`DIFFERING_FRACTION`] of
//! the pixels may differ (rasterisers of different adapters disagree on edge pixels). A missing
//! reference fails the test. After a deliberate change of the pictures, write a new reference
//! with `COSSERAT_BLESS_GOLDEN=1 cargo test -p cosserat-render --test golden`, look at it, and
//! commit it.
//!
//! Without an adapter these tests pass without checking anything, unless
//! `COSSERAT_REQUIRE_GPU=1` (as in CI), which makes a missing adapter a failure.

use std::path::{Path, PathBuf};

use cosserat_render::{
    Bounds, Camera, Image, Projection, RenderError, RenderSettings, Renderer, RodPose, SurfaceMesh,
    View, include_rod, read_png, write_png,
};

const CHANNEL_TOLERANCE: u8 = 24;
const DIFFERING_FRACTION: f64 = 0.01;
const WIDTH: u32 = 96;
const HEIGHT: u32 = 64;

/// A renderer, or `None` (test skipped) when there is no adapter and none is required.
fn renderer(settings: RenderSettings) -> Option<Renderer> {
    match Renderer::new(settings) {
        Ok(r) => Some(r),
        Err(RenderError::NoAdapter(why)) => {
            assert!(
                std::env::var("COSSERAT_REQUIRE_GPU").as_deref() != Ok("1"),
                "COSSERAT_REQUIRE_GPU=1 but there is no adapter: {why}"
            );
            eprintln!("skipped: no adapter ({why})");
            None
        }
        Err(e) => panic!("{e}"),
    }
}

/// A quarter circle of radius 1 in the `xy` plane, 24 elements, pressed at its middle point.
fn arc() -> (Vec<[f64; 3]>, Vec<[f64; 3]>, Vec<f64>) {
    let n = 24;
    let points: Vec<[f64; 3]> = (0..=n)
        .map(|i| {
            let a = std::f64::consts::FRAC_PI_2 * i as f64 / n as f64;
            [a.cos(), a.sin(), 0.0]
        })
        .collect();
    let d1 = vec![[0.0, 0.0, 1.0]; n];
    let mut force = vec![0.0; n + 1];
    force[n / 2] = 1.0;
    force[n / 2 + 1] = 0.3;
    (points, d1, force)
}

/// Two triangles behind the arc (normals towards `+z`, the camera's side) and one facing away,
/// which is culled.
fn wall() -> SurfaceMesh {
    SurfaceMesh {
        vertices: vec![
            [-0.1, -0.1, -0.3],
            [1.2, -0.1, -0.3],
            [1.2, 1.2, -0.3],
            [-0.1, 1.2, -0.3],
            [0.5, 0.5, 0.2],
            [0.6, 0.5, 0.2],
            [0.5, 0.6, 0.2],
        ],
        triangles: vec![[0, 1, 2], [0, 2, 3], [4, 6, 5]],
    }
}

fn tiny_scene(renderer: &mut Renderer) -> (Image, Camera) {
    let (points, d1, force) = arc();
    let rod = RodPose {
        points: &points,
        d1: &d1,
        radius: 0.06,
        contact_force: Some(&force),
    };
    let mesh = wall();
    let mut bounds = Bounds::EMPTY;
    include_rod(&mut bounds, &rod);
    mesh.include_in(&mut bounds);
    let camera = Camera::framing(&bounds, View::Auto, Projection::Orthographic, WIDTH, HEIGHT)
        .expect("camera");
    renderer.set_mesh(Some(&mesh));
    (renderer.render(&camera, &[rod]).expect("render"), camera)
}

fn settings() -> RenderSettings {
    RenderSettings {
        width: WIDTH,
        height: HEIGHT,
        force_scale: 1.0,
        samples: Some(4),
        ..Default::default()
    }
}

fn reference() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/golden/tiny_scene.png")
}

#[test]
fn the_tiny_scene_matches_its_reference() {
    let Some(mut r) = renderer(settings()) else {
        return;
    };
    let (image, _) = tiny_scene(&mut r);
    let path = reference();
    if std::env::var("COSSERAT_BLESS_GOLDEN").as_deref() == Ok("1") {
        write_png(&path, &image).expect("write the reference");
        eprintln!("wrote {} on {}", path.display(), r.adapter());
        return;
    }
    let expected = read_png(&path).unwrap_or_else(|e| {
        panic!("no reference picture ({e}); write one with COSSERAT_BLESS_GOLDEN=1 (module docs)")
    });
    assert_eq!((expected.width, expected.height), (WIDTH, HEIGHT));
    let differing = image
        .rgba
        .chunks(4)
        .zip(expected.rgba.chunks(4))
        .filter(|(a, b)| {
            a.iter()
                .zip(*b)
                .any(|(x, y)| x.abs_diff(*y) > CHANNEL_TOLERANCE)
        })
        .count();
    let fraction = differing as f64 / f64::from(WIDTH * HEIGHT);
    if fraction > DIFFERING_FRACTION {
        let got = std::env::temp_dir().join("cosserat-render-tiny_scene.png");
        write_png(&got, &image).ok();
        panic!(
            "{differing} pixels ({:.2} %) differ from {} by more than {CHANNEL_TOLERANCE} on {}; this run's picture is {}",
            100.0 * fraction,
            path.display(),
            r.adapter(),
            got.display()
        );
    }
}

/// Reads the pixel where `p` projects.
fn pixel_at(image: &Image, camera: &Camera, p: [f64; 3]) -> [u8; 3] {
    let m = camera.view_projection;
    let v = [p[0], p[1], p[2], 1.0];
    let c: [f64; 4] = std::array::from_fn(|r| (0..4).map(|k| f64::from(m[k][r]) * v[k]).sum());
    let (x, y) = (c[0] / c[3], c[1] / c[3]);
    let px = ((x + 1.0) * 0.5 * f64::from(image.width)) as usize;
    let py = ((1.0 - y) * 0.5 * f64::from(image.height)) as usize;
    let o = 4 * (py * image.width as usize + px);
    [image.rgba[o], image.rgba[o + 1], image.rgba[o + 2]]
}

/// The rod is blue, its pressed point red, the wall behind it pink over the background, the
/// background light grey: checked where those things project, on any adapter.
#[test]
fn colours_mean_what_the_docs_say() {
    let Some(mut r) = renderer(settings()) else {
        return;
    };
    let (image, camera) = tiny_scene(&mut r);
    let (points, ..) = arc();
    let [r0, g0, b0] = pixel_at(&image, &camera, points[3]);
    assert!(
        b0 > r0 + 60 && b0 > g0 + 40,
        "rod not blue: {:?}",
        [r0, g0, b0]
    );
    let [r1, g1, b1] = pixel_at(&image, &camera, points[12]);
    assert!(
        r1 > 150 && r1 > g1 + 100 && r1 > b1 + 100,
        "pressed point not red: {:?}",
        [r1, g1, b1]
    );
    let [r2, g2, b2] = pixel_at(&image, &camera, [0.2, 0.2, -0.3]);
    assert!(
        r2 > g2 + 12 && r2 > b2 + 12,
        "wall not pink: {:?}",
        [r2, g2, b2]
    );
    let corner = &image.rgba[..3];
    assert!(corner.iter().all(|&c| c > 235), "background {corner:?}");
}

#[test]
fn the_same_input_gives_the_same_bytes() {
    let Some(mut r) = renderer(settings()) else {
        return;
    };
    let (a, _) = tiny_scene(&mut r);
    let (b, _) = tiny_scene(&mut r);
    assert!(a == b, "two renders of one scene differ");
}
