//! The supertoroid model (paper §II): shape, pose, the inside-outside function, the
//! parametric surface, the mean superellipse, the meridian radial distance (§III) and the
//! differential geometry of §IV. Everything here is plain f64 and allocation-free; it is
//! the reference that the GPU kernels and the solver are tested against.

mod differential;
mod distance;
mod object;
mod plane;
mod shape;

pub use differential::{
    NormalCurvatures, PrincipalFrame, SurfaceJet, normal_curvatures, principal_frame, surface_jet,
    tangents, unit_normal,
};
pub use distance::{
    MeridianPoint, ResidualGradient, meridian_distance, meridian_distance_stepwise,
    meridian_residual_with_gradient,
};
pub use object::{FittedObject, PoseIn};
pub use plane::Plane;
pub use shape::{
    Pose, Shape, ShapeBounds, mean_superellipse_point, mean_superellipse_radius, parse_floats,
    signed_pow, superellipse_norm,
};
