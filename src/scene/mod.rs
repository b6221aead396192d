//! Scenes: the triangles every later stage traces, where they come from, and how to look at them.
//!
//! A [`Scene`] is a flat triangle list with a per-triangle object id; an [`InstancedScene`]
//! holds meshes once and places them by instances, for two-level structures. It is loaded from an OBJ
//! file, a glTF/GLB file or a TOML scene file (which arranges meshes and adds a camera and a
//! light), or built procedurally ([`builtin`]) so that tests and benchmarks need no files.
//! Every loader validates before returning, so later stages may assume finite vertices and
//! in-range indices.
//!
//! Scenes whose files carry materials (OBJ `Kd`/`map_Kd`, glTF `baseColorFactor`/
//! `baseColorTexture`) also get [`SurfaceMaterials`]: a base colour per triangle and texture
//! coordinates per corner. Scenes without them get none, so they cost nothing.

pub mod builtin;
mod camera;
mod gltf;
mod instances;
mod light;
mod load;
pub mod material;
mod mesh;
mod mesh_file;
pub mod mipmap;
mod obj;
mod sample;
mod scene_file;
pub mod texture;
mod topology;
mod view;

pub use camera::{Camera, CameraFault, DEFAULT_VFOV_DEG};
pub use instances::{available_memory, transform_fault, transformed_box, Instance, InstancedScene};
pub use instances::{FLAT_BYTES_PER_TRIANGLE, MAX_INSTANCES, MIN_RELATIVE_DETERMINANT};
pub use light::Light;
pub use material::{Material, SurfaceMaterials, NO_MATERIAL};
pub use mesh::{ObjectSurface, Scene};
pub use mipmap::MipChain;
pub use sample::{PointSource, SCAN_MATCH};
pub use texture::{Texture, Wrap};
pub use topology::{creases, open_boundary, topology, Topology};
pub use view::{Instances, SceneView};
