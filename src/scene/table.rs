//! The table in a depth frame's box: where a plane holds a good share of the box's
//! pixels (the table around and under the object) and has the rest on the camera's side
//! (else it is a face of the object, and the table is looked for off it), its pixels
//! and those below it go,
//! and the object is the largest 8-connected region of what is left, neighbours joined
//! where their depths differ by less than [`DEPTH_JUMP`] of the depth. What a detector's
//! box gives: the object and the table around it.

use super::objects::towards_the_camera;
use super::plane::{PlaneFit, fit_plane};
use crate::io::depth::{DepthOptions, Roi, back_project_pixels};
use crate::model::Plane;
use crate::synth::DepthImage;
use glam::DVec3;

/// A plane is the table when it holds at least this share of the box's points.
pub const MIN_TABLE_SHARE: f64 = 0.15;
/// Points within this fraction of their depth of the plane are the table's (5 mm at
/// 1 m: a D435's noise at that range, with room for a table that is not quite flat).
pub const TABLE_TOLERANCE: f64 = 0.005;
/// Neighbouring pixels belong together when their depths differ by less than this
/// fraction of the depth.
pub const DEPTH_JUMP: f64 = 0.02;
/// The object must keep at least this many points, and this share of the box's.
pub const MIN_OBJECT_POINTS: usize = 50;
pub const MIN_OBJECT_SHARE: f64 = 0.02;
/// The most planes tried for the table: the largest plane in a box can be a face of the
/// object (a box's front, a ring standing on its rim), and the table is then the next.
pub const MAX_PLANES: usize = 3;

/// Back-projected pixels: points with their pixel positions.
pub struct Pixels {
    pub points: Vec<DVec3>,
    /// (column, row) of each point
    pub pixels: Vec<(u32, u32)>,
    /// the pixel rectangle [x, y, width, height] they were read from: the whole image,
    /// or the region of interest asked for (what lies outside it the fit never saw)
    pub window: [u32; 4],
    /// the edges of that rectangle seen from the camera ([`crate::fit::FieldOfView`])
    pub field_of_view: crate::fit::FieldOfView,
}

/// What [`remove_table`] did.
#[derive(Clone, Debug)]
pub enum TableOutcome {
    /// no plane holds enough of the box: the points are kept as they are
    NoTable,
    /// the table removed: its plane (normal towards the camera), how many points it
    /// had, and the object's points
    Removed {
        plane: Plane,
        table_points: usize,
        object: Vec<DVec3>,
        /// the object's pixels, in the order of its points
        object_pixels: Vec<(u32, u32)>,
    },
    /// nothing but the table (and specks) in the box
    NothingOnIt { plane: Plane, left: usize },
}

pub fn remove_table(pixels: &Pixels, seed: u64) -> TableOutcome {
    let Some(Table {
        plane,
        table_points,
        above,
        enough,
    }) = find_table(&pixels.points, seed)
    else {
        return TableOutcome::NoTable;
    };
    let region = largest_region(pixels, &above);
    if region.len() < enough {
        return TableOutcome::NothingOnIt {
            plane,
            left: region.len(),
        };
    }
    TableOutcome::Removed {
        plane,
        table_points,
        object: region.iter().map(|&i| pixels.points[i]).collect(),
        object_pixels: region.iter().map(|&i| pixels.pixels[i]).collect(),
    }
}

/// A box's table: its plane (normal towards the camera), its points' count, which
/// points are above it, and how many an object on it must keep.
struct Table {
    plane: Plane,
    table_points: usize,
    above: Vec<bool>,
    enough: usize,
}

/// The plane of [`remove_table`] among `points`: one that holds a good share of them
/// and has more of the rest on the camera's side than behind it.
fn find_table(points: &[DVec3], seed: u64) -> Option<Table> {
    if points.len() < 3 {
        return None;
    }
    let mut depths: Vec<f64> = points.iter().map(|p| p.z).collect();
    let median = *depths
        .select_nth_unstable_by(points.len() / 2, f64::total_cmp)
        .1;
    let tolerance = TABLE_TOLERANCE * median;
    let enough = MIN_OBJECT_POINTS.max((MIN_OBJECT_SHARE * points.len() as f64) as usize);
    // the points no face of the object found so far holds
    let mut left: Vec<usize> = (0..points.len()).collect();
    for _ in 0..MAX_PLANES {
        let candidates: Vec<DVec3> = left.iter().map(|&i| points[i]).collect();
        let PlaneFit { plane, .. } = fit_plane(&candidates, tolerance, seed)?;
        let inliers: Vec<bool> = points
            .iter()
            .map(|&p| plane.signed_distance(p).abs() <= tolerance)
            .collect();
        let inlier_count = inliers.iter().filter(|&&on| on).count();
        if (inlier_count as f64) < MIN_TABLE_SHARE * points.len() as f64 {
            return None;
        }
        let plane = towards_the_camera(plane);
        let above: Vec<bool> = points
            .iter()
            .zip(&inliers)
            .map(|(&p, &on)| !on && plane.signed_distance(p) > 0.0)
            .collect();
        // a table has the object on the camera's side; a plane with more of the rest
        // behind it is a face of the object itself (a box's front, a standing ring's
        // side): the table is looked for among the points off that face
        let n_above = above.iter().filter(|&&a| a).count();
        let behind = (points.len() - inlier_count) - n_above;
        if behind >= enough && behind > n_above {
            left.retain(|&i| !inliers[i]);
            continue;
        }
        return Some(Table {
            plane,
            table_points: inlier_count,
            above,
            enough,
        });
    }
    None
}

/// How a depth frame's object was picked out of it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Selection {
    /// a detector's box and no mask: the table around the object is in it
    DetectorBox,
    /// a segmenter's mask: the object's pixels alone
    Mask,
    /// neither (the whole frame, or a box the caller says holds the object alone)
    Pixels,
}

/// A depth frame's object points, their pixels, and the table it rests on, where one
/// was found.
pub struct DepthObject {
    pub points: Vec<DVec3>,
    pub pixels: Vec<(u32, u32)>,
    pub table: Option<Plane>,
}

/// The object in the pixels read (`selected`, read from `image` by `read`), as
/// `/v1/fit/depth` takes it: from a detector's box, the table taken away
/// ([`remove_table`]); from a mask, the table found around it ([`table_beside`]);
/// otherwise the pixels as they are. Err: the box holds a table and nothing on it (the
/// points left off the table).
pub fn depth_object(
    selected: Pixels,
    image: &DepthImage,
    read: &DepthOptions,
    selection: Selection,
    seed: u64,
) -> Result<DepthObject, usize> {
    let table = match selection {
        Selection::DetectorBox => match remove_table(&selected, seed) {
            TableOutcome::NoTable => None,
            TableOutcome::Removed {
                plane,
                object,
                object_pixels,
                ..
            } => {
                return Ok(DepthObject {
                    points: object,
                    pixels: object_pixels,
                    table: Some(plane),
                });
            }
            TableOutcome::NothingOnIt { left, .. } => return Err(left),
        },
        Selection::Mask => table_beside(image, read, &selected, seed),
        Selection::Pixels => None,
    };
    Ok(DepthObject {
        points: selected.points,
        pixels: selected.pixels,
        table,
    })
}

/// How much wider than a masked object's pixels the box is that its table is looked for
/// in ([`table_beside`]), on each side, as a share of the box's width (and height): as
/// loose as a detector's box.
pub const TABLE_BESIDE_PAD: f64 = 0.1;

/// The table a masked object stands on: found as in a detector's box ([`remove_table`])
/// among every [`TABLE_BESIDE_STRIDE`]-th row and column of the bounding box of the
/// object's pixels widened by [`TABLE_BESIDE_PAD`], read from `image` without the mask;
/// None where that box holds no table with enough points above it. (The mask is the
/// object: no region of the box need be found, and a plane needs no more pixels.)
pub fn table_beside(
    image: &DepthImage,
    options: &DepthOptions,
    object: &Pixels,
    seed: u64,
) -> Option<Plane> {
    let around = DepthOptions {
        roi: Some(widened_box(&object.pixels, TABLE_BESIDE_PAD)?),
        ..options.clone()
    };
    let read = back_project_pixels(image, &around, None).ok()?;
    let points: Vec<DVec3> = read
        .points
        .iter()
        .zip(&read.pixels)
        .filter(|(_, (u, v))| u % TABLE_BESIDE_STRIDE == 0 && v % TABLE_BESIDE_STRIDE == 0)
        .map(|(p, _)| *p)
        .collect();
    let table = find_table(&points, seed)?;
    let above = table.above.iter().filter(|&&a| a).count();
    (above >= table.enough).then_some(table.plane)
}

/// [`table_beside`] reads every this-many-th row and column of its box: a quarter of a
/// box of a hundred thousand pixels holds the plane as well.
pub const TABLE_BESIDE_STRIDE: u32 = 2;

/// The bounding box of `pixels` widened by `pad` of its width and height on every side
/// (reading it clips it to the image); None for no pixels.
pub fn widened_box(pixels: &[(u32, u32)], pad: f64) -> Option<Roi> {
    if pixels.is_empty() {
        return None;
    }
    let (u0, v0, u1, v1) = pixels
        .iter()
        .fold((u32::MAX, u32::MAX, 0, 0), |(a, b, c, d), &(u, v)| {
            (a.min(u), b.min(v), c.max(u), d.max(v))
        });
    let (w, h) = (u1 - u0 + 1, v1 - v0 + 1);
    let (pu, pv) = (
        (pad * w as f64).round() as u32,
        (pad * h as f64).round() as u32,
    );
    Some(Roi {
        x: u0 as i64 - pu as i64,
        y: v0 as i64 - pv as i64,
        width: w + 2 * pu,
        height: h + 2 * pv,
    })
}

/// The points of the largest 8-connected region of kept pixels, neighbours joined where
/// their depths differ by less than [`DEPTH_JUMP`].
fn largest_region(pixels: &Pixels, keep: &[bool]) -> Vec<usize> {
    let (u0, v0) = pixels
        .pixels
        .iter()
        .fold((u32::MAX, u32::MAX), |(a, b), &(u, v)| (a.min(u), b.min(v)));
    let (u1, v1) = pixels
        .pixels
        .iter()
        .fold((0, 0), |(a, b), &(u, v)| (a.max(u), b.max(v)));
    let (w, h) = ((u1 - u0 + 1) as usize, (v1 - v0 + 1) as usize);
    // the point at each pixel of the box, if kept
    let mut at = vec![usize::MAX; w * h];
    for (i, &(u, v)) in pixels.pixels.iter().enumerate() {
        if keep[i] {
            at[(v - v0) as usize * w + (u - u0) as usize] = i;
        }
    }
    let mut label = vec![usize::MAX; w * h];
    let mut best: Vec<usize> = Vec::new();
    let mut stack = Vec::new();
    for start in 0..w * h {
        if at[start] == usize::MAX || label[start] != usize::MAX {
            continue;
        }
        let mut region = Vec::new();
        label[start] = start;
        stack.push(start);
        while let Some(cell) = stack.pop() {
            let i = at[cell];
            region.push(i);
            let (x, y) = ((cell % w) as i64, (cell / w) as i64);
            let z = pixels.points[i].z;
            for (dx, dy) in [
                (-1, -1),
                (0, -1),
                (1, -1),
                (-1, 0),
                (1, 0),
                (-1, 1),
                (0, 1),
                (1, 1),
            ] {
                let (nx, ny) = (x + dx, y + dy);
                if nx < 0 || ny < 0 || nx >= w as i64 || ny >= h as i64 {
                    continue;
                }
                let n = ny as usize * w + nx as usize;
                if at[n] == usize::MAX || label[n] != usize::MAX {
                    continue;
                }
                if (pixels.points[at[n]].z - z).abs() < DEPTH_JUMP * z {
                    label[n] = start;
                    stack.push(n);
                }
            }
        }
        if region.len() > best.len() {
            best = region;
        }
    }
    best.sort_unstable();
    best
}
