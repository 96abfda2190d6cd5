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

/// A rectangle of pixels: columns x..x+width, rows y..y+height. A detector's box may
/// reach past the image (x, y negative, or past its far edges): it is clipped to it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct Roi {
    pub x: i64,
    pub y: i64,
    pub width: u32,
    pub height: u32,
}

impl std::fmt::Display for Roi {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "x {} y {} width {} height {}",
            self.x, self.y, self.width, self.height
        )
    }
}

impl Roi {
    /// The part of the rectangle inside a `width` x `height` image, None where nothing
    /// of it is.
    pub fn clipped(&self, width: u32, height: u32) -> Option<Roi> {
        let span = |start: i64, len: u32, size: u32| {
            let lo = start.clamp(0, size as i64);
            let hi = (start + len as i64).clamp(0, size as i64);
            (hi > lo).then_some((lo, (hi - lo) as u32))
        };
        let (x, w) = span(self.x, self.width, width)?;
        let (y, h) = span(self.y, self.height, height)?;
        Some(Roi {
            x,
            y,
            width: w,
            height: h,
        })
    }
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
        let inside = |c: f64, size: u32| (0.0..=size as f64).contains(&c);
        if !(inside(k.cx, width) && inside(k.cy, height)) {
            return Err(CloudError::InvalidDepthOptions(format!(
                "the principal point (cx {}, cy {}) lies outside the {width}x{height} image: \
                 intrinsics of another resolution, or fields swapped",
                k.cx, k.cy
            )));
        }
        if !(self.depth_scale.is_finite() && self.depth_scale > 0.0) {
            return Err(CloudError::InvalidDepthOptions(format!(
                "depth_scale must be positive and finite, not {}",
                self.depth_scale
            )));
        }
        if let Some(r) = self.roi
            && r.clipped(width, height).is_none()
        {
            return Err(CloudError::InvalidDepthOptions(format!(
                "the roi ({r}) is empty or lies outside the {width}x{height} image"
            )));
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

/// Focal lengths in this range of the image's larger side are a depth camera's (a
/// D435's 640x480 stream: 0.6-1.0); outside it the intrinsics are likely another
/// stream's or another unit's.
pub const PLAUSIBLE_FOCAL: std::ops::RangeInclusive<f64> = 0.2..=5.0;

/// A note for the report where the focal lengths are implausible for the image
/// ([`PLAUSIBLE_FOCAL`]).
pub fn intrinsics_note(k: &PinholeIntrinsics, width: u32, height: u32) -> Option<String> {
    let side = width.max(height) as f64;
    let plausible = |f: f64| PLAUSIBLE_FOCAL.contains(&(f / side));
    (!(plausible(k.fx) && plausible(k.fy))).then(|| {
        format!(
            "intrinsics look wrong: fx {} and fy {} pixels for a {width}x{height} image \
             (a depth camera's are {}-{} times its larger side); the pose and size \
             scale with them",
            k.fx,
            k.fy,
            PLAUSIBLE_FOCAL.start(),
            PLAUSIBLE_FOCAL.end()
        )
    })
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
            "a depth PNG must be 16-bit grayscale, this one is {} {}",
            bits(bit_depth),
            colour(color)
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

/// Decodes a mask PNG (1-, 2-, 4-, 8- or 16-bit grayscale; non-zero keeps the pixel).
pub fn decode_mask_png(
    bytes: &[u8],
    width: u32,
    height: u32,
    limits: ReadLimits,
) -> Result<Vec<bool>, CloudError> {
    // masks of fewer than 8 bits (what datasets ship) come out one byte a pixel
    let (w, h, bit_depth, color, data) =
        decode_png_with(bytes, limits, png::Transformations::EXPAND)?;
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
            "a mask PNG must be grayscale (1 to 16 bits), this one is {} {}",
            bits(bit_depth),
            colour(color)
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

/// A PNG's bit depth in words.
fn bits(depth: png::BitDepth) -> String {
    format!("{}-bit", depth as u8)
}

/// A PNG's colour type in words.
fn colour(color: png::ColorType) -> &'static str {
    match color {
        png::ColorType::Grayscale => "grayscale",
        png::ColorType::GrayscaleAlpha => "grayscale with alpha",
        png::ColorType::Rgb => "RGB",
        png::ColorType::Rgba => "RGBA",
        png::ColorType::Indexed => "palette",
    }
}

fn decode_png(bytes: &[u8], limits: ReadLimits) -> Result<Decoded, CloudError> {
    decode_png_with(bytes, limits, png::Transformations::IDENTITY)
}

/// Decodes a PNG under `transformations`; the bit depth and colour type returned are the
/// output's.
fn decode_png_with(
    bytes: &[u8],
    limits: ReadLimits,
    transformations: png::Transformations,
) -> Result<Decoded, CloudError> {
    let png_err = |e: png::DecodingError| bad(format!("PNG: {e}"));
    let mut decoder = png::Decoder::new(std::io::Cursor::new(bytes));
    decoder.set_transformations(transformations);
    // no more memory than the largest allowed frame takes
    decoder.set_limits(png::Limits {
        bytes: limits.max_points.saturating_mul(2).max(1 << 20),
    });
    let mut reader = decoder.read_info().map_err(png_err)?;
    let info = reader.info();
    let (width, height) = (info.width, info.height);
    let (color, bit_depth) = reader.output_color_type();
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
    back_project_pixels(image, options, mask).map(|p| p.points)
}

/// [`back_project`] keeping each point's pixel.
pub fn back_project_pixels(
    image: &DepthImage,
    options: &DepthOptions,
    mask: Option<&[bool]>,
) -> Result<crate::scene::table::Pixels, CloudError> {
    options.validate(image.width, image.height)?;
    if image.data.len() != image.width as usize * image.height as usize {
        return Err(bad("the depth data does not match the image size"));
    }
    if let Some(m) = mask
        && m.len() != image.data.len()
    {
        return Err(bad("the mask does not match the image size"));
    }
    let whole = Roi {
        x: 0,
        y: 0,
        width: image.width,
        height: image.height,
    };
    let roi = options
        .roi
        .and_then(|r| r.clipped(image.width, image.height))
        .unwrap_or(whole);
    let (x0, y0) = (roi.x as u32, roi.y as u32);
    let [lo, hi] = options.depth_range.unwrap_or([0.0, f64::INFINITY]);
    let k = options.intrinsics;
    let mut points = Vec::new();
    let mut pixels = Vec::new();
    for v in y0..y0 + roi.height {
        for u in x0..x0 + roi.width {
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
            pixels.push((u, v));
        }
    }
    if points.is_empty() {
        return Err(CloudError::NoValidDepth);
    }
    Ok(crate::scene::table::Pixels {
        points,
        pixels,
        window: [x0, y0, roi.width, roi.height],
        field_of_view: crate::fit::FieldOfView::of_pixels(
            k.fx,
            k.fy,
            k.cx,
            k.cy,
            [x0, y0, roi.width, roi.height],
        ),
    })
}
