//! ꟻLIP (Andersson et al., "FLIP: A Difference Evaluator for Alternating Images", HPG 2020), the
//! one image difference that both `bench` (renders against the exact BVH's) and `regress` (renders
//! against goldens) report, through nv-flip, at its default 67 pixels per degree (a 0.7 m view
//! of a 31.6" 4K monitor).

use crate::{Error, Result};

/// Per-pixel ꟻLIP errors in `[0, 1]`, row by row, of `test` against `reference`: both tightly
/// packed 8-bit sRGB RGB of a `width`×`height` image, as their PNGs hold them. Fails with
/// [`Error::InvalidParameter`] for an empty image or a byte count that is not three per pixel.
pub fn errors(width: u32, height: u32, reference: &[u8], test: &[u8]) -> Result<Vec<f32>> {
    let bytes = 3 * width as usize * height as usize;
    if bytes == 0 || reference.len() != bytes || test.len() != bytes {
        return Err(Error::param(
            "image",
            format!(
                "ꟻLIP of a {width}×{height} image needs {bytes} RGB bytes in each, got {} and {}",
                reference.len(),
                test.len()
            ),
        ));
    }
    Ok(nv_flip::flip(
        nv_flip::FlipImageRgb8::with_data(width, height, reference),
        nv_flip::FlipImageRgb8::with_data(width, height, test),
        nv_flip::DEFAULT_PIXELS_PER_DEGREE,
    )
    .to_vec())
}

/// The mean of per-pixel errors (0 for none).
pub fn mean(errors: &[f32]) -> f64 {
    errors.iter().map(|&e| f64::from(e)).sum::<f64>() / errors.len().max(1) as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn identical_images_score_zero_and_a_wrong_size_is_an_error() {
        let image = [10u8, 200, 30].repeat(16);
        let e = errors(4, 4, &image, &image).unwrap();
        assert_eq!(e.len(), 16);
        assert_eq!(mean(&e), 0.0);
        let mut changed = image.clone();
        changed[0] = 250;
        assert!(mean(&errors(4, 4, &image, &changed).unwrap()) > 0.0);
        assert!(errors(4, 4, &image, &image[3..]).is_err());
        assert!(errors(0, 4, &[], &[]).is_err());
    }
}
