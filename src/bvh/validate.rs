//! Structural invariants of a built BVH, checked by tests on every scene and degenerate input
//! (after obvhs' `validate`): a tree that breaks one of them can make traversal miss geometry.

use super::layout::{ChildRef, LEAF_BIT, STACK_SIZE};
use super::Bvh;
use crate::geom::Aabb;

impl Bvh {
    /// Checks that every node index is in range and reached once, every triangle slot is referenced
    /// exactly once, each child box contains everything below it, and the depth fits the stack.
    /// Returns the first violation found.
    pub fn validate(&self) -> Result<(), String> {
        let mut node_seen = vec![false; self.nodes.len()];
        let mut slot_seen = vec![false; self.triangles.len()];
        let mut work = vec![(0u32, 1u32)];
        let mut max_depth = 0;
        while let Some((index, depth)) = work.pop() {
            let seen = node_seen
                .get_mut(index as usize)
                .ok_or_else(|| format!("node index {index} out of range"))?;
            if std::mem::replace(seen, true) {
                return Err(format!("node {index} is reached twice"));
            }
            max_depth = max_depth.max(depth);
            for child in self.nodes[index as usize].children() {
                let inside = self.subtree_bounds(&child)?;
                if !inside.is_empty() && !contains(&child.bounds, &inside) {
                    return Err(format!(
                        "a child box of node {index} does not contain its subtree"
                    ));
                }
                if child.child & LEAF_BIT != 0 {
                    let first = (child.child & !LEAF_BIT) as usize;
                    for slot in first..first + child.count as usize {
                        let s = slot_seen
                            .get_mut(slot)
                            .ok_or_else(|| format!("triangle slot {slot} out of range"))?;
                        if std::mem::replace(s, true) {
                            return Err(format!("triangle slot {slot} is in two leaves"));
                        }
                    }
                } else {
                    work.push((child.child, depth + 1));
                }
            }
        }
        if let Some(n) = node_seen.iter().position(|s| !s) {
            return Err(format!("node {n} is unreachable"));
        }
        if let Some(s) = slot_seen.iter().position(|s| !s) {
            return Err(format!("triangle slot {s} is in no leaf"));
        }
        if max_depth > STACK_SIZE || max_depth != self.depth.max(1) {
            return Err(format!(
                "depth {max_depth} (recorded {}), stack {STACK_SIZE}",
                self.depth
            ));
        }
        Ok(())
    }

    fn subtree_bounds(&self, child: &ChildRef) -> Result<Aabb, String> {
        if child.is_leaf() {
            let first = (child.child & !LEAF_BIT) as usize;
            let tris = self
                .triangles
                .get(first..first + child.count as usize)
                .ok_or_else(|| format!("leaf range {first}+{} out of range", child.count))?;
            Ok(Aabb::from_points(tris.iter().flat_map(|t| t.vertices())))
        } else {
            let node = self
                .nodes
                .get(child.child as usize)
                .ok_or_else(|| format!("node index {} out of range", child.child))?;
            Ok(node.children().iter().fold(Aabb::EMPTY, |b, c| {
                if c.is_leaf() && c.count == 0 {
                    b
                } else {
                    b.union(c.bounds)
                }
            }))
        }
    }
}

fn contains(outer: &Aabb, inner: &Aabb) -> bool {
    outer.min.cmple(inner.min).all() && outer.max.cmpge(inner.max).all()
}
