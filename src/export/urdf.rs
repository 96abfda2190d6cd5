//! The URDF document: a `world` link, the table as a thin box, each object a link fixed
//! to `world` at its pose with its visual mesh, its collision pieces and its inertia.

use super::{ObjectEntry, SceneExport, object_name};
use glam::{DQuat, DVec3, EulerRot};
use std::fmt::Write;

/// Thickness of the table's box below its plane.
const TABLE_THICKNESS: f64 = 0.02;

/// URDF's origin: xyz, and rpy with R = Rz(yaw)·Ry(pitch)·Rx(roll).
fn origin(t: DVec3, q: DQuat) -> String {
    let (yaw, pitch, roll) = q.to_euler(EulerRot::ZYX);
    format!(
        "<origin xyz=\"{:.9} {:.9} {:.9}\" rpy=\"{roll:.9} {pitch:.9} {yaw:.9}\"/>",
        t.x, t.y, t.z
    )
}

pub fn document(scene: &SceneExport, entries: &[ObjectEntry]) -> String {
    let mut x = String::new();
    let _ = writeln!(x, "<?xml version=\"1.0\"?>");
    let _ = writeln!(x, "<robot name=\"supertoroid_scene\">");
    let _ = writeln!(x, "  <link name=\"world\"/>");
    if let Some(plane) = &scene.plane {
        let n = plane.normal();
        let point = scene.table_point(plane) - n * (TABLE_THICKNESS / 2.0);
        let q = DQuat::from_rotation_arc(DVec3::Z, n);
        let geometry = format!("<geometry><box size=\"2 2 {TABLE_THICKNESS}\"/></geometry>");
        let _ = writeln!(x, "  <link name=\"table\">");
        let _ = writeln!(x, "    <visual>{geometry}</visual>");
        let _ = writeln!(x, "    <collision>{geometry}</collision>");
        let _ = writeln!(x, "  </link>");
        let _ = writeln!(x, "  <joint name=\"table_joint\" type=\"fixed\">");
        let _ = writeln!(x, "    <parent link=\"world\"/><child link=\"table\"/>");
        let _ = writeln!(x, "    {}", origin(point, q));
        let _ = writeln!(x, "  </joint>");
    }
    for (i, (object, entry)) in scene.objects.iter().zip(entries).enumerate() {
        let n = entry.pieces;
        let name = object_name(i);
        let m = entry.inertia;
        let _ = writeln!(x, "  <link name=\"{name}\">");
        let _ = writeln!(x, "    <inertial>");
        let _ = writeln!(x, "      {}", origin(entry.com, DQuat::IDENTITY));
        let _ = writeln!(x, "      <mass value=\"{:.9}\"/>", entry.mass);
        let _ = writeln!(
            x,
            "      <inertia ixx=\"{:.9e}\" ixy=\"{:.9e}\" ixz=\"{:.9e}\" iyy=\"{:.9e}\" iyz=\"{:.9e}\" izz=\"{:.9e}\"/>",
            m.x_axis.x, m.y_axis.x, m.z_axis.x, m.y_axis.y, m.z_axis.y, m.z_axis.z
        );
        let _ = writeln!(x, "    </inertial>");
        let _ = writeln!(
            x,
            "    <visual><geometry><mesh filename=\"{name}_visual.obj\"/></geometry></visual>"
        );
        for k in 0..n {
            let _ = writeln!(
                x,
                "    <collision><geometry><mesh filename=\"{name}_piece_{k:02}.stl\"/></geometry></collision>"
            );
        }
        let _ = writeln!(x, "  </link>");
        let _ = writeln!(x, "  <joint name=\"{name}_joint\" type=\"fixed\">");
        let _ = writeln!(x, "    <parent link=\"world\"/><child link=\"{name}\"/>");
        let _ = writeln!(
            x,
            "    {}",
            origin(object.pose.translation, object.pose.rotation)
        );
        let _ = writeln!(x, "  </joint>");
    }
    let _ = writeln!(x, "</robot>");
    x
}
