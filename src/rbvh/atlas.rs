//! Packing the leaves' tiles into one texel atlas (Novák & Dachsbacher 2012 store every height
//! field as a tile of a shared 2D atlas; how to pack is not in the slides, this is our choice).
//!
//! Shelf packing ("next fit decreasing height", Coffman et al., "Performance Bounds for
//! Level-Oriented Two-Dimensional Packing Algorithms", SIAM J. Comput. 1980): tiles sorted by
//! height are placed left to right on shelves as tall as their first tile. It is simple, fast and
//! deterministic, and since the builder's tiles are many and small next to the atlas, it wastes
//! little (the tests ask for a fill ratio of at least 0.7 on random tiles of 4–64 texels a side).

use std::borrow::Borrow;

use super::layout::{Atlas, Texel};
use super::raster::Tile;
use crate::{Error, Result};

/// Smallest atlas pitch.
const MIN_PITCH: u64 = 16;
/// Largest pitch chosen for the sake of a square-ish atlas. The builder's tiles are at most
/// `max_tile` ≤ 4096 texels wide, so they always fit; a wider tile (never produced) gets the
/// power of two above its width instead, so that packing still succeeds.
const MAX_PITCH: u64 = 16384;

/// Where each tile lives in the atlas.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Packing {
    /// Texels per atlas row.
    pub pitch: u32,
    pub rows: u32,
    /// Per tile (input order): atlas index of its texel (0, 0), `y * pitch + x`. Tiles without
    /// texels (a zero side) are not placed and get 0.
    pub bases: Vec<u32>,
}

/// Shelf packing of tiles given as `(res_u, res_v)`: sorted by `res_v` descending, ties by `res_u`
/// descending then input index (deterministic), placed left to right on shelves as tall as their
/// first tile, with a new shelf when the row is full. The pitch is the smallest power of two
/// ≥ max(widest tile, ⌈√(1.1 · total texels)⌉) and ≥ 16, capped at 16384 (see [`MAX_PITCH`]).
///
/// Fails when the atlas would need more texels than a 32-bit texel index can address.
pub fn pack(sizes: &[(u32, u32)]) -> Result<Packing> {
    let placed = || sizes.iter().filter(|&&(u, v)| u > 0 && v > 0);
    let total = placed().fold(0u64, |sum, &(u, v)| sum.saturating_add(u as u64 * v as u64));
    let widest = placed().map(|&(u, _)| u as u64).max().unwrap_or(0);
    let square = (total as f64 * 1.1).sqrt().ceil() as u64;
    let pitch = widest
        .max(square)
        .max(MIN_PITCH)
        .next_power_of_two()
        .min(MAX_PITCH.max(widest.next_power_of_two()));

    let mut order: Vec<usize> = (0..sizes.len()).collect();
    order.sort_unstable_by_key(|&i| {
        let (u, v) = sizes[i];
        (std::cmp::Reverse(v), std::cmp::Reverse(u), i)
    });

    let mut origins = vec![(0u64, 0u64); sizes.len()];
    let (mut x, mut shelf_y, mut shelf_h) = (0u64, 0u64, 0u64);
    for i in order {
        let (u, v) = (sizes[i].0 as u64, sizes[i].1 as u64);
        if u == 0 || v == 0 {
            continue;
        }
        if x + u > pitch {
            shelf_y += shelf_h;
            x = 0;
            shelf_h = 0;
        }
        if x == 0 {
            shelf_h = v;
        }
        origins[i] = (x, shelf_y);
        x += u;
    }
    let rows = shelf_y + shelf_h;

    let texels = rows * pitch;
    if texels > u32::MAX as u64 {
        return Err(Error::param(
            "texels_per_diagonal",
            format!(
                "the atlas would need {texels} texels ({pitch} × {rows}), more than the 2^32 − 1 \
                 a 32-bit texel index addresses; lower the sampling rate"
            ),
        ));
    }
    Ok(Packing {
        pitch: pitch as u32,
        rows: rows as u32,
        bases: origins
            .iter()
            .map(|&(x, y)| (y * pitch + x) as u32)
            .collect(),
    })
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
            let p = pack(&s).unwrap();
            check_placement(&s, &p);
            let used: u64 = s.iter().map(|&(u, v)| u as u64 * v as u64).sum();
            let fill = used as f64 / (p.pitch as u64 * p.rows as u64) as f64;
            if n >= 100 {
                assert!(fill >= 0.7, "{n} tiles: fill {fill}");
            }
            assert_eq!(pack(&s).unwrap(), p, "not deterministic");
        }
    }

    #[test]
    fn equal_and_zero_sized_tiles_are_placed_deterministically() {
        let s = vec![(8, 8), (0, 5), (8, 8), (16, 4), (3, 0), (8, 8)];
        let p = pack(&s).unwrap();
        check_placement(&s, &p);
        // Equal tiles keep their input order along the shelf.
        assert!(p.bases[0] < p.bases[2] && p.bases[2] < p.bases[5]);
        assert_eq!((p.bases[1], p.bases[4]), (0, 0));
    }

    #[test]
    fn empty_input_gives_an_empty_atlas() {
        let p = pack(&[]).unwrap();
        assert_eq!(
            p,
            Packing {
                pitch: 16,
                rows: 0,
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
            let err = pack(&s).unwrap_err().to_string();
            assert!(err.contains("texels_per_diagonal") && err.contains("lower the sampling rate"));
        }
        // A tile wider than the usual pitch cap still packs.
        let p = pack(&[(20000, 2)]).unwrap();
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
                covered: u * v,
                sources: Vec::new(),
                exposed: Vec::new(),
            })
            .collect();
        let p = pack(&s).unwrap();
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
