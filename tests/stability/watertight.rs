//! Watertightness.

use super::*;

/// Per vertex, its adjacent triangles; per undirected edge, its two endpoints.
fn adjacency(scene: &Scene) -> (Vec<Vec<usize>>, Vec<(u32, u32)>) {
    let mut around = vec![Vec::new(); scene.positions.len()];
    let mut edges = Vec::new();
    for (t, tri) in scene.triangles.iter().enumerate() {
        for k in 0..3 {
            around[tri[k] as usize].push(t);
            let (a, b) = (tri[k], tri[(k + 1) % 3]);
            if a < b {
                edges.push((a, b));
            }
        }
    }
    (around, edges)
}

/// Unit geometric normal of triangle `t`.
fn face_normal(scene: &Scene, t: usize) -> Vec3 {
    let [a, b, c] = scene.triangle(t);
    (b - a).cross(c - a).normalize()
}

/// Rays through every vertex and every edge midpoint of a closed mesh, from `dist` outside along
/// directions that enter every triangle around the target at more than ~12° from grazing (so a
/// float ulp off the line cannot turn a crossing into a touch). Vertices get three directions:
/// against the vertex normal, tilted by ~35°, and the coordinate axis nearest the normal (exact
/// `±0` components). `t = 1` at the target.
fn rays_at_vertices_and_edges(scene: &Scene, dist: f32, seed: u64) -> Vec<Ray> {
    let (around, edges) = adjacency(scene);
    let normals: Vec<Vec3> = (0..scene.triangle_count())
        .map(|t| face_normal(scene, t))
        .collect();
    let mut rng = common::Rng::new(seed);
    let mut rays = Vec::new();
    let mut push = |target: Vec3, inward: Vec3, faces: &[usize]| {
        if faces.iter().all(|&f| inward.dot(normals[f]) < -0.2) {
            let origin = target - dist * inward;
            rays.push(Ray::new(origin, target - origin, 0.0, f32::INFINITY));
        }
    };
    for (v, faces) in around.iter().enumerate() {
        if faces.is_empty() {
            continue;
        }
        let p = scene.positions[v];
        let n = faces
            .iter()
            .fold(Vec3::ZERO, |s, &f| s + normals[f])
            .normalize();
        let spin = rng.next_f32() * std::f32::consts::TAU;
        let t = tangent(n);
        let t = t * spin.cos() + n.cross(t) * spin.sin();
        let k = n.abs().max_position();
        let mut axis = Vec3::ZERO;
        axis[k] = -n[k].signum();
        push(p, -n, faces);
        push(p, -(n + 0.7 * t).normalize(), faces);
        push(p, axis, faces);
    }
    for &(a, b) in &edges {
        let faces: Vec<usize> = around[a as usize]
            .iter()
            .filter(|f| around[b as usize].contains(f))
            .copied()
            .collect();
        let n = faces
            .iter()
            .fold(Vec3::ZERO, |s, &f| s + normals[f])
            .normalize();
        let m = 0.5 * (scene.positions[a as usize] + scene.positions[b as usize]);
        let tilt = tangent(n) * (rng.next_f32() - 0.5);
        push(m, -(n + tilt).normalize(), &faces);
    }
    rays
}

/// **Bound: zero false misses.** On closed meshes — "sphere", "torus", the smooth "blob" and the
/// scanned-like "bumpy-sphere" — rays aimed from outside at every vertex and every edge midpoint
/// (three directions per vertex, one per edge, all entering the surface) must hit at `t ≤ 1 + 1e-4`
/// (the target is at `t = 1`), on the GPU and the CPU, closest-hit and any-hit. The watertight
/// test accepts zero edge functions on both sides, so no ray slips between triangles sharing an
/// edge or a vertex, axis-aligned directions (`±0` components) included.
#[test]
fn exact_path_is_watertight_at_vertices_and_edge_midpoints() {
    let ctx = common::context();
    let mut total = 0;
    for (k, name) in ["sphere", "torus", "blob", "bumpy-sphere"]
        .into_iter()
        .enumerate()
    {
        let scene = Scene::builtin(name).unwrap();
        let exact = Structure::from(Bvh::build(&scene).unwrap());
        let dist = 0.02 * scene.bounds().diagonal();
        let rays = rays_at_vertices_and_edges(&scene, dist, k as u64 + 1);
        let targets = scene.positions.len() + 3 * scene.triangle_count() / 2;
        assert!(
            rays.len() >= targets,
            "{name}: only {} rays for {targets} targets",
            rays.len()
        );
        total += rays.len();
        for query in [Query::Closest, Query::Any] {
            for (which, hits) in PATHS.iter().zip(exact_hits(&ctx, &exact, &rays, query)) {
                let misses: Vec<_> = rays
                    .iter()
                    .zip(&hits)
                    .filter(|(_, h)| !h.is_hit() || (query == Query::Closest && h.t > 1.0 + 1e-4))
                    .collect();
                assert!(
                    misses.is_empty(),
                    "{name} {which} {query:?}: {} false misses of {}, first {:?}",
                    misses.len(),
                    rays.len(),
                    misses[0]
                );
            }
        }
    }
    println!("watertight: {total} rays at vertices and edge midpoints, no false miss");
}

/// **Bound: zero false misses along a face's plane.** Rays travelling exactly in the plane of one
/// face of the built-in cube (its faces on the planes ±1) and aimed at that face's edge with a
/// neighbouring face, along the neighbour's axis, with every sign of their zero components, hit
/// the neighbour at the edge, on the GPU and the CPU, closest-hit and any-hit. The origin lies on
/// a plane of the BVH nodes' boxes there; a box plane decoded exactly at the face made the slab
/// test (`1/±0` taken as `±f32::MAX`) close the box at `t = 0` for one sign of zero, so a ray
/// along an axis missed the edges of axis-aligned geometry (half the sign combinations at an
/// edge, three of four at a corner); the nodes' planes now lie strictly outside their triangles.
#[test]
fn axis_rays_in_a_face_plane_hit_the_edge_they_aim_at() {
    let ctx = common::context();
    let scene = Scene::builtin("cube").unwrap();
    let exact = Structure::from(Bvh::build(&scene).unwrap());
    let dist = 2.0;
    let mut rays = Vec::new();
    for a in 0..3 {
        for s in [-1.0f32, 1.0] {
            for b in (0..3).filter(|&b| b != a) {
                let c = 3 - a - b;
                for t in [-1.0f32, 1.0] {
                    for along in [-1.0f32, -0.5, 0.0, 0.37, 1.0] {
                        for zeros in 0..4u32 {
                            let mut target = Vec3::ZERO;
                            target[a] = s;
                            target[b] = t;
                            target[c] = along;
                            let mut dir = Vec3::ZERO;
                            dir[a] = -s;
                            dir[b] = if zeros & 1 == 0 { 0.0 } else { -0.0 };
                            dir[c] = if zeros & 2 == 0 { 0.0 } else { -0.0 };
                            let origin = target - dist * dir;
                            rays.push(Ray::new(origin, dir, 0.0, f32::INFINITY));
                        }
                    }
                }
            }
        }
    }
    for query in [Query::Closest, Query::Any] {
        for (which, hits) in PATHS.iter().zip(exact_hits(&ctx, &exact, &rays, query)) {
            let misses: Vec<_> = rays
                .iter()
                .zip(&hits)
                .filter(|(_, h)| {
                    !h.is_hit() || (query == Query::Closest && (h.t - dist).abs() > 1e-5)
                })
                .collect();
            assert!(
                misses.is_empty(),
                "cube {which} {query:?}: {} false misses of {}, first {:?}",
                misses.len(),
                rays.len(),
                misses[0]
            );
        }
    }
}
