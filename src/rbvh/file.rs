//! Saving and loading a built RBVH: one versioned binary file holding everything [`Rbvh`] holds,
//! so that a build (minutes for a large scene) is done once and traced many times.
//!
//! All numbers are little-endian; floats are stored as their IEEE-754 bits, so every value
//! (NaN payloads and signed zeros included) round-trips exactly and `save → load → save` is
//! byte-identical. Encoding goes word by word through `to_le_bytes`/`from_le_bytes`, so the file
//! means the same on a big-endian host (where the conversion swaps) as on a little-endian one
//! (where it is a plain copy). There is no padding anywhere.
//!
//! | bytes | type | field |
//! |---|---|---|
//! | 0..8 | `[u8; 8]` | magic `RBVHv` followed by three zero bytes |
//! | 8..12 | u32 | format version: 12 (this build writes it; it reads 1–11 as well, see below) |
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
//! | then | `L` × 64 bytes | `leaves` ([`super::GpuHeightfield`], 16 words each) |
//! | then | `X` × 4 bytes | `atlas.texels` ([`super::Texel`], one word each), row by row; height-only texels: `X` × 2 bytes, each texel's height code (u16) |
//! | then | u64 | with a colour channel only: colour count `C`, which must equal `X` |
//! | then | `C` × 4 bytes | with a colour channel only: `colours` (packed RGBA8, see [`crate::rgba`]), parallel to the texels |
//!
//! A height-only RBVH has no colour channel: a file that claims both is malformed.
//!
//! **Older versions** load as the RBVHs they described. Versions 1–4 stored each node in 64
//! bytes with both children's boxes at full precision (`a_min`, `a_child`, `a_max`, `a_count`,
//! then the same for `b`); loading quantizes them as the builder does now ([`GpuNode::new`]), so
//! every box only grows and every hit stays. The header of versions 1–3 lacks bytes 40..52: the
//! texel format and the colour channel were the version's (1: normals, no colours; 2: normals and
//! colours; 3: height-only), and they were built by the paper's rule alone
//! (`sampled_criterion_texels` = 0). Versions 1–5 carry no mark of which heights were sampled
//! from the surface and which extrapolated (the parity of a height code, [`Texel::is_sampled`]):
//! every sampled-looking code is made odd on loading, within one code and inside its leaf's box
//! (where the box allows: `unmark`), so that the march hangs no skirt under them and the RBVH
//! traces as it was built. Versions 1–6 took every texel from the scene (`object_rate` 0). Versions 1–7 have 16-bit
//! codes everywhere (`narrow_rows` 0). Versions 1–8 sampled every triangle a height field could
//! hold (`exact_when_cheaper` false), and versions 1–9 traced exactly the triangles of at least
//! what 96 bytes of texels buy (`exact_from_texels` 0), and versions 1–10 traced none exactly
//! for the length of its edges (`exact_edge_fraction` 0), and versions 1–11 none for a crease
//! (`exact_crease_deg` 0). Saving such an RBVH writes version 12. A colour section
//! that is cut short, or whose count is not `X`, is an [`Error::Parse`] like any other
//! malformation.
//!
//! Loading checks everything a tracer relies on, so a loaded RBVH is safe to trace and to upload:
//! the magic and version, the length (counts × record sizes must be exactly what follows the
//! header), `X = pitch × rows` with a power-of-two pitch, `narrow_rows ≤ rows` with every
//! texel of those rows a hole or an 8-bit code (a multiple of [`Texel::NARROW_STEP`]: what the
//! device can store there), no NaN in the header's floats, enum tags and flags in range, every
//! node's grid (a finite origin, exponents in range, reserved bits zero; a version 1–4 node's
//! boxes free of NaN), every node's children (inner: a node index, with count 0; triangle leaf: a range within `triangles`;
//! height-field leaf: an index into `leaves`), every leaf's tile inside the atlas with finite
//! frame and a non-negative height scale, every triangle's scene index below 2³¹ (hit ids with
//! bit 31 set are height-field hits, `u32::MAX` a miss), and its flags 0 or an exact part of one of
//! the leaves (`GpuTriangle::PART`), its padding 0 (files written before parts carried flags load
//! with theirs 0: level-of-detail grids then sample them, and their hits take the scene's
//! material colours, as they did then). Every failure is an [`Error::Parse`]
//! naming the file.

use std::io::Write;
use std::path::Path;

use bytemuck::{Pod, Zeroable};

use super::layout::tile_fits;
use super::layout::{Atlas, GpuHeightfield, Texel, HEIGHTFIELD_COUNT, LEAF_BIT};
use super::params::{RbvhParams, Refinement, Subdivision, TexelFormat};
use super::{Rbvh, RbvhStats};
use crate::bvh::{ChildRef, GpuNode, GpuTriangle};
use crate::geom::Aabb;
use crate::io::write_atomically;
use crate::{Error, Result};

/// The first eight bytes of every RBVH file.
const MAGIC: [u8; 8] = *b"RBVHv\0\0\0";
/// The format version this build writes.
const VERSION: u32 = 12;
/// Bytes before the arrays (see the table in the module docs).
const HEADER_BYTES: usize = 172;
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

impl Rbvh {
    /// Writes the versioned binary file described in the module docs, atomically (through
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

    /// Reads a file written by [`Rbvh::save`]. A missing or unreadable file is [`Error::Io`];
    /// every malformation (bad magic, unsupported version, truncation, counts inconsistent with the
    /// length, references out of range, NaN) is [`Error::Parse`] naming the file and the problem.
    pub fn load(path: &Path) -> Result<Rbvh> {
        let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
        Self::from_bytes(&bytes, path)
    }

    /// The bytes [`Rbvh::save`] writes.
    pub fn to_bytes(&self) -> Vec<u8> {
        let arrays = std::mem::size_of_val(self.nodes.as_slice())
            + std::mem::size_of_val(self.triangles.as_slice())
            + std::mem::size_of_val(self.leaves.as_slice())
            + self.atlas.texels.len() * self.params.texels.bytes() as usize
            + self.colours.as_ref().map_or(0, |_| 8)
            + self.colour_bytes() as usize;
        let mut out = Vec::with_capacity(HEADER_BYTES + arrays);
        out.extend_from_slice(&MAGIC);
        put_u32(&mut out, VERSION);

        let p = &self.params;
        put_f32(&mut out, p.texels_per_diagonal);
        let (tag, value) = match p.refinement {
            Refinement::NormalCone { max_angle_deg } => (0, max_angle_deg),
            Refinement::ProjectedArea { min_ratio } => (1, min_ratio),
        };
        put_u32(&mut out, tag);
        put_f32(&mut out, value);
        put_u32(
            &mut out,
            match p.subdivision {
                Subdivision::SpatialMedian => 0,
                Subdivision::AreaSah => 1,
            },
        );
        put_u32(&mut out, u32::from(p.object_split));
        put_u32(&mut out, p.max_tile);
        put_f32(&mut out, p.min_leaf_texels);
        put_f32(&mut out, p.sampled_criterion_texels);
        put_u32(
            &mut out,
            match p.texels {
                TexelFormat::HeightNormal => 0,
                TexelFormat::Height => 1,
            },
        );
        put_u32(&mut out, u32::from(self.has_colour_section()));

        for x in self.bounds.min.to_array() {
            put_f32(&mut out, x);
        }
        for x in self.bounds.max.to_array() {
            put_f32(&mut out, x);
        }
        put_u32(&mut out, self.depth);
        put_f32(&mut out, self.texel_size);
        out.extend_from_slice(&self.stats.build_ms.to_bits().to_le_bytes());
        put_u32(&mut out, self.stats.heightfield_leaves);
        put_u32(&mut out, self.stats.triangle_leaves);
        out.extend_from_slice(&self.stats.tile_texels.to_le_bytes());
        put_u32(&mut out, self.atlas.pitch);
        put_u32(&mut out, self.atlas.rows);
        for count in [
            self.nodes.len(),
            self.triangles.len(),
            self.leaves.len(),
            self.atlas.texels.len(),
        ] {
            out.extend_from_slice(&(count as u64).to_le_bytes());
        }
        put_f32(&mut out, p.object_rate);
        put_u32(&mut out, self.atlas.narrow_rows);
        put_u32(&mut out, u32::from(p.exact_when_cheaper));
        put_f32(&mut out, p.exact_from_texels);
        put_f32(&mut out, p.exact_edge_fraction);
        put_f32(&mut out, p.exact_crease_deg);
        debug_assert_eq!(out.len(), HEADER_BYTES);

        put_records(&mut out, &self.nodes);
        put_records(&mut out, &self.triangles);
        put_records(&mut out, &self.leaves);
        match self.params.texels {
            TexelFormat::HeightNormal => put_records(&mut out, &self.atlas.texels),
            TexelFormat::Height => {
                for t in &self.atlas.texels {
                    out.extend_from_slice(&t.height_code().to_le_bytes());
                }
            }
        }
        if let (true, Some(colours)) = (self.has_colour_section(), &self.colours) {
            out.extend_from_slice(&(colours.len() as u64).to_le_bytes());
            put_records(&mut out, colours);
        }
        out
    }

    /// Whether the file carries the colour channel: a height-only RBVH has none (the builder
    /// bakes none, and [`Rbvh::save`] refuses one painted later).
    fn has_colour_section(&self) -> bool {
        self.params.texels == TexelFormat::HeightNormal && self.colours.is_some()
    }

    /// Parses the bytes of an RBVH file; `name_for_errors` is the file named in every error.
    pub fn from_bytes(bytes: &[u8], name_for_errors: &Path) -> Result<Rbvh> {
        let path = name_for_errors;
        let err = |message: String| Error::parse(path, None, message);
        let head = &bytes[..bytes.len().min(MAGIC.len())];
        if head != &MAGIC[..head.len()] {
            return Err(err(format!(
                "not an RBVH file: it starts with {head:02x?}, not the magic {MAGIC:02x?} (\"RBVHv\")"
            )));
        }
        let mut r = Reader {
            bytes,
            pos: 0,
            path,
        };
        r.take(MAGIC.len(), "the magic")?;
        let version = r.u32("the version")?;
        if !(1..=VERSION).contains(&version) {
            return Err(err(format!(
                "unsupported version {version} (this build reads versions 1 to {VERSION})"
            )));
        }

        let texels_per_diagonal = r.f32("params.texels_per_diagonal")?;
        let refinement = match (
            r.u32("params.refinement")?,
            r.f32("params.refinement value")?,
        ) {
            (0, max_angle_deg) => Refinement::NormalCone { max_angle_deg },
            (1, min_ratio) => Refinement::ProjectedArea { min_ratio },
            (tag, _) => {
                return Err(err(format!(
                "params.refinement has tag {tag}; known are 0 (NormalCone) and 1 (ProjectedArea)"
            )))
            }
        };
        let subdivision = match r.u32("params.subdivision")? {
            0 => Subdivision::SpatialMedian,
            1 => Subdivision::AreaSah,
            tag => {
                return Err(err(format!(
                    "params.subdivision has tag {tag}; known are 0 (SpatialMedian) and 1 (AreaSah)"
                )))
            }
        };
        let object_split = match r.u32("params.object_split")? {
            0 => false,
            1 => true,
            x => return Err(err(format!("params.object_split is {x}, not 0 or 1"))),
        };
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
                let colour_channel = match r.u32("the colour channel flag")? {
                    0 => false,
                    1 => true,
                    x => return Err(err(format!("the colour channel flag is {x}, not 0 or 1"))),
                };
                if colour_channel && texels == TexelFormat::Height {
                    return Err(err(
                        "a height-only RBVH claims a colour channel (it cannot have one)"
                            .to_string(),
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
            _ => HEADER_BYTES,
        };
        let params = RbvhParams {
            texels_per_diagonal,
            object_rate: 0.0,
            refinement,
            subdivision,
            object_split,
            max_tile,
            min_leaf_texels,
            sampled_criterion_texels,
            texels,
            exact_when_cheaper: false,
            exact_from_texels: 0.0,
            exact_edge_fraction: 0.0,
            exact_crease_deg: 0.0,
        };
        let bounds = Aabb {
            min: [r.f32("bounds")?, r.f32("bounds")?, r.f32("bounds")?].into(),
            max: [r.f32("bounds")?, r.f32("bounds")?, r.f32("bounds")?].into(),
        };
        let depth = r.u32("depth")?;
        let texel_size = r.f32("texel_size")?;
        let stats = RbvhStats {
            build_ms: f64::from_bits(r.u64("stats.build_ms")?),
            heightfield_leaves: r.u32("stats.heightfield_leaves")?,
            triangle_leaves: r.u32("stats.triangle_leaves")?,
            tile_texels: r.u64("stats.tile_texels")?,
        };
        let pitch = r.u32("atlas.pitch")?;
        let rows = r.u32("atlas.rows")?;
        let counts = [
            r.u64("the node count")?,
            r.u64("the triangle count")?,
            r.u64("the leaf count")?,
            r.u64("the texel count")?,
        ];
        // Versions 1–6 took every texel from the scene's diagonal.
        let object_rate = if version >= 7 {
            r.f32("params.object_rate")?
        } else {
            0.0
        };
        let params = RbvhParams {
            object_rate,
            ..params
        };
        // Versions 1–7 stored 16-bit codes everywhere.
        let narrow_rows = if version >= 8 {
            r.u32("atlas.narrow_rows")?
        } else {
            0
        };
        // Versions 1–8 sampled every triangle a height field could hold.
        let exact_when_cheaper = match version {
            1..=8 => false,
            _ => match r.u32("params.exact_when_cheaper")? {
                0 => false,
                1 => true,
                x => return Err(err(format!("params.exact_when_cheaper is {x}, not 0 or 1"))),
            },
        };
        // Versions 1–9 traced exactly from what 96 bytes of texels buy.
        let exact_from_texels = if version >= 10 {
            r.f32("params.exact_from_texels")?
        } else {
            0.0
        };
        // Versions 1–10 traced no triangle exactly for the length of its edges.
        let exact_edge_fraction = if version >= 11 {
            r.f32("params.exact_edge_fraction")?
        } else {
            0.0
        };
        // Versions 1–11 traced no triangle exactly for a crease.
        let exact_crease_deg = if version >= 12 {
            r.f32("params.exact_crease_deg")?
        } else {
            0.0
        };
        let params = RbvhParams {
            exact_when_cheaper,
            exact_from_texels,
            exact_edge_fraction,
            exact_crease_deg,
            ..params
        };

        let floats = [
            ("params.texels_per_diagonal", texels_per_diagonal),
            ("params.object_rate", object_rate),
            ("params.refinement value", refinement_value(refinement)),
            ("params.min_leaf_texels", params.min_leaf_texels),
            ("params.sampled_criterion_texels", sampled_criterion_texels),
            ("params.exact_from_texels", exact_from_texels),
            ("params.exact_edge_fraction", exact_edge_fraction),
            ("params.exact_crease_deg", exact_crease_deg),
            ("texel_size", texel_size),
        ];
        for (name, x) in floats {
            if x.is_nan() {
                return Err(err(format!("{name} is NaN")));
            }
        }
        if !(exact_from_texels.is_finite() && exact_from_texels >= 0.0)
            || (exact_from_texels > 0.0 && !exact_when_cheaper)
        {
            return Err(err(format!(
                "params.exact_from_texels is {exact_from_texels}: a size in texels, at least 0, and \
                 0 where exact_when_cheaper is off"
            )));
        }
        if !(0.0..=1.0).contains(&exact_edge_fraction)
            || (exact_edge_fraction > 0.0 && !exact_when_cheaper)
        {
            return Err(err(format!(
                "params.exact_edge_fraction is {exact_edge_fraction}: a fraction of an object's \
                 diagonal, in 0..=1, and 0 where exact_when_cheaper is off"
            )));
        }
        if !(0.0..=180.0).contains(&exact_crease_deg) {
            return Err(err(format!(
                "params.exact_crease_deg is {exact_crease_deg}: an angle in 0..=180 degrees"
            )));
        }
        // Infinite bounds are legitimate (the empty box of an empty scene); NaN is not.
        if bounds.min.is_nan() || bounds.max.is_nan() {
            return Err(err(format!("bounds {bounds:?} contain NaN")));
        }
        if stats.build_ms.is_nan() {
            return Err(err("stats.build_ms is NaN".to_string()));
        }

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
        if !pitch.is_power_of_two() {
            return Err(err(format!(
                "the atlas pitch is {pitch} texels, not a power of two (the builder makes every \
                 pitch one, and the shaders count on it)"
            )));
        }
        if n_texels != u64::from(pitch) * u64::from(rows) {
            return Err(err(format!(
                "the atlas has {n_texels} texels, not pitch × rows = {pitch} × {rows}"
            )));
        }

        // The lengths now match the file, so each count fits in memory (usize).
        let nodes: Vec<GpuNode> = if version < 5 {
            let old: Vec<NodeV4> = r.records(n_nodes as usize)?;
            let mut nodes = Vec::with_capacity(old.len());
            for (index, node) in old.iter().enumerate() {
                nodes.push(
                    node.quantized()
                        .map_err(|why| err(format!("node {index}: {why}")))?,
                );
            }
            nodes
        } else {
            r.records(n_nodes as usize)?
        };
        let triangles: Vec<GpuTriangle> = r.records(n_triangles as usize)?;
        let leaves: Vec<GpuHeightfield> = r.records(n_leaves as usize)?;
        let texel_words: Vec<Texel> = match texels {
            TexelFormat::HeightNormal => r.records(n_texels as usize)?,
            TexelFormat::Height => r
                .take(n_texels as usize * 2, "the arrays")?
                .chunks_exact(2)
                .map(|b| Texel(u32::from(u16::from_le_bytes([b[0], b[1]]))))
                .collect(),
        };
        let colours = if colour_channel {
            r.u64("the colour count")?;
            Some(r.records(n_colours as usize)?)
        } else {
            None
        };
        let mut atlas = Atlas {
            pitch,
            rows,
            narrow_rows,
            texels: texel_words,
        };
        if narrow_rows > rows {
            return Err(err(format!(
                "atlas.narrow_rows {narrow_rows} exceeds its {rows} rows"
            )));
        }
        if let Some((k, code)) = atlas.first_wide_code_in_narrow_band() {
            return Err(err(format!(
                "atlas texel {k} lies in the narrow rows but has height code {code}, not a \
                 multiple of {} (an 8-bit code)",
                Texel::NARROW_STEP
            )));
        }

        for (index, node) in nodes.iter().enumerate() {
            if let Some(why) = node.malformation() {
                return Err(err(format!("node {index}: {why}")));
            }
            let children = [
                ('a', node.a_child, node.a_count),
                ('b', node.b_child, node.b_count),
            ];
            for (name, child, count) in children {
                check_child(child, count, &nodes, &triangles, &leaves)
                    .map_err(|why| err(format!("node {index}, child {name}: {why}")))?;
            }
        }
        for (index, leaf) in leaves.iter().enumerate() {
            check_leaf(leaf, &atlas)
                .map_err(|why| err(format!("height-field leaf {index}: {why}")))?;
        }
        if version < 6 {
            unmark(&nodes, &leaves, &mut atlas, bounds);
        }
        if let Some((index, t)) = triangles.iter().enumerate().find(|(_, t)| {
            let flags_ok = match t.part_leaf() {
                Some(leaf) => (leaf as usize) < leaves.len(),
                None => t.flags == 0,
            };
            !flags_ok || t.pad2 != 0
        }) {
            return Err(err(format!(
                "triangle {index} has flags {:#x} and padding {:#x}: neither 0 nor an exact \
                 part of one of the {} height-field leaves",
                t.flags,
                t.pad2,
                leaves.len()
            )));
        }
        // A triangle's `prim` is its hit id: bit 31 marks height-field hits, and u32::MAX a miss.
        if let Some((index, t)) = triangles
            .iter()
            .enumerate()
            .find(|(_, t)| t.prim & LEAF_BIT != 0)
        {
            return Err(err(format!(
                "triangle {index} has scene index {:#x}, which has bit 31 set: such ids are \
                 reserved for height-field hits and misses",
                t.prim
            )));
        }

        Ok(Rbvh {
            params,
            nodes,
            triangles,
            leaves,
            atlas,
            bounds,
            depth,
            texel_size,
            stats,
            colours,
        })
    }
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

fn refinement_value(r: Refinement) -> f32 {
    match r {
        Refinement::NormalCone { max_angle_deg } => max_angle_deg,
        Refinement::ProjectedArea { min_ratio } => min_ratio,
    }
}

/// Files before version 6 carry no mark of which heights were sampled from the surface
/// ([`Texel::is_sampled`]): their codes' parities are arbitrary. Each even code is made odd, so
/// that no skirt hangs under it and the RBVH traces as it was built (its heights within one code,
/// 1/65534 of the leaf's height range), taking the neighbouring code that keeps the sample inside
/// its leaf's box in the tree, so that the box still holds the surface. A sample that neither
/// keeps inside (one on a face of its box, in a leaf so tall that one code exceeds the box's
/// margin of 1/1024 texel: more than 64 texels from its lowest sample to its highest) keeps its
/// code, and a skirt may hang under it.
fn unmark(nodes: &[GpuNode], leaves: &[GpuHeightfield], atlas: &mut Atlas, bounds: Aabb) {
    let mut boxes = vec![bounds; leaves.len()];
    for node in nodes {
        for c in node.children() {
            if c.child & LEAF_BIT != 0 && c.count == HEIGHTFIELD_COUNT {
                boxes[(c.child & !LEAF_BIT) as usize] = c.bounds;
            }
        }
    }
    let pitch = atlas.pitch as usize;
    for (leaf, b) in leaves.iter().zip(&boxes) {
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

/// Checks one child reference against the layout rules (see [`super::layout`]).
fn check_child(
    child: u32,
    count: u32,
    nodes: &[GpuNode],
    triangles: &[GpuTriangle],
    leaves: &[GpuHeightfield],
) -> std::result::Result<(), String> {
    let index = child & !LEAF_BIT;
    if child & LEAF_BIT == 0 {
        if count != 0 {
            return Err(format!("inner node reference with count {count}, not 0"));
        }
        if index as usize >= nodes.len() {
            return Err(format!(
                "node index {index} is out of range (there are {} nodes)",
                nodes.len()
            ));
        }
    } else if count == HEIGHTFIELD_COUNT {
        if index as usize >= leaves.len() {
            return Err(format!(
                "height-field leaf index {index} is out of range (there are {} leaves)",
                leaves.len()
            ));
        }
    } else if u64::from(index) + u64::from(count) > triangles.len() as u64 {
        return Err(format!(
            "triangles {index}..{} are out of range (there are {})",
            u64::from(index) + u64::from(count),
            triangles.len()
        ));
    }
    Ok(())
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
            "its {}×{} tile at texel {} does not fit the {}×{} atlas",
            leaf.res_u, leaf.res_v, leaf.atlas_base, atlas.pitch, atlas.rows
        ));
    }
    Ok(())
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

/// A cursor over the file's bytes whose every read names the field it wanted when the file ends.
struct Reader<'a> {
    bytes: &'a [u8],
    pos: usize,
    path: &'a Path,
}

impl<'a> Reader<'a> {
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

    /// Reads `n` records of 4-byte words written by [`put_records`].
    fn records<T: Pod>(&mut self, n: usize) -> Result<Vec<T>> {
        let size = std::mem::size_of::<T>();
        let bytes = self.take(n.saturating_mul(size), "the arrays")?;
        let mut out = vec![T::zeroed(); n];
        let words = bytemuck::cast_slice_mut::<T, u32>(&mut out);
        for (word, b) in words.iter_mut().zip(bytes.chunks_exact(4)) {
            *word = u32::from_le_bytes([b[0], b[1], b[2], b[3]]);
        }
        Ok(out)
    }
}
