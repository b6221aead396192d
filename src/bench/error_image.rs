//! Where a method is wrong, as a picture: per pixel, the primary hit's distance error against the
//! exact BVH, to look at beside the exact render.
//!
//! Colours: pixels both miss are white (background); pixels one side hits and the other misses
//! are magenta, a colour the error map never takes; pixels both hit show `|t − t_exact| / diagonal`
//! in the Turbo map of [`crate::output::heatmap`] on a logarithmic scale: [`LOW`] (10⁻⁵ of the
//! diagonal) or less is the dark end, [`FULL_SCALE`] (10⁻²) or more the dark red end, and each
//! decade between takes a third of the map. Logarithmic, because the errors worth seeing span
//! decades — sub-texel noise on smooth surfaces, texel-sized steps at silhouettes — and a linear
//! map would show only the largest. The scale is fixed rather than fitted to each image, so the
//! pictures of different levels and scenes compare colour for colour.

use glam::Vec3;

use super::validate::MAX_T_ERR_P99;
use crate::geom::{Hit, Ray};
use crate::output::{heatmap, Image};
use crate::Result;

/// The relative distance error shown as the end of the map: the validator's p99 limit, so red
/// means "as far off as a valid method may be for its worst 1% of rays".
pub const FULL_SCALE: f64 = MAX_T_ERR_P99;

/// The relative distance error shown as the start of the map: far below a texel even at Q4
/// (about 1/1024 of the diagonal), so the dark end means "no visible error".
pub const LOW: f64 = 1.0e-5;

/// Steps of the quantized error handed to the heat map: finer than 8-bit colour can show.
const STEPS: u32 = 1024;

const BACKGROUND: Vec3 = Vec3::ONE;
const MISMATCH: Vec3 = Vec3::new(1.0, 0.0, 1.0);

/// The error image of `test` against `exact`, both hits of the primary `rays` of a `width` ×
/// `height` image; `diagonal` is the scene's bounding-box diagonal.
pub fn error_image(
    rays: &[Ray],
    exact: &[Hit],
    test: &[Hit],
    diagonal: f32,
    width: u32,
    height: u32,
) -> Result<Image> {
    super::metrics::check_lengths(rays, exact, test)?;
    let steps: Vec<u32> = rays
        .iter()
        .zip(exact.iter().zip(test))
        .map(|(ray, (e, h))| {
            if !(e.is_hit() && h.is_hit()) {
                return 0;
            }
            let relative = f64::from((h.t - e.t).abs() * ray.dir().length()) / f64::from(diagonal);
            // NaN (a broken hit) saturates like a large error; zero is below LOW.
            let fraction = if relative.is_nan() {
                1.0
            } else {
                ((relative / LOW).log10() / (FULL_SCALE / LOW).log10()).clamp(0.0, 1.0)
            };
            (fraction * f64::from(STEPS)).round() as u32
        })
        .collect();
    let mut image = heatmap(&steps, width, height, Some(STEPS))?;
    for ((pixel, e), h) in image.pixels.iter_mut().zip(exact).zip(test) {
        match (e.is_hit(), h.is_hit()) {
            (false, false) => *pixel = BACKGROUND,
            (true, false) | (false, true) => *pixel = MISMATCH,
            (true, true) => {}
        }
    }
    Ok(image)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn background_mismatch_and_saturated_error_are_distinct() {
        let ray = Ray::new(Vec3::ZERO, Vec3::Z, 0.0, f32::INFINITY);
        let at = |t: f32| Hit {
            t,
            normal: [0.0, 0.0, 1.0],
            id: 0,
            ..Hit::MISS
        };
        let exact = [Hit::MISS, at(1.0), at(1.0), at(1.0)];
        let test = [Hit::MISS, Hit::MISS, at(1.0), at(2.0)];
        let img = error_image(&[ray; 4], &exact, &test, 1.0, 2, 2).unwrap();
        assert_eq!(img.pixels[0], BACKGROUND);
        assert_eq!(img.pixels[1], MISMATCH);
        assert!(img.pixels[2].max_element() < 0.05, "no error is dark");
        assert!(img.pixels[3].x > img.pixels[3].z, "a large error is red");
        assert!(error_image(&[ray; 3], &exact, &test, 1.0, 2, 2).is_err());
    }
}
