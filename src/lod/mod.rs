//! Per-ray level of detail for an RBVH: coarse representations at inner nodes, chosen per ray by its
//! footprint (a ray cone), so that distant geometry ends traversal early.
//!
//! The talk of Novák & Dachsbacher (2012) shows level of detail as an application of RBVHs; this is
//! our reading of it. An inner node of the RBVH may carry a *coarse* representation: a grid of
//! solid columns along the node box's thinnest world axis, each filled between the lowest and the
//! highest surface sample of the node's subtree that falls into it (two height fields back to
//! back, see [`layout::GpuLod`]). Every inner node but the root (which no ray can choose) with at
//! least [`LodParams::min_leaves`] leaves below it gets one, [`LodParams::columns`] columns across
//! its box's longer side: each node is drawn at the same number of columns, like a mip level that
//! fits the node rather than the texel. While traversing, an inner child whose column is no wider
//! than `2^bias` times the ray's cone at the child's box entry ([`cone::selects`],
//! [`LodParams::selection_width`]) is not descended into: its columns are marched instead
//! (`glsl/lod.glsl`, `march`). A whole object, or a group of them, is thus chosen as soon as the
//! ray sees it at most `columns · 2^bias` footprints wide, and costs one short march instead of a
//! descent through many leaves. (Column widths that doubled per tree level, as mip maps do per
//! texel, made whole objects so blocky that only their last few levels were ever chosen: 1.08× at
//! FLIP 0.017 on the `grove-aerial` view, against 1.82× at 0.023 with the defaults now.)
//!
//! The data is built from a finished RBVH ([`Lod::build`]), not from the scene: it approximates the
//! RBVH's own surface (height-field samples and triangle-leaf triangles, but for the exact parts
//! beside height fields that the fields stand for: `GpuTriangle::PART` without `BARE`), works for RBVHs loaded
//! from files, and exists only when asked for — a trace that does not ask for them (with `--method rbvh-lod`) allocates nothing.
//!
//! * [`cone`]: ray cones and the selection rule;
//! * `build`: splatting the subtree's surface samples into each node's columns;
//! * [`layout`]: the records the GPU reads;
//! * `march`: the CPU reference of the column march;
//! * `trace`: the CPU caster with level of detail, a hook of the shared traversal around the
//!   RBVH's leaves, and its device twin ([`LodTwin`]).

mod build;
pub mod cone;
pub mod layout;
pub(crate) mod march;
mod trace;

pub use cone::{selects, Cones, RayCone};
pub use layout::{Column, GpuLod, LOD_BIT};
pub use trace::LodTwin;

use crate::rbvh::Child;
use crate::{Error, Result};

/// How the coarse levels are made, and how eagerly rays choose them.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct LodParams {
    /// Columns along the longer side of every node's grid. A grid does not skip empty space as
    /// the tree does, so a wide one costs more to march; fewer columns cost less memory and
    /// marching, but are blockier, so the same image needs a smaller `bias`.
    pub columns: u32,
    /// Fewest leaves below a node for it to get a grid: descending into a few leaves (each
    /// marched with block jumps) costs about what marching a grid does, so a grid there adds
    /// error and memory for little speed (measured on `grove-aerial`, docs/level-of-detail.md).
    /// A value above the tree's leaf count leaves no node a grid.
    pub min_leaves: u32,
    /// A node is chosen where its column is no wider than `2^bias` footprints, so at least
    /// `2^-bias` columns fall in a footprint: 0 puts one column per footprint, −1 (the default)
    /// two; lower values choose later (sharper, slower), higher ones earlier — the LOD bias of
    /// texture samplers. The device reads it as built into [`Lod::annotated_nodes`] when a
    /// tracer is made, so changing it afterwards changes only the CPU caster's choice.
    pub bias: f32,
}

impl Default for LodParams {
    fn default() -> Self {
        LodParams {
            columns: 24,
            min_leaves: 8,
            bias: -1.0,
        }
    }
}

/// The range `LodParams::bias` may take: beyond ±8 a node is chosen 256× before or after its
/// columns fit the footprint, which is no longer a level of detail.
pub const MAX_BIAS: f32 = 8.0;

impl LodParams {
    /// Fails with [`Error::InvalidParameter`] when `columns` is outside 1..=256, `min_leaves` is
    /// 0, or `bias` is outside ±[`MAX_BIAS`].
    pub fn validate(&self) -> Result<()> {
        if !(1..=256).contains(&self.columns) {
            return Err(Error::param(
                "lod columns",
                format!("{} is outside 1..=256", self.columns),
            ));
        }
        if self.min_leaves == 0 {
            return Err(Error::param("lod min leaves", "must be at least 1"));
        }
        if !(-MAX_BIAS..=MAX_BIAS).contains(&self.bias) {
            return Err(Error::param(
                "lod bias",
                format!("{} is outside -{MAX_BIAS}..={MAX_BIAS}", self.bias),
            ));
        }
        Ok(())
    }

    /// The column width a footprint is compared with for a node whose columns are `width` wide
    /// (see `bias`).
    pub fn selection_width(&self, width: f32) -> f32 {
        width * (-self.bias).exp2()
    }
}

/// The coarse representations of one RBVH's inner nodes, in the packed form the GPU reads.
#[derive(Clone, Debug, PartialEq)]
pub struct Lod {
    /// The parameters it was built with; `bias` also steers the CPU caster's choice.
    pub params: LodParams,
    /// One record per RBVH node, in node order ([`GpuLod::NONE`] for a node without one).
    pub nodes: Vec<GpuLod>,
    /// Column words of all records, two per column.
    pub texels: Vec<u32>,
    /// Where the RBVH has a colour channel: the colour (RGBA8, as [`crate::rbvh::Rbvh::colours`])
    /// of each column word's surface sample, parallel to `texels` (0: none). Host-side only: the
    /// colour of a coarse hit is looked up after the trace ([`Lod::colour_at`]).
    pub colours: Option<Vec<u32>>,
    /// What the build made and how long it took.
    pub stats: LodStats,
}

/// Accounting of one build.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LodStats {
    /// Wall time of [`Lod::build`] in milliseconds.
    pub build_ms: f64,
    /// Nodes with a coarse representation.
    pub coarse_nodes: u32,
    /// Columns over all nodes.
    pub columns: u64,
}

impl Lod {
    /// Checks that this was built for `rbvh` (one record per node).
    pub fn check_for(&self, rbvh: &crate::rbvh::Rbvh) -> Result<()> {
        no_height_only(rbvh)?;
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
                .map_or(f32::INFINITY, |r| self.params.selection_width(r.texel_size))
                .to_bits()
        };
        rbvh.nodes
            .iter()
            .map(|n| {
                let mut n = *n;
                if let Child::Inner(child) = Child::decode(n.a_child, n.a_count) {
                    n.a_count = width(child);
                }
                if let Child::Inner(child) = Child::decode(n.b_child, n.b_count) {
                    n.b_count = width(child);
                }
                n
            })
            .collect()
    }

    /// The colour word of the coarse surface of `node` nearest `point` (a coarse hit's point): the
    /// column holding it — or, for a hit on a column's side, which lies on the border with an
    /// empty neighbour, the nearest non-empty column around it — and there its top or bottom
    /// surface, whichever is nearer along the grid's axis; where that surface has no colour (its
    /// extreme sample came from a triangle leaf), the nearest column around it that has one.
    /// `None` without colours, for a node without a coarse representation, or where no column
    /// around the point has a colour.
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
                let Some((column, _)) = record
                    .column(&self.texels, i, j)
                    .filter(|(c, _)| !c.is_empty())
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

/// Levels of detail take their columns' normals from the texels, which a height-only RBVH
/// ([`crate::rbvh::TexelFormat::Height`]) does not keep: refused with a way out.
pub(crate) fn no_height_only(rbvh: &crate::rbvh::Rbvh) -> Result<()> {
    no_height_only_texels(rbvh.params.texels)
}

/// [`no_height_only`] of an RBVH to be built with `texels`, before it is built.
pub(crate) fn no_height_only_texels(texels: crate::rbvh::TexelFormat) -> Result<()> {
    if texels == crate::rbvh::TexelFormat::Height {
        return Err(Error::param(
            "lod",
            "levels of detail need the texels' normals, which a height-only RBVH does not keep: \
             build it with normals (--texels normals, the default; a height-only file must be \
             built again, `rbvh build --out FILE.rbvh` without --texels height)",
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bias_scales_the_width_a_footprint_is_compared_with() {
        let biased = |bias| LodParams {
            bias,
            ..LodParams::default()
        };
        assert_eq!(biased(0.0).selection_width(0.25), 0.25);
        assert_eq!(biased(1.0).selection_width(0.25), 0.125);
        assert_eq!(biased(-2.0).selection_width(0.25), 1.0);
    }
}
