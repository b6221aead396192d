//! A pinhole camera: where primary rays come from, and a default view for scenes without one.

use glam::Vec3;
use rayon::prelude::*;

use crate::geom::{Aabb, Ray};

/// A pinhole camera looking from `eye` at `target`, with `up` fixing the roll and `vfov_deg`
/// the vertical field of view in degrees.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    pub eye: Vec3,
    pub target: Vec3,
    pub up: Vec3,
    pub vfov_deg: f32,
}

/// The vertical field of view of framing cameras: moderate, so perspective stays gentle.
const FRAMING_VFOV_DEG: f32 = 40.0;

/// Aspect ratios are clamped to this range (and its inverse) when framing, so an absurd window
/// shape cannot push the eye to infinity.
const MAX_ASPECT: f32 = 1.0e4;

impl Camera {
    /// Frames `bounds` for images of `aspect` = width/height: looks at the centre from the
    /// direction (0.8, 0.55, 1.3), a three-quarter view from above that shows three faces of a
    /// box, far enough that the bounding sphere fits both the vertical and the horizontal field
    /// of view. Empty, flat and single-point boxes still give a finite camera: an empty box is
    /// treated as the unit sphere at the origin, and a point gets a radius large enough that
    /// the eye stays distinguishable from the target in `f32`.
    pub fn framing(bounds: &Aabb, aspect: f32) -> Camera {
        let (center, radius) = bounding_sphere(bounds);
        let aspect = if aspect.is_finite() && aspect > 0.0 {
            aspect.clamp(1.0 / MAX_ASPECT, MAX_ASPECT)
        } else {
            1.0
        };
        let half_v = (0.5 * FRAMING_VFOV_DEG).to_radians();
        let half_h = (half_v.tan() * aspect).atan();
        let distance = radius / half_v.min(half_h).sin();
        Camera {
            eye: center + Vec3::new(0.8, 0.55, 1.3).normalize() * distance,
            target: center,
            up: Vec3::Y,
            vfov_deg: FRAMING_VFOV_DEG,
        }
    }

    /// One ray per pixel centre of a `width` × `height` image, row-major with the top row
    /// first (the order of image files), unit directions, `tmin` 0 and `tmax` +∞.
    pub fn primary_rays(&self, width: u32, height: u32) -> Vec<Ray> {
        let view = &View::new(self, width, height);
        (0..height)
            .into_par_iter()
            .flat_map_iter(|y| (0..width).map(move |x| view.ray(x as f32 + 0.5, y as f32 + 0.5)))
            .collect()
    }

    /// The ray through image position (`x`, `y`) in pixel units: (0.5, 0.5) is the centre of
    /// the top-left pixel and (`width`/2, `height`/2) the image centre, which looks at `target`.
    pub fn ray(&self, x: f32, y: f32, width: u32, height: u32) -> Ray {
        View::new(self, width, height).ray(x, y)
    }
}

/// The centre and radius of the sphere around `bounds` that framing fits into the view.
fn bounding_sphere(bounds: &Aabb) -> (Vec3, f32) {
    let (center, radius) = (bounds.center(), 0.5 * bounds.diagonal());
    if bounds.is_empty() || !center.is_finite() || !radius.is_finite() {
        return (Vec3::ZERO, 1.0);
    }
    // Far from the origin, a tiny radius would put the eye within rounding of the target.
    let floor = center.abs().max_element() * 1.0e-4;
    let radius = if radius > floor {
        radius
    } else {
        floor.max(1.0)
    };
    (center, radius)
}

/// A camera resolved for one image size: the pixel-to-direction mapping, computed once per
/// image rather than once per ray.
struct View {
    eye: Vec3,
    forward: Vec3,
    /// Image-plane axes at unit distance, scaled so that ±1 reaches the image's edges.
    right: Vec3,
    up: Vec3,
    inv_width: f32,
    inv_height: f32,
}

impl View {
    fn new(camera: &Camera, width: u32, height: u32) -> View {
        let (width, height) = (width.max(1) as f32, height.max(1) as f32);
        let forward = (camera.target - camera.eye).normalize_or(Vec3::NEG_Z);
        // An `up` parallel to the view direction leaves the roll open; any perpendicular will do.
        let right = forward
            .cross(camera.up)
            .try_normalize()
            .unwrap_or_else(|| forward.any_orthonormal_vector());
        let up = right.cross(forward);
        let tan_half = (0.5 * camera.vfov_deg).to_radians().tan();
        View {
            eye: camera.eye,
            forward,
            right: right * (tan_half * width / height),
            up: up * tan_half,
            inv_width: 1.0 / width,
            inv_height: 1.0 / height,
        }
    }

    fn ray(&self, x: f32, y: f32) -> Ray {
        let sx = 2.0 * x * self.inv_width - 1.0;
        let sy = 1.0 - 2.0 * y * self.inv_height;
        let dir = (self.forward + sx * self.right + sy * self.up).normalize();
        Ray::new(self.eye, dir, 0.0, f32::INFINITY)
    }
}
