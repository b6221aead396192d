//! Making leaves (Novák & Dachsbacher 2012: "rasterize surfaces into the atlas"): a set judged
//! one height field is rasterized (or its points splatted) into tiles of at most `max_tile`
//! samples a side, which overlap by a cell (the paper's "subdivide large height fields"); beside
//! them go the exact parts of its triangles that the tiles leave uncovered ([`Tile::exposed`]),
//! and the subtrees over tiles and parts. A set of points that stays unrepresentable is splatted
//! regardless (a forced leaf).

use glam::Vec3;

use super::{Builder, Input, Node, MAX_TRIANGLE_LEAF};
use crate::bvh::GpuTriangle;
use crate::geom::Aabb;
use crate::rbvh::frame::{
    fails_every_axis, fit, passes, projection_axis, rounding_pad, triangle_element,
    triangle_elements,
};
use crate::rbvh::raster::{rasterize, ring_reach, Frame, Ring, Tile, NO_SOURCE};
use crate::rbvh::splat::{splat, Splat};

/// How many times its surface in texels a set's frame may hold in samples (beside sixteen tiles
/// for the rims, `Builder::frame_samples`) and still be rasterized as one height field. Far
/// beyond any tile of a connected surface turned to its tightest rectangle; the structures of
/// the built-in and benchmark scenes are the same with and without the bound.
const FRAME_SURFACE_FACTOR: f64 = 64.0;

impl Builder<'_> {
    /// The subtree of the set `order` made one height field of `tiles`: the tiles, and beside
    /// them, when they leave some of the set's triangles uncovered ([`Tile::exposed`]: over a
    /// cell the ring found no surface for, or rising above or sinking under a cell's surface
    /// beyond what it stands in for), those triangles' parts there as triangle leaves,
    /// traced exactly, so that a ray entering the solid through them meets them where the
    /// height field, and its neighbours', may leave a gap.
    pub(super) fn surface_subtree(
        &self,
        tiles: Vec<Tile>,
        pieces: Vec<GpuTriangle>,
        order: &[u32],
    ) -> Node {
        let surface = tiles_subtree(self.scene_sources(tiles, order));
        if pieces.is_empty() {
            return surface;
        }
        Node::Surface(Box::new([
            surface,
            pieces_subtree(pieces, MAX_TRIANGLE_LEAF),
        ]))
    }

    /// The exact parts of the set `order`'s triangles beside its `tiles` (see
    /// [`Builder::surface_subtree`]), each naming its tile.
    pub(super) fn parts(&self, tiles: &[Tile], order: &[u32]) -> Vec<GpuTriangle> {
        match self.input {
            Input::Triangles(all) => tiles
                .iter()
                .enumerate()
                .flat_map(|(k, tile)| {
                    tile.exposed.iter().flat_map(move |e| {
                        let prim = order[e.input as usize];
                        e.part(&tile.frame, &all[prim as usize])
                            .into_iter()
                            .map(move |t| GpuTriangle {
                                flags: GpuTriangle::part_flags(k as u32, e.bare),
                                ..GpuTriangle::new(t, prim)
                            })
                    })
                })
                .collect(),
            Input::Points(_) => Vec::new(),
        }
    }

    /// The forced leaf of the points `order` (see [`Builder::forced_heightfield`]).
    pub(super) fn forced(&self, points: &[Splat], order: &[u32], offset: u32, texel: f32) -> Node {
        self.progress.advance(order.len() as u64);
        let tiles = self.forced_heightfield(points, order, texel);
        if tiles.is_empty() {
            // Unreachable for finite points (each marks the sample nearest to it); an empty
            // leaf keeps the tree whole if it were not.
            return Node::Triangles {
                start: offset,
                count: 0,
            };
        }
        tiles_subtree(self.scene_sources(tiles, order))
    }

    /// `tiles` of the set `order` with their sources turned from indices into the set to scene
    /// triangle or point indices, or dropped when no colour channel needs them.
    fn scene_sources(&self, mut tiles: Vec<Tile>, order: &[u32]) -> Vec<Tile> {
        for tile in &mut tiles {
            tile.sources = if self.keep_sources {
                let scene_index = |s: u32| order.get(s as usize).copied();
                tile.sources
                    .iter()
                    .map(|&s| scene_index(s).unwrap_or(NO_SOURCE))
                    .collect()
            } else {
                Vec::new()
            };
        }
        tiles
    }

    /// The tiles of the set `order` (whose box diagonal is `diagonal`) as one height field of
    /// texels `texel` wide, or None when it is not representable.
    pub(super) fn heightfield(
        &self,
        order: &[u32],
        diagonal: f32,
        texel: f32,
    ) -> Option<Vec<Tile>> {
        match self.input {
            Input::Triangles(all) => {
                // A set that fails the criterion whatever its axis, and is too large to be judged
                // on its samples, is refused before it is gathered.
                if diagonal > self.params.sampled_criterion_texels * texel
                    && fails_every_axis(
                        self.params.refinement,
                        order.iter().map(|&i| triangle_element(&all[i as usize])),
                    )
                {
                    return None;
                }
                let tris: Vec<[Vec3; 3]> = order.iter().map(|&i| all[i as usize]).collect();
                let open: Vec<bool> = if self.open.is_empty() {
                    Vec::new()
                } else {
                    order.iter().map(|&i| self.open[i as usize]).collect()
                };
                let elements = triangle_elements(&tris);
                let (frame, judge) =
                    self.judged_frame(&elements, tris.as_flattened(), 0.0, diagonal, texel)?;
                let ring = self.surface.map(|surface| Ring {
                    surface,
                    reach: ring_reach(self.params.refinement),
                });
                // Layers closer than a texel are one surface at this sampling rate.
                self.tiles(&frame, |window| {
                    rasterize(&tris, window, texel, judge, ring, &open)
                })
            }
            Input::Points(all) => {
                let (points, positions, reach) = gather(all, order);
                let elements = point_elements(&points);
                let (frame, judge) =
                    self.judged_frame(&elements, &positions, reach, diagonal, texel)?;
                self.tiles(&frame, |window| splat(&points, window, texel, judge, false))
            }
        }
    }

    /// The frame of a set of surface `elements` (see `frame::triangle_elements`) with corner or
    /// point `positions` reaching `margin` beyond them, and the criterion its samples must pass
    /// (None: its elements passed already); None when it is not representable as one height field
    /// at any sampling: no projection axis, or failing the criterion while larger than
    /// `sampled_criterion_texels`, or a frame of samples out of proportion to its surface
    /// (`Builder::frame_samples`).
    fn judged_frame(
        &self,
        elements: &[Vec3],
        positions: &[Vec3],
        margin: f32,
        diagonal: f32,
        texel: f32,
    ) -> Option<(Frame, Option<crate::rbvh::Refinement>)> {
        let w = projection_axis(elements)?;
        let elements_pass = passes(self.params.refinement, elements, w);
        if !elements_pass && diagonal > self.params.sampled_criterion_texels * texel {
            return None;
        }
        // Elements that fail the criterion get a second hearing on their surface as sampled.
        let judge = (!elements_pass).then_some(self.params.refinement);
        // A set of little surface spread far (a degenerate triangle's long segment, rasterized
        // at its neighbours' fine texel) would ask samples out of all proportion to its surface:
        // not a height field at this rate (found by fuzzing: a 5.9e17-unit segment at 6.5 units
        // a texel asked 4 GiB of windows).
        let frame = fit(positions, w, texel, margin);
        let samples = u64::from(frame.res_u) * u64::from(frame.res_v);
        (samples as f64 <= self.frame_samples(elements, texel)).then_some((frame, judge))
    }

    /// The most samples the frame of a set of surface `elements` may have at `texel`:
    /// [`FRAME_SURFACE_FACTOR`] times its surface in texels (the elements' lengths are twice a
    /// triangle's area, a point's area), at most four times the whole build's estimated texels
    /// (a coarse object's large surface in a set rasterized at a small neighbour's fine texel),
    /// and sixteen tiles of `max_tile` samples a side for the rims of small sets.
    fn frame_samples(&self, elements: &[Vec3], texel: f32) -> f64 {
        // An element whose float32 cross product overflowed counts for nothing.
        let surface: f64 = elements
            .iter()
            .map(|e| e.as_dvec3().length())
            .filter(|a| a.is_finite())
            .sum();
        let texel = f64::from(texel);
        (FRAME_SURFACE_FACTOR * surface / (texel * texel)).min(4.0 * self.estimate)
            + 16.0 * f64::from(self.params.max_tile).powi(2)
    }

    /// The covered tiles of `frame`'s windows (at most `max_tile` samples a side), each sampled
    /// by `sample`; None when any window is not a height field, or none is covered.
    fn tiles(&self, frame: &Frame, sample: impl Fn(&Frame) -> Option<Tile>) -> Option<Vec<Tile>> {
        let mut tiles = Vec::new();
        for window in windows(frame, self.params.max_tile) {
            let tile = sample(&window)?;
            if tile.covered > 0 {
                tiles.push(tile);
            }
        }
        (!tiles.is_empty()).then_some(tiles)
    }

    /// A forced leaf of the points `order` (see `splat.rs`): splatted along their area-weighted
    /// normal (or the first point's, when their normals cancel), the nearest point winning where
    /// they overlap.
    fn forced_heightfield(&self, all: &[Splat], order: &[u32], texel: f32) -> Vec<Tile> {
        let (points, positions, reach) = gather(all, order);
        let w = projection_axis(&point_elements(&points))
            .or_else(|| points.first().map(|p| p.normal))
            .unwrap_or(Vec3::Z);
        let frame = fit(&positions, w, texel, reach);
        self.tiles(&frame, |window| splat(&points, window, texel, None, true))
            .unwrap_or_default()
    }
}

/// A balanced subtree over `nodes` (at least one), in their order.
pub(super) fn balanced(mut nodes: Vec<Node>) -> Node {
    if nodes.len() == 1 {
        return nodes.pop().expect("one node");
    }
    let right = nodes.split_off(nodes.len() / 2);
    Node::Inner(Box::new([balanced(nodes), balanced(right)]))
}

/// The points `order` of `all`, their positions, and the farthest any of their splats reaches.
fn gather(all: &[Splat], order: &[u32]) -> (Vec<Splat>, Vec<Vec3>, f32) {
    let points: Vec<Splat> = order.iter().map(|&i| all[i as usize]).collect();
    let positions = points.iter().map(|p| p.position).collect();
    let reach = points.iter().map(Splat::reach).fold(0.0, f32::max);
    (points, positions, reach)
}

/// The surface elements of points (see `frame::triangle_elements`): each normal times the area
/// its spacing stands for.
fn point_elements(points: &[Splat]) -> Vec<Vec3> {
    points
        .iter()
        .map(|p| p.normal * (p.spacing * p.spacing))
        .collect()
}

/// Cuts `frame` into windows of at most `max` samples per side. Neighbouring windows overlap by
/// one cell (window k starts at sample k·(max − 2)): each window's origin is rounded to f32 on its
/// own, so samples that two windows would share in exact arithmetic lie up to an ulp apart, and a
/// ray aimed exactly at a seam of shared samples could slip between the two tiles. Far from the
/// world origin, where rounding moves grids by a noticeable part of a texel, the overlap grows
/// by [`rounding_pad`] cells (at most `(max − 2) / 2`).
fn windows(frame: &Frame, max: u32) -> Vec<Frame> {
    let reach =
        frame.origin.abs().max_element() + (frame.res_u as f32 + frame.res_v as f32) * frame.texel;
    let overlap = rounding_pad(2.0 * reach, frame.texel)
        .max(1)
        .min((max - 2) / 2);
    let starts = |res: u32| -> Vec<(u32, u32)> {
        if res <= max {
            return vec![(0, res)];
        }
        let step = max - 1 - overlap;
        let mut out = Vec::new();
        let mut s = 0;
        loop {
            let n = max.min(res - s);
            out.push((s, n));
            if s + n >= res {
                break;
            }
            s += step;
        }
        out
    };
    let mut out = Vec::new();
    for &(sv, nv) in &starts(frame.res_v) {
        for &(su, nu) in &starts(frame.res_u) {
            out.push(Frame {
                origin: (frame.origin.as_dvec3()
                    + (su as f64 * frame.texel as f64) * frame.u.as_dvec3()
                    + (sv as f64 * frame.texel as f64) * frame.v.as_dvec3())
                .as_vec3(),
                res_u: nu,
                res_v: nv,
                ..*frame
            });
        }
    }
    out
}

/// A balanced subtree over the tiles of one subdivided height field (in window order, so halves
/// are spatially coherent).
fn tiles_subtree(tiles: Vec<Tile>) -> Node {
    balanced(
        tiles
            .into_iter()
            .map(|tile| Node::Heightfield(Box::new(tile)))
            .collect(),
    )
}

/// A subtree of [`Node::Pieces`] leaves over `pieces`: halved at the median of their centroids
/// along the longest side of the centroids' box until a leaf holds at most `max_leaf` pieces
/// lying together, its box at most twice as long as its longest piece's. Exact parts take
/// [`MAX_TRIANGLE_LEAF`]; triangles traced exactly for their size one each, since their long
/// boxes overlap, and rays entering a leaf of eight of them tested most for nothing (28
/// triangles per primary ray on the paper-scale scene at Q2, against the exact BVH's 5.3); the
/// tree built again over the leaves groups them where its SAH finds that cheaper
/// (`flatten::upper_tree`).
/// Pieces from places apart in one leaf (two rims of one surface) would give it a box
/// that rays between them enter for nothing: on the default scene at Q2–Q4, 0.11–0.14
/// triangles tested per primary ray instead of 0.00–0.01. Ties keep their order (a stable
/// sort), so it is deterministic.
pub(super) fn pieces_subtree(mut pieces: Vec<GpuTriangle>, max_leaf: usize) -> Node {
    let bounds = |t: &GpuTriangle| Aabb::from_points(t.vertices());
    let union = pieces.iter().fold(Aabb::EMPTY, |b, t| b.union(bounds(t)));
    let longest = pieces
        .iter()
        .map(|t| bounds(t).extent().max_element())
        .fold(0.0, f32::max);
    let together = union.extent().max_element() <= 2.0 * longest;
    if pieces.len() == 1 || (pieces.len() <= max_leaf && together) {
        return Node::Pieces(pieces);
    }
    let centroid = |t: &GpuTriangle| t.vertices().into_iter().sum::<Vec3>();
    let axis = pieces
        .iter()
        .fold(Aabb::EMPTY, |b, t| b.grow(centroid(t)))
        .largest_axis();
    pieces.sort_by(|a, b| centroid(a)[axis].total_cmp(&centroid(b)[axis]));
    let right = pieces.split_off(pieces.len() / 2);
    Node::Inner(Box::new([
        pieces_subtree(pieces, max_leaf),
        pieces_subtree(right, max_leaf),
    ]))
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use crate::rbvh::{Rbvh, RbvhParams};
    use crate::scene::Scene;

    /// Whether `point` lies over `leaf`'s tile or the ring of cells around it, where its exact
    /// parts are cut (a cell and a half past its outer samples).
    fn over_tile(leaf: &crate::rbvh::GpuHeightfield, point: Vec3) -> bool {
        let f = leaf.to_frame(point);
        let (lo, hi) = (-1.5, [leaf.res_u as f32 + 1.5, leaf.res_v as f32 + 1.5]);
        f.x >= lo && f.y >= lo && f.x <= hi[0] && f.y <= hi[1]
    }

    /// Preset `level` with every triangle sampled: the parts these tests check stand beside the
    /// default scene's cube and cone, which the presets trace exactly.
    fn sampled(level: u32) -> RbvhParams {
        RbvhParams {
            exact_when_cheaper: false,
            ..RbvhParams::quality(level).unwrap()
        }
    }

    /// Every exact part names the height-field leaf it stands beside: it lies over that leaf's
    /// tile (the cells it was cut to and their ring), and no other leaf's index is named.
    #[test]
    fn exact_parts_name_the_leaf_they_stand_beside() {
        let scene = Scene::builtin("default").unwrap();
        let r = Rbvh::build(&scene, &sampled(2)).unwrap();
        let mut parts = 0;
        for t in r.triangles.iter() {
            let Some(leaf) = t.part_leaf() else { continue };
            parts += 1;
            let leaf = r.heightfields[leaf as usize];
            for q in t.vertices() {
                assert!(over_tile(&leaf, q), "{q} beside {leaf:?}");
            }
        }
        assert!(parts > 50, "{parts} parts");
    }

    /// A hit on an exact part lands on the leaf it stands beside, also where its scene triangle
    /// left parts beside several leaves (a triangle crossing tiles of one surface), not on the
    /// first leaf found for that triangle. The default scene has such at Q4s with leaves seen
    /// nearly edge-on (φ_max 89.5°), whose lids keep the strict sink
    /// (`raster::exposed::lid_sink_texels`); at the presets' criterion it has none.
    #[test]
    fn a_hit_on_an_exact_part_lands_on_its_own_leaf() {
        let scene = Scene::builtin("default").unwrap();
        let params = RbvhParams {
            refinement: crate::rbvh::Refinement::NormalCone {
                max_angle_deg: 89.5,
            },
            ..sampled(4)
        };
        let r = Rbvh::build(&scene, &params).unwrap();
        let shared = r.part_leaves().values().filter(|l| l.len() > 1).count();
        assert!(shared > 0, "no triangle with parts beside several leaves");
        hits_on_parts_land_on_their_leaves(&r);
    }

    /// Every exact part of `r`, hit straight on at its centre, lands on the leaf it stands beside.
    fn hits_on_parts_land_on_their_leaves(r: &Rbvh) {
        use crate::geom::{Hit, Ray};
        for t in r.triangles.iter().filter(|t| t.part_leaf().is_some()) {
            let [a, b, c] = t.vertices();
            let centre = (a + b + c) / 3.0;
            let ray = Ray::new(centre + t.normal(), -t.normal(), 0.0, f32::INFINITY);
            let hit = Hit {
                t: 1.0,
                normal: t.normal().to_array(),
                id: t.prim,
                instance: 0,
                reserved: [0; 2],
            };
            let loc = r.locate(&ray, &hit).expect("a part's hit has a texel");
            assert!(
                over_tile(&r.heightfields[loc.leaf as usize], centre),
                "part of {} at {centre}: leaf {}",
                t.prim,
                loc.leaf
            );
        }
    }
}
