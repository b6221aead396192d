//! The exact surfaces some built-in scenes tessellate: oracles that tests compare hits against,
//! with the tessellation's own error bound so that tolerances are computed, not guessed.

use glam::{DVec3, Vec3};

/// The ideal surface behind a built-in scene.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Analytic {
    /// The square of side `2 * half_extent` centred at `point` in the plane through it with
    /// unit `normal`, its edges along the plane's coordinate axes.
    Plane {
        /// World-space centre of the square.
        point: Vec3,
        /// Unit normal of the plane.
        normal: Vec3,
        /// Half the square's side, world units.
        half_extent: f32,
    },
    /// A sphere, and the largest distance between it and its tessellation (anywhere on any
    /// triangle, inside or outside), measured on the actual vertices.
    Sphere {
        /// World-space centre.
        center: Vec3,
        /// Radius, world units.
        radius: f32,
        /// Largest distance between sphere and tessellation, world units (computed in `f64`,
        /// rounded up), so that a test's hit tolerance is computed rather than guessed.
        max_chord_error: f32,
    },
}

/// The largest distance between the sphere (`center`, `radius`) and any point of the given
/// triangles. Inwards, a triangle strays furthest at its point closest to the centre; outwards,
/// distance from the centre is convex, so at a vertex. Computed in `f64` and rounded up.
pub(super) fn sphere_chord_error(
    positions: &[Vec3],
    triangles: &[[u32; 3]],
    center: Vec3,
    radius: f32,
) -> f32 {
    let (c, r) = (center.as_dvec3(), f64::from(radius));
    let error = triangles
        .iter()
        .map(|t| {
            let [a, b, p] = t.map(|i| positions[i as usize].as_dvec3() - c);
            let inward = r - distance_to_triangle(a, b, p);
            let outward = [a, b, p]
                .map(|v| v.length() - r)
                .into_iter()
                .fold(0.0, f64::max);
            inward.max(outward)
        })
        .fold(0.0, f64::max);
    let rounded = error as f32;
    if f64::from(rounded) < error {
        rounded * (1.0 + f32::EPSILON)
    } else {
        rounded
    }
}

/// Distance from the origin to triangle (a, b, c): to its plane when the foot of the
/// perpendicular lies inside, otherwise to the nearest edge.
fn distance_to_triangle(a: DVec3, b: DVec3, c: DVec3) -> f64 {
    let n = (b - a).cross(c - a);
    let inside = [(a, b), (b, c), (c, a)]
        .iter()
        .all(|&(p, q)| (q - p).cross(-p).dot(n) >= 0.0);
    if inside && n.length_squared() > 0.0 {
        return a.dot(n).abs() / n.length();
    }
    [(a, b), (b, c), (c, a)]
        .iter()
        .map(|&(p, q)| distance_to_segment(p, q))
        .fold(f64::INFINITY, f64::min)
}

fn distance_to_segment(p: DVec3, q: DVec3) -> f64 {
    let d = q - p;
    let t = if d.length_squared() > 0.0 {
        (-p.dot(d) / d.length_squared()).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p + t * d).length()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distance_is_to_the_plane_inside_and_to_an_edge_outside() {
        let z = 0.5;
        let (a, b, c) = (
            DVec3::new(-1.0, -1.0, z),
            DVec3::new(1.0, -1.0, z),
            DVec3::new(0.0, 1.0, z),
        );
        assert!((distance_to_triangle(a, b, c) - z).abs() < 1e-12);
        let shift = DVec3::new(0.0, 3.0, 0.0);
        let d = distance_to_triangle(a + shift, b + shift, c + shift);
        assert!((d - (4.0f64 + z * z).sqrt()).abs() < 1e-12, "{d}");
    }
}
