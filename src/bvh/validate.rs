//! Structural invariants of a built BVH, checked by tests on every scene and degenerate input
//! (after obvhs' `validate`): a tree that breaks one of them can make traversal miss geometry.

use super::layout::{LEAF_BIT, STACK_SIZE};
use super::Bvh;
use crate::geom::Aabb;

impl Bvh {
    /// Checks that every node index is in range and reached once, every triangle slot is referenced
    /// exactly once, each child box contains the triangles below it, and the depth fits the stack.
    /// Returns the first violation found.
    ///
    /// A child box must contain its *triangles*, not its descendants' boxes: a box quantized to
    /// its parent's grid ([`super::GpuNode`]) rounds outward on a coarser grid than the boxes below
    /// it, which may stick out of it where there is nothing to hit.
    pub fn validate(&self) -> Result<(), String> {
        let mut node_seen = vec![false; self.nodes.len()];
        let mut slot_seen = vec![false; self.triangles.len()];
        let mut work = vec![(0u32, 1u32)];
        let mut order = Vec::with_capacity(self.nodes.len());
        let mut max_depth = 0;
        while let Some((index, depth)) = work.pop() {
            let seen = node_seen
                .get_mut(index as usize)
                .ok_or_else(|| format!("node index {index} out of range"))?;
            if std::mem::replace(seen, true) {
                return Err(format!("node {index} is reached twice"));
            }
            order.push(index);
            max_depth = max_depth.max(depth);
            for child in self.nodes[index as usize].children() {
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
        // Children come after their parents in `order`: in reverse, each node's triangle bounds
        // are known before its parent needs them.
        let mut inside = vec![Aabb::EMPTY; self.nodes.len()];
        for &index in order.iter().rev() {
            let mut node_bounds = Aabb::EMPTY;
            for child in self.nodes[index as usize].children() {
                let below = if child.is_leaf() {
                    let first = (child.child & !LEAF_BIT) as usize;
                    let tris = &self.triangles[first..first + child.count as usize];
                    Aabb::from_points(tris.iter().flat_map(|t| t.vertices()))
                } else {
                    inside[child.child as usize]
                };
                if !below.is_empty() && !contains(&child.bounds, &below) {
                    return Err(format!(
                        "a child box of node {index} does not contain the triangles below it"
                    ));
                }
                node_bounds = node_bounds.union(below);
            }
            inside[index as usize] = node_bounds;
        }
        if max_depth > STACK_SIZE || max_depth != self.depth.max(1) {
            return Err(format!(
                "depth {max_depth} (recorded {}), stack {STACK_SIZE}",
                self.depth
            ));
        }
        Ok(())
    }
}

fn contains(outer: &Aabb, inner: &Aabb) -> bool {
    outer.min.cmple(inner.min).all() && outer.max.cmpge(inner.max).all()
}
