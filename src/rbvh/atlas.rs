//! Packing the leaves' tiles into one texel atlas (Novák & Dachsbacher 2012 store every height
//! field as a tile of a shared 2D atlas; how to pack is not in the slides, this is our choice).
//!
//! Shelf packing ("next fit decreasing height", Coffman et al., "Performance Bounds for
//! Level-Oriented Two-Dimensional Packing Algorithms", SIAM J. Comput. 1980): tiles sorted by
//! height are placed left to right on shelves as tall as their first tile. It is simple, fast and
//! deterministic, and since the builder's tiles are many and small next to the atlas, it wastes
//! little (the tests ask for a fill ratio of at least 0.7 on random tiles of 4–64 texels a side).

use std::borrow::Borrow;

use super::layout::{Atlas, Texel, PACKED_BITS};
use super::params::TexelFormat;
use super::ranges::BLOCK;
use super::raster::Tile;
use super::words::rank_words;
use crate::{Error, Result};

/// Smallest atlas pitch.
const MIN_PITCH: u64 = 16;
/// Largest pitch [`pack`] tries. The builder's tiles are at most
/// `max_tile` ≤ 4096 texels wide, so they always fit; a wider tile (never produced) gets the
/// power of two above its width instead, so that packing still succeeds.
const MAX_PITCH: u64 = 16384;

/// What packing needs to know of a tile: its size in texels, and the bits of its height codes
/// (16, or one of [`PACKED_BITS`]: it then goes to the atlas's band of that width,
/// [`Atlas::packed_rows`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Footprint {
    pub res_u: u32,
    pub res_v: u32,
    pub bits: u32,
}

impl Footprint {
    /// The footprint of `tile`.
    pub fn of(tile: &Tile) -> Footprint {
        Footprint {
            res_u: tile.frame.res_u,
            res_v: tile.frame.res_v,
            bits: tile.bits,
        }
    }
}

/// Where each tile lives in the atlas.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Packing {
    /// Texels per atlas row.
    pub pitch: u32,
    pub rows: u32,
    /// Rows at the end that hold the packed tiles, band by band in the order of [`PACKED_BITS`]
    /// (and only those: [`Atlas::packed_rows`]).
    pub packed_rows: [u32; 3],
    /// Per tile (input order): atlas index of its texel (0, 0), `y * pitch + x`. Tiles without
    /// texels (a zero side) are not placed and get 0.
    pub bases: Vec<u32>,
}

/// Shelf packing of `tiles`: the 16-bit ones first, then on new shelves each band of packed
/// heights, widest first (so that each band is whole rows, the 8-bit one at the end); within
/// each, sorted by `res_v` descending, ties by `res_u` descending then input index
/// (deterministic), placed left to right on shelves as tall as their first tile, with a new
/// shelf when the row is full. The pitch is the power of two, from the widest tile's (at least
/// 16) up to 16384 (see [`MAX_PITCH`]), whose texels cost the device the fewest bytes in `format`
/// (then the fewest texels, then the smallest pitch): every unused texel costs the device its
/// bytes, and a pitch chosen for a square atlas left a last shelf of 64-texel tiles mostly empty
/// (the default scene's Q2: 83.5% filled at pitch 1024). Without packed bands that is the pitch
/// of the fewest texels.
///
/// Each band keeps its tiles only where that costs the device fewer bytes in `format` than
/// storing them with 16-bit codes: a band starts on a shelf of its own, and a few tiles save less
/// than that shelf's unused texels cost (the default scene's Q2, 1.4% of its texels 8-bit, took
/// 0.508 → 0.513 MB of atlas with its band). Every choice of bands kept is packed and the
/// cheapest taken (ties keep more bands). A tile stored with 16-bit codes keeps its codes
/// (`step · c`, [`Texel::code_of`]), which every reader decodes the same; so one RBVH's builds in
/// the two formats hold the same tiles and codes, placed apart only where one keeps a band and
/// the other does not.
///
/// Fails when the atlas would need more texels than a 32-bit texel index can address.
pub fn pack(tiles: &[Footprint], format: TexelFormat) -> Result<Packing> {
    let present: Vec<usize> = (0..PACKED_BITS.len())
        .filter(|&b| tiles.iter().any(|f| f.bits == PACKED_BITS[b]))
        .collect();
    let mut best: Option<(u64, Packing)> = None;
    // Subsets of the present bands dropped, the fewest first, so that a tie keeps more bands.
    let mut subsets: Vec<u32> = (0..1u32 << present.len()).collect();
    subsets.sort_by_key(|&dropped| (dropped.count_ones(), dropped));
    for dropped in subsets {
        let kept: Vec<u32> = present
            .iter()
            .enumerate()
            .filter(|&(n, _)| dropped & (1 << n) == 0)
            .map(|(_, &b)| PACKED_BITS[b])
            .collect();
        let given: Vec<Footprint> = tiles
            .iter()
            .map(|&f| Footprint {
                bits: if kept.contains(&f.bits) { f.bits } else { 16 },
                ..f
            })
            .collect();
        let packing = pack_as_given(&given, format)?;
        let bytes = device_bytes(&packing, format);
        if best.as_ref().is_none_or(|(least, _)| bytes < *least) {
            best = Some((bytes, packing));
        }
    }
    Ok(best
        .expect("at least the packing with every present band")
        .1)
}

/// What `packing`'s atlas costs the device in `format` where packing decides it (as
/// [`Atlas::device_words`] lays it out: 2 bytes a 16-bit code, `bits / 8` a packed one, 4 a
/// block range, with normals 12 a span of the rank directory), to a few bytes of rounding. The
/// normals themselves, one a texel that is not a hole, cost the same however the tiles lie.
fn device_bytes(packing: &Packing, format: TexelFormat) -> u64 {
    let (pitch, rows) = (u64::from(packing.pitch), u64::from(packing.rows));
    let blocks = pitch.div_ceil(u64::from(BLOCK)) * rows.div_ceil(u64::from(BLOCK));
    texel_bytes(pitch, rows, packing.packed_rows.map(u64::from), format) + 4 * blocks
}

/// What `rows` rows of `pitch` texels cost the device in `format`, the last `packed_rows` of
/// them in the bands of [`PACKED_BITS`]: their height codes and, with normals, the rank
/// directory over them (the block ranges and the normals aside).
fn texel_bytes(pitch: u64, rows: u64, packed_rows: [u64; 3], format: TexelFormat) -> u64 {
    let wide_rows = rows - packed_rows.iter().sum::<u64>();
    let packed_bits: u64 = PACKED_BITS
        .iter()
        .zip(packed_rows)
        .map(|(&bits, rows)| rows * pitch * u64::from(bits))
        .sum();
    let ranks = match format {
        TexelFormat::HeightNormal => 4 * rank_words((pitch * rows) as usize) as u64,
        TexelFormat::Height => 0,
    };
    2 * wide_rows * pitch + packed_bits.div_ceil(8) + ranks
}

/// [`pack`] with every tile's bits as given.
fn pack_as_given(tiles: &[Footprint], format: TexelFormat) -> Result<Packing> {
    let widest = tiles
        .iter()
        .filter(|f| f.res_v > 0)
        .map(|f| u64::from(f.res_u))
        .max()
        .unwrap_or(0);
    let least = widest.max(MIN_PITCH).next_power_of_two();
    let most = MAX_PITCH.max(least);
    let mut order: Vec<usize> = (0..tiles.len()).collect();
    order.sort_unstable_by_key(|&i| {
        let f = tiles[i];
        (
            std::cmp::Reverse(f.bits),
            std::cmp::Reverse(f.res_v),
            std::cmp::Reverse(f.res_u),
            i,
        )
    });
    let (pitch, shelves) = std::iter::successors(Some(least), |&p| (p < most).then_some(p * 2))
        .map(|pitch| (pitch, shelve(tiles, &order, pitch)))
        .min_by_key(|(pitch, shelves)| {
            let bytes = texel_bytes(*pitch, shelves.rows, shelves.packed_rows(), format);
            (bytes, pitch * shelves.rows, *pitch)
        })
        .expect("at least one pitch");

    let texels = shelves.rows * pitch;
    if texels > u32::MAX as u64 {
        return Err(Error::param(
            "texels_per_diagonal",
            format!(
                "the atlas would need {texels} texels ({pitch} × {}), more than the 2^32 − 1 a \
                 32-bit texel index addresses; lower the sampling rate",
                shelves.rows
            ),
        ));
    }
    Ok(Packing {
        pitch: pitch as u32,
        rows: shelves.rows as u32,
        packed_rows: shelves.packed_rows().map(|r| r as u32),
        bases: shelves
            .origins
            .iter()
            .map(|&(x, y)| (y * pitch + x) as u32)
            .collect(),
    })
}

/// Where [`pack`]'s shelves put the tiles at one pitch.
struct Shelves {
    /// Per tile (input order), its texel (0, 0) as (column, row); (0, 0) for a tile not placed.
    origins: Vec<(u64, u64)>,
    rows: u64,
    /// First row of each band of [`PACKED_BITS`] (where the next begins, or `rows`, for a band
    /// without tiles).
    packed_from: [u64; 3],
}

impl Shelves {
    /// Rows of each band of [`PACKED_BITS`].
    fn packed_rows(&self) -> [u64; 3] {
        let end = |b: usize| self.packed_from.get(b + 1).copied().unwrap_or(self.rows);
        [0, 1, 2].map(|b| end(b) - self.packed_from[b])
    }
}

/// Places `tiles` in `order` (16-bit tiles first, then by band) on shelves of `pitch` texels.
fn shelve(tiles: &[Footprint], order: &[usize], pitch: u64) -> Shelves {
    let mut origins = vec![(0u64, 0u64); tiles.len()];
    let (mut x, mut shelf_y, mut shelf_h) = (0u64, 0u64, 0u64);
    let mut starts: [Option<u64>; 3] = [None; 3];
    for &i in order {
        let f = tiles[i];
        let (u, v) = (u64::from(f.res_u), u64::from(f.res_v));
        if u == 0 || v == 0 {
            continue;
        }
        let band = PACKED_BITS.iter().position(|&b| b == f.bits);
        if let Some(b) = band.filter(|&b| starts[b].is_none()) {
            // Each band starts on a shelf of its own.
            shelf_y += shelf_h;
            (x, shelf_h) = (0, 0);
            starts[b] = Some(shelf_y);
        }
        if x + u > pitch {
            shelf_y += shelf_h;
            (x, shelf_h) = (0, 0);
        }
        if x == 0 {
            shelf_h = v;
        }
        origins[i] = (x, shelf_y);
        x += u;
    }
    let rows = shelf_y + shelf_h;
    let mut packed_from = [rows; 3];
    for b in (0..3).rev() {
        let next = packed_from.get(b + 1).copied().unwrap_or(rows);
        packed_from[b] = starts[b].unwrap_or(next);
    }
    Shelves {
        origins,
        rows,
        packed_from,
    }
}

/// Copies every tile's texels into an atlas of `pitch × rows` texels ([`Texel::HOLE`] elsewhere).
/// `tiles` may be `&[Tile]` or `&[&Tile]` (anything that borrows as a [`Tile`]), in the order that
/// was given to [`pack`]. Should a tile not match the packing (a caller's error), only the part of
/// it that lies inside its own rows and inside the atlas is copied.
pub fn assemble<T: Borrow<Tile>>(tiles: &[T], packing: &Packing) -> Atlas {
    let pitch = packing.pitch as usize;
    let mut texels = vec![Texel::HOLE; pitch * packing.rows as usize];
    for (tile, &base) in tiles.iter().zip(&packing.bases) {
        let tile = tile.borrow();
        let res_u = tile.frame.res_u as usize;
        if res_u == 0 {
            continue;
        }
        for (j, row) in tile.texels.chunks(res_u).enumerate() {
            let start = base as usize + j * pitch;
            if let Some(dst) = texels.get_mut(start..start + row.len()) {
                dst.copy_from_slice(row);
            }
        }
    }
    Atlas {
        pitch: packing.pitch,
        rows: packing.rows,
        packed_rows: packing.packed_rows,
        texels,
    }
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::super::raster::Frame;
    use super::*;

    /// Deterministic pseudo-random tile sizes in `lo..=hi` (a 64-bit LCG, Knuth's MMIX constants).
    fn sizes(n: usize, lo: u32, hi: u32) -> Vec<(u32, u32)> {
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut next = || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            lo + ((state >> 33) % (hi - lo + 1) as u64) as u32
        };
        (0..n).map(|_| (next(), next())).collect()
    }

    /// Footprints of wide tiles of the given sizes.
    fn wide(sizes: &[(u32, u32)]) -> Vec<Footprint> {
        sizes
            .iter()
            .map(|&(res_u, res_v)| Footprint {
                res_u,
                res_v,
                bits: 16,
            })
            .collect()
    }

    fn check_placement(sizes: &[(u32, u32)], p: &Packing) {
        assert_eq!(p.bases.len(), sizes.len());
        assert!(p.pitch.is_power_of_two() && p.pitch >= 16);
        let rects: Vec<_> = sizes
            .iter()
            .zip(&p.bases)
            .map(|(&(u, v), &b)| (b % p.pitch, b / p.pitch, u, v))
            .collect();
        for &(x, y, u, v) in &rects {
            assert!(
                x + u <= p.pitch && y + v <= p.rows,
                "({x}, {y}) {u}×{v} outside"
            );
        }
        for (a, &(ax, ay, au, av)) in rects.iter().enumerate() {
            for &(bx, by, bu, bv) in &rects[a + 1..] {
                let apart = ax + au <= bx || bx + bu <= ax || ay + av <= by || by + bv <= ay;
                assert!(
                    apart,
                    "({ax}, {ay}) {au}×{av} overlaps ({bx}, {by}) {bu}×{bv}"
                );
            }
        }
    }

    #[test]
    fn random_tiles_do_not_overlap_and_fill_well() {
        for n in [1, 7, 100, 300, 600] {
            let s = sizes(n, 4, 64);
            let p = pack(&wide(&s), TexelFormat::HeightNormal).unwrap();
            check_placement(&s, &p);
            let used: u64 = s.iter().map(|&(u, v)| u as u64 * v as u64).sum();
            let fill = used as f64 / (p.pitch as u64 * p.rows as u64) as f64;
            if n >= 100 {
                assert!(fill >= 0.7, "{n} tiles: fill {fill}");
            }
            assert_eq!(
                pack(&wide(&s), TexelFormat::HeightNormal).unwrap(),
                p,
                "not deterministic"
            );
        }
    }

    /// Each band of packed heights is whole rows after the 16-bit ones, widest first, and holds
    /// its tiles alone.
    #[test]
    fn packed_tiles_fill_whole_rows_at_the_end_band_by_band() {
        let s = sizes(400, 4, 64);
        let tiles: Vec<Footprint> = s
            .iter()
            .enumerate()
            .map(|(n, &(res_u, res_v))| Footprint {
                res_u,
                res_v,
                bits: [16, 12, 10, 8][n % 4],
            })
            .collect();
        let p = pack(&tiles, TexelFormat::HeightNormal).unwrap();
        check_placement(&s, &p);
        assert!(p.packed_rows.iter().all(|&r| r > 0), "{:?}", p.packed_rows);
        let atlas = assemble::<Tile>(&[], &p);
        let bands = Atlas {
            texels: vec![Texel::HOLE; (p.pitch * p.rows) as usize],
            ..atlas
        }
        .bands();
        assert!(!bands[0].1.is_empty());
        for (f, &base) in tiles.iter().zip(&p.bases) {
            let last = base + (f.res_v - 1) * p.pitch + f.res_u - 1;
            let (_, band) = bands.iter().find(|(bits, _)| *bits == f.bits).unwrap();
            assert!(
                band.contains(&(base as usize)) && band.contains(&(last as usize)),
                "a {}-bit tile at {base}..={last} outside its band {band:?}",
                f.bits
            );
        }
        for bits in PACKED_BITS {
            let all: Vec<Footprint> = tiles.iter().map(|&f| Footprint { bits, ..f }).collect();
            let p = pack(&all, TexelFormat::HeightNormal).unwrap();
            let b = PACKED_BITS.iter().position(|&x| x == bits).unwrap();
            assert_eq!(p.packed_rows[b], p.rows, "{bits} bits");
        }
        assert_eq!(
            pack(&wide(&s), TexelFormat::HeightNormal)
                .unwrap()
                .packed_rows,
            [0; 3]
        );
    }

    /// A band of one small 8-bit tile would take a shelf of its own, where stored wide it fits
    /// beside the last wide tile: it is stored wide, in either format.
    #[test]
    fn a_band_that_costs_more_than_it_saves_is_not_kept() {
        let mut tiles = wide(&[(60, 64); 5]);
        tiles.push(Footprint {
            res_u: 4,
            res_v: 8,
            bits: 8,
        });
        let sizes: Vec<(u32, u32)> = tiles.iter().map(|f| (f.res_u, f.res_v)).collect();
        for format in [TexelFormat::HeightNormal, TexelFormat::Height] {
            let p = pack(&tiles, format).unwrap();
            check_placement(&sizes, &p);
            assert_eq!(
                (p.pitch, p.rows, p.packed_rows),
                (64, 320, [0; 3]),
                "{format:?}"
            );
            let banded = pack_as_given(&tiles, format).unwrap();
            assert_eq!(banded.packed_rows, [0, 0, 8]);
            assert!(device_bytes(&p, format) < device_bytes(&banded, format));
        }
        // Beside five whole 12-bit tiles, whose band pays, the small tile's band (10-bit now) is
        // still dropped: each band is judged, not all of them together.
        let mut mixed = tiles.clone();
        mixed[5].bits = 10;
        mixed.extend((0..5).map(|_| Footprint {
            res_u: 64,
            res_v: 64,
            bits: 12,
        }));
        let sizes: Vec<(u32, u32)> = mixed.iter().map(|f| (f.res_u, f.res_v)).collect();
        let p = pack(&mixed, TexelFormat::HeightNormal).unwrap();
        check_placement(&sizes, &p);
        assert_eq!((p.pitch, p.rows, p.packed_rows), (64, 640, [320, 0, 0]));
        assert!(
            p.bases[5] < 320 * 64,
            "the 10-bit tile among the 16-bit rows"
        );
    }

    /// Five 64 × 64 tiles: a square atlas (pitch 256) would leave its second shelf half empty
    /// (32,768 texels); the pitch of one tile wastes nothing.
    #[test]
    fn the_pitch_with_the_fewest_texels_is_chosen() {
        let s = vec![(64, 64); 5];
        let p = pack(&wide(&s), TexelFormat::HeightNormal).unwrap();
        check_placement(&s, &p);
        assert_eq!((p.pitch, p.rows), (64, 320));
        // Against every pitch it could have taken, none holds them in fewer texels.
        let tiles = wide(&s);
        let order: Vec<usize> = (0..tiles.len()).collect();
        for pitch in [64u64, 128, 256, 512, 1024] {
            let rows = shelve(&tiles, &order, pitch).rows;
            assert!(
                pitch * rows >= u64::from(p.pitch) * u64::from(p.rows),
                "{pitch}"
            );
        }
    }

    #[test]
    fn equal_and_zero_sized_tiles_are_placed_deterministically() {
        let s = vec![(8, 8), (0, 5), (8, 8), (16, 4), (3, 0), (8, 8)];
        let p = pack(&wide(&s), TexelFormat::HeightNormal).unwrap();
        check_placement(&s, &p);
        // Equal tiles keep their input order along the shelf.
        assert!(p.bases[0] < p.bases[2] && p.bases[2] < p.bases[5]);
        assert_eq!((p.bases[1], p.bases[4]), (0, 0));
    }

    #[test]
    fn empty_input_gives_an_empty_atlas() {
        let p = pack(&[], TexelFormat::HeightNormal).unwrap();
        assert_eq!(
            p,
            Packing {
                pitch: 16,
                rows: 0,
                packed_rows: [0; 3],
                bases: vec![]
            }
        );
        let atlas = assemble::<Tile>(&[], &p);
        assert_eq!((atlas.pitch, atlas.rows), (16, 0));
        assert!(atlas.texels.is_empty());
    }

    #[test]
    fn oversized_atlas_is_a_parameter_error() {
        for s in [vec![(16384, 16384); 17], vec![(u32::MAX, u32::MAX)]] {
            let err = pack(&wide(&s), TexelFormat::HeightNormal)
                .unwrap_err()
                .to_string();
            assert!(err.contains("texels_per_diagonal") && err.contains("lower the sampling rate"));
        }
        // A tile wider than the usual pitch cap still packs.
        let p = pack(&wide(&[(20000, 2)]), TexelFormat::HeightNormal).unwrap();
        assert_eq!((p.pitch, p.rows), (32768, 2));
    }

    #[test]
    fn assemble_places_texels_at_their_bases() {
        let s = sizes(40, 1, 9);
        let tiles: Vec<Tile> = s
            .iter()
            .enumerate()
            .map(|(n, &(u, v))| Tile {
                frame: Frame {
                    origin: Vec3::ZERO,
                    u: Vec3::X,
                    v: Vec3::Y,
                    w: Vec3::Z,
                    texel: 1.0,
                    res_u: u,
                    res_v: v,
                },
                texels: (0..u * v)
                    .map(|k| Texel::new((n as u32 * 100 + k) as u16, Vec3::Z))
                    .collect(),
                h_scale: 1.0,
                slope: glam::Vec2::ZERO,
                bits: 16,
                covered: u * v,
                sources: Vec::new(),
                exposed: Vec::new(),
            })
            .collect();
        let p = pack(&wide(&s), TexelFormat::HeightNormal).unwrap();
        let refs: Vec<&Tile> = tiles.iter().collect();
        let atlas = assemble(&refs, &p);
        assert_eq!(atlas, assemble(&tiles, &p));
        assert_eq!(atlas.texels.len(), (p.pitch * p.rows) as usize);
        let mut filled = 0;
        for (tile, &base) in tiles.iter().zip(&p.bases) {
            let (u, v) = (tile.frame.res_u, tile.frame.res_v);
            for j in 0..v {
                for i in 0..u {
                    let got = atlas.texels[(base + j * p.pitch + i) as usize];
                    assert_eq!(got, tile.texels[(j * u + i) as usize]);
                    filled += 1;
                }
            }
        }
        let non_holes = atlas.texels.iter().filter(|t| !t.is_hole()).count();
        assert_eq!(non_holes, filled);
    }
}
