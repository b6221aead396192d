//! Rays aimed at the seams between height-field leaves, and the leaks they find (issue "No leaks
//! between height fields").
//!
//! Each leaf's surface ends one dilation ring beyond its own triangles (`raster.rs`, step 4), and
//! neighbouring leaves meet by overlapping there; under the rims sampled from the surface the
//! march hangs a skirt one texel deep (`layout::MARCH_SKIRT_TEXELS`). Where they do not overlap — at corners where
//! several leaves meet, or at a rim the texel grid cannot hold — a ray can pass between them and
//! through a closed surface: a light leak for shadow and ambient-occlusion rays. Random rays find
//! such gaps rarely (about 1 in 40,000 at Q0 on the blob), so these rays are aimed where the gaps
//! are: at every leaf's *rim*, its valid samples that have a hole or the tile's edge among their
//! eight neighbours (the corners of the footprint among them), and half a texel beyond each, from
//! outside along the sample's normal, tilted by up to about 22° in changing directions.
//!
//! A ray *leaks* when the exact BVH finds the surface at `t` and the RBVH finds nothing before
//! `t + 2` texels: the approximation lies within a fraction of a texel of the surface (README
//! "Guarantees"), so a hit two texels behind it has passed through. Rays the exact BVH does not
//! see hitting (aimed past an open boundary) do not count, nor rays whose exact hit lies within
//! [`CLEARANCE_TEXELS`] of their origin: started in a crevice or inside a thin part, they judge
//! nothing, since the approximation may lie on either side of an origin that close. Nor do rays
//! that only graze the solid, never [`DEPTH_TEXELS`] inside it ([`Entry::depth`]): they skim a
//! bulge of the surface that the approximation may undercut by that much, a silhouette error
//! (counted by the hit/miss mismatches of `rbvh bench`), not light through a closed surface.
//! Nor, last, rays whose first exact hit is a *back* face (as wound): started 8 texels out along
//! the normal inside a thin part, they leave the solid rather than enter it, and no light comes
//! that way (on the dragon 6% of the counted seam rays at Q0 started so, and half its leaks; a
//! mesh wound inconsistently loses the rays that meet a flipped face first from the count).

use glam::Vec3;

use rayon::prelude::*;

use super::{Rbvh, TexelFormat};
use crate::bvh::Bvh;
use crate::geom::{Hit, Ray};
use crate::random::{mix64, SplitMix64};
use crate::scene::{open_boundary, Scene};

/// How far behind the exact hit an RBVH hit counts as a leak, in texels.
pub const LEAK_TEXELS: f32 = 2.0;

/// How far from its origin a ray's exact hit must lie for the ray to count, in texels: the
/// approximation's error reaches about a texel at the coarsest presets (t p99 of the dragon at
/// Q0: 1.4 texels), so a surface nearer the origin may be approximated behind it, and the RBVH's
/// first hit is then the next surface. On the dragon a third of the leaks at Q0 were such rays,
/// started 8 texels out along the normal in a crevice or inside a thin part (most hit a back
/// face first).
pub const CLEARANCE_TEXELS: f32 = 1.0;

/// How deep inside the solid a ray must pass for it to count, in texels ([`Entry::depth`]): the
/// cells undercut a bulge of the surface by up to about this much, so a ray that passes less
/// deep only skims it. Half of the dragon's leaks at Q0 were such skims, 0–0.5 texel over
/// cells that lay below a grazed bulge (docs/guarantees.md).
pub const DEPTH_TEXELS: f32 = 0.5;

/// Where a seam ray enters the solid, by the exact BVH, and how deep inside it passes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Entry {
    /// Distance to the exact hit.
    pub t: f32,
    /// The deepest the ray gets inside the solid between its entry and its exit, measured from
    /// the planes of the faces it enters and leaves by: `chord · a · b / (a + b)` with `a`, `b`
    /// the cosines between the ray and their normals (exact between two planes; a ray tangent
    /// to a bulge has both small). Infinite when nothing lies behind the entry (an open mesh);
    /// zero when nothing does but the entry's object is closed: the ray only touched it, at an
    /// edge or a corner, and passes outside.
    pub depth: f32,
}

/// The exact BVH's [`Entry`] of each ray (None for a miss, or a ray whose first hit is a back
/// face, as wound: it starts inside the solid), for rays of unit direction such as
/// [`Rbvh::seam_rays`] makes, `texel` the RBVH's texel size; the exit is the next hit a
/// thousandth of a texel past the entry. `closed`, per scene triangle ([`closed_triangles`];
/// empty when unknown), says which lie on closed objects: a ray that enters one has an exit,
/// so without one it only touched it (a cube's corner, or its edge, seen along a face: on
/// the cube, every ray counted as leaking at Q0 and Q4 did). In parallel.
pub fn exact_entries(exact: &Bvh, rays: &[Ray], texel: f32, closed: &[bool]) -> Vec<Option<Entry>> {
    rays.par_iter()
        .map(|ray| {
            let (entry, _) = exact.closest_hit(ray);
            let dir = ray.dir();
            // A back face first: the ray started inside the solid and leaves it.
            if !entry.is_hit() || dir.dot(entry.normal()) > 0.0 {
                return None;
            }
            // The exit: the next crossing, however far (the ray's own end does not bound the solid).
            let past = Ray::new(ray.origin(), dir, entry.t + 1e-3 * texel, f32::INFINITY);
            let (exit, _) = exact.closest_hit(&past);
            let depth = if exit.is_hit() {
                let (a, b) = (dir.dot(entry.normal()).abs(), dir.dot(exit.normal()).abs());
                if a + b > 0.0 {
                    (exit.t - entry.t) * a * b / (a + b)
                } else {
                    0.0
                }
            } else if closed.get(entry.id as usize) == Some(&true) {
                0.0
            } else {
                f32::INFINITY
            };
            Some(Entry { t: entry.t, depth })
        })
        .collect()
}

/// Per triangle of `scene`, whether the object it belongs to is closed: none of the object's
/// triangles touches the scene's open boundary ([`open_boundary`]).
pub fn closed_triangles(scene: &Scene) -> Vec<bool> {
    let open = open_boundary(scene);
    let object = |t: usize| scene.object_of_triangle.get(t).copied().unwrap_or(0) as usize;
    let objects = (0..open.len()).map(object).max().map_or(0, |m| m + 1);
    let mut open_object = vec![false; objects];
    for (t, &o) in open.iter().enumerate() {
        open_object[object(t)] |= o;
    }
    (0..open.len()).map(|t| !open_object[object(t)]).collect()
}

/// Where a seam ray is aimed: a point on or just beyond a leaf's rim, and the outward normal it
/// is aimed against.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SeamTarget {
    /// World position: a rim sample, or half a texel beyond it towards a hole or the tile's edge.
    pub point: Vec3,
    /// Unit outward normal there: the sample's (the leaf's projection axis for height-only
    /// texels, which carry none).
    pub normal: Vec3,
}

impl Rbvh {
    /// The seam targets of every height-field leaf: each rim sample (a valid sample with a hole
    /// or the tile's edge among its eight neighbours) and, for each such neighbour, the point half
    /// a texel towards it at the sample's height. In leaf order, deterministic.
    pub fn seam_targets(&self) -> Vec<SeamTarget> {
        let mut out = Vec::new();
        let pitch = self.atlas.pitch as usize;
        for leaf in &self.leaves {
            let (res_u, res_v) = (leaf.res_u as i64, leaf.res_v as i64);
            let grid = leaf.grid();
            let (du, dv, w) = (grid.step_u, grid.step_v, grid.axis_w);
            let texel = |i: i64, j: i64| {
                if i < 0 || j < 0 || i >= res_u || j >= res_v {
                    return None;
                }
                let index = leaf.atlas_base as usize + j as usize * pitch + i as usize;
                self.atlas
                    .texels
                    .get(index)
                    .copied()
                    .filter(|t| !t.is_hole())
            };
            for j in 0..res_v {
                for i in 0..res_u {
                    let Some(sample) = texel(i, j) else { continue };
                    let point = grid.point(i as u32, j as u32, sample.height_code());
                    let normal = match self.params.texels {
                        TexelFormat::HeightNormal => sample.normal(),
                        TexelFormat::Height => w,
                    };
                    let mut rim = false;
                    for (di, dj) in NEIGHBOURS {
                        if texel(i + di, j + dj).is_none() {
                            rim = true;
                            out.push(SeamTarget {
                                point: point + 0.5 * (di as f32 * du + dj as f32 * dv),
                                normal,
                            });
                        }
                    }
                    if rim {
                        out.push(SeamTarget { point, normal });
                    }
                }
            }
        }
        out
    }

    /// `count` rays aimed at [`Rbvh::seam_targets`] (ray `k` at target `⌊k · targets / count⌋`:
    /// each target a run of equal shares when there are fewer targets than rays, every
    /// `targets / count`-th when there are more), each starting 8 texels out along its target's
    /// normal tilted by up to about 22° (atan 0.4) in a random direction, and aimed at the
    /// target; unit directions, so `t` is a world distance.
    /// Reproducible: each ray's tilt comes from a stream hashed from `seed` and its index.
    pub fn seam_rays(&self, count: usize, seed: u64) -> Vec<Ray> {
        let targets = self.seam_targets();
        if targets.is_empty() {
            return Vec::new();
        }
        let reach = 8.0 * self.texel_size;
        (0..count)
            .map(|k| {
                let target = targets[(k as u128 * targets.len() as u128 / count as u128) as usize];
                let mut rng = SplitMix64::new(mix64(seed ^ mix64(k as u64)));
                let n = target.normal;
                let (a, b) = n.any_orthonormal_pair();
                let angle = std::f32::consts::TAU * rng.next_f32();
                let tilt = 0.4 * rng.next_f32().sqrt();
                let out = (n + tilt * (angle.cos() * a + angle.sin() * b)).normalize();
                Ray::new(target.point + reach * out, -out, 0.0, f32::INFINITY)
            })
            .collect()
    }
}

/// The eight neighbours of a sample.
const NEIGHBOURS: [(i64, i64); 8] = [
    (-1, -1),
    (0, -1),
    (1, -1),
    (-1, 0),
    (1, 0),
    (-1, 1),
    (0, 1),
    (1, 1),
];

/// How many of the rays leaked: the exact BVH finds them entering the solid (`exact`, from
/// [`exact_entries`]) at least [`CLEARANCE_TEXELS`] from their origin and passing
/// [`DEPTH_TEXELS`] or more inside it, and the RBVH found nothing before `LEAK_TEXELS` texels of
/// `texel` behind the entry (`approx`: the same rays in the same order, with unit directions so
/// that `t` is a world distance, as [`Rbvh::seam_rays`] makes them; pairs beyond the shorter
/// slice are not counted).
pub fn count_leaks(exact: &[Option<Entry>], approx: &[Hit], texel: f32) -> usize {
    exact
        .iter()
        .zip(approx)
        .filter(|(e, a)| {
            e.is_some_and(|e| {
                e.t >= CLEARANCE_TEXELS * texel
                    && e.depth >= DEPTH_TEXELS * texel
                    && (!a.is_hit() || a.t > e.t + LEAK_TEXELS * texel)
            })
        })
        .count()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The default scene's ground is an open sheet; every other object in it is closed.
    #[test]
    fn triangles_of_closed_objects_are_told_from_open_ones() {
        let scene = Scene::builtin("default").unwrap();
        let closed = closed_triangles(&scene);
        assert_eq!(closed.len(), scene.triangle_count());
        for (t, &c) in closed.iter().enumerate() {
            let name = &scene.object_names[scene.object_of_triangle[t] as usize];
            assert_eq!(c, name != "ground", "triangle {t} of {name}");
        }
    }
}
