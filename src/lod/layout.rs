//! GPU layout of the level-of-detail data, read by `glsl/lod.glsl`. `tests/layout.rs` checks every
//! offset against the compiled SPIR-V.
//!
//! One [`GpuLod`] record per RBVH node (indexed like [`crate::rbvh::Rbvh::nodes`]); a node without a
//! coarse representation has `texel_size = +inf`, so no footprint ever selects it. The columns of
//! all records live in one `u32` array, two words per column ([`Column`]).

use crate::rbvh::Texel;
use bytemuck::{Pod, Zeroable};

/// Marks a traversal entry (GPU and CPU) as "march the coarse representation of node `n`":
/// `LOD_BIT | n`. Node indices stay below it ([`crate::lod::Lod::build`] checks). A hit on a
/// coarse representation reports `id = LEAF_BIT | LOD_BIT | node`.
pub const LOD_BIT: u32 = 0x4000_0000;

/// The coarse representation of one inner node: a grid of solid *columns* along the world axis
/// `axis` (the node box's thinnest), each filled between a bottom and a top height — two height
/// fields facing away from each other, so that a closed object is solid from every side. 48 bytes:
///
/// | bytes | field |
/// |---|---|
/// | 0..12, 12..16 | `origin` (world corner of column (0, 0) at height 0), `texel_size` (world side of a column; +inf: none) |
/// | 16..32 | `axis` (0 x, 1 y, 2 z; `u` = axis + 1, `v` = axis + 2, mod 3), `res_u`, `res_v`, `base` (first word of column (0, 0)) |
/// | 32..48 | `h_scale` (world height per code), `inv_texel` (1 / `texel_size`), two pad words |
///
/// Column `(i, j)` spans `u ∈ origin_u + [i, i + 1)·texel_size` (likewise `v`); its words are at
/// `base + 2·(j·res_u + i)`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct GpuLod {
    /// GLSL `RbvhLod.origin`: world-space corner of column (0, 0) at height code 0 (the node box's
    /// minimum corner).
    pub origin: [f32; 3],
    /// GLSL `texel_size`: world width of one (square) column; +inf for a node without a grid.
    pub texel_size: f32,
    /// GLSL `axis`: the world axis the columns stand along, `w` (0 x, 1 y, 2 z).
    pub axis: u32,
    /// GLSL `res_u`: columns along `u` = (`axis` + 1) mod 3, at most
    /// [`LodParams::columns`](crate::lod::LodParams::columns).
    pub res_u: u32,
    /// GLSL `res_v`: columns along `v` = (`axis` + 2) mod 3.
    pub res_v: u32,
    /// GLSL `base`: index in the column-word array of column (0, 0)'s top word.
    pub base: u32,
    /// GLSL `h_scale`: world height along `w` per unit of a 16-bit height code.
    pub h_scale: f32,
    /// GLSL `inv_texel`: `1 / texel_size`, so that the march multiplies instead of dividing.
    pub inv_texel: f32,
    /// GLSL `pad0`, `pad1`: padding to 48 bytes; always 0.
    pub pad: [u32; 2],
}
const _: () = assert!(std::mem::size_of::<GpuLod>() == 48);

impl GpuLod {
    /// The record of a node with no coarse representation.
    pub const NONE: GpuLod = GpuLod {
        origin: [0.0; 3],
        texel_size: f32::INFINITY,
        axis: 0,
        res_u: 0,
        res_v: 0,
        base: 0,
        h_scale: 0.0,
        inv_texel: 0.0,
        pad: [0; 2],
    };

    /// Whether the node has a coarse representation (`texel_size` finite).
    pub fn is_some(&self) -> bool {
        self.texel_size.is_finite()
    }

    /// World axes `(u, v, w)` of the column grid: `w` is `axis`, `u` and `v` the next two.
    pub fn axes(&self) -> [usize; 3] {
        let w = (self.axis % 3) as usize;
        [(w + 1) % 3, (w + 2) % 3, w]
    }

    /// The words of column `(i, j)` of this record in `texels`, and the index of its first word, if
    /// they are in range.
    pub fn column(&self, texels: &[u32], i: u32, j: u32) -> Option<(Column, usize)> {
        if i >= self.res_u || j >= self.res_v {
            return None;
        }
        let index =
            u64::from(self.base) + 2 * (u64::from(j) * u64::from(self.res_u) + u64::from(i));
        let index = usize::try_from(index).ok()?;
        let column = Column {
            top: Texel(*texels.get(index)?),
            bottom: Texel(*texels.get(index.checked_add(1)?)?),
        };
        Some((column, index))
    }
}

/// One column: its top and bottom surface, each a [`Texel`] (16-bit height code above the record's
/// origin along `w`, 8:8 octahedral normal of the surface there). An empty column has a hole top.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Column {
    /// Highest sample's height code (rounded up) with the mean normal of the samples facing up
    /// `w`; a hole for an empty column.
    pub top: Texel,
    /// Lowest sample's height code (rounded down) with the mean normal of those facing down `w`.
    pub bottom: Texel,
}

impl Column {
    /// A column no sample fell into: both words holes; rays pass through it.
    pub const EMPTY: Column = Column {
        top: Texel::HOLE,
        bottom: Texel::HOLE,
    };

    /// Whether the column holds no surface (its top is a hole).
    pub fn is_empty(&self) -> bool {
        self.top.is_hole()
    }
}
