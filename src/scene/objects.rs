//! The objects on a table in a depth frame: the table's plane found over the frame (a
//! seeded RANSAC on an even stride of its pixels, [`super::plane`]), its points and
//! everything below it taken away, and what stands above it split into objects by
//! Euclidean clustering on a grid of cells: points closer than a gap join one
//! object. Clusters too small to fit (specks, flying pixels at silhouettes) are dropped,
//! and so are those too large to be a table-top object (a wall behind the table).
//!
//! Objects that touch one another join one cluster: a known limit of clustering by
//! distance, which a detector's masks (one `/v1/fit/depth` request each) do not have.

use super::plane::{PlaneFit, fit_plane};
use super::table::{Pixels, TABLE_TOLERANCE};
use crate::model::Plane;
use glam::DVec3;
use rustc_hash::FxHashMap;
use serde::{Deserialize, Serialize};

/// The most points the plane's RANSAC looks at (an even stride of the frame).
const PLANE_POINTS: usize = 20_000;
/// The table must hold at least this share of the frame's points (a table filling a
/// fifth of a frame is the least a table-top scene shows).
pub const MIN_TABLE_SHARE: f64 = 0.15;
/// The gap that splits objects, as a share of the depth (1 cm at 1 m): about eight
/// pixel footprints of a 640-pixel-wide sensor, wider than the holes its noise and
/// dropouts leave in one surface, narrower than the space between two objects set
/// apart on a table.
pub const GAP_SHARE: f64 = 0.01;

/// What the caller may set about a scene.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields, default)]
pub struct SceneOptions {
    /// the fewest points an object keeps (fewer: a speck, dropped)
    pub min_points: usize,
    /// the smallest object, its bounding-box half-diagonal in the depth's scaled unit
    /// (metres by default); smaller clusters are dropped
    pub min_size: f64,
    /// the largest object (likewise); larger clusters (a wall, the floor) are dropped
    pub max_size: f64,
    /// the most objects a scene may hold (more: 422 `too_many_objects`)
    pub max_objects: usize,
    /// keep each object's fit above the table (free-space points under it, the fit's
    /// `support`). On by default: with the table's axes among the fit's starts it keeps a
    /// standing object's fit from reaching through the table (`bench scenes`, five sets:
    /// 384 of 434 objects right with it, 374 without; `docs/scenes.md`)
    pub table_prior: bool,
}

impl Default for SceneOptions {
    fn default() -> Self {
        Self {
            min_points: 100,
            min_size: 0.01,
            max_size: 0.5,
            max_objects: 16,
            table_prior: true,
        }
    }
}

/// One object's points, with their pixels.
#[derive(Clone, Debug)]
pub struct Segment {
    pub points: Vec<DVec3>,
    pub pixels: Vec<(u32, u32)>,
    /// free space the camera saw past the object: points on its rays to the table
    /// within the object's pixel box, inside the object's box and in front of the table
    /// (`seen_through`)
    pub seen_through: Vec<DVec3>,
}

impl Segment {
    /// The pixel box [x, y, width, height] of the object.
    pub fn pixel_box(&self) -> [u32; 4] {
        let (mut u0, mut v0, mut u1, mut v1) = (u32::MAX, u32::MAX, 0, 0);
        for &(u, v) in &self.pixels {
            (u0, v0, u1, v1) = (u0.min(u), v0.min(v), u1.max(u), v1.max(v));
        }
        [u0, v0, u1 - u0 + 1, v1 - v0 + 1]
    }

    /// How many of its pixels lie on the edge of `window` ([x, y, width, height]): an
    /// object the frame's edge cuts shows a run of them, one wholly in the frame none.
    pub fn edge_pixels(&self, window: [u32; 4]) -> usize {
        pixels_on_edge(&self.pixels, window)
    }
}

/// How many of `pixels` lie on the edge of the pixel rectangle `window` [x, y, w, h].
pub fn pixels_on_edge(pixels: &[(u32, u32)], window: [u32; 4]) -> usize {
    let [x, y, w, h] = window;
    let (right, bottom) = ((x + w).saturating_sub(1), (y + h).saturating_sub(1));
    pixels
        .iter()
        .filter(|&&(u, v)| u <= x || v <= y || u >= right || v >= bottom)
        .count()
}

/// A frame split into its table and the objects on it.
#[derive(Clone, Debug)]
pub struct Segmentation {
    /// the table's plane, its normal towards the camera
    pub plane: Plane,
    pub table_points: usize,
    /// largest first
    pub objects: Vec<Segment>,
    /// clusters dropped as too small or too large
    pub dropped: usize,
    /// the pixel rectangle the frame's points came from ([`Pixels::window`])
    pub window: [u32; 4],
    /// its edges seen from the camera
    pub field_of_view: crate::fit::FieldOfView,
}

#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SceneError {
    #[error("no table: the largest plane holds {share:.0}% of the points (at least {min:.0}% needed)", share = 100.0 * share, min = 100.0 * MIN_TABLE_SHARE)]
    NoPlane { share: f64 },
    #[error(
        "nothing stands on the table: {dropped} clusters above it, each too small or too large for an object"
    )]
    NoObject { dropped: usize },
    #[error("{found} objects on the table, more than max_objects {max}")]
    TooManyObjects { found: usize, max: usize },
}

/// The table and the objects on it, from a frame's back-projected pixels (the camera's
/// optical frame: the camera at the origin, depth along z).
pub fn segment(
    frame: &Pixels,
    options: &SceneOptions,
    seed: u64,
) -> Result<Segmentation, SceneError> {
    let points = &frame.points;
    let depth = median_depth(points);
    let tolerance = TABLE_TOLERANCE * depth;
    let stride: Vec<DVec3> = points
        .iter()
        .step_by(points.len().div_ceil(PLANE_POINTS).max(1))
        .copied()
        .collect();
    let Some(PlaneFit {
        plane,
        inlier_count,
        ..
    }) = fit_plane(&stride, tolerance, seed)
    else {
        return Err(SceneError::NoPlane { share: 0.0 });
    };
    let share = inlier_count as f64 / stride.len().max(1) as f64;
    if share < MIN_TABLE_SHARE {
        return Err(SceneError::NoPlane { share });
    }
    let plane = towards_the_camera(plane);
    let above: Vec<usize> = (0..points.len())
        .filter(|&i| plane.signed_distance(points[i]) > tolerance)
        .collect();
    let table: Vec<usize> = (0..points.len())
        .filter(|&i| plane.signed_distance(points[i]).abs() <= tolerance)
        .collect();
    let above_points: Vec<DVec3> = above.iter().map(|&i| points[i]).collect();
    let clusters = euclidean_clusters(&above_points, GAP_SHARE * median_depth(&above_points));
    let mut objects = Vec::new();
    let mut dropped = 0;
    for cluster in clusters {
        let segment = Segment {
            points: cluster.iter().map(|&i| above_points[i]).collect(),
            pixels: cluster.iter().map(|&i| frame.pixels[above[i]]).collect(),
            seen_through: Vec::new(),
        };
        let size = half_diagonal(&segment.points);
        if segment.points.len() < options.min_points
            || size < options.min_size
            || size > options.max_size
        {
            dropped += 1;
        } else {
            objects.push(segment);
        }
    }
    if objects.is_empty() {
        return Err(SceneError::NoObject { dropped });
    }
    if objects.len() > options.max_objects {
        return Err(SceneError::TooManyObjects {
            found: objects.len(),
            max: options.max_objects,
        });
    }
    objects.sort_by_key(|o| std::cmp::Reverse(o.points.len()));
    for object in &mut objects {
        object.seen_through = seen_through(object, &table, frame, 3.0 * tolerance);
    }
    Ok(Segmentation {
        plane,
        table_points: table.len(),
        objects,
        dropped,
        window: frame.window,
        field_of_view: frame.field_of_view,
    })
}

/// The most rays to the table an object's free space is sampled on.
const SEEN_THROUGH_RAYS: usize = 400;

/// Free space past an object: on the camera's rays (from the origin) to the table points
/// within the object's pixel box, three points (at a quarter, half and three quarters)
/// where the ray crosses the object's box, grown by a tenth of its size and at least
/// `margin` in front of the table point. The box is the camera's, so over a flat object
/// it reaches well above it: most points bound the object from above and beside, few
/// fall in a ring's hole. (Points every 15% of the size along each ray, which fill the
/// hole, did worse: `bench scenes` sets 750000-770000 right 213 against 215, and a
/// third slower.)
fn seen_through(object: &Segment, table: &[usize], frame: &Pixels, margin: f64) -> Vec<DVec3> {
    let [x, y, w, h] = object.pixel_box();
    let rays: Vec<DVec3> = table
        .iter()
        .filter(|&&i| {
            let (u, v) = frame.pixels[i];
            (x..x + w).contains(&u) && (y..y + h).contains(&v)
        })
        .map(|&i| frame.points[i])
        .collect();
    let (lo, hi) = bounding_box(&object.points);
    let grow = DVec3::splat(0.1 * (hi - lo).length());
    let (lo, hi) = (lo - grow, hi + grow);
    let mut out = Vec::new();
    for &end in rays
        .iter()
        .step_by(rays.len().div_ceil(SEEN_THROUGH_RAYS).max(1))
    {
        let length = end.length();
        if length <= margin {
            continue;
        }
        // the ray s·end, s in [0, 1 - margin/length], clipped to the box (slabs)
        let (mut s0, mut s1) = (0.0_f64, 1.0 - margin / length);
        for k in 0..3 {
            let d = end[k];
            if d.abs() < 1e-12 {
                if !(lo[k]..=hi[k]).contains(&0.0) {
                    s1 = -1.0;
                }
                continue;
            }
            let (a, b) = (lo[k] / d, hi[k] / d);
            s0 = s0.max(a.min(b));
            s1 = s1.min(a.max(b));
        }
        if s1 > s0 {
            for f in [0.25, 0.5, 0.75] {
                out.push(end * (s0 + f * (s1 - s0)));
            }
        }
    }
    out
}

/// The plane with its normal towards the origin (the camera).
pub(super) fn towards_the_camera(plane: Plane) -> Plane {
    if plane.signed_distance(DVec3::ZERO) < 0.0 {
        Plane {
            normal: (-plane.normal()).to_array(),
            offset: -plane.offset,
        }
    } else {
        plane
    }
}

fn median_depth(points: &[DVec3]) -> f64 {
    if points.is_empty() {
        return 0.0;
    }
    let mut z: Vec<f64> = points.iter().map(|p| p.z).collect();
    *z.select_nth_unstable_by(points.len() / 2, f64::total_cmp).1
}

/// The points' axis-aligned box, (least, greatest) corner.
fn bounding_box(points: &[DVec3]) -> (DVec3, DVec3) {
    points.iter().fold(
        (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
        |(lo, hi), &p| (lo.min(p), hi.max(p)),
    )
}

/// Half the diagonal of the points' axis-aligned box.
fn half_diagonal(points: &[DVec3]) -> f64 {
    let (lo, hi) = bounding_box(points);
    0.5 * (hi - lo).length()
}

/// The points' clusters (indices, each in increasing order, the clusters in the order of
/// their first point): points within `gap` of one another join, transitively.
///
/// On a grid of cells `gap / sqrt(3)` across, any two points of one cell are within the
/// gap, so a cell's points are one cluster's; two cells join where any pair of their
/// points does, and only cells up to two apart along each axis can hold such a pair. Each
/// pair of cells is tested once, stopping at the first pair of points within the gap.
/// The same clusters as a flood fill over a k-d tree's radius queries (the tests hold
/// the two together), where each of a frame's 50,000 points met about a hundred
/// neighbours: a frame's segmentation took 66 ms that way, 15 ms on the grid (`bench
/// scenes`' frames 750000-750005).
pub fn euclidean_clusters(points: &[DVec3], gap: f64) -> Vec<Vec<usize>> {
    if points.is_empty() || !(gap > 0.0) {
        return (0..points.len()).map(|i| vec![i]).collect();
    }
    let side = gap / 3f64.sqrt();
    // (keyed as `fit::isolated` keys its occupancy grid)
    let cell_of = |p: &DVec3| (*p / side).floor().as_i64vec3().to_array();
    let mut cells: CellMap = CellMap::default();
    let mut members: Vec<Vec<usize>> = Vec::new();
    let mut cell_of_point = Vec::with_capacity(points.len());
    for (i, p) in points.iter().enumerate() {
        let next = members.len();
        let cell = *cells.entry(cell_of(p)).or_insert(next);
        if cell == next {
            members.push(Vec::new());
        }
        members[cell].push(i);
        cell_of_point.push(cell);
    }
    let mut roots = UnionFind::new(members.len());
    let gap2 = gap * gap;
    for (&[x, y, z], &a) in &cells {
        for [dx, dy, dz] in HALF_NEIGHBOURHOOD {
            let Some(&b) = cells.get(&[x + dx, y + dy, z + dz]) else {
                continue;
            };
            if roots.find(a) == roots.find(b) {
                continue;
            }
            let near = members[a].iter().any(|&i| {
                members[b]
                    .iter()
                    .any(|&j| (points[i] - points[j]).length_squared() <= gap2)
            });
            if near {
                roots.join(a, b);
            }
        }
    }
    // the clusters in the order of their first point, each point's cluster its cell's
    let mut cluster_of_root = vec![usize::MAX; members.len()];
    let mut clusters: Vec<Vec<usize>> = Vec::new();
    for (i, &cell) in cell_of_point.iter().enumerate() {
        let root = roots.find(cell);
        if cluster_of_root[root] == usize::MAX {
            cluster_of_root[root] = clusters.len();
            clusters.push(Vec::new());
        }
        clusters[cluster_of_root[root]].push(i);
    }
    clusters
}

/// Cells by their grid position, hashed by FxHash (the standard library's SipHash, built
/// against adversarial keys, was a third of the clustering's time).
type CellMap = FxHashMap<[i64; 3], usize>;

/// The cell offsets up to two apart along each axis, each pair of opposite ones once (the
/// 62 lexicographically after zero).
const HALF_NEIGHBOURHOOD: [[i64; 3]; 62] = {
    let mut out = [[0; 3]; 62];
    let mut k = 0;
    let mut dx = -2;
    while dx <= 2 {
        let mut dy = -2;
        while dy <= 2 {
            let mut dz = -2;
            while dz <= 2 {
                if dx > 0 || (dx == 0 && (dy > 0 || (dy == 0 && dz > 0))) {
                    out[k] = [dx, dy, dz];
                    k += 1;
                }
                dz += 1;
            }
            dy += 1;
        }
        dx += 1;
    }
    out
};

/// Disjoint sets of cells, joined by union by size with path halving.
struct UnionFind {
    parent: Vec<usize>,
    size: Vec<usize>,
}

impl UnionFind {
    fn new(count: usize) -> Self {
        Self {
            parent: (0..count).collect(),
            size: vec![1; count],
        }
    }

    fn find(&mut self, mut i: usize) -> usize {
        while self.parent[i] != i {
            self.parent[i] = self.parent[self.parent[i]];
            i = self.parent[i];
        }
        i
    }

    fn join(&mut self, a: usize, b: usize) {
        let (mut a, mut b) = (self.find(a), self.find(b));
        if a == b {
            return;
        }
        if self.size[a] < self.size[b] {
            std::mem::swap(&mut a, &mut b);
        }
        self.parent[b] = a;
        self.size[a] += self.size[b];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The flood fill over a k-d tree's radius queries: every point's neighbours within
    /// the gap, transitively (what the cell grid must give, faster).
    fn clusters_by_radius_queries(points: &[DVec3], gap: f64) -> Vec<Vec<usize>> {
        use kiddo::{ImmutableKdTree, SquaredEuclidean};
        let entries: Vec<[f64; 3]> = points.iter().map(|p| p.to_array()).collect();
        let tree = ImmutableKdTree::<f64, 3>::new_from_slice(&entries).unwrap();
        let mut label = vec![usize::MAX; points.len()];
        let mut clusters = Vec::new();
        for start in 0..points.len() {
            if label[start] != usize::MAX {
                continue;
            }
            let id = clusters.len();
            label[start] = id;
            let (mut stack, mut members) = (vec![start], Vec::new());
            while let Some(i) = stack.pop() {
                members.push(i);
                let near = tree
                    .query(&entries[i])
                    .within::<SquaredEuclidean<f64>>(gap * gap)
                    .unsorted()
                    .execute();
                for n in near {
                    let j = n.item as usize;
                    if label[j] == usize::MAX {
                        label[j] = id;
                        stack.push(j);
                    }
                }
            }
            members.sort_unstable();
            clusters.push(members);
        }
        clusters
    }

    /// The cell grid gives the clusters the radius queries give: on random clouds of
    /// specks and chains at several gaps, and on `bench scenes`' frames above their table.
    #[test]
    fn the_cell_grid_clusters_as_radius_queries_do() {
        use rand::Rng;
        let mut rng = crate::synth::rng(8);
        for (count, gap) in [(300, 0.05), (2000, 0.02), (2000, 0.07), (5000, 0.01)] {
            let points: Vec<DVec3> = (0..count)
                .map(|_| DVec3::new(rng.random(), rng.random(), rng.random::<f64>() - 3.0))
                .collect();
            assert_eq!(
                euclidean_clusters(&points, gap),
                clusters_by_radius_queries(&points, gap),
                "{count} points, gap {gap}"
            );
        }
        for seed in [750_000, 800_010, 860_010] {
            let frame = crate::bench::scenes::BenchFrame::new(seed).unwrap();
            let points = &frame.pixels.points;
            let depth = median_depth(points);
            let plane = fit_plane(points, TABLE_TOLERANCE * depth, seed)
                .unwrap()
                .plane;
            let above: Vec<DVec3> = points
                .iter()
                .copied()
                .filter(|p| plane.signed_distance(*p).abs() > TABLE_TOLERANCE * depth)
                .collect();
            let gap = GAP_SHARE * median_depth(&above);
            let clusters = euclidean_clusters(&above, gap);
            assert!(clusters.len() >= 3, "{seed}: {} clusters", clusters.len());
            assert_eq!(clusters, clusters_by_radius_queries(&above, gap), "{seed}");
        }
    }

    #[test]
    fn points_closer_than_the_gap_join_and_farther_ones_do_not() {
        let mut points: Vec<DVec3> = (0..20)
            .map(|i| DVec3::new(i as f64 * 0.004, 0.0, 1.0))
            .collect();
        points.extend((0..10).map(|i| DVec3::new(0.2 + i as f64 * 0.004, 0.0, 1.0)));
        let clusters = euclidean_clusters(&points, 0.005);
        assert_eq!(clusters.len(), 2);
        assert_eq!(clusters[0], (0..20).collect::<Vec<_>>());
        assert_eq!(clusters[1], (20..30).collect::<Vec<_>>());
        assert_eq!(euclidean_clusters(&points, 0.003).len(), 30);
    }
}
