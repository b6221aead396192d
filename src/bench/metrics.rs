//! How wrong a method is, measured against the exact BVH on the same rays (the measures that
//! `docs/measuring.md`, "Benchmarks: the speed/accuracy trade", reports for every level):
//!
//! * **hit/miss disagreement**: the fraction of rays that one side hits and the other misses;
//! * **hit distance error** `|t − t_exact| · |dir| / diagonal`, over the rays both hit, as a
//!   fraction of the scene's bounding-box diagonal so that it means the same at any scale, and
//!   as a fraction of the diagonal of the object the exact ray hit (`t_err_object`): what a
//!   preset that samples each object for its own size promises, so that a dragon in a courtyard
//!   is judged as the dragon alone would be;
//! * **back-facing hits**: the fraction of rays both hit whose normal faces away from the ray
//!   while the exact normal faces it: shaded, the dark specks along silhouettes that a coarse
//!   preset may bring (issue "Small and valid at every scale", item 5);
//! * **normal angle error** in degrees between the two geometric normals, over the rays both hit.
//!   Normals are compared as wound, not flipped towards the ray: a height field that reports the
//!   back side is an error. RBVH normals are reconstructed from quantized heights, so a few
//!   degrees are expected even where the surface is right;
//! * for primary rays, **PSNR** and **FLIP** between the shaded images (Andersson et al., "FLIP:
//!   A Difference Evaluator for Alternating Images", HPG 2020, through the `nv-flip` bindings).
//!
//! Distance and normal errors are only defined for closest-hit queries: an any-hit query answers
//! with whichever hit traversal finds first, which legitimately differs between two correct
//! structures, so for occlusion rays only the disagreement counts.
//!
//! Percentiles use the nearest-rank definition: p99 is the smallest value with at least 99% of
//! the values at or below it, so it is always one of the measured values.

use crate::flip;
use crate::geom::{Hit, Ray};
use crate::gpu::Query;
use crate::output::Image;
use crate::{Error, Result};

/// Mean, 99th percentile and maximum of a set of errors.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Summary {
    /// Arithmetic mean of the values.
    pub mean: f64,
    /// Nearest-rank 99th percentile: one of the values.
    pub p99: f64,
    /// Largest value.
    pub max: f64,
}

impl Summary {
    /// None for an empty set, where no statistic is defined.
    pub fn of(mut values: Vec<f64>) -> Option<Summary> {
        if values.is_empty() {
            return None;
        }
        values.sort_by(f64::total_cmp);
        Some(Summary {
            mean: values.iter().sum::<f64>() / values.len() as f64,
            p99: nearest_rank(&values, 0.99),
            max: values[values.len() - 1],
        })
    }
}

/// The nearest-rank `q`-quantile of ascending, non-empty `sorted`.
fn nearest_rank(sorted: &[f64], q: f64) -> f64 {
    let rank = (q * sorted.len() as f64).ceil() as usize;
    sorted[rank.clamp(1, sorted.len()) - 1]
}

/// The errors of one method's hits against the exact hits of the same rays.
#[derive(Clone, Debug, PartialEq)]
pub struct HitErrors {
    /// Rays compared: the denominator of `miss_mismatch_rate`.
    pub rays: usize,
    /// Rays hit by one side and missed by the other, over all rays (0 when there are none).
    pub miss_mismatch_rate: f64,
    /// `|t − t_exact| · |dir| / diagonal` over rays both hit; None for any-hit queries or when no
    /// ray was hit by both.
    pub t_err: Option<Summary>,
    /// The same distance error over the diagonal of the object the reference hit, over the rays
    /// both hit whose reference object is known; None as for `t_err`, or when no object is.
    pub t_err_object: Option<Summary>,
    /// Angle between the normals in degrees, over rays both hit; None as for `t_err`.
    pub normal_err_deg: Option<Summary>,
    /// Rays both hit whose normal faces away from the ray (as wound) while the exact one faces
    /// it, over all rays; 0 for any-hit queries.
    pub back_facing_rate: f64,
    /// Hits of the method under test with a non-finite `t` or normal: always a bug.
    pub non_finite: usize,
}

/// Both hit lists must answer every ray.
pub(crate) fn check_lengths(rays: &[Ray], exact: &[Hit], test: &[Hit]) -> Result<()> {
    if exact.len() != rays.len() || test.len() != rays.len() {
        return Err(Error::param(
            "hits",
            format!(
                "{} rays but {} exact and {} tested hits",
                rays.len(),
                exact.len(),
                test.len()
            ),
        ));
    }
    Ok(())
}

/// Compares `test` with `exact`, both answers to `rays` for `query`; `diagonal` is the scene's
/// bounding-box diagonal, and `object_diagonal` that of the object an exact hit lies on (None
/// where it is not known: a hit that is not a scene triangle, a degenerate object).
pub fn hit_errors(
    rays: &[Ray],
    exact: &[Hit],
    test: &[Hit],
    diagonal: f32,
    object_diagonal: &dyn Fn(&Hit) -> Option<f32>,
    query: Query,
) -> Result<HitErrors> {
    check_lengths(rays, exact, test)?;
    if !(diagonal.is_finite() && diagonal > 0.0) {
        return Err(Error::param(
            "diagonal",
            format!("{diagonal} is not a positive length"),
        ));
    }
    let mut mismatches = 0usize;
    let mut non_finite = 0usize;
    let mut t_err = Vec::new();
    let mut t_err_object = Vec::new();
    let mut normal_err = Vec::new();
    let mut back_facing = 0usize;
    for ((ray, e), h) in rays.iter().zip(exact).zip(test) {
        if h.is_hit() && !(h.t.is_finite() && h.normal().is_finite()) {
            non_finite += 1;
            continue;
        }
        match (e.is_hit(), h.is_hit()) {
            (true, true) if query == Query::Closest => {
                let off = (f64::from(h.t) - f64::from(e.t)).abs() * f64::from(ray.dir().length());
                t_err.push(off / f64::from(diagonal));
                if let Some(d) = object_diagonal(e).filter(|d| d.is_finite() && *d > 0.0) {
                    t_err_object.push(off / f64::from(d));
                }
                normal_err.push(angle_deg(e, h));
                let d = ray.dir();
                back_facing += usize::from(h.normal().dot(d) > 0.0 && e.normal().dot(d) < 0.0);
            }
            (a, b) if a != b => mismatches += 1,
            _ => {}
        }
    }
    Ok(HitErrors {
        rays: rays.len(),
        miss_mismatch_rate: if rays.is_empty() {
            0.0
        } else {
            mismatches as f64 / rays.len() as f64
        },
        t_err: Summary::of(t_err),
        t_err_object: Summary::of(t_err_object),
        normal_err_deg: Summary::of(normal_err),
        back_facing_rate: if rays.is_empty() {
            0.0
        } else {
            back_facing as f64 / rays.len() as f64
        },
        non_finite,
    })
}

/// Angle between the two hits' normals in degrees; a zero normal counts as 90°.
fn angle_deg(a: &Hit, b: &Hit) -> f64 {
    let cos = a
        .normal()
        .normalize_or_zero()
        .dot(b.normal().normalize_or_zero());
    f64::from(cos.clamp(-1.0, 1.0)).acos().to_degrees()
}

/// Differences between two shaded renders of the same view.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImageErrors {
    /// Over the 8-bit sRGB channels; +∞ for identical images.
    pub psnr_db: f64,
    /// Mean of FLIP's per-pixel error map, in [0, 1].
    pub flip_mean: f64,
}

/// PSNR and mean FLIP of `test` against `reference`, both compared as the 8-bit sRGB pixels that
/// `output::write_png` would store — what a viewer of the PNGs sees, and what FLIP expects.
/// FLIP uses its default 67 pixels per degree (roughly a 31.6" 3840-pixel-wide monitor seen from
/// 70 cm).
pub fn image_errors(reference: &Image, test: &Image) -> Result<ImageErrors> {
    if (reference.width, reference.height) != (test.width, test.height)
        || reference.pixels.len() != test.pixels.len()
        || reference.pixels.len() != reference.width as usize * reference.height as usize
        || reference.pixels.is_empty()
    {
        return Err(Error::param(
            "image",
            format!(
                "cannot compare a {}×{} image with {} pixels to a {}×{} image with {}",
                reference.width,
                reference.height,
                reference.pixels.len(),
                test.width,
                test.height,
                test.pixels.len()
            ),
        ));
    }
    let (a, b) = (srgb8(reference), srgb8(test));
    let squared: f64 = a
        .iter()
        .zip(&b)
        .map(|(&x, &y)| (f64::from(x) - f64::from(y)).powi(2))
        .sum();
    let mse = squared / a.len() as f64;
    let psnr_db = 10.0 * (255.0f64.powi(2) / mse).log10();
    let flip_mean = flip::mean(&flip::errors(reference.width, reference.height, &a, &b)?);
    Ok(ImageErrors { psnr_db, flip_mean })
}

/// The image as tightly packed 8-bit sRGB, exactly as `output::write_png` stores it.
fn srgb8(image: &Image) -> Vec<u8> {
    image
        .pixels
        .iter()
        .flat_map(|p| p.to_array().map(crate::srgb::encode_u8))
        .collect()
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::*;

    fn hit(t: f32, normal: Vec3) -> Hit {
        Hit {
            t,
            normal: normal.to_array(),
            id: 0,
            ..Hit::MISS
        }
    }

    #[test]
    fn known_values_on_hand_made_hits() {
        // Diagonal 10; the third ray's direction has length 2, so its t error counts double.
        let unit = Ray::new(Vec3::ZERO, Vec3::Z, 0.0, f32::INFINITY);
        let long = Ray::new(Vec3::ZERO, Vec3::Z * 2.0, 0.0, f32::INFINITY);
        let rays = [unit, unit, long, unit, unit];
        let tilted = Vec3::new(1.0, 0.0, 1.0).normalize();
        let exact = [
            hit(1.0, Vec3::Z),
            hit(2.0, Vec3::Z),
            hit(3.0, Vec3::Z),
            hit(4.0, Vec3::Z),
            Hit::MISS,
        ];
        let test = [
            hit(1.0, Vec3::Z),  // exact
            hit(2.5, tilted),   // 0.5 / 10 = 0.05, 45°
            hit(3.25, Vec3::Z), // 0.25 · 2 / 10 = 0.05
            Hit::MISS,          // disagreement
            hit(1.0, Vec3::Z),  // disagreement
        ];
        // The object of the second exact hit has diagonal 2, the others none known.
        let object = |h: &Hit| (h.t == 2.0).then_some(2.0);
        let e = hit_errors(&rays, &exact, &test, 10.0, &object, Query::Closest).unwrap();
        assert_eq!(e.rays, 5);
        let o = e.t_err_object.unwrap();
        assert!(
            (o.mean - 0.25).abs() < 1e-9 && (o.max - 0.25).abs() < 1e-9,
            "{o:?}"
        );
        assert_eq!(e.miss_mismatch_rate, 0.4);
        let t = e.t_err.unwrap();
        assert!((t.mean - 0.1 / 3.0).abs() < 1e-9, "{t:?}");
        assert!((t.p99 - 0.05).abs() < 1e-9 && (t.max - 0.05).abs() < 1e-9);
        // Every exact normal here faces away from its ray (+z along +z): none counts.
        assert_eq!(e.back_facing_rate, 0.0);
        let n = e.normal_err_deg.unwrap();
        assert!(
            (n.mean - 15.0).abs() < 1e-4 && (n.p99 - 45.0).abs() < 1e-4,
            "{n:?}"
        );
        assert_eq!(e.non_finite, 0);

        let any = hit_errors(&rays, &exact, &test, 10.0, &object, Query::Any).unwrap();
        assert_eq!(any.miss_mismatch_rate, 0.4);
        assert_eq!(
            (any.t_err, any.t_err_object, any.normal_err_deg),
            (None, None, None)
        );
    }

    /// A hit counts as back-facing when its normal faces away from the ray and the exact one
    /// faces it; misses and any-hit queries do not count.
    #[test]
    fn back_facing_hits_are_counted_against_front_facing_exact_ones() {
        let down = Ray::new(Vec3::Z, -Vec3::Z, 0.0, f32::INFINITY);
        let rays = [down; 4];
        let tilted = Vec3::new(0.9, 0.0, 0.1).normalize();
        let exact = [
            hit(1.0, Vec3::Z),
            hit(1.0, Vec3::Z),
            hit(1.0, -Vec3::Z),
            Hit::MISS,
        ];
        let test = [
            hit(1.0, -Vec3::Z),
            hit(1.0, tilted),
            hit(1.0, -Vec3::Z),
            hit(1.0, -Vec3::Z),
        ];
        let none = |_: &Hit| None;
        let e = hit_errors(&rays, &exact, &test, 1.0, &none, Query::Closest).unwrap();
        assert_eq!(e.back_facing_rate, 0.25);
        let any = hit_errors(&rays, &exact, &test, 1.0, &none, Query::Any).unwrap();
        assert_eq!(any.back_facing_rate, 0.0);
    }

    #[test]
    fn p99_is_nearest_rank() {
        let s = Summary::of((1..=200).map(f64::from).collect()).unwrap();
        assert_eq!((s.p99, s.max, s.mean), (198.0, 200.0, 100.5));
        assert_eq!(Summary::of(vec![3.0]).unwrap().p99, 3.0);
        assert_eq!(Summary::of(Vec::new()), None);
    }

    #[test]
    fn mismatched_lengths_and_bad_diagonals_are_errors() {
        let ray = Ray::new(Vec3::ZERO, Vec3::Z, 0.0, 1.0);
        let none = |_: &Hit| None;
        assert!(hit_errors(&[ray], &[], &[Hit::MISS], 1.0, &none, Query::Closest).is_err());
        assert!(hit_errors(
            &[ray],
            &[Hit::MISS],
            &[Hit::MISS],
            0.0,
            &none,
            Query::Closest
        )
        .is_err());
    }

    #[test]
    fn psnr_of_a_known_difference_and_flip_of_identical_images() {
        let grey = Image {
            width: 4,
            height: 4,
            pixels: vec![Vec3::splat(0.0); 16],
        };
        let same = image_errors(&grey, &grey).unwrap();
        assert_eq!(same.psnr_db, f64::INFINITY);
        assert_eq!(same.flip_mean, 0.0);
        // One channel of one pixel off by the full range: MSE = 255² / 48.
        let mut one = grey.clone();
        one.pixels[5].x = 1.0;
        let e = image_errors(&grey, &one).unwrap();
        assert!((e.psnr_db - 10.0 * 48f64.log10()).abs() < 1e-9, "{e:?}");
        assert!(e.flip_mean > 0.0);
        let small = Image {
            width: 2,
            height: 2,
            pixels: vec![Vec3::ZERO; 4],
        };
        assert!(image_errors(&grey, &small).is_err());
    }
}
