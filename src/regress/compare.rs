//! How a render is judged against its golden: ꟻLIP (Andersson et al. 2020, via `nv-flip`) on the
//! shaded image — its mean, and the share of pixels it finds clearly different — and the relative
//! error of the hit distances. Each comparison also yields a per-pixel error picture, written only
//! for failures.

use crate::flip;
use crate::output::{heatmap, Image};
use crate::{Error, Result};

use super::golden::{Depth, Rgb8};

/// Pass/fail limits of a comparison.
///
/// The defaults ([`Tolerance::default`]) were measured, not guessed. Renders are deterministic, so
/// on the device that blessed the goldens every score is exactly 0; the limits are there for other
/// drivers and CPUs, whose rounding may differ. That was modelled by moving the camera by 1e-5 and
/// 1e-4 of its distance — 10 to 100 times more than a rounding difference moves a ray — and the
/// shipped suite then scored at most: ꟻLIP mean 0.00019 / 0.00055, 9 / 9 pixels over ꟻLIP 0.1,
/// 0.016% of pixels off in depth at 1e-5 (every pixel at 1e-4, which moves every distance by 1e-4:
/// a real change of camera, rightly caught). Deliberately broken RBVH shaders (one corner's height
/// decoded ×0.5 or ×0.99, all heights ×1.01, the first row and column of every tile dropped,
/// normal components swapped) failed every RBVH case, mostly on both checks: ꟻLIP means of 0.0011
/// to 0.035 and 15 to 3000 pixels over 0.1, or 0.2% to 18% of pixels off in depth. A height one
/// 16-bit code off (invisible) passes. Each limit sits between the two with a margin of about 2×
/// on the noise side.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tolerance {
    /// Most mean ꟻLIP error over the image. Default 0.001: twice the worst camera-shift noise;
    /// the broken shaders above measured 0.0011 and more.
    pub flip_mean: f64,
    /// A pixel whose ꟻLIP error exceeds this is an outlier. Default 0.1, not the "clearly
    /// different" 0.5 ꟻLIP's authors use for photographs: these previews are smooth grey shapes on
    /// a smooth sky, where no geometric break measured reached 0.5 on even one pixel, while 0.1
    /// separates them (15+ pixels) from noise (≤ 9, a silhouette pixel flipping between surface and
    /// sky, spread by ꟻLIP's filters).
    pub outlier_flip: f32,
    /// Most share of outlier pixels. Default 0.001 (19 of 160 × 120 pixels): room for two such
    /// silhouette flips, since another device may round a grazing ray differently, and not for a
    /// change to leaves, shaders or camera, which moves whole edges.
    pub outlier_fraction: f64,
    /// A pixel's depth is off when its relative hit-distance error exceeds this, or when it hits
    /// in one image and misses in the other. Default 1e-4: hundreds of float roundings, and at the
    /// framing camera's distance (1.5 diagonals) a seventh of a Q4 texel (1/1024 of the diagonal).
    pub depth_relative: f64,
    /// Most share of pixels whose depth is off. Default 0.001: six times the camera-shift noise,
    /// half the smallest break measured (the dropped tile edges, hidden in the image by the
    /// neighbours' dilated rims).
    pub depth_outlier_fraction: f64,
}

impl Default for Tolerance {
    fn default() -> Self {
        Tolerance {
            flip_mean: 0.001,
            outlier_flip: 0.1,
            outlier_fraction: 0.001,
            depth_relative: 1e-4,
            depth_outlier_fraction: 0.001,
        }
    }
}

impl Tolerance {
    /// Checks that every limit is a number in its range, naming the first that is not.
    pub fn validate(&self) -> Result<()> {
        let fractions = [
            ("flip_mean", self.flip_mean),
            ("outlier_flip", f64::from(self.outlier_flip)),
            ("outlier_fraction", self.outlier_fraction),
            ("depth_outlier_fraction", self.depth_outlier_fraction),
        ];
        for (name, value) in fractions {
            if !(0.0..=1.0).contains(&value) {
                return Err(Error::param(name, format!("{value} is outside 0..=1")));
            }
        }
        if !(self.depth_relative.is_finite() && self.depth_relative >= 0.0) {
            return Err(Error::param(
                "depth_relative",
                format!("{} is not a finite number ≥ 0", self.depth_relative),
            ));
        }
        Ok(())
    }
}

/// How far a shaded render is from its golden.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImageScore {
    /// Mean of ꟻLIP's per-pixel error, in [0, 1].
    pub flip_mean: f64,
    /// Share of pixels whose ꟻLIP error exceeds [`Tolerance::outlier_flip`].
    pub outlier_fraction: f64,
}

impl ImageScore {
    /// Within both image limits: `flip_mean` and `outlier_fraction` at most `tol`'s.
    pub fn passes(&self, tol: &Tolerance) -> bool {
        self.flip_mean <= tol.flip_mean && self.outlier_fraction <= tol.outlier_fraction
    }
}

/// ꟻLIP's per-pixel error of a render against its golden.
#[derive(Debug)]
pub struct FlipMap {
    width: u32,
    height: u32,
    errors: Vec<f32>,
}

/// Colour steps of the error pictures: finer than 8-bit colour can show.
const STEPS: u32 = 1000;

impl FlipMap {
    /// The error map in the Turbo colours of [`crate::output::heatmap`] on a fixed scale: dark
    /// blue is no difference, dark red is ꟻLIP error 1, so pictures of different cases compare.
    pub fn picture(&self) -> Result<Image> {
        let values: Vec<u32> = self
            .errors
            .iter()
            .map(|&e| (e.clamp(0.0, 1.0) * STEPS as f32).round() as u32)
            .collect();
        heatmap(&values, self.width, self.height, Some(STEPS))
    }
}

/// Compares `render` with `golden` by ꟻLIP at its default 67 pixels per degree (a 0.7 m view of a
/// 31.6" 4K monitor): both as the sRGB bytes their PNGs hold. Images of different sizes are an
/// error saying which is which.
pub fn compare_images(
    golden: &Rgb8,
    render: &Rgb8,
    tol: &Tolerance,
) -> Result<(ImageScore, FlipMap)> {
    check_sizes((golden.width, golden.height), (render.width, render.height))?;
    let pixels = golden.width as usize * golden.height as usize;
    if golden.bytes.len() != 3 * pixels || render.bytes.len() != 3 * pixels {
        return Err(Error::param(
            "image",
            format!(
                "{} and {} bytes for {pixels} RGB pixels",
                golden.bytes.len(),
                render.bytes.len()
            ),
        ));
    }
    let errors = flip::errors(golden.width, golden.height, &golden.bytes, &render.bytes)?;
    let n = errors.len().max(1) as f64;
    let flip_mean = flip::mean(&errors);
    let outliers = errors.iter().filter(|&&e| e > tol.outlier_flip).count();
    let score = ImageScore {
        flip_mean,
        outlier_fraction: outliers as f64 / n,
    };
    let map = FlipMap {
        width: golden.width,
        height: golden.height,
        errors,
    };
    Ok((score, map))
}

/// How far a render's hit distances are from the golden's.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DepthScore {
    /// Share of pixels whose depth is off (see [`Tolerance::depth_relative`]).
    pub off_fraction: f64,
    /// Pixels that hit in one image and miss in the other (counted in `off_fraction` too).
    pub hit_mismatches: usize,
    /// Largest relative distance error over the pixels both images hit.
    pub max_relative: f64,
}

impl DepthScore {
    /// Within the depth limit: `off_fraction` at most [`Tolerance::depth_outlier_fraction`]
    /// (`max_relative` is shown, not judged).
    pub fn passes(&self, tol: &Tolerance) -> bool {
        self.off_fraction <= tol.depth_outlier_fraction
    }
}

/// Per pixel, the relative depth error of a render against its golden: 0 where both miss, +inf
/// where only one hits.
#[derive(Debug)]
pub struct DepthMap {
    width: u32,
    height: u32,
    relative: Vec<f64>,
    tolerance: f64,
}

impl DepthMap {
    /// The error map in Turbo colours on a logarithmic scale around the tolerance: a tenth of it or
    /// less is dark blue, the tolerance itself is the middle (green), ten times it or more — and a
    /// hit against a miss — dark red. Logarithmic, because depth errors span decades, from float
    /// rounding to whole surfaces moved.
    pub fn picture(&self) -> Result<Image> {
        let floor = (self.tolerance / 10.0).max(f64::MIN_POSITIVE);
        let values: Vec<u32> = self
            .relative
            .iter()
            .map(|&r| {
                let fraction = if r <= floor {
                    0.0
                } else {
                    ((r / floor).log10() / 2.0).min(1.0)
                };
                (fraction * f64::from(STEPS)).round() as u32
            })
            .collect();
        heatmap(&values, self.width, self.height, Some(STEPS))
    }
}

/// Compares hit distances pixel by pixel: relative error `|z − z_golden| / z_golden` where both
/// hit (absolute where the golden distance is 0), and a hit against a miss is always off.
pub fn compare_depth(
    golden: &Depth,
    render: &Depth,
    tol: &Tolerance,
) -> Result<(DepthScore, DepthMap)> {
    check_sizes((golden.width, golden.height), (render.width, render.height))?;
    if golden.z.len() != render.z.len() {
        return Err(Error::param(
            "depth",
            format!("{} and {} samples", golden.z.len(), render.z.len()),
        ));
    }
    // NaN is neither a hit nor a miss a tracer may return; count it as off.
    let relative: Vec<f64> = golden
        .z
        .iter()
        .zip(&render.z)
        .map(|(&g, &r)| {
            let (g, r) = (f64::from(g), f64::from(r));
            match (g.is_finite(), r.is_finite()) {
                (false, false) if g == r => 0.0,
                (true, true) => (r - g).abs() / if g.abs() > 0.0 { g.abs() } else { 1.0 },
                _ => f64::INFINITY,
            }
        })
        .collect();
    let off = relative.iter().filter(|&&r| r > tol.depth_relative).count();
    let score = DepthScore {
        off_fraction: off as f64 / relative.len().max(1) as f64,
        hit_mismatches: relative.iter().filter(|r| r.is_infinite()).count(),
        max_relative: relative
            .iter()
            .copied()
            .filter(|r| r.is_finite())
            .fold(0.0, f64::max),
    };
    let map = DepthMap {
        width: golden.width,
        height: golden.height,
        relative,
        tolerance: tol.depth_relative,
    };
    Ok((score, map))
}

/// An error when a golden and a render differ in size: compared pixel by pixel they would mean
/// nothing, and the usual cause is a `--width`/`--height` other than the goldens were blessed at.
fn check_sizes(golden: (u32, u32), render: (u32, u32)) -> Result<()> {
    if golden == render {
        return Ok(());
    }
    Err(Error::param(
        "size",
        format!(
            "the golden is {}×{} but the render is {}×{}; render at the golden's size (--width/--height) or re-bless",
            golden.0, golden.1, render.0, render.1
        ),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grey(width: u32, height: u32, level: u8) -> Rgb8 {
        Rgb8 {
            width,
            height,
            bytes: vec![level; (3 * width * height) as usize],
        }
    }

    #[test]
    fn identical_images_score_zero_and_a_changed_block_is_outliers() {
        let tol = Tolerance::default();
        let a = grey(32, 32, 128);
        let (score, map) = compare_images(&a, &a, &tol).unwrap();
        assert_eq!(score.flip_mean, 0.0);
        assert_eq!(score.outlier_fraction, 0.0);
        assert!(score.passes(&tol));
        assert_eq!(map.picture().unwrap().pixels.len(), 32 * 32);

        let mut b = a.clone();
        for y in 8..16 {
            for x in 0..32 {
                let i = 3 * (y * 32 + x);
                b.bytes[i..i + 3].fill(255);
            }
        }
        let (score, _) = compare_images(&a, &b, &tol).unwrap();
        assert!(score.outlier_fraction > 0.2, "{score:?}");
        assert!(!score.passes(&tol));

        let err = compare_images(&a, &grey(16, 32, 128), &tol).unwrap_err();
        assert!(err.to_string().contains("32×32"), "{err}");
    }

    #[test]
    fn depth_counts_relative_errors_and_hit_miss_mismatches() {
        let tol = Tolerance::default();
        let inf = f32::INFINITY;
        let golden = Depth {
            width: 5,
            height: 1,
            z: vec![inf, 2.0, 2.0, 4.0, inf],
        };
        let render = Depth {
            width: 5,
            height: 1,
            z: vec![inf, 2.0, 2.0 * (1.0 + 5e-5), 4.4, 1.0],
        };
        let (score, map) = compare_depth(&golden, &render, &tol).unwrap();
        assert_eq!(score.hit_mismatches, 1);
        assert_eq!(score.off_fraction, 2.0 / 5.0);
        assert!((score.max_relative - 0.1).abs() < 1e-6, "{score:?}");
        assert!(!score.passes(&tol));
        let picture = map.picture().unwrap();
        assert_eq!(
            picture.pixels[0], picture.pixels[1],
            "no error is one colour"
        );
        assert_eq!(
            picture.pixels[3], picture.pixels[4],
            "10× off saturates like a mismatch"
        );
    }

    #[test]
    fn tolerances_out_of_range_are_named() {
        let bad = Tolerance {
            outlier_fraction: 1.5,
            ..Tolerance::default()
        };
        assert!(bad
            .validate()
            .unwrap_err()
            .to_string()
            .contains("outlier_fraction"));
        Tolerance::default().validate().unwrap();
    }
}
