//! The `supertoroid` command line. Bad input gives one clear line on stderr and exit
//! code 2; internal failures exit 1.

use crate::eval::{Backend, Normalization, make_evaluator};
use crate::io::{Format, read_cloud, write_cloud};
use crate::model::{Pose, Shape, meridian_distance};
use crate::synth::{self, Camera, Intrinsics};
use clap::{Args, Parser, Subcommand};
use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

mod objects;
mod scene;

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
    /// Example: supertoroid fit mug.pcd --seed 3 --backend cpu --mesh fitted.ply
    ///
    /// Formats: .pcd (ascii, binary, binary_compressed), .ply (ascii, binary), .xyz / .txt
    /// / .csv text, .raw float32 triples; `-` reads standard input (format sniffed, or
    /// --format).
    Fit(FitArgs),
    /// Write a supertoroid as a binary PLY triangle mesh with normals, from --shape (and
    /// --translation, --quaternion) or from the JSON that `fit` printed.
    ///
    /// Example: supertoroid fit mug.pcd > fit.json && supertoroid mesh --fit fit.json -o mug.ply
    Mesh(MeshArgs),
    /// Run the HTTP fitting service (POST /v1/fit, /v1/fit/depth, /v1/fit/batch, /v1/scene,
    /// /v1/grasps, /v1/surface; GET
    /// /healthz, /readyz, /metrics, /openapi.json). Every flag also reads its
    /// SUPERTOROID_* environment variable.
    ///
    /// Example: supertoroid serve --bind 0.0.0.0:8080
    Serve(crate::service::ServiceConfig),
    /// Benchmarks: the paper's clouds (its Table II), the ground-truth suite, evaluator
    /// scaling. Each writes JSON, CSV and a markdown report into --out.
    ///
    /// Example: supertoroid bench paper ../shared/clouds/paper --out bench-results
    Bench(BenchArgs),
    /// Draw a cloud with its fitted surface from three views (along the hole axis, side,
    /// oblique) into a PNG, headless on the GPU context (lavapipe works). Points are
    /// coloured by distance to the fit: blue on the surface, red at 5% of the size.
    ///
    /// Example: supertoroid render mug.pcd -o mug.png   (fits first; or --fit fit.json)
    Render(RenderArgs),
    /// Plan parallel-jaw grasps on a fit (the JSON `fit` printed) and print them as JSON,
    /// best first (the gripper defaults to a Franka-Hand-like one, in metres).
    ///
    /// Example: supertoroid grasps fit.json --max-opening 0.08 --plane 0,0,1,0 --graspnet
    Grasps(objects::GraspArgs),
    /// Print points of a fit's surface with normals, principal curvatures and directions
    /// as JSON: on a grid, or nearest to the points of a cloud file.
    ///
    /// Example: supertoroid surface fit.json --grid 16x32
    Surface(objects::SurfaceArgs),
    /// Write fitted objects for simulators and planners: OBJ and STL meshes, an MJCF
    /// scene for MuJoCo and a URDF, into --out.
    ///
    /// Example: supertoroid export fit.json --plane 0,0,1,0 --out scene/
    Export(objects::ExportArgs),
    /// Find the table in a depth frame and fit every object on it (supertoroid or
    /// superellipsoid, chosen by BIC), as POST /v1/scene does; print the scene as JSON
    /// (poses in the camera's optical frame), which `export` and `grasps` read.
    ///
    /// Example: supertoroid scene frame.png --intrinsics 615,615,320,240 --meshes objects/ > scene.json
    Scene(scene::SceneArgs),
}

#[derive(Args, Debug)]
pub struct RenderArgs {
    #[command(flatten)]
    pub input: InputArgs,
    /// the fit to draw (JSON of `supertoroid fit`); without it the cloud is fitted first
    #[arg(long, conflicts_with = "no_fit")]
    pub fit: Option<PathBuf>,
    /// draw the points only
    #[arg(long)]
    pub no_fit: bool,
    /// pixels per view (the image is 3 views wide)
    #[arg(long, default_value_t = 400)]
    pub size: u32,
    /// output .png
    #[arg(short, long)]
    pub output: PathBuf,
}

#[derive(Args, Debug)]
pub struct BenchArgs {
    #[command(subcommand)]
    pub which: BenchCommand,
    /// directory for `<name>.json`, `<name>.csv` and `<name>.md`
    #[arg(long, global = true, default_value = "bench-results")]
    pub out: PathBuf,
    /// evaluator for the fits (paper, synthetic, broad): auto, gpu, cpu
    #[arg(long, global = true, value_enum)]
    pub backend: Option<Backend>,
    /// draw pictures (paper: each cloud with its seed-0 fit; synthetic: up to six failed
    /// cases) into DIR, relative to --out unless absolute; the report embeds them
    #[arg(long, global = true)]
    pub render: Option<PathBuf>,
    /// pipeline for the fits (paper, synthetic, broad): default (the search) or paper
    #[arg(long, global = true, value_enum, default_value = "default")]
    pub method: crate::fit::Method,
    /// model of the fits: as `fit --model` (default: as `fit`; auto for `models`, `scenes`
    /// and `boxes`)
    #[arg(long, global = true, value_enum)]
    pub model: Option<crate::fit::Model>,
    /// the fits' time budget in milliseconds (paper, synthetic, broad; see `fit --time-budget-ms`)
    #[arg(long, global = true)]
    pub time_budget_ms: Option<f64>,
    /// leave these optional stages of the fit out (paper, synthetic, broad), comma-separated:
    /// for ablations, each stage's gain against its time
    #[arg(long, global = true, value_enum, value_delimiter = ',')]
    pub skip: Vec<crate::fit::ablation::Stage>,
}

#[derive(Subcommand, Debug)]
pub enum BenchCommand {
    /// Fit every cloud in DIR --runs times with different downsampling seeds; Good /
    /// Decent / Bad by the rule in the report; the paper's row beside ours.
    Paper {
        dir: PathBuf,
        #[arg(long, default_value_t = 10)]
        runs: usize,
        /// the fits' viewpoint: `none` (the default) as the paper fitted its clouds, or
        /// `auto` as `fit` does (these clouds are views from their frame's origin)
        #[arg(long, default_value = "none")]
        viewpoint: String,
    },
    /// The ground-truth suite: --cases seeded synthetic clouds over 18 categories (full /
    /// partial x noise x outliers); success rates and error distributions.
    Synthetic {
        #[arg(long, default_value_t = 180)]
        cases: usize,
        /// first seed of a set of --cases cases; a comma-separated list runs each set and
        /// reports them together (e.g. 10000,20000,30000)
        #[arg(long, value_delimiter = ',', default_values_t = [crate::bench::synthetic::DEFAULT_SEED])]
        seed: Vec<u64>,
        /// do not tell the fit where the camera of a single-view case was (by default it
        /// gets the camera's position, as a depth frame gives it)
        #[arg(long, conflicts_with = "camera_frame")]
        no_viewpoint: bool,
        /// give the clouds as a user posts them, with no viewpoint option: a single view in
        /// its camera's frame (the fit must find the view itself), a full cloud as drawn
        #[arg(long)]
        camera_frame: bool,
        /// also refine each case from its true parameters with the fit's own estimator
        /// and report how many land within the tolerances: the ceiling of any search
        /// (about 0.1 s more per noisy case)
        #[arg(long)]
        from_truth: bool,
    },
    /// The ground-truth suite's cases fitted with every optional stage of the fit and
    /// without each in turn, interleaved: what each stage gains and costs.
    Ablation {
        #[arg(long, default_value_t = 180)]
        cases: usize,
        #[arg(long, value_delimiter = ',', default_values_t = [crate::bench::synthetic::DEFAULT_SEED])]
        seed: Vec<u64>,
        /// how the clouds reach the fit
        #[arg(long, value_enum, default_value = "camera")]
        presentation: crate::bench::synthetic::Presentation,
        /// the stages to leave out one at a time (default: all)
        #[arg(long, value_enum, value_delimiter = ',')]
        stages: Vec<crate::fit::ablation::Stage>,
    },
    /// The ground-truth suite's cases fitted, the best grasp planned on each fit and
    /// checked on the true surface (contacts within 2 mm, antipodal there).
    Grasps {
        #[arg(long, default_value_t = 180)]
        cases: usize,
        #[arg(long, default_value_t = crate::bench::synthetic::DEFAULT_SEED)]
        seed: u64,
    },
    /// Single views beyond the suite (its ranges, tall rolls, thin washers, oval rings)
    /// through a D435-like sensor, as users post them: success per family, warnings, and
    /// whose each miss is (the search's or the estimator's).
    Broad {
        #[arg(long, default_value_t = 80)]
        cases: usize,
        #[arg(long, default_value_t = 2_000_000)]
        seed: u64,
    },
    /// Model choice on a mixed suite: half supertoroids with a hole, half
    /// superellipsoids, as users post them; fitted with `--model` (default auto here).
    Models {
        #[arg(long, default_value_t = 72)]
        cases: usize,
        #[arg(long, default_value_t = crate::bench::synthetic::DEFAULT_SEED)]
        seed: u64,
    },
    /// Synthetic table-top frames (3-6 objects, with a hole and without, a D435-like
    /// sensor), segmented and fitted as `/v1/scene` does.
    Scenes {
        #[arg(long, default_value_t = 20)]
        frames: usize,
        #[arg(long, default_value_t = crate::bench::synthetic::DEFAULT_SEED)]
        seed: u64,
    },
    /// The objects of `scenes`' frames fitted as `/v1/fit/depth` fits them from a
    /// detector's box (the table in it taken away) and from a segmenter's mask: each
    /// against the truth, and the two against each other.
    Boxes {
        #[arg(long, default_value_t = 20)]
        frames: usize,
        #[arg(long, default_value_t = crate::bench::synthetic::DEFAULT_SEED)]
        seed: u64,
    },
    /// Time per solver iteration against points and candidates, per backend.
    Scaling {
        /// comma-separated point counts
        #[arg(long, default_value = "1000,10000,100000,1000000")]
        points: String,
        /// comma-separated candidate counts
        #[arg(long, default_value = "1,8,64")]
        candidates: String,
        /// comma-separated backends (cpu, gpu)
        #[arg(long, default_value = "cpu,gpu")]
        backends: String,
        /// seconds per cell
        #[arg(long, default_value_t = 2.0)]
        budget: f64,
    },
}

/// The cloud a command reads.
#[derive(Args, Debug)]
pub struct InputArgs {
    /// input cloud; `-` reads standard input
    pub file: PathBuf,
    /// input format (default: from the extension, else sniffed from the content)
    #[arg(long, value_enum)]
    pub format: Option<Format>,
}

impl InputArgs {
    fn read(&self) -> Result<Vec<glam::DVec3>, Failure> {
        read_cloud(&self.file, self.format)
            .map_err(|e| Failure::input(format!("{}: {e}", self.file.display())))
    }

    /// The cloud and the viewpoint its file states (a PCD header's `VIEWPOINT`), else
    /// `Auto`.
    fn read_with_viewpoint(&self) -> Result<(Vec<glam::DVec3>, crate::fit::Viewpoint), Failure> {
        let failed =
            |e: crate::io::CloudError| Failure::input(format!("{}: {e}", self.file.display()));
        let bytes = crate::io::read_bytes(&self.file).map_err(failed)?;
        let format = self.format.or_else(|| Format::from_extension(&self.file));
        let points = crate::io::parse_cloud(&bytes, format, Default::default()).map_err(failed)?;
        Ok((points, crate::io::pcd::header_viewpoint(&bytes, format)))
    }
}

#[derive(Args, Debug)]
pub struct MeshArgs {
    /// a1,a2,a3,a4,eps1,eps2 (or use --fit)
    #[arg(long, allow_hyphen_values = true, conflicts_with = "fit")]
    pub shape: Option<String>,
    #[arg(long, allow_hyphen_values = true, requires = "shape")]
    pub translation: Option<String>,
    /// w,x,y,z
    #[arg(long, allow_hyphen_values = true, requires = "shape")]
    pub quaternion: Option<String>,
    /// the JSON object `supertoroid fit` printed (`-` for stdin)
    #[arg(long)]
    pub fit: Option<PathBuf>,
    /// steps around the cross-section (eta) and around the hole axis (omega)
    #[arg(long, default_value_t = 64)]
    pub rings: usize,
    #[arg(long, default_value_t = 128)]
    pub segments: usize,
    /// output .ply
    #[arg(short, long)]
    pub output: PathBuf,
}

#[derive(Args, Debug)]
pub struct FitArgs {
    #[command(flatten)]
    pub input: InputArgs,
    /// seed of the random downsampling
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// evaluator: auto (GPU when found), gpu, cpu; default from SUPERTOROID_BACKEND, else auto
    #[arg(long, value_enum)]
    pub backend: Option<Backend>,
    /// known hole axis x,y,z in the cloud's frame (e.g. 0,0,1 for "on a table, hole up")
    #[arg(long, allow_hyphen_values = true)]
    pub axis: Option<String>,
    /// pipeline: default (one bounded search on the noise model) or paper (the paper's
    /// procedure as a baseline; see the README)
    #[arg(long, value_enum, default_value = "default")]
    pub method: crate::fit::Method,
    /// model: supertoroid (a4 free: a hole or none), superellipsoid (a4 = 0), or auto
    /// (both fitted, the lower BIC chosen; the report says both)
    #[arg(long, value_enum, default_value_t = crate::fit::FitOptions::default().model)]
    pub model: crate::fit::Model,
    /// known section half-height a3 in the cloud's units (held fixed): one view cannot
    /// tell how thick an object is
    #[arg(long)]
    pub a3: Option<f64>,
    /// known shape parameters, held fixed: name=value pairs, e.g. a1=0.05,a4=2.1 (sizes in
    /// the cloud's units; a product's dimensions)
    #[arg(long)]
    pub known: Option<String>,
    /// where the depth sensor was: x,y,z in the cloud's frame, `none` for a view from
    /// nowhere (a merged all-round cloud), or `auto` (the default): a PCD header's
    /// VIEWPOINT, else the frame's origin where the cloud is a view from it (as sensors
    /// write clouds), else none. The fit keeps solid out of the space the sensor saw
    /// through
    #[arg(long, allow_hyphen_values = true)]
    pub viewpoint: Option<String>,
    /// time budget in milliseconds: no likelihood step of the search or the polish is
    /// taken past it; the least-squares rounds always complete (default: no budget)
    #[arg(long)]
    pub time_budget_ms: Option<f64>,
    /// also write the fitted surface as a PLY mesh with normals
    #[arg(long)]
    pub mesh: Option<PathBuf>,
    /// also write the input points coloured by their distance to the fit (blue 0, red at
    /// 5% of the size or more) as PLY, with the distance as a property
    #[arg(long)]
    pub residuals: Option<PathBuf>,
    /// write the JSON here instead of standard output
    #[arg(short, long)]
    pub output: Option<PathBuf>,
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
    /// viewpoint chosen by the seed; the camera's position goes to stderr as the
    /// `--viewpoint` to give `fit`
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
    #[command(flatten)]
    pub input: InputArgs,
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
        Command::Mesh(args) => mesh(args),
        Command::Serve(config) => serve(config),
        Command::Bench(args) => bench(args),
        Command::Render(args) => render(args),
        Command::Grasps(args) => objects::grasps(args),
        Command::Scene(args) => scene::scene(args),
        Command::Surface(args) => objects::surface(args),
        Command::Export(args) => objects::export(args),
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
        let eye = camera.pose.translation;
        eprintln!("camera at --viewpoint {},{},{}", eye.x, eye.y, eye.z);
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
    let points = args.input.read()?;
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
        let mut evaluator = make_evaluator(backend, points.len()).map_err(|e| Failure {
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
    let (points, header_viewpoint) = args.input.read_with_viewpoint()?;
    let known_axis = match &args.axis {
        Some(a) => Some(glam::DVec3::from_array(
            crate::model::parse_floats::<3>(a, "axis x,y,z").map_err(Failure::input)?,
        )),
        None => None,
    };
    let viewpoint = match &args.viewpoint {
        Some(v) => crate::fit::viewpoint::parse(v).map_err(Failure::input)?,
        None => header_viewpoint,
    };
    let options = crate::fit::FitOptions {
        seed: args.seed,
        known_axis,
        known_shape: args
            .known
            .as_deref()
            .map_or(Ok([None; 6]), crate::fit::parse_known_shape)
            .and_then(|known| crate::fit::known_with_a3(known, args.a3))
            .map_err(Failure::input)?,
        viewpoint,
        method: args.method,
        model: args.model,
        time_budget_ms: args.time_budget_ms,
        ..Default::default()
    };
    let backend = args
        .backend
        .or_else(Backend::from_env)
        .unwrap_or(Backend::Auto);
    let work = options.stage2_points.min(points.len());
    let mut evaluator = make_evaluator(backend, work).map_err(|e| Failure {
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
    for warning in &report.warnings {
        eprintln!("warning: {warning}");
    }
    let (shape, pose) = report.fitted;
    if let Some(path) = &args.mesh {
        let mesh = crate::io::mesh::tessellate(&shape, &pose, 64, 128);
        write_file(path, |out| crate::io::write_ply_mesh(out, &mesh))?;
    }
    if let Some(path) = &args.residuals {
        let distances: Vec<f64> = points
            .iter()
            .map(|p| meridian_distance(&shape, pose.to_canonical(*p)).distance)
            .collect();
        write_file(path, |out| {
            crate::io::write_ply_residuals(out, &points, &distances, 0.05 * shape.size())
        })?;
    }
    let json = serde_json::to_string_pretty(&report).map_err(internal)?;
    match &args.output {
        Some(path) => write_file(path, |out| writeln!(out, "{json}")),
        None => {
            println!("{json}");
            Ok(())
        }
    }
}

pub(crate) fn internal(e: impl std::fmt::Display) -> Failure {
    Failure {
        code: 1,
        message: e.to_string(),
    }
}

pub(crate) fn write_file(
    path: &std::path::Path,
    write: impl FnOnce(&mut Vec<u8>) -> std::io::Result<()>,
) -> Result<(), Failure> {
    let mut buf = Vec::new();
    write(&mut buf).map_err(internal)?;
    std::fs::write(path, buf).map_err(|e| Failure::input(format!("{}: {e}", path.display())))
}

/// Shape and pose from the JSON `supertoroid fit` printed (`-` for stdin).
fn read_fit_json(path: &std::path::Path) -> Result<(Shape, Pose), Failure> {
    let bytes = crate::io::read_bytes(path).map_err(|e| Failure::input(e.to_string()))?;
    crate::fit::parse_report_json(&bytes)
        .map_err(|e| Failure::input(format!("{}: {e}", path.display())))
}

fn mesh(args: MeshArgs) -> Result<(), Failure> {
    let (shape, pose) = match (&args.shape, &args.fit) {
        (Some(shape), None) => ShapePoseArgs {
            shape: shape.clone(),
            translation: args.translation.clone(),
            quaternion: args.quaternion.clone(),
        }
        .parse()
        .map_err(Failure::input)?,
        (None, Some(path)) => read_fit_json(path)?,
        _ => return Err(Failure::input("give either --shape or --fit")),
    };
    if !(3..=4096).contains(&args.rings) || !(3..=4096).contains(&args.segments) {
        return Err(Failure::input("--rings and --segments must be in 3..=4096"));
    }
    let mesh = crate::io::mesh::tessellate(&shape, &pose, args.rings, args.segments);
    write_file(&args.output, |out| crate::io::write_ply_mesh(out, &mesh))
}

fn serve(config: crate::service::ServiceConfig) -> Result<(), Failure> {
    config.validate().map_err(Failure::input)?;
    crate::service::init_logging(config.log_format);
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .map_err(internal)?;
    runtime
        .block_on(crate::service::serve(config))
        .map_err(|e| Failure::input(format!("serve: {e}")))
}

fn parse_list(text: &str, what: &str) -> Result<Vec<usize>, Failure> {
    text.split(',')
        .map(|t| {
            t.trim()
                .parse::<usize>()
                .ok()
                .filter(|&v| v > 0)
                .ok_or_else(|| Failure::input(format!("{what}: {t:?} is not a positive integer")))
        })
        .collect()
}

fn bench(args: BenchArgs) -> Result<(), Failure> {
    use crate::bench::{Report, write_report};
    let backend = args
        .backend
        .or_else(Backend::from_env)
        .unwrap_or(Backend::Auto);
    let options = crate::fit::FitOptions {
        method: args.method,
        model: args
            .model
            .unwrap_or(crate::fit::FitOptions::default().model),
        skip: args.skip.clone(),
        time_budget_ms: args.time_budget_ms,
        ..Default::default()
    };
    // (the benches of objects with and without a hole choose the model unless told)
    let auto = crate::fit::FitOptions {
        model: args.model.unwrap_or(crate::fit::Model::Auto),
        ..options.clone()
    };
    let render = args
        .render
        .as_ref()
        .map(|dir| crate::bench::RenderTarget::new(&args.out, dir, 300));
    let write = |report: &dyn Fn(&std::path::Path) -> std::io::Result<Vec<PathBuf>>, md: String| {
        let paths = report(&args.out)
            .map_err(|e| Failure::input(format!("{}: {e}", args.out.display())))?;
        println!("{md}");
        for p in paths {
            eprintln!("wrote {}", p.display());
        }
        Ok(())
    };
    match &args.which {
        BenchCommand::Paper {
            dir,
            runs,
            viewpoint,
        } => {
            let options = crate::fit::FitOptions {
                viewpoint: crate::fit::viewpoint::parse(viewpoint).map_err(Failure::input)?,
                ..options
            };
            let r = crate::bench::paper::run(dir, *runs, backend, &options, render.as_ref())
                .map_err(Failure::input)?;
            write(&|d| write_report(d, &r), r.markdown())
        }
        BenchCommand::Synthetic {
            cases,
            seed,
            no_viewpoint,
            camera_frame,
            from_truth,
        } => {
            use crate::bench::synthetic::Presentation;
            let presentation = match (*no_viewpoint, *camera_frame) {
                (true, _) => Presentation::NoViewpoint,
                (_, true) => Presentation::Camera,
                _ => Presentation::Viewpoint,
            };
            let r = crate::bench::synthetic::run(
                *cases,
                seed,
                presentation,
                *from_truth,
                backend,
                &options,
                render.as_ref(),
            )
            .map_err(Failure::input)?;
            write(&|d| write_report(d, &r), r.markdown())
        }
        BenchCommand::Ablation {
            cases,
            seed,
            presentation,
            stages,
        } => {
            let r =
                crate::bench::ablation::run(*cases, seed, *presentation, stages, backend, &options)
                    .map_err(Failure::input)?;
            write(&|d| write_report(d, &r), r.markdown())
        }
        BenchCommand::Grasps { cases, seed } => {
            let r = crate::bench::grasps::run(*cases, *seed, backend).map_err(Failure::input)?;
            write(&|d| write_report(d, &r), r.markdown())
        }
        BenchCommand::Broad { cases, seed } => {
            let r = crate::bench::broad::run(*cases, *seed, backend, &options)
                .map_err(Failure::input)?;
            write(&|d| write_report(d, &r), r.markdown())
        }
        BenchCommand::Models { cases, seed } => {
            let r =
                crate::bench::models::run(*cases, *seed, backend, &auto).map_err(Failure::input)?;
            write(&|d| write_report(d, &r), r.markdown())
        }
        BenchCommand::Scenes { frames, seed } => {
            let r = crate::bench::scenes::run(*frames, *seed, backend, &auto)
                .map_err(Failure::input)?;
            write(&|d| write_report(d, &r), r.markdown())
        }
        BenchCommand::Boxes { frames, seed } => {
            let r =
                crate::bench::boxes::run(*frames, *seed, backend, &auto).map_err(Failure::input)?;
            write(&|d| write_report(d, &r), r.markdown())
        }
        BenchCommand::Scaling {
            points,
            candidates,
            backends,
            budget,
        } => {
            if !(budget.is_finite() && *budget > 0.0) {
                return Err(Failure::input("--budget must be positive"));
            }
            let o = crate::bench::scaling::ScalingOptions {
                points: parse_list(points, "--points")?,
                candidates: parse_list(candidates, "--candidates")?,
                backends: backends.split(',').map(|b| b.trim().to_owned()).collect(),
                budget: *budget,
                ..Default::default()
            };
            let r = crate::bench::scaling::run(&o).map_err(Failure::input)?;
            write(&|d| write_report(d, &r), r.markdown())
        }
    }
}

fn render(args: RenderArgs) -> Result<(), Failure> {
    let points = args.input.read()?;
    let fit = if args.no_fit {
        None
    } else if let Some(path) = &args.fit {
        Some(read_fit_json(path)?)
    } else {
        let report = crate::fit::fit(
            &mut crate::eval::CpuEvaluator::new(),
            &points,
            &Default::default(),
        )
        .map_err(|e| Failure::input(e.to_string()))?;
        Some(report.fitted)
    };
    let png = crate::render::render_png(
        &crate::render::Scene {
            points: &points,
            fit,
            objects: None,
        },
        args.size,
    )
    .map_err(|e| Failure::input(format!("render: {e}")))?;
    write_file(&args.output, |out| {
        out.extend_from_slice(&png);
        Ok(())
    })
}
