//! Every cloud parser on arbitrary bytes: errors are fine, panics are not. The parsers
//! are called directly, not through `parse_cloud`'s panic guard.
#![no_main]
use libfuzzer_sys::fuzz_target;
use supertoroid::io::ReadLimits;

fuzz_target!(|data: &[u8]| {
    let limits = ReadLimits { max_points: 1_000_000 };
    let _ = supertoroid::io::pcd::parse_pcd(data, limits);
    let _ = supertoroid::io::ply::parse_ply(data, limits);
    let _ = supertoroid::io::xyz::parse_xyz_bytes(data, limits);
    let _ = supertoroid::io::raw::parse_raw_f32(data, limits);
});
