//! Overlap tests of convex shapes in 2D by the separating axis theorem: two convex shapes are
//! apart exactly when their projections onto one of their edges' normals are. The RBVH builder
//! finds the cells of a tile that a projected triangle meets, and whether it meets their bare
//! parts, with them (`crate::rbvh`'s `raster/cells.rs` and `raster/exposed.rs`).

use glam::{DVec2, DVec3};

/// Whether the projected triangle `p` (x, y in sample space) meets the cell square
/// `[i, i + 1] × [j, j + 1]`, edges included: no separating axis among the square's two and the
/// triangle's three edge normals.
pub(crate) fn triangle_meets_square(p: &[DVec3; 3], i: f64, j: f64) -> bool {
    let square = [
        DVec2::new(i, j),
        DVec2::new(i + 1.0, j),
        DVec2::new(i, j + 1.0),
        DVec2::new(i + 1.0, j + 1.0),
    ];
    let tri = p.map(|q| DVec2::new(q.x, q.y));
    let separated = |axis: DVec2| {
        let span = |points: &[DVec2]| {
            points
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), q| {
                    let d = q.dot(axis);
                    (lo.min(d), hi.max(d))
                })
        };
        let (a, b) = (span(&square), span(&tri));
        a.1 < b.0 || b.1 < a.0
    };
    ![DVec2::X, DVec2::Y]
        .into_iter()
        .chain((0..3).map(|e| (tri[(e + 1) % 3] - tri[e]).perp()))
        .any(separated)
}

/// Whether the convex polygons `a` and `b` (vertices in order around each; a segment will do)
/// overlap over some area, or a segment passes through the other's inside: no separating axis
/// among their edges' normals. Sharing an edge or a corner is not overlapping.
pub(crate) fn convex_overlap(a: &[DVec2], b: &[DVec2]) -> bool {
    let span = |points: &[DVec2], axis: DVec2| {
        points
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), q| {
                let d = q.dot(axis);
                (lo.min(d), hi.max(d))
            })
    };
    let separated = |axis: DVec2| {
        let ((a_lo, a_hi), (b_lo, b_hi)) = (span(a, axis), span(b, axis));
        a_hi <= b_lo || b_hi <= a_lo
    };
    !edge_normals(a)
        .chain(edge_normals(b))
        .filter(|axis| *axis != DVec2::ZERO)
        .any(separated)
}

/// The normals of a polygon's edges (not unit).
fn edge_normals(poly: &[DVec2]) -> impl Iterator<Item = DVec2> + '_ {
    (0..poly.len()).map(move |e| (poly[(e + 1) % poly.len()] - poly[e]).perp())
}
