//! Rasterizing one leaf's triangles into its height-field tile (Novák & Dachsbacher 2012: "rasterize
//! surfaces into the atlas"; "texel centres sample the exact triangles"), then dilating and
//! quantizing it into the packed [`Texel`]s of `layout.rs`.
//!
//! ## Algorithm
//! 1. **Sampling.** Each triangle's geometric normal `n = normalize((b − a) × (c − a))` is taken as
//!    wound (the same convention as [`crate::geom::Hit`]); zero-area triangles are skipped. Its
//!    vertices are projected into *sample space*: `x = (p − origin)·u / texel − ½`,
//!    `y = (p − origin)·v / texel − ½`, so that sample `(i, j)` sits at `(x, y) = (i, j)`, and height
//!    `h = (p − origin)·w`. Triangles seen edge-on (`|n·w|` below [`EDGE_ON_COS`]) are skipped: they
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
//! 5. **Quantization.** With `h_lo`, `h_hi` the extreme heights of all valid samples (after
//!    dilation, the ring, the walls and the open boundary), `frame.origin` moves by `h_lo · w`,
//!    so code 0 is the lowest height, and the code of height `h` is the code nearest
//!    `(h − h_lo) / h_scale` whose parity tells a sampled height (even) from an extrapolated one
//!    (odd). A tile whose range is at most 254 · [`NARROW_QUANTUM_TEXELS`] texels is *narrow*:
//!    `h_scale = (h_hi − h_lo) / NARROW_MAX` and its codes are 8-bit ones
//!    ([`Texel::narrow_code_of`]), a worst quantization error of `(h_hi − h_lo) / 254`, at most
//!    [`NARROW_QUANTUM_TEXELS`] of a texel; the device stores them a byte each (issue "Small and
//!    valid at every scale": bytes per texel that fit the surface). Any other tile takes
//!    `h_scale = (h_hi − h_lo) / MAX_CODE` and 16-bit codes ([`Texel::code_of`]), a worst error
//!    of `(h_hi − h_lo) / 65534`. (Flat or empty tiles: `h_scale` 0, narrow.) Both add the f32
//!    rounding of the moved origin.
//! 6. **Exposed triangles** ([`Tile::exposed`], issue "No leaks between height fields"): the
//!    leaf's triangles that meet the bare part of a cell (no cell triangle over it: the ring
//!    found no surface for a corner), or rise more than [`CREST_TEXELS`] above a cell, or lie
//!    more than that below a cell of sampled corners or more than [`EXPOSED_SINK_TEXELS`] below
//!    one with an extrapolated corner, or face away from the axis over a steep cell
//!    ([`STEEP_CELL_TEXELS`]; [`exposed`]).
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

use glam::{DVec2, DVec3, Vec3};

use super::layout::{cell_triangles, GpuHeightfield, Texel};
use super::Refinement;
use crate::bvh::LinearBvh;
use crate::geom::{Aabb, Ray};

/// Triangles whose unit normal makes `|n·w|` at most this are treated as edge-on and skipped. A
/// triangle exactly edge-on projects, after f32 rounding of its vertices and of the frame axes,
/// to `|n·w|` of order 1e-7; 1e-5 leaves a margin above that while dropping only triangles within
/// 0.0006° of the projection direction.
pub const EDGE_ON_COS: f32 = 1.0e-5;

/// How far from its written neighbours' mean height a ring sample may find the surface, in
/// texels, at least: 2 where 3 made leaf boxes taller for nothing (dragon at the presets: the
/// same or fewer seam leaks, t p99 the same or better, 3% fewer cells per ray at Q0; 1.5 lost
/// accuracy, t p99 +7%; 3 and 4 for every leaf cost its Q0 t p99 0.150 → 0.155 and 0.170%).
pub(super) const RING_REACH: f32 = 2.0;

/// How far one of the leaf's triangles may rise above its cell's surface, or lie below a cell
/// of sampled corners, before it is traced exactly too, in texels (`exposed`): **the
/// approximation may clip a crest, or pass over a sheet under its surface, by up to two
/// texels** (issue "Small and valid at every scale"). A crest running between samples, or a
/// sheet the leaf's samples jump to, is cut under by the cells' chords; a ray entering the
/// solid there passes over the cell, and meets the leaf's surface at most this far in. Below
/// the sampling rate (a horn, a claw, a dragon's scales at a coarse preset) nearly every
/// triangle rises or sinks that much somewhere, so tighter rules (half a texel over sampled
/// corners, 0.3 over extrapolated ones, a texel under sampled ones, kept since the seam work)
/// made most of a small, detailed object's triangles exact: 167.5 of the 210.8 MB of the
/// paper-scale scene's Q0 (21.85M triangles), 2.79 of the dragon's 3.74 MB at 64 texels along
/// its diagonal. At two texels the dragon at 64 keeps 0.97 MB of them, at Q0 0.34 instead of
/// 0.58 MB, with its errors and FLIP unchanged; the default scene, whose cube, cylinder and cone
/// have edges the chords now clip, loses a little accuracy (t p99 0.057 → 0.089% of the diagonal
/// at Q0, 0.013 → 0.015% at Q2) for 4–7% less memory. No seam ray through a closed solid
/// anywhere, and seam leaks 3 → 7 per million over the default scene's Q0–Q4 (the leak
/// threshold is two texels behind the surface, `seams::LEAK_TEXELS`: a clipped crest is what it
/// allows) and as before on the dragon, the closed meshes and at the extreme criteria
/// (docs/guarantees.md).
pub const CREST_TEXELS: f32 = 2.0;

/// Largest quantization step, in texels, of a tile's 8-bit heights (step 5 of the module docs):
/// a tile whose heights span at most 254 such steps (two texels) stores a byte per height instead
/// of two (issue "Small and valid at every scale", bytes per texel that fit the surface). The
/// step is what accuracy allows, measured (`rbvh bench`, default scene and dragon close-up, Q0,
/// Q2 and Q4, 256 × 192): at 1/16 of a texel the default scene's t p99 rose by 14–83% (Q2
/// 0.0217 → 0.0266% of the diagonal), at 1/32 and 1/64 by up to 13% and 4%; at 1/128 every
/// figure of the default scene is unchanged and the dragon's t p99 within 0.4%, its mean within
/// 1.2% (its scanned detail errs far more than any quantum). The paper-scale scene's Q2 then keeps 72% of its texels in
/// 8-bit tiles (89% at 1/64).
pub const NARROW_QUANTUM_TEXELS: f32 = 1.0 / 128.0;

/// How far below the surface of a cell with an extrapolated corner one of the leaf's triangles
/// may lie before it is traced exactly too, in texels ([`exposed`]): there the extrapolation
/// has made a lid over the leaf's own surface, and a ray coming in from the side under the lid
/// (where the skirt tapers to nothing, `layout::MARCH_SKIRT_TEXELS`) meets the triangle but none
/// of the leaf's cells. Half a texel took the dragon's seam leaks at A⊥/A 0.01 from 210 to 74 per
/// million for 9% more exact parts at Q0 than a texel; with the steep-cell rule
/// ([`STEEP_CELL_TEXELS`]), 0.3 texel from 32 to 16, 0.1 texel to 14. At [`CREST_TEXELS`] the
/// cone's seam leaks at A⊥/A 0.01 rose from 25 to 215 per million: the lids keep theirs
/// (docs/guarantees.md).
const EXPOSED_SINK_TEXELS: f32 = 0.3;

/// How far apart in height the corners of a cell (holes aside) may lie before the cell counts as
/// *steep*, in texels ([`exposed`]): more than 71° on average along a side. There a height field
/// is a poor stand-in for the surface, which it meets nearly edge-on: one of the leaf's triangles
/// facing away from the axis over a steep cell is always traced exactly (an overhang's
/// underside, where the leaf's samples flip between the fold's sheets and a ray from below
/// slides under a pit of its surface). After the sink ([`EXPOSED_SINK_TEXELS`]) this took the
/// dragon's seam leaks at A⊥/A 0.01 from 16 to 9 per million (8% more exact parts there)
/// (docs/guarantees.md).
const STEEP_CELL_TEXELS: f32 = 3.0;

/// How far a ring sample may find the surface at most, in texels ([`ring_reach`]): at 8 the ring
/// of leaves seen nearly edge-on reached other sheets across creases (dragon at φ_max 89.5°:
/// t p99 0.207 → 0.301%, where 4 gave 0.193%).
const MAX_RING_REACH: f32 = 4.0;

/// How far from its written neighbours' mean height a leaf's ring sample may find the surface,
/// in texels, for a leaf built to `refinement`: the slope the criterion lets its surface have
/// (the tangent of the largest angle between its normals and its axis, or of the angle whose
/// cosine is the least projected area ratio), within [`RING_REACH`] and [`MAX_RING_REACH`]. The
/// presets' 60° allows 1.7 texels a texel, so they keep 2; leaves seen nearly edge-on rise
/// further within the texel to their ring, and with 2 their rings found no surface over many
/// corners, left bare (1M seam rays at Q0, 2 → 4: φ_max 89.5° dragon 21 → 3 leaks, bunny
/// 75 → 50; A⊥/A 0.01 dragon 4,475 → 2,887, bunny 3,916 → 3,173; t p99 better on all four).
pub(super) fn ring_reach(refinement: Refinement) -> f32 {
    let cos = match refinement {
        Refinement::NormalCone { max_angle_deg } => max_angle_deg.to_radians().cos(),
        Refinement::ProjectedArea { min_ratio } => min_ratio,
    };
    // `refinement` is validated: the cosine lies in (0, 1].
    let slope = (1.0 - cos * cos).max(0.0).sqrt() / cos;
    slope.clamp(RING_REACH, MAX_RING_REACH)
}

/// Where a leaf's ring of samples comes from (`raster.rs`, step 4): the scene's triangles in a
/// BVH, searched `reach` texels either side of each sample's estimate ([`ring_reach`]).
#[derive(Clone, Copy)]
pub struct Ring<'a> {
    /// The scene's triangles, the leaf's own among them.
    pub surface: &'a LinearBvh<'a>,
    /// How far from its estimate a ring sample may find the surface, in texels.
    pub reach: f32,
}

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
    /// Whether the codes are 8-bit ones (step 5 of the module docs): the tile goes to the atlas's
    /// narrow band ([`crate::rbvh::Atlas::narrow_rows`]).
    pub narrow: bool,
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
    /// The packed record: `axis_u = u / texel`, `axis_v = v / texel`, `axis_w = w`, resolution and
    /// `h_scale` from the tile, `atlas_base` as placed by `atlas::pack`.
    pub fn heightfield(&self, atlas_base: u32) -> GpuHeightfield {
        let f = &self.frame;
        GpuHeightfield {
            origin: f.origin.to_array(),
            atlas_base,
            axis_u: (f.u / f.texel).to_array(),
            res_u: f.res_u,
            axis_v: (f.v / f.texel).to_array(),
            res_v: f.res_v,
            axis_w: f.w.to_array(),
            h_scale: self.h_scale,
        }
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
                    corners.push(f.origin + s * f.texel * f.u + t * f.texel * f.v + h * f.w);
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
                b = b.grow(
                    f.origin
                        + (i as f32 + 0.5) * f.texel * f.u
                        + (j as f32 + 0.5) * f.texel * f.v
                        + h * f.w,
                );
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
    tile.exposed = exposed(triangles, frame, &height, &source, &sampled);
    tile.sources = source
        .iter()
        .map(|&s| input_index.get(s as usize).copied().unwrap_or(NO_SOURCE))
        .collect();
    Some(tile)
}

/// Step 1 for one triangle: `visit(k, h)` for every sample `k` of `frame` it covers (inclusive
/// edge functions, canonical edge order; see the module docs) with its height `h` there, until
/// `visit` returns false; then its unit normal as wound. None, visiting nothing, for a triangle
/// that is degenerate, seen edge-on, not finite, or beside the tile.
fn covered_samples(
    tri: &[Vec3; 3],
    frame: &Frame,
    mut visit: impl FnMut(usize, f32) -> bool,
) -> Option<Vec3> {
    let (res_u, res_v) = (frame.res_u as usize, frame.res_v as usize);
    let normal = unit_normal(tri)?;
    if normal.dot(frame.w).abs() <= EDGE_ON_COS {
        return None;
    }
    let p = tri.map(|q| frame.project(q));
    if !p.iter().all(|q| q.is_finite()) {
        return None;
    }
    let [a, b, c] = p.map(|q| DVec2::new(q.x, q.y));
    let lo = a.min(b).min(c).ceil().max(DVec2::ZERO);
    let hi = a
        .max(b)
        .max(c)
        .floor()
        .min(DVec2::new(res_u as f64 - 1.0, res_v as f64 - 1.0));
    if lo.x > hi.x || lo.y > hi.y {
        return None;
    }
    for j in lo.y as usize..=hi.y as usize {
        for i in lo.x as usize..=hi.x as usize {
            let s = DVec2::new(i as f64, j as f64);
            let e = [edge(b, c, s), edge(c, a, s), edge(a, b, s)];
            let inside = e.iter().all(|&x| x >= 0.0) || e.iter().all(|&x| x <= 0.0);
            let sum = e[0] + e[1] + e[2];
            if !inside || sum == 0.0 {
                continue;
            }
            let h = ((e[0] * p[0].z + e[1] * p[1].z + e[2] * p[2].z) / sum) as f32;
            if !visit(j * res_u + i, h) {
                return Some(normal);
            }
        }
    }
    Some(normal)
}

/// A triangle's unit normal as wound (step 1); None when it has no area.
fn unit_normal(tri: &[Vec3; 3]) -> Option<Vec3> {
    (tri[1] - tri[0]).cross(tri[2] - tri[0]).try_normalize()
}

/// A ring sample taken from the surface itself: its height, the normal of the triangle it lies
/// on, and the index in the leaf's triangles of the one it stands beside (whose source it reports
/// for colours).
struct RingSample {
    height: f32,
    normal: Vec3,
    input: u32,
}

/// The [`cell_corners`] the ring asks for: holes with no written sample (`source`) among their
/// eight neighbours, at the corners of any of the leaf's triangles' cells.
fn ring_corners(triangles: &[[Vec3; 3]], frame: &Frame, source: &[u32]) -> Vec<(usize, f32, u32)> {
    let written = |i: i64, j: i64| written_at(source, frame.res_u as usize, i, j).is_some();
    cell_corners(
        triangles,
        frame,
        |_| true,
        |ci, cj| !(-1..=1).any(|dj| (-1..=1).any(|di| written(ci + di, cj + dj))),
    )
}

/// The `wanted` samples `(i, j)` at a corner of a cell that one of the `triangles` that `which`
/// picks (by index) overlaps in projection, each with the height of that triangle's plane over
/// it (clamped to the triangle's own height range) and the triangle's index, the first such
/// triangle's; sorted by sample. A leaf's full cells must cover its whole footprint, not only
/// the surroundings of the sample centres its triangles happen to hold: a sliver, or a triangle
/// smaller than a texel (a leaf of one, where the criterion allows nothing larger), may hold
/// none, and the ring around written samples left the rest of it bare; so the ring asks for the
/// holes with no written sample among their eight neighbours (which it samples anyway), and the
/// open boundary for the holes left at the end. A short list, not a map over the tile: most
/// corners are written or beside written samples.
fn cell_corners(
    triangles: &[[Vec3; 3]],
    frame: &Frame,
    which: impl Fn(usize) -> bool,
    wanted: impl Fn(i64, i64) -> bool,
) -> Vec<(usize, f32, u32)> {
    let (res_u, res_v) = (frame.res_u as i64, frame.res_v as i64);
    let mut out = Vec::new();
    for (input, tri) in triangles.iter().enumerate() {
        if !which(input) {
            continue;
        }
        // As step 1: a face seen edge-on defines no height over a sample.
        let facing = unit_normal(tri);
        if facing.is_none_or(|n| n.dot(frame.w).abs() <= EDGE_ON_COS) {
            continue;
        }
        let p = tri.map(|q| frame.project(q));
        let (e1, e2) = (p[1] - p[0], p[2] - p[0]);
        let det = e1.x * e2.y - e2.x * e1.y;
        if !det.is_finite() || det == 0.0 {
            continue;
        }
        // The plane h(x, y) = h0 + a·(x − x0) + b·(y − y0) through the three projected corners.
        let a = (e1.z * e2.y - e2.z * e1.y) / det;
        let b = (e2.z * e1.x - e1.z * e2.x) / det;
        let lo = p[0].min(p[1]).min(p[2]);
        let hi = p[0].max(p[1]).max(p[2]);
        let [i0, j0, i1, j1] = cell_range(lo, hi, res_u, res_v);
        for j in j0..=j1 {
            for i in i0..=i1 {
                if !triangle_meets_square(&p, i as f64, j as f64) {
                    continue;
                }
                for (ci, cj) in [(i, j), (i + 1, j), (i, j + 1), (i + 1, j + 1)] {
                    if !wanted(ci, cj) {
                        continue;
                    }
                    let h = p[0].z + a * (ci as f64 - p[0].x) + b * (cj as f64 - p[0].y);
                    let h = h.clamp(lo.z, hi.z) as f32;
                    out.push(((cj * res_u + ci) as usize, h, input as u32));
                }
            }
        }
    }
    // First triangle wins: a stable sort keeps the order of equal samples.
    out.sort_by_key(|&(k, _, _)| k);
    out.dedup_by_key(|&mut (k, _, _)| k);
    out
}

/// The cells `[i0, j0, i1, j1]` of a `res_u` × `res_v` tile (by their lowest corner) that the box
/// from `lo` to `hi` (x, y in sample space) meets.
fn cell_range(lo: DVec3, hi: DVec3, res_u: i64, res_v: i64) -> [i64; 4] {
    [
        (lo.x.floor() as i64).max(0),
        (lo.y.floor() as i64).max(0),
        (hi.x.floor() as i64).min(res_u - 2),
        (hi.y.floor() as i64).min(res_v - 2),
    ]
}

/// The cells `(i, j)` (by their lowest corner) of a `res_u` × `res_v` tile that the projected
/// triangle `p` (x, y in sample space) meets, edges included.
fn cells_met(p: &[DVec3; 3], res_u: i64, res_v: i64) -> impl Iterator<Item = (i64, i64)> + '_ {
    let (lo, hi) = (p[0].min(p[1]).min(p[2]), p[0].max(p[1]).max(p[2]));
    let [i0, j0, i1, j1] = cell_range(lo, hi, res_u, res_v);
    (j0..=j1)
        .flat_map(move |j| (i0..=i1).map(move |i| (i, j)))
        .filter(|&(i, j)| triangle_meets_square(p, i as f64, j as f64))
}

/// The `triangles` (by index, ascending) that the finished height field does not cover well
/// enough for a ray entering the solid through them to be sure to meet it, so that the builder
/// adds them to the tree as triangles, traced exactly (`build.rs`): those that meet
/// * the *bare* part of a cell, which no cell triangle covers ([`cell_triangles`]): all of a
///   cell with two holes or more among its corners, or the half on a lone hole's side of the
///   diagonal between its neighbours. Edge-on triangles (a wall between two samples) count;
///   touching the bare part along an edge or at a point does not. After the ring and the open
///   boundary, these are cells over which the ring found no surface within its reach (a rim
///   seen nearly edge-on, a crease whose other sheet lies further), where rays aimed at the
///   seams passed between the leaves;
/// * a cell, rising more than [`CREST_TEXELS`] above its surface somewhere over it: the cell
///   cuts under a crest or a sheet its corners jump to or from, and a ray entering the solid
///   there passes over it (or, over an extrapolated corner, may leave the leaf over the rim
///   before it crosses the surface);
/// * a cell with an extrapolated corner (`sampled` false: the ring found no surface over it),
///   lying more than [`EXPOSED_SINK_TEXELS`] below it: the extrapolation is a lid over the
///   surface, which a ray from the side passes under;
/// * a cell of sampled corners (three or four), lying more than [`CREST_TEXELS`] below it: a
///   sheet under the leaf's surface, which a ray meets from below or from the side, not through
///   the cell over it;
/// * a steep cell, facing away from the axis: the underside of an overhang, whose sheet the
///   leaf's samples leave and rejoin, so that a ray from below slides under a pit of the
///   surface.
///
/// `height` and `source` as after step 4 (`NONE` a hole).
fn exposed(
    triangles: &[[Vec3; 3]],
    frame: &Frame,
    height: &[f32],
    source: &[u32],
    sampled: &[bool],
) -> Vec<Exposed> {
    exposed_in(triangles, frame, height, source, sampled, true)
}

/// [`exposed`], skipping with `prefilter` the triangles that a bound on their corners shows
/// need no test (without, the tests' oracle of that bound).
fn exposed_in(
    triangles: &[[Vec3; 3]],
    frame: &Frame,
    height: &[f32],
    source: &[u32],
    sampled: &[bool],
    prefilter: bool,
) -> Vec<Exposed> {
    let (res_u, res_v) = (frame.res_u as i64, frame.res_v as i64);
    let texel = frame.texel as f64;
    let crest = CREST_TEXELS as f64 * texel;
    let sink_extrapolated = EXPOSED_SINK_TEXELS as f64 * texel;
    let steep = STEEP_CELL_TEXELS as f64 * texel;
    let mut out = Vec::new();
    for (input, tri) in triangles.iter().enumerate() {
        let p = tri.map(|q| frame.project(q));
        let Some(n) = unit_normal(tri).filter(|_| p.iter().all(|q| q.is_finite())) else {
            continue;
        };
        let faces_away = n.dot(frame.w) < 0.0;
        // Most triangles lie over cells of sampled corners only, within the rise and sink
        // allowed there: nothing to test. Over a cell's triangle, the height of the triangle's
        // plane above the cell's surface is linear, so its extremes lie at the cell's corners.
        let (lo, hi) = (p[0].min(p[1]).min(p[2]), p[0].max(p[1]).max(p[2]));
        let [i0, j0, i1, j1] = cell_range(lo, hi, res_u, res_v);
        let edge_on = (p[1] - p[0]).truncate().perp_dot((p[2] - p[0]).truncate()) == 0.0;
        let (mut rise_max, mut sink_max, mut suspect) =
            (f64::NEG_INFINITY, f64::NEG_INFINITY, false);
        let (mut h_lo, mut h_hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for (i, j) in (j0..=j1 + 1).flat_map(|j| (i0..=i1 + 1).map(move |i| (i, j))) {
            let k = (j * res_u + i) as usize;
            suspect |= source[k] == NONE || !sampled[k];
            let above = plane_height(&p, DVec2::new(i as f64, j as f64)) - height[k] as f64;
            rise_max = rise_max.max(above);
            sink_max = sink_max.max(-above);
            (h_lo, h_hi) = (h_lo.min(height[k] as f64), h_hi.max(height[k] as f64));
        }
        // No cell of the range is steeper than the range's corners span.
        suspect |= h_hi - h_lo > steep;
        // A triangle seen edge-on (no plane over the cells) is tested; so is one within
        // rounding of a threshold, which the test proper computes otherwise.
        let slack = 1e-9 * texel;
        if prefilter
            && !suspect
            && !edge_on
            && rise_max + slack <= crest
            && sink_max + slack <= crest
        {
            continue;
        }
        let flat_p = p.map(|q| q.truncate());
        // Whether the triangle is uncovered over cell (i, j): None where the cell covers it,
        // else whether the cell is bare there (no cell triangle over that part of it).
        let uncovered = |(i, j): (i64, i64)| -> Option<bool> {
            // The corners in cycle order c00, c10, c11, c01 (counter-clockwise).
            let cycle = [(i, j), (i + 1, j), (i + 1, j + 1), (i, j + 1)];
            let k = |c: usize| (cycle[c % 4].1 * res_u + cycle[c % 4].0) as usize;
            let at = |c: usize| {
                let (ci, cj) = cycle[c % 4];
                DVec3::new(ci as f64, cj as f64, height[k(c)] as f64)
            };
            let hole = |c: usize| source[k(c)] == NONE;
            let (h_lo, h_hi) = (0..4)
                .filter(|&c| !hole(c))
                .map(|c| at(c).z)
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), h| {
                    (lo.min(h), hi.max(h))
                });
            let steep_cell = h_hi - h_lo > steep;
            // Touching the cell along an edge or at a corner is not meeting it.
            let square = [0, 1, 2, 3].map(|c| at(c).truncate());
            if !convex_overlap(&square, &flat_p) {
                return None;
            }
            // Two holes or more leave the whole cell bare; one, the half on its side.
            let lone = match (0..4).filter(|&c| hole(c)).count() {
                0 => None,
                1 => (0..4).find(|&c| hole(c)),
                _ => return Some(true),
            };
            if let Some(h) = lone {
                let bare = [at(h + 3), at(h), at(h + 1)].map(|q| q.truncate());
                if convex_overlap(&bare, &flat_p) {
                    return Some(true);
                }
            }
            if steep_cell && faces_away {
                return Some(false);
            }
            let sink = if (0..4).all(|c| hole(c) || sampled[k(c)]) {
                crest
            } else {
                sink_extrapolated
            };
            let quad = [[at(0), at(1), at(2)], [at(0), at(2), at(3)]];
            let three;
            let surface: &[[DVec3; 3]] = match lone {
                None => &quad,
                Some(h) => {
                    three = [[at(h + 1), at(h + 2), at(h + 3)]];
                    &three
                }
            };
            let off = surface.iter().any(|cell| {
                clip(&p, cell).iter().any(|q| {
                    let above = q.z - plane_height(cell, q.truncate());
                    above > crest || -above > sink
                })
            });
            off.then_some(false)
        };
        let found: Vec<((i64, i64), bool)> = cells_met(&p, res_u, res_v)
            .filter_map(|c| Some((c, uncovered(c)?)))
            .collect();
        let cells = cell_boxes(found.iter().map(|&(c, _)| c));
        if !cells.is_empty() {
            out.push(Exposed {
                input: input as u32,
                cells,
                bare: found.iter().any(|&(_, bare)| bare),
            });
        }
    }
    out
}

/// How far apart, in cells, two boxes of a triangle's uncovered cells must lie along u or v to
/// stay apart ([`cell_boxes`]): then their windows, each box with the ring of cells around it
/// ([`Exposed::part`]), at most touch.
const BOX_GAP_CELLS: i64 = 2;

/// `cells` as boxes `[i0, j0, i1, j1]` of cells, sorted: each cell joins a box, and boxes merge
/// while two lie within [`BOX_GAP_CELLS`] of each other along both u and v. A long triangle
/// uncovered at both ends (a cap's sliver, bare at the centre and past the rim at the other)
/// thus gives a box at each end rather than one spanning its whole length, which every ray
/// along it would enter (on the default scene at Q0, six such parts 36 texels long made shadow
/// rays test 0.4 triangles each).
fn cell_boxes(cells: impl Iterator<Item = (i64, i64)>) -> Vec<[i64; 4]> {
    let near = |a: [i64; 4], b: [i64; 4]| {
        b[0] <= a[2] + BOX_GAP_CELLS
            && a[0] <= b[2] + BOX_GAP_CELLS
            && b[1] <= a[3] + BOX_GAP_CELLS
            && a[1] <= b[3] + BOX_GAP_CELLS
    };
    let union = |a: [i64; 4], b: [i64; 4]| {
        [
            a[0].min(b[0]),
            a[1].min(b[1]),
            a[2].max(b[2]),
            a[3].max(b[3]),
        ]
    };
    let mut boxes: Vec<[i64; 4]> = Vec::new();
    for (i, j) in cells {
        let cell = [i, j, i, j];
        match boxes.iter_mut().find(|b| near(**b, cell)) {
            Some(b) => *b = union(*b, cell),
            None => boxes.push(cell),
        }
    }
    // A box that grew may now lie near another.
    while let Some((a, b)) = (0..boxes.len())
        .flat_map(|a| (a + 1..boxes.len()).map(move |b| (a, b)))
        .find(|&(a, b)| near(boxes[a], boxes[b]))
    {
        boxes[a] = union(boxes[a], boxes[b]);
        boxes.swap_remove(b);
    }
    boxes.sort_unstable();
    boxes
}

/// One of a leaf's triangles that its tile leaves uncovered ([`exposed`]), and where.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Exposed {
    /// Its index in the triangles given to [`rasterize`].
    pub input: u32,
    /// The cells it is uncovered over lie within these boxes `[i0, i1] × [j0, j1]`, each
    /// `[i0, j0, i1, j1]`: one or more, sorted, more than [`BOX_GAP_CELLS`] apart along u or v
    /// ([`cell_boxes`]).
    pub cells: Vec<[i64; 4]>,
    /// Whether some of those cells are bare where it meets them (no cell triangle over it):
    /// there its part is the only surface the leaf has.
    pub bare: bool,
}

impl Exposed {
    /// The part of the triangle `tri` (its world corners, as wound) over each box of cells it
    /// is uncovered over and the ring of cells around it, in `frame`: the triangle itself where
    /// it lies within one, else its clipped polygon as a fan of triangles per box, winding
    /// kept. Only that part is traced exactly: a long triangle meeting a bare cell at one end (a
    /// cone's side at its apex) would otherwise add its whole length to every ray along it. The
    /// ring keeps the cut a cell away from where the height field leaves it, over the covered
    /// cells; the boxes lie far enough apart that their windows do not overlap. Corners kept
    /// from `tri` keep their bits; new ones lie on its plane to f32 rounding. Cut in world
    /// space against the planes of the cells' sides, in f64.
    pub fn part(&self, frame: &Frame, tri: &[Vec3; 3]) -> Vec<[Vec3; 3]> {
        self.cells
            .iter()
            .flat_map(|&cells| window_part(frame, tri, cells))
            .collect()
    }
}

/// The part of `tri` over the cells `[i0, j0, i1, j1]` of `frame` and the ring around them
/// ([`Exposed::part`]).
fn window_part(frame: &Frame, tri: &[Vec3; 3], cells: [i64; 4]) -> Vec<[Vec3; 3]> {
    let [i0, j0, i1, j1] = cells.map(|c| c as f64);
    // Sample space x, y of the ring's outer sides: cell i spans [i, i + 1].
    let (lo, hi) = (
        DVec2::new(i0 - 1.0, j0 - 1.0),
        DVec2::new(i1 + 2.0, j1 + 2.0),
    );
    // `Frame::project`'s x, y of a world point, in f64 throughout.
    let (origin, u, v) = (
        frame.origin.as_dvec3(),
        frame.u.as_dvec3(),
        frame.v.as_dvec3(),
    );
    let texel = frame.texel as f64;
    let xy = |q: DVec3| {
        let d = q - origin;
        DVec2::new(d.dot(u) / texel - 0.5, d.dot(v) / texel - 0.5)
    };
    let world = tri.map(|q| q.as_dvec3());
    if world
        .iter()
        .all(|&q| xy(q).cmpge(lo).all() && xy(q).cmple(hi).all())
    {
        return vec![*tri];
    }
    let mut poly = world.to_vec();
    for signed in [
        &|q| xy(q).x - lo.x,
        &|q| hi.x - xy(q).x,
        &|q| xy(q).y - lo.y,
        &|q| hi.y - xy(q).y,
    ] as [&dyn Fn(DVec3) -> f64; 4]
    {
        poly = clip_half(&poly, signed);
    }
    // Slivers left where a corner lies on a side are dropped: the ring around the cells
    // keeps them over covered cells, and their normals would be rounding.
    let area = |[a, b, c]: [DVec3; 3]| (b - a).cross(c - a).length();
    let least = 1e-6 * area(world);
    (1..poly.len().saturating_sub(1))
        .map(|k| [poly[0], poly[k], poly[k + 1]])
        .filter(|&piece| area(piece) > least)
        .map(|piece| piece.map(|q| q.as_vec3()))
        .collect()
}

/// The part of the polygon `poly` (x, y in sample space, z carried along linearly) over the
/// triangle `window` (counter-clockwise in x, y): Sutherland–Hodgman clipping against its edges.
fn clip(poly: &[DVec3], window: &[DVec3; 3]) -> Vec<DVec3> {
    let mut out = poly.to_vec();
    for e in 0..3 {
        let (a, b) = (window[e].truncate(), window[(e + 1) % 3].truncate());
        out = clip_half(&out, |q| (b - a).perp_dot(q.truncate() - a));
    }
    out
}

/// The part of the convex polygon `poly` (its points carried along linearly) where `signed` is
/// at least 0: one step of Sutherland–Hodgman clipping. A corner on the line is kept once, and
/// an edge that only touches the line adds no point.
fn clip_half(poly: &[DVec3], signed: impl Fn(DVec3) -> f64) -> Vec<DVec3> {
    let mut out = Vec::with_capacity(poly.len() + 1);
    for (n, &q0) in poly.iter().enumerate() {
        let q1 = poly[(n + 1) % poly.len()];
        let (s0, s1) = (signed(q0), signed(q1));
        if s0 >= 0.0 {
            out.push(q0);
        }
        if (s0 > 0.0 && s1 < 0.0) || (s0 < 0.0 && s1 > 0.0) {
            out.push(q0 + (q1 - q0) * (s0 / (s0 - s1)));
        }
    }
    out
}

/// The height over `(x, y)` of the plane through the three points of `tri` (that of its first
/// point when they lie on a line in x, y).
fn plane_height(tri: &[DVec3; 3], q: DVec2) -> f64 {
    let (e1, e2, d) = (tri[1] - tri[0], tri[2] - tri[0], q - tri[0].truncate());
    let det = e1.truncate().perp_dot(e2.truncate());
    if det == 0.0 {
        return tri[0].z;
    }
    let u = d.perp_dot(e2.truncate()) / det;
    let v = e1.truncate().perp_dot(d) / det;
    tri[0].z + u * e1.z + v * e2.z
}

/// Whether the projected triangle `p` (x, y in sample space) meets the cell square
/// `[i, i + 1] × [j, j + 1]`, edges included: no separating axis among the square's two and the
/// triangle's three edge normals.
fn triangle_meets_square(p: &[DVec3; 3], i: f64, j: f64) -> bool {
    let square = [
        DVec2::new(i, j),
        DVec2::new(i + 1.0, j),
        DVec2::new(i, j + 1.0),
        DVec2::new(i + 1.0, j + 1.0),
    ];
    let tri = p.map(|q| DVec2::new(q.x, q.y));
    let separated = |axis: DVec2| {
        let span = |points: &[DVec2]| {
            points
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), q| {
                    let d = q.dot(axis);
                    (lo.min(d), hi.max(d))
                })
        };
        let (a, b) = (span(&square), span(&tri));
        a.1 < b.0 || b.1 < a.0
    };
    ![DVec2::X, DVec2::Y]
        .into_iter()
        .chain((0..3).map(|e| (tri[(e + 1) % 3] - tri[e]).perp()))
        .any(separated)
}

/// Whether the convex polygons `a` and `b` (vertices in order around each; a segment will do)
/// overlap over some area, or a segment passes through the other's inside: no separating axis
/// among their edges' normals. Sharing an edge or a corner is not overlapping.
fn convex_overlap(a: &[DVec2], b: &[DVec2]) -> bool {
    let span = |points: &[DVec2], axis: DVec2| {
        points
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), q| {
                let d = q.dot(axis);
                (lo.min(d), hi.max(d))
            })
    };
    let separated = |axis: DVec2| {
        let ((a_lo, a_hi), (b_lo, b_hi)) = (span(a, axis), span(b, axis));
        a_hi <= b_lo || b_hi <= a_lo
    };
    !edge_normals(a)
        .chain(edge_normals(b))
        .filter(|axis| *axis != DVec2::ZERO)
        .any(separated)
}

/// The normals of a polygon's edges (not unit).
fn edge_normals(poly: &[DVec2]) -> impl Iterator<Item = DVec2> + '_ {
    (0..poly.len()).map(move |e| (poly[(e + 1) % poly.len()] - poly[e]).perp())
}

/// The ring around the written samples (holes with a written sample among their eight
/// neighbours) and the `corners` ([`cell_corners`]), sampled from `ring.surface` — the scene's
/// triangles, the leaf's own among them — where one of them lies over the sample within
/// `ring.reach` texels of an estimate (the nearest such): the written neighbours' mean height,
/// or for a corner without any the plane of the triangle that needs it. The leaf's surface then
/// continues onto its neighbours' real surface, corners included, instead of a linear
/// extrapolation that sticks out at silhouettes. Each ring sample is found by two short rays
/// along `±w` from its estimate (the second only as far as the first one's hit), so the cost follows the ring's length, not how many triangles lie
/// near the tile: gathering and rasterizing those grew without bound where triangles are much
/// smaller than a texel (the paper-scale scene's Q2 took 98 s; 22 s by rays, below its exact BVH).
fn ring_from_surface(
    ring: Ring,
    frame: &Frame,
    height: &[f32],
    source: &[u32],
    input_index: &[u32],
    corners: &[(usize, f32, u32)],
) -> Vec<(usize, RingSample)> {
    let (res_u, res_v) = (frame.res_u as usize, frame.res_v as usize);
    let reach = ring.reach * frame.texel;
    // The nearest hit before `tmax` along `dir` from `from` on a face not seen edge-on (which
    // covers no sample centre in a way that defines one height, as in step 1).
    let probe = |from: Vec3, dir: Vec3, tmax: f32| {
        let facing = |n: Vec3| n.dot(frame.w).abs() > EDGE_ON_COS;
        let hit = ring
            .surface
            .closest_hit_where(&Ray::new(from, dir, 0.0, tmax), facing);
        hit.is_hit().then_some(hit)
    };
    let mut ring = Vec::new();
    for j in 0..res_v {
        for i in 0..res_u {
            let k = j * res_u + i;
            if source[k] != NONE {
                continue;
            }
            let (mut sum, mut n, mut beside) = (0.0f32, 0u32, NONE);
            for dj in -1i64..=1 {
                for di in -1i64..=1 {
                    if let Some(q) = written_at(source, res_u, i as i64 + di, j as i64 + dj) {
                        sum += height[q];
                        n += 1;
                        beside = source[q];
                    }
                }
            }
            // Beside written samples, their mean height; else the plane of a triangle whose cell
            // needs the sample as a corner.
            let (estimate, input) = if n > 0 {
                (sum / n as f32, input_index[beside as usize])
            } else if let Ok(c) = corners.binary_search_by_key(&k, |&(k, _, _)| k) {
                (corners[c].1, corners[c].2)
            } else {
                continue;
            };
            let from = frame.origin
                + (i as f32 + 0.5) * frame.texel * frame.u
                + (j as f32 + 0.5) * frame.texel * frame.v
                + estimate * frame.w;
            // Downwards only as far as the surface found upwards: only nearer counts (nothing
            // is nearer than a hit at the estimate itself).
            let up = probe(from, frame.w, reach);
            let down = match up {
                Some(h) if h.t == 0.0 => None,
                _ => probe(from, -frame.w, up.map_or(reach, |h| h.t)),
            };
            let nearest = match (up, down) {
                (_, Some(down)) => Some((estimate - down.t, down)),
                (Some(up), None) => Some((estimate + up.t, up)),
                (None, None) => None,
            };
            if let Some((height, hit)) = nearest {
                ring.push((
                    k,
                    RingSample {
                        height,
                        normal: hit.normal(),
                        input,
                    },
                ));
            }
        }
    }
    ring
}

/// Step 3's judgement: whether the surface as sampled (`height`, world units along `w`, where
/// `source` is not [`NONE`]) passes `refinement`. Sample `(i, j)` is the point
/// `(i·texel, j·texel, height)`; each cell contributes the march's triangles over its written
/// corners ([`cell_triangles`]), each judged by its normal's `w` component.
pub(super) fn sampled_passes(
    refinement: Refinement,
    height: &[f32],
    source: &[u32],
    res_u: usize,
    res_v: usize,
    texel: f32,
) -> bool {
    let texel = texel as f64;
    let point = |i: usize, j: usize| {
        let k = j * res_u + i;
        (source[k] != NONE)
            .then(|| DVec3::new(i as f64 * texel, j as f64 * texel, height[k] as f64))
    };
    // Σ |n·w|, Σ |n| over the cell triangles (twice their projected and true areas), and the
    // smallest cosine between a cell normal and `w`.
    let (mut projected, mut total, mut min_cos) = (0.0f64, 0.0f64, 1.0f64);
    let mut judged = false;
    for j in 0..res_v.saturating_sub(1) {
        for i in 0..res_u.saturating_sub(1) {
            let corners = [
                point(i, j),
                point(i + 1, j),
                point(i + 1, j + 1),
                point(i, j + 1),
            ];
            for [a, b, c] in cell_triangles(corners) {
                let n = (b - a).cross(c - a);
                let len = n.length();
                if len > 0.0 {
                    judged = true;
                    projected += n.z.abs();
                    total += len;
                    min_cos = min_cos.min(n.z.abs() / len);
                }
            }
        }
    }
    judged
        && match refinement {
            Refinement::NormalCone { max_angle_deg } => {
                min_cos >= f64::from(max_angle_deg).to_radians().cos()
            }
            Refinement::ProjectedArea { min_ratio } => projected >= f64::from(min_ratio) * total,
        }
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

/// Twice the signed area of `(a, b, p)`. The endpoints are put in a canonical (lexicographic) order
/// and the result negated when swapped, so `edge(a, b, p) == -edge(b, a, p)` exactly: the shared
/// edge of two triangles classifies every point consistently for both.
fn edge(a: DVec2, b: DVec2, p: DVec2) -> f64 {
    let orient = |a: DVec2, b: DVec2| (b.x - a.x) * (p.y - a.y) - (b.y - a.y) * (p.x - a.x);
    if (a.x, a.y) <= (b.x, b.y) {
        orient(a, b)
    } else {
        -orient(b, a)
    }
}

/// Step 4 of the module docs: one dilation pass, reading only the undilated state. Returns the
/// heights, the sources and, per sample, whether it was written before the pass (sampled, not
/// extrapolated: [`Texel::is_sampled`]).
pub(super) fn dilate(
    height: &[f32],
    source: &[u32],
    res_u: usize,
    res_v: usize,
) -> (Vec<f32>, Vec<u32>, Vec<bool>) {
    let mut out_h = height.to_vec();
    let mut out_s = source.to_vec();
    let sampled = source.iter().map(|&s| s != NONE).collect();
    let at = |i: isize, j: isize| written_at(source, res_u, i as i64, j as i64);
    for j in 0..res_v {
        for i in 0..res_u {
            let k = j * res_u + i;
            if source[k] != NONE {
                continue;
            }
            let (mut sum, mut count, mut first) = (0.0f64, 0u32, NONE);
            for (di, dj) in [(-1isize, 0isize), (1, 0), (0, -1), (0, 1)] {
                let (i, j) = (i as isize, j as isize);
                let Some(k1) = at(i + di, j + dj) else {
                    continue;
                };
                let h1 = height[k1] as f64;
                sum += match at(i + 2 * di, j + 2 * dj) {
                    Some(k2) => 2.0 * h1 - height[k2] as f64,
                    None => h1,
                };
                count += 1;
                if first == NONE {
                    first = source[k1];
                }
            }
            if count > 0 {
                out_h[k] = (sum / count as f64) as f32;
                out_s[k] = first;
            }
        }
    }
    (out_h, out_s, sampled)
}

/// Step 4's walls: for each extrapolated sample (dilated, not taken from the surface by the
/// ring) and each `written` 4-neighbour it extends, that direction's extrapolation is replaced
/// by the lowest height of the leaf's own triangles between the two where the extrapolation goes
/// down and the triangles fall further (the highest, where both rise), and the sample takes the
/// mean over the directions, as `dilate` does. Where a leaf's surface turns edge-on at its rim (a
/// silhouette seen from `w`), the linear extrapolation stops short of where the surface ends, and
/// the gap to the neighbouring leaf, tens of texels tall on a hemisphere seen from its pole, let
/// rays through; the cell from the last sample to the moved one walls it off, within the texel
/// beside the rim. Where the triangles end before they pass the extrapolation (a plane, a gentle
/// crease, an open boundary) nothing moves. Returns the samples it moved that lie a texel or more
/// above or below a written 4-neighbour (a cell steeper than 45°): their heights lie on the
/// surface's edge-on rim, so `rasterize` marks them sampled, and the skirt hangs under them.
fn walls(
    triangles: &[[Vec3; 3]],
    frame: &Frame,
    written: &[bool],
    source: &[u32],
    sampled: &[bool],
    height: &mut [f32],
) -> Vec<usize> {
    let (res_u, res_v) = (frame.res_u as i64, frame.res_v as i64);
    let wanted = |i: i64, j: i64| {
        (0..res_u).contains(&i)
            && (0..res_v).contains(&j)
            && source[(j * res_u + i) as usize] != NONE
            && !sampled[(j * res_u + i) as usize]
    };
    let is_written = |i: i64, j: i64| {
        (0..res_u).contains(&i) && (0..res_v).contains(&j) && written[(j * res_u + i) as usize]
    };
    const DIRECTIONS: [(i64, i64); 4] = [(-1, 0), (1, 0), (0, -1), (0, 1)];
    // Per extrapolated sample met (`slot` into `ranges`, in `samples`) and direction towards a
    // written neighbour, the height range of the own triangles over the segment between them.
    let mut slot = vec![u32::MAX; source.len()];
    let mut ranges: Vec<[(f64, f64); 4]> = Vec::new();
    let mut samples: Vec<usize> = Vec::new();
    for tri in triangles {
        let p = tri.map(|q| frame.project(q));
        if p.iter().any(|q| !q.is_finite()) {
            continue;
        }
        let lo = p[0].min(p[1]).min(p[2]);
        let hi = p[0].max(p[1]).max(p[2]);
        for j in (lo.y.floor() as i64 - 1).max(0)..=(hi.y.ceil() as i64 + 1).min(res_v - 1) {
            for i in (lo.x.floor() as i64 - 1).max(0)..=(hi.x.ceil() as i64 + 1).min(res_u - 1) {
                if !wanted(i, j) {
                    continue;
                }
                for (dir, &(di, dj)) in DIRECTIONS.iter().enumerate() {
                    if !is_written(i + di, j + dj) {
                        continue;
                    }
                    // The segment from the neighbour to the sample, along x (dj = 0) or y.
                    let along_x = dj == 0;
                    let (plane, a0, a1) = if along_x {
                        (j as f64, (i + di).min(i) as f64, (i + di).max(i) as f64)
                    } else {
                        (i as f64, (j + dj).min(j) as f64, (j + dj).max(j) as f64)
                    };
                    let off = |q: DVec3| if along_x { q.y - plane } else { q.x - plane };
                    let pos = |q: DVec3| if along_x { q.x } else { q.y };
                    // Where the triangle meets the segment's vertical plane: at most a corner
                    // and a crossing per edge.
                    let mut pts = [(0.0f64, 0.0f64); 6];
                    let mut count = 0;
                    for e in 0..3 {
                        let (a, b) = (p[e], p[(e + 1) % 3]);
                        let (da, db) = (off(a), off(b));
                        if da == 0.0 {
                            pts[count] = (pos(a), a.z);
                            count += 1;
                        }
                        if (da < 0.0 && db > 0.0) || (da > 0.0 && db < 0.0) {
                            let t = da / (da - db);
                            let q = a + (b - a) * t;
                            pts[count] = (pos(q), q.z);
                            count += 1;
                        }
                    }
                    let pts = &pts[..count];
                    let k = (j * res_u + i) as usize;
                    if slot[k] == u32::MAX {
                        slot[k] = ranges.len() as u32;
                        ranges.push([(f64::INFINITY, f64::NEG_INFINITY); 4]);
                        samples.push(k);
                    }
                    let entry = &mut ranges[slot[k] as usize][dir];
                    for x in 0..pts.len() {
                        for y in x..pts.len() {
                            let ((xa, ha), (xb, hb)) = (pts[x], pts[y]);
                            let (ta, tb) = if xa == xb {
                                if xa < a0 || xa > a1 {
                                    continue;
                                }
                                (0.0, 1.0)
                            } else {
                                let t0 = ((a0 - xa) / (xb - xa)).clamp(0.0, 1.0);
                                let t1 = ((a1 - xa) / (xb - xa)).clamp(0.0, 1.0);
                                let (t0, t1) = (t0.min(t1), t0.max(t1));
                                let (x0, x1) = (xa + (xb - xa) * t0, xa + (xb - xa) * t1);
                                if x1 < a0 || x0 > a1 {
                                    continue;
                                }
                                (t0, t1)
                            };
                            for t in [ta, tb] {
                                let h = ha + (hb - ha) * t;
                                entry.0 = entry.0.min(h);
                                entry.1 = entry.1.max(h);
                            }
                        }
                    }
                }
            }
        }
    }
    // Per sample, each direction whose extrapolation the triangles pass that way: the lowest
    // (highest) of their extremes where some fall (rise) further; the sample as dilated where
    // none do.
    let mut steep_walls = Vec::new();
    samples.sort_unstable();
    for k in samples {
        let (i, j) = ((k as i64) % res_u, (k as i64) / res_u);
        let (mut down, mut up) = (f64::INFINITY, f64::NEG_INFINITY);
        for (dir, &(di, dj)) in DIRECTIONS.iter().enumerate() {
            let (lo, hi) = ranges[slot[k] as usize][dir];
            if lo > hi {
                continue;
            }
            let h1 = height[((j + dj) * res_u + i + di) as usize] as f64;
            let e = if is_written(i + 2 * di, j + 2 * dj) {
                2.0 * h1 - height[((j + 2 * dj) * res_u + i + 2 * di) as usize] as f64
            } else {
                h1
            };
            if e <= h1 && lo < e {
                down = down.min(lo);
            } else if e >= h1 && hi > e {
                up = up.max(hi);
            }
        }
        // Down wins where directions disagree: the wall under a silhouette.
        let before = height[k];
        if down.is_finite() {
            height[k] = height[k].min(down as f32);
        } else if up.is_finite() {
            height[k] = height[k].max(up as f32);
        }
        let steep = || {
            DIRECTIONS.iter().any(|&(di, dj)| {
                is_written(i + di, j + dj)
                    && (height[((j + dj) * res_u + i + di) as usize] - height[k]).abs()
                        >= frame.texel
            })
        };
        if height[k] != before && steep() {
            steep_walls.push(k);
        }
    }
    steep_walls
}

/// Step 5 of the module docs: 8- or 16-bit heights over the tile's own range, origin moved to
/// `h_lo`.
pub(super) fn quantize(
    frame: &Frame,
    height: &[f32],
    source: &[u32],
    sampled: &[bool],
    normals: &[Vec3],
    covered: u32,
) -> Tile {
    let valid = || {
        height
            .iter()
            .zip(source)
            .filter(|(_, &s)| s != NONE)
            .map(|(&h, _)| h)
    };
    let h_lo = valid().fold(f32::INFINITY, f32::min);
    let h_hi = valid().fold(f32::NEG_INFINITY, f32::max);
    let range = if h_lo <= h_hi {
        h_hi as f64 - h_lo as f64
    } else {
        0.0
    };
    let narrow = range <= 254.0 * f64::from(NARROW_QUANTUM_TEXELS) * f64::from(frame.texel);
    let top = if narrow {
        Texel::NARROW_MAX
    } else {
        u32::from(Texel::MAX_CODE)
    };
    let (h_lo, h_scale) = if h_lo <= h_hi {
        (h_lo, (range / f64::from(top)) as f32)
    } else {
        (0.0, 0.0)
    };
    let texels = height
        .iter()
        .zip(source)
        .zip(sampled)
        .map(|((&h, &s), &sampled)| {
            if s == NONE {
                return Texel::HOLE;
            }
            let q = if h_scale > 0.0 {
                (h as f64 - h_lo as f64) / h_scale as f64
            } else {
                0.0
            };
            let code = if narrow {
                Texel::narrow_code_of(q, sampled)
            } else {
                Texel::code_of(q, sampled)
            };
            Texel::new(code, normals[s as usize])
        })
        .collect();
    Tile {
        frame: Frame {
            origin: frame.origin + h_lo * frame.w,
            ..*frame
        },
        texels,
        h_scale,
        narrow,
        covered,
        sources: Vec::new(),
        exposed: Vec::new(),
    }
}

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
    fn square(frame: &Frame, lo: f32, hi: f32, h: impl Fn(f32, f32) -> f32) -> Vec<[Vec3; 3]> {
        let p = |s: f32, t: f32| {
            frame.origin + s * frame.texel * frame.u + t * frame.texel * frame.v + h(s, t) * frame.w
        };
        vec![
            [p(lo, lo), p(hi, lo), p(hi, hi)],
            [p(lo, lo), p(hi, hi), p(lo, hi)],
        ]
    }

    /// [`rasterize`] with no criterion, no surface around the leaf and no open boundary.
    fn plain(triangles: &[[Vec3; 3]], frame: &Frame, fold_tolerance: f32) -> Option<Tile> {
        rasterize(triangles, frame, fold_tolerance, None, None, &[])
    }

    /// World height of one step of `tile`'s codes: its quantization error bound.
    fn quantum(tile: &Tile) -> f32 {
        let step = if tile.narrow { Texel::NARROW_STEP } else { 1 };
        tile.h_scale * step as f32
    }

    /// Height of sample `k` measured along `w` from `reference`, decoded from the tile.
    fn decoded(tile: &Tile, k: usize, reference: Vec3) -> f32 {
        let f = &tile.frame;
        (f.origin - reference).dot(f.w) + tile.texels[k].height_code() as f32 * tile.h_scale
    }

    fn world_sample(tile: &Tile, i: u32, j: u32) -> Vec3 {
        let f = &tile.frame;
        let k = (j * f.res_u + i) as usize;
        f.origin
            + (i as f32 + 0.5) * f.texel * f.u
            + (j as f32 + 0.5) * f.texel * f.v
            + tile.texels[k].height_code() as f32 * tile.h_scale * f.w
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

    /// A triangle over a cell that the finished tile leaves bare is exposed (traced exactly by
    /// the builder's triangle leaves), one the tile covers is not: the small triangle of
    /// [`cells_beside_the_open_boundary_are_full`], made level, leaves cell (3, 3) a hole short
    /// of full without the open boundary, and is covered with it.
    #[test]
    fn triangles_over_bare_cells_are_exposed() {
        let frame = xy_frame(8);
        let corner = |x: f32, y: f32| Vec3::new(x + 0.5, y + 0.5, 1.0);
        let tri = [[corner(2.9, 2.9), corner(3.9, 3.2), corner(3.2, 3.9)]];
        let tile = plain(&tri, &frame, 0.01).unwrap();
        assert_eq!(
            tile.exposed,
            [Exposed {
                input: 0,
                cells: vec![[3, 3, 3, 3]],
                bare: true,
            }]
        );
        let open = rasterize(&tri, &frame, 0.01, None, None, &[true]).unwrap();
        assert!(open.exposed.is_empty());
        // A plane over the whole frame: every cell full.
        let whole = square(&frame, 0.0, 8.0, |s, t| 0.3 * s - 0.2 * t);
        assert!(plain(&whole, &frame, 0.01).unwrap().exposed.is_empty());
    }

    /// The bare part of a cell with one hole is the half on the hole's side of the diagonal
    /// between its neighbours; a triangle in the other half, or touching the bare half only
    /// along that diagonal, is covered.
    #[test]
    fn only_the_holes_half_of_a_three_sample_cell_is_bare() {
        let frame = xy_frame(3);
        let mut source = vec![0; 9];
        // Cell (0, 0) has its hole at c11, sample (1, 1): its surface is the triangle c00, c10,
        // c01, and its bare half lies beyond the diagonal x + y = 1.
        source[4] = NONE;
        let (height, sampled) = (vec![0.0; 9], vec![true; 9]);
        let world = |x: f32, y: f32| Vec3::new(x + 0.5, y + 0.5, 0.0);
        let covered = [world(0.1, 0.1), world(0.6, 0.1), world(0.1, 0.6)];
        let on_diagonal = [world(0.0, 0.0), world(1.0, 0.0), world(0.0, 1.0)];
        let across = [world(0.1, 0.1), world(0.9, 0.3), world(0.3, 0.9)];
        let tris = [covered, on_diagonal, across];
        let inputs = |e: Vec<Exposed>| e.iter().map(|e| e.input).collect::<Vec<_>>();
        assert_eq!(
            inputs(exposed(&tris, &frame, &height, &source, &sampled)),
            [2]
        );
    }

    /// Only the part of an exposed triangle over its uncovered cells and the ring around them is
    /// kept: a triangle within them whole, bit for bit; a long one cut at the ring's sides, its
    /// pieces on its plane, wound as it is, and covering just that part of it.
    #[test]
    fn an_exposed_triangle_is_cut_to_its_uncovered_cells_and_their_ring() {
        let frame = xy_frame(16);
        // Sample space (x, y) at world (x + 0.5, y + 0.5), on the plane h = 1 + 0.5 x.
        let p = |x: f32, y: f32| Vec3::new(x + 0.5, y + 0.5, 1.0 + 0.5 * x);
        let long = [p(1.0, 1.0), p(14.0, 2.0), p(1.2, 3.0)];
        let at_start = Exposed {
            input: 0,
            cells: vec![[1, 1, 2, 2]],
            bare: true,
        };
        let pieces = at_start.part(&frame, &long);
        assert!(!pieces.is_empty() && pieces.len() <= 5, "{pieces:?}");
        let normal = (long[1] - long[0]).cross(long[2] - long[0]).normalize();
        let mut area = 0.0;
        for piece in &pieces {
            let n = (piece[1] - piece[0]).cross(piece[2] - piece[0]);
            assert!(n.normalize().dot(normal) > 0.9999, "{piece:?}");
            area += n.length() / 2.0;
            for q in piece {
                let s = frame.project(*q);
                // Cells 1..=2 and their ring: x, y within [0, 4].
                assert!(s.x >= -1e-5 && s.x <= 4.0 + 1e-5, "{q}");
                assert!((q.z - (1.0 + 0.5 * s.x as f32)).abs() < 1e-5, "{q}");
            }
        }
        // The long triangle's part with x ≤ 4: what clipping at x = 4 leaves of it.
        let whole = (long[1] - long[0]).cross(long[2] - long[0]).length() / 2.0;
        assert!(
            area > 0.3 * whole && area < 0.5 * whole,
            "{area} of {whole}"
        );
        let inside = Exposed {
            input: 0,
            cells: vec![[0, 0, 13, 3]],
            bare: true,
        };
        assert_eq!(inside.part(&frame, &long), [long]);
    }

    /// Uncovered cells form boxes that merge while two lie within [`BOX_GAP_CELLS`] of each other
    /// along both axes, whatever the order they come in, and stay apart otherwise.
    #[test]
    fn uncovered_cells_form_boxes_apart_by_more_than_the_gap() {
        let gap = BOX_GAP_CELLS;
        assert_eq!(
            cell_boxes([(0, 0), (gap, gap)].into_iter()),
            [[0, 0, gap, gap]]
        );
        assert_eq!(
            cell_boxes([(0, 0), (gap + 1, 0)].into_iter()),
            [[0, 0, 0, 0], [gap + 1, 0, gap + 1, 0]]
        );
        assert_eq!(
            cell_boxes([(0, gap + 1), (0, 0)].into_iter()),
            [[0, 0, 0, 0], [0, gap + 1, 0, gap + 1]]
        );
        // Far apart along u only: near along v does not join them.
        assert_eq!(cell_boxes([(0, 0), (9, 0), (9, 1)].into_iter()).len(), 2);
        // The third cell bridges the first two after both became boxes.
        for order in [
            [(0, 0), (2 * gap, 0), (gap, 0)],
            [(gap, 0), (0, 0), (2 * gap, 0)],
        ] {
            assert_eq!(
                cell_boxes(order.into_iter()),
                [[0, 0, 2 * gap, 0]],
                "{order:?}"
            );
        }
        assert!(cell_boxes(std::iter::empty()).is_empty());
    }

    /// A long flat triangle over a flat tile with a hole near each end is uncovered at both ends
    /// only: two boxes, and its exact part two pieces there, none over the covered middle.
    #[test]
    fn a_triangle_uncovered_at_both_ends_keeps_two_parts() {
        let frame = xy_frame(16);
        let (height, sampled) = (vec![0.0; 256], vec![true; 256]);
        let mut source = vec![0; 256];
        for (i, j) in [(2, 2), (13, 2)] {
            source[j * 16 + i] = NONE;
        }
        let p = |x: f32, y: f32| Vec3::new(x + 0.5, y + 0.5, 0.0);
        let long = [p(1.0, 1.0), p(14.0, 2.0), p(1.2, 3.0)];
        let found = exposed(&[long], &frame, &height, &source, &sampled);
        assert_eq!(found.len(), 1, "{found:?}");
        assert!(found[0].bare, "the holes leave cells bare");
        let boxes = &found[0].cells;
        assert_eq!(boxes.len(), 2, "{boxes:?}");
        assert!(boxes[0][2] <= 3 && boxes[1][0] >= 11, "{boxes:?}");
        let pieces = found[0].part(&frame, &long);
        let xs: Vec<f64> = pieces
            .iter()
            .flatten()
            .map(|&q| frame.project(q).x)
            .collect();
        assert!(
            xs.iter().all(|&x| x <= 5.0 + 1e-5 || x >= 9.0 - 1e-5),
            "{xs:?}"
        );
        assert!(
            xs.iter().any(|&x| x <= 2.0) && xs.iter().any(|&x| x >= 13.0),
            "{xs:?}"
        );
    }

    /// Over a cell with an extrapolated corner, a triangle rising more than [`CREST_TEXELS`]
    /// above the cell's surface, or lying more than [`EXPOSED_SINK_TEXELS`] below it, is
    /// exposed; one rising or sinking less is not, nor one lying as far below a cell of sampled
    /// corners.
    #[test]
    fn a_triangle_past_a_crest_or_under_an_extrapolated_lid_is_exposed() {
        let frame = xy_frame(3);
        let (height, source) = (vec![0.0; 9], vec![0; 9]);
        let mut sampled = vec![true; 9];
        // Cell (1, 1), all corners at height 0; its corner (2, 2) extrapolated below.
        let over = |rise: f32| {
            let p = |x: f32, y: f32, h: f32| Vec3::new(x + 0.5, y + 0.5, h);
            [[p(1.0, 1.0, 0.0), p(2.0, 1.0, 0.0), p(2.0, 2.0, rise)]]
        };
        let sink = EXPOSED_SINK_TEXELS;
        assert!(exposed(&over(-sink - 0.05), &frame, &height, &source, &sampled).is_empty());
        sampled[8] = false;
        let rise = CREST_TEXELS;
        assert_eq!(
            exposed(&over(rise + 0.05), &frame, &height, &source, &sampled),
            [Exposed {
                input: 0,
                cells: vec![[1, 1, 1, 1]],
                bare: false,
            }]
        );
        assert!(exposed(&over(rise - 0.05), &frame, &height, &source, &sampled).is_empty());
        // A little below the surface it is hit from above through the cell; further below,
        // under an extrapolated lid, a ray from the side would miss the cell.
        assert!(exposed(&over(-sink + 0.05), &frame, &height, &source, &sampled).is_empty());
        assert_eq!(
            exposed(&over(-sink - 0.05), &frame, &height, &source, &sampled).len(),
            1
        );
    }

    /// Over a cell of sampled corners, a triangle rising more than [`CREST_TEXELS`] above its
    /// surface or lying more than that below it is exposed, whichever way it faces; one rising
    /// or sinking less is not.
    #[test]
    fn triangles_far_above_or_below_sampled_corners_are_exposed() {
        let frame = xy_frame(3);
        let (height, source, sampled) = (vec![0.0; 9], vec![0; 9], vec![true; 9]);
        let p = |x: f32, y: f32, h: f32| Vec3::new(x + 0.5, y + 0.5, h);
        let over = |rise: f32| [[p(1.0, 1.0, 0.0), p(2.0, 1.0, 0.0), p(2.0, 2.0, rise)]];
        let exposed = |tris: &[[Vec3; 3]]| exposed(tris, &frame, &height, &source, &sampled);
        let rise = CREST_TEXELS;
        assert_eq!(
            exposed(&over(rise + 0.05)),
            [Exposed {
                input: 0,
                cells: vec![[1, 1, 1, 1]],
                bare: false,
            }]
        );
        assert!(exposed(&over(rise - 0.05)).is_empty());
        let sink = CREST_TEXELS;
        let flat = |h: f32, up: bool| {
            let (a, b) = (p(2.0, 1.0, h), p(2.0, 2.0, h));
            if up {
                [[p(1.0, 1.0, h), a, b]]
            } else {
                [[p(1.0, 1.0, h), b, a]]
            }
        };
        for up in [true, false] {
            assert_eq!(exposed(&flat(-sink - 0.05, up)).len(), 1);
            assert!(exposed(&flat(-sink + 0.05, up)).is_empty());
        }
        // With a hole at (1, 2) the cell's surface is the triangle (1, 1), (2, 1), (2, 2) and no
        // bound skips the test: the same thresholds hold over three sampled corners.
        let mut holed = source.clone();
        holed[7] = NONE;
        let three = |tris: &[[Vec3; 3]]| super::exposed(tris, &frame, &height, &holed, &sampled);
        assert_eq!(three(&over(rise + 0.05)).len(), 1);
        assert!(three(&over(rise - 0.05)).is_empty());
        assert_eq!(three(&flat(-sink - 0.05, false)).len(), 1);
        assert!(three(&flat(-sink + 0.05, false)).is_empty());
    }

    /// Over a steep cell of sampled corners (heights more than [`STEEP_CELL_TEXELS`] apart), a
    /// triangle facing away from the axis is exposed wherever it lies; over a gentle cell it is
    /// not. Rising above either, it is exposed past [`CREST_TEXELS`] only.
    #[test]
    fn triangles_facing_away_over_steep_cells_are_exposed() {
        let frame = xy_frame(3);
        let (source, sampled) = (vec![0; 9], vec![true; 9]);
        // Samples (i, j) at height 0 for i ≤ 1 and `wall` for i = 2: cell (1, 1) climbs `wall`
        // along u, its surface h = wall · (x − 1) over x ∈ [1, 2].
        let heights = |wall: f32| {
            (0..9)
                .map(|k| if k % 3 == 2 { wall } else { 0.0 })
                .collect()
        };
        let (steep, gentle): (Vec<f32>, Vec<f32>) = (
            heights(STEEP_CELL_TEXELS + 0.5),
            heights(STEEP_CELL_TEXELS - 0.5),
        );
        let p = |x: f32, y: f32, h: f32| Vec3::new(x + 0.5, y + 0.5, h);
        // Within the cell, wound up (+w) or down, `rise` above the surface at its far corner.
        let over = |wall: f32, rise: f32, up: bool| {
            let (a, b, c) = (
                p(1.2, 1.2, 0.2 * wall),
                p(1.8, 1.2, 0.8 * wall + rise),
                p(1.8, 1.8, 0.8 * wall + rise),
            );
            if up {
                [[a, b, c]]
            } else {
                [[a, c, b]]
            }
        };
        let exposed =
            |tris: &[[Vec3; 3]], height: &[f32]| exposed(tris, &frame, height, &source, &sampled);
        let rise = CREST_TEXELS;
        let wall = STEEP_CELL_TEXELS + 0.5;
        assert_eq!(
            exposed(&over(wall, rise + 0.05, true), &steep),
            [Exposed {
                input: 0,
                cells: vec![[1, 1, 1, 1]],
                bare: false,
            }]
        );
        assert!(exposed(&over(wall, rise - 0.05, true), &steep).is_empty());
        assert_eq!(exposed(&over(wall, 0.0, false), &steep).len(), 1);
        let wall = STEEP_CELL_TEXELS - 0.5;
        assert_eq!(exposed(&over(wall, rise + 0.05, true), &gentle).len(), 1);
        assert!(exposed(&over(wall, rise - 0.05, true), &gentle).is_empty());
        assert!(exposed(&over(wall, 0.0, false), &gentle).is_empty());
    }

    /// The bound that lets [`exposed`] skip most triangles never skips one that the test of its
    /// cells would find exposed: random triangles over a tile of random sampled heights, both
    /// ways, wound either way, tilted and flat, agree — over gentle heights (within ±1.5 texels,
    /// no cell steep), and near the surface of rough ones (±3, many cells steeper than
    /// [`STEEP_CELL_TEXELS`], each corner within 0.45 texel of it, where only the steep rules
    /// expose a triangle).
    #[test]
    fn the_corner_bound_skips_no_exposed_triangle() {
        let frame = xy_frame(6);
        let mut rng = crate::random::SplitMix64::new(0x5EED_0018);
        let mut uniform = |lo: f32, hi: f32| lo + (hi - lo) * rng.next_f32();
        for (spread, near, least, most) in [(1.5, false, 300, 2700), (3.0, true, 100, 2900)] {
            let height: Vec<f32> = (0..36).map(|_| uniform(-spread, spread)).collect();
            // The bilinear surface through the samples at sample-space (x, y) in [0, 5]².
            let surface = |x: f32, y: f32| {
                let (x, y) = (x.clamp(0.0, 5.0), y.clamp(0.0, 5.0));
                let (i, j) = ((x as usize).min(4), (y as usize).min(4));
                let (fx, fy) = (x - i as f32, y - j as f32);
                let h = |i: usize, j: usize| height[j * 6 + i];
                (h(i, j) * (1.0 - fx) + h(i + 1, j) * fx) * (1.0 - fy)
                    + (h(i, j + 1) * (1.0 - fx) + h(i + 1, j + 1) * fx) * fy
            };
            let (source, sampled) = (vec![0; 36], vec![true; 36]);
            let triangles: Vec<[Vec3; 3]> = (0..3000)
                .map(|_| {
                    let centre = Vec3::new(
                        uniform(0.5, 5.5),
                        uniform(0.5, 5.5),
                        uniform(-spread, spread),
                    );
                    let size = uniform(0.1, 2.0);
                    std::array::from_fn(|_| {
                        let q = centre
                            + Vec3::new(
                                uniform(-size, size),
                                uniform(-size, size),
                                uniform(-0.5, 0.5),
                            );
                        if near {
                            let z = surface(q.x - 0.5, q.y - 0.5) + uniform(-0.45, 0.45);
                            Vec3::new(q.x, q.y, z)
                        } else {
                            q
                        }
                    })
                })
                .collect();
            let with = exposed_in(&triangles, &frame, &height, &source, &sampled, true);
            let without = exposed_in(&triangles, &frame, &height, &source, &sampled, false);
            let differ = with.iter().zip(&without).find(|(a, b)| a != b);
            assert!(
                with.len() == without.len() && differ.is_none(),
                "±{spread}: {} exposed with the bound, {} without; first difference {differ:?}",
                with.len(),
                without.len()
            );
            println!("±{spread}: {} of {} exposed", with.len(), triangles.len());
            assert!(
                with.len() > least && with.len() < most,
                "±{spread}: {} exposed",
                with.len()
            );
        }
    }

    #[test]
    fn flat_square_is_exact() {
        let frame = xy_frame(8);
        let tile = plain(&square(&frame, 0.0, 8.0, |_, _| 2.0), &frame, 0.01).unwrap();
        assert_eq!(tile.covered, 64);
        assert_eq!(tile.h_scale, 0.0);
        assert_eq!(tile.frame.origin, Vec3::new(0.0, 0.0, 2.0));
        for t in &tile.texels {
            assert_eq!(t.height_code(), 0);
            assert!(t.normal().dot(Vec3::Z) > 0.9999);
        }
    }

    /// Heights spanning up to 254 steps of [`NARROW_QUANTUM_TEXELS`] take 8-bit codes, and err by
    /// at most that step; a span a little larger keeps 16-bit codes.
    #[test]
    fn narrow_tiles_err_by_at_most_their_quantum() {
        let frame = Frame {
            texel: 0.5,
            ..xy_frame(16)
        };
        // Heights over the sample centres 0.5..15.5 of s: a span of 15 · slope world units.
        let span_texels = 254.0 * NARROW_QUANTUM_TEXELS;
        for (span, narrow) in [(0.0, true), (0.5, true), (0.99, true), (1.02, false)] {
            let slope = span * span_texels * frame.texel / 15.0;
            let plane = |s: f32, _: f32| slope * s;
            let tile = plain(&square(&frame, 0.0, 16.0, plane), &frame, 0.01).unwrap();
            assert_eq!(tile.narrow, narrow, "a span of {span} × 254 steps");
            assert!(quantum(&tile) <= NARROW_QUANTUM_TEXELS * frame.texel * 1.0001 || !narrow);
            for k in 0..256usize {
                let want = plane((k % 16) as f32 + 0.5, 0.0);
                let got = decoded(&tile, k, frame.origin);
                assert!((got - want).abs() <= quantum(&tile) + 1e-5, "{span}: {k}");
                let code = u32::from(tile.texels[k].height_code());
                assert!(!narrow || code % Texel::NARROW_STEP == 0, "{span}: {k}");
            }
        }
    }

    #[test]
    fn tilted_plane_is_within_the_quantization_bound() {
        let frame = Frame {
            origin: Vec3::new(10.0, -3.0, 1.0),
            texel: 0.25,
            ..xy_frame(16)
        };
        let plane = |s: f32, t: f32| 0.3 * s + 0.2 * t + 1.0;
        let tile = plain(&square(&frame, 0.0, 16.0, plane), &frame, 0.01).unwrap();
        assert_eq!(tile.covered, 256);
        let bound = quantum(&tile) + 1e-5;
        for j in 0..16 {
            for i in 0..16 {
                let k = j * 16 + i;
                let want = plane(i as f32 + 0.5, j as f32 + 0.5);
                let got = decoded(&tile, k, frame.origin);
                assert!((got - want).abs() <= bound, "({i}, {j}): {got} vs {want}");
            }
        }
        let n = Vec3::new(-0.3 / 0.25, -0.2 / 0.25, 1.0).normalize();
        assert!(tile.texels[0].normal().dot(n) > 0.999);
    }

    #[test]
    fn parallel_layers_fold_unless_within_tolerance() {
        let frame = xy_frame(8);
        let mut two = square(&frame, 0.0, 8.0, |_, _| 0.0);
        two.extend(square(&frame, 0.0, 8.0, |_, _| 10.0));
        assert_eq!(plain(&two, &frame, 1.0), None);

        let mut close = square(&frame, 0.0, 8.0, |_, _| 0.0);
        close.extend(square(&frame, 0.0, 8.0, |_, _| 0.05));
        let tile = plain(&close, &frame, 0.1).unwrap();
        assert_eq!(tile.covered, 64);
        // First writer wins: the lower layer.
        assert_eq!(tile.frame.origin.z, 0.0);
        assert_eq!(tile.h_scale, 0.0);
    }

    #[test]
    fn dilation_fills_the_ring_and_extrapolates_linearly() {
        let frame = xy_frame(16);
        let plane = |s: f32, t: f32| 0.5 * s - 0.25 * t + 3.0;
        // Samples 4..=11 in each direction are covered (centres 4.5 ..= 11.5).
        let tile = plain(&square(&frame, 4.0, 12.0, plane), &frame, 0.01).unwrap();
        assert_eq!(tile.covered, 64);
        let core = |x: u32| (4..=11).contains(&x);
        let ring = |x: u32| x == 3 || x == 12;
        let bound = quantum(&tile) + 1e-5;
        for j in 0..16 {
            for i in 0..16 {
                let k = (j * 16 + i) as usize;
                let expect = (core(i) && core(j)) || (core(i) && ring(j)) || (ring(i) && core(j));
                assert_eq!(!tile.texels[k].is_hole(), expect, "({i}, {j})");
                assert_eq!(
                    tile.texels[k].is_sampled(),
                    core(i) && core(j),
                    "({i}, {j})"
                );
                if expect {
                    let want = plane(i as f32 + 0.5, j as f32 + 0.5);
                    let got = decoded(&tile, k, frame.origin);
                    assert!((got - want).abs() <= bound, "({i}, {j}): {got} vs {want}");
                }
            }
        }
    }

    /// A flat top (height 5) whose last texel falls steeply (slope 5) to height 0 at s = 8.2:
    /// the dilated sample beyond it (i = 8) would continue the slope only to 2; the wall takes
    /// it down to 0, where the leaf's own triangles end, and marks it sampled (steeper than 45°:
    /// the skirt hangs under it). The flat side (i = 1) extends flat, unmoved.
    #[test]
    fn walls_take_extrapolated_samples_down_to_where_the_own_surface_ends() {
        let frame = xy_frame(16);
        let p = |s: f32, t: f32, h: f32| Vec3::new(s, t, h);
        let tris = vec![
            [p(2.0, 2.0, 5.0), p(7.2, 2.0, 5.0), p(7.2, 12.0, 5.0)],
            [p(2.0, 2.0, 5.0), p(7.2, 12.0, 5.0), p(2.0, 12.0, 5.0)],
            [p(7.2, 2.0, 5.0), p(8.2, 2.0, 0.0), p(8.2, 12.0, 0.0)],
            [p(7.2, 2.0, 5.0), p(8.2, 12.0, 0.0), p(7.2, 12.0, 5.0)],
        ];
        let tile = plain(&tris, &frame, 0.01).unwrap();
        let at = |i: usize, j: usize| (j * 16 + i, tile.texels[j * 16 + i]);
        for j in 3..=10 {
            let (k, steep) = at(7, j);
            assert!((decoded(&tile, k, frame.origin) - 3.5).abs() < quantum(&tile) + 1e-3);
            assert!(steep.is_sampled());
            let (k, wall) = at(8, j);
            let h = decoded(&tile, k, frame.origin);
            assert!(h.abs() < quantum(&tile) + 1e-3, "({j}): {h}");
            // 3.5 texels below its written neighbour: a steep wall, marked for the skirt.
            assert!(wall.is_sampled());
            let (k, flat) = at(1, j);
            assert!((decoded(&tile, k, frame.origin) - 5.0).abs() < quantum(&tile) + 1e-3);
            assert!(!flat.is_sampled());
        }
        // A rim that falls only half a texel: the wall moves the sample down to 4.5 all the
        // same, a third of a texel below its written neighbour, and leaves it extrapolated.
        let gentle = vec![
            tris[0],
            tris[1],
            [p(7.2, 2.0, 5.0), p(8.2, 2.0, 4.5), p(8.2, 12.0, 4.5)],
            [p(7.2, 2.0, 5.0), p(8.2, 12.0, 4.5), p(7.2, 12.0, 5.0)],
        ];
        let tile = plain(&gentle, &frame, 0.01).unwrap();
        for j in 3..=10 {
            let k = j * 16 + 8;
            let h = decoded(&tile, k, frame.origin);
            assert!((h - 4.5).abs() < quantum(&tile) + 1e-3, "({j}): {h}");
            assert!(!tile.texels[k].is_sampled());
        }
    }

    /// An L-shaped patch of the plane h = 2s − t: the hole in its inner corner extends two
    /// written samples (one each way), and the walls leave it on the plane, as dilation put it.
    #[test]
    fn walls_leave_planes_extended_exactly() {
        let frame = xy_frame(16);
        let plane = |s: f32, t: f32| 2.0 * s - t;
        let mut tris = square(&frame, 2.0, 6.0, plane);
        let p = |s: f32, t: f32| Vec3::new(s, t, plane(s, t));
        tris.extend([
            [p(6.0, 2.0), p(10.0, 2.0), p(10.0, 6.0)],
            [p(6.0, 2.0), p(10.0, 6.0), p(6.0, 6.0)],
            [p(2.0, 6.0), p(6.0, 6.0), p(6.0, 10.0)],
            [p(2.0, 6.0), p(6.0, 10.0), p(2.0, 10.0)],
        ]);
        let tile = plain(&tris, &frame, 0.01).unwrap();
        let bound = quantum(&tile) + 1e-4;
        for (i, j) in [(6, 6), (10, 4), (4, 10), (1, 4), (4, 1)] {
            let k = j * 16 + i;
            let got = decoded(&tile, k, frame.origin);
            let want = plane(i as f32 + 0.5, j as f32 + 0.5);
            assert!((got - want).abs() <= bound, "({i}, {j}): {got} vs {want}");
            assert!(!tile.texels[k].is_sampled(), "({i}, {j})");
        }
    }

    #[test]
    fn the_ring_reaches_as_far_as_the_criterion_lets_the_surface_rise() {
        let cone = |max_angle_deg| ring_reach(Refinement::NormalCone { max_angle_deg });
        let area = |min_ratio| ring_reach(Refinement::ProjectedArea { min_ratio });
        // The presets' 60° (1.73 texels a texel) and anything flatter keep the least reach.
        assert_eq!(cone(60.0), RING_REACH);
        assert_eq!(cone(0.5), RING_REACH);
        assert_eq!(area(1.0), RING_REACH);
        // Steeper, the slope: tan 70° = 2.75.
        assert!((cone(70.0) - 70f32.to_radians().tan()).abs() < 1e-5);
        assert!((area(0.3) - (1.0f32 - 0.09).sqrt() / 0.3).abs() < 1e-5);
        // Nearly edge-on, at most MAX_RING_REACH.
        assert_eq!(cone(89.5), MAX_RING_REACH);
        assert_eq!(area(0.01), MAX_RING_REACH);
    }

    #[test]
    fn the_ring_follows_the_neighbouring_surface_nearest_the_rim() {
        let frame = xy_frame(16);
        // The leaf: flat at height 3 over samples 4..=11. Beyond its +u side the scene bends up
        // (slope 1), and a decoy layer lies 1.9 above the rim there, also within reach.
        let own = square(&frame, 4.0, 12.0, |_, _| 3.0);
        let bend = |s: f32, _: f32| 3.0 + (s - 12.0);
        let p = |s: f32, t: f32, h: f32| Vec3::new(s, t, h);
        let mut scene_tris = own.clone();
        scene_tris.push([p(12.0, 4.0, 3.0), p(16.0, 4.0, 7.0), p(16.0, 12.0, 7.0)]);
        scene_tris.push([p(12.0, 4.0, 3.0), p(16.0, 12.0, 7.0), p(12.0, 12.0, 3.0)]);
        scene_tris.push([p(12.0, 4.0, 4.9), p(16.0, 4.0, 4.9), p(16.0, 12.0, 4.9)]);
        scene_tris.push([p(12.0, 4.0, 4.9), p(16.0, 12.0, 4.9), p(12.0, 12.0, 4.9)]);
        let mut scene = crate::scene::Scene::new("bend");
        let positions: Vec<Vec3> = scene_tris.iter().flatten().copied().collect();
        let indices: Vec<[u32; 3]> = (0..scene_tris.len() as u32)
            .map(|k| [3 * k, 3 * k + 1, 3 * k + 2])
            .collect();
        scene.push_object("bend", &positions, &indices);
        let surface = LinearBvh::build(&scene, 4).expect("builds");
        let ring = Ring {
            surface: &surface,
            reach: RING_REACH,
        };
        let tile = rasterize(&own, &frame, 0.01, None, Some(ring), &[]).unwrap();
        let plain = plain(&own, &frame, 0.01).unwrap();
        for j in 4..=11u32 {
            // +u: the bent surface at the ring sample's centre, not the flat extrapolation
            // nor the decoy, marked as sampled; -u, where no surface continues: the
            // extrapolation, marked as such (no skirt hangs under it).
            let k = (j * 16 + 12) as usize;
            let got = decoded(&tile, k, frame.origin);
            assert!(
                (got - bend(12.5, 0.0)).abs() < quantum(&tile) + 1e-3,
                "({j}): {got}"
            );
            assert!(tile.texels[k].is_sampled());
            assert!((decoded(&plain, k, frame.origin) - 3.0).abs() < quantum(&plain) + 1e-3);
            assert!(!plain.texels[k].is_sampled());
            let k = (j * 16 + 3) as usize;
            assert!((decoded(&tile, k, frame.origin) - 3.0).abs() < quantum(&tile) + 1e-3);
            assert!(!tile.texels[k].is_sampled());
        }
    }

    #[test]
    fn cells_under_a_triangle_without_sample_centres_get_their_corners() {
        let frame = xy_frame(8);
        // A triangle inside the cell between samples 3 and 4 on both axes, holding no centre,
        // on the plane h = 2 + x (sample space): nothing written, four corners wanted.
        let p = |x: f32, y: f32| Vec3::new(x + 0.5, y + 0.5, 2.0 + x);
        let sliver = [[p(3.2, 3.2), p(3.8, 3.3), p(3.3, 3.8)]];
        let source = vec![NONE; 64];
        let corners = ring_corners(&sliver, &frame, &source);
        let at: Vec<(usize, f32)> = corners.iter().map(|&(k, h, _)| (k, h)).collect();
        // Corners (3, 3), (4, 3), (3, 4), (4, 4); heights from the plane, clamped to the
        // triangle's own range [5.2, 5.8].
        assert_eq!(at, [(27, 5.2), (28, 5.8), (35, 5.2), (36, 5.8)]);
        // Beside a written sample, a corner is left to the ring around it.
        let mut written = source.clone();
        written[26] = 0;
        let corners = ring_corners(&sliver, &frame, &written);
        assert!(
            corners.iter().all(|&(k, _, _)| k == 36 || k == 28),
            "{corners:?}"
        );
        // Seen edge-on, a triangle wants nothing.
        let edge_on = [[
            Vec3::new(3.6, 3.6, 0.0),
            Vec3::new(4.4, 3.6, 0.0),
            Vec3::new(3.6, 3.6, 1.0),
        ]];
        assert!(ring_corners(&edge_on, &frame, &source).is_empty());
    }

    #[test]
    fn shared_edges_through_sample_centres_lose_no_sample() {
        // A rotated, offset frame with an odd texel size, and a mesh reaching past the frame whose
        // vertices lie on sample centres (up to f32 rounding): its edges, diagonals included, run
        // through sample centres, and every sample must still be covered.
        let (c, s) = (0.6f32.cos(), 0.6f32.sin());
        let frame = Frame {
            origin: Vec3::new(123.37, -45.1, 7.3),
            u: Vec3::new(c, s, 0.0),
            v: Vec3::new(-s, c, 0.0),
            w: Vec3::Z,
            texel: 0.1,
            res_u: 17,
            res_v: 17,
        };
        let p = |i: i32, j: i32| {
            let (x, y) = (i as f32 + 0.5, j as f32 + 0.5);
            frame.origin
                + x * frame.texel * frame.u
                + y * frame.texel * frame.v
                + (0.01 * x - 0.02 * y) * frame.w
        };
        let mut tris = Vec::new();
        for j in (-2..18).step_by(2) {
            for i in (-2..18).step_by(2) {
                let q = [p(i, j), p(i + 2, j), p(i + 2, j + 2), p(i, j + 2)];
                if (i + j).rem_euclid(4) == 0 {
                    tris.push([q[0], q[1], q[2]]);
                    tris.push([q[0], q[2], q[3]]);
                } else {
                    tris.push([q[0], q[1], q[3]]);
                    tris.push([q[1], q[2], q[3]]);
                }
            }
        }
        let tile = plain(&tris, &frame, 1e-3).unwrap();
        assert_eq!(tile.covered, 17 * 17);
    }

    #[test]
    fn degenerate_input_gives_holes_without_panic() {
        let frame = xy_frame(8);
        let a = Vec3::new(1.0, 1.0, 0.0);
        let b = Vec3::new(6.0, 5.0, 1.0);
        let inputs: [Vec<[Vec3; 3]>; 4] = [
            vec![],
            vec![[a, a, b]],
            vec![[a, b, 0.5 * (a + b)]],
            // Edge-on: the plane y = 4.5 runs exactly through a row of sample centres.
            vec![[
                Vec3::new(0.0, 4.5, 0.0),
                Vec3::new(8.0, 4.5, 0.0),
                Vec3::new(4.0, 4.5, 5.0),
            ]],
        ];
        for tris in inputs {
            let tile = plain(&tris, &frame, 0.1).unwrap();
            assert_eq!(tile.covered, 0);
            assert_eq!(tile.h_scale, 0.0);
            assert_eq!(tile.texels.len(), 64);
            assert!(tile.texels.iter().all(|t| t.is_hole()));
        }
        let empty = Frame {
            res_u: 0,
            res_v: 0,
            ..frame
        };
        let tile = plain(&square(&frame, 0.0, 8.0, |_, _| 1.0), &empty, 0.1).unwrap();
        assert!(tile.texels.is_empty() && tile.covered == 0);
        let zero_texel = Frame {
            texel: 0.0,
            ..frame
        };
        let tile = plain(&square(&frame, 0.0, 8.0, |_, _| 1.0), &zero_texel, 0.1).unwrap();
        assert_eq!(tile.covered, 0);
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
        // The tilted, bumpy tile's samples fill much less than the box of its tile box (the two
        // may differ by the tight box's margin where a sample is extreme along a world axis).
        let tight = tile.surface_bounds();
        assert!(tight.area() < 0.9 * b.area(), "{tight:?} against {b:?}");
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
        assert_eq!(Vec3::from(r.axis_w), f.w);
    }

    /// A grid of `n × n` vertices spaced `spacing` over the xy plane at heights `h(i, j)`, two
    /// triangles per grid cell, wound to face +z.
    fn grid_mesh(n: usize, spacing: f32, h: impl Fn(usize, usize) -> f32) -> Vec<[Vec3; 3]> {
        let p = |i: usize, j: usize| Vec3::new(i as f32 * spacing, j as f32 * spacing, h(i, j));
        let mut tris = Vec::new();
        for j in 0..n - 1 {
            for i in 0..n - 1 {
                tris.push([p(i, j), p(i + 1, j), p(i + 1, j + 1)]);
                tris.push([p(i, j), p(i + 1, j + 1), p(i, j + 1)]);
            }
        }
        tris
    }

    /// Sub-texel noise (a checkerboard of 0.4-texel bumps on a quarter-texel mesh: its triangles
    /// slope 66° off the axis) fails the triangles' cone of 60° and their projected-area ratio of
    /// 0.9, but its samples (at texel centres, every fourth vertex, all at height 0) pass both; a ridge sloping 63°
    /// at texel scale fails both on its samples as well.
    #[test]
    fn the_sampled_surface_is_judged_at_the_sampling_rate() {
        let frame = xy_frame(8);
        let noisy = grid_mesh(33, 0.25, |i, j| if (i + j) % 2 == 1 { 0.4 } else { 0.0 });
        let ridge = grid_mesh(33, 0.25, |i, _| 2.0 * (i as f32 * 0.25 - 4.0).abs());
        let criteria = [
            Refinement::NormalCone {
                max_angle_deg: 60.0,
            },
            Refinement::ProjectedArea { min_ratio: 0.9 },
        ];
        for criterion in criteria {
            for tris in [&noisy, &ridge] {
                assert!(!super::super::frame::passes(
                    criterion,
                    &super::super::frame::triangle_elements(tris),
                    Vec3::Z
                ));
                assert!(plain(tris, &frame, 1.0).is_some());
            }
            let tile =
                rasterize(&noisy, &frame, 1.0, Some(criterion), None, &[]).expect("noise passes");
            assert_eq!(tile.covered, 64);
            assert!(
                rasterize(&ridge, &frame, 1.0, Some(criterion), None, &[]).is_none(),
                "{criterion:?}: the ridge passed"
            );
        }
        // At 70° the ridge's 63° passes on its samples.
        let wide = Refinement::NormalCone {
            max_angle_deg: 70.0,
        };
        assert!(rasterize(&ridge, &frame, 1.0, Some(wide), None, &[]).is_some());
    }

    /// A tile whose written samples form no cell (one sliver covering a single sample centre) has
    /// no sampled surface to judge, so it fails: the judgement never passes for want of cells.
    #[test]
    fn a_tile_without_cells_fails_the_sampled_judgement() {
        let frame = xy_frame(4);
        let sliver = vec![[
            Vec3::new(1.4, 1.4, 0.0),
            Vec3::new(1.6, 1.4, 0.0),
            Vec3::new(1.5, 1.7, 0.0),
        ]];
        let criterion = Refinement::NormalCone {
            max_angle_deg: 60.0,
        };
        assert_eq!(plain(&sliver, &frame, 1.0).unwrap().covered, 1);
        assert!(rasterize(&sliver, &frame, 1.0, Some(criterion), None, &[]).is_none());
    }
}
