//! PCD v0.7 (PCL's point cloud format): ascii, binary and binary_compressed (LZF), read
//! through the `pcd-rs` crate.
//!
//! Before `pcd-rs` sees the bytes, [`PcdHeader::scan`] reads the header itself and checks
//! every claim that decides an allocation or a slice: the field table is consistent, x, y
//! and z exist and are numbers, POINTS = WIDTH·HEIGHT, the count is within the limits,
//! binary data is as long as POINTS records, and a compressed block's sizes match the
//! bytes present and the record layout. What is left for the crate is decoding.
//!
//! Points are looked up by field name, so any field order, extra fields (rgb, normals,
//! `_` padding) and COUNT > 1 on other fields are fine. NaN points are dropped in
//! organised clouds (HEIGHT > 1) and in clouds that PCL marks as not dense by their
//! NaNs; an infinite coordinate is an error.

use super::{CloudError, ReadLimits, check_count};
use glam::DVec3;
use pcd_rs::{DataKind, DynReader, DynRecord, Field, Schema, ValueKind, WriterInit};
use std::io::{Seek, Write};

const FORMAT: &str = "pcd";

fn bad(message: impl Into<String>) -> CloudError {
    CloudError::malformed(FORMAT, message)
}

/// What the header says, checked.
#[derive(Debug, Clone, PartialEq)]
pub struct PcdHeader {
    pub fields: Vec<String>,
    pub sizes: Vec<usize>,
    pub types: Vec<char>,
    pub counts: Vec<usize>,
    pub width: u64,
    pub height: u64,
    pub points: u64,
    pub data: String,
    /// byte offset of the data section
    pub data_offset: usize,
    /// the sensor's position, `VIEWPOINT`'s tx ty tz, where the line has three numbers
    pub viewpoint: Option<DVec3>,
}

impl PcdHeader {
    /// Bytes per point record.
    pub fn record_size(&self) -> usize {
        self.sizes
            .iter()
            .zip(&self.counts)
            .map(|(s, c)| s * c)
            .sum()
    }

    fn field_index(&self, name: &str) -> Option<usize> {
        self.fields.iter().position(|f| f == name)
    }

    /// Reads and checks the header (see the module docs).
    pub fn scan(bytes: &[u8], limits: ReadLimits) -> Result<Self, CloudError> {
        let lines = HeaderLines::read(bytes)?;
        let FieldTable {
            fields,
            sizes,
            types,
            counts,
        } = lines.field_table()?;
        let (width, height, points) = lines.dimensions()?;
        check_count(points, limits)?;
        let header = PcdHeader {
            fields,
            sizes,
            types,
            counts,
            width,
            height,
            points,
            viewpoint: lines.viewpoint(),
            data: lines.data,
            data_offset: lines.data_offset,
        };
        header.check_coordinates()?;
        header.check_body(&bytes[header.data_offset..])?;
        Ok(header)
    }

    /// x, y and z are fields of one value each.
    fn check_coordinates(&self) -> Result<(), CloudError> {
        for axis in ["x", "y", "z"] {
            let i = self
                .field_index(axis)
                .ok_or_else(|| bad(format!("no {axis} field (FIELDS {:?})", self.fields)))?;
            if self.counts[i] != 1 {
                return Err(bad(format!("field {axis} has COUNT {}", self.counts[i])));
            }
        }
        Ok(())
    }

    /// The data section `body` holds what the header promises: binary data POINTS
    /// records long, a compressed block whose sizes match the bytes present and the
    /// records.
    fn check_body(&self, body: &[u8]) -> Result<(), CloudError> {
        let points = self.points;
        let expected = (points as usize).saturating_mul(self.record_size());
        match self.data.as_str() {
            "ascii" => {}
            "binary" => {
                if body.len() < expected {
                    return Err(bad(format!(
                        "truncated binary data: {} bytes for {points} points of {} bytes",
                        body.len(),
                        self.record_size()
                    )));
                }
            }
            "binary_compressed" => {
                if body.len() < 8 {
                    return Err(bad("truncated binary_compressed block sizes"));
                }
                let compressed = u32::from_le_bytes(body[0..4].try_into().unwrap()) as usize;
                let uncompressed = u32::from_le_bytes(body[4..8].try_into().unwrap()) as usize;
                if compressed > body.len() - 8 {
                    return Err(bad(format!(
                        "truncated compressed data: the block claims {compressed} bytes, {} present",
                        body.len() - 8
                    )));
                }
                if uncompressed != expected {
                    return Err(bad(format!(
                        "the compressed block decompresses to {uncompressed} bytes, but {points} points of {} bytes need {expected}",
                        self.record_size()
                    )));
                }
            }
            other => return Err(bad(format!("unknown DATA kind {other:?}"))),
        }
        Ok(())
    }
}

/// The header's columns, one entry per field.
struct FieldTable {
    fields: Vec<String>,
    sizes: Vec<usize>,
    types: Vec<char>,
    counts: Vec<usize>,
}

/// The header's lines up to DATA: each key (upper case) with its values, DATA's kind
/// (lower case) and where the data section starts.
struct HeaderLines {
    keys: std::collections::HashMap<String, Vec<String>>,
    data: String,
    data_offset: usize,
}

impl HeaderLines {
    fn read(bytes: &[u8]) -> Result<Self, CloudError> {
        let mut offset = 0;
        let mut keys: std::collections::HashMap<String, Vec<String>> = Default::default();
        let data = loop {
            if offset >= bytes.len() {
                return Err(bad("the header ends before its DATA line"));
            }
            if offset > 64 * 1024 {
                return Err(bad("no DATA line in the first 64 KiB"));
            }
            let end = bytes[offset..]
                .iter()
                .position(|&b| b == b'\n')
                .map(|p| offset + p + 1)
                .unwrap_or(bytes.len());
            let line = String::from_utf8_lossy(&bytes[offset..end]);
            offset = end;
            let line = line.split('#').next().unwrap_or("");
            let mut tokens = line.split_ascii_whitespace();
            let Some(key) = tokens.next() else { continue };
            let key = key.to_ascii_uppercase();
            let values: Vec<String> = tokens.map(str::to_owned).collect();
            if key == "DATA" {
                break values
                    .first()
                    .cloned()
                    .unwrap_or_default()
                    .to_ascii_lowercase();
            }
            keys.insert(key, values);
        };
        Ok(Self {
            keys,
            data,
            data_offset: offset,
        })
    }

    fn list(&self, key: &str) -> Result<Vec<String>, CloudError> {
        self.keys
            .get(key)
            .cloned()
            .ok_or_else(|| bad(format!("the header has no {key} line")))
    }

    fn number(&self, key: &str) -> Result<u64, CloudError> {
        let v = self.list(key)?;
        v.first()
            .and_then(|s| s.parse::<u64>().ok())
            .ok_or_else(|| bad(format!("{key} is not a non-negative integer: {v:?}")))
    }

    /// FIELDS, SIZE, TYPE and COUNT (1 each where absent), as long as each other, every
    /// field's type and size one the reader decodes.
    fn field_table(&self) -> Result<FieldTable, CloudError> {
        let fields = self.list("FIELDS")?;
        let n = fields.len();
        let sizes = self
            .list("SIZE")?
            .iter()
            .map(|s| {
                s.parse::<usize>()
                    .map_err(|_| bad(format!("bad SIZE {s:?}")))
            })
            .collect::<Result<Vec<_>, _>>()?;
        let types = self
            .list("TYPE")?
            .iter()
            .map(|s| {
                let c = s.to_ascii_uppercase();
                match c.as_str() {
                    "F" | "I" | "U" => Ok(c.chars().next().unwrap()),
                    _ => Err(bad(format!("unknown field type {s:?} (F, I or U)"))),
                }
            })
            .collect::<Result<Vec<_>, _>>()?;
        let counts = match self.keys.get("COUNT") {
            Some(c) => c
                .iter()
                .map(|s| {
                    s.parse::<usize>()
                        .ok()
                        .filter(|&c| (1..=4096).contains(&c))
                        .ok_or_else(|| bad(format!("bad COUNT {s:?}")))
                })
                .collect::<Result<Vec<_>, _>>()?,
            None => vec![1; n],
        };
        if sizes.len() != n || types.len() != n || counts.len() != n {
            return Err(bad(format!(
                "FIELDS has {n} entries but SIZE has {}, TYPE {}, COUNT {}",
                sizes.len(),
                types.len(),
                counts.len()
            )));
        }
        for ((f, &s), &t) in fields.iter().zip(&sizes).zip(&types) {
            let ok = match t {
                'F' => s == 4 || s == 8,
                _ => matches!(s, 1 | 2 | 4 | 8),
            };
            if !ok {
                return Err(bad(format!(
                    "field {f}: type {t} with size {s} is not supported"
                )));
            }
        }
        Ok(FieldTable {
            fields,
            sizes,
            types,
            counts,
        })
    }

    /// WIDTH, HEIGHT (1 where absent) and POINTS (WIDTH·HEIGHT where absent), POINTS
    /// equal to WIDTH·HEIGHT.
    fn dimensions(&self) -> Result<(u64, u64, u64), CloudError> {
        let width = self.number("WIDTH")?;
        let height = self
            .keys
            .get("HEIGHT")
            .map(|_| self.number("HEIGHT"))
            .transpose()?
            .unwrap_or(1);
        let points = match self.keys.get("POINTS") {
            Some(_) => self.number("POINTS")?,
            None => width.saturating_mul(height),
        };
        if width.checked_mul(height) != Some(points) {
            return Err(bad(format!(
                "POINTS {points} does not equal WIDTH {width} x HEIGHT {height}"
            )));
        }
        Ok((width, height, points))
    }

    /// VIEWPOINT's tx ty tz, where the line has three numbers.
    fn viewpoint(&self) -> Option<DVec3> {
        self.keys.get("VIEWPOINT").and_then(|v| {
            let t: Vec<f64> = v
                .iter()
                .take(3)
                .map(|x| x.parse().ok())
                .collect::<Option<_>>()?;
            (t.len() == 3).then(|| DVec3::new(t[0], t[1], t[2]))
        })
    }
}

fn field_value(field: &Field) -> Option<f64> {
    Some(match field {
        Field::F32(v) => *v.first()? as f64,
        Field::F64(v) => *v.first()?,
        Field::I8(v) => *v.first()? as f64,
        Field::I16(v) => *v.first()? as f64,
        Field::I32(v) => *v.first()? as f64,
        Field::I64(v) => *v.first()? as f64,
        Field::U8(v) => *v.first()? as f64,
        Field::U16(v) => *v.first()? as f64,
        Field::U32(v) => *v.first()? as f64,
        Field::U64(v) => *v.first()? as f64,
    })
}

/// Parses a PCD file held in memory.
pub fn parse_pcd(bytes: &[u8], limits: ReadLimits) -> Result<Vec<DVec3>, CloudError> {
    let header = PcdHeader::scan(bytes, limits)?;
    let index = |name| header.field_index(name).unwrap();
    let (ix, iy, iz) = (index("x"), index("y"), index("z"));
    let reader = DynReader::from_bytes(bytes).map_err(|e| bad(e.to_string()))?;
    if reader.meta().num_points != header.points {
        return Err(bad("the header could not be read consistently"));
    }
    let mut points = Vec::with_capacity(header.points as usize);
    for (i, record) in reader.enumerate() {
        let DynRecord(fields) = record.map_err(|e| bad(format!("point {i}: {e}")))?;
        let value = |k: usize| {
            fields
                .get(k)
                .and_then(field_value)
                .ok_or_else(|| bad(format!("point {i}: field {k} missing")))
        };
        let p = DVec3::new(value(ix)?, value(iy)?, value(iz)?);
        if p.is_nan() {
            // PCL's "no return" in organised and non-dense clouds
            continue;
        }
        if !p.is_finite() {
            return Err(CloudError::NonFinite { index: i });
        }
        points.push(p);
    }
    if points.is_empty() && header.points > 0 {
        return Err(bad("every point is NaN"));
    }
    Ok(points)
}

/// Which PCD data section to write.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PcdData {
    Ascii,
    Binary,
    BinaryCompressed,
}

/// Writes x, y, z as F4 fields (or F8 with `double`) through `pcd-rs`.
pub fn write_pcd<W: Write + Seek>(
    out: W,
    points: &[DVec3],
    data: PcdData,
    double: bool,
) -> Result<(), CloudError> {
    let kind = if double {
        ValueKind::F64
    } else {
        ValueKind::F32
    };
    let schema: Schema = [("x", kind, 1), ("y", kind, 1), ("z", kind, 1)]
        .into_iter()
        .collect();
    let data_kind = match data {
        PcdData::Ascii => DataKind::Ascii,
        PcdData::Binary => DataKind::Binary,
        PcdData::BinaryCompressed => DataKind::BinaryCompressed,
    };
    let io = |e: pcd_rs::Error| CloudError::Io(e.to_string());
    let mut writer = WriterInit {
        width: points.len() as u64,
        height: 1,
        viewpoint: Default::default(),
        data_kind,
        schema: Some(schema),
        version: None,
    }
    .build_from_writer::<DynRecord, _>(out)
    .map_err(io)?;
    for p in points {
        let record = if double {
            DynRecord(vec![
                Field::F64(vec![p.x]),
                Field::F64(vec![p.y]),
                Field::F64(vec![p.z]),
            ])
        } else {
            DynRecord(vec![
                Field::F32(vec![p.x as f32]),
                Field::F32(vec![p.y as f32]),
                Field::F32(vec![p.z as f32]),
            ])
        };
        writer.push(&record).map_err(io)?;
    }
    writer.finish().map_err(io)
}

/// Binary F4 PCD into a byte vector (what `write_cloud` uses for `.pcd`).
pub fn write_pcd_binary(out: &mut Vec<u8>, points: &[DVec3]) -> std::io::Result<()> {
    let mut cursor = std::io::Cursor::new(Vec::new());
    write_pcd(&mut cursor, points, PcdData::Binary, false)
        .map_err(|e| std::io::Error::other(e.to_string()))?;
    out.extend_from_slice(&cursor.into_inner());
    Ok(())
}

/// The sensor's position a PCD header states (`VIEWPOINT tx ty tz qw qx qy qz`), for a
/// cloud of that format: `Viewpoint::At` where it is off the origin, `Auto` otherwise
/// (PCL writes the origin whether or not it knows, so an origin there says nothing).
pub fn header_viewpoint(bytes: &[u8], format: Option<super::Format>) -> crate::fit::Viewpoint {
    use crate::fit::{Viewpoint, ViewpointSource};
    let is_pcd = format.or_else(|| super::Format::sniff(bytes)) == Some(super::Format::Pcd);
    if !is_pcd {
        return Viewpoint::Auto;
    }
    let stated = PcdHeader::scan(bytes, ReadLimits::default())
        .ok()
        .and_then(|h| h.viewpoint);
    match stated {
        Some(p) if p.is_finite() && p != DVec3::ZERO => {
            Viewpoint::At(p, ViewpointSource::PcdHeader)
        }
        _ => Viewpoint::Auto,
    }
}
