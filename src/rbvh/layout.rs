//! GPU layout of the RBVH: the tree reuses the exact BVH's 48-byte node ([`GpuNode`]); triangle
//! leaves' triangles are indexed ([`crate::rbvh::ExactTriangles`], made from [`GpuTriangle`]s);
//! height-field leaves are [`GpuHeightfield`] records; the atlas is
//! an array of 32-bit texels ([`Texel`]) with a fixed row pitch.
//!
//! What a node's child reference names (inner node, triangle leaf, height-field leaf) is read in
//! one place, [`super::child`].
//!
//! ## Leaf frame and texel grid
//! A leaf is an orthographic projection along `axis_w` (the normalised area-weighted normal sum
//! Σ nᵢAᵢ of its triangles, Novák & Dachsbacher 2012), with tangents `u`, `v`. A point `p` has
//! texel-space coordinates `s = (p − origin)·axis_u`, `t = (p − origin)·axis_v` (so `axis_u =
//! u / texel_size`) and height `h = (p − origin)·axis_w`, measured along the unit axis `w` from
//! the tile's plane: `axis_w = w − a·axis_u − b·axis_v` for the plane's slopes `a`, `b` (world
//! height per texel; zero for most tiles, `axis_w = w`), which narrows a tilted tile's range of
//! heights and so its codes (`raster/quantize.rs`). The map is affine either way, and the march
//! works in its coordinates alone. Sample `(i, j)` sits at the texel centre
//! `(s, t) = (i + ½, j + ½)` with height `q · h_scale`, `q` its 16-bit quantized height. The surface
//! inside the *cell* between samples `(i, j)` and `(i + 1, j + 1)` is two triangles through the four
//! corner samples (see `march/cell.rs`); cells with a missing corner keep the triangle of the other three.

use bytemuck::{Pod, Zeroable};
use glam::{Vec2, Vec3};

pub use crate::bvh::{GpuNode, GpuTriangle, LEAF_BIT};

/// Relative rounding slack of the height-field march (steps 2–4 of `march/`); `glsl/rbvh.glsl`
/// defines the same value. Frame-space quantities (the ray's height `o_h + d_h·t`,
/// the triangle test's hit, boundary crossings) carry rounding errors of a few ulps of the
/// magnitudes involved; the march's box and per-cell height rejection are widened by this much of
/// `|o_h| + h_top` (plus one height quantum), and a grid vertex counts as passed ambiguously
/// within this much of `|o_s| + |o_t| + res_u + res_v` texels. 1e-5 (about 80 ulps) is far beyond
/// the rounding and still costs almost nothing: few cells are rejected less, few vertices are
/// passed that closely.
pub const MARCH_SLACK: f32 = 1e-5;

/// Padding of the march's box beyond the outermost samples, in texels (step 2): a ray running
/// exactly in a border plane of an unpadded box is in or out of the slab by the sign of its zero
/// direction component (`safe_inverse`); the padding leaves that decision to the triangles.
pub const MARCH_EDGE_PAD: f32 = 1.0 / 64.0;

/// Depth of the skirt under a height field's rims, in texels (issue "No leaks between height
/// fields"): a ray that enters a cell with a surface (three or four samples) across an edge of
/// that surface from a cell without four (or through the tile's side), below that edge by at
/// most the skirt's depth there, hits at its entry. The depth is this much under an edge whose
/// samples both lie on the surface ([`Texel::is_sampled`]); under an edge from such a sample to
/// an extrapolated one, this much at the sampled end, tapering to nothing half-way (a ray aimed
/// at a rim sample whose edge ends in an extrapolated sample found no skirt there before: the
/// sphere's 4 and 168 leaks per million at φ_max 89.5° and A⊥/A 0.01; tapering all the way to
/// the extrapolated end cost t p99 a little, 0.150 → 0.151–0.152% on the dragon's Q0). Neighbouring leaves
/// overlap by their rings of samples; where a ray still passes between them (a corner where
/// several leaves meet, a rim over a fold), it enters a field from its side, under its surface,
/// and the skirt catches it there. Under an extrapolated rim the skirt would hang in the air
/// beside a silhouette: that lip cost the dragon a quarter of its t p99 at Q0 (0.150 → 0.188%),
/// so those rims have none. One texel: deeper would hang below thin parts, where a ray may pass
/// outside the object. The skirt hangs within the leaf's boxes (the march's tile box and the
/// box of its samples in the tree), so under a rim at the leaf's lowest samples it is cut short:
/// growing both boxes by a texel downwards took the dragon's seam leaks only from 13 / 12 / 3 /
/// 1 / 2 to 10 / 11 / 3 / 1 / 2 per million, for 10% more leaves visited per ray at Q0 and 2–7%
/// of the speed.
pub const MARCH_SKIRT_TEXELS: f32 = 1.0;

/// Depth of the skirt under the diagonal of a cell of three samples, the edge of its triangle
/// that faces the hole, in texels (tapered as [`MARCH_SKIRT_TEXELS`]): a ray that crosses that
/// diagonal from the hole's side, below it by at most this much, hits there. It closes the
/// rounding of rays that run along such a rim at its very height (the sphere's last leak per
/// million at A⊥/A 0.01), and little more: a texel deep, it hung beside silhouettes, where rays
/// pass just under rims, and cost the dragon 5% of its t p99 at Q0–Q2 (0.150 → 0.158% at Q0);
/// a tenth of a texel leaves it unchanged.
pub const MARCH_DIAGONAL_SKIRT_TEXELS: f32 = 0.1;

/// The least slope of a tile's plane, in texels of height a texel, that its record carries
/// ([`GpuHeightfield::grid`], `raster/quantize.rs`): ten times the f32 rounding that leaves a
/// plane-less record's `axis_w` not quite orthogonal to its `axis_u` and `axis_v`. The builder
/// keeps a plane only where it narrows the heights' range by a narrow quantum (1/128 texel), which
/// a tile of at most 4096 texels a side could do with both slopes just under 1/(2 · 128 · 4095)
/// ≈ 9.5e-7, so it also keeps none whose steeper slope is below this (`raster/quantize.rs`):
/// builder and reader agree by construction.
pub const MIN_PLANE_SLOPE: f32 = 1e-6;

/// One height-field leaf. 64 bytes:
///
/// | bytes | field |
/// |---|---|
/// | 0..12, 12..16 | `origin` (world), `atlas_base` (index of texel (0, 0) in the atlas) |
/// | 16..28, 28..32 | `axis_u` (= u / texel size), `res_u` (samples along u) |
/// | 32..44, 44..48 | `axis_v` (= v / texel size), `res_v` |
/// | 48..60, 60..64 | `axis_w` (height row: the unit projection axis, sheared by the tile's plane), `h_scale` (world height per quantum) |
///
/// Texel `(i, j)` of the tile is at atlas index `atlas_base + j · pitch + i`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuHeightfield {
    /// GLSL `RbvhHeightfield.origin`: world-space origin of the leaf frame (`s = t = h = 0`).
    pub origin: [f32; 3],
    /// GLSL `atlas_base`: atlas index of texel (0, 0) of the tile.
    pub atlas_base: u32,
    /// GLSL `axis_u`: world tangent `u` divided by the texel size, so `s = (p − origin)·axis_u`
    /// is in texels.
    pub axis_u: [f32; 3],
    /// GLSL `res_u`: samples (texels) along `u`; at most
    /// [`RbvhParams::max_tile`](crate::rbvh::RbvhParams::max_tile).
    pub res_u: u32,
    /// GLSL `axis_v`: world tangent `v` divided by the texel size (`t` in texels).
    pub axis_v: [f32; 3],
    /// GLSL `res_v`: samples (texels) along `v`.
    pub res_v: u32,
    /// GLSL `axis_w`: the height row of the frame, `h = (p − origin)·axis_w`: the unit
    /// world-space projection axis `w`, less the tile's plane `a·axis_u + b·axis_v` where it has
    /// one (module docs); heights are measured along `w`.
    pub axis_w: [f32; 3],
    /// GLSL `h_scale`: world height per height-code quantum (`h = code · h_scale`).
    pub h_scale: f32,
}
const _: () = assert!(std::mem::size_of::<GpuHeightfield>() == 64);

/// The leaf frame's maps, in one place for every user outside the march (which inlines the same
/// dot products: `march/walk.rs` step 1; `glsl/paint.comp` mirrors [`GpuHeightfield::sample_point`]).
impl GpuHeightfield {
    /// This leaf in a world `2^k` times larger, exactly (`geom::scale`): its origin and height
    /// quantum scaled, its tangents over the texel scaled inversely; the height row, a unit axis
    /// less the tile's plane in texels, has no unit and stays.
    pub fn scaled_pow2(self, k: i32) -> GpuHeightfield {
        let (s, inverse) = (crate::geom::scale::pow2(k), crate::geom::scale::pow2(-k));
        GpuHeightfield {
            origin: self.origin.map(|x| x * s),
            axis_u: self.axis_u.map(|x| x * inverse),
            axis_v: self.axis_v.map(|x| x * inverse),
            h_scale: self.h_scale * s,
            ..self
        }
    }

    /// Frame coordinates `(s, t, h)` of world point `p`: `s`, `t` in texels, `h` in world units.
    pub fn to_frame(&self, p: Vec3) -> Vec3 {
        let rel = p - Vec3::from(self.origin);
        Vec3::new(
            rel.dot(Vec3::from(self.axis_u)),
            rel.dot(Vec3::from(self.axis_v)),
            rel.dot(Vec3::from(self.axis_w)),
        )
    }

    /// The world-space sample grid of the leaf (see [`SampleGrid`]): the inverse of the frame's
    /// map. With `axis_u ⟂ axis_v` and `w` orthogonal to both, `axis_w = w − a·axis_u −
    /// b·axis_v` gives the plane's slopes `a = −axis_w·axis_u / |axis_u|²` (likewise `b`) and `w =
    /// axis_w + a·axis_u + b·axis_v`, so a step along `u` is `axis_u / |axis_u|² + a·w`.
    /// A record whose slopes are below [`MIN_PLANE_SLOPE`] texels a texel has no plane: its
    /// `axis_w` is `w`, and the grid is made without the plane, bit for bit as before planes.
    pub fn grid(&self) -> SampleGrid {
        let (u, v) = (Vec3::from(self.axis_u), Vec3::from(self.axis_v));
        let row = Vec3::from(self.axis_w);
        let (uu, vv) = (u.dot(u), v.dot(v));
        let (a, b) = (-row.dot(u) / uu, -row.dot(v) / vv);
        let (step_u, step_v, w) =
            if (a * uu.sqrt()).abs() < MIN_PLANE_SLOPE && (b * vv.sqrt()).abs() < MIN_PLANE_SLOPE {
                (u / uu, v / vv, row)
            } else {
                let w = row + a * u + b * v;
                (u / uu + a * w, v / vv + b * w, w)
            };
        SampleGrid {
            origin: Vec3::from(self.origin),
            step_u,
            step_v,
            axis_w: w,
            h_scale: self.h_scale,
        }
    }

    /// World size of the leaf's texel: `|axis_u / |axis_u|²|` (the grid's steps rise along the
    /// tile's plane, so they are longer where it has one).
    pub fn texel_size(&self) -> f32 {
        let u = Vec3::from(self.axis_u);
        (u / u.dot(u)).length()
    }

    /// World position of sample `(i, j)` with height code `code` ([`SampleGrid::point`]).
    pub fn sample_point(&self, i: u32, j: u32, code: u16) -> Vec3 {
        self.grid().point(i, j, code)
    }

    /// World box of the tile's box (`s, t` over the sample centres, `h ∈ [0, MAX_CODE·h_scale]`),
    /// widened by a few ulps: every sample point, and the surface between them, lies inside.
    pub fn world_bounds(&self) -> crate::geom::Aabb {
        let top = Texel::MAX_CODE;
        let (i1, j1) = (self.res_u.max(1) - 1, self.res_v.max(1) - 1);
        let mut b = crate::geom::Aabb::EMPTY;
        for (i, j, code) in [
            (0, 0, 0),
            (i1, 0, 0),
            (0, j1, 0),
            (i1, j1, 0),
            (0, 0, top),
            (i1, 0, top),
            (0, j1, top),
            (i1, j1, top),
        ] {
            b = b.grow(self.sample_point(i, j, code));
        }
        let margin = b.min.abs().max(b.max.abs()) * (8.0 * f32::EPSILON);
        crate::geom::Aabb {
            min: b.min - margin,
            max: b.max + margin,
        }
    }
}

/// A 32-bit atlas texel: bits 0–15 the quantized height (`HOLE` = no surface), bits 16–31 the
/// world-space unit normal in 8:8 octahedral encoding (Cigolle et al., "A Survey of Efficient
/// Representations for Independent Unit Vectors", JCGT 2014), worst-case error about 1.2°.
///
/// The height code's lowest bit tells where the height came from ([`Texel::is_sampled`]): even
/// for a sample of the surface (a leaf's own triangle, the ring taken from the neighbouring
/// surface, or a wall steeper than 45° down the leaf's own triangles at an edge-on rim), odd for
/// an extrapolated one (dilation). The march's skirt hangs under sampled heights and
/// tapers to nothing half-way to extrapolated ones ([`MARCH_SKIRT_TEXELS`]). The bit costs the quantization one bit: heights
/// round to the nearest code of their parity, within one code.
#[repr(transparent)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct Texel(pub u32);
const _: () = assert!(std::mem::size_of::<Texel>() == 4);

impl Texel {
    /// The height code of an empty texel (a hole: no surface, not even after dilation).
    pub const HOLE_CODE: u16 = 0xFFFF;
    /// Largest height code of a surface texel.
    pub const MAX_CODE: u16 = 0xFFFE;
    /// An empty texel: [`Texel::HOLE_CODE`] with a zero normal word.
    pub const HOLE: Texel = Texel(Self::HOLE_CODE as u32);

    /// The 16-bit code of one step of a `bits`-bit code ([`Texel::code_of`]; `bits` 16 or one of
    /// [`PACKED_BITS`]): the largest odd number with `2^bits − 2` steps within [`Texel::MAX_CODE`]
    /// — 1 for 16 bits, 15 for 12, 63 for 10, 257 for 8 (byte `c` is code `c · 257`, `c`
    /// repeated in both bytes). Odd, so that a code keeps its step count's parity (the sampled
    /// mark, [`Texel::is_sampled`]).
    pub const fn step(bits: u32) -> u32 {
        let s = Self::MAX_CODE as u32 / ((1 << bits) - 2);
        s - (1 - s % 2)
    }

    /// Largest height code of a surface texel of a `bits`-bit tile: `(2^bits − 2) · step(bits)`
    /// ([`Texel::MAX_CODE`] for 16 bits); `2^bits − 1` steps stand for a hole.
    pub const fn top(bits: u32) -> u32 {
        ((1 << bits) - 2) * Self::step(bits)
    }

    /// Whether a `bits`-bit tile can hold `code`: a hole, or a whole number of its steps up to
    /// [`Texel::top`].
    pub fn fits(code: u16, bits: u32) -> bool {
        let code = u32::from(code);
        code == u32::from(Self::HOLE_CODE)
            || (code % Self::step(bits) == 0 && code <= Self::top(bits))
    }

    /// The 16-bit code the device reads for the `bits`-bit field `c` it stores
    /// (`glsl/atlas.glsl`): `c` steps, or a hole for all ones.
    pub fn expand(c: u32, bits: u32) -> u16 {
        if c == (1 << bits) - 1 {
            Self::HOLE_CODE
        } else {
            (c * Self::step(bits)) as u16
        }
    }

    /// A surface texel of height code `height_code` (at most [`Texel::MAX_CODE`]) and world-space
    /// unit `normal`, octahedrally encoded.
    pub fn new(height_code: u16, normal: Vec3) -> Texel {
        debug_assert!(height_code != Self::HOLE_CODE);
        Texel(height_code as u32 | (encode_octahedral(normal) as u32) << 16)
    }

    /// Whether the texel has no surface ([`Texel::HOLE_CODE`]).
    pub fn is_hole(self) -> bool {
        self.height_code() == Self::HOLE_CODE
    }

    /// Bits 0–15: the quantized height, in units of the leaf's `h_scale` along `axis_w`.
    pub fn height_code(self) -> u16 {
        (self.0 & 0xFFFF) as u16
    }

    /// Whether the height was sampled from the surface (an even code), not extrapolated (odd);
    /// see the type's docs. False for a hole.
    pub fn is_sampled(self) -> bool {
        self.height_code() & 1 == 0
    }

    /// The code nearest `q` (a height in quanta of a 16-bit code, clamped to `[0, top(bits)]`)
    /// among the codes a `bits`-bit tile can hold: [`Texel::step`]`(bits) · c` with `c` of
    /// `sampled`'s parity ([`Texel::is_sampled`]) in `0..=2^bits − 2`, within one step of `q`.
    pub fn code_of(q: f64, sampled: bool, bits: u32) -> u16 {
        let step = Self::step(bits);
        (u32::from(nearest_code(
            q / f64::from(step),
            sampled,
            ((1u32 << bits) - 2) as u16,
        )) * step) as u16
    }

    /// Bits 16–31 decoded: the world-space unit normal (meaningless for a hole).
    pub fn normal(self) -> Vec3 {
        decode_octahedral((self.0 >> 16) as u16)
    }

    /// Whether the texel's normal faces a ray along `dir` (world space): their dot product,
    /// summed in the order `glsl/rbvh.glsl`'s `rbvh_faces` sums it, is negative.
    pub fn faces(self, dir: Vec3) -> bool {
        let n = octahedral_direction((self.0 >> 16) as u16);
        n.x * dir.x + n.y * dir.y + n.z * dir.z < 0.0
    }
}

/// The code nearest `q` in `[0, max]` (`max` even) of `sampled`'s parity (even when sampled).
fn nearest_code(q: f64, sampled: bool, max: u16) -> u16 {
    debug_assert!(!q.is_nan(), "a height code of NaN");
    let (odd, max) = (f64::from(u8::from(!sampled)), f64::from(max));
    let half = (q.clamp(0.0, max) - odd) / 2.0;
    ((2.0 * half.round()).clamp(0.0, max - 2.0 * odd) + odd) as u16
}

/// A leaf's samples in world space: `step_u` and `step_v`, the world vectors of one texel step
/// at a constant height over the tile's plane (`u · texel`, plus the plane's rise along `w`), and
/// the unit axis `w` heights are measured along ([`GpuHeightfield::grid`]). Computed once per
/// leaf, on the host, for the CPU and for `glsl/paint.comp` alike.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SampleGrid {
    /// World-space frame origin, as [`GpuHeightfield::origin`].
    pub origin: Vec3,
    /// World vector of one texel step along `u`.
    pub step_u: Vec3,
    /// World vector of one texel step along `v`.
    pub step_v: Vec3,
    /// Unit world-space height axis `w` (the record's [`GpuHeightfield::axis_w`] without the
    /// plane).
    pub axis_w: Vec3,
    /// World height per height-code quantum, as [`GpuHeightfield::h_scale`].
    pub h_scale: f32,
}

impl SampleGrid {
    /// Sample `(i, j)` at height code `code`: `origin + (i + ½)·step_u + (j + ½)·step_v +
    /// (code·h_scale)·axis_w`, evaluated in this order. `glsl/paint.comp` does the same with
    /// `precise` (no fused multiply-add), so both give the same bits.
    pub fn point(&self, i: u32, j: u32, code: u16) -> Vec3 {
        let s = i as f32 + 0.5;
        let t = j as f32 + 0.5;
        let h = code as f32 * self.h_scale;
        self.origin + self.step_u * s + self.step_v * t + self.axis_w * h
    }
}

/// The surface of one cell from its corners in cycle order c00, c10, c11, c01 (`None` for a
/// hole): with all four, the triangles (c00, c10, c11) and (c00, c11, c01); with one hole, the
/// triangle of the other three in that cycle (so the winding stays the quad's); with two or more,
/// none. The march (`march/`, steps 4–5, and `glsl/rbvh.glsl`) inlines this choice for speed;
/// everything else that needs a cell's triangles takes them from here.
pub(crate) fn cell_triangles<T: Copy>(corners: [Option<T>; 4]) -> impl Iterator<Item = [T; 3]> {
    let mut present = corners.into_iter().flatten();
    let first_four = [
        present.next(),
        present.next(),
        present.next(),
        present.next(),
    ];
    let triangles = match first_four {
        [Some(a), Some(b), Some(c), Some(d)] => [Some([a, b, c]), Some([a, c, d])],
        [Some(a), Some(b), Some(c), None] => [Some([a, b, c]), None],
        _ => [None, None],
    };
    triangles.into_iter().flatten()
}

/// 8:8 octahedral encoding of a unit vector.
pub fn encode_octahedral(n: Vec3) -> u16 {
    let n = n / (n.x.abs() + n.y.abs() + n.z.abs()).max(f32::MIN_POSITIVE);
    let mut p = Vec2::new(n.x, n.y);
    if n.z < 0.0 {
        p = (Vec2::ONE - Vec2::new(p.y.abs(), p.x.abs())) * Vec2::new(sign(p.x), sign(p.y));
    }
    let q = |x: f32| ((x.clamp(-1.0, 1.0) * 0.5 + 0.5) * 255.0).round() as u16;
    q(p.x) | q(p.y) << 8
}

/// Inverse of [`encode_octahedral`]; `glsl/rbvh.glsl` decodes identically.
pub fn decode_octahedral(code: u16) -> Vec3 {
    octahedral_direction(code).normalize()
}

/// The direction of octahedral `code` before normalizing: exact arithmetic on the code's bytes
/// (`glsl/rbvh.glsl` computes the same bits), so a sign taken from it agrees on every device.
fn octahedral_direction(code: u16) -> Vec3 {
    let f = |b: u16| (b & 0xFF) as f32 / 255.0 * 2.0 - 1.0;
    let (x, y) = (f(code), f(code >> 8));
    let z = 1.0 - x.abs() - y.abs();
    let t = (-z).max(0.0);
    let x = x + if x >= 0.0 { -t } else { t };
    let y = y + if y >= 0.0 { -t } else { t };
    Vec3::new(x, y, z)
}

fn sign(x: f32) -> f32 {
    if x >= 0.0 {
        1.0
    } else {
        -1.0
    }
}

/// The texel atlas: `rows` rows of `pitch` texels. Tiles are packed on shelves (see `atlas.rs`).
/// The shaders require `pitch` to be a power of two (they locate tiles with shifts): the builder
/// makes it one, and the file reader and the upload refuse any other.
///
/// The last rows are the *bands of packed heights* ([`Atlas::packed_rows`]): every tile in the
/// band of [`PACKED_BITS`]`[b]` has codes of that many bits ([`Texel::fits`]), which the device
/// stores that many bits each ([`Atlas::device_words`]); the rows above hold 16-bit codes. The
/// host keeps every texel as a full [`Texel`] either way, so that the CPU march reads the codes
/// the device decodes.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Atlas {
    /// Texels per row; a power of two (the row stride of every tile).
    pub pitch: u32,
    /// Rows of texels.
    pub rows: u32,
    /// Rows at the end of the atlas whose tiles have packed height codes, band by band in the
    /// order of [`PACKED_BITS`] (the 12-bit rows first, the 8-bit ones last; 0: no such band).
    pub packed_rows: [u32; 3],
    /// `pitch × rows` texels, row-major; unused texels are holes.
    pub texels: Vec<Texel>,
}

/// Widths of the height codes of the atlas's bands of packed heights, widest first (issue
/// "Small and valid at every scale": bytes per texel that fit the surface). A tile whose heights
/// span at most `2^b − 2` quanta of `NARROW_QUANTUM_TEXELS` (1/128 texel, `raster/quantize.rs`)
/// takes the narrowest such `b`, 16 bits where none holds them. Measured on the presets' Q2
/// before the 12- and 10-bit bands (docs/paper-scale.md, "Heights in 10 and 12 bits"): every
/// tile's heights spanned at most 4,094 quanta (32 texels) over its plane, 55–90% at most 1,022.
pub const PACKED_BITS: [u32; 3] = [12, 10, 8];

impl Atlas {
    /// The atlas's bands as (bits, texel range), in the order the device stores them: the
    /// 16-bit rows, then those of each of [`PACKED_BITS`] (empty ranges where a band has none).
    pub fn bands(&self) -> [(u32, std::ops::Range<usize>); 4] {
        let len = self.texels.len();
        let packed: u64 = self.packed_rows.iter().map(|&r| u64::from(r)).sum();
        let at = |rows: u64| (rows as usize).saturating_mul(self.pitch as usize).min(len);
        let mut start = at(u64::from(self.rows).saturating_sub(packed));
        let mut bands = [(16, 0..start), (0, 0..0), (0, 0..0), (0, 0..0)];
        for (b, (&bits, &rows)) in PACKED_BITS.iter().zip(&self.packed_rows).enumerate() {
            let end = start.saturating_add(at(u64::from(rows))).min(len);
            bands[b + 1] = (bits, start..end);
            start = end;
        }
        bands
    }

    /// Bits of the height codes of the band that holds texel `index` (16 beyond the atlas).
    pub fn bits_at(&self, index: usize) -> u32 {
        self.bands()
            .into_iter()
            .find(|(_, range)| range.contains(&index))
            .map_or(16, |(bits, _)| bits)
    }

    /// Texels before the ends of the 16-, 12- and 10-bit bands ([`Atlas::bands`]; the 8-bit band
    /// ends with the atlas): what the trace shaders take as `atlas_wide_len`, `atlas_end12` and
    /// `atlas_end10` (`glsl/atlas.glsl`).
    pub fn band_ends(&self) -> [usize; 3] {
        let bands = self.bands();
        [0, 1, 2].map(|b| bands[b].1.end)
    }

    /// Texels before the bands of packed heights: those the device stores with 16-bit codes.
    pub fn wide_len(&self) -> usize {
        self.bands()[0].1.end
    }

    /// The first texel of a band of packed heights (index, code, the band's bits) whose height
    /// code that band cannot hold ([`Texel::fits`]), which the device could not store: None when
    /// all can.
    pub fn first_code_off_its_band(&self) -> Option<(usize, u16, u32)> {
        self.bands().into_iter().skip(1).find_map(|(bits, range)| {
            range
                .clone()
                .find(|&k| !Texel::fits(self.texels[k].height_code(), bits))
                .map(|k| (k, self.texels[k].height_code(), bits))
        })
    }
}

/// Whether every texel of `leaf`'s tile lies in the atlas: at least one sample per side, each tile
/// row within one atlas row, its last texel `atlas_base + (res_v − 1)·pitch + res_u − 1` in
/// range, and in the band of its first ([`Atlas::bands`]).
/// The loader rejects files with a leaf that does not fit; the march treats one as empty.
pub(super) fn tile_fits(leaf: &GpuHeightfield, atlas: &Atlas) -> bool {
    if leaf.res_u == 0 || leaf.res_v == 0 || leaf.res_u > atlas.pitch {
        return false;
    }
    // A tile must not wrap across atlas rows: its rows are atlas rows (and the device march's
    // block jumps, `src/rbvh/ranges.rs`, count on it).
    if leaf.atlas_base % atlas.pitch + leaf.res_u > atlas.pitch {
        return false;
    }
    let last = u64::from(leaf.atlas_base)
        + u64::from(leaf.res_v - 1) * u64::from(atlas.pitch)
        + u64::from(leaf.res_u - 1);
    // One band: the device reads a tile's texels with its first texel's band (`glsl/atlas.glsl`).
    last < atlas.texels.len() as u64
        && atlas.bits_at(leaf.atlas_base as usize) == atlas.bits_at(last as usize)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rbvh::march::tests::flat_leaf;

    #[test]
    fn codes_carry_their_mark_within_one_code() {
        for sampled in [true, false] {
            for q in [
                0.0, 0.4, 0.5, 1.0, 1.5, 2.49, 777.7, 65533.0, 65533.6, 65534.0, 7e4, -3.0,
            ] {
                let code = Texel::code_of(q, sampled, 16);
                assert!(code <= Texel::MAX_CODE, "{q}: {code}");
                let t = Texel::new(code, Vec3::Z);
                assert_eq!(t.is_sampled(), sampled, "{q}: {code}");
                let clamped = q.clamp(0.0, f64::from(Texel::MAX_CODE));
                assert!((f64::from(code) - clamped).abs() <= 1.0, "{q}: {code}");
            }
        }
        assert_eq!(Texel::code_of(0.0, true, 16), 0);
        assert_eq!(Texel::code_of(0.0, false, 16), 1);
        assert_eq!(Texel::code_of(1e9, true, 16), Texel::MAX_CODE);
        assert_eq!(Texel::code_of(1e9, false, 16), Texel::MAX_CODE - 1);
        assert!(!Texel::HOLE.is_sampled());
    }

    /// A packed code is a whole number of odd steps that keeps its mark, within a step of what
    /// it stands for; the device's expansion of the stored field gives it back, all ones a hole.
    #[test]
    fn packed_codes_are_steps_with_their_mark() {
        assert_eq!(
            PACKED_BITS.map(Texel::step),
            [15, 63, 257],
            "steps of 12, 10 and 8 bits"
        );
        assert_eq!(
            (Texel::step(16), Texel::top(16)),
            (1, u32::from(Texel::MAX_CODE))
        );
        for bits in PACKED_BITS {
            let (step, top) = (Texel::step(bits), Texel::top(bits));
            assert!(
                step % 2 == 1 && top <= u32::from(Texel::MAX_CODE),
                "{bits} bits"
            );
            for sampled in [true, false] {
                for q in [
                    0.0, 100.0, 128.5, 257.0, 3000.3, 61410.0, 65277.0, 65534.0, 1e9, -5.0,
                ] {
                    let code = Texel::code_of(q, sampled, bits);
                    let c = u32::from(code) / step;
                    assert_eq!(u32::from(code), c * step, "{bits} bits, {q}");
                    assert!(
                        u32::from(code) <= top && Texel::fits(code, bits),
                        "{q}: {code}"
                    );
                    assert_eq!(Texel::expand(c, bits), code, "{bits} bits, {q}");
                    assert_eq!(
                        Texel::new(code, Vec3::Z).is_sampled(),
                        sampled,
                        "{q}: {code}"
                    );
                    let clamped = q.clamp(0.0, f64::from(top));
                    assert!(
                        (f64::from(code) - clamped).abs() <= f64::from(step),
                        "{q}: {code}"
                    );
                }
            }
            assert_eq!(Texel::expand((1 << bits) - 1, bits), Texel::HOLE_CODE);
            assert!(Texel::fits(Texel::HOLE_CODE, bits));
            assert!(!Texel::fits(step as u16 + 1, bits), "{bits} bits");
            assert_eq!(u32::from(Texel::code_of(1e9, true, bits)), top);
        }
        assert_eq!(0xFF * Texel::step(8), u32::from(Texel::HOLE_CODE));
    }

    #[test]
    fn octahedral_round_trip_is_within_its_bound() {
        let mut worst = 0.0f32;
        for i in 0..2000 {
            let a = i as f32 * 2.399_963;
            let z = 1.0 - 2.0 * (i as f32 + 0.5) / 2000.0;
            let r = (1.0 - z * z).sqrt();
            let n = Vec3::new(r * a.cos(), r * a.sin(), z);
            let back = decode_octahedral(encode_octahedral(n));
            worst = worst.max(n.dot(back).clamp(-1.0, 1.0).acos().to_degrees());
        }
        assert!(worst < 1.3, "worst octahedral error {worst}°");
        for n in [Vec3::X, Vec3::Y, Vec3::Z, -Vec3::X, -Vec3::Y, -Vec3::Z] {
            assert!(
                decode_octahedral(encode_octahedral(n)).dot(n) > 0.9999,
                "{n}"
            );
        }
    }

    #[test]
    fn a_cell_is_two_triangles_one_with_a_hole_none_with_two() {
        let all: Vec<[u8; 3]> = cell_triangles([Some(0), Some(1), Some(2), Some(3)]).collect();
        assert_eq!(all, [[0, 1, 2], [0, 2, 3]]);
        // One hole: the other three in cycle order, wherever the hole is.
        for hole in 0..4 {
            let mut corners = [Some(0u8), Some(1), Some(2), Some(3)];
            corners[hole] = None;
            let kept: Vec<u8> = (0..4).filter(|&k| k != hole as u8).collect();
            let tris: Vec<[u8; 3]> = cell_triangles(corners).collect();
            assert_eq!(tris, [[kept[0], kept[1], kept[2]]], "hole {hole}");
        }
        assert_eq!(cell_triangles([Some(0), None, Some(2), None]).count(), 0);
        assert_eq!(cell_triangles::<u8>([None; 4]).count(), 0);
    }

    #[test]
    fn texel_packs_height_and_normal() {
        let t = Texel::new(1234, Vec3::Y);
        assert_eq!(t.height_code(), 1234);
        assert!(!t.is_hole() && Texel::HOLE.is_hole());
        assert!(t.normal().dot(Vec3::Y) > 0.9999);
    }

    #[test]
    fn tile_fits_checks_the_last_texel_and_refuses_rows_that_wrap() {
        let atlas = Atlas {
            pitch: 8,
            rows: 4,
            packed_rows: [0; 3],
            texels: vec![Texel::HOLE; 32],
        };
        let fits = |base, res_u, res_v| {
            tile_fits(
                &GpuHeightfield {
                    atlas_base: base,
                    ..flat_leaf(0.0, res_u, res_v, 0.0)
                },
                &atlas,
            )
        };
        assert!(fits(0, 8, 4) && fits(4, 4, 4) && fits(31, 1, 1));
        assert!(!fits(5, 4, 4) && !fits(0, 9, 1) && !fits(0, 0, 1) && !fits(32, 1, 1));
        assert!(!fits(u32::MAX, u32::MAX, u32::MAX));
        // Columns 6, 7 of one row, then 0, 1 of the next: in range, but wrapped.
        assert!(fits(6, 2, 2) && !fits(6, 3, 2) && !fits(14, 4, 1));
        // With its last row 8-bit, a tile of rows 2 and 3 straddles two bands.
        let banded = Atlas {
            packed_rows: [0, 0, 1],
            ..atlas.clone()
        };
        let leaf = |base, res_v| GpuHeightfield {
            atlas_base: base,
            ..flat_leaf(0.0, 4, res_v, 0.0)
        };
        assert!(tile_fits(&leaf(16, 1), &banded) && tile_fits(&leaf(24, 1), &banded));
        assert!(!tile_fits(&leaf(16, 2), &banded) && tile_fits(&leaf(16, 2), &atlas));
    }
}
