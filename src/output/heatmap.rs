//! False-colour pictures of per-pixel counts (traversal steps, leaf visits, ...), for debugging
//! where the work goes.

use glam::Vec3;
use rayon::prelude::*;

use super::image::{check_per_pixel, Image};
use super::srgb;

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
}
