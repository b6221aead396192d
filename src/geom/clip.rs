//! Clipping a convex polygon by half-planes and by a triangle, the Sutherland–Hodgman algorithm
//! (Sutherland & Hodgman, "Reentrant Polygon Clipping", CACM 1974), in f64: the RBVH builder cuts
//! a leaf's exposed triangles to the cells they are uncovered over, and tests them against the
//! cells' triangles, with it (`crate::rbvh`'s `raster/exposed.rs`).

use glam::DVec3;

/// The part of the polygon `poly` (x, y in sample space, z carried along linearly) over the
/// triangle `window` (counter-clockwise in x, y): Sutherland–Hodgman clipping against its edges.
pub(crate) fn clip(poly: &[DVec3], window: &[DVec3; 3]) -> Vec<DVec3> {
    let mut out = poly.to_vec();
    for e in 0..3 {
        let (a, b) = (window[e].truncate(), window[(e + 1) % 3].truncate());
        out = clip_half(&out, |q| (b - a).perp_dot(q.truncate() - a));
    }
    out
}

/// The part of the convex polygon `poly` (its points carried along linearly) where `signed` is
/// at least 0: one step of Sutherland–Hodgman clipping. A corner on the line is kept once, and
/// an edge that only touches the line adds no point.
pub(crate) fn clip_half(poly: &[DVec3], signed: impl Fn(DVec3) -> f64) -> Vec<DVec3> {
    let mut out = Vec::with_capacity(poly.len() + 1);
    for (n, &q0) in poly.iter().enumerate() {
        let q1 = poly[(n + 1) % poly.len()];
        let (s0, s1) = (signed(q0), signed(q1));
        if s0 >= 0.0 {
            out.push(q0);
        }
        if (s0 > 0.0 && s1 < 0.0) || (s0 < 0.0 && s1 > 0.0) {
            out.push(q0 + (q1 - q0) * (s0 / (s0 - s1)));
        }
    }
    out
}
