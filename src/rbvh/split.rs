//! Where to split a set of triangles that cannot be one height field: the paper's subdivision
//! strategies (spatial median, modified SAH) and the complementary object split, each returning a
//! partition of the node's triangle order in place.

use std::collections::BTreeMap;

use glam::Vec3;

use super::params::Subdivision;
use crate::bvh::partition;
use crate::geom::Aabb;

/// What the splitter needs of one triangle.
pub(crate) struct SplitPrim {
    pub bounds: Aabb,
    pub centroid: Vec3,
    pub area: f32,
    /// Connected part (vertices welded by position) within its scene object.
    pub component: u32,
}

/// Candidate planes per axis for the modified SAH (the paper's 32).
const SAH_BINS: usize = 32;

/// Splits `order` (non-empty, ≥ 2 entries), whose centroids' box is `centroids`, and returns the
/// size of the first part, always in `1..order.len()`. `by_object` separates connected parts first
/// when the node has several.
pub(crate) fn split(
    prims: &[SplitPrim],
    order: &mut [u32],
    centroids: &Aabb,
    strategy: Subdivision,
    by_object: bool,
    median_only: bool,
) -> usize {
    let axis = centroids.largest_axis();
    if median_only {
        return object_median(prims, order, axis);
    }
    if by_object {
        if let Some(mid) = object_split(prims, order, axis) {
            return mid;
        }
    }
    let mid = match strategy {
        Subdivision::SpatialMedian => {
            let plane = centroids.center()[axis];
            partition(order, |i| prims[i as usize].centroid[axis] < plane)
        }
        Subdivision::AreaSah => area_sah(prims, order, centroids),
    };
    if mid == 0 || mid == order.len() {
        object_median(prims, order, axis)
    } else {
        mid
    }
}

/// Groups the node's connected parts by their mean centroid along `axis` and cuts between groups as
/// near the middle triangle as possible. None when the node is one part.
fn object_split(prims: &[SplitPrim], order: &mut [u32], axis: usize) -> Option<usize> {
    // Sums per part, in the order's order. A node's order holds its parts in runs (its parents
    // partitioned them), so a run is summed beside the map and written back when the part
    // changes: the same additions in the same order, one map lookup a run rather than a
    // triangle (the lookups were a fifth of the recursion's time at the paper's scale).
    let mut parts: BTreeMap<u32, (f32, u32)> = BTreeMap::new();
    let mut run: Option<(u32, (f32, u32))> = None;
    for &i in order.iter() {
        let p = &prims[i as usize];
        let (part, sums) = match run {
            Some((part, sums)) if part == p.component => (part, sums),
            _ => {
                if let Some((part, sums)) = run {
                    parts.insert(part, sums);
                }
                let sums = parts.get(&p.component).copied().unwrap_or((0.0, 0));
                (p.component, sums)
            }
        };
        run = Some((part, (sums.0 + p.centroid[axis], sums.1 + 1)));
    }
    if let Some((part, sums)) = run {
        parts.insert(part, sums);
    }
    if parts.len() < 2 {
        return None;
    }
    let mut ranked: Vec<(f32, u32, u32)> = parts
        .iter()
        .map(|(&c, &(sum, n))| (sum / n as f32, c, n))
        .collect();
    ranked.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    let half = order.len() as u32 / 2;
    let (mut best, mut best_gap, mut acc) = (1, u32::MAX, 0u32);
    for (k, part) in ranked[..ranked.len() - 1].iter().enumerate() {
        acc += part.2;
        if acc.abs_diff(half) < best_gap {
            best_gap = acc.abs_diff(half);
            best = k + 1;
        }
    }
    let mut left: Vec<u32> = ranked[..best].iter().map(|r| r.1).collect();
    left.sort_unstable();
    Some(partition(order, |i| {
        left.binary_search(&prims[i as usize].component).is_ok()
    }))
}

/// The paper's modified SAH: cost = P(left)·A_left + P(right)·A_right with P the box-area ratio
/// and A the *surface area of the triangles*, over 32 bins per axis of the centroid bounds.
fn area_sah(prims: &[SplitPrim], order: &mut [u32], centroids: &Aabb) -> usize {
    let extent = centroids.extent();
    let mut best: Option<(f32, usize, usize)> = None;
    for axis in 0..3 {
        if extent[axis] <= 0.0 {
            continue;
        }
        let scale = SAH_BINS as f32 / extent[axis];
        let lo = centroids.min[axis];
        let bin = |p: &SplitPrim| (((p.centroid[axis] - lo) * scale) as usize).min(SAH_BINS - 1);
        let mut boxes = [Aabb::EMPTY; SAH_BINS];
        let mut areas = [0.0f32; SAH_BINS];
        for &i in order.iter() {
            let p = &prims[i as usize];
            let b = bin(p);
            boxes[b] = boxes[b].union(p.bounds);
            areas[b] += p.area;
        }
        let mut right = [(0.0f32, 0.0f32); SAH_BINS];
        let (mut rb, mut ra) = (Aabb::EMPTY, 0.0);
        for k in (1..SAH_BINS).rev() {
            rb = rb.union(boxes[k]);
            ra += areas[k];
            right[k] = (rb.area(), ra);
        }
        let (mut lb, mut la) = (Aabb::EMPTY, 0.0);
        for k in 1..SAH_BINS {
            lb = lb.union(boxes[k - 1]);
            la += areas[k - 1];
            if lb.is_empty() || right[k].0 == 0.0 && right[k].1 == 0.0 {
                continue;
            }
            let cost = lb.area() * la + right[k].0 * right[k].1;
            if best.is_none_or(|b| cost < b.0) {
                best = Some((cost, axis, k));
            }
        }
    }
    let Some((_, axis, k)) = best else { return 0 };
    let scale = SAH_BINS as f32 / extent[axis];
    let lo = centroids.min[axis];
    partition(order, |i| {
        ((((prims[i as usize].centroid[axis] - lo) * scale) as usize).min(SAH_BINS - 1)) < k
    })
}

/// Half the triangles on each side by centroid along `axis`, ties broken by index (so the result
/// does not depend on the selection algorithm's stability).
fn object_median(prims: &[SplitPrim], order: &mut [u32], axis: usize) -> usize {
    let mid = order.len() / 2;
    order.select_nth_unstable_by(mid, |&a, &b| {
        prims[a as usize].centroid[axis]
            .total_cmp(&prims[b as usize].centroid[axis])
            .then(a.cmp(&b))
    });
    mid
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `split` of `order`, given its centroids' box as the recursion gives it.
    fn split(
        prims: &[SplitPrim],
        order: &mut [u32],
        strategy: Subdivision,
        by_object: bool,
        median_only: bool,
    ) -> usize {
        let centroids = order
            .iter()
            .fold(Aabb::EMPTY, |b, &i| b.grow(prims[i as usize].centroid));
        super::split(prims, order, &centroids, strategy, by_object, median_only)
    }

    /// Unit triangles at x = 0..n, two connected parts (first half, second half).
    fn row(n: usize) -> Vec<SplitPrim> {
        (0..n)
            .map(|i| {
                let c = Vec3::new(i as f32, 0.0, 0.0);
                SplitPrim {
                    bounds: Aabb::from_points([c - Vec3::splat(0.5), c + Vec3::splat(0.5)]),
                    centroid: c,
                    area: 1.0 + i as f32,
                    component: (2 * i / n) as u32,
                }
            })
            .collect()
    }

    fn check(order: &[u32], mid: usize, prims: &[SplitPrim]) {
        assert!(mid > 0 && mid < order.len());
        let max_left = order[..mid]
            .iter()
            .map(|&i| prims[i as usize].centroid.x)
            .fold(f32::MIN, f32::max);
        let min_right = order[mid..]
            .iter()
            .map(|&i| prims[i as usize].centroid.x)
            .fold(f32::MAX, f32::min);
        assert!(max_left <= min_right, "not a spatial partition");
    }

    #[test]
    fn every_strategy_partitions_in_space() {
        let prims = row(40);
        for strategy in [Subdivision::SpatialMedian, Subdivision::AreaSah] {
            for by_object in [false, true] {
                let mut order: Vec<u32> = (0..40).collect();
                let mid = split(&prims, &mut order, strategy, by_object, false);
                check(&order, mid, &prims);
            }
        }
    }

    #[test]
    fn object_split_separates_parts() {
        let prims = row(10);
        let mut order: Vec<u32> = (0..10).rev().collect();
        let mid = split(&prims, &mut order, Subdivision::SpatialMedian, true, false);
        assert!(order[..mid]
            .iter()
            .all(|&i| prims[i as usize].component == 0));
        assert!(order[mid..]
            .iter()
            .all(|&i| prims[i as usize].component == 1));
    }

    #[test]
    fn coincident_centroids_fall_back_to_the_median() {
        let prims: Vec<SplitPrim> = (0..9)
            .map(|_| SplitPrim {
                bounds: Aabb::from_points([Vec3::ZERO, Vec3::ONE]),
                centroid: Vec3::splat(0.5),
                area: 1.0,
                component: 0,
            })
            .collect();
        for strategy in [Subdivision::SpatialMedian, Subdivision::AreaSah] {
            let mut order: Vec<u32> = (0..9).collect();
            assert_eq!(split(&prims, &mut order, strategy, true, false), 4);
        }
    }
}
