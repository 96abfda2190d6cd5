//! Point clouds and depth frames in, meshes and reports out.
//!
//! Every reader takes bytes and returns points or a [`CloudError`] that names the
//! problem; none panics on any input (the parsers are fuzzed by property tests), and none
//! allocates more than the header's claims allow after checking them against
//! [`ReadLimits`] and the bytes actually present.
//!
//! * [`pcd`]: PCD v0.7 ascii / binary / binary_compressed (through `pcd-rs`).
//! * [`ply`]: PLY ascii / binary LE / BE (through `ply-rs-bw`); point, coloured-point and
//!   mesh writers.
//! * [`xyz`]: whitespace or comma separated text.
//! * [`raw`]: little-endian float32 x,y,z triples (a ROS PointCloud2 xyz layout).
//! * [`depth`]: 16-bit depth frames (PNG or raw u16) back-projected through pinhole
//!   intrinsics.
//! * [`mesh`]: a triangle mesh of a fitted supertoroid.
//! * [`encode_rgb_png`]: the pictures' and plots' PNG encoding.

pub mod depth;
pub mod mesh;
pub mod pcd;
pub mod ply;
pub mod raw;
pub mod xyz;

pub use ply::{write_ply_mesh, write_ply_points, write_ply_residuals};
pub use xyz::{parse_xyz, write_xyz};

use glam::DVec3;
use serde::{Deserialize, Serialize};
use std::io::Read;
use std::path::Path;

/// An 8-bit RGB image (rows of `width` pixels, three bytes each) as PNG bytes: the
/// pictures' and plots' format.
pub fn encode_rgb_png(width: u32, height: u32, rgb: &[u8]) -> Result<Vec<u8>, String> {
    let mut out = Vec::new();
    {
        let mut encoder = png::Encoder::new(&mut out, width, height);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        let mut writer = encoder.write_header().map_err(|e| e.to_string())?;
        writer.write_image_data(rgb).map_err(|e| e.to_string())?;
    }
    Ok(out)
}

/// The cloud formats the readers know.
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum, utoipa::ToSchema,
)]
#[serde(rename_all = "lowercase")]
pub enum Format {
    /// text: x y z per line, whitespace or comma separated
    Xyz,
    /// PCD v0.7 (ascii, binary, binary_compressed)
    Pcd,
    /// PLY (ascii, binary little or big endian)
    Ply,
    /// raw little-endian float32 x,y,z triples
    Raw,
}

impl Format {
    pub fn name(self) -> &'static str {
        match self {
            Format::Xyz => "xyz",
            Format::Pcd => "pcd",
            Format::Ply => "ply",
            Format::Raw => "raw",
        }
    }

    /// The format a file extension names, if any.
    pub fn from_extension(path: &Path) -> Option<Format> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        match ext.as_str() {
            "xyz" | "txt" | "csv" | "pts" => Some(Format::Xyz),
            "pcd" => Some(Format::Pcd),
            "ply" => Some(Format::Ply),
            "raw" | "bin" | "f32" => Some(Format::Raw),
            _ => None,
        }
    }

    /// Guesses the format from the first bytes: PLY and PCD by their headers, text by
    /// being printable ASCII, otherwise raw float32 when the length is a multiple of 12.
    pub fn sniff(bytes: &[u8]) -> Option<Format> {
        let head = &bytes[..bytes.len().min(4096)];
        if head.starts_with(b"ply") {
            return Some(Format::Ply);
        }
        let text_head = String::from_utf8_lossy(head);
        let has_key = |key: &str| text_head.lines().take(40).any(|l| l.starts_with(key));
        if has_key("FIELDS") && has_key("DATA") {
            return Some(Format::Pcd);
        }
        let printable = head
            .iter()
            .all(|&b| b == b'\n' || b == b'\r' || b == b'\t' || (0x20..0x7f).contains(&b));
        if printable && !head.is_empty() {
            return Some(Format::Xyz);
        }
        if !bytes.is_empty() && bytes.len() % 12 == 0 {
            return Some(Format::Raw);
        }
        None
    }
}

/// Limits a reader checks before it allocates for what a header claims.
#[derive(Clone, Copy, Debug)]
pub struct ReadLimits {
    pub max_points: usize,
}

impl Default for ReadLimits {
    fn default() -> Self {
        Self {
            max_points: 20_000_000,
        }
    }
}

/// Why a cloud or depth frame could not be read.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum CloudError {
    #[error("line {line}: {message}")]
    Parse { line: usize, message: String },
    #[error("{format}: {message}")]
    Malformed {
        format: &'static str,
        message: String,
    },
    #[error("point {index} has a non-finite coordinate")]
    NonFinite { index: usize },
    #[error("the cloud is empty")]
    Empty,
    #[error("too many points: {points} (the limit is {limit})")]
    TooLarge { points: u64, limit: usize },
    #[error("unsupported format {0:?} (supported: xyz, txt, csv, pcd, ply, raw)")]
    UnsupportedFormat(String),
    #[error("invalid depth options: {0}")]
    InvalidDepthOptions(String),
    #[error("no pixel has a valid depth (all zero, or outside the ROI, mask or depth range)")]
    NoValidDepth,
    #[error("{0}")]
    Io(String),
}

impl CloudError {
    /// A short machine-readable name of the error class (used in HTTP error bodies).
    pub fn code(&self) -> &'static str {
        match self {
            CloudError::Malformed {
                format: "depth", ..
            } => "malformed_image",
            CloudError::Parse { .. } | CloudError::Malformed { .. } => "malformed_cloud",
            CloudError::NonFinite { .. } => "non_finite",
            CloudError::Empty => "empty_cloud",
            CloudError::TooLarge { .. } => "too_many_points",
            CloudError::UnsupportedFormat(_) => "unsupported_format",
            CloudError::InvalidDepthOptions(_) => "invalid_depth_options",
            CloudError::NoValidDepth => "no_valid_depth",
            CloudError::Io(_) => "io",
        }
    }

    pub(crate) fn malformed(format: &'static str, message: impl Into<String>) -> Self {
        CloudError::Malformed {
            format,
            message: message.into(),
        }
    }
}

/// Parses a cloud held in memory. `format: None` sniffs it.
pub fn parse_cloud(
    bytes: &[u8],
    format: Option<Format>,
    limits: ReadLimits,
) -> Result<Vec<DVec3>, CloudError> {
    if bytes.is_empty() {
        return Err(CloudError::Empty);
    }
    let format = match format.or_else(|| Format::sniff(bytes)) {
        Some(f) => f,
        None => {
            return Err(CloudError::UnsupportedFormat(
                "unrecognised content (not PLY, PCD, text, or float32 triples)".into(),
            ));
        }
    };
    // The third-party parsers are guarded as well as pre-checked: a panic in one of them
    // becomes an error, never a crash of the service.
    let result = std::panic::catch_unwind(|| match format {
        Format::Xyz => xyz::parse_xyz_bytes(bytes, limits),
        Format::Pcd => pcd::parse_pcd(bytes, limits),
        Format::Ply => ply::parse_ply(bytes, limits),
        Format::Raw => raw::parse_raw_f32(bytes, limits),
    })
    .unwrap_or_else(|_| {
        Err(CloudError::malformed(
            format.name(),
            "the parser rejected the content",
        ))
    })?;
    if result.is_empty() {
        return Err(CloudError::Empty);
    }
    Ok(result)
}

/// Reads a whole file, or standard input for `-`.
pub fn read_bytes(path: &Path) -> Result<Vec<u8>, CloudError> {
    if path.as_os_str() == "-" {
        let mut buf = Vec::new();
        std::io::stdin()
            .lock()
            .read_to_end(&mut buf)
            .map_err(|e| CloudError::Io(format!("stdin: {e}")))?;
        Ok(buf)
    } else {
        std::fs::read(path).map_err(|e| CloudError::Io(format!("{}: {e}", path.display())))
    }
}

/// Reads a cloud from a file (or stdin for `-`). The format is `format` if given, else
/// the extension's, else sniffed from the content.
pub fn read_cloud(path: &Path, format: Option<Format>) -> Result<Vec<DVec3>, CloudError> {
    let bytes = read_bytes(path)?;
    let format = format.or_else(|| Format::from_extension(path));
    parse_cloud(&bytes, format, ReadLimits::default())
}

/// Writes a cloud to a file, the format chosen by the file's extension (.xyz/.txt text,
/// .ply binary, .pcd binary, .raw float32).
pub fn write_cloud(path: &Path, points: &[DVec3]) -> Result<(), CloudError> {
    let format = Format::from_extension(path).ok_or_else(|| {
        CloudError::UnsupportedFormat(
            path.extension()
                .map(|e| e.to_string_lossy().into_owned())
                .unwrap_or_default(),
        )
    })?;
    let mut out = Vec::new();
    match format {
        Format::Xyz => write_xyz(&mut out, points),
        Format::Ply => write_ply_points(&mut out, points),
        Format::Pcd => pcd::write_pcd_binary(&mut out, points),
        Format::Raw => raw::write_raw_f32(&mut out, points),
    }
    .map_err(|e| CloudError::Io(e.to_string()))?;
    std::fs::write(path, out).map_err(|e| CloudError::Io(format!("{}: {e}", path.display())))
}

/// Checks a point count a header claims against the limits.
pub(crate) fn check_count(points: u64, limits: ReadLimits) -> Result<usize, CloudError> {
    if points > limits.max_points as u64 {
        return Err(CloudError::TooLarge {
            points,
            limit: limits.max_points,
        });
    }
    Ok(points as usize)
}
