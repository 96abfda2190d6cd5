//! Synthetic table-top scenes (`supertoroid bench scenes`): frames of 3-6 objects, with a
//! hole and without, resting on a table and rendered by the project's camera with a
//! D435-like sensor model ([`crate::synth::scene`]), segmented and fitted as
//! `/v1/scene` does. Per object: found (a segment whose pixels are mostly its), and right
//! (the true model chosen and the fit within the model-choice suite's rule); per frame:
//! phantoms (segments mostly of table or nothing), duplicates (a second segment of one
//! object) and the time of the whole scene.

use super::{Report, percentile};
use crate::eval::{Backend, make_evaluator};
use crate::fit::{FitOptions, FitReport, Model};
use crate::io::depth::{DepthOptions, PinholeIntrinsics, back_project_pixels};
use crate::model::{Pose, Shape};
use crate::scene::fit::fit_scene;
use crate::scene::objects::SceneOptions;
use crate::scene::table::Pixels;
use crate::suite::chamfer::{CHAMFER_BOUND, relative_chamfer};
use crate::suite::ground_truth::compare;
use crate::synth::scene::{
    FIRST_OBJECT, RenderedScene, TableScene, random_table_scene, render_scene, with_sensor_noise,
};
use crate::synth::{Camera, DepthImage, render_view};
use serde::Serialize;

/// The sensor model of the suite: 1 mm of depth noise at 0.5 m (growing with the range
/// squared), 1 mm quantisation, flying pixels at a third of the silhouette edges.
pub const NOISE_AT_HALF_METRE: f64 = 0.001;
pub const FLYING_SHARE: f64 = 0.3;
/// An object with at least this share of its silhouette in the frame counts as wholly
/// in it; the rest the frame's edge cuts, and what lies past the edge no camera saw.
pub const WHOLLY_IN_FRAME: f64 = 0.9;

#[derive(Clone, Debug, Serialize)]
pub struct SceneObjectCase {
    pub frame: u64,
    pub holed: bool,
    /// pixels the object shows in the frame
    pub visible_pixels: usize,
    /// it shows at least the fewest points an object keeps ([`SceneOptions::min_points`]):
    /// the rest (out of the frame, or hidden behind others) cannot be found and are left
    /// out of the rates
    pub in_view: bool,
    /// the share of its whole silhouette (as a camera without the frame's edges would
    /// see it alone) that lies in the frame: under [`WHOLLY_IN_FRAME`] the edge cuts it
    pub in_frame: f64,
    pub found: bool,
    pub model_right: bool,
    pub success: bool,
    pub chamfer: f64,
    /// its fit carries a warning
    pub warned: bool,
}

#[derive(Clone, Debug, Serialize)]
pub struct SceneFrame {
    pub seed: u64,
    pub objects: usize,
    pub segments: usize,
    /// segments mostly of table or nothing
    pub phantoms: usize,
    /// further segments of an object that has one already (an object split in two by
    /// another in front of it): a second, made-up object to the robot
    pub duplicates: usize,
    pub total_ms: f64,
    pub segment_ms: f64,
}

#[derive(Clone, Debug, Serialize)]
pub struct ScenesReport {
    pub machine: super::Machine,
    pub frames: Vec<SceneFrame>,
    pub objects: Vec<SceneObjectCase>,
}

/// One frame of the benchmark: its scene (the truth), the rendered depth and labels, and
/// the noisy depth's pixels back-projected as `/v1/scene` reads them.
pub struct BenchFrame {
    pub scene: TableScene,
    pub rendered: RenderedScene,
    /// the depth as the sensor gives it (noise, quantisation, flying pixels)
    pub depth: DepthImage,
    pub depth_options: DepthOptions,
    pub pixels: Pixels,
}

impl BenchFrame {
    /// Frame `seed`: 3-6 objects (3 + seed mod 4), the sensor model above.
    pub fn new(seed: u64) -> Result<Self, String> {
        let scene = random_table_scene(seed, 3 + (seed % 4) as usize);
        let rendered = render_scene(&scene, 0.001)?;
        let depth = with_sensor_noise(&rendered.depth, NOISE_AT_HALF_METRE, FLYING_SHARE, seed);
        let k = scene.camera.intrinsics;
        let options = DepthOptions {
            intrinsics: PinholeIntrinsics {
                fx: k.fx,
                fy: k.fy,
                cx: k.cx,
                cy: k.cy,
            },
            depth_scale: depth.scale,
            roi: None,
            depth_range: None,
        };
        let pixels = back_project_pixels(&depth, &options, None).map_err(|e| e.to_string())?;
        Ok(Self {
            scene,
            rendered,
            depth,
            depth_options: options,
            pixels,
        })
    }

    /// The object most of `pixels` show, if an object is what most of them show.
    pub fn owner(&self, pixels: &[(u32, u32)]) -> Option<usize> {
        majority_object(
            pixels,
            &self.rendered.labels,
            self.scene.camera.intrinsics.width,
        )
    }

    /// Object `i`'s shape and its pose in the camera's optical frame, where fits are.
    pub fn truth(&self, i: usize) -> (Shape, Pose) {
        let (shape, pose) = self.scene.objects[i];
        let camera = &self.scene.camera.pose;
        (
            shape,
            Pose::new(
                camera.rotation.inverse() * pose.rotation,
                camera.to_canonical(pose.translation),
            ),
        )
    }
}

pub fn run(
    frames: usize,
    seed: u64,
    backend: Backend,
    base: &FitOptions,
) -> Result<ScenesReport, String> {
    if frames == 0 {
        return Err("--frames must be at least 1".into());
    }
    let mut evaluator = make_evaluator(backend, base.stage2_points).map_err(|e| e.to_string())?;
    let bar = super::progress(frames as u64, "table-top scenes");
    let (mut out_frames, mut out_objects) = (Vec::new(), Vec::new());
    for f in 0..frames {
        let frame_seed = seed + f as u64;
        let frame = BenchFrame::new(frame_seed)?;
        let fit_options = FitOptions {
            seed: frame_seed,
            ..base.clone()
        };
        let report = fit_scene(
            evaluator.as_mut(),
            &frame.pixels,
            &SceneOptions::default(),
            &fit_options,
        )
        .map_err(|e| format!("frame {frame_seed}: {e}"))?;
        // each segment's object: the label most of its pixels carry
        let owner: Vec<Option<usize>> = report
            .objects
            .iter()
            .map(|o| frame.owner(&o.pixels))
            .collect();
        let phantoms = owner.iter().filter(|o| o.is_none()).count();
        let owned: std::collections::HashSet<usize> = owner.iter().flatten().copied().collect();
        let duplicates = owner.iter().flatten().count() - owned.len();
        for (i, (shape, pose)) in frame.scene.objects.iter().enumerate() {
            let visible = frame
                .rendered
                .labels
                .iter()
                .filter(|&&l| l == FIRST_OBJECT + i as u16)
                .count();
            let mine = owner.iter().position(|o| *o == Some(i));
            let fit = mine.and_then(|s| report.objects[s].fit.as_ref());
            let (_, truth_pose) = frame.truth(i);
            let holed = shape.a4 > 0.0;
            let in_frame = silhouette_in_frame(shape, pose, &frame.scene.camera)?;
            let warned = fit.is_some_and(|r| !r.warnings.is_empty());
            let Judged {
                model_right,
                within,
                chamfer,
            } = judge(shape, &truth_pose, fit);
            out_objects.push(SceneObjectCase {
                frame: frame_seed,
                holed,
                visible_pixels: visible,
                in_view: visible >= SceneOptions::default().min_points,
                in_frame,
                found: mine.is_some(),
                model_right,
                success: model_right && within,
                chamfer,
                warned,
            });
        }
        out_frames.push(SceneFrame {
            seed: frame_seed,
            objects: frame.scene.objects.len(),
            segments: report.objects.len(),
            phantoms,
            duplicates,
            total_ms: report.timing_ms.total,
            segment_ms: report.timing_ms.segment,
        });
        bar.inc(1);
    }
    bar.finish_and_clear();
    Ok(ScenesReport {
        machine: super::Machine::probe(),
        frames: out_frames,
        objects: out_objects,
    })
}

/// An object's fit against its truth: the model right (a hole or none), and the fit
/// within the model-choice suite's rule (the ground-truth rule for a holed object, the
/// surface chamfer under [`CHAMFER_BOUND`] of its size for one without).
pub struct Judged {
    pub model_right: bool,
    pub within: bool,
    /// the relative surface chamfer distance to the truth (NaN without a fit)
    pub chamfer: f64,
}

impl Judged {
    pub fn right(&self) -> bool {
        self.model_right && self.within
    }
}

/// [`Judged`] for `fit` (none: not found) of the object `shape` at `truth` (the camera's
/// optical frame).
pub fn judge(shape: &Shape, truth: &Pose, fit: Option<&FitReport>) -> Judged {
    let Some(r) = fit else {
        return Judged {
            model_right: false,
            within: false,
            chamfer: f64::NAN,
        };
    };
    let holed = shape.a4 > 0.0;
    let chamfer = relative_chamfer((shape, truth), (&r.fitted.0, &r.fitted.1));
    Judged {
        model_right: (r.model.kind == Model::Supertoroid) == holed,
        within: if holed {
            compare((shape, truth), (&r.fitted.0, &r.fitted.1)).success()
        } else {
            chamfer < CHAMFER_BOUND
        },
        chamfer,
    }
}

/// The share of an object's silhouette, seen alone, that lies in the camera's frame
/// (against a camera whose frame is wider by [`FRAME_PAD`] pixels on every side).
pub(super) fn silhouette_in_frame(
    shape: &Shape,
    pose: &Pose,
    camera: &Camera,
) -> Result<f64, String> {
    let mut wider = *camera;
    wider.intrinsics.width += 2 * FRAME_PAD;
    wider.intrinsics.height += 2 * FRAME_PAD;
    wider.intrinsics.cx += FRAME_PAD as f64;
    wider.intrinsics.cy += FRAME_PAD as f64;
    let whole = render_view(shape, pose, &wider, 0.001)?.pixels;
    let k = camera.intrinsics;
    let in_frame = |c: u32, size: u32| (FRAME_PAD..FRAME_PAD + size).contains(&c);
    let framed = whole
        .iter()
        .filter(|[u, v]| in_frame(*u, k.width) && in_frame(*v, k.height))
        .count();
    Ok(framed as f64 / whole.len().max(1) as f64)
}

/// How far past the frame [`silhouette_in_frame`] looks: the scenes' objects are at most
/// about 300 pixels across.
const FRAME_PAD: u32 = 400;

/// The object most of the pixels show, if an object is what most of them show.
fn majority_object(pixels: &[(u32, u32)], labels: &[u16], width: u32) -> Option<usize> {
    let mut counts = std::collections::HashMap::new();
    for &(u, v) in pixels {
        *counts
            .entry(labels[(v * width + u) as usize])
            .or_insert(0usize) += 1;
    }
    let (&label, &count) = counts.iter().max_by_key(|(l, c)| (**c, **l))?;
    (label >= FIRST_OBJECT && 2 * count > pixels.len()).then(|| (label - FIRST_OBJECT) as usize)
}

fn share(n: usize, d: usize) -> f64 {
    100.0 * n as f64 / d.max(1) as f64
}

impl Report for ScenesReport {
    fn name(&self) -> &'static str {
        "scenes"
    }

    fn csv(&self) -> String {
        let mut s = String::from(
            "frame,holed,visible_pixels,in_view,in_frame,found,model_right,success,chamfer,warned\n",
        );
        for o in &self.objects {
            s += &format!(
                "{},{},{},{},{:.3},{},{},{},{:.5},{}\n",
                o.frame,
                o.holed,
                o.visible_pixels,
                o.in_view,
                o.in_frame,
                o.found,
                o.model_right,
                o.success,
                o.chamfer,
                o.warned
            );
        }
        s
    }

    fn markdown(&self) -> String {
        let seen: Vec<&SceneObjectCase> = self.objects.iter().filter(|o| o.in_view).collect();
        let objects = seen.len();
        let found = seen.iter().filter(|o| o.found).count();
        let right = seen.iter().filter(|o| o.success).count();
        let model_right = seen.iter().filter(|o| o.model_right).count();
        let hidden = self.objects.len() - objects;
        let with_phantom = self
            .frames
            .iter()
            .filter(|f| f.phantoms + f.duplicates > 0)
            .count();
        let mut md = format!(
            "# Table-top scenes\n\n{}\n\n{} frames of 3-6 objects on a table (640x480, D435-like: {} m depth noise at 0.5 m growing with range squared, 1 mm quantisation, flying pixels at {:.0}% of silhouette edges), fitted as `/v1/scene` does (model auto). Objects in view (at least {} visible pixels; {hidden} more were out of the frame or hidden):\n\n| objects | found | model right | right (model and fit) | frames with a made-up object (of nothing, or a second of one object) |\n|---|---|---|---|---|\n| {objects} | {found} ({:.1}%) | {model_right} ({:.1}%) | {right} ({:.1}%) | {with_phantom} of {} ({:.1}%) |\n",
            self.machine.markdown(),
            self.frames.len(),
            NOISE_AT_HALF_METRE,
            100.0 * FLYING_SHARE,
            SceneOptions::default().min_points,
            share(found, objects),
            share(model_right, objects),
            share(right, objects),
            self.frames.len(),
            share(with_phantom, self.frames.len()),
        );
        for (label, holed) in [("with a hole", true), ("without", false)] {
            let kept: Vec<_> = seen.iter().filter(|o| o.holed == holed).collect();
            md += &format!(
                "\nObjects {label}: {} of {} found, {} right.",
                kept.iter().filter(|o| o.found).count(),
                kept.len(),
                kept.iter().filter(|o| o.success).count()
            );
        }
        for (label, whole) in [
            ("wholly in the frame", true),
            ("cut by the frame's edge", false),
        ] {
            let kept: Vec<_> = seen
                .iter()
                .filter(|o| (o.in_frame >= WHOLLY_IN_FRAME) == whole)
                .collect();
            let right = kept.iter().filter(|o| o.success).count();
            md += &format!(
                "\nObjects {label}: {right} of {} right ({:.1}%).",
                kept.len(),
                share(right, kept.len())
            );
        }
        // (of the objects found: right ones, and the wrong ones)
        let warned = |success: bool| {
            seen.iter()
                .filter(|o| o.found && o.success == success && o.warned)
                .count()
        };
        md += &format!(
            "\n\nWarnings: {} of the {} wrong fits carry one, {} of the {right} right ones.",
            warned(false),
            found - right,
            warned(true)
        );
        if !self.frames.is_empty() {
            let times = || self.frames.iter().map(|f| f.total_ms).collect::<Vec<_>>();
            let segment: Vec<f64> = self.frames.iter().map(|f| f.segment_ms).collect();
            md += &format!(
                "\n\nTime per frame (segmentation and every fit): median {:.0} ms, p95 {:.0} ms; segmentation alone median {:.0} ms.\n",
                percentile(times(), 0.5),
                percentile(times(), 0.95),
                percentile(segment, 0.5)
            );
        }
        md
    }
}
