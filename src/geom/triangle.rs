//! The watertight ray/triangle test of Woop, Benthin & Wald, "Watertight Ray/Triangle
//! Intersection" (JCGT 2(1), 2013), in single precision.
//!
//! The ray is sheared so that it runs along +z through the origin; each vertex is transformed once,
//! and the three 2D edge functions are evaluated on transformed vertices. An edge shared by two
//! triangles is evaluated from the same two transformed vertices in both, so the two results are
//! exact negatives of each other and no ray can slip between them. The paper falls back to double
//! precision when an edge function is exactly zero; we instead accept zeros on both sides (a ray
//! through an edge or vertex hits every triangle there), which is equally watertight, needs no
//! `float64` on the GPU, and only costs a duplicate hit at the same `t`, harmless for closest-hit
//! and any-hit queries. The GLSL twin (`glsl/intersect.glsl`) keeps the same permutation and
//! shear, computes the very same values, and marks its arithmetic `precise` so that FMA
//! contraction cannot break the negation symmetry.

use glam::Vec3;

use super::Ray;

/// Per-ray shear constants (section 3 of the paper): `k` are the permuted axes with `kz` the
/// dominant direction axis, `s` the shear, and `sz = 1/d[kz]`.
#[derive(Clone, Copy, Debug)]
pub struct RayShear {
    /// The ray's origin, subtracted from each vertex before shearing.
    pub origin: Vec3,
    /// Axis indices `[kx, ky, kz]`: `kz` the direction's largest component, `kx`, `ky` the others,
    /// swapped when `d[kz] < 0` to keep the winding.
    pub k: [usize; 3],
    /// Shear `[d[kx]/d[kz], d[ky]/d[kz], 1/d[kz]]` (the paper's `Sx`, `Sy`, `Sz`).
    pub s: [f32; 3],
}

impl RayShear {
    /// The shear constants of `ray`, computed once per ray and reused for every triangle it
    /// is tested against; `ray.dir` must be non-zero.
    pub fn new(ray: &Ray) -> Self {
        let d = ray.dir();
        let a = d.abs();
        let kz = if a.x >= a.y && a.x >= a.z {
            0
        } else if a.y >= a.z {
            1
        } else {
            2
        };
        let mut kx = (kz + 1) % 3;
        let mut ky = (kx + 1) % 3;
        // Swap to keep the triangles' winding (and so the sign of the edge functions) intact.
        if d[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        RayShear {
            origin: ray.origin(),
            k: [kx, ky, kz],
            s: [d[kx] / d[kz], d[ky] / d[kz], 1.0 / d[kz]],
        }
    }
}

/// The unit normal of the triangle `(a, b, c)` as wound, `normalize((b − a) × (c − a))`; zero for
/// a degenerate one. The edges and then their cross product are scaled by powers of two before it
/// is normalized, which is exact, so that a triangle of any size gets its normal: the squared
/// cross product of a triangle a trillionth of a unit across underflows `f32`, and normalized
/// plainly it was infinite on the device and zero here (tests/stability, scale and offset). The
/// scaling changes no bit of any other normal. `rbvh_unit_normal` in `glsl/intersect.glsl`
/// takes the same steps.
pub fn unit_normal(a: Vec3, b: Vec3, c: Vec3) -> Vec3 {
    unit(pow2_scaled(b - a).cross(pow2_scaled(c - a)))
}

/// `v` normalized at any magnitude, zero where it is zero: scaled by a power of two first, as
/// [`unit_normal`] scales its cross product (an instance's transformed normal, whose transform
/// may scale by 1e-20, too). `rbvh_unit` in `glsl/intersect.glsl`.
pub fn unit(v: Vec3) -> Vec3 {
    pow2_scaled(v).normalize_or_zero()
}

/// `v` scaled by the power of two that brings its largest component's magnitude into
/// `[0.5, 1)` (`frexp`'s exponent, kept within ±125 so that the factor is a normal `f32`); as it
/// is where that component is zero or not finite.
fn pow2_scaled(v: Vec3) -> Vec3 {
    let m = v.abs().max_element();
    if !(m > 0.0 && m.is_finite()) {
        return v;
    }
    // m = f·2^e with f in [0.5, 1): e is the biased exponent − 126 (a subnormal m counts as
    // 2^−126's, as `frexp` does not, which the clamp to −125 makes the same).
    let e = ((((m.to_bits() >> 23) & 0xFF) as i32) - 126).clamp(-125, 125);
    v * f32::from_bits(((127 - e) as u32) << 23)
}

/// Intersects the sheared ray with triangle `(a, b, c)` and returns the hit distance when it lies in
/// `[tmin, tmax)`. The distance is measured in units of the ray's (unnormalised) direction.
#[inline]
pub fn intersect_triangle(
    r: &RayShear,
    a: Vec3,
    b: Vec3,
    c: Vec3,
    tmin: f32,
    tmax: f32,
) -> Option<f32> {
    let [kx, ky, kz] = r.k;
    let [sx, sy, sz] = r.s;
    let a = a - r.origin;
    let b = b - r.origin;
    let c = c - r.origin;
    let ax = a[kx] - sx * a[kz];
    let ay = a[ky] - sy * a[kz];
    let bx = b[kx] - sx * b[kz];
    let by = b[ky] - sy * b[kz];
    let cx = c[kx] - sx * c[kz];
    let cy = c[ky] - sy * c[kz];
    let u = cx * by - cy * bx;
    let v = ax * cy - ay * cx;
    let w = bx * ay - by * ax;
    if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
        return None;
    }
    let det = u + v + w;
    if det == 0.0 {
        return None;
    }
    let az = sz * a[kz];
    let bz = sz * b[kz];
    let cz = sz * c[kz];
    let t_scaled = u * az + v * bz + w * cz;
    // Compare before dividing, as the paper does, so that rounding cannot move a hit across tmin.
    let (lo, hi) = if det > 0.0 {
        (t_scaled >= tmin * det, t_scaled < tmax * det)
    } else {
        (t_scaled <= tmin * det, t_scaled > tmax * det)
    };
    if !(lo && hi) {
        return None;
    }
    // The quotient rounds apart from the products, so the interval is checked on it too: without,
    // 7-10% of the primary hits on the default scene and the blob, cast again with `tmax` at their
    // distance, met the same triangle at `tmax` (a point aimed at on a surface was occluded by
    // it), and a hit could round below `tmin`.
    let t = t_scaled / det;
    (t >= tmin && t < tmax).then_some(t)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shear(o: [f32; 3], d: [f32; 3]) -> RayShear {
        RayShear::new(&Ray::new(o.into(), d.into(), 0.0, f32::INFINITY))
    }

    #[test]
    fn hits_centre_and_misses_outside() {
        let (a, b, c) = (
            Vec3::new(-1.0, -1.0, 0.0),
            Vec3::new(1.0, -1.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
        );
        let r = shear([0.0, 0.0, -2.0], [0.0, 0.0, 1.0]);
        assert_eq!(
            intersect_triangle(&r, a, b, c, 0.0, f32::INFINITY),
            Some(2.0)
        );
        let r = shear([5.0, 0.0, -2.0], [0.0, 0.0, 1.0]);
        assert_eq!(intersect_triangle(&r, a, b, c, 0.0, f32::INFINITY), None);
        // Back side and reversed winding are hit too (no culling).
        let r = shear([0.0, 0.0, 2.0], [0.0, 0.0, -1.0]);
        assert_eq!(
            intersect_triangle(&r, a, c, b, 0.0, f32::INFINITY),
            Some(2.0)
        );
    }

    #[test]
    fn interval_is_half_open() {
        let (a, b, c) = (
            Vec3::new(-1.0, -1.0, 0.0),
            Vec3::new(1.0, -1.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
        );
        let r = shear([0.0, 0.0, -2.0], [0.0, 0.0, 1.0]);
        assert_eq!(intersect_triangle(&r, a, b, c, 0.0, 2.0), None);
        assert_eq!(intersect_triangle(&r, a, b, c, 2.0, 3.0), Some(2.0));
    }

    /// A hit cast again with `tmax` at its distance is not met there, nor with `tmin` above it,
    /// whatever the rounding (before the quotient was checked, about one in ten was).
    #[test]
    fn a_hit_lies_in_the_interval_after_rounding() {
        let mut rng = crate::random::SplitMix64::new(7);
        let mut point = |scale: f32| {
            Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * scale - scale * 0.5
        };
        let mut hits = 0;
        for _ in 0..20_000 {
            let (a, b, c) = (point(2.0), point(2.0), point(2.0));
            let (o, target) = (point(20.0), (a + b + c) / 3.0 + point(0.2));
            let r = RayShear::new(&Ray::new(o, target - o, 0.0, f32::INFINITY));
            let Some(t) = intersect_triangle(&r, a, b, c, 0.0, f32::INFINITY) else {
                continue;
            };
            hits += 1;
            assert_eq!(intersect_triangle(&r, a, b, c, 0.0, t), None, "{t}");
            let above = t + t.abs().max(f32::MIN_POSITIVE) * f32::EPSILON;
            assert_eq!(intersect_triangle(&r, a, b, c, above, f32::INFINITY), None);
        }
        assert!(hits > 5_000, "{hits}");
    }

    #[test]
    fn shared_edge_is_watertight() {
        // Two triangles sharing the diagonal of a quad; rays exactly through the diagonal.
        let p = [
            Vec3::new(-1.0, -1.0, 0.3),
            Vec3::new(1.0, -1.0, 0.1),
            Vec3::new(1.0, 1.0, -0.2),
            Vec3::new(-1.0, 1.0, 0.4),
        ];
        for i in 4..=60 {
            let s = -1.0 + 2.0 * i as f32 / 64.0;
            let r = shear([s, s, 5.0], [0.013, -0.007, -1.0]);
            let h0 = intersect_triangle(&r, p[0], p[1], p[2], 0.0, f32::INFINITY);
            let h1 = intersect_triangle(&r, p[0], p[2], p[3], 0.0, f32::INFINITY);
            assert!(
                h0.is_some() || h1.is_some(),
                "ray {i} leaked through the shared edge"
            );
        }
    }

    #[test]
    fn unit_normals_at_any_scale_and_the_same_bits_at_ordinary_ones() {
        let (a, b, c) = (
            Vec3::new(0.3, -1.2, 2.0),
            Vec3::new(1.7, 0.4, -0.6),
            Vec3::new(-0.9, 2.2, 0.8),
        );
        let plain = (b - a).cross(c - a).normalize_or_zero();
        assert_eq!(unit_normal(a, b, c).to_array(), plain.to_array());
        for scale in [1e-12f32, 1e-20, 1e-30, 1e30] {
            let n = unit_normal(a * scale, b * scale, c * scale);
            assert!(
                n.is_finite() && (n.length() - 1.0).abs() < 1e-6 && n.dot(plain) > 0.999_999,
                "scale {scale:e}: {n}"
            );
        }
        // Degenerate: zero, as before.
        assert_eq!(unit_normal(a, b, a), Vec3::ZERO);
        assert_eq!(unit_normal(a, 2.0 * a, 3.0 * a), Vec3::ZERO);
        assert_eq!(unit(Vec3::ZERO), Vec3::ZERO);
        assert_eq!(unit(Vec3::new(0.0, 3e-39, 0.0)), Vec3::Y);
    }
}
