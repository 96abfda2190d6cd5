//! Depth frames in: a 16-bit PNG (through the `png` crate) or raw little-endian u16,
//! plus pinhole intrinsics and the depth scale, back-projected to a cloud in the camera's
//! optical frame (x right, y down, z forward; metres when the scale is metres per unit).
//! Zero means "no return". An ROI rectangle, a mask PNG (non-zero = keep) and a depth
//! range select the object's pixels.

use super::{CloudError, ReadLimits};
use crate::synth::DepthImage;
use glam::DVec3;
use serde::{Deserialize, Serialize};

const FORMAT: &str = "depth";

fn bad(message: impl Into<String>) -> CloudError {
    CloudError::malformed(FORMAT, message)
}

/// Pinhole intrinsics of the depth stream in pixels (OpenCV convention).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct PinholeIntrinsics {
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
}

/// A rectangle of pixels: columns x..x+width, rows y..y+height.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct Roi {
    pub x: u32,
    pub y: u32,
    pub width: u32,
    pub height: u32,
}

/// How to turn a depth frame into a cloud.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct DepthOptions {
    pub intrinsics: PinholeIntrinsics,
    /// metres (or the caller's unit) per depth unit; 0.001 for RealSense D400
    #[serde(default = "default_depth_scale")]
    pub depth_scale: f64,
    /// keep only these pixels
    #[serde(default)]
    pub roi: Option<Roi>,
    /// keep only depths in [min, max], in the scaled unit
    #[serde(default)]
    pub depth_range: Option<[f64; 2]>,
}

pub fn default_depth_scale() -> f64 {
    0.001
}

impl DepthOptions {
    pub fn validate(&self, width: u32, height: u32) -> Result<(), CloudError> {
        let k = &self.intrinsics;
        if !(k.fx.is_finite() && k.fy.is_finite() && k.fx > 0.0 && k.fy > 0.0) {
            return Err(CloudError::InvalidDepthOptions(format!(
                "fx and fy must be positive and finite (fx = {}, fy = {})",
                k.fx, k.fy
            )));
        }
        if !(k.cx.is_finite() && k.cy.is_finite()) {
            return Err(CloudError::InvalidDepthOptions(
                "cx and cy must be finite".into(),
            ));
        }
        if !(self.depth_scale.is_finite() && self.depth_scale > 0.0) {
            return Err(CloudError::InvalidDepthOptions(format!(
                "depth_scale must be positive and finite, not {}",
                self.depth_scale
            )));
        }
        if let Some(r) = self.roi {
            let fits = r.width > 0
                && r.height > 0
                && r.x.checked_add(r.width).is_some_and(|e| e <= width)
                && r.y.checked_add(r.height).is_some_and(|e| e <= height);
            if !fits {
                return Err(CloudError::InvalidDepthOptions(format!(
                    "roi {r:?} is empty or outside the {width}x{height} image"
                )));
            }
        }
        if let Some([lo, hi]) = self.depth_range
            && !(lo.is_finite() && hi.is_finite() && 0.0 <= lo && lo < hi)
        {
            return Err(CloudError::InvalidDepthOptions(format!(
                "depth_range [{lo}, {hi}] must satisfy 0 <= min < max"
            )));
        }
        Ok(())
    }
}

/// Decodes a 16-bit grayscale PNG depth image. `expected` (width, height), when given,
/// must match.
pub fn decode_depth_png(
    bytes: &[u8],
    scale: f64,
    expected: Option<(u32, u32)>,
    limits: ReadLimits,
) -> Result<DepthImage, CloudError> {
    let (width, height, bit_depth, color, data) = decode_png(bytes, limits)?;
    if color != png::ColorType::Grayscale || bit_depth != png::BitDepth::Sixteen {
        return Err(bad(format!(
            "a depth PNG must be 16-bit grayscale, this one is {bit_depth:?}-bit {color:?}"
        )));
    }
    check_size(width, height, expected)?;
    let data = data
        .chunks_exact(2)
        .map(|c| u16::from_be_bytes([c[0], c[1]]))
        .collect();
    Ok(DepthImage {
        width,
        height,
        scale,
        data,
    })
}

/// Raw little-endian u16 depth of a known size.
pub fn decode_depth_raw(
    bytes: &[u8],
    width: u32,
    height: u32,
    scale: f64,
    limits: ReadLimits,
) -> Result<DepthImage, CloudError> {
    let pixels = width as u64 * height as u64;
    if pixels == 0 {
        return Err(bad("width and height must be positive"));
    }
    super::check_count(pixels, limits)?;
    if bytes.len() as u64 != 2 * pixels {
        return Err(bad(format!(
            "{} bytes of raw u16 depth, but {width}x{height} needs {}",
            bytes.len(),
            2 * pixels
        )));
    }
    Ok(DepthImage {
        width,
        height,
        scale,
        data: bytes
            .chunks_exact(2)
            .map(|c| u16::from_le_bytes([c[0], c[1]]))
            .collect(),
    })
}

/// Decodes a mask PNG (8- or 16-bit grayscale; non-zero keeps the pixel).
pub fn decode_mask_png(
    bytes: &[u8],
    width: u32,
    height: u32,
    limits: ReadLimits,
) -> Result<Vec<bool>, CloudError> {
    let (w, h, bit_depth, color, data) = decode_png(bytes, limits)?;
    check_size(w, h, Some((width, height))).map_err(|e| bad(format!("mask: {e}")))?;
    match (color, bit_depth) {
        (png::ColorType::Grayscale, png::BitDepth::Eight) => {
            Ok(data.iter().map(|&v| v != 0).collect())
        }
        (png::ColorType::Grayscale, png::BitDepth::Sixteen) => Ok(data
            .chunks_exact(2)
            .map(|c| c[0] != 0 || c[1] != 0)
            .collect()),
        _ => Err(bad(format!(
            "a mask PNG must be 8- or 16-bit grayscale, this one is {bit_depth:?}-bit {color:?}"
        ))),
    }
}

fn check_size(width: u32, height: u32, expected: Option<(u32, u32)>) -> Result<(), CloudError> {
    match expected {
        Some((w, h)) if (w, h) != (width, height) => Err(bad(format!(
            "the image is {width}x{height}, expected {w}x{h}"
        ))),
        _ => Ok(()),
    }
}

type Decoded = (u32, u32, png::BitDepth, png::ColorType, Vec<u8>);

fn decode_png(bytes: &[u8], limits: ReadLimits) -> Result<Decoded, CloudError> {
    let png_err = |e: png::DecodingError| bad(format!("PNG: {e}"));
    let mut decoder = png::Decoder::new(std::io::Cursor::new(bytes));
    // no more memory than the largest allowed frame takes
    decoder.set_limits(png::Limits {
        bytes: limits.max_points.saturating_mul(2).max(1 << 20),
    });
    let mut reader = decoder.read_info().map_err(png_err)?;
    let info = reader.info();
    let (width, height, bit_depth, color) =
        (info.width, info.height, info.bit_depth, info.color_type);
    super::check_count(width as u64 * height as u64, limits)?;
    let size = reader
        .output_buffer_size()
        .ok_or_else(|| bad("PNG: image too large"))?;
    let mut data = vec![0u8; size];
    let frame = reader.next_frame(&mut data).map_err(png_err)?;
    data.truncate(frame.buffer_size());
    Ok((width, height, bit_depth, color, data))
}

/// Encodes a depth image as a 16-bit grayscale PNG (the inverse of `decode_depth_png`).
pub fn encode_depth_png(image: &DepthImage) -> Vec<u8> {
    let mut out = Vec::new();
    {
        let mut encoder = png::Encoder::new(&mut out, image.width, image.height);
        encoder.set_color(png::ColorType::Grayscale);
        encoder.set_depth(png::BitDepth::Sixteen);
        let mut writer = encoder.write_header().expect("PNG header into memory");
        let bytes: Vec<u8> = image.data.iter().flat_map(|v| v.to_be_bytes()).collect();
        writer
            .write_image_data(&bytes)
            .expect("PNG data into memory");
    }
    out
}

/// Back-projects the selected valid pixels (see the module docs).
pub fn back_project(
    image: &DepthImage,
    options: &DepthOptions,
    mask: Option<&[bool]>,
) -> Result<Vec<DVec3>, CloudError> {
    options.validate(image.width, image.height)?;
    if image.data.len() != image.width as usize * image.height as usize {
        return Err(bad("the depth data does not match the image size"));
    }
    if let Some(m) = mask
        && m.len() != image.data.len()
    {
        return Err(bad("the mask does not match the image size"));
    }
    let roi = options.roi.unwrap_or(Roi {
        x: 0,
        y: 0,
        width: image.width,
        height: image.height,
    });
    let [lo, hi] = options.depth_range.unwrap_or([0.0, f64::INFINITY]);
    let k = options.intrinsics;
    let mut points = Vec::new();
    for v in roi.y..roi.y + roi.height {
        for u in roi.x..roi.x + roi.width {
            let i = (v * image.width + u) as usize;
            let raw = image.data[i];
            if raw == 0 || mask.is_some_and(|m| !m[i]) {
                continue;
            }
            let z = raw as f64 * options.depth_scale;
            if z < lo || z > hi {
                continue;
            }
            points.push(DVec3::new(
                (u as f64 - k.cx) / k.fx * z,
                (v as f64 - k.cy) / k.fy * z,
                z,
            ));
        }
    }
    if points.is_empty() {
        return Err(CloudError::NoValidDepth);
    }
    Ok(points)
}
