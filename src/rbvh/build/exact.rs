//! Which triangles are traced exactly because that costs fewer bytes than sampling them
//! (`exact_when_cheaper`, on in the presets; `exact_edge_fraction`, `exact_crease_deg`): before
//! the recursion every triangle large enough, long enough or on a crease
//! ([`Builder::exact_by_size`]), and in it every set whose tiles would cost more than its
//! triangles ([`sampled_bytes`]) — the paper's "triangle leaves where needed" (Novák &
//! Dachsbacher 2012), decided by the bytes each way.

use super::{Builder, Input};
use crate::bvh::GpuTriangle;
use crate::rbvh::raster::Tile;
use crate::rbvh::TexelFormat;

/// What a triangle traced exactly costs: its 48 bytes gathered ([`GpuTriangle`]) and, alone in
/// its leaf, the 48-byte node above it. A triangle whose area covers at least the texels these
/// bytes buy (24 with normals, 48 height-only) is traced exactly instead of sampled
/// ([`Builder::exact_by_size`]). The device has held the triangles indexed since
/// `crate::rbvh::ExactTriangles` (16 bytes a slot and 16 a distinct vertex); the rule still
/// counts them gathered, as it was tuned and measured (docs/paper-scale.md, "Exact triangles
/// indexed"), so indexing changed no structure.
pub(super) const EXACT_TRIANGLE_BYTES: f32 = 96.0;

/// The least longest edge, in texels of its object, of a triangle that
/// [`RbvhParams::exact_crease_deg`](crate::rbvh::RbvhParams::exact_crease_deg) traces exactly: a
/// crease shorter than that is detail the texels average (a scan's noise meets its neighbours at
/// 30° and more in many places, and at 1 texel the dragon's Q4 took 8.5% more bytes for the same
/// accuracy; at 2, 1.4%: docs/paper-scale.md, "What the view asks of Q0").
pub const CREASE_EDGE_TEXELS: f32 = 2.0;

impl Builder<'_> {
    /// The scene's triangles split into those to sample (their indices, the construction's
    /// `order`) and, with `exact_when_cheaper`, those traced exactly because that costs fewer
    /// bytes: a triangle whose area covers at least [`EXACT_TRIANGLE_BYTES`] worth of texels of
    /// its object ([`Builder::texel_of`]), at the texel format's full bytes a texel. Such a triangle has no detail between its corners for
    /// texels to sample: a wall, a floor, a column's face, a cube's side. Sampled, it would also
    /// be widened at its silhouette by the dilated rim, the largest error on architecture (the
    /// columns and arches of the paper-scale scene's Sponza). With
    /// [`RbvhParams::exact_edge_fraction`], so is every triangle whose longest edge is at least
    /// that fraction of its object's diagonal, and with [`RbvhParams::exact_crease_deg`] every
    /// triangle on a crease that spans [`CREASE_EDGE_TEXELS`] texels. Points have no such
    /// triangles.
    pub(super) fn exact_by_size(&self) -> (Vec<u32>, Vec<GpuTriangle>) {
        let all = match self.input {
            Input::Triangles(all) if self.params.exact_when_cheaper => all,
            _ => return ((0..self.prims.len() as u32).collect(), Vec::new()),
        };
        let texels = if self.params.exact_from_texels > 0.0 {
            self.params.exact_from_texels
        } else {
            EXACT_TRIANGLE_BYTES / self.params.texels.bytes() as f32
        };
        let (mut sampled, mut exact) = (Vec::new(), Vec::new());
        for (i, &[a, b, c]) in (0u32..).zip(all.iter()) {
            let texel = self.texel_of(&[i]);
            let area = 0.5 * (b - a).cross(c - a).length();
            let longest = (b - a).length().max((c - b).length()).max((a - c).length());
            if area >= texels * texel * texel
                || self.long_edge(i, longest)
                || self.on_crease(i, longest, texel)
            {
                exact.push(GpuTriangle::new([a, b, c], i));
            } else {
                sampled.push(i);
            }
        }
        (sampled, exact)
    }

    /// Whether triangle `i`, whose longest edge is `longest`, has an edge of at least
    /// [`RbvhParams::exact_edge_fraction`] of its object's diagonal (never where that is 0).
    fn long_edge(&self, i: u32, longest: f32) -> bool {
        let Some(&diagonal) = self
            .objects
            .get(i as usize)
            .and_then(|&o| self.object_diagonal.get(o as usize))
        else {
            return false;
        };
        longest >= self.params.exact_edge_fraction * diagonal
    }

    /// Whether triangle `i`, whose longest edge is `longest`, meets a neighbour at a crease of at
    /// least [`RbvhParams::exact_crease_deg`] (never where that is 0) with an edge of at least
    /// [`CREASE_EDGE_TEXELS`] of its object's `texel`.
    fn on_crease(&self, i: u32, longest: f32, texel: f32) -> bool {
        let angle = self.params.exact_crease_deg;
        let on = self.creases.get(i as usize).is_some_and(|&c| c >= angle);
        angle > 0.0 && on && longest >= CREASE_EDGE_TEXELS * texel
    }
}

/// The bytes a height field of `tiles` beside `parts` exact parts is priced at: each tile's texels
/// at [`TexelFormat::bytes`] (one byte less for 8-bit heights; what the device kept before it
/// kept normals only where there are samples, left so that the structures stay as measured),
/// its 64-byte leaf record and a 48-byte node over it, and each part's triangle at its 48 bytes
/// gathered (as [`EXACT_TRIANGLE_BYTES`] counts it).
pub(super) fn sampled_bytes(tiles: &[Tile], parts: usize, format: TexelFormat) -> f32 {
    let tiles: u64 = tiles
        .iter()
        .map(|tile| {
            // 12- and 10-bit tiles are priced as 16-bit ones: priced at their bits, fewer
            // triangles were traced exactly, for more bytes in all and less accuracy
            // (docs/paper-scale.md, "Heights in 10 and 12 bits").
            let texel = format.bytes() - u64::from(tile.bits == 8);
            tile.texels.len() as u64 * texel + 64 + 48
        })
        .sum();
    (tiles + parts as u64 * 48) as f32
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use crate::rbvh::{Rbvh, TexelFormat};
    use crate::scene::Scene;

    /// The default scene's ground triangles cover 27 texels each at Q2: at 4 bytes a texel (108)
    /// more than a triangle traced exactly costs (96), at 2 (54) less. So with normals every
    /// ground triangle is traced exactly, whole (not an exact part), and height-only none is;
    /// the sphere's triangles (under 2 texels each) are sampled in both.
    #[test]
    fn triangles_that_cost_more_as_texels_are_traced_exactly() {
        let scene = Scene::builtin("default").unwrap();
        let objects = &scene.object_of_triangle;
        let object = |name: &str| {
            let o = scene.object_names.iter().position(|n| n == name).unwrap() as u32;
            let of = move |prim: u32| objects[prim as usize] == o;
            (of, objects.iter().filter(|&&x| x == o).count())
        };
        let (ground, ground_count) = object("ground");
        let (sphere, _) = object("sphere");
        let whole = |r: &Rbvh, of: &dyn Fn(u32) -> bool| {
            r.triangles
                .iter()
                .filter(|t| t.part_leaf().is_none() && of(t.prim))
                .count()
        };
        let mut params = crate::rbvh::RbvhParams {
            exact_when_cheaper: true,
            ..crate::rbvh::RbvhParams::quality(2).unwrap()
        };
        let r = Rbvh::build(&scene, &params).unwrap();
        assert_eq!(whole(&r, &ground), ground_count);
        assert_eq!(whole(&r, &sphere), 0);
        params.texels = TexelFormat::Height;
        let r = Rbvh::build(&scene, &params).unwrap();
        assert_eq!(whole(&r, &ground), 0);
        assert_eq!(whole(&r, &sphere), 0);
    }

    /// A unit square in one object, cut into `cells` × `cells` cells of two triangles each.
    fn square(cells: u32) -> Scene {
        let n = cells + 1;
        let positions: Vec<Vec3> = (0..n * n)
            .map(|k| Vec3::new((k % n) as f32, (k / n) as f32, 0.0) / cells as f32)
            .collect();
        let mut triangles = Vec::new();
        for j in 0..cells {
            for i in 0..cells {
                let k = j * n + i;
                triangles.push([k, k + 1, k + n + 1]);
                triangles.push([k, k + n + 1, k + n]);
            }
        }
        let mut scene = Scene::new("square");
        scene.push_object("square", &positions, &triangles);
        scene
    }

    /// At 9 texels along its diagonal a unit square's two triangles cover 20.25 texels each,
    /// under what a triangle alone must cover to be traced exactly (24 with normals), but its
    /// tile, with the ring of samples around it, costs more than the two triangles do (192
    /// bytes): the set is traced exactly, in either texel format. Cut into 16 × 16 cells, its
    /// 512 triangles cost more than that tile: it is sampled.
    #[test]
    fn a_set_whose_tiles_cost_more_than_its_triangles_is_traced_exactly() {
        for format in [TexelFormat::HeightNormal, TexelFormat::Height] {
            let params = crate::rbvh::RbvhParams {
                texels_per_diagonal: 9.0,
                texels: format,
                exact_when_cheaper: true,
                ..crate::rbvh::RbvhParams::quality(2).unwrap()
            };
            let r = Rbvh::build(&square(1), &params).unwrap();
            assert!(
                r.heightfields.is_empty(),
                "{format:?}: {} leaves",
                r.heightfields.len()
            );
            assert_eq!(r.triangles.len(), 2);
            assert!(r.triangles.iter().all(|t| t.part_leaf().is_none()));
            let r = Rbvh::build(&square(16), &params).unwrap();
            assert!(!r.heightfields.is_empty(), "{format:?}");
            assert!(r.triangles.is_empty(), "{format:?}: {}", r.triangles.len());
        }
    }
}
