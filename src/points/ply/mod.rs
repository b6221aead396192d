//! PLY files: the Polygon File Format of Greg Turk ("The PLY Polygon File Format", 1994), as
//! Paul Bourke describes it ("PLY - Polygon File Format", paulbourke.net/dataformats/ply/).
//!
//! A PLY file is a text header — `ply`, a `format` line (`ascii`, `binary_little_endian` or
//! `binary_big_endian`), then `element <name> <count>` lines, each followed by the
//! `property <type> <name>` or `property list <count type> <item type> <name>` lines of its
//! records, and `end_header` — then every element's records in the header's order: one record per
//! line for `ascii`, packed values with no padding for the binary formats.
//!
//! Of all that, only the `vertex` element is read, and of it:
//!
//! * `x y z`, required, of any scalar type;
//! * `nx ny nz`, all three or none, of any scalar type;
//! * `red green blue`, all three or none, with `alpha` optional (opaque when absent), as `uchar`
//!   (0–255, taken as they are: sRGB-encoded) or as `float`/`double` (0–1, clamped and rounded
//!   to bytes).
//!
//! Every other vertex property (a scanner's `confidence` or `intensity`, a list) and every other
//! element (`face`, `edge`, anything custom) is stepped over: a mesh's PLY is read as the scan it
//! came from: its vertices. What follows the vertex element is not read at all. Scalar types may
//! go by either of their names (`char`/`int8` … `double`/`float64`); comments, `obj_info` and
//! blank lines are ignored.
//!
//! The reader is this module's own rather than a crate's: the maintained `ply-rs-bw` (3.x) keeps
//! every record of every element in memory, faces included, and reports errors as multi-line
//! parser dumps that cite a "line" in binary files too. Here a file is streamed; a header's count
//! reserves no more room than the rest of the file could fill, so a lying one costs nothing
//! before the file runs out ("the file ends after 2 of 4000000000 vertices"); a list is stepped
//! over unread, and refused when the rest of the file cannot hold its length; and every error is
//! one sentence naming the file, and the line in a header or an ascii body. The `format` line's
//! version is not checked: 1.0 is the only one there is.
//!
//! ## Files
//! [`header`]: the header; [`layout`]: the vertex properties' channels; [`body`]: the records.
//! Here: reading a file, the three in order.

mod body;
mod header;
mod layout;

use std::io::{BufRead, BufReader};
use std::path::Path;

use super::RawPoints;
use crate::{Error, Result};
use body::Body;
use header::read_header;
use layout::Layout;

/// The vertex properties that are read, in the order of a record's channels.
const CHANNELS: [&str; 10] = [
    "x", "y", "z", "nx", "ny", "nz", "red", "green", "blue", "alpha",
];
/// First channel of the normal.
const NORMAL: usize = 3;
/// First channel of the colour (red, green, blue, alpha).
const COLOUR: usize = 6;

/// Reads the vertices of the PLY file at `path`.
pub(super) fn read(path: &Path) -> Result<RawPoints> {
    let file = crate::io::input::open(path)?;
    let metadata = file.metadata().map_err(|e| Error::io(path, e))?;
    let len = metadata.is_file().then_some(metadata.len());
    read_from(path, BufReader::new(file), len)
}

/// Reads the vertices of a PLY file from `reader`, which holds `len` bytes when known; `path`
/// names it in errors.
fn read_from(path: &Path, mut reader: impl BufRead, len: Option<u64>) -> Result<RawPoints> {
    let header = read_header(path, &mut reader)?;
    let Some(vertices) = header.elements.iter().find(|e| e.name == "vertex") else {
        return Err(Error::parse(
            path,
            None,
            "the header declares no `vertex` element: there are no points to read",
        ));
    };
    let layout = Layout::new(vertices).map_err(|m| Error::parse(path, Some(vertices.line), m))?;
    let mut body = Body {
        path,
        reader,
        format: header.format,
        line: header.lines,
        offset: header.bytes,
        len,
        text: Vec::new(),
    };
    for element in header.elements.iter().take_while(|e| e.name != "vertex") {
        body.skip_element(element)?;
    }
    body.read_vertices(vertices, &layout)
}

#[cfg(test)]
pub(super) mod tests {
    use glam::Vec3;

    use super::header::Scalar;
    use super::*;

    pub(super) const PATH: &str = "cloud.ply";

    pub(super) fn load(bytes: &[u8]) -> Result<RawPoints> {
        read_from(Path::new(PATH), bytes, Some(bytes.len() as u64))
    }

    /// The line and message of the parse error that `bytes` must give.
    pub(super) fn parse_error(bytes: &[u8]) -> (Option<usize>, String) {
        super::super::parse_error_of(load(bytes), PATH)
    }

    pub(super) fn ascii(rest: &str) -> Vec<u8> {
        format!("ply\nformat ascii 1.0\n{rest}").into_bytes()
    }

    /// `v` as a value of type `ty`, least significant byte first unless `big_endian`.
    pub(super) fn encode(ty: Scalar, v: f64, big_endian: bool) -> Vec<u8> {
        let mut bytes = match ty {
            Scalar::Char => (v as i8).to_le_bytes().to_vec(),
            Scalar::UChar => (v as u8).to_le_bytes().to_vec(),
            Scalar::Short => (v as i16).to_le_bytes().to_vec(),
            Scalar::UShort => (v as u16).to_le_bytes().to_vec(),
            Scalar::Int => (v as i32).to_le_bytes().to_vec(),
            Scalar::UInt => (v as u32).to_le_bytes().to_vec(),
            Scalar::Float => (v as f32).to_le_bytes().to_vec(),
            Scalar::Double => v.to_le_bytes().to_vec(),
        };
        if big_endian {
            bytes.reverse();
        }
        bytes
    }

    /// A binary PLY: `header` (the lines after `format`, `end_header` included), then `values`,
    /// each encoded as its type.
    pub(super) fn binary(big_endian: bool, header: &str, values: &[(Scalar, f64)]) -> Vec<u8> {
        let format = if big_endian {
            "binary_big_endian"
        } else {
            "binary_little_endian"
        };
        let mut bytes = format!("ply\nformat {format} 1.0\n{header}").into_bytes();
        for &(ty, v) in values {
            bytes.extend(encode(ty, v, big_endian));
        }
        bytes
    }

    pub(super) const XYZ: &str = "property float x\nproperty float y\nproperty float z\n";

    pub(super) fn positions(points: &[[f32; 3]]) -> Vec<Vec3> {
        points.iter().map(|&p| Vec3::from(p)).collect()
    }

    pub(super) fn rgba(r: u8, g: u8, b: u8, a: u8) -> u32 {
        u32::from_le_bytes([r, g, b, a])
    }

    /// Three vertices with everything: a face element before them, a list and extra scalars among
    /// their properties, and elements after them.
    pub(super) const FULL_HEADER: &str = "comment made by a test\n\
        obj_info scanner 7\n\
        element face 2\n\
        property list uchar int vertex_indices\n\
        element edge 1\n\
        property int vertex1\n\
        property int vertex2\n\
        element vertex 3\n\
        property double x\n\
        property double y\n\
        property double z\n\
        property float nx\n\
        property float ny\n\
        property float nz\n\
        property uchar red\n\
        property uchar green\n\
        property uchar blue\n\
        property uchar alpha\n\
        property ushort intensity\n\
        property list uint float samples\n\
        property float confidence\n\
        element material 1\n\
        property uchar ambient_red\n\
        end_header\n";

    pub(super) const FULL_POSITIONS: [[f32; 3]; 3] =
        [[1.0, 2.0, 3.0], [-4.5, 0.25, 1e6], [0.0, 0.0, -7.0]];
    pub(super) const FULL_NORMALS: [[f32; 3]; 3] =
        [[0.0, 0.0, 1.0], [0.6, 0.8, 0.0], [-1.0, 0.0, 0.0]];
    pub(super) const FULL_COLOURS: [[u8; 4]; 3] =
        [[255, 0, 0, 255], [1, 2, 3, 4], [200, 100, 50, 0]];

    /// [`FULL_HEADER`]'s body.
    pub(super) fn full_values() -> Vec<(Scalar, f64)> {
        use Scalar::*;
        let mut values = vec![
            // Two faces, then an edge.
            (UChar, 3.0),
            (Int, 0.0),
            (Int, 1.0),
            (Int, 2.0),
            (UChar, 0.0),
            (Int, 1.0),
            (Int, 2.0),
        ];
        for i in 0..3 {
            values.extend(FULL_POSITIONS[i].map(|v| (Double, f64::from(v))));
            values.extend(FULL_NORMALS[i].map(|v| (Float, f64::from(v))));
            values.extend(FULL_COLOURS[i].map(|v| (UChar, f64::from(v))));
            values.push((UShort, 60000.0));
            // `samples`: i items.
            values.push((UInt, i as f64));
            values.extend((0..i).map(|k| (Float, k as f64)));
            values.push((Float, 0.5));
        }
        values.push((UChar, 9.0));
        values
    }

    pub(super) fn full_binary(big_endian: bool) -> Vec<u8> {
        binary(big_endian, FULL_HEADER, &full_values())
    }

    pub(super) fn full_points() -> RawPoints {
        RawPoints {
            positions: positions(&FULL_POSITIONS),
            normals: Some(positions(&FULL_NORMALS)),
            colours: Some(
                FULL_COLOURS
                    .iter()
                    .map(|&c| u32::from_le_bytes(c))
                    .collect(),
            ),
        }
    }

    pub(super) const FULL_ASCII: &str = "comment made by a test\n\
        element face 1\n\
        property list uchar int vertex_indices\n\
        element vertex 3\n\
        property float x\n\
        property float y\n\
        property float z\n\
        property list uchar int neighbours\n\
        property float nx\n\
        property float ny\n\
        property float nz\n\
        property float confidence\n\
        property uchar red\n\
        property uchar green\n\
        property uchar blue\n\
        property uchar alpha\n\
        element face 1\n\
        property list uchar int vertex_indices\n\
        end_header\n\
        3 0 1 2\n\
        1 2 3 2 1 2 0 0 1 0.5 255 0 0 255\n\
        \n\
        -4.5 0.25 1e6 0 0.6 0.8 0 0.5 1 2 3 4\n\
        0 0 -7 1 0 -1 0 0 0.5 200 100 50 0\n\
        3 0 1 2\n";

    #[test]
    fn ascii_reads_positions_normals_and_colours() {
        assert_eq!(load(&ascii(FULL_ASCII)).unwrap(), full_points());
    }

    #[test]
    fn ascii_with_crlf_line_endings() {
        let text = ascii(FULL_ASCII);
        let crlf = String::from_utf8(text).unwrap().replace('\n', "\r\n");
        assert_eq!(load(crlf.as_bytes()).unwrap(), full_points());
    }

    #[test]
    fn binary_in_both_byte_orders_skips_other_elements_and_properties() {
        for big_endian in [false, true] {
            assert_eq!(load(&full_binary(big_endian)).unwrap(), full_points());
        }
    }

    #[test]
    fn positions_and_normals_of_every_scalar_type_under_both_names() {
        use Scalar::*;
        let types = [
            (Char, "char", "int8"),
            (UChar, "uchar", "uint8"),
            (Short, "short", "int16"),
            (UShort, "ushort", "uint16"),
            (Int, "int", "int32"),
            (UInt, "uint", "uint32"),
            (Float, "float", "float32"),
            (Double, "double", "float64"),
        ];
        for (ty, name, sized) in types {
            for type_name in [name, sized] {
                let header = format!(
                    "element vertex 2\nproperty {type_name} x\nproperty {type_name} y\nproperty {type_name} z\n\
                     property {type_name} nx\nproperty {type_name} ny\nproperty {type_name} nz\nend_header\n"
                );
                let values = [1.0, 2.0, 127.0, 0.0, 0.0, 1.0, 5.0, 6.0, 7.0, 1.0, 0.0, 0.0];
                let expected = RawPoints {
                    positions: positions(&[[1.0, 2.0, 127.0], [5.0, 6.0, 7.0]]),
                    normals: Some(positions(&[[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])),
                    colours: None,
                };
                for big_endian in [false, true] {
                    let typed: Vec<_> = values.iter().map(|&v| (ty, v)).collect();
                    assert_eq!(
                        load(&binary(big_endian, &header, &typed)).unwrap(),
                        expected,
                        "{type_name}, big endian {big_endian}"
                    );
                }
                let body = "1 2 127 0 0 1\n5 6 7 1 0 0\n";
                assert_eq!(
                    load(&ascii(&format!("{header}{body}"))).unwrap(),
                    expected,
                    "{type_name}, ascii"
                );
            }
        }
    }

    #[test]
    fn negative_and_extreme_integers() {
        let header =
            "element vertex 1\nproperty char x\nproperty short y\nproperty uint z\nend_header\n";
        let values = [
            (Scalar::Char, -128.0),
            (Scalar::Short, -32768.0),
            (Scalar::UInt, 4_294_967_295.0),
        ];
        let expected = positions(&[[-128.0, -32768.0, 4_294_967_295.0]]);
        for big_endian in [false, true] {
            let points = load(&binary(big_endian, header, &values)).unwrap();
            assert_eq!(points.positions, expected);
        }
        let points = load(&ascii(&format!("{header}-128 -32768 4294967295\n"))).unwrap();
        assert_eq!(points.positions, expected);
    }

    #[test]
    fn float_colours_are_clamped_and_rounded_and_alpha_defaults_to_opaque() {
        let header = format!(
            "element vertex 2\n{XYZ}property float red\nproperty double green\nproperty float blue\nend_header\n"
        );
        let expected = vec![rgba(0, 128, 255, 255), rgba(255, 64, 0, 255)];
        let text = format!("{header}0 0 0 -0.1 0.5 1.2\n1 0 0 1 0.25 0\n");
        assert_eq!(load(&ascii(&text)).unwrap().colours, Some(expected.clone()));
        use Scalar::*;
        let mut values = vec![];
        for [x, r, g, b] in [[0.0, -0.1, 0.5, 1.2], [1.0, 1.0, 0.25, 0.0]] {
            values.extend([(Float, x), (Float, 0.0), (Float, 0.0)]);
            values.extend([(Float, r), (Double, g), (Float, b)]);
        }
        for big_endian in [false, true] {
            let points = load(&binary(big_endian, &header, &values)).unwrap();
            assert_eq!(points.colours, Some(expected.clone()));
            assert_eq!(points.normals, None);
        }
        let with_alpha = format!(
            "element vertex 1\n{XYZ}property uchar red\nproperty uchar green\nproperty uchar blue\n\
             property float alpha\nend_header\n0 0 0 10 20 30 0.5\n"
        );
        assert_eq!(
            load(&ascii(&with_alpha)).unwrap().colours,
            Some(vec![rgba(10, 20, 30, 128)])
        );
    }

    #[test]
    fn positions_alone() {
        let text = format!("element vertex 3\n{XYZ}end_header\n0 0 0\n1 0 0\n0 1 0\n");
        let points = load(&ascii(&text)).unwrap();
        assert_eq!(
            points,
            RawPoints {
                positions: positions(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]),
                normals: None,
                colours: None,
            }
        );
    }

    #[test]
    fn no_vertices_and_empty_elements() {
        let text = format!("element empty 1000000000000\nelement vertex 0\n{XYZ}end_header\n");
        assert_eq!(load(&ascii(&text)).unwrap(), RawPoints::default());
        assert_eq!(
            load(&binary(false, &text, &[])).unwrap(),
            RawPoints::default()
        );
    }

    #[test]
    fn a_file_of_unknown_length_reads_the_same() {
        for big_endian in [false, true] {
            let bytes = full_binary(big_endian);
            let points = read_from(Path::new(PATH), &bytes[..], None).unwrap();
            assert_eq!(points, full_points());
        }
        let header = format!("element vertex 4000000000\n{XYZ}end_header\n");
        let bytes = binary(false, &header, &[(Scalar::Float, 1.0); 3]);
        let error = read_from(Path::new(PATH), &bytes[..], None).unwrap_err();
        assert!(error
            .to_string()
            .ends_with("the file ends after 1 of 4000000000 vertices"));
    }

    /// Cut anywhere, a file gives an error naming it — or, once the vertices are whole, them.
    #[test]
    fn truncation_at_every_offset_never_panics() {
        for big_endian in [false, true] {
            let full = full_binary(big_endian);
            // Everything after the vertices is the material's one byte.
            let vertices_end = full.len() - 1;
            for cut in 0..full.len() {
                match load(&full[..cut]) {
                    Ok(points) => {
                        assert!(cut >= vertices_end, "cut at {cut} read {points:?}");
                        assert_eq!(points, full_points());
                    }
                    Err(e) => {
                        assert!(cut < vertices_end, "cut at {cut}: {e}");
                        assert!(e.to_string().starts_with(PATH), "{e}");
                    }
                }
            }
        }
        let text = ascii(FULL_ASCII);
        let header_end = text.windows(11).position(|w| w == b"end_header\n").unwrap() + 10;
        for cut in 0..text.len() {
            if let Err(e) = load(&text[..cut]) {
                assert!(e.to_string().starts_with(PATH), "{e}");
            } else {
                assert!(cut > header_end, "cut at {cut} inside the header read");
            }
        }
    }

    /// Deterministic byte mutations of valid files: any result but a panic (or a hang).
    #[test]
    fn mutated_files_never_panic() {
        let originals = [full_binary(false), full_binary(true), ascii(FULL_ASCII)];
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut random = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        for round in 0..6000 {
            let mut bytes = originals[round % originals.len()].clone();
            for _ in 0..1 + random() % 4 {
                let at = (random() % bytes.len() as u64) as usize;
                let choices = b"0123456789 \n-.e\xff\x00xlist";
                bytes[at] = match random() % 3 {
                    0 => random() as u8,
                    _ => choices[(random() % choices.len() as u64) as usize],
                };
            }
            if let Err(e) = load(&bytes) {
                assert!(e.to_string().starts_with(PATH), "{e}");
            }
        }
    }

    #[test]
    fn reads_a_file_and_names_a_missing_one() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("scan.ply");
        std::fs::write(&path, full_binary(true)).unwrap();
        assert_eq!(read(&path).unwrap(), full_points());
        let missing = dir.path().join("missing.ply");
        match read(&missing) {
            Err(Error::Io { path, .. }) => assert_eq!(path, missing),
            other => panic!("expected an I/O error, got {other:?}"),
        }
    }
}
