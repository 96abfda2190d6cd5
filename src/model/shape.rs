use glam::{DMat3, DQuat, DVec3};
use serde::{Deserialize, Serialize};

/// Intrinsic parameters v_i = (a1, a2, a3, a4, eps1, eps2) of paper eq. (2)/(3).
///
/// a1, a2, a3 are the sizes along the canonical x, y, z axes; a4 is the (dimensionless)
/// radius of the mean superellipse in units of a1/a2 (a4 = 0: superellipsoid, 0 < a4 < 1:
/// apple shape, a4 > 1: a real hole); eps1 shapes the cross-section (meridian) curve and
/// eps2 the top-view (x-y) curve.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct Shape {
    pub a1: f64,
    pub a2: f64,
    pub a3: f64,
    pub a4: f64,
    pub eps1: f64,
    pub eps2: f64,
}

/// Bounds the fit keeps the shape in (defaults are the paper's: eps in [0.1, 2]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShapeBounds {
    pub eps_min: f64,
    pub eps_max: f64,
    pub a4_max: f64,
}

impl Default for ShapeBounds {
    fn default() -> Self {
        Self {
            eps_min: 0.1,
            eps_max: 2.0,
            a4_max: 10.0,
        }
    }
}

impl Shape {
    pub const fn new(a1: f64, a2: f64, a3: f64, a4: f64, eps1: f64, eps2: f64) -> Self {
        Self {
            a1,
            a2,
            a3,
            a4,
            eps1,
            eps2,
        }
    }

    pub fn to_array(self) -> [f64; 6] {
        [self.a1, self.a2, self.a3, self.a4, self.eps1, self.eps2]
    }

    pub fn from_array(v: [f64; 6]) -> Self {
        Self::new(v[0], v[1], v[2], v[3], v[4], v[5])
    }

    /// Parses "a1,a2,a3,a4,eps1,eps2" (the CLI's `--shape`).
    pub fn parse(text: &str) -> Result<Self, String> {
        let v = parse_floats::<6>(text, "shape a1,a2,a3,a4,eps1,eps2")?;
        let s = Self::from_array(v);
        s.validate()?;
        Ok(s)
    }

    /// A shape is usable when every size is positive, a4 >= 0 and both exponents are in
    /// (0, 4]; the fit itself keeps tighter bounds (see [`ShapeBounds`]).
    pub fn validate(&self) -> Result<(), String> {
        let v = self.to_array();
        if v.iter().any(|x| !x.is_finite()) {
            return Err(format!("shape has a non-finite value: {v:?}"));
        }
        if self.a1 <= 0.0 || self.a2 <= 0.0 || self.a3 <= 0.0 {
            return Err(format!("a1, a2, a3 must be > 0, got {v:?}"));
        }
        if self.a4 < 0.0 {
            return Err(format!("a4 must be >= 0, got {}", self.a4));
        }
        if !(self.eps1 > 0.0 && self.eps1 <= 4.0 && self.eps2 > 0.0 && self.eps2 <= 4.0) {
            return Err(format!(
                "eps1, eps2 must be in (0, 4], got {}, {}",
                self.eps1, self.eps2
            ));
        }
        Ok(())
    }

    /// The smallest of a1, a2, a3: what sensor noise has to be small against for the
    /// shape to be measurable.
    pub fn thinnest_half_axis(&self) -> f64 {
        self.a1.min(self.a2).min(self.a3)
    }

    /// Half-extents of the canonical bounding box: the supertoroid lies within
    /// |x| <= a1(1+a4), |y| <= a2(1+a4), |z| <= a3 (paper, after eq. 3).
    pub fn half_extents(&self) -> DVec3 {
        DVec3::new(
            self.a1 * (1.0 + self.a4),
            self.a2 * (1.0 + self.a4),
            self.a3,
        )
    }

    /// The object's size used for relative tolerances (noise, errors): the half-diagonal
    /// of the canonical bounding box.
    pub fn size(&self) -> f64 {
        self.half_extents().length()
    }

    /// G(p) = (|x/a1|^(2/eps2) + |y/a2|^(2/eps2))^(eps2/2): the top-view superellipse
    /// "norm", homogeneous of degree one in (x, y). G = a4 on the mean superellipse (eq. 5).
    pub fn top_view_norm(&self, x: f64, y: f64) -> f64 {
        superellipse_norm(x / self.a1, y / self.a2, self.eps2)
    }

    /// Inside-outside function F_t of paper eq. (3): < 1 inside, = 1 on, > 1 outside.
    pub fn inside_outside(&self, p: DVec3) -> f64 {
        let g = self.top_view_norm(p.x, p.y);
        let e = 2.0 / self.eps1;
        (g - self.a4).abs().powf(e) + (p.z / self.a3).abs().powf(e)
    }

    /// The section "norm" N = F_t^(eps1/2), homogeneous of degree one in the section
    /// coordinates (G - a4, z/a3); computed without raising to 2/eps1 so it neither
    /// overflows nor underflows for small eps1.
    pub fn section_norm(&self, p: DVec3) -> f64 {
        let g = self.top_view_norm(p.x, p.y);
        superellipse_norm(g - self.a4, p.z / self.a3, self.eps1)
    }

    /// Parametric surface r_t(eta, omega) of paper eq. (2), with signed powers.
    ///
    /// Only the part of the parameter domain where a4 + cos^eps1(eta) >= 0 lies on the
    /// implicit surface (3); for a4 >= 1 that is everything, for a4 < 1 the rest folds
    /// through the z axis. [`Shape::eta_range`] gives the valid interval.
    pub fn surface_point(&self, eta: f64, omega: f64) -> DVec3 {
        let c = self.a4 + signed_pow(eta.cos(), self.eps1);
        DVec3::new(
            self.a1 * c * signed_pow(omega.cos(), self.eps2),
            self.a2 * c * signed_pow(omega.sin(), self.eps2),
            self.a3 * signed_pow(eta.sin(), self.eps1),
        )
    }

    /// The eta interval [-eta_max, eta_max] on which r_t lies on the implicit surface:
    /// eta_max = pi for a4 >= 1, and acos(-a4^(1/eps1)) below that (pi/2 at a4 = 0, the
    /// superellipsoid).
    pub fn eta_range(&self) -> f64 {
        if self.a4 >= 1.0 {
            std::f64::consts::PI
        } else {
            (-self.a4.powf(1.0 / self.eps1)).acos()
        }
    }

    /// True when the surface has a through hole (a4 > 1).
    pub fn has_hole(&self) -> bool {
        self.a4 > 1.0
    }

    /// How far the surface dips below its top where it meets the z axis (the surface at
    /// [`Shape::eta_range`]): 0 for a superellipsoid, an apple's dimple for 0 < a4 < 1,
    /// infinite for a ring (a4 >= 1).
    pub fn dimple_depth(&self) -> f64 {
        if self.a4 >= 1.0 {
            return f64::INFINITY;
        }
        self.a3 - self.surface_point(self.eta_range(), 0.0).z
    }
}

/// sign(x)·|x|^e, the paper's convention for cos^eps and sin^eps.
pub fn signed_pow(x: f64, e: f64) -> f64 {
    x.signum() * x.abs().powf(e)
}

/// (|u|^(2/eps) + |v|^(2/eps))^(eps/2), scaled by the larger component so that large
/// exponents (eps -> 0.1 gives 20) neither overflow nor underflow.
pub fn superellipse_norm(u: f64, v: f64, eps: f64) -> f64 {
    let (u, v) = (u.abs(), v.abs());
    let m = u.max(v);
    if m == 0.0 || !m.is_finite() {
        return m;
    }
    // the larger component contributes exactly 1; one ln/exp pair for the other
    let t = u.min(v) / m;
    let p = if t == 0.0 {
        0.0
    } else {
        (2.0 / eps * t.ln()).exp()
    };
    m * ((1.0 + p).ln() * (eps / 2.0)).exp()
}

/// Point of the mean superellipse r_m(omega) (eq. 6).
pub fn mean_superellipse_point(shape: &Shape, omega: f64) -> [f64; 2] {
    [
        shape.a1 * shape.a4 * signed_pow(omega.cos(), shape.eps2),
        shape.a2 * shape.a4 * signed_pow(omega.sin(), shape.eps2),
    ]
}

/// Radius of the mean superellipse at parameter omega (eq. 7).
pub fn mean_superellipse_radius(shape: &Shape, omega: f64) -> f64 {
    let [x, y] = mean_superellipse_point(shape, omega);
    x.hypot(y)
}

/// Rigid pose: a canonical point p maps to the world as R·p + t.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose {
    pub rotation: DQuat,
    pub translation: DVec3,
}

impl Default for Pose {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl Pose {
    pub const IDENTITY: Self = Self {
        rotation: DQuat::IDENTITY,
        translation: DVec3::ZERO,
    };

    pub fn new(rotation: DQuat, translation: DVec3) -> Self {
        Self {
            rotation: rotation.normalize(),
            translation,
        }
    }

    pub fn matrix(&self) -> DMat3 {
        DMat3::from_quat(self.rotation)
    }

    pub fn to_world(&self, canonical: DVec3) -> DVec3 {
        self.rotation * canonical + self.translation
    }

    pub fn to_canonical(&self, world: DVec3) -> DVec3 {
        self.rotation.inverse() * (world - self.translation)
    }

    /// This pose after `inner`: canonical points mapped by `inner`, then by this pose (a
    /// fit in a camera's frame taken to the world by the camera's pose).
    pub fn compose(&self, inner: &Pose) -> Pose {
        Pose::new(
            self.rotation * inner.rotation,
            self.to_world(inner.translation),
        )
    }

    /// The hole axis (canonical z) in world coordinates.
    pub fn axis(&self) -> DVec3 {
        self.rotation * DVec3::Z
    }

    /// Parses the CLI's "--translation x,y,z" and "--quaternion w,x,y,z" (either optional).
    pub fn parse(translation: Option<&str>, quaternion_wxyz: Option<&str>) -> Result<Self, String> {
        let t = match translation {
            Some(s) => DVec3::from_array(parse_floats::<3>(s, "translation x,y,z")?),
            None => DVec3::ZERO,
        };
        let q = match quaternion_wxyz {
            Some(s) => {
                let [w, x, y, z] = parse_floats::<4>(s, "quaternion w,x,y,z")?;
                let q = DQuat::from_xyzw(x, y, z, w);
                if q.length() < 1e-12 {
                    return Err("quaternion must not be zero".into());
                }
                q.normalize()
            }
            None => DQuat::IDENTITY,
        };
        Ok(Self::new(q, t))
    }
}

/// Parses exactly `N` comma-separated finite floats.
pub fn parse_floats<const N: usize>(text: &str, what: &str) -> Result<[f64; N], String> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    if parts.len() != N {
        return Err(format!(
            "{what}: expected {N} comma-separated numbers, got {:?}",
            text
        ));
    }
    let mut out = [0.0; N];
    for (o, p) in out.iter_mut().zip(&parts) {
        *o = p
            .parse::<f64>()
            .map_err(|_| format!("{what}: {p:?} is not a number"))?;
        if !o.is_finite() {
            return Err(format!("{what}: {p:?} is not finite"));
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A superellipsoid has no dimple and a ring a hole; an apple's dimple is deep where
    /// its section is round and vanishes as its section squares off (a box's shallow
    /// apple fit).
    #[test]
    fn an_apples_dimple_is_where_its_surface_meets_its_axis() {
        let depth = |a4, eps1| Shape::new(0.04, 0.03, 0.05, a4, eps1, 1.0).dimple_depth();
        assert_eq!(depth(0.0, 0.5), 0.0);
        assert_eq!(depth(1.5, 0.5), f64::INFINITY);
        // round section: it meets the axis at cos(eta) = -a4, z = a3·sqrt(1 - a4²)
        let expected = 0.05 * (1.0 - (1.0f64 - 0.49).sqrt());
        assert!(
            (depth(0.7, 1.0) - expected).abs() < 1e-12,
            "{}",
            depth(0.7, 1.0)
        );
        // a squared-off section: under a thousandth of its height
        assert!(depth(0.55, 0.19) < 1e-3 * 0.05, "{}", depth(0.55, 0.19));
    }

    /// Nothing beyond the bounding box is inside the solid: the meridian distance of a
    /// point past any of the box's faces is never negative, whatever the shape (the
    /// evaluators skip free-space points there).
    #[test]
    fn no_point_beyond_the_bounding_box_is_inside() {
        use crate::suite::ground_truth::{random_shape, random_superellipsoid};
        use rand::Rng;
        let mut rng = crate::synth::rng(3);
        for i in 0..2000 {
            // superellipsoids, rings and apples (0 < a4 < 1)
            let shape = match i % 3 {
                0 => random_superellipsoid(&mut rng).0,
                1 => random_shape(&mut rng).0,
                _ => Shape {
                    a4: rng.random_range(0.05..1.0),
                    ..random_shape(&mut rng).0
                },
            };
            let half = shape.half_extents();
            // just past one face, anywhere across the others (and beyond them)
            let axis = rng.random_range(0..3);
            let mut q = DVec3::new(
                rng.random_range(-1.5..1.5) * half.x,
                rng.random_range(-1.5..1.5) * half.y,
                rng.random_range(-1.5..1.5) * half.z,
            );
            let past = half[axis] * rng.random_range(1.0001..1.2);
            q[axis] = if rng.random_bool(0.5) { past } else { -past };
            let signed = crate::model::meridian_distance(&shape, q).signed;
            assert!(signed >= 0.0, "{shape:?} {q} {signed}");
        }
    }

    #[test]
    fn a_composed_pose_maps_a_point_as_its_two_poses_in_turn() {
        let outer = Pose::new(DQuat::from_rotation_x(0.7), DVec3::new(1.0, -2.0, 0.5));
        let inner = Pose::new(DQuat::from_rotation_z(-1.1), DVec3::new(0.2, 0.3, 4.0));
        let p = DVec3::new(0.3, -0.4, 0.9);
        let composed = outer.compose(&inner).to_world(p);
        assert!(composed.distance(outer.to_world(inner.to_world(p))) < 1e-12);
    }
}
