//! The top-down recursion of the construction (Novák & Dachsbacher 2012, `ConstructRBVH`; see
//! [`super`]): a set that is one height field becomes a leaf ([`super::leaf`]); one that is not
//! is kept as triangles when small, or split — by space and connected parts
//! ([`crate::rbvh::split`]), or, for small or thin sets of points, by facing.

use glam::Vec3;

use super::exact::{sampled_bytes, EXACT_TRIANGLE_BYTES};
use super::leaf::{balanced, pieces_subtree};
use super::{
    Builder, Input, Node, MAX_TRIANGLE_LEAF, MEDIAN_BELOW_DEPTH, PARALLEL_THRESHOLD, SLAB,
};
use crate::bvh::{join_halves, GpuTriangle};
use crate::geom::Aabb;
use crate::rbvh::splat::Splat;
use crate::rbvh::split::split;

/// The most the texels a set's triangles ask for may differ, as a ratio, for the set to be
/// sampled at its finest: a height field at most twice as fine as some of its triangles need
/// (four times their texels) where the view refines some of them
/// ([`crate::rbvh::RbvhParams::view_rate`]).
const VIEW_SPAN: f32 = 2.0;

impl Builder<'_> {
    /// The texel of the set `order`: the finest its objects ([`RbvhParams::object_rate`]) and
    /// the view ([`RbvhParams::view_rate`]) ask of its triangles, or the scene's. With object
    /// split on, a set that becomes a leaf lies in one object.
    pub(super) fn texel_of(&self, order: &[u32]) -> f32 {
        self.texels_of(order).0
    }

    /// The finest and the coarsest texel the triangles of `order` ask for, in one pass: a set
    /// of one connected part (one object, whose texel is one) whose texels lie more than
    /// [`VIEW_SPAN`] apart, which only the view makes them do, is split rather than sampled at
    /// its finest texel throughout, so that a surface reaching from the camera into the
    /// distance is not sampled at its nearest texel everywhere.
    fn texels_of(&self, order: &[u32]) -> (f32, f32) {
        if self.objects.is_empty() {
            // Points: the cloud is one object.
            let t = self.object_texel.first().copied().unwrap_or(self.texel);
            return (t, t);
        }
        if self.object_texel.is_empty() && self.view_texel.is_empty() {
            return (self.texel, self.texel);
        }
        order
            .iter()
            .fold((self.texel, 0.0f32), |(finest, coarsest), &i| {
                let i = i as usize;
                let object = self.object_texel.get(self.objects[i] as usize);
                let view = self.view_texel.get(i);
                let t = self
                    .texel
                    .min(object.copied().unwrap_or(self.texel))
                    .min(view.copied().unwrap_or(self.texel));
                (finest.min(t), coarsest.max(t))
            })
    }

    pub(super) fn build(&self, order: &mut [u32], offset: u32, depth: u32) -> Node {
        let n = order.len();
        // One pass over the set (its triangles lie scattered in memory at the paper's scale):
        // the box of the surface it samples (its triangles, or its points, whose splits see them
        // with their reach but whose size is that of the samples), its centroids' box for the
        // split, and whether it is one connected part.
        let part = self.prims[order[0] as usize].component;
        let (bounds, centroids, same_part) = order.iter().fold(
            (Aabb::EMPTY, Aabb::EMPTY, true),
            |(bounds, centroids, same), &i| {
                let prim = &self.prims[i as usize];
                let bounds = match self.input {
                    Input::Triangles(_) => bounds.union(prim.bounds),
                    Input::Points(_) => bounds.grow(prim.centroid),
                };
                (
                    bounds,
                    centroids.grow(prim.centroid),
                    same && prim.component == part,
                )
            },
        );
        let one_part = !self.params.object_split || same_part;
        // The set's texel, a pass over its triangles, where a decision reads it: a set of several
        // parts at least `min_leaf_texels` of the scene's texel across is not small at any finer
        // one (no object's texel is coarser than the scene's), and is split.
        let (texel, coarsest) = if one_part
            || matches!(self.input, Input::Points(_))
            || bounds.diagonal() < self.params.min_leaf_texels * self.texel
        {
            self.texels_of(order)
        } else {
            (self.texel, self.texel)
        };
        let spread = same_part && n > 1 && coarsest > VIEW_SPAN * texel;
        if one_part && !spread {
            if let Some(tiles) = self.heightfield(order, bounds.diagonal(), texel) {
                self.progress.advance(n as u64);
                let parts = self.parts(&tiles, order);
                if let (Input::Triangles(all), true) = (&self.input, self.params.exact_when_cheaper)
                {
                    if sampled_bytes(&tiles, parts.len(), self.params.texels)
                        > n as f32 * EXACT_TRIANGLE_BYTES
                    {
                        let exact = order.iter().map(|&i| GpuTriangle::new(all[i as usize], i));
                        return pieces_subtree(exact.collect(), 1);
                    }
                }
                return self.surface_subtree(tiles, parts, order);
            }
        }
        let small = bounds.diagonal() < self.params.min_leaf_texels * texel;
        // A slab (thinner than that, or than a quarter of its length: two sides of a thin sheet,
        // scanned from both): space splits along its length and never between its sides, only
        // their facing does.
        let extent = bounds.extent();
        let thin = extent.min_element()
            < (self.params.min_leaf_texels * texel).max(SLAB * extent.max_element());
        match self.input {
            Input::Triangles(_) if n == 1 || (n <= MAX_TRIANGLE_LEAF && small) => {
                self.progress.advance(n as u64);
                return Node::Triangles {
                    start: offset,
                    count: n as u32,
                };
            }
            Input::Points(points) if n > 1 && (small || thin) => {
                let classes = facing_classes(points, order);
                let two_sided = (0..3).any(|axis| classes >> (2 * axis) & 0b11 == 0b11);
                if (small && classes.count_ones() > 1) || (thin && two_sided) {
                    return self.split_by_facing(points, order, offset, depth);
                }
                if n == 1 || small {
                    return self.forced(points, order, offset, texel);
                }
            }
            Input::Points(points) if n == 1 => return self.forced(points, order, offset, texel),
            _ => {}
        }
        let mid = split(
            self.prims,
            order,
            &centroids,
            self.params.subdivision,
            self.params.object_split,
            depth >= MEDIAN_BELOW_DEPTH,
        );
        let (left, right) = order.split_at_mut(mid);
        let (a, b) = join_halves(
            n >= PARALLEL_THRESHOLD,
            || self.build(left, offset, depth + 1),
            || self.build(right, offset + mid as u32, depth + 1),
        );
        Node::Inner(Box::new([a, b]))
    }

    /// A small or thin set of points that is not one height field, split by which of the six
    /// axis directions each normal is nearest (at most 54.7° away): where space can no longer be
    /// split usefully (a closed speck: a claw, a horn's tip) or never between the sides (a thin
    /// sheet scanned from both), the sides a set shows each way are split apart, each a better
    /// candidate for a height field than the whole, instead of being cut into leaves of a few
    /// points or squashed into one forced leaf. Triangles need no such split: they fall back to
    /// exact leaves.
    fn split_by_facing(&self, all: &[Splat], order: &mut [u32], offset: u32, depth: u32) -> Node {
        order.sort_by_key(|&i| facing_class(all[i as usize].normal));
        let mut children = Vec::new();
        let (mut rest, mut start) = (order, 0usize);
        while !rest.is_empty() {
            let class = facing_class(all[rest[0] as usize].normal);
            let len = rest
                .iter()
                .position(|&i| facing_class(all[i as usize].normal) != class)
                .unwrap_or(rest.len());
            let (group, tail) = rest.split_at_mut(len);
            children.push(self.build(group, offset + start as u32, depth + 1));
            start += len;
            rest = tail;
        }
        balanced(children)
    }
}

/// Which of the six axis directions (+x, −x, +y, −y, +z, −z: 0…5) `normal` is nearest.
fn facing_class(normal: Vec3) -> u8 {
    let a = normal.abs();
    let axis = if a.x >= a.y && a.x >= a.z {
        0
    } else if a.y >= a.z {
        1
    } else {
        2
    };
    2 * axis + u8::from(normal[axis as usize] < 0.0)
}

/// The facing classes the points `order` fall into, as a mask (bit `c` for class `c`).
fn facing_classes(all: &[Splat], order: &[u32]) -> u8 {
    order
        .iter()
        .fold(0u8, |m, &i| m | 1 << facing_class(all[i as usize].normal))
}
