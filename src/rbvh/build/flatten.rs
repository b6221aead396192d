//! Packing the construction's tree depth-first into the device's node array ([`Flattened`]),
//! its leaves' records, triangles and tiles, and choosing the tree a ray traverses over the
//! leaves: the construction's own, or an SAH tree built again over the leaves' boxes (the exact
//! BVH's builder, sweeping rather than binning), whichever the SAH finds cheaper ([`upper_tree`]).

use super::{Builder, Input, Node};
use crate::bvh::{ChildRef, GpuNode, GpuTriangle, Placed, STACK_SIZE};
use crate::geom::Aabb;
use crate::rbvh::child::Child;
use crate::rbvh::raster::Tile;
use crate::{Error, Result};

/// Most triangles the tree built again over the leaves puts in one leaf: as the exact BVH's
/// (`BuildParams::DEFAULT`); its SAH groups them only where testing them together costs less than
/// the nodes between them.
const MAX_TRIANGLES_A_LEAF: usize = 8;

/// The tree traversal runs over the leaves of `out`: the construction's own (`out.nodes`, of
/// depth `root`'s), or one built again over the leaves' boxes by the exact BVH's builder with a
/// full-sweep SAH ([`crate::bvh::tree_over`]), whichever the SAH finds cheaper ([`crate::bvh::sah_cost`]),
/// the construction's on a tie.
///
/// The construction splits until a set is one height field: its splits serve the refinement
/// criterion and the object split, not traversal. Over many objects that tree is poor: on the
/// paper-scale scene at Q2 a primary ray visited 108 inner nodes against the exact BVH's 63, and
/// the SAH tree over the same leaves costs 62.4 against 107.9 (inner nodes' areas over the root's)
/// and takes rays through 59 nodes. Within one detailed object the construction's tree can be
/// the better one: on the dragon close-up it costs 24.0 against 24.7 at Q2, and rays visit 5%
/// fewer nodes through it than through the SAH tree. The cost decides, so each scene gets the
/// cheaper of the two.
///
/// The tree built again takes each triangle the construction left alone in its leaf (traced
/// exactly for its size) loose, and groups those as the exact BVH does; exact parts' leaves stay
/// whole (regrouped too, they split finer on the dragon close-up and cost it bytes). At the
/// paper's scale at Q2 this took the tree from 13.88 to 12.93 MB and a primary ray from 2.79
/// triangle leaves to 1.37 (docs/paper-scale.md, "Lone exact triangles grouped").
pub(super) fn upper_tree(out: &mut Flattened, root: Option<&Node>) -> Result<(Vec<GpuNode>, u32)> {
    let mut items = Vec::with_capacity(out.refs.len());
    // The triangles of the leaves kept whole, first, in their leaves' order; the loose ones follow
    // them in the order the tree built again gives them.
    let mut kept = Vec::new();
    // For each item that is a loose triangle, its index in `out.triangles`.
    let mut loose = Vec::with_capacity(out.refs.len());
    for leaf in &out.refs {
        match leaf.kind() {
            // A triangle alone in its leaf (traced exactly for its size): loose.
            Child::Triangles { first, count: 1 } => {
                items.push(Placed::Triangle(leaf.bounds));
                loose.push(first);
            }
            // An exact part's pieces, which lie together: kept whole.
            Child::Triangles { first, count } => {
                let at = kept.len() as u32;
                let range = first as usize..first as usize + count as usize;
                kept.extend_from_slice(out.triangles.get(range).unwrap_or_default());
                let child = Child::Triangles { first: at, count };
                items.push(Placed::Leaf(child.with_bounds(leaf.bounds)));
                loose.push(u32::MAX);
            }
            Child::Absent => {}
            Child::Inner(_) | Child::Heightfield(_) => {
                items.push(Placed::Leaf(*leaf));
                loose.push(u32::MAX);
            }
        }
    }
    let base = kept.len() as u32;
    let (rebuilt, rebuilt_depth, order) =
        crate::bvh::tree_over(&items, MAX_TRIANGLES_A_LEAF, base)?;
    // A height field's leaf term is the same in both trees: only the triangles' count.
    let triangles = |c: &ChildRef| match c.kind() {
        Child::Triangles { count, .. } => f64::from(count),
        _ => 0.0,
    };
    if crate::bvh::sah_cost(&rebuilt, &triangles) < crate::bvh::sah_cost(&out.nodes, &triangles) {
        kept.extend(
            order
                .iter()
                .map(|&item| out.triangles[loose[item as usize] as usize]),
        );
        out.triangles = kept;
        out.triangle_leaves = rebuilt
            .iter()
            .flat_map(GpuNode::children)
            .filter(|c| matches!(c.kind(), Child::Triangles { .. }))
            .count() as u32;
        return Ok((rebuilt, rebuilt_depth));
    }
    crate::bvh::check_node_count(out.nodes.len())?;
    let depth = root.map_or(0, depth_of).max(1);
    if depth > STACK_SIZE {
        return Err(Error::param(
            "scene",
            format!("RBVH depth {depth} exceeds the {STACK_SIZE}-entry stack"),
        ));
    }
    Ok((std::mem::take(&mut out.nodes), depth))
}

fn depth_of(node: &Node) -> u32 {
    match node {
        Node::Inner(c) | Node::Surface(c) => 1 + depth_of(&c[0]).max(depth_of(&c[1])),
        _ => 0,
    }
}

/// The construction's tree packed depth-first, with its leaves' references and everything they
/// refer to.
#[derive(Default)]
pub(super) struct Flattened {
    pub(super) nodes: Vec<GpuNode>,
    /// Each leaf's reference and box, in depth-first order, for the tree built again over them
    /// ([`crate::bvh::tree_over`]).
    refs: Vec<ChildRef>,
    pub(super) triangles: Vec<GpuTriangle>,
    pub(super) heightfields: Vec<crate::rbvh::GpuHeightfield>,
    pub(super) tiles: Vec<Tile>,
    pub(super) triangle_leaves: u32,
    /// The leaf of the first tile of the [`Node::Surface`] being flattened, which its parts'
    /// flags count from.
    surface_leaves: u32,
}

impl Flattened {
    /// The two children of `node` (inner or [`Node::Surface`]), flattened in order; a
    /// surface's parts name their tiles' leaves, which its first child has just numbered.
    pub(super) fn flatten_children(
        &mut self,
        node: &Node,
        children: &[Node; 2],
        b: &Builder,
        order: &[u32],
    ) -> [ChildRef; 2] {
        let first_leaf = self.heightfields.len() as u32;
        let l = self.flatten(&children[0], b, order);
        if matches!(node, Node::Surface(_)) {
            self.surface_leaves = first_leaf;
        }
        [l, self.flatten(&children[1], b, order)]
    }

    /// Depth-first packing; inner boxes are the union of their children's boxes: a height-field
    /// leaf's is the box of its samples, dilated rim included (`Tile::surface_bounds`).
    pub(super) fn flatten(&mut self, node: &Node, b: &Builder, order: &[u32]) -> ChildRef {
        let leaf = match node {
            Node::Inner(children) | Node::Surface(children) => {
                let index = self.nodes.len() as u32;
                self.nodes.push(GpuNode::default());
                let [l, r] = self.flatten_children(node, children, b, order);
                self.nodes[index as usize] = GpuNode::new(l, r);
                return Child::Inner(index).with_bounds(l.bounds.union(r.bounds));
            }
            Node::Heightfield(tile) => {
                let index = self.heightfields.len() as u32;
                self.heightfields.push(tile.heightfield(0));
                self.tiles.push((**tile).clone());
                Child::Heightfield(index).with_bounds(tile.surface_bounds())
            }
            Node::Pieces(pieces) => {
                let first = self.triangles.len() as u32;
                let bounds = pieces
                    .iter()
                    .fold(Aabb::EMPTY, |b, t| b.union(Aabb::from_points(t.vertices())));
                let base = self.surface_leaves;
                self.triangles
                    .extend(pieces.iter().map(|&t| match t.part_leaf() {
                        None => t,
                        Some(k) => GpuTriangle {
                            flags: GpuTriangle::part_flags(
                                base + k,
                                t.flags & GpuTriangle::BARE != 0,
                            ),
                            ..t
                        },
                    }));
                self.triangle_leaves += 1;
                Child::Triangles {
                    first,
                    count: pieces.len() as u32,
                }
                .with_bounds(bounds)
            }
            Node::Triangles { start, count } => {
                let first = self.triangles.len() as u32;
                let mut bounds = Aabb::EMPTY;
                let Input::Triangles(tris) = b.input else {
                    // A point set's empty leaf (see `Builder::build`).
                    return ChildRef::ABSENT;
                };
                for &i in &order[*start as usize..(*start + *count) as usize] {
                    let t = tris[i as usize];
                    bounds = bounds.union(Aabb::from_points(t));
                    self.triangles.push(GpuTriangle::new(t, i));
                }
                self.triangle_leaves += 1;
                Child::Triangles {
                    first,
                    count: *count,
                }
                .with_bounds(bounds)
            }
        };
        self.refs.push(leaf);
        leaf
    }
}
