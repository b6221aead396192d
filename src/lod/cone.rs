//! Ray cones: the footprint a ray stands for, after Akenine-Möller et al., "Texture Level of
//! Detail Strategies for Real-Time Ray Tracing" (Ray Tracing Gems, 2019, ch. 20), and Amanatides,
//! "Ray Tracing with Cones" (SIGGRAPH 1984). A cone's width at distance `t` is
//! `width + spread · t`; level-of-detail traversal uses the coarsest representation whose column,
//! scaled by the LOD bias ([`crate::lod::LodParams::selection_width`]), is no larger than that
//! width where the ray enters it.

use bytemuck::{Pod, Zeroable};

use crate::geom::Ray;
use crate::scene::Camera;
use crate::{Error, Result};

/// The cone of one ray: `width` (world units) at `t = 0` and `spread`, the growth of the width per
/// unit of `t` (for a unit direction, the cone's full angle in radians, small-angle). 8 bytes; the
/// per-ray record of the LOD trace's cone buffer (`vec2` in `glsl/trace_rbvh_lod.comp`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct RayCone {
    /// Footprint width at the ray origin (`t = 0`), world units; ≥ 0.
    pub width: f32,
    /// Growth of the width per unit of `t`, ≥ 0 (radians of full cone angle for a unit direction).
    pub spread: f32,
}
const _: () = assert!(std::mem::size_of::<RayCone>() == 8);

impl RayCone {
    /// A ray with no footprint: level-of-detail traversal then never leaves the finest data.
    pub const POINT: RayCone = RayCone {
        width: 0.0,
        spread: 0.0,
    };

    /// The cone of a pixel of a pinhole camera: spread `α = atan(2·tan(fov/2) / height)`, the
    /// angle one pixel subtends at the image centre (Akenine-Möller et al. 2019, eq. 20.1), and no
    /// width at the eye. Every pixel's ray gets the same cone (the centre pixel's, the largest).
    pub fn pixel(camera: &Camera, height: u32) -> RayCone {
        let tan_half = (0.5 * camera.vfov_deg).to_radians().tan();
        RayCone {
            width: 0.0,
            spread: (2.0 * tan_half / height.max(1) as f32).atan(),
        }
    }

    /// The width at ray parameter `t`.
    pub fn width_at(&self, t: f32) -> f32 {
        self.width + self.spread * t
    }

    /// Checks that the cone is finite and not negative, naming it `what`.
    pub fn validate(&self, what: &str) -> Result<()> {
        if self.width.is_finite()
            && self.spread.is_finite()
            && self.width >= 0.0
            && self.spread >= 0.0
        {
            Ok(())
        } else {
            Err(Error::param(
                what,
                format!(
                    "cone width {} and spread {} must be finite and not negative",
                    self.width, self.spread
                ),
            ))
        }
    }
}

/// The level-of-detail rule, shared by the CPU caster and (as its GLSL twin) the shader: a coarse
/// representation whose selection width is `texel_size` (its column width scaled by the LOD
/// bias, [`crate::lod::LodParams::selection_width`]) is used for a ray that enters it at
/// `t_entry` when that width is no larger than the cone there. The cone only widens with `t`, so for one ray
/// the selection is monotone: whatever is chosen at some distance is chosen at every larger one.
/// A node without a coarse representation (`texel_size` +inf, or 0 in a tree whose nodes were not
/// annotated, see [`crate::lod::Lod::annotated_nodes`]) is never chosen, whatever the cone.
#[inline]
pub fn selects(texel_size: f32, cone: &RayCone, t_entry: f32) -> bool {
    texel_size.is_finite() && texel_size > 0.0 && texel_size <= cone.width + cone.spread * t_entry
}

/// Checks that there is one valid cone per ray.
pub fn check_cones(rays: &[Ray], cones: &[RayCone]) -> Result<()> {
    if rays.len() != cones.len() {
        return Err(Error::param(
            "cones",
            format!("{} cones for {} rays", cones.len(), rays.len()),
        ));
    }
    cones
        .iter()
        .enumerate()
        .try_for_each(|(i, c)| c.validate(&format!("cone {i}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn selection_is_monotone_in_distance() {
        let cone = RayCone {
            width: 0.01,
            spread: 0.002,
        };
        for texel in [0.005, 0.02, 0.5, 3.0] {
            let mut chosen = false;
            for k in 0..10_000 {
                let t = k as f32 * 0.5;
                let now = selects(texel, &cone, t);
                assert!(
                    !chosen || now,
                    "texel {texel}: chosen before t = {t}, not at it"
                );
                chosen |= now;
            }
        }
        assert!(!selects(0.5, &RayCone::POINT, 1e30));
        let huge = RayCone {
            width: 0.0,
            spread: 1e38,
        };
        assert!(!selects(f32::INFINITY, &huge, 10.0));
        assert!(!selects(0.0, &huge, 10.0));
    }

    #[test]
    fn pixel_cone_spans_one_pixel_at_the_image_centre() {
        let camera = Camera {
            eye: glam::Vec3::ZERO,
            target: glam::Vec3::NEG_Z,
            up: glam::Vec3::Y,
            vfov_deg: 90.0,
        };
        let cone = RayCone::pixel(&camera, 100);
        // The image plane at distance 1 is 2 units tall: one pixel is 0.02 there.
        assert!((cone.width_at(1.0) - 0.02).abs() < 1e-4, "{cone:?}");
        assert!(RayCone {
            width: -1.0,
            spread: 0.0
        }
        .validate("c")
        .is_err());
        assert!(RayCone {
            width: 0.0,
            spread: f32::NAN
        }
        .validate("c")
        .is_err());
    }
}
