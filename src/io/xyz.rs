use super::{CloudError, ReadLimits};
use glam::DVec3;
use std::io::Write;

/// Parses XYZ / CSV bytes (UTF-8 text), stopping at the point limit.
pub fn parse_xyz_bytes(bytes: &[u8], limits: ReadLimits) -> Result<Vec<DVec3>, CloudError> {
    let text = std::str::from_utf8(bytes)
        .map_err(|e| CloudError::malformed("xyz", format!("not UTF-8 text: {e}")))?;
    parse_xyz_limited(text, limits)
}

/// Parses XYZ / CSV text with the default limits.
pub fn parse_xyz(text: &str) -> Result<Vec<DVec3>, CloudError> {
    parse_xyz_limited(text, ReadLimits::default())
}

/// Parses XYZ / CSV text: one point per line, x y z separated by whitespace or commas,
/// further columns ignored; blank lines and `#` comments skipped; one header line of
/// non-numbers allowed as the first non-comment line.
fn parse_xyz_limited(text: &str, limits: ReadLimits) -> Result<Vec<DVec3>, CloudError> {
    let mut points = Vec::new();
    let mut seen_data = false;
    for (i, raw) in text.lines().enumerate() {
        let line = raw.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let fields: Vec<&str> = line
            .split(|c: char| c == ',' || c.is_whitespace())
            .filter(|f| !f.is_empty())
            .collect();
        let parsed: Result<Vec<f64>, _> = fields.iter().take(3).map(|f| f.parse::<f64>()).collect();
        match parsed {
            Ok(v) if v.len() == 3 => {
                let p = DVec3::new(v[0], v[1], v[2]);
                if !p.is_finite() {
                    return Err(CloudError::NonFinite {
                        index: points.len(),
                    });
                }
                if points.len() == limits.max_points {
                    return Err(CloudError::TooLarge {
                        points: points.len() as u64 + 1,
                        limit: limits.max_points,
                    });
                }
                points.push(p);
                seen_data = true;
            }
            Ok(v) => {
                return Err(CloudError::Parse {
                    line: i + 1,
                    message: format!("expected 3 coordinates, found {}", v.len()),
                });
            }
            Err(_)
                if !seen_data
                    && points.is_empty()
                    && fields.iter().all(|f| f.parse::<f64>().is_err()) =>
            {
                seen_data = true; // a header line such as "x,y,z"
            }
            Err(_) => {
                return Err(CloudError::Parse {
                    line: i + 1,
                    message: format!("not a number in {line:?}"),
                });
            }
        }
    }
    if points.is_empty() {
        return Err(CloudError::Empty);
    }
    Ok(points)
}

/// Writes one `x y z` line per point, with enough digits to round-trip an f64.
pub fn write_xyz(out: &mut impl Write, points: &[DVec3]) -> std::io::Result<()> {
    for p in points {
        writeln!(out, "{} {} {}", p.x, p.y, p.z)?;
    }
    Ok(())
}
