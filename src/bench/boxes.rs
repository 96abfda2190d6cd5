//! A detector's box against a segmenter's mask (`supertoroid bench boxes`): every object
//! in view of the frames of [`super::scenes`], fitted as `/v1/fit/depth` fits it from
//! the object's pixel box (its visible pixels' bounding box widened by [`BOX_PAD`] on
//! every side, as a detector's box sits loosely; the table it holds found and taken away,
//! the object fitted as resting on it) and from its mask (its visible pixels). Per
//! object: each fit right by the scenes' rule ([`super::scenes::judge`]), and whether
//! the two fits agree (the same model, surfaces within [`CHAMFER_BOUND`] of each other).

use super::scenes::{BenchFrame, WHOLLY_IN_FRAME, judge, silhouette_in_frame};
use super::{Report, percentile};
use crate::eval::{Backend, Evaluator, make_evaluator};
use crate::fit::{FitOptions, FitReport, fit};
use crate::io::depth::{DepthOptions, Roi, back_project_pixels};
use crate::scene::fit::{depth_options, edge_warning};
use crate::scene::objects::SceneOptions;
use crate::scene::objects::pixels_on_edge;
use crate::scene::table::{DepthObject, Pixels, Selection, depth_object, widened_box};
use crate::suite::chamfer::{CHAMFER_BOUND, relative_chamfer};
use crate::synth::DepthImage;
use crate::synth::scene::FIRST_OBJECT;
use serde::Serialize;
use std::time::Instant;

/// How much wider than the object's pixels its box is, on each side, as a share of the
/// box's width (and height): detectors' boxes sit a little loose.
pub const BOX_PAD: f64 = 0.1;

#[derive(Clone, Debug, Serialize)]
pub struct BoxCase {
    pub frame: u64,
    pub object: usize,
    pub holed: bool,
    pub visible_pixels: usize,
    pub in_frame: f64,
    /// a table was found in the box and taken away
    pub table_found: bool,
    /// the box held a table and nothing on it (`no_object_found`): a failed box fit
    pub box_refused: bool,
    pub box_right: bool,
    pub box_chamfer: f64,
    pub mask_right: bool,
    pub mask_chamfer: f64,
    /// the box's and the mask's fits have the same model and surfaces within
    /// [`CHAMFER_BOUND`] of each other
    pub agree: bool,
    /// each fit warned `cut by the frame's edge` (the edge of the image or of the box)
    pub box_edge_warned: bool,
    pub mask_edge_warned: bool,
    pub box_ms: f64,
    pub mask_ms: f64,
}

#[derive(Clone, Debug, Serialize)]
pub struct BoxesReport {
    pub machine: super::Machine,
    pub frames: usize,
    pub objects: Vec<BoxCase>,
}

pub fn run(
    frames: usize,
    seed: u64,
    backend: Backend,
    base: &FitOptions,
) -> Result<BoxesReport, String> {
    if frames == 0 {
        return Err("--frames must be at least 1".into());
    }
    let mut evaluator = make_evaluator(backend, base.stage2_points).map_err(|e| e.to_string())?;
    let bar = super::progress(frames as u64, "boxes and masks");
    let mut objects = Vec::new();
    for f in 0..frames {
        let frame_seed = seed + f as u64;
        let frame = BenchFrame::new(frame_seed)?;
        let options = FitOptions {
            seed: frame_seed,
            ..base.clone()
        };
        for (i, (shape, pose)) in frame.scene.objects.iter().enumerate() {
            let label = FIRST_OBJECT + i as u16;
            let mask: Vec<bool> = frame.rendered.labels.iter().map(|&l| l == label).collect();
            let visible = mask.iter().filter(|&&m| m).count();
            if visible < SceneOptions::default().min_points {
                continue;
            }
            let (_, truth) = frame.truth(i);
            let boxed = DepthOptions {
                roi: Some(detector_box(&mask, frame.depth.width)),
                ..frame.depth_options.clone()
            };
            let mut fit_as = |read: &DepthOptions, mask: Option<&[bool]>, selection| {
                let pixels =
                    back_project_pixels(&frame.depth, read, mask).map_err(|e| e.to_string())?;
                Ok::<_, String>(fit_depth_object(
                    evaluator.as_mut(),
                    pixels,
                    (&frame.depth, read),
                    selection,
                    &options,
                ))
            };
            let by_box = fit_as(&boxed, None, Selection::DetectorBox)?;
            let by_mask = fit_as(&frame.depth_options, Some(&mask), Selection::Mask)?;
            let (box_judged, mask_judged) = (
                judge(shape, &truth, by_box.fit.as_ref()),
                judge(shape, &truth, by_mask.fit.as_ref()),
            );
            let agree = match (&by_box.fit, &by_mask.fit) {
                (Some(b), Some(m)) => {
                    b.model.kind == m.model.kind
                        && relative_chamfer((&m.fitted.0, &m.fitted.1), (&b.fitted.0, &b.fitted.1))
                            < CHAMFER_BOUND
                }
                _ => false,
            };
            objects.push(BoxCase {
                frame: frame_seed,
                object: i,
                holed: shape.a4 > 0.0,
                visible_pixels: visible,
                in_frame: silhouette_in_frame(shape, pose, &frame.scene.camera)?,
                table_found: by_box.table_found,
                box_refused: by_box.refused,
                box_right: box_judged.right(),
                box_chamfer: box_judged.chamfer,
                mask_right: mask_judged.right(),
                mask_chamfer: mask_judged.chamfer,
                agree,
                box_edge_warned: by_box.edge_warned,
                mask_edge_warned: by_mask.edge_warned,
                box_ms: by_box.ms,
                mask_ms: by_mask.ms,
            });
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    Ok(BoxesReport {
        machine: super::Machine::probe(),
        frames,
        objects,
    })
}

/// The bounding box of the mask's pixels, widened by [`BOX_PAD`] on every side (the
/// reading clips it to the image).
pub fn detector_box(mask: &[bool], width: u32) -> Roi {
    let pixels: Vec<(u32, u32)> = (0..mask.len() as u32)
        .filter(|&i| mask[i as usize])
        .map(|i| (i % width, i / width))
        .collect();
    widened_box(&pixels, BOX_PAD).expect("an object in view has pixels")
}

/// An object fitted from the pixels of its box or its mask.
struct DepthFit {
    /// none where the box held nothing but a table, or the fit failed
    fit: Option<FitReport>,
    table_found: bool,
    /// the box held a table and nothing on it (`no_object_found`)
    refused: bool,
    /// warned `cut by the frame's edge` (as `/v1/fit/depth` warns it)
    edge_warned: bool,
    /// the table's removal and the fit
    ms: f64,
}

/// `pixels` (read from `image` as its options say) fitted as `/v1/fit/depth` fits them
/// ([`depth_object`], [`depth_options`]).
fn fit_depth_object(
    evaluator: &mut dyn Evaluator,
    pixels: Pixels,
    (image, read): (&DepthImage, &DepthOptions),
    selection: Selection,
    options: &FitOptions,
) -> DepthFit {
    let start = Instant::now();
    let (field, window) = (pixels.field_of_view, pixels.window);
    let (fit, table_found, refused, edge_warned) =
        match depth_object(pixels, image, read, selection, options.seed) {
            Err(_) => (None, true, true, false),
            Ok(DepthObject {
                points,
                pixels,
                table,
            }) => {
                let fitted = fit(
                    evaluator,
                    &points,
                    &depth_options(options, table.as_ref(), field),
                );
                let warned = edge_warning(pixels_on_edge(&pixels, window), pixels.len());
                (fitted.ok(), table.is_some(), false, warned.is_some())
            }
        };
    DepthFit {
        fit,
        table_found,
        refused,
        edge_warned,
        ms: start.elapsed().as_secs_f64() * 1e3,
    }
}

fn share(n: usize, d: usize) -> f64 {
    100.0 * n as f64 / d.max(1) as f64
}

impl Report for BoxesReport {
    fn name(&self) -> &'static str {
        "boxes"
    }

    fn csv(&self) -> String {
        let mut s = String::from(
            "frame,object,holed,visible_pixels,in_frame,table_found,box_refused,box_right,box_chamfer,mask_right,mask_chamfer,agree,box_edge_warned,mask_edge_warned,box_ms,mask_ms\n",
        );
        for o in &self.objects {
            s += &format!(
                "{},{},{},{},{:.3},{},{},{},{:.5},{},{:.5},{},{},{},{:.1},{:.1}\n",
                o.frame,
                o.object,
                o.holed,
                o.visible_pixels,
                o.in_frame,
                o.table_found,
                o.box_refused,
                o.box_right,
                o.box_chamfer,
                o.mask_right,
                o.mask_chamfer,
                o.agree,
                o.box_edge_warned,
                o.mask_edge_warned,
                o.box_ms,
                o.mask_ms
            );
        }
        s
    }

    fn markdown(&self) -> String {
        let mut md = format!(
            "# A detector's box against a segmenter's mask\n\n{}\n\n{} frames of `bench scenes` (same seeds); every object in view fitted as `/v1/fit/depth` fits it from its box (its visible pixels' bounding box widened by {:.0}% on every side; the table in it taken away, the object resting on it) and from its mask (its visible pixels). Right: the true model and the fit within the scenes' rule; agree: the same model and surfaces within {:.0}% of the size of each other.\n\n| objects | box right | mask right | box and mask agree | table found in the box | box refused |\n|---|---|---|---|---|---|\n",
            self.machine.markdown(),
            self.frames,
            100.0 * BOX_PAD,
            100.0 * CHAMFER_BOUND,
        );
        let row = |label: &str, kept: &[&BoxCase]| {
            let n = kept.len();
            let count = |f: &dyn Fn(&BoxCase) -> bool| kept.iter().filter(|o| f(o)).count();
            let cell = |c: usize| format!("{c} ({:.1}%)", share(c, n));
            format!(
                "| {label}: {n} | {} | {} | {} | {} | {} |\n",
                cell(count(&|o| o.box_right)),
                cell(count(&|o| o.mask_right)),
                cell(count(&|o| o.agree)),
                count(&|o| o.table_found),
                count(&|o| o.box_refused),
            )
        };
        let all: Vec<&BoxCase> = self.objects.iter().collect();
        md += &row("all", &all);
        for (label, keep) in [
            (
                "with a hole",
                &(|o: &BoxCase| o.holed) as &dyn Fn(&BoxCase) -> bool,
            ),
            ("without", &|o: &BoxCase| !o.holed),
            ("wholly in the frame", &|o: &BoxCase| {
                o.in_frame >= WHOLLY_IN_FRAME
            }),
            ("cut by the frame's edge", &|o: &BoxCase| {
                o.in_frame < WHOLLY_IN_FRAME
            }),
        ] {
            let kept: Vec<&BoxCase> = all.iter().copied().filter(|o| keep(o)).collect();
            md += &row(label, &kept);
        }
        let cut = |o: &&BoxCase| o.in_frame < WHOLLY_IN_FRAME;
        let warned = |f: fn(&BoxCase) -> bool, keep: &dyn Fn(&&BoxCase) -> bool| {
            self.objects.iter().filter(keep).filter(|o| f(o)).count()
        };
        md += &format!(
            "\nWarned `cut by the frame's edge`: from the box {} of the {} objects cut by the frame's edge and {} of the {} wholly in it; from the mask {} and {}.\n",
            warned(|o| o.box_edge_warned, &cut),
            self.objects.iter().filter(cut).count(),
            warned(|o| o.box_edge_warned, &|o| !cut(o)),
            self.objects.iter().filter(|o| !cut(o)).count(),
            warned(|o| o.mask_edge_warned, &cut),
            warned(|o| o.mask_edge_warned, &|o| !cut(o)),
        );
        if !self.objects.is_empty() {
            let times = |f: fn(&BoxCase) -> f64| self.objects.iter().map(f).collect::<Vec<_>>();
            md += &format!(
                "\nTime per object (the table's removal and the fit): from the box median {:.0} ms, p95 {:.0} ms; from the mask median {:.0} ms, p95 {:.0} ms.\n",
                percentile(times(|o| o.box_ms), 0.5),
                percentile(times(|o| o.box_ms), 0.95),
                percentile(times(|o| o.mask_ms), 0.5),
                percentile(times(|o| o.mask_ms), 0.95),
            );
        }
        md
    }
}
