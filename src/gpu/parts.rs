//! What uploading a structure for the trace shaders takes: the push constants they share
//! ([`TraceParams`]: the sizes each shader needs) and each structure's arrays in binding order,
//! checked against what the shaders can address (32-bit counts, the traversal stack).

use bytemuck::{Pod, Zeroable};

use crate::bvh::{Bvh, InstancedBvh, STACK_SIZE};
use crate::lod::Lod;
use crate::rbvh::{Rbvh, TexelFormat};
use crate::structure::{Kind, Structure};
use crate::{Error, Result};

/// Push constants of the trace shaders (`glsl/trace_params.glsl`, 112 bytes); the exact one
/// ignores the sizes after `tri_count`, the plain RBVH one the LOD sizes, all but the two-level
/// ones `instance_count`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct TraceParams {
    /// GLSL `pc.ray_offset`: ray index of this dispatch's first invocation (dispatches are split at
    /// `maxComputeWorkGroupCount`).
    pub ray_offset: u32,
    /// GLSL `ray_count`: rays in the whole batch; invocations at or past it do nothing.
    pub ray_count: u32,
    /// GLSL `flags`: bit 0 set for [`Query::Any`](super::Query::Any), clear for [`Query::Closest`](super::Query::Closest); no other bits.
    pub flags: u32,
    /// GLSL `node_count`: [`GpuNode`](crate::bvh::GpuNode)s of the tree; bounds the traversal loop.
    pub node_count: u32,
    /// GLSL `tri_count`: triangles of the BVH, or of the RBVH's triangle leaves (whose reads the
    /// RBVH traversal clamps to it).
    pub tri_count: u32,
    /// GLSL `heightfield_count`: height-field leaves of the RBVH; 0 for the exact BVH.
    pub heightfield_count: u32,
    /// GLSL `atlas_pitch`: texels per atlas row, a power of two; 0 for the exact BVH.
    pub atlas_pitch: u32,
    /// GLSL `atlas_len`: texels in the atlas; the blocks' height ranges follow their codes in the
    /// same buffer (then, with normals, the rank directory and the normals), and texel reads
    /// at or beyond it see holes.
    pub atlas_len: u32,
    /// GLSL `atlas_wide_len`: texels before the atlas's bands of packed heights
    /// ([`Atlas::wide_len`](crate::rbvh::Atlas::wide_len)), whose heights are 16-bit codes.
    pub atlas_wide_len: u32,
    /// GLSL `atlas_end12`: texels before the end of the atlas's band of 12-bit heights
    /// ([`Atlas::bands`](crate::rbvh::Atlas::bands)); the 10-bit band starts there.
    pub atlas_end12: u32,
    /// GLSL `atlas_end10`: texels before the end of the atlas's band of 10-bit heights; the
    /// 8-bit band starts there and ends at `atlas_len`.
    pub atlas_end10: u32,
    /// LOD records (one per node; 0 without LOD).
    pub lod_node_count: u32,
    /// LOD column words.
    pub lod_texel_len: u32,
    /// GLSL `instance_count`: instances of a two-level structure (exact BVH or RBVH); 0 for the
    /// others.
    pub instance_count: u32,
    /// Device addresses of the structure's arrays in binding order (nodes, triangles, height
    /// fields, atlas, LOD records, LOD columns, instances), read by the `_bda` shaders; zero
    /// where arrays are bound or absent.
    pub addresses: [u64; 7],
}
const _: () = assert!(std::mem::size_of::<TraceParams>() == 112);

/// Calls `f` with what uploading `structure` takes: the shader (its kind and texel format), the
/// sizes the shader needs, and the named arrays in binding order. Fails for a tree deeper than
/// the traversal's stack.
pub(super) fn with_parts<T>(
    structure: &Structure,
    f: impl FnOnce((Kind, TexelFormat), TraceParams, &[(&str, &[u8])]) -> Result<T>,
) -> Result<T> {
    let texels = match structure {
        Structure::RbvhInstanced(two) => two.params().texels,
        _ => structure
            .rbvh()
            .map_or(TexelFormat::default(), |rbvh| rbvh.params.texels),
    };
    let shader = (structure.kind(), texels);
    match structure {
        Structure::Exact(bvh) => {
            check_depth("bvh", bvh.depth)?;
            let (sizes, arrays) = exact_parts(bvh)?;
            f(shader, sizes, &arrays)
        }
        Structure::ExactInstanced(bvh) => {
            let (sizes, arrays) = instanced_parts(bvh)?;
            f(shader, sizes, &arrays)
        }
        Structure::Rbvh(rbvh) => {
            check_depth("rbvh", rbvh.depth)?;
            let words = rbvh.atlas_words();
            let (sizes, arrays) = rbvh_parts(rbvh, &words)?;
            f(shader, sizes, &arrays)
        }
        Structure::RbvhInstanced(two) => {
            let rbvh = two.parts();
            check_depth("rbvh", rbvh.depth)?;
            let words = rbvh.atlas_words();
            let (mut sizes, [nodes, tris, heightfields, atlas]) = rbvh_parts(rbvh, &words)?;
            sizes.instance_count = count32("rbvh", "instances", two.instances.len())?;
            let instances = ("RBVH instances", bytemuck::cast_slice(&two.instances));
            f(
                shader,
                sizes,
                &[nodes, tris, heightfields, atlas, instances],
            )
        }
        Structure::RbvhLod(rbvh, lod) => {
            check_depth("rbvh", rbvh.depth)?;
            let nodes = lod.annotated_nodes(rbvh);
            let words = rbvh.atlas_words();
            let (sizes, arrays) = lod_parts(rbvh, &words, lod, &nodes)?;
            f(shader, sizes, &arrays)
        }
    }
}

/// The shader sizes and the arrays (name, bytes) of the exact BVH, in binding order.
fn exact_parts(bvh: &Bvh) -> Result<(TraceParams, Arrays<'_, 2>)> {
    let sizes = TraceParams {
        node_count: count32("bvh", "nodes", bvh.nodes.len())?,
        tri_count: count32("bvh", "triangles", bvh.triangles.len())?,
        ..TraceParams::default()
    };
    let arrays = [
        ("BVH nodes", bytemuck::cast_slice(&bvh.nodes)),
        ("BVH triangles", bytemuck::cast_slice(&bvh.triangles)),
    ];
    Ok((sizes, arrays))
}

/// The shader sizes and the arrays (name, bytes) of a two-level exact BVH, in binding order. Its
/// builder keeps both levels' depths together within the stack
/// ([`InstancedBvh`](crate::bvh::InstancedBvh)); a changed one is checked here again.
fn instanced_parts(bvh: &InstancedBvh) -> Result<(TraceParams, Arrays<'_, 3>)> {
    let deepest = bvh.meshes.iter().map(|m| m.depth).max().unwrap_or(0);
    check_depth("bvh", bvh.top_depth + 1 + deepest)?;
    let count = |what: &str, n: usize| count32("bvh", what, n);
    let sizes = TraceParams {
        node_count: count("nodes", bvh.nodes.len())?,
        tri_count: count("triangles", bvh.triangles.len())?,
        instance_count: count("instances", bvh.instances.len())?,
        ..TraceParams::default()
    };
    let arrays = [
        ("BVH nodes (two levels)", bytemuck::cast_slice(&bvh.nodes)),
        ("BVH triangles", bytemuck::cast_slice(&bvh.triangles)),
        ("BVH instances", bytemuck::cast_slice(&bvh.instances)),
    ];
    Ok((sizes, arrays))
}

/// `n` (of `what`, in `structure`) as the shaders' 32-bit count, or an error saying it is more.
fn count32(structure: &str, what: &str, n: usize) -> Result<u32> {
    u32::try_from(n).map_err(|_| Error::param(structure, format!("{n} {what}: more than 2^32")))
}

/// What the shaders that read `rbvh`'s atlas (the trace, painting) are given of it, checked as
/// they count on: texels before the ends of its 16-, 12- and 10-bit bands
/// ([`crate::rbvh::Atlas::band_ends`]) and in all, each a 32-bit count; its pitch a power of two;
/// each packed band's codes ones its fields can hold (a hand-made or edited atlas may break any).
pub(super) fn atlas_sizes(rbvh: &Rbvh) -> Result<[u32; 4]> {
    if !rbvh.atlas.pitch.is_power_of_two() {
        return Err(Error::param(
            "rbvh",
            format!(
                "atlas pitch {}: not a power of two, which the shaders count on (the builder \
                 and the file reader make every pitch one)",
                rbvh.atlas.pitch
            ),
        ));
    }
    if let Some((k, code, bits)) = rbvh.atlas.first_code_off_its_band() {
        return Err(Error::param(
            "rbvh",
            format!(
                "atlas texel {k} lies in the {bits}-bit rows but has height code {code}, not a \
                 multiple of {} up to {} (a {bits}-bit code, all the device stores there)",
                crate::rbvh::Texel::step(bits),
                crate::rbvh::Texel::top(bits)
            ),
        ));
    }
    let count = |n: usize| count32("rbvh", "atlas texels", n);
    let [wide, end12, end10] = rbvh.atlas.band_ends();
    Ok([
        count(wide)?,
        count(end12)?,
        count(end10)?,
        count(rbvh.atlas.texels.len())?,
    ])
}

/// The shader sizes and the arrays (name, bytes) of an RBVH, in binding order; `atlas_words` is
/// its atlas as the shaders read it ([`crate::rbvh::Rbvh::atlas_words`]: height codes, the
/// blocks' height ranges, with normals the rank directory and the normals).
fn rbvh_parts<'a>(rbvh: &'a Rbvh, atlas_words: &'a [u32]) -> Result<(TraceParams, Arrays<'a, 4>)> {
    let count = |what: &str, n: usize| count32("rbvh", what, n);
    let [wide_len, end12, end10, atlas_len] = atlas_sizes(rbvh)?;
    let sizes = TraceParams {
        node_count: count("nodes", rbvh.nodes.len())?,
        tri_count: count("triangles", rbvh.triangles.len())?,
        heightfield_count: count("height fields", rbvh.heightfields.len())?,
        atlas_pitch: rbvh.atlas.pitch,
        atlas_len,
        atlas_wide_len: wide_len,
        atlas_end12: end12,
        atlas_end10: end10,
        ..TraceParams::default()
    };
    // The shaders index the atlas's words with 32 bits too.
    count(
        "atlas words (height codes, block ranges, rank directory and normals)",
        atlas_words.len(),
    )?;
    let arrays = [
        ("RBVH nodes", bytemuck::cast_slice(&rbvh.nodes)),
        (
            "RBVH triangles",
            bytemuck::cast_slice(rbvh.triangles.device_words()),
        ),
        (
            "RBVH height-field leaves",
            bytemuck::cast_slice(&rbvh.heightfields),
        ),
        ("RBVH atlas", bytemuck::cast_slice(atlas_words)),
    ];
    Ok((sizes, arrays))
}

/// Named byte arrays of a structure, in binding order.
type Arrays<'a, const N: usize> = [(&'static str, &'a [u8]); N];

/// The shader sizes and the arrays (name, bytes) of an RBVH traced with levels of detail: the
/// RBVH's, with `nodes` ([`Lod::annotated_nodes`]) for its nodes, then the LOD records and columns.
fn lod_parts<'a>(
    rbvh: &'a Rbvh,
    atlas_words: &'a [u32],
    lod: &'a Lod,
    nodes: &'a [crate::bvh::GpuNode],
) -> Result<(TraceParams, Arrays<'a, 6>)> {
    lod.check_for(rbvh)?;
    let (mut sizes, [_, tris, heightfields, atlas]) = rbvh_parts(rbvh, atlas_words)?;
    sizes.lod_node_count = lod.nodes.len() as u32;
    sizes.lod_texel_len = u32::try_from(lod.texels.len())
        .map_err(|_| Error::param("lod", "more than 2^32 column words"))?;
    let arrays = [
        ("RBVH nodes (LOD-annotated)", bytemuck::cast_slice(nodes)),
        tris,
        heightfields,
        atlas,
        ("LOD records", bytemuck::cast_slice(&lod.nodes)),
        ("LOD columns", bytemuck::cast_slice(&lod.texels)),
    ];
    Ok((sizes, arrays))
}

/// Our trees never exceed the traversal stack; a hand-made or corrupt one is refused up front.
fn check_depth(what: &str, depth: u32) -> Result<()> {
    if depth > STACK_SIZE {
        return Err(Error::param(
            what,
            format!("depth {depth} exceeds the {STACK_SIZE}-entry traversal stack"),
        ));
    }
    Ok(())
}
