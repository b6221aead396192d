//! Scenes that place meshes by instances: each mesh held once in its own space, placed any number
//! of times by a transform (issue "Instances"), as engines place them, glTF nodes that share a
//! mesh do, and Vulkan's acceleration structures split them (a top level over bottom levels).
//!
//! An [`InstancedScene`] is what a two-level structure is built from
//! ([`InstancedBvh`](crate::bvh::InstancedBvh), [`InstancedRbvh`](crate::rbvh::InstancedRbvh):
//! one bottom level per mesh, a top level over the instances' boxes). Every stage that traces a flat triangle list takes
//! [`InstancedScene::into_flat`]: the same scene with each instance's mesh copied in place, which is
//! also the referee an instanced trace is checked against.

use glam::{Mat4, Vec3, Vec4};
use rayon::prelude::*;

use super::{Camera, Light, Scene};
use crate::geom::Aabb;
use crate::{Error, Result};

/// Instances a scene may hold: a top-level leaf names one by 31 bits, and the traversal's node
/// visits per ray stay countable in 32 bits.
pub const MAX_INSTANCES: usize = 1 << 24;

/// The smallest `|det|` of a transform's linear part, relative to the cube of its largest column,
/// that [`InstancedScene::validate`] accepts: below it the inverse that takes rays into the mesh's
/// space loses most of float32's digits (a scale of 1e-4 along one axis against 1 along the
/// others is 1e-8).
pub const MIN_RELATIVE_DETERMINANT: f32 = 1e-9;

/// One placement of a mesh: `transform` takes the mesh's space to the scene's.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Instance {
    /// Index into [`InstancedScene::meshes`].
    pub mesh: u32,
    /// Mesh space to world space: affine (last row `0 0 0 1`), finite and invertible once
    /// [`InstancedScene::validate`] has passed; a mirroring transform (negative determinant) is
    /// allowed and traced as the mirrored copy [`Scene::append`] makes.
    pub transform: Mat4,
}

/// Meshes in their own spaces and the instances that place them, with the camera and light of
/// the scene file.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct InstancedScene {
    /// The file name or built-in name (or a scene file's `name`), used in messages.
    pub name: String,
    /// Each mesh once, in its own space; its `name` prefixes its objects' names when flattened.
    pub meshes: Vec<Scene>,
    /// The placements, in the order the scene lists them (the flat scene's order).
    pub instances: Vec<Instance>,
    /// The camera a scene file asked for.
    pub camera: Option<Camera>,
    /// The light a scene file asked for.
    pub light: Option<Light>,
}

impl InstancedScene {
    /// `scene` as one mesh placed once, where it is: how a mesh file or a built-in scene enters
    /// a two-level structure.
    pub fn single(scene: Scene) -> InstancedScene {
        InstancedScene {
            name: scene.name.clone(),
            camera: scene.camera,
            light: scene.light,
            meshes: vec![scene],
            instances: vec![Instance {
                mesh: 0,
                transform: Mat4::IDENTITY,
            }],
        }
    }

    /// The scene [`InstancedScene::single`] wrapped, where this is one mesh placed once where it
    /// is; else `None`.
    pub fn into_single(mut self) -> Option<Scene> {
        match (self.meshes.len(), self.instances.as_slice()) {
            (1, [only]) if only.mesh == 0 && only.transform == Mat4::IDENTITY => {
                let mut scene = self.meshes.remove(0);
                scene.camera = self.camera;
                scene.light = self.light;
                Some(scene)
            }
            _ => None,
        }
    }

    /// Triangles as placed: each instance counts its mesh's triangles.
    pub fn placed_triangle_count(&self) -> usize {
        self.instances
            .iter()
            .filter_map(|i| self.meshes.get(i.mesh as usize))
            .map(Scene::triangle_count)
            .sum()
    }

    /// Whether some mesh is placed more than once: what instances save over a flat copy.
    pub fn repeats_a_mesh(&self) -> bool {
        let mut placed = vec![false; self.meshes.len()];
        self.instances
            .iter()
            .any(|i| match placed.get_mut(i.mesh as usize) {
                Some(seen) => std::mem::replace(seen, true),
                None => false,
            })
    }

    /// Triangles stored: each mesh once.
    pub fn stored_triangle_count(&self) -> usize {
        self.meshes.iter().map(Scene::triangle_count).sum()
    }

    /// Per instance, the index of its first triangle in the flat scene ([`InstancedScene::into_flat`]
    /// places them one after another, in order): how a flat triangle index is made from an
    /// instance and its mesh's triangle.
    pub fn flat_bases(&self) -> Vec<u32> {
        let mut base = 0u32;
        self.instances
            .iter()
            .map(|i| {
                let first = base;
                let n = self
                    .meshes
                    .get(i.mesh as usize)
                    .map_or(0, Scene::triangle_count);
                base = base.saturating_add(u32::try_from(n).unwrap_or(u32::MAX));
                first
            })
            .collect()
    }

    /// The world box of each instance: its mesh's box transformed (the box of the transformed
    /// corners, which holds every transformed vertex).
    pub fn instance_bounds(&self) -> Vec<Aabb> {
        let mesh_bounds: Vec<Aabb> = self.meshes.iter().map(Scene::bounds).collect();
        self.instances
            .iter()
            .map(|i| match mesh_bounds.get(i.mesh as usize) {
                Some(b) => transformed_box(*b, i.transform),
                None => Aabb::EMPTY,
            })
            .collect()
    }

    /// The box of every instance.
    pub fn bounds(&self) -> Aabb {
        self.instance_bounds()
            .into_iter()
            .fold(Aabb::EMPTY, Aabb::union)
    }

    /// The box of every placed vertex that a triangle uses (and of every placed point cloud's
    /// box): [`Scene::bounds`] of [`InstancedScene::into_flat`] bit for bit where there are no
    /// points, each vertex placed as [`Scene::append`] places it, without making the flat scene.
    /// What a two-level RBVH's texel is taken from, so that it is the flat scene's
    /// (`crate::rbvh::InstancedRbvh`).
    pub fn placed_bounds(&self) -> Aabb {
        let used: Vec<Vec<Vec3>> = self
            .meshes
            .iter()
            .map(|mesh| {
                let mut seen = vec![false; mesh.positions.len()];
                for &i in mesh.triangles.iter().flatten() {
                    if let Some(s) = seen.get_mut(i as usize) {
                        *s = true;
                    }
                }
                mesh.positions
                    .iter()
                    .zip(seen)
                    .filter_map(|(&p, s)| s.then_some(p))
                    .collect()
            })
            .collect();
        self.instances
            .par_iter()
            .map(|instance| {
                let m = instance.transform;
                let Some(mesh) = self.meshes.get(instance.mesh as usize) else {
                    return Aabb::EMPTY;
                };
                let points = match &mesh.points {
                    Some(cloud) => transformed_box(cloud.bounds(), m),
                    None => Aabb::EMPTY,
                };
                used[instance.mesh as usize]
                    .iter()
                    .fold(points, |b, &p| b.grow(m.transform_point3(p)))
            })
            .reduce(|| Aabb::EMPTY, Aabb::union)
    }

    /// Per instance, the box of each object of its mesh as placed: [`Scene::object_bounds`] of
    /// [`InstancedScene::into_flat`] bit for bit (each vertex placed as [`Scene::append`] places
    /// it), without making the flat scene. What an error relative to the object hit measures
    /// against in a scene traced in two levels alone.
    pub fn placed_object_bounds(&self) -> Vec<Vec<Aabb>> {
        // Per mesh, per object, the vertices its triangles use, each once.
        let vertices: Vec<Vec<Vec<u32>>> = self
            .meshes
            .iter()
            .map(|mesh| {
                let mut of_object = vec![Vec::new(); mesh.object_names.len()];
                for (t, &o) in mesh.triangles.iter().zip(&mesh.object_of_triangle) {
                    if let Some(list) = of_object.get_mut(o as usize) {
                        list.extend_from_slice(t);
                    }
                }
                for list in &mut of_object {
                    list.sort_unstable();
                    list.dedup();
                }
                of_object
            })
            .collect();
        self.instances
            .par_iter()
            .map(|instance| {
                let (Some(mesh), Some(objects)) = (
                    self.meshes.get(instance.mesh as usize),
                    vertices.get(instance.mesh as usize),
                ) else {
                    return Vec::new();
                };
                let m = instance.transform;
                objects
                    .iter()
                    .map(|list| {
                        list.iter()
                            .filter_map(|&v| mesh.positions.get(v as usize))
                            .fold(Aabb::EMPTY, |b, &p| b.grow(m.transform_point3(p)))
                    })
                    .collect()
            })
            .collect()
    }

    /// Refuses to flatten where the flat scene and the flat structures built from it would not
    /// fit in `available` bytes of host memory (`None`: not known, not checked), estimated at
    /// [`FLAT_BYTES_PER_TRIANGLE`] per triangle as placed: an error naming the scene, its
    /// triangles and the bytes, where the system would otherwise kill the process part way
    /// (`scenes/dragons-1000.toml` places 871M triangles; its two-level structures take
    /// megabytes).
    pub fn check_flat_fits(&self, available: Option<u64>) -> Result<()> {
        check_flat_triangles(&self.name, self.placed_triangle_count() as u64, available)
    }

    /// Checks what a two-level build relies on: each mesh valid ([`Scene::validate`]; an unnamed
    /// mesh's error names the scene and the mesh's index), at most [`MAX_INSTANCES`] instances,
    /// each naming a mesh that exists with a transform that is affine, finite and invertible
    /// ([`MIN_RELATIVE_DETERMINANT`]) and places the mesh's box within float32's range. The error
    /// names the scene and the instance.
    pub fn validate(&self) -> Result<()> {
        let invalid = |message: String| Error::InvalidGeometry {
            source_name: self.name.clone(),
            message,
        };
        for (m, mesh) in self.meshes.iter().enumerate() {
            // An unnamed mesh (a glTF mesh read once for its nodes) is named by the scene.
            mesh.validate().map_err(|e| match e {
                Error::InvalidGeometry {
                    source_name,
                    message,
                } if source_name.is_empty() => invalid(format!("mesh {m}: {message}")),
                e => e,
            })?;
        }
        if self.instances.len() > MAX_INSTANCES {
            return Err(invalid(format!(
                "{} instances, more than the {MAX_INSTANCES} a top-level tree can name",
                self.instances.len()
            )));
        }
        let mesh_bounds: Vec<Aabb> = self.meshes.iter().map(Scene::bounds).collect();
        for (k, instance) in self.instances.iter().enumerate() {
            let Some(&bounds) = mesh_bounds.get(instance.mesh as usize) else {
                return Err(invalid(format!(
                    "instance {k} places mesh {}, but there are only {} meshes",
                    instance.mesh,
                    self.meshes.len()
                )));
            };
            transform_fault(&instance.transform).map_or(Ok(()), |fault| {
                Err(invalid(format!("instance {k}: {fault}")))
            })?;
            // As the flat scene's vertices must be finite, so must the placed mesh's box.
            let placed = transformed_box(bounds, instance.transform);
            let beyond = !(placed.min.is_finite() && placed.max.is_finite());
            if !bounds.is_empty() && beyond {
                return Err(invalid(format!(
                    "instance {k} places mesh {} beyond float32's range (its box reaches {} to {})",
                    instance.mesh, placed.min, placed.max
                )));
            }
        }
        Ok(())
    }

    /// [`InstancedScene::into_flat`], validated, once [`InstancedScene::check_flat_fits`] passes
    /// against this host's [`available_memory`]: what every loader of a flat scene from a scene
    /// file takes, so that a scene too large to flatten is refused by name before it is copied.
    pub fn into_flat_checked(self) -> Result<Scene> {
        self.check_flat_fits(available_memory())?;
        let scene = self.into_flat();
        scene.validate()?;
        Ok(scene)
    }

    /// The flat scene: every instance's mesh copied in place ([`Scene::append`], so mirrors keep
    /// their winding and object names their mesh's prefix), with this scene's name, camera and
    /// light. What every stage without instances traces, and the referee of the instanced trace.
    /// A first instance that places an unnamed mesh (a scene file's `[[mesh]]` entries) where
    /// it is, and alone, is moved rather than copied: a flat scene file costs no second copy.
    pub fn into_flat(mut self) -> Scene {
        let movable = self.instances.first().is_some_and(|first| {
            first.transform == Mat4::IDENTITY
                && self
                    .meshes
                    .get(first.mesh as usize)
                    .is_some_and(|m| m.name.is_empty())
                && self.instances[1..].iter().all(|i| i.mesh != first.mesh)
        });
        let (mut flat, rest) = if movable {
            let first = self.instances[0].mesh as usize;
            (
                std::mem::take(&mut self.meshes[first]),
                &self.instances[1..],
            )
        } else {
            (Scene::default(), &self.instances[..])
        };
        for instance in rest {
            if let Some(mesh) = self.meshes.get(instance.mesh as usize) {
                flat.append(mesh, instance.transform);
            }
        }
        flat.name = self.name;
        flat.camera = self.camera;
        flat.light = self.light;
        flat
    }
}

/// [`InstancedScene::check_flat_fits`] of a scene named `name` that places `triangles`: also
/// what a glTF file's flat loader checks before it copies its nodes' meshes in place.
pub(crate) fn check_flat_triangles(
    name: &str,
    triangles: u64,
    available: Option<u64>,
) -> Result<()> {
    let needed = triangles.saturating_mul(FLAT_BYTES_PER_TRIANGLE);
    match available {
        Some(available) if needed > available => Err(Error::InvalidGeometry {
            source_name: name.to_owned(),
            message: format!(
                "{triangles} triangles as placed; flattened, its scene and flat structures \
                 would need about {:.1} GB of host memory, and {:.1} GB are available: it is \
                 traced in two levels only (its meshes held once)",
                needed as f64 / 1e9,
                available as f64 / 1e9
            ),
        }),
        _ => Ok(()),
    }
}

/// Host memory available now (Linux's `MemAvailable`), in bytes; None where the system does not
/// say. What a scene with instances is checked against before it is flattened
/// ([`InstancedScene::check_flat_fits`]).
pub fn available_memory() -> Option<u64> {
    std::fs::read_to_string("/proc/meminfo")
        .ok()?
        .lines()
        .find_map(|l| l.strip_prefix("MemAvailable:"))
        .and_then(|v| v.trim().strip_suffix("kB"))
        .and_then(|kb| kb.trim().parse::<u64>().ok())
        .map(|kb| kb * 1024)
}

/// Host bytes per triangle as placed that flattening a scene and building its flat exact BVH
/// took at the paper's scale (a 4.63 GB peak for 21.85M triangles, `rbvh build` of
/// `scenes/paper-scale-instanced.toml`, docs/paper-scale.md): what
/// [`InstancedScene::check_flat_fits`] counts on.
pub const FLAT_BYTES_PER_TRIANGLE: u64 = 212;

/// What is wrong with `m` as an instance's transform, if anything: an entry that is not finite,
/// a last row other than `0 0 0 1` (a projection, not a placement), a linear part whose scale
/// overflows 32-bit floats (it was reported as not invertible), or one too close to singular to
/// take rays into the mesh's space ([`MIN_RELATIVE_DETERMINANT`]).
pub fn transform_fault(m: &Mat4) -> Option<String> {
    if !m.is_finite() {
        return Some(format!(
            "the transform has entries that are not finite: {m}"
        ));
    }
    if m.row(3) != Vec4::W {
        return Some(format!(
            "the transform's last row is {}, not 0 0 0 1: only affine placements are instances",
            m.row(3)
        ));
    }
    let linear = glam::Mat3::from_mat4(*m);
    let largest = [linear.x_axis, linear.y_axis, linear.z_axis]
        .iter()
        .map(|c| c.length())
        .fold(0.0f32, f32::max);
    let det = linear.determinant();
    if !det.is_finite() || !largest.is_finite() {
        return Some(format!(
            "the transform's scale is too large for 32-bit floats (determinant {det:e} of a \
             linear part whose longest axis is {largest})"
        ));
    }
    let invertible = det.abs() > MIN_RELATIVE_DETERMINANT * largest.powi(3);
    if !invertible {
        return Some(format!(
            "the transform is not invertible (determinant {det:e} of a linear part whose longest \
             axis is {largest}): it flattens the mesh"
        ));
    }
    None
}

/// The box of `b`'s eight corners under `m`: it holds every point of `b` transformed, since an
/// affine map takes the box to a parallelepiped whose corners are those eight.
pub fn transformed_box(b: Aabb, m: Mat4) -> Aabb {
    if b.is_empty() {
        return Aabb::EMPTY;
    }
    (0..8).fold(Aabb::EMPTY, |acc, k| {
        let corner = Vec3::new(
            if k & 1 == 0 { b.min.x } else { b.max.x },
            if k & 2 == 0 { b.min.y } else { b.max.y },
            if k & 4 == 0 { b.min.z } else { b.max.z },
        );
        acc.grow(m.transform_point3(corner))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn triangle_mesh(name: &str) -> Scene {
        let mut mesh = Scene::new(name);
        mesh.push_object("t", &[Vec3::ZERO, Vec3::X, Vec3::Y], &[[0, 1, 2]]);
        mesh
    }

    fn two_instances() -> InstancedScene {
        InstancedScene {
            name: "two".into(),
            meshes: vec![triangle_mesh("m")],
            instances: vec![
                Instance {
                    mesh: 0,
                    transform: Mat4::from_translation(Vec3::Z),
                },
                Instance {
                    mesh: 0,
                    transform: Mat4::from_scale(Vec3::new(-2.0, 1.0, 1.0)),
                },
            ],
            ..InstancedScene::default()
        }
    }

    #[test]
    fn flattening_copies_each_instance_as_append_does() {
        let scene = two_instances();
        scene.validate().unwrap();
        let flat = scene.clone().into_flat();
        let mut expected = Scene::new("two");
        expected.append(&scene.meshes[0], scene.instances[0].transform);
        expected.append(&scene.meshes[0], scene.instances[1].transform);
        assert_eq!(flat, expected);
        assert_eq!(scene.placed_triangle_count(), 2);
        assert_eq!(scene.stored_triangle_count(), 1);
        assert_eq!(scene.bounds(), flat.bounds());

        // An unnamed mesh placed where it is, once, first: moved, and the same as copied.
        let mut copied = scene.clone();
        copied.meshes.insert(0, triangle_mesh(""));
        copied.instances.iter_mut().for_each(|i| i.mesh += 1);
        copied.instances.insert(
            0,
            Instance {
                mesh: 0,
                transform: Mat4::IDENTITY,
            },
        );
        let mut expected = Scene::new("two");
        expected.append(&triangle_mesh(""), Mat4::IDENTITY);
        expected.append(&scene.meshes[0], scene.instances[0].transform);
        expected.append(&scene.meshes[0], scene.instances[1].transform);
        assert_eq!(copied.into_flat(), expected);
    }

    #[test]
    fn bad_instances_are_named() {
        let mut scene = two_instances();
        scene.instances[1].mesh = 3;
        let e = scene.validate().unwrap_err().to_string();
        assert!(e.contains("instance 1 places mesh 3"), "{e}");

        for (bad, what) in [
            (Mat4::from_scale(Vec3::new(1.0, 0.0, 1.0)), "not invertible"),
            (
                Mat4::from_scale(Vec3::new(1.0, 1e-5, 1e-5)),
                "not invertible",
            ),
            (
                Mat4::from_translation(Vec3::new(f32::NAN, 0.0, 0.0)),
                "not finite",
            ),
            (Mat4::from_scale(Vec3::splat(f32::INFINITY)), "not finite"),
            (
                Mat4::from_cols(Vec4::X, Vec4::Y, Vec4::Z, Vec4::new(0.0, 0.0, -1.0, 0.0)),
                "affine",
            ),
        ] {
            let mut scene = two_instances();
            scene.instances[0].transform = bad;
            let e = scene.validate().unwrap_err().to_string();
            assert!(e.contains("instance 0") && e.contains(what), "{what}: {e}");
        }
    }

    #[test]
    fn transformed_boxes_hold_their_transformed_corners() {
        let b = Aabb::from_points([Vec3::ZERO, Vec3::new(1.0, 2.0, 3.0)]);
        let m = Mat4::from_rotation_y(0.7) * Mat4::from_scale(Vec3::new(-1.0, 2.0, 0.5));
        let t = transformed_box(b, m);
        for p in [
            Vec3::ZERO,
            Vec3::new(1.0, 2.0, 3.0),
            Vec3::new(0.5, 1.0, 1.5),
        ] {
            let q = m.transform_point3(p);
            assert!(t.min.cmple(q + 1e-5).all() && t.max.cmpge(q - 1e-5).all());
        }
        assert!(transformed_box(Aabb::EMPTY, m).is_empty());
    }
}
