//! Binned SAH construction (Wald 2007), parallel and deterministic.
//!
//! Parallelism comes only from `rayon::join` over independent subtrees and from order-independent
//! reductions (bin counts and box unions, which are exact), so the tree is byte-identical whatever
//! the thread count.

use std::time::Instant;

use glam::Vec3;
use rayon::prelude::*;

use super::layout::{ChildRef, GpuNode, GpuTriangle, LEAF_BIT, MAX_NODES, STACK_SIZE};
use crate::geom::Aabb;
use crate::progress::{step, Progress, Quiet};
use crate::scene::Scene;
use crate::{Error, Result};

/// Knobs of the exact BVH build.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BuildParams {
    /// SAH bins per axis.
    pub bins: usize,
    /// Largest leaf the SAH may choose; larger sets are always split.
    pub max_leaf: usize,
    /// Cost of one box-pair test relative to one triangle test in the SAH.
    pub traversal_cost: f32,
    /// From this depth on, nodes are split at the object median instead of by SAH, which bounds the
    /// depth by `median_below_depth + log2(n)` and so keeps it within [`STACK_SIZE`] for any input
    /// (SAH alone can build arbitrarily deep chains on adversarial input).
    pub median_below_depth: u32,
}

impl BuildParams {
    /// 16 bins, leaves of at most 8 triangles, unit traversal cost, median splits from depth 32.
    pub const DEFAULT: BuildParams = BuildParams {
        bins: 16,
        max_leaf: 8,
        traversal_cost: 1.0,
        median_below_depth: 32,
    };
}

impl Default for BuildParams {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// A built exact BVH in its GPU layout, ready to upload or trace on the CPU.
#[derive(Clone, Debug, PartialEq)]
pub struct Bvh {
    /// Node 0 is the root; each node holds both children's boxes.
    pub nodes: Vec<GpuNode>,
    /// Triangles in leaf order.
    pub triangles: Vec<GpuTriangle>,
    /// Bounds of the whole scene.
    pub bounds: Aabb,
    /// Inner nodes on the longest root-to-leaf path, at least 1 (≤ [`STACK_SIZE`], which bounds
    /// the traversal stack by it).
    pub depth: u32,
    /// Wall time of the build in milliseconds.
    pub build_ms: f64,
}

/// Per-triangle build input.
pub(super) struct Prim {
    pub(super) bounds: Aabb,
    pub(super) centroid: Vec3,
}

pub(super) enum BuildNode {
    Leaf {
        bounds: Aabb,
        start: u32,
        count: u32,
    },
    Inner {
        bounds: Aabb,
        /// Inner nodes in this subtree, itself included: where [`pack_with`] places its second
        /// child's nodes, so that the two subtrees are packed in parallel.
        inner: u32,
        /// Levels of inner nodes from this one down to its deepest leaf, itself included.
        depth: u32,
        children: Box<[BuildNode; 2]>,
    },
}

impl BuildNode {
    /// The inner node over `a` and `b`, whose box is `bounds`.
    pub(super) fn inner(bounds: Aabb, a: BuildNode, b: BuildNode) -> BuildNode {
        BuildNode::Inner {
            bounds,
            inner: 1 + a.inner_count() + b.inner_count(),
            depth: 1 + a.depth().max(b.depth()),
            children: Box::new([a, b]),
        }
    }

    pub(super) fn bounds(&self) -> Aabb {
        match self {
            BuildNode::Leaf { bounds, .. } | BuildNode::Inner { bounds, .. } => *bounds,
        }
    }

    /// Inner nodes in the subtree (0 for a leaf).
    fn inner_count(&self) -> u32 {
        match self {
            BuildNode::Leaf { .. } => 0,
            BuildNode::Inner { inner, .. } => *inner,
        }
    }

    /// Levels of inner nodes down to the deepest leaf (0 for a leaf).
    fn depth(&self) -> u32 {
        match self {
            BuildNode::Leaf { .. } => 0,
            BuildNode::Inner { depth, .. } => *depth,
        }
    }
}

/// Frees a built tree, its two halves in parallel where they are large (the exact BVH's at the
/// paper's scale has 12.1M inner nodes, each a box of its own).
pub(super) fn free(node: BuildNode) {
    if let BuildNode::Inner {
        inner, children, ..
    } = node
    {
        let [a, b] = *children;
        join_halves(inner as usize >= PARALLEL_THRESHOLD, || free(a), || free(b));
    }
}

/// Subtrees smaller than this are built on the calling thread.
pub(super) const PARALLEL_THRESHOLD: usize = 4096;

impl Bvh {
    /// Builds with [`BuildParams::DEFAULT`].
    pub fn build(scene: &Scene) -> Result<Bvh> {
        Self::build_with(scene, &BuildParams::DEFAULT)
    }

    /// Builds with explicit `params`. Fails with [`Error::InvalidParameter`] when `bins` is
    /// outside 2..=256, `max_leaf` outside 1..=64, `median_below_depth` leaves no room in
    /// [`STACK_SIZE`], the scene has 2^31 triangles or more, or the tree still comes out deeper
    /// than the stack, or the scene is a point cloud without triangles; with
    /// [`Error::InvalidGeometry`] from [`Scene::validate`] for a malformed scene.
    pub fn build_with(scene: &Scene, params: &BuildParams) -> Result<Bvh> {
        Self::build_observed(scene, params, &Quiet)
    }

    /// [`Bvh::build_with`], reporting to `progress` the triangles placed in leaves.
    pub fn build_observed(
        scene: &Scene,
        params: &BuildParams,
        progress: &dyn Progress,
    ) -> Result<Bvh> {
        if params.bins < 2 || params.bins > 256 {
            return Err(Error::param(
                "bins",
                format!("{} is outside 2..=256", params.bins),
            ));
        }
        if params.max_leaf == 0 || params.max_leaf > 64 {
            return Err(Error::param(
                "max_leaf",
                format!("{} is outside 1..=64", params.max_leaf),
            ));
        }
        if params.median_below_depth + 1 >= STACK_SIZE {
            return Err(Error::param(
                "median_below_depth",
                format!(
                    "{} leaves no room below the {STACK_SIZE}-entry stack",
                    params.median_below_depth
                ),
            ));
        }
        let start = Instant::now();
        let prims = prims(scene)?;
        let mut order: Vec<u32> = (0..prims.len() as u32).collect();
        let builder = Builder {
            prims: &prims,
            params,
            progress,
            groupable: None,
        };
        let root = step(
            progress,
            "building the exact BVH (triangles)",
            prims.len() as u64,
            || (!order.is_empty()).then(|| builder.build(&mut order, 0, 0)),
        );
        let bvh = assemble(scene, root.as_ref(), &order, start);
        if let Some(root) = root {
            free(root);
        }
        bvh
    }

    /// Bytes of the node array.
    pub fn tree_bytes(&self) -> u64 {
        std::mem::size_of_val(self.nodes.as_slice()) as u64
    }

    /// Bytes of the triangle array.
    pub fn triangle_bytes(&self) -> u64 {
        std::mem::size_of_val(self.triangles.as_slice()) as u64
    }
}

/// The build input of `scene`'s triangles, once the scene is checked: [`Scene::validate`], fewer
/// than 2^31 triangles, and triangles at all where it is a point cloud.
pub(super) fn prims(scene: &Scene) -> Result<Vec<Prim>> {
    check_triangles(scene)?;
    Ok((0..scene.triangle_count())
        .into_par_iter()
        .map(|i| {
            let bounds = Aabb::from_points(scene.triangle(i));
            Prim {
                bounds,
                centroid: bounds.center(),
            }
        })
        .collect())
}

/// The checks of [`prims`]: a valid scene, fewer than 2^31 triangles, and triangles rather than
/// only points.
pub(super) fn check_triangles(scene: &Scene) -> Result<()> {
    scene.validate()?;
    if scene.triangle_count() >= LEAF_BIT as usize {
        return Err(Error::param(
            "scene",
            format!("{} triangles exceed 2^31", scene.triangle_count()),
        ));
    }
    if scene.triangle_count() == 0 && scene.points.is_some() {
        return Err(Error::param(
            "scene",
            format!(
                "{} is a point cloud: it has no triangles for an exact BVH to trace; build an RBVH \
                 of its points instead",
                scene.name
            ),
        ));
    }
    Ok(())
}

/// The packed [`Bvh`] of the tree `root` over `scene`'s triangles in leaf `order`, built since
/// `start`; an error when it is deeper than the traversal stack.
fn assemble(scene: &Scene, root: Option<&BuildNode>, order: &[u32], start: Instant) -> Result<Bvh> {
    let (nodes, depth) = pack(root, "median_below_depth")?;
    let triangles = order
        .par_iter()
        .map(|&i| GpuTriangle::new(scene.triangle(i as usize), i))
        .collect();
    Ok(Bvh {
        nodes,
        triangles,
        bounds: root.map_or(Aabb::EMPTY, BuildNode::bounds),
        depth,
        build_ms: start.elapsed().as_secs_f64() * 1e3,
    })
}

/// The node array of the tree `root` (depth-first, node 0 the root) and its depth (at least 1);
/// an error naming `parameter` (what bounds the depth) when it is deeper than the traversal
/// stack. A leaf refers to its triangles: `LEAF_BIT | start`, `count`.
pub(super) fn pack(root: Option<&BuildNode>, parameter: &str) -> Result<(Vec<GpuNode>, u32)> {
    pack_with(root, parameter, &|bounds, start, count| ChildRef {
        bounds,
        child: LEAF_BIT | start,
        count,
    })
}

/// What a tree over finished leaves places ([`tree_over`]).
pub(crate) enum Placed {
    /// A finished leaf (its reference and box): one child of the tree's nodes, as it is.
    Leaf(ChildRef),
    /// One triangle, by its box: the SAH may put it in a leaf with other triangles.
    Triangle(Aabb),
}

/// A tree over finished leaves and loose triangles, `items`: each finished leaf (absent ones are
/// skipped) becomes one
/// child of the tree's nodes, and the triangles go into leaves of at most `max_group` of them,
/// as this builder's SAH, sweeping rather than binning, places and groups them (a set holding a
/// finished leaf is always split). The node array (depth-first, node 0 the root), its depth, as
/// [`pack`] gives them, and the triangles' items in the order their leaves refer to them: a triangle leaf is
/// `LEAF_BIT | (base + first)`, `count` into that order placed from `base` on.
///
/// The RBVH's upper tree where it is cheaper than the construction's own (issue "A tree that
/// earns its leaves"; `crate::rbvh`'s `upper_tree`). Its SAH weighs every place between the
/// items sorted by centroid (`Builder::build_sorted`), not bins as the exact BVH's does: a few
/// hundred thousand leaves of very different sizes (a courtyard's walls beside a dragon's
/// tiles) bin poorly. On the paper-scale scene at Q2 a primary ray went through 65 inner nodes
/// of a 16-bin tree, 62 of a 64-bin one and 59 of a 256-bin one (before the exact parts); at
/// 1b3db26 63.4 of the 256-bin tree and 60.5 of the sweep's, the exact BVH 60.7
/// (docs/speed.md, "A tree over the leaves by sweep"). The items are sorted along each axis
/// once, and each split partitions the three orders (`Builder::build_sorted`): O(n log n).
pub(crate) fn tree_over(
    items: &[Placed],
    max_group: usize,
    base: u32,
) -> Result<(Vec<GpuNode>, u32, Vec<u32>)> {
    // Absent leaves hold nothing and have no box to place.
    let present: Vec<u32> = (0..items.len() as u32)
        .filter(|&i| !matches!(&items[i as usize], Placed::Leaf(leaf) if leaf.is_absent()))
        .collect();
    let items: Vec<&Placed> = present.iter().map(|&i| &items[i as usize]).collect();
    let prims: Vec<Prim> = items
        .par_iter()
        .map(|item| {
            let bounds = match item {
                Placed::Leaf(leaf) => leaf.bounds,
                Placed::Triangle(bounds) => *bounds,
            };
            Prim {
                bounds,
                centroid: bounds.center(),
            }
        })
        .collect();
    let groupable: Vec<bool> = items
        .iter()
        .map(|item| matches!(item, Placed::Triangle(_)))
        .collect();
    let params = BuildParams {
        max_leaf: max_group.max(1),
        ..BuildParams::DEFAULT
    };
    let builder = Builder {
        prims: &prims,
        params: &params,
        progress: &Quiet,
        groupable: Some(&groupable),
    };
    let mut order: Vec<u32> = (0..prims.len() as u32).collect();
    let [mut y, mut z] = [1, 2].map(|axis| {
        let mut by_axis = order.clone();
        by_axis.par_sort_unstable_by(builder.centroid_order(axis));
        by_axis
    });
    order.par_sort_unstable_by(builder.centroid_order(0));
    let root =
        (!order.is_empty()).then(|| builder.build_sorted([&mut order, &mut y, &mut z], 0, 0));
    // Where each place of the order starts among the triangles, which keep the order's.
    let mut first = Vec::with_capacity(order.len());
    let mut triangles = Vec::new();
    for &i in &order {
        first.push(triangles.len() as u32);
        if groupable[i as usize] {
            triangles.push(present[i as usize]);
        }
    }
    let (nodes, depth) = pack_with(root.as_ref(), "scene", &|bounds, start, count| {
        match items[order[start as usize] as usize] {
            // Never grouped: a leaf of its own.
            Placed::Leaf(leaf) => *leaf,
            Placed::Triangle(_) => ChildRef {
                bounds,
                child: LEAF_BIT | (base + first[start as usize]),
                count,
            },
        }
    })?;
    if let Some(root) = root {
        free(root);
    }
    Ok((nodes, depth, triangles))
}

/// The surface-area cost of the tree `nodes` (node 0 the root): the areas of its inner nodes'
/// boxes (the union of each node's children's boxes as decoded, which traversal tests) and of
/// its leaves' boxes, each leaf's weighted by `leaf_cost` (what testing it costs, in box tests),
/// over the root's: what a ray through the root's box costs when rays are spread evenly
/// (Goldsmith & Salmon 1987; MacDonald & Booth 1990). A term the same for every tree compared
/// (a leaf each has) may be left out by a `leaf_cost` of 0.
pub(crate) fn sah_cost(nodes: &[GpuNode], leaf_cost: &dyn Fn(&ChildRef) -> f64) -> f64 {
    let union = |n: &GpuNode| {
        n.children()
            .iter()
            .filter(|c| !c.is_absent())
            .fold(Aabb::EMPTY, |u, c| u.union(c.bounds))
    };
    let area = |b: Aabb| {
        if b.is_empty() {
            0.0
        } else {
            f64::from(b.area())
        }
    };
    let root = nodes.first().map_or(0.0, |n| area(union(n)));
    if root <= 0.0 {
        return nodes.len() as f64;
    }
    let cost: f64 = nodes
        .iter()
        .map(|n| {
            let leaves: f64 = n
                .children()
                .iter()
                .filter(|c| c.is_leaf() && !c.is_absent())
                .map(|c| area(c.bounds) * leaf_cost(c))
                .sum();
            area(union(n)) + leaves
        })
        .sum();
    cost / root
}

/// An error when a tree has more than [`MAX_NODES`] inner nodes, which its traversal stack
/// entries cannot name.
pub(crate) fn check_node_count(nodes: usize) -> Result<()> {
    if nodes > MAX_NODES {
        return Err(Error::param(
            "scene",
            format!(
                "the tree has {nodes} inner nodes, more than the {MAX_NODES} a traversal can name"
            ),
        ));
    }
    Ok(())
}

/// [`pack`] with `leaf(bounds, start, count)` the reference of a leaf holding
/// `order[start..start + count]`. The node array is allocated once at its size, which each subtree
/// knows, and the two halves of a large subtree are packed in parallel into their own ranges of
/// it: the same array, byte for byte, as one thread packing depth-first made. At the paper's scale, on two cores,
/// that and [`free`] took the exact BVH's time outside its recursion from 5.9–7.1 s to 3.4–3.8 s
/// and the linear BVH of the RBVH's rings from 3.9–4.5 s to 2.3–2.6 s (docs/paper-scale.md,
/// "Packing in parallel").
fn pack_with(
    root: Option<&BuildNode>,
    parameter: &str,
    leaf: &LeafRef,
) -> Result<(Vec<GpuNode>, u32)> {
    let nodes = match root {
        None => vec![GpuNode::new(ChildRef::ABSENT, ChildRef::ABSENT)],
        Some(node @ BuildNode::Leaf { .. }) => {
            vec![GpuNode::new(child_ref(node, 0, leaf), ChildRef::ABSENT)]
        }
        Some(node @ BuildNode::Inner { inner, .. }) => {
            check_node_count(*inner as usize)?;
            let mut nodes = vec![GpuNode::default(); *inner as usize];
            flatten(node, 0, &mut nodes, leaf);
            nodes
        }
    };
    let depth = root.map_or(0, BuildNode::depth).max(1);
    if depth > STACK_SIZE {
        return Err(Error::param(
            parameter,
            format!("the tree has depth {depth}, beyond the {STACK_SIZE}-entry traversal stack"),
        ));
    }
    Ok((nodes, depth))
}

/// How [`pack_with`] refers to a leaf: from its box and its range `start`, `count` of the order.
type LeafRef<'a> = dyn Fn(Aabb, u32, u32) -> ChildRef + Sync + 'a;

fn child_ref(node: &BuildNode, index: u32, leaf: &LeafRef) -> ChildRef {
    match node {
        BuildNode::Leaf {
            bounds,
            start,
            count,
        } => leaf(*bounds, *start, *count),
        BuildNode::Inner { bounds, .. } => ChildRef {
            bounds: *bounds,
            child: index,
            count: 0,
        },
    }
}

/// Depth-first packing: a node's first child follows it directly, which keeps the common descent
/// path close in memory. `out` holds the subtree's nodes, `node` first, at `index` in the array.
fn flatten(node: &BuildNode, index: u32, out: &mut [GpuNode], leaf: &LeafRef) -> ChildRef {
    if let BuildNode::Inner {
        inner, children, ..
    } = node
    {
        let (this, below) = out.split_at_mut(1);
        let first = children[0].inner_count();
        let (a_out, b_out) = below.split_at_mut(first as usize);
        let (a, b) = join_halves(
            *inner as usize >= PARALLEL_THRESHOLD,
            || flatten(&children[0], index + 1, a_out, leaf),
            || flatten(&children[1], index + 1 + first, b_out, leaf),
        );
        this[0] = GpuNode::new(a, b);
    }
    child_ref(node, index, leaf)
}

struct Builder<'a> {
    prims: &'a [Prim],
    params: &'a BuildParams,
    /// Which prims may share a leaf; `None`: all (the exact BVH's triangles).
    groupable: Option<&'a [bool]>,
    /// Told of every leaf's triangles as the leaf is made.
    progress: &'a dyn Progress,
}

#[derive(Clone, Copy)]
struct Bin {
    bounds: Aabb,
    count: u32,
}

const EMPTY_BIN: Bin = Bin {
    bounds: Aabb::EMPTY,
    count: 0,
};

impl Builder<'_> {
    /// Builds the subtree over the non-empty `order` (a slice of the global order starting at
    /// `offset`).
    fn build(&self, order: &mut [u32], offset: u32, depth: u32) -> BuildNode {
        let (bounds, centroids) = self.bounds_of(order);
        let n = order.len();
        let made_leaf = || self.leaf(bounds, offset, n);
        if n == 1 {
            return made_leaf();
        }
        let groups = self.may_group(order);
        let split = if depth < self.params.median_below_depth {
            self.sah_split(order, &bounds, &centroids)
        } else {
            None
        };
        let mid = match split {
            Some(s) if s.cost >= n as f32 && groups => return made_leaf(),
            Some(s) => partition(order, |i| s.bin_of(&self.prims[i as usize]) < s.bin),
            None if groups => return made_leaf(),
            None => self.median_split(order, &centroids),
        };
        let (left, right) = order.split_at_mut(mid);
        let (a, b) = join_halves(
            n >= PARALLEL_THRESHOLD,
            || self.build(left, offset, depth + 1),
            || self.build(right, offset + mid as u32, depth + 1),
        );
        BuildNode::inner(bounds, a, b)
    }

    /// A leaf of the `n` prims of the order from `offset` on, whose box is `bounds`, told to the
    /// progress as it is made.
    fn leaf(&self, bounds: Aabb, offset: u32, n: usize) -> BuildNode {
        self.progress.advance(n as u64);
        BuildNode::Leaf {
            bounds,
            start: offset,
            count: n as u32,
        }
    }

    /// Whether the prims of `order` may share one leaf: few enough, and each one that may.
    fn may_group(&self, order: &[u32]) -> bool {
        order.len() <= self.params.max_leaf
            && self
                .groupable
                .is_none_or(|g| order.iter().all(|&i| g[i as usize]))
    }

    /// Bounds of the triangles and of their centroids; a parallel, exact reduction for big sets.
    fn bounds_of(&self, order: &[u32]) -> (Aabb, Aabb) {
        let one = |i: &u32| {
            let p = &self.prims[*i as usize];
            (p.bounds, Aabb::EMPTY.grow(p.centroid))
        };
        let merge = |a: (Aabb, Aabb), b: (Aabb, Aabb)| (a.0.union(b.0), a.1.union(b.1));
        if order.len() >= PARALLEL_THRESHOLD {
            use rayon::prelude::*;
            order
                .par_iter()
                .map(one)
                .reduce(|| (Aabb::EMPTY, Aabb::EMPTY), merge)
        } else {
            order
                .iter()
                .map(one)
                .fold((Aabb::EMPTY, Aabb::EMPTY), merge)
        }
    }

    /// The cheapest SAH plane over all axes, or `None` when all centroids coincide.
    fn sah_split(&self, order: &[u32], bounds: &Aabb, centroids: &Aabb) -> Option<SahSplit> {
        let nb = self.params.bins;
        let extent = centroids.extent();
        let mut best: Option<SahSplit> = None;
        for axis in 0..3 {
            if extent[axis] <= 0.0 {
                continue;
            }
            let binning = SahSplit {
                cost: 0.0,
                axis,
                lo: centroids.min[axis],
                scale: nb as f32 / extent[axis],
                bins: nb,
                bin: 0,
            };
            let bins = self.fill_bins(order, nb, |i| binning.bin_of(&self.prims[i as usize]));
            // Sweep from the right to get suffix areas and counts, then from the left.
            let mut right_area = vec![0.0f32; nb];
            let mut right_count = vec![0u32; nb];
            let mut acc = EMPTY_BIN;
            for b in (1..nb).rev() {
                acc = Bin {
                    bounds: acc.bounds.union(bins[b].bounds),
                    count: acc.count + bins[b].count,
                };
                right_area[b] = acc.bounds.area();
                right_count[b] = acc.count;
            }
            let mut left = EMPTY_BIN;
            for b in 1..nb {
                left = Bin {
                    bounds: left.bounds.union(bins[b - 1].bounds),
                    count: left.count + bins[b - 1].count,
                };
                if left.count == 0 || right_count[b] == 0 {
                    continue;
                }
                let cost = self.params.traversal_cost
                    + (left.bounds.area() * left.count as f32
                        + right_area[b] * right_count[b] as f32)
                        / bounds.area().max(f32::MIN_POSITIVE);
                if best.as_ref().is_none_or(|s| cost < s.cost) {
                    best = Some(SahSplit {
                        cost,
                        bin: b,
                        ..binning
                    });
                }
            }
        }
        best
    }

    /// [`Builder::build`] with a full-sweep SAH: every place between the node's prims sorted by
    /// centroid along each axis is a candidate. `sorted` holds the node's prims three times, each
    /// sorted along one axis by [`Builder::centroid_order`]; a split partitions all three stably,
    /// so that no level sorts again (O(n log n) in all, where sorting at every node would be
    /// O(n log² n)). `sorted[0]` becomes the order the leaves refer to. For a tree over a few
    /// hundred thousand leaves (`tree_over`), whose boxes bin poorly; the exact BVH's millions
    /// of triangles keep binning.
    fn build_sorted(&self, sorted: [&mut [u32]; 3], offset: u32, depth: u32) -> BuildNode {
        let (bounds, centroids) = self.bounds_of(sorted[0]);
        let n = sorted[0].len();
        let made_leaf = || self.leaf(bounds, offset, n);
        if n == 1 {
            return made_leaf();
        }
        let groups = self.may_group(sorted[0]);
        let split = if depth < self.params.median_below_depth {
            self.sweep(&sorted, &bounds)
        } else {
            None
        };
        // The left side: the first `mid` prims along `axis`. As median_split: the object median
        // along the centroids' longest axis.
        let (axis, mid) = match split {
            Some((cost, _, _)) if cost >= n as f32 && groups => return made_leaf(),
            Some((_, axis, mid)) => (axis, mid),
            None if groups => return made_leaf(),
            None => (centroids.largest_axis(), n / 2),
        };
        let first_right = sorted[axis][mid];
        let [x, y, z] = sorted;
        let [x, y, z] = [x, y, z].map(|order| {
            let (left, right): (Vec<u32>, Vec<u32>) = order.iter().partition(|&&i| {
                self.centroid_order(axis)(&i, &first_right) == std::cmp::Ordering::Less
            });
            order[..left.len()].copy_from_slice(&left);
            order[left.len()..].copy_from_slice(&right);
            order.split_at_mut(mid)
        });
        let (a, b) = join_halves(
            n >= PARALLEL_THRESHOLD,
            || self.build_sorted([x.0, y.0, z.0], offset, depth + 1),
            || self.build_sorted([x.1, y.1, z.1], offset + mid as u32, depth + 1),
        );
        BuildNode::inner(bounds, a, b)
    }

    /// How [`Builder::build_sorted`] orders prims along `axis`: by centroid, ties by index.
    fn centroid_order(&self, axis: usize) -> impl Fn(&u32, &u32) -> std::cmp::Ordering + '_ {
        move |&a, &b| {
            let ca = self.prims[a as usize].centroid[axis];
            let cb = self.prims[b as usize].centroid[axis];
            ca.total_cmp(&cb).then(a.cmp(&b))
        }
    }

    /// The cheapest SAH split of a node whose prims `sorted` holds as
    /// [`Builder::build_sorted`] does: its cost, axis and where its right side starts along
    /// that axis; the first axis and place on a tie.
    fn sweep(&self, sorted: &[&mut [u32]; 3], bounds: &Aabb) -> Option<(f32, usize, usize)> {
        let n = sorted[0].len();
        let scale = 1.0 / bounds.area().max(f32::MIN_POSITIVE);
        let mut best: Option<(f32, usize, usize)> = None;
        let mut right_area = vec![0.0f32; n];
        for (axis, order) in sorted.iter().enumerate() {
            let mut acc = Aabb::EMPTY;
            for k in (1..n).rev() {
                acc = acc.union(self.prims[order[k] as usize].bounds);
                right_area[k] = acc.area();
            }
            let mut left = Aabb::EMPTY;
            for k in 1..n {
                left = left.union(self.prims[order[k - 1] as usize].bounds);
                let cost = self.params.traversal_cost
                    + (left.area() * k as f32 + right_area[k] * (n - k) as f32) * scale;
                if best.is_none_or(|(c, _, _)| cost < c) {
                    best = Some((cost, axis, k));
                }
            }
        }
        best
    }

    fn fill_bins(
        &self,
        order: &[u32],
        nb: usize,
        bin_of: impl Fn(u32) -> usize + Sync,
    ) -> Vec<Bin> {
        let add = |mut bins: Vec<Bin>, i: &u32| {
            let b = &mut bins[bin_of(*i)];
            b.bounds = b.bounds.union(self.prims[*i as usize].bounds);
            b.count += 1;
            bins
        };
        let merge = |mut a: Vec<Bin>, b: Vec<Bin>| {
            for (x, y) in a.iter_mut().zip(b) {
                x.bounds = x.bounds.union(y.bounds);
                x.count += y.count;
            }
            a
        };
        if order.len() >= PARALLEL_THRESHOLD {
            use rayon::prelude::*;
            order
                .par_iter()
                .fold(|| vec![EMPTY_BIN; nb], add)
                .reduce(|| vec![EMPTY_BIN; nb], merge)
        } else {
            order.iter().fold(vec![EMPTY_BIN; nb], add)
        }
    }

    /// Object median along the centroids' longest axis; ties broken by triangle index so the result
    /// does not depend on the sort's stability.
    fn median_split(&self, order: &mut [u32], centroids: &Aabb) -> usize {
        let axis = centroids.largest_axis();
        let mid = order.len() / 2;
        order.select_nth_unstable_by(mid, |&a, &b| {
            let ca = self.prims[a as usize].centroid[axis];
            let cb = self.prims[b as usize].centroid[axis];
            ca.total_cmp(&cb).then(a.cmp(&b))
        });
        mid
    }
}

/// A split between bins `bin - 1` and `bin` on `axis`. Partitioning reuses [`SahSplit::bin_of`],
/// the very function that filled the bins, so no rounding can put a triangle on the other side of
/// the plane than the cost assumed (and neither side can come out empty).
#[derive(Clone, Copy)]
struct SahSplit {
    cost: f32,
    axis: usize,
    lo: f32,
    scale: f32,
    bins: usize,
    bin: usize,
}

impl SahSplit {
    fn bin_of(&self, p: &Prim) -> usize {
        (((p.centroid[self.axis] - self.lo) * self.scale) as usize).min(self.bins - 1)
    }
}

/// Builds both halves of a split, in parallel when the node is large enough to pay for a task.
/// Shared with the RBVH builder.
pub(crate) fn join_halves<T: Send>(
    parallel: bool,
    a: impl FnOnce() -> T + Send,
    b: impl FnOnce() -> T + Send,
) -> (T, T) {
    if parallel {
        rayon::join(a, b)
    } else {
        (a(), b())
    }
}

/// In-place partition; returns the number of elements for which `pred` holds (now first). Shared
/// with the RBVH's splitter.
pub(crate) fn partition(order: &mut [u32], pred: impl Fn(u32) -> bool) -> usize {
    let mut i = 0;
    for j in 0..order.len() {
        if pred(order[j]) {
            order.swap(i, j);
            i += 1;
        }
    }
    i
}

#[cfg(test)]
mod tests {
    use super::*;

    fn leaf(min: Vec3, size: f32, first: u32) -> ChildRef {
        ChildRef {
            bounds: Aabb {
                min,
                max: min + Vec3::splat(size),
            },
            child: LEAF_BIT | first,
            count: 3,
        }
    }

    /// Every reference below node `index` as the node decodes it, with the box it is under.
    fn under(nodes: &[GpuNode], index: u32, out: &mut Vec<(ChildRef, Aabb)>) {
        for (c, b) in nodes[index as usize]
            .children()
            .into_iter()
            .zip(nodes[index as usize].boxes())
        {
            if c.is_leaf() {
                out.push((c, b));
            } else {
                under(nodes, c.child, out);
            }
        }
    }

    /// The first child's inner nodes follow their parent, then the second's, as one thread
    /// packing depth-first lays them out, also where the two halves are packed in parallel; and
    /// the depth is the tree's.
    #[test]
    fn packed_in_parallel_the_nodes_lie_depth_first() {
        fn walk(nodes: &[GpuNode], index: u32, next: &mut u32) -> u32 {
            let mut depth = 0;
            for c in nodes[index as usize].children() {
                if !c.is_leaf() {
                    assert_eq!(c.child, *next, "below node {index}");
                    *next += 1;
                    depth = depth.max(walk(nodes, c.child, next));
                }
            }
            1 + depth
        }
        let scene = Scene::builtin("default").expect("built-in scene");
        let bvh = Bvh::build(&scene).unwrap();
        assert!(
            bvh.nodes.len() > 4 * PARALLEL_THRESHOLD,
            "too small to pack in parallel"
        );
        let mut next = 1;
        let depth = walk(&bvh.nodes, 0, &mut next);
        assert_eq!(next as usize, bvh.nodes.len(), "every node once");
        assert_eq!(depth, bvh.depth);
    }

    #[test]
    fn a_tree_over_leaves_holds_each_once_in_a_box_that_holds_it() {
        let mut leaves: Vec<ChildRef> = (0..300u32)
            .map(|i| {
                let cluster = Vec3::new((i % 3) as f32 * 100.0, 0.0, 0.0);
                let jitter = Vec3::new((i * 7 % 11) as f32, (i * 5 % 13) as f32, (i % 4) as f32);
                leaf(cluster + jitter, 1.0 + (i % 5) as f32, 10 * i)
            })
            .collect();
        leaves.insert(17, ChildRef::ABSENT);
        let placed: Vec<Placed> = leaves.iter().map(|&l| Placed::Leaf(l)).collect();
        let (nodes, depth, triangles) = tree_over(&placed, 8, 0).unwrap();
        assert!(triangles.is_empty());
        assert!(depth <= STACK_SIZE);
        let mut found = Vec::new();
        under(&nodes, 0, &mut found);
        let present: Vec<&ChildRef> = leaves.iter().filter(|l| !l.is_absent()).collect();
        assert_eq!(
            found.len(),
            present.len(),
            "one child per leaf, no absent one"
        );
        for (c, decoded) in &found {
            let l = present
                .iter()
                .find(|l| l.child == c.child)
                .expect("a leaf of the input");
            assert_eq!(c.count, l.count);
            assert!(
                decoded.min.cmple(l.bounds.min).all() && decoded.max.cmpge(l.bounds.max).all(),
                "{decoded:?} does not hold {:?}",
                l.bounds
            );
        }
        // The SAH keeps the three clusters apart (each at most 15 wide): the root splits one of
        // them off whole.
        let root = nodes[0].boxes();
        assert!(root.iter().any(|b| b.extent().x < 20.0), "{root:?}");
    }

    #[test]
    fn a_tree_over_one_leaf_or_none_is_one_node() {
        let one = leaf(Vec3::ZERO, 1.0, 0);
        let (nodes, depth, _) =
            tree_over(&[Placed::Leaf(ChildRef::ABSENT), Placed::Leaf(one)], 8, 0).unwrap();
        assert_eq!((nodes.len(), depth), (1, 1));
        assert_eq!(nodes[0].children()[0].child, one.child);
        assert!(nodes[0].children()[1].is_absent());
        let (nodes, _, _) = tree_over(&[], 8, 0).unwrap();
        assert_eq!(nodes.len(), 1);
        assert!(nodes[0].children().iter().all(ChildRef::is_absent));
    }

    #[test]
    fn loose_triangles_share_leaves_and_finished_leaves_never_do() {
        // Clusters of small triangles, each cluster beside a finished leaf, and an absent one.
        let mut items = vec![Placed::Leaf(ChildRef::ABSENT)];
        for c in 0..6u32 {
            let at = Vec3::new(50.0 * c as f32, 0.0, 0.0);
            items.push(Placed::Leaf(leaf(
                at + Vec3::splat(5.0),
                2.0,
                LEAF_BIT - 1 - c,
            )));
            for k in 0..20u32 {
                let p = at + Vec3::new((k % 5) as f32 * 0.3, (k / 5) as f32 * 0.3, 0.0);
                items.push(Placed::Triangle(Aabb {
                    min: p,
                    max: p + Vec3::splat(0.2),
                }));
            }
        }
        let (nodes, depth, triangles) = tree_over(&items, 4, 0).unwrap();
        assert!(depth <= STACK_SIZE);
        // Every triangle once, in the order the leaves refer to.
        let mut sorted = triangles.clone();
        sorted.sort_unstable();
        let expected: Vec<u32> = (0..items.len() as u32)
            .filter(|&i| matches!(items[i as usize], Placed::Triangle(_)))
            .collect();
        assert_eq!(sorted, expected);
        let mut found = Vec::new();
        under(&nodes, 0, &mut found);
        let (mut finished, mut covered, mut shared) = (0, vec![false; triangles.len()], 0);
        for (c, decoded) in &found {
            if c.child >= LEAF_BIT | (LEAF_BIT - 7) {
                finished += 1;
                assert_eq!(c.count, 3, "a finished leaf as it was");
                continue;
            }
            let first = (c.child & !LEAF_BIT) as usize;
            assert!((1..=4).contains(&c.count), "{c:?}");
            shared += usize::from(c.count > 1);
            for k in first..first + c.count as usize {
                assert!(!covered[k], "triangle {k} in two leaves");
                covered[k] = true;
                let Placed::Triangle(b) = items[triangles[k] as usize] else {
                    unreachable!("only triangles are listed")
                };
                assert!(decoded.min.cmple(b.min).all() && decoded.max.cmpge(b.max).all());
            }
        }
        assert_eq!(finished, 6);
        assert!(covered.iter().all(|&c| c));
        assert!(
            shared > 10,
            "{shared} leaves of several triangles: the SAH grouped none"
        );
    }
}
