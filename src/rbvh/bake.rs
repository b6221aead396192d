//! Baking the scene's base colour into the RBVH's colour channel at build time. The atlas is a
//! parameterization of the surface (Novák & Dachsbacher 2012 list "a surface parameterization for
//! free" among the RBVH's properties, and painting among its applications), so each height-field
//! texel can carry the colour of the surface point it samples.
//!
//! That point is the one the rasterizer sampled: the texel centre on the triangle that won the
//! texel ([`Tile::sources`]: the first writer, or for a dilated rim texel the neighbour's
//! triangle). Its barycentrics are those of the texel centre in the leaf's projection along `w`,
//! the same 2D interpolation the rasterizer used for the height; they are clamped to the triangle
//! for rim texels (which lie just outside it). Barycentrics → texture coordinates → texture
//! sample, times the interpolated vertex colour where the scene has them →
//! [`crate::rgba::pack`]. A texel stands for a patch of surface one texel wide, which at
//! coarse levels spans many texture texels, so the texture is sampled over the patch: the
//! coordinates one texel further along `u` and `v` give the patch's extent in the texture, and
//! its mip chain ([`crate::scene::MipChain`]) the mean colour there. (Point samples made a fine
//! checker bake to noise of its two colours at Q0.)

use std::collections::HashMap;
use std::sync::OnceLock;

use glam::{DVec2, DVec3, Vec3, Vec4};
use rayon::prelude::*;

use super::raster::{Tile, NO_SOURCE};
use crate::rgba;
use crate::scene::material::clamp_to_triangle;
use crate::scene::{MipChain, Scene, SurfaceMaterials, Texture};

/// The mip chain of every material's texture, built once per distinct texture when a texel
/// first needs it (fine levels, whose patches are smaller than a texture texel, never do).
struct Mips<'a> {
    textures: Vec<&'a Texture>,
    chains: Vec<OnceLock<MipChain<'a>>>,
    /// Per material, its texture's chain in `chains`.
    of_material: Vec<Option<usize>>,
}

impl<'a> Mips<'a> {
    fn new(surface: &'a SurfaceMaterials) -> Mips<'a> {
        let mut index: HashMap<*const Texture, usize> = HashMap::new();
        let mut textures: Vec<&Texture> = Vec::new();
        let of_material = surface
            .materials
            .iter()
            .map(|m| {
                let t = m.texture.as_deref()?;
                Some(*index.entry(std::ptr::from_ref(t)).or_insert_with(|| {
                    textures.push(t);
                    textures.len() - 1
                }))
            })
            .collect();
        Mips {
            chains: textures.iter().map(|_| OnceLock::new()).collect(),
            textures,
            of_material,
        }
    }

    /// The chain of triangle `triangle`'s texture; `None` without a textured material.
    fn of(&self, surface: &SurfaceMaterials, triangle: usize) -> Option<&MipChain<'a>> {
        let material = *surface.material_of_triangle.get(triangle)?;
        let k = (*self.of_material.get(material as usize)?)?;
        let texture = *self.textures.get(k)?;
        Some(self.chains.get(k)?.get_or_init(|| MipChain::new(texture)))
    }
}

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
    let mips = Mips::new(surface);
    let per_tile: Vec<Vec<u32>> = tiles
        .par_iter()
        .map(|t| bake_tile(scene, surface, &mips, t))
        .collect();
    place(tiles, &per_tile, bases, pitch, atlas_len)
}

/// [`bake`] for an RBVH of points, whose tiles carry point indices in `sources`: each texel
/// takes the colour (packed as [`crate::rgba`]) of the point it samples, as a scan's colours are
/// its samples of the surface's.
pub(crate) fn point_colours(
    colours: &[u32],
    tiles: &[Tile],
    bases: &[u32],
    pitch: u32,
    atlas_len: usize,
) -> Vec<u32> {
    let per_tile: Vec<Vec<u32>> = tiles
        .iter()
        .map(|t| {
            t.sources
                .iter()
                .map(|&s| colours.get(s as usize).copied().unwrap_or(0))
                .collect()
        })
        .collect();
    place(tiles, &per_tile, bases, pitch, atlas_len)
}

/// The atlas-wide channel of `per_tile` row-major texel words, each tile's at its base.
fn place(
    tiles: &[Tile],
    per_tile: &[Vec<u32>],
    bases: &[u32],
    pitch: u32,
    atlas_len: usize,
) -> Vec<u32> {
    let mut colours = vec![0u32; atlas_len];
    let pitch = pitch as usize;
    for ((tile, &base), tile_colours) in tiles.iter().zip(bases).zip(per_tile) {
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
fn bake_tile(scene: &Scene, surface: &SurfaceMaterials, mips: &Mips, tile: &Tile) -> Vec<u32> {
    let f = &tile.frame;
    let res_u = f.res_u as usize;
    // The footprint of the last textured triangle: the plane-to-texture mapping is affine, so
    // it is the same at every texel the triangle wins.
    let mut last_footprint: Option<(u32, f32)> = None;
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
            let corners = [plane(a), plane(b), plane(c)];
            let Some(raw) = barycentrics_2d(corners, centre) else {
                return rgba::pack(surface.colour(source as usize, Vec3::X));
            };
            let bary = clamp_to_triangle(raw);
            let triangle = source as usize;
            let uv = surface.uv(triangle, bary);
            let base = match surface.material(triangle) {
                None => Vec4::ONE,
                Some(material) if material.texture.is_none() => material.colour(uv),
                Some(material) => {
                    let footprint = match last_footprint {
                        Some((s, footprint)) if s == source => footprint,
                        _ => {
                            // The texture coordinates across the texel's patch, from the
                            // unclamped barycentrics one texel along u and v: its exact extent.
                            let uv_at = |d: DVec2| {
                                let b = barycentrics_2d(corners, centre + d).unwrap_or(raw);
                                surface.uv(triangle, b.as_vec3())
                            };
                            let origin = uv_at(DVec2::ZERO);
                            let patch = material.footprint([
                                uv_at(DVec2::new(texel, 0.0)) - origin,
                                uv_at(DVec2::new(0.0, texel)) - origin,
                            ]);
                            // A triangle steep to the leaf plane stretches the patch beyond
                            // the triangle's own part of the texture, which bounds it.
                            let [a, b, c] = surface
                                .uv_of_triangle
                                .get(triangle)
                                .copied()
                                .unwrap_or_default();
                            let own = material
                                .footprint([b - a, c - a])
                                .max(material.footprint([c - b, c - b]));
                            let footprint = patch.min(own);
                            last_footprint = Some((source, footprint));
                            footprint
                        }
                    };
                    match mips.of(surface, triangle) {
                        Some(chain) if footprint > 1.0 => {
                            material.colour_over(uv, footprint, chain)
                        }
                        _ => material.colour(uv),
                    }
                }
            };
            let colour = base * surface.vertex_colour(triangle, bary);
            rgba::pack(colour)
        })
        .collect()
}

/// Barycentrics of `p` in the 2D triangle `t`, negative outside it; `None` when degenerate.
fn barycentrics_2d(t: [DVec2; 3], p: DVec2) -> Option<DVec3> {
    let [a, b, c] = t;
    let area = (b - a).perp_dot(c - a);
    if area == 0.0 || !area.is_finite() {
        return None;
    }
    let wa = (c - b).perp_dot(p - b) / area;
    let wb = (a - c).perp_dot(p - c) / area;
    let wc = (b - a).perp_dot(p - a) / area;
    Some(DVec3::new(wa, wb, wc))
}
