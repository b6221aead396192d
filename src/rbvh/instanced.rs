//! The RBVH of a scene with instances, in two levels (issue "Instances"): one RBVH per mesh,
//! rasterized once in the mesh's own space, under the top level of `crate::bvh` (`top_level.rs`)
//! that the two-level exact BVH has too, traced by the one traversal with the same instance hook
//! around the RBVH's own leaves.
//!
//! **The rate of a mesh placed at several scales.** The flat scene's texel is its diagonal over
//! `texels_per_diagonal` ([`InstancedScene::placed_bounds`]: the box of the placed vertices, the
//! flat scene's own). An instance stretches its mesh by at most its transform's largest stretch
//! ([`stretch`]: the longest axis of the linear part where its axes are orthogonal, a rotation and
//! scales, else a bound above it), so a mesh is rasterized at that texel over its largest stretch:
//! its largest placement then has the flat scene's world texel, and smaller ones a finer one
//! (never a coarser one), stored once. Objects' own rates ([`RbvhParams::object_rate`]) are
//! relative to their own boxes, so they are the flat scene's in any space; where an object's own
//! rate is the finer one (an object small beside its scene: the presets' 3/16 makes it so for
//! every dragon of the paper-scale scene), each placement has the flat scene's world texel,
//! whatever its scale, and the rule above costs nothing. `docs/paper-scale.md` ("The RBVH in two
//! levels") measures it: the dragons, placed at scales 9 to 13, take their own rate there.
//!
//! **Painting** is not offered for it yet (the painter takes a flat RBVH): it would write texels
//! of the one tile a mesh's surface has, which every instance of the mesh shows, so a colour of
//! one instance alone needs that instance's mesh copied.
//!
//! **Files**: [`InstancedRbvh::save`] writes every mesh's arrays once and the placements
//! (`file/instanced.rs`); [`InstancedRbvh::load`] builds the top level again, and
//! [`InstancedRbvh::check_built_from`] takes a scene's placements.
//!
//! **Offsets**: a secondary ray leaves an instance's surface by that instance's own texel
//! ([`InstancedRbvh::instance_texel`]), so that texel-sized quantities scale with each instance.
//!
//! **Level of detail** is not built over instances: a coarse node would stand for one placement
//! of a mesh, and the columns of its grid are world-sized; the flat scene keeps it.
//!
//! One set of RBVH arrays serves every mesh: their trees after the top level in one node array
//! (child references offset to where they lie), their height-field records and exact triangles
//! one mesh after another (an exact part's leaf offset with them), and their tiles packed again
//! into one atlas, so that the device reads them as it reads one RBVH's.

use std::time::Instant;

use glam::{Mat3, Mat4};

use super::atlas::{self, Footprint};
use super::child::Child;
use super::layout::Texel;
use super::march::{trace_instanced, Walk};
use super::{
    Atlas, ExactTriangles, GpuHeightfield, Rbvh, RbvhParams, RbvhSource, RbvhStats, TexelFormat,
};
use crate::bvh::{
    check_transforms, index, place, top_node_count, BottomLevel, GpuInstance, GpuNode, GpuTriangle,
};
use crate::geom::{Aabb, Hit, Ray};
use crate::probe::TraceStats;
use crate::progress::{Progress, Quiet};
use crate::scene::InstancedScene;
use crate::{Error, Result};

/// A two-level RBVH in its GPU layout.
#[derive(Clone, Debug, PartialEq)]
pub struct InstancedRbvh {
    /// Every mesh's RBVH in one set of arrays: the top level's nodes first (node 0 its root),
    /// then each mesh's tree; height fields, atlas and exact triangles of every mesh. Not an
    /// RBVH to trace alone: its top level's leaves are instances (and the grafted first
    /// instance's mesh, [`crate::bvh::GRAFTED`]).
    pub(crate) rbvh: Rbvh,
    /// Per instance of the scene, its record.
    pub instances: Vec<GpuInstance>,
    /// Per instance, the transform it is placed by (mesh space to world), as last set: what a
    /// file stores ([`InstancedRbvh::save`]), since the records hold its inverse.
    pub transforms: Vec<Mat4>,
    /// Per mesh of the scene, where its tree lies (its triangles: its exact ones).
    pub meshes: Vec<BottomLevel>,
    /// Per mesh, its texel in its own space, before its objects' own rates
    /// ([`RbvhParams::object_rate`]), which make an object's finer where they ask for it; 0 for a
    /// mesh no instance places (it has no tree).
    pub mesh_texels: Vec<f32>,
    /// Nodes of the top level.
    pub top_nodes: u32,
    /// Inner nodes on the top level's longest root-to-leaf path.
    pub top_depth: u32,
}

impl InstancedRbvh {
    /// Builds each placed mesh's RBVH in its own space at the texel its placements ask for (the
    /// module's rate rule) and the top level over the instances. Fails as [`Rbvh::build`] does,
    /// with [`crate::Error::InvalidGeometry`] from [`InstancedScene::validate`], and with
    /// [`crate::Error::InvalidParameter`] where the arrays outgrow 31-bit indices or the two
    /// levels together are deeper than the traversal stack.
    pub fn build(scene: &InstancedScene, params: &RbvhParams) -> Result<InstancedRbvh> {
        Self::build_observed(scene, params, &Quiet)
    }

    /// [`InstancedRbvh::build`], reporting each mesh's build to `progress`.
    pub fn build_observed(
        scene: &InstancedScene,
        params: &RbvhParams,
        progress: &dyn Progress,
    ) -> Result<InstancedRbvh> {
        let start = Instant::now();
        params.validate()?;
        if params.view_rate > 0.0 {
            // Each mesh is built once in its own space for every place it stands: no one
            // distance from the camera to refine it for.
            return Err(Error::param(
                "view_rate",
                "a scene with instances in two levels is built once a mesh, for every place it \
                 stands, and cannot be refined for one view; build it flat"
                    .to_string(),
            ));
        }
        scene.validate()?;
        let diagonal = scene.placed_bounds().diagonal();
        let texel = if diagonal > 0.0 {
            diagonal / params.texels_per_diagonal
        } else {
            1.0
        };
        let mesh_texels = mesh_texels(scene, texel);
        let parts = scene
            .meshes
            .iter()
            .zip(&mesh_texels)
            .map(|(mesh, &t)| match t > 0.0 {
                true => Rbvh::build_at(&RbvhSource::new(mesh)?, params, t, progress).map(Some),
                false => Ok(None),
            })
            .collect::<Result<Vec<Option<Rbvh>>>>()?;
        let mesh_of: Vec<u32> = scene.instances.iter().map(|i| i.mesh).collect();
        let transforms: Vec<Mat4> = scene.instances.iter().map(|i| i.transform).collect();
        let (rbvh, meshes) = merge(&parts, &mesh_of, params, texel)?;
        let mut two = InstancedRbvh::placed(rbvh, meshes, mesh_texels, &mesh_of, &transforms)?;
        two.rbvh.stats.build_ms = start.elapsed().as_secs_f64() * 1e3;
        Ok(two)
    }

    /// The meshes' merged arrays `rbvh` (its first [`top_node_count`] nodes set aside for the
    /// top level), lying as `meshes` say, under a top level built here over instances of meshes
    /// `mesh_of` at `transforms`: what a build merges and what a file holds
    /// ([`InstancedRbvh::load`]). Fails as [`InstancedRbvh::set_transforms`] does.
    pub(crate) fn placed(
        rbvh: Rbvh,
        meshes: Vec<BottomLevel>,
        mesh_texels: Vec<f32>,
        mesh_of: &[u32],
        transforms: &[Mat4],
    ) -> Result<InstancedRbvh> {
        let mut two = InstancedRbvh {
            top_nodes: top_node_count(&meshes, mesh_of),
            rbvh,
            instances: Vec::new(),
            transforms: Vec::new(),
            meshes,
            mesh_texels,
            top_depth: 0,
        };
        two.place(transforms, mesh_of)?;
        Ok(two)
    }

    /// Moves every instance to its new transform (one per instance, in the scene's order) and
    /// rebuilds the top level alone, as [`crate::bvh::InstancedBvh::set_transforms`] does (same
    /// errors; on one, nothing changes). The meshes keep the texels their first placements
    /// chose.
    pub fn set_transforms(&mut self, transforms: &[Mat4]) -> Result<()> {
        let start = Instant::now();
        check_transforms(transforms, self.instances.len())?;
        let mesh_of: Vec<u32> = self.instances.iter().map(|i| i.mesh).collect();
        self.place(transforms, &mesh_of)?;
        self.rbvh.stats.build_ms = start.elapsed().as_secs_f64() * 1e3;
        Ok(())
    }

    fn place(&mut self, transforms: &[Mat4], mesh_of: &[u32]) -> Result<()> {
        let top = place(
            &self.meshes,
            &self.rbvh.nodes,
            transforms,
            mesh_of,
            self.top_nodes,
        )?;
        let deepest = self.meshes.iter().map(|m| m.depth).max().unwrap_or(0);
        self.rbvh.nodes[..top.nodes.len()].copy_from_slice(&top.nodes);
        self.rbvh.depth = top.depth + 1 + deepest;
        self.rbvh.bounds = top.bounds;
        self.top_depth = top.depth;
        self.instances = top.instances;
        self.transforms = transforms.to_vec();
        Ok(())
    }

    /// The parameters it was built with.
    pub fn params(&self) -> &RbvhParams {
        &self.rbvh.params
    }

    /// What the meshes' builds made (summed), and how long the last build (or top-level
    /// rebuild) took.
    pub fn stats(&self) -> RbvhStats {
        self.rbvh.stats
    }

    /// Box of every instance, world space.
    pub fn bounds(&self) -> Aabb {
        self.rbvh.bounds
    }

    /// The flat scene's texel, world space; each mesh's own is in [`InstancedRbvh::mesh_texels`].
    pub fn texel_size(&self) -> f32 {
        self.rbvh.texel_size
    }

    /// The world texel of instance `k` (a hit's [`Hit::instance`]): its mesh's texel times the
    /// instance's stretch (`stretch`): at most [`InstancedRbvh::texel_size`] as built (the rate rule),
    /// smaller for a smaller placement, larger for one moved to a larger scale since
    /// ([`InstancedRbvh::set_transforms`] keeps the meshes' texels). What a secondary ray leaving
    /// that instance's surface is offset by, so that it scales with the instance; the flat
    /// scene's texel for an instance that does not exist.
    pub fn instance_texel(&self, k: u32) -> f32 {
        let (Some(instance), Some(m)) = (
            self.instances.get(k as usize),
            self.transforms.get(k as usize),
        ) else {
            return self.texel_size();
        };
        let mesh_texel = self
            .mesh_texels
            .get(instance.mesh as usize)
            .copied()
            .unwrap_or(0.0);
        mesh_texel * stretch(*m)
    }

    /// Nodes (both levels) and height-field records: [`Rbvh::tree_bytes`].
    pub fn tree_bytes(&self) -> u64 {
        self.rbvh.tree_bytes()
    }

    /// The atlas as the device holds it: [`Rbvh::atlas_bytes`].
    pub fn atlas_bytes(&self) -> u64 {
        self.rbvh.atlas_bytes()
    }

    /// The exact triangles, indexed: [`Rbvh::triangle_bytes`].
    pub fn triangle_bytes(&self) -> u64 {
        self.rbvh.triangle_bytes()
    }

    /// Bytes of the instance records.
    pub fn instance_bytes(&self) -> u64 {
        std::mem::size_of_val(self.instances.as_slice()) as u64
    }

    /// Device bytes of the whole structure.
    pub fn total_bytes(&self) -> u64 {
        self.tree_bytes() + self.atlas_bytes() + self.triangle_bytes() + self.instance_bytes()
    }

    /// The arrays the device reads (the instances apart): every mesh's RBVH in one.
    pub(crate) fn parts(&self) -> &Rbvh {
        &self.rbvh
    }

    /// Closest hit of one ray, or [`Hit::MISS`]: ids as [`Rbvh::closest_hit`]'s (a triangle's is
    /// its index in its mesh, a height field's its record among every mesh's), the instance in
    /// [`Hit::instance`], the normal in world space.
    pub fn closest_hit(&self, ray: &Ray) -> (Hit, TraceStats) {
        trace_instanced(
            &self.rbvh,
            &self.instances,
            ray,
            false,
            Walk::PLAIN,
            &mut (),
        )
    }

    /// Whether anything is hit in `[tmin, tmax)`: the hit returned is *some* hit, not the closest.
    pub fn any_hit(&self, ray: &Ray) -> (Hit, TraceStats) {
        trace_instanced(&self.rbvh, &self.instances, ray, true, Walk::PLAIN, &mut ())
    }

    /// The device's twin ([`super::DeviceTwin`]), read for read, instances included.
    pub fn device_twin(&self) -> super::DeviceTwin<'_> {
        super::DeviceTwin::new(&self.rbvh, &self.instances)
    }

    /// Traces many rays in parallel with `rayon`; hits in ray order.
    pub fn trace_cpu(&self, rays: &[Ray], any_hit: bool) -> Vec<Hit> {
        use rayon::prelude::*;
        rays.par_iter()
            .map(|r| self.trace_one(r, any_hit))
            .collect()
    }

    fn trace_one(&self, ray: &Ray, any_hit: bool) -> Hit {
        trace_instanced(
            &self.rbvh,
            &self.instances,
            ray,
            any_hit,
            Walk::PLAIN,
            &mut (),
        )
        .0
    }
}

/// Per mesh, the texel it is rasterized at in its own space: the flat scene's `texel` over the
/// largest stretch of any of its placements (the longest axis of the transform's linear part);
/// 0 for a mesh that no instance places.
fn mesh_texels(scene: &InstancedScene, texel: f32) -> Vec<f32> {
    let mut stretch = vec![0.0f32; scene.meshes.len()];
    for instance in &scene.instances {
        if let Some(s) = stretch.get_mut(instance.mesh as usize) {
            *s = s.max(self::stretch(instance.transform));
        }
    }
    stretch
        .into_iter()
        .map(|s| if s > 0.0 { texel / s } else { 0.0 })
        .collect()
}

/// How far `m` stretches a mesh at most (the largest singular value of its linear part, or a bound
/// above it): the longest axis where the axes are orthogonal (a rotation and scales, which every
/// scene file's `translate · rotate · scale` is), else the Frobenius norm (a glTF node's parent's
/// uneven scale under a child's rotation shears), which is never below it.
pub(crate) fn stretch(m: Mat4) -> f32 {
    let linear = Mat3::from_mat4(m);
    let axes = [linear.x_axis, linear.y_axis, linear.z_axis];
    let longest = axes.iter().map(|c| c.length()).fold(0.0f32, f32::max);
    let square = longest * longest;
    let orthogonal = [(0, 1), (0, 2), (1, 2)]
        .iter()
        .all(|&(a, b)| axes[a].dot(axes[b]).abs() <= 1e-5 * square);
    if orthogonal {
        longest
    } else {
        axes.iter().map(|c| c.length_squared()).sum::<f32>().sqrt()
    }
}

/// The meshes' RBVHs (`None`: a mesh not placed) in one set of arrays, room left before them
/// for the top level over instances of `mesh_of`, and where each mesh's tree lies.
fn merge(
    parts: &[Option<Rbvh>],
    mesh_of: &[u32],
    params: &RbvhParams,
    texel: f32,
) -> Result<(Rbvh, Vec<BottomLevel>)> {
    let unplaced = |base: u32| BottomLevel {
        root: 0,
        nodes: 0,
        first_triangle: base,
        triangles: 0,
        depth: 0,
        bounds: Aabb::EMPTY,
    };
    // The top level's size depends on which meshes have something to enter: known from the
    // parts' boxes before any node is placed.
    let provisional: Vec<BottomLevel> = parts
        .iter()
        .map(|p| match p {
            Some(r) if !r.bounds.is_empty() => BottomLevel {
                bounds: r.bounds,
                ..unplaced(0)
            },
            _ => unplaced(0),
        })
        .collect();
    let top_nodes = top_node_count(&provisional, mesh_of);
    let mut nodes = vec![GpuNode::default(); top_nodes as usize];
    let mut gathered: Vec<GpuTriangle> = Vec::new();
    let mut heightfields: Vec<GpuHeightfield> = Vec::new();
    let mut footprints = Vec::new();
    let mut meshes = Vec::with_capacity(parts.len());
    let mut stats = RbvhStats::default();
    for part in parts {
        let triangle_base = index(gathered.len(), "exact triangles")?;
        let Some(r) = part else {
            meshes.push(unplaced(triangle_base));
            continue;
        };
        let node_base = index(nodes.len(), "nodes")?;
        let heightfield_base = index(heightfields.len(), "height fields")?;
        nodes.extend(
            r.nodes
                .iter()
                .map(|n| relocated(n, node_base, triangle_base, heightfield_base)),
        );
        gathered.extend(r.triangles.iter().map(|t| {
            let mut t = *t;
            if let Some(leaf) = t.part_leaf() {
                let bare = t.flags & GpuTriangle::BARE != 0;
                t.flags = GpuTriangle::part_flags(leaf + heightfield_base, bare);
            }
            t
        }));
        footprints.extend(r.heightfields.iter().map(|h| Footprint {
            res_u: h.res_u,
            res_v: h.res_v,
            bits: r.atlas.bits_at(h.atlas_base as usize),
        }));
        heightfields.extend_from_slice(&r.heightfields);
        stats.heightfield_leaves += r.stats.heightfield_leaves;
        stats.triangle_leaves += r.stats.triangle_leaves;
        stats.tile_texels += r.stats.tile_texels;
        meshes.push(BottomLevel {
            root: node_base,
            nodes: r.nodes.len() as u32,
            first_triangle: triangle_base,
            triangles: r.triangles.len() as u32,
            depth: r.depth,
            bounds: if r.bounds.is_empty() {
                Aabb::EMPTY
            } else {
                r.bounds
            },
        });
    }
    index(nodes.len(), "nodes")?;
    index(gathered.len(), "exact triangles")?;
    index(heightfields.len(), "height fields")?;
    let (atlas, colours) = repack(parts, &footprints, &mut heightfields, params.texels)?;
    let rbvh = Rbvh {
        params: *params,
        nodes,
        triangles: ExactTriangles::new(gathered),
        heightfields,
        atlas,
        bounds: Aabb::EMPTY,
        depth: 1,
        texel_size: texel,
        stats,
        colours,
    };
    Ok((rbvh, meshes))
}

/// `node` of a mesh's RBVH placed at `node_base` among the nodes, `triangle_base` among the
/// exact triangles and `heightfield_base` among the height-field records.
fn relocated(node: &GpuNode, node_base: u32, triangle_base: u32, heightfield_base: u32) -> GpuNode {
    let shift = |child: u32, count: u32| match Child::decode(child, count) {
        Child::Inner(n) => (n + node_base, count),
        Child::Absent => (child, count),
        Child::Triangles { first, count } => Child::Triangles {
            first: first + triangle_base,
            count,
        }
        .encode(),
        Child::Heightfield(i) => Child::Heightfield(i + heightfield_base).encode(),
    };
    let (a_child, a_count) = shift(node.a_child, node.a_count);
    let (b_child, b_count) = shift(node.b_child, node.b_count);
    GpuNode {
        a_child,
        a_count,
        b_child,
        b_count,
        ..*node
    }
}

/// Every part's tiles (`footprints`, in the order of `heightfields`) packed into one atlas for
/// texels in `format`,
/// their texels (and colours, where any part has them) copied there and `heightfields`' bases
/// moved to match.
fn repack(
    parts: &[Option<Rbvh>],
    footprints: &[Footprint],
    heightfields: &mut [GpuHeightfield],
    format: TexelFormat,
) -> Result<(Atlas, Option<Vec<u32>>)> {
    let packing = atlas::pack(footprints, format)?;
    let pitch = packing.pitch as usize;
    let len = pitch * packing.rows as usize;
    let mut texels = vec![Texel::HOLE; len];
    let coloured = parts.iter().flatten().any(|r| r.colours.is_some());
    let mut colours = coloured.then(|| vec![0u32; len]);
    let sources = parts
        .iter()
        .flatten()
        .flat_map(|r| r.heightfields.iter().map(move |h| (r, h.atlas_base)));
    for ((leaf, (r, from)), &to) in heightfields.iter_mut().zip(sources).zip(&packing.bases) {
        let (res_u, from, to) = (leaf.res_u as usize, from as usize, to as usize);
        let src_pitch = r.atlas.pitch as usize;
        for j in 0..leaf.res_v as usize {
            let (src, dst) = (from + j * src_pitch, to + j * pitch);
            texels[dst..dst + res_u].copy_from_slice(&r.atlas.texels[src..src + res_u]);
            if let (Some(out), Some(own)) = (colours.as_mut(), r.colours.as_ref()) {
                out[dst..dst + res_u].copy_from_slice(&own[src..src + res_u]);
            }
        }
        leaf.atlas_base = to as u32;
    }
    let atlas = Atlas {
        pitch: packing.pitch,
        rows: packing.rows,
        packed_rows: packing.packed_rows,
        texels,
    };
    Ok((atlas, colours))
}

#[cfg(test)]
mod tests {
    use glam::{Quat, Vec3};

    use super::*;
    use crate::scene::{Instance, Scene};

    /// Two built-in meshes placed five times (turned, scaled unevenly, one mirrored) and a third
    /// mesh placed nowhere.
    fn placed() -> InstancedScene {
        let meshes: Vec<Scene> = ["bumpy-sphere", "torus", "cube"]
            .iter()
            .map(|name| Scene::builtin(name).unwrap())
            .collect();
        let instances = (0..5u32)
            .map(|k| {
                let turn =
                    Quat::from_euler(glam::EulerRot::XYZ, 0.4 * k as f32, 0.9 * k as f32, 0.1);
                let mirror = if k == 3 { -1.0 } else { 1.0 };
                let scale = Vec3::new(mirror * (0.5 + 0.2 * k as f32), 0.7, 0.6);
                let at = Vec3::new(k as f32 * 0.8 - 1.6, 0.2 * k as f32, 0.1 * k as f32);
                Instance {
                    mesh: k % 2,
                    transform: Mat4::from_scale_rotation_translation(scale, turn, at),
                }
            })
            .collect();
        InstancedScene {
            name: "placed".into(),
            meshes,
            instances,
            ..InstancedScene::default()
        }
    }

    fn rays(scene: &InstancedScene, n: usize) -> Vec<Ray> {
        let b = scene.bounds();
        let (c, r) = (b.center(), 0.5 * b.diagonal());
        let mut seed = 0x9E37_79B9_7F4A_7C15u64;
        let mut next = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 40) as f32 / (1u64 << 24) as f32
        };
        let mut unit = move || {
            let z = 2.0 * next() - 1.0;
            let a = std::f32::consts::TAU * next();
            let s = (1.0 - z * z).max(0.0).sqrt();
            (Vec3::new(s * a.cos(), s * a.sin(), z), next())
        };
        (0..n)
            .map(|_| {
                let ((u, f), (v, _)) = (unit(), unit());
                let origin = c + u * r * (0.3 + 1.5 * f);
                Ray::new(origin, c + v * r * 0.5 - origin, 0.0, f32::INFINITY)
            })
            .collect()
    }

    /// The referee: each mesh's own RBVH, built alone at the texel the two-level build chose,
    /// traced along the ray taken into each instance's space; the nearest hit wins. The two-level
    /// arrays are those RBVHs' own, relocated and packed again, so the hits are theirs bit for
    /// bit.
    #[test]
    fn two_levels_hit_what_each_mesh_rbvh_hits_alone() {
        let scene = placed();
        for (level, height_only) in [(2, false), (1, true)] {
            let mut params = RbvhParams::quality(level).unwrap();
            if height_only {
                params.texels = super::super::TexelFormat::Height;
            }
            let two = InstancedRbvh::build(&scene, &params).unwrap();
            assert_eq!(two.mesh_texels[2], 0.0, "an unplaced mesh has no tree");
            assert_eq!(two.meshes[2].nodes, 0);
            let alone: Vec<Option<Rbvh>> = scene
                .meshes
                .iter()
                .zip(&two.mesh_texels)
                .map(|(mesh, &t)| {
                    (t > 0.0).then(|| {
                        let source = RbvhSource::new(mesh).unwrap();
                        Rbvh::build_at(&source, &params, t, &Quiet).unwrap()
                    })
                })
                .collect();
            let heightfield_base: Vec<u32> = alone
                .iter()
                .scan(0u32, |base, r| {
                    let first = *base;
                    *base += r.as_ref().map_or(0, |r| r.heightfields.len() as u32);
                    Some(first)
                })
                .collect();
            let (mut hits, mut compared) = (0, 0);
            for (i, ray) in rays(&scene, 3000).iter().enumerate() {
                let (h, stats) = two.closest_hit(ray);
                assert!(!stats.overflow, "ray {i}");
                let mut best = Hit::MISS;
                for (k, instance) in two.instances.iter().enumerate() {
                    let mesh = instance.mesh as usize;
                    let Some(r) = &alone[mesh] else { continue };
                    let (f, _) = r.closest_hit(&instance.ray_into(ray));
                    if f.is_hit() && f.t < best.t {
                        let id = match f.id & crate::bvh::LEAF_BIT {
                            0 => f.id,
                            _ => f.id + heightfield_base[mesh],
                        };
                        best = Hit {
                            id,
                            instance: k as u32,
                            normal: instance.normal_out(f.normal()).to_array(),
                            ..f
                        };
                    }
                }
                compared += 1;
                assert_eq!(h.is_hit(), best.is_hit(), "ray {i}: {h:?} vs {best:?}");
                if h.is_hit() {
                    hits += 1;
                    assert_eq!(
                        (h.t.to_bits(), h.id, h.instance, h.normal),
                        (best.t.to_bits(), best.id, best.instance, best.normal),
                        "ray {i} (level {level})"
                    );
                }
            }
            assert!(hits * 4 > compared, "{hits} hits of {compared} rays");
        }
    }

    #[test]
    fn a_mesh_takes_the_texel_of_its_largest_placement() {
        let mut scene = placed();
        scene.instances[1].transform = Mat4::from_scale(Vec3::new(0.5, 3.0, 1.0));
        let texels = mesh_texels(&scene, 0.1);
        let longest = |k: usize| stretch(scene.instances[k].transform);
        let of = |mesh: u32| {
            (0..scene.instances.len())
                .filter(|&k| scene.instances[k].mesh == mesh)
                .map(longest)
                .fold(0.0f32, f32::max)
        };
        assert_eq!(texels[1], 0.1 / 3.0f32.max(of(1)));
        assert_eq!(texels[0], 0.1 / of(0));
        assert_eq!(texels[2], 0.0);
    }

    /// A transform's stretch is its longest axis where the axes are orthogonal, and never below
    /// its largest singular value where they are not (a shear).
    #[test]
    fn a_stretch_bounds_what_a_transform_does_to_lengths() {
        let trs = Mat4::from_scale_rotation_translation(
            Vec3::new(0.5, 3.0, 2.0),
            Quat::from_rotation_y(0.7),
            Vec3::ONE,
        );
        assert!((stretch(trs) - 3.0).abs() < 1e-5);
        let shear = Mat4::from_cols_array(&[
            1.0, 0.0, 0.0, 0.0, 2.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0,
        ]);
        // The largest singular value of [[1, 2], [0, 1]] is 1 + sqrt(2).
        let largest = 1.0 + 2.0f32.sqrt();
        assert!(stretch(shear) >= largest, "{}", stretch(shear));
        for k in 0..64 {
            let a = k as f32 * 0.1;
            let d = Vec3::new(a.cos(), a.sin(), 0.3 * a).normalize();
            assert!(shear.transform_vector3(d).length() <= stretch(shear) * (1.0 + 1e-6));
        }
    }
}
