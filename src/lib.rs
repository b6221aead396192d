//! # rbvh — Rasterized Bounding Volume Hierarchies on Vulkan compute
//!
//! An implementation of Novák & Dachsbacher, "Rasterized Bounding Volume Hierarchies"
//! (Eurographics 2012): approximate ray casting through a BVH whose leaves are height fields
//! in a texture atlas, ray-marched in GLSL compute shaders. The exact triangle BVH in [`bvh`] is
//! the referee every approximation is measured against.
//!
//! Data flows one way, and the modules follow it:
//!
//! ```text
//! points (PLY / XYZ readers; normals and spacing estimated from nearest neighbours)
//!   → scene (load / built-in / camera; points sampled from triangles)
//! scene (load / built-in / camera) → bvh  (exact: build, GPU layout, CPU reference tracer)
//!                                  → rbvh (build, raster or splat, atlas, GPU layout, CPU caster)
//!                                       → lod (coarse column grids at inner nodes, ray cones)
//!                                       → surface (colour channel, hit → texel, painting)
//!        → gpu (Vulkan context, own or embedded; uploads, pipelines, tracer, painter)
//!        → output (PNG, EXR)
//!        → random (SplitMix64 streams, cosine directions)
//!        → rays (secondary rays from hits: ambient occlusion, shadow, diffuse)
//!        → ibl (image-based lighting: environment light, visibility through either structure)
//!        → bench, regress (measurement and image regression; feature `measure`), both scoring
//!          images by flip
//! probe: per-ray counters and the reads of the CPU twins, shared by bvh, rbvh, gpu and bench
//! progress: how a caller watches long steps (loading, building, tracing), shared likewise
//! ```
//!
//! The types most users need are at the crate root:
//!
//! ```
//! use rbvh::{Bvh, Context, ContextOptions, Query, Rbvh, RbvhParams, Scene, Structure, Tracer};
//!
//! let scene = Scene::load("sphere")?;
//! let rays = scene.camera_or_framed(1.0).primary_rays(64, 64);
//! let ctx = Context::new(&ContextOptions::default())?;
//!
//! // The referee: the exact triangle BVH.
//! let exact = Structure::from(Bvh::build(&scene)?);
//! let exact = Tracer::new(&ctx, &exact)?.trace(&rays, Query::Closest)?;
//! // The approximation: an RBVH at quality Q2.
//! let rbvh = Structure::from(Rbvh::build(&scene, &RbvhParams::quality(2)?)?);
//! let approx = Tracer::new(&ctx, &rbvh)?.trace(&rays, Query::Closest)?;
//!
//! for (e, a) in exact.hits.iter().zip(&approx.hits) {
//!     if e.is_hit() && a.is_hit() {
//!         assert!((e.t - a.t).abs() < 0.01 * scene.bounds().diagonal());
//!     }
//! }
//! # Ok::<(), rbvh::Error>(())
//! ```
//!
//! Engines that own their Vulkan device use [`gpu::Context::embedded`] and record the trace
//! into their own command buffers ([`gpu::Tracer::new_recorded`], [`gpu::Tracer::bind`],
//! [`gpu::Tracer::record`]); `examples/embed.rs` shows the whole contract, and
//! `glsl/rbvh.glsl` can be included in an engine's own shaders.
//!
//! ## Features
//!
//! All are on by default, for the `rbvh` tool. An engine takes `default-features = false` and
//! adds what it uses; the library itself (scenes, builders, Vulkan tracing) needs none of them.
//!
//! * `loaded` — [`Context::new`], which loads libvulkan at run time; off, the library works on the
//!   engine's device through [`Context::embedded`].
//! * `exr` — EXR output ([`output::write_exr`]) and EXR environment maps for [`ibl`].
//! * `measure` — [`mod@bench`] and [`regress`] (FLIP through nv-flip's C++, charts through plotters).
//! * `cli` — the `rbvh` binary (clap, indicatif, anyhow).
//!
//! Shaders are compiled at build time by `glslc` (found as `$GLSLC`, in `$VULKAN_SDK`, or on
//! `PATH`); nothing else is needed from the system to build.

#![warn(missing_docs)]

#[cfg(feature = "measure")]
pub mod bench;
pub mod bvh;
pub mod error;
#[cfg(feature = "measure")]
pub mod flip;
pub mod geom;
pub mod gpu;
pub mod ibl;
pub mod io;
pub mod lod;
pub mod output;
pub mod points;
pub mod preview;
pub mod probe;
pub mod progress;
pub mod random;
pub mod rays;
pub mod rbvh;
#[cfg(feature = "measure")]
pub mod regress;
pub mod rgba;
pub mod scene;
mod srgb;
pub mod structure;
pub mod surface;

pub use error::{Error, Result};

// The types most users need, at the crate root (their modules hold the rest).
pub use bvh::{Bvh, InstancedBvh};
pub use geom::{Aabb, Hit, Ray};
pub use gpu::{Context, ContextOptions, External, Query, Tracer};
pub use lod::{Lod, LodParams, RayCone};
pub use rbvh::{Rbvh, RbvhParams};
pub use scene::{Camera, Instance, InstancedScene, Scene};
pub use structure::Structure;

// The crates whose types appear in the public API (`gpu::External` holds `ash` handles and a
// `gpu_allocator` allocator; rays and cameras take `glam` vectors), re-exported so that an engine
// uses the very versions this crate was built with: ash 0.38, gpu-allocator 0.28, glam 0.34.
pub use ash;
pub use glam;
pub use gpu_allocator;
