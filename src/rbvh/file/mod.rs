//! Saving and loading a built RBVH: one binary file holding everything [`Rbvh`] holds, so that a
//! build (minutes for a large scene) is done once and traced many times.
//!
//! The file is a table of typed, versioned sections (format version 13), so that what is still to
//! come (texel encodings) adds a section, or a version of one, instead of a version of the whole
//! file, and a reader skips what it may ignore and refuses what it may not. A two-level RBVH's
//! file (every mesh and its instances) is this file with two required sections more, `MESH` and
//! `PLAC` (`instanced.rs`), so that a flat reader refuses it by name.
//! Files of versions 1–12 (a fixed header, then the arrays) load through `legacy`, upgraded in
//! memory; `rbvh upgrade` rewrites one as version 13. Their colour channels may be painted, and
//! paint cannot be rebuilt from the scene, so every old file stays readable.
//!
//! All numbers are little-endian; floats are stored as their IEEE-754 bits, so every value (NaN
//! payloads and signed zeros included) round-trips exactly and `save → load → save` is
//! byte-identical. Encoding goes word by word through `to_le_bytes`/`from_le_bytes`, so the file
//! means the same on a big-endian host (where the conversion swaps) as on a little-endian one
//! (where it is a plain copy).
//!
//! | bytes | type | field |
//! |---|---|---|
//! | 0..8 | `[u8; 8]` | magic `RBVHv` followed by three zero bytes |
//! | 8..12 | u32 | format version: 13 (this build writes it; it reads 1–12 as well) |
//! | 12..16 | u32 | section count `S` |
//! | 16..16 + 28·`S` | `S` × 28 bytes | the section table, one entry per section (below) |
//! | then | | zero bytes up to the next multiple of 8, then the sections in any order, each starting at a multiple of 8, the gap before it (fewer than 8 bytes) zero, the file ending where the last one ends |
//!
//! A table entry:
//!
//! | bytes | type | field |
//! |---|---|---|
//! | 0..4 | `[u8; 4]` | tag: four printable ASCII characters, at most one section of each tag |
//! | 4..8 | u32 | the section's own version: its layout, which grows without the file's |
//! | 8..12 | u32 | flags: bit 0 = required (a reader that does not know this tag at this version must refuse the file); the other bits are 0 |
//! | 12..20 | u64 | byte offset of the section in the file |
//! | 20..28 | u64 | byte length of the section |
//!
//! A reader reads the sections it knows (tag and version) and skips the others where they are
//! optional; a required one it does not know refuses the file, naming it: a section that changes
//! what the others mean (a new texel encoding) is required, so that no older reader misreads it,
//! and one that only adds (a hint, a cache) is optional. The sections this build writes, in this
//! order (each array's records one after another, every 4-byte word little-endian):
//!
//! | tag | version | flags | content |
//! |---|---|---|---|
//! | `PARM` | 8 | required | the build parameters (below), 56 bytes; versions 1–7 load, the later fields taking the values that mean "rule off" |
//! | `HEAD` | 2 | required | the structure, 76 bytes: `bounds` (6 × f32: min x, y, z, max x, y, z), `depth` (u32), `texel_size` (f32), `stats.build_ms` (f64), `stats.heightfield_leaves`, `stats.triangle_leaves` (u32 each), `stats.tile_texels` (u64), `atlas.pitch`, `atlas.rows` (u32 each), `atlas.packed_rows` (3 × u32: the rows at the end whose heights are 12-, 10- and 8-bit codes, in that order); version 1 (68 bytes) ends with the 8-bit rows alone and loads with no 12- or 10-bit rows |
//! | `NODE` | 1 | required | `nodes`, 48 bytes each ([`crate::bvh::GpuNode`]) |
//! | `TRIS` | 1 | required | `triangles`, 48 bytes each ([`crate::bvh::GpuTriangle`], gathered: the device's indexed form is made from them, [`crate::rbvh::ExactTriangles`]) |
//! | `LEAF` | 2 | required | `heightfields`, 64 bytes each ([`super::GpuHeightfield`]); since version 2 a record's `axis_w` may carry its tile's plane (version 1 loads: its records have none) |
//! | `TEXN` or `TEXH` | 1 | required | `atlas.texels` row by row, exactly one of the two: `TEXN` 4 bytes each (height code and normal, [`super::Texel`]), `TEXH` 2 bytes each (the height code, for `params.texels` = `Height`). The tag is the texel format: a new encoding is a new tag |
//! | `COLR` | 1 | optional | with a colour channel only: `colours`, one packed RGBA8 word per texel (see [`crate::rgba`]); a height-only RBVH has none |
//! | `SUMS` | 1 | optional | last: for each section before it, its tag (4 bytes) and the CRC-32 (IEEE, u32) of its bytes, so that a damaged file is refused, naming the section; a file without it (written before it, or by another writer) loads unchecked |
//!
//! The counts are the lengths: a section's length must be a whole number of its records, and
//! the texels `pitch × rows` with a power-of-two pitch. `PARM` holds `params` but for `texels`
//! (which the texel section's tag says), one 4-byte word each, in the order they came: each
//! version appended what the one before lacked, and a section of an older version loads the
//! missing ones with the value a file without them has always meant.
//!
//! | `PARM` bytes | since version | field |
//! |---|---|---|
//! | 0..4 | 1 | `texels_per_diagonal` (f32) |
//! | 4..8, 8..12 | 1 | `refinement`: tag (0 = `NormalCone`, 1 = `ProjectedArea`), its value (f32: `max_angle_deg` or `min_ratio`) |
//! | 12..16 | 1 | `subdivision`: 0 = `SpatialMedian`, 1 = `AreaSah` |
//! | 16..20 | 1 | `object_split`: 0 or 1 |
//! | 20..24 | 1 | `max_tile` (u32) |
//! | 24..28 | 1 | `min_leaf_texels` (f32) |
//! | 28..32 | 2 | `sampled_criterion_texels` (f32; before: 0, the paper's rule alone) |
//! | 32..36 | 3 | `object_rate` (f32; before: 0, every texel the scene's) |
//! | 36..40 | 4 | `exact_when_cheaper`: 0 or 1 (before: 0, every triangle sampled where a height field holds it) |
//! | 40..44 | 5 | `exact_from_texels` (f32; before: 0, what 96 bytes buy) |
//! | 44..48 | 6 | `exact_edge_fraction` (f32; before: 0, none) |
//! | 48..52 | 7 | `exact_crease_deg` (f32; before: 0, none) |
//! | 52..56 | 8 | `view_rate` (f32; before: 0, none): the rate, not the view, which is the scene's camera at the build |
//!
//! Loading checks everything a tracer relies on, so a loaded RBVH is safe to trace and to upload:
//! the magic and version; the table (every section inside the file, after the table, none
//! overlapping another, no gap but the zero padding before an aligned start, no byte after the
//! last, no tag twice, flags known, every required section known, every section this build needs
//! present); each known section's length; the packed rows within `rows` with every texel of
//! those rows a hole or a code of its band's bits ([`Texel::fits`]: what the device can store
//! there); no NaN in the parameters, the bounds, the texel size or the build time; enum tags and
//! flags in range; every node's grid (a finite origin, exponents in range, reserved bits zero);
//! every node's children (inner: a node index, with count 0; triangle leaf: a range within
//! `triangles`; height-field leaf: an index into `heightfields`); every leaf's tile inside the atlas
//! with finite frame and a non-negative height scale; every triangle's scene index below 2³¹
//! (hit ids with bit 31 set are height-field hits, `u32::MAX` a miss), and its flags 0 or an
//! exact part of one of the leaves (`GpuTriangle::PART`), its padding 0. Every failure is an
//! [`Error::Parse`] naming the file, and in a sectioned file the section and its bytes. A
//! two-level RBVH's file gets these checks on every mesh's nodes and its own on the meshes and
//! placements (`instanced.rs`).

mod instanced;
mod legacy;
mod sections;

use std::io::Write;
use std::path::Path;

use bytemuck::Pod;

use super::child::Child;
use super::layout::{tile_fits, Atlas, GpuHeightfield, Texel, LEAF_BIT};
use super::params::{Refinement, Subdivision, TexelFormat};
use super::{Rbvh, RbvhStats};
use crate::bvh::GpuTriangle;
use crate::geom::Aabb;
use crate::io::write_atomically;
use crate::{Error, Result};

pub use sections::{section_table, Section, REQUIRED};

/// Whether the RBVH file at `path` holds a two-level RBVH (sections `MESH` and `PLAC`, read by
/// [`crate::rbvh::InstancedRbvh::load`]) rather than a flat one ([`Rbvh::load`]), from its
/// header and section table alone (16 bytes and 28 a section), so that a command picks the
/// loader without reading the file twice. False for a file that is no sectioned RBVH file (an
/// earlier version, other bytes, a table cut short before a `MESH` entry), which the flat loader
/// then refuses by name; a broken file whose table lists `MESH` is true, and the two-level loader
/// refuses it by name. An [`Error::Io`] where it cannot be opened or read.
pub fn holds_instances(path: &Path) -> Result<bool> {
    use std::io::Read;
    let mut file = crate::io::input::open(path)?;
    let mut head = Vec::with_capacity(sections::TABLE_AT);
    (&mut file)
        .take(sections::TABLE_AT as u64)
        .read_to_end(&mut head)
        .map_err(|e| Error::io(path, e))?;
    if head.len() < sections::TABLE_AT || file_version(&head, path).ok() != Some(VERSION) {
        return Ok(false);
    }
    let count = u32::from_le_bytes([head[12], head[13], head[14], head[15]]);
    // At most what the file holds, whatever the count says.
    let mut table = Vec::new();
    file.take(u64::from(count) * sections::ENTRY_BYTES as u64)
        .read_to_end(&mut table)
        .map_err(|e| Error::io(path, e))?;
    Ok(table
        .chunks_exact(sections::ENTRY_BYTES)
        .any(|entry| entry[..4] == sections::MESHES))
}

/// The first eight bytes of every RBVH file.
const MAGIC: [u8; 8] = *b"RBVHv\0\0\0";
/// The format version this build writes: the sectioned one.
pub const VERSION: u32 = 13;

impl Rbvh {
    /// Writes the sectioned binary file described in the module docs, atomically (through
    /// [`write_atomically`]): a failed save leaves `path` as it was and no temporary file behind.
    pub fn save(&self, path: &Path) -> Result<()> {
        if self.params.texels == TexelFormat::Height && self.colours.is_some() {
            return Err(Error::param(
                "rbvh",
                format!(
                    "{}: a height-only RBVH's file has no colour channel, and this one has \
                     colours (painted after the build?): build it with normals to keep them",
                    path.display()
                ),
            ));
        }
        let bytes = self.to_bytes();
        write_atomically(path, |w| w.write_all(&bytes))
    }

    /// Reads a file written by [`Rbvh::save`], of this version or any earlier one. A missing or
    /// unreadable file is [`Error::Io`]; every malformation (bad magic, unsupported version,
    /// truncation, a broken section table, lengths inconsistent with the contents, references
    /// out of range, NaN) is [`Error::Parse`] naming the file and the problem.
    pub fn load(path: &Path) -> Result<Rbvh> {
        let bytes = crate::io::input::read(path)?;
        Self::from_bytes(&bytes, path)
    }

    /// The bytes [`Rbvh::save`] writes: always [`VERSION`].
    pub fn to_bytes(&self) -> Vec<u8> {
        sections::write(self, Vec::new())
    }

    /// Whether the file carries the colour channel: a height-only RBVH has none (the builder
    /// bakes none, and [`Rbvh::save`] refuses one painted later).
    fn has_colour_section(&self) -> bool {
        self.params.texels == TexelFormat::HeightNormal && self.colours.is_some()
    }

    /// Parses the bytes of an RBVH file of any version; `name_for_errors` is the file named in
    /// every error. An older version is upgraded in memory as its module documents
    /// (`legacy`).
    pub fn from_bytes(bytes: &[u8], name_for_errors: &Path) -> Result<Rbvh> {
        let version = file_version(bytes, name_for_errors)?;
        if version < VERSION {
            legacy::read(bytes, version, name_for_errors)
        } else {
            sections::read(bytes, name_for_errors)
        }
    }
}

/// The format version of an RBVH file's bytes, after checking its magic; an
/// [`Error::Parse`] for a file that is no RBVH or of a version this build cannot read. `rbvh
/// upgrade` reports it.
pub fn file_version(bytes: &[u8], name_for_errors: &Path) -> Result<u32> {
    let head = &bytes[..bytes.len().min(MAGIC.len())];
    if head != &MAGIC[..head.len()] {
        return Err(Error::parse(
            name_for_errors,
            None,
            format!(
                "not an RBVH file: it starts with {head:02x?}, not the magic {MAGIC:02x?} (\"RBVHv\")"
            ),
        ));
    }
    let mut r = Reader::new(bytes, name_for_errors);
    r.take(MAGIC.len(), "the magic")?;
    let version = r.u32("the version")?;
    if !(1..=VERSION).contains(&version) {
        return Err(Error::parse(
            name_for_errors,
            None,
            format!("unsupported version {version} (this build reads versions 1 to {VERSION})"),
        ));
    }
    Ok(version)
}

/// Which part of an RBVH a failed check is about, so that a sectioned file's error names the
/// section holding it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Part {
    Params,
    Head,
    Nodes,
    Triangles,
    Leaves,
    Texels,
}

/// A check that failed: where ([`Part`] and, for an array, the record's index) and why.
struct Bad {
    part: Part,
    record: Option<usize>,
    message: String,
}

impl Bad {
    fn of(part: Part, message: String) -> Bad {
        Bad {
            part,
            record: None,
            message,
        }
    }

    fn at(part: Part, record: usize, message: String) -> Bad {
        Bad {
            part,
            record: Some(record),
            message,
        }
    }
}

/// Checks a parsed RBVH against everything a tracer relies on (the module docs' list, less what
/// the file's framing already guarantees), whatever version it was read from. Its first
/// `top_nodes` nodes are a two-level RBVH's top level, built on load rather than read (0 for a
/// flat RBVH): they are not checked, and no other node may name one of them.
fn check(r: &Rbvh, top_nodes: usize) -> std::result::Result<(), Bad> {
    let p = &r.params;
    let floats = [
        ("params.texels_per_diagonal", p.texels_per_diagonal),
        ("params.object_rate", p.object_rate),
        ("params.refinement value", refinement_value(p.refinement)),
        ("params.min_leaf_texels", p.min_leaf_texels),
        (
            "params.sampled_criterion_texels",
            p.sampled_criterion_texels,
        ),
        ("params.exact_from_texels", p.exact_from_texels),
        ("params.exact_edge_fraction", p.exact_edge_fraction),
        ("params.exact_crease_deg", p.exact_crease_deg),
        ("params.view_rate", p.view_rate),
    ];
    for (name, x) in floats {
        if x.is_nan() {
            return Err(Bad::of(Part::Params, format!("{name} is NaN")));
        }
    }
    let from = p.exact_from_texels;
    if !(from.is_finite() && from >= 0.0) || (from > 0.0 && !p.exact_when_cheaper) {
        return Err(Bad::of(
            Part::Params,
            format!(
                "params.exact_from_texels is {from}: a size in texels, at least 0, and 0 where \
                 exact_when_cheaper is off"
            ),
        ));
    }
    let edge = p.exact_edge_fraction;
    if !(0.0..=1.0).contains(&edge) || (edge > 0.0 && !p.exact_when_cheaper) {
        return Err(Bad::of(
            Part::Params,
            format!(
                "params.exact_edge_fraction is {edge}: a fraction of an object's diagonal, in \
                 0..=1, and 0 where exact_when_cheaper is off"
            ),
        ));
    }
    if !(0.0..=180.0).contains(&p.exact_crease_deg) {
        return Err(Bad::of(
            Part::Params,
            format!(
                "params.exact_crease_deg is {}: an angle in 0..=180 degrees",
                p.exact_crease_deg
            ),
        ));
    }
    let view = p.view_rate;
    if !(view == 0.0 || (1.0..=1.0e6).contains(&view)) {
        return Err(Bad::of(
            Part::Params,
            format!(
                "params.view_rate is {view}: 0 (none) or texels across the view's field, in \
                 1..=1e6"
            ),
        ));
    }
    if r.texel_size.is_nan() {
        return Err(Bad::of(Part::Head, "texel_size is NaN".to_string()));
    }
    // Infinite bounds are legitimate (the empty box of an empty scene); NaN is not.
    if r.bounds.min.is_nan() || r.bounds.max.is_nan() {
        return Err(Bad::of(
            Part::Head,
            format!("bounds {:?} contain NaN", r.bounds),
        ));
    }
    if r.stats.build_ms.is_nan() {
        return Err(Bad::of(Part::Head, "stats.build_ms is NaN".to_string()));
    }
    if r.nodes.len() > crate::bvh::MAX_NODES {
        return Err(Bad::of(
            Part::Nodes,
            format!(
                "{} nodes, more than the {} a traversal can name",
                r.nodes.len(),
                crate::bvh::MAX_NODES
            ),
        ));
    }
    check_atlas(&r.atlas)?;

    for (index, node) in r.nodes.iter().enumerate().skip(top_nodes) {
        if let Some(why) = node.malformation() {
            return Err(Bad::at(Part::Nodes, index, format!("node {index}: {why}")));
        }
        let children = [
            ('a', node.a_child, node.a_count),
            ('b', node.b_child, node.b_count),
        ];
        for (name, child, count) in children {
            check_child(child, count, r, top_nodes).map_err(|why| {
                Bad::at(
                    Part::Nodes,
                    index,
                    format!("node {index}, child {name}: {why}"),
                )
            })?;
        }
    }
    for (index, leaf) in r.heightfields.iter().enumerate() {
        check_leaf(leaf, &r.atlas).map_err(|why| {
            Bad::at(
                Part::Leaves,
                index,
                format!("height-field leaf {index}: {why}"),
            )
        })?;
    }
    check_triangles(r.triangles.gathered(), r.heightfields.len())
}

/// The atlas's shape: a power-of-two pitch, `pitch × rows` texels, packed rows within the rows
/// and holding only codes of their band's bits.
fn check_atlas(atlas: &Atlas) -> std::result::Result<(), Bad> {
    let (pitch, rows) = (atlas.pitch, atlas.rows);
    if !pitch.is_power_of_two() {
        return Err(Bad::of(
            Part::Head,
            format!(
                "the atlas pitch is {pitch} texels, not a power of two (the builder makes every \
                 pitch one, and the shaders count on it)"
            ),
        ));
    }
    let n_texels = atlas.texels.len() as u64;
    if n_texels != u64::from(pitch) * u64::from(rows) {
        return Err(Bad::of(
            Part::Texels,
            format!("the atlas has {n_texels} texels, not pitch × rows = {pitch} × {rows}"),
        ));
    }
    let packed: u64 = atlas.packed_rows.iter().map(|&r| u64::from(r)).sum();
    if packed > u64::from(rows) {
        return Err(Bad::of(
            Part::Head,
            format!(
                "atlas.packed_rows {:?} (12-, 10- and 8-bit rows) exceed its {rows} rows",
                atlas.packed_rows
            ),
        ));
    }
    if let Some((k, code, bits)) = atlas.first_code_off_its_band() {
        return Err(Bad::at(
            Part::Texels,
            k,
            format!(
                "atlas texel {k} lies in the {bits}-bit rows but has height code {code}, not a \
                 multiple of {} up to {} (a {bits}-bit code)",
                Texel::step(bits),
                Texel::top(bits)
            ),
        ));
    }
    Ok(())
}

/// Each triangle's flags (0, or an exact part of an existing leaf), padding (0) and scene index
/// (bit 31 clear: a triangle's `prim` is its hit id, bit 31 marks height-field hits and
/// `u32::MAX` a miss).
fn check_triangles(triangles: &[GpuTriangle], leaves: usize) -> std::result::Result<(), Bad> {
    for (index, t) in triangles.iter().enumerate() {
        let flags_ok = match t.part_leaf() {
            Some(leaf) => (leaf as usize) < leaves,
            None => t.flags == 0,
        };
        if !flags_ok || t.pad2 != 0 {
            return Err(Bad::at(
                Part::Triangles,
                index,
                format!(
                    "triangle {index} has flags {:#x} and padding {:#x}: neither 0 nor an exact \
                     part of one of the {leaves} height-field leaves",
                    t.flags, t.pad2
                ),
            ));
        }
    }
    if let Some((index, t)) = triangles
        .iter()
        .enumerate()
        .find(|(_, t)| t.prim & LEAF_BIT != 0)
    {
        return Err(Bad::at(
            Part::Triangles,
            index,
            format!(
                "triangle {index} has scene index {:#x}, which has bit 31 set: such ids are \
                 reserved for height-field hits and misses",
                t.prim
            ),
        ));
    }
    Ok(())
}

/// Checks one child reference against the layout rules (see [`super::child`]). An absent child's
/// index is not read, by the device or here.
fn check_child(
    child: u32,
    count: u32,
    r: &Rbvh,
    top_nodes: usize,
) -> std::result::Result<(), String> {
    match Child::decode(child, count) {
        Child::Inner(index) if (index as usize) < top_nodes => Err(format!(
            "node index {index} lies in the top level (nodes 0..{top_nodes}), which a mesh's \
             tree cannot enter"
        )),
        Child::Inner(_) if count != 0 => {
            Err(format!("inner node reference with count {count}, not 0"))
        }
        Child::Inner(index) if index as usize >= r.nodes.len() => Err(format!(
            "node index {index} is out of range (there are {} nodes)",
            r.nodes.len()
        )),
        Child::Heightfield(index) if index as usize >= r.heightfields.len() => Err(format!(
            "height-field leaf index {index} is out of range (there are {} leaves)",
            r.heightfields.len()
        )),
        Child::Triangles { first, count }
            if u64::from(first) + u64::from(count) > r.triangles.len() as u64 =>
        {
            Err(format!(
                "triangles {first}..{} are out of range (there are {})",
                u64::from(first) + u64::from(count),
                r.triangles.len()
            ))
        }
        Child::Inner(_) | Child::Absent | Child::Triangles { .. } | Child::Heightfield(_) => Ok(()),
    }
}

/// Checks that a leaf's frame is finite and its tile lies in the atlas.
fn check_leaf(leaf: &GpuHeightfield, atlas: &Atlas) -> std::result::Result<(), String> {
    let frame = [leaf.origin, leaf.axis_u, leaf.axis_v, leaf.axis_w];
    if frame.iter().flatten().any(|x| !x.is_finite()) || !leaf.h_scale.is_finite() {
        return Err("its frame (origin, axes, h_scale) is not finite".to_string());
    }
    if leaf.h_scale < 0.0 {
        return Err(format!("h_scale {} is negative", leaf.h_scale));
    }
    if !tile_fits(leaf, atlas) {
        return Err(format!(
            "its {}×{} tile at texel {} does not fit the {}×{} atlas (or lies across two of its bands)",
            leaf.res_u, leaf.res_v, leaf.atlas_base, atlas.pitch, atlas.rows
        ));
    }
    Ok(())
}

fn refinement_value(r: Refinement) -> f32 {
    match r {
        Refinement::NormalCone { max_angle_deg } => max_angle_deg,
        Refinement::ProjectedArea { min_ratio } => min_ratio,
    }
}

/// `params.refinement` from its tag and value, as every version stores it.
fn refinement(tag: u32, value: f32) -> std::result::Result<Refinement, String> {
    match tag {
        0 => Ok(Refinement::NormalCone {
            max_angle_deg: value,
        }),
        1 => Ok(Refinement::ProjectedArea { min_ratio: value }),
        _ => Err(format!(
            "params.refinement has tag {tag}; known are 0 (NormalCone) and 1 (ProjectedArea)"
        )),
    }
}

/// `params.refinement` as its tag and value.
fn refinement_words(r: Refinement) -> (u32, f32) {
    match r {
        Refinement::NormalCone { max_angle_deg } => (0, max_angle_deg),
        Refinement::ProjectedArea { min_ratio } => (1, min_ratio),
    }
}

/// `params.subdivision` from its tag, as every version stores it.
fn subdivision(tag: u32) -> std::result::Result<Subdivision, String> {
    match tag {
        0 => Ok(Subdivision::SpatialMedian),
        1 => Ok(Subdivision::AreaSah),
        _ => Err(format!(
            "params.subdivision has tag {tag}; known are 0 (SpatialMedian) and 1 (AreaSah)"
        )),
    }
}

fn subdivision_tag(s: Subdivision) -> u32 {
    match s {
        Subdivision::SpatialMedian => 0,
        Subdivision::AreaSah => 1,
    }
}

/// A flag stored as a word: 0 or 1, anything else an error naming it.
fn flag(name: &str, x: u32) -> std::result::Result<bool, String> {
    match x {
        0 => Ok(false),
        1 => Ok(true),
        _ => Err(format!("{name} is {x}, not 0 or 1")),
    }
}

fn put_u32(out: &mut Vec<u8>, x: u32) {
    out.extend_from_slice(&x.to_le_bytes());
}

fn put_f32(out: &mut Vec<u8>, x: f32) {
    put_u32(out, x.to_bits());
}

/// Appends records of 4-byte words (every packed type here is made of `u32`/`f32` fields), each
/// word little-endian.
fn put_records<T: Pod>(out: &mut Vec<u8>, records: &[T]) {
    for &word in bytemuck::cast_slice::<T, u32>(records) {
        put_u32(out, word);
    }
}

/// The records [`put_records`] wrote as `bytes`, whose length is a whole number of records.
fn records<T: Pod>(bytes: &[u8]) -> Vec<T> {
    let n = bytes.len() / std::mem::size_of::<T>();
    let mut out = vec![T::zeroed(); n];
    let words = bytemuck::cast_slice_mut::<T, u32>(&mut out);
    for (word, b) in words.iter_mut().zip(bytes.chunks_exact(4)) {
        *word = u32::from_le_bytes([b[0], b[1], b[2], b[3]]);
    }
    out
}

/// A cursor over the file's bytes whose every read names the field it wanted when the file ends.
struct Reader<'a> {
    bytes: &'a [u8],
    pos: usize,
    path: &'a Path,
}

impl Reader<'_> {
    /// The structure's bounds, depth, texel size and build statistics, in the order every
    /// version since 1 stores them (the v1–12 header from byte 52, the `HEAD` section from its
    /// start).
    fn structure_head(&mut self) -> Result<(Aabb, u32, f32, RbvhStats)> {
        let bounds = Aabb {
            min: [
                self.f32("bounds")?,
                self.f32("bounds")?,
                self.f32("bounds")?,
            ]
            .into(),
            max: [
                self.f32("bounds")?,
                self.f32("bounds")?,
                self.f32("bounds")?,
            ]
            .into(),
        };
        let depth = self.u32("depth")?;
        let texel_size = self.f32("texel_size")?;
        let stats = RbvhStats {
            build_ms: f64::from_bits(self.u64("stats.build_ms")?),
            heightfield_leaves: self.u32("stats.heightfield_leaves")?,
            triangle_leaves: self.u32("stats.triangle_leaves")?,
            tile_texels: self.u64("stats.tile_texels")?,
        };
        Ok((bounds, depth, texel_size, stats))
    }
}

impl<'a> Reader<'a> {
    fn new(bytes: &'a [u8], path: &'a Path) -> Reader<'a> {
        Reader {
            bytes,
            pos: 0,
            path,
        }
    }

    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8]> {
        let Some(slice) = self.bytes.get(self.pos..self.pos.saturating_add(n)) else {
            return Err(Error::parse(
                self.path,
                None,
                format!(
                    "truncated at byte {}: {what} needs bytes {}..{}",
                    self.bytes.len(),
                    self.pos,
                    self.pos.saturating_add(n)
                ),
            ));
        };
        self.pos += n;
        Ok(slice)
    }

    fn u32(&mut self, what: &str) -> Result<u32> {
        let b = self.take(4, what)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }

    fn f32(&mut self, what: &str) -> Result<f32> {
        self.u32(what).map(f32::from_bits)
    }

    fn u64(&mut self, what: &str) -> Result<u64> {
        let b = self.take(8, what)?;
        let mut a = [0u8; 8];
        a.copy_from_slice(b);
        Ok(u64::from_le_bytes(a))
    }
}
