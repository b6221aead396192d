//! Step 6 of rasterizing a leaf (see [`super`]): the **exposed triangles** (issue "No leaks
//! between height fields"), the leaf's triangles that its finished tile does not cover well
//! enough for a ray entering the solid through them to be sure to meet it, and the part of each
//! ([`Exposed::part`]) that the builder traces exactly beside the tile.

use glam::{DVec2, DVec3, Vec3};

use super::cells::{cell_range, cells_met};
use super::ring::RING_REACH;
use super::sample::unit_normal;
use super::{Frame, NONE};
use crate::geom::clip::{clip, clip_half};
use crate::geom::sat::convex_overlap;

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
///
/// Since a743f82 a triangle under a lid (a cell with an extrapolated corner) may lie this far
/// below it too where the leaf's criterion is the presets' or gentler (`lid_sink_texels`).
pub const CREST_TEXELS: f32 = 2.0;

/// How far below the surface of a cell with an extrapolated corner one of the leaf's triangles
/// may lie before it is traced exactly too, in texels, for a leaf whose criterion lets its
/// surface turn steeper than the presets' ([`lid_sink_texels`]): there the extrapolation has
/// made a lid over the leaf's own surface, and a ray coming in from the side under the lid
/// (where the skirt tapers to nothing, `layout::MARCH_SKIRT_TEXELS`) meets the triangle but none
/// of the leaf's cells. Half a texel took the dragon's seam leaks at A⊥/A 0.01 from 210 to 74 per
/// million for 9% more exact parts at Q0 than a texel; with the steep-cell rule
/// ([`STEEP_CELL_TEXELS`]), 0.3 texel from 32 to 16, 0.1 texel to 14. At [`CREST_TEXELS`] the
/// cone's seam leaks at A⊥/A 0.01 rose from 10 to 224 per million and the dragon's from 314 to
/// 737, two of them through it: at such criteria the lids keep theirs (docs/guarantees.md).
const EXPOSED_SINK_TEXELS: f32 = 0.3;

/// How far below an extrapolated lid one of the leaf's triangles may lie before it is traced
/// exactly too ([`exposed`]), in texels, for a leaf whose ring reaches `reach` texels
/// ([`ring_reach`](super::ring_reach): the slope its criterion allows; `None` without a ring):
/// [`CREST_TEXELS`] where the criterion keeps the slope within the ring's least reach
/// ([`RING_REACH`]: φ_max up to 63°, the presets' 60° among them), as under any other cell,
/// else [`EXPOSED_SINK_TEXELS`]. Under the presets the leaf's surface falls at most that steeply
/// from its ring, and below the sampling rate nearly every triangle of a scan by a rim lies a
/// few tenths of a texel under the lid somewhere: at 0.3 texel these were three quarters of the
/// paper-scale scene's exposed triangles at Q2 (300,786 of 393,251; its exact triangles 13.3 of
/// its 30.9 MB), at two texels its exact triangles take 5.2 MB, the tree 9.7, the whole 19.5;
/// t p99 at Q2 0.811 → 0.816% of the diagonal, seam leaks at the presets 23 → 33 of 21M rays on
/// the small scenes and scans, none through; at 5M rays a level 148 → 168 of 105M, and one
/// through a closed solid: a part thinner than the lid may hide (a critter's fin in `hall` at Q0)
/// vanishes under it. Keeping such triangles exact where the part is thinner than two texels
/// stopped that ray and doubled the paper-scale scene's exact triangles (docs/guarantees.md,
/// "Crests clipped by up to two texels").
pub(super) fn lid_sink_texels(reach: Option<f32>) -> f32 {
    match reach {
        Some(reach) if reach <= RING_REACH => CREST_TEXELS,
        _ => EXPOSED_SINK_TEXELS,
    }
}

/// How far apart in height the corners of a cell (holes aside) may lie before the cell counts as
/// *steep*, in texels ([`exposed`]): more than 71° on average along a side. There a height field
/// is a poor stand-in for the surface, which it meets nearly edge-on: one of the leaf's triangles
/// facing away from the axis over a steep cell is always traced exactly (an overhang's
/// underside, where the leaf's samples flip between the fold's sheets and a ray from below
/// slides under a pit of its surface). After the sink ([`EXPOSED_SINK_TEXELS`]) this took the
/// dragon's seam leaks at A⊥/A 0.01 from 16 to 9 per million (8% more exact parts there)
/// (docs/guarantees.md).
const STEEP_CELL_TEXELS: f32 = 3.0;

/// The `triangles` (by index, ascending) that the finished height field does not cover well
/// enough for a ray entering the solid through them to be sure to meet it, so that the builder
/// adds them to the tree as triangles, traced exactly (`build/leaf.rs`): those that meet
/// * the *bare* part of a cell, which no cell triangle covers
///   ([`cell_triangles`](crate::rbvh::layout::cell_triangles)): all of a cell with two holes or
///   more among its corners, or the half on a lone hole's side of the diagonal between its
///   neighbours. Edge-on triangles (a wall between two samples) count;
///   touching the bare part along an edge or at a point does not. After the ring and the open
///   boundary, these are cells over which the ring found no surface within its reach (a rim
///   seen nearly edge-on, a crease whose other sheet lies further), where rays aimed at the
///   seams passed between the leaves;
/// * a cell, rising more than [`CREST_TEXELS`] above its surface somewhere over it: the cell
///   cuts under a crest or a sheet its corners jump to or from, and a ray entering the solid
///   there passes over it (or, over an extrapolated corner, may leave the leaf over the rim
///   before it crosses the surface);
/// * a cell with an extrapolated corner (`sampled` false: the ring found no surface over it),
///   lying more than `lid_sink` texels below it ([`lid_sink_texels`]): the extrapolation is a
///   lid over the surface, which a ray from the side passes under;
/// * a cell of sampled corners (three or four), lying more than [`CREST_TEXELS`] below it: a
///   sheet under the leaf's surface, which a ray meets from below or from the side, not through
///   the cell over it;
/// * a steep cell, facing away from the axis: the underside of an overhang, whose sheet the
///   leaf's samples leave and rejoin, so that a ray from below slides under a pit of the
///   surface.
///
/// `height` and `source` as after step 4 (`NONE` a hole).
pub(super) fn exposed(
    triangles: &[[Vec3; 3]],
    frame: &Frame,
    height: &[f32],
    source: &[u32],
    sampled: &[bool],
    lid_sink: f32,
) -> Vec<Exposed> {
    exposed_in(triangles, frame, height, source, sampled, lid_sink, true)
}

/// [`exposed`], skipping with `prefilter` the triangles that a bound on their corners shows
/// need no test (without, the tests' oracle of that bound).
pub(super) fn exposed_in(
    triangles: &[[Vec3; 3]],
    frame: &Frame,
    height: &[f32],
    source: &[u32],
    sampled: &[bool],
    lid_sink: f32,
    prefilter: bool,
) -> Vec<Exposed> {
    let (res_u, res_v) = (frame.res_u as i64, frame.res_v as i64);
    let texel = frame.texel as f64;
    let crest = CREST_TEXELS as f64 * texel;
    let sink_extrapolated = lid_sink as f64 * texel;
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

#[cfg(test)]
mod tests {
    use super::super::rasterize;
    use super::super::tests::{plain, square, xy_frame};
    use super::*;
    use crate::rbvh::Refinement;

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
            inputs(exposed(
                &tris,
                &frame,
                &height,
                &source,
                &sampled,
                EXPOSED_SINK_TEXELS
            )),
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
        let found = exposed(
            &[long],
            &frame,
            &height,
            &source,
            &sampled,
            EXPOSED_SINK_TEXELS,
        );
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
    /// above the cell's surface, or lying more than the lid's sink below it (at the presets'
    /// criterion [`CREST_TEXELS`], at steeper ones [`EXPOSED_SINK_TEXELS`]), is exposed; one
    /// rising or sinking less is not, nor one lying as far below a cell of sampled corners.
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
        for reach in [
            super::super::ring_reach(Refinement::NormalCone {
                max_angle_deg: 89.5,
            }),
            RING_REACH,
        ] {
            let sink = lid_sink_texels(Some(reach));
            let exposed = |tris: &[[Vec3; 3]], sampled: &[bool]| {
                exposed(tris, &frame, &height, &source, sampled, sink)
            };
            // Under a steeper criterion's shallower lid, as far below sampled corners is fine.
            sampled[8] = true;
            assert_eq!(
                exposed(&over(-sink - 0.05), &sampled).is_empty(),
                sink < CREST_TEXELS
            );
            sampled[8] = false;
            let rise = CREST_TEXELS;
            assert_eq!(
                exposed(&over(rise + 0.05), &sampled),
                [Exposed {
                    input: 0,
                    cells: vec![[1, 1, 1, 1]],
                    bare: false,
                }]
            );
            assert!(exposed(&over(rise - 0.05), &sampled).is_empty());
            // A little below the surface it is hit from above through the cell; further below,
            // under an extrapolated lid, a ray from the side would miss the cell.
            assert!(exposed(&over(-sink + 0.05), &sampled).is_empty());
            assert_eq!(exposed(&over(-sink - 0.05), &sampled).len(), 1);
        }
    }

    /// A lid may hide the surface by [`CREST_TEXELS`] where the leaf's criterion keeps its slope
    /// within the ring's least reach (the presets), by [`EXPOSED_SINK_TEXELS`] where it lets the
    /// surface turn edge-on, or without a ring.
    #[test]
    fn the_lid_sinks_as_far_as_the_criterion_lets_the_surface_fall() {
        use super::super::ring_reach;
        let cone = |deg: f32| Some(ring_reach(Refinement::NormalCone { max_angle_deg: deg }));
        let area = |min_ratio: f32| Some(ring_reach(Refinement::ProjectedArea { min_ratio }));
        assert_eq!(lid_sink_texels(cone(60.0)), CREST_TEXELS);
        assert_eq!(lid_sink_texels(cone(0.5)), CREST_TEXELS);
        assert_eq!(lid_sink_texels(area(1.0)), CREST_TEXELS);
        assert_eq!(lid_sink_texels(cone(70.0)), EXPOSED_SINK_TEXELS);
        assert_eq!(lid_sink_texels(cone(89.5)), EXPOSED_SINK_TEXELS);
        assert_eq!(lid_sink_texels(area(0.01)), EXPOSED_SINK_TEXELS);
        assert_eq!(lid_sink_texels(None), EXPOSED_SINK_TEXELS);
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
        let exposed = |tris: &[[Vec3; 3]]| {
            exposed(
                tris,
                &frame,
                &height,
                &source,
                &sampled,
                EXPOSED_SINK_TEXELS,
            )
        };
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
        let three = |tris: &[[Vec3; 3]]| {
            super::exposed(tris, &frame, &height, &holed, &sampled, EXPOSED_SINK_TEXELS)
        };
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
        let exposed = |tris: &[[Vec3; 3]], height: &[f32]| {
            exposed(tris, &frame, height, &source, &sampled, EXPOSED_SINK_TEXELS)
        };
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
            let found = |prefilter| {
                let lid = EXPOSED_SINK_TEXELS;
                exposed_in(
                    &triangles, &frame, &height, &source, &sampled, lid, prefilter,
                )
            };
            let (with, without) = (found(true), found(false));
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
}
