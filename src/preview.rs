//! The preview image: Lambert shading under the scene's light, with the hit surfaces' base colour
//! as albedo where the scene has materials or the RBVH a colour channel
//! ([`crate::surface::hit_albedo`]), else the neutral grey of [`crate::output::shade`]. One
//! function for what `rbvh render` writes and what the image regression compares with its
//! goldens, so that the goldens guard the path users run.

use crate::geom::{Hit, Ray};
use crate::output::{shade as shade_grey, shade_with_albedo, Image};
use crate::scene::SceneView;
use crate::structure::Structure;
use crate::surface::hit_albedo;
use crate::Result;

/// The preview of `hits` (one per ray of `rays`, a `width` × `height` image in row order) of
/// `scene` (flat, or its instances traced in two levels), traced through `structure`.
pub fn shade<'a>(
    scene: impl Into<SceneView<'a>>,
    structure: &Structure,
    rays: &[Ray],
    hits: &[Hit],
    width: u32,
    height: u32,
) -> Result<Image> {
    let scene = scene.into();
    let light = scene.light();
    match hit_albedo(scene, structure, rays, hits) {
        Some(albedo) => shade_with_albedo(rays, hits, width, height, light, &albedo),
        None => shade_grey(rays, hits, width, height, light),
    }
}
