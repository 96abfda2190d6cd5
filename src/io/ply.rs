//! PLY in (ascii, binary little and big endian; any numeric x/y/z type; extra properties
//! and elements ignored) through the `ply-rs-bw` crate, and PLY out: points, points
//! coloured by residual, and triangle meshes with normals, all binary little endian
//! (MeshLab, Open3D, CloudCompare and three.js read them).

use super::mesh::Mesh;
use super::{CloudError, ReadLimits, check_count};
use glam::DVec3;
use ply_rs_bw::parser::{Parser, Reader};
use ply_rs_bw::ply::{Property, PropertyAccess, PropertyAccessResult, PropertyType};
use std::io::Write;

const FORMAT: &str = "ply";

/// One vertex's coordinates; every other property is ignored.
struct Vertex([f64; 3]);

impl PropertyAccess for Vertex {
    fn new() -> Self {
        Vertex([f64::NAN; 3])
    }

    fn set_property(&mut self, key: &str, property: Property) -> PropertyAccessResult {
        let axis = match key {
            "x" => 0,
            "y" => 1,
            "z" => 2,
            _ => return PropertyAccessResult::Ignored,
        };
        let value = match property {
            Property::Float(v) => v as f64,
            Property::Double(v) => v,
            Property::Char(v) => v as f64,
            Property::UChar(v) => v as f64,
            Property::Short(v) => v as f64,
            Property::UShort(v) => v as f64,
            Property::Int(v) => v as f64,
            Property::UInt(v) => v as f64,
            _ => return PropertyAccessResult::UnsupportedType,
        };
        self.0[axis] = value;
        PropertyAccessResult::Set
    }
}

/// An element this reader skips (faces, edges, ...).
struct Skipped;

impl PropertyAccess for Skipped {
    fn new() -> Self {
        Skipped
    }
}

/// Parses a PLY file held in memory and returns its vertices.
pub fn parse_ply(bytes: &[u8], limits: ReadLimits) -> Result<Vec<DVec3>, CloudError> {
    let bad = |e: &dyn std::fmt::Display| CloudError::malformed(FORMAT, e.to_string());
    let mut reader = Reader::new(std::io::BufReader::new(bytes));
    let vertex_parser = Parser::<Vertex>::new();
    let skip_parser = Parser::<Skipped>::new();
    let header = vertex_parser
        .read_header(&mut reader)
        .map_err(|e| bad(&e))?;
    let Some(vertex_def) = header.elements.get("vertex") else {
        return Err(CloudError::malformed(FORMAT, "no vertex element"));
    };
    for axis in ["x", "y", "z"] {
        match vertex_def.properties.get(axis).map(|p| &p.data_type) {
            Some(PropertyType::Scalar(_)) => {}
            Some(PropertyType::List(..)) => {
                return Err(CloudError::malformed(
                    FORMAT,
                    format!("vertex property {axis} is a list"),
                ));
            }
            None => {
                return Err(CloudError::malformed(
                    FORMAT,
                    format!("the vertex element has no {axis} property"),
                ));
            }
        }
    }
    check_count(vertex_def.count as u64, limits)?;
    for (_, element) in &header.elements {
        if element.name == "vertex" {
            let vertices = vertex_parser
                .read_payload_for_element(&mut reader, element, &header)
                .map_err(|e| bad(&e))?;
            let mut points = Vec::with_capacity(vertices.len());
            for (index, Vertex(v)) in vertices.into_iter().enumerate() {
                let p = DVec3::from_array(v);
                if !p.is_finite() {
                    return Err(CloudError::NonFinite { index });
                }
                points.push(p);
            }
            return Ok(points);
        }
        // elements before the vertices must be read through to reach them
        check_count(element.count as u64, limits)?;
        skip_parser
            .read_payload_for_element(&mut reader, element, &header)
            .map_err(|e| bad(&e))?;
    }
    unreachable!("the vertex element is in the header")
}

fn header(out: &mut impl Write, vertices: usize, properties: &[&str]) -> std::io::Result<()> {
    write!(
        out,
        "ply\nformat binary_little_endian 1.0\ncomment written by supertoroid\nelement vertex {vertices}\n"
    )?;
    for p in properties {
        writeln!(out, "property {p}")?;
    }
    Ok(())
}

fn put_f32(out: &mut impl Write, values: &[f64]) -> std::io::Result<()> {
    for &c in values {
        out.write_all(&(c as f32).to_le_bytes())?;
    }
    Ok(())
}

/// Writes a binary PLY with float x, y, z vertices.
pub fn write_ply_points(out: &mut impl Write, points: &[DVec3]) -> std::io::Result<()> {
    header(out, points.len(), &["float x", "float y", "float z"])?;
    out.write_all(b"end_header\n")?;
    for p in points {
        put_f32(out, &p.to_array())?;
    }
    Ok(())
}

/// Writes the points coloured by |residual| (blue at 0, through green, to red at
/// `scale` and beyond), with the residual itself as a float property `distance`.
pub fn write_ply_residuals(
    out: &mut impl Write,
    points: &[DVec3],
    residuals: &[f64],
    scale: f64,
) -> std::io::Result<()> {
    assert_eq!(points.len(), residuals.len(), "one residual per point");
    header(
        out,
        points.len(),
        &[
            "float x",
            "float y",
            "float z",
            "uchar red",
            "uchar green",
            "uchar blue",
            "float distance",
        ],
    )?;
    out.write_all(b"end_header\n")?;
    for (p, &r) in points.iter().zip(residuals) {
        put_f32(out, &p.to_array())?;
        out.write_all(&colormap((r.abs() / scale.max(1e-300)).min(1.0)))?;
        put_f32(out, &[r])?;
    }
    Ok(())
}

/// A blue-green-red ramp for t in [0, 1].
pub fn colormap(t: f64) -> [u8; 3] {
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        1.0
    };
    let (r, g, b) = if t < 0.5 {
        (0.0, 2.0 * t, 1.0 - 2.0 * t)
    } else {
        (2.0 * t - 1.0, 2.0 - 2.0 * t, 0.0)
    };
    [(r * 255.0) as u8, (g * 255.0) as u8, (b * 255.0) as u8]
}

/// Writes a triangle mesh with per-vertex normals.
pub fn write_ply_mesh(out: &mut impl Write, mesh: &Mesh) -> std::io::Result<()> {
    header(
        out,
        mesh.vertices.len(),
        &[
            "float x", "float y", "float z", "float nx", "float ny", "float nz",
        ],
    )?;
    writeln!(
        out,
        "element face {}\nproperty list uchar uint vertex_indices\nend_header",
        mesh.triangles.len()
    )?;
    for (v, n) in mesh.vertices.iter().zip(&mesh.normals) {
        put_f32(out, &v.to_array())?;
        put_f32(out, &n.to_array())?;
    }
    for t in &mesh.triangles {
        out.write_all(&[3u8])?;
        for i in t {
            out.write_all(&i.to_le_bytes())?;
        }
    }
    Ok(())
}
