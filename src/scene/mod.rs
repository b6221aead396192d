//! Scenes: the triangles every later stage traces, where they come from, and how to look at them.
//!
//! A [`Scene`] is a flat triangle list with a per-triangle object id. It is loaded from an OBJ
//! file, a glTF/GLB file or a TOML scene file (which arranges meshes and adds a camera and a
//! light), or built procedurally ([`builtin`]) so that tests and benchmarks need no files.
//! Every loader validates before returning, so later stages may assume finite vertices and
//! in-range indices.

pub mod builtin;
mod camera;
mod gltf;
mod light;
mod load;
mod mesh;
mod obj;
mod scene_file;

pub use camera::Camera;
pub use light::Light;
pub use mesh::Scene;
