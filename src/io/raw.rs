//! Raw little-endian float32 x,y,z triples, 12 bytes per point, nothing else: the data
//! of a ROS `sensor_msgs/PointCloud2` whose fields are exactly x, y, z (FLOAT32,
//! point_step 12). NaN points (what organised ROS clouds use for "no return") are
//! dropped; infinities are an error.

use super::{CloudError, ReadLimits, check_count};
use glam::DVec3;
use std::io::Write;

pub fn parse_raw_f32(bytes: &[u8], limits: ReadLimits) -> Result<Vec<DVec3>, CloudError> {
    if bytes.len() % 12 != 0 {
        return Err(CloudError::malformed(
            "raw",
            format!(
                "{} bytes is not a whole number of float32 x,y,z triples (12 bytes each)",
                bytes.len()
            ),
        ));
    }
    let count = check_count(bytes.len() as u64 / 12, limits)?;
    let mut points = Vec::with_capacity(count);
    for (index, chunk) in bytes.chunks_exact(12).enumerate() {
        let c = |i: usize| f32::from_le_bytes(chunk[i..i + 4].try_into().unwrap()) as f64;
        let p = DVec3::new(c(0), c(4), c(8));
        if p.is_nan() {
            continue;
        }
        if !p.is_finite() {
            return Err(CloudError::NonFinite { index });
        }
        points.push(p);
    }
    Ok(points)
}

pub fn write_raw_f32(out: &mut impl Write, points: &[DVec3]) -> std::io::Result<()> {
    for p in points {
        for c in [p.x, p.y, p.z] {
            out.write_all(&(c as f32).to_le_bytes())?;
        }
    }
    Ok(())
}
