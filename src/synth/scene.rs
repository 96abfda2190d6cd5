//! Table-top scenes with known objects: supertoroids and superellipsoids of table-top
//! sizes resting on the table z = 0 (world), set apart on it, seen by one camera from
//! above and in front (so some hide parts of others), rendered into one depth frame with
//! a label per pixel, and a D435-like sensor model for the frame.

use super::{Camera, DepthImage, Intrinsics, SeededRng, render_view, with_table};
use crate::model::{Plane, Pose, Shape};
use glam::{DQuat, DVec3};
use rand::Rng;
use rand_distr::{Distribution, Normal};

/// A scene's truth: the objects, the camera and the table.
#[derive(Clone, Debug)]
pub struct TableScene {
    pub objects: Vec<(Shape, Pose)>,
    pub camera: Camera,
    pub table: Plane,
}

/// A rendered scene: the depth frame and, per pixel, what it shows.
#[derive(Clone, Debug)]
pub struct RenderedScene {
    pub depth: DepthImage,
    /// per pixel: [`NOTHING`], [`TABLE`], or the object's index plus [`FIRST_OBJECT`]
    pub labels: Vec<u16>,
}

pub const NOTHING: u16 = 0;
pub const TABLE: u16 = 1;
pub const FIRST_OBJECT: u16 = 2;

/// Objects' footprints on the table stay at least this far apart (metres): touching
/// objects are one cluster to a segmentation by distance.
pub const FOOTPRINT_GAP: f64 = 0.03;

/// A random object of table-top size resting on the table: with a hole (a tape, a
/// bearing, a ring lying flat or standing on its rim) or without (a box, a can, a
/// bottle, a pebble), at `(x, y)` on the table, turned about the vertical.
pub fn random_object(rng: &mut SeededRng, holed: bool, x: f64, y: f64) -> (Shape, Pose) {
    let yaw = DQuat::from_rotation_z(rng.random_range(0.0..std::f64::consts::TAU));
    if holed {
        let shape = Shape::new(
            rng.random_range(0.012..0.03),
            rng.random_range(0.012..0.03),
            rng.random_range(0.008..0.03),
            rng.random_range(1.3..3.0),
            rng.random_range(0.3..1.5),
            rng.random_range(0.5..1.5),
        );
        if rng.random_bool(0.5) {
            // lying flat: the hole axis up, its bottom face on the table
            (shape, Pose::new(yaw, DVec3::new(x, y, shape.a3)))
        } else {
            // standing on its rim: the hole axis level
            let up = DQuat::from_rotation_x(std::f64::consts::FRAC_PI_2);
            let height = shape.a2 * (1.0 + shape.a4);
            (shape, Pose::new(yaw * up, DVec3::new(x, y, height)))
        }
    } else {
        let shape = Shape::new(
            rng.random_range(0.02..0.06),
            rng.random_range(0.02..0.06),
            rng.random_range(0.02..0.08),
            0.0,
            rng.random_range(0.1..1.5),
            rng.random_range(0.1..1.9),
        );
        (shape, Pose::new(yaw, DVec3::new(x, y, shape.a3)))
    }
}

/// A scene of `count` objects, about half of them with a hole, placed at random on a
/// 0.6 x 0.4 m patch of table with their footprints [`FOOTPRINT_GAP`] apart, and a
/// camera 0.5-0.7 m from the patch's centre looking down on it at 35-55 degrees.
pub fn random_table_scene(seed: u64, count: usize) -> TableScene {
    let mut rng = super::rng(seed);
    let mut objects: Vec<(Shape, Pose)> = Vec::new();
    let mut tries = 0;
    while objects.len() < count && tries < 1000 {
        tries += 1;
        let holed = objects.len() % 2 == 0;
        let (x, y) = (rng.random_range(-0.3..0.3), rng.random_range(-0.2..0.2));
        let object = random_object(&mut rng, holed, x, y);
        let reach = footprint(&object.0, &object.1);
        let clear = objects.iter().all(|(s, p)| {
            let d = (p.translation - object.1.translation).truncate().length();
            d > reach + footprint(s, p) + FOOTPRINT_GAP
        });
        if clear {
            objects.push(object);
        }
    }
    let distance = rng.random_range(0.5..0.7);
    let elevation = rng.random_range(35f64..55.0).to_radians();
    let azimuth = rng.random_range(-0.4..0.4) - std::f64::consts::FRAC_PI_2;
    let eye = DVec3::new(
        distance * elevation.cos() * azimuth.cos(),
        distance * elevation.cos() * azimuth.sin(),
        distance * elevation.sin(),
    );
    TableScene {
        objects,
        camera: Camera::look_at(Intrinsics::REALSENSE_640X480, eye, DVec3::ZERO, DVec3::Z),
        table: Plane::through(DVec3::ZERO, DVec3::Z),
    }
}

/// The radius of a circle on the table that holds the object's footprint.
fn footprint(shape: &Shape, pose: &Pose) -> f64 {
    let h = shape.half_extents();
    // the box's corners projected on the table, from its centre
    [-1.0, 1.0]
        .into_iter()
        .flat_map(|x| [-1.0, 1.0].into_iter().map(move |y| (x, y)))
        .flat_map(|(x, y)| {
            [-1.0, 1.0]
                .into_iter()
                .map(move |z| DVec3::new(x, y, z) * h)
        })
        .map(|c| (pose.rotation * c).truncate().length())
        .fold(0.0, f64::max)
}

/// The scene's depth frame (metres per unit `depth_scale`) and its labels: the nearest
/// surface at each pixel, objects and table.
pub fn render_scene(scene: &TableScene, depth_scale: f64) -> Result<RenderedScene, String> {
    let k = scene.camera.intrinsics;
    let n = (k.width * k.height) as usize;
    let mut depth = DepthImage {
        width: k.width,
        height: k.height,
        scale: depth_scale,
        data: vec![0; n],
    };
    let mut labels = vec![NOTHING; n];
    for (i, (shape, pose)) in scene.objects.iter().enumerate() {
        let view = render_view(shape, pose, &scene.camera, depth_scale)?;
        for [u, v] in view.pixels {
            let at = (v * k.width + u) as usize;
            let raw = view.depth.data[at];
            if depth.data[at] == 0 || raw < depth.data[at] {
                depth.data[at] = raw;
                labels[at] = FIRST_OBJECT + i as u16;
            }
        }
    }
    let with = with_table(&depth, &scene.camera, &scene.table);
    for at in 0..n {
        if with.data[at] != depth.data[at] {
            labels[at] = TABLE;
        }
    }
    Ok(RenderedScene {
        depth: with,
        labels,
    })
}

/// A D435-like sensor over a rendered frame: depth noise along the ray with a sigma of
/// `sigma_at_half_metre` at 0.5 m growing with the range squared, the frame's own
/// quantisation (its depth scale), and flying pixels: where a pixel's neighbour lies
/// more than 2 cm deeper, with probability `flying_share` it takes a depth between the
/// two.
pub fn with_sensor_noise(
    depth: &DepthImage,
    sigma_at_half_metre: f64,
    flying_share: f64,
    seed: u64,
) -> DepthImage {
    let mut rng = super::rng(seed);
    let unit = Normal::new(0.0, 1.0).expect("unit normal");
    let (w, h) = (depth.width as usize, depth.height as usize);
    let mut out = depth.clone();
    for v in 0..h {
        for u in 0..w {
            let at = v * w + u;
            let raw = depth.data[at];
            if raw == 0 {
                continue;
            }
            let z = raw as f64 * depth.scale;
            let mut noisy = z + sigma_at_half_metre * (z / 0.5).powi(2) * unit.sample(&mut rng);
            let deeper = [(1i64, 0i64), (-1, 0), (0, 1), (0, -1)]
                .into_iter()
                .filter_map(|(du, dv)| {
                    let (x, y) = (u as i64 + du, v as i64 + dv);
                    (x >= 0 && y >= 0 && (x as usize) < w && (y as usize) < h)
                        .then(|| depth.data[y as usize * w + x as usize])
                })
                .map(|r| r as f64 * depth.scale)
                .fold(z, f64::max);
            if deeper > z + 0.02 && rng.random_bool(flying_share) {
                noisy = z + rng.random_range(0.0..1.0) * (deeper - z);
            }
            out.data[at] = (noisy / depth.scale).round().clamp(1.0, u16::MAX as f64) as u16;
        }
    }
    out
}
