//! The MJCF document: one free body per object (visual mesh without contacts, the
//! collision pieces with them, inertia from the solid), the table as a plane.

use super::{ObjectEntry, SceneExport, object_name};
use glam::{DQuat, DVec3};
use std::fmt::Write;

fn v3(v: DVec3) -> String {
    format!("{:.9} {:.9} {:.9}", v.x, v.y, v.z)
}

fn quat(q: DQuat) -> String {
    format!("{:.9} {:.9} {:.9} {:.9}", q.w, q.x, q.y, q.z)
}

pub fn document(scene: &SceneExport, entries: &[ObjectEntry]) -> String {
    let mut x = String::new();
    let _ = writeln!(x, "<mujoco model=\"supertoroid_scene\">");
    let _ = writeln!(x, "  <compiler angle=\"radian\" meshdir=\".\"/>");
    let _ = writeln!(
        x,
        "  <option gravity=\"{}\" timestep=\"0.002\"/>",
        v3(scene.gravity())
    );
    let _ = writeln!(x, "  <asset>");
    for (i, entry) in entries.iter().enumerate() {
        let n = entry.pieces;
        let name = object_name(i);
        let _ = writeln!(
            x,
            "    <mesh name=\"{name}_visual\" file=\"{name}_visual.obj\"/>"
        );
        for k in 0..n {
            let _ = writeln!(
                x,
                "    <mesh name=\"{name}_piece_{k:02}\" file=\"{name}_piece_{k:02}.stl\"/>"
            );
        }
    }
    let _ = writeln!(x, "  </asset>");
    let _ = writeln!(x, "  <worldbody>");
    if let Some(plane) = &scene.plane {
        let point = scene.table_point(plane);
        let q = DQuat::from_rotation_arc(DVec3::Z, plane.normal());
        let _ = writeln!(
            x,
            "    <geom name=\"table\" type=\"plane\" size=\"1 1 0.01\" pos=\"{}\" quat=\"{}\"/>",
            v3(point),
            quat(q)
        );
    }
    for (i, (object, entry)) in scene.objects.iter().zip(entries).enumerate() {
        let n = entry.pieces;
        let name = object_name(i);
        let m = entry.inertia;
        let _ = writeln!(
            x,
            "    <body name=\"{name}\" pos=\"{}\" quat=\"{}\">",
            v3(object.pose.translation),
            quat(object.pose.rotation)
        );
        let _ = writeln!(x, "      <freejoint name=\"{name}_free\"/>");
        let _ = writeln!(
            x,
            "      <inertial pos=\"{}\" mass=\"{:.9}\" fullinertia=\"{:.9e} {:.9e} {:.9e} {:.9e} {:.9e} {:.9e}\"/>",
            v3(entry.com),
            entry.mass,
            m.x_axis.x,
            m.y_axis.y,
            m.z_axis.z,
            m.y_axis.x,
            m.z_axis.x,
            m.z_axis.y
        );
        let _ = writeln!(
            x,
            "      <geom name=\"{name}_visual\" type=\"mesh\" mesh=\"{name}_visual\" contype=\"0\" conaffinity=\"0\" group=\"1\"/>"
        );
        for k in 0..n {
            let _ = writeln!(
                x,
                "      <geom name=\"{name}_piece_{k:02}\" type=\"mesh\" mesh=\"{name}_piece_{k:02}\" group=\"3\"/>"
            );
        }
        let _ = writeln!(x, "    </body>");
    }
    let _ = writeln!(x, "  </worldbody>");
    let _ = writeln!(x, "</mujoco>");
    x
}
