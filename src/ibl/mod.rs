//! Image-based lighting: Lambertian surfaces lit by an environment — an HDR latitude–longitude
//! map or an analytic sky — with every light sample's visibility traced through the exact BVH or
//! an RBVH. The paper names image-based lighting as one of the applications where an RBVH's
//! approximate, compact visibility pays off (Novák & Dachsbacher, "Rasterized Bounding Volume
//! Hierarchies", Computer Graphics Forum 31(2), Eurographics 2012).
//!
//! * [`environment`]: where the light comes from;
//! * [`sampling`]: reproducible cosine-distributed directions;
//! * [`mod@render`]: the progressive integrator over sample passes.
//!
//! ```no_run
//! use glam::Vec3;
//! use rbvh::bvh::Bvh;
//! use rbvh::gpu::{Context, ContextOptions, Query, Tracer};
//! use rbvh::ibl::{self, Environment, Frame, Settings, Sky};
//! use rbvh::structure::Structure;
//! use rbvh::scene::Scene;
//!
//! let scene = Scene::load("default")?;
//! let (width, height) = (64, 48);
//! let rays = scene.camera_or_framed(width as f32 / height as f32).primary_rays(width, height);
//! let ctx = Context::new(&ContextOptions::default())?;
//! let tracer = Tracer::new(&ctx, &Structure::from(Bvh::build(&scene)?))?;
//! let hits = tracer.trace(&rays, Query::Closest)?.hits;
//! let albedo = vec![Vec3::splat(ibl::GREY); rays.len()];
//! let frame = Frame { width, height, rays: &rays, hits: &hits, albedo: &albedo, offsets: None };
//! let settings = Settings { samples: 16, seed: 1, diagonal: scene.bounds().diagonal(), surface_offset: 0.0, cone: None };
//! let rendered = ibl::render(&tracer, &frame, &Environment::Sky(Sky::default()), &settings, |_| {})?;
//! assert_eq!(rendered.image.pixels.len(), rays.len());
//! # Ok::<(), rbvh::Error>(())
//! ```

pub mod environment;
pub mod render;
pub mod sampling;

pub use environment::{Environment, LatLongMap, Sky};
pub use render::{render, render_side_by_side, Frame, Pass, Rendered, Settings, MAX_SAMPLES};

/// The albedo of surfaces without a base colour: the neutral grey of the preview shading.
pub const GREY: f32 = 0.8;
