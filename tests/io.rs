//! Readers and writers: the paper's real clouds, round trips of every writer/reader pair,
//! depth frames, malformed input, and property tests that feed random and mutated bytes
//! to every parser.

use glam::DVec3;
use proptest::prelude::*;
use std::io::Cursor;
use std::path::PathBuf;
use supertoroid::io::depth::{self, DepthOptions, PinholeIntrinsics, Roi};
use supertoroid::io::pcd::{PcdData, PcdHeader, parse_pcd, write_pcd};
use supertoroid::io::{CloudError, Format, ReadLimits, parse_cloud};
use supertoroid::model::{Pose, Shape, meridian_distance};
use supertoroid::synth::{self, Camera, Intrinsics};

fn paper(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/clouds/paper")
        .join(name)
}

const PAPER_CLOUDS: [&str; 4] = [
    "gearclean.pcd",
    "pot2clean.pcd",
    "perfectnoisedisplaced.pcd",
    "roll.pcd",
];

fn read_paper(name: &str) -> Vec<u8> {
    std::fs::read(paper(name)).unwrap_or_else(|e| {
        panic!(
            "{}: {e} (the paper's clouds live in ../shared/clouds/paper)",
            paper(name).display()
        )
    })
}

fn limits() -> ReadLimits {
    ReadLimits::default()
}

#[test]
fn every_paper_cloud_loads_with_its_header_point_count() {
    for name in PAPER_CLOUDS {
        let bytes = read_paper(name);
        let header = PcdHeader::scan(&bytes, limits()).unwrap();
        let points = parse_cloud(&bytes, None, limits()).unwrap();
        assert_eq!(points.len() as u64, header.points, "{name}");
        assert!(points.iter().all(|p| p.is_finite()), "{name}");
        // a real object, not zeros: tens of centimetres or less, spread in 3D
        let (lo, hi) = points
            .iter()
            .fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(lo, hi), p| {
                (lo.min(*p), hi.max(*p))
            });
        assert!((hi - lo).min_element() > 0.0, "{name}: {lo} {hi}");
        eprintln!(
            "{name}: {} points, {} data, extent {}",
            points.len(),
            header.data,
            hi - lo
        );
    }
    let kinds: Vec<String> = PAPER_CLOUDS
        .iter()
        .map(|n| PcdHeader::scan(&read_paper(n), limits()).unwrap().data)
        .collect();
    assert!(
        kinds.contains(&"ascii".to_string()) && kinds.contains(&"binary_compressed".to_string())
    );
}

fn resave(points: &[DVec3], data: PcdData, double: bool) -> Vec<DVec3> {
    let mut out = Cursor::new(Vec::new());
    write_pcd(&mut out, points, data, double).unwrap();
    parse_pcd(out.get_ref(), limits()).unwrap()
}

#[test]
fn compressed_binary_and_ascii_saves_give_the_same_numbers() {
    // gear: binary_compressed F4 with rgb and normals; re-saved as ascii, binary and
    // binary_compressed it must read back identically (f32 values print exactly)
    let gear = parse_pcd(&read_paper("gearclean.pcd"), limits()).unwrap();
    for data in [PcdData::Ascii, PcdData::Binary, PcdData::BinaryCompressed] {
        assert_eq!(resave(&gear, data, false), gear, "{data:?}");
    }
    // the synthetic cloud: ascii F8
    let synthetic = parse_pcd(&read_paper("perfectnoisedisplaced.pcd"), limits()).unwrap();
    for data in [PcdData::Binary, PcdData::BinaryCompressed, PcdData::Ascii] {
        assert_eq!(resave(&synthetic, data, true), synthetic, "{data:?}");
    }
}

fn sample_points() -> Vec<DVec3> {
    let shape = Shape::new(0.05, 0.04, 0.02, 2.0, 0.7, 1.3);
    let pose = Pose::new(
        glam::DQuat::from_rotation_x(0.4),
        DVec3::new(0.1, -0.2, 0.7),
    );
    synth::sample_surface(&shape, &pose, 500, &mut synth::rng(1))
}

/// f32 storage: equal after rounding each coordinate to f32.
fn as_f32(points: &[DVec3]) -> Vec<DVec3> {
    points
        .iter()
        .map(|p| DVec3::new(p.x as f32 as f64, p.y as f32 as f64, p.z as f32 as f64))
        .collect()
}

#[test]
fn every_writer_reads_back_through_its_reader() {
    let points = sample_points();
    let dir = std::env::temp_dir().join(format!("supertoroid-io-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    for (ext, exact) in [
        ("xyz", true),
        ("ply", false),
        ("pcd", false),
        ("raw", false),
    ] {
        let path = dir.join(format!("cloud.{ext}"));
        supertoroid::io::write_cloud(&path, &points).unwrap();
        let back = supertoroid::io::read_cloud(&path, None).unwrap();
        let expected = if exact {
            points.clone()
        } else {
            as_f32(&points)
        };
        assert_eq!(back, expected, "{ext}");
        // and sniffed without the extension's help
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(
            parse_cloud(&bytes, None, limits()).unwrap(),
            expected,
            "{ext} sniffed"
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// A PLY written by hand in any encoding and coordinate type, with extra properties and
/// a face element after the vertices.
fn handmade_ply(points: &[DVec3], encoding: &str, coord: &str) -> Vec<u8> {
    let mut out = format!(
        "ply\nformat {encoding} 1.0\ncomment handmade\nelement vertex {}\nproperty {coord} x\nproperty uchar red\nproperty {coord} y\nproperty {coord} z\nproperty float nx\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n",
        points.len()
    )
    .into_bytes();
    let big = encoding == "binary_big_endian";
    let num = |out: &mut Vec<u8>, v: f64| match (encoding, coord) {
        ("ascii", _) => out.extend_from_slice(format!("{v} ").as_bytes()),
        (_, "double") if big => out.extend_from_slice(&v.to_be_bytes()),
        (_, "double") => out.extend_from_slice(&v.to_le_bytes()),
        _ if big => out.extend_from_slice(&(v as f32).to_be_bytes()),
        _ => out.extend_from_slice(&(v as f32).to_le_bytes()),
    };
    for p in points {
        num(&mut out, p.x);
        if encoding == "ascii" {
            out.extend_from_slice(b"7 ");
        } else {
            out.push(7);
        }
        num(&mut out, p.y);
        num(&mut out, p.z);
        if encoding == "ascii" {
            out.extend_from_slice(b"0.5\n");
        } else if big {
            out.extend_from_slice(&0.5f32.to_be_bytes());
        } else {
            out.extend_from_slice(&0.5f32.to_le_bytes());
        }
    }
    if encoding == "ascii" {
        out.extend_from_slice(b"3 0 1 2\n");
    } else {
        out.push(3);
        for i in [0i32, 1, 2] {
            out.extend_from_slice(&if big {
                i.to_be_bytes()
            } else {
                i.to_le_bytes()
            });
        }
    }
    out
}

#[test]
fn ply_reads_ascii_little_and_big_endian_float_and_double() {
    let points = sample_points();
    for encoding in ["ascii", "binary_little_endian", "binary_big_endian"] {
        for coord in ["float", "double"] {
            let bytes = handmade_ply(&points, encoding, coord);
            let back = parse_cloud(&bytes, Some(Format::Ply), limits())
                .unwrap_or_else(|e| panic!("{encoding} {coord}: {e}"));
            let expected = if coord == "double" {
                points.clone()
            } else {
                as_f32(&points)
            };
            assert_eq!(back.len(), points.len());
            for (a, b) in back.iter().zip(&expected) {
                assert!(
                    (*a - *b).abs().max_element() <= 1e-12 * (1.0 + b.length()),
                    "{encoding} {coord}: {a} vs {b}"
                );
            }
        }
    }
}

#[test]
fn xyz_csv_with_header_and_raw_float32() {
    let csv = "x,y,z,intensity\n1,2,3,9\n4.5,-6,7e-1,9\n";
    assert_eq!(
        parse_cloud(csv.as_bytes(), None, limits()).unwrap(),
        vec![DVec3::new(1.0, 2.0, 3.0), DVec3::new(4.5, -6.0, 0.7)]
    );
    let mut raw = Vec::new();
    for v in [
        1.0f32,
        2.0,
        3.0,
        f32::NAN,
        f32::NAN,
        f32::NAN,
        -1.0,
        0.5,
        0.25,
    ] {
        raw.extend_from_slice(&v.to_le_bytes());
    }
    // NaN triples are "no return" in ROS clouds and are dropped
    assert_eq!(
        parse_cloud(&raw, Some(Format::Raw), limits()).unwrap(),
        vec![DVec3::new(1.0, 2.0, 3.0), DVec3::new(-1.0, 0.5, 0.25)]
    );
}

/// A known supertoroid seen by a RealSense-like camera (0.1 mm depth units).
fn rendered_frame() -> (Shape, Pose, Camera, supertoroid::synth::DepthImage) {
    let shape = Shape::new(0.06, 0.05, 0.025, 1.8, 0.8, 1.0);
    let pose = Pose::new(
        glam::DQuat::from_rotation_x(0.3),
        DVec3::new(0.02, -0.01, 0.6),
    );
    let camera = Camera::look_at(
        Intrinsics::REALSENSE_640X480,
        DVec3::new(0.0, -0.25, 0.25),
        pose.translation,
        DVec3::Z,
    );
    let view = synth::render_view(&shape, &pose, &camera, 0.0001).unwrap();
    (shape, pose, camera, view.depth)
}

fn options_of(camera: &Camera, scale: f64) -> DepthOptions {
    let k = camera.intrinsics;
    DepthOptions {
        intrinsics: PinholeIntrinsics {
            fx: k.fx,
            fy: k.fy,
            cx: k.cx,
            cy: k.cy,
        },
        depth_scale: scale,
        roi: None,
        depth_range: None,
    }
}

#[test]
fn a_rendered_depth_png_back_projects_onto_the_surface() {
    let (shape, pose, camera, image) = rendered_frame();
    let png = depth::encode_depth_png(&image);
    let decoded = depth::decode_depth_png(&png, image.scale, Some((640, 480)), limits()).unwrap();
    assert_eq!(decoded, image);
    let cloud = depth::back_project(&decoded, &options_of(&camera, image.scale), None).unwrap();
    assert!(cloud.len() > 1000, "{} points", cloud.len());
    let worst = cloud
        .iter()
        .map(|c| meridian_distance(&shape, pose.to_canonical(camera.pose.to_world(*c))).distance)
        .fold(0.0, f64::max);
    // 0.1 mm depth quantisation, seen at grazing angles
    assert!(
        worst < 0.002 * shape.size() + 2e-4,
        "worst distance {worst}"
    );

    // raw u16 gives the same cloud; ROI, mask and range select subsets
    let raw: Vec<u8> = image.data.iter().flat_map(|v| v.to_le_bytes()).collect();
    let from_raw = depth::decode_depth_raw(&raw, 640, 480, image.scale, limits()).unwrap();
    assert_eq!(from_raw, image);
    let mut opts = options_of(&camera, image.scale);
    opts.roi = Some(Roi {
        x: 0,
        y: 0,
        width: 320,
        height: 480,
    });
    let left = depth::back_project(&image, &opts, None).unwrap();
    // a detector's box reaching past the image is clipped to it: the same pixels
    opts.roi = Some(Roi {
        x: -50,
        y: -10,
        width: 370,
        height: 600,
    });
    assert_eq!(depth::back_project(&image, &opts, None).unwrap(), left);
    assert!(left.len() < cloud.len() && left.iter().all(|p| p.x < 0.0 + 1e-9 || p.z > 0.0));
    let mask: Vec<bool> = (0..640 * 480).map(|i| i % 640 >= 320).collect();
    let right =
        depth::back_project(&image, &options_of(&camera, image.scale), Some(&mask)).unwrap();
    assert_eq!(left.len() + right.len(), cloud.len());
    let mut opts = options_of(&camera, image.scale);
    let zs: Vec<f64> = cloud.iter().map(|p| p.z).collect();
    let mid = zs.iter().sum::<f64>() / zs.len() as f64;
    opts.depth_range = Some([0.0, mid]);
    let near = depth::back_project(&image, &opts, None).unwrap();
    assert!(near.len() < cloud.len() && near.iter().all(|p| p.z <= mid));
}

#[test]
fn fitting_a_rendered_depth_frame_recovers_the_object() {
    let (shape, pose, camera, image) = rendered_frame();
    let cloud = depth::back_project(&image, &options_of(&camera, image.scale), None).unwrap();
    // world frame, to compare with the ground truth
    let world: Vec<DVec3> = cloud.iter().map(|c| camera.pose.to_world(*c)).collect();
    let mut evaluator = supertoroid::eval::CpuEvaluator::new();
    let report = supertoroid::fit::fit(&mut evaluator, &world, &Default::default()).unwrap();
    let e = supertoroid::suite::ground_truth::compare(
        (&shape, &pose),
        (&report.fitted.0, &report.fitted.1),
    );
    assert!(e.success(), "{e:?}");
}

fn expect_malformed(result: Result<Vec<DVec3>, CloudError>, what: &str) -> String {
    match result {
        Ok(p) => panic!("{what}: accepted {} points", p.len()),
        Err(e) => {
            let m = e.to_string();
            assert!(!m.is_empty());
            eprintln!("{what}: {m}");
            m
        }
    }
}

#[test]
fn malformed_clouds_are_errors_that_name_the_problem() {
    let gear = read_paper("gearclean.pcd");
    let header_end = PcdHeader::scan(&gear, limits()).unwrap().data_offset;
    // truncated at every region: header, block sizes, compressed data
    for cut in [
        10,
        header_end - 3,
        header_end + 5,
        header_end + 100,
        gear.len() - 1,
    ] {
        expect_malformed(
            parse_cloud(&gear[..cut], Some(Format::Pcd), limits()),
            &format!("gear cut at {cut}"),
        );
    }
    let text = String::from_utf8_lossy(&gear[..header_end]).into_owned();
    let body = &gear[header_end..];
    let with_header = |h: String| [h.into_bytes(), body.to_vec()].concat();
    let m = expect_malformed(
        parse_cloud(
            &with_header(text.replace("POINTS 2445", "POINTS 2444")),
            None,
            limits(),
        ),
        "POINTS mismatch",
    );
    assert!(m.contains("WIDTH"), "{m}");
    let m = expect_malformed(
        parse_cloud(
            &with_header(text.replace("TYPE F F F U", "TYPE F F F Q")),
            None,
            limits(),
        ),
        "unknown type",
    );
    assert!(m.contains("unknown field type"), "{m}");
    // corrupt LZF: damage the compressed stream's control bytes
    let mut corrupt = gear.clone();
    for i in (header_end + 8..corrupt.len()).step_by(7) {
        corrupt[i] = 0xff;
    }
    expect_malformed(
        parse_cloud(&corrupt, Some(Format::Pcd), limits()),
        "corrupt LZF",
    );
    // a huge claimed count is refused before any allocation
    let m = expect_malformed(
        parse_cloud(
            &with_header(
                text.replace("WIDTH 2445", "WIDTH 4000000000")
                    .replace("POINTS 2445", "POINTS 4000000000"),
            ),
            None,
            limits(),
        ),
        "huge count",
    );
    assert!(m.contains("too many points"), "{m}");
    // NaN / Inf
    let m = expect_malformed(parse_cloud(b"1 2 3\n4 inf 6\n", None, limits()), "inf");
    assert!(m.contains("non-finite"), "{m}");
    expect_malformed(parse_cloud(b"1 2 3\nnan 5 6\n", None, limits()), "nan");
    let pcd_inf = b"VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 1\nHEIGHT 1\nPOINTS 1\nDATA ascii\n1 inf 2\n";
    expect_malformed(parse_cloud(pcd_inf, None, limits()), "pcd inf");
    // empty input, a header without points, wrong shapes
    assert_eq!(parse_cloud(b"", None, limits()), Err(CloudError::Empty));
    expect_malformed(
        parse_cloud(b"\n\n# nothing\n", Some(Format::Xyz), limits()),
        "blank xyz",
    );
    expect_malformed(parse_cloud(b"1 2\n", None, limits()), "two columns");
    expect_malformed(
        parse_cloud(&[0u8; 13], Some(Format::Raw), limits()),
        "raw length",
    );
    expect_malformed(parse_cloud(b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nend_header\n1 2\n3 4\n", None, limits()), "ply without z");
    expect_malformed(parse_cloud(b"ply\nformat binary_little_endian 1.0\nelement vertex 100\nproperty float x\nproperty float y\nproperty float z\nend_header\n\x00\x00", None, limits()), "truncated ply");
    let mut organised = b"VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 2\nHEIGHT 2\nPOINTS 4\nDATA ascii\n".to_vec();
    organised.extend_from_slice(b"1 2 3\nnan nan nan\n4 5 6\nnan nan nan\n");
    // an organised cloud's NaN points are dropped, the rest kept
    assert_eq!(parse_cloud(&organised, None, limits()).unwrap().len(), 2);
}

#[test]
fn bad_depth_frames_and_intrinsics_are_errors() {
    let (_, _, camera, image) = rendered_frame();
    let png = depth::encode_depth_png(&image);
    // wrong size
    let e = depth::decode_depth_png(&png, 0.001, Some((640, 400)), limits()).unwrap_err();
    assert!(e.to_string().contains("expected 640x400"), "{e}");
    // 8-bit PNG
    let mut eight = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut eight, 4, 4);
        enc.set_color(png::ColorType::Grayscale);
        enc.set_depth(png::BitDepth::Eight);
        enc.write_header()
            .unwrap()
            .write_image_data(&[9u8; 16])
            .unwrap();
    }
    let e = depth::decode_depth_png(&eight, 0.001, None, limits()).unwrap_err();
    assert!(e.to_string().contains("16-bit grayscale"), "{e}");
    // truncated and garbage PNGs
    assert!(depth::decode_depth_png(&png[..png.len() / 2], 0.001, None, limits()).is_err());
    assert!(depth::decode_depth_png(b"not a png", 0.001, None, limits()).is_err());
    // raw of the wrong length
    assert!(depth::decode_depth_raw(&[0u8; 11], 2, 3, 0.001, limits()).is_err());
    // intrinsics and options
    for (fx, scale) in [(0.0, 0.001), (f64::NAN, 0.001), (615.0, 0.0), (615.0, -1.0)] {
        let mut opts = options_of(&camera, scale);
        opts.intrinsics.fx = fx;
        let e = depth::back_project(&image, &opts, None).unwrap_err();
        assert_eq!(e.code(), "invalid_depth_options", "{e}");
    }
    let mut opts = options_of(&camera, 0.001);
    opts.roi = Some(Roi {
        x: 700,
        y: 0,
        width: 100,
        height: 10,
    });
    let e = depth::back_project(&image, &opts, None).unwrap_err();
    assert_eq!(e.code(), "invalid_depth_options");
    // in words, not in the code's syntax
    assert!(
        e.to_string().contains("x 700 y 0 width 100 height 10") && !e.to_string().contains('{'),
        "{e}"
    );
    // all-zero depth
    let zero = supertoroid::synth::DepthImage {
        data: vec![0; image.data.len()],
        ..image.clone()
    };
    assert_eq!(
        depth::back_project(&zero, &options_of(&camera, 0.001), None),
        Err(CloudError::NoValidDepth)
    );
}

fn mutate(mut bytes: Vec<u8>, edits: &[(usize, u8)], cut: Option<usize>) -> Vec<u8> {
    if bytes.is_empty() {
        return bytes;
    }
    for &(i, v) in edits {
        let n = bytes.len();
        bytes[i % n] = v;
    }
    if let Some(c) = cut {
        bytes.truncate(c % (bytes.len() + 1));
    }
    bytes
}

fn every_parser(bytes: &[u8]) {
    // each parser directly (not through parse_cloud's panic guard): none may panic
    let l = ReadLimits {
        max_points: 100_000,
    };
    let _ = parse_pcd(bytes, l);
    let _ = supertoroid::io::ply::parse_ply(bytes, l);
    let _ = supertoroid::io::xyz::parse_xyz_bytes(bytes, l);
    let _ = supertoroid::io::raw::parse_raw_f32(bytes, l);
    let _ = depth::decode_depth_png(bytes, 0.001, None, l);
    let _ = depth::decode_mask_png(bytes, 8, 8, l);
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 200, .. ProptestConfig::default() })]

    #[test]
    fn random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..600)) {
        every_parser(&bytes);
    }

    #[test]
    fn mutated_real_files_never_panic(
        which in 0usize..5,
        edits in proptest::collection::vec((any::<usize>(), any::<u8>()), 0..6),
        cut in proptest::option::of(any::<usize>()),
    ) {
        let (_, _, _, image) = rendered_frame_small();
        let original = match which {
            0 => read_paper("gearclean.pcd"),
            1 => read_paper("perfectnoisedisplaced.pcd")[..4000].to_vec(),
            2 => handmade_ply(&sample_points()[..20], "binary_big_endian", "double"),
            3 => handmade_ply(&sample_points()[..20], "ascii", "float"),
            _ => depth::encode_depth_png(&image),
        };
        every_parser(&mutate(original, &edits, cut));
    }
}

fn rendered_frame_small() -> ((), (), (), supertoroid::synth::DepthImage) {
    let data = (0..64u16).map(|i| i * 1000).collect();
    (
        (),
        (),
        (),
        supertoroid::synth::DepthImage {
            width: 8,
            height: 8,
            scale: 0.001,
            data,
        },
    )
}

/// Masks come as datasets ship them: 1-bit grayscale (GraspNet and others), 8- and
/// 16-bit; each keeps the same pixels. A colour mask is refused in words.
#[test]
fn masks_of_one_eight_and_sixteen_bits_keep_the_same_pixels() {
    let (w, h) = (13u32, 5u32);
    let keep = |x: u32, y: u32| (x + 2 * y) % 3 == 0;
    let encode = |depth: png::BitDepth, color: png::ColorType, row: &dyn Fn(u32) -> Vec<u8>| {
        let mut out = Vec::new();
        let mut encoder = png::Encoder::new(&mut out, w, h);
        encoder.set_color(color);
        encoder.set_depth(depth);
        let mut writer = encoder.write_header().unwrap();
        let data: Vec<u8> = (0..h).flat_map(|y| row(y)).collect();
        writer.write_image_data(&data).unwrap();
        drop(writer);
        out
    };
    let one_bit = encode(png::BitDepth::One, png::ColorType::Grayscale, &|y| {
        (0..w.div_ceil(8))
            .map(|byte| {
                (0..8).fold(0u8, |acc, bit| {
                    let x = byte * 8 + bit;
                    acc | (((x < w && keep(x, y)) as u8) << (7 - bit))
                })
            })
            .collect()
    });
    let eight = encode(png::BitDepth::Eight, png::ColorType::Grayscale, &|y| {
        (0..w).map(|x| if keep(x, y) { 255 } else { 0 }).collect()
    });
    let sixteen = encode(png::BitDepth::Sixteen, png::ColorType::Grayscale, &|y| {
        (0..w)
            .flat_map(|x| if keep(x, y) { [0, 1] } else { [0, 0] })
            .collect()
    });
    let expected: Vec<bool> = (0..h)
        .flat_map(|y| (0..w).map(move |x| keep(x, y)))
        .collect();
    for (name, png) in [("1-bit", one_bit), ("8-bit", eight), ("16-bit", sixteen)] {
        let mask = depth::decode_mask_png(&png, w, h, limits()).unwrap();
        assert_eq!(mask, expected, "{name}");
    }
    let rgb = encode(png::BitDepth::Eight, png::ColorType::Rgb, &|_| {
        vec![0; 3 * w as usize]
    });
    let e = depth::decode_mask_png(&rgb, w, h, limits()).unwrap_err();
    assert_eq!(e.code(), "malformed_image");
    assert!(e.to_string().contains("8-bit RGB"), "{e}");
}

/// A PCD header's `VIEWPOINT` off the origin says where the sensor was; at the origin
/// (what PCL writes whether or not it knows) it says nothing, and neither does another
/// format.
#[test]
fn a_pcd_header_viewpoint_off_the_origin_is_where_the_sensor_was() {
    use supertoroid::fit::{Viewpoint, ViewpointSource};
    use supertoroid::io::pcd::header_viewpoint;
    let pcd = |viewpoint: &str| {
        format!(
            "VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 1\nHEIGHT 1\n\
             VIEWPOINT {viewpoint}\nPOINTS 1\nDATA ascii\n1 2 3\n"
        )
        .into_bytes()
    };
    let stated = pcd("0.1 -0.2 0.3 1 0 0 0");
    assert_eq!(parse_cloud(&stated, None, limits()).unwrap().len(), 1);
    assert_eq!(
        header_viewpoint(&stated, None),
        Viewpoint::At(DVec3::new(0.1, -0.2, 0.3), ViewpointSource::PcdHeader)
    );
    assert_eq!(
        header_viewpoint(&pcd("0 0 0 1 0 0 0"), None),
        Viewpoint::Auto
    );
    assert_eq!(
        header_viewpoint(&pcd("nan 0 0 1 0 0 0"), None),
        Viewpoint::Auto
    );
    assert_eq!(header_viewpoint(b"1 2 3\n4 5 6\n", None), Viewpoint::Auto);
}

/// Intrinsics that do not fit the image: a principal point outside it is refused, focal
/// lengths far from a depth camera's are noted.
#[test]
fn intrinsics_that_disagree_with_the_image_are_refused_or_noted() {
    let k = PinholeIntrinsics {
        fx: 615.0,
        fy: 615.0,
        cx: 320.0,
        cy: 240.0,
    };
    assert_eq!(depth::intrinsics_note(&k, 640, 480), None);
    // fx and cx swapped
    let swapped = PinholeIntrinsics {
        fx: 320.0,
        cx: 615.0,
        ..k
    };
    assert_eq!(depth::intrinsics_note(&swapped, 640, 480), None);
    let tiny = PinholeIntrinsics { fx: 50.0, ..k };
    assert!(depth::intrinsics_note(&tiny, 640, 480).is_some_and(|n| n.contains("fx 50")));
    let options = |k: PinholeIntrinsics| DepthOptions {
        intrinsics: k,
        depth_scale: 0.001,
        roi: None,
        depth_range: None,
    };
    assert!(options(swapped).validate(640, 480).is_ok());
    let outside = PinholeIntrinsics { cx: 700.0, ..k };
    let e = options(outside).validate(640, 480).unwrap_err();
    assert_eq!(e.code(), "invalid_depth_options");
    assert!(e.to_string().contains("principal point"), "{e}");
}
