//! The texels a view asks for ([`RbvhParams::view_rate`]): where the scene's camera sees a
//! triangle, its texel is at most the view's field of view at the triangle's distance over the
//! rate, however coarse its object's texel. What decides a preset's validity at the paper's
//! scale is the texel against the view, which no rule on the geometry alone can see: a texel of
//! the courtyard is 12 pixels at the arcade five metres from the camera, and every silhouette a
//! height field widens by a texel sends that band of pixels to the wall behind
//! (docs/paper-scale.md, "What the view asks of Q0"). The geometry's rules stay; the view only
//! makes texels finer where it looks closely.

use glam::Vec3;
use rayon::prelude::*;

use crate::scene::Camera;

#[cfg(doc)]
use crate::rbvh::RbvhParams;

/// The widest image, width over height, whose corners the view's cone reaches: the camera
/// gives a vertical field of view only, and the images a scene is rendered at are 4:3, 16:9 or
/// square. A triangle outside a wider image's view is sampled at its object's texel.
pub const VIEW_ASPECT: f32 = 2.0;

/// The finest texel the view asks for, as a fraction of the scene's texel: a surface at the
/// eye would otherwise ask for unbounded texels. 64 times finer is 4,096 times the texels where
/// it binds, which the builder's texel estimate still refuses past its limit.
pub const FINEST_VIEW_TEXEL: f32 = 1.0 / 64.0;

/// Per triangle, the texel `camera` asks of it at `rate` texels across its vertical field of
/// view, where that is finer than `texel_of(i)` (its object's or the scene's texel), or
/// `f32::INFINITY` where the view asks for nothing finer: the triangle's bounding sphere lies
/// outside the cone that holds a [`VIEW_ASPECT`] image (behind the eye, or beside the view).
/// The distance is from the eye to the nearest point of the triangle's box, so that a
/// triangle reaching towards the camera is sampled for its nearest part. Also returns the texels the finer texels add to the estimate
/// the builder checks against its limit (each refined triangle's area over its texel squared,
/// less what its own texel asked).
pub(super) fn view_texels(
    camera: &Camera,
    tris: &[[Vec3; 3]],
    rate: f32,
    scene_texel: f32,
    texel_of: impl Fn(usize) -> f32 + Sync,
) -> (Vec<f32>, f64) {
    let eye = camera.eye;
    let ahead = (camera.target - eye).normalize_or_zero();
    let tan = (camera.vfov_deg.to_radians() * 0.5).tan();
    let cone = (tan * (1.0 + VIEW_ASPECT * VIEW_ASPECT).sqrt()).atan();
    let per_distance = 2.0 * tan / rate;
    let finest = scene_texel * FINEST_VIEW_TEXEL;
    // Whether the cone meets the triangle's bounding sphere (about its centroid): the angle
    // from the axis to the centre, less the angle the sphere subtends, within the cone's; the
    // eye inside the sphere sees it. A big triangle whose corners all lie outside the cone (a
    // floor under the camera) is seen.
    let seen = |t: &[Vec3; 3]| {
        let centre = (t[0] + t[1] + t[2]) / 3.0;
        let radius = t.iter().map(|&p| p.distance(centre)).fold(0.0, f32::max);
        let d = centre - eye;
        let length = d.length();
        if length <= radius {
            return true;
        }
        let off_axis = (d.dot(ahead) / length).clamp(-1.0, 1.0).acos();
        off_axis - (radius / length).asin() <= cone
    };
    let texels: Vec<(f32, f64)> = tris
        .par_iter()
        .enumerate()
        .map(|(i, t)| {
            if !seen(t) {
                return (f32::INFINITY, 0.0);
            }
            let nearest = eye.clamp(t[0].min(t[1]).min(t[2]), t[0].max(t[1]).max(t[2]));
            let asked = ((nearest - eye).length() * per_distance).max(finest);
            let own = texel_of(i);
            if asked < own {
                let [a, b, c] = t.map(|p| p.as_dvec3());
                let area = (b - a).cross(c - a).length() * 0.5;
                let added = area / f64::from(asked).powi(2) - area / f64::from(own).powi(2);
                (asked, added)
            } else {
                (f32::INFINITY, 0.0)
            }
        })
        .collect();
    let added = texels.iter().map(|&(_, a)| a).sum();
    (texels.into_iter().map(|(t, _)| t).collect(), added)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A camera at the origin looking down −z with a 90° field: the field at distance d is 2d.
    fn camera() -> Camera {
        Camera {
            eye: Vec3::ZERO,
            target: Vec3::NEG_Z,
            up: Vec3::Y,
            vfov_deg: 90.0,
        }
    }

    /// A small triangle around `at`.
    fn triangle(at: Vec3) -> [Vec3; 3] {
        [
            at,
            at + Vec3::new(0.01, 0.0, 0.0),
            at + Vec3::new(0.0, 0.01, 0.0),
        ]
    }

    #[test]
    fn the_view_asks_its_field_over_the_rate_at_each_distance() {
        let tris = [
            triangle(Vec3::new(0.0, 0.0, -4.0)),
            triangle(Vec3::new(0.0, 0.0, -16.0)),
        ];
        let (texels, added) = view_texels(&camera(), &tris, 64.0, 1.0, |_| 1.0);
        // 2 · 4 / 64 and 2 · 16 / 64 (the nearest point of each box lies on the axis).
        assert!((texels[0] - 0.125).abs() < 1e-6, "{}", texels[0]);
        assert!((texels[1] - 0.5).abs() < 1e-6, "{}", texels[1]);
        let area = 0.5 * 0.01 * 0.01;
        let expected = area * (64.0 + 4.0) - 2.0 * area;
        assert!((added - expected).abs() < 1e-6 * expected, "{added}");
    }

    #[test]
    fn a_texel_the_object_already_has_finer_is_left_alone() {
        let tris = [triangle(Vec3::new(0.0, 0.0, -4.0))];
        let (texels, added) = view_texels(&camera(), &tris, 64.0, 1.0, |_| 0.1);
        assert_eq!(texels, [f32::INFINITY]);
        assert_eq!(added, 0.0);
    }

    #[test]
    fn what_the_view_does_not_see_is_not_refined() {
        let tris = [
            // Behind the eye.
            triangle(Vec3::new(0.0, 0.0, 4.0)),
            // 60° off the axis: inside the cone of a 90° field's 2:1 image, whose corners lie
            // atan(√5) = 65.9° off the axis.
            triangle(Vec3::new(4.0 * 60f32.to_radians().tan(), 0.0, -4.0)),
            // 80° off the axis: outside.
            triangle(Vec3::new(4.0 * 80f32.to_radians().tan(), 0.0, -4.0)),
        ];
        let (texels, _) = view_texels(&camera(), &tris, 64.0, 1.0, |_| 1.0);
        assert_eq!(texels[0], f32::INFINITY);
        assert!(texels[1].is_finite());
        assert_eq!(texels[2], f32::INFINITY);
    }

    /// A long sliver crossing the view one unit ahead, whose corners and centroid all lie
    /// outside the cone, is seen through its middle: its bounding sphere meets the cone.
    #[test]
    fn a_big_triangle_seen_between_its_corners_is_refined() {
        let sliver = [[
            Vec3::new(-100.0, 0.0, -1.0),
            Vec3::new(100.0, 0.0, -1.0),
            Vec3::new(100.0, 0.01, -1.0),
        ]];
        let (texels, _) = view_texels(&camera(), &sliver, 64.0, 1.0, |_| 1.0);
        // Its nearest point lies on the axis, 1 ahead: 2 · 1 / 64.
        assert!((texels[0] - 1.0 / 32.0).abs() < 1e-6, "{}", texels[0]);
    }

    #[test]
    fn a_surface_at_the_eye_asks_no_finer_than_the_floor() {
        let tris = [[
            Vec3::new(-1.0, -1.0, -0.001),
            Vec3::new(1.0, -1.0, -0.001),
            Vec3::new(0.0, 1.0, -0.001),
        ]];
        let (texels, _) = view_texels(&camera(), &tris, 64.0, 2.0, |_| 2.0);
        assert_eq!(texels, [2.0 * FINEST_VIEW_TEXEL]);
    }
}
