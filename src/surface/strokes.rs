//! The strokes file of `rbvh paint`: brush dabs aimed through the scene's render camera.
//!
//! UTF-8 text, one statement per line; blank lines are skipped, and a `#` at the start of a line
//! or followed by a space starts a comment (one followed by hex digits is a colour):
//!
//! ```text
//! # x y radius colour
//! dab  0.50 0.40 0.02 #ff0000
//! # x0 y0 x1 y1 radius colour
//! line 0.20 0.60 0.80 0.60 0.01 #2060ffcc
//! ```
//!
//! * `x`, `y`: the aim as fractions of the image's width and height, `(0, 0)` its top-left
//!   corner, so that a file does not depend on the resolution it is rendered at (`0..=1`: an aim
//!   off the screen is an error);
//! * `radius`: world-space brush radius as a fraction of the scene's bounding-box diagonal (> 0);
//! * `colour`: `#rrggbb` or `#rrggbbaa`, sRGB-encoded like CSS colours, alpha linear (default
//!   ff): a dab is composited over the texels it covers, in file order ([`rgba::over`]);
//! * `line` places dabs along the segment, one per [`LINE_SPACING`] of the screen (and at both
//!   ends).
//!
//! Every malformation is an [`Error::Parse`] naming the file and line.

use std::path::Path;

use glam::Vec2;

use crate::rgba;
use crate::{Error, Result};

/// Spacing of the dabs of a `line`, as a fraction of the screen.
pub const LINE_SPACING: f32 = 0.004;
/// Most dabs one file may place (20 MiB of dabs): a `line` across the screen places ~350, so
/// without a cap a megabyte of text would ask for gigabytes and minutes of painting.
pub const MAX_DABS: usize = 1 << 20;

/// One brush dab on the screen.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Dab {
    /// Fractions of the image's width and height, from the top-left corner.
    pub screen: Vec2,
    /// Fraction of the scene's bounding-box diagonal.
    pub radius: f32,
    /// Packed RGBA8 ([`crate::rgba`]).
    pub colour: u32,
}

/// Reads and parses the strokes file at `path`.
pub fn load(path: &Path) -> Result<Vec<Dab>> {
    let text = crate::io::input::read_to_string(path)?;
    parse(&text, path)
}

/// Parses strokes text; `path` names the file in errors.
pub fn parse(text: &str, path: &Path) -> Result<Vec<Dab>> {
    let mut dabs = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let err = |message: String| Error::parse(path, Some(n + 1), message);
        let words: Vec<&str> = strip_comment(line).split_whitespace().collect();
        let Some((&keyword, args)) = words.split_first() else {
            continue;
        };
        let (points, rest) = match keyword {
            "dab" => (1, args),
            "line" => (2, args),
            other => {
                return Err(err(format!(
                    "unknown statement {other:?}: expected `dab x y radius colour` or \
                     `line x0 y0 x1 y1 radius colour`"
                )))
            }
        };
        if rest.len() != 2 * points + 2 {
            return Err(err(format!(
                "`{keyword}` takes {} values, got {}",
                2 * points + 2,
                rest.len()
            )));
        }
        let number = |k: usize, what: &str| -> Result<f32> {
            rest[k]
                .parse::<f32>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| err(format!("{what} {:?} is not a finite number", rest[k])))
        };
        let on_screen = |k: usize, what: &str| -> Result<f32> {
            let x = number(k, what)?;
            if (0.0..=1.0).contains(&x) {
                Ok(x)
            } else {
                Err(err(format!(
                    "{what} {x} is off the screen: positions are fractions of the image, 0..1"
                )))
            }
        };
        let mut ends = Vec::new();
        for p in 0..points {
            ends.push(Vec2::new(
                on_screen(2 * p, "x")?,
                on_screen(2 * p + 1, "y")?,
            ));
        }
        let radius = number(2 * points, "radius")?;
        if radius <= 0.0 {
            return Err(err(format!("radius {radius} must be positive")));
        }
        let colour = parse_colour(rest[2 * points + 1]).ok_or_else(|| {
            err(format!(
                "colour {:?} is not #rrggbb or #rrggbbaa",
                rest[2 * points + 1]
            ))
        })?;
        let (a, b) = (ends[0], *ends.last().unwrap_or(&ends[0]));
        // Both ends are on the screen, so a line is at most √2 long: ~354 steps.
        let steps = ((b - a).length() / LINE_SPACING).ceil() as usize;
        if dabs.len() + steps + 1 > MAX_DABS {
            return Err(err(format!(
                "the file would place more than {MAX_DABS} dabs in all"
            )));
        }
        for k in 0..=steps {
            let f = if steps == 0 {
                0.0
            } else {
                k as f32 / steps as f32
            };
            dabs.push(Dab {
                screen: a.lerp(b, f),
                radius,
                colour,
            });
        }
    }
    Ok(dabs)
}

/// `line` without its comment: from a `#` that begins the line's content or is followed by
/// whitespace or the line's end (a `#` followed by anything else begins a colour).
fn strip_comment(line: &str) -> &str {
    let start = line.len() - line.trim_start().len();
    for (i, _) in line.match_indices('#') {
        let next = line[i + 1..].chars().next();
        if i == start || next.is_none_or(char::is_whitespace) {
            return &line[..i];
        }
    }
    line
}

/// `#rrggbb` or `#rrggbbaa` as packed RGBA8.
fn parse_colour(word: &str) -> Option<u32> {
    let hex = word.strip_prefix('#')?;
    if !(hex.len() == 6 || hex.len() == 8) || !hex.chars().all(|c| c.is_ascii_hexdigit()) {
        return None;
    }
    let byte = |k: usize| u8::from_str_radix(hex.get(2 * k..2 * k + 2)?, 16).ok();
    let alpha = if hex.len() == 8 { byte(3)? } else { 255 };
    Some(rgba::from_bytes([byte(0)?, byte(1)?, byte(2)?, alpha]))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dabs_lines_colours_and_comments() {
        let text =
            "# strokes\n\ndab 0.5 0.25 0.02 #ff0000 # red\nline 0 0.5 0.008 0.5 0.01 #00ff0080\n";
        let dabs = parse(text, Path::new("s.txt")).unwrap();
        assert_eq!(dabs.len(), 1 + 3);
        assert_eq!(dabs[0].screen, Vec2::new(0.5, 0.25));
        assert_eq!(dabs[0].colour, 0xFF00_00FF);
        assert_eq!(dabs[1].colour, 0x8000_FF00);
        assert_eq!(dabs[3].screen, Vec2::new(0.008, 0.5));
    }

    #[test]
    fn errors_name_file_and_line() {
        // A diagonal line places 355 dabs: 2953 fit in MAX_DABS, the 2954th does not.
        let long = "line 0 0 1 1 0.1 #ffffff\n".repeat(2954);
        for (text, expect) in [
            ("dab 0.5 0.5 0.1 #ff0000\ndab 0.5 x 0.1 #ff0000", "y \"x\""),
            ("\n\nsplat 1 2", "unknown statement"),
            ("dab 0.5 0.5 0.1", "takes 4 values"),
            ("dab 0.5 0.5 -1 #ffffff", "must be positive"),
            ("dab 0.5 0.5 0.1 #fff", "not #rrggbb"),
            ("line 0 0 1.5 0 0.1 #ffffff", "off the screen"),
            ("dab 0.5 0.5 0.1 #ff0000800", "not #rrggbb"),
            (long.as_str(), "in all"),
        ] {
            let e = parse(text, Path::new("s.txt")).unwrap_err();
            let line = text.lines().count();
            let s = e.to_string();
            assert!(
                s.contains(&format!("s.txt:{line}")) && s.contains(expect),
                "{s}"
            );
        }
    }
}
