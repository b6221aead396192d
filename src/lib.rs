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
//! scene (load / built-in / camera) → bvh (exact build, GPU layout, CPU reference tracer)
//!        → gpu (Vulkan context, uploads, pipelines, tracer) → output (shading, PNG, EXR)
//! ```
//!
//! ```no_run
//! use rbvh::{bvh::Bvh, gpu::{Context, ContextOptions, Tracer}, scene::Scene};
//!
//! let scene = Scene::load("sphere")?;
//! let bvh = Bvh::build(&scene)?;
//! let ctx = Context::new(&ContextOptions::default())?;
//! let tracer = Tracer::exact(&ctx, &bvh)?;
//! let camera = scene.camera_or_framed(1.0);
//! let rays = camera.primary_rays(64, 64);
//! let traced = tracer.trace(&rays, rbvh::gpu::Query::Closest)?;
//! assert_eq!(traced.hits.len(), 64 * 64);
//! # Ok::<(), rbvh::Error>(())
//! ```

pub mod bench;
pub mod bvh;
pub mod error;
pub mod geom;
pub mod gpu;
pub mod io;
pub mod output;
pub mod rbvh;
pub mod scene;

pub use error::{Error, Result};
