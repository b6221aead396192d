//! Baking the scene's base colour into the RBVH's colour channel at build time. The atlas is a
//! parameterization of the surface (Novák & Dachsbacher 2012 list "a surface parameterization for
//! free" among the RBVH's properties, and painting among its applications), so each height-field
//! texel can carry the colour of the surface point it samples.
//!
//! That point is the one the rasterizer sampled: the texel centre on the triangle that won the
//! texel ([`Tile::sources`]: the first writer, or for a dilated rim texel the neighbour's
//! triangle). Its barycentrics are those of the texel centre in the leaf's projection along `w`,
//! the same 2D interpolation the rasterizer used for the height; they are clamped to the triangle
//! for rim texels (which lie just outside it). Barycentrics → texture coordinates → bilinear
//! sample ([`crate::scene::SurfaceMaterials::colour`]) → [`super::rgba::pack`].

use glam::{DVec2, Vec3};
use rayon::prelude::*;

use super::rgba;
use crate::rbvh::raster::{Tile, NO_SOURCE};
use crate::scene::material::clamp_to_triangle;
use crate::scene::{Scene, SurfaceMaterials};

/// The colour channel of an atlas of `atlas_len` texels and row `pitch` holding `tiles` at
/// `bases` (as packed by the builder, whose tiles carry scene triangle indices in `sources`); 0
/// where no tile samples a surface.
pub(crate) fn bake(
    scene: &Scene,
    surface: &SurfaceMaterials,
    tiles: &[Tile],
    bases: &[u32],
    pitch: u32,
    atlas_len: usize,
) -> Vec<u32> {
    let per_tile: Vec<Vec<u32>> = tiles
        .par_iter()
        .map(|t| bake_tile(scene, surface, t))
        .collect();
    let mut colours = vec![0u32; atlas_len];
    let pitch = pitch as usize;
    for ((tile, &base), tile_colours) in tiles.iter().zip(bases).zip(&per_tile) {
        let res_u = tile.frame.res_u as usize;
        if res_u == 0 {
            continue;
        }
        for (j, row) in tile_colours.chunks(res_u).enumerate() {
            let start = base as usize + j * pitch;
            if let Some(dst) = colours.get_mut(start..start + row.len()) {
                dst.copy_from_slice(row);
            }
        }
    }
    colours
}

/// Row-major colours of one tile's texels.
fn bake_tile(scene: &Scene, surface: &SurfaceMaterials, tile: &Tile) -> Vec<u32> {
    let f = &tile.frame;
    let res_u = f.res_u as usize;
    tile.sources
        .iter()
        .enumerate()
        .map(|(k, &source)| {
            if source == NO_SOURCE {
                return 0;
            }
            let Some(tri) = scene.triangles.get(source as usize) else {
                return 0;
            };
            let corners = tri.map(|v| scene.positions.get(v as usize).copied());
            let [Some(a), Some(b), Some(c)] = corners else {
                return 0;
            };
            // Texel centre and corners in the leaf's (u, v) plane, relative to its origin.
            let plane = |p: Vec3| {
                let d = p.as_dvec3() - f.origin.as_dvec3();
                DVec2::new(d.dot(f.u.as_dvec3()), d.dot(f.v.as_dvec3()))
            };
            let texel = f.texel as f64;
            let centre = DVec2::new(
                ((k % res_u) as f64 + 0.5) * texel,
                ((k / res_u) as f64 + 0.5) * texel,
            );
            let bary = barycentrics_2d([plane(a), plane(b), plane(c)], centre);
            rgba::pack(surface.colour(source as usize, bary))
        })
        .collect()
}

/// Barycentrics of `p` in the 2D triangle `t`, clamped to it; the first corner when degenerate.
fn barycentrics_2d(t: [DVec2; 3], p: DVec2) -> Vec3 {
    let [a, b, c] = t;
    let area = (b - a).perp_dot(c - a);
    if area == 0.0 || !area.is_finite() {
        return Vec3::X;
    }
    let wa = (c - b).perp_dot(p - b) / area;
    let wb = (a - c).perp_dot(p - c) / area;
    let wc = (b - a).perp_dot(p - a) / area;
    clamp_to_triangle(glam::DVec3::new(wa, wb, wc))
}
