//! The benchmark harness behind `rbvh bench`: how fast each method traces, what it costs in
//! memory, and how wrong it is — measured together, on the same rays, in the same run.
//!
//! For every scene, the exact BVH and each RBVH quality level trace the same rays of each
//! [`RayType`]: camera rays, and ambient-occlusion, shadow and diffuse rays that all start at the
//! *exact* primary hits ([`crate::rays`]), so that every method answers identical questions. Each method
//! first traces once (warm-up), and those hits are compared with the exact BVH's
//! ([`metrics`]: hit/miss disagreement, hit-distance and normal errors, PSNR and FLIP) and judged
//! ([`validate`]): a method whose answers are wrong is flagged, loudly, rather than reported as
//! fast — the check tinybvh's speed test runs before timing each layout. Then all methods trace the
//! rays `runs` times, interleaved, so that machine noise hits all of them alike ([`harness`]).
//!
//! The result is a [`BenchReport`] ([`record`] documents its JSON and CSV schema), printed as a
//! [`table()`], and optionally charts and error images ([`plot`], [`error_image`]).
//!
//! ```no_run
//! use rbvh::bench::{self, BenchConfig, Device};
//! use rbvh::gpu::ContextOptions;
//! use rbvh::rbvh::RbvhParams;
//!
//! let mut config = BenchConfig::new(vec!["sphere".into()], Device::Create(ContextOptions::default()));
//! config.levels = vec![RbvhParams::quality(0)?, RbvhParams::quality(2)?];
//! let report = bench::run(&config)?;
//! print!("{}", bench::table(&report));
//! bench::write_json(std::path::Path::new("bench.json"), &report)?;
//! # Ok::<(), rbvh::Error>(())
//! ```

pub mod error_image;
pub mod harness;
pub mod markdown;
pub mod metrics;
pub mod plot;
pub mod provenance;
pub mod record;
pub mod seams;
pub mod shaders;
pub mod steps;
pub mod table;
pub mod traffic;
mod transcribed;
pub mod validate;

use std::path::PathBuf;

pub use crate::rays::RayType;
pub use harness::{run, run_keeping, run_observed, Event};
pub use record::{write_csv, write_json, BenchReport, Record, ShaderRecord};
pub use shaders::{shader_report, shader_report_table, write_shader_json, ShaderReport};
pub use table::{host_line, shader_table, steps_table, table, work_table};

use crate::gpu::Context;
#[cfg(feature = "loaded")]
use crate::gpu::ContextOptions;
use crate::lod::LodParams;
use crate::points::MIN_POINTS;
use crate::rbvh::{RbvhParams, TexelFormat};
use crate::scene::{Instances, PointSource};
use crate::{Error, Result};

/// Where the benchmark's Vulkan device comes from.
#[derive(Clone, Debug)]
pub enum Device {
    /// Trace on this context (tests pass theirs, created with validation).
    Existing(Context),
    /// Create a context with these options when the run starts.
    #[cfg(feature = "loaded")]
    Create(ContextOptions),
}

/// What to measure. [`BenchConfig::new`] gives the defaults of `rbvh bench`.
#[derive(Clone, Debug)]
pub struct BenchConfig {
    /// Scene specs for [`crate::scene::Scene::load`]: built-in names, OBJ/glTF files, scene files.
    pub scenes: Vec<String>,
    /// RBVH levels, each measured against the exact BVH (which is always measured) and named by
    /// [`RbvhParams::quality_name`] (a preset's name, or "custom"). Their `texels` field is not
    /// read: each level is built in every format of [`BenchConfig::texels`].
    pub levels: Vec<RbvhParams>,
    /// Ray types to measure, in this order; at least one, and primary when plotting.
    pub ray_types: Vec<RayType>,
    /// Primary-ray image width in pixels, 1..=16384; secondary rays start at its exact hits, one
    /// per hit pixel.
    pub width: u32,
    /// Primary-ray image height in pixels, 1..=16384.
    pub height: u32,
    /// Timed runs per method and ray type, after one warm-up.
    pub runs: u32,
    /// Shortest timed run, in milliseconds: a method whose trace of the rays takes less traces
    /// them this many times over back to back in each run (its time divided by the passes), so
    /// that a fast GPU is timed busy and over milliseconds, not over one pass of a fraction of a
    /// millisecond between idle gaps, where its clocks drop and timestamps resolve poorly (one
    /// H200 measured the same exact-BVH pass at 4,300 and 6,800 MRays/s in two invocations).
    /// 0: one pass per run.
    pub min_run_ms: f64,
    /// Length of ambient-occlusion rays as a fraction of the scene's bounding-box diagonal.
    pub ao_radius: f32,
    /// Seed of the secondary rays' random directions.
    pub seed: u64,
    /// The Vulkan device to trace on.
    pub device: Device,
    /// Write charts and error images under this directory, one subdirectory per scene.
    pub plot_dir: Option<PathBuf>,
    /// Measure every level traced without level of detail (method `rbvh`); the default. Off,
    /// only the levels with level of detail are measured (and no seam rays are aimed: they
    /// referee the plain levels).
    pub plain: bool,
    /// Also measure every level traced with level of detail, built with these parameters. Primary
    /// rays get their pixel's cone; secondary rays a cone from their origin with the pixel's
    /// spread (no width, so that the surface a ray leaves is never coarsened under it).
    pub lod: Option<LodParams>,
    /// Also trace every method's CPU twin and model its memory traffic (`bench::traffic`): bytes
    /// and cache lines per ray, the frame's working set, DRAM bytes per ray behind 4, 32 and
    /// 72 MiB caches. Costs a CPU trace per method and ray type.
    pub traffic: bool,
    /// Also trace the exact BVH's and every plain RBVH level's CPU twin to say where each ray's
    /// steps go ([`steps`]): nodes by depth, why leaves handed to the march gave no hit, leaf
    /// boxes at the hit. Costs a CPU trace per method and ray type. Flat structures only (the
    /// two-level ones and the levels of detail have no such twin), so not with
    /// [`Instances::TwoLevel`].
    pub steps: bool,
    /// Rays aimed at every plain RBVH level's seams between leaves ([`seams`]),
    /// traced by the CPU twins of it and of the exact BVH, for the level's leak count (0: none).
    pub seam_rays: usize,
    /// Texel formats to build every level in, each measured as its own RBVH (at least one; the
    /// default: height and normal only). A height-only level gets no level-of-detail record.
    pub texels: Vec<TexelFormat>,
    /// Block jumps in the RBVH march on or off; None: the tracer's choice for the device
    /// ([`crate::gpu::Tracer::block_jumps`]).
    pub block_jumps: Option<bool>,
    /// Build every RBVH level from points ([`crate::scene::Scene::add_points`]): sampled over
    /// each scene's triangles (seeded by `seed`), as from a scan of it, or a scan's file, while
    /// the exact BVH stays on the triangles: the referee of point-built RBVHs. None: RBVHs of the
    /// triangles.
    pub points: Option<PointSource>,
    /// How a scene with instances is measured ([`Instances`]): flat and in two levels (`Auto`,
    /// two levels alone where flattening would not fit in memory, flat alone with
    /// [`BenchConfig::points`]), flat alone, or in two levels alone (refereed by the two-level
    /// exact BVH).
    pub instances: Instances,
}

/// Longest timed run that may be asked for: ten seconds a run is already far past any need.
const MAX_MIN_RUN_MS: f64 = 10_000.0;

/// Largest image side accepted, as for `rbvh render`.
const MAX_SIDE: u32 = 16384;

impl BenchConfig {
    /// The defaults of `rbvh bench`: all five presets, all ray types, 256×256 (small enough to
    /// stay quick on lavapipe), 5 runs of at least 20 ms, AO rays 5% of the diagonal long.
    pub fn new(scenes: Vec<String>, device: Device) -> BenchConfig {
        BenchConfig {
            scenes,
            levels: RbvhParams::presets(),
            ray_types: RayType::ALL.to_vec(),
            width: 256,
            height: 256,
            runs: 5,
            min_run_ms: 20.0,
            ao_radius: 0.05,
            seed: 0x5EED_2012,
            device,
            plot_dir: None,
            plain: true,
            lod: None,
            traffic: false,
            steps: false,
            seam_rays: 100_000,
            texels: vec![TexelFormat::HeightNormal],
            block_jumps: None,
            points: None,
            instances: Instances::Auto,
        }
    }

    /// Checks every field; the error names the field and its allowed range.
    pub fn validate(&self) -> Result<()> {
        if self.scenes.is_empty() {
            return Err(Error::param("scenes", "no scene to benchmark"));
        }
        if self.ray_types.is_empty() {
            return Err(Error::param("rays", "no ray type to trace"));
        }
        if self.texels.is_empty() {
            return Err(Error::param("texels", "no texel format to build"));
        }
        for (name, side) in [("width", self.width), ("height", self.height)] {
            if !(1..=MAX_SIDE).contains(&side) {
                return Err(Error::param(
                    name,
                    format!("{side} is outside 1..={MAX_SIDE}"),
                ));
            }
        }
        if self.runs == 0 {
            return Err(Error::param("runs", "needs at least one timed run"));
        }
        if !(0.0..=MAX_MIN_RUN_MS).contains(&self.min_run_ms) {
            return Err(Error::param(
                "min_run_ms",
                format!("{} is outside 0..={MAX_MIN_RUN_MS} ms", self.min_run_ms),
            ));
        }
        if !(self.ao_radius.is_finite() && self.ao_radius > 0.0) {
            return Err(Error::param(
                "ao_radius",
                format!(
                    "{} is not a positive fraction of the diagonal",
                    self.ao_radius
                ),
            ));
        }
        for level in &self.levels {
            level.validate()?;
        }
        if !self.plain && self.lod.is_none() {
            return Err(Error::param(
                "plain",
                "neither the plain levels nor levels of detail: no RBVH to measure".to_string(),
            ));
        }
        if let Some(lod) = &self.lod {
            lod.validate()?;
        }
        if let Some(PointSource::Sampled(count)) = self.points {
            if count < MIN_POINTS {
                return Err(Error::param(
                    "points",
                    format!("{count} point(s) to sample: give at least {MIN_POINTS}"),
                ));
            }
        }
        if self.points.is_some() && self.levels.iter().any(|p| p.view_rate > 0.0) {
            return Err(Error::param(
                "view_rate",
                "the view refines triangles, and the RBVHs are built from points".to_string(),
            ));
        }
        if self.instances == Instances::TwoLevel {
            if self.points.is_some() {
                return Err(Error::param(
                    "points",
                    "an RBVH of points is built over the flat scene: not with instances in two \
                     levels alone"
                        .to_string(),
                ));
            }
            if self.lod.is_some() {
                return Err(Error::param(
                    "lod",
                    "levels of detail are built over a flat RBVH: in two levels alone, measure \
                     the plain levels"
                        .to_string(),
                ));
            }
            if self.steps {
                return Err(Error::param(
                    "steps",
                    "where steps go is counted by the flat structures' CPU twins: not with \
                     instances in two levels alone"
                        .to_string(),
                ));
            }
            if self.levels.iter().any(|p| p.view_rate > 0.0) {
                return Err(Error::param(
                    "view_rate",
                    "an RBVH refined for one view is built over the flat scene: not with \
                     instances in two levels alone"
                        .to_string(),
                ));
            }
        }
        if self.plot_dir.is_some() && !self.ray_types.contains(&RayType::Primary) {
            return Err(Error::param(
                "plot",
                "charts and error images are made from primary rays: add the primary ray type",
            ));
        }
        Ok(())
    }
}
