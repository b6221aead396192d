//! The leaf frustum and the refinement criteria: an orthographic projection along the
//! normalised area-weighted normal sum Σ nᵢAᵢ (Novák & Dachsbacher 2012), with tangents turned to
//! the tightest enclosing rectangle so that elongated leaves get narrow tiles, and an extent that
//! just encloses the leaf's triangles plus the texel margin that dilation fills.

use glam::{DVec2, DVec3, Vec3};

use super::params::Refinement;
use super::raster::Frame;

/// The surface elements of a set as the criteria see them: per element its normal scaled by its
/// area (any common factor is harmless). A triangle's is `(b − a) × (c − a)` (twice its area, as
/// wound); a point's is its normal times the square of its spacing, the area it stands for
/// (`crate::points::PointCloud::spacing`). Both inputs of the RBVH are judged, and framed, alike.
pub(crate) fn triangle_elements(tris: &[[Vec3; 3]]) -> Vec<Vec3> {
    tris.iter().map(triangle_element).collect()
}

/// One triangle's element (see [`triangle_elements`]).
pub(crate) fn triangle_element([a, b, c]: &[Vec3; 3]) -> Vec3 {
    (*b - *a).cross(*c - *a)
}

/// Whether no projection axis can bring `elements` within `refinement`'s normal cone: two of them
/// (whose squared lengths are normal floats) face apart by more than twice its angle, and a 2°
/// margin far beyond rounding, so that every
/// axis lies more than the angle from one of them and [`passes`] fails whatever
/// [`projection_axis`] gives. Elements are compared with the first such one, up to the first
/// that faces apart: a large curved set (a whole dragon, at the recursion's first levels)
/// is refused after a few of its triangles, where the axis and the criterion read all of them.
pub(crate) fn fails_every_axis(
    refinement: Refinement,
    elements: impl IntoIterator<Item = Vec3>,
) -> bool {
    let Refinement::NormalCone { max_angle_deg } = refinement else {
        return false;
    };
    let apart = 2.0 * max_angle_deg + 2.0;
    if apart >= 180.0 {
        return false;
    }
    let max_cos = apart.to_radians().cos();
    // Elements whose squared length is subnormal have lengths off by up to a tenth: left out,
    // which only weakens the test (`passes` still counts them).
    let mut elements = elements
        .into_iter()
        .filter(|e| e.length_squared() >= f32::MIN_POSITIVE);
    let Some(first) = elements.next() else {
        return false;
    };
    let first = first.normalize();
    elements.any(|e| first.dot(e) < max_cos * e.length())
}

/// The projection axis: the normalised area-weighted normal sum Σ nᵢAᵢ of `elements` (see
/// [`triangle_elements`]), or None when the normals cancel out (a closed or folded surface).
pub(crate) fn projection_axis(elements: &[Vec3]) -> Option<Vec3> {
    let n = elements.iter().fold(Vec3::ZERO, |s, &e| s + e);
    let len = n.length();
    let area: f32 = elements.iter().map(|e| e.length()).sum();
    // Below this the axis is noise (e.g. both sides of a closed surface).
    (len > 1e-6 * area && len.is_finite()).then(|| n / len)
}

/// Whether `elements` (see [`triangle_elements`]), seen along `w`, pass the refinement criterion.
pub(crate) fn passes(refinement: Refinement, elements: &[Vec3], w: Vec3) -> bool {
    match refinement {
        Refinement::NormalCone { max_angle_deg } => {
            let min_cos = max_angle_deg.to_radians().cos();
            elements.iter().all(|&n| {
                let len = n.length();
                // Zero-area elements have no normal and cover nothing; they do not count.
                len == 0.0 || n.dot(w) >= min_cos * len
            })
        }
        Refinement::ProjectedArea { min_ratio } => {
            let (projected, total) = elements.iter().fold((0.0f32, 0.0f32), |(p, t), &n| {
                (p + n.dot(w), t + n.length())
            });
            total > 0.0 && projected >= min_ratio * total
        }
    }
}

/// Orthonormal tangents for `w` (Duff et al., "Building an Orthonormal Basis, Revisited", JCGT 2017).
fn basis(w: Vec3) -> (Vec3, Vec3) {
    let sign = 1.0f32.copysign(w.z);
    let a = -1.0 / (sign + w.z);
    let b = w.x * w.y * a;
    (
        Vec3::new(1.0 + sign * w.x * w.x * a, sign * b, -sign * w.x),
        Vec3::new(b, sign + w.y * w.y * a, -w.y),
    )
}

/// Samples by which f32 rounding may move a tile's grid, for a tile whose points reach
/// `magnitude` (largest absolute world coordinate) at `texel` size. Rounding a point to f32 moves
/// it by at most half an ulp per coordinate, less than `magnitude · ε` along any direction; a
/// tile's origin is rounded twice (placed, then moved to its lowest height), hence twice that.
/// Zero when this is below a thousandth of a texel, as for any scene near the world origin; far
/// from it, where an ulp approaches a texel, margins and the overlap of neighbouring tiles must
/// be widened by this much, or tiles crack apart. Capped at [`MAX_ROUNDING_PAD`]: beyond it f32
/// cannot resolve the texels at all.
pub(crate) fn rounding_pad(magnitude: f32, texel: f32) -> u32 {
    let shift = 2.0 * magnitude * f32::EPSILON;
    if shift > 1e-3 * texel {
        (shift / texel).ceil().min(MAX_ROUNDING_PAD as f32) as u32
    } else {
        0
    }
}

/// Most samples [`rounding_pad`] adds.
pub(crate) const MAX_ROUNDING_PAD: u32 = 4;

/// Tangent orientations tried per leaf: every 5° over a quarter turn (a rectangle repeats after 90°).
const ORIENTATIONS: u32 = 18;

/// The frame of a leaf projected along `w` at `texel` size: of [`ORIENTATIONS`] tangent directions
/// `u` (with `v = w × u`), the one whose enclosing rectangle needs the fewest samples — texels are
/// memory, so an elongated leaf gets a narrow tile — with `res = ceil(extent / texel) + 2` samples
/// per side, centred, so that the samples reach at least half a texel beyond `points` (a leaf's
/// triangle corners, or its points) grown by `margin` on every side (dilation then fills that rim
/// and neighbouring leaves overlap instead of cracking). `margin` is 0 for triangles and a
/// point leaf's splat reach for points.
/// Projections are taken in f64 relative to a vertex of the leaf, and the origin rounded to f32
/// once; far from the world origin the margin grows by [`rounding_pad`] samples per side.
pub(crate) fn fit(points: &[Vec3], w: Vec3, texel: f32, margin: f32) -> Frame {
    let (b1, b2) = basis(w);
    let reference = points.first().map_or(DVec3::ZERO, |p| p.as_dvec3());
    let texel64 = f64::from(texel);
    let margin = f64::from(margin.max(0.0));
    let res = |extent: f64| {
        (((extent + 2.0 * margin) / texel64).ceil().max(0.0) as u32).saturating_add(2)
    };
    let wd = w.as_dvec3();
    // Each point's offset from the reference and its height along `w` are the same for every
    // orientation: taken once, not once an orientation (this fit took 7% of a level's build in
    // a profile of Q2 at the paper's scale).
    let offsets: Vec<DVec3> = points.iter().map(|p| p.as_dvec3() - reference).collect();
    let (w_lo, w_hi) = offsets
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), d| {
            let h = d.dot(wd);
            // As `DVec3::min` and `max` choose (the later of equal values, -0 or +0), which
            // `f64::min` and `max` leave open.
            (if lo < h { lo } else { h }, if hi > h { hi } else { h })
        });
    let extents = |u: DVec3, v: DVec3| {
        let (mut lo, mut hi) = (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY));
        for d in &offsets {
            let q = DVec2::new(d.dot(u), d.dot(v));
            lo = lo.min(q);
            hi = hi.max(q);
        }
        (lo.extend(w_lo), hi.extend(w_hi))
    };
    let mut best: Option<(u64, Vec3, Vec3, DVec3, DVec3)> = None;
    for k in 0..ORIENTATIONS {
        let theta = (k as f32 * 90.0 / ORIENTATIONS as f32).to_radians();
        let u = (theta.cos() * b1 + theta.sin() * b2).normalize();
        let v = w.cross(u);
        let (lo, hi) = extents(u.as_dvec3(), v.as_dvec3());
        let samples = res(hi.x - lo.x) as u64 * res(hi.y - lo.y) as u64;
        if best.is_none_or(|b| samples < b.0) {
            best = Some((samples, u, v, lo, hi));
        }
    }
    let (_, u, v, lo, hi) = best.expect("at least one orientation");
    let (mut res_u, mut res_v) = (res(hi.x - lo.x), res(hi.y - lo.y));
    // Far from the world origin the f32 origin cannot be placed to within a texel: widen the
    // margin by what rounding may take from it (nothing near the origin).
    let reach = reference.abs().max_element() + (hi - lo).max_element() + 2.0 * margin;
    let pad = rounding_pad(reach as f32, texel);
    res_u = res_u.saturating_add(2 * pad);
    res_v = res_v.saturating_add(2 * pad);
    let cu = 0.5 * (lo.x + hi.x) - 0.5 * res_u as f64 * texel64;
    let cv = 0.5 * (lo.y + hi.y) - 0.5 * res_v as f64 * texel64;
    let origin = reference + cu * u.as_dvec3() + cv * v.as_dvec3() + lo.z * wd;
    Frame {
        origin: origin.as_vec3(),
        u,
        v,
        w,
        texel,
        res_u,
        res_v,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const QUAD: [[Vec3; 3]; 2] = [
        [
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(4.0, 0.0, 0.0),
            Vec3::new(4.0, 0.0, -1.0),
        ],
        [
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(4.0, 0.0, -1.0),
            Vec3::new(0.0, 0.0, -1.0),
        ],
    ];

    #[test]
    fn axis_is_the_area_weighted_normal() {
        let w = projection_axis(&triangle_elements(&QUAD)).unwrap();
        assert!((w - Vec3::Y).length() < 1e-6, "{w}");
        // Two opposite faces cancel: no axis.
        let flipped: Vec<[Vec3; 3]> = QUAD
            .iter()
            .map(|[a, b, c]| [*a, *c, *b])
            .chain(QUAD)
            .collect();
        assert!(projection_axis(&triangle_elements(&flipped)).is_none());
    }

    #[test]
    fn a_set_refused_for_every_axis_fails_the_criterion_on_any() {
        let cone = |deg: f32| Refinement::NormalCone { max_angle_deg: deg };
        // Normals 90° apart (a 45° tent is the tent below): within a cone of 45°, so never
        // refused; 100° apart: refused under 49° (the 2° margin), not at 49°.
        let apart = |deg: f32| {
            let r = deg.to_radians();
            [Vec3::Y * 2.0, Vec3::new(r.sin(), r.cos(), 0.0) * 0.5]
        };
        assert!(!fails_every_axis(cone(45.0), apart(90.0)));
        assert!(fails_every_axis(cone(48.9), apart(100.0)));
        assert!(!fails_every_axis(cone(49.1), apart(100.0)));
        // Zero-area elements do not count, first or later; one element, or none, is never refused;
        // the projected-area criterion is not judged this way.
        assert!(!fails_every_axis(cone(10.0), [Vec3::ZERO, Vec3::Y]));
        assert!(fails_every_axis(
            cone(10.0),
            [Vec3::ZERO, Vec3::Y, Vec3::ZERO, -Vec3::Y]
        ));
        assert!(!fails_every_axis(cone(10.0), []));
        // Nor do elements whose squared length is subnormal, whose lengths are inexact.
        assert!(!fails_every_axis(
            cone(10.0),
            [Vec3::new(-1e-22, 0.0, 0.0), Vec3::X]
        ));
        assert!(!fails_every_axis(
            cone(10.0),
            [Vec3::X, Vec3::new(-1e-22, 0.0, 0.0)]
        ));
        let area = Refinement::ProjectedArea { min_ratio: 0.9 };
        assert!(!fails_every_axis(area, [Vec3::Y, -Vec3::Y]));
        // Wherever a random set is refused, no axis passes it: not its own, not any of many.
        let mut rng = crate::random::SplitMix64::new(7);
        let mut unit = || {
            let v = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0 - 1.0;
            v.normalize_or_zero()
        };
        let mut refused = 0;
        for set in 0..400 {
            let spread = (set % 8) as f32 * 0.25;
            let centre = unit();
            let elements: Vec<Vec3> = (0..6).map(|_| centre + spread * unit()).collect();
            if !fails_every_axis(cone(60.0), elements.iter().copied()) {
                continue;
            }
            refused += 1;
            let own = projection_axis(&elements);
            for w in own.into_iter().chain((0..200).map(|_| unit())) {
                assert!(
                    !passes(cone(60.0), &elements, w),
                    "{elements:?} passes along {w}"
                );
            }
        }
        assert!(refused > 50, "{refused} of 400 sets refused");
    }

    #[test]
    fn criteria_accept_flat_and_reject_folded() {
        let w = Vec3::Y;
        assert!(passes(
            Refinement::NormalCone { max_angle_deg: 1.0 },
            &triangle_elements(&QUAD),
            w
        ));
        assert!(passes(
            Refinement::ProjectedArea { min_ratio: 0.999 },
            &triangle_elements(&QUAD),
            w
        ));
        // A 45° tent: cone half-angle 45°.
        let tent = [
            [
                Vec3::ZERO,
                Vec3::new(1.0, 1.0, 0.0),
                Vec3::new(0.0, 0.0, -1.0),
            ],
            [
                Vec3::ZERO,
                Vec3::new(0.0, 0.0, -1.0),
                Vec3::new(-1.0, 1.0, 0.0),
            ],
        ];
        assert!(passes(
            Refinement::NormalCone {
                max_angle_deg: 46.0
            },
            &triangle_elements(&tent),
            w
        ));
        assert!(!passes(
            Refinement::NormalCone {
                max_angle_deg: 44.0
            },
            &triangle_elements(&tent),
            w
        ));
        assert!(passes(
            Refinement::ProjectedArea { min_ratio: 0.70 },
            &triangle_elements(&tent),
            w
        ));
        assert!(!passes(
            Refinement::ProjectedArea { min_ratio: 0.71 },
            &triangle_elements(&tent),
            w
        ));
    }

    #[test]
    fn frame_encloses_triangles_with_a_margin_and_follows_the_long_axis() {
        let texel = 0.1;
        let f = fit(QUAD.as_flattened(), Vec3::Y, texel, 0.0);
        assert!((f.u.dot(f.v)).abs() < 1e-6 && (f.u.cross(f.v) - f.w).length() < 1e-5);
        // The quad is 4 × 1: the tightest tile runs along x.
        assert!(f.u.x.abs() > 0.999, "{}", f.u);
        assert!(
            (42..=43).contains(&f.res_u) && (12..=13).contains(&f.res_v),
            "{} {}",
            f.res_u,
            f.res_v
        );
        for p in QUAD.iter().flatten() {
            let s = (*p - f.origin).dot(f.u) / texel;
            let t = (*p - f.origin).dot(f.v) / texel;
            assert!(s >= 1.0 - 1e-3 && s <= f.res_u as f32 - 1.0 + 1e-3, "{s}");
            assert!(t >= 1.0 - 1e-3 && t <= f.res_v as f32 - 1.0 + 1e-3, "{t}");
            assert!((*p - f.origin).dot(f.w).abs() < 1e-6);
        }
    }

    #[test]
    fn a_margin_widens_the_frame_by_as_many_samples_on_each_side() {
        let texel = 0.1;
        let points = QUAD.as_flattened();
        let plain = fit(points, Vec3::Y, texel, 0.0);
        let grown = fit(points, Vec3::Y, texel, 0.5);
        assert_eq!(grown.u, plain.u);
        assert!(
            (grown.res_u as i64 - plain.res_u as i64 - 10).abs() <= 1
                && (grown.res_v as i64 - plain.res_v as i64 - 10).abs() <= 1,
            "{} × {} against {} × {}",
            grown.res_u,
            grown.res_v,
            plain.res_u,
            plain.res_v
        );
    }

    #[test]
    fn points_are_judged_by_their_normals_weighted_by_their_areas() {
        // A point's element is its normal times its area: two points 60° apart, one with four
        // times the other's area, tilt the axis towards the larger.
        let tilted = Vec3::new(60f32.to_radians().sin(), 0.0, 60f32.to_radians().cos());
        let elements = [Vec3::Z * 4.0, tilted];
        let w = projection_axis(&elements).unwrap();
        let angle = w.angle_between(Vec3::Z).to_degrees();
        assert!((10.0..14.0).contains(&angle), "{angle}");
        let cone = |max_angle_deg| Refinement::NormalCone { max_angle_deg };
        assert!(passes(cone(50.0), &elements, w));
        assert!(!passes(cone(45.0), &elements, w));
    }
}
