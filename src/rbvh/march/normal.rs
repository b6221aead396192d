//! Step 5 of the height-field march (see [`super`]): a hit's **normal** — the stored normal of the
//! corner sample nearest the hit, or with height-only texels the normal of the cell triangle hit
//! — and the reads the device makes for it once its ray is done, which the twin reports
//! ([`HitNormal`], [`NormalReads`]).

use glam::Vec3;

use super::leaf::{texel, Cells};
use crate::probe::{Array, Read};
use crate::rbvh::layout::{GpuHeightfield, Texel};

/// A height-field hit's normal, and what the device reads for it once its ray is done: what
/// [`RbvhLeafHook::finish`] reports.
#[derive(Clone, Copy, Debug)]
pub(crate) struct HitNormal {
    pub(crate) normal: Vec3,
    pub(super) reads: NormalReads,
}

/// Atlas indices of the texels read for a hit's normal, in order: at most the nearest corner and
/// then the four corners; for a facet's normal (height-only texels), the first corner of each of
/// the cell's rows present in the atlas (the device reads a row's two codes together,
/// [`crate::rbvh::Atlas::pair_read`]), after the leaf's record (`facet`).
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct NormalReads {
    texels: [u32; 5],
    len: usize,
    /// A facet's leaf, and whether the hit is a skirt's: the device makes the facet once the ray
    /// is done from the leaf's frame and the cell's codes, read again
    /// (`rbvh_height_field_facet` in `glsl/rbvh.glsl`), and a skirt's from the frame ray too,
    /// which needs the leaf's origin.
    pub(super) facet: Option<(u32, bool)>,
}

impl NormalReads {
    /// The device's reads of leaf `leaf`'s record for a facet: from `atlas_base` to `h_scale`
    /// (the frame and the tile), and the origin before them for a skirt. Never the whole record,
    /// which only a march reads.
    pub(super) fn facet_leaf_reads(leaf: u32, skirt: bool) -> impl Iterator<Item = Read> {
        let base = u64::from(leaf) * std::mem::size_of::<GpuHeightfield>() as u64;
        let frame = Read {
            array: Array::Heightfields,
            offset: base + 12,
            bytes: 52,
        };
        let origin = Read {
            array: Array::Heightfields,
            offset: base,
            bytes: 12,
        };
        std::iter::once(frame).chain(skirt.then_some(origin))
    }
}

impl NormalReads {
    pub(super) fn push(&mut self, texel: u32) {
        self.texels[self.len] = texel;
        self.len += 1;
    }

    pub(super) fn iter(&self) -> impl Iterator<Item = u32> + '_ {
        self.texels[..self.len].iter().copied()
    }
}

/// The world-space unit normal of the cell triangle `(a, b, c)` (frame coordinates, counter-
/// clockwise in `(s, t)`, so the normal points along `+h`, the side the leaf's surface faces):
/// the frame maps world offsets by the rows `axis_u`, `axis_v`, `axis_w`, so normals map back by
/// its transpose. The hit normal of a height-only RBVH; `glsl/rbvh.glsl` computes it in the same
/// order.
pub(super) fn facet_normal(leaf: &GpuHeightfield, a: Vec3, b: Vec3, c: Vec3) -> Vec3 {
    let n = (b - a).cross(c - a);
    let (u, v, w) = (
        Vec3::from(leaf.axis_u),
        Vec3::from(leaf.axis_v),
        Vec3::from(leaf.axis_w),
    );
    (u * n.x + v * n.y + w * n.z).normalize()
}

impl Cells<'_> {
    /// A facet's `normal` (height-only texels) for a hit in cell `(ci, cj)`, on its skirt or not,
    /// with the reads the device makes for it once the ray is done ([`NormalReads::facet`]).
    pub(super) fn facet(&self, normal: Vec3, (ci, cj): (i64, i64), skirt: bool) -> HitNormal {
        let mut reads = NormalReads {
            facet: Some((self.leaf_index, skirt)),
            ..NormalReads::default()
        };
        for row in 0..2 {
            if let (_, Some(index)) = texel(self.atlas, self.leaf, ci, cj + row) {
                reads.push(index as u32);
            }
        }
        HitNormal { normal, reads }
    }

    /// The normal of the corner sample nearest the point at `t` in cell `(ci, cj)`: sample i sits
    /// at s = i + ½, so the nearest is floor(s) (halves round up), clamped to the cell; a hole
    /// there falls back to the first present corner in the order c00, c10, c01, c11. Unless that
    /// normal faces away from the ray while another present corner's faces it: then the first
    /// such in the same order. Along a silhouette, the nearest sample may lie on the far side of
    /// a spike or a horn (its normal turned away from the viewer), and a hit shaded with it is a
    /// dark speck the exact surface does not have (issue "Small and valid at every scale",
    /// item 5: on the dragon close-up at Q0, 207 of 386 dark pixels).
    ///
    /// The device reads these texels once its ray is done (`rbvh_normal_texel`): the nearest, then
    /// while none faces the ray, each present corner in that order; `HitNormal::reads` lists them.
    pub(super) fn nearest_normal(
        &self,
        corner: &[Texel; 4],
        ci: i64,
        cj: i64,
        t: f32,
    ) -> HitNormal {
        let (o, d) = (self.fr.ray.origin(), self.fr.ray.dir());
        let s = o.x + d.x * t;
        let r = o.y + d.y * t;
        let di = ((s.floor() as i64).clamp(ci, ci + 1) - ci) as usize;
        let dj = ((r.floor() as i64).clamp(cj, cj + 1) - cj) as usize;
        let mut k = di + 2 * dj;
        if corner[k].is_hole() {
            k = (0..4).find(|&q| !corner[q].is_hole()).unwrap_or(k);
        }
        let pitch = i64::from(self.atlas.pitch);
        let k00 = i64::from(self.leaf.atlas_base) + cj * pitch + ci;
        let index = |q: usize| (k00 + (q & 1) as i64 + (q >> 1) as i64 * pitch) as u32;
        let mut reads = NormalReads::default();
        reads.push(index(k));
        let mut nearest = corner[k];
        if !nearest.faces(self.dir) {
            for q in (0..4).filter(|&q| !corner[q].is_hole()) {
                reads.push(index(q));
                if corner[q].faces(self.dir) {
                    nearest = corner[q];
                    break;
                }
            }
        }
        HitNormal {
            normal: nearest.normal(),
            reads,
        }
    }
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::super::tests::*;
    use crate::rbvh::layout::{Texel, LEAF_BIT};

    #[test]
    fn normal_is_the_nearest_samples() {
        let normal = |i: u32, j: u32| Vec3::new(i as f32 - 3.5, 8.0, j as f32 - 3.5).normalize();
        let l = flat_leaf(1.0, 8, 8, 0.0);
        let r = single(l, tile(8, 8, |i, j| Texel::new(0, normal(i, j))));
        for (s, t, i, j) in [
            (2.3, 3.8, 2, 3),
            (2.7, 3.2, 2, 3),
            (3.1, 0.6, 3, 0),
            (6.9, 7.4, 6, 7),
        ] {
            let p = world(&l, s, t, 0.0);
            let hit = assert_hit(&r, &down(p.x, p.z), 9.0, LEAF_BIT);
            assert!(
                hit.normal().dot(normal(i, j)) > 0.9999,
                "({s}, {t}) → {hit:?}"
            );
        }
    }
}
