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

use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering};

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
/// and its triangle, grouped by its lower end and sorted there, so that the triangles of one edge
/// lie side by side (an open edge is one alone). In parallel and linear besides the sort of the
/// positions and of each end's few edges: while it runs, 8 bytes per edge, 12 per triangle and
/// 37 per vertex, no hash map (at the paper's scale, 21.85M triangles, 3.5 s instead of 5.5–5.8
/// with a sort of the whole edge list, 16 bytes an edge, on a 2-core Xeon guest).
pub fn topology(scene: &Scene) -> Topology {
    analyse(scene, true)
}

/// [`topology`], its creases only `with_creases` (else empty): the seam probe's
/// [`open_boundary`] needs no normals.
fn analyse(scene: &Scene, with_creases: bool) -> Topology {
    let welded = weld(scene);
    // Ids are vertex indices: below the vertex count.
    let count = welded.len() as u32;
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
    let edges = EdgesByEnd::new(scene, &welded);
    // Angles are at least 0, so their bits order as the angles do.
    let crease: Vec<AtomicU32> = (0..if with_creases {
        scene.triangles.len()
    } else {
        0
    })
        .into_par_iter()
        .map(|_| AtomicU32::new(0))
        .collect();
    let on_open: Vec<AtomicBool> = (0..count)
        .into_par_iter()
        .map(|_| AtomicBool::new(false))
        .collect();
    (0..count)
        .into_par_iter()
        .for_each_init(Vec::new, |run, lower| {
            let words = edges.at(lower);
            let mut k = 0;
            while k < words.len() {
                // The triangles on the edge from `lower` to `upper`: a run of the sorted words.
                let upper = (words[k] >> 32) as u32;
                run.clear();
                run.extend(
                    words[k..]
                        .iter()
                        .take_while(|&&w| (w >> 32) as u32 == upper)
                        .map(|&w| w as u32),
                );
                k += run.len();
                if with_creases && run.len() > MOST_ON_AN_EDGE {
                    for &t in run.iter() {
                        crease[t as usize].fetch_max(180.0f32.to_bits(), Ordering::Relaxed);
                    }
                } else if with_creases {
                    crease_pairs(run, &normals, &crease);
                }
                if run.len() == 1 {
                    on_open[lower as usize].store(true, Ordering::Relaxed);
                    on_open[upper as usize].store(true, Ordering::Relaxed);
                }
            }
        });
    drop(edges);
    let on_open: Vec<bool> = on_open.into_iter().map(AtomicBool::into_inner).collect();
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
fn crease_pairs(run: &[u32], normals: &[Vec3], crease: &[AtomicU32]) {
    for (k, &a) in run.iter().enumerate() {
        for &b in &run[k + 1..] {
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

/// One id per distinct vertex position (`-0.0` and `0.0` the same), per vertex: the position's
/// first vertex's index, so that neighbouring triangles, which a
/// mesh stores near each other, have ends with nearby ids: the edges' counting sort then reads
/// and writes memory nearly in order (ids in the positions' sorted order scattered it across
/// gigabytes at the paper's scale).
fn weld(scene: &Scene) -> Vec<u32> {
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
    let mut first = 0u32;
    for (n, &(key, v)) in by_position.iter().enumerate() {
        // Sorted by position, then index: a position's first vertex comes first.
        if n == 0 || by_position[n - 1].0 != key {
            first = v;
        }
        welded[v as usize] = first;
    }
    welded
}

/// Lower ends whose edges one parallel task sorts.
const ENDS_A_BLOCK: usize = 4096;

/// Every non-degenerate edge of the scene's triangles, grouped by its lower welded end: a
/// counting sort (linear, where a comparison sort of the whole list was most of this analysis at
/// the paper's scale: 65.5M edges), each end's few edges then sorted. An edge is a word, its upper
/// end above its triangle, so that the triangles of one edge lie side by side, in the order of a
/// sort of the whole list: 8 bytes an edge rather than 16.
struct EdgesByEnd {
    /// Where each lower end's words start, and the last one's end.
    starts: Vec<usize>,
    words: Vec<u64>,
}

impl EdgesByEnd {
    /// The edges of `scene`'s triangles between the `welded` ids of their ends (vertex indices).
    fn new(scene: &Scene, welded: &[u32]) -> EdgesByEnd {
        let count = welded.len();
        let ends = |t: &[u32; 3]| -> [Option<(u32, u32)>; 3] {
            let w = t.map(|v| welded[v as usize]);
            std::array::from_fn(|e| {
                let (a, b) = (w[e], w[(e + 1) % 3]);
                (a != b).then(|| (a.min(b), a.max(b)))
            })
        };
        // Counted in 64 bits: a scene of up to 2^31 triangles has up to 3 · 2^31 edges.
        let next: Vec<AtomicU64> = (0..=count)
            .into_par_iter()
            .map(|_| AtomicU64::new(0))
            .collect();
        scene.triangles.par_iter().for_each(|t| {
            for (lower, _) in ends(t).into_iter().flatten() {
                next[lower as usize + 1].fetch_add(1, Ordering::Relaxed);
            }
        });
        let mut total = 0u64;
        let starts: Vec<usize> = next
            .iter()
            .map(|n| {
                total += n.load(Ordering::Relaxed);
                n.store(total, Ordering::Relaxed);
                total as usize
            })
            .collect();
        // Each edge at its lower end's next free slot; within an end in any order, sorted below.
        let slots: Vec<AtomicU64> = (0..total)
            .into_par_iter()
            .map(|_| AtomicU64::new(0))
            .collect();
        scene.triangles.par_iter().enumerate().for_each(|(i, t)| {
            for (lower, upper) in ends(t).into_iter().flatten() {
                let at = next[lower as usize].fetch_add(1, Ordering::Relaxed) as usize;
                slots[at].store(u64::from(upper) << 32 | i as u64, Ordering::Relaxed);
            }
        });
        let mut words: Vec<u64> = slots.into_iter().map(AtomicU64::into_inner).collect();
        // Sorted end by end, in parallel over blocks of ends (whose words lie together).
        let mut blocks = Vec::new();
        let mut rest = words.as_mut_slice();
        for first in (0..count).step_by(ENDS_A_BLOCK) {
            let last = (first + ENDS_A_BLOCK).min(count);
            let (block, tail) = rest.split_at_mut(starts[last] - starts[first]);
            blocks.push((first, last, block));
            rest = tail;
        }
        blocks.into_par_iter().for_each(|(first, last, block)| {
            let base = starts[first];
            for end in first..last {
                block[starts[end] - base..starts[end + 1] - base].sort_unstable();
            }
        });
        EdgesByEnd { starts, words }
    }

    /// The words of the edges whose lower end is `lower`, sorted.
    fn at(&self, lower: u32) -> &[u64] {
        &self.words[self.starts[lower as usize]..self.starts[lower as usize + 1]]
    }
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::{creases, open_boundary, topology, MOST_ON_AN_EDGE};
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

    /// Ten triangles on one edge (a fan, more than `MOST_ON_AN_EDGE`): a crease of 180° for
    /// each (their other edges are each one's alone: open).
    #[test]
    fn a_fan_on_one_edge_is_a_crease_for_all() {
        let mut fan = Scene::new("fan");
        for k in 0..10 {
            let turn = k as f32 * 0.6;
            let tip = Vec3::new(turn.cos(), turn.sin(), 0.5);
            fan.push_object("blade", &[Vec3::ZERO, Vec3::Z, tip], &[[0, 1, 2]]);
        }
        assert_eq!(creases(&fan), vec![180.0; 10]);
        assert!(topology(&fan).open.iter().all(|&o| o));
    }

    /// The grouping of edges by their lower end against a reference that shares nothing with it:
    /// positions and edges matched in hash maps, each edge's triangles compared pair by pair, on
    /// built-in scenes with open rims, creases, fans and vertices split at seams.
    #[test]
    fn edges_grouped_by_end_agree_with_a_map_of_every_edge() {
        use std::collections::HashMap;
        for name in ["default", "bumpy-sphere", "torus", "grove"] {
            let scene = Scene::builtin(name).unwrap();
            let key = |v: u32| {
                (scene.positions[v as usize] + Vec3::ZERO)
                    .to_array()
                    .map(f32::to_bits)
            };
            let mut ids: HashMap<[u32; 3], usize> = HashMap::new();
            let id = |v: u32, ids: &mut HashMap<[u32; 3], usize>| {
                let n = ids.len();
                *ids.entry(key(v)).or_insert(n)
            };
            let mut on_edge: HashMap<(usize, usize), Vec<usize>> = HashMap::new();
            for (i, t) in scene.triangles.iter().enumerate() {
                let w = t.map(|v| id(v, &mut ids));
                for e in 0..3 {
                    let (a, b) = (w[e], w[(e + 1) % 3]);
                    if a != b {
                        on_edge.entry((a.min(b), a.max(b))).or_default().push(i);
                    }
                }
            }
            let normal = |i: usize| {
                let [a, b, c] = scene.triangle(i);
                (b - a).cross(c - a).normalize_or_zero()
            };
            let mut crease = vec![0.0f32; scene.triangles.len()];
            let mut open_end = vec![false; ids.len()];
            for (&(a, b), run) in &on_edge {
                if run.len() == 1 {
                    open_end[a] = true;
                    open_end[b] = true;
                }
                for (k, &x) in run.iter().enumerate() {
                    for &y in &run[k + 1..] {
                        let angle = if run.len() > MOST_ON_AN_EDGE {
                            180.0
                        } else if normal(x) == Vec3::ZERO || normal(y) == Vec3::ZERO {
                            continue;
                        } else {
                            normal(x)
                                .dot(normal(y))
                                .clamp(-1.0, 1.0)
                                .acos()
                                .to_degrees()
                        };
                        crease[x] = crease[x].max(angle);
                        crease[y] = crease[y].max(angle);
                    }
                }
            }
            let open: Vec<bool> = scene
                .triangles
                .iter()
                .map(|t| t.iter().any(|&v| open_end[ids[&key(v)]]))
                .collect();
            let found = topology(&scene);
            assert_eq!(found.open, open, "{name}: open boundary");
            assert_eq!(found.creases, crease, "{name}: creases");
            assert!(
                open.contains(&true) || name != "default",
                "{name}: the reference has an open rim"
            );
        }
    }
}
