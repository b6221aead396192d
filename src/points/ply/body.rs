//! The records after a PLY header (see [`super`]), read in order: the elements before `vertex`
//! stepped over, then the vertices decoded, from text lines (`ascii`) or packed values (the
//! binary formats). A header's counts reserve no more room than the rest of the file could
//! fill, and every error names the file, and the line in an ascii body.

use std::io::{self, BufRead, Read};
use std::path::Path;

use glam::Vec3;

use super::header::{Element, Format, Kind, Property, Scalar};
use super::layout::Layout;
use super::{RawPoints, CHANNELS, COLOUR, NORMAL};
use crate::{Error, Result};

/// Vertices to reserve room for up front when the file's length is unknown (not a regular file),
/// and a lying count therefore cannot be caught before reading.
const UNKNOWN_LENGTH_CAPACITY: u64 = 1 << 16;

/// A colour channel's byte: a `uchar` as it is (the ascii reader refuses one out of range), a
/// `float`/`double` from 0–1, clamped; a NaN is an error, where it used to become 0 (black, or
/// transparent).
fn colour_byte(value: f64, ty: Scalar) -> std::result::Result<u8, String> {
    match ty {
        Scalar::UChar => Ok(value as u8),
        _ if value.is_nan() => Err("a colour is NaN".to_owned()),
        _ => Ok((value.clamp(0.0, 1.0) * 255.0).round() as u8),
    }
}

/// The records after the header, read in order.
pub(super) struct Body<'a, R> {
    pub(super) path: &'a Path,
    pub(super) reader: R,
    pub(super) format: Format,
    /// Lines read so far, the header's included (ascii).
    pub(super) line: usize,
    /// Bytes read so far, the header's included.
    pub(super) offset: u64,
    /// The file's length, when known.
    pub(super) len: Option<u64>,
    /// The current ascii line.
    pub(super) text: Vec<u8>,
}

impl<R: BufRead> Body<'_, R> {
    /// Steps over all of `element`'s records.
    pub(super) fn skip_element(&mut self, element: &Element) -> Result<()> {
        if element.properties.is_empty() {
            return Ok(());
        }
        let fixed = element
            .properties
            .iter()
            .all(|p| matches!(p.kind, Kind::Scalar(_)));
        if let (Format::Binary { .. }, true) = (self.format, fixed) {
            let stride: u64 = element.properties.iter().map(|p| p.kind.min_bytes()).sum();
            let start = self.offset;
            // A length past u64 is past the end of any file: the skip falls short either way.
            // `stride` is not 0: the element has properties, each of a byte or more.
            if self.skip(element.count.saturating_mul(stride))? {
                return Ok(());
            }
            return Err(self.ends_early(element, (self.offset - start) / stride));
        }
        let slots = vec![None; element.properties.len()];
        let mut values = [0.0; CHANNELS.len()];
        for index in 0..element.count {
            if !self.record(element, &slots, &mut values, index)? {
                return Err(self.ends_early(element, index));
            }
        }
        Ok(())
    }

    /// Reads the vertex element's records.
    pub(super) fn read_vertices(
        &mut self,
        vertices: &Element,
        layout: &Layout,
    ) -> Result<RawPoints> {
        let capacity = self.capacity(vertices);
        let mut positions = Vec::with_capacity(capacity);
        let mut normals = layout.normals.then(|| Vec::with_capacity(capacity));
        let mut colours = layout
            .colours
            .map(|types| (types, Vec::with_capacity(capacity)));
        let mut values = [0.0; CHANNELS.len()];
        for index in 0..vertices.count {
            if !self.record(vertices, &layout.slots, &mut values, index)? {
                return Err(self.ends_early(vertices, index));
            }
            let vector = |what: &str, channel: usize| {
                let [x, y, z] = [0, 1, 2].map(|k| values[channel + k]);
                let v = Vec3::new(x as f32, y as f32, z as f32);
                match v.is_finite() {
                    true => Ok(v),
                    false => Err(self.bad_vertex(
                        index,
                        format!("its {what} ({x:?}, {y:?}, {z:?}) is not finite in 32-bit floats"),
                    )),
                }
            };
            positions.push(vector("position", 0)?);
            if let Some(normals) = &mut normals {
                normals.push(vector("normal", NORMAL)?);
            }
            if let Some((types, colours)) = &mut colours {
                let mut bytes = [u8::MAX; 4];
                for (i, byte) in bytes.iter_mut().enumerate() {
                    if let Some(ty) = types[i] {
                        *byte = colour_byte(values[COLOUR + i], ty)
                            .map_err(|m| self.bad_vertex(index, m))?;
                    }
                }
                colours.push(u32::from_le_bytes(bytes));
            }
        }
        Ok(RawPoints {
            positions,
            normals,
            colours: colours.map(|(_, colours)| colours),
        })
    }

    /// Room to reserve for `element`'s records: its count, but no more than the rest of the file
    /// could hold, so that a lying count allocates nothing it cannot fill.
    fn capacity(&self, element: &Element) -> usize {
        let min_bytes = match self.format {
            // A value and a separator per property.
            Format::Ascii => 2 * element.properties.len() as u64,
            Format::Binary { .. } => element.properties.iter().map(|p| p.kind.min_bytes()).sum(),
        };
        let room = self
            .left()
            .map_or(UNKNOWN_LENGTH_CAPACITY, |left| left / min_bytes.max(1));
        usize::try_from(element.count.min(room)).unwrap_or(0)
    }

    /// Bytes left in the file, when its length is known.
    fn left(&self) -> Option<u64> {
        self.len.map(|len| len.saturating_sub(self.offset))
    }

    /// The error for vertex `index`, just read, whose values cannot be traced (as a NaN vertex
    /// of a mesh is): named by its line in an ascii body.
    fn bad_vertex(&self, index: u64, message: String) -> Error {
        let source_name = match self.format {
            Format::Ascii => format!("{}:{}", self.path.display(), self.line),
            Format::Binary { .. } => self.path.display().to_string(),
        };
        Error::InvalidGeometry {
            source_name,
            message: format!("vertex {index}: {message}"),
        }
    }

    /// The error for a file that ends after `done` of `element`'s records.
    fn ends_early(&self, element: &Element, done: u64) -> Error {
        Error::parse(self.path, None, self.ends_early_message(element, done))
    }

    fn ends_early_message(&self, element: &Element, done: u64) -> String {
        let what = if element.name == "vertex" {
            "vertices".to_owned()
        } else {
            format!("`{}` records (declared before the vertices)", element.name)
        };
        format!("the file ends after {done} of {} {what}", element.count)
    }

    /// Reads record `index` of `element`, storing each property that `slots` gives a channel
    /// into `values`. `Ok(false)` when the file ends first.
    fn record(
        &mut self,
        element: &Element,
        slots: &[Option<usize>],
        values: &mut [f64; CHANNELS.len()],
        index: u64,
    ) -> Result<bool> {
        match self.format {
            Format::Ascii => {
                let path = self.path;
                let Some((line, text)) = self.next_line()? else {
                    return Ok(false);
                };
                parse_ascii_record(text, element, slots, values).map_err(|m| {
                    Error::parse(path, Some(line), format!("{} {index}: {m}", element.name))
                })?;
                Ok(true)
            }
            Format::Binary { big_endian } => {
                for (property, &slot) in element.properties.iter().zip(slots) {
                    match property.kind {
                        Kind::Scalar(ty) => {
                            let Some(value) = self.binary_value(ty, big_endian)? else {
                                return Ok(false);
                            };
                            if let Some(channel) = slot {
                                values[channel] = value;
                            }
                        }
                        Kind::List { count, item } => {
                            let Some(n) = self.binary_value(count, big_endian)? else {
                                return Ok(false);
                            };
                            let bytes = self.list_bytes(element, index, property, n, item)?;
                            if !self.skip(bytes)? {
                                return Ok(false);
                            }
                        }
                    }
                }
                Ok(true)
            }
        }
    }

    /// Bytes of a binary list of `n` values of type `item`, refused when negative or longer than
    /// the rest of the file (a truncated file, or a lying length: either way, nothing is read
    /// for it).
    fn list_bytes(
        &self,
        element: &Element,
        index: u64,
        property: &Property,
        n: f64,
        item: Scalar,
    ) -> Result<u64> {
        let at = format!(
            "{} {index}'s list `{}` (at byte {})",
            element.name, property.name, self.offset
        );
        if n < 0.0 {
            return Err(Error::parse(
                self.path,
                None,
                format!("{at} has the negative length {n}"),
            ));
        }
        let bytes = n as u64 * item.size() as u64;
        match self.left() {
            Some(left) if bytes > left => Err(Error::parse(
                self.path,
                None,
                format!(
                    "{}: {at} claims {n} items ({bytes} bytes), more than the {left} bytes left",
                    self.ends_early_message(element, index)
                ),
            )),
            _ => Ok(bytes),
        }
    }

    /// The next binary value of type `ty`; `None` when the file ends first.
    fn binary_value(&mut self, ty: Scalar, big_endian: bool) -> Result<Option<f64>> {
        let mut bytes = [0u8; 8];
        let value = &mut bytes[..ty.size()];
        if !self.fill(value)? {
            return Ok(None);
        }
        if big_endian {
            value.reverse();
        }
        Ok(Some(ty.decode_le(bytes)))
    }

    /// Reads exactly `buf.len()` bytes; `Ok(false)` when the file ends first.
    fn fill(&mut self, buf: &mut [u8]) -> Result<bool> {
        match self.reader.read_exact(buf) {
            Ok(()) => {
                self.offset += buf.len() as u64;
                Ok(true)
            }
            Err(e) if e.kind() == io::ErrorKind::UnexpectedEof => Ok(false),
            Err(e) => Err(Error::io(self.path, e)),
        }
    }

    /// Steps over `n` bytes; `Ok(false)` when the file ends first.
    fn skip(&mut self, n: u64) -> Result<bool> {
        let skipped = io::copy(&mut self.reader.by_ref().take(n), &mut io::sink())
            .map_err(|e| Error::io(self.path, e))?;
        self.offset += skipped;
        Ok(skipped == n)
    }

    /// The next line that is not blank, with its 1-based number; `None` at the end of the file.
    fn next_line(&mut self) -> Result<Option<(usize, &str)>> {
        loop {
            self.text.clear();
            let n = self
                .reader
                .read_until(b'\n', &mut self.text)
                .map_err(|e| Error::io(self.path, e))?;
            if n == 0 {
                return Ok(None);
            }
            self.line += 1;
            self.offset += n as u64;
            if !self.text.iter().all(u8::is_ascii_whitespace) {
                break;
            }
        }
        let line = self.line;
        let text = std::str::from_utf8(&self.text)
            .map_err(|_| Error::parse(self.path, Some(line), "the line is not text (UTF-8)"))?;
        Ok(Some((line, text)))
    }
}

/// Parses one ascii record of `element` from its line, storing each property that `slots` gives
/// a channel into `values`; the error says what is wrong with the line.
fn parse_ascii_record(
    text: &str,
    element: &Element,
    slots: &[Option<usize>],
    values: &mut [f64; CHANNELS.len()],
) -> std::result::Result<(), String> {
    let mut tokens = text.split_whitespace();
    for (property, &slot) in element.properties.iter().zip(slots) {
        let name = property.name.as_str();
        match property.kind {
            Kind::Scalar(ty) => {
                let value = ascii_value(&mut tokens, ty, name)?;
                if let Some(channel) = slot {
                    values[channel] = value;
                }
            }
            Kind::List { count, item } => {
                let n = ascii_value(&mut tokens, count, name)?;
                if n < 0.0 {
                    return Err(format!("the list `{name}` has the negative length {n}"));
                }
                for i in 0..n as u64 {
                    let Some(token) = tokens.next() else {
                        return Err(format!(
                            "the list `{name}` declares {n} items, but the line ends after {i}"
                        ));
                    };
                    if item.parse(token).is_none() {
                        return Err(format!(
                            "`{token}` is not a {} (item {i} of the list `{name}`)",
                            item.name()
                        ));
                    }
                }
            }
        }
    }
    match tokens.next() {
        Some(extra) => Err(format!(
            "`{extra}` is left over after the last property `{}`",
            element.properties.last().map_or("", |p| p.name.as_str())
        )),
        None => Ok(()),
    }
}

/// The next ascii value, of type `ty`, for the property `name`.
fn ascii_value<'a>(
    tokens: &mut impl Iterator<Item = &'a str>,
    ty: Scalar,
    name: &str,
) -> std::result::Result<f64, String> {
    let token = tokens
        .next()
        .ok_or_else(|| format!("the line ends before `{name}`"))?;
    ty.parse(token)
        .ok_or_else(|| format!("`{token}` is not a {} (property `{name}`)", ty.name()))
}

#[cfg(test)]
mod tests {
    use super::super::tests::*;
    use super::Scalar;

    #[test]
    fn ascii_body_errors_name_their_line() {
        let header = format!(
            "element vertex 2\n{XYZ}property list uchar int near\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n"
        );
        // The header ends on line 11; the first vertex is on line 12.
        let cases = [
            (
                "0 0 0 0 1 2 3\n0 x1 0 0 1 2 3\n",
                13,
                "vertex 1: `x1` is not a float (property `y`)",
            ),
            (
                "0 0 0 0 1 2 3\n0 0\n",
                13,
                "vertex 1: the line ends before `z`",
            ),
            (
                "0 0 0 0 1 2 3 4\n",
                12,
                "vertex 0: `4` is left over after the last property `blue`",
            ),
            (
                "0 0 0 0 300 2 3\n",
                12,
                "`300` is not a uchar (property `red`)",
            ),
            (
                "0 0 0 0 1.5 2 3\n",
                12,
                "`1.5` is not a uchar (property `red`)",
            ),
            (
                "0 0 0 2 7\n",
                12,
                "the list `near` declares 2 items, but the line ends after 1",
            ),
            (
                "0 0 0 200 1 2 3\n",
                12,
                "the list `near` declares 200 items, but the line ends after 3",
            ),
            (
                "0 0 0 1 q 1 2 3\n",
                12,
                "`q` is not a int (item 0 of the list `near`)",
            ),
            (
                "0 0 0 -1 1 2 3\n",
                12,
                "`-1` is not a uchar (property `near`)",
            ),
            (
                "0 0 0 0 1 2 3\n\n\n0 0 \u{fffd}\n",
                15,
                "`\u{fffd}` is not a float",
            ),
        ];
        for (body, line, message) in cases {
            let (got_line, got) = parse_error(&ascii(&format!("{header}{body}")));
            assert!(
                got.contains(message) && got_line == Some(line),
                "{body:?}: expected line {line} and {message:?}, got line {got_line:?}: {got:?}"
            );
        }
        let signed =
            format!("element vertex 1\n{XYZ}property list char int near\nend_header\n0 0 0 -2\n");
        let (line, message) = parse_error(&ascii(&signed));
        assert_eq!(line, Some(9));
        assert!(
            message.contains("the list `near` has the negative length -2"),
            "{message}"
        );
        let (line, message) = parse_error(
            &[
                &ascii(&format!("element vertex 1\n{XYZ}end_header\n"))[..],
                b"0 \xff 0\n",
            ]
            .concat(),
        );
        assert_eq!(line, Some(8));
        assert!(message.contains("not text"), "{message}");
    }

    /// Values that are no colour or no 32-bit float are refused at their vertex (and line, in
    /// ascii), where a NaN colour became black and a double beyond f32 became an infinity that
    /// the cloud then refused by point number alone.
    #[test]
    fn values_that_do_not_fit_are_refused_at_their_vertex() {
        let header = format!(
            "element vertex 2\n{XYZ}property float red\nproperty float green\nproperty float blue\nend_header\n"
        );
        // The header ends on line 10.
        for (body, line, message) in [
            (
                "0 0 0 1 1 1\n0 0 0 nan 1 1\n",
                12,
                "vertex 1: a colour is NaN",
            ),
            (
                "0 0 1e300 1 1 1\n0 0 0 1 1 1\n",
                11,
                "vertex 0: its position (0.0, 0.0, 1e300) is not finite in 32-bit floats",
            ),
        ] {
            let e = load(&ascii(&format!("{header}{body}")))
                .unwrap_err()
                .to_string();
            assert!(
                e.contains(&format!(":{line}:")) && e.contains(message),
                "{e}"
            );
        }
        use Scalar::*;
        let doubles = header.replace("float", "double");
        let values = [0.0, 0.0, 0.0, 1.0, f64::NAN, 1.0].map(|v| (Double, v));
        let values: Vec<_> = [(Double, 0.0); 6].into_iter().chain(values).collect();
        for big_endian in [false, true] {
            let e = load(&binary(big_endian, &doubles, &values))
                .unwrap_err()
                .to_string();
            assert!(e.contains("vertex 1: a colour is NaN"), "{e}");
        }
        let values: Vec<_> = [1e300, 0.0, 0.0, 1.0, 1.0, 1.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0]
            .map(|v| (Double, v))
            .into();
        let e = load(&binary(false, &doubles, &values))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("vertex 0: its position (1e300, 0.0, 0.0) is not finite"),
            "{e}"
        );
    }

    #[test]
    fn truncated_bodies_say_how_far_they_got() {
        let text = ascii(&format!(
            "element vertex 3\n{XYZ}end_header\n0 0 0\n1 0 0\n"
        ));
        assert_eq!(
            parse_error(&text),
            (None, "the file ends after 2 of 3 vertices".into())
        );
        let faces_first = ascii(&format!(
            "element face 2\nproperty list uchar int vertex_indices\nelement vertex 3\n{XYZ}end_header\n3 0 1 2\n"
        ));
        assert_eq!(
            parse_error(&faces_first),
            (
                None,
                "the file ends after 1 of 2 `face` records (declared before the vertices)".into()
            )
        );
        for big_endian in [false, true] {
            let full = full_binary(big_endian);
            // The material's byte, the last vertex's confidence and one byte more.
            let (_, message) = parse_error(&full[..full.len() - 6]);
            assert!(
                message
                    .starts_with("the file ends after 2 of 3 vertices: vertex 2's list `samples`"),
                "{message}"
            );
            let header = format!("element edge 5\nproperty int a\nproperty int b\nelement vertex 1\n{XYZ}end_header\n");
            let values = [(Scalar::Int, 0.0); 5];
            let (_, message) = parse_error(&binary(big_endian, &header, &values));
            assert_eq!(
                message,
                "the file ends after 2 of 5 `edge` records (declared before the vertices)"
            );
        }
    }

    #[test]
    fn lying_counts_and_lengths_are_refused_without_allocating_for_them() {
        for big_endian in [false, true] {
            let header = format!("element vertex 4000000000\n{XYZ}end_header\n");
            let values = [(Scalar::Float, 1.0); 3];
            let (_, message) = parse_error(&binary(big_endian, &header, &values));
            assert_eq!(message, "the file ends after 1 of 4000000000 vertices");

            let header =
                format!("element vertex 1\n{XYZ}property list uint double samples\nend_header\n");
            let values = [
                (Scalar::Float, 1.0),
                (Scalar::Float, 1.0),
                (Scalar::Float, 1.0),
                (Scalar::UInt, 4e9),
                (Scalar::Double, 1.0),
            ];
            let bytes = binary(big_endian, &header, &values);
            let (line, message) = parse_error(&bytes);
            assert_eq!(line, None);
            assert!(
                message.starts_with(
                    "the file ends after 0 of 1 vertices: vertex 0's list `samples` (at byte "
                ) && message.ends_with(
                    ") claims 4000000000 items (32000000000 bytes), more than the 8 bytes left"
                ),
                "{message}"
            );

            let header = format!("element vertex 1\n{XYZ}property list int int near\nend_header\n");
            let values = [
                (Scalar::Float, 1.0),
                (Scalar::Float, 1.0),
                (Scalar::Float, 1.0),
                (Scalar::Int, -1.0),
            ];
            let (_, message) = parse_error(&binary(big_endian, &header, &values));
            assert!(
                message.starts_with("vertex 0's list `near` (at byte ")
                    && message.ends_with(") has the negative length -1"),
                "{message}"
            );

            let header = format!(
                "element face 4000000000\nproperty int a\nelement vertex 1\n{XYZ}end_header\n"
            );
            let (_, message) = parse_error(&binary(big_endian, &header, &[(Scalar::Int, 0.0); 7]));
            assert_eq!(
                message,
                "the file ends after 7 of 4000000000 `face` records (declared before the vertices)"
            );
        }
        let text = ascii(&format!(
            "element vertex 18446744073709551615\n{XYZ}end_header\n0 0 0\n"
        ));
        assert_eq!(
            parse_error(&text).1,
            "the file ends after 1 of 18446744073709551615 vertices"
        );
    }
}
