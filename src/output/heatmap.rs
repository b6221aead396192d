//! False-colour pictures of per-pixel counts (traversal steps, leaf visits, ...), for debugging
//! where the work goes.

use glam::Vec3;
use rayon::prelude::*;

use super::image::{check_per_pixel, Image};
use crate::srgb;

/// Maps each of `values` (one per pixel, row-major, top row first) to the Turbo colour map,
/// 0 at the dark blue end and `max` or more at the dark red end. `max` defaults to the largest
/// value, so one picture uses the whole map; pass the same `max` to several pictures to make
/// their colours comparable. A `max` of 0 is treated as 1.
///
/// Turbo is used because, unlike the classic rainbow map, it is smooth and monotonic enough in
/// lightness that steps in the picture are steps in the data, while its many hues still make
/// small differences in counts visible.
pub fn heatmap(values: &[u32], width: u32, height: u32, max: Option<u32>) -> crate::Result<Image> {
    check_per_pixel("values", values.len(), width, height)?;
    let max = max
        .unwrap_or_else(|| values.iter().copied().max().unwrap_or(0))
        .max(1);
    let scale = 1.0 / f64::from(max);
    let pixels = values
        .par_iter()
        .map(|&v| turbo((f64::from(v) * scale).min(1.0)))
        .collect();
    Ok(Image {
        width,
        height,
        pixels,
    })
}

/// `map` (a [`heatmap`] scaled to `max`) with a colour bar below it: the Turbo map from 0 at the
/// left to `max` at the right, labelled with both numbers, so that a picture says its own scale
/// and two pictures made with the same `max` can be compared by eye. The bar is as wide as the
/// picture; the digits are drawn from a built-in 3 × 5 pixel font at twice that size, so nothing
/// depends on fonts being installed.
pub fn with_colour_bar(map: &Image, max: u32) -> Image {
    const GAP: u32 = 3;
    const BAR: u32 = 10;
    const SCALE: u32 = 2;
    const LABEL: u32 = 5 * SCALE;
    let extra = GAP + BAR + GAP + LABEL + GAP;
    let (width, height) = (map.width, map.height + extra);
    let mut pixels = map.pixels.clone();
    pixels.resize(width as usize * height as usize, Vec3::ZERO);
    let row = |y: u32| y as usize * width as usize;
    for x in 0..width {
        let colour = turbo(f64::from(x) / f64::from(width.saturating_sub(1).max(1)));
        for y in map.height + GAP..map.height + GAP + BAR {
            pixels[row(y) + x as usize] = colour;
        }
    }
    let top = map.height + GAP + BAR + GAP;
    let mut text = |label: &str, right_aligned: bool| {
        let text_width = label.len() as u32 * 4 * SCALE;
        let left = if right_aligned {
            width.saturating_sub(text_width)
        } else {
            0
        };
        for (k, digit) in label.bytes().enumerate() {
            let glyph = DIGITS[usize::from(digit - b'0')];
            for (gy, bits) in glyph.iter().enumerate() {
                for gx in 0..3u32 {
                    if bits >> (2 - gx) & 1 == 0 {
                        continue;
                    }
                    for (dx, dy) in (0..SCALE).flat_map(|dx| (0..SCALE).map(move |dy| (dx, dy))) {
                        let x = left + (k as u32 * 4 + gx) * SCALE + dx;
                        let y = top + gy as u32 * SCALE + dy;
                        if x < width {
                            pixels[row(y) + x as usize] = Vec3::ONE;
                        }
                    }
                }
            }
        }
    };
    text("0", false);
    text(&max.max(1).to_string(), true);
    Image {
        width,
        height,
        pixels,
    }
}

/// Digits 0-9 in a 3 × 5 pixel font: one row per entry, the high bit of three on the left.
const DIGITS: [[u8; 5]; 10] = [
    [0b111, 0b101, 0b101, 0b101, 0b111],
    [0b010, 0b110, 0b010, 0b010, 0b111],
    [0b111, 0b001, 0b111, 0b100, 0b111],
    [0b111, 0b001, 0b111, 0b001, 0b111],
    [0b101, 0b101, 0b111, 0b001, 0b001],
    [0b111, 0b100, 0b111, 0b001, 0b111],
    [0b111, 0b100, 0b111, 0b101, 0b111],
    [0b111, 0b001, 0b001, 0b001, 0b001],
    [0b111, 0b101, 0b111, 0b101, 0b111],
    [0b111, 0b101, 0b111, 0b001, 0b111],
];

/// The Turbo colour map at `x ∈ [0, 1]`, as linear RGB.
///
/// Turbo was designed by Anton Mikhailov (Google AI blog, "Turbo, An Improved Rainbow Colormap
/// for Visualization", 2019); this is Ruofei Du's published polynomial approximation of it
/// (<https://gist.github.com/mikhailov-work/0d177465a8151eb6ede1768d51d476c7>, Apache-2.0),
/// a degree-5 polynomial per channel, close to the original table except at the very ends.
/// The polynomial yields sRGB-encoded values, so they are decoded to linear here and re-encoded
/// by the PNG writer.
fn turbo(x: f64) -> Vec3 {
    const RED: [f64; 6] = [
        0.13572138,
        4.61539260,
        -42.66032258,
        132.13108234,
        -152.94239396,
        59.28637943,
    ];
    const GREEN: [f64; 6] = [
        0.09140261,
        2.19418839,
        4.84296658,
        -14.18503333,
        4.27729857,
        2.82956604,
    ];
    const BLUE: [f64; 6] = [
        0.10667330,
        12.64194608,
        -60.58204836,
        110.36276771,
        -89.90310912,
        27.34824973,
    ];
    let x = x.clamp(0.0, 1.0);
    let poly = |c: &[f64; 6]| c.iter().rev().fold(0.0, |acc, &k| acc * x + k) as f32;
    Vec3::new(
        srgb::decode(poly(&RED)),
        srgb::decode(poly(&GREEN)),
        srgb::decode(poly(&BLUE)),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn runs_from_dark_through_blue_green_and_red() {
        assert!(turbo(0.0).max_element() < 0.05, "{}", turbo(0.0));
        let [r, g, b] = turbo(0.1).to_array();
        assert!(b > r && b > g, "{r} {g} {b}");
        let [r, g, b] = turbo(0.5).to_array();
        assert!(g > r && g > b, "{r} {g} {b}");
        let [r, g, b] = turbo(0.9).to_array();
        assert!(r > g && r > b, "{r} {g} {b}");
    }

    #[test]
    fn normalises_to_the_data_max() {
        let img = heatmap(&[0, 5, 10, 20], 2, 2, None).unwrap();
        assert_eq!(img.pixels[0], turbo(0.0));
        assert_eq!(img.pixels[2], turbo(0.5));
        assert_eq!(img.pixels[3], turbo(1.0));
        let capped = heatmap(&[0, 5, 10, 20], 2, 2, Some(10)).unwrap();
        assert_eq!(capped.pixels[2], capped.pixels[3]);
        assert!(heatmap(&[1, 2, 3], 2, 2, None).is_err());
    }

    #[test]
    fn the_colour_bar_runs_the_map_and_is_labelled_with_its_ends() {
        let map = heatmap(&[0; 64 * 4], 64, 4, Some(250)).unwrap();
        let barred = with_colour_bar(&map, 250);
        assert_eq!(barred.width, 64);
        assert!(barred.height > map.height + 20);
        // The picture is unchanged on top.
        assert_eq!(&barred.pixels[..map.pixels.len()], &map.pixels[..]);
        // The bar: Turbo's dark blue at the left end, dark red at the right.
        let bar_row = (map.height + 5) as usize * 64;
        assert_eq!(barred.pixels[bar_row], turbo(0.0));
        assert_eq!(barred.pixels[bar_row + 63], turbo(1.0));
        // Labels: "0" at the left, "250" (three digits, 8 pixels each) at the right, in white.
        let label_rows = &barred.pixels[(map.height + 16) as usize * 64..];
        let white_columns = |range: std::ops::Range<usize>| {
            range
                .filter(|&x| label_rows.chunks(64).any(|row| row[x] == Vec3::ONE))
                .count()
        };
        assert!(white_columns(0..8) > 0);
        assert_eq!(white_columns(8..40), 0);
        assert!(white_columns(40..64) >= 3 * 4);
    }
}
