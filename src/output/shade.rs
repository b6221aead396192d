//! Preview shading of traced hits. Deliberately simple and deterministic: a picture to check
//! shape and orientation at a glance, not a render. Nothing here traces rays, so there are no
//! shadows.

use glam::Vec3;
use rayon::prelude::*;

use super::image::{check_per_pixel, Image};
use crate::geom::{Hit, Ray};
use crate::scene::Light;

/// Neutral grey, so that the shape reads from the shading alone, not from colour.
const ALBEDO: f32 = 0.8;
/// Keeps surfaces facing away from the light visible rather than black.
const AMBIENT: f32 = 0.15;
/// With the ambient term, a surface facing the light straight on reaches exactly [`ALBEDO`].
const KEY: f32 = 1.0 - AMBIENT;
/// Sky colours looking straight down and straight up; misses get a gradient between them so that
/// the background is distinguishable from an unlit surface and shows which way is up.
const SKY_DOWN: Vec3 = Vec3::new(0.7, 0.72, 0.75);
const SKY_UP: Vec3 = Vec3::new(0.25, 0.38, 0.6);

/// Shades one hit per pixel for a preview.
///
/// A hit is Lambertian with a neutral grey albedo (0.8) under one key light plus an ambient term
/// (0.15), so a surface facing the key light straight on is exactly 0.8. The geometric
/// normal is flipped to face the ray, so back faces shade like front faces (the tracers do not
/// cull). The key light is `light` when given (a [`Light::Directional`] light travels along its
/// `direction`; a [`Light::Point`] light shines from its `position`, without distance falloff so
/// that the exposure does not depend on the scene's scale), and otherwise a headlight at the ray
/// origin, which lights every visible surface. Misses show a vertical sky gradient by the ray
/// direction's `y`.
///
/// `rays` and `hits` must both have `width × height` entries, row-major, top row first.
pub fn shade(
    rays: &[Ray],
    hits: &[Hit],
    width: u32,
    height: u32,
    light: Option<&Light>,
) -> crate::Result<Image> {
    check_per_pixel("rays", rays.len(), width, height)?;
    check_per_pixel("hits", hits.len(), width, height)?;
    let pixels = rays
        .par_iter()
        .zip(hits)
        .map(|(ray, hit)| shade_one(ray, hit, light, Vec3::ONE))
        .collect();
    Ok(Image {
        width,
        height,
        pixels,
    })
}

/// As [`shade`], with the grey albedo multiplied per pixel by `albedo` (linear RGB, e.g. the base
/// colours of [`crate::surface::hit_albedo`]); `albedo` must have `width × height` entries. An
/// all-white `albedo` gives exactly the image of [`shade`].
pub fn shade_with_albedo(
    rays: &[Ray],
    hits: &[Hit],
    width: u32,
    height: u32,
    light: Option<&Light>,
    albedo: &[Vec3],
) -> crate::Result<Image> {
    check_per_pixel("rays", rays.len(), width, height)?;
    check_per_pixel("hits", hits.len(), width, height)?;
    check_per_pixel("albedo", albedo.len(), width, height)?;
    let pixels = rays
        .par_iter()
        .zip(hits)
        .zip(albedo)
        .map(|((ray, hit), &a)| shade_one(ray, hit, light, a))
        .collect();
    Ok(Image {
        width,
        height,
        pixels,
    })
}

/// Shows hit normals as colours, `n * 0.5 + 0.5`, with misses black. The normal is shown as
/// wound, not flipped towards the ray, so that inconsistent winding in a mesh is visible.
///
/// `rays` and `hits` must both have `width × height` entries; `rays` is only checked, so that
/// the signature matches [`shade`] and a mismatched pair of buffers is caught here too.
pub fn shade_normals(rays: &[Ray], hits: &[Hit], width: u32, height: u32) -> crate::Result<Image> {
    check_per_pixel("rays", rays.len(), width, height)?;
    check_per_pixel("hits", hits.len(), width, height)?;
    let pixels = hits
        .par_iter()
        .map(|hit| {
            if hit.is_hit() {
                hit.normal() * 0.5 + 0.5
            } else {
                Vec3::ZERO
            }
        })
        .collect();
    Ok(Image {
        width,
        height,
        pixels,
    })
}

fn shade_one(ray: &Ray, hit: &Hit, light: Option<&Light>, albedo: Vec3) -> Vec3 {
    let dir = ray.dir().normalize_or_zero();
    if !hit.is_hit() {
        return sky(dir);
    }
    let mut normal = hit.normal().normalize_or_zero();
    if normal.dot(dir) > 0.0 {
        normal = -normal;
    }
    let to_light = match light {
        Some(Light::Directional { direction }) => -direction.normalize_or_zero(),
        Some(Light::Point { position }) => {
            let point = ray.origin() + hit.t * ray.dir();
            (*position - point).normalize_or_zero()
        }
        None => -dir,
    };
    albedo * (ALBEDO * (AMBIENT + KEY * normal.dot(to_light).max(0.0)))
}

fn sky(dir: Vec3) -> Vec3 {
    SKY_DOWN.lerp(SKY_UP, 0.5 * (dir.y + 1.0))
}
