//! Building the coarse representations: every inner node's columns are filled by *splatting* the
//! surface samples of its subtree — the height-field samples of its height-field leaves and points
//! spread over its triangle-leaf triangles — into the column grid over the node's box.
//!
//! A sample covers a square patch about one fine texel wide, so it is splatted into every column
//! its patch overlaps; since columns are at least two fine texels wide, a surface crossing a
//! column leaves samples in it and the coarse level has no pinholes. A column keeps the lowest and
//! highest sample along the grid's axis, with their normals (and colours, where the RBVH has a
//! colour channel), and is solid in between.

use std::time::Instant;

use glam::Vec3;
use rayon::prelude::*;

use super::layout::{Column, GpuLod, LOD_BIT};
use super::{Lod, LodParams, LodStats};
use crate::geom::Aabb;
use crate::rbvh::{layout::HEIGHTFIELD_COUNT, layout::LEAF_BIT, Rbvh, Texel};
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
        let column_sizes = column_sizes(rbvh, &order);
        let records: Vec<Coarse> = (0..rbvh.nodes.len())
            .into_par_iter()
            .map(|n| match order.span[n] {
                Some((bounds, range)) => coarse_node(
                    &bounds,
                    &sources[range.0..range.1],
                    fine,
                    column_sizes[n],
                    params.columns,
                ),
                None => (GpuLod::NONE, Vec::new(), Vec::new()),
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
    /// Nodes in the order the walk left them: every child before its parent.
    post_order: Vec<u32>,
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
    let mut post_order = Vec::with_capacity(n);
    if n == 0 {
        return SubtreeOrder {
            sources,
            span,
            post_order,
        };
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
                post_order.push(node);
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
                    if c.child & LEAF_BIT == 0 {
                        stack.push(Step::Enter(c.child, c.bounds));
                    } else if c.count == HEIGHTFIELD_COUNT {
                        sources.push(Source::Heightfield(c.child & !LEAF_BIT));
                    } else if c.count > 0 {
                        sources.push(Source::Triangles {
                            first: c.child & !LEAF_BIT,
                            count: c.count,
                        });
                    }
                }
            }
        }
    }
    SubtreeOrder {
        sources,
        span,
        post_order,
    }
}

/// The column width of every node, children first: twice the widest of its inner children's
/// (leaves count as the fine texel). Each level is thus half as sharp as the one below — a
/// pyramid, as mip maps are, so that some level fits every footprint between the fine texel and
/// the whole scene.
fn column_sizes(rbvh: &Rbvh, order: &SubtreeOrder) -> Vec<f32> {
    let fine = rbvh.texel_size;
    let mut size = vec![fine; rbvh.nodes.len()];
    for &node in &order.post_order {
        let below = rbvh.nodes[node as usize]
            .children()
            .iter()
            .filter(|c| c.child & LEAF_BIT == 0)
            .filter_map(|c| size.get(c.child as usize).copied())
            .fold(fine, f32::max);
        size[node as usize] = 2.0 * below;
    }
    size
}

impl Source {
    /// At most how many samples [`Source::samples`] gives, without making them.
    fn sample_count(&self, rbvh: &Rbvh) -> u64 {
        match *self {
            Source::Heightfield(leaf) => rbvh
                .leaves
                .get(leaf as usize)
                .map_or(0, |hf| u64::from(hf.res_u) * u64::from(hf.res_v)),
            Source::Triangles { first, count } => leaf_triangles(rbvh, first, count)
                .iter()
                .map(|t| {
                    let d = u64::from(divisions(t.vertices(), rbvh.texel_size));
                    (d + 1) * (d + 2) / 2
                })
                .sum(),
        }
    }

    /// The leaf's surface samples: every sample of a height field (holes excepted) at its world
    /// position, or points spread over each triangle no further apart than a fine texel.
    fn samples(&self, rbvh: &Rbvh) -> Vec<Sample> {
        match *self {
            Source::Heightfield(leaf) => heightfield_samples(rbvh, leaf),
            Source::Triangles { first, count } => leaf_triangles(rbvh, first, count)
                .iter()
                .flat_map(|t| triangle_samples(t.vertices(), rbvh.texel_size))
                .collect(),
        }
    }
}

/// The triangles of a triangle leaf, cut to the array (corrupt ranges give fewer or none).
fn leaf_triangles(rbvh: &Rbvh, first: u32, count: u32) -> &[crate::bvh::GpuTriangle] {
    let first = first as usize;
    let end = first
        .saturating_add(count as usize)
        .min(rbvh.triangles.len());
    rbvh.triangles.get(first..end).unwrap_or_default()
}

fn heightfield_samples(rbvh: &Rbvh, leaf: u32) -> Vec<Sample> {
    let Some(hf) = rbvh.leaves.get(leaf as usize) else {
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
    let normal = crate::rbvh::layout::encode_octahedral((b - a).cross(c - a).normalize_or(Vec3::Z));
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
fn coarse_node(
    bounds: &Aabb,
    sources: &[Vec<Sample>],
    fine: f32,
    texel_size: f32,
    columns: u32,
) -> Coarse {
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
    if !(texel_size.is_finite() && texel_size > 0.0) {
        return (GpuLod::NONE, Vec::new(), Vec::new());
    }
    let res = |axis: usize| ((extent[axis] / texel_size).ceil() as u32).max(1);
    let (res_u, res_v) = (res(u), res(v));
    // A grid does not skip empty space as a tree does: a ray may walk all its columns. Only a node
    // that the ray sees at most `columns` footprints wide is worth marching instead of descending.
    if res_u > columns || res_v > columns {
        return (GpuLod::NONE, Vec::new(), Vec::new());
    }
    let origin = bounds.min;
    let radius = SPLAT_RADIUS * fine;
    // Per column: (lowest height, its sample, highest height, its sample).
    let none = Sample {
        p: Vec3::ZERO,
        normal: 0,
        colour: 0,
    };
    let mut acc = vec![(f32::INFINITY, none, f32::NEG_INFINITY, none); (res_u * res_v) as usize];
    let cell = |x: f32, res: u32| ((x / texel_size).floor().max(0.0) as u32).min(res - 1);
    for s in sources.iter().flatten() {
        let rel = s.p - origin;
        let (i0, i1) = (cell(rel[u] - radius, res_u), cell(rel[u] + radius, res_u));
        let (j0, j1) = (cell(rel[v] - radius, res_v), cell(rel[v] + radius, res_v));
        let h = rel[w];
        for j in j0..=j1 {
            for i in i0..=i1 {
                let a = &mut acc[(j * res_u + i) as usize];
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
    for &(lo, bottom, hi, top) in &acc {
        let column = if lo <= hi {
            Column {
                top: Texel(u32::from(code(hi, true)) | u32::from(top.normal) << 16),
                bottom: Texel(u32::from(code(lo, false)) | u32::from(bottom.normal) << 16),
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
