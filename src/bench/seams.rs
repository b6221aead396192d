//! Rays aimed at the seams between height-field leaves, and the leaks they find (issue "No leaks
//! between height fields"): a probe of an RBVH that the bench (its `leaks` and `through`
//! columns) and the seam tests run, so it sits beside the bench rather than in the structure.
//!
//! Each leaf's surface ends one dilation ring beyond its own triangles (`raster/`, step 4), and
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
//! that only graze the solid, never [`DEPTH_TEXELS`] inside it ([`passes_deeper`]): they skim a
//! bulge of the surface that the approximation may undercut by that much, a silhouette error
//! (counted by the hit/miss mismatches of `rbvh bench`), not light through a closed surface.
//! Nor, last, rays whose first exact hit is a *back* face (as wound): started 8 texels out along
//! the normal inside a thin part, they leave the solid rather than enter it, and no light comes
//! that way (on the dragon 6% of the counted seam rays at Q0 started so, and half its leaks; a
//! mesh wound inconsistently loses the rays that meet a flipped face first from the count).
//!
//! A leak that the RBVH does not meet before it leaves the solid either — nothing before two
//! texels behind the exact exit — passes *through* it ([`Leaks::through`]): light through a
//! closed object for a shadow or ambient-occlusion ray. The other leaks slip in past the
//! surface and meet the approximation of its far side: for a primary ray, a depth error.

use glam::Vec3;

use rayon::prelude::*;

use crate::bvh::Bvh;
use crate::geom::{Hit, Ray};
use crate::random::{mix64, SplitMix64};
use crate::rbvh::{Rbvh, TexelFormat};
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

/// How deep inside the solid a ray must pass for it to count, in texels ([`passes_deeper`]):
/// the cells undercut a bulge of the surface by up to about this much, so a ray that passes less
/// deep only skims it. Half of the dragon's leaks at Q0 were such skims, 0–0.5 texel over
/// cells that lay below a grazed bulge (docs/guarantees.md).
pub const DEPTH_TEXELS: f32 = 0.5;

/// How many directions [`passes_deeper`] probes from each point of a chord. Whatever their
/// spread, the nearest surface they meet bounds the point's distance from the surface from
/// above; how tightly depends on it: 64 spread evenly over the sphere leave no direction more
/// than about 20° from one, so beside a plane the bound is within 6.5% of the distance (at a thin
/// crest between two probes it may be looser, which counts more rays, never fewer).
pub const PROBES: usize = 64;

/// At most how many points of a chord [`passes_deeper`] probes from: they lie a tenth of a
/// texel apart where the chord is shorter than 25.6 texels, further apart on longer ones (whose
/// margin for the spacing grows with them: a chord longer than `2 · CHORD_POINTS` times the
/// depth asked counts without a probe).
pub const CHORD_POINTS: usize = 256;

/// Where a seam ray enters the solid, by the exact BVH, and where it leaves it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Entry {
    /// Distance to the exact hit, where the ray enters.
    pub t: f32,
    /// Distance to the exact hit after it, where the ray leaves the solid: infinite when
    /// nothing lies behind the entry (an open mesh); `t` when nothing does but the entry's
    /// object is closed: the ray only touched it, at an edge or a corner, and passes outside.
    pub exit: f32,
}

/// The exact BVH's [`Entry`] of each ray (None for a miss, or a ray whose first hit is a back
/// face, as wound: it starts inside the solid), for rays of unit direction such as
/// [`Rbvh::seam_rays`] makes, `texels` the texel size of the leaf each is aimed at; the exit is
/// the next hit a thousandth of a texel past the entry. `closed`, per scene triangle ([`closed_triangles`];
/// empty when unknown), says which lie on closed objects: a ray that enters one has an exit,
/// so without one it only touched it (a cube's corner, or its edge, seen along a face: on
/// the cube, every ray counted as leaking at Q0 and Q4 did). In parallel.
pub fn exact_entries(
    exact: &Bvh,
    rays: &[Ray],
    texels: &[f32],
    closed: &[bool],
) -> Vec<Option<Entry>> {
    rays.par_iter()
        .zip(texels)
        .map(|(ray, &texel)| {
            let (entry, _) = exact.closest_hit(ray);
            let dir = ray.dir();
            // A back face first: the ray started inside the solid and leaves it.
            if !entry.is_hit() || dir.dot(entry.normal()) > 0.0 {
                return None;
            }
            // The exit: the next crossing, however far (the ray's own end does not bound the solid).
            let past = Ray::new(ray.origin(), dir, entry.t + 1e-3 * texel, f32::INFINITY);
            let (exit, _) = exact.closest_hit(&past);
            let exit = if exit.is_hit() {
                exit.t
            } else if closed.get(entry.id as usize) == Some(&true) {
                entry.t
            } else {
                f32::INFINITY
            };
            Some(Entry { t: entry.t, exit })
        })
        .collect()
}

/// Whether `ray` (unit direction), entering the solid at `entry`, may pass `depth` or more
/// inside it: its depth, the largest distance from the surface of a point of its chord from
/// entry to exit, is not shown to be less. From points of the chord a tenth of a texel apart
/// (`texel`; at most [`CHORD_POINTS`], middle first), [`PROBES`] rays go out in directions
/// spread over the sphere: the nearest surface they meet bounds that point's distance from
/// above, and the distance changes along the chord no faster than the chord, so where every
/// point meets the surface within `depth` less half the points' spacing, the ray passes less
/// deep. A bound, tight up to the probes' spread ([`PROBES`]), where an estimate from the faces
/// the ray enters and leaves by is exact between two planes and may fall either side elsewhere:
/// a ray threading a thin fin's crest, 1.7 texels of chord, estimated 0.59 texel deep by those
/// planes, passes 0.34 deep (brute force over every triangle); the probes find 0.340 at its
/// deepest point, so with the margin of their spacing it passes at most 0.39 deep. An open
/// mesh's entry (no exit) passes deeper; a touch (no chord) does not. `ray`'s direction must be
/// of unit length (the margin is in `t`).
pub fn passes_deeper(exact: &Bvh, ray: &Ray, entry: &Entry, depth: f32, texel: f32) -> bool {
    debug_assert!((ray.dir().length() - 1.0).abs() < 1e-4, "{ray:?}");
    let chord = entry.exit - entry.t;
    if !chord.is_finite() {
        return true;
    }
    if chord <= 0.0 {
        return false;
    }
    let points = ((chord / (0.1 * texel)).ceil() as usize).clamp(1, CHORD_POINTS);
    let reach = depth - 0.5 * chord / points as f32;
    if reach <= 0.0 {
        return true;
    }
    let mut order: Vec<usize> = (0..points).collect();
    order.sort_by_key(|&k| (2 * k + 1).abs_diff(points));
    let directions = probe_directions();
    order.into_iter().any(|k| {
        let p = ray.origin() + ray.dir() * (entry.t + chord * (k as f32 + 0.5) / points as f32);
        directions
            .iter()
            .all(|&d| !exact.any_hit(&Ray::new(p, d, 0.0, reach)).0.is_hit())
    })
}

/// [`PROBES`] unit directions spread evenly over the sphere: the Fibonacci lattice (González,
/// "Measurement of areas on a sphere using Fibonacci and latitude–longitude lattices",
/// Mathematical Geosciences 2010).
fn probe_directions() -> [Vec3; PROBES] {
    let golden = std::f32::consts::PI * (3.0 - 5f32.sqrt());
    std::array::from_fn(|k| {
        let z = 1.0 - (2 * k + 1) as f32 / PROBES as f32;
        let r = (1.0 - z * z).max(0.0).sqrt();
        let a = golden * k as f32;
        Vec3::new(r * a.cos(), r * a.sin(), z)
    })
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
    /// The leaf's texel size: leaves of objects sampled at their own rate
    /// ([`super::RbvhParams::object_rate`]) have finer texels than the scene's, and the
    /// seam rays' distances and the leak thresholds scale with the leaf they are aimed at.
    pub texel: f32,
}

/// Rays aimed at seams ([`Rbvh::seam_rays`]) and the texel size of the leaf each is aimed at.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SeamRays {
    /// Unit-direction rays, each from outside towards its target.
    pub rays: Vec<Ray>,
    /// Per ray, its target's [`SeamTarget::texel`].
    pub texels: Vec<f32>,
}

impl Rbvh {
    /// The seam targets of every height-field leaf: each rim sample (a valid sample with a hole
    /// or the tile's edge among its eight neighbours) and, for each such neighbour, the point half
    /// a texel step of the leaf's grid towards it (at the sample's height over the tile's plane,
    /// where the leaf has one). In leaf order, deterministic.
    pub fn seam_targets(&self) -> Vec<SeamTarget> {
        let mut out = Vec::new();
        let pitch = self.atlas.pitch as usize;
        for leaf in &self.heightfields {
            let (res_u, res_v) = (leaf.res_u as i64, leaf.res_v as i64);
            let grid = leaf.grid();
            let (du, dv, w) = (grid.step_u, grid.step_v, grid.axis_w);
            let size = leaf.texel_size();
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
                                texel: size,
                            });
                        }
                    }
                    if rim {
                        out.push(SeamTarget {
                            point,
                            normal,
                            texel: size,
                        });
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
    /// target; unit directions, so `t` is a world distance. Texels are the target leaf's.
    /// Reproducible: each ray's tilt comes from a stream hashed from `seed` and its index.
    pub fn seam_rays(&self, count: usize, seed: u64) -> SeamRays {
        let targets = self.seam_targets();
        if targets.is_empty() {
            return SeamRays::default();
        }
        let (rays, texels) = (0..count)
            .map(|k| {
                let target = targets[(k as u128 * targets.len() as u128 / count as u128) as usize];
                let mut rng = SplitMix64::new(mix64(seed ^ mix64(k as u64)));
                let n = target.normal;
                let (a, b) = n.any_orthonormal_pair();
                let angle = std::f32::consts::TAU * rng.next_f32();
                let tilt = 0.4 * rng.next_f32().sqrt();
                let out = (n + tilt * (angle.cos() * a + angle.sin() * b)).normalize();
                let reach = 8.0 * target.texel;
                let ray = Ray::new(target.point + reach * out, -out, 0.0, f32::INFINITY);
                (ray, target.texel)
            })
            .unzip();
        SeamRays { rays, texels }
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

/// How many seam rays leaked ([`count_leaks`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Leaks {
    /// Rays the RBVH lets past the surface: it finds nothing before [`LEAK_TEXELS`] behind the
    /// exact entry.
    pub leaks: usize,
    /// Of those, the rays it lets through the solid: nothing before [`LEAK_TEXELS`] behind the
    /// exact exit either, so that a shadow or ambient-occlusion ray sees light through a closed
    /// object. The others meet the approximation of the far side (a primary ray's depth error).
    /// The exit is the next surface of any object, and an open mesh's entry has none: there,
    /// through means that the RBVH missed altogether.
    pub through: usize,
}

/// How many of `rays` (unit directions, as [`Rbvh::seam_rays`] makes them) leaked: the exact
/// BVH `bvh` finds them entering the solid (`exact`, from [`exact_entries`]) at least
/// [`CLEARANCE_TEXELS`] from their origin and passing [`DEPTH_TEXELS`] or more inside it
/// ([`passes_deeper`]), and the RBVH (`approx`, the same rays in the same order) found nothing
/// before [`LEAK_TEXELS`] texels behind the entry, each ray's texel its target leaf's
/// (`texels`); and how many of those it let through the solid. Rays beyond the shortest slice
/// are not counted. In parallel.
pub fn count_leaks(
    bvh: &Bvh,
    rays: &[Ray],
    exact: &[Option<Entry>],
    approx: &[Hit],
    texels: &[f32],
) -> Leaks {
    let leaked: Vec<bool> = exact
        .par_iter()
        .zip(approx)
        .zip(rays)
        .zip(texels)
        .filter_map(|(((e, a), ray), &texel)| {
            let e = e.as_ref()?;
            let behind = |a: &Hit, t: f32| !a.is_hit() || a.t > t + LEAK_TEXELS * texel;
            let counts = e.t >= CLEARANCE_TEXELS * texel
                && behind(a, e.t)
                && passes_deeper(bvh, ray, e, DEPTH_TEXELS * texel, texel);
            counts.then(|| behind(a, e.exit))
        })
        .collect();
    Leaks {
        leaks: leaked.len(),
        through: leaked.iter().filter(|&&through| through).count(),
    }
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
