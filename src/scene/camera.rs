//! A pinhole camera: where primary rays come from, and a default view for scenes without one.

use glam::Vec3;
use rayon::prelude::*;

use crate::geom::{Aabb, Ray};

/// A pinhole camera looking from `eye` at `target`, with `up` fixing the roll and `vfov_deg`
/// the vertical field of view in degrees.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// World-space position of the pinhole, where every primary ray starts.
    pub eye: Vec3,
    /// World-space point at the image centre; must differ from `eye`.
    pub target: Vec3,
    /// World-space up hint, fixing the roll; any length, but not parallel to `target − eye`.
    pub up: Vec3,
    /// Vertical field of view in degrees, in (0, 180).
    pub vfov_deg: f32,
}

/// The vertical field of view of framing cameras, and of cameras that give none: moderate, so
/// perspective stays gentle.
pub const DEFAULT_VFOV_DEG: f32 = 40.0;

/// Aspect ratios are clamped to this range (and its inverse) when framing, so an absurd window
/// shape cannot push the eye to infinity.
const MAX_ASPECT: f32 = 1.0e4;

/// Why [`Camera::look_at`] refused a camera.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum CameraFault {
    /// A coordinate or the field of view is NaN or infinite.
    NotFinite,
    /// The eye is the target: no view direction.
    SameEyeAndTarget,
    /// `up` is zero or parallel to the view direction: no roll.
    BadUp,
    /// The vertical field of view (degrees) is outside (0, 180).
    BadVfov(f32),
}

impl std::fmt::Display for CameraFault {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            CameraFault::NotFinite => write!(f, "camera coordinates must be finite"),
            CameraFault::SameEyeAndTarget => write!(f, "camera `target` must differ from `eye`"),
            CameraFault::BadUp => write!(
                f,
                "camera `up` must be non-zero and not parallel to the view direction"
            ),
            CameraFault::BadVfov(v) => write!(f, "`vfov` must be in (0, 180) degrees, got {v}"),
        }
    }
}

/// The unit vector along `v`, scaled to its largest component first, so that a vector of tiny
/// or huge finite components (1e-30, 1e30), whose squared length underflows or overflows `f32`,
/// keeps its direction; `None` for a zero or non-finite vector.
pub(crate) fn direction(v: Vec3) -> Option<Vec3> {
    let largest = v.abs().max_element();
    if largest > 0.0 && largest.is_finite() {
        (v / largest).try_normalize()
    } else {
        None
    }
}

impl Camera {
    /// The camera at `eye` looking at `target`, rolled by `up`, with a vertical field of view of
    /// `vfov_deg` degrees; refused when it cannot make rays (the fault says why, for the caller
    /// to place: a scene file names the line, the CLI the flag).
    pub fn look_at(
        eye: Vec3,
        target: Vec3,
        up: Vec3,
        vfov_deg: f32,
    ) -> Result<Camera, CameraFault> {
        if !(eye.is_finite() && target.is_finite() && up.is_finite()) {
            return Err(CameraFault::NotFinite);
        }
        let Some(view) = direction(target - eye) else {
            // Equal, or so far apart that their difference overflows.
            return Err(if eye == target {
                CameraFault::SameEyeAndTarget
            } else {
                CameraFault::NotFinite
            });
        };
        if direction(up).is_none_or(|up| view.cross(up).length() < 1.0e-4) {
            return Err(CameraFault::BadUp);
        }
        if !(vfov_deg > 0.0 && vfov_deg < 180.0) {
            return Err(CameraFault::BadVfov(vfov_deg));
        }
        Ok(Camera {
            eye,
            target,
            up,
            vfov_deg,
        })
    }

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
        let half_v = (0.5 * DEFAULT_VFOV_DEG).to_radians();
        let half_h = (half_v.tan() * aspect).atan();
        let distance = radius / half_v.min(half_h).sin();
        Camera {
            eye: center + Vec3::new(0.8, 0.55, 1.3).normalize() * distance,
            target: center,
            up: Vec3::Y,
            vfov_deg: DEFAULT_VFOV_DEG,
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
        let forward = direction(camera.target - camera.eye).unwrap_or(Vec3::NEG_Z);
        // An `up` parallel to the view direction leaves the roll open; any perpendicular will do.
        let right = forward
            .cross(direction(camera.up).unwrap_or(Vec3::ZERO))
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn look_at_refuses_cameras_that_cannot_make_rays() {
        let (eye, target) = (Vec3::new(0.0, 0.0, 4.0), Vec3::ZERO);
        let camera = Camera::look_at(eye, target, Vec3::Y, 30.0).unwrap();
        assert_eq!((camera.eye, camera.vfov_deg), (eye, 30.0));
        let fault = |eye, target, up, vfov| Camera::look_at(eye, target, up, vfov).unwrap_err();
        assert_eq!(
            fault(eye, eye, Vec3::Y, 30.0),
            CameraFault::SameEyeAndTarget
        );
        assert_eq!(fault(Vec3::Y, target, Vec3::Y, 30.0), CameraFault::BadUp);
        assert_eq!(fault(eye, target, Vec3::ZERO, 30.0), CameraFault::BadUp);
        assert_eq!(
            fault(eye, target, Vec3::Y, 180.0),
            CameraFault::BadVfov(180.0)
        );
        assert!(matches!(
            fault(eye, target, Vec3::Y, f32::NAN),
            CameraFault::BadVfov(_)
        ));
        assert_eq!(
            fault(Vec3::NAN, target, Vec3::Y, 30.0),
            CameraFault::NotFinite
        );
        let far = Vec3::new(3e38, 0.0, 0.0);
        assert_eq!(fault(-far, far, Vec3::Y, 30.0), CameraFault::NotFinite);
    }

    /// Directions whose squared length underflows or overflows `f32` keep their direction: a
    /// target 1e-30 beside the eye is looked at, not replaced by -Z, and so is an `up` of 1e30.
    #[test]
    fn tiny_and_huge_directions_are_kept() {
        assert_eq!(direction(Vec3::new(1e-30, 0.0, 0.0)), Some(Vec3::X));
        assert_eq!(direction(Vec3::new(0.0, -1e30, 0.0)), Some(Vec3::NEG_Y));
        assert_eq!(direction(Vec3::ZERO), None);
        let eye = Vec3::new(0.0, 0.0, 4.0);
        let camera =
            Camera::look_at(eye, eye + Vec3::new(1e-30, 0.0, 0.0), Vec3::Y * 1e30, 30.0).unwrap();
        let ray = camera.primary_rays(1, 1)[0];
        assert!((ray.dir() - Vec3::X).length() < 1e-6, "{:?}", ray.dir());
    }
}
