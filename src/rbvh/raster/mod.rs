//! Rasterizing one leaf's triangles into its height-field tile (Novák & Dachsbacher 2012: "rasterize
//! surfaces into the atlas"; "texel centres sample the exact triangles"), then dilating and
//! quantizing it into the packed [`Texel`]s of `layout.rs`.
//!
//! ## Algorithm
//! 1. **Sampling.** Each triangle's geometric normal `n = normalize((b − a) × (c − a))` is taken as
//!    wound (the same convention as [`crate::geom::Hit`]); zero-area triangles are skipped. Its
//!    vertices are projected into *sample space*: `x = (p − origin)·u / texel − ½`,
//!    `y = (p − origin)·v / texel − ½`, so that sample `(i, j)` sits at `(x, y) = (i, j)`, and height
//!    `h = (p − origin)·w`. Triangles seen edge-on (`|n·w|` below [`sample::EDGE_ON_COS`]) are skipped: they
//!    cover no sample centre in a way that defines one height, and their neighbours cover the same
//!    samples. Every sample of the grid inside the triangle's 2D bounding box is tested with 2D edge
//!    functions *inclusive* of the edges (all ≥ 0 or all ≤ 0, so either winding is accepted), and
//!    its height is interpolated with the barycentrics. Each edge function is evaluated with its
//!    two endpoints in a canonical order, so that the two triangles sharing an edge compute exactly
//!    opposite values: a sample centre on a shared edge is inside at least one of them, never lost
//!    to rounding (the argument of Woop, Benthin & Wald, "Watertight Ray/Triangle Intersection",
//!    JCGT 2013, in 2D).
//! 2. **Single-valuedness.** A sample already written by an earlier triangle keeps its height
//!    (first writer wins, which is deterministic because triangles are processed in order) unless
//!    the heights differ by more than `fold_tolerance`: then two layers fold onto one texel, the
//!    set is not a height field, and [`rasterize`] returns `None`.
//! 3. `covered` counts the samples written in 1–2. When [`rasterize`] is given a criterion to
//!    judge, the surface as sampled must meet it here or the set is not a height field
//!    (`None`): the cells whose corners were all written — two triangles each, as the march
//!    splits them, or the one triangle of three written corners — are the surface, and their
//!    normals stand in for the triangles' in [`Refinement`]'s test (every cell normal within
//!    φ_max of `w`, or cells' projected over true area ≥ a). A tile with no such cell fails.
//! 4. **Dilation** (the paper's crack avoidance: "allow overlaps + dilation filter"). One pass over
//!    the state after step 2: each hole with at least one covered 4-neighbour gets the mean, over
//!    those neighbour directions, of a linear extrapolation (`2h₁ − h₂` when the sample two steps
//!    away is also covered, else `h₁`), and the normal of the first such neighbour in the fixed
//!    order −u, +u, −v, +v. Planar surfaces are thus extended exactly. Every leaf's surface reaches
//!    half a texel or more beyond its triangles, so that neighbouring leaves overlap and meet
//!    without gaps. The cost: at open mesh boundaries (where no neighbour leaf continues the
//!    surface) the surface grows a rim of at most one texel.
//!
//!    Then the **ring from the surface itself** (issue "No leaks between height fields"): every
//!    hole with a covered sample among its *eight* neighbours, and every hole at a corner of a
//!    cell that one of the leaf's triangles overlaps in projection (so that full cells cover the
//!    whole footprint, slivers and triangles smaller than a texel included), is sampled from the
//!    scene's triangles (two short rays along `±w` through the sample, in a BVH of the scene the
//!    builder gives), taking the one over the sample whose height lies nearest the mean of those
//!    neighbours (or, without any, the plane of the triangle whose cell needs it), within two
//!    texels, or as far as the leaf's criterion lets its surface rise in a texel, up to four
//!    ([`ring_reach`]); that replaces the extrapolation there.
//!    Neighbouring leaves then overlap on the real surface, at corners too, where one
//!    extrapolated 4-neighbour ring left gaps (about 4 in 10,000 rays aimed at the seams of the
//!    blob at Q0 slipped through; none now at any preset), and the ring follows the surface
//!    where extrapolation stuck out at silhouettes and folds (t p99 on the dragon
//!    Q2 0.075% → 0.031% of the diagonal). Where no triangle lies over a ring sample (an open
//!    boundary, a face turned edge-on) the extrapolation stays, and is marked as such: the
//!    march hangs a skirt under the rims of sampled heights only ([`Texel::is_sampled`]).
//!
//!    Then the **walls**: where the leaf's own triangles fall (or rise) further than an
//!    extrapolation within the texel between the sample and the written sample it extends (a
//!    rim seen nearly edge-on), that direction takes their extreme there, so that the cell walls
//!    the surface down to where the leaf's triangles end ([`walls`]); planes still extend
//!    exactly. At φ_max 89.5° the sphere's
//!    seam leaks fell from 26,461 to 117 per million, and t p99 from 0.43 to 0.26% of the
//!    diagonal. A wall that ends a texel or more above or below a written 4-neighbour (a cell
//!    steeper than 45°) lies on the surface's edge-on rim, and is marked sampled, so that the
//!    march's skirt hangs under it too (the sphere at φ_max 89.5° 117 → 4 per million, at A⊥/A
//!    0.01 9,029 → 168; gentler walls keep their mark: under them the skirt's lip would stick
//!    out, and the presets' t p99 and leaks are unchanged).
//!
//!    Last, the **open boundary**: a corner still a hole of a cell that a triangle touching the
//!    scene's open boundary meets ([`crate::scene::open_boundary`]) takes that triangle's plane
//!    (clamped to its heights, marked extrapolated). Nothing continues the surface beyond such
//!    an edge, and a corner seen only diagonally from the written samples, with no surface over
//!    it for the ring, left the cell bare: rays entering within a texel of a hole's rim passed
//!    through (the Stanford bunny's base: 75/62/69/24/29 of a million seam rays at Q0–Q4, now
//!    2/2/0/0/1, t p99 the same). Filling every such corner, not only beside open edges, cost
//!    the dragon's Q0 t p99 0.150 → 0.326% (docs/guarantees.md).
//! 5. **Quantization.** Heights are first measured from the valid samples' least-squares plane
//!    where that narrows their range by a narrow quantum or more ([`Tile::slope`]; the record
//!    shears the plane into its height row, so the tracers read it at no cost): a tilted tile's
//!    range shrinks to its relief, and more tiles take 8-bit codes (the paper-scale scene's Q2
//!    62.8 → 75.1% of its texels). With `h_lo`, `h_hi` the extreme heights of all valid samples
//!    (after dilation, the ring, the walls and the open boundary), `frame.origin` moves by
//!    `h_lo · w`, so code 0 is the lowest height, and the code of height `h` is the code nearest `(h − h_lo) /
//!    h_scale` whose parity tells a sampled height (even) from an extrapolated one (odd). A tile
//!    whose range is at most `2^b − 2` quanta of [`quantize::NARROW_QUANTUM_TEXELS`] (1/128
//!    texel) for `b` one of [`PACKED_BITS`](crate::rbvh::PACKED_BITS) (12, 10, 8) takes the narrowest such `b`: `h_scale =
//!    (h_hi − h_lo) / top(b)` and `b`-bit codes ([`Texel::code_of`], [`Texel::top`]), a worst
//!    quantization error of `(h_hi − h_lo) / (2^b − 2)`, at most that quantum; the device stores
//!    them `b` bits each (issue "Small and valid at every scale": bytes per texel that fit the
//!    surface). Any other tile takes `h_scale = (h_hi − h_lo) / MAX_CODE` and 16-bit codes, a
//!    worst error of `(h_hi − h_lo) / 65534`. (Flat or empty tiles: `h_scale` 0, 8 bits.) Both
//!    add the f32 rounding of the moved origin.
//! 6. **Exposed triangles** ([`Tile::exposed`], issue "No leaks between height fields"): the
//!    leaf's triangles that meet the bare part of a cell (no cell triangle over it: the ring found
//!    no surface for a corner), or rise more than [`CREST_TEXELS`] above a cell, or lie more than
//!    that below a cell of sampled corners or below a lid, one with an extrapolated corner (that
//!    far too under the presets' criterion, 0.3 texel at steeper ones:
//!    [`exposed::lid_sink_texels`]), or face away from the axis over a steep cell
//!    ([`exposed::STEEP_CELL_TEXELS`]; [`exposed`]).
//!    A ray entering the solid through one may pass beside the height field, slide over its
//!    rim, pass under an extrapolated lid, or reach the triangle from below or beside rather
//!    than through the cells over it, so the builder adds their parts there to the tree as
//!    triangle leaves, traced exactly, beside the tile.
//! 7. A tile without any covered sample is still returned (`covered = 0`, all holes); the builder
//!    decides what to do with it.
//!
//! All arithmetic on projected coordinates is done in f64 so that large tiles and far-from-origin
//! scenes keep sub-texel accuracy; the ring's rays start from f32 world points, as the tracers'
//! rays do, and the heights they find are relative to the frame's f32 origin like the rest. The
//! functions are pure (the builder calls them from rayon tasks).
//!
//! ## Files
//! One step each, in the order [`rasterize`] runs them: [`sample`] (steps 1–2), [`judge`] (step
//! 3), [`dilate`], [`ring`] and [`walls`] (step 4; its open boundary is [`rasterize`]'s own, on
//! [`cells`]), [`quantize`] (step 5), [`exposed`] (step 6). [`cells`] finds the cells a triangle
//! meets, for the ring, the open boundary and the exposed triangles; the 2D clipping and overlap
//! tests they use are `crate::geom`'s (`clip`, `sat`).

mod cells;
mod dilate;
mod exposed;
mod judge;
mod quantize;
mod ring;
mod sample;
mod walls;

use glam::{DVec3, Vec2, Vec3};

pub(super) use dilate::dilate;
pub use exposed::{Exposed, CREST_TEXELS};
pub(super) use judge::sampled_passes;
pub(super) use quantize::quantize;
pub(super) use ring::{ring_reach, Ring};

use super::layout::{GpuHeightfield, Texel};
use super::Refinement;
use crate::geom::Aabb;
use cells::cell_corners;
use exposed::exposed;
use ring::{ring_corners, ring_from_surface};
use sample::{covered_samples, unit_normal};
use walls::walls;

/// A leaf's orthographic projection. `u`, `v`, `w` orthonormal (`w` = projection axis, pointing to
/// where the surface faces); sample `(i, j)` lies at `origin + (i + ½)·texel·u + (j + ½)·texel·v`,
/// with height measured along `w` from `origin`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame {
    pub origin: Vec3,
    pub u: Vec3,
    pub v: Vec3,
    pub w: Vec3,
    /// World size of one texel.
    pub texel: f32,
    pub res_u: u32,
    pub res_v: u32,
}

impl Frame {
    /// Sample-space coordinates `(x, y, h)` of a world point (see the module docs).
    pub(super) fn project(&self, p: Vec3) -> DVec3 {
        let d = p.as_dvec3() - self.origin.as_dvec3();
        let texel = self.texel as f64;
        DVec3::new(
            d.dot(self.u.as_dvec3()) / texel - 0.5,
            d.dot(self.v.as_dvec3()) / texel - 0.5,
            d.dot(self.w.as_dvec3()),
        )
    }

    fn samples(&self) -> usize {
        self.res_u as usize * self.res_v as usize
    }
}

/// A rasterized leaf: `frame.origin` has been moved along `w` so that height code 0 is the lowest
/// height; texels row-major (`j * res_u + i`), [`Texel::HOLE`] where there is no surface.
#[derive(Clone, Debug, PartialEq)]
pub struct Tile {
    pub frame: Frame,
    pub texels: Vec<Texel>,
    /// World height per quantum along `w`.
    pub h_scale: f32,
    /// The plane the heights are measured from, as world height along `w` per texel along `u`
    /// and `v` (step 5: zero unless a tilted plane narrows the heights' range): sample `(i, j)`
    /// of code `q` lies `q · h_scale + slope · (i + ½, j + ½)` above `frame.origin` along `w`.
    /// The record shears it into its height axis ([`Tile::heightfield`]).
    pub slope: Vec2,
    /// Bits of the codes (step 5 of the module docs): 16, or one of [`crate::rbvh::PACKED_BITS`], whose
    /// tiles go to the atlas's band of that width ([`crate::rbvh::Atlas::packed_rows`]) where the
    /// band pays (`atlas::pack`).
    pub bits: u32,
    /// Samples covered by triangles (before dilation).
    pub covered: u32,
    /// Per texel, the index (into the triangles given to [`rasterize`]) of the triangle whose
    /// surface the texel samples — the first writer of step 2; for a dilated texel the triangle
    /// its normal came from in step 4; for a ring sample taken from the surface, the leaf's
    /// triangle it stands beside (that of a written neighbour, or the one whose cell needs it) —
    /// and [`NO_SOURCE`] for a hole. Baking surface
    /// data (`crate::surface`) evaluates that triangle at the texel centre.
    pub sources: Vec<u32>,
    /// The triangles given to [`rasterize`] that the tile leaves uncovered, and where
    /// ([`exposed`]); by ascending index. The builder traces those parts exactly.
    pub exposed: Vec<Exposed>,
}

/// [`Tile::sources`] of a hole.
pub const NO_SOURCE: u32 = u32::MAX;

impl Tile {
    /// The packed record: `axis_u = u / texel`, `axis_v = v / texel`, `axis_w = w − slope.x ·
    /// axis_u − slope.y · axis_v` (so that `(p − origin) · axis_w` is the height over the tile's
    /// plane, [`Tile::slope`]; `w` itself where the slope is zero), resolution and `h_scale` from
    /// the tile, `atlas_base` as placed by `atlas::pack`.
    pub fn heightfield(&self, atlas_base: u32) -> GpuHeightfield {
        let f = &self.frame;
        let (axis_u, axis_v) = (f.u / f.texel, f.v / f.texel);
        let axis_w = if self.slope == Vec2::ZERO {
            f.w
        } else {
            f.w - self.slope.x * axis_u - self.slope.y * axis_v
        };
        GpuHeightfield {
            origin: f.origin.to_array(),
            atlas_base,
            axis_u: axis_u.to_array(),
            res_u: f.res_u,
            axis_v: axis_v.to_array(),
            res_v: f.res_v,
            axis_w: axis_w.to_array(),
            h_scale: self.h_scale,
        }
    }

    /// World position of the point at texel coordinates `(s, t)` (sample `(i, j)` at `(i + ½,
    /// j + ½)`) whose height over the tile's plane is `h` (a code times `h_scale`).
    pub fn point(&self, s: f32, t: f32, h: f32) -> Vec3 {
        let f = &self.frame;
        let over = h + self.slope.x * s + self.slope.y * t;
        f.origin + s * f.texel * f.u + t * f.texel * f.v + over * f.w
    }

    /// World AABB of the eight corners of the tile's box: `s, t ∈ [½, res − ½]` (texel units, i.e.
    /// sample centres) and `h ∈ [0, MAX_CODE · h_scale]`. Every reconstructed surface point is a
    /// convex combination of sample points, so it lies inside; the box is widened by a few ulps of
    /// its coordinates so that f32 rounding of the corners cannot cut off a surface point either.
    pub fn world_bounds(&self) -> Aabb {
        let f = &self.frame;
        let s = [0.5, f.res_u as f32 - 0.5];
        let t = [0.5, f.res_v as f32 - 0.5];
        let h = [0.0, Texel::MAX_CODE as f32 * self.h_scale];
        let mut corners = Vec::with_capacity(8);
        for s in s {
            for t in t {
                for h in h {
                    corners.push(self.point(s, t, h));
                }
            }
        }
        let b = Aabb::from_points(corners);
        let margin = b.min.abs().max(b.max.abs()) * (4.0 * f32::EPSILON);
        Aabb {
            min: b.min - margin,
            max: b.max + margin,
        }
    }
}

impl Tile {
    /// World AABB of the tile's surface: of its sample points (holes left out), widened by a few
    /// ulps of its coordinates and 1/1024 texel against f32 rounding. Every reconstructed surface
    /// point is a convex combination of sample points, so it lies inside; this is the leaf's box
    /// in the tree. It is tighter than [`Tile::world_bounds`] (the box of the whole tile box)
    /// wherever the tile is tilted against the world axes or has holes, so that fewer rays are
    /// handed to the march only to miss the tile's box (the speed study found 44–63% of the
    /// leaves a ray reaches rejected there). A tile without samples gets its tile box.
    pub fn surface_bounds(&self) -> Aabb {
        let f = &self.frame;
        let mut b = Aabb::EMPTY;
        for j in 0..f.res_v {
            for i in 0..f.res_u {
                let texel = self.texels[(j * f.res_u + i) as usize];
                if texel.is_hole() {
                    continue;
                }
                let h = f32::from(texel.height_code()) * self.h_scale;
                b = b.grow(self.point(i as f32 + 0.5, j as f32 + 0.5, h));
            }
        }
        if b.min.cmpgt(b.max).any() {
            return self.world_bounds();
        }
        let margin = b.min.abs().max(b.max.abs()) * (8.0 * f32::EPSILON) + f.texel / 1024.0;
        Aabb {
            min: b.min - margin,
            max: b.max + margin,
        }
    }
}

/// Rasterizes `triangles` (world space) into `frame`'s sample grid, or returns `None` when the
/// result is not single-valued: two triangles covering the same sample centre at heights differing
/// by more than `fold_tolerance` (world units; it should exceed f32 rounding of the heights, e.g. a
/// fraction of a texel, or samples on shared edges count as folds). See the module docs for the
/// steps. The grid of `res_u × res_v` samples is allocated in full; the builder keeps both sides
/// at most `max_tile` (≤ 4096). With `judge`, the sampled surface must also pass that criterion
/// (step 3). With `ring`, the ring of samples around the written ones comes from the surface
/// (step 4). `open` says, per triangle, whether it touches the scene's open boundary
/// ([`crate::scene::open_boundary`]; empty: none does), for step 4's last part.
pub fn rasterize(
    triangles: &[[Vec3; 3]],
    frame: &Frame,
    fold_tolerance: f32,
    judge: Option<Refinement>,
    ring: Option<Ring>,
    open: &[bool],
) -> Option<Tile> {
    let res_u = frame.res_u as usize;
    let res_v = frame.res_v as usize;
    let n = frame.samples();
    let mut height = vec![0.0f32; n];
    // Index into `normals` of the triangle that wrote each sample, NONE for a hole.
    let mut source = vec![NONE; n];
    let mut normals = Vec::new();
    // Per id (index into `normals`), the index of its triangle in `triangles`.
    let mut input_index = Vec::new();
    let mut covered = 0u32;

    for (input, tri) in triangles.iter().enumerate() {
        let id = normals.len() as u32;
        let mut folded = false;
        let Some(normal) = covered_samples(tri, frame, |k, h| {
            if source[k] == NONE {
                height[k] = h;
                source[k] = id;
                covered += 1;
            } else if (h - height[k]).abs() > fold_tolerance {
                folded = true;
            }
            !folded
        }) else {
            continue;
        };
        if folded {
            return None;
        }
        normals.push(normal);
        input_index.push(input as u32);
    }

    if let Some(refinement) = judge {
        if !sampled_passes(refinement, &height, &source, res_u, res_v, frame.texel) {
            return None;
        }
    }
    // How deep a lid may hide the surface: as far as the criterion lets it fall from the ring.
    let lid_sink = exposed::lid_sink_texels(ring.map(|ring| ring.reach));
    let ring = match ring {
        Some(ring) => {
            let corners = ring_corners(triangles, frame, &source);
            ring_from_surface(ring, frame, &height, &source, &input_index, &corners)
        }
        None => Vec::new(),
    };
    let (mut height, mut source, mut sampled) = dilate(&height, &source, res_u, res_v);
    let written = sampled.clone();
    for (k, fill) in ring {
        sampled[k] = true;
        let id = normals.len() as u32;
        normals.push(fill.normal);
        input_index.push(fill.input);
        height[k] = fill.height;
        source[k] = id;
    }
    for k in walls(triangles, frame, &written, &source, &sampled, &mut height) {
        sampled[k] = true;
    }
    // The open boundary (step 4's last part): every cell a triangle beside it meets is full.
    if !open.is_empty() {
        let hole = |i: i64, j: i64| source[j as usize * res_u + i as usize] == NONE;
        let corners = cell_corners(triangles, frame, |t| open[t], hole);
        for (k, h, input) in corners {
            let tri = triangles[input as usize];
            source[k] = normals.len() as u32;
            normals.push(unit_normal(&tri).unwrap_or(Vec3::ZERO));
            input_index.push(input);
            height[k] = h;
        }
    }
    let mut tile = quantize(frame, &height, &source, &sampled, &normals, covered);
    tile.exposed = exposed(triangles, frame, &height, &source, &sampled, lid_sink);
    tile.sources = source
        .iter()
        .map(|&s| input_index.get(s as usize).copied().unwrap_or(NO_SOURCE))
        .collect();
    Some(tile)
}

/// The index of sample `(i, j)` of a grid `res_u` samples wide (as many rows as `source` holds)
/// when it lies in the grid and is written (its `source` not [`NONE`]): the neighbour test of
/// dilation, of the ring and of the cell corners.
fn written_at(source: &[u32], res_u: usize, i: i64, j: i64) -> Option<usize> {
    let res_v = source.len().checked_div(res_u).unwrap_or(0);
    if !(0..res_u as i64).contains(&i) || !(0..res_v as i64).contains(&j) {
        return None;
    }
    let k = j as usize * res_u + i as usize;
    (source[k] != NONE).then_some(k)
}

/// Marks a hole in the per-sample source index.
pub(super) const NONE: u32 = u32::MAX;

#[cfg(test)]
pub(super) mod tests {
    use super::*;

    /// Axis-aligned frame over `[0, res]²` in x, y with unit texels, heights along +z (also for
    /// `splat.rs`'s tests).
    pub(in crate::rbvh) fn xy_frame(res: u32) -> Frame {
        Frame {
            origin: Vec3::ZERO,
            u: Vec3::X,
            v: Vec3::Y,
            w: Vec3::Z,
            texel: 1.0,
            res_u: res,
            res_v: res,
        }
    }

    /// The square `[lo, hi]²` (in u, v texel units of `frame`) on the height function `h`, as two
    /// triangles wound so that their normal has a positive w component.
    pub(super) fn square(
        frame: &Frame,
        lo: f32,
        hi: f32,
        h: impl Fn(f32, f32) -> f32,
    ) -> Vec<[Vec3; 3]> {
        let p = |s: f32, t: f32| {
            frame.origin + s * frame.texel * frame.u + t * frame.texel * frame.v + h(s, t) * frame.w
        };
        vec![
            [p(lo, lo), p(hi, lo), p(hi, hi)],
            [p(lo, lo), p(hi, hi), p(lo, hi)],
        ]
    }

    /// [`rasterize`] with no criterion, no surface around the leaf and no open boundary.
    pub(super) fn plain(
        triangles: &[[Vec3; 3]],
        frame: &Frame,
        fold_tolerance: f32,
    ) -> Option<Tile> {
        rasterize(triangles, frame, fold_tolerance, None, None, &[])
    }

    /// World height of one step of `tile`'s codes: its quantization error bound.
    pub(super) fn quantum(tile: &Tile) -> f32 {
        tile.h_scale * Texel::step(tile.bits) as f32
    }

    /// Height of sample `k` measured along `w` from `reference`, decoded from the tile.
    pub(super) fn decoded(tile: &Tile, k: usize, reference: Vec3) -> f32 {
        (world_sample(
            tile,
            k as u32 % tile.frame.res_u,
            k as u32 / tile.frame.res_u,
        ) - reference)
            .dot(tile.frame.w)
    }

    pub(super) fn world_sample(tile: &Tile, i: u32, j: u32) -> Vec3 {
        let k = (j * tile.frame.res_u + i) as usize;
        let h = tile.texels[k].height_code() as f32 * tile.h_scale;
        tile.point(i as f32 + 0.5, j as f32 + 0.5, h)
    }

    /// A small triangle that touches the open boundary leaves no cell it meets bare: the corner
    /// seen only diagonally from its one written sample, with no surface over it for the ring,
    /// takes the triangle's plane (clamped to its heights), marked extrapolated. Without the
    /// boundary it stays a hole, as the neighbouring leaf is then expected to cover it.
    #[test]
    fn cells_beside_the_open_boundary_are_full() {
        let frame = xy_frame(8);
        let plane = |x: f32, y: f32| 1.0 + 0.5 * x + 0.25 * y;
        // In sample space (sample (i, j) at (i, j)): it holds sample (3, 3) alone.
        let corner = |x: f32, y: f32| Vec3::new(x + 0.5, y + 0.5, plane(x, y));
        let tri = [[corner(2.9, 2.9), corner(3.9, 3.2), corner(3.2, 3.9)]];
        let closed = plain(&tri, &frame, 0.01).unwrap();
        let open = rasterize(&tri, &frame, 0.01, None, None, &[true]).unwrap();
        assert_eq!((closed.covered, open.covered), (1, 1));
        let at = |tile: &Tile, i: usize, j: usize| tile.texels[j * 8 + i];
        assert!(at(&closed, 4, 4).is_hole());
        for (ci, cj) in [(2, 2), (3, 2), (2, 3), (3, 3)] {
            for (i, j) in [(ci, cj), (ci + 1, cj), (ci, cj + 1), (ci + 1, cj + 1)] {
                assert!(
                    !at(&open, i, j).is_hole(),
                    "cell ({ci}, {cj}), corner ({i}, {j})"
                );
            }
        }
        let filled = at(&open, 4, 4);
        assert!(!filled.is_sampled());
        let highest = plane(3.9, 3.2);
        let h = decoded(&open, 4 * 8 + 4, Vec3::ZERO);
        assert!(
            (h - highest).abs() <= 2.0 * quantum(&open) + 1e-5,
            "{h} vs {highest}"
        );
        assert!(filled.normal().dot(Vec3::new(-0.5, -0.25, 1.0).normalize()) > 0.999);
    }

    #[test]
    fn world_bounds_contain_every_sample() {
        let (c, s) = (0.3f32.cos(), 0.3f32.sin());
        let frame = Frame {
            origin: Vec3::new(-5.0, 2.0, 40.0),
            u: Vec3::new(c, 0.0, -s),
            v: Vec3::Y,
            w: Vec3::new(s, 0.0, c),
            texel: 0.5,
            res_u: 12,
            res_v: 9,
        };
        let bumpy = |s: f32, t: f32| (0.7 * s).sin() + 0.3 * t;
        let tile = plain(&square(&frame, 1.0, 11.0, bumpy), &frame, 0.01).unwrap();
        assert!(tile.covered > 0 && tile.h_scale > 0.0);
        let b = tile.world_bounds();
        // The tilted, bumpy tile's samples fill no more than the box of its tile box, which its
        // plane narrows to nearly theirs (the two may differ by the tight box's margin where a
        // sample is extreme along a world axis).
        assert_ne!(tile.slope, Vec2::ZERO);
        let tight = tile.surface_bounds();
        assert!(tight.area() <= b.area(), "{tight:?} against {b:?}");
        for j in 0..9 {
            for i in 0..12 {
                if !tile.texels[(j * 12 + i) as usize].is_hole() {
                    let p = world_sample(&tile, i, j);
                    for b in [b, tight] {
                        assert!(b.contains(p), "{p} not in {b:?}");
                    }
                }
            }
        }
    }

    #[test]
    fn heightfield_record_matches_the_frame() {
        let frame = Frame {
            texel: 0.25,
            ..xy_frame(8)
        };
        let plane = |s: f32, _| 0.1 * s;
        let tile = plain(&square(&frame, 0.0, 8.0, plane), &frame, 0.01).unwrap();
        let r = tile.heightfield(1234);
        let f = &tile.frame;
        assert_eq!(r.atlas_base, 1234);
        assert_eq!((r.res_u, r.res_v), (8, 8));
        assert_eq!(r.origin, f.origin.to_array());
        assert_eq!(r.h_scale, tile.h_scale);
        assert!((Vec3::from(r.axis_u).dot(f.u) - 1.0 / f.texel).abs() < 1e-5);
        assert!((Vec3::from(r.axis_v).dot(f.v) - 1.0 / f.texel).abs() < 1e-5);
        assert!(Vec3::from(r.axis_u).dot(f.v).abs() < 1e-6);
        // The tilted plane is sheared into the height row; a level one keeps `w` itself.
        assert!(tile.slope.x > 0.0);
        let sheared =
            f.w - tile.slope.x * Vec3::from(r.axis_u) - tile.slope.y * Vec3::from(r.axis_v);
        assert_eq!(Vec3::from(r.axis_w), sheared);
        let level = plain(&square(&frame, 0.0, 8.0, |_, _| 1.0), &frame, 0.01).unwrap();
        assert_eq!(level.slope, Vec2::ZERO);
        assert_eq!(Vec3::from(level.heightfield(0).axis_w), level.frame.w);
    }
}
