//! Pictures of a cloud with its fitted surface, rendered headless with the project's own
//! wgpu context (works on lavapipe): three orthographic views side by side — along the
//! hole axis, from the side, and oblique — into a PNG. A scene is drawn the same way
//! about its table's normal, each object's points and surface in a colour of its own.
//!
//! The host does the shading (Lambert on the mesh's normals, points coloured by their
//! distance to the fit: `geometry`), so the shader (`shaders/render.wgsl`) only
//! transforms (`gpu`).

mod geometry;
mod gpu;

use crate::eval::{AdapterChoice, GpuContext};
use crate::model::{Pose, Shape};
use glam::DVec3;

/// What to draw.
pub struct Scene<'a> {
    pub points: &'a [DVec3],
    pub fit: Option<(Shape, Pose)>,
    /// a whole scene instead: every object's fitted surface, the points coloured by the
    /// object they belong to (`owners[i]`, an index into `objects`), the views about the
    /// table's normal `up` (from above, from the side, oblique)
    pub objects: Option<SceneObjects<'a>>,
}

pub struct SceneObjects<'a> {
    pub fits: &'a [(Shape, Pose)],
    pub owners: &'a [usize],
    pub up: DVec3,
}

/// Distinct colours for the objects of a scene, in turn.
const OBJECT_COLOURS: [[f32; 3]; 8] = [
    [0.90, 0.30, 0.25],
    [0.25, 0.60, 0.90],
    [0.35, 0.75, 0.35],
    [0.95, 0.70, 0.20],
    [0.65, 0.40, 0.85],
    [0.20, 0.80, 0.80],
    [0.90, 0.45, 0.70],
    [0.60, 0.60, 0.60],
];

/// Renders three `view_size`-pixel square views side by side and returns the PNG bytes
/// (width 3·view_size, height view_size).
pub fn render_png(scene: &Scene, view_size: u32) -> Result<Vec<u8>, String> {
    if !(16..=4096).contains(&view_size) {
        return Err("view size must be in 16..=4096 pixels".into());
    }
    if scene.points.is_empty() && scene.fit.is_none() && scene.objects.is_none() {
        return Err("nothing to draw".into());
    }
    let ctx = GpuContext::shared(&AdapterChoice::from_env()).map_err(|e| e.to_string())?;
    let frame = geometry::view_frame(scene);
    let rgba = gpu::render_rgba(&ctx, &geometry::geometry(scene, &frame), &frame, view_size)?;
    let (width, height) = (3 * view_size, view_size);
    let rgb: Vec<u8> = rgba
        .chunks_exact(4)
        .flat_map(|p| [p[0], p[1], p[2]])
        .collect();
    crate::io::encode_rgb_png(width, height, &rgb)
}
