//! The sectioned format (version 13, the module docs' tables): its writer, the section table's
//! reader and checks, and the reader of the sections this build knows.

use std::ops::Range;
use std::path::Path;

use super::{
    check, file_version, flag, put_f32, put_records, put_u32, records, refinement,
    refinement_words, subdivision, subdivision_tag, Part, Reader, MAGIC, VERSION,
};
use crate::bvh::{GpuNode, GpuTriangle};
use crate::rbvh::layout::{Atlas, GpuHeightfield, Texel};
use crate::rbvh::params::{RbvhParams, TexelFormat};
use crate::rbvh::{ExactTriangles, Rbvh};
use crate::{Error, Result};

/// Where the section table starts: after the magic, the version and the section count.
pub(super) const TABLE_AT: usize = 16;
/// Bytes of one table entry: tag, version, flags, offset (u64), length (u64).
pub(super) const ENTRY_BYTES: usize = 28;
/// Every section starts at a multiple of this many bytes.
const ALIGN: u64 = 8;
/// The flag of a section that a reader which does not know it must refuse the file for.
pub const REQUIRED: u32 = 1;

/// One entry of a version 13 file's section table, as [`section_table`] reads it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Section {
    /// Four printable ASCII characters naming what the section holds (`NODE`, `COLR`).
    pub tag: [u8; 4],
    /// The version of the section's own layout.
    pub version: u32,
    /// [`REQUIRED`] or 0.
    pub flags: u32,
    /// The section's first byte in the file.
    pub offset: u64,
    /// The section's length in bytes.
    pub length: u64,
}

impl Section {
    /// Whether a reader that does not know this section must refuse the file.
    pub fn required(&self) -> bool {
        self.flags & REQUIRED != 0
    }

    /// The tag as text (its bytes are printable ASCII once the table is checked).
    pub fn name(&self) -> String {
        self.tag.escape_ascii().to_string()
    }

    /// The section's bytes in the file (in range for an entry [`section_table`] returns).
    pub fn bytes(&self) -> Range<usize> {
        self.offset as usize..self.offset.saturating_add(self.length) as usize
    }

    /// How errors name it: tag, table entry and bytes.
    fn place(&self, entry: usize) -> String {
        format!(
            "section {} (table entry {entry}, bytes {}..{})",
            self.name(),
            self.offset,
            self.offset.saturating_add(self.length)
        )
    }
}

/// A section this build knows: its tag, the versions it reads, whether it is required, and the
/// bytes of one record of it (0: not an array).
struct Known {
    tag: [u8; 4],
    versions: Range<u32>,
    required: bool,
    record: usize,
}

/// The build parameters (`PARM`), at its current version [`PARAMS_VERSION`].
const PARAMS: [u8; 4] = *b"PARM";
const HEAD: [u8; 4] = *b"HEAD";
const NODES: [u8; 4] = *b"NODE";
const TRIANGLES: [u8; 4] = *b"TRIS";
const LEAVES: [u8; 4] = *b"LEAF";
/// Texels of height and normal, one word each.
const TEXELS_HEIGHT_NORMAL: [u8; 4] = *b"TEXN";
/// Texels of height alone, one 16-bit code each.
const TEXELS_HEIGHT: [u8; 4] = *b"TEXH";
const COLOURS: [u8; 4] = *b"COLR";
/// A two-level RBVH's meshes: where each mesh's tree and triangles lie in the arrays.
pub(super) const MESHES: [u8; 4] = *b"MESH";
/// A two-level RBVH's instances: each one's mesh and transform.
pub(super) const PLACEMENTS: [u8; 4] = *b"PLAC";
/// Bytes of a `MESH` record: `root`, `nodes`, `first_triangle`, `triangles`, `depth` (u32 each),
/// the mesh's texel (f32), its bounds (6 × f32).
pub(super) const MESH_BYTES: usize = 48;
/// Bytes of a `PLAC` record: the mesh (u32), then the transform's first three rows (12 × f32;
/// the last row is `0 0 0 1`).
pub(super) const PLACEMENT_BYTES: usize = 52;
/// Each other section's checksum, so that a file damaged on a disk or on its way (a bit flipped
/// in a node or a leaf, which no structural check sees) is refused rather than traced.
const CHECKSUMS: [u8; 4] = *b"SUMS";
/// Bytes of a `SUMS` record: the tag of the section it checks, its CRC-32 (u32).
const CHECKSUM_BYTES: usize = 8;

/// The version of `PARM` this build writes: 8, for the fields of the module docs' table.
const PARAMS_VERSION: u32 = 8;
/// Words of `PARM` at each version, from 1: each version appended one parameter (the first had
/// the paper's, `refinement` taking two words).
const PARAMS_WORDS: [usize; PARAMS_VERSION as usize] = [7, 8, 9, 10, 11, 12, 13, 14];
/// The version of `LEAF` this build writes: 2, whose records may carry their tile's plane in
/// `axis_w` ([`GpuHeightfield::grid`] reads it back); version 1's never do, and read the same. A
/// reader of version 1 alone refuses version 2, whose planes it would not undo where it places
/// samples in the world (painting, seam rays, level of detail).
const LEAVES_VERSION: u32 = 2;
/// The version of `HEAD` this build writes: 2, whose atlas has rows of 12-, 10- and 8-bit
/// heights ([`crate::rbvh::Atlas::packed_rows`]); version 1 has 8-bit rows alone, and reads
/// the same.
const HEAD_VERSION: u32 = 2;
/// Bytes of `HEAD` at each version, from 1.
const HEAD_BYTES: [usize; HEAD_VERSION as usize] = [68, 76];

/// Every section this build knows, in the order it writes them.
const KNOWN: [Known; 11] = [
    Known {
        tag: PARAMS,
        versions: 1..PARAMS_VERSION + 1,
        required: true,
        record: 0,
    },
    Known {
        tag: HEAD,
        versions: 1..HEAD_VERSION + 1,
        required: true,
        record: 0,
    },
    Known {
        tag: NODES,
        versions: 1..2,
        required: true,
        record: std::mem::size_of::<GpuNode>(),
    },
    Known {
        tag: TRIANGLES,
        versions: 1..2,
        required: true,
        record: std::mem::size_of::<GpuTriangle>(),
    },
    Known {
        tag: LEAVES,
        versions: 1..LEAVES_VERSION + 1,
        required: true,
        record: std::mem::size_of::<GpuHeightfield>(),
    },
    Known {
        tag: TEXELS_HEIGHT_NORMAL,
        versions: 1..2,
        required: true,
        record: 4,
    },
    Known {
        tag: TEXELS_HEIGHT,
        versions: 1..2,
        required: true,
        record: 2,
    },
    Known {
        tag: COLOURS,
        versions: 1..2,
        required: false,
        record: 4,
    },
    Known {
        tag: MESHES,
        versions: 1..2,
        required: true,
        record: MESH_BYTES,
    },
    Known {
        tag: PLACEMENTS,
        versions: 1..2,
        required: true,
        record: PLACEMENT_BYTES,
    },
    // Optional: a reader that does not know it reads the file as before, unchecked.
    Known {
        tag: CHECKSUMS,
        versions: 1..2,
        required: false,
        record: CHECKSUM_BYTES,
    },
];

/// The index in [`KNOWN`] of `tag`.
fn known(tag: [u8; 4]) -> usize {
    KNOWN
        .iter()
        .position(|k| k.tag == tag)
        .expect("a known tag")
}

/// `x` rounded up to a multiple of [`ALIGN`].
fn aligned(x: u64) -> u64 {
    x.div_ceil(ALIGN) * ALIGN
}

/// Writes one section's content.
pub(super) type Put<'a> = Box<dyn Fn(&mut Vec<u8>) + 'a>;

/// The bytes of `r` as a version 13 file, with the sections of `extra` (tag, length, content:
/// a two-level RBVH's meshes and placements) after its own.
pub(super) fn write<'a>(r: &'a Rbvh, extra: Vec<([u8; 4], usize, Put<'a>)>) -> Vec<u8> {
    let texels: ([u8; 4], Put) = match r.params.texels {
        TexelFormat::HeightNormal => (
            TEXELS_HEIGHT_NORMAL,
            Box::new(|out| put_records(out, &r.atlas.texels)),
        ),
        TexelFormat::Height => (
            TEXELS_HEIGHT,
            Box::new(|out| {
                for t in &r.atlas.texels {
                    out.extend_from_slice(&t.height_code().to_le_bytes());
                }
            }),
        ),
    };
    let texel_bytes = r.atlas.texels.len() * r.params.texels.bytes() as usize;
    // (tag, length, content)
    let mut sections: Vec<([u8; 4], usize, Put)> = vec![
        (
            PARAMS,
            4 * PARAMS_WORDS[PARAMS_WORDS.len() - 1],
            Box::new(|out| put_params(out, &r.params)),
        ),
        (
            HEAD,
            HEAD_BYTES[HEAD_BYTES.len() - 1],
            Box::new(|out| put_head(out, r)),
        ),
        (
            NODES,
            std::mem::size_of_val(r.nodes.as_slice()),
            Box::new(|out| put_records(out, &r.nodes)),
        ),
        (
            TRIANGLES,
            std::mem::size_of_val(r.triangles.gathered()),
            Box::new(|out| put_records(out, r.triangles.gathered())),
        ),
        (
            LEAVES,
            std::mem::size_of_val(r.heightfields.as_slice()),
            Box::new(|out| put_records(out, &r.heightfields)),
        ),
        (texels.0, texel_bytes, texels.1),
    ];
    if let (true, Some(colours)) = (r.has_colour_section(), &r.colours) {
        sections.push((
            COLOURS,
            std::mem::size_of_val(colours.as_slice()),
            Box::new(|out| put_records(out, colours)),
        ));
    }
    sections.extend(extra);
    // Written last, as zeros, and filled once every section it checks is in place.
    let checked = sections.len();
    sections.push((
        CHECKSUMS,
        CHECKSUM_BYTES * checked,
        Box::new(move |out| out.resize(out.len() + CHECKSUM_BYTES * checked, 0)),
    ));

    let table_end = (TABLE_AT + ENTRY_BYTES * sections.len()) as u64;
    let mut offset = aligned(table_end);
    let total = sections
        .iter()
        .fold(offset, |end, s| aligned(end) + s.1 as u64);
    let mut out = Vec::with_capacity(total as usize);
    out.extend_from_slice(&MAGIC);
    put_u32(&mut out, VERSION);
    put_u32(&mut out, sections.len() as u32);
    for (tag, length, _) in &sections {
        let k = &KNOWN[known(*tag)];
        out.extend_from_slice(tag);
        put_u32(&mut out, k.versions.end - 1);
        put_u32(&mut out, if k.required { REQUIRED } else { 0 });
        out.extend_from_slice(&offset.to_le_bytes());
        out.extend_from_slice(&(*length as u64).to_le_bytes());
        offset = aligned(offset + *length as u64);
    }
    let mut ranges = Vec::with_capacity(sections.len());
    for (tag, length, put) in &sections {
        out.resize(aligned(out.len() as u64) as usize, 0);
        let start = out.len();
        put(&mut out);
        debug_assert_eq!(out.len() - start, *length, "{}", tag.escape_ascii());
        ranges.push(start..out.len());
    }
    debug_assert_eq!(out.len() as u64, total);
    let sums = ranges[checked].start;
    for (k, ((tag, _, _), range)) in sections.iter().zip(&ranges).take(checked).enumerate() {
        let at = sums + CHECKSUM_BYTES * k;
        let crc = crc32fast::hash(&out[range.clone()]);
        out[at..at + 4].copy_from_slice(tag);
        out[at + 4..at + 8].copy_from_slice(&crc.to_le_bytes());
    }
    out
}

/// Refuses a file whose `SUMS` (the section at `sums`) names a section it lacks or a CRC-32 that
/// is not its bytes': the file was damaged after it was written. Sections without a checksum
/// (an optional one an older writer added) are not checked.
fn check_sums(bytes: &[u8], table: &[Section], sums: (usize, Section), path: &Path) -> Result<()> {
    let (entry, s) = sums;
    for record in bytes[s.bytes()].chunks_exact(CHECKSUM_BYTES) {
        let tag: [u8; 4] = [record[0], record[1], record[2], record[3]];
        let stored = u32::from_le_bytes([record[4], record[5], record[6], record[7]]);
        let Some((k, checked)) = table.iter().enumerate().find(|(_, c)| c.tag == tag) else {
            return Err(Error::parse(
                path,
                None,
                format!(
                    "{}: a checksum of section {}, which the file does not have: the file is \
                     damaged",
                    s.place(entry),
                    tag.escape_ascii()
                ),
            ));
        };
        let computed = crc32fast::hash(&bytes[checked.bytes()]);
        if computed != stored {
            return Err(Error::parse(
                path,
                None,
                format!(
                    "{}: its bytes' CRC-32 is {computed:08x}, not the {stored:08x} it was written \
                     with: the file is damaged",
                    checked.place(k)
                ),
            ));
        }
    }
    Ok(())
}

/// `PARM` at [`PARAMS_VERSION`].
fn put_params(out: &mut Vec<u8>, p: &RbvhParams) {
    put_f32(out, p.texels_per_diagonal);
    let (tag, value) = refinement_words(p.refinement);
    put_u32(out, tag);
    put_f32(out, value);
    put_u32(out, subdivision_tag(p.subdivision));
    put_u32(out, u32::from(p.object_split));
    put_u32(out, p.max_tile);
    put_f32(out, p.min_leaf_texels);
    put_f32(out, p.sampled_criterion_texels);
    put_f32(out, p.object_rate);
    put_u32(out, u32::from(p.exact_when_cheaper));
    put_f32(out, p.exact_from_texels);
    put_f32(out, p.exact_edge_fraction);
    put_f32(out, p.exact_crease_deg);
    put_f32(out, p.view_rate);
}

/// `HEAD`.
fn put_head(out: &mut Vec<u8>, r: &Rbvh) {
    for x in r
        .bounds
        .min
        .to_array()
        .into_iter()
        .chain(r.bounds.max.to_array())
    {
        put_f32(out, x);
    }
    put_u32(out, r.depth);
    put_f32(out, r.texel_size);
    out.extend_from_slice(&r.stats.build_ms.to_bits().to_le_bytes());
    put_u32(out, r.stats.heightfield_leaves);
    put_u32(out, r.stats.triangle_leaves);
    out.extend_from_slice(&r.stats.tile_texels.to_le_bytes());
    put_u32(out, r.atlas.pitch);
    put_u32(out, r.atlas.rows);
    for rows in r.atlas.packed_rows {
        put_u32(out, rows);
    }
}

/// The section table of a version 13 file, checked (module docs): every section inside the
/// file after the table, aligned, none overlapping another, the gaps before them zero and
/// shorter than the alignment, nothing after the last, no tag twice, no flag but
/// [`REQUIRED`]. What the sections hold is not read; [`Rbvh::from_bytes`] does that. An
/// [`Error::Parse`] naming `name_for_errors` for a file that is not version 13 or whose table
/// is broken.
pub fn section_table(bytes: &[u8], name_for_errors: &Path) -> Result<Vec<Section>> {
    let path = name_for_errors;
    let err = |message: String| Error::parse(path, None, message);
    let version = file_version(bytes, path)?;
    if version != VERSION {
        return Err(err(format!(
            "version {version} has no section table (version {VERSION} is the first with one)"
        )));
    }
    let mut r = Reader::new(bytes, path);
    r.take(TABLE_AT - 4, "the magic and version")?;
    let count = r.u32("the section count")?;
    let table_end = TABLE_AT as u64 + ENTRY_BYTES as u64 * u64::from(count);
    if table_end > bytes.len() as u64 {
        return Err(err(format!(
            "truncated at byte {}: the table of {count} sections needs bytes {TABLE_AT}..{table_end}",
            bytes.len()
        )));
    }
    let mut table = Vec::with_capacity(count as usize);
    for entry in 0..count as usize {
        let mut tag = [0; 4];
        tag.copy_from_slice(r.take(4, "a section tag")?);
        let s = Section {
            tag,
            version: r.u32("a section version")?,
            flags: r.u32("a section's flags")?,
            offset: r.u64("a section offset")?,
            length: r.u64("a section length")?,
        };
        if !tag.iter().all(u8::is_ascii_graphic) {
            return Err(err(format!(
                "table entry {entry}: the tag {tag:02x?} is not four printable ASCII characters"
            )));
        }
        if let Some(first) = table.iter().position(|t: &Section| t.tag == tag) {
            return Err(err(format!(
                "{}: a second section {} (the first is table entry {first})",
                s.place(entry),
                s.name()
            )));
        }
        if s.flags & !REQUIRED != 0 {
            return Err(err(format!(
                "{}: flags {:#x}, of which only bit 0 (required) is defined",
                s.place(entry),
                s.flags
            )));
        }
        match s.offset.checked_add(s.length) {
            Some(end) if end <= bytes.len() as u64 => {}
            _ => {
                return Err(err(format!(
                    "{}: truncated, the file has {} bytes",
                    s.place(entry),
                    bytes.len()
                )))
            }
        }
        table.push(s);
    }

    // In file order, each section starts at the first aligned byte after the one before (the
    // table for the first), and the file ends where the last one does. An empty section comes
    // before a section at its offset, wherever the table lists it.
    let mut order: Vec<usize> = (0..table.len()).collect();
    order.sort_by_key(|&k| (table[k].offset, table[k].length, k));
    let (mut end, mut before) = (
        table_end,
        format!("the section table (bytes 0..{table_end})"),
    );
    for &k in &order {
        let s = &table[k];
        let start = aligned(end);
        if s.offset < end {
            return Err(err(format!("{}: overlaps {before}", s.place(k))));
        }
        if s.offset != start {
            return Err(err(format!(
                "{}: a gap after {before}; the section must start at byte {start}, the first \
                 multiple of {ALIGN} after it",
                s.place(k)
            )));
        }
        if let Some(at) = (end..start).find(|&at| bytes[at as usize] != 0) {
            return Err(err(format!(
                "{}: padding byte {at} before it is {:#04x}, not 0",
                s.place(k),
                bytes[at as usize]
            )));
        }
        end = s.offset + s.length;
        before = s.place(k);
    }
    if end != bytes.len() as u64 {
        return Err(err(format!(
            "{} trailing bytes after {before}, which ends at byte {end}",
            bytes.len() as u64 - end
        )));
    }
    Ok(table)
}

/// Parses a version 13 file of a flat RBVH (its magic and version already checked); a file of
/// a two-level RBVH is refused, naming what reads it.
pub(super) fn read(bytes: &[u8], path: &Path) -> Result<Rbvh> {
    let parsed = parse(bytes, path)?;
    if let (Some(meshes), Some(placements)) = (parsed.meshes, parsed.placements) {
        return Err(Error::parse(
            path,
            None,
            format!(
                "a two-level RBVH ({} meshes, {} instances: sections MESH and PLAC), not a flat \
                 one: load it with InstancedRbvh::load, or trace it with the scene of instances \
                 it was built from",
                meshes.len() / MESH_BYTES,
                placements.len() / PLACEMENT_BYTES
            ),
        ));
    }
    parsed.checked(0)
}

/// A version 13 file's sections read into an RBVH not checked yet ([`Parsed::checked`]), with
/// a two-level RBVH's meshes and placements as their bytes.
pub(super) struct Parsed<'a> {
    rbvh: Rbvh,
    found: [Option<(usize, Section)>; KNOWN.len()],
    path: &'a Path,
    /// The file, and its section table: what `SUMS` is checked against, last.
    bytes: &'a [u8],
    table: Vec<Section>,
    /// `MESH`'s bytes, if the file has it.
    pub(super) meshes: Option<&'a [u8]>,
    /// `PLAC`'s bytes, if the file has it.
    pub(super) placements: Option<&'a [u8]>,
}

impl Parsed<'_> {
    /// The RBVH read, not checked yet.
    pub(super) fn rbvh(&self) -> &Rbvh {
        &self.rbvh
    }

    /// An error naming the file and the section `tag` (read by now), for what is wrong in it.
    pub(super) fn error_in(&self, tag: [u8; 4], message: String) -> Error {
        let (entry, s) = found_of(&self.found, tag);
        Error::parse(self.path, None, format!("{}: {message}", s.place(entry)))
    }

    /// The RBVH, checked as the module docs list (its first `top_nodes` nodes, a two-level
    /// RBVH's top level built on load, skipped), every failure naming its section and bytes,
    /// then its sections against their checksums.
    pub(super) fn checked(self, top_nodes: usize) -> Result<Rbvh> {
        let (found, path) = (self.found, self.path);
        let err = |message: String| Error::parse(path, None, message);
        check(&self.rbvh, top_nodes).map_err(|bad| {
            let (entry, s) = match bad.part {
                Part::Params => found_of(&found, PARAMS),
                Part::Head => found_of(&found, HEAD),
                Part::Nodes => found_of(&found, NODES),
                Part::Triangles => found_of(&found, TRIANGLES),
                Part::Leaves => found_of(&found, LEAVES),
                Part::Texels => found[known(TEXELS_HEIGHT_NORMAL)]
                    .or(found[known(TEXELS_HEIGHT)])
                    .expect("a texel section read"),
            };
            let place = match bad.record {
                Some(index) => {
                    let record = KNOWN[known(s.tag)].record as u64;
                    format!(
                        "section {} (table entry {entry}) at byte {}",
                        s.name(),
                        s.offset + record * index as u64
                    )
                }
                None => s.place(entry),
            };
            err(format!("{place}: {}", bad.message))
        })?;
        // Last, so that a file whose contents are wrong as written is told what is wrong with
        // them, and one that passes every check but its bytes changed since is told that.
        if let Some(sums) = found[known(CHECKSUMS)] {
            check_sums(self.bytes, &self.table, sums, path)?;
        }
        Ok(self.rbvh)
    }
}

/// Reads a version 13 file's sections (its magic and version already checked) into a
/// [`Parsed`]: every framing check made, the contents not yet checked.
pub(super) fn parse<'a>(bytes: &'a [u8], path: &'a Path) -> Result<Parsed<'a>> {
    let err = |message: String| Error::parse(path, None, message);
    let table = section_table(bytes, path)?;
    // The entry and section of each known tag present.
    let mut found: [Option<(usize, Section)>; KNOWN.len()] = [None; KNOWN.len()];
    for (entry, s) in table.iter().enumerate() {
        let k = KNOWN.iter().position(|k| k.tag == s.tag);
        match k.filter(|&k| KNOWN[k].versions.contains(&s.version)) {
            Some(k) => found[k] = Some((entry, *s)),
            None if s.required() => {
                let what = match k {
                    Some(k) => format!(
                        "its version {}: it reads {}..={}",
                        s.version,
                        KNOWN[k].versions.start,
                        KNOWN[k].versions.end - 1
                    ),
                    None => "its tag".to_string(),
                };
                return Err(err(format!(
                    "{} is required, and this build does not know {what} (a newer rbvh wrote \
                     it: read it with that one)",
                    s.place(entry)
                )));
            }
            // An optional section this build does not know: skipped.
            None => {}
        }
    }
    for (k, known) in KNOWN.iter().enumerate() {
        let (Some((entry, s)), true) = (found[k], known.record > 0) else {
            continue;
        };
        if s.length % known.record as u64 != 0 {
            return Err(err(format!(
                "{}: {} bytes, not a whole number of {}-byte records",
                s.place(entry),
                s.length,
                known.record
            )));
        }
    }

    let section = |tag: [u8; 4]| found[known(tag)];
    let need = |tag: [u8; 4]| {
        section(tag).ok_or_else(|| {
            err(format!(
                "no section {} of a version this build reads (the file's sections: {})",
                tag.escape_ascii(),
                names(&table)
            ))
        })
    };
    let (params_entry, params_section) = need(PARAMS)?;
    let (head_entry, head) = need(HEAD)?;
    let (texels, texel_section) = match (section(TEXELS_HEIGHT_NORMAL), section(TEXELS_HEIGHT)) {
        (Some(s), None) => (TexelFormat::HeightNormal, s),
        (None, Some(s)) => (TexelFormat::Height, s),
        _ => {
            return Err(err(format!(
                "not one texel section (TEXN or TEXH) but {}: the file's sections are {}",
                if section(TEXELS_HEIGHT).is_some() {
                    "both"
                } else {
                    "neither"
                },
                names(&table)
            )))
        }
    };
    let colours = section(COLOURS);
    if let (Some((entry, s)), TexelFormat::Height) = (colours, texels) {
        return Err(err(format!(
            "{}: a height-only RBVH (texels TEXH) has no colour channel",
            s.place(entry)
        )));
    }

    let params = read_params(
        &bytes[params_section.bytes()],
        params_section.version,
        texels,
    )
    .map_err(|why| err(format!("{}: {why}", params_section.place(params_entry))))?;
    let head_bytes = &bytes[head.bytes()];
    let head_len = HEAD_BYTES[head.version as usize - 1];
    if head_bytes.len() != head_len {
        return Err(err(format!(
            "{}: {} bytes, not the {head_len} of its version",
            head.place(head_entry),
            head_bytes.len()
        )));
    }
    let mut h = Reader::new(head_bytes, path);
    let (bounds, depth, texel_size, stats) = h.structure_head()?;
    let (pitch, rows) = (h.u32("atlas.pitch")?, h.u32("atlas.rows")?);
    let packed_rows = if head.version >= 2 {
        [
            h.u32("atlas.packed_rows[0]")?,
            h.u32("atlas.packed_rows[1]")?,
            h.u32("atlas.packed_rows[2]")?,
        ]
    } else {
        [0, 0, h.u32("atlas.narrow_rows")?]
    };

    let array = |tag| need(tag).map(|(_, s)| &bytes[s.bytes()]);
    let texel_bytes = &bytes[texel_section.1.bytes()];
    let texel_words: Vec<Texel> = match texels {
        TexelFormat::HeightNormal => records(texel_bytes),
        TexelFormat::Height => texel_bytes
            .chunks_exact(2)
            .map(|b| Texel(u32::from(u16::from_le_bytes([b[0], b[1]]))))
            .collect(),
    };
    let colours = match colours {
        Some((entry, s)) if s.length / 4 != texel_words.len() as u64 => {
            return Err(err(format!(
                "{}: {} colours for {} texels (it must have one per texel)",
                s.place(entry),
                s.length / 4,
                texel_words.len()
            )))
        }
        Some((_, s)) => Some(records(&bytes[s.bytes()])),
        None => None,
    };
    let (meshes, placements) = match (section(MESHES), section(PLACEMENTS)) {
        (Some(m), Some(p)) => (Some(&bytes[m.1.bytes()]), Some(&bytes[p.1.bytes()])),
        (None, None) => (None, None),
        _ => {
            return Err(err(format!(
                "a two-level RBVH has both sections MESH and PLAC, a flat one neither; the \
                 file's sections are {}",
                names(&table)
            )))
        }
    };
    let rbvh = Rbvh {
        params,
        nodes: records(array(NODES)?),
        triangles: ExactTriangles::new(records(array(TRIANGLES)?)),
        heightfields: records(array(LEAVES)?),
        atlas: Atlas {
            pitch,
            rows,
            packed_rows,
            texels: texel_words,
        },
        bounds,
        depth,
        texel_size,
        stats,
        colours,
    };
    Ok(Parsed {
        rbvh,
        found,
        path,
        bytes,
        table,
        meshes,
        placements,
    })
}

/// The entry and section of a known tag that [`parse`] found (every array's is, by then).
fn found_of(found: &[Option<(usize, Section)>], tag: [u8; 4]) -> (usize, Section) {
    found[known(tag)].expect("a section read")
}

/// The tags of `table`, comma-separated, for messages.
fn names(table: &[Section]) -> String {
    if table.is_empty() {
        return "none".to_string();
    }
    table
        .iter()
        .map(|s| format!("{} v{}", s.name(), s.version))
        .collect::<Vec<_>>()
        .join(", ")
}

/// `PARM` of `version` (1..=[`PARAMS_VERSION`]); fields after its last take the value a file
/// without them has always meant (the rule off).
fn read_params(
    bytes: &[u8],
    version: u32,
    texels: TexelFormat,
) -> std::result::Result<RbvhParams, String> {
    let words_of = PARAMS_WORDS[version as usize - 1];
    if bytes.len() != 4 * words_of {
        return Err(format!(
            "{} bytes, not the {} of its version {version}",
            bytes.len(),
            4 * words_of
        ));
    }
    let word = |k: usize| {
        bytes
            .get(4 * k..4 * k + 4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    };
    let float = |k: usize| word(k).map(f32::from_bits);
    let [tpd, refinement_tag, refinement_value, subdivision_word, split, max_tile, min_leaf] =
        [0, 1, 2, 3, 4, 5, 6].map(|k| word(k).unwrap_or(0));
    Ok(RbvhParams {
        texels_per_diagonal: f32::from_bits(tpd),
        refinement: refinement(refinement_tag, f32::from_bits(refinement_value))?,
        subdivision: subdivision(subdivision_word)?,
        object_split: flag("params.object_split", split)?,
        max_tile,
        min_leaf_texels: f32::from_bits(min_leaf),
        sampled_criterion_texels: float(7).unwrap_or(0.0),
        object_rate: float(8).unwrap_or(0.0),
        exact_when_cheaper: flag("params.exact_when_cheaper", word(9).unwrap_or(0))?,
        exact_from_texels: float(10).unwrap_or(0.0),
        exact_edge_fraction: float(11).unwrap_or(0.0),
        exact_crease_deg: float(12).unwrap_or(0.0),
        view_rate: float(13).unwrap_or(0.0),
        texels,
    })
}
