//! Point-cloud input and output. Text XYZ and PLY for now; every reader returns a clear
//! [`CloudError`] on bad input and never panics.

mod ply;
mod xyz;

pub use ply::write_ply_points;
pub use xyz::{parse_xyz, write_xyz};

use glam::DVec3;
use std::path::Path;

/// Why a cloud could not be read.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum CloudError {
    #[error("line {line}: {message}")]
    Parse { line: usize, message: String },
    #[error("point {index} has a non-finite coordinate")]
    NonFinite { index: usize },
    #[error("the cloud is empty")]
    Empty,
    #[error("unsupported format {0:?} (supported: xyz, ply)")]
    UnsupportedFormat(String),
    #[error("{0}")]
    Io(String),
}

/// Reads a cloud from a file, the format chosen by the file's extension.
pub fn read_cloud(path: &Path) -> Result<Vec<DVec3>, CloudError> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    let bytes =
        std::fs::read(path).map_err(|e| CloudError::Io(format!("{}: {e}", path.display())))?;
    match ext.as_str() {
        "xyz" | "txt" | "csv" => parse_xyz(&String::from_utf8_lossy(&bytes)),
        other => Err(CloudError::UnsupportedFormat(other.to_string())),
    }
}

/// Writes a cloud to a file, the format chosen by the file's extension (.xyz or .ply).
pub fn write_cloud(path: &Path, points: &[DVec3]) -> Result<(), CloudError> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    let mut out = Vec::new();
    match ext.as_str() {
        "xyz" | "txt" => write_xyz(&mut out, points),
        "ply" => write_ply_points(&mut out, points),
        other => return Err(CloudError::UnsupportedFormat(other.to_string())),
    }
    .map_err(|e| CloudError::Io(e.to_string()))?;
    std::fs::write(path, out).map_err(|e| CloudError::Io(format!("{}: {e}", path.display())))
}
