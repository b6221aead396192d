//! RBVH files that this build does not write, for the tests of its readers, of `rbvh upgrade`
//! and for the fuzz target (each includes this file and uses some of it): files of the versions
//! before the sectioned format (`src/rbvh/file/legacy.rs` holds their layout), which no build
//! writes any more, and sectioned files laid out by hand.
#![allow(dead_code)]

use std::path::Path;

use rbvh::rbvh::file::{section_table, Section};
use rbvh::rbvh::{Rbvh, Refinement, Subdivision, TexelFormat};

/// Bytes before the arrays in version 12.
pub const V12_HEADER_BYTES: usize = 172;
/// The header of version 11, which ends before `params.exact_crease_deg`.
const V11_HEADER_BYTES: usize = 168;
/// The header of version 10, which ends before `params.exact_edge_fraction`.
const V10_HEADER_BYTES: usize = 164;
/// The header of version 9, which ends before `params.exact_from_texels`.
const V9_HEADER_BYTES: usize = 160;
/// The header of version 8, which ends before `params.exact_when_cheaper`.
const V8_HEADER_BYTES: usize = 156;
/// The header of version 7, which ends before `atlas.narrow_rows`.
const V7_HEADER_BYTES: usize = 152;
/// The header of versions 4–6, which ends before `object_rate`.
pub const V6_HEADER_BYTES: usize = 148;

/// `rbvh` as version 12 wrote it: its 172-byte header, then the arrays, which are the sections
/// of the current format byte for byte (nodes, triangles, leaves, texels), then with a colour
/// channel its count and its colours.
pub fn as_v12(rbvh: &Rbvh) -> Vec<u8> {
    let current = rbvh.to_bytes();
    let table = section_table(&current, Path::new("current.rbvh")).expect("a saved file's table");
    let section = |tag: &[u8; 4]| {
        table
            .iter()
            .find(|s| &s.tag == tag)
            .map(|s| &current[s.bytes()])
    };
    let p = &rbvh.params;
    let (refinement, value) = match p.refinement {
        Refinement::NormalCone { max_angle_deg } => (0, max_angle_deg),
        Refinement::ProjectedArea { min_ratio } => (1, min_ratio),
    };
    let subdivision = match p.subdivision {
        Subdivision::SpatialMedian => 0,
        Subdivision::AreaSah => 1,
    };
    let texels = match p.texels {
        TexelFormat::HeightNormal => 0,
        TexelFormat::Height => 1,
    };
    let colours = section(b"COLR");
    let [lo, hi] = [rbvh.bounds.min, rbvh.bounds.max].map(|v| v.to_array().map(f32::to_bits));
    let mut out = b"RBVHv\0\0\0".to_vec();
    put(
        &mut out,
        &[
            12,
            p.texels_per_diagonal.to_bits(),
            refinement,
            value.to_bits(),
        ],
    );
    put(
        &mut out,
        &[
            subdivision,
            u32::from(p.object_split),
            p.max_tile,
            p.min_leaf_texels.to_bits(),
            p.sampled_criterion_texels.to_bits(),
            texels,
            u32::from(colours.is_some()),
        ],
    );
    put(&mut out, &lo);
    put(&mut out, &hi);
    put(&mut out, &[rbvh.depth, rbvh.texel_size.to_bits()]);
    out.extend_from_slice(&rbvh.stats.build_ms.to_bits().to_le_bytes());
    put(
        &mut out,
        &[rbvh.stats.heightfield_leaves, rbvh.stats.triangle_leaves],
    );
    out.extend_from_slice(&rbvh.stats.tile_texels.to_le_bytes());
    put(&mut out, &[rbvh.atlas.pitch, rbvh.atlas.rows]);
    for count in [
        rbvh.nodes.len(),
        rbvh.triangles.len(),
        rbvh.heightfields.len(),
        rbvh.atlas.texels.len(),
    ] {
        out.extend_from_slice(&(count as u64).to_le_bytes());
    }
    put(
        &mut out,
        &[
            p.object_rate.to_bits(),
            rbvh.atlas.packed_rows[2],
            u32::from(p.exact_when_cheaper),
            p.exact_from_texels.to_bits(),
            p.exact_edge_fraction.to_bits(),
            p.exact_crease_deg.to_bits(),
        ],
    );
    assert_eq!(out.len(), V12_HEADER_BYTES);
    let texels = section(b"TEXN")
        .or(section(b"TEXH"))
        .expect("a texel section");
    for tag in [b"NODE", b"TRIS", b"LEAF"] {
        out.extend_from_slice(section(tag).expect("an array section"));
    }
    out.extend_from_slice(texels);
    if let Some(c) = colours {
        out.extend_from_slice(&(c.len() as u64 / 4).to_le_bytes());
        out.extend_from_slice(c);
    }
    out
}

/// `rbvh` as a file of version 12 or before loads it: those versions had no 12- or 10-bit rows,
/// so [`as_v12`] writes its 8-bit rows alone, and the rows of the others load as 16-bit ones
/// (their codes are 16-bit codes as well).
pub fn as_v12_loads(rbvh: &Rbvh) -> Rbvh {
    let mut r = rbvh.clone();
    r.atlas.packed_rows = [0, 0, rbvh.atlas.packed_rows[2]];
    r
}

/// Appends little-endian words.
fn put(out: &mut Vec<u8>, words: &[u32]) {
    for w in words {
        out.extend_from_slice(&w.to_le_bytes());
    }
}

/// `rbvh` as `version` (1–12) wrote it: the version 12 header without what later versions
/// appended (`exact_crease_deg` from 12, `exact_edge_fraction` from 11, `exact_from_texels` from
/// 10, `exact_when_cheaper` from 9, `narrow_rows` from 8, `object_rate` from 7), before version 5
/// each node in 64 bytes with its children's boxes at full precision (here the decoded ones),
/// and before version 4 without header bytes 40..52 (the texel format and colour flag: the
/// version's, so that version 2 must have colours and version 3 height-only texels).
pub fn as_version(rbvh: &Rbvh, version: u32) -> Vec<u8> {
    let mut bytes = as_v12(rbvh);
    let end = match version {
        ..=6 => V6_HEADER_BYTES,
        7 => V7_HEADER_BYTES,
        8 => V8_HEADER_BYTES,
        9 => V9_HEADER_BYTES,
        10 => V10_HEADER_BYTES,
        11 => V11_HEADER_BYTES,
        _ => V12_HEADER_BYTES,
    };
    let nodes_end = V12_HEADER_BYTES + 48 * rbvh.nodes.len();
    if version < 5 {
        let mut wide = Vec::with_capacity(64 * rbvh.nodes.len());
        for node in &rbvh.nodes {
            for c in node.children() {
                let [x, y, z] = c.bounds.min.to_array();
                let [u, v, w] = c.bounds.max.to_array();
                put(&mut wide, &[x.to_bits(), y.to_bits(), z.to_bits(), c.child]);
                put(&mut wide, &[u.to_bits(), v.to_bits(), w.to_bits(), c.count]);
            }
        }
        bytes.splice(V12_HEADER_BYTES..nodes_end, wide);
    }
    bytes.drain(end..V12_HEADER_BYTES);
    bytes[8..12].copy_from_slice(&version.to_le_bytes());
    if version < 4 {
        bytes.drain(40..52);
    }
    bytes
}

/// A current file's sections in table order: tag, version, flags and content.
pub type Parts = Vec<([u8; 4], u32, u32, Vec<u8>)>;

/// The sections of a current file.
pub fn parts(bytes: &[u8]) -> Parts {
    section_table(bytes, Path::new("parts.rbvh"))
        .expect("a current file's table")
        .iter()
        .map(|s: &Section| (s.tag, s.version, s.flags, bytes[s.bytes()].to_vec()))
        .collect()
}

/// A version 13 file of `parts`, laid out as the module docs of `src/rbvh/file` say: the
/// table, then each section in table order at the first multiple of 8 after the one before; a
/// `SUMS` part is made again, as a writer makes it, from the other parts as they are now.
pub fn assemble(parts: &Parts) -> Vec<u8> {
    let sums: Vec<u8> = parts
        .iter()
        .filter(|p| &p.0 != b"SUMS")
        .flat_map(|(tag, _, _, content)| {
            let mut record = tag.to_vec();
            record.extend(crc32fast::hash(content).to_le_bytes());
            record
        })
        .collect();
    let parts: Parts = parts
        .iter()
        .map(|p| match &p.0 {
            b"SUMS" => (p.0, p.1, p.2, sums.clone()),
            _ => p.clone(),
        })
        .collect();
    let aligned = |x: usize| x.div_ceil(8) * 8;
    let mut out = b"RBVHv\0\0\0".to_vec();
    put(&mut out, &[13, parts.len() as u32]);
    let mut offset = aligned(16 + 28 * parts.len());
    for (tag, version, flags, content) in &parts {
        out.extend_from_slice(tag);
        put(&mut out, &[*version, *flags]);
        out.extend_from_slice(&(offset as u64).to_le_bytes());
        out.extend_from_slice(&(content.len() as u64).to_le_bytes());
        offset = aligned(offset + content.len());
    }
    for (_, _, _, content) in &parts {
        out.resize(aligned(out.len()), 0);
        out.extend_from_slice(content);
    }
    out
}
