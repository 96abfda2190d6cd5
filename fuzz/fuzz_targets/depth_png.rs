//! Depth and mask PNG decoding on arbitrary bytes.
#![no_main]
use libfuzzer_sys::fuzz_target;
use supertoroid::io::ReadLimits;
use supertoroid::io::depth;

fuzz_target!(|data: &[u8]| {
    let limits = ReadLimits { max_points: 4_000_000 };
    if let Ok(image) = depth::decode_depth_png(data, 0.001, None, limits) {
        let _ = depth::decode_mask_png(data, image.width, image.height, limits);
    }
});
