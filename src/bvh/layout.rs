//! GPU layout of the exact BVH, read by `glsl/bvh.glsl`. `tests/layout.rs` checks every offset
//! against the compiled SPIR-V.

use bytemuck::{Pod, Zeroable};
use glam::{Mat3, Mat4, Vec3, Vec4};

use crate::geom::{Aabb, Ray};

/// Entries of the traversal stack, in GLSL and in the CPU reference. Nearest-first traversal
/// pushes at most one entry per level, so a tree of depth ≤ `STACK_SIZE` cannot overflow it; the
/// builder enforces that (see [`crate::bvh::BuildParams::median_below_depth`]) and the GPU still
/// counts overflows, so a violation is reported, never silent.
pub const STACK_SIZE: u32 = 64;

/// Inner nodes a tree may have: a traversal stack entry names a leaf by its parent node and side
/// in 31 bits (`StackEntry` in `traverse.rs`, `rbvh_stack_entry` in `glsl/bvh.glsl`), and level
/// of detail marks inner references with bit 30 (`crate::lod::LOD_BIT`).
pub const MAX_NODES: usize = 1 << 30;

/// Marks a child reference as a leaf: `child = LEAF_BIT | first_triangle`, `count` triangles.
pub const LEAF_BIT: u32 = 0x8000_0000;

/// The `count` of a top-level leaf of a two-level structure: `child = LEAF_BIT | instance`
/// ([`GpuInstance`]). No triangle leaf holds this many, and it is not an RBVH height field's
/// count (`u32::MAX`, `crate::rbvh::HEIGHTFIELD_COUNT`), so that the top level can hold the
/// leaves of the mesh it grafts ([`GRAFTED`](super::GRAFTED)) beside its instances.
pub const INSTANCE_LEAF: u32 = u32::MAX - 1;

/// An inner node holding both children's boxes (Aila & Laine 2009), quantized against the node's
/// own box as compressed wide BVHs do (Ylitie, Karras & Laine, "Efficient Incoherent Ray Traversal
/// on GPUs Through Compressed Wide BVHs", HPG 2017): 48 bytes where two full-precision boxes took
/// 64.
///
/// | bytes | field |
/// |---|---|
/// | 0..12, 12..16 | `origin` (lower corner of the node's box), `exponents` |
/// | 16..28, 28..32 | `planes` (one word per axis), `a_child` |
/// | 32..36, 36..40, 40..44, 44..48 | `a_count`, `b_child`, `b_count`, `pad` |
///
/// Along axis `k` the grid step is the power of two `2^(e_k − 127)`, `e_k` byte `k` of `exponents`
/// (1..=254, so the step is a normal float and `float(q) · step` is exact). Word `k` of `planes`
/// holds four 8-bit grid coordinates, `a_lo | a_hi << 8 | b_lo << 16 | b_hi << 24`, and a plane is
/// `origin_k + q · step_k`: one rounding, the same with or without a fused multiply-add, so the
/// CPU and every device decode the same bits, but for a subnormal `origin` on a device that
/// flushes subnormals (where `q · step` passes `f32::MAX`, in a node spanning half the float
/// range, the product is +∞ and the shader's `precise` sum keeps it so, as here).
/// [`GpuNode::new`] rounds each plane outward and checks the decoded value, so a decoded child
/// box always contains the exact one.
///
/// A child is an inner node (`child` = node index, `count` = 0) or a leaf (`child` =
/// [`LEAF_BIT`] | first triangle, `count` triangles; 0 for an absent child, whose box decodes
/// to the point `origin`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuNode {
    /// GLSL `BvhNode.origin`: just below the lower corner of the node's box (the union of its
    /// present children's boxes; a float below, a grid step below zero, so that every plane lies
    /// strictly outside the children's triangles: `quantize_axis`), world space.
    pub origin: [f32; 3],
    /// GLSL `exponents`: bytes 0, 1, 2 the biased exponents (1..=254) of the grid steps along
    /// x, y, z; byte 3 zero.
    pub exponents: u32,
    /// GLSL `planes`: per axis, the children's quantized planes `a_lo | a_hi << 8 | b_lo << 16 |
    /// b_hi << 24`.
    pub planes: [u32; 3],
    /// GLSL `a_child`: node index of child `a`, or [`LEAF_BIT`] | its first triangle.
    pub a_child: u32,
    /// GLSL `a_count`: triangles of leaf `a`; 0 for an inner node or an absent child.
    pub a_count: u32,
    /// GLSL `b_child`: node index of child `b`, or [`LEAF_BIT`] | its first triangle.
    pub b_child: u32,
    /// GLSL `b_count`: triangles of leaf `b`; 0 for an inner node or an absent child.
    pub b_count: u32,
    /// GLSL `pad`: keeps the record three 16-byte words (one aligned load each); always 0.
    pub pad: u32,
}
const _: () = assert!(std::mem::size_of::<GpuNode>() == 48);

/// Largest grid coordinate of a quantized plane.
const MAX_PLANE: u32 = 255;
/// Biased exponents of the grid step: 2^-126 (the smallest normal float) to 2^127.
const MIN_EXPONENT: u32 = 1;
const MAX_EXPONENT: u32 = 254;

/// The grid step `2^(e − 127)` of biased exponent `e` (1..=254): a normal float, built from its
/// bits as `glsl/bvh.glsl` does.
fn grid_step(e: u32) -> f32 {
    f32::from_bits(e << 23)
}

/// Plane `q` of a grid at `origin` with step `step`; `glsl/bvh.glsl` (`rbvh_node_boxes`) computes
/// the same. `q · step` is exact (an 8-bit integer times a power of two), so this rounds once.
fn plane(origin: f32, q: u32, step: f32) -> f32 {
    origin + q as f32 * step
}

/// The smallest biased exponent whose grid of [`MAX_PLANE`] steps spans `extent`, clamped to
/// 1..=254; [`quantize_axis`] raises it when rounding at `origin` needs one more step.
fn first_exponent(extent: f64) -> u32 {
    let step = extent / MAX_PLANE as f64;
    if step.is_nan() || step <= 0.0 {
        return MIN_EXPONENT;
    }
    let bits = step.to_bits();
    let mut exp = ((bits >> 52) & 0x7ff) as i64 - 1023;
    if bits & ((1u64 << 52) - 1) != 0 {
        exp += 1;
    }
    (exp + 127).clamp(MIN_EXPONENT as i64, MAX_EXPONENT as i64) as u32
}

/// The origin, exponent and four planes (`[a_lo, a_hi, b_lo, b_hi]`) of one axis: lower planes
/// strictly below their child's `lo` and upper planes strictly above its `hi`, each checked as
/// decoded. `spans` are the present children's `(lo, hi)` (absent ones `None`, encoded as the
/// point at the origin), `least` at most every `lo`; the origin lies a float below `least` (a
/// grid step below zero), strictly below every `lo` and scaling with the node
/// ([`GpuNode::scaled_pow2`]).
///
/// Strictly outside, not merely outside: a ray with a zero direction component whose origin lies
/// exactly on a box's plane along that axis is in or out of the slab by the sign of its zero
/// (`safe_inverse` takes `1/±0` as `±f32::MAX`, so the plane's distance is `0 · MAX = 0`), and a
/// plane decoded exactly at a triangle's coordinate closed the box at `t = 0` for a ray running
/// in that triangle's plane: rays along an axis missed half the edge midpoints of an
/// axis-aligned cube. With every plane strictly outside its triangles, a ray on a plane runs
/// outside them all and misses nothing there (`tests/stability/watertight.rs`).
fn quantize_axis(least: f32, spans: [Option<(f32, f32)>; 2], widest: f64) -> (f32, u32, [u32; 4]) {
    let top = spans
        .iter()
        .flatten()
        .fold(least as f64, |m, &(_, hi)| m.max(hi as f64));
    // An axis of no extent (a flat node) takes its step from the node's widest axis, so that its
    // planes lie a step off the flat children as the others do, and scale with the node.
    let extent = match top - least as f64 {
        0.0 => widest,
        extent => extent,
    };
    let mut e = first_exponent(extent);
    loop {
        let step = grid_step(e);
        // The next float below `least`: the box no looser than it must be; at zero, where the
        // next float is subnormal (and would not scale with the node), a step below. Below
        // -f32::MAX no float is finite: such a node's lower planes are not strict.
        let origin = match (spans.iter().flatten().next(), least) {
            (None, _) => least,
            (Some(_), 0.0) => -step,
            (Some(_), _) => next_down(least).max(-f32::MAX),
        };
        let mut q = [0u32; 4];
        let mut fits = true;
        for (k, span) in spans.iter().enumerate() {
            let Some((lo, hi)) = *span else { continue };
            let mut q_lo = (((lo as f64 - origin as f64) / step as f64).floor())
                .clamp(0.0, MAX_PLANE as f64) as u32;
            while q_lo > 0 && plane(origin, q_lo, step) >= lo {
                q_lo -= 1;
            }
            let mut q_hi = (((hi as f64 - origin as f64) / step as f64).ceil())
                .clamp(0.0, MAX_PLANE as f64 + 1.0) as u32;
            while q_hi <= MAX_PLANE && plane(origin, q_hi, step) <= hi {
                q_hi += 1;
            }
            fits &= q_hi <= MAX_PLANE;
            q[2 * k] = q_lo;
            q[2 * k + 1] = q_hi.min(MAX_PLANE);
        }
        if fits || e == MAX_EXPONENT {
            return (origin, e, q);
        }
        e += 1;
    }
}
/// The next float below `x`, finite and nonzero (`f32::next_down`, stable since Rust 1.86,
/// after this crate's least supported version).
fn next_down(x: f32) -> f32 {
    match x > 0.0 {
        true => f32::from_bits(x.to_bits() - 1),
        false => f32::from_bits(x.to_bits() + 1),
    }
}

/// One child as the builder sees it, before packing.
#[derive(Clone, Copy, Debug)]
pub struct ChildRef {
    /// World-space box of the child's subtree (or leaf triangles).
    pub bounds: Aabb,
    /// Node index of an inner child, or [`LEAF_BIT`] | first triangle of a leaf.
    pub child: u32,
    /// Triangles of a leaf; 0 for an inner node or an absent child.
    pub count: u32,
}

impl ChildRef {
    /// A child that no ray can reach usefully: a leaf with no triangles and a point box.
    pub const ABSENT: ChildRef = ChildRef {
        bounds: Aabb {
            min: Vec3::ZERO,
            max: Vec3::ZERO,
        },
        child: LEAF_BIT,
        count: 0,
    };

    /// Whether `child` carries [`LEAF_BIT`] (a leaf, possibly the empty [`ChildRef::ABSENT`]).
    pub fn is_leaf(&self) -> bool {
        self.child & LEAF_BIT != 0
    }

    /// Whether this is an absent child: a leaf with nothing in it, whose box means nothing.
    pub fn is_absent(&self) -> bool {
        self.is_leaf() && self.count == 0
    }
}

impl GpuNode {
    /// This node in a world `2^k` times larger, exactly (`geom::scale`): its origin scaled and
    /// each axis's grid step's exponent raised by `k`, its planes kept; an axis of no extent
    /// (every plane 0) keeps the least exponent [`GpuNode::new`] gives it. Where a step or the
    /// origin would leave the normal floats (boxes within ~1e-36 of zero), the scaled children's
    /// boxes are packed again instead, as [`GpuNode::new`] packs any.
    pub fn scaled_pow2(self, k: i32) -> GpuNode {
        let s = crate::geom::scale::pow2(k);
        let origin = self.origin.map(|x| x * s);
        let mut exponents = 0;
        let axes = self.planes.iter().zip(self.origin.iter().zip(&origin));
        for (axis, (&planes, (&was, &now))) in axes.enumerate() {
            let e = (self.exponents >> (8 * axis)) & 0xff;
            let e = match planes {
                0 => e as i32,
                _ => e as i32 + k,
            };
            let normal = was == 0.0 || now.is_normal();
            if !(MIN_EXPONENT as i32..=MAX_EXPONENT as i32).contains(&e) || !normal {
                let [a, b] = self.children().map(|c| ChildRef {
                    bounds: Aabb {
                        min: c.bounds.min * s,
                        max: c.bounds.max * s,
                    },
                    ..c
                });
                return GpuNode::new(a, b);
            }
            exponents |= (e as u32) << (8 * axis);
        }
        GpuNode {
            origin,
            exponents,
            ..self
        }
    }

    /// Packs two children, `a` and `b`, into one node, each box rounded outward to the node's
    /// grid; [`GpuNode::children`] decodes them, boxes containing the given ones. An absent child
    /// (a leaf of no triangles) or one with an empty box keeps no box of its own: it decodes to
    /// the point `origin`, which only reaches a leaf with nothing to test.
    pub fn new(a: ChildRef, b: ChildRef) -> Self {
        let span = |c: &ChildRef| {
            let present = !c.is_absent() && c.bounds.min.cmple(c.bounds.max).all();
            present.then_some(c.bounds)
        };
        let boxes = [span(&a), span(&b)];
        let origin = boxes
            .iter()
            .flatten()
            .fold(None, |m: Option<Vec3>, b| {
                Some(m.map_or(b.min, |m| m.min(b.min)))
            })
            .unwrap_or(Vec3::ZERO);
        let mut exponents = 0u32;
        let mut planes = [0u32; 3];
        let mut origin = origin;
        let widest = (0..3)
            .map(|axis| {
                let spans = boxes.iter().flatten().map(|b| (b.min[axis], b.max[axis]));
                let top = spans
                    .clone()
                    .fold(origin[axis] as f64, |m, (_, hi)| m.max(hi as f64));
                top - origin[axis] as f64
            })
            .fold(0.0, f64::max);
        for axis in 0..3 {
            let spans = boxes.map(|b| b.map(|b| (b.min[axis], b.max[axis])));
            let (o, e, q) = quantize_axis(origin[axis], spans, widest);
            origin[axis] = o;
            exponents |= e << (8 * axis);
            planes[axis] = q[0] | q[1] << 8 | q[2] << 16 | q[3] << 24;
        }
        GpuNode {
            origin: origin.to_array(),
            exponents,
            planes,
            a_child: a.child,
            a_count: a.count,
            b_child: b.child,
            b_count: b.count,
            pad: 0,
        }
    }

    /// The two children, `a` then `b`, with their boxes as decoded (as the shaders decode them).
    pub fn children(&self) -> [ChildRef; 2] {
        let boxes = self.boxes();
        [
            ChildRef {
                bounds: boxes[0],
                child: self.a_child,
                count: self.a_count,
            },
            ChildRef {
                bounds: boxes[1],
                child: self.b_child,
                count: self.b_count,
            },
        ]
    }

    /// The decoded boxes of children `a` and `b` (`glsl/bvh.glsl`'s `rbvh_node_boxes`).
    pub fn boxes(&self) -> [Aabb; 2] {
        let origin = Vec3::from(self.origin);
        let mut out = [Aabb {
            min: origin,
            max: origin,
        }; 2];
        for axis in 0..3 {
            let step = grid_step((self.exponents >> (8 * axis)) & 0xff);
            let q = |k: u32| plane(origin[axis], (self.planes[axis] >> (8 * k)) & 0xff, step);
            out[0].min[axis] = q(0);
            out[0].max[axis] = q(1);
            out[1].min[axis] = q(2);
            out[1].max[axis] = q(3);
        }
        out
    }

    /// Why this record cannot be a node: a non-finite origin, an exponent outside 1..=254, or a
    /// nonzero byte 3 of `exponents` or `pad` (checked on loading a file).
    pub fn malformation(&self) -> Option<String> {
        if !Vec3::from(self.origin).is_finite() {
            return Some(format!("origin {:?} is not finite", self.origin));
        }
        for axis in 0..3 {
            let e = (self.exponents >> (8 * axis)) & 0xff;
            if !(MIN_EXPONENT..=MAX_EXPONENT).contains(&e) {
                return Some(format!(
                    "grid exponent {e} of axis {axis} is outside 1..=254"
                ));
            }
        }
        if self.exponents >> 24 != 0 || self.pad != 0 {
            return Some("reserved bits are set".to_string());
        }
        None
    }
}

/// A triangle in BVH order, vertices gathered so that a leaf is one contiguous read. 48 bytes:
/// `v0` + `prim` (the triangle's index in the scene, reported as the hit `id`), `v1` + `flags`,
/// `v2` + pad.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuTriangle {
    /// GLSL `BvhTriangle.v0`: first vertex, world space.
    pub v0: [f32; 3],
    /// GLSL `prim`: the triangle's index in the scene, returned as the hit `id`.
    pub prim: u32,
    /// GLSL `v1`: second vertex, world space.
    pub v1: [f32; 3],
    /// GLSL `flags`: `PART | leaf << 2` for an exact part beside height-field leaf `leaf`
    /// ([`GpuTriangle::PART`]), with [`GpuTriangle::BARE`] too where it stands in for a bare
    /// stretch of that field; else 0. The tracers ignore it (it pads `v1` to 16 bytes).
    pub flags: u32,
    /// GLSL `v2`: third vertex, world space; winding `v0, v1, v2` gives [`GpuTriangle::normal`].
    pub v2: [f32; 3],
    /// GLSL `pad2`: padding to 16 bytes; always 0.
    pub pad2: u32,
}
const _: () = assert!(std::mem::size_of::<GpuTriangle>() == 48);

impl GpuTriangle {
    /// This triangle in a world `2^k` times larger, exactly (`geom::scale`).
    pub fn scaled_pow2(self, k: i32) -> GpuTriangle {
        let s = crate::geom::scale::pow2(k);
        GpuTriangle {
            v0: self.v0.map(|x| x * s),
            v1: self.v1.map(|x| x * s),
            v2: self.v2.map(|x| x * s),
            ..self
        }
    }

    /// The bit of [`GpuTriangle::flags`] that marks an RBVH's *exact part*: a leaf's own
    /// triangle (or its part) traced exactly beside the height field that leaves it uncovered
    /// (`rbvh::raster::Exposed`), whose leaf index the bits from bit 2 up name. It is traced like
    /// any triangle, and its hits read that leaf's colours (`Rbvh::locate`).
    pub const PART: u32 = 1;

    /// The bit of [`GpuTriangle::flags`] that marks an exact part over bare cells of its height
    /// field (no cell triangle there): the only surface the leaf has there, which
    /// level-of-detail grids sample. They leave the other parts out: the height field beside
    /// them stands for that surface already, and their samples only widened the solid columns
    /// (an image-based-lighting render with level of detail at bias −2 lost FLIP 0.0164 →
    /// 0.0186 when more such parts came, and not without them).
    pub const BARE: u32 = 2;

    /// The flags of an exact part beside height-field leaf `leaf`, over bare cells of it or not:
    /// `PART | BARE? | leaf << 2` (read back by [`GpuTriangle::part_leaf`]).
    pub fn part_flags(leaf: u32, bare: bool) -> u32 {
        Self::PART | if bare { Self::BARE } else { 0 } | leaf << 2
    }

    /// The height-field leaf an exact part stands beside ([`GpuTriangle::PART`]); None for any
    /// other triangle.
    pub fn part_leaf(&self) -> Option<u32> {
        (self.flags & Self::PART != 0).then_some(self.flags >> 2)
    }

    /// Packs the vertices `[v0, v1, v2]` (winding kept) of scene triangle `prim`, padding zeroed.
    pub fn new([a, b, c]: [Vec3; 3], prim: u32) -> Self {
        GpuTriangle {
            v0: a.to_array(),
            prim,
            v1: b.to_array(),
            flags: 0,
            v2: c.to_array(),
            pad2: 0,
        }
    }

    /// The vertices `[v0, v1, v2]`, world space.
    pub fn vertices(&self) -> [Vec3; 3] {
        [self.v0.into(), self.v1.into(), self.v2.into()]
    }

    /// The unit geometric normal as wound, `normalize((v1 − v0) × (v2 − v0))`
    /// ([`crate::geom::unit_normal`], at any scale); zero for a degenerate triangle (which the
    /// watertight test never reports as hit).
    pub fn normal(&self) -> Vec3 {
        Self::normal_of(self.vertices())
    }

    /// [`GpuTriangle::normal`] of vertices `[v0, v1, v2]` however they are stored (an RBVH's
    /// indexed triangles, `crate::rbvh::ExactTriangles`, too).
    pub fn normal_of([a, b, c]: [Vec3; 3]) -> Vec3 {
        crate::geom::unit_normal(a, b, c)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::random::SplitMix64;

    fn child(min: Vec3, max: Vec3, child: u32) -> ChildRef {
        ChildRef {
            bounds: Aabb { min, max },
            child,
            count: 0,
        }
    }

    fn contains(outer: Aabb, inner: Aabb) -> bool {
        outer.min.cmple(inner.min).all() && outer.max.cmpge(inner.max).all()
    }

    /// Packs `a` and `b` and checks the decoded boxes: each contains its child's and is wider by
    /// at most two grid steps per plane (one for rounding to the grid, one for the origin's
    /// rounding), the grid step being at most twice the node's extent over 255. Where `q · step`
    /// passes `f32::MAX` (a node spanning more than half the float range) the plane is +∞:
    /// still a box that contains, no longer a tight one.
    fn check_pair(a: ChildRef, b: ChildRef) {
        let node = GpuNode::new(a, b);
        assert_eq!(node.malformation(), None, "{a:?} {b:?}");
        let [da, db] = node.children();
        let node_box = a.bounds.union(b.bounds);
        for (given, decoded) in [(a, da), (b, db)] {
            assert_eq!((decoded.child, decoded.count), (given.child, given.count));
            assert!(
                contains(decoded.bounds, given.bounds),
                "{given:?} decoded as {decoded:?}"
            );
            // Strictly: a ray on a decoded plane runs outside the child (quantize_axis).
            assert!(
                decoded.bounds.min.cmplt(given.bounds.min).all()
                    && decoded.bounds.max.cmpgt(given.bounds.max).all(),
                "{given:?} decoded as {decoded:?}: a plane on the child's"
            );
            let widest = (0..3)
                .map(|axis| (node_box.max[axis] as f64 - node_box.min[axis] as f64).max(0.0))
                .fold(0.0, f64::max);
            for axis in 0..3 {
                let extent = (node_box.max[axis] as f64 - node_box.min[axis] as f64).max(0.0);
                let step = f32::from_bits(((node.exponents >> (8 * axis)) & 0xff) << 23) as f64;
                let ulp = (node_box.min[axis].abs().max(node_box.max[axis].abs()) as f64)
                    * f32::EPSILON as f64;
                // A flat axis steps as the widest; the origin a step below the box widens the
                // grid's span by that step (255 steps over the extent and one more).
                let spanned = if extent > 0.0 { extent } else { widest };
                assert!(step <= (2.0 * spanned / 254.0).max(f32::MIN_POSITIVE as f64) + 2.0 * ulp);
                let slack = 2.0 * step + ulp;
                if decoded.bounds.max[axis].is_infinite() {
                    assert!(extent > f32::MAX as f64 / 2.0, "{decoded:?}");
                    continue;
                }
                assert!(
                    given.bounds.min[axis] as f64 - decoded.bounds.min[axis] as f64 <= slack
                        && decoded.bounds.max[axis] as f64 - given.bounds.max[axis] as f64 <= slack,
                    "axis {axis}: {given:?} decoded as {decoded:?} (step {step})"
                );
            }
        }
    }

    #[test]
    fn decoded_boxes_contain_the_given_ones_and_stay_tight() {
        let mut rng = SplitMix64::new(7);
        let mut unit = || (rng.next_u64() >> 40) as f32 / (1u64 << 24) as f32;
        for scale in [1e-30f32, 1e-6, 1.0, 3.7, 1e4, 1e30] {
            for offset in [0.0f32, -1e3, 1e6, 1e-3] {
                for _ in 0..200 {
                    let mut corner =
                        || Vec3::new(unit(), unit(), unit()) * scale + Vec3::splat(offset * scale);
                    let (p, q, r, s) = (corner(), corner(), corner(), corner());
                    check_pair(child(p.min(q), p.max(q), 1), child(r.min(s), r.max(s), 2));
                }
            }
        }
    }

    #[test]
    fn flat_point_and_extreme_boxes_stay_conservative() {
        let big = f32::MAX / 2.0;
        let cases = [
            // Flat along y, a point, far apart.
            (
                child(Vec3::new(0.0, 1.0, 0.0), Vec3::new(2.0, 1.0, 2.0), 1),
                child(Vec3::splat(5.0), Vec3::splat(5.0), 2),
            ),
            // Across almost the whole float range.
            (
                child(Vec3::splat(-big), Vec3::splat(-big / 2.0), 1),
                child(Vec3::splat(big / 3.0), Vec3::splat(big), 2),
            ),
            // Tiny boxes near a large offset: steps below the coordinates' ulp.
            (
                child(Vec3::splat(1e7), Vec3::splat(1e7 + 1.0), 1),
                child(Vec3::splat(1e7 + 2.0), Vec3::splat(1e7 + 2.0), 2),
            ),
            // Subnormal coordinates.
            (
                child(Vec3::splat(0.0), Vec3::splat(1e-40), 1),
                child(Vec3::splat(-1e-42), Vec3::splat(1e-39), 2),
            ),
        ];
        for (a, b) in cases {
            check_pair(a, b);
        }
    }

    #[test]
    fn an_absent_child_is_a_point_at_the_origin_and_takes_no_room() {
        let a = child(Vec3::new(10.0, 20.0, 30.0), Vec3::new(11.0, 22.0, 33.0), 3);
        let node = GpuNode::new(a, ChildRef::ABSENT);
        let [da, db] = node.children();
        assert!(contains(da.bounds, a.bounds));
        assert_eq!((db.child, db.count), (LEAF_BIT, 0));
        assert_eq!(db.bounds.min, Vec3::from(node.origin));
        assert_eq!(db.bounds.max, Vec3::from(node.origin));
        // The absent child's point at zero did not stretch the grid: the step fits `a` alone,
        // and the origin lies a float below it.
        let below = [10.0f32, 20.0, 30.0].map(next_down);
        assert_eq!(node.origin, below);
        assert!(da.bounds.max.x - a.bounds.max.x <= 2.0 / 255.0);
        // Both absent (an empty tree's root): a valid node of two points.
        let empty = GpuNode::new(ChildRef::ABSENT, ChildRef::ABSENT);
        assert_eq!(empty.malformation(), None);
    }

    #[test]
    fn malformed_records_are_named() {
        let good = GpuNode::new(
            child(Vec3::ZERO, Vec3::ONE, 1),
            child(Vec3::ONE, Vec3::splat(2.0), 2),
        );
        let mut nan = good;
        nan.origin[1] = f32::NAN;
        assert!(nan.malformation().unwrap().contains("origin"));
        let mut zero_exponent = good;
        zero_exponent.exponents &= !0xff00;
        assert!(zero_exponent.malformation().unwrap().contains("axis 1"));
        let mut reserved = good;
        reserved.pad = 1;
        assert!(reserved.malformation().unwrap().contains("reserved"));
    }
}

/// One instance of a two-level structure ([`InstancedBvh`](super::InstancedBvh)): what a ray
/// needs to enter it. 64 bytes.
///
/// | bytes | field |
/// |---|---|
/// | 0..48 | `world_to_mesh`: rows 0..3 of the inverse of the instance's transform |
/// | 48..52, 52..56, 56..64 | `root`, `mesh`, `pad` |
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuInstance {
    /// World to mesh space, the affine inverse of the instance's transform by rows: `p'_i =
    /// dot(row_i.xyz, p) + row_i.w`. Rays are taken into the mesh's space by it and normals out
    /// by its transpose.
    pub world_to_mesh: [[f32; 4]; 3],
    /// Node index of the root of the instance's mesh's tree.
    pub root: u32,
    /// The mesh the instance places ([`crate::scene::Instance::mesh`]).
    pub mesh: u32,
    /// Keeps the record four 16-byte words; always 0.
    pub pad: [u32; 2],
}
const _: () = assert!(std::mem::size_of::<GpuInstance>() == 64);

impl GpuInstance {
    /// The record of an instance placed by `transform` (affine and invertible: see
    /// [`crate::scene::transform_fault`]) whose mesh's tree starts at node `root`.
    pub fn new(transform: Mat4, root: u32, mesh: u32) -> GpuInstance {
        let inverse = transform.inverse();
        GpuInstance {
            world_to_mesh: [0, 1, 2].map(|i| inverse.row(i).to_array()),
            root,
            mesh,
            pad: [0; 2],
        }
    }

    fn rows(&self) -> [Vec4; 3] {
        self.world_to_mesh.map(Vec4::from_array)
    }

    /// The linear part of [`GpuInstance::world_to_mesh`].
    fn linear(&self) -> Mat3 {
        let [x, y, z] = self.rows().map(|r| r.truncate());
        Mat3::from_cols(x, y, z).transpose()
    }

    /// `ray` in the instance's mesh space: origin and direction transformed, the direction not
    /// normalized, so that a hit's `t` is the same along both, and `tmin`, `tmax` kept.
    pub fn ray_into(&self, ray: &Ray) -> Ray {
        let o = ray.origin();
        let origin = Vec3::from_array(self.rows().map(|r| r.truncate().dot(o) + r.w));
        Ray::new(origin, self.linear() * ray.dir(), ray.tmin, ray.tmax)
    }

    /// A normal of the mesh's space in world space: the inverse transpose of the transform,
    /// normalized; for a mirroring transform it points as the flat copy's (whose winding
    /// [`crate::scene::Scene::append`] reverses) does.
    pub fn normal_out(&self, normal: Vec3) -> Vec3 {
        crate::geom::unit(self.linear().transpose() * normal)
    }
}
