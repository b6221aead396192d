//! Where a scene's surface is open — the triangle edges that no other triangle shares, and the
//! triangles beside them — and where it folds: the angle at which each triangle meets its
//! neighbours ([`creases`]).
//!
//! An RBVH leaf's surface ends within a texel of its triangles; where a neighbouring leaf
//! continues the surface the two overlap, but at an *open edge* (a scan's hole, the rim of a
//! sheet) nothing continues it, and the leaf alone must reach the edge (`rbvh::raster`: every
//! cell that a triangle beside it meets is full). Edges are matched by their endpoints' positions, not their
//! vertex indices: OBJ and glTF files split vertices where normals or texture coordinates change,
//! and such an edge is still closed.

use std::sync::atomic::{AtomicU32, Ordering};

use glam::Vec3;
use rayon::prelude::*;

use super::Scene;

/// Per triangle, whether it touches the scene's open boundary: one of its corners lies on an
/// open edge, an edge between two positions that no other triangle has (either way round; a
/// degenerate edge, both ends at one position, is never open). A leaf must reach the boundary
/// through every cell such a triangle meets: a ray that enters the surface a hundredth of a
/// texel from a hole's rim may hit the triangle beside the one that has the open edge.
pub fn open_boundary(scene: &Scene) -> Vec<bool> {
    analyse(scene, false).open
}

/// Per triangle, the largest angle in degrees between its normal (as wound) and the normal of a
/// triangle sharing one of its edges, matched by position as for [`open_boundary`]; 0 for a
/// triangle with no neighbour or a degenerate one. A mesh's crease — an edge of a moulding, a
/// column, a cube — is an edge the surface does not continue smoothly across, which a height field
/// would round by a texel; neighbours wound against each other count as 180°.
pub fn creases(scene: &Scene) -> Vec<f32> {
    topology(scene).creases
}

/// Where a scene's surface is open and where it folds, per triangle: what [`open_boundary`] and
/// [`creases`] return, from one pass over its edges.
pub struct Topology {
    /// Whether the triangle touches the open boundary.
    pub open: Vec<bool>,
    /// The largest angle in degrees at which it meets a neighbour.
    pub creases: Vec<f32>,
}

/// Most triangles on one edge whose normals [`creases`] compares pair by pair; an edge shared by
/// more is a crease of 180° for all of them (no surface continues smoothly through a fan).
const MOST_ON_AN_EDGE: usize = 8;

/// [`open_boundary`] and [`creases`] together: every non-degenerate edge as its two welded ends
/// and its triangle, sorted, so that the triangles of one edge lie side by side (an open edge is
/// one alone). Sorting-based and in parallel, linear besides the sorts: 16 bytes per edge and 12
/// per triangle while it runs, no hash map.
pub fn topology(scene: &Scene) -> Topology {
    analyse(scene, true)
}

/// [`topology`], its creases only `with_creases` (else empty): the seam probe's
/// [`open_boundary`] needs no normals.
fn analyse(scene: &Scene, with_creases: bool) -> Topology {
    let (welded, count) = weld(scene);
    let normals: Vec<Vec3> = if with_creases {
        scene
            .triangles
            .par_iter()
            .map(|t| {
                let [a, b, c] = t.map(|v| scene.positions[v as usize]);
                (b - a).cross(c - a).normalize_or_zero()
            })
            .collect()
    } else {
        Vec::new()
    };
    let mut edges: Vec<(u64, u32)> = scene
        .triangles
        .par_iter()
        .enumerate()
        .flat_map_iter(|(i, t)| {
            let w = t.map(|v| welded[v as usize]);
            (0..3)
                .filter(move |&e| w[e] != w[(e + 1) % 3])
                .map(move |e| (edge_key(w[e], w[(e + 1) % 3]), i as u32))
        })
        .collect();
    edges.par_sort_unstable();
    // Angles are at least 0, so their bits order as the angles do.
    let crease: Vec<AtomicU32> = (0..if with_creases {
        scene.triangles.len()
    } else {
        0
    })
        .map(|_| AtomicU32::new(0))
        .collect();
    let open_ends: Vec<u32> = edges
        .par_chunk_by(|a, b| a.0 == b.0)
        .flat_map_iter(|run| {
            let key = run[0].0;
            if with_creases && run.len() > MOST_ON_AN_EDGE {
                for &(_, t) in run {
                    crease[t as usize].fetch_max(180.0f32.to_bits(), Ordering::Relaxed);
                }
            } else if with_creases {
                crease_pairs(run, &normals, &crease);
            }
            let open = (run.len() == 1).then_some([(key >> 32) as u32, key as u32]);
            open.into_iter().flatten()
        })
        .collect();
    drop(edges);
    let mut on_open = vec![false; count as usize];
    for v in open_ends {
        on_open[v as usize] = true;
    }
    Topology {
        open: scene
            .triangles
            .par_iter()
            .map(|t| t.iter().any(|&v| on_open[welded[v as usize] as usize]))
            .collect(),
        creases: crease
            .into_iter()
            .map(|c| f32::from_bits(c.into_inner()))
            .collect(),
    }
}

/// Each pair of the triangles `run` on one edge: the angle between their `normals` raised into
/// both triangles' `crease` (a degenerate triangle's zero normal compares with none).
fn crease_pairs(run: &[(u64, u32)], normals: &[Vec3], crease: &[AtomicU32]) {
    for (k, &(_, a)) in run.iter().enumerate() {
        for &(_, b) in &run[k + 1..] {
            let (na, nb) = (normals[a as usize], normals[b as usize]);
            if na == Vec3::ZERO || nb == Vec3::ZERO {
                continue;
            }
            let angle = na.dot(nb).clamp(-1.0, 1.0).acos().to_degrees().to_bits();
            crease[a as usize].fetch_max(angle, Ordering::Relaxed);
            crease[b as usize].fetch_max(angle, Ordering::Relaxed);
        }
    }
}

/// One id per distinct vertex position (`-0.0` and `0.0` the same), per vertex, and how many
/// there are.
fn weld(scene: &Scene) -> (Vec<u32>, u32) {
    let mut by_position: Vec<([u32; 3], u32)> = scene
        .positions
        .par_iter()
        .enumerate()
        .map(|(v, &p)| {
            let p = p + Vec3::ZERO;
            ([p.x.to_bits(), p.y.to_bits(), p.z.to_bits()], v as u32)
        })
        .collect();
    by_position.par_sort_unstable();
    let mut welded = vec![0u32; scene.positions.len()];
    let mut count = 0u32;
    for (n, &(key, v)) in by_position.iter().enumerate() {
        if n == 0 || by_position[n - 1].0 != key {
            count += 1;
        }
        welded[v as usize] = count - 1;
    }
    (welded, count)
}

/// An edge between two welded positions, either way round.
fn edge_key(a: u32, b: u32) -> u64 {
    (u64::from(a.min(b)) << 32) | u64::from(a.max(b))
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::{creases, open_boundary};
    use crate::scene::Scene;

    const RIM: [Vec3; 4] = [Vec3::X, Vec3::Y, Vec3::NEG_X, Vec3::NEG_Y];

    /// An octahedron with every vertex stored once per face (as files split vertices at normal
    /// seams), its upper apex written as `-0.0` on every other face: closed, matched by position.
    fn octahedron() -> Scene {
        let mut scene = Scene::new("octahedron");
        for k in 0..4 {
            let (a, b) = (RIM[k], RIM[(k + 1) % 4]);
            let apex = if k % 2 == 0 {
                Vec3::Z
            } else {
                Vec3::new(-0.0, 0.0, 1.0)
            };
            scene.push_object("top", &[a, b, apex], &[[0, 1, 2]]);
            scene.push_object("bottom", &[b, a, Vec3::NEG_Z], &[[0, 1, 2]]);
        }
        scene
    }

    /// The octahedron's faces meet at 70.5° (the supplement of its dihedral angle, 109.5°),
    /// whichever way its vertices are stored; a face turned over meets its neighbours at 180° less
    /// that, and a triangle alone has no crease.
    #[test]
    fn creases_are_the_angles_between_neighbouring_normals() {
        let octahedron_angle = (1.0f32 / 3.0).acos().to_degrees();
        for c in creases(&octahedron()) {
            assert!((c - octahedron_angle).abs() < 1e-3, "{c}");
        }
        let mut turned = octahedron();
        turned.triangles[0].swap(0, 1);
        let c = creases(&turned);
        assert!((c[0] - (180.0 - octahedron_angle)).abs() < 1e-3, "{c:?}");
        let mut alone = Scene::new("alone");
        alone.push_object("t", &[Vec3::ZERO, Vec3::X, Vec3::Y], &[[0, 1, 2]]);
        assert_eq!(creases(&alone), vec![0.0]);
    }

    /// A flat grid has no crease; folding it along a line makes the triangles on both sides of
    /// the fold meet at the fold's angle, and only those.
    #[test]
    fn a_fold_is_a_crease_and_a_plane_is_not() {
        let flat = grid(5, 0.0);
        assert!(creases(&flat).iter().all(|&c| c < 1e-3));
        let folded = grid(5, 40.0);
        let c = creases(&folded);
        let at_fold = c.iter().filter(|&&c| (c - 40.0).abs() < 1e-2).count();
        assert_eq!(at_fold, 10, "{c:?}");
        assert!(
            c.iter().all(|&c| c < 1e-2 || (c - 40.0).abs() < 1e-2),
            "{c:?}"
        );
    }

    /// An `n` × `n` grid of quads (two triangles each) in the plane z = 0, vertex `j · (n + 1) +
    /// i` at column i and row j, its columns from `n / 2` on turned up about their first edge by
    /// `fold_deg`.
    fn grid(n: u32, fold_deg: f32) -> Scene {
        let half = (n / 2) as f32;
        let (sin, cos) = fold_deg.to_radians().sin_cos();
        let positions: Vec<Vec3> = (0..=n)
            .flat_map(|j| {
                (0..=n).map(move |i| {
                    let x = i as f32 - half;
                    if x <= 0.0 {
                        Vec3::new(x, j as f32, 0.0)
                    } else {
                        Vec3::new(x * cos, j as f32, x * sin)
                    }
                })
            })
            .collect();
        let at = |i: u32, j: u32| j * (n + 1) + i;
        let mut triangles = Vec::new();
        for j in 0..n {
            for i in 0..n {
                triangles.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
                triangles.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
            }
        }
        let mut scene = Scene::new("grid");
        scene.push_object("grid", &positions, &triangles);
        scene
    }

    #[test]
    fn a_closed_mesh_has_no_boundary_whatever_its_vertices() {
        assert_eq!(open_boundary(&octahedron()), vec![false; 8]);
    }

    /// A needle triangle from one octahedron vertex to itself and a neighbour: its edge of
    /// length zero is not open, and its other two lie on a closed edge.
    #[test]
    fn a_degenerate_edge_is_not_open() {
        let mut scene = octahedron();
        scene.push_object("needle", &[RIM[0], RIM[0], RIM[1]], &[[0, 1, 2]]);
        assert_eq!(open_boundary(&scene), vec![false; 9]);
    }

    #[test]
    fn every_face_of_an_open_pyramid_touches_its_rim() {
        let mut pyramid = Scene::new("pyramid");
        for k in 0..4 {
            pyramid.push_object("top", &[RIM[k], RIM[(k + 1) % 4], Vec3::Z], &[[0, 1, 2]]);
        }
        assert_eq!(open_boundary(&pyramid), vec![true; 4]);
    }

    /// A 5 × 5 grid of quads (two triangles each) on a plane: a triangle is marked when one of
    /// its corners lies on the grid's rim, by an edge or a corner alone, and only then.
    #[test]
    fn triangles_with_a_corner_on_an_open_edge_are_marked() {
        const N: u32 = 5;
        let grid = grid(N, 0.0);
        let triangles = &grid.triangles;
        let on_rim = |v: u32| {
            let (i, j) = (v % (N + 1), v / (N + 1));
            i == 0 || j == 0 || i == N || j == N
        };
        let expected: Vec<bool> = triangles
            .iter()
            .map(|t| t.iter().any(|&v| on_rim(v)))
            .collect();
        assert_eq!(open_boundary(&grid), expected);
        // The 3 × 3 middle quads stay unmarked.
        assert_eq!(expected.iter().filter(|&&b| !b).count(), 18);
    }
}
