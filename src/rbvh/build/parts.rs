//! The connected parts of a scene's triangles, for the object split (Novák & Dachsbacher 2012:
//! a height field is "one connected part"): vertices welded by position within each object, then
//! joined by the triangles that share them (union–find).

use std::collections::HashMap;

use glam::Vec3;
use rayon::prelude::*;

use crate::scene::Scene;

/// Per triangle, a dense id of its connected part: vertices are welded by position within each
/// scene object (loaders often duplicate vertices along UV or normal seams), then joined by the
/// triangles that share them. Ids are numbered in order of first appearance, so they are
/// deterministic.
///
/// Parts never span objects, so when each object's triangles are one run (as [`Scene::append`]
/// makes them) the objects are found in parallel and numbered one after the other, which is the
/// same numbering; otherwise the whole scene is one run.
pub(super) fn connected_parts(scene: &Scene) -> Vec<u32> {
    let object = |t: usize| scene.object_of_triangle.get(t).copied().unwrap_or(0);
    let mut runs: Vec<std::ops::Range<usize>> = Vec::new();
    for t in 0..scene.triangle_count() {
        match runs.last_mut() {
            Some(run) if object(run.start) == object(t) => run.end = t + 1,
            _ => runs.push(t..t + 1),
        }
    }
    if runs
        .windows(2)
        .any(|w| object(w[0].start) >= object(w[1].start))
    {
        runs.clear();
        runs.push(0..scene.triangle_count());
    }
    let parts: Vec<(Vec<u32>, u32)> = runs
        .par_iter()
        .map(|run| parts_of_run(scene, run.clone()))
        .collect();
    let mut offset = 0;
    let mut ids = Vec::with_capacity(scene.triangle_count());
    for (local, count) in parts {
        ids.extend(local.into_iter().map(|id| id + offset));
        offset += count;
    }
    ids
}

/// [`connected_parts`] of triangles `run`, numbered from 0, and how many parts there are.
///
/// A vertex index remembers its (object, welded vertex) once looked up, so the position map is
/// consulted once per vertex rather than once per corner: a sixth of the lookups on a closed
/// mesh, which take most of the time on a scene of millions of triangles.
fn parts_of_run(scene: &Scene, run: std::ops::Range<usize>) -> (Vec<u32>, u32) {
    const UNSEEN: (u32, u32) = (u32::MAX, u32::MAX);
    let triangles = &scene.triangles[run.clone()];
    let first_vertex = triangles.iter().flatten().copied().min().unwrap_or(0);
    let last_vertex = triangles.iter().flatten().copied().max().unwrap_or(0);
    let mut welded_of_vertex = vec![UNSEEN; (last_vertex - first_vertex) as usize + 1];
    let mut key_of: HashMap<(u32, [u32; 3]), u32> = HashMap::new();
    let mut parent: Vec<u32> = Vec::new();
    let mut corners = Vec::with_capacity(triangles.len());
    for (t, tri) in run.zip(triangles) {
        let object = scene.object_of_triangle.get(t).copied().unwrap_or(0);
        let ids = tri.map(|v| {
            let slot = &mut welded_of_vertex[(v - first_vertex) as usize];
            if slot.0 == object && slot.1 != u32::MAX {
                return slot.1;
            }
            let p = scene.positions[v as usize] + Vec3::ZERO;
            let key = (object, [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()]);
            let welded = *key_of.entry(key).or_insert_with(|| {
                parent.push(parent.len() as u32);
                parent.len() as u32 - 1
            });
            *slot = (object, welded);
            welded
        });
        union(&mut parent, ids[0], ids[1]);
        union(&mut parent, ids[0], ids[2]);
        corners.push(ids[0]);
    }
    let mut dense = vec![u32::MAX; parent.len()];
    let mut count = 0;
    let ids = corners
        .into_iter()
        .map(|v| {
            let root = find(&mut parent, v) as usize;
            if dense[root] == u32::MAX {
                dense[root] = count;
                count += 1;
            }
            dense[root]
        })
        .collect();
    (ids, count)
}

fn find(parent: &mut [u32], mut x: u32) -> u32 {
    while parent[x as usize] != x {
        parent[x as usize] = parent[parent[x as usize] as usize];
        x = parent[x as usize];
    }
    x
}

fn union(parent: &mut [u32], a: u32, b: u32) {
    let (ra, rb) = (find(parent, a), find(parent, b));
    if ra != rb {
        parent[ra.max(rb) as usize] = ra.min(rb);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two triangles welded along a duplicated edge, and one apart, in one object.
    fn object(scene: &mut Scene, x: f32) {
        let p = |a: f32, b: f32| Vec3::new(x + a, b, 0.0);
        scene.push_object(
            "o",
            &[
                p(0.0, 0.0),
                p(1.0, 0.0),
                p(0.0, 1.0),
                // The shared edge again, as a loader splits vertices along a UV seam.
                p(1.0, 0.0),
                p(0.0, 1.0),
                p(1.0, 1.0),
                p(5.0, 5.0),
                p(6.0, 5.0),
                p(5.0, 6.0),
            ],
            &[[0, 1, 2], [3, 5, 4], [6, 7, 8]],
        );
    }

    #[test]
    fn parts_weld_within_an_object_never_across_and_number_by_first_appearance() {
        let mut scene = Scene::new("parts");
        object(&mut scene, 0.0);
        // The same positions in another object: touching, but a part of its own.
        object(&mut scene, 0.0);
        assert_eq!(connected_parts(&scene), [0, 0, 1, 2, 2, 3]);

        // Objects interleaved (public fields allow it): found as one run. The second triangle
        // now belongs to the other object and welds with the fourth; the fifth, in the first
        // object, with the first.
        let mut interleaved = scene.clone();
        interleaved.object_of_triangle = vec![0, 1, 0, 1, 0, 1];
        assert_eq!(connected_parts(&interleaved), [0, 1, 2, 1, 0, 3]);
    }
}
