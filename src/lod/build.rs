//! Building the coarse representations: every inner node's columns are filled by *splatting* the
//! surface samples of its subtree — the height-field samples of its height-field leaves and points
//! spread over its triangle-leaf triangles — into the column grid over the node's box.
//!
//! A sample covers a square patch about one fine texel wide, so it is splatted into every column
//! its patch overlaps; since columns are at least two fine texels wide, a surface crossing a
//! column leaves samples in it and the coarse level has no pinholes. A column keeps the lowest and
//! highest sample along the grid's axis (with their colours, where the RBVH has a colour channel)
//! and is solid in between. Its top takes the mean normal of the samples facing up the axis, its
//! bottom that of those facing down — the surface a ray sees from either side, averaged as normal
//! maps are when mip-mapped — so that a coarse blob is shaded as round as the fine one is
//! (measured on `grove-aerial` with 8 columns at bias 0: the extreme samples' normals gave an
//! 18.0° mean normal error against exact, the mean normals 16.2°).

use std::time::Instant;

use glam::Vec3;
use rayon::prelude::*;

use super::layout::{Column, GpuLod, LOD_BIT};
use super::{Lod, LodParams, LodStats};
use crate::bvh::GpuTriangle;
use crate::geom::Aabb;
use crate::rbvh::layout::{decode_octahedral, encode_octahedral};
use crate::rbvh::Child;
use crate::rbvh::{Rbvh, Texel};
use crate::{Error, Result};

/// Most points spread along a triangle edge; bounds the work of a huge triangle in a triangle
/// leaf (its samples are then sparser than a texel, which coarse columns tolerate).
const MAX_TRIANGLE_DIVISIONS: u32 = 1024;

/// Most surface samples a build may gather (about 1.5 GB): the samples of all leaves are held at
/// once, so a hand-made RBVH file with huge triangle leaves must not ask for unbounded memory.
const MAX_SAMPLES: u64 = 1 << 26;

/// Half the side of the patch a sample stands for, in fine texels. Height-field samples are one
/// texel apart in their leaf's plane, which is tilted against the column grid, so the patch is
/// taken a little larger than half a texel.
const SPLAT_RADIUS: f32 = 0.75;

/// One node's record, its column words and their colour words (parallel to the words).
type Coarse = (GpuLod, Vec<u32>, Vec<u32>);

/// A surface point and its 8:8 octahedral normal.
#[derive(Clone, Copy)]
struct Sample {
    p: Vec3,
    normal: u16,
    /// The RBVH's colour word at the sample (RGBA8; 0 where it has none: triangle leaves, or an
    /// RBVH without a colour channel).
    colour: u32,
}

impl Lod {
    /// Builds the coarse representation of every inner node of `rbvh` (see the module docs).
    pub fn build(rbvh: &Rbvh, params: &LodParams) -> Result<Lod> {
        params.validate()?;
        super::no_height_only(rbvh)?;
        let start = Instant::now();
        let fine = rbvh.texel_size;
        if !(fine.is_finite() && fine > 0.0) {
            return Err(Error::param(
                "rbvh",
                format!("texel size {fine} must be finite and positive to build levels of detail"),
            ));
        }
        if rbvh.nodes.len() >= LOD_BIT as usize {
            return Err(Error::param(
                "rbvh",
                format!(
                    "{} nodes; levels of detail need fewer than {LOD_BIT}",
                    rbvh.nodes.len()
                ),
            ));
        }
        let order = subtree_order(rbvh);
        let estimate: u64 = order.sources.iter().map(|s| s.sample_count(rbvh)).sum();
        if estimate > MAX_SAMPLES {
            return Err(Error::param(
                "rbvh",
                format!(
                    "its leaves would give {estimate} surface samples to build levels of detail \
                     from (at most {MAX_SAMPLES}); use fewer texels per diagonal"
                ),
            ));
        }
        let sources: Vec<Vec<Sample>> = order.sources.par_iter().map(|s| s.samples(rbvh)).collect();
        let records: Vec<Coarse> = (0..rbvh.nodes.len())
            .into_par_iter()
            .map(|n| match order.span[n] {
                // The root is never a child, so no ray could choose its grid.
                Some((bounds, range))
                    if n > 0 && range.1 - range.0 >= params.min_leaves as usize =>
                {
                    coarse_node(&bounds, &sources[range.0..range.1], fine, params.columns)
                }
                _ => (GpuLod::NONE, Vec::new(), Vec::new()),
            })
            .collect();
        let mut nodes = Vec::with_capacity(records.len());
        let mut texels = Vec::new();
        let mut stats = LodStats::default();
        let mut colours = Vec::new();
        for (mut record, words, column_colours) in records {
            if record.is_some() {
                record.base = u32::try_from(texels.len()).map_err(|_| {
                    Error::param("lod", "more than 2^32 column words; use fewer columns")
                })?;
                stats.coarse_nodes += 1;
                stats.columns += u64::from(record.res_u) * u64::from(record.res_v);
            }
            texels.extend(words);
            colours.extend(column_colours);
            nodes.push(record);
        }
        stats.build_ms = start.elapsed().as_secs_f64() * 1e3;
        Ok(Lod {
            params: *params,
            nodes,
            texels,
            colours: rbvh.colours.is_some().then_some(colours),
            stats,
        })
    }
}

/// Where a node's subtree lies: its box, and the range of [`SubtreeOrder::sources`] below it.
type Span = Option<(Aabb, (usize, usize))>;

/// The leaves of the tree in depth-first order, so that every node's subtree is one contiguous
/// range of them.
struct SubtreeOrder {
    sources: Vec<Source>,
    span: Vec<Span>,
}

/// A leaf whose surface is splatted.
#[derive(Clone, Copy)]
enum Source {
    Heightfield(u32),
    Triangles { first: u32, count: u32 },
}

/// Walks the tree depth first from the root. Every node is entered at most once (a corrupt tree
/// with shared or cyclic children is cut there), so the walk is bounded by the node count.
fn subtree_order(rbvh: &Rbvh) -> SubtreeOrder {
    let n = rbvh.nodes.len();
    let mut span: Vec<Span> = vec![None; n];
    let mut sources = Vec::new();
    let mut entered = vec![false; n];
    if n == 0 {
        return SubtreeOrder { sources, span };
    }
    // (node, its box, first source) on the way down; the node's span closes on the way up.
    enum Step {
        Enter(u32, Aabb),
        Leave(u32, Aabb, usize),
    }
    let mut stack = vec![Step::Enter(0, rbvh.bounds)];
    while let Some(step) = stack.pop() {
        match step {
            Step::Leave(node, bounds, first) => {
                span[node as usize] = Some((bounds, (first, sources.len())));
            }
            Step::Enter(node, bounds) => {
                let Some(gpu) = rbvh.nodes.get(node as usize) else {
                    continue;
                };
                if std::mem::replace(&mut entered[node as usize], true) {
                    continue;
                }
                stack.push(Step::Leave(node, bounds, sources.len()));
                for c in gpu.children().iter().rev() {
                    match c.kind() {
                        Child::Inner(child) => stack.push(Step::Enter(child, c.bounds)),
                        Child::Heightfield(index) => sources.push(Source::Heightfield(index)),
                        Child::Triangles { first, count } => {
                            sources.push(Source::Triangles { first, count })
                        }
                        Child::Absent => {}
                    }
                }
            }
        }
    }
    SubtreeOrder { sources, span }
}

/// The width of `columns` columns across `side`, made a hair wider so that `side` spans at most
/// `columns` of them despite rounding, and at least two `fine` texels.
fn column_width(side: f32, fine: f32, columns: u32) -> f32 {
    (side / columns as f32 * (1.0 + 1e-6)).max(2.0 * fine)
}

impl Source {
    /// At most how many samples [`Source::samples`] gives, without making them.
    fn sample_count(&self, rbvh: &Rbvh) -> u64 {
        match *self {
            Source::Heightfield(leaf) => rbvh
                .heightfields
                .get(leaf as usize)
                .map_or(0, |hf| u64::from(hf.res_u) * u64::from(hf.res_v)),
            Source::Triangles { first, count } => leaf_triangles(rbvh, first, count)
                .map(|t| {
                    let d = u64::from(divisions(t.vertices(), rbvh.texel_size));
                    (d + 1) * (d + 2) / 2
                })
                .sum(),
        }
    }

    /// The leaf's surface samples: every sample of a height field (holes excepted) at its world
    /// position, or points spread over each triangle no further apart than a fine texel (but
    /// for exact parts, [`GpuTriangle::PART`], whose height field stands for them; not those
    /// over its bare cells).
    fn samples(&self, rbvh: &Rbvh) -> Vec<Sample> {
        match *self {
            Source::Heightfield(leaf) => heightfield_samples(rbvh, leaf),
            Source::Triangles { first, count } => leaf_triangles(rbvh, first, count)
                .flat_map(|t| triangle_samples(t.vertices(), rbvh.texel_size))
                .collect(),
        }
    }
}

/// The triangles of a triangle leaf that its grids sample, cut to the array (corrupt ranges give
/// fewer or none): all but the exact parts ([`GpuTriangle::PART`]) that do not stand in for bare
/// cells ([`GpuTriangle::BARE`]).
fn leaf_triangles(rbvh: &Rbvh, first: u32, count: u32) -> impl Iterator<Item = &GpuTriangle> {
    let first = first as usize;
    let end = first
        .saturating_add(count as usize)
        .min(rbvh.triangles.len());
    let all = rbvh
        .triangles
        .gathered()
        .get(first..end)
        .unwrap_or_default();
    all.iter()
        .filter(|t| t.flags & GpuTriangle::PART == 0 || t.flags & GpuTriangle::BARE != 0)
}

fn heightfield_samples(rbvh: &Rbvh, leaf: u32) -> Vec<Sample> {
    let Some(hf) = rbvh.heightfields.get(leaf as usize) else {
        return Vec::new();
    };
    let grid = hf.grid();
    let pitch = rbvh.atlas.pitch as usize;
    let mut out = Vec::new();
    for j in 0..hf.res_v {
        for i in 0..hf.res_u {
            let index = hf.atlas_base as usize + j as usize * pitch + i as usize;
            let Some(&texel) = rbvh.atlas.texels.get(index) else {
                continue;
            };
            if texel.is_hole() {
                continue;
            }
            let p = grid.point(i, j, texel.height_code());
            if p.is_finite() {
                out.push(Sample {
                    p,
                    normal: (texel.0 >> 16) as u16,
                    colour: rbvh
                        .colours
                        .as_ref()
                        .and_then(|c| c.get(index))
                        .copied()
                        .unwrap_or(0),
                });
            }
        }
    }
    out
}

/// Divisions of a triangle's edges so that its samples lie no further apart than `spacing`.
fn divisions([a, b, c]: [Vec3; 3], spacing: f32) -> u32 {
    let longest = (b - a).length().max((c - b).length()).max((a - c).length());
    ((longest / spacing).ceil() as u32).clamp(1, MAX_TRIANGLE_DIVISIONS)
}

fn triangle_samples([a, b, c]: [Vec3; 3], spacing: f32) -> Vec<Sample> {
    let unit = crate::geom::unit_normal(a, b, c);
    let normal =
        crate::rbvh::layout::encode_octahedral(if unit == Vec3::ZERO { Vec3::Z } else { unit });
    let divisions = divisions([a, b, c], spacing);
    let mut out = Vec::new();
    for i in 0..=divisions {
        for j in 0..=divisions - i {
            let (s, t) = (i as f32 / divisions as f32, j as f32 / divisions as f32);
            let p = a + s * (b - a) + t * (c - a);
            if p.is_finite() {
                out.push(Sample {
                    p,
                    normal,
                    colour: 0,
                });
            }
        }
    }
    out
}

/// The column record of one node over `bounds` and its packed column words, or
/// [`GpuLod::NONE`] when its subtree has no surface.
///
/// The grid spans the node's box in `columns` columns along its longer side: every node is
/// drawn at the same number of columns across, so a node is chosen once the ray sees it at most
/// `columns · 2^bias` footprints wide, whatever the depth of the subtree below it (a pyramid over
/// the tree depth, doubling per level, made whole objects far too blocky to ever be chosen).
/// Columns are at least two fine texels wide, so that a surface crossing a column leaves samples
/// in it.
fn coarse_node(bounds: &Aabb, sources: &[Vec<Sample>], fine: f32, columns: u32) -> Coarse {
    if bounds.is_empty() || sources.iter().all(Vec::is_empty) {
        return (GpuLod::NONE, Vec::new(), Vec::new());
    }
    let extent = bounds.extent();
    let w = if extent.x <= extent.y && extent.x <= extent.z {
        0
    } else if extent.y <= extent.z {
        1
    } else {
        2
    };
    let (u, v) = ((w + 1) % 3, (w + 2) % 3);
    let texel_size = column_width(extent[u].max(extent[v]), fine, columns);
    if !(texel_size.is_finite() && texel_size > 0.0) {
        return (GpuLod::NONE, Vec::new(), Vec::new());
    }
    let res = |axis: usize| ((extent[axis] / texel_size).ceil() as u32).clamp(1, columns);
    let (res_u, res_v) = (res(u), res(v));
    let origin = bounds.min;
    let radius = SPLAT_RADIUS * fine;
    // Per column: (lowest height, its sample, highest height, its sample).
    let none = Sample {
        p: Vec3::ZERO,
        normal: 0,
        colour: 0,
    };
    let mut acc = vec![(f32::INFINITY, none, f32::NEG_INFINITY, none); (res_u * res_v) as usize];
    // Per column: the sums of the normals facing up and down the grid's axis.
    let mut facing = vec![(Vec3::ZERO, Vec3::ZERO); acc.len()];
    let cell = |x: f32, res: u32| ((x / texel_size).floor().max(0.0) as u32).min(res - 1);
    for s in sources.iter().flatten() {
        let rel = s.p - origin;
        let (i0, i1) = (cell(rel[u] - radius, res_u), cell(rel[u] + radius, res_u));
        let (j0, j1) = (cell(rel[v] - radius, res_v), cell(rel[v] + radius, res_v));
        let h = rel[w];
        let n = decode_octahedral(s.normal);
        for j in j0..=j1 {
            for i in i0..=i1 {
                let c = (j * res_u + i) as usize;
                let f = &mut facing[c];
                if n[w] >= 0.0 {
                    f.0 += n;
                } else {
                    f.1 += n;
                }
                let a = &mut acc[c];
                if h < a.0 {
                    (a.0, a.1) = (h, *s);
                }
                if h > a.2 {
                    (a.2, a.3) = (h, *s);
                }
            }
        }
    }
    let h_scale = extent[w] / f32::from(Texel::MAX_CODE);
    let code = |h: f32, up: bool| -> u16 {
        if h_scale > 0.0 {
            let q = h / h_scale;
            let q = if up { q.ceil() } else { q.floor() };
            q.clamp(0.0, f32::from(Texel::MAX_CODE)) as u16
        } else {
            0
        }
    };
    let mut words = Vec::with_capacity(acc.len() * 2);
    let mut colours = Vec::with_capacity(acc.len() * 2);
    let mean = |sum: Vec3, fallback: u16| match sum.try_normalize() {
        Some(n) => encode_octahedral(n),
        None => fallback,
    };
    for (&(lo, bottom, hi, top), &(up, down)) in acc.iter().zip(&facing) {
        let column = if lo <= hi {
            Column {
                top: Texel(u32::from(code(hi, true)) | u32::from(mean(up, top.normal)) << 16),
                bottom: Texel(
                    u32::from(code(lo, false)) | u32::from(mean(down, bottom.normal)) << 16,
                ),
            }
        } else {
            Column::EMPTY
        };
        words.extend([column.top.0, column.bottom.0]);
        colours.extend([top.colour, bottom.colour]);
    }
    let record = GpuLod {
        origin: origin.to_array(),
        texel_size,
        axis: w as u32,
        res_u,
        res_v,
        base: 0,
        h_scale,
        inv_texel: 1.0 / texel_size,
        pad: [0; 2],
    };
    (record, words, colours)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rbvh::{ExactTriangles, RbvhParams};
    use crate::scene::Scene;

    /// Leaves below a node, counted by walking the tree: all of them, and those that give its
    /// grid samples (height fields, and triangle leaves holding more than exact parts).
    fn leaves_below(rbvh: &Rbvh, node: u32) -> (usize, usize) {
        rbvh.nodes[node as usize]
            .children()
            .iter()
            .map(|c| match c.kind() {
                Child::Inner(child) => leaves_below(rbvh, child),
                Child::Absent => (0, 0),
                Child::Heightfield(_) => (1, 1),
                Child::Triangles { first, count } => {
                    let surface = leaf_triangles(rbvh, first, count).next().is_some();
                    (1, usize::from(surface))
                }
            })
            .fold((0, 0), |(a, b), (c, d)| (a + c, b + d))
    }

    /// The default scene's exact parts, but for those over bare cells, give its grids no
    /// samples: with them flagged as ordinary triangles, the same grids hold more column words.
    /// At A⊥/A 0.01, whose leaves turn edge-on and leave thousands of parts not over bare cells
    /// (at the presets, a crest may be clipped by two texels and few are left).
    #[test]
    fn exact_parts_give_no_samples() {
        let mut rbvh = Rbvh::build(
            &Scene::builtin("default").unwrap(),
            &RbvhParams {
                refinement: crate::rbvh::Refinement::ProjectedArea { min_ratio: 0.01 },
                ..RbvhParams::quality(2).unwrap()
            },
        )
        .unwrap();
        let parts = rbvh.triangles.iter().filter(|t| t.part_leaf().is_some());
        assert!(parts.filter(|t| t.flags & GpuTriangle::BARE == 0).count() > 1000);
        let params = LodParams::default();
        let with_parts_left_out = Lod::build(&rbvh, &params).unwrap();
        let unflagged = rbvh
            .triangles
            .iter()
            .map(|&t| GpuTriangle { flags: 0, ..t });
        rbvh.triangles = ExactTriangles::new(unflagged.collect());
        let with_parts = Lod::build(&rbvh, &params).unwrap();
        let words = |lod: &Lod| lod.texels.len();
        assert!(words(&with_parts_left_out) < words(&with_parts));
    }

    #[test]
    fn every_grid_spans_its_node_in_at_most_columns_columns_of_at_least_two_texels() {
        let rbvh = Rbvh::build(
            &Scene::builtin("default").unwrap(),
            &RbvhParams::quality(3).unwrap(),
        )
        .unwrap();
        let fine = rbvh.texel_size;
        for params in [
            LodParams::default(),
            LodParams {
                columns: 3,
                min_leaves: 1,
                bias: 0.0,
            },
        ] {
            let lod = Lod::build(&rbvh, &params).unwrap();
            let order = subtree_order(&rbvh);
            let mut longest_side_full = 0;
            assert!(!lod.nodes[0].is_some(), "no ray can choose the root");
            for (n, record) in lod.nodes.iter().enumerate().skip(1) {
                let (below, surface) = leaves_below(&rbvh, n as u32);
                if below < params.min_leaves as usize || surface == 0 {
                    assert!(
                        !record.is_some(),
                        "node {n}: {below} leaves, {surface} sampled"
                    );
                    continue;
                }
                assert!(record.is_some(), "node {n}: {below} leaves but no grid");
                let (bounds, _) = order.span[n].unwrap();
                let [u, v, w] = record.axes();
                let extent = bounds.extent();
                assert!(extent[w] <= extent[u] && extent[w] <= extent[v], "node {n}");
                assert!(record.texel_size >= 2.0 * fine, "node {n}");
                for (axis, res) in [(u, record.res_u), (v, record.res_v)] {
                    assert!((1..=params.columns).contains(&res), "node {n}");
                    assert!(res as f32 * record.texel_size >= extent[axis], "node {n}");
                }
                if record.texel_size > 2.0 * fine {
                    assert_eq!(record.res_u.max(record.res_v), params.columns, "node {n}");
                    longest_side_full += 1;
                }
            }
            assert!(longest_side_full > 0);
        }
    }
}
