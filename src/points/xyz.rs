//! XYZ files: plain text, one point per line. The format has no specification — it is what
//! scanning and point-cloud tools (CloudCompare, MeshLab, PDAL's text writer) write when asked for
//! bare ASCII points — so this is the variant read here:
//!
//! * a data line is `x y z`, or `x y z nx ny nz` with the point's normal, its values separated by
//!   whitespace, commas, or both;
//! * the first data line sets the columns, 3 or 6, and every other data line must have as many;
//! * blank lines, and lines that begin (after any blank) with `#` or `//`, are skipped, and so is a
//!   UTF-8 byte-order mark at the start of the file;
//! * values are decimal numbers, in scientific notation or not (`-1.5`, `2e-3`).
//!
//! There are no colours: six columns are always a normal, never `r g b` (a file with colours
//! belongs in a PLY, where its header says what each column is), and columns 4–6 with a value
//! beyond ±1.5, as colours of 0–255 have, are refused as no normal. An error names the line.

use std::io::{BufRead, BufReader};
use std::path::Path;

use glam::Vec3;

use super::RawPoints;
use crate::{Error, Result};

/// Reads the points of the XYZ file at `path`.
pub(super) fn read(path: &Path) -> Result<RawPoints> {
    let file = crate::io::input::open(path)?;
    read_from(path, BufReader::new(file))
}

/// Reads the points of an XYZ file from `reader`; `path` names it in errors.
fn read_from(path: &Path, mut reader: impl BufRead) -> Result<RawPoints> {
    let mut positions = Vec::new();
    let mut normals = Vec::new();
    // The first data line's number and its count of values.
    let mut first: Option<(usize, usize)> = None;
    let mut buf = Vec::new();
    let mut line = 0;
    loop {
        buf.clear();
        let n = reader
            .read_until(b'\n', &mut buf)
            .map_err(|e| Error::io(path, e))?;
        if n == 0 {
            break;
        }
        line += 1;
        let fail = |message: String| Error::parse(path, Some(line), message);
        let text =
            std::str::from_utf8(&buf).map_err(|_| fail("the line is not text (UTF-8)".into()))?;
        let text = if line == 1 {
            text.trim_start_matches('\u{feff}')
        } else {
            text
        }
        .trim();
        if text.is_empty() || text.starts_with('#') || text.starts_with("//") {
            continue;
        }
        let mut values = [0.0f32; 6];
        let mut count = 0;
        for token in text
            .split(|c: char| c.is_whitespace() || c == ',')
            .filter(|t| !t.is_empty())
        {
            let value = token
                .parse::<f32>()
                .map_err(|_| fail(format!("`{token}` is not a number")))?;
            if !value.is_finite() {
                return Err(Error::InvalidGeometry {
                    source_name: format!("{}:{line}", path.display()),
                    message: format!("`{token}` is not a finite number in 32-bit floats"),
                });
            }
            if let Some(slot) = values.get_mut(count) {
                *slot = value;
            }
            count += 1;
        }
        match first {
            None if count == 3 || count == 6 => first = Some((line, count)),
            None => {
                return Err(fail(format!(
                    "{count} values: an XYZ line is `x y z` or `x y z nx ny nz`"
                )))
            }
            Some((first_line, columns)) if count != columns => {
                return Err(fail(format!(
                    "{count} values, but the first data line (line {first_line}) has {columns}: every line must have as many"
                )))
            }
            Some(_) => {}
        }
        let [x, y, z, nx, ny, nz] = values;
        positions.push(Vec3::new(x, y, z));
        if count == 6 {
            let normal = Vec3::new(nx, ny, nz);
            // Many tools write `x y z r g b` with colours 0–255 under the same extension; read
            // as normals they would tilt every point. A normal's components lie within ±1
            // (unnormalized ones rarely far beyond).
            if normal.abs().max_element() > MAX_NORMAL_COMPONENT {
                return Err(fail(format!(
                    "columns 4–6 ({nx} {ny} {nz}) are not a normal: an XYZ line is `x y z` or `x y z nx ny nz`; \
                     colours are not read from XYZ files (write a PLY with red green blue)"
                )));
            }
            normals.push(normal);
        }
    }
    Ok(RawPoints {
        positions,
        normals: matches!(first, Some((_, 6))).then_some(normals),
        colours: None,
    })
}

/// Largest normal component accepted in columns 4–6 (see [`read`]).
const MAX_NORMAL_COMPONENT: f32 = 1.5;

#[cfg(test)]
mod tests {
    use super::*;

    const PATH: &str = "cloud.xyz";

    fn load(text: &[u8]) -> Result<RawPoints> {
        read_from(Path::new(PATH), text)
    }

    /// The line and message of the parse error that `text` must give.
    fn parse_error(text: &[u8]) -> (Option<usize>, String) {
        super::super::parse_error_of(load(text), PATH)
    }

    fn vecs(points: &[[f32; 3]]) -> Vec<Vec3> {
        points.iter().map(|&p| Vec3::from(p)).collect()
    }

    #[test]
    fn positions_with_any_separators_comments_and_blank_lines() {
        let text = "\u{feff}# scanned on a Tuesday\r\n\
                    1 2 3\r\n\
                    \r\n\
                    // millimetres\n\
                    \t-4.5,0.25 , 1e3\n\
                    \x20 # an indented comment\n\
                    0,\t0,\t-7\n\
                    +.5 6. -0\n";
        assert_eq!(
            load(text.as_bytes()).unwrap(),
            RawPoints {
                positions: vecs(&[
                    [1.0, 2.0, 3.0],
                    [-4.5, 0.25, 1000.0],
                    [0.0, 0.0, -7.0],
                    [0.5, 6.0, -0.0]
                ]),
                normals: None,
                colours: None,
            }
        );
    }

    #[test]
    fn positions_and_normals() {
        let text = b"0 0 0 0 0 1\n1, 0, 0, 0.6, 0.8, 0\n0 1 0 -1 0 0";
        assert_eq!(
            load(text).unwrap(),
            RawPoints {
                positions: vecs(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]),
                normals: Some(vecs(&[[0.0, 0.0, 1.0], [0.6, 0.8, 0.0], [-1.0, 0.0, 0.0]])),
                colours: None,
            }
        );
    }

    #[test]
    fn nothing_but_comments_is_no_points() {
        assert_eq!(load(b"").unwrap(), RawPoints::default());
        assert_eq!(
            load(b"# empty\n\n// still\n").unwrap(),
            RawPoints::default()
        );
    }

    #[test]
    fn errors_name_their_line() {
        let cases: [(&[u8], usize, &str); 8] = [
            (
                b"1 2\n",
                1,
                "2 values: an XYZ line is `x y z` or `x y z nx ny nz`",
            ),
            (
                b"# rgb\n1 2 3 255 0 0 1\n",
                2,
                "7 values: an XYZ line is `x y z` or `x y z nx ny nz`",
            ),
            (
                b"1 2 3\n4 5 6\n\n7 8 9 0 0 1\n",
                4,
                "6 values, but the first data line (line 1) has 3",
            ),
            (
                b"# n\n1 2 3 0 0 1\n4 5 6\n",
                3,
                "3 values, but the first data line (line 2) has 6",
            ),
            (b"1 2 3\n4 five 6\n", 2, "`five` is not a number"),
            (b"1 2 3 # trailing comment\n", 1, "`#` is not a number"),
            (b"1;2;3\n", 1, "`1;2;3` is not a number"),
            (b"1 2 3\n4 \xff 6\n", 2, "the line is not text (UTF-8)"),
        ];
        for (text, line, message) in cases {
            let (got_line, got) = parse_error(text);
            assert!(
                got_line == Some(line) && got.contains(message),
                "{:?}: expected line {line} and {message:?}, got {got_line:?}: {got:?}",
                String::from_utf8_lossy(text)
            );
        }
    }

    /// Values that are no 32-bit float are invalid geometry named by their line, as a mesh's NaN
    /// vertex is, where the cloud used to refuse them by point number alone ("point 3").
    #[test]
    fn non_finite_values_are_refused_at_their_line() {
        for (text, at, message) in [
            (
                &b"# a\n\n1 2 3\nnan 0 0\n"[..],
                4,
                "`nan` is not a finite number",
            ),
            (b"1 2 3\n0 inf 0\n", 2, "`inf` is not a finite number"),
            (
                b"1 1 1e300\n",
                1,
                "`1e300` is not a finite number in 32-bit floats",
            ),
        ] {
            match load(text) {
                Err(e @ Error::InvalidGeometry { .. }) => {
                    let e = e.to_string();
                    assert!(
                        e.starts_with(&format!("{PATH}:{at}: ")) && e.contains(message),
                        "{e}"
                    );
                }
                other => panic!("expected invalid geometry, got {other:?}"),
            }
        }
    }

    #[test]
    fn truncation_at_every_offset_never_panics() {
        let text = b"# a comment\n1 2 3 0 0 1\n-4.5, 0.25, 1e3, 0.6, 0.8, 0\n\n0 0 -7 1 0 0\n";
        for cut in 0..=text.len() {
            if let Err(e) = load(&text[..cut]) {
                assert!(e.to_string().starts_with(&format!("{PATH}:")), "{e}");
            }
        }
    }

    #[test]
    fn reads_a_file_and_names_a_missing_one() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("scan.xyz");
        std::fs::write(&path, "0 0 0\n1 0 0\n0 1 0\n").unwrap();
        assert_eq!(read(&path).unwrap().positions.len(), 3);
        let missing = dir.path().join("missing.xyz");
        match read(&missing) {
            Err(Error::Io { path, .. }) => assert_eq!(path, missing),
            other => panic!("expected an I/O error, got {other:?}"),
        }
    }

    #[test]
    fn colours_in_the_normal_columns_are_refused() {
        let (line, message) = parse_error(b"0 0 0 0 0 1\n1 0 0 200 30 10\n");
        assert_eq!(line, Some(2));
        assert!(
            message.contains("not a normal") && message.contains("PLY"),
            "{message}"
        );
        assert!(
            load(b"0 0 0 0 0 1.2\n").is_ok(),
            "an unnormalized normal is still one"
        );
    }
}
