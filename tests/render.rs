//! `supertoroid render`: a PNG of the right size whose pixels show the object, drawn by
//! the project's wgpu context (lavapipe in CI).

use std::process::Command;

fn decode(path: &std::path::Path) -> (u32, u32, Vec<u8>) {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!(info.color_type, png::ColorType::Rgb);
    buf.truncate(info.buffer_size());
    (info.width, info.height, buf)
}

fn render(extra: &[&str], out: &std::path::Path) {
    let cloud = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../shared/clouds/paper/roll.pcd"
    );
    let o = Command::new(env!("CARGO_BIN_EXE_supertoroid"))
        .args([
            "render",
            cloud,
            "--size",
            "120",
            "-o",
            out.to_str().unwrap(),
        ])
        .args(extra)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

#[test]
fn render_draws_the_cloud_and_its_fit_in_three_views() {
    let dir = std::env::temp_dir().join(format!("supertoroid-render-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let with_fit = dir.join("roll.png");
    render(&[], &with_fit);
    let (w, h, rgb) = decode(&with_fit);
    assert_eq!((w, h), (360, 120));
    let pixels: Vec<[u8; 3]> = rgb.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect();
    let background = pixels.iter().filter(|p| **p == [255, 255, 255]).count();
    let drawn = pixels.len() - background;
    assert!(
        drawn > pixels.len() / 20,
        "only {drawn} of {} pixels drawn",
        pixels.len()
    );
    assert!(background > pixels.len() / 4, "no background left");
    // every view shows something
    for view in 0..3 {
        let in_view = pixels
            .iter()
            .enumerate()
            .filter(|(i, p)| (*i as u32 % w) / 120 == view && **p != [255, 255, 255])
            .count();
        assert!(in_view > 200, "view {view}: {in_view} pixels");
    }
    // points on the surface are blue (the residual colour map), the mesh grey-blue
    let pure_blue = pixels
        .iter()
        .filter(|p| p[2] > 200 && p[0] < 40 && p[1] < 80)
        .count();
    let shaded = pixels
        .iter()
        .filter(|p| p[0] > 20 && p[2] > p[0] && p[1] > p[0] && p[2] < 230)
        .count();
    assert!(pure_blue > 100, "{pure_blue} point pixels");
    assert!(shaded > 100, "{shaded} mesh pixels");

    // the cloud alone: orange points, no mesh
    let points_only = dir.join("points.png");
    render(&["--no-fit"], &points_only);
    let (_, _, rgb) = decode(&points_only);
    let orange = rgb
        .chunks_exact(3)
        .filter(|p| p[0] > 200 && p[2] < 80)
        .count();
    assert!(orange > 200, "{orange} orange pixels");
}
