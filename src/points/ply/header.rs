//! The header of a PLY file (Turk 1994; Bourke, "PLY - Polygon File Format"): `ply`, the
//! `format` line, and the `element` and `property` lines up to `end_header`, read line by line
//! with every error naming its line. What the records hold and how they are encoded
//! ([`Header`]); the vertex element's properties are mapped to channels by
//! [`super::layout`].

use std::io::{BufRead, Read};
use std::path::Path;

use crate::{Error, Result};

/// Longest header line accepted. Real header lines are short; the limit keeps a binary file that
/// happens to begin with `ply` from being read whole in search of a line's end.
const MAX_HEADER_LINE: u64 = 64 * 1024;

/// How the records are encoded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Format {
    /// Text, one record per line.
    Ascii,
    /// Packed values, least or most significant byte first.
    Binary { big_endian: bool },
}

/// PLY's scalar types.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Scalar {
    Char,
    UChar,
    Short,
    UShort,
    Int,
    UInt,
    Float,
    Double,
}

impl Scalar {
    /// The type a header names, by its original name or its sized one.
    pub(super) fn from_name(name: &str) -> Option<Scalar> {
        Some(match name {
            "char" | "int8" => Scalar::Char,
            "uchar" | "uint8" => Scalar::UChar,
            "short" | "int16" => Scalar::Short,
            "ushort" | "uint16" => Scalar::UShort,
            "int" | "int32" => Scalar::Int,
            "uint" | "uint32" => Scalar::UInt,
            "float" | "float32" => Scalar::Float,
            "double" | "float64" => Scalar::Double,
            _ => return None,
        })
    }

    pub(super) fn name(self) -> &'static str {
        match self {
            Scalar::Char => "char",
            Scalar::UChar => "uchar",
            Scalar::Short => "short",
            Scalar::UShort => "ushort",
            Scalar::Int => "int",
            Scalar::UInt => "uint",
            Scalar::Float => "float",
            Scalar::Double => "double",
        }
    }

    /// Bytes of one value in a binary file.
    pub(super) fn size(self) -> usize {
        match self {
            Scalar::Char | Scalar::UChar => 1,
            Scalar::Short | Scalar::UShort => 2,
            Scalar::Int | Scalar::UInt | Scalar::Float => 4,
            Scalar::Double => 8,
        }
    }

    /// The range of an integer type; `None` for the floating-point ones.
    pub(super) fn integer_range(self) -> Option<(i64, i64)> {
        match self {
            Scalar::Char => Some((i8::MIN.into(), i8::MAX.into())),
            Scalar::UChar => Some((0, u8::MAX.into())),
            Scalar::Short => Some((i16::MIN.into(), i16::MAX.into())),
            Scalar::UShort => Some((0, u16::MAX.into())),
            Scalar::Int => Some((i32::MIN.into(), i32::MAX.into())),
            Scalar::UInt => Some((0, u32::MAX.into())),
            Scalar::Float | Scalar::Double => None,
        }
    }

    /// The value of the first [`Scalar::size`] bytes of `b`, least significant first. Every
    /// type's values are exact in `f64`.
    pub(super) fn decode_le(self, b: [u8; 8]) -> f64 {
        match self {
            Scalar::Char => i8::from_le_bytes([b[0]]).into(),
            Scalar::UChar => b[0].into(),
            Scalar::Short => i16::from_le_bytes([b[0], b[1]]).into(),
            Scalar::UShort => u16::from_le_bytes([b[0], b[1]]).into(),
            Scalar::Int => i32::from_le_bytes([b[0], b[1], b[2], b[3]]).into(),
            Scalar::UInt => u32::from_le_bytes([b[0], b[1], b[2], b[3]]).into(),
            Scalar::Float => f32::from_le_bytes([b[0], b[1], b[2], b[3]]).into(),
            Scalar::Double => f64::from_le_bytes(b),
        }
    }

    /// The value of an ascii token: a whole number in range for an integer type, any number for
    /// a floating-point one.
    pub(super) fn parse(self, token: &str) -> Option<f64> {
        match self.integer_range() {
            Some((min, max)) => token
                .parse::<i64>()
                .ok()
                .filter(|v| (min..=max).contains(v))
                .map(|v| v as f64),
            None => token.parse::<f64>().ok(),
        }
    }
}

/// What a property holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Kind {
    Scalar(Scalar),
    /// A length of type `count`, then that many values of type `item`.
    List {
        count: Scalar,
        item: Scalar,
    },
}

impl Kind {
    /// Fewest bytes the property takes in a binary record (an empty list takes its length).
    pub(super) fn min_bytes(self) -> u64 {
        match self {
            Kind::Scalar(s) | Kind::List { count: s, .. } => s.size() as u64,
        }
    }
}

#[derive(Debug)]
pub(super) struct Property {
    pub(super) name: String,
    pub(super) kind: Kind,
}

#[derive(Debug)]
pub(super) struct Element {
    pub(super) name: String,
    pub(super) count: u64,
    pub(super) properties: Vec<Property>,
    /// The header line that declares it, for errors about its properties.
    pub(super) line: usize,
}

#[derive(Debug)]
pub(super) struct Header {
    pub(super) format: Format,
    pub(super) elements: Vec<Element>,
    /// Lines in the header, `end_header`'s included.
    pub(super) lines: usize,
    /// Bytes in the header: where the body begins.
    pub(super) bytes: u64,
}

/// Reads the header, up to and including the `end_header` line.
pub(super) fn read_header(path: &Path, reader: &mut impl BufRead) -> Result<Header> {
    let mut buf = Vec::new();
    let mut bytes = 0u64;
    let mut line = 0usize;
    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    loop {
        buf.clear();
        let n = reader
            .by_ref()
            .take(MAX_HEADER_LINE)
            .read_until(b'\n', &mut buf)
            .map_err(|e| Error::io(path, e))?;
        line += 1;
        bytes += n as u64;
        let fail = |message: String| Error::parse(path, Some(line), message);
        if line == 1 {
            if buf.trim_ascii() != b"ply" {
                return Err(Error::parse(
                    path,
                    None,
                    "not a PLY file: it does not begin with the line `ply`",
                ));
            }
            continue;
        }
        if n == 0 {
            return Err(fail(
                "the file ends inside the header (no `end_header` line)".into(),
            ));
        }
        if n as u64 == MAX_HEADER_LINE && !buf.ends_with(b"\n") {
            return Err(fail(format!(
                "a header line longer than {MAX_HEADER_LINE} bytes: this is no PLY header"
            )));
        }
        let text = std::str::from_utf8(&buf)
            .map_err(|_| fail("the header line is not text (UTF-8)".into()))?;
        let mut words = text.split_whitespace();
        match words.next() {
            None | Some("comment" | "obj_info") => {}
            Some("end_header") => break,
            Some("format") => {
                if format.is_some() {
                    return Err(fail("a second `format` line".into()));
                }
                format = Some(match words.next() {
                    Some("ascii") => Format::Ascii,
                    Some("binary_little_endian") => Format::Binary { big_endian: false },
                    Some("binary_big_endian") => Format::Binary { big_endian: true },
                    other => {
                        return Err(fail(format!(
                            "unknown format `{}`: PLY's are ascii, binary_little_endian and binary_big_endian",
                            other.unwrap_or_default()
                        )))
                    }
                });
            }
            Some("element") => {
                let (Some(name), Some(count), None) = (words.next(), words.next(), words.next())
                else {
                    return Err(fail("an `element` line is `element <name> <count>`".into()));
                };
                let count = count.parse::<u64>().map_err(|_| {
                    fail(format!(
                        "element `{name}` has the count `{count}`, which is not a whole number"
                    ))
                })?;
                if name == "vertex" && elements.iter().any(|e| e.name == "vertex") {
                    return Err(fail("a second `vertex` element".into()));
                }
                elements.push(Element {
                    name: name.to_owned(),
                    count,
                    properties: Vec::new(),
                    line,
                });
            }
            Some("property") => {
                let Some(element) = elements.last_mut() else {
                    return Err(fail("a `property` line before any `element` line".into()));
                };
                let property = parse_property(words).map_err(fail)?;
                if element.properties.iter().any(|p| p.name == property.name) {
                    return Err(fail(format!(
                        "element `{}` declares the property `{}` twice",
                        element.name, property.name
                    )));
                }
                element.properties.push(property);
            }
            Some(other) => return Err(fail(format!("unknown header keyword `{other}`"))),
        }
    }
    let format = format.ok_or_else(|| {
        Error::parse(
            path,
            None,
            "the header has no `format` line (e.g. `format binary_little_endian 1.0`)",
        )
    })?;
    Ok(Header {
        format,
        elements,
        lines: line,
        bytes,
    })
}

/// The property declared by the words after `property`.
fn parse_property<'a>(
    mut words: impl Iterator<Item = &'a str>,
) -> std::result::Result<Property, String> {
    let scalar = |word: Option<&str>| {
        let word = word.unwrap_or_default();
        Scalar::from_name(word).ok_or_else(|| {
            format!("`{word}` is not a PLY type (char, uchar, short, ushort, int, uint, float, double, or int8 … float64)")
        })
    };
    let kind = match words.next() {
        Some("list") => {
            let count = scalar(words.next())?;
            if count.integer_range().is_none() {
                return Err(format!(
                    "a list's length must have an integer type, not {}",
                    count.name()
                ));
            }
            Kind::List {
                count,
                item: scalar(words.next())?,
            }
        }
        word => Kind::Scalar(scalar(word)?),
    };
    match (words.next(), words.next()) {
        (Some(name), None) => Ok(Property {
            name: name.to_owned(),
            kind,
        }),
        _ => Err("a `property` line is `property <type> <name>` or `property list <count type> <item type> <name>`".into()),
    }
}

#[cfg(test)]
mod tests {
    use super::super::tests::*;

    #[test]
    fn header_errors_name_their_line() {
        let vertex = format!("element vertex 1\n{XYZ}");
        let cases: Vec<(Vec<u8>, Option<usize>, &str)> = vec![
            (b"".to_vec(), None, "not a PLY file"),
            (b"plx\nformat ascii 1.0\n".to_vec(), None, "not a PLY file"),
            (b"\x89PNG\r\n\x1a\n".to_vec(), None, "not a PLY file"),
            (
                format!("ply\nformat ascii_text 1.0\n{vertex}end_header\n").into_bytes(),
                Some(2),
                "unknown format `ascii_text`",
            ),
            (
                b"ply\nformat\nend_header\n".to_vec(),
                Some(2),
                "unknown format ``",
            ),
            (
                format!("ply\n{vertex}end_header\n0 0 0\n").into_bytes(),
                None,
                "no `format` line",
            ),
            (
                ascii("format ascii 1.0\nend_header\n"),
                Some(3),
                "a second `format` line",
            ),
            (ascii(&vertex), Some(7), "no `end_header`"),
            (ascii("elemnt vertex 1\n"), Some(3), "unknown header keyword `elemnt`"),
            (ascii("property float x\n"), Some(3), "before any `element`"),
            (
                ascii("element vertex 1\nproperty flaot x\n"),
                Some(4),
                "`flaot` is not a PLY type",
            ),
            (
                ascii("element vertex 1\nproperty\n"),
                Some(4),
                "`` is not a PLY type",
            ),
            (
                ascii("element vertex 1\nproperty float\n"),
                Some(4),
                "`property <type> <name>`",
            ),
            (
                ascii("element vertex 1\nproperty float x y\n"),
                Some(4),
                "`property <type> <name>`",
            ),
            (
                ascii("element face 1\nproperty list float int vertex_indices\n"),
                Some(4),
                "integer type, not float",
            ),
            (
                ascii("element face 1\nproperty list uchar\n"),
                Some(4),
                "`` is not a PLY type",
            ),
            (ascii("element vertex -3\n"), Some(3), "`-3`, which is not a whole number"),
            (ascii("element vertex many\n"), Some(3), "not a whole number"),
            (ascii("element vertex\n"), Some(3), "`element <name> <count>`"),
            (ascii("element vertex 1 2\n"), Some(3), "`element <name> <count>`"),
            (
                ascii(&format!("{vertex}property double x\n")),
                Some(7),
                "declares the property `x` twice",
            ),
            (
                ascii(&format!("{vertex}{vertex}")),
                Some(7),
                "a second `vertex` element",
            ),
            (
                ascii("element face 1\nproperty list uchar int vertex_indices\nend_header\n3 0 1 2\n"),
                None,
                "no `vertex` element",
            ),
            (
                ascii("comment\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n"),
                Some(4),
                "no `z` property",
            ),
            (
                ascii(&format!("{vertex}property float nx\nproperty float nz\nend_header\n")),
                Some(3),
                "only some of `nx ny nz`",
            ),
            (
                ascii(&format!("{vertex}property uchar red\nend_header\n")),
                Some(3),
                "only some of `red green blue`",
            ),
            (
                ascii(&format!("{vertex}property uchar alpha\nend_header\n")),
                Some(3),
                "`alpha` but no `red green blue`",
            ),
            (
                ascii(&format!(
                    "{vertex}property ushort red\nproperty ushort green\nproperty ushort blue\nend_header\n"
                )),
                Some(3),
                "`red` is ushort: colours must be uchar (0–255) or float/double (0–1)",
            ),
            (
                ascii("element vertex 1\nproperty list uchar float x\nproperty float y\nproperty float z\nend_header\n"),
                Some(3),
                "`x` is a list",
            ),
            (
                b"ply\nformat ascii 1.0\ncomment \xff\xfe\nend_header\n".to_vec(),
                Some(3),
                "not text",
            ),
            (
                [&b"ply\n"[..], &[b'a'; 70_000]].concat(),
                Some(2),
                "longer than 65536 bytes",
            ),
        ];
        for (bytes, line, message) in cases {
            let (got_line, got) = parse_error(&bytes);
            assert!(
                got.contains(message) && got_line == line,
                "{:?}: expected line {line:?} and {message:?}, got line {got_line:?}: {got:?}",
                String::from_utf8_lossy(&bytes)
            );
        }
    }
}
