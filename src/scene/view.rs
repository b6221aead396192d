//! A scene as it is traced: flat ([`Scene`], one triangle list) or its meshes placed by
//! instances ([`InstancedScene`], traced through a two-level structure without being copied).
//! What shading, framing and messages read of a scene, from either, so that a scene too large to
//! flatten (`scenes/dragons-1000.toml`) renders as a flat one does (issue "Instances").

use glam::Vec3;

use super::{Camera, InstancedScene, Light, Scene};
use crate::geom::{Aabb, Hit, Ray};

/// How a scene whose meshes are placed by instances is traced (the CLI's `--instances`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Instances {
    /// As the scene asks: a command traces two levels where the scene places a mesh more than
    /// once, else flat; the bench measures a scene with instances both ways, in two levels
    /// alone where its flat copy would not fit in memory
    /// ([`InstancedScene::check_flat_fits`]), and flat alone where its RBVHs are built from
    /// points (over the flat scene).
    #[default]
    Auto,
    /// Every placement copied in place: one triangle list.
    Flat,
    /// Each mesh held once, a top level over its placements (a scene without instances is one
    /// mesh placed once).
    TwoLevel,
}

/// A flat scene or a scene of instances, borrowed.
#[derive(Clone, Copy, Debug)]
pub enum SceneView<'a> {
    /// One triangle list: hits' ids index its triangles.
    Flat(&'a Scene),
    /// Meshes placed by instances: a hit names its instance ([`Hit::instance`]) and its mesh's
    /// triangle.
    Instanced(&'a InstancedScene),
}

impl<'a> From<&'a Scene> for SceneView<'a> {
    fn from(scene: &'a Scene) -> Self {
        SceneView::Flat(scene)
    }
}

impl<'a> From<&'a InstancedScene> for SceneView<'a> {
    fn from(scene: &'a InstancedScene) -> Self {
        SceneView::Instanced(scene)
    }
}

impl<'a> SceneView<'a> {
    /// The scene's name, for messages.
    pub fn name(self) -> &'a str {
        match self {
            SceneView::Flat(s) => &s.name,
            SceneView::Instanced(s) => &s.name,
        }
    }

    /// The light the scene asked for.
    pub fn light(self) -> Option<&'a Light> {
        match self {
            SceneView::Flat(s) => s.light.as_ref(),
            SceneView::Instanced(s) => s.light.as_ref(),
        }
    }

    /// The box of every vertex as placed: for instances [`InstancedScene::placed_bounds`], the
    /// flat scene's box bit for bit (so that a framing camera and every diagonal-relative
    /// quantity are the flat scene's), found by placing each vertex, once per call.
    pub fn bounds(self) -> Aabb {
        match self {
            SceneView::Flat(s) => s.bounds(),
            SceneView::Instanced(s) => s.placed_bounds(),
        }
    }

    /// The scene's camera, or one framing [`SceneView::bounds`] at `aspect`.
    pub fn camera_or_framed(self, aspect: f32) -> Camera {
        match self {
            SceneView::Flat(s) => s.camera_or_framed(aspect),
            SceneView::Instanced(s) => s
                .camera
                .unwrap_or_else(|| Camera::framing(&s.placed_bounds(), aspect)),
        }
    }

    /// Triangles as placed: each instance counts its mesh's.
    pub fn triangle_count(self) -> usize {
        match self {
            SceneView::Flat(s) => s.triangle_count(),
            SceneView::Instanced(s) => s.placed_triangle_count(),
        }
    }

    /// Points as placed: each instance counts its mesh's.
    pub fn point_count(self) -> usize {
        match self {
            SceneView::Flat(s) => s.point_count(),
            SceneView::Instanced(s) => s
                .instances
                .iter()
                .filter_map(|i| s.meshes.get(i.mesh as usize))
                .map(Scene::point_count)
                .sum(),
        }
    }

    /// Whether any triangle has a material ([`Scene::surface`]).
    pub fn has_surface(self) -> bool {
        match self {
            SceneView::Flat(s) => s.surface.is_some(),
            SceneView::Instanced(s) => s.meshes.iter().any(|m| m.surface.is_some()),
        }
    }

    /// The mesh `hit` (of `ray`) lies on, by its index and itself, with the ray taken into that
    /// mesh's space (the same `t` reaches the same point, as the two-level traversal takes it):
    /// mesh 0, the scene itself and `ray` when flat; `None` for a miss or an instance that does
    /// not exist.
    pub fn hit_mesh(self, ray: &Ray, hit: &Hit) -> Option<(usize, &'a Scene, Ray)> {
        if !hit.is_hit() {
            return None;
        }
        match self {
            SceneView::Flat(s) => Some((0, s, *ray)),
            SceneView::Instanced(s) => {
                let instance = s.instances.get(hit.instance as usize)?;
                let mesh = s.meshes.get(instance.mesh as usize)?;
                let to_mesh = instance.transform.inverse();
                let origin = to_mesh.transform_point3(ray.origin());
                let dir: Vec3 = to_mesh.transform_vector3(ray.dir());
                Some((
                    instance.mesh as usize,
                    mesh,
                    Ray::new(origin, dir, ray.tmin, ray.tmax),
                ))
            }
        }
    }
}
