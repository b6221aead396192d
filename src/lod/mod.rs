//! Per-ray level of detail for an RBVH: coarse representations at inner nodes, chosen per ray by its
//! footprint (a ray cone), so that distant geometry ends traversal early.
//!
//! The talk of Novák & Dachsbacher (2012) shows level of detail as an application of RBVHs; this is
//! our reading of it. An inner node of the RBVH may carry a *coarse* representation: a grid of
//! solid columns along the node box's thinnest world axis, each filled between the lowest and the
//! highest surface sample of the node's subtree that falls into it (two height fields back to
//! back, see [`layout::GpuLod`]). Column widths form a pyramid over the leaves, as mip maps do:
//! a node's columns are twice as wide as the widest of its children's (leaves: the RBVH's texel).
//! Only nodes whose grid has at most [`LodParams::columns`] columns a side get one, because a grid
//! does not skip empty space the way the tree does. While traversing, an inner child whose column
//! is no wider than the ray's cone at the child's box entry ([`cone::selects`]) is not descended
//! into: its columns are marched instead (`glsl/lod.glsl`, `march`). Subtrees a ray sees at less
//! than a column per footprint thus cost one short march instead of a descent through many leaves.
//!
//! The data is built from a finished RBVH ([`Lod::build`]), not from the scene: it approximates the
//! RBVH's own surface (height-field samples and triangle-leaf triangles), works for RBVHs loaded
//! from files, and exists only when asked for — a trace without `--lod` allocates nothing.
//!
//! * [`cone`]: ray cones and the selection rule;
//! * `build`: splatting the subtree's surface samples into each node's columns;
//! * [`layout`]: the records the GPU reads;
//! * `march`: the CPU reference of the column march (the traversal hook is in `rbvh::march`).

mod build;
pub mod cone;
pub mod layout;
pub(crate) mod march;

pub use cone::{selects, RayCone};
pub use layout::{Column, GpuLod, LOD_BIT};

use crate::{Error, Result};

/// How the coarse levels are made.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LodParams {
    /// Most columns along a side of a node's grid: a node whose grid would be wider gets no
    /// coarse representation (rays descend to its children). A grid does not skip empty space as
    /// the tree does, so marching a wide one costs more than it saves; fewer columns also cost
    /// less memory, but select coarse nodes only for smaller footprints-per-node.
    pub columns: u32,
}

impl Default for LodParams {
    fn default() -> Self {
        LodParams { columns: 8 }
    }
}

impl LodParams {
    pub fn validate(&self) -> Result<()> {
        if !(1..=256).contains(&self.columns) {
            return Err(Error::param(
                "lod columns",
                format!("{} is outside 1..=256", self.columns),
            ));
        }
        Ok(())
    }
}

/// The coarse representations of one RBVH's inner nodes, in the packed form the GPU reads.
#[derive(Clone, Debug, PartialEq)]
pub struct Lod {
    pub params: LodParams,
    /// One record per RBVH node, in node order ([`GpuLod::NONE`] for a node without one).
    pub nodes: Vec<GpuLod>,
    /// Column words of all records, two per column.
    pub texels: Vec<u32>,
    /// Where the RBVH has a colour channel: the colour (RGBA8, as [`crate::rbvh::Rbvh::colours`])
    /// of each column word's surface sample, parallel to `texels` (0: none). Host-side only: the
    /// colour of a coarse hit is looked up after the trace ([`Lod::colour_at`]).
    pub colours: Option<Vec<u32>>,
    pub stats: LodStats,
}

/// Accounting of one build.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LodStats {
    pub build_ms: f64,
    /// Nodes with a coarse representation.
    pub coarse_nodes: u32,
    /// Columns over all nodes.
    pub columns: u64,
}

impl Lod {
    /// Checks that this was built for `rbvh` (one record per node).
    pub fn check_for(&self, rbvh: &crate::rbvh::Rbvh) -> Result<()> {
        if self.nodes.len() != rbvh.nodes.len() {
            return Err(Error::param(
                "lod",
                format!(
                    "built for a tree of {} nodes, used with one of {}",
                    self.nodes.len(),
                    rbvh.nodes.len()
                ),
            ));
        }
        Ok(())
    }

    /// The RBVH's nodes as the LOD trace reads them: every inner child's `count` (0, unused, in
    /// the plain tree) holds the bits of that child's column width (`+inf` without a coarse
    /// representation), so that choosing a coarse node needs no read beyond the node itself.
    pub fn annotated_nodes(&self, rbvh: &crate::rbvh::Rbvh) -> Vec<crate::bvh::GpuNode> {
        let width = |child: u32| {
            self.nodes
                .get(child as usize)
                .map_or(f32::INFINITY, |r| r.texel_size)
                .to_bits()
        };
        rbvh.nodes
            .iter()
            .map(|n| {
                let mut n = *n;
                if n.a_child & crate::bvh::LEAF_BIT == 0 {
                    n.a_count = width(n.a_child);
                }
                if n.b_child & crate::bvh::LEAF_BIT == 0 {
                    n.b_count = width(n.b_child);
                }
                n
            })
            .collect()
    }

    /// The colour word of the coarse surface of `node` nearest `point` (a coarse hit's point): the
    /// column holding it — or, for a hit on a column's side, which lies on the border with an
    /// empty neighbour, the nearest non-empty column around it — and there its top or bottom
    /// surface, whichever is nearer along the grid's axis. `None` without colours, for a node
    /// without a coarse representation, or where the surface has no colour (triangle leaves).
    pub fn colour_at(&self, node: u32, point: glam::Vec3) -> Option<u32> {
        let colours = self.colours.as_ref()?;
        let record = self.nodes.get(node as usize).filter(|r| r.is_some())?;
        let [u, v, w] = record.axes();
        let rel = point - glam::Vec3::from(record.origin);
        let (x, y) = (rel[u] * record.inv_texel, rel[v] * record.inv_texel);
        let h = rel[w];
        let clamp = |c: f32, res: u32| (c.floor().max(0.0) as u32).min(res.saturating_sub(1));
        let (ci, cj) = (clamp(x, record.res_u), clamp(y, record.res_v));
        let mut best: Option<(f32, u32)> = None;
        for j in cj.saturating_sub(1)..=(cj + 1).min(record.res_v.saturating_sub(1)) {
            for i in ci.saturating_sub(1)..=(ci + 1).min(record.res_u.saturating_sub(1)) {
                let Some(column) = record.column(&self.texels, i, j).filter(|c| !c.is_empty())
                else {
                    continue;
                };
                // Distance from the point to the column's footprint, in columns.
                let dx = (i as f32 - x).max(x - (i + 1) as f32).max(0.0);
                let dy = (j as f32 - y).max(y - (j + 1) as f32).max(0.0);
                let distance = dx.max(dy);
                if best.is_some_and(|(d, _)| d <= distance) {
                    continue;
                }
                let top = f32::from(column.top.height_code()) * record.h_scale;
                let bottom = f32::from(column.bottom.height_code()) * record.h_scale;
                let word = u64::from(record.base)
                    + 2 * (u64::from(j) * u64::from(record.res_u) + u64::from(i))
                    + u64::from(top - h > h - bottom);
                let colour = usize::try_from(word)
                    .ok()
                    .and_then(|k| colours.get(k))
                    .copied()
                    .filter(|&c| c != 0);
                if let Some(colour) = colour {
                    best = Some((distance, colour));
                }
            }
        }
        best.map(|(_, colour)| colour)
    }

    /// Bytes on the device: the per-node records and the columns.
    pub fn bytes(&self) -> u64 {
        (std::mem::size_of_val(self.nodes.as_slice())
            + std::mem::size_of_val(self.texels.as_slice())) as u64
    }
}
