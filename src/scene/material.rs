//! Surface materials of a scene: a base colour per triangle, from a constant factor times an
//! optional texture looked up by per-corner texture coordinates. Only scenes whose files carry
//! materials have them ([`super::Scene::surface`] is `None` otherwise), so a plain mesh pays
//! nothing.
//!
//! Texture coordinates are stored per triangle corner rather than per vertex: OBJ indexes them
//! separately from positions, and storing them per vertex would split vertices along every UV
//! seam, changing the geometry every builder sees. Per corner keeps positions and triangles
//! exactly as without materials, so BVH and RBVH builds are the same with and without them.

use std::sync::Arc;

use glam::{Vec2, Vec3, Vec4};

use super::mipmap::MipChain;
use super::texture::{Texture, Wrap};

/// Material id of a triangle without a material: its base colour is white, so that shading
/// multiplied by it is unchanged.
pub const NO_MATERIAL: u32 = u32::MAX;

/// A base colour: `factor` (linear RGBA; glTF `baseColorFactor`, OBJ `Kd` with alpha 1) times
/// the `texture` sample when there is one (glTF `baseColorTexture`, OBJ `map_Kd`).
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    /// The name in the source file (OBJ `newmtl`, glTF `name` or `material<index>`).
    pub name: String,
    /// Constant linear RGBA that the texture sample is multiplied by; the whole colour without a
    /// texture.
    pub factor: Vec4,
    /// Shared, so that instances of one mesh share its images.
    pub texture: Option<Arc<Texture>>,
    /// Wrap modes along u and v.
    pub wrap: [Wrap; 2],
}

impl Material {
    /// A constant colour.
    pub fn constant(name: impl Into<String>, factor: Vec4) -> Material {
        Material {
            name: name.into(),
            factor,
            texture: None,
            wrap: [Wrap::Repeat; 2],
        }
    }

    /// Linear RGBA at texture coordinate `uv`.
    pub fn colour(&self, uv: Vec2) -> Vec4 {
        match &self.texture {
            Some(t) => self.factor * t.sample(uv, self.wrap),
            None => self.factor,
        }
    }

    /// The longer side, in texels of this material's texture, of a patch whose sides span the
    /// texture-coordinate steps `d_uv`; 0 without a texture.
    pub(crate) fn footprint(&self, d_uv: [Vec2; 2]) -> f32 {
        match &self.texture {
            Some(t) => {
                let size = Vec2::new(t.width as f32, t.height as f32);
                (d_uv[0] * size).length().max((d_uv[1] * size).length())
            }
            None => 0.0,
        }
    }

    /// Linear RGBA over a patch `footprint` texels wide around `uv` ([`Material::footprint`]),
    /// sampled from `mips`, the mip chain of this material's texture, so that a patch covering
    /// many texels gets their mean instead of one of them.
    pub(crate) fn colour_over(&self, uv: Vec2, footprint: f32, mips: &MipChain) -> Vec4 {
        match &self.texture {
            Some(t) => {
                debug_assert!(mips.is_of(t), "the mip chain of another texture");
                self.factor * mips.sample(uv, self.wrap, footprint)
            }
            None => self.factor,
        }
    }
}

/// Per-triangle materials and texture coordinates, parallel to [`super::Scene::triangles`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SurfaceMaterials {
    /// The scene's materials, indexed by `material_of_triangle`.
    pub materials: Vec<Material>,
    /// Per triangle, an index into `materials` or [`NO_MATERIAL`].
    pub material_of_triangle: Vec<u32>,
    /// Per triangle, the texture coordinates of its three corners (in the triangle's winding).
    pub uv_of_triangle: Vec<[Vec2; 3]>,
    /// Per triangle, the linear RGBA vertex colours of its three corners (glTF `COLOR_0`), which
    /// multiply the material's colour; only when some object has them (white for the others).
    pub colour_of_triangle: Option<Vec<[Vec4; 3]>>,
}

impl SurfaceMaterials {
    /// Linear RGBA of triangle `triangle` at barycentrics `bary` (weights of its three corners):
    /// its material's colour (white without one, or out of range) times its vertex colour.
    pub fn colour(&self, triangle: usize, bary: Vec3) -> Vec4 {
        let material = match self.material(triangle) {
            Some(material) => material.colour(self.uv(triangle, bary)),
            None => Vec4::ONE,
        };
        material * self.vertex_colour(triangle, bary)
    }

    /// The vertex colour of triangle `triangle` at barycentrics `bary`; white without vertex
    /// colours or out of range.
    pub fn vertex_colour(&self, triangle: usize, bary: Vec3) -> Vec4 {
        match self
            .colour_of_triangle
            .as_ref()
            .and_then(|c| c.get(triangle))
        {
            Some([a, b, c]) => *a * bary.x + *b * bary.y + *c * bary.z,
            None => Vec4::ONE,
        }
    }

    /// The material of triangle `triangle`; `None` without one or out of range.
    pub fn material(&self, triangle: usize) -> Option<&Material> {
        self.material_of_triangle
            .get(triangle)
            .and_then(|&m| self.materials.get(m as usize))
    }

    /// Texture coordinates of triangle `triangle` at barycentrics `bary`, which may lie outside
    /// the triangle (the corners' coordinates extrapolate linearly); `(0, 0)` out of range.
    pub fn uv(&self, triangle: usize, bary: Vec3) -> Vec2 {
        let [a, b, c] = self
            .uv_of_triangle
            .get(triangle)
            .copied()
            .unwrap_or([Vec2::ZERO; 3]);
        a * bary.x + b * bary.y + c * bary.z
    }
}

/// Barycentrics of `p` projected onto the plane of `tri`, clamped to the triangle (so that points
/// a little off it, from rounding or dilation, take the colour of its nearest part). A degenerate
/// triangle gives its first corner.
pub fn barycentrics(tri: [Vec3; 3], p: Vec3) -> Vec3 {
    let [a, b, c] = tri.map(|v| v.as_dvec3());
    let p = p.as_dvec3();
    let (e1, e2, d) = (b - a, c - a, p - a);
    let (d11, d12, d22) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
    let (dp1, dp2) = (d.dot(e1), d.dot(e2));
    let det = d11 * d22 - d12 * d12;
    if det.is_nan() || det <= 0.0 || det.is_infinite() {
        return Vec3::X;
    }
    let v = (d22 * dp1 - d12 * dp2) / det;
    let w = (d11 * dp2 - d12 * dp1) / det;
    clamp_to_triangle(glam::DVec3::new(1.0 - v - w, v, w))
}

/// Barycentrics of a point outside the triangle (some negative) moved onto it: negatives clamped
/// to 0 and the rest renormalised; the first corner when nothing is left (or not finite).
pub(crate) fn clamp_to_triangle(bary: glam::DVec3) -> Vec3 {
    let bary = bary.max(glam::DVec3::ZERO);
    let sum = bary.x + bary.y + bary.z;
    if sum > 0.0 && sum.is_finite() {
        (bary / sum).as_vec3()
    } else {
        Vec3::X
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn barycentrics_reproduce_the_point_and_clamp() {
        let tri = [Vec3::ZERO, Vec3::X, Vec3::Y];
        let b = barycentrics(tri, Vec3::new(0.25, 0.5, 3.0));
        assert!((b - Vec3::new(0.25, 0.25, 0.5)).abs().max_element() < 1e-6);
        let b = barycentrics(tri, Vec3::new(2.0, 0.0, 0.0));
        assert_eq!(b, Vec3::new(0.0, 1.0, 0.0));
        assert_eq!(barycentrics([Vec3::ZERO; 3], Vec3::ONE), Vec3::X);
    }

    #[test]
    fn colour_is_factor_times_texture_and_white_without_material() {
        let texture = Arc::new(Texture {
            name: "t".into(),
            width: 1,
            height: 1,
            texels: vec![[255, 255, 255, 128]],
        });
        let s = SurfaceMaterials {
            materials: vec![Material {
                texture: Some(texture),
                ..Material::constant("m", Vec4::new(0.5, 0.25, 1.0, 1.0))
            }],
            material_of_triangle: vec![0, NO_MATERIAL],
            uv_of_triangle: vec![[Vec2::ZERO; 3]; 2],
            colour_of_triangle: None,
        };
        let c = s.colour(0, Vec3::X);
        assert!(
            (c - Vec4::new(0.5, 0.25, 1.0, 128.0 / 255.0))
                .abs()
                .max_element()
                < 1e-6
        );
        assert_eq!(s.colour(1, Vec3::X), Vec4::ONE);
        assert_eq!(s.colour(7, Vec3::X), Vec4::ONE);

        // Vertex colours multiply, interpolated between the corners; without a material they
        // are the colour.
        let corners = [
            Vec4::new(1.0, 0.0, 0.0, 1.0),
            Vec4::ONE,
            Vec4::new(0.0, 0.0, 1.0, 0.5),
        ];
        let coloured = SurfaceMaterials {
            colour_of_triangle: Some(vec![corners; 2]),
            ..s
        };
        let bary = Vec3::new(0.5, 0.25, 0.25);
        let vertex = Vec4::new(0.75, 0.25, 0.5, 0.875);
        assert!(
            (coloured.vertex_colour(1, bary) - vertex)
                .abs()
                .max_element()
                < 1e-6
        );
        assert!((coloured.colour(1, bary) - vertex).abs().max_element() < 1e-6);
        assert!((coloured.colour(0, bary) - c * vertex).abs().max_element() < 1e-6);
    }
}
