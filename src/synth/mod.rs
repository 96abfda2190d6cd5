//! Synthetic, seeded point clouds with known ground truth: near-uniform surface samples,
//! single-view renders through a pinhole camera with a z-buffer (and the depth image it
//! produces), Gaussian noise and uniform outliers, and table-top scenes ([`scene`]).

mod camera;
mod sampling;
pub mod scene;

pub use camera::{Camera, DepthImage, Intrinsics, RenderedView, render_view, with_table};
pub use sampling::{add_noise, add_outliers, sample_surface, sample_surface_on_grid, subsample};

/// A seeded random generator, the same stream on every platform.
pub type SeededRng = rand::rngs::StdRng;

pub fn rng(seed: u64) -> SeededRng {
    use rand::SeedableRng;
    SeededRng::seed_from_u64(seed)
}
