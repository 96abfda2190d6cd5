//! Fitted objects out to simulators and planners: each object's surface as an OBJ mesh,
//! its collision geometry as STL pieces (convex by piece: a ring is cut into arcs, see
//! [`meshes::RING_PIECES`]), and the scene as MJCF (MuJoCo: free bodies on the table
//! plane under gravity) and URDF (planners' collision scenes: objects fixed to `world`).
//!
//! Everything is written in the fits' frame (the camera's for depth frames) or, given
//! `world_from_frame`, in a world frame. Gravity is along the table's normal where the
//! table is known, else along -z of the output frame.

pub mod meshes;
mod mjcf;
mod urdf;

use crate::model::{Plane, Pose, Shape};
use glam::{DMat3, DVec3};
use std::path::{Path, PathBuf};

/// Default density of the objects, kg/m³ (plastic and cardboard lie around 200-1200).
pub const DEFAULT_DENSITY: f64 = 500.0;

pub struct ExportObject {
    pub shape: Shape,
    /// canonical -> output frame
    pub pose: Pose,
}

pub struct SceneExport {
    pub objects: Vec<ExportObject>,
    pub plane: Option<Plane>,
    pub density: f64,
}

impl SceneExport {
    /// Objects and plane given in the fits' frame, moved into a world frame.
    pub fn new(
        objects: Vec<(Shape, Pose)>,
        plane: Option<Plane>,
        world_from_frame: Option<Pose>,
        density: f64,
    ) -> Result<Self, String> {
        if objects.is_empty() {
            return Err("nothing to export: no objects".into());
        }
        if !(density.is_finite() && density > 0.0) {
            return Err(format!("density must be positive, got {density}"));
        }
        let to_world = world_from_frame.unwrap_or(Pose::IDENTITY);
        let objects = objects
            .into_iter()
            .map(|(shape, pose)| ExportObject {
                shape,
                pose: to_world.compose(&pose),
            })
            .collect();
        let plane = plane
            .map(|p| {
                let p = p.validated()?;
                // a point of the plane and its normal, moved
                let n = p.normal();
                let point = -n * p.offset;
                Ok::<_, String>(Plane::through(
                    to_world.to_world(point),
                    to_world.rotation * n,
                ))
            })
            .transpose()?;
        Ok(Self {
            objects,
            plane,
            density,
        })
    }

    pub fn gravity(&self) -> DVec3 {
        match &self.plane {
            Some(p) => -9.81 * p.normal(),
            None => DVec3::new(0.0, 0.0, -9.81),
        }
    }

    /// The point of the table under the objects (their centroid's projection).
    fn table_point(&self, plane: &Plane) -> DVec3 {
        let centroid = self
            .objects
            .iter()
            .map(|o| o.pose.translation)
            .sum::<DVec3>()
            / self.objects.len() as f64;
        centroid - plane.normal() * plane.signed_distance(centroid)
    }
}

/// What the scene documents say of one object: its collision pieces and its inertial
/// properties in its body frame.
pub(crate) struct ObjectEntry {
    pub pieces: usize,
    pub mass: f64,
    pub com: DVec3,
    pub inertia: DMat3,
}

pub(crate) fn object_name(i: usize) -> String {
    format!("object_{i}")
}

/// One file of an export: its name (no directories) and its bytes.
pub struct ExportFile {
    pub name: String,
    pub bytes: Vec<u8>,
}

/// `scene.xml` (MJCF), `scene.urdf` and each object's meshes, in memory; the documents
/// name the meshes by these file names, beside them.
pub fn files(scene: &SceneExport) -> Vec<ExportFile> {
    let mut out = Vec::new();
    let mut file = |name: String, write: &dyn Fn(&mut Vec<u8>) -> std::io::Result<()>| {
        let mut bytes = Vec::new();
        write(&mut bytes).expect("writing into memory does not fail");
        out.push(ExportFile { name, bytes });
    };
    let mut entries = Vec::new();
    for (i, object) in scene.objects.iter().enumerate() {
        let name = object_name(i);
        let visual = meshes::visual(&object.shape);
        file(format!("{name}_visual.obj"), &|out| {
            meshes::write_obj(out, &visual)
        });
        let pieces = if object.shape.has_hole() {
            let arcs = meshes::ring_pieces(&object.shape);
            for (k, piece) in arcs.iter().enumerate() {
                file(format!("{name}_piece_{k:02}.stl"), &|out| {
                    meshes::write_stl_points(out, piece, meshes::PIECE_GRID.0)
                });
            }
            arcs.len()
        } else {
            // without a hole the surface is its own (near-)convex piece
            let triangles: Vec<[DVec3; 3]> = visual
                .triangles
                .iter()
                .map(|t| t.map(|v| visual.vertices[v as usize]))
                .collect();
            file(format!("{name}_piece_00.stl"), &|out| {
                meshes::write_stl(out, &triangles)
            });
            1
        };
        let (volume, com, inertia) = meshes::mass_properties(&visual);
        entries.push(ObjectEntry {
            pieces,
            mass: volume * scene.density,
            com,
            inertia: inertia * scene.density,
        });
    }
    let mjcf = mjcf::document(scene, &entries);
    file("scene.xml".into(), &|out| {
        out.extend_from_slice(mjcf.as_bytes());
        Ok(())
    });
    let urdf = urdf::document(scene, &entries);
    file("scene.urdf".into(), &|out| {
        out.extend_from_slice(urdf.as_bytes());
        Ok(())
    });
    out
}

/// Writes [`files`] into `dir`; returns the paths written.
pub fn write(scene: &SceneExport, dir: &Path) -> Result<Vec<PathBuf>, String> {
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    files(scene)
        .into_iter()
        .map(|f| {
            let path = dir.join(&f.name);
            std::fs::write(&path, &f.bytes).map_err(|e| format!("{}: {e}", path.display()))?;
            Ok(path)
        })
        .collect()
}

/// [`files`] as one ustar archive (`tar -x` unpacks a directory MuJoCo and URDF tools
/// load as it is).
pub fn tar_archive(scene: &SceneExport) -> Vec<u8> {
    let mut archive = tar::Builder::new(Vec::new());
    for f in files(scene) {
        let mut header = tar::Header::new_ustar();
        header.set_size(f.bytes.len() as u64);
        header.set_mode(0o644);
        archive
            .append_data(&mut header, &f.name, f.bytes.as_slice())
            .expect("appending to an archive in memory does not fail");
    }
    archive
        .into_inner()
        .expect("finishing an archive in memory does not fail")
}
