//! The RBVH file through the public API: exact round trips, the documented layout, errors that
//! name the file and say what is wrong, and saves that are all or nothing.

mod rbvh_files;

use std::ops::Range;
use std::path::Path;

use glam::Vec3;
use rbvh::bvh::{GpuNode, GpuTriangle, LEAF_BIT};
use rbvh::geom::Aabb;
use rbvh::rbvh::file::{section_table, REQUIRED};
use rbvh::rbvh::{
    Atlas, Child, ExactTriangles, GpuHeightfield, Rbvh, RbvhParams, RbvhStats, Refinement,
    Subdivision, Texel, TexelFormat,
};
use rbvh::Error;

use rbvh_files::{as_v12, as_version, assemble, parts, Parts, V12_HEADER_BYTES, V6_HEADER_BYTES};

/// A small hybrid RBVH built by hand: a root over an inner node (two height-field leaves) and a
/// triangle leaf, in a 8 × 9 atlas holding a 4 × 4 and a 3 × 5 tile.
fn sample() -> Rbvh {
    let leaf = |origin: [f32; 3], atlas_base, res_u, res_v| GpuHeightfield {
        origin,
        atlas_base,
        axis_u: [2.0, 0.0, 0.0],
        res_u,
        axis_v: [0.0, 0.0, 2.0],
        res_v,
        axis_w: [0.0, 1.0, 0.0],
        h_scale: 1.0e-4,
    };
    let heightfields = vec![
        leaf([0.0, 0.0, 0.0], 0, 4, 4),
        leaf([5.0, -1.0, 0.5], 36, 3, 5),
    ];
    let mut texels = vec![Texel::HOLE; 8 * 9];
    for (k, t) in texels.iter_mut().enumerate() {
        if k % 5 != 3 {
            *t = Texel::new(
                (k * 977 % 65_000) as u16,
                Vec3::new(0.1 * k as f32, 1.0, -0.3),
            );
        }
    }
    let triangles = vec![
        GpuTriangle::new([Vec3::ZERO, Vec3::X, Vec3::Z], 4),
        // An exact part beside height-field leaf 1: its flags round-trip.
        GpuTriangle {
            flags: GpuTriangle::part_flags(1, false),
            ..GpuTriangle::new([Vec3::ONE, Vec3::Y, -Vec3::Z], 9)
        },
    ];
    let unit = Aabb {
        min: Vec3::splat(-1.0),
        max: Vec3::splat(6.0),
    };
    let hf = |index| Child::Heightfield(index).with_bounds(unit);
    let nodes = vec![
        GpuNode::new(
            Child::Inner(1).with_bounds(unit),
            Child::Triangles { first: 0, count: 2 }.with_bounds(unit),
        ),
        GpuNode::new(hf(0), hf(1)),
    ];
    Rbvh {
        params: RbvhParams {
            refinement: Refinement::ProjectedArea { min_ratio: 0.75 },
            subdivision: Subdivision::AreaSah,
            object_split: false,
            sampled_criterion_texels: 2.5,
            object_rate: 0.375,
            exact_when_cheaper: true,
            // As every version before 12 loads: the crease rule is a field they lack.
            exact_crease_deg: 0.0,
            ..RbvhParams::quality(3).unwrap()
        },
        nodes,
        triangles: ExactTriangles::new(triangles),
        heightfields,
        atlas: Atlas {
            pitch: 8,
            rows: 9,
            packed_rows: [0; 3],
            texels,
        },
        bounds: unit,
        depth: 2,
        texel_size: 0.5,
        colours: None,
        stats: RbvhStats {
            build_ms: 12.25,
            heightfield_leaves: 2,
            triangle_leaves: 1,
            tile_texels: 31,
        },
    }
}

/// The message of a Parse error, after checking that it names `path`.
fn parse_error(result: rbvh::Result<Rbvh>, path: &Path) -> String {
    match result {
        Err(e @ Error::Parse { .. }) => {
            let text = e.to_string();
            assert!(text.contains(&path.display().to_string()), "{text}");
            text
        }
        other => panic!("expected a parse error, got {other:?}"),
    }
}

#[test]
fn save_load_round_trips_exactly() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("scene.rbvh");
    let original = sample();
    original.save(&path).unwrap();
    let loaded = Rbvh::load(&path).unwrap();
    assert_eq!(loaded, original);
    let bytes = std::fs::read(&path).unwrap();
    assert_eq!(bytes, original.to_bytes());
    let again = dir.path().join("again.rbvh");
    loaded.save(&again).unwrap();
    assert_eq!(std::fs::read(&again).unwrap(), bytes);

    // The documented framing: magic, version 13, six sections (no colour channel) and their
    // checksums in the written order, each at the first multiple of 8 after the one before, the
    // file ending with the last.
    assert_eq!(&bytes[..8], b"RBVHv\0\0\0");
    assert_eq!((word(&bytes, 8), word(&bytes, 12)), (13, 7));
    assert_eq!(&bytes[16..20], b"PARM");
    assert_eq!(u64_at(&bytes, 28), 216);
    let table: Vec<_> = section_table(&bytes, &path)
        .unwrap()
        .into_iter()
        .map(|s| (s.tag, s.version, s.flags, s.offset, s.length))
        .collect();
    assert_eq!(
        table,
        [
            (*b"PARM", 8, REQUIRED, 216, 56),
            (*b"HEAD", 2, REQUIRED, 272, 76),
            (*b"NODE", 1, REQUIRED, 352, 2 * 48),
            (*b"TRIS", 1, REQUIRED, 448, 2 * 48),
            (*b"LEAF", 2, REQUIRED, 544, 2 * 64),
            (*b"TEXN", 1, REQUIRED, 672, 72 * 4),
            (*b"SUMS", 1, 0, 960, 6 * 8),
        ]
    );
    assert_eq!(bytes.len(), 960 + 6 * 8);
    // Each section's tag and CRC-32, in the table's order.
    for (k, s) in section_table(&bytes, &path).unwrap()[..6]
        .iter()
        .enumerate()
    {
        let record = 960 + 8 * k;
        assert_eq!(&bytes[record..record + 4], &s.tag);
        assert_eq!(word(&bytes, record + 4), crc32fast::hash(&bytes[s.bytes()]));
    }
    // The parameters: the sampling judgement's size, each object's rate, whether triangles are
    // traced exactly where cheaper, from what size, from what edge, from what crease, and the
    // view's rate last.
    assert_eq!(f32::from_bits(word(&bytes, parm(&bytes, 7))), 2.5);
    assert_eq!(f32::from_bits(word(&bytes, parm(&bytes, 8))), 0.375);
    assert_eq!(word(&bytes, parm(&bytes, 9)), 1);
    for k in 10..14 {
        assert_eq!(f32::from_bits(word(&bytes, parm(&bytes, k))), 0.0);
    }
    // The structure: the atlas's pitch, rows and packed rows last.
    let at = head(&bytes);
    assert_eq!(
        [56, 60, 64, 68, 72].map(|k| word(&bytes, at + k)),
        [8, 9, 0, 0, 0]
    );
    assert_eq!(word(&bytes, 672), original.atlas.texels[0].0);
}

/// The little-endian u64 at byte `at`.
fn u64_at(bytes: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(bytes[at..at + 8].try_into().unwrap())
}

/// The bytes of section `tag` of a current file.
fn section(bytes: &[u8], tag: &[u8; 4]) -> Range<usize> {
    section_table(bytes, Path::new("any.rbvh"))
        .unwrap()
        .iter()
        .find(|s| &s.tag == tag)
        .unwrap_or_else(|| panic!("no section {}", tag.escape_ascii()))
        .bytes()
}

/// The byte of word `k` of a current file's `PARM` section (the parameters' table in the
/// module docs).
fn parm(bytes: &[u8], k: usize) -> usize {
    section(bytes, b"PARM").start + 4 * k
}

/// The first byte of a current file's `HEAD` section.
fn head(bytes: &[u8]) -> usize {
    section(bytes, b"HEAD").start
}

/// Sets the little-endian u32 at byte `at`.
fn set(bytes: &mut [u8], at: usize, value: u32) {
    bytes[at..at + 4].copy_from_slice(&value.to_le_bytes());
}

/// The little-endian u32 at byte `at`.
fn word(bytes: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap())
}

#[test]
fn odd_float_values_survive_bit_for_bit() {
    let mut r = sample();
    r.bounds = Aabb::EMPTY;
    r.stats.build_ms = -0.0;
    edit_triangle(&mut r, 0, |t| {
        t.v0 = [f32::from_bits(0x7fc0_1234), -0.0, f32::MIN_POSITIVE]
    });
    let back = Rbvh::from_bytes(&r.to_bytes(), Path::new("odd.rbvh")).unwrap();
    assert_eq!(back.to_bytes(), r.to_bytes());
    assert_eq!(back.bounds, Aabb::EMPTY);
}

#[test]
fn truncated_files_are_parse_errors_naming_the_file() {
    let path = Path::new("cut.rbvh");
    let current = sample().to_bytes();
    let v12 = as_v12(&sample());
    let cuts = [
        // The magic, the version, the section count, the table, each section.
        (
            &current,
            vec![
                0,
                3,
                8,
                11,
                12,
                15,
                16,
                50,
                184,
                240,
                400,
                current.len() - 1,
            ],
        ),
        (
            &v12,
            vec![
                50,
                V12_HEADER_BYTES - 1,
                V12_HEADER_BYTES,
                V12_HEADER_BYTES + 100,
                v12.len() - 1,
            ],
        ),
    ];
    for (bytes, lens) in cuts {
        for len in lens {
            let message = parse_error(Rbvh::from_bytes(&bytes[..len], path), path);
            assert!(message.contains("truncated"), "{len}: {message}");
        }
        // One byte too many is as wrong as one too few.
        let mut long = bytes.clone();
        long.push(0);
        let message = parse_error(Rbvh::from_bytes(&long, path), path);
        assert!(message.contains("trailing"), "{message}");
    }
}

#[test]
fn bad_magic_and_unknown_versions_are_rejected() {
    let path = Path::new("x.rbvh");
    let mut bytes = sample().to_bytes();
    bytes[0] = b'P';
    let message = parse_error(Rbvh::from_bytes(&bytes, path), path);
    assert!(message.contains("not an RBVH file"), "{message}");

    for version in [0, 14, u32::MAX] {
        let mut bytes = sample().to_bytes();
        bytes[8..12].copy_from_slice(&version.to_le_bytes());
        let message = parse_error(Rbvh::from_bytes(&bytes, path), path);
        assert!(
            message.contains(&format!("unsupported version {version}")),
            "{message}"
        );
        assert!(message.contains("reads versions 1 to 13"), "{message}");
    }
}

/// Files written before version 6 (1: normal texels; 2: with colours; 3: height-only; 4: with
/// the sampled judgement's size and the texel format in the header, all with 64-byte nodes; 5:
/// 48-byte nodes) load as the RBVHs they described, their nodes quantized, and are saved again as
/// version 13. Before version 4 they were built by the paper's rule alone, before version 7
/// every texel was the scene's (`object_rate` 0), and before version 9 every triangle a height
/// field could hold was sampled (`exact_when_cheaper` false). Their height codes
/// carry no mark of which were sampled, so each even one becomes odd (extrapolated: no skirt)
/// within one code where that keeps it inside its leaf's box, the normals as they were.
#[test]
fn older_versions_load_as_what_they_described() {
    let path = Path::new("old.rbvh");
    let plain = sample();
    let mut painted = sample();
    painted.colours = Some((0..72u32).map(|k| k.wrapping_mul(0x0101_0107)).collect());
    let mut height = sample();
    height.params.texels = TexelFormat::Height;
    for t in &mut height.atlas.texels {
        *t = Texel(u32::from(t.height_code()));
    }
    let mut v4 = sample();
    v4.colours = Some((0..72u32).map(|k| k.wrapping_mul(0x0301_0701)).collect());
    let v5 = sample();
    for (version, rbvh) in [(1, plain), (2, painted), (3, height), (4, v4), (5, v5)] {
        let old = as_version(&rbvh, version);
        let mut loaded = Rbvh::from_bytes(&old, path).unwrap();
        let mut unmarked = 0;
        for (got, was) in loaded.atlas.texels.iter().zip(&rbvh.atlas.texels) {
            let (g, w) = (got.height_code(), was.height_code());
            assert_eq!(got.0 >> 16, was.0 >> 16, "version {version}");
            assert!(
                g == w || (w % 2 == 0 && g % 2 == 1 && g.abs_diff(w) == 1),
                "{w} → {g}"
            );
            unmarked += usize::from(g != w);
        }
        assert!(
            unmarked >= 5,
            "version {version}: {unmarked} codes unmarked"
        );
        loaded.atlas.texels.clone_from(&rbvh.atlas.texels);
        // Nodes saved as full boxes (before version 5) are quantized again, each plane strictly
        // outside the one it was (the nodes' planes never meet what they bound); later ones come
        // back as they were: the same children, in boxes that hold the saved ones, a step looser
        // at most.
        assert_eq!(loaded.nodes.len(), rbvh.nodes.len(), "version {version}");
        for (got, was) in loaded.nodes.iter().zip(&rbvh.nodes) {
            for (g, w) in got.children().iter().zip(was.children()) {
                assert_eq!((g.child, g.count), (w.child, w.count), "version {version}");
                if w.count == 0 && w.child & rbvh::bvh::LEAF_BIT != 0 {
                    continue;
                }
                let (gb, wb) = (g.bounds, w.bounds);
                assert!(
                    gb.min.cmple(wb.min).all() && gb.max.cmpge(wb.max).all(),
                    "version {version}: {gb:?} does not hold {wb:?}"
                );
                let loose = (wb.min - gb.min).max(gb.max - wb.max);
                assert!(
                    loose
                        .cmple(
                            2.0 * (wb.max - wb.min).max_element() / 254.0
                                + 1e-6 * wb.max.abs().max(wb.min.abs())
                        )
                        .all(),
                    "version {version}: {gb:?} against {wb:?}"
                );
            }
        }
        loaded.nodes.clone_from(&rbvh.nodes);
        let sampled_criterion_texels = if version < 4 {
            0.0
        } else {
            rbvh.params.sampled_criterion_texels
        };
        let expected = Rbvh {
            params: RbvhParams {
                sampled_criterion_texels,
                object_rate: 0.0,
                exact_when_cheaper: false,
                ..rbvh.params
            },
            ..rbvh
        };
        assert_eq!(loaded, expected, "version {version}");
        assert_eq!(word(&loaded.to_bytes(), 8), 13);
        let header = if version < 4 { 136 } else { V6_HEADER_BYTES };
        let message = parse_error(Rbvh::from_bytes(&old[..old.len() - 1], path), path);
        assert!(
            message.contains("truncated") && message.contains(&format!("{header}-byte header")),
            "version {version}: {message}"
        );
    }
}

/// A version 6 file (marked heights, no `object_rate`) loads as it was, every texel the
/// scene's, and is saved again as version 13.
#[test]
fn version_6_loads_with_every_texel_the_scenes() {
    let rbvh = sample();
    let loaded = Rbvh::from_bytes(&as_version(&rbvh, 6), Path::new("v6.rbvh")).unwrap();
    let expected = Rbvh {
        params: RbvhParams {
            object_rate: 0.0,
            exact_when_cheaper: false,
            ..rbvh.params
        },
        ..rbvh
    };
    assert_eq!(loaded, expected);
    assert_eq!(word(&loaded.to_bytes(), 8), 13);
}

/// `rbvh` built without tracing any triangle exactly for its size, as versions 1–8 were.
fn all_sampled(rbvh: &Rbvh) -> Rbvh {
    Rbvh {
        params: RbvhParams {
            exact_when_cheaper: false,
            ..rbvh.params
        },
        ..rbvh.clone()
    }
}

/// A version 8 file loads as built by sampling every triangle it could (`exact_when_cheaper`
/// false); both values round-trip; any other value of the flag is a parse error.
#[test]
fn exact_when_cheaper_round_trips_and_is_checked() {
    let rbvh = sample();
    let path = Path::new("v8.rbvh");
    let loaded = Rbvh::from_bytes(&as_version(&rbvh, 8), path).unwrap();
    assert_eq!(loaded, all_sampled(&rbvh));
    let saved = loaded.to_bytes();
    assert_eq!(word(&saved, parm(&saved, 9)), 0);
    for r in [rbvh.clone(), all_sampled(&rbvh)] {
        assert_eq!(Rbvh::from_bytes(&r.to_bytes(), path).unwrap(), r);
    }
    let mut bad = rbvh.to_bytes();
    let at = parm(&bad, 9);
    set(&mut bad, at, 2);
    let message = parse_error(Rbvh::from_bytes(&bad, path), path);
    assert!(
        message.contains("params.exact_when_cheaper is 2, not 0 or 1"),
        "{message}"
    );
}

/// A version 9 file loads as tracing exactly from what 96 bytes of texels buy
/// (`exact_from_texels` 0); a size round-trips; a NaN or negative one is refused.
#[test]
fn exact_from_texels_round_trips_and_is_checked() {
    let rbvh = sample();
    let path = Path::new("v9.rbvh");
    assert_eq!(rbvh.params.exact_from_texels, 0.0);
    assert_eq!(Rbvh::from_bytes(&as_version(&rbvh, 9), path).unwrap(), rbvh);
    let from = Rbvh {
        params: RbvhParams {
            exact_from_texels: 1.5,
            ..rbvh.params
        },
        ..rbvh.clone()
    };
    let bytes = from.to_bytes();
    assert_eq!(f32::from_bits(word(&bytes, parm(&bytes, 10))), 1.5);
    assert_eq!(Rbvh::from_bytes(&bytes, path).unwrap(), from);
    for bad_value in [f32::NAN, -1.0] {
        let mut bad = bytes.clone();
        set(&mut bad, parm(&bytes, 10), bad_value.to_bits());
        let message = parse_error(Rbvh::from_bytes(&bad, path), path);
        assert!(message.contains("exact_from_texels"), "{message}");
    }
}

/// A version 10 file loads as tracing no triangle exactly for its edges
/// (`exact_edge_fraction` 0); a fraction round-trips; a NaN, negative or above-one value is
/// refused, and so is one where every triangle is sampled.
#[test]
fn exact_edge_fraction_round_trips_and_is_checked() {
    let rbvh = sample();
    let path = Path::new("v10.rbvh");
    assert_eq!(rbvh.params.exact_edge_fraction, 0.0);
    assert_eq!(
        Rbvh::from_bytes(&as_version(&rbvh, 10), path).unwrap(),
        rbvh
    );
    let from = Rbvh {
        params: RbvhParams {
            exact_edge_fraction: 0.0078125,
            ..rbvh.params
        },
        ..rbvh.clone()
    };
    let bytes = from.to_bytes();
    assert_eq!(f32::from_bits(word(&bytes, parm(&bytes, 11))), 0.0078125);
    assert_eq!(Rbvh::from_bytes(&bytes, path).unwrap(), from);
    for bad_value in [f32::NAN, -1.0, 1.5] {
        let mut bad = bytes.clone();
        set(&mut bad, parm(&bytes, 11), bad_value.to_bits());
        let message = parse_error(Rbvh::from_bytes(&bad, path), path);
        assert!(message.contains("exact_edge_fraction"), "{message}");
    }
    let mut sampled = all_sampled(&from).to_bytes();
    set(&mut sampled, parm(&bytes, 11), 0.0078125f32.to_bits());
    let message = parse_error(Rbvh::from_bytes(&sampled, path), path);
    assert!(message.contains("exact_edge_fraction"), "{message}");
}

/// A `PARM` of version 7 loads as refined for no view (`view_rate` 0); a rate round-trips; a
/// NaN, negative, infinite or sub-1 one is refused, naming the field.
#[test]
fn view_rate_round_trips_and_is_checked() {
    let rbvh = sample();
    let path = Path::new("view.rbvh");
    assert_eq!(rbvh.params.view_rate, 0.0);
    let viewed = Rbvh {
        params: RbvhParams {
            view_rate: 384.0,
            ..rbvh.params
        },
        ..rbvh.clone()
    };
    let bytes = viewed.to_bytes();
    assert_eq!(f32::from_bits(word(&bytes, parm(&bytes, 13))), 384.0);
    assert_eq!(Rbvh::from_bytes(&bytes, path).unwrap(), viewed);
    let mut p = parts(&bytes);
    p[0].1 = 7;
    p[0].3.truncate(4 * 13);
    assert_eq!(Rbvh::from_bytes(&assemble(&p), path).unwrap(), rbvh);
    for bad_value in [f32::NAN, -1.0, 0.5, f32::INFINITY] {
        let mut bad = bytes.clone();
        set(&mut bad, parm(&bytes, 13), bad_value.to_bits());
        let message = parse_error(Rbvh::from_bytes(&bad, path), path);
        assert!(message.contains("view_rate"), "{message}");
    }
}

/// A version 11 file loads as tracing no triangle exactly for a crease (`exact_crease_deg` 0);
/// an angle round-trips; a NaN, negative or above-180 one is refused.
#[test]
fn exact_crease_deg_round_trips_and_is_checked() {
    let rbvh = sample();
    let path = Path::new("v11.rbvh");
    assert_eq!(
        Rbvh::from_bytes(&as_version(&rbvh, 11), path).unwrap(),
        rbvh
    );
    let crease = Rbvh {
        params: RbvhParams {
            exact_crease_deg: 30.0,
            ..rbvh.params
        },
        ..rbvh.clone()
    };
    let bytes = crease.to_bytes();
    assert_eq!(f32::from_bits(word(&bytes, parm(&bytes, 12))), 30.0);
    assert_eq!(Rbvh::from_bytes(&bytes, path).unwrap(), crease);
    for bad_value in [f32::NAN, -1.0, 200.0] {
        let mut bad = bytes.clone();
        set(&mut bad, parm(&bytes, 12), bad_value.to_bits());
        let message = parse_error(Rbvh::from_bytes(&bad, path), path);
        assert!(message.contains("exact_crease_deg"), "{message}");
    }
}

/// `sample()` with its last four atlas rows packed — a row of 12-bit heights, one of 10-bit
/// heights and two of 8-bit ones — their codes made codes of those bits, and its second leaf cut
/// to its first row (row 4, 16-bit), so that each tile lies in one band.
fn packed_sample() -> Rbvh {
    let mut r = sample();
    r.atlas.packed_rows = [1, 1, 2];
    r.heightfields[1].res_v = 1;
    for (bits, range) in r.atlas.bands().into_iter().skip(1) {
        let step = Texel::step(bits);
        for t in &mut r.atlas.texels[range] {
            if !t.is_hole() {
                let code = (u32::from(t.height_code()) / step).min((1 << bits) - 2) * step;
                *t = Texel(t.0 & !0xFFFF | code);
            }
        }
    }
    r
}

/// A version 7 file (16-bit codes everywhere, no `narrow_rows`) loads with no packed rows; an
/// RBVH with packed rows round-trips, and a `HEAD` of version 1 (its 8-bit rows alone) loads
/// with no 12- or 10-bit rows; packed rows beyond the atlas, or a code in them that is not one
/// of their bits (which the device could not store), are parse errors.
#[test]
fn packed_rows_round_trip_and_are_checked() {
    let rbvh = sample();
    let v7 = as_version(&rbvh, 7);
    assert_eq!(
        Rbvh::from_bytes(&v7, Path::new("v7.rbvh")).unwrap(),
        all_sampled(&rbvh)
    );

    let packed = packed_sample();
    assert_eq!(packed.atlas.band_ends(), [40, 48, 56]);
    let bytes = packed.to_bytes();
    let packed_rows = head(&bytes) + 64;
    assert_eq!([0, 4, 8].map(|k| word(&bytes, packed_rows + k)), [1, 1, 2]);
    assert_eq!(
        Rbvh::from_bytes(&bytes, Path::new("p.rbvh")).unwrap(),
        packed
    );

    // HEAD version 1: 8-bit rows alone, 68 bytes (the 12- and 10-bit codes are 16-bit ones).
    let mut eight = packed.clone();
    eight.atlas.packed_rows = [0, 0, 2];
    let mut p = parts(&eight.to_bytes());
    let head_part = p.iter_mut().find(|part| &part.0 == b"HEAD").unwrap();
    assert_eq!(head_part.1, 2);
    head_part.1 = 1;
    head_part.3.drain(64..72);
    assert_eq!(
        Rbvh::from_bytes(&assemble(&p), Path::new("v1.rbvh")).unwrap(),
        eight
    );

    let path = Path::new("rows.rbvh");
    let mut bad = bytes.clone();
    set(&mut bad, packed_rows, 7);
    let message = parse_error(Rbvh::from_bytes(&bad, path), path);
    assert!(
        message.contains("atlas.packed_rows [7, 1, 2] (12-, 10- and 8-bit rows) exceed its 9 rows"),
        "{message}"
    );

    for (rows, bits) in [(40..48, 12), (48..56, 10), (56..72, 8)] {
        let mut odd = packed.clone();
        let k = rows
            .clone()
            .find(|&k| !odd.atlas.texels[k].is_hole())
            .unwrap();
        odd.atlas.texels[k].0 += 1;
        let path = Path::new("odd.rbvh");
        let message = parse_error(Rbvh::from_bytes(&odd.to_bytes(), path), path);
        assert!(
            message.contains(&format!("atlas texel {k} lies in the {bits}-bit rows")),
            "{message}"
        );
    }
}

/// A version 1–4 node whose box holds NaN has no grid to be quantized to: a parse error naming
/// the node.
#[test]
fn an_old_node_with_a_nan_box_is_rejected() {
    let path = Path::new("nan.rbvh");
    let mut old = as_version(&sample(), 4);
    // Node 1's `a_min.y`.
    let at = V6_HEADER_BYTES + 64 + 4;
    old[at..at + 4].copy_from_slice(&f32::NAN.to_bits().to_le_bytes());
    let message = parse_error(Rbvh::from_bytes(&old, path), path);
    assert!(
        message.contains("node 1") && message.contains("NaN"),
        "{message}"
    );
}

/// A version 5 node's grid is checked: an exponent of zero would decode every plane to the origin
/// (boxes that no longer contain their children).
#[test]
fn a_node_with_a_broken_grid_is_rejected() {
    let path = Path::new("grid.rbvh");
    let mut bytes = sample().to_bytes();
    // Node 0's `exponents`.
    let at = section(&bytes, b"NODE").start + 12;
    set(&mut bytes, at, 0);
    let message = parse_error(Rbvh::from_bytes(&bytes, path), path);
    assert!(
        message.contains("node 0") && message.contains("exponent 0"),
        "{message}"
    );
}

#[test]
fn height_only_texels_round_trip_in_half_the_bytes() {
    let path = Path::new("height.rbvh");
    let mut height = sample();
    height.params.texels = TexelFormat::Height;
    for t in &mut height.atlas.texels {
        *t = Texel(u32::from(t.height_code()));
    }
    let bytes = height.to_bytes();
    assert_eq!(Rbvh::from_bytes(&bytes, path).unwrap(), height);
    // The texel section's tag says height-only; the other sections are the same, the texels
    // two bytes each, and their checksums last.
    let normals = sample().to_bytes();
    let texels = section(&bytes, b"TEXH");
    assert_eq!(
        (texels.len(), texels.end),
        (72 * 2, section(&bytes, b"SUMS").start)
    );
    assert_eq!(bytes.len(), normals.len() - 72 * 2);
    for tag in [b"PARM", b"HEAD", b"NODE", b"TRIS", b"LEAF"] {
        assert_eq!(bytes[section(&bytes, tag)], normals[section(&normals, tag)]);
    }
    let first_texel = texels.start;
    assert_eq!(
        u16::from_le_bytes([bytes[first_texel], bytes[first_texel + 1]]),
        height.atlas.texels[0].height_code()
    );
    // On the device: 4-byte words of two texels' codes, then the block ranges, as with normals,
    // which add the rank directory and a normal a texel that is not a hole.
    let words = height.atlas_words();
    let codes = |k: usize| height.atlas.texels[k].height_code() as u32;
    assert_eq!(words[0], codes(0) | codes(1) << 16);
    assert_eq!(words[35], codes(70) | codes(71) << 16);
    assert_eq!(height.atlas_bytes(), 4 * words.len() as u64);
    let with_normals = sample().atlas_words();
    assert_eq!(with_normals[..words.len()], words[..]);
    let samples = sample().atlas.samples();
    assert_eq!(
        with_normals.len(),
        words.len() + rbvh::rbvh::words::rank_words(72) + samples.div_ceil(2)
    );

    for cut in [1, 2, 72 * 2] {
        let message = parse_error(Rbvh::from_bytes(&bytes[..bytes.len() - cut], path), path);
        assert!(message.contains("truncated"), "{cut}: {message}");
    }
    // Colours (painted on a height-only RBVH in memory) have no place in its file: refused.
    let dir = tempfile::tempdir().unwrap();
    let mut painted = height.clone();
    painted.colours = Some(vec![0; 72]);
    let err = painted
        .save(&dir.path().join("p.rbvh"))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("height-only") && err.contains("colour"),
        "{err}"
    );
    assert!(!dir.path().join("p.rbvh").exists());
}

#[test]
fn inconsistent_contents_are_rejected_with_the_reason() {
    let path = Path::new("bad.rbvh");
    let check = |r: Rbvh, expect: &str| {
        let message = parse_error(Rbvh::from_bytes(&r.to_bytes(), path), path);
        assert!(message.contains(expect), "expected {expect:?} in {message}");
    };
    let mut r = sample();
    r.nodes[0].a_child = 2;
    check(r, "node 0, child a: node index 2 is out of range");
    let mut r = sample();
    r.nodes[0].a_child ^= 1 << 20;
    check(r, "out of range");
    let mut r = sample();
    r.nodes[1].b_child = LEAF_BIT | 2;
    check(
        r,
        "node 1, child b: height-field leaf index 2 is out of range",
    );
    let mut r = sample();
    r.nodes[0].b_count = 3;
    check(r, "triangles 0..3 are out of range");
    let mut r = sample();
    r.nodes[0].a_count = 5;
    check(r, "inner node reference with count 5");
    // An absent child's index is read by nothing, the device included: any index loads.
    let mut r = sample();
    (r.nodes[0].b_child, r.nodes[0].b_count) = (LEAF_BIT | 1000, 0);
    Rbvh::from_bytes(&r.to_bytes(), path).expect("an absent child with any index loads");
    let mut r = sample();
    r.heightfields[1].res_v = 6;
    check(r, "height-field leaf 1");
    let mut r = sample();
    r.heightfields[0].atlas_base = u32::MAX;
    check(r, "does not fit");
    let mut r = sample();
    r.heightfields[0].axis_w[1] = f32::NAN;
    check(r, "not finite");
    let mut r = sample();
    r.atlas.rows = 8;
    check(r, "pitch × rows");
    let mut r = sample();
    (r.atlas.pitch, r.atlas.rows) = (12, 6);
    check(r, "the atlas pitch is 12 texels, not a power of two");
    let mut r = sample();
    edit_triangle(&mut r, 1, |t| t.flags = GpuTriangle::part_flags(2, false));
    check(
        r,
        "triangle 1 has flags 0x9 and padding 0x0: neither 0 nor an exact part of one of the 2",
    );
    let mut r = sample();
    edit_triangle(&mut r, 0, |t| t.flags = GpuTriangle::BARE);
    check(r, "triangle 0 has flags 0x2");
    let mut r = sample();
    edit_triangle(&mut r, 0, |t| t.pad2 = 1);
    check(r, "triangle 0 has flags 0x0 and padding 0x1");
    let mut r = sample();
    r.params.texels_per_diagonal = f32::NAN;
    check(r, "texels_per_diagonal is NaN");
    let mut r = sample();
    r.params.object_rate = f32::NAN;
    check(r, "object_rate is NaN");
    let mut r = sample();
    r.texel_size = f32::NAN;
    check(r, "texel_size is NaN");

    // A version 12 file's counts that overflow, or promise more than the file holds.
    let mut bytes = as_v12(&sample());
    // Bytes 140..148: the texel count.
    bytes[140..148].copy_from_slice(&u64::MAX.to_le_bytes());
    let message = parse_error(Rbvh::from_bytes(&bytes, path), path);
    assert!(message.contains("counts"), "{message}");
    // More nodes than a traversal stack entry can name (bytes 116..124: the node count).
    let mut bytes = as_v12(&sample());
    let too_many = rbvh::bvh::MAX_NODES as u64 + 1;
    bytes[116..124].copy_from_slice(&too_many.to_le_bytes());
    let message = parse_error(Rbvh::from_bytes(&bytes, path), path);
    assert!(
        message.contains(&format!("{too_many} nodes, more than the")),
        "{message}"
    );
    // Unknown enum tags and flags, in the parameters' section and in a version 12 header, and a
    // version 12 height-only RBVH claiming colours.
    let current = sample().to_bytes();
    for (at, value, expect) in [
        (parm(&current, 1), 5u32, "params.refinement has tag 5"),
        (parm(&current, 3), 7, "params.subdivision has tag 7"),
        (parm(&current, 4), 2, "params.object_split is 2, not 0 or 1"),
    ] {
        let mut bytes = current.clone();
        set(&mut bytes, at, value);
        let message = parse_error(Rbvh::from_bytes(&bytes, path), path);
        assert!(
            message.contains(expect) && message.contains("section PARM (table entry 0"),
            "{message}"
        );
    }
    for (at, value, expect) in [
        (24, 7u32, "params.subdivision has tag 7"),
        (44, 2, "params.texels has tag 2"),
        (48, 3, "the colour channel flag is 3"),
    ] {
        let mut bytes = as_v12(&sample());
        set(&mut bytes, at, value);
        let message = parse_error(Rbvh::from_bytes(&bytes, path), path);
        assert!(message.contains(expect), "{message}");
    }
    let mut bytes = as_v12(&sample());
    bytes[44..52].copy_from_slice(&[1, 0, 0, 0, 1, 0, 0, 0]);
    let message = parse_error(Rbvh::from_bytes(&bytes, path), path);
    assert!(
        message.contains("height-only RBVH claims a colour channel"),
        "{message}"
    );
}

#[test]
fn colours_round_trip_after_the_texels() {
    let path = Path::new("painted.rbvh");
    let mut painted = sample();
    painted.colours = Some((0..72u32).map(|k| k.wrapping_mul(0x0101_0107)).collect());
    let bytes = painted.to_bytes();
    assert_eq!(Rbvh::from_bytes(&bytes, path).unwrap(), painted);
    // An optional seventh section after the texels; the others as without colours.
    let plain = sample().to_bytes();
    let table = section_table(&bytes, path).unwrap();
    assert_eq!(
        (&table[6].tag, table[6].flags, table[6].length),
        (b"COLR", 0, 72 * 4)
    );
    for tag in [b"PARM", b"HEAD", b"NODE", b"TRIS", b"LEAF", b"TEXN"] {
        assert_eq!(bytes[section(&bytes, tag)], plain[section(&plain, tag)]);
    }
    let colours = section(&bytes, b"COLR");
    assert_eq!(word(&bytes, colours.start + 4), 0x0101_0107);

    // A colour section cut short, or with a count that is not one per texel.
    for cut in [1, 4, 72 * 4] {
        let message = parse_error(Rbvh::from_bytes(&bytes[..bytes.len() - cut], path), path);
        assert!(message.contains("truncated"), "{cut}: {message}");
    }
    let mut odd = painted.clone();
    odd.colours.as_mut().unwrap().pop();
    let message = parse_error(Rbvh::from_bytes(&odd.to_bytes(), path), path);
    assert!(
        message.contains("section COLR (table entry 6")
            && message.contains("71 colours for 72 texels"),
        "{message}"
    );

    // Version 12: the header's flag, then after the texels the colour count and the colours.
    let v12 = as_v12(&painted);
    assert_eq!(Rbvh::from_bytes(&v12, path).unwrap(), painted);
    assert_eq!(word(&v12, 48), 1);
    let plain = as_v12(&sample());
    assert_eq!(v12.len(), plain.len() + 8 + 72 * 4);
    assert_eq!(v12[plain.len()..plain.len() + 8], 72u64.to_le_bytes());
    for cut in [1, 4, 72 * 4, 72 * 4 + 7] {
        let message = parse_error(Rbvh::from_bytes(&v12[..v12.len() - cut], path), path);
        assert!(message.contains("truncated"), "{cut}: {message}");
    }
    let message = parse_error(Rbvh::from_bytes(&as_v12(&odd), path), path);
    assert!(message.contains("71 colours for 72 texels"), "{message}");
}

#[test]
fn a_missing_file_is_an_io_error_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("nowhere.rbvh");
    match Rbvh::load(&path) {
        Err(e @ Error::Io { .. }) => assert!(e.to_string().contains("nowhere.rbvh"), "{e}"),
        other => panic!("expected an I/O error, got {other:?}"),
    }
}

#[test]
fn a_failed_save_leaves_nothing_behind() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("missing-dir").join("scene.rbvh");
    match sample().save(&path) {
        Err(e @ Error::Io { .. }) => assert!(e.to_string().contains("scene.rbvh"), "{e}"),
        other => panic!("expected an I/O error, got {other:?}"),
    }
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    // A save over an existing file replaces it whole.
    let path = dir.path().join("scene.rbvh");
    std::fs::write(&path, b"old").unwrap();
    sample().save(&path).unwrap();
    assert_eq!(Rbvh::load(&path).unwrap(), sample());
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
}

/// A file knows its box, not its scene: `check_built_from` accepts the scene an RBVH was built
/// from, at every level and with the extreme criteria, and refuses another scene, naming both boxes.
#[test]
fn an_rbvh_is_checked_against_the_scene_it_is_used_with() {
    use rbvh::rbvh::SCENE_MATCH_TEXELS;
    let mut worst = 0.0f32;
    for name in ["default", "sphere", "blob", "grove"] {
        let scene = rbvh::scene::Scene::builtin(name).unwrap();
        let mut params: Vec<RbvhParams> =
            (0..=4).map(|q| RbvhParams::quality(q).unwrap()).collect();
        params.push(RbvhParams {
            refinement: Refinement::NormalCone {
                max_angle_deg: 85.0,
            },
            ..RbvhParams::quality(0).unwrap()
        });
        for p in &params {
            let r = Rbvh::build(&scene, p).unwrap();
            let b = scene.bounds();
            let apart = (r.bounds.min - b.min)
                .abs()
                .max((r.bounds.max - b.max).abs())
                .max_element();
            worst = worst.max(apart / r.texel_size);
            r.check_built_from(&scene)
                .unwrap_or_else(|e| panic!("{name} {p:?}: {e}"));
        }
    }
    println!("farthest box side: {worst:.2} texels (allowed {SCENE_MATCH_TEXELS})");
    let sphere = rbvh::scene::Scene::builtin("sphere").unwrap();
    let r = Rbvh::build(&sphere, &RbvhParams::quality(2).unwrap()).unwrap();
    let other = rbvh::scene::Scene::builtin("blob").unwrap();
    let e = r.check_built_from(&other).unwrap_err().to_string();
    assert!(
        e.contains("built for another scene") && e.contains("blob"),
        "{e}"
    );
}

/// `sample()` with colours, and a height-only one.
fn painted_and_height() -> [Rbvh; 2] {
    let mut painted = sample();
    painted.colours = Some((0..72u32).map(|k| k.wrapping_mul(0x0101_0107)).collect());
    let mut height = sample();
    height.params.texels = TexelFormat::Height;
    for t in &mut height.atlas.texels {
        *t = Texel(u32::from(t.height_code()));
    }
    [painted, height]
}

/// The writer lays its sections out as documented, and a reader takes them in any order.
#[test]
fn sections_are_laid_out_as_documented_and_read_in_any_order() {
    let path = Path::new("order.rbvh");
    let [painted, height] = painted_and_height();
    for r in [sample(), painted, height] {
        let bytes = r.to_bytes();
        let mut p = parts(&bytes);
        assert_eq!(assemble(&p), bytes);
        p.reverse();
        let reversed = assemble(&p);
        assert_ne!(reversed, bytes);
        let back = Rbvh::from_bytes(&reversed, path).unwrap();
        assert_eq!(back, r);
        assert_eq!(back.to_bytes(), bytes);
    }
}

/// An optional section this build does not know (a tag, or a version of a known tag) is skipped,
/// and saving drops it; a required one refuses the file, naming it.
#[test]
fn unknown_sections_are_skipped_when_optional_and_refused_when_required() {
    let path = Path::new("new.rbvh");
    let bytes = sample().to_bytes();
    let extra = (*b"XTRA", 1, 0, vec![1, 2, 3]);
    let mut p = parts(&bytes);
    p.insert(2, extra.clone());
    let loaded = Rbvh::from_bytes(&assemble(&p), path).unwrap();
    assert_eq!(loaded, sample());
    assert_eq!(loaded.to_bytes(), bytes);

    p[2].2 = REQUIRED;
    let message = parse_error(Rbvh::from_bytes(&assemble(&p), path), path);
    assert!(
        message.contains("section XTRA (table entry 2, bytes 376..379) is required")
            && message.contains("does not know its tag"),
        "{message}"
    );

    let mut p = parts(&bytes);
    p[2].1 = 2;
    let message = parse_error(Rbvh::from_bytes(&assemble(&p), path), path);
    assert!(
        message.contains("section NODE (table entry 2")
            && message.contains("does not know its version 2: it reads 1..=1"),
        "{message}"
    );

    // Leaves as version 1 wrote them (no tile's plane: the sample's records have none) load the
    // same; a later version is refused by name.
    let mut p = parts(&bytes);
    assert_eq!(&p[4].0, b"LEAF");
    p[4].1 = 1;
    assert_eq!(Rbvh::from_bytes(&assemble(&p), path).unwrap(), sample());
    p[4].1 = 3;
    let message = parse_error(Rbvh::from_bytes(&assemble(&p), path), path);
    assert!(
        message.contains("section LEAF (table entry 4")
            && message.contains("does not know its version 3: it reads 1..=2"),
        "{message}"
    );

    // Colours of a later encoding (an optional section's later version) are skipped.
    let [painted, _] = painted_and_height();
    let mut p = parts(&painted.to_bytes());
    p[6].1 = 2;
    assert_eq!(Rbvh::from_bytes(&assemble(&p), path).unwrap(), sample());
}

/// A broken table or a section that does not fit what it holds is a parse error naming the
/// section, its table entry and its bytes; no input panics.
#[test]
fn broken_section_tables_are_refused_naming_the_section() {
    let path = Path::new("table.rbvh");
    // Without its checksums, whose section would come last: the offsets below are the six
    // sections' (a_damaged_section_is_refused_by_its_checksum checks SUMS).
    let bytes = {
        let mut p = parts(&sample().to_bytes());
        p.retain(|part| &part.0 != b"SUMS");
        assemble(&p)
    };
    let refused = |file: &[u8], expect: &[&str]| {
        let message = parse_error(Rbvh::from_bytes(file, path), path);
        for e in expect {
            assert!(message.contains(e), "expected {e:?} in {message}");
        }
    };
    // Table entry k starts at byte 16 + 28 k: tag, version, flags, offset, length.
    let entry = |k: usize| 16 + 28 * k;
    let edit = |f: &dyn Fn(&mut Vec<u8>)| {
        let mut b = bytes.clone();
        f(&mut b);
        b
    };
    refused(
        &edit(&|b| set(b, 12, 1000)),
        &[
            "truncated",
            "the table of 1000 sections needs bytes 16..28016",
        ],
    );
    refused(
        &edit(&|b| set(b, entry(5) + 20, 72 * 4 + 8)),
        &["section TEXN (table entry 5, bytes 640..936): truncated, the file has 928 bytes"],
    );
    refused(
        &edit(&|b| b[entry(5) + 12..entry(5) + 20].copy_from_slice(&u64::MAX.to_le_bytes())),
        &["section TEXN (table entry 5", "truncated"],
    );
    refused(
        &edit(&|b| set(b, entry(1) + 12, 232)),
        &["section HEAD (table entry 1, bytes 232..308): overlaps section PARM (table entry 0, bytes 184..240)"],
    );
    refused(
        &edit(&|b| set(b, entry(0) + 12, 176)),
        &["section PARM (table entry 0, bytes 176..232): overlaps the section table (bytes 0..184)"],
    );
    refused(
        &edit(&|b| set(b, entry(1) + 12, 248)),
        &[
            "section HEAD (table entry 1, bytes 248..324): a gap",
            "must start at byte 240",
        ],
    );
    refused(
        &edit(&|b| b[317] = 1),
        &[
            "section NODE (table entry 2",
            "padding byte 317 before it is 0x01",
        ],
    );
    refused(
        &edit(&|b| set(b, entry(0) + 8, 3)),
        &[
            "section PARM (table entry 0",
            "flags 0x3, of which only bit 0",
        ],
    );
    refused(
        &edit(&|b| b[entry(2) + 2] = 0),
        &["table entry 2: the tag [4e, 4f, 00, 45] is not four printable ASCII characters"],
    );

    let with = |f: &dyn Fn(&mut Parts)| {
        let mut p = parts(&bytes);
        f(&mut p);
        assemble(&p)
    };
    refused(
        &with(&|p| p.push(p[2].clone())),
        &[
            "section NODE (table entry 6",
            "a second section NODE (the first is table entry 2)",
        ],
    );
    refused(
        &with(&|p| drop(p.remove(4))),
        &["no section LEAF of a version this build reads (the file's sections: PARM v8, HEAD v2, NODE v1, TRIS v1, TEXN v1)"],
    );
    refused(&with(&|p| drop(p.remove(0))), &["no section PARM"]);
    refused(
        &with(&|p| drop(p.remove(5))),
        &["not one texel section (TEXN or TEXH) but neither"],
    );
    refused(
        &with(&|p| p.push((*b"TEXH", 1, REQUIRED, vec![0; 144]))),
        &["not one texel section (TEXN or TEXH) but both"],
    );
    refused(
        &with(&|p| p[2].3.extend([0; 4])),
        &["section NODE (table entry 2, bytes 320..420): 100 bytes, not a whole number of 48-byte records"],
    );
    refused(
        &with(&|p| p[1].3.extend([0; 4])),
        &["section HEAD (table entry 1, bytes 240..320): 80 bytes, not the 76 of its version"],
    );
    refused(
        &with(&|p| drop(p[0].3.drain(48..))),
        &["section PARM (table entry 0, bytes 184..232): 48 bytes, not the 56 of its version 8"],
    );
    refused(
        &with(&|p| p[0].1 = 9),
        &[
            "section PARM (table entry 0",
            "does not know its version 9: it reads 1..=8",
        ],
    );
    let [_, height] = painted_and_height();
    let mut p = parts(&height.to_bytes());
    // Before its checksums, as a writer places it.
    p.insert(6, (*b"COLR", 1, 0, vec![0; 72 * 4]));
    refused(
        &assemble(&p),
        &[
            "section COLR (table entry 6",
            "a height-only RBVH (texels TEXH) has no colour channel",
        ],
    );

    // What a section holds is checked as in every version; the error names the record's byte.
    let mut r = sample();
    r.nodes[1].b_child = LEAF_BIT | 2;
    refused(
        &r.to_bytes(),
        &["section NODE (table entry 2) at byte 400: node 1, child b: height-field leaf index"],
    );
    let mut r = sample();
    edit_triangle(&mut r, 1, |t| t.pad2 = 1);
    refused(
        &r.to_bytes(),
        &["section TRIS (table entry 3) at byte 496: triangle 1"],
    );
    let mut r = sample();
    r.texel_size = f32::NAN;
    refused(
        &r.to_bytes(),
        &["section HEAD (table entry 1, bytes 272..348): texel_size is NaN"],
    );
    // A version 12 file has no table to read.
    let message = section_table(&as_v12(&sample()), path)
        .unwrap_err()
        .to_string();
    assert!(
        message.contains("version 12 has no section table"),
        "{message}"
    );
}

/// `PARM` grew one field a version; a section of an older version loads with the later fields
/// at the values that mean "rule off", and is saved at the current version.
#[test]
fn an_older_params_section_loads_with_defaults_for_later_fields() {
    let path = Path::new("params.rbvh");
    let mut r = sample();
    r.params = RbvhParams {
        exact_from_texels: 1.5,
        exact_edge_fraction: 0.0078125,
        exact_crease_deg: 30.0,
        view_rate: 384.0,
        ..r.params
    };
    let bytes = r.to_bytes();
    // Each version's words, and the parameters it lacks, at their defaults.
    let words = [7, 8, 9, 10, 11, 12, 13, 14];
    for (version, &n) in (1u32..).zip(&words) {
        let mut p = parts(&bytes);
        p[0].1 = version;
        p[0].3.truncate(4 * n);
        let loaded = Rbvh::from_bytes(&assemble(&p), path).unwrap();
        let q = r.params;
        let expected = RbvhParams {
            sampled_criterion_texels: if n > 7 {
                q.sampled_criterion_texels
            } else {
                0.0
            },
            object_rate: if n > 8 { q.object_rate } else { 0.0 },
            exact_when_cheaper: n > 9 && q.exact_when_cheaper,
            exact_from_texels: if n > 10 { q.exact_from_texels } else { 0.0 },
            exact_edge_fraction: if n > 11 { q.exact_edge_fraction } else { 0.0 },
            exact_crease_deg: if n > 12 { q.exact_crease_deg } else { 0.0 },
            view_rate: if n > 13 { q.view_rate } else { 0.0 },
            ..q
        };
        assert_eq!(loaded.params, expected, "PARM version {version}");
        let saved = loaded.to_bytes();
        assert_eq!(parts(&saved)[0].1, 8);
        assert_eq!(Rbvh::from_bytes(&saved, path).unwrap().to_bytes(), saved);
    }
}

/// Every earlier version loads, and what it is saved as loads back to the same bytes.
#[test]
fn every_earlier_version_upgrades_to_a_file_that_round_trips() {
    let path = Path::new("upgrade.rbvh");
    let [painted, height] = painted_and_height();
    for version in 1..=12 {
        // Version 2 had colours, version 3 height-only texels, and neither said so.
        let r = match version {
            2 => &painted,
            3 => &height,
            _ => &sample(),
        };
        let old = as_version(r, version);
        let saved = Rbvh::from_bytes(&old, path).unwrap().to_bytes();
        assert_eq!(word(&saved, 8), 13);
        let again = Rbvh::from_bytes(&saved, path).unwrap();
        assert_eq!(again.to_bytes(), saved, "version {version}");
    }
    assert_eq!(
        Rbvh::from_bytes(&as_v12(&sample()), path).unwrap(),
        sample()
    );
}

/// An empty section lies at the offset of the section after it, and the table may list the two in
/// either order (the docs: "sections may come in any order"); the file loads as it was.
#[test]
fn an_empty_section_may_be_listed_after_the_one_at_its_offset() {
    let bytes = sample().to_bytes();
    let mut p = parts(&bytes);
    let leaf = p.iter().position(|s| &s.0 == b"LEAF").unwrap();
    p.insert(leaf, (*b"XTRA", 1, 0, Vec::new()));
    let mut file = assemble(&p);
    // Swap the two table entries; the layout stays.
    let (a, b) = (16 + 28 * leaf, 16 + 28 * (leaf + 1));
    let entry = file[a..a + 28].to_vec();
    file.copy_within(b..b + 28, a);
    file[b..b + 28].copy_from_slice(&entry);
    let path = Path::new("x.rbvh");
    let table = section_table(&file, path).unwrap();
    assert_eq!((&table[leaf].tag, &table[leaf + 1].tag), (b"LEAF", b"XTRA"));
    assert_eq!(table[leaf].offset, table[leaf + 1].offset);
    let loaded = Rbvh::from_bytes(&file, path).unwrap();
    assert_eq!(loaded.to_bytes(), bytes);
}

/// `r` with its triangle `i` changed by `edit` (the indexed form made again from it).
fn edit_triangle(r: &mut Rbvh, i: usize, edit: impl FnOnce(&mut GpuTriangle)) {
    let mut triangles = r.triangles.gathered().to_vec();
    edit(&mut triangles[i]);
    r.triangles = ExactTriangles::new(triangles);
}

/// **A saved RBVH is checked against the scene it is traced with by its exact triangles too**:
/// a scene whose box is the RBVH's within the texels the check allows, but whose triangles are
/// others, is refused, naming a triangle; the scene it was built from passes.
#[test]
fn an_rbvh_of_another_scene_in_the_same_box_is_refused() {
    let cube = rbvh::Scene::builtin("cube").unwrap();
    let built = Rbvh::build(&cube, &RbvhParams::quality(0).unwrap()).unwrap();
    assert!(
        !built.triangles.is_empty(),
        "the cube's Q0 traces none exactly"
    );
    built.check_built_from(&cube).unwrap();
    let b = cube.bounds();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("one.obj");
    let v = |p: Vec3| format!("v {} {} {}\n", p.x, p.y, p.z);
    let text = v(b.min) + &v(b.max) + &v(Vec3::new(b.max.x, b.min.y, b.max.z)) + "f 1 2 3\n";
    std::fs::write(&path, text).unwrap();
    let one = rbvh::Scene::load(path.to_str().unwrap()).unwrap();
    assert_eq!(one.bounds().min, b.min);
    let e = built.check_built_from(&one).unwrap_err().to_string();
    assert!(
        e.contains("built for another scene") && e.contains("exact triangle"),
        "{e}"
    );
}

/// **A damaged file is refused, naming the section**: every section but `SUMS` is checked by
/// its CRC-32 there, so a byte changed in a node or a texel (which every structural check may
/// pass, and which would trace otherwise) is an error; a file without `SUMS` (older, or another
/// writer's) loads unchecked, and so does an optional section `SUMS` does not list.
#[test]
fn a_damaged_section_is_refused_by_its_checksum() {
    let path = Path::new("damaged.rbvh");
    let bytes = sample().to_bytes();
    let table = section_table(&bytes, path).unwrap();
    assert_eq!(&table.last().unwrap().tag, b"SUMS");
    for tag in [b"NODE", b"TRIS", b"LEAF", b"TEXN"] {
        let s = table.iter().find(|s| &s.tag == tag).unwrap();
        let mut damaged = bytes.clone();
        damaged[s.bytes().start + 5] ^= 0x10;
        let message = parse_error(Rbvh::from_bytes(&damaged, path), path);
        let name = String::from_utf8_lossy(tag).into_owned();
        assert!(
            message.contains(&format!("section {name}"))
                && message.contains("CRC-32")
                && message.contains("damaged"),
            "{message}"
        );
    }
    let mut p = parts(&bytes);
    p.retain(|part| &part.0 != b"SUMS");
    assert_eq!(Rbvh::from_bytes(&assemble(&p), path).unwrap(), sample());
}
