//! From a hit to the surface data under it: the height-field texel it landed on
//! ([`SurfaceLocation`]), that texel's colour, painting one texel, and a per-pixel albedo for
//! renders that colours hits of either structure (height-field hits from the RBVH's colour
//! channel; triangle hits, of the exact BVH or an RBVH's triangle leaves, from the scene's
//! material at the hit's barycentrics).

use std::collections::HashMap;

use glam::{Vec3, Vec4};
use rayon::prelude::*;

use crate::bvh::{GpuTriangle, LEAF_BIT};
use crate::geom::{Hit, Ray};
use crate::lod::LOD_BIT;
use crate::rbvh::layout::Texel;
use crate::rbvh::Rbvh;
use crate::rgba;
use crate::scene::SceneView;
use crate::structure::Structure;

/// A texel of a height-field leaf: sample `(i, j)` of leaf `leaf`, at `atlas_index` in
/// [`Rbvh::atlas`] (and in [`Rbvh::colours`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SurfaceLocation {
    /// Index of the height-field leaf in [`Rbvh::heightfields`] (the hit's `id` without `LEAF_BIT`).
    pub leaf: u32,
    /// Sample column along the leaf's `u`, `0..res_u`.
    pub i: u32,
    /// Sample row along the leaf's `v`, `0..res_v`.
    pub j: u32,
    /// `atlas_base + j · pitch + i`: the texel's index in the atlas and in the colour channel.
    pub atlas_index: u32,
}

impl Rbvh {
    /// The texel a height-field hit landed on: the hit point moved into the leaf's frame, and the
    /// sample nearest it (sample `i` sits at `s = i + ½`, so the nearest is `⌊s⌋`), falling back,
    /// when that sample is a hole, to the first present corner of the cell holding the point in the
    /// order c00, c10, c01, c11 (the march picks the hit's normal the same way). A hit on an
    /// exact part beside a height field (`GpuTriangle::PART`) lands on that field's texel the
    /// same way ([`Rbvh::leaf_beside`]; its leaves found by a scan of the triangles, which
    /// [`Rbvh::part_leaves`] does for all parts at once). `None` for misses, other triangle
    /// hits, and leaves or atlas indices out of range.
    pub fn locate(&self, ray: &Ray, hit: &Hit) -> Option<SurfaceLocation> {
        if !hit.is_hit() {
            return None;
        }
        let leaf_index = if hit.id & LEAF_BIT != 0 {
            hit.id & !LEAF_BIT
        } else {
            let leaves = self
                .triangles
                .iter()
                .filter(|t| t.prim == hit.id)
                .filter_map(|t| t.part_leaf());
            self.leaf_beside(leaves, ray.origin() + ray.dir() * hit.t)?
        };
        let leaf = self.heightfields.get(leaf_index as usize)?;
        if leaf.res_u == 0 || leaf.res_v == 0 {
            return None;
        }
        let f = leaf.to_frame(ray.origin() + ray.dir() * hit.t);
        let clamp = |x: f32, res: u32| (x.floor() as i64).clamp(0, i64::from(res) - 1);
        let (i, j) = (clamp(f.x, leaf.res_u), clamp(f.y, leaf.res_v));
        let cell =
            |x: f32, res: u32| ((x - 0.5).floor() as i64).clamp(0, (i64::from(res) - 2).max(0));
        let (ci, cj) = (cell(f.x, leaf.res_u), cell(f.y, leaf.res_v));
        let index = |i: i64, j: i64| -> Option<u32> {
            if i >= i64::from(leaf.res_u) || j >= i64::from(leaf.res_v) {
                return None;
            }
            let k = i64::from(leaf.atlas_base) + j * i64::from(self.atlas.pitch) + i;
            let k = u32::try_from(k).ok()?;
            let texel = self.atlas.texels.get(k as usize)?;
            (!texel.is_hole()).then_some(k)
        };
        let corners = [(ci, cj), (ci + 1, cj), (ci, cj + 1), (ci + 1, cj + 1)];
        let (i, j, atlas_index) = std::iter::once((i, j))
            .chain(corners)
            .find_map(|(i, j)| index(i, j).map(|k| (i, j, k)))?;
        Some(SurfaceLocation {
            leaf: leaf_index,
            i: i as u32,
            j: j as u32,
            atlas_index,
        })
    }

    /// The height-field leaves that exact parts stand beside (`GpuTriangle::PART`), by the
    /// parts' scene triangle index (a hit's `id`): more than one where a triangle crossing
    /// several tiles of a surface left parts in each.
    pub fn part_leaves(&self) -> HashMap<u32, Vec<u32>> {
        part_leaves_of(self.triangles.iter())
    }

    /// Of `leaves`, the one whose tile `point` lies over, or nearest to (in texels beyond its
    /// samples), first among equals: the leaf an exact part's hit at `point` stands beside.
    pub fn leaf_beside(&self, leaves: impl IntoIterator<Item = u32>, point: Vec3) -> Option<u32> {
        let beyond = |index: u32| {
            let leaf = self.heightfields.get(index as usize)?;
            let f = leaf.to_frame(point);
            let (u, v) = (leaf.res_u as f32, leaf.res_v as f32);
            Some((-f.x).max(f.x - u).max(-f.y).max(f.y - v).max(0.0))
        };
        leaves
            .into_iter()
            .filter_map(|l| Some((l, beyond(l)?)))
            .fold(None, |best: Option<(u32, f32)>, (l, d)| match best {
                Some((_, b)) if b <= d => best,
                _ => Some((l, d)),
            })
            .map(|(l, _)| l)
    }

    /// Linear RGBA at a height-field hit, filtered bilinearly (in linear light) between the four
    /// samples of the cell holding the hit point, as the surface itself is interpolated between
    /// them; holes are left out and the others' weights renormalised. Falls back to the texel of
    /// [`Rbvh::locate`] where the cell has no colour. `None` without a colour channel, for misses
    /// and triangle hits.
    pub fn filtered_colour(&self, ray: &Ray, hit: &Hit) -> Option<Vec4> {
        let colours = self.colours.as_ref()?;
        let loc = self.locate(ray, hit)?;
        let leaf = self.heightfields.get(loc.leaf as usize)?;
        if leaf.res_u < 2 || leaf.res_v < 2 {
            return self.surface_colour(loc);
        }
        let f = leaf.to_frame(ray.origin() + ray.dir() * hit.t);
        // Cell `c` lies between samples `c` and `c + 1`, at s = c + ½ … c + 3⁄2.
        let axis = |x: f32, res: u32| {
            let c = ((x - 0.5).floor().max(0.0) as u32).min(res - 2);
            (c, (x - 0.5 - c as f32).clamp(0.0, 1.0))
        };
        let ((ci, fx), (cj, fy)) = (axis(f.x, leaf.res_u), axis(f.y, leaf.res_v));
        let (mut sum, mut weight) = (Vec4::ZERO, 0.0);
        for (di, dj, w) in [
            (0, 0, (1.0 - fx) * (1.0 - fy)),
            (1, 0, fx * (1.0 - fy)),
            (0, 1, (1.0 - fx) * fy),
            (1, 1, fx * fy),
        ] {
            let k = u64::from(leaf.atlas_base)
                + u64::from(cj + dj) * u64::from(self.atlas.pitch)
                + u64::from(ci + di);
            let present = self
                .atlas
                .texels
                .get(k as usize)
                .is_some_and(|t| !t.is_hole());
            if let (true, Some(&c)) = (present, colours.get(k as usize)) {
                sum += w * rgba::unpack(c);
                weight += w;
            }
        }
        if weight > 0.0 {
            Some(sum / weight)
        } else {
            self.surface_colour(loc)
        }
    }

    /// Linear RGBA of the texel at `loc`; `None` without a colour channel or out of range.
    pub fn surface_colour(&self, loc: SurfaceLocation) -> Option<Vec4> {
        let word = *self.colours.as_ref()?.get(loc.atlas_index as usize)?;
        Some(rgba::unpack(word))
    }

    /// Sets the texel at `loc` to `colour` (linear RGBA), creating the colour channel
    /// ([`Rbvh::colour_channel`]) if there is none. Returns whether `loc` was in range.
    pub fn paint_texel(&mut self, loc: SurfaceLocation, colour: Vec4) -> bool {
        let word = rgba::pack(colour);
        match self.colour_channel().get_mut(loc.atlas_index as usize) {
            Some(c) => {
                *c = word;
                true
            }
            None => false,
        }
    }

    /// The colour channel, created on first use for an RBVH built without materials: opaque
    /// white on every surface texel (so shading is unchanged until painted), 0 at holes.
    pub fn colour_channel(&mut self) -> &mut Vec<u32> {
        let texels = &self.atlas.texels;
        self.colours.get_or_insert_with(|| blank_colours(texels))
    }
}

/// A fresh colour channel for `texels`: opaque white on surface texels, 0 at holes.
pub fn blank_colours(texels: &[Texel]) -> Vec<u32> {
    let white = rgba::from_bytes([255; 4]);
    texels
        .iter()
        .map(|t| if t.is_hole() { 0 } else { white })
        .collect()
}

/// Per pixel, the linear RGB base colour of the hit (white for misses and for surfaces without
/// colour), or `None` when there is no colour to show: neither the scene has materials nor
/// the `structure` traced (if an RBVH) a colour channel — renders then stay
/// exactly as they were without surface data. Hit ids: a coarse level-of-detail hit (`LEAF_BIT |
/// LOD_BIT`) reads the colour of the column it hit in the levels of detail ([`crate::lod::Lod::colour_at`]); a height-field
/// hit (`LEAF_BIT`) the RBVH's colours filtered at the hit ([`Rbvh::filtered_colour`]), and so
/// does a hit on an exact part beside a height field (its colours are the RBVH's surface data,
/// painted strokes included); any other hit is a scene triangle, coloured by its material at the
/// hit point's barycentrics. In a scene of instances each hit is looked up in its instance's mesh
/// ([`SceneView::hit_mesh`]): a two-level RBVH's leaves and colours, and a mesh's triangles, lie
/// in the mesh's own space.
pub fn hit_albedo<'a>(
    scene: impl Into<SceneView<'a>>,
    structure: &Structure,
    rays: &[Ray],
    hits: &[Hit],
) -> Option<Vec<Vec3>> {
    let scene = scene.into();
    // A two-level RBVH's arrays hold every mesh's leaves and colours, in the meshes' spaces.
    let surfaces = match structure {
        Structure::RbvhInstanced(two) => Some(two.parts()),
        _ => structure.rbvh(),
    };
    let channel = surfaces.filter(|r| r.colours.is_some());
    let lod = structure.lod();
    if !scene.has_surface() && channel.is_none() {
        return None;
    }
    let parts = channel.map(|r| part_leaves_by_mesh(r, structure));
    let albedo = rays
        .par_iter()
        .zip(hits)
        .map(|(ray, hit)| {
            // The hit in its mesh's space, where its leaves and triangles lie.
            let Some((mesh_index, mesh, ray)) = scene.hit_mesh(ray, hit) else {
                return Vec3::ONE;
            };
            let point = ray.origin() + ray.dir() * hit.t;
            let coarse = LEAF_BIT | LOD_BIT;
            let colour = if hit.id & coarse == coarse {
                lod.and_then(|l| l.colour_at(hit.id & !coarse, point))
                    .map(rgba::unpack)
            } else if hit.id & LEAF_BIT != 0 {
                channel.and_then(|r| r.filtered_colour(&ray, hit))
            } else if let Some((r, leaves)) =
                channel.zip(parts.as_ref().and_then(|p| p.get(mesh_index)?.get(&hit.id)))
            {
                r.leaf_beside(leaves.iter().copied(), point)
                    .and_then(|leaf| {
                        let beside = Hit {
                            id: LEAF_BIT | leaf,
                            ..*hit
                        };
                        r.filtered_colour(&ray, &beside)
                    })
                    .or_else(|| mesh.colour_at(hit.id as usize, point))
            } else {
                mesh.colour_at(hit.id as usize, point)
            };
            colour.map_or(Vec3::ONE, |c| c.truncate())
        })
        .collect();
    Some(albedo)
}

/// The leaves that the exact parts among `triangles` stand beside, by their triangle index
/// ([`Rbvh::part_leaves`]).
fn part_leaves_of<'t>(triangles: impl Iterator<Item = &'t GpuTriangle>) -> HashMap<u32, Vec<u32>> {
    let mut map: HashMap<u32, Vec<u32>> = HashMap::new();
    for t in triangles {
        if let Some(leaf) = t.part_leaf() {
            let leaves = map.entry(t.prim).or_default();
            if !leaves.contains(&leaf) {
                leaves.push(leaf);
            }
        }
    }
    map
}

/// [`Rbvh::part_leaves`] per mesh: one map for a flat RBVH; for a two-level one (whose exact
/// triangles lie mesh after mesh, each naming its own mesh's triangle) one per mesh, so that
/// the same triangle index of two meshes finds its own mesh's leaves.
fn part_leaves_by_mesh(r: &Rbvh, structure: &Structure) -> Vec<HashMap<u32, Vec<u32>>> {
    match structure {
        Structure::RbvhInstanced(two) => two
            .meshes
            .iter()
            .map(|m| {
                let first = m.first_triangle as usize;
                part_leaves_of(r.triangles.iter().skip(first).take(m.triangles as usize))
            })
            .collect(),
        _ => vec![r.part_leaves()],
    }
}
