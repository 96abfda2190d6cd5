//! The `supertoroid` command line. Bad input gives one clear line on stderr and exit
//! code 2; internal failures exit 1.

use crate::eval::{Backend, Normalization, make_evaluator};
use crate::io::{read_cloud, write_cloud};
use crate::model::{Pose, Shape, meridian_distance};
use crate::synth::{self, Camera, Intrinsics};
use clap::{Args, Parser, Subcommand};
use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Parser, Debug)]
#[command(name = "supertoroid", version, about = "Fit supertoroids to 3D point clouds", long_about = None)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Write a synthetic cloud sampled from a known supertoroid.
    ///
    /// Example: supertoroid sample --shape 0.05,0.05,0.02,2,1,1 --points 2000 --view --noise 0.01 -o mug.xyz
    Sample(SampleArgs),
    /// Print the meridian radial distance of every point of FILE to a supertoroid, one
    /// per line, in input order.
    ///
    /// Example: supertoroid distance --shape 0.05,0.05,0.02,2,1,1 mug.xyz
    Distance(DistanceArgs),
    /// Fit a supertoroid to a cloud and print the result as one JSON object (shape, pose,
    /// quality, timing, iterations, backend, points; see the README).
    ///
    /// Example: supertoroid fit mug.xyz --seed 3 --backend cpu
    Fit(FitArgs),
}

#[derive(Args, Debug)]
pub struct FitArgs {
    /// input cloud (.xyz)
    pub file: PathBuf,
    /// seed of the random downsampling
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// evaluator: auto (GPU when found), gpu, cpu; default from SUPERTOROID_BACKEND, else auto
    #[arg(long, value_enum)]
    pub backend: Option<Backend>,
    /// points in stage 1 / stage 2 (the paper's 150 / 1000)
    #[arg(long, default_value_t = 150)]
    pub stage1_points: usize,
    #[arg(long, default_value_t = 1000)]
    pub stage2_points: usize,
    /// known hole axis x,y,z in the cloud's frame (e.g. 0,0,1 for "on a table, hole up")
    #[arg(long, allow_hyphen_values = true)]
    pub axis: Option<String>,
}

/// Shape and pose of a supertoroid, as the CLI takes them.
#[derive(Args, Debug, Clone)]
pub struct ShapePoseArgs {
    /// a1,a2,a3,a4,eps1,eps2 (sizes in the cloud's units; a4 = 0 is a superellipsoid)
    #[arg(long, allow_hyphen_values = true)]
    pub shape: String,
    /// x,y,z of the canonical origin in the world
    #[arg(long, allow_hyphen_values = true)]
    pub translation: Option<String>,
    /// w,x,y,z rotation (canonical to world; normalised)
    #[arg(long, allow_hyphen_values = true)]
    pub quaternion: Option<String>,
}

impl ShapePoseArgs {
    fn parse(&self) -> Result<(Shape, Pose), String> {
        Ok((
            Shape::parse(&self.shape)?,
            Pose::parse(self.translation.as_deref(), self.quaternion.as_deref())?,
        ))
    }
}

#[derive(Args, Debug)]
pub struct SampleArgs {
    #[command(flatten)]
    pub object: ShapePoseArgs,
    /// number of points (with --view: at most this many of the visible ones)
    #[arg(long, default_value_t = 2000)]
    pub points: usize,
    /// keep only what one pinhole camera (640x480, RealSense-like) sees from a random
    /// viewpoint chosen by the seed
    #[arg(long)]
    pub view: bool,
    /// Gaussian noise sigma as a fraction of the object size (bounding-box half-diagonal)
    #[arg(long, default_value_t = 0.0)]
    pub noise: f64,
    /// fraction of the output that is uniform outliers in the object's bounding box
    #[arg(long, default_value_t = 0.0)]
    pub outliers: f64,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// output file: .xyz (text) or .ply (binary)
    #[arg(short, long)]
    pub output: PathBuf,
}

#[derive(Args, Debug)]
pub struct DistanceArgs {
    #[command(flatten)]
    pub object: ShapePoseArgs,
    /// evaluator: cpu (f64 reference), gpu (WGSL; fails without an adapter), auto (GPU
    /// when found); default from SUPERTOROID_BACKEND, else cpu
    #[arg(long, value_enum)]
    pub backend: Option<Backend>,
    /// input cloud (.xyz)
    pub file: PathBuf,
}

/// A failure with its exit code: 2 for bad input, 1 for everything else.
pub struct Failure {
    pub code: u8,
    pub message: String,
}

impl Failure {
    pub fn input(message: impl Into<String>) -> Self {
        Self {
            code: 2,
            message: message.into(),
        }
    }
}

pub fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => {
            let code = if e.use_stderr() { 2 } else { 0 };
            let _ = e.print();
            return ExitCode::from(code);
        }
    };
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(f) => {
            eprintln!("error: {}", f.message);
            ExitCode::from(f.code)
        }
    }
}

pub fn run(cli: Cli) -> Result<(), Failure> {
    match cli.command {
        Command::Sample(args) => sample(args),
        Command::Distance(args) => distance(args),
        Command::Fit(args) => fit(args),
    }
}

fn sample(args: SampleArgs) -> Result<(), Failure> {
    let (shape, pose) = args.object.parse().map_err(Failure::input)?;
    if args.points == 0 {
        return Err(Failure::input("--points must be at least 1"));
    }
    if !(0.0..=0.5).contains(&args.noise) {
        return Err(Failure::input("--noise must be in [0, 0.5]"));
    }
    if !(0.0..0.95).contains(&args.outliers) {
        return Err(Failure::input("--outliers must be in [0, 0.95)"));
    }
    let mut rng = synth::rng(args.seed);
    let mut points = if args.view {
        let camera = Camera::random_view(&shape, &pose, Intrinsics::REALSENSE_640X480, &mut rng);
        let view = synth::render_view(&shape, &pose, &camera, 0.0001).map_err(Failure::input)?;
        if view.points.is_empty() {
            return Err(Failure::input("the camera sees no part of the object"));
        }
        synth::subsample(&view.points, args.points, &mut rng)
    } else {
        synth::sample_surface(&shape, &pose, args.points, &mut rng)
    };
    synth::add_noise(&mut points, args.noise * shape.size(), &mut rng);
    synth::add_outliers(&mut points, &shape, &pose, args.outliers, &mut rng);
    write_cloud(&args.output, &points).map_err(|e| Failure::input(e.to_string()))
}

fn distance(args: DistanceArgs) -> Result<(), Failure> {
    let (shape, pose) = args.object.parse().map_err(Failure::input)?;
    let points = read_cloud(&args.file)
        .map_err(|e| Failure::input(format!("{}: {e}", args.file.display())))?;
    let backend = args
        .backend
        .or_else(Backend::from_env)
        .unwrap_or(Backend::Cpu);
    let distances: Vec<f64> = if backend == Backend::Cpu {
        points
            .iter()
            .map(|p| meridian_distance(&shape, pose.to_canonical(*p)).distance)
            .collect()
    } else {
        let mut evaluator = make_evaluator(backend).map_err(|e| Failure {
            code: 1,
            message: e.to_string(),
        })?;
        let norm = Normalization::of(&points);
        evaluator
            .set_points(&norm.points(&points))
            .map_err(|e| Failure {
                code: 1,
                message: e.to_string(),
            })?;
        let r = evaluator
            .residuals(&[norm.candidate(&shape, &pose)])
            .map_err(|e| Failure {
                code: 1,
                message: e.to_string(),
            })?;
        r.into_iter().map(|r| (r * norm.scale).abs()).collect()
    };
    let stdout = std::io::stdout();
    let mut out = std::io::BufWriter::new(stdout.lock());
    for d in distances {
        writeln!(out, "{d}").map_err(|e| Failure {
            code: 1,
            message: e.to_string(),
        })?;
    }
    out.flush().map_err(|e| Failure {
        code: 1,
        message: e.to_string(),
    })
}

fn fit(args: FitArgs) -> Result<(), Failure> {
    let points = read_cloud(&args.file)
        .map_err(|e| Failure::input(format!("{}: {e}", args.file.display())))?;
    let known_axis = match &args.axis {
        Some(a) => Some(glam::DVec3::from_array(
            crate::model::parse_floats::<3>(a, "axis x,y,z").map_err(Failure::input)?,
        )),
        None => None,
    };
    let options = crate::fit::FitOptions {
        seed: args.seed,
        stage1_points: args.stage1_points,
        stage2_points: args.stage2_points,
        known_axis,
        ..Default::default()
    };
    let backend = args
        .backend
        .or_else(Backend::from_env)
        .unwrap_or(Backend::Auto);
    let mut evaluator = make_evaluator(backend).map_err(|e| Failure {
        code: 1,
        message: e.to_string(),
    })?;
    let report = crate::fit::fit(evaluator.as_mut(), &points, &options).map_err(|e| match e {
        crate::fit::FitError::Evaluator(m) => Failure {
            code: 1,
            message: m,
        },
        other => Failure::input(other.to_string()),
    })?;
    println!(
        "{}",
        serde_json::to_string_pretty(&report).map_err(|e| Failure {
            code: 1,
            message: e.to_string()
        })?
    );
    Ok(())
}
