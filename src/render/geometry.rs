//! What the views show, built on the host: the frame the views are taken in, the fitted
//! surfaces as shaded triangle meshes, and the points in their colours, all relative to
//! the views' centre in f32.

use super::{OBJECT_COLOURS, Scene};
use crate::io::mesh::tessellate;
use crate::io::ply::colormap;
use crate::model::{Pose, Shape, meridian_distance};
use glam::{DMat3, DVec3};

/// One vertex as the shader takes it: a mesh corner or a point's centre.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(super) struct Vertex {
    pub position: [f32; 3],
    pub color: [f32; 3],
}

/// The frame the views are taken in: its axes (the fit's, hole axis up; the table's
/// normal up for a scene; else the world's), its centre, and the radius of a sphere about
/// the centre that holds everything drawn.
pub(super) struct ViewFrame {
    pub axes: DMat3,
    pub centre: DVec3,
    pub radius: f64,
}

/// The shaded surfaces (triangles of `mesh`, by `indices`) and the coloured points.
pub(super) struct Geometry {
    pub mesh: Vec<Vertex>,
    pub indices: Vec<u32>,
    pub points: Vec<Vertex>,
}

/// The frame of `scene`'s views.
pub(super) fn view_frame(scene: &Scene) -> ViewFrame {
    let mut lo = DVec3::INFINITY;
    let mut hi = DVec3::NEG_INFINITY;
    for p in scene.points {
        lo = lo.min(*p);
        hi = hi.max(*p);
    }
    let (axes, centre) = match (&scene.fit, &scene.objects) {
        (_, Some(objects)) => {
            for (shape, pose) in objects.fits {
                let e = shape.half_extents().max_element();
                lo = lo.min(pose.translation - DVec3::splat(e));
                hi = hi.max(pose.translation + DVec3::splat(e));
            }
            let z = objects.up.normalize();
            let (x, y) = z.any_orthonormal_pair();
            (DMat3::from_cols(x, y, z), 0.5 * (lo + hi))
        }
        (Some((shape, pose)), None) => {
            let e = shape.half_extents();
            for corner in [-1.0, 1.0] {
                lo = lo.min(pose.translation + DVec3::splat(corner * e.max_element()));
                hi = hi.max(pose.translation + DVec3::splat(corner * e.max_element()));
            }
            (pose.matrix(), pose.translation)
        }
        (None, None) => (DMat3::IDENTITY, 0.5 * (lo + hi)),
    };
    let radius = scene
        .points
        .iter()
        .map(|p| (*p - centre).length())
        .fold(0.5 * (hi - lo).length(), f64::max)
        .max(1e-9);
    ViewFrame {
        axes,
        centre,
        radius,
    }
}

/// The meshes and points of `scene` in `frame`: each surface Lambert-shaded under a light
/// fixed in the frame; a single fit's points coloured by their distance to it (blue on
/// the surface, red at 5% of its size), a scene's by their object, a bare cloud's orange.
pub(super) fn geometry(scene: &Scene, frame: &ViewFrame) -> Geometry {
    let local = |p: DVec3| (p - frame.centre).as_vec3().to_array();
    let light = (frame.axes * DVec3::new(0.4, -0.5, 0.8)).normalize();
    let mut mesh = Vec::new();
    let mut indices = Vec::new();
    let mut add_mesh = |shape: &Shape, pose: &Pose, tint: [f32; 3]| {
        let surface = tessellate(shape, pose, 64, 128);
        let first = mesh.len() as u32;
        mesh.extend(surface.vertices.iter().zip(&surface.normals).map(|(v, n)| {
            let shade = (0.35 + 0.65 * n.dot(light).abs()) as f32;
            Vertex {
                position: local(*v),
                color: tint.map(|c| c * shade),
            }
        }));
        indices.extend(surface.triangles.iter().flatten().map(|i| first + i));
    };
    let mut point_colors = vec![[1.0f32, 0.55, 0.1]; scene.points.len()];
    if let Some(objects) = &scene.objects {
        for (k, (shape, pose)) in objects.fits.iter().enumerate() {
            // the surface a paler shade of its points' colour
            let tint = OBJECT_COLOURS[k % OBJECT_COLOURS.len()].map(|c| 0.5 + 0.4 * c);
            add_mesh(shape, pose, tint);
        }
        for (c, &owner) in point_colors.iter_mut().zip(objects.owners) {
            *c = OBJECT_COLOURS[owner % OBJECT_COLOURS.len()];
        }
    } else if let Some((shape, pose)) = &scene.fit {
        add_mesh(shape, pose, [0.55, 0.65, 0.8]);
        let scale = 0.05 * shape.size();
        for (c, p) in point_colors.iter_mut().zip(scene.points) {
            let d = meridian_distance(shape, pose.to_canonical(*p)).distance;
            *c = colormap((d / scale).min(1.0)).map(|v| v as f32 / 255.0);
        }
    }
    let points = scene
        .points
        .iter()
        .zip(&point_colors)
        .map(|(p, c)| Vertex {
            position: local(*p),
            color: *c,
        })
        .collect();
    Geometry {
        mesh,
        indices,
        points,
    }
}
