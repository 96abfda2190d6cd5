//! The commands on fitted objects: `grasps`, `surface`, `export`. Each reads the JSON
//! `supertoroid fit` printed (or a file of several: `{"objects": [...], "plane": ...}`,
//! as `supertoroid scene` prints it, each object's fit under `fit`).

use super::{Failure, internal};
use crate::grasp::{GraspOptions, Gripper, surface as query};
use crate::model::{FittedObject, Plane, Pose, Shape, parse_floats};
use clap::Args;
use glam::DVec3;
use std::path::{Path, PathBuf};

#[derive(Args, Debug)]
pub struct GraspArgs {
    /// the fit's JSON (`-` for standard input)
    pub fit: PathBuf,
    /// widest opening between the fingers
    #[arg(long, default_value_t = Gripper::FRANKA_LIKE.max_opening)]
    pub max_opening: f64,
    #[arg(long, default_value_t = 0.0)]
    pub min_opening: f64,
    /// finger length from the palm to the tip
    #[arg(long, default_value_t = Gripper::FRANKA_LIKE.finger_depth)]
    pub finger_depth: f64,
    /// finger size across the closing direction
    #[arg(long, default_value_t = Gripper::FRANKA_LIKE.finger_width)]
    pub finger_width: f64,
    /// finger size along the closing direction (default: a quarter of the depth)
    #[arg(long)]
    pub finger_thickness: Option<f64>,
    /// friction coefficient at the contacts
    #[arg(long, default_value_t = crate::grasp::DEFAULT_FRICTION)]
    pub friction: f64,
    #[arg(long, default_value_t = crate::grasp::DEFAULT_MAX_GRASPS)]
    pub max_grasps: usize,
    /// the table as nx,ny,nz,offset (n·x + offset = 0, n towards the objects)
    #[arg(long)]
    pub plane: Option<String>,
    /// the camera's position x,y,z (default: the fit's viewpoint, where it had one)
    #[arg(long)]
    pub viewpoint: Option<String>,
    /// also print GraspNet-1Billion rows
    #[arg(long)]
    pub graspnet: bool,
    /// the object of a file of several (a scene's `id`, else its place, from 0)
    #[arg(long)]
    pub object: Option<u64>,
}

#[derive(Args, Debug)]
pub struct SurfaceArgs {
    /// the fit's JSON (`-` for standard input)
    pub fit: PathBuf,
    /// a grid of the parameters, N_ETAxN_OMEGA
    #[arg(long, conflicts_with = "nearest")]
    pub grid: Option<String>,
    /// a cloud file: the surface points nearest to its points
    #[arg(long)]
    pub nearest: Option<PathBuf>,
    /// the object of a file of several (a scene's `id`, else its place, from 0)
    #[arg(long)]
    pub object: Option<u64>,
}

#[derive(Args, Debug)]
pub struct ExportArgs {
    /// fits' JSON files (each one fit, or `{"objects": [...], "plane": {...}}`)
    #[arg(required = true)]
    pub fits: Vec<PathBuf>,
    /// the table as nx,ny,nz,offset in the fits' frame (overrides a file's plane)
    #[arg(long)]
    pub plane: Option<String>,
    /// the world frame: the camera's position in it, x,y,z ...
    #[arg(long)]
    pub world_translation: Option<String>,
    /// ... and its orientation, w,x,y,z (world = R·camera + t)
    #[arg(long)]
    pub world_quaternion: Option<String>,
    /// density of the objects, kg/m³ (metres assumed)
    #[arg(long, default_value_t = crate::export::DEFAULT_DENSITY)]
    pub density: f64,
    #[arg(long, short)]
    pub out: PathBuf,
}

/// The objects (and plane, and the first fit's viewpoint) of a fits' JSON file.
struct FitsFile {
    objects: Vec<(Shape, Pose)>,
    /// each object's name in the file: a scene object's `id`, else its place
    ids: Vec<u64>,
    plane: Option<Plane>,
    viewpoint: Option<DVec3>,
}

fn read_fits(path: &Path) -> Result<FitsFile, Failure> {
    let bytes = crate::io::read_bytes(path).map_err(|e| Failure::input(e.to_string()))?;
    let what = |e: String| Failure::input(format!("{}: {e}", path.display()));
    let value: serde_json::Value =
        serde_json::from_slice(&bytes).map_err(|e| what(e.to_string()))?;
    let items: Vec<serde_json::Value> = match value.get("objects") {
        Some(serde_json::Value::Array(items)) => items.clone(),
        Some(_) => return Err(what("objects must be an array".into())),
        None => vec![value.clone()],
    };
    // a scene's object carries its fit under `fit` (none where it could not be fitted)
    let (ids, items): (Vec<u64>, Vec<&serde_json::Value>) = items
        .iter()
        .enumerate()
        .filter_map(|(place, item)| {
            let id = item
                .get("id")
                .and_then(|i| i.as_u64())
                .unwrap_or(place as u64);
            match (item.get("fit"), item.get("error")) {
                (Some(fit), _) => Some((id, fit)),
                (None, Some(_)) => None,
                (None, None) => Some((id, item)),
            }
        })
        .unzip();
    let mut objects = Vec::new();
    for item in &items {
        let object: FittedObject =
            serde_json::from_value((*item).clone()).map_err(|e| what(e.to_string()))?;
        objects.push(object.validated().map_err(what)?);
    }
    let plane = match value.get("plane") {
        Some(p) if !p.is_null() => Some(
            serde_json::from_value::<Plane>(p.clone())
                .map_err(|e| what(e.to_string()))?
                .validated()
                .map_err(what)?,
        ),
        _ => None,
    };
    let viewpoint = items
        .first()
        .and_then(|i| i.pointer("/viewpoint/position"))
        .and_then(|p| serde_json::from_value::<[f64; 3]>(p.clone()).ok())
        .map(DVec3::from_array);
    Ok(FitsFile {
        objects,
        ids,
        plane,
        viewpoint,
    })
}

fn parse_plane(text: &str) -> Result<Plane, Failure> {
    let [a, b, c, d] = parse_floats::<4>(text, "plane nx,ny,nz,offset").map_err(Failure::input)?;
    Plane {
        normal: [a, b, c],
        offset: d,
    }
    .validated()
    .map_err(Failure::input)
}

fn print_json(value: &impl serde::Serialize) -> Result<(), Failure> {
    println!("{}", serde_json::to_string_pretty(value).map_err(internal)?);
    Ok(())
}

/// The file's one object, or the one `object` names.
fn one_object(file: &FitsFile, path: &Path, object: Option<u64>) -> Result<(Shape, Pose), Failure> {
    match (object, file.objects.as_slice()) {
        (Some(id), objects) => file
            .ids
            .iter()
            .position(|&i| i == id)
            .map(|k| objects[k])
            .ok_or_else(|| {
                Failure::input(format!(
                    "{}: no fitted object {id} (it holds {:?})",
                    path.display(),
                    file.ids
                ))
            }),
        (None, [one]) => Ok(*one),
        (None, many) => Err(Failure::input(format!(
            "{}: holds {} objects; give one fit, or --object ID of {:?}",
            path.display(),
            many.len(),
            file.ids
        ))),
    }
}

pub fn grasps(args: GraspArgs) -> Result<(), Failure> {
    let file = read_fits(&args.fit)?;
    let (shape, pose) = one_object(&file, &args.fit, args.object)?;
    let options = GraspOptions {
        gripper: Gripper {
            max_opening: args.max_opening,
            min_opening: args.min_opening,
            finger_depth: args.finger_depth,
            finger_width: args.finger_width,
            finger_thickness: args.finger_thickness,
        },
        friction: Some(args.friction),
        max_grasps: Some(args.max_grasps),
        plane: args
            .plane
            .as_deref()
            .map(parse_plane)
            .transpose()?
            .or(file.plane),
        viewpoint: args
            .viewpoint
            .as_deref()
            .map(|v| parse_floats::<3>(v, "viewpoint x,y,z"))
            .transpose()
            .map_err(Failure::input)?,
        graspnet: Some(args.graspnet),
    };
    let out = options
        .plan(shape, pose, file.viewpoint)
        .map_err(Failure::input)?;
    print_json(&out)
}

pub fn surface(args: SurfaceArgs) -> Result<(), Failure> {
    let file = read_fits(&args.fit)?;
    let (shape, pose) = one_object(&file, &args.fit, args.object)?;
    let points = match (&args.grid, &args.nearest) {
        (Some(grid), None) => {
            let (n_eta, n_omega) = grid
                .split_once('x')
                .and_then(|(a, b)| Some((a.trim().parse::<usize>().ok()?, b.trim().parse::<usize>().ok()?)))
                .filter(|(a, b)| *a > 0 && *b > 0 && a * b <= crate::service::geometry::MAX_SURFACE_POINTS)
                .ok_or_else(|| Failure::input(format!("--grid {grid:?}: expected N_ETAxN_OMEGA, e.g. 16x32, at most 1,000,000 points")))?;
            query::grid(&shape, &pose, n_eta, n_omega)
        }
        (None, Some(cloud)) => {
            let cloud =
                crate::io::read_cloud(cloud, None).map_err(|e| Failure::input(e.to_string()))?;
            cloud
                .iter()
                .map(|p| query::nearest(&shape, &pose, *p))
                .collect::<Result<Vec<_>, _>>()
                .map_err(Failure::input)?
        }
        _ => return Err(Failure::input("give one of --grid and --nearest")),
    };
    print_json(&serde_json::json!({ "points": points }))
}

pub fn export(args: ExportArgs) -> Result<(), Failure> {
    let mut objects = Vec::new();
    let mut plane = None;
    for path in &args.fits {
        let file = read_fits(path)?;
        objects.extend(file.objects);
        plane = plane.or(file.plane);
    }
    if let Some(p) = &args.plane {
        plane = Some(parse_plane(p)?);
    }
    let world = match (&args.world_translation, &args.world_quaternion) {
        (None, None) => None,
        (t, q) => Some(Pose::parse(t.as_deref(), q.as_deref()).map_err(Failure::input)?),
    };
    let scene = crate::export::SceneExport::new(objects, plane, world, args.density)
        .map_err(Failure::input)?;
    let written = crate::export::write(&scene, &args.out).map_err(Failure::input)?;
    for path in written {
        eprintln!("wrote {}", path.display());
    }
    Ok(())
}
