//! Procedural tessellations of the primitive solids the built-in scenes are made of.
//!
//! Every closed shape shares its vertices between neighbouring triangles (or repeats them
//! bit-for-bit), so a watertight ray/triangle test has no cracks to leak through, and is wound
//! counter-clockwise seen from outside: `cross(b - a, c - a)` points out of the solid. Angles
//! and subdivisions are computed in `f64` and rounded once, so that vertices sit as close to the
//! ideal surface as `f32` allows.

use std::collections::HashMap;
use std::f64::consts::TAU;

use glam::{DVec3, Mat4, Vec3};

/// An indexed triangle mesh under construction.
#[derive(Clone, Debug, Default)]
pub(super) struct Shape {
    pub positions: Vec<Vec3>,
    pub triangles: Vec<[u32; 3]>,
}

impl Shape {
    /// The shape under the affine transform `m` (not mirroring, so windings stay outward).
    pub fn transformed(mut self, m: Mat4) -> Shape {
        for p in &mut self.positions {
            *p = m.transform_point3(*p);
        }
        self
    }
}

/// The index the next pushed vertex will get; shapes stay far below `u32::MAX` vertices.
fn next_index(positions: &[Vec3]) -> u32 {
    positions.len() as u32
}

/// A flat square in y = 0 with x, z ∈ [-half, half], split into `n` × `n` quads, facing +y.
pub(super) fn grid_plane(half: f32, n: u32) -> Shape {
    let coord = |i: u32| half * (2.0 * i as f32 / n as f32 - 1.0);
    let mut shape = Shape::default();
    for i in 0..=n {
        for j in 0..=n {
            shape.positions.push(Vec3::new(coord(i), 0.0, coord(j)));
        }
    }
    let at = |i: u32, j: u32| i * (n + 1) + j;
    for i in 0..n {
        for j in 0..n {
            // Stepping +z then +x turns counter-clockwise seen from +y.
            shape.triangles.push([at(i, j), at(i, j + 1), at(i + 1, j)]);
            shape
                .triangles
                .push([at(i + 1, j), at(i, j + 1), at(i + 1, j + 1)]);
        }
    }
    shape
}

/// Unit directions of an icosahedron subdivided `level` times (20·4^level triangles), with
/// shared edge midpoints so that the result is closed. Returned in `f64` so that displaced
/// spheres can evaluate their displacement before rounding.
pub(super) fn icosphere_directions(level: u32) -> (Vec<DVec3>, Vec<[u32; 3]>) {
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let mut dirs: Vec<DVec3> = [
        [-1.0, t, 0.0],
        [1.0, t, 0.0],
        [-1.0, -t, 0.0],
        [1.0, -t, 0.0],
        [0.0, -1.0, t],
        [0.0, 1.0, t],
        [0.0, -1.0, -t],
        [0.0, 1.0, -t],
        [t, 0.0, -1.0],
        [t, 0.0, 1.0],
        [-t, 0.0, -1.0],
        [-t, 0.0, 1.0],
    ]
    .into_iter()
    .map(|p| DVec3::from_array(p).normalize())
    .collect();
    let mut faces: Vec<[u32; 3]> = [
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ]
    .into_iter()
    .map(|[a, b, c]| {
        // Orient by construction rather than trusting a hand-typed table.
        let [pa, pb, pc] = [a, b, c].map(|i| dirs[i as usize]);
        if (pb - pa).cross(pc - pa).dot(pa + pb + pc) > 0.0 {
            [a, b, c]
        } else {
            [a, c, b]
        }
    })
    .collect();
    for _ in 0..level {
        let mut midpoints: HashMap<(u32, u32), u32> = HashMap::new();
        let mut midpoint = |a: u32, b: u32, dirs: &mut Vec<DVec3>| -> u32 {
            *midpoints.entry((a.min(b), a.max(b))).or_insert_with(|| {
                dirs.push((dirs[a as usize] + dirs[b as usize]).normalize());
                dirs.len() as u32 - 1
            })
        };
        let mut finer = Vec::with_capacity(faces.len() * 4);
        for [a, b, c] in faces {
            let ab = midpoint(a, b, &mut dirs);
            let bc = midpoint(b, c, &mut dirs);
            let ca = midpoint(c, a, &mut dirs);
            finer.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        faces = finer;
    }
    (dirs, faces)
}

/// A closed sphere-like surface: each icosphere direction `d` pushed out to radius `radius(d)`,
/// which must be positive so that the surface stays star-shaped and outward-wound.
pub(super) fn displaced_sphere(level: u32, radius: impl Fn(DVec3) -> f64) -> Shape {
    let (dirs, triangles) = icosphere_directions(level);
    Shape {
        positions: dirs.iter().map(|&d| (d * radius(d)).as_vec3()).collect(),
        triangles,
    }
}

/// A torus around the y axis: tube radius `minor` at distance `major` from the axis,
/// `around` segments along the ring and `across` around the tube.
pub(super) fn torus(major: f64, minor: f64, around: u32, across: u32) -> Shape {
    let mut shape = Shape::default();
    for i in 0..around {
        let u = TAU * f64::from(i) / f64::from(around);
        for j in 0..across {
            let v = TAU * f64::from(j) / f64::from(across);
            let ring = major + minor * v.cos();
            let p = DVec3::new(ring * u.cos(), minor * v.sin(), ring * u.sin());
            shape.positions.push(p.as_vec3());
        }
    }
    let at = |i: u32, j: u32| (i % around) * across + j % across;
    for i in 0..around {
        for j in 0..across {
            // Along the tube (v) first, then along the ring (u): ∂v × ∂u points outwards.
            shape
                .triangles
                .push([at(i, j), at(i, j + 1), at(i + 1, j + 1)]);
            shape
                .triangles
                .push([at(i, j), at(i + 1, j + 1), at(i + 1, j)]);
        }
    }
    shape
}

/// The cube [-1, 1]³ with each face split into `n` × `n` quads. Faces have their own vertices
/// (hard 90° edges), computed from the same exact grid values, so vertices on a shared edge are
/// bit-identical and the cube stays watertight. `n` should be a power of two for exactness.
pub(super) fn cube(n: u32) -> Shape {
    let coord = |i: u32| 2.0 * i as f32 / n as f32 - 1.0;
    let mut shape = Shape::default();
    for axis in 0..3 {
        for side in [-1.0f32, 1.0] {
            let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
            let base = next_index(&shape.positions);
            for i in 0..=n {
                for j in 0..=n {
                    let mut p = Vec3::ZERO;
                    p[axis] = side;
                    p[u] = coord(i);
                    p[v] = coord(j);
                    shape.positions.push(p);
                }
            }
            let at = |i: u32, j: u32| base + i * (n + 1) + j;
            for i in 0..n {
                for j in 0..n {
                    // e_u × e_v = e_axis, so (u, then v) faces +axis; the -axis face is reversed.
                    let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
                    if side > 0.0 {
                        shape.triangles.extend([[a, b, c], [a, c, d]]);
                    } else {
                        shape.triangles.extend([[a, c, b], [a, d, c]]);
                    }
                }
            }
        }
    }
    shape
}

/// `count` points on the unit circle in the plane y = `y`, counter-clockwise seen from +y.
fn ring(count: u32, y: f32) -> impl Iterator<Item = Vec3> {
    (0..count).map(move |k| {
        let a = TAU * f64::from(k) / f64::from(count);
        Vec3::new(a.cos() as f32, y, -a.sin() as f32)
    })
}

/// The cylinder of radius 1 around the y axis with y ∈ [-1, 1], closed by flat caps with
/// sharp rims; the side is split into `rows` bands of `segments` quads.
pub(super) fn cylinder(segments: u32, rows: u32) -> Shape {
    let mut shape = Shape::default();
    for r in 0..=rows {
        shape
            .positions
            .extend(ring(segments, 2.0 * r as f32 / rows as f32 - 1.0));
    }
    let at = |r: u32, k: u32| r * segments + k % segments;
    for r in 0..rows {
        for k in 0..segments {
            let (a, b, c, d) = (at(r, k), at(r + 1, k), at(r + 1, k + 1), at(r, k + 1));
            shape.triangles.extend([[a, c, b], [a, d, c]]);
        }
    }
    let bottom = next_index(&shape.positions);
    shape.positions.push(Vec3::new(0.0, -1.0, 0.0));
    let top = bottom + 1;
    shape.positions.push(Vec3::new(0.0, 1.0, 0.0));
    for k in 0..segments {
        shape.triangles.push([bottom, at(0, k + 1), at(0, k)]);
        shape.triangles.push([top, at(rows, k), at(rows, k + 1)]);
    }
    shape
}

/// The cone with apex (0, 1, 0) over the unit disk at y = -1, with a flat base: a sharp apex
/// and a sharp rim.
pub(super) fn cone(segments: u32) -> Shape {
    let mut shape = Shape::default();
    shape.positions.extend(ring(segments, -1.0));
    let apex = next_index(&shape.positions);
    shape.positions.push(Vec3::Y);
    let center = apex + 1;
    shape.positions.push(Vec3::new(0.0, -1.0, 0.0));
    for k in 0..segments {
        let (a, b) = (k, (k + 1) % segments);
        shape.triangles.push([a, b, apex]);
        shape.triangles.push([center, b, a]);
    }
    shape
}
