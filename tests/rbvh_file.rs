//! The RBVH file through the public API: exact round trips, the documented layout, errors that
//! name the file and say what is wrong, and saves that are all or nothing.

use std::path::Path;

use glam::Vec3;
use rbvh::bvh::{ChildRef, GpuNode, GpuTriangle, LEAF_BIT};
use rbvh::geom::Aabb;
use rbvh::rbvh::{
    Atlas, GpuHeightfield, Rbvh, RbvhParams, RbvhStats, Refinement, Subdivision, Texel,
    TexelFormat, HEIGHTFIELD_COUNT,
};
use rbvh::Error;

/// Bytes before the arrays, per the format table in `src/rbvh/file.rs`.
const HEADER_BYTES: usize = 172;
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
const V6_HEADER_BYTES: usize = 148;

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
    let leaves = vec![
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
    let hf = |index| ChildRef {
        bounds: unit,
        child: LEAF_BIT | index,
        count: HEIGHTFIELD_COUNT,
    };
    let nodes = vec![
        GpuNode::new(
            ChildRef {
                bounds: unit,
                child: 1,
                count: 0,
            },
            ChildRef {
                bounds: unit,
                child: LEAF_BIT,
                count: 2,
            },
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
        triangles,
        leaves,
        atlas: Atlas {
            pitch: 8,
            rows: 9,
            narrow_rows: 0,
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

    // The documented framing: magic, version 12, the sampling judgement's size, normal texels, no
    // colour channel, each object's rate, the narrow rows, whether triangles were traced exactly
    // where cheaper, from what size, from what edge and from what crease last, then the arrays
    // after a 172-byte header.
    assert_eq!(&bytes[..8], b"RBVHv\0\0\0");
    assert_eq!(word(&bytes, 8), 12);
    assert_eq!(f32::from_bits(word(&bytes, 160)), 0.0);
    assert_eq!(f32::from_bits(word(&bytes, 164)), 0.0);
    assert_eq!(f32::from_bits(word(&bytes, 168)), 0.0);
    assert_eq!(f32::from_bits(word(&bytes, 148)), 0.375);
    assert_eq!(word(&bytes, 152), 0);
    assert_eq!(word(&bytes, 156), 1);
    assert_eq!(f32::from_bits(word(&bytes, 40)), 2.5);
    assert_eq!((word(&bytes, 44), word(&bytes, 48)), (0, 0));
    let arrays = 2 * 48 + 2 * 48 + 2 * 64 + 72 * 4;
    assert_eq!(bytes.len(), HEADER_BYTES + arrays);
    let first_texel = HEADER_BYTES + arrays - 72 * 4;
    let word = u32::from_le_bytes(bytes[first_texel..first_texel + 4].try_into().unwrap());
    assert_eq!(word, original.atlas.texels[0].0);
}

/// The little-endian u32 at byte `at`.
fn word(bytes: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap())
}

/// `rbvh` as the older `version` (1–4) wrote it: each node in 64 bytes with its children's boxes
/// at full precision (here the decoded ones), and before version 4 without header bytes 40..52.
fn as_old_version(rbvh: &Rbvh, version: u32) -> Vec<u8> {
    let bytes = rbvh.to_bytes();
    let mut old = bytes[..V6_HEADER_BYTES].to_vec();
    old[8..12].copy_from_slice(&version.to_le_bytes());
    for node in &rbvh.nodes {
        for c in node.children() {
            let [x, y, z] = c.bounds.min.to_array();
            let [u, v, w] = c.bounds.max.to_array();
            for word in [x.to_bits(), y.to_bits(), z.to_bits(), c.child] {
                old.extend_from_slice(&word.to_le_bytes());
            }
            for word in [u.to_bits(), v.to_bits(), w.to_bits(), c.count] {
                old.extend_from_slice(&word.to_le_bytes());
            }
        }
    }
    let nodes_end = HEADER_BYTES + rbvh.nodes.len() * std::mem::size_of::<GpuNode>();
    old.extend_from_slice(&bytes[nodes_end..]);
    if version < 4 {
        old.drain(40..52);
    }
    old
}

#[test]
fn odd_float_values_survive_bit_for_bit() {
    let mut r = sample();
    r.bounds = Aabb::EMPTY;
    r.stats.build_ms = -0.0;
    r.triangles[0].v0 = [f32::from_bits(0x7fc0_1234), -0.0, f32::MIN_POSITIVE];
    let back = Rbvh::from_bytes(&r.to_bytes(), Path::new("odd.rbvh")).unwrap();
    assert_eq!(back.to_bytes(), r.to_bytes());
    assert_eq!(back.bounds, Aabb::EMPTY);
}

#[test]
fn truncated_files_are_parse_errors_naming_the_file() {
    let bytes = sample().to_bytes();
    let path = Path::new("cut.rbvh");
    for len in [
        0,
        3,
        8,
        11,
        12,
        50,
        HEADER_BYTES - 1,
        HEADER_BYTES,
        HEADER_BYTES + 100,
        bytes.len() - 1,
    ] {
        let message = parse_error(Rbvh::from_bytes(&bytes[..len], path), path);
        assert!(message.contains("truncated"), "{len}: {message}");
    }
    // One byte too many is as wrong as one too few.
    let mut long = bytes.clone();
    long.push(0);
    let message = parse_error(Rbvh::from_bytes(&long, path), path);
    assert!(message.contains("trailing"), "{message}");
}

#[test]
fn bad_magic_and_unknown_versions_are_rejected() {
    let path = Path::new("x.rbvh");
    let mut bytes = sample().to_bytes();
    bytes[0] = b'P';
    let message = parse_error(Rbvh::from_bytes(&bytes, path), path);
    assert!(message.contains("not an RBVH file"), "{message}");

    for version in [0, 13, u32::MAX] {
        let mut bytes = sample().to_bytes();
        bytes[8..12].copy_from_slice(&version.to_le_bytes());
        let message = parse_error(Rbvh::from_bytes(&bytes, path), path);
        assert!(
            message.contains(&format!("unsupported version {version}")),
            "{message}"
        );
        assert!(message.contains("reads versions 1 to 12"), "{message}");
    }
}

/// Files written before version 6 (1: normal texels; 2: with colours; 3: height-only; 4: with
/// the sampled judgement's size and the texel format in the header, all with 64-byte nodes; 5:
/// 48-byte nodes) load as the RBVHs they described, their nodes quantized, and are saved again as
/// version 12. Before version 4 they were built by the paper's rule alone, before version 7
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
        let old = if version < 5 {
            as_old_version(&rbvh, version)
        } else {
            as_version(&rbvh, version)
        };
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
        // Quantizing decoded boxes again gives the same node, so the nodes come back as they were.
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
        assert_eq!(word(&loaded.to_bytes(), 8), 12);
        let header = if version < 4 { 136 } else { V6_HEADER_BYTES };
        let message = parse_error(Rbvh::from_bytes(&old[..old.len() - 1], path), path);
        assert!(
            message.contains("truncated") && message.contains(&format!("{header}-byte header")),
            "version {version}: {message}"
        );
    }
}

/// A version 6 file (marked heights, no `object_rate`) loads as it was, every texel the
/// scene's, and is saved again as version 12.
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
    assert_eq!(word(&loaded.to_bytes(), 8), 12);
}

/// `rbvh` as version 5–11 wrote it: its header without what later versions appended
/// (`exact_crease_deg` from 12, `exact_edge_fraction` from 11, `exact_from_texels` from 10,
/// `exact_when_cheaper` from 9, `narrow_rows` from 8, `object_rate` from 7).
fn as_version(rbvh: &Rbvh, version: u32) -> Vec<u8> {
    let mut bytes = rbvh.to_bytes();
    let end = match version {
        ..=6 => V6_HEADER_BYTES,
        7 => V7_HEADER_BYTES,
        8 => V8_HEADER_BYTES,
        9 => V9_HEADER_BYTES,
        10 => V10_HEADER_BYTES,
        _ => V11_HEADER_BYTES,
    };
    bytes.drain(end..HEADER_BYTES);
    bytes[8..12].copy_from_slice(&version.to_le_bytes());
    bytes
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
    assert_eq!(word(&loaded.to_bytes(), 156), 0);
    for r in [rbvh.clone(), all_sampled(&rbvh)] {
        assert_eq!(Rbvh::from_bytes(&r.to_bytes(), path).unwrap(), r);
    }
    let mut bad = rbvh.to_bytes();
    bad[156..160].copy_from_slice(&2u32.to_le_bytes());
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
    assert_eq!(f32::from_bits(word(&bytes, 160)), 1.5);
    assert_eq!(Rbvh::from_bytes(&bytes, path).unwrap(), from);
    for bad_value in [f32::NAN, -1.0] {
        let mut bad = bytes.clone();
        bad[160..164].copy_from_slice(&bad_value.to_le_bytes());
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
    assert_eq!(f32::from_bits(word(&bytes, 164)), 0.0078125);
    assert_eq!(Rbvh::from_bytes(&bytes, path).unwrap(), from);
    for bad_value in [f32::NAN, -1.0, 1.5] {
        let mut bad = bytes.clone();
        bad[164..168].copy_from_slice(&bad_value.to_le_bytes());
        let message = parse_error(Rbvh::from_bytes(&bad, path), path);
        assert!(message.contains("exact_edge_fraction"), "{message}");
    }
    let mut sampled = all_sampled(&from).to_bytes();
    sampled[164..168].copy_from_slice(&0.0078125f32.to_le_bytes());
    let message = parse_error(Rbvh::from_bytes(&sampled, path), path);
    assert!(message.contains("exact_edge_fraction"), "{message}");
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
    assert_eq!(f32::from_bits(word(&bytes, 168)), 30.0);
    assert_eq!(Rbvh::from_bytes(&bytes, path).unwrap(), crease);
    for bad_value in [f32::NAN, -1.0, 200.0] {
        let mut bad = bytes.clone();
        bad[168..172].copy_from_slice(&bad_value.to_le_bytes());
        let message = parse_error(Rbvh::from_bytes(&bad, path), path);
        assert!(message.contains("exact_crease_deg"), "{message}");
    }
}

/// `sample()` with its last four atlas rows narrow: their codes made 8-bit ones.
fn narrow_sample() -> Rbvh {
    let mut r = sample();
    r.atlas.narrow_rows = 4;
    let wide = r.atlas.wide_len();
    for t in &mut r.atlas.texels[wide..] {
        let code = u32::from(t.height_code()) / Texel::NARROW_STEP * Texel::NARROW_STEP;
        *t = Texel(t.0 & !0xFFFF | code);
    }
    r
}

/// A version 7 file (16-bit codes everywhere, no `narrow_rows`) loads with no narrow rows; an
/// RBVH with narrow rows round-trips; narrow rows beyond the atlas, or a code in them that is
/// not an 8-bit one (which the device could not store), are parse errors.
#[test]
fn narrow_rows_round_trip_and_are_checked() {
    let rbvh = sample();
    let v7 = as_version(&rbvh, 7);
    assert_eq!(
        Rbvh::from_bytes(&v7, Path::new("v7.rbvh")).unwrap(),
        all_sampled(&rbvh)
    );

    let narrow = narrow_sample();
    assert_eq!(narrow.atlas.wide_len(), 40);
    let bytes = narrow.to_bytes();
    assert_eq!(word(&bytes, 152), 4);
    assert_eq!(
        Rbvh::from_bytes(&bytes, Path::new("n.rbvh")).unwrap(),
        narrow
    );

    let path = Path::new("rows.rbvh");
    let mut bad = bytes.clone();
    bad[152..156].copy_from_slice(&10u32.to_le_bytes());
    let message = parse_error(Rbvh::from_bytes(&bad, path), path);
    assert!(
        message.contains("narrow_rows 10 exceeds its 9 rows"),
        "{message}"
    );

    let mut odd = narrow.clone();
    let k = (40..72).find(|&k| !odd.atlas.texels[k].is_hole()).unwrap();
    odd.atlas.texels[k].0 += 1;
    let path = Path::new("odd.rbvh");
    let message = parse_error(Rbvh::from_bytes(&odd.to_bytes(), path), path);
    assert!(
        message.contains(&format!("atlas texel {k} lies in the narrow rows")),
        "{message}"
    );
}

/// A version 1–4 node whose box holds NaN has no grid to be quantized to: a parse error naming
/// the node.
#[test]
fn an_old_node_with_a_nan_box_is_rejected() {
    let path = Path::new("nan.rbvh");
    let mut old = as_old_version(&sample(), 4);
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
    let at = HEADER_BYTES + 12;
    bytes[at..at + 4].copy_from_slice(&0u32.to_le_bytes());
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
    // The header says height-only; the arrays are the same, with two-byte texels.
    let normals = sample().to_bytes();
    assert_eq!(word(&bytes, 44), 1);
    assert_eq!(bytes.len(), normals.len() - 72 * 2);
    assert_eq!(bytes[..44], normals[..44]);
    assert_eq!(bytes[48..HEADER_BYTES], normals[48..HEADER_BYTES]);
    let first_texel = bytes.len() - 72 * 2;
    assert_eq!(
        u16::from_le_bytes([bytes[first_texel], bytes[first_texel + 1]]),
        height.atlas.texels[0].height_code()
    );
    // On the device: 4-byte words of two texels, then the block ranges as before.
    assert_eq!(
        height.atlas_bytes() + 72 * 2,
        sample().atlas_bytes(),
        "half the texel bytes"
    );
    let words = height.atlas_words();
    let codes = |k: usize| height.atlas.texels[k].height_code() as u32;
    assert_eq!(words[0], codes(0) | codes(1) << 16);
    assert_eq!(words[35], codes(70) | codes(71) << 16);
    assert_eq!(words[36..], sample().atlas_words()[72..]);

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
    let mut r = sample();
    r.leaves[1].res_v = 6;
    check(r, "height-field leaf 1");
    let mut r = sample();
    r.leaves[0].atlas_base = u32::MAX;
    check(r, "does not fit");
    let mut r = sample();
    r.leaves[0].axis_w[1] = f32::NAN;
    check(r, "not finite");
    let mut r = sample();
    r.atlas.rows = 8;
    check(r, "pitch × rows");
    let mut r = sample();
    (r.atlas.pitch, r.atlas.rows) = (12, 6);
    check(r, "the atlas pitch is 12 texels, not a power of two");
    let mut r = sample();
    r.triangles[1].flags = GpuTriangle::part_flags(2, false);
    check(
        r,
        "triangle 1 has flags 0x9 and padding 0x0: neither 0 nor an exact part of one of the 2",
    );
    let mut r = sample();
    r.triangles[0].flags = GpuTriangle::BARE;
    check(r, "triangle 0 has flags 0x2");
    let mut r = sample();
    r.triangles[0].pad2 = 1;
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

    // Counts that overflow, or promise more than the file holds.
    let mut bytes = sample().to_bytes();
    // Bytes 140..148: the texel count.
    bytes[140..148].copy_from_slice(&u64::MAX.to_le_bytes());
    let message = parse_error(Rbvh::from_bytes(&bytes, path), path);
    assert!(message.contains("counts"), "{message}");
    // More nodes than a traversal stack entry can name (bytes 116..124: the node count).
    let mut bytes = sample().to_bytes();
    let too_many = rbvh::bvh::MAX_NODES as u64 + 1;
    bytes[116..124].copy_from_slice(&too_many.to_le_bytes());
    let message = parse_error(Rbvh::from_bytes(&bytes, path), path);
    assert!(
        message.contains(&format!("{too_many} nodes, more than the")),
        "{message}"
    );
    // Unknown enum tags and flags, and a height-only RBVH claiming colours.
    for (at, value, expect) in [
        (24, 7u32, "params.subdivision has tag 7"),
        (44, 2, "params.texels has tag 2"),
        (48, 3, "the colour channel flag is 3"),
    ] {
        let mut bytes = sample().to_bytes();
        bytes[at..at + 4].copy_from_slice(&value.to_le_bytes());
        let message = parse_error(Rbvh::from_bytes(&bytes, path), path);
        assert!(message.contains(expect), "{message}");
    }
    let mut bytes = sample().to_bytes();
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
    // The header's flag says so; the bytes without colours follow, then the colour count and
    // the colours.
    let plain = sample().to_bytes();
    assert_eq!(word(&bytes, 48), 1);
    assert_eq!(bytes.len(), plain.len() + 8 + 72 * 4);
    assert_eq!(bytes[..48], plain[..48]);
    assert_eq!(bytes[52..plain.len()], plain[52..]);
    assert_eq!(bytes[plain.len()..plain.len() + 8], 72u64.to_le_bytes());

    // A colour section cut short, or with a count that is neither 0 nor one per texel.
    for cut in [1, 4, 72 * 4, 72 * 4 + 7] {
        let message = parse_error(Rbvh::from_bytes(&bytes[..bytes.len() - cut], path), path);
        assert!(message.contains("truncated"), "{cut}: {message}");
    }
    let mut odd = painted.clone();
    odd.colours.as_mut().unwrap().pop();
    let message = parse_error(Rbvh::from_bytes(&odd.to_bytes(), path), path);
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
