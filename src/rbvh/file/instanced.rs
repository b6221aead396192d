//! A two-level RBVH's file ([`InstancedRbvh::save`]): the sections of the RBVH that merges every
//! mesh's arrays, as a flat RBVH's file holds them, and two more, both required, so that no
//! reader takes it for a flat RBVH:
//!
//! | tag | version | content |
//! |---|---|---|
//! | `MESH` | 1 | per mesh, 48 bytes: `root`, `nodes`, `first_triangle`, `triangles`, `depth` (u32 each: where its tree and exact triangles lie, [`BottomLevel`]), its texel in its own space (f32), its bounds in its own space (6 × f32: min x, y, z, max x, y, z) |
//! | `PLAC` | 1 | per instance, 52 bytes: its mesh (u32), its transform's first three rows (12 × f32, row by row; the last row is `0 0 0 1`) |
//!
//! The top level is not read: its nodes (the first of `NODE`) are built again on load over the
//! placements, by the builder's own code, so a file cannot hand the traversal a top level that
//! enters instances wrongly; every mesh's tree is checked as a flat RBVH's nodes are, and may
//! not name a node of the top level. The meshes' records are checked against the arrays (a tree
//! within the nodes after the top level, triangles within the exact triangles, a finite texel,
//! bounds without NaN), the placements against the meshes (an existing mesh, a transform that
//! [`crate::scene::transform_fault`] accepts), and the two levels' depth against the stack.

use std::io::Write;
use std::path::Path;

use glam::{Mat4, Vec4};

use super::sections::{self, parse, Put, MESHES, MESH_BYTES, PLACEMENTS, PLACEMENT_BYTES};
use super::{file_version, put_f32, put_u32, Reader, VERSION};
use crate::bvh::{check_transforms, top_node_count, BottomLevel, STACK_SIZE};
use crate::geom::Aabb;
use crate::io::write_atomically;
use crate::rbvh::params::TexelFormat;
use crate::rbvh::InstancedRbvh;
use crate::scene::InstancedScene;
use crate::{Error, Result};

impl InstancedRbvh {
    /// Writes the file the module describes, atomically (as [`crate::rbvh::Rbvh::save`]).
    pub fn save(&self, path: &Path) -> Result<()> {
        let r = self.parts();
        if r.params.texels == TexelFormat::Height && r.colours.is_some() {
            return Err(Error::param(
                "rbvh",
                format!(
                    "{}: a height-only RBVH's file has no colour channel, and this one has colours",
                    path.display()
                ),
            ));
        }
        let bytes = self.to_bytes();
        write_atomically(path, |w| w.write_all(&bytes))
    }

    /// The bytes [`InstancedRbvh::save`] writes.
    pub fn to_bytes(&self) -> Vec<u8> {
        let meshes: Put = Box::new(|out| {
            for (m, &texel) in self.meshes.iter().zip(&self.mesh_texels) {
                for word in [m.root, m.nodes, m.first_triangle, m.triangles, m.depth] {
                    put_u32(out, word);
                }
                put_f32(out, texel);
                for x in m
                    .bounds
                    .min
                    .to_array()
                    .into_iter()
                    .chain(m.bounds.max.to_array())
                {
                    put_f32(out, x);
                }
            }
        });
        let placements: Put = Box::new(|out| {
            for (instance, m) in self.instances.iter().zip(&self.transforms) {
                put_u32(out, instance.mesh);
                for row in 0..3 {
                    for x in m.row(row).to_array() {
                        put_f32(out, x);
                    }
                }
            }
        });
        sections::write(
            self.parts(),
            vec![
                (MESHES, MESH_BYTES * self.meshes.len(), meshes),
                (
                    PLACEMENTS,
                    PLACEMENT_BYTES * self.instances.len(),
                    placements,
                ),
            ],
        )
    }

    /// Reads a file written by [`InstancedRbvh::save`]. A missing or unreadable file is
    /// [`Error::Io`]; a flat RBVH's file, or any malformation (the flat file's, and the module's
    /// checks of meshes and placements), is [`Error::Parse`] naming the file and the section.
    pub fn load(path: &Path) -> Result<InstancedRbvh> {
        let bytes = crate::io::input::read(path)?;
        Self::from_bytes(&bytes, path)
    }

    /// Parses the bytes of a two-level RBVH's file; `name_for_errors` is the file named in
    /// every error.
    pub fn from_bytes(bytes: &[u8], name_for_errors: &Path) -> Result<InstancedRbvh> {
        let path = name_for_errors;
        let version = file_version(bytes, path)?;
        if version != VERSION {
            return Err(Error::parse(
                path,
                None,
                format!("version {version}: a flat RBVH's file (two-level RBVHs are saved from version {VERSION})"),
            ));
        }
        let parsed = parse(bytes, path)?;
        let (Some(mesh_bytes), Some(placement_bytes)) = (parsed.meshes, parsed.placements) else {
            return Err(Error::parse(
                path,
                None,
                "a flat RBVH (no sections MESH and PLAC): load it with Rbvh::load, or trace it \
                 with the flat scene it was built from"
                    .to_string(),
            ));
        };
        let (meshes, mesh_texels) = read_meshes(mesh_bytes, path)?;
        let (mesh_of, transforms) = read_placements(placement_bytes, path)?;
        if let Some((k, &m)) = mesh_of
            .iter()
            .enumerate()
            .find(|(_, &m)| m as usize >= meshes.len())
        {
            return Err(parsed.error_in(
                PLACEMENTS,
                format!(
                    "instance {k} places mesh {m}, but there are {} meshes",
                    meshes.len()
                ),
            ));
        }
        let top_nodes = top_node_count(&meshes, &mesh_of) as usize;
        let r = parsed.rbvh();
        check_meshes(
            &meshes,
            &mesh_texels,
            top_nodes,
            r.nodes.len(),
            r.triangles.len(),
        )
        .map_err(|why| parsed.error_in(MESHES, why))?;
        check_transforms(&transforms, transforms.len())
            .map_err(|e| parsed.error_in(PLACEMENTS, e.to_string()))?;
        let rbvh = parsed.checked(top_nodes)?;
        InstancedRbvh::placed(rbvh, meshes, mesh_texels, &mesh_of, &transforms)
            .map_err(|e| Error::parse(path, None, format!("its placements: {e}")))
    }

    /// Checks that this two-level RBVH (from a file) was built from `scene`'s meshes, and takes
    /// the scene's placements: as many meshes, each mesh's box within
    /// [`crate::rbvh::SCENE_MATCH_TEXELS`] of its texels of the scene's, and as many instances,
    /// each of the same mesh; the instances then move to the scene's transforms (the top level
    /// is rebuilt), so that a file serves a scene whose instances moved ([`Self::stats`] keeps
    /// the build's time). An [`Error::InvalidParameter`] names the first difference.
    pub fn check_built_from(&mut self, scene: &InstancedScene) -> Result<()> {
        let fail = |why: String| {
            Err(Error::param(
                "rbvh",
                format!("built for another scene than {:?}: {why}; rebuild it from this scene (rbvh build --scene ... --out ...)", scene.name),
            ))
        };
        if self.meshes.len() != scene.meshes.len() || self.instances.len() != scene.instances.len()
        {
            return fail(format!(
                "it has {} meshes and {} instances, the scene {} and {}",
                self.meshes.len(),
                self.instances.len(),
                scene.meshes.len(),
                scene.instances.len()
            ));
        }
        for (k, (built, mesh)) in self.meshes.iter().zip(&scene.meshes).enumerate() {
            let placed = self.instances.iter().any(|i| i.mesh as usize == k);
            let (b, e) = (built.bounds, mesh.bounds());
            if placed && !(b.is_empty() && e.is_empty()) {
                if b.is_empty() != e.is_empty() {
                    return fail(format!(
                        "its mesh {k}'s box and the scene's are not both empty"
                    ));
                }
                let apart = (b.min - e.min)
                    .abs()
                    .max((b.max - e.max).abs())
                    .max_element();
                let tolerance = crate::rbvh::SCENE_MATCH_TEXELS * self.mesh_texels[k].max(0.0)
                    + 1e-5 * e.diagonal();
                if apart.is_nan() || apart > tolerance {
                    return fail(format!(
                        "its mesh {k}'s box is {:?}..{:?}, the scene's {:?}..{:?} ({apart} apart)",
                        b.min.to_array(),
                        b.max.to_array(),
                        e.min.to_array(),
                        e.max.to_array()
                    ));
                }
            }
        }
        if let Some(k) =
            (0..self.instances.len()).find(|&k| self.instances[k].mesh != scene.instances[k].mesh)
        {
            return fail(format!(
                "its instance {k} places mesh {}, the scene's mesh {}",
                self.instances[k].mesh, scene.instances[k].mesh
            ));
        }
        let transforms: Vec<Mat4> = scene.instances.iter().map(|i| i.transform).collect();
        // The build time stays the build's, not the top level's rebuild here.
        let built_ms = self.rbvh.stats.build_ms;
        self.set_transforms(&transforms)?;
        self.rbvh.stats.build_ms = built_ms;
        Ok(())
    }
}

/// `MESH`'s records: the meshes and their texels.
fn read_meshes(bytes: &[u8], path: &Path) -> Result<(Vec<BottomLevel>, Vec<f32>)> {
    let mut r = Reader::new(bytes, path);
    let mut meshes = Vec::with_capacity(bytes.len() / MESH_BYTES);
    let mut texels = Vec::with_capacity(bytes.len() / MESH_BYTES);
    for _ in 0..bytes.len() / MESH_BYTES {
        let mut words = [0u32; 5];
        for w in &mut words {
            *w = r.u32("a mesh's record")?;
        }
        texels.push(r.f32("a mesh's texel")?);
        let mut corners = [0f32; 6];
        for c in &mut corners {
            *c = r.f32("a mesh's bounds")?;
        }
        let [root, nodes, first_triangle, triangles, depth] = words;
        meshes.push(BottomLevel {
            root,
            nodes,
            first_triangle,
            triangles,
            depth,
            bounds: Aabb {
                min: [corners[0], corners[1], corners[2]].into(),
                max: [corners[3], corners[4], corners[5]].into(),
            },
        });
    }
    Ok((meshes, texels))
}

/// `PLAC`'s records: each instance's mesh and transform.
fn read_placements(bytes: &[u8], path: &Path) -> Result<(Vec<u32>, Vec<Mat4>)> {
    let mut r = Reader::new(bytes, path);
    let n = bytes.len() / PLACEMENT_BYTES;
    let (mut mesh_of, mut transforms) = (Vec::with_capacity(n), Vec::with_capacity(n));
    for _ in 0..n {
        mesh_of.push(r.u32("an instance's mesh")?);
        let mut rows = [Vec4::ZERO; 3];
        for row in &mut rows {
            *row = Vec4::new(
                r.f32("an instance's transform")?,
                r.f32("an instance's transform")?,
                r.f32("an instance's transform")?,
                r.f32("an instance's transform")?,
            );
        }
        transforms.push(Mat4::from_cols(rows[0], rows[1], rows[2], Vec4::W).transpose());
    }
    Ok((mesh_of, transforms))
}

/// Each mesh's record against the arrays: its tree within the nodes after the top level, its
/// triangles within the exact triangles, a finite texel of at least 0, bounds without NaN.
fn check_meshes(
    meshes: &[BottomLevel],
    texels: &[f32],
    top_nodes: usize,
    nodes: usize,
    triangles: usize,
) -> std::result::Result<(), String> {
    if nodes < top_nodes.max(1) {
        return Err(format!(
            "{nodes} nodes: fewer than the top level's {top_nodes} over the placements"
        ));
    }
    for (k, (m, &texel)) in meshes.iter().zip(texels).enumerate() {
        let tree = u64::from(m.root)..u64::from(m.root) + u64::from(m.nodes);
        if m.nodes > 0 && (tree.start < top_nodes as u64 || tree.end > nodes as u64) {
            return Err(format!(
                "mesh {k}'s tree, nodes {}..{}, lies outside the meshes' nodes {top_nodes}..{nodes}",
                tree.start, tree.end
            ));
        }
        if u64::from(m.first_triangle) + u64::from(m.triangles) > triangles as u64 {
            return Err(format!(
                "mesh {k}'s triangles {}..{} are out of range (there are {triangles})",
                m.first_triangle,
                u64::from(m.first_triangle) + u64::from(m.triangles)
            ));
        }
        if !(texel.is_finite() && texel >= 0.0) || (m.nodes > 0 && texel == 0.0) {
            return Err(format!(
                "mesh {k}'s texel is {texel}: a finite size of at least 0, and above 0 for a \
                 mesh with a tree"
            ));
        }
        if m.depth > STACK_SIZE {
            return Err(format!(
                "mesh {k}'s tree is {} deep, deeper than the {STACK_SIZE}-entry traversal stack",
                m.depth
            ));
        }
        if m.bounds.min.is_nan() || m.bounds.max.is_nan() {
            return Err(format!("mesh {k}'s bounds contain NaN"));
        }
        // A mesh without a tree has nothing to enter: its box must be empty, or the top level
        // would place it and its instances would enter an unchecked root.
        match (m.nodes > 0, m.bounds.is_empty()) {
            (true, true) => return Err(format!("mesh {k} has a tree but an empty box")),
            (false, false) => {
                return Err(format!("mesh {k} has no tree but the box {:?}", m.bounds))
            }
            (true, false) if !(m.bounds.min.is_finite() && m.bounds.max.is_finite()) => {
                return Err(format!("mesh {k}'s box {:?} is not finite", m.bounds))
            }
            _ => {}
        }
    }
    Ok(())
}
