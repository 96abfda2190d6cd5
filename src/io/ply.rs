use glam::DVec3;
use std::io::Write;

/// Writes a binary little-endian PLY with float x, y, z vertices (what MeshLab, Open3D
/// and CloudCompare read).
pub fn write_ply_points(out: &mut impl Write, points: &[DVec3]) -> std::io::Result<()> {
    write!(
        out,
        "ply\nformat binary_little_endian 1.0\ncomment written by supertoroid\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nend_header\n",
        points.len()
    )?;
    for p in points {
        for c in [p.x, p.y, p.z] {
            out.write_all(&(c as f32).to_le_bytes())?;
        }
    }
    Ok(())
}
