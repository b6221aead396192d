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
/// per-ray record of the LOD trace's cone buffer (`vec2` in `glsl/trace_rbvh_main.glsl`, under `RBVH_LOD`).
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
fn check_cones(rays: &[Ray], cones: &[RayCone]) -> Result<()> {
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

/// The footprints of a batch of rays, as a trace takes them: none, one cone for every ray (a
/// camera's pixel cone: every primary ray of [`RayCone::pixel`] has the same), or one per ray.
/// Only a structure with levels of detail reads them ([`crate::structure::Structure::RbvhLod`]);
/// every other structure ignores them, so that a caller hands its rays' cones to whatever
/// structure it traces without asking which one it is, as a texture sampler takes ray
/// differentials whether or not the texture has mip levels.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum Cones<'a> {
    /// No footprints: a level-of-detail trace refuses such rays.
    #[default]
    None,
    /// The same cone for every ray.
    Same(RayCone),
    /// One cone per ray, in ray order.
    PerRay(&'a [RayCone]),
}

impl<'a> Cones<'a> {
    /// Whether there are footprints at all.
    pub fn is_some(&self) -> bool {
        !matches!(self, Cones::None)
    }

    /// The cones of `rays[range]` (the same cone stays the same); none where a per-ray list is
    /// shorter than `range`, which only a structure that ignores the cones is given.
    pub fn slice(&self, range: std::ops::Range<usize>) -> Cones<'a> {
        match *self {
            Cones::PerRay(cones) => cones.get(range).map_or(Cones::None, Cones::PerRay),
            other => other,
        }
    }

    /// The cone of ray `i`, if there are footprints.
    pub fn get(&self, i: usize) -> Option<RayCone> {
        match *self {
            Cones::None => None,
            Cones::Same(cone) => Some(cone),
            Cones::PerRay(cones) => cones.get(i).copied(),
        }
    }

    /// One cone per ray of `count` rays, for a device buffer; `None` without footprints.
    pub fn per_ray(&self, count: usize) -> Option<std::borrow::Cow<'a, [RayCone]>> {
        match *self {
            Cones::None => None,
            Cones::Same(cone) => Some(std::borrow::Cow::Owned(vec![cone; count])),
            Cones::PerRay(cones) => Some(std::borrow::Cow::Borrowed(cones)),
        }
    }

    /// Checks that the footprints fit `rays`: one valid cone per ray, or one valid cone for all.
    pub fn check(&self, rays: &[Ray]) -> Result<()> {
        match self {
            Cones::None => Ok(()),
            Cones::Same(cone) => cone.validate("cone"),
            Cones::PerRay(cones) => check_cones(rays, cones),
        }
    }
}

impl<'a> From<&'a [RayCone]> for Cones<'a> {
    fn from(cones: &'a [RayCone]) -> Self {
        Cones::PerRay(cones)
    }
}

impl<'a> From<&'a Vec<RayCone>> for Cones<'a> {
    fn from(cones: &'a Vec<RayCone>) -> Self {
        Cones::PerRay(cones)
    }
}

impl From<RayCone> for Cones<'_> {
    fn from(cone: RayCone) -> Self {
        Cones::Same(cone)
    }
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
