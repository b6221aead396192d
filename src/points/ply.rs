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

use std::fs::File;
use std::io::{self, BufRead, BufReader, Read};
use std::path::Path;

use glam::Vec3;

use super::RawPoints;
use crate::{Error, Result};

/// The vertex properties that are read, in the order of a record's channels.
const CHANNELS: [&str; 10] = [
    "x", "y", "z", "nx", "ny", "nz", "red", "green", "blue", "alpha",
];
/// First channel of the normal.
const NORMAL: usize = 3;
/// First channel of the colour (red, green, blue, alpha).
const COLOUR: usize = 6;

/// Longest header line accepted. Real header lines are short; the limit keeps a binary file that
/// happens to begin with `ply` from being read whole in search of a line's end.
const MAX_HEADER_LINE: u64 = 64 * 1024;

/// Vertices to reserve room for up front when the file's length is unknown (not a regular file),
/// and a lying count therefore cannot be caught before reading.
const UNKNOWN_LENGTH_CAPACITY: u64 = 1 << 16;

/// Reads the vertices of the PLY file at `path`.
pub(super) fn read(path: &Path) -> Result<RawPoints> {
    let file = File::open(path).map_err(|e| Error::io(path, e))?;
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

/// How the records are encoded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Format {
    /// Text, one record per line.
    Ascii,
    /// Packed values, least or most significant byte first.
    Binary { big_endian: bool },
}

/// PLY's scalar types.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Scalar {
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
    fn from_name(name: &str) -> Option<Scalar> {
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

    fn name(self) -> &'static str {
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
    fn size(self) -> usize {
        match self {
            Scalar::Char | Scalar::UChar => 1,
            Scalar::Short | Scalar::UShort => 2,
            Scalar::Int | Scalar::UInt | Scalar::Float => 4,
            Scalar::Double => 8,
        }
    }

    /// The range of an integer type; `None` for the floating-point ones.
    fn integer_range(self) -> Option<(i64, i64)> {
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
    fn decode_le(self, b: [u8; 8]) -> f64 {
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
    fn parse(self, token: &str) -> Option<f64> {
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
enum Kind {
    Scalar(Scalar),
    /// A length of type `count`, then that many values of type `item`.
    List {
        count: Scalar,
        item: Scalar,
    },
}

impl Kind {
    /// Fewest bytes the property takes in a binary record (an empty list takes its length).
    fn min_bytes(self) -> u64 {
        match self {
            Kind::Scalar(s) | Kind::List { count: s, .. } => s.size() as u64,
        }
    }
}

#[derive(Debug)]
struct Property {
    name: String,
    kind: Kind,
}

#[derive(Debug)]
struct Element {
    name: String,
    count: u64,
    properties: Vec<Property>,
    /// The header line that declares it, for errors about its properties.
    line: usize,
}

#[derive(Debug)]
struct Header {
    format: Format,
    elements: Vec<Element>,
    /// Lines in the header, `end_header`'s included.
    lines: usize,
    /// Bytes in the header: where the body begins.
    bytes: u64,
}

/// Reads the header, up to and including the `end_header` line.
fn read_header(path: &Path, reader: &mut impl BufRead) -> Result<Header> {
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

/// Where the vertex element's properties go.
#[derive(Debug)]
struct Layout {
    /// Per property, the channel it fills, or `None` when it is stepped over.
    slots: Vec<Option<usize>>,
    normals: bool,
    /// The types of red, green, blue and (when given) alpha, when the vertices have colours.
    colours: Option<[Option<Scalar>; 4]>,
}

impl Layout {
    /// The layout of `vertices`, or why its properties cannot be read as points.
    fn new(vertices: &Element) -> std::result::Result<Layout, String> {
        let mut types = [None; CHANNELS.len()];
        let mut slots = Vec::with_capacity(vertices.properties.len());
        for property in &vertices.properties {
            let channel = CHANNELS.iter().position(|&c| c == property.name);
            if let Some(channel) = channel {
                let Kind::Scalar(scalar) = property.kind else {
                    return Err(format!(
                        "the vertex property `{}` is a list; it must be a single number",
                        property.name
                    ));
                };
                types[channel] = Some(scalar);
            }
            slots.push(channel);
        }
        let [x, y, z, nx, ny, nz, red, green, blue, alpha] = types;
        for (name, ty) in [("x", x), ("y", y), ("z", z)] {
            if ty.is_none() {
                return Err(format!("the vertex element has no `{name}` property"));
            }
        }
        let complete = |set: [Option<Scalar>; 3], names: &str| match set.iter().flatten().count() {
            0 => Ok(false),
            3 => Ok(true),
            _ => Err(format!(
                "the vertex element has only some of `{names}`: give all three or none"
            )),
        };
        let normals = complete([nx, ny, nz], "nx ny nz")?;
        let has_colours = complete([red, green, blue], "red green blue")?;
        if alpha.is_some() && !has_colours {
            return Err("the vertex element has `alpha` but no `red green blue`".into());
        }
        for (name, ty) in [
            ("red", red),
            ("green", green),
            ("blue", blue),
            ("alpha", alpha),
        ] {
            if let Some(ty) =
                ty.filter(|&t| !matches!(t, Scalar::UChar | Scalar::Float | Scalar::Double))
            {
                return Err(format!(
                    "the vertex colour `{name}` is {}: colours must be uchar (0–255) or float/double (0–1)",
                    ty.name()
                ));
            }
        }
        Ok(Layout {
            slots,
            normals,
            colours: has_colours.then_some([red, green, blue, alpha]),
        })
    }
}

/// A colour channel's byte: a `uchar` as it is, a `float`/`double` from 0–1.
fn colour_byte(value: f64, ty: Scalar) -> u8 {
    match ty {
        Scalar::UChar => value as u8,
        _ => (value.clamp(0.0, 1.0) * 255.0).round() as u8,
    }
}

/// The records after the header, read in order.
struct Body<'a, R> {
    path: &'a Path,
    reader: R,
    format: Format,
    /// Lines read so far, the header's included (ascii).
    line: usize,
    /// Bytes read so far, the header's included.
    offset: u64,
    /// The file's length, when known.
    len: Option<u64>,
    /// The current ascii line.
    text: Vec<u8>,
}

impl<R: BufRead> Body<'_, R> {
    /// Steps over all of `element`'s records.
    fn skip_element(&mut self, element: &Element) -> Result<()> {
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
    fn read_vertices(&mut self, vertices: &Element, layout: &Layout) -> Result<RawPoints> {
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
            let v = |channel: usize| values[channel] as f32;
            positions.push(Vec3::new(v(0), v(1), v(2)));
            if let Some(normals) = &mut normals {
                normals.push(Vec3::new(v(NORMAL), v(NORMAL + 1), v(NORMAL + 2)));
            }
            if let Some((types, colours)) = &mut colours {
                let byte =
                    |i: usize| types[i].map_or(u8::MAX, |ty| colour_byte(values[COLOUR + i], ty));
                colours.push(u32::from_le_bytes([byte(0), byte(1), byte(2), byte(3)]));
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
    use super::*;

    const PATH: &str = "cloud.ply";

    fn load(bytes: &[u8]) -> Result<RawPoints> {
        read_from(Path::new(PATH), bytes, Some(bytes.len() as u64))
    }

    /// The line and message of the parse error that `bytes` must give.
    fn parse_error(bytes: &[u8]) -> (Option<usize>, String) {
        super::super::parse_error_of(load(bytes), PATH)
    }

    fn ascii(rest: &str) -> Vec<u8> {
        format!("ply\nformat ascii 1.0\n{rest}").into_bytes()
    }

    /// `v` as a value of type `ty`, least significant byte first unless `big_endian`.
    fn encode(ty: Scalar, v: f64, big_endian: bool) -> Vec<u8> {
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
    fn binary(big_endian: bool, header: &str, values: &[(Scalar, f64)]) -> Vec<u8> {
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

    const XYZ: &str = "property float x\nproperty float y\nproperty float z\n";

    fn positions(points: &[[f32; 3]]) -> Vec<Vec3> {
        points.iter().map(|&p| Vec3::from(p)).collect()
    }

    fn rgba(r: u8, g: u8, b: u8, a: u8) -> u32 {
        u32::from_le_bytes([r, g, b, a])
    }

    /// Three vertices with everything: a face element before them, a list and extra scalars among
    /// their properties, and elements after them.
    const FULL_HEADER: &str = "comment made by a test\n\
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

    const FULL_POSITIONS: [[f32; 3]; 3] = [[1.0, 2.0, 3.0], [-4.5, 0.25, 1e6], [0.0, 0.0, -7.0]];
    const FULL_NORMALS: [[f32; 3]; 3] = [[0.0, 0.0, 1.0], [0.6, 0.8, 0.0], [-1.0, 0.0, 0.0]];
    const FULL_COLOURS: [[u8; 4]; 3] = [[255, 0, 0, 255], [1, 2, 3, 4], [200, 100, 50, 0]];

    /// [`FULL_HEADER`]'s body.
    fn full_values() -> Vec<(Scalar, f64)> {
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

    fn full_binary(big_endian: bool) -> Vec<u8> {
        binary(big_endian, FULL_HEADER, &full_values())
    }

    fn full_points() -> RawPoints {
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

    const FULL_ASCII: &str = "comment made by a test\n\
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
