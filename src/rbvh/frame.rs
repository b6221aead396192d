//! The leaf frustum and the refinement criteria: an orthographic projection along the
//! normalised area-weighted normal sum Σ nᵢAᵢ (Novák & Dachsbacher 2012), with tangents turned to
//! the tightest enclosing rectangle so that elongated leaves get narrow tiles, and an extent that
//! just encloses the leaf's triangles plus the texel margin that dilation fills.

use glam::Vec3;

use super::params::Refinement;
use super::raster::Frame;

/// `Σ (b − a) × (c − a)` = 2 Σ nᵢAᵢ over `tris`.
pub(crate) fn weighted_normal_sum(tris: &[[Vec3; 3]]) -> Vec3 {
    tris.iter()
        .fold(Vec3::ZERO, |s, [a, b, c]| s + (*b - *a).cross(*c - *a))
}

/// The projection axis, or None when the normals cancel out (a closed or folded surface).
pub(crate) fn projection_axis(tris: &[[Vec3; 3]]) -> Option<Vec3> {
    let n = weighted_normal_sum(tris);
    let len = n.length();
    let area2: f32 = tris
        .iter()
        .map(|[a, b, c]| (*b - *a).cross(*c - *a).length())
        .sum();
    // Below this the axis is noise (e.g. both sides of a closed surface).
    (len > 1e-6 * area2 && len.is_finite()).then(|| n / len)
}

/// Whether `tris`, seen along `w`, pass the refinement criterion.
pub(crate) fn passes(refinement: Refinement, tris: &[[Vec3; 3]], w: Vec3) -> bool {
    match refinement {
        Refinement::NormalCone { max_angle_deg } => {
            let min_cos = max_angle_deg.to_radians().cos();
            tris.iter().all(|[a, b, c]| {
                let n = (*b - *a).cross(*c - *a);
                let len = n.length();
                // Zero-area triangles have no normal and cover nothing; they do not count.
                len == 0.0 || n.dot(w) >= min_cos * len
            })
        }
        Refinement::ProjectedArea { min_ratio } => {
            let (projected, total) = tris.iter().fold((0.0f32, 0.0f32), |(p, t), [a, b, c]| {
                let n = (*b - *a).cross(*c - *a);
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

/// Tangent orientations tried per leaf: every 5° over a quarter turn (a rectangle repeats after 90°).
const ORIENTATIONS: u32 = 18;

/// The frame of a leaf projected along `w` at `texel` size: of [`ORIENTATIONS`] tangent directions
/// `u` (with `v = w × u`), the one whose enclosing rectangle needs the fewest samples — texels are
/// memory, so an elongated leaf gets a narrow tile — with `res = ceil(extent / texel) + 2` samples
/// per side, centred, so that the samples reach at least half a texel beyond the triangles on every
/// side (dilation then fills that rim and neighbouring leaves overlap instead of cracking).
pub(crate) fn fit(tris: &[[Vec3; 3]], w: Vec3, texel: f32) -> Frame {
    let (b1, b2) = basis(w);
    let res = |extent: f32| ((extent / texel).ceil().max(0.0) as u32).saturating_add(2);
    let extents = |u: Vec3, v: Vec3| {
        let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        for p in tris.iter().flatten() {
            let q = Vec3::new(p.dot(u), p.dot(v), p.dot(w));
            lo = lo.min(q);
            hi = hi.max(q);
        }
        (lo, hi)
    };
    let mut best: Option<(u64, Vec3, Vec3, Vec3, Vec3)> = None;
    for k in 0..ORIENTATIONS {
        let theta = (k as f32 * 90.0 / ORIENTATIONS as f32).to_radians();
        let u = (theta.cos() * b1 + theta.sin() * b2).normalize();
        let v = w.cross(u);
        let (lo, hi) = extents(u, v);
        let samples = res(hi.x - lo.x) as u64 * res(hi.y - lo.y) as u64;
        if best.is_none_or(|b| samples < b.0) {
            best = Some((samples, u, v, lo, hi));
        }
    }
    let (_, u, v, lo, hi) = best.expect("at least one orientation");
    let (res_u, res_v) = (res(hi.x - lo.x), res(hi.y - lo.y));
    let cu = 0.5 * (lo.x + hi.x) - 0.5 * res_u as f32 * texel;
    let cv = 0.5 * (lo.y + hi.y) - 0.5 * res_v as f32 * texel;
    Frame {
        origin: cu * u + cv * v + lo.z * w,
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
        let w = projection_axis(&QUAD).unwrap();
        assert!((w - Vec3::Y).length() < 1e-6, "{w}");
        // Two opposite faces cancel: no axis.
        let flipped: Vec<[Vec3; 3]> = QUAD
            .iter()
            .map(|[a, b, c]| [*a, *c, *b])
            .chain(QUAD)
            .collect();
        assert!(projection_axis(&flipped).is_none());
    }

    #[test]
    fn criteria_accept_flat_and_reject_folded() {
        let w = Vec3::Y;
        assert!(passes(
            Refinement::NormalCone { max_angle_deg: 1.0 },
            &QUAD,
            w
        ));
        assert!(passes(
            Refinement::ProjectedArea { min_ratio: 0.999 },
            &QUAD,
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
            &tent,
            w
        ));
        assert!(!passes(
            Refinement::NormalCone {
                max_angle_deg: 44.0
            },
            &tent,
            w
        ));
        assert!(passes(
            Refinement::ProjectedArea { min_ratio: 0.70 },
            &tent,
            w
        ));
        assert!(!passes(
            Refinement::ProjectedArea { min_ratio: 0.71 },
            &tent,
            w
        ));
    }

    #[test]
    fn frame_encloses_triangles_with_a_margin_and_follows_the_long_axis() {
        let texel = 0.1;
        let f = fit(&QUAD, Vec3::Y, texel);
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
}
