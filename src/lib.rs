//! supertoroid: fits supertoroids (one-hole superquadrics; superellipsoids as a4 = 0) to
//! 3D point clouds, after Badia Torres et al., "Supertoroid fitting of objects with holes
//! for robotic grasping and scene generation".
//!
//! Architecture, bottom-up:
//! * [`model`]: the surface in f64: shape, pose, inside-outside function, meridian radial
//!   distance, differential geometry. The reference for everything else.
//! * [`synth`]: seeded synthetic clouds with ground truth (surface samples, single-view
//!   renders with depth images, noise, outliers).
//! * [`eval`]: evaluators (residuals, Jacobians, normal equations for batches of
//!   candidates): WGSL compute shaders through wgpu, and the f64 CPU reference.
//! * [`io`]: cloud readers and writers.
//! * [`fit`], [`solve`]: the two-stage fit and its interior-point solver.
//! * [`suite`]: the ground-truth suite the fit is judged on (cases, the success rule) and
//!   the share of them an efficient estimator would get right.
//! * [`grasp`]: surface queries and parallel-jaw grasps on a fitted object.
//! * [`export`]: fitted objects as meshes, MJCF and URDF for simulators and planners.
//! * [`scene`]: the table found and taken away from a depth frame's box.
//! * [`service`]: the HTTP service (axum).
//! * [`bench`](mod@bench): the benchmark harness (paper clouds, ground-truth suite, scaling).
//! * [`render`]: headless pictures of clouds and fits (wgpu render pipeline).
//! * [`cli`]: the `supertoroid` command line.

pub mod bench;
pub mod cli;
pub mod eval;
pub mod export;
pub mod fit;
pub mod grasp;
pub mod io;
pub mod model;
pub mod render;
pub mod scene;
pub mod service;
pub mod solve;
pub mod suite;
pub mod synth;
