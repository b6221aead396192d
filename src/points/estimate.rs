//! What a point file may lack, and what none says: a normal per point, and the spacing of the
//! samples around it. Both start from each point's nearest neighbours, found once per call in a
//! k-d tree (kiddo's `ImmutableKdTree`, which, unlike its mutable tree, accepts any number of
//! points sharing a coordinate, as flat scans do).
//!
//! **Duplicates.** Positions that occur more than once (meshes exported with vertices split at
//! seams, scans merged twice) are searched once: the neighbours of a point are other *distinct*
//! positions, and every copy gets the estimate of its position. So a neighbourhood is never a
//! pile of copies (which would give no plane and no distance), and a duplicated cloud gets the
//! normals and spacing of the cloud without its copies.
//!
//! **Normals** follow Hoppe, DeRose, Duchamp, McDonald & Stuetzle, "Surface Reconstruction from
//! Unorganized Points", SIGGRAPH 1992, §3.2–3.3:
//! * the tangent plane of a point is the least-squares plane of the point and its
//!   [`NORMAL_NEIGHBOURS`] = 12 nearest other positions: the normal is the eigenvector of the
//!   smallest eigenvalue of their covariance, found by Jacobi rotations in `f64`
//!   ([`symmetric_eigen`]), which stay accurate for repeated eigenvalues. A neighbourhood too
//!   thin to span a plane (a scan line: the middle eigenvalue below [`THIN`] of the largest) is
//!   widened, doubling, until it spans one (or reaches [`WIDEST`]);
//! * the planes are oriented consistently by propagation along a minimum spanning tree of the
//!   symmetric k-nearest-neighbour graph, whose edges cost `1 − |nᵢ·nⱼ|`: crossing from a plane to
//!   a nearly parallel one first, so that a flip is decided where it is least ambiguous;
//! * each connected component of that graph then gets one sign for all its normals, which the
//!   paper fixes by pointing the normal of the highest point (largest z) along +z. That fails
//!   where the highest point's normal is horizontal (a wall, a y-up terrain) and rests on one
//!   point. Here the sign rests on all points, with the divergence theorem: over a closed
//!   surface, the vector area `Σ aᵢnᵢ` (aᵢ the area a point stands for) vanishes, and the flux
//!   `Σ aᵢ nᵢ·(pᵢ − c)` of the field from the centroid `c` is three times the enclosed volume,
//!   positive when the normals point out. So a component whose vector area is under
//!   [`OPEN`] = ½ of its total area is taken as closed (or nearly: a sphere with holes, a box
//!   without a lid) and made to point outwards; one above is an open sheet (terrain, a wall, a
//!   flat square, a bowl) and its vector area is made to point along the positive side of the
//!   axis it is largest along (ties: z, then y, then x), so that terrain faces up whether the
//!   scene is z-up or y-up.
//!
//! Like the paper's, the propagation takes each connected part for one sheet. Sheets that touch
//! tangentially with opposite normals (a ball resting on a floor: at the contact, the ball's
//! normal points down and the floor's up) are joined by edges between parallel planes, and one of
//! them comes out flipped; no local test tells those edges from a sheet's own.
//!
//! **Spacing** is the side of the square of surface a point stands for: with `r_k` the distance
//! to its k-th nearest other position, a uniform density of ρ points per unit area puts `k`
//! points in the disc `π r_k² ρ = k`, so `√(π/k)·r_k = 1/√ρ`. `k` is [`SPACING_NEIGHBOURS`] = 8
//! (fewer in clouds of fewer distinct positions). Counting distinct positions keeps it above 0;
//! it is floored anyway, at the step between float32 values at the cloud's largest coordinate
//! (finer than that, positions are not resolved across the whole cloud), so that it is positive
//! for any input, even positions a denormal apart. It is capped at [`OUTLIER_CAP`] times the
//! median of its neighbours' spacings, so that a stray point is not splatted as a disc as wide
//! as its distance from the rest.
//!
//! Every step is deterministic: per-point work is written to its own slot, sums over points
//! run in index order, and sorts are by total orders with indices breaking ties, so the result
//! is the same bits whatever the number of threads.

use std::f64::consts::PI;
use std::num::NonZero;

use glam::{DVec3, Vec3};
use kiddo::immutable::float::kdtree::ImmutableKdTree;
use kiddo::SquaredEuclidean;
use rayon::prelude::*;

/// Other positions whose plane a point's normal is fitted to (the point itself is the 13th).
/// Hoppe et al. use a "k-neighbourhood" of about this size; fewer make noisy normals, more round
/// off edges and cost time.
const NORMAL_NEIGHBOURS: usize = 12;

/// Neighbours whose distance measures the spacing: the k of `√(π/k)·r_k`. Eight reach past the
/// nearest ring of a regular grid, so that one missing point does not change the estimate much.
const SPACING_NEIGHBOURS: usize = 8;

/// A neighbourhood is too thin to span a plane when its middle eigenvalue is below this fraction
/// of its largest: its points then lie within 1% of their extent of one line.
const THIN: f64 = 1.0e-4;

/// Most neighbours a thin neighbourhood is widened to (12 doubled 7 times): enough to reach
/// across scan lines 60 samples apart, and a bound on the work for a cloud that is a long
/// straight line somewhere, whose points keep a normal perpendicular to it.
const WIDEST: usize = NORMAL_NEIGHBOURS << 7;

/// A component whose vector area `|Σ aᵢnᵢ|` is at least this fraction of its area `Σ aᵢ` is an
/// open sheet (a hemisphere is exactly ½, a plane 1, a closed surface 0).
const OPEN: f64 = 0.5;

/// Positions in `f32`, items as `u32` (clouds of up to 2³² distinct positions), 32 per leaf
/// (kiddo's default).
type Tree = ImmutableKdTree<f32, u32, 3, 32>;

/// What a cloud's points lack: unit normals when `normals` (for a cloud that has none), oriented
/// consistently per connected part, and the spacing around each point (module documentation),
/// from one neighbour search. `positions` are finite ([`super::PointCloud::new`] checks); any
/// number of them is accepted, including duplicates and tiny clouds.
pub(super) fn estimate(positions: &[Vec3], normals: bool) -> (Option<Vec<Vec3>>, Vec<f32>) {
    let k = if normals {
        NORMAL_NEIGHBOURS.max(SPACING_NEIGHBOURS)
    } else {
        SPACING_NEIGHBOURS
    };
    let hoods = Neighbourhoods::new(positions, k);
    let normals = normals.then(|| normals_of(&hoods));
    (normals, spacing_of(&hoods, positions))
}

/// Unit normals of every point of `hoods`, oriented (the first [`NORMAL_NEIGHBOURS`] of each
/// row are its plane's).
fn normals_of(hoods: &Neighbourhoods) -> Vec<Vec3> {
    let planes: Vec<Vec3> = (0..hoods.distinct.len())
        .into_par_iter()
        .map(|u| hoods.plane_normal(u))
        .collect();
    let oriented = orient(hoods, &planes);
    hoods
        .of_point
        .iter()
        .map(|&u| oriented[u as usize])
        .collect()
}

/// The spacing of every point of `hoods` (the first [`SPACING_NEIGHBOURS`] of each row are the
/// ones it is measured to).
fn spacing_of(hoods: &Neighbourhoods, positions: &[Vec3]) -> Vec<f32> {
    let k = SPACING_NEIGHBOURS.min(hoods.k);
    let largest = positions
        .iter()
        .map(|p| p.abs().max_element())
        .fold(0.0f32, f32::max);
    let floor = (largest * f32::EPSILON).max(f32::MIN_POSITIVE);
    let factor = (PI / k.max(1) as f64).sqrt();
    let raw: Vec<f32> = (0..hoods.distinct.len())
        .into_par_iter()
        .map(|u| {
            let r_k = hoods.row(u)[..k]
                .last()
                .map_or(0.0, |&v| hoods.distance(u, v as usize));
            ((factor * r_k) as f32).max(floor)
        })
        .collect();
    // A point at a border, a corner or apart from the rest (a stray return of the scanner)
    // finds its k-th neighbour far away, and would stand for a disc reaching far past the
    // surface: no point stands for more than OUTLIER_CAP times the median of its neighbours'.
    let per_distinct: Vec<f32> = (0..hoods.distinct.len())
        .into_par_iter()
        .map(|u| {
            let mut around: Vec<f32> = hoods.row(u)[..k].iter().map(|&v| raw[v as usize]).collect();
            if around.is_empty() {
                return raw[u];
            }
            around.sort_by(f32::total_cmp);
            raw[u].min(OUTLIER_CAP * around[around.len() / 2])
        })
        .collect();
    hoods
        .of_point
        .iter()
        .map(|&u| per_distinct[u as usize])
        .collect()
}

/// Most a point's spacing may exceed the median of its neighbours' ([`spacing_of`]): a border
/// point of a regular grid measures about 1.4 times an interior one, a corner about 2, so 2
/// leaves borders as they are and brings a lone point's disc down to its surroundings'.
const OUTLIER_CAP: f32 = 2.0;

/// The distinct positions of a cloud, a k-d tree over them, and the `k` nearest other distinct
/// positions of each: the neighbour search [`normals_of`] and [`spacing_of`] share.
struct Neighbourhoods {
    /// Distinct positions, in the order of their first occurrence.
    distinct: Vec<Vec3>,
    /// Per input point, the index of its position in `distinct`.
    of_point: Vec<u32>,
    tree: Tree,
    /// Neighbours per distinct position: the `k` asked for, or all others when fewer.
    k: usize,
    /// Row `u` (`k` entries, nearest first) holds the neighbours of `distinct[u]`.
    table: Vec<u32>,
}

impl Neighbourhoods {
    fn new(positions: &[Vec3], k: usize) -> Neighbourhoods {
        let (distinct, of_point) = distinct_positions(positions);
        let points: Vec<[f32; 3]> = distinct.iter().map(|p| p.to_array()).collect();
        let tree = Tree::new_from_slice(&points);
        let k = k.min(distinct.len().saturating_sub(1));
        let mut table = vec![0u32; distinct.len() * k];
        if k > 0 {
            table.par_chunks_mut(k).enumerate().for_each(|(u, row)| {
                for (slot, v) in row.iter_mut().zip(nearest_others(&tree, &points[u], u, k)) {
                    *slot = v;
                }
            });
        }
        Neighbourhoods {
            distinct,
            of_point,
            tree,
            k,
            table,
        }
    }

    /// The `k` nearest other positions of `distinct[u]`, nearest first.
    fn row(&self, u: usize) -> &[u32] {
        &self.table[u * self.k..(u + 1) * self.k]
    }

    /// Distance between two distinct positions, in `f64` (positive, however close they are).
    fn distance(&self, u: usize, v: usize) -> f64 {
        self.distinct[u]
            .as_dvec3()
            .distance(self.distinct[v].as_dvec3())
    }

    /// The unit normal of the least-squares plane through `distinct[u]` and its neighbours,
    /// unoriented; the neighbourhood is doubled while it is too thin to span a plane, up to
    /// [`WIDEST`] neighbours or the whole cloud.
    fn plane_normal(&self, u: usize) -> Vec3 {
        let widest = self.distinct.len().saturating_sub(1).min(WIDEST);
        let mut count = self.k;
        let mut wider = Vec::new();
        loop {
            let neighbours = if count == self.k {
                self.row(u)
            } else {
                wider.clear();
                wider.extend(nearest_others(
                    &self.tree,
                    &self.distinct[u].to_array(),
                    u,
                    count,
                ));
                wider.as_slice()
            };
            let (values, vectors) = symmetric_eigen(self.covariance(u, neighbours));
            let mut order = [0, 1, 2];
            order.sort_by(|&i, &j| values[i].total_cmp(&values[j]));
            let thin = values[order[1]] <= THIN * values[order[2]];
            if !thin || count >= widest {
                return vectors[order[0]].as_vec3().normalize_or(Vec3::Z);
            }
            count = (count * 2).min(widest);
        }
    }

    /// Covariance of `distinct[u]` and `neighbours` about their mean, in `f64`, from their
    /// offsets to `distinct[u]`: those are exact (differences of nearby `f32` values fit an
    /// `f64`), so a plane along an axis gives exact zeros, however far from the origin it lies.
    fn covariance(&self, u: usize, neighbours: &[u32]) -> [[f64; 3]; 3] {
        let origin = self.distinct[u].as_dvec3();
        let offsets = || {
            std::iter::once(DVec3::ZERO).chain(
                neighbours
                    .iter()
                    .map(move |&v| self.distinct[v as usize].as_dvec3() - origin),
            )
        };
        let mean = offsets().sum::<DVec3>() / (neighbours.len() + 1) as f64;
        let mut c = [[0.0; 3]; 3];
        for d in offsets().map(|d| (d - mean).to_array()) {
            for (i, row) in c.iter_mut().enumerate() {
                for (j, entry) in row.iter_mut().enumerate() {
                    *entry += d[i] * d[j];
                }
            }
        }
        c
    }
}

/// The `count` nearest positions in `tree` to `query` (`distinct[u]`) other than `u` itself,
/// nearest first (kiddo sorts by distance; equal distances come in the tree's fixed order).
fn nearest_others(
    tree: &Tree,
    query: &[f32; 3],
    u: usize,
    count: usize,
) -> impl Iterator<Item = u32> {
    tree.nearest_n::<SquaredEuclidean>(query, NonZero::<usize>::MIN.saturating_add(count))
        .into_iter()
        .map(|n| n.item)
        .filter(move |&v| v as usize != u)
        .take(count)
}

/// The distinct positions of `positions` in the order of first occurrence, and per point the
/// index of its position among them. Positions are equal when their coordinates are (−0 = +0).
fn distinct_positions(positions: &[Vec3]) -> (Vec<Vec3>, Vec<u32>) {
    let key = |i: u32| {
        (positions[i as usize] + Vec3::ZERO)
            .to_array()
            .map(f32::to_bits)
    };
    let mut order: Vec<u32> = (0..positions.len() as u32).collect();
    order.par_sort_unstable_by_key(|&i| (key(i), i));
    // Per point, the first point at its position (the lowest index of its group).
    let mut first: Vec<u32> = (0..positions.len() as u32).collect();
    for group in order.chunk_by(|&a, &b| key(a) == key(b)) {
        for &i in group {
            first[i as usize] = group[0];
        }
    }
    let mut distinct = Vec::new();
    let mut of_point = vec![0u32; positions.len()];
    for (i, &f) in first.iter().enumerate() {
        if f as usize == i {
            of_point[i] = distinct.len() as u32;
            distinct.push(positions[i]);
        } else {
            of_point[i] = of_point[f as usize];
        }
    }
    (distinct, of_point)
}

/// Orients `planes` (one unit normal per distinct position) consistently: along a minimum
/// spanning tree of the symmetric k-nearest-neighbour graph from each component's lowest index,
/// then each component by the divergence-theorem rule of the module documentation.
fn orient(hoods: &Neighbourhoods, planes: &[Vec3]) -> Vec<Vec3> {
    let n = planes.len();
    // Each edge of the symmetric graph once: from u to a neighbour v when u < v, or when u is
    // not among v's neighbours (then v never lists it). The cost is sin²θ = 1 − cos²θ, which
    // orders edges as Hoppe's 1 − |cos θ| does (so gives the same tree) but keeps its
    // precision for nearly parallel normals, which are most of them.
    let mut edges: Vec<(f32, u32, u32)> = (0..n)
        .into_par_iter()
        .flat_map_iter(|u| {
            let ui = u as u32;
            hoods
                .row(u)
                .iter()
                .filter(move |&&v| ui < v || !hoods.row(v as usize).contains(&ui))
                .map(move |&v| {
                    let cost = planes[u].cross(planes[v as usize]).length_squared();
                    (cost, ui.min(v), ui.max(v))
                })
        })
        .collect();
    edges.par_sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));

    // Kruskal's algorithm: the cheapest edges that join two trees.
    let mut sets = DisjointSets::new(n);
    let mut degree = vec![0u32; n];
    let mut tree_edges = Vec::with_capacity(n.saturating_sub(1));
    for &(_, a, b) in &edges {
        if sets.union(a, b) {
            tree_edges.push((a, b));
            degree[a as usize] += 1;
            degree[b as usize] += 1;
        }
    }
    drop(edges);
    // The tree as adjacency lists: entries start[u]..start[u + 1] of `adjacent`.
    let mut start = vec![0usize; n + 1];
    for u in 0..n {
        start[u + 1] = start[u] + degree[u] as usize;
    }
    let mut fill = start.clone();
    let mut adjacent = vec![0u32; 2 * tree_edges.len()];
    for &(a, b) in &tree_edges {
        adjacent[fill[a as usize]] = b;
        fill[a as usize] += 1;
        adjacent[fill[b as usize]] = a;
        fill[b as usize] += 1;
    }

    // Propagation: a child takes the sign that agrees with its parent.
    let mut oriented = planes.to_vec();
    let mut component = vec![u32::MAX; n];
    let mut components = 0u32;
    let mut queue = Vec::new();
    for root in 0..n {
        if component[root] != u32::MAX {
            continue;
        }
        component[root] = components;
        queue.clear();
        queue.push(root);
        let mut next = 0;
        while let Some(&u) = queue.get(next) {
            next += 1;
            for &v in &adjacent[start[u]..start[u + 1]] {
                let v = v as usize;
                if component[v] == u32::MAX {
                    component[v] = components;
                    if oriented[u].dot(planes[v]) < 0.0 {
                        oriented[v] = -planes[v];
                    }
                    queue.push(v);
                }
            }
        }
        components += 1;
    }

    // One sign per component (module documentation). aᵢ, the area a point stands for, is taken
    // proportional to r_k², its neighbourhood's squared radius.
    let components = components as usize;
    let mut area = vec![0.0f64; components];
    let mut vector_area = vec![DVec3::ZERO; components];
    let mut centroid = vec![DVec3::ZERO; components];
    let mut count = vec![0usize; components];
    let weight = |u: usize| {
        hoods
            .row(u)
            .last()
            .map_or(0.0, |&v| hoods.distance(u, v as usize).powi(2))
    };
    for u in 0..n {
        let c = component[u] as usize;
        let a = weight(u);
        area[c] += a;
        vector_area[c] += a * oriented[u].as_dvec3();
        centroid[c] += hoods.distinct[u].as_dvec3();
        count[c] += 1;
    }
    for (c, &members) in centroid.iter_mut().zip(&count) {
        *c /= members.max(1) as f64;
    }
    let mut flux = vec![0.0f64; components];
    for u in 0..n {
        let c = component[u] as usize;
        flux[c] += weight(u)
            * oriented[u]
                .as_dvec3()
                .dot(hoods.distinct[u].as_dvec3() - centroid[c]);
    }
    let flip: Vec<bool> = (0..components)
        .map(|c| {
            let v = vector_area[c];
            if v.length() >= OPEN * area[c] {
                let dominant = [v.z, v.y, v.x].into_iter().fold(0.0f64, |best, x| {
                    if x.abs() > best.abs() {
                        x
                    } else {
                        best
                    }
                });
                dominant < 0.0
            } else {
                flux[c] < 0.0
            }
        })
        .collect();
    for (normal, &c) in oriented.iter_mut().zip(&component) {
        if flip[c as usize] {
            *normal = -*normal;
        }
    }
    oriented
}

/// Union–find with union by size and path halving (Tarjan & van Leeuwen, "Worst-case analysis
/// of set union algorithms", JACM 1984), for Kruskal's algorithm.
struct DisjointSets {
    parent: Vec<u32>,
    size: Vec<u32>,
}

impl DisjointSets {
    fn new(n: usize) -> DisjointSets {
        DisjointSets {
            parent: (0..n as u32).collect(),
            size: vec![1; n],
        }
    }

    fn find(&mut self, mut x: u32) -> u32 {
        while self.parent[x as usize] != x {
            let grandparent = self.parent[self.parent[x as usize] as usize];
            self.parent[x as usize] = grandparent;
            x = grandparent;
        }
        x
    }

    /// Joins the sets of `a` and `b`; false when they were one already.
    fn union(&mut self, a: u32, b: u32) -> bool {
        let (a, b) = (self.find(a), self.find(b));
        if a == b {
            return false;
        }
        let (big, small) = if self.size[a as usize] >= self.size[b as usize] {
            (a, b)
        } else {
            (b, a)
        };
        self.parent[small as usize] = big;
        self.size[big as usize] += self.size[small as usize];
        true
    }
}

/// Eigenvalues of the symmetric `a` and their unit eigenvectors (same order), by cyclic Jacobi
/// rotations (Golub & Van Loan, *Matrix Computations*, 4th ed., §8.5.2; rotation angles as in
/// Press et al., *Numerical Recipes*, 3rd ed., §11.1). Unlike the closed-form roots of the
/// characteristic cubic, it loses no accuracy when eigenvalues coincide (a flat neighbourhood's
/// two in-plane ones often nearly do), and its eigenvectors are orthonormal by construction.
fn symmetric_eigen(mut a: [[f64; 3]; 3]) -> ([f64; 3], [DVec3; 3]) {
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    // Quadratic convergence: a handful of sweeps suffice; the bound only guards the loop.
    for _ in 0..32 {
        let off = a[0][1] * a[0][1] + a[0][2] * a[0][2] + a[1][2] * a[1][2];
        let diagonal = a[0][0] * a[0][0] + a[1][1] * a[1][1] + a[2][2] * a[2][2];
        if off <= f64::EPSILON * f64::EPSILON * diagonal || off == 0.0 {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if a[p][q] == 0.0 {
                continue;
            }
            // The rotation in the (p, q) plane that zeroes a[p][q]: t = tan φ, the smaller root
            // of t² + 2θt − 1 = 0.
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + theta.hypot(1.0));
            let c = 1.0 / t.hypot(1.0);
            let s = t * c;
            for row in a.iter_mut() {
                let (x, y) = (row[p], row[q]);
                row[p] = c * x - s * y;
                row[q] = s * x + c * y;
            }
            let (x, y) = (a[p], a[q]);
            a[p] = std::array::from_fn(|k| c * x[k] - s * y[k]);
            a[q] = std::array::from_fn(|k| s * x[k] + c * y[k]);
            for row in v.iter_mut() {
                let (x, y) = (row[p], row[q]);
                row[p] = c * x - s * y;
                row[q] = s * x + c * y;
            }
        }
    }
    let column = |j: usize| DVec3::new(v[0][j], v[1][j], v[2][j]);
    (
        [a[0][0], a[1][1], a[2][2]],
        [column(0), column(1), column(2)],
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn normals(positions: &[Vec3]) -> Vec<Vec3> {
        estimate(positions, true).0.expect("normals asked for")
    }

    fn spacing(positions: &[Vec3]) -> Vec<f32> {
        let (_, spacing) = estimate(positions, false);
        assert_eq!(
            spacing,
            estimate(positions, true).1,
            "one search serves both"
        );
        spacing
    }
    use crate::random::{mix64, SplitMix64};

    /// `n` points spread evenly over the sphere of `radius` about `centre` (the Fibonacci
    /// lattice, González, "Measurement of areas on a sphere using Fibonacci and
    /// latitude–longitude lattices", Math. Geosci. 2010).
    fn fibonacci_sphere(n: usize, radius: f32, centre: Vec3) -> Vec<Vec3> {
        let golden = std::f64::consts::PI * (3.0 - 5.0f64.sqrt());
        (0..n)
            .map(|i| {
                let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
                let r = (1.0 - z * z).sqrt();
                let phi = golden * i as f64;
                centre + radius * DVec3::new(r * phi.cos(), r * phi.sin(), z).as_vec3()
            })
            .collect()
    }

    /// A `side × side` grid of spacing `h` in the xy plane at height `z`, without the points
    /// that `keep` rejects.
    fn grid(side: usize, h: f32, keep: impl Fn(f32, f32) -> bool) -> Vec<Vec3> {
        (0..side * side)
            .map(|i| Vec3::new((i % side) as f32 * h, (i / side) as f32 * h, 0.0))
            .filter(|p| keep(p.x, p.y))
            .collect()
    }

    fn degrees(a: Vec3, b: Vec3) -> f32 {
        a.dot(b).clamp(-1.0, 1.0).acos().to_degrees()
    }

    fn assert_outward(points: &[Vec3], normals: &[Vec3], centre: Vec3, max_degrees: f32) {
        for (p, n) in points.iter().zip(normals) {
            let outward = (*p - centre).normalize();
            let angle = degrees(*n, outward);
            assert!(
                angle < max_degrees,
                "normal {n} at {p} is {angle}° off outward"
            );
        }
    }

    fn bits(v: &[Vec3]) -> Vec<[u32; 3]> {
        v.iter().map(|p| p.to_array().map(f32::to_bits)).collect()
    }

    #[test]
    fn jacobi_solves_symmetric_matrices_with_repeated_eigenvalues() {
        let mut rng = SplitMix64::new(mix64(3));
        let mut random = || f64::from(rng.next_f32()) * 2.0 - 1.0;
        for case in 0..200 {
            // A random rotation applied to a diagonal whose values repeat in some cases.
            let axis = DVec3::new(random(), random(), random()).normalize_or(DVec3::Z);
            let r = glam::DMat3::from_axis_angle(axis, random() * 3.0);
            let d = match case % 4 {
                0 => DVec3::new(1.0, 1.0, 2.0),
                1 => DVec3::new(0.0, 0.0, 5.0),
                2 => DVec3::splat(3.0),
                _ => DVec3::new(random(), random(), random()),
            };
            let m = r * glam::DMat3::from_diagonal(d) * r.transpose();
            let a = [0, 1, 2].map(|i| [0, 1, 2].map(|j| m.col(j)[i]));
            let (values, vectors) = symmetric_eigen(a);
            for (k, (&l, &x)) in values.iter().zip(&vectors).enumerate() {
                assert!(
                    (x.length() - 1.0).abs() < 1e-12,
                    "case {case}: |v{k}| = {}",
                    x.length()
                );
                assert!(
                    (m * x - l * x).length() < 1e-12,
                    "case {case}: A v{k} ≠ λ v{k}"
                );
                assert!(x.dot(vectors[(k + 1) % 3]).abs() < 1e-12, "case {case}");
            }
            let mut sorted = values;
            sorted.sort_by(f64::total_cmp);
            let mut expected = d.to_array();
            expected.sort_by(f64::total_cmp);
            for (s, e) in sorted.iter().zip(expected) {
                assert!(
                    (s - e).abs() < 1e-12,
                    "case {case}: {sorted:?} vs {expected:?}"
                );
            }
        }
    }

    #[test]
    fn sphere_normals_all_point_outward() {
        let points = fibonacci_sphere(4000, 1.0, Vec3::ZERO);
        assert_outward(&points, &normals(&points), Vec3::ZERO, 2.0);
    }

    #[test]
    fn two_spheres_are_each_oriented_outward() {
        let centre_b = Vec3::new(5.0, 1.0, 0.0);
        let mut points = fibonacci_sphere(3000, 1.0, Vec3::ZERO);
        points.extend(fibonacci_sphere(1500, 0.5, centre_b));
        let n = normals(&points);
        assert_outward(&points[..3000], &n[..3000], Vec3::ZERO, 2.0);
        assert_outward(&points[3000..], &n[3000..], centre_b, 3.0);
    }

    #[test]
    fn box_faces_point_outward() {
        // The surface of the unit cube, 30 × 30 points a face: sharp edges, closed.
        let side = 30;
        let mut points = Vec::new();
        for axis in 0..3 {
            for face in [0.0, 1.0] {
                for i in 0..side * side {
                    let a = ((i % side) as f32 + 0.5) / side as f32;
                    let b = ((i / side) as f32 + 0.5) / side as f32;
                    let mut p = [face; 3];
                    p[(axis + 1) % 3] = a;
                    p[(axis + 2) % 3] = b;
                    points.push(Vec3::from_array(p));
                }
            }
        }
        let n = normals(&points);
        let centre = Vec3::splat(0.5);
        for (p, n) in points.iter().zip(&n) {
            let d = *p - centre;
            // Away from the edges the normal is the face's, outward.
            let inner = (d.abs().cmplt(Vec3::splat(0.4))).bitmask().count_ones() == 2;
            if inner {
                let face = Vec3::select(d.abs().cmpge(Vec3::splat(0.5)), d.signum(), Vec3::ZERO);
                assert!(degrees(*n, face) < 1.0, "{n} at {p}");
            }
            assert!(n.dot(d) > 0.0, "{n} at {p} points in");
        }
    }

    #[test]
    fn flat_square_normals_are_all_plus_the_axis() {
        let square = grid(40, 0.1, |_, _| true);
        assert!(normals(&square).iter().all(|&n| n == Vec3::Z));
        // The same square as a wall facing x, and as y-up terrain.
        let wall: Vec<Vec3> = square.iter().map(|p| Vec3::new(p.z, p.x, p.y)).collect();
        assert!(normals(&wall).iter().all(|&n| n == Vec3::X));
        let floor: Vec<Vec3> = square.iter().map(|p| Vec3::new(p.x, p.z, p.y)).collect();
        assert!(normals(&floor).iter().all(|&n| n == Vec3::Y));
    }

    #[test]
    fn noisy_plane_normals_are_up() {
        let mut rng = SplitMix64::new(mix64(11));
        let points: Vec<Vec3> = grid(50, 0.1, |_, _| true)
            .into_iter()
            .map(|p| p + Vec3::new(0.0, 0.0, (rng.next_f32() - 0.5) * 0.01))
            .collect();
        for n in normals(&points) {
            assert!(degrees(n, Vec3::Z) < 5.0, "{n}");
        }
    }

    #[test]
    fn plane_with_a_hole_is_one_consistent_sheet() {
        let points = grid(50, 0.1, |x, y| (x - 2.5).hypot(y - 2.5) > 1.0);
        assert!(normals(&points).iter().all(|&n| n == Vec3::Z));
    }

    #[test]
    fn scan_lines_widen_to_a_plane() {
        // Lines along y, points 0.01 apart, the lines 0.3 apart: every point's 12 nearest lie on
        // its own line, which spans no plane.
        let points: Vec<Vec3> = (0..10)
            .flat_map(|line| {
                (0..200).map(move |i| Vec3::new(line as f32 * 0.3, i as f32 * 0.01, 1.0))
            })
            .collect();
        assert!(normals(&points).iter().all(|&n| n == Vec3::Z));
    }

    #[test]
    fn duplicates_get_the_estimates_of_their_position() {
        let sphere = fibonacci_sphere(2000, 1.0, Vec3::ZERO);
        // Every point three times, and the first twenty times more, interleaved.
        let mut points: Vec<Vec3> = sphere.iter().flat_map(|&p| [p, p, p]).collect();
        points.extend(std::iter::repeat_n(sphere[0], 20));
        let (n, s) = (normals(&points), spacing(&points));
        let (n1, s1) = (normals(&sphere), spacing(&sphere));
        for (i, (normal, space)) in n.iter().zip(&s).enumerate() {
            let j = if i < 3 * sphere.len() { i / 3 } else { 0 };
            assert_eq!(normal.to_array(), n1[j].to_array(), "point {i}");
            assert_eq!(*space, s1[j], "point {i}");
        }
        assert_outward(&sphere, &n1, Vec3::ZERO, 2.0);
    }

    #[test]
    fn tiny_clouds_get_finite_estimates() {
        let triangle = [Vec3::ZERO, Vec3::X, Vec3::Y];
        assert!(normals(&triangle).iter().all(|&n| n == Vec3::Z));
        for n in 3..=14 {
            let points = fibonacci_sphere(n, 1.0, Vec3::ZERO);
            let (normal, space) = (normals(&points), spacing(&points));
            assert!(normal
                .iter()
                .all(|n| n.is_finite() && (n.length() - 1.0).abs() < 1e-6));
            assert!(space.iter().all(|&s| s.is_finite() && s > 0.0), "{space:?}");
        }
        // Clouds that the checks before these estimates reject must not panic either.
        for points in [vec![], vec![Vec3::ONE; 5], vec![Vec3::ZERO, Vec3::X]] {
            let (normal, space) = (normals(&points), spacing(&points));
            assert!(normal.iter().all(|n| n.is_finite()));
            assert!(space.iter().all(|&s| s.is_finite() && s > 0.0));
        }
    }

    #[test]
    fn spacing_of_a_grid_is_its_step() {
        let h = 0.1;
        let side = 40;
        let points = grid(side, h, |_, _| true);
        let far = (side - 4) as f32 * h;
        for (p, s) in points.iter().zip(spacing(&points)) {
            if p.x > 3.0 * h && p.y > 3.0 * h && p.x < far && p.y < far {
                assert!((s / h - 1.0).abs() < 0.15, "{s} at {p}");
            }
        }
    }

    #[test]
    fn estimates_do_not_depend_on_threads() {
        let mut rng = SplitMix64::new(mix64(5));
        let mut points: Vec<Vec3> = fibonacci_sphere(20_000, 2.0, Vec3::ONE)
            .into_iter()
            .map(|p| p + 0.003 * Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()))
            .collect();
        points.extend_from_within(..100);
        let run = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .expect("a thread pool of a few threads can be built")
                .install(|| (bits(&normals(&points)), spacing(&points)))
        };
        let one = run(1);
        assert_eq!(one, run(4));
        assert_eq!(one, run(4));
    }

    /// Times both estimates on a cloud the size of the Stanford dragon (437,645 vertices): run
    /// by hand with `cargo test --release --lib points::estimate -- --ignored --nocapture`.
    #[test]
    #[ignore]
    fn time_on_a_dragon_sized_cloud() {
        let mut rng = SplitMix64::new(mix64(7));
        let points: Vec<Vec3> = fibonacci_sphere(437_645, 1.0, Vec3::ZERO)
            .into_iter()
            .map(|p| p * (1.0 + 0.001 * rng.next_f32()))
            .collect();
        let start = std::time::Instant::now();
        let n = normals(&points);
        let after_normals = start.elapsed();
        let s = spacing(&points);
        let total = start.elapsed();
        eprintln!(
            "{} points on {} threads: normals {:.2} s, spacing {:.2} s",
            points.len(),
            rayon::current_num_threads(),
            after_normals.as_secs_f64(),
            (total - after_normals).as_secs_f64()
        );
        assert_outward(&points, &n, Vec3::ZERO, 5.0);
        assert!(s.iter().all(|&s| s > 0.0));
    }
}
