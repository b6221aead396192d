//! The preview image: Lambert shading under the scene's light, with the hit surfaces' base colour
//! as albedo where the scene has materials or the RBVH a colour channel
//! ([`crate::surface::hit_albedo`]), else the neutral grey of [`crate::output::shade`]. One
//! function for what `rbvh render` writes and what the image regression compares with its
//! goldens, so that the goldens guard the path users run.

use crate::geom::{Hit, Ray};
use crate::lod::Lod;
use crate::output::{shade as shade_grey, shade_with_albedo, Image};
use crate::rbvh::Rbvh;
use crate::scene::Scene;
use crate::surface::hit_albedo;
use crate::Result;

/// The preview of `hits` (one per ray of `rays`, a `width` × `height` image in row order) of
/// `scene`, traced through `rbvh` (with its levels of detail `lod`) or, when `rbvh` is None,
/// through the exact BVH.
pub fn shade(
    scene: &Scene,
    rbvh: Option<&Rbvh>,
    lod: Option<&Lod>,
    rays: &[Ray],
    hits: &[Hit],
    width: u32,
    height: u32,
) -> Result<Image> {
    let light = scene.light.as_ref();
    match hit_albedo(scene, rbvh, lod, rays, hits) {
        Some(albedo) => shade_with_albedo(rays, hits, width, height, light, &albedo),
        None => shade_grey(rays, hits, width, height, light),
    }
}
