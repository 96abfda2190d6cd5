//! `supertoroid scene`: a depth frame's table found and every object on it fitted, as
//! `POST /v1/scene` does; the scene's JSON on standard output (which `export` and
//! `grasps` read), and the objects' meshes on request.

use super::{Failure, internal, write_file};
use crate::eval::{Backend, make_evaluator};
use crate::fit::{FitOptions, Model};
use crate::io::ReadLimits;
use crate::io::depth::{self, DepthOptions, PinholeIntrinsics, Roi};
use crate::model::parse_floats;
use crate::scene::fit::{SceneFitError, fit_scene};
use crate::scene::objects::SceneOptions;
use clap::Args;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct SceneArgs {
    /// the depth frame: a 16-bit grayscale PNG
    pub depth: PathBuf,
    /// the camera's intrinsics fx,fy,cx,cy (pixels)
    #[arg(long)]
    pub intrinsics: String,
    /// metres per depth unit
    #[arg(long, default_value_t = depth::default_depth_scale())]
    pub depth_scale: f64,
    /// the workspace's pixel box x,y,width,height
    #[arg(long)]
    pub roi: Option<String>,
    /// a workspace mask PNG (non-zero keeps the pixel)
    #[arg(long)]
    pub mask: Option<PathBuf>,
    /// keep depths in min,max (scaled units)
    #[arg(long)]
    pub depth_range: Option<String>,
    /// the objects' model: auto (supertoroid or superellipsoid by BIC), supertoroid,
    /// superellipsoid
    #[arg(long, value_enum, default_value = "auto")]
    pub model: Model,
    #[arg(long, default_value_t = SceneOptions::default().min_points)]
    pub min_points: usize,
    /// the smallest object's half-diagonal (scaled units)
    #[arg(long, default_value_t = SceneOptions::default().min_size)]
    pub min_size: f64,
    /// the largest object's half-diagonal (scaled units)
    #[arg(long, default_value_t = SceneOptions::default().max_size)]
    pub max_size: f64,
    #[arg(long, default_value_t = SceneOptions::default().max_objects)]
    pub max_objects: usize,
    /// let each object's fit reach below the table (no free space under it; see
    /// `docs/scenes.md`)
    #[arg(long)]
    pub no_table_prior: bool,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// evaluator: auto, gpu, cpu
    #[arg(long, value_enum)]
    pub backend: Option<Backend>,
    /// also write each object's fitted surface as DIR/object-ID.ply
    #[arg(long)]
    pub meshes: Option<PathBuf>,
    /// also draw the scene into a PNG: each object's points and fitted surface in a colour
    /// of its own, from above the table, from the side and oblique (headless GPU context;
    /// lavapipe works)
    #[arg(long)]
    pub picture: Option<PathBuf>,
}

pub fn scene(args: SceneArgs) -> Result<(), Failure> {
    let [fx, fy, cx, cy] =
        parse_floats::<4>(&args.intrinsics, "intrinsics fx,fy,cx,cy").map_err(Failure::input)?;
    let roi = args
        .roi
        .as_deref()
        .map(|r| {
            let [x, y, w, h] = parse_floats::<4>(r, "roi x,y,width,height")?;
            if w < 1.0 || h < 1.0 {
                return Err("roi width and height must be at least 1".to_string());
            }
            Ok(Roi {
                x: x as i64,
                y: y as i64,
                width: w as u32,
                height: h as u32,
            })
        })
        .transpose()
        .map_err(Failure::input)?;
    let depth_range = args
        .depth_range
        .as_deref()
        .map(|r| parse_floats::<2>(r, "depth range min,max"))
        .transpose()
        .map_err(Failure::input)?;
    let read = |path: &PathBuf| {
        std::fs::read(path).map_err(|e| Failure::input(format!("{}: {e}", path.display())))
    };
    let limits = ReadLimits::default();
    let image = depth::decode_depth_png(&read(&args.depth)?, args.depth_scale, None, limits)
        .map_err(|e| Failure::input(e.to_string()))?;
    let mask = args
        .mask
        .as_ref()
        .map(|m| {
            depth::decode_mask_png(&read(m)?, image.width, image.height, limits)
                .map_err(|e| Failure::input(e.to_string()))
        })
        .transpose()?;
    let options = DepthOptions {
        intrinsics: PinholeIntrinsics { fx, fy, cx, cy },
        depth_scale: args.depth_scale,
        roi,
        depth_range,
    };
    let pixels = depth::back_project_pixels(&image, &options, mask.as_deref())
        .map_err(|e| Failure::input(e.to_string()))?;
    let scene_options = SceneOptions {
        min_points: args.min_points,
        min_size: args.min_size,
        max_size: args.max_size,
        max_objects: args.max_objects,
        table_prior: !args.no_table_prior,
    };
    let fit_options = FitOptions {
        seed: args.seed,
        model: args.model,
        ..Default::default()
    };
    let backend = args
        .backend
        .or_else(Backend::from_env)
        .unwrap_or(Backend::Auto);
    let mut evaluator =
        make_evaluator(backend, fit_options.stage2_points).map_err(|e| Failure {
            code: 1,
            message: e.to_string(),
        })?;
    let report = fit_scene(evaluator.as_mut(), &pixels, &scene_options, &fit_options).map_err(
        |e| match e {
            SceneFitError::Fit(crate::fit::FitError::Evaluator(m)) => Failure {
                code: 1,
                message: m,
            },
            other => Failure::input(other.to_string()),
        },
    )?;
    for object in &report.objects {
        for warning in object.fit.iter().flat_map(|f| &f.warnings) {
            eprintln!("warning: object {}: {warning}", object.id);
        }
        if let Some(error) = &object.error {
            eprintln!("warning: object {} not fitted: {error}", object.id);
        }
    }
    if let Some(dir) = &args.meshes {
        std::fs::create_dir_all(dir)
            .map_err(|e| Failure::input(format!("{}: {e}", dir.display())))?;
        for object in &report.objects {
            if let Some(fit) = &object.fit {
                let (shape, pose) = fit.fitted;
                let mesh = crate::io::mesh::tessellate(&shape, &pose, 64, 128);
                let path = dir.join(format!("object-{}.ply", object.id));
                write_file(&path, |out| crate::io::write_ply_mesh(out, &mesh))?;
                eprintln!("wrote {}", path.display());
            }
        }
    }
    if let Some(path) = &args.picture {
        let png = picture(&report).map_err(|e| Failure::input(format!("picture: {e}")))?;
        write_file(path, |out| {
            out.extend_from_slice(&png);
            Ok(())
        })?;
        eprintln!("wrote {}", path.display());
    }
    println!(
        "{}",
        serde_json::to_string_pretty(&report).map_err(internal)?
    );
    Ok(())
}

/// The scene drawn: the fitted objects' points in their object's colour, and their
/// surfaces.
fn picture(report: &crate::scene::fit::SceneReport) -> Result<Vec<u8>, String> {
    let (mut points, mut owners, mut fits) = (Vec::new(), Vec::new(), Vec::new());
    for object in &report.objects {
        let Some(fit) = &object.fit else { continue };
        points.extend_from_slice(&object.cloud);
        owners.extend(std::iter::repeat_n(fits.len(), object.cloud.len()));
        fits.push(fit.fitted);
    }
    crate::render::render_png(
        &crate::render::Scene {
            points: &points,
            fit: None,
            objects: Some(crate::render::SceneObjects {
                fits: &fits,
                owners: &owners,
                up: report.plane.normal(),
            }),
        },
        400,
    )
}
