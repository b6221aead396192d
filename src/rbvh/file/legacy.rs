//! Readers of the files written before the sectioned format (versions 1–12): a fixed header, then
//! the arrays. They load as the RBVHs they described, upgraded in memory, so that every old file
//! (whose colours may be painted, which no scene can rebuild) stays usable; saving one, or `rbvh
//! upgrade`, writes the current version. Nothing writes these versions any more.
//!
//! Version 12, the last of them:
//!
//! | bytes | type | field |
//! |---|---|---|
//! | 0..8 | `[u8; 8]` | magic `RBVHv` followed by three zero bytes |
//! | 8..12 | u32 | format version |
//! | 12..16 | f32 | `params.texels_per_diagonal` |
//! | 16..20, 20..24 | u32, f32 | `params.refinement`: tag (0 = `NormalCone`, 1 = `ProjectedArea`), its value (`max_angle_deg` or `min_ratio`) |
//! | 24..28 | u32 | `params.subdivision`: 0 = `SpatialMedian`, 1 = `AreaSah` |
//! | 28..32 | u32 | `params.object_split`: 0 or 1 |
//! | 32..36 | u32 | `params.max_tile` |
//! | 36..40 | f32 | `params.min_leaf_texels` |
//! | 40..44 | f32 | `params.sampled_criterion_texels` |
//! | 44..48 | u32 | `params.texels`: 0 = `HeightNormal`, 1 = `Height` |
//! | 48..52 | u32 | colour channel: 0 = none, 1 = the colour section follows the texels |
//! | 52..76 | 6 × f32 | `bounds`: min x, y, z, max x, y, z |
//! | 76..80 | u32 | `depth` |
//! | 80..84 | f32 | `texel_size` |
//! | 84..92 | f64 | `stats.build_ms` |
//! | 92..96, 96..100 | u32, u32 | `stats.heightfield_leaves`, `stats.triangle_leaves` |
//! | 100..108 | u64 | `stats.tile_texels` |
//! | 108..112, 112..116 | u32, u32 | `atlas.pitch`, `atlas.rows` |
//! | 116..148 | 4 × u64 | counts: nodes `N`, triangles `T`, leaves `L`, texels `X` |
//! | 148..152 | f32 | `params.object_rate` (0: none) |
//! | 152..156 | u32 | `atlas.narrow_rows`: rows at the end whose heights are 8-bit codes |
//! | 156..160 | u32 | `params.exact_when_cheaper`: 0 or 1 |
//! | 160..164 | f32 | `params.exact_from_texels` (0: what 96 bytes buy) |
//! | 164..168 | f32 | `params.exact_edge_fraction` (0: none) |
//! | 168..172 | f32 | `params.exact_crease_deg` (0: none; nothing where `exact_when_cheaper` is 0) |
//! | 172.. | `N` × 48 bytes | `nodes` ([`crate::bvh::GpuNode`], 12 words each) |
//! | then | `T` × 48 bytes | `triangles` ([`crate::bvh::GpuTriangle`], 12 words each) |
//! | then | `L` × 64 bytes | `heightfields` ([`super::super::GpuHeightfield`], 16 words each) |
//! | then | `X` × 4 bytes | `atlas.texels` ([`Texel`], one word each), row by row; height-only texels: `X` × 2 bytes, each texel's height code (u16) |
//! | then | u64 | with a colour channel only: colour count `C`, which must equal `X` |
//! | then | `C` × 4 bytes | with a colour channel only: `colours` (packed RGBA8, see [`crate::rgba`]), parallel to the texels |
//!
//! A height-only RBVH has no colour channel: a file that claims both is malformed.
//!
//! Each version before appended to the header of the one before it. Versions 1–4 stored each
//! node in 64 bytes with both children's boxes at full precision (`a_min`, `a_child`, `a_max`,
//! `a_count`, then the same for `b`); loading quantizes them as the builder does now
//! ([`GpuNode::new`]), so every box only grows and every hit stays. The header of versions 1–3
//! lacks bytes 40..52: the texel format and the colour channel were the version's (1: normals,
//! no colours; 2: normals and colours; 3: height-only), and they were built by the paper's rule
//! alone (`sampled_criterion_texels` = 0). Versions 1–5 carry no mark of which heights were
//! sampled from the surface and which extrapolated (the parity of a height code,
//! [`Texel::is_sampled`]): every sampled-looking code is made odd on loading, within one code
//! and inside its leaf's box (where the box allows: `unmark`), so that the march hangs no skirt
//! under them and the RBVH traces as it was built. Versions 1–6 took every texel from the scene
//! (`object_rate` 0). Versions 1–7 have 16-bit codes everywhere (`narrow_rows` 0). Versions 1–8
//! sampled every triangle a height field could hold (`exact_when_cheaper` false), and versions
//! 1–9 traced exactly the triangles of at least what 96 bytes of texels buy
//! (`exact_from_texels` 0), and versions 1–10 traced none exactly for the length of its edges
//! (`exact_edge_fraction` 0), and versions 1–11 none for a crease (`exact_crease_deg` 0). Files
//! written before triangles carried flags load with theirs 0: level-of-detail grids then sample
//! them, and their hits take the scene's material colours, as they did then. A colour section
//! that is cut short, or whose count is not `X`, is an [`Error::Parse`] like any other
//! malformation; so is everything the sectioned format's loader checks.

use std::path::Path;

use bytemuck::{Pod, Zeroable};

use super::{check, flag, records, refinement, subdivision, Reader};
use crate::bvh::{ChildRef, GpuNode, GpuTriangle};
use crate::geom::Aabb;
use crate::rbvh::child::Child;
use crate::rbvh::layout::{Atlas, GpuHeightfield, Texel};
use crate::rbvh::params::{RbvhParams, TexelFormat};
use crate::rbvh::{ExactTriangles, Rbvh};
use crate::{Error, Result};

/// Bytes before the arrays in version 12.
const V12_HEADER_BYTES: usize = 172;
/// Bytes before the arrays in version 11, whose header ends before `exact_crease_deg`.
const V11_HEADER_BYTES: usize = 168;
/// Bytes before the arrays in version 10, whose header ends before `exact_edge_fraction`.
const V10_HEADER_BYTES: usize = 164;
/// Bytes before the arrays in version 9, whose header ends before `exact_from_texels`.
const V9_HEADER_BYTES: usize = 160;
/// Bytes before the arrays in version 8, whose header ends before `exact_when_cheaper`.
const V8_HEADER_BYTES: usize = 156;
/// Bytes before the arrays in version 7, whose header ends before `narrow_rows`.
const V7_HEADER_BYTES: usize = 152;
/// Bytes before the arrays in versions 4–6, whose header ends before `object_rate`.
const V6_HEADER_BYTES: usize = 148;
/// Bytes before the arrays in versions 1–3, whose header lacks bytes 40..52 of later ones.
const OLD_HEADER_BYTES: usize = 136;

/// Parses a file of `version` (1–12, its magic and version already checked) as the RBVH it
/// described; `path` is the file named in every error.
pub(super) fn read(bytes: &[u8], version: u32, path: &Path) -> Result<Rbvh> {
    let err = |message: String| Error::parse(path, None, message);
    let mut r = Reader::new(bytes, path);
    r.take(12, "the magic and version")?;

    let texels_per_diagonal = r.f32("params.texels_per_diagonal")?;
    let refinement = refinement(
        r.u32("params.refinement")?,
        r.f32("params.refinement value")?,
    )
    .map_err(err)?;
    let subdivision = subdivision(r.u32("params.subdivision")?).map_err(err)?;
    let object_split = flag("params.object_split", r.u32("params.object_split")?).map_err(err)?;
    let max_tile = r.u32("params.max_tile")?;
    let min_leaf_texels = r.f32("params.min_leaf_texels")?;
    let (sampled_criterion_texels, texels, colour_channel) = match version {
        1 => (0.0, TexelFormat::HeightNormal, false),
        2 => (0.0, TexelFormat::HeightNormal, true),
        3 => (0.0, TexelFormat::Height, false),
        _ => {
            let sampled = r.f32("params.sampled_criterion_texels")?;
            let texels = match r.u32("params.texels")? {
                0 => TexelFormat::HeightNormal,
                1 => TexelFormat::Height,
                tag => {
                    return Err(err(format!(
                        "params.texels has tag {tag}; known are 0 (HeightNormal) and 1 (Height)"
                    )))
                }
            };
            let colour_channel =
                flag("the colour channel flag", r.u32("the colour channel flag")?).map_err(err)?;
            if colour_channel && texels == TexelFormat::Height {
                return Err(err(
                    "a height-only RBVH claims a colour channel (it cannot have one)".to_string(),
                ));
            }
            (sampled, texels, colour_channel)
        }
    };
    let header_bytes = match version {
        1..=3 => OLD_HEADER_BYTES,
        4..=6 => V6_HEADER_BYTES,
        7 => V7_HEADER_BYTES,
        8 => V8_HEADER_BYTES,
        9 => V9_HEADER_BYTES,
        10 => V10_HEADER_BYTES,
        11 => V11_HEADER_BYTES,
        _ => V12_HEADER_BYTES,
    };
    let (bounds, depth, texel_size, stats) = r.structure_head()?;
    let pitch = r.u32("atlas.pitch")?;
    let rows = r.u32("atlas.rows")?;
    let counts = [
        r.u64("the node count")?,
        r.u64("the triangle count")?,
        r.u64("the leaf count")?,
        r.u64("the texel count")?,
    ];
    // Each later field is one the versions before it lacked, loaded as what they meant.
    let object_rate = if version >= 7 {
        r.f32("params.object_rate")?
    } else {
        0.0
    };
    let narrow_rows = if version >= 8 {
        r.u32("atlas.narrow_rows")?
    } else {
        0
    };
    let exact_when_cheaper = if version >= 9 {
        let x = r.u32("params.exact_when_cheaper")?;
        flag("params.exact_when_cheaper", x).map_err(err)?
    } else {
        false
    };
    let exact_from_texels = if version >= 10 {
        r.f32("params.exact_from_texels")?
    } else {
        0.0
    };
    let exact_edge_fraction = if version >= 11 {
        r.f32("params.exact_edge_fraction")?
    } else {
        0.0
    };
    let exact_crease_deg = if version >= 12 {
        r.f32("params.exact_crease_deg")?
    } else {
        0.0
    };
    let params = RbvhParams {
        texels_per_diagonal,
        object_rate,
        refinement,
        subdivision,
        object_split,
        max_tile,
        min_leaf_texels,
        sampled_criterion_texels,
        texels,
        exact_when_cheaper,
        exact_from_texels,
        exact_edge_fraction,
        exact_crease_deg,
        view_rate: 0.0,
    };

    let node_bytes = if version < 5 {
        std::mem::size_of::<NodeV4>()
    } else {
        std::mem::size_of::<GpuNode>()
    };
    let sizes = [
        node_bytes,
        std::mem::size_of::<GpuTriangle>(),
        std::mem::size_of::<GpuHeightfield>(),
        texels.bytes() as usize,
    ];
    let mut needed = Some(0u64);
    for k in 0..4 {
        needed = needed.and_then(|n| n.checked_add(counts[k].checked_mul(sizes[k] as u64)?));
    }
    let remaining = (bytes.len() - r.pos) as u64;
    let [n_nodes, n_triangles, n_leaves, n_texels] = counts;
    if n_nodes > crate::bvh::MAX_NODES as u64 {
        return Err(err(format!(
            "{n_nodes} nodes, more than the {} a traversal can name",
            crate::bvh::MAX_NODES
        )));
    }
    // The colour section follows the arrays; its length is checked below.
    let colour_section = if colour_channel {
        let colour_count = needed.and_then(|n| {
            let at = usize::try_from(n).ok()?.checked_add(r.pos)?;
            let b = bytes.get(at..at.checked_add(8)?)?;
            Some(u64::from_le_bytes(b.try_into().ok()?))
        });
        match colour_count {
            Some(c) => c
                .checked_mul(4)
                .and_then(|b| b.checked_add(8))
                .map(|b| (c, b)),
            // The arrays or the count itself are cut off: reported as truncation below.
            None => Some((0, 8)),
        }
    } else {
        Some((0, 0))
    };
    let Some((n_colours, colour_bytes)) = colour_section else {
        return Err(err(
            "the colour section's count is corrupt (more than 2^64 bytes)".to_string(),
        ));
    };
    let needed = needed.and_then(|n| n.checked_add(colour_bytes));
    if needed != Some(remaining) {
        let (needed, verdict) = match needed {
            Some(n) if n < remaining => (n.to_string(), "trailing bytes after the arrays"),
            Some(n) => (n.to_string(), "the file is truncated"),
            None => ("more than 2^64".to_string(), "the counts are corrupt"),
        };
        return Err(err(format!(
            "the header counts {n_nodes} nodes, {n_triangles} triangles, {n_leaves} leaves and \
             {n_texels} texels (and the colour section {n_colours} colours), which take \
             {needed} bytes, but {remaining} bytes follow the {header_bytes}-byte header: \
             {verdict}"
        )));
    }
    if colour_channel && n_colours != n_texels {
        return Err(err(format!(
            "the colour section has {n_colours} colours for {n_texels} texels (it must have \
             one per texel)"
        )));
    }

    // The lengths now match the file, so each count fits in memory (usize).
    let mut take = |n: u64, size: usize, what: &str| r.take(n as usize * size, what);
    let node_bytes = take(n_nodes, node_bytes, "the nodes")?;
    let nodes: Vec<GpuNode> = if version < 5 {
        let old: Vec<NodeV4> = records(node_bytes);
        let mut nodes = Vec::with_capacity(old.len());
        for (index, node) in old.iter().enumerate() {
            nodes.push(
                node.quantized()
                    .map_err(|why| err(format!("node {index}: {why}")))?,
            );
        }
        nodes
    } else {
        records(node_bytes)
    };
    let triangles = records(take(n_triangles, sizes[1], "the triangles")?);
    let heightfields = records(take(n_leaves, sizes[2], "the leaves")?);
    let texel_bytes = take(n_texels, sizes[3], "the texels")?;
    let texel_words: Vec<Texel> = match texels {
        TexelFormat::HeightNormal => records(texel_bytes),
        TexelFormat::Height => texel_bytes
            .chunks_exact(2)
            .map(|b| Texel(u32::from(u16::from_le_bytes([b[0], b[1]]))))
            .collect(),
    };
    let colours = if colour_channel {
        take(1, 8, "the colour count")?;
        Some(records(take(n_colours, 4, "the colours")?))
    } else {
        None
    };
    let mut rbvh = Rbvh {
        params,
        nodes,
        triangles: ExactTriangles::new(triangles),
        heightfields,
        atlas: Atlas {
            pitch,
            rows,
            packed_rows: [0, 0, narrow_rows],
            texels: texel_words,
        },
        bounds,
        depth,
        texel_size,
        stats,
        colours,
    };
    check(&rbvh, 0).map_err(|bad| err(bad.message))?;
    if version < 6 {
        unmark(&mut rbvh);
    }
    Ok(rbvh)
}

/// A node as versions 1–4 stored it: both children's boxes at full precision, 64 bytes.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct NodeV4 {
    a_min: [f32; 3],
    a_child: u32,
    a_max: [f32; 3],
    a_count: u32,
    b_min: [f32; 3],
    b_child: u32,
    b_max: [f32; 3],
    b_count: u32,
}
const _: () = assert!(std::mem::size_of::<NodeV4>() == 64);

impl NodeV4 {
    /// The node as this version stores it, its boxes quantized outward; an error for NaN boxes,
    /// which no grid holds.
    fn quantized(&self) -> std::result::Result<GpuNode, String> {
        let child = |min: [f32; 3], max: [f32; 3], child, count| {
            if min.iter().chain(&max).any(|x| x.is_nan()) {
                return Err(format!("a child box ({min:?}, {max:?}) contains NaN"));
            }
            Ok(ChildRef {
                bounds: Aabb {
                    min: min.into(),
                    max: max.into(),
                },
                child,
                count,
            })
        };
        Ok(GpuNode::new(
            child(self.a_min, self.a_max, self.a_child, self.a_count)?,
            child(self.b_min, self.b_max, self.b_child, self.b_count)?,
        ))
    }
}

/// Files before version 6 carry no mark of which heights were sampled from the surface
/// ([`Texel::is_sampled`]): their codes' parities are arbitrary. Each even code is made odd, so
/// that no skirt hangs under it and the RBVH traces as it was built (its heights within one code,
/// 1/65534 of the leaf's height range), taking the neighbouring code that keeps the sample inside
/// its leaf's box in the tree, so that the box still holds the surface. A sample that neither
/// keeps inside (one on a face of its box, in a leaf so tall that one code exceeds the box's
/// margin of 1/1024 texel: more than 64 texels from its lowest sample to its highest) keeps its
/// code, and a skirt may hang under it. Runs on a checked RBVH (indices and tiles in range).
fn unmark(r: &mut Rbvh) {
    let mut boxes = vec![r.bounds; r.heightfields.len()];
    for node in &r.nodes {
        for c in node.children() {
            if let Child::Heightfield(index) = c.kind() {
                boxes[index as usize] = c.bounds;
            }
        }
    }
    let atlas = &mut r.atlas;
    let pitch = atlas.pitch as usize;
    for (leaf, b) in r.heightfields.iter().zip(&boxes) {
        let grid = leaf.grid();
        for j in 0..leaf.res_v {
            for i in 0..leaf.res_u {
                let k = leaf.atlas_base as usize + j as usize * pitch + i as usize;
                let texel = atlas.texels[k];
                if !texel.is_sampled() {
                    continue;
                }
                let code = texel.height_code();
                let odd = [code.checked_add(1), code.checked_sub(1)]
                    .into_iter()
                    .flatten()
                    .find(|&c| c <= Texel::MAX_CODE && b.contains(grid.point(i, j, c)));
                if let Some(odd) = odd {
                    atlas.texels[k] = Texel((texel.0 & !0xFFFF) | u32::from(odd));
                }
            }
        }
    }
}
