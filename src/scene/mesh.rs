//! The scene's geometry: one shared vertex array, indexed triangles and the object each belongs
//! to. A flat list (rather than a tree of instances) is what both BVH builders consume, and the
//! object ids keep enough structure for per-object statistics and false-colour renders.

use glam::{Mat4, Vec2, Vec3, Vec4};

use super::material::{Material, SurfaceMaterials, NO_MATERIAL};
use super::{Camera, Light};
use crate::geom::Aabb;
use crate::points::PointCloud;
use crate::{Error, Result};

/// Coarsest float32 resolution, as a fraction of the scene diagonal, that
/// [`Scene::precision_warning`] accepts silently: a quarter of a Q0 texel (1/256 of the diagonal).
pub const COORDINATE_RESOLUTION_LIMIT: f32 = 1.0 / 1024.0;

/// Triangles, their objects, and optionally the camera and light of a scene file.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Scene {
    /// The file name or built-in name (or a scene file's `name`), used in messages.
    pub name: String,
    /// World-space vertices shared by all objects (finite once validated).
    pub positions: Vec<Vec3>,
    /// Indices into `positions`.
    pub triangles: Vec<[u32; 3]>,
    /// Per triangle, an index into `object_names`.
    pub object_of_triangle: Vec<u32>,
    /// Per object, its name (OBJ `o`/`g` name, glTF `mesh/primitive`), prefixed with
    /// `scene-name/` for meshes placed by [`Scene::append`].
    pub object_names: Vec<String>,
    /// The camera a scene file asked for.
    pub camera: Option<Camera>,
    /// The light a scene file asked for.
    pub light: Option<Light>,
    /// Materials and texture coordinates, only when some loaded file had materials.
    pub surface: Option<SurfaceMaterials>,
    /// Points of a scan (a `.ply` or `.xyz` file, placed by a scene file, or sampled from the
    /// triangles by [`Scene::sample_points`]). When present, an RBVH is built from them rather
    /// than from the triangles, which stay for the exact BVH: the referee of a point-built RBVH.
    pub points: Option<PointCloud>,
}

/// The surface data of one object for [`Scene::push_textured_object`]: per triangle, a material
/// id returned by [`Scene::add_material`] (or [`NO_MATERIAL`]), its corners' texture coordinates
/// and, where the object has them, its corners' vertex colours.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ObjectSurface {
    /// Per triangle, a material id or [`NO_MATERIAL`].
    pub material_of_triangle: Vec<u32>,
    /// Per triangle, the texture coordinates of its three corners, in its winding.
    pub uv_of_triangle: Vec<[Vec2; 3]>,
    /// Per triangle, the linear RGBA colours of its three corners; `None`: all white.
    pub colour_of_triangle: Option<Vec<[Vec4; 3]>>,
}

impl Scene {
    /// An empty scene called `name`.
    pub fn new(name: impl Into<String>) -> Scene {
        Scene {
            name: name.into(),
            ..Scene::default()
        }
    }

    /// Adds one object: `triangles` index into `positions`, which are appended to the scene's
    /// vertices. Every loader builds its scene through this, so the index offsetting lives in
    /// one place. Indices that would not fit a `u32` saturate, which [`Scene::validate`] reports.
    pub fn push_object(
        &mut self,
        name: impl Into<String>,
        positions: &[Vec3],
        triangles: &[[u32; 3]],
    ) {
        let before = self.triangles.len();
        self.append_parts(
            positions.iter().copied(),
            triangles.iter().copied(),
            std::iter::once(name.into()),
            std::iter::repeat_n(0, triangles.len()),
        );
        self.extend_surface(before, None);
    }

    /// Adds a material to the scene's table (creating the table, with every existing triangle
    /// material-less, on first use) and returns its id for [`Scene::push_textured_object`].
    pub fn add_material(&mut self, material: Material) -> u32 {
        let surface = self.surface_mut();
        surface.materials.push(material);
        saturating_u32(surface.materials.len() - 1)
    }

    /// As [`Scene::push_object`], with a material and texture coordinates per triangle. Lengths
    /// that do not match `triangles` and unknown ids are reported by [`Scene::validate`].
    pub fn push_textured_object(
        &mut self,
        name: impl Into<String>,
        positions: &[Vec3],
        triangles: &[[u32; 3]],
        surface: ObjectSurface,
    ) {
        let before = self.triangles.len();
        self.surface_mut();
        self.append_parts(
            positions.iter().copied(),
            triangles.iter().copied(),
            std::iter::once(name.into()),
            std::iter::repeat_n(0, triangles.len()),
        );
        self.extend_surface(before, Some(surface));
    }

    /// The surface table, created on first use with every existing triangle material-less.
    fn surface_mut(&mut self) -> &mut SurfaceMaterials {
        let n = self.triangles.len();
        self.surface.get_or_insert_with(|| SurfaceMaterials {
            materials: Vec::new(),
            material_of_triangle: vec![NO_MATERIAL; n],
            uv_of_triangle: vec![[Vec2::ZERO; 3]; n],
            colour_of_triangle: None,
        })
    }

    /// Keeps the surface table parallel to the triangles after triangles from index `before` on
    /// were appended: with `added`, its entries; without, material-less ones (only when the scene
    /// has a table at all: scenes without materials get none).
    fn extend_surface(&mut self, before: usize, added: Option<ObjectSurface>) {
        let new = self.triangles.len() - before;
        if added.is_none() && self.surface.is_none() {
            return;
        }
        let surface = self.surface_mut();
        let colours = match added {
            Some(o) => {
                surface.material_of_triangle.extend(o.material_of_triangle);
                surface.uv_of_triangle.extend(o.uv_of_triangle);
                o.colour_of_triangle
            }
            None => {
                surface
                    .material_of_triangle
                    .extend(std::iter::repeat_n(NO_MATERIAL, new));
                surface
                    .uv_of_triangle
                    .extend(std::iter::repeat_n([Vec2::ZERO; 3], new));
                None
            }
        };
        // Vertex colours exist once some object brings them; every other triangle is white.
        match (colours, &mut surface.colour_of_triangle) {
            (Some(c), Some(all)) => all.extend(c),
            (Some(c), none) => {
                let mut all = vec![[Vec4::ONE; 3]; before];
                all.extend(c);
                *none = Some(all);
            }
            (None, Some(all)) => all.extend(std::iter::repeat_n([Vec4::ONE; 3], new)),
            (None, None) => {}
        }
    }

    /// Triangles of the scene (= `triangles.len()`), the primitive count of every builder.
    pub fn triangle_count(&self) -> usize {
        self.triangles.len()
    }

    /// Bounds of the vertices that triangles use, and of the points: unreferenced vertices (OBJ
    /// files often carry them) must not widen the box a camera frames or a BVH root covers.
    pub fn bounds(&self) -> Aabb {
        let triangles = self
            .triangles
            .iter()
            .flatten()
            .filter_map(|&i| self.positions.get(i as usize))
            .fold(Aabb::EMPTY, |b, &p| b.grow(p));
        match &self.points {
            Some(cloud) => triangles.union(cloud.bounds()),
            None => triangles,
        }
    }

    /// Per object ([`Scene::object_names`]), the box of its triangles (empty for an object
    /// without any): what an object's own sampling rate and its distance errors are measured
    /// against.
    pub fn object_bounds(&self) -> Vec<Aabb> {
        let mut boxes = vec![Aabb::EMPTY; self.object_names.len()];
        for (i, &o) in self.object_of_triangle.iter().enumerate() {
            if let Some(b) = boxes.get_mut(o as usize) {
                *b = b.union(Aabb::from_points(self.triangle(i)));
            }
        }
        boxes
    }

    /// Points of the scene (0 without a point cloud).
    pub fn point_count(&self) -> usize {
        self.points.as_ref().map_or(0, PointCloud::len)
    }

    /// How finely float32 resolves this scene: the spacing of representable coordinates at the
    /// scene's largest coordinate (`max |x| · 2⁻²³`) as a fraction of its bounding-box diagonal.
    /// Near the origin this is ~1e-7; a scene far from the origin loses precision in its vertices,
    /// hits and (for RBVHs) leaf frames — `tests/stability/scale_and_offset.rs` measures the consequences.
    pub fn coordinate_resolution(&self) -> f32 {
        let b = self.bounds();
        let diagonal = b.diagonal();
        if b.is_empty() || diagonal <= 0.0 {
            return 0.0;
        }
        let largest = b.min.abs().max(b.max.abs()).max_element();
        largest * f32::EPSILON / diagonal
    }

    /// A warning for the user when float32 resolves the scene coarser than
    /// `COORDINATE_RESOLUTION_LIMIT` (1/1024) of its diagonal (about a quarter of the coarsest RBVH
    /// preset's texel): hits then err by that much, and RBVH leaves may crack. Recentring the
    /// scene near the origin removes the loss.
    ///
    /// Also where the scene is so small that float32 cannot square its triangles' areas (more
    /// than 1% of them, [`Scene::area_underflows`]) and the RBVH builder cannot scale it up to
    /// where it can (`geom::scale`: even the coarsest preset's texel, a 256th of the diagonal,
    /// lies below [`TRACEABLE_TEXELS`](crate::geom::scale::TRACEABLE_TEXELS)): an RBVH's builder
    /// then finds no surface to sample and traces every such triangle exactly, as large as the
    /// exact BVH, with the right hits (tests/stability, scale and offset: a unit sphere scaled by
    /// 1e-18; at 1e-12 it is built scaled up). Scaling the scene up removes it.
    pub fn precision_warning(&self) -> Option<String> {
        let r = self.coordinate_resolution();
        let far = (r > COORDINATE_RESOLUTION_LIMIT).then(|| {
            let c = self.bounds().center();
            format!(
                "the scene lies far from the origin (centre {c}); float32 resolves only {r:.1e} of its \
                 diagonal there, so hits may err by that much and RBVH leaves may crack; recentre the scene"
            )
        });
        let coarsest_texel = self.bounds().diagonal() / 256.0;
        let underflows = match coarsest_texel < *crate::geom::scale::TRACEABLE_TEXELS.start() {
            true => self.area_underflows(),
            false => 0,
        };
        let tiny = (underflows * 100 > self.triangles.len()).then(|| {
            format!(
                "{underflows} of its {} triangles are so small (the scene is {:.1e} units across) that \
                 float32 cannot square their areas, so an RBVH traces them exactly instead of sampling \
                 them, as large as the exact BVH; scale the scene up (by a power of two, which is exact)",
                self.triangles.len(),
                self.bounds().diagonal()
            )
        });
        let said: Vec<String> = far.into_iter().chain(tiny).collect();
        (!said.is_empty()).then(|| format!("{}: {}", self.name, said.join("; and ")))
    }

    /// How many triangles have an area (their edges' cross product) whose square float32 rounds
    /// to zero: the RBVH builder weighs and compares triangles by those squares
    /// (`rbvh::frame`), and finds no surface to sample in them.
    pub fn area_underflows(&self) -> usize {
        use rayon::prelude::*;
        self.triangles
            .par_iter()
            .filter(|t| {
                let [a, b, c] = t.map(|v| self.positions[v as usize]);
                // The cheap test first: most triangles stop at it.
                (b - a).cross(c - a).length_squared() == 0.0
                    && crate::geom::unit_normal(a, b, c) != Vec3::ZERO
            })
            .count()
    }

    /// The three corners of triangle `i`.
    ///
    /// # Panics
    /// If `i` or one of its indices is out of range (never after [`Scene::validate`]).
    pub fn triangle(&self, i: usize) -> [Vec3; 3] {
        self.triangles[i].map(|v| self.positions[v as usize])
    }

    /// Checks what every tracer relies on: finite vertices, indices in range, one object per
    /// triangle. The error names the scene (its file) and the first offending element.
    pub fn validate(&self) -> Result<()> {
        let invalid = |message: String| Error::InvalidGeometry {
            source_name: self.name.clone(),
            message,
        };
        let vertex_count = self.positions.len();
        if u32::try_from(vertex_count).is_err() {
            return Err(invalid(format!(
                "{vertex_count} vertices, but triangle indices are 32-bit"
            )));
        }
        if let Some((i, p)) = self
            .positions
            .iter()
            .enumerate()
            .find(|(_, p)| !p.is_finite())
        {
            return Err(invalid(format!(
                "vertex {i} is not finite: ({}, {}, {})",
                p.x, p.y, p.z
            )));
        }
        for (t, tri) in self.triangles.iter().enumerate() {
            if let Some(&v) = tri.iter().find(|&&v| v as usize >= vertex_count) {
                return Err(invalid(format!(
                    "triangle {t} refers to vertex {v}, but there are only {vertex_count} vertices"
                )));
            }
        }
        if self.object_of_triangle.len() != self.triangles.len() {
            return Err(invalid(format!(
                "{} object ids for {} triangles",
                self.object_of_triangle.len(),
                self.triangles.len()
            )));
        }
        let object_count = self.object_names.len();
        if let Some((t, o)) = self
            .object_of_triangle
            .iter()
            .enumerate()
            .find(|(_, &o)| o as usize >= object_count)
        {
            return Err(invalid(format!(
                "triangle {t} belongs to object {o}, but there are only {object_count} objects"
            )));
        }
        if let Some(cloud) = &self.points {
            let n = cloud.len();
            if n < crate::points::MIN_POINTS {
                return Err(invalid(format!(
                    "{n} point(s): a point cloud needs at least {}",
                    crate::points::MIN_POINTS
                )));
            }
            if cloud.normals.len() != n || cloud.spacing.len() != n {
                return Err(invalid(format!(
                    "{} normals and {} spacings for {n} points",
                    cloud.normals.len(),
                    cloud.spacing.len()
                )));
            }
            if let Some(colours) = cloud.colours.as_ref().filter(|c| c.len() != n) {
                return Err(invalid(format!(
                    "{} point colours for {n} points",
                    colours.len()
                )));
            }
            let bad = (0..n).find(|&i| {
                !(cloud.positions[i].is_finite()
                    && cloud.normals[i].is_normalized()
                    && cloud.spacing[i].is_finite()
                    && cloud.spacing[i] > 0.0)
            });
            if let Some(i) = bad {
                return Err(invalid(format!(
                    "point {i} at {} has normal {} and spacing {}: positions must be finite, normals unit length, spacings positive",
                    cloud.positions[i], cloud.normals[i], cloud.spacing[i]
                )));
            }
        }
        if let Some(surface) = &self.surface {
            let n = self.triangles.len();
            let (m, u) = (
                surface.material_of_triangle.len(),
                surface.uv_of_triangle.len(),
            );
            if m != n || u != n {
                return Err(invalid(format!(
                    "{m} material ids and {u} texture-coordinate triples for {n} triangles"
                )));
            }
            if let Some(colours) = &surface.colour_of_triangle {
                if colours.len() != n {
                    return Err(invalid(format!(
                        "{} vertex-colour triples for {n} triangles",
                        colours.len()
                    )));
                }
                if let Some(t) = colours
                    .iter()
                    .position(|c| !c.iter().all(|v| v.is_finite()))
                {
                    return Err(invalid(format!(
                        "triangle {t} has non-finite vertex colours {:?}",
                        colours[t]
                    )));
                }
            }
            let count = surface.materials.len();
            if let Some((t, id)) = surface
                .material_of_triangle
                .iter()
                .enumerate()
                .find(|(_, &id)| id != NO_MATERIAL && id as usize >= count)
            {
                return Err(invalid(format!(
                    "triangle {t} has material {id}, but there are only {count} materials"
                )));
            }
            if let Some(t) = surface
                .uv_of_triangle
                .iter()
                .position(|uv| !uv.iter().all(|c| c.is_finite()))
            {
                return Err(invalid(format!(
                    "triangle {t} has non-finite texture coordinates {:?}",
                    surface.uv_of_triangle[t]
                )));
            }
        }
        Ok(())
    }

    /// This scene scaled by `2^k` ([`crate::geom::scale::pow2`]), exactly: its vertices, its
    /// points and their spacing, its camera and a point light's position. What the RBVH builder
    /// builds a scene too large or too small for float32's squares from (`geom::scale`).
    pub fn scaled_pow2(&self, k: i32) -> Scene {
        let s = crate::geom::scale::pow2(k);
        let mut scaled = self.clone();
        scaled.positions.iter_mut().for_each(|p| *p *= s);
        if let Some(camera) = &mut scaled.camera {
            camera.eye *= s;
            camera.target *= s;
        }
        if let Some(Light::Point { position, .. }) = &mut scaled.light {
            *position *= s;
        }
        if let Some(points) = &mut scaled.points {
            points.positions.iter_mut().for_each(|p| *p *= s);
            points.spacing.iter_mut().for_each(|d| *d *= s);
        }
        scaled
    }

    /// Appends `other`'s geometry transformed by the affine `m`. Its objects keep their names,
    /// prefixed with `other.name` and `/` so that two copies of one mesh stay apart. A mirroring
    /// `m` (negative determinant) would turn outward windings inward, so it also reverses the
    /// winding.
    pub fn append(&mut self, other: &Scene, m: Mat4) {
        let mirror = m.determinant() < 0.0;
        let before = self.triangles.len();
        // The table must exist before the triangles are appended, so that it pads only the
        // triangles already here.
        let material_base = match other.surface {
            Some(_) => saturating_u32(self.surface_mut().materials.len()),
            None => 0,
        };
        let prefix = if other.name.is_empty() {
            String::new()
        } else {
            format!("{}/", other.name)
        };
        self.append_parts(
            other.positions.iter().map(|&p| m.transform_point3(p)),
            other
                .triangles
                .iter()
                .map(|&[a, b, c]| if mirror { [a, c, b] } else { [a, b, c] }),
            other.object_names.iter().map(|n| format!("{prefix}{n}")),
            other.object_of_triangle.iter().copied(),
        );
        let added = other.surface.as_ref().map(|o| {
            self.surface_mut()
                .materials
                .extend(o.materials.iter().cloned());
            ObjectSurface {
                material_of_triangle: o
                    .material_of_triangle
                    .iter()
                    .map(|&id| {
                        if id == NO_MATERIAL {
                            id
                        } else {
                            material_base.saturating_add(id)
                        }
                    })
                    .collect(),
                uv_of_triangle: o
                    .uv_of_triangle
                    .iter()
                    .map(|&[a, b, c]| if mirror { [a, c, b] } else { [a, b, c] })
                    .collect(),
                colour_of_triangle: o.colour_of_triangle.as_ref().map(|colours| {
                    colours
                        .iter()
                        .map(|&[a, b, c]| if mirror { [a, c, b] } else { [a, b, c] })
                        .collect()
                }),
            }
        });
        self.extend_surface(before, added);
        if let Some(theirs) = &other.points {
            let placed = theirs.transformed(m);
            match &mut self.points {
                Some(mine) => mine.append(&placed),
                None => self.points = Some(placed),
            }
        }
    }

    /// Linear RGBA base colour of triangle `triangle` at world point `p` (on or near it), or
    /// `None` when the scene has no materials or the triangle does not exist.
    pub fn colour_at(&self, triangle: usize, p: Vec3) -> Option<glam::Vec4> {
        let surface = self.surface.as_ref()?;
        let tri = self.triangles.get(triangle)?;
        let corners = tri.map(|v| self.positions.get(v as usize).copied());
        let [Some(a), Some(b), Some(c)] = corners else {
            return None;
        };
        let bary = super::material::barycentrics([a, b, c], p);
        Some(surface.colour(triangle, bary))
    }

    /// The scene file's camera, or one that frames [`Scene::bounds`] for `aspect` (width/height).
    pub fn camera_or_framed(&self, aspect: f32) -> Camera {
        self.camera
            .unwrap_or_else(|| Camera::framing(&self.bounds(), aspect))
    }

    /// Appends vertices, triangles (indexing the new vertices) and objects (with triangles'
    /// object ids relative to the new objects), offsetting indices by what is already here.
    fn append_parts(
        &mut self,
        positions: impl Iterator<Item = Vec3>,
        triangles: impl Iterator<Item = [u32; 3]>,
        object_names: impl Iterator<Item = String>,
        object_of_triangle: impl Iterator<Item = u32>,
    ) {
        let vertex_base = saturating_u32(self.positions.len());
        let object_base = saturating_u32(self.object_names.len());
        self.positions.extend(positions);
        self.triangles
            .extend(triangles.map(|t| t.map(|v| vertex_base.saturating_add(v))));
        self.object_names.extend(object_names);
        self.object_of_triangle
            .extend(object_of_triangle.map(|o| object_base.saturating_add(o)));
    }
}

/// A count as a `u32` index base; saturating makes an overflow an out-of-range index that
/// [`Scene::validate`] reports, instead of a wrapped index that silently points elsewhere.
fn saturating_u32(n: usize) -> u32 {
    u32::try_from(n).unwrap_or(u32::MAX)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit_triangle() -> Scene {
        let mut s = Scene::new("tri");
        s.push_object("t", &[Vec3::ZERO, Vec3::X, Vec3::Z], &[[0, 2, 1]]);
        s
    }

    #[test]
    fn append_offsets_prefixes_and_keeps_winding_under_mirrors() {
        let mut s = unit_triangle();
        s.append(
            &unit_triangle(),
            Mat4::from_scale(Vec3::new(-1.0, 1.0, 1.0)),
        );
        assert_eq!(s.triangles, vec![[0, 2, 1], [3, 4, 5]]);
        assert_eq!(s.object_names, vec!["t", "tri/t"]);
        assert_eq!(s.object_of_triangle, vec![0, 1]);
        let n = |[a, b, c]: [Vec3; 3]| (b - a).cross(c - a);
        assert_eq!(n(s.triangle(0)).y, n(s.triangle(1)).y);
        s.validate().unwrap();
    }

    #[test]
    fn validate_names_the_bad_element() {
        let mut s = unit_triangle();
        s.triangles.push([0, 1, 7]);
        s.object_of_triangle.push(0);
        let e = s.validate().unwrap_err().to_string();
        assert!(
            e.contains("tri") && e.contains("triangle 1") && e.contains("vertex 7"),
            "{e}"
        );
        let mut s = unit_triangle();
        s.positions[1].y = f32::INFINITY;
        let e = s.validate().unwrap_err().to_string();
        assert!(e.contains("vertex 1") && e.contains("inf"), "{e}");
    }

    #[test]
    fn surface_stays_parallel_through_push_and_append() {
        let uv = [Vec2::ZERO, Vec2::X, Vec2::Y];
        let mut textured = Scene::new("tex");
        let red = textured.add_material(Material::constant("red", glam::Vec4::X));
        textured.push_textured_object(
            "t",
            &[Vec3::ZERO, Vec3::X, Vec3::Z],
            &[[0, 2, 1]],
            ObjectSurface {
                material_of_triangle: vec![red],
                uv_of_triangle: vec![uv],
                colour_of_triangle: None,
            },
        );
        // A plain object first, then two instances of the textured one, one mirrored.
        let mut s = unit_triangle();
        assert!(s.surface.is_none());
        s.append(&textured, Mat4::IDENTITY);
        s.append(&textured, Mat4::from_scale(Vec3::new(-1.0, 1.0, 1.0)));
        s.push_object("plain", &[Vec3::ZERO, Vec3::X, Vec3::Y], &[[0, 1, 2]]);
        s.validate().unwrap();
        let surface = s.surface.as_ref().unwrap();
        assert_eq!(surface.materials.len(), 2);
        assert_eq!(
            surface.material_of_triangle,
            vec![NO_MATERIAL, 0, 1, NO_MATERIAL]
        );
        assert_eq!(surface.uv_of_triangle[1], uv);
        assert_eq!(surface.uv_of_triangle[2], [uv[0], uv[2], uv[1]]);
        // The mirrored copy keeps each corner's texture coordinate with its vertex.
        let corner = |t: usize, c: usize| s.positions[s.triangles[t][c] as usize];
        assert_eq!(corner(2, 1).x, -corner(1, 2).x);
        assert_eq!(surface.colour_of_triangle, None);

        // Vertex colours, once some object brings them, pad every other triangle with white, and
        // a mirrored copy keeps each corner's colour with its vertex.
        let (r, g, b) = (glam::Vec4::X, glam::Vec4::Y, glam::Vec4::Z);
        let mut coloured = Scene::new("col");
        coloured.push_textured_object(
            "c",
            &[Vec3::ZERO, Vec3::X, Vec3::Z],
            &[[0, 2, 1]],
            ObjectSurface {
                material_of_triangle: vec![NO_MATERIAL],
                uv_of_triangle: vec![uv],
                colour_of_triangle: Some(vec![[r, g, b]]),
            },
        );
        let mut c = s.clone();
        c.append(&coloured, Mat4::from_scale(Vec3::new(-1.0, 1.0, 1.0)));
        c.push_object("plain", &[Vec3::ZERO, Vec3::X, Vec3::Y], &[[0, 1, 2]]);
        c.validate().unwrap();
        let colours = c
            .surface
            .as_ref()
            .unwrap()
            .colour_of_triangle
            .as_ref()
            .unwrap();
        let white = [glam::Vec4::ONE; 3];
        assert_eq!(colours, &vec![white, white, white, white, [r, b, g], white]);
        let mut bad = c.clone();
        bad.surface.as_mut().unwrap().colour_of_triangle = Some(vec![white; 2]);
        assert!(bad
            .validate()
            .unwrap_err()
            .to_string()
            .contains("vertex-colour"));
        let mut bad = s.clone();
        bad.surface.as_mut().unwrap().material_of_triangle[1] = 5;
        assert!(bad
            .validate()
            .unwrap_err()
            .to_string()
            .contains("material 5"));
    }

    #[test]
    fn bounds_ignore_unreferenced_vertices() {
        let mut s = unit_triangle();
        s.positions.push(Vec3::splat(100.0));
        assert_eq!(s.bounds().max, Vec3::new(1.0, 0.0, 1.0));
    }
}
