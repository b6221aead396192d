//! The run loop. Per scene: build the exact BVH and every RBVH level and upload them all; trace
//! the primary rays through the exact BVH once, to place the secondary rays; then per ray type:
//!
//! 1. **warm-up and validation** — every method traces the rays once; those hits are compared
//!    with the exact BVH's ([`metrics`]) and judged ([`validate`]). The exact BVH itself is judged
//!    against the CPU reference tracer ([`Bvh::trace_cpu`]), so a broken referee is caught too;
//! 2. **timing** — `runs` rounds, each tracing with every method in turn (A B C A B C …), so that
//!    a slow spell of the machine lands on all methods alike instead of on whichever ran then.
//!    A method whose warm-up trace was shorter than [`BenchConfig::min_run_ms`] traces the rays
//!    several times back to back in each run, so that a fast GPU is timed busy.
//!
//! 3. **counting** — every method traces once more through its counting pipeline
//!    ([`crate::probe::RayCounters`]: untimed, so that timed runs compile the counting away);
//! 4. **memory traffic** (with [`BenchConfig::traffic`]) — the CPU twins trace the rays again in
//!    screen-tile order, reporting every read of the structure's device arrays to the cache model
//!    of [`traffic`], and counting as the device does (the two must agree).
//! 5. **where the steps go** (with [`BenchConfig::steps`]) — the CPU twins of the exact BVH and
//!    of each plain RBVH level trace the rays again, and [`steps`] accounts for their nodes by
//!    depth and for every leaf handed to the march.
//!
//! Throughput is `rays / time` per run, from GPU timestamps around the trace dispatches (uploads
//! and read-back excluded). When a device cannot time, every method of that ray type falls back to
//! host wall time (submit to fence) together, so that speedups always compare like with like.

use std::collections::HashSet;
use std::path::PathBuf;

use rayon::prelude::*;

use super::error_image::error_image;
use super::metrics::{self, HitErrors, Summary};
use super::plot;
use super::provenance::{self, Provenance};
use super::record::{
    BenchReport, Errors, Params, Record, SeamRecord, ShaderRecord, Spread, TimingSource,
    TrafficRecord,
};
use super::seams::closed_triangles;
use super::steps;
use super::traffic::{self, TrafficModel, CACHE_SIZES, DRAM_LINE};
use super::validate;
use super::{BenchConfig, Device};
use crate::bvh::{Bvh, InstancedBvh, LEAF_BIT};
use crate::geom::Aabb;
use crate::geom::{Hit, Ray};
use crate::gpu::{Context, Query, Timing, Traced, Tracer};
use crate::lod::{Cones, Lod, RayCone};
use crate::output::{self, Image};
use crate::probe::{Array, MeanCounters, Read, TraceStats};
use crate::progress::{Progress, Quiet};
use crate::rays::{self, RayType, Secondary, DEFAULT_LIGHT};
use crate::rbvh::{InstancedRbvh, Rbvh, RbvhParams, RbvhSource, TexelFormat};
use crate::scene::{InstancedScene, Instances, Scene, SceneView};
use crate::structure::{Kind, Recipe, Structure};
use crate::{Error, Result};

/// What the run tells its caller while it works.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Event {
    /// What it is doing now (for a progress display).
    Progress(String),
    /// Something the user must see: above all a method flagged invalid, as soon as it is found.
    Warning(String),
}

/// Runs the benchmark `config` describes.
pub fn run(config: &BenchConfig) -> Result<BenchReport> {
    run_observed(config, &mut |_| {}, &Quiet)
}

/// [`run`], reporting what it is doing and warnings to `observe` as they happen (each
/// measurement's messages prefixed `[k/n]`), and the counted steps of loading and building to
/// `progress`.
pub fn run_observed(
    config: &BenchConfig,
    observe: &mut dyn FnMut(Event),
    progress: &dyn Progress,
) -> Result<BenchReport> {
    match run_keeping(config, observe, progress)? {
        (report, None) => Ok(report),
        (_, Some(error)) => Err(error),
    }
}

/// [`run_observed`], keeping what a run measured before an error stopped it: the report of the
/// scenes measured whole (their records, shaders and plots), and the error, None where the run
/// reached its end. A scene's load or a device's failure late in a long run then loses neither
/// the scenes measured before it, which the caller can still write, nor the error (the run
/// stops there: the scenes after it are not measured). An error before any scene is measured
/// (the configuration, a scene that is not there, the device) is returned alone.
pub fn run_keeping(
    config: &BenchConfig,
    observe: &mut dyn FnMut(Event),
    progress: &dyn Progress,
) -> Result<(BenchReport, Option<Error>)> {
    config.validate()?;
    // Every scene before any work: a mistyped last scene must not cost the others' run.
    for spec in &config.scenes {
        Scene::check(spec)?;
    }
    let date = provenance::utc_now();
    let ctx = match &config.device {
        Device::Existing(ctx) => ctx.clone(),
        #[cfg(feature = "loaded")]
        Device::Create(options) => {
            observe(Event::Progress("creating the Vulkan device".into()));
            Context::new(options)?
        }
    };
    let mut report = BenchReport {
        provenance: Provenance {
            date,
            ..Provenance::of(&ctx)
        },
        runs: config.runs,
        min_run_ms: config.min_run_ms,
        width: config.width,
        height: config.height,
        ao_radius: config.ao_radius,
        seed: config.seed,
        results: Vec::new(),
        shaders: Vec::new(),
        written: Vec::new(),
    };
    let mut plot_dirs = HashSet::new();
    let mut measurement = 0;
    for spec in &config.scenes {
        if let Err(error) = measure_scene(
            &ctx,
            config,
            spec,
            &mut report,
            (&mut measurement, &mut plot_dirs),
            observe,
            progress,
        ) {
            return match report.results.is_empty() {
                true => Err(error),
                false => Ok((report, Some(error))),
            };
        }
    }
    Ok((report, None))
}

/// Measures scene `spec` as `config` asks, its records, shaders and plots added to `report`
/// once it is measured whole; `numbering` counts the measurements made and the plots' folders.
fn measure_scene(
    ctx: &Context,
    config: &BenchConfig,
    spec: &str,
    report: &mut BenchReport,
    numbering: (&mut usize, &mut HashSet<String>),
    observe: &mut dyn FnMut(Event),
    progress: &dyn Progress,
) -> Result<()> {
    let (measurement, plot_dirs) = numbering;
    let measurements = config.scenes.len() * config.ray_types.len();
    let placed = {
        observe(Event::Progress(format!("{spec}: loading")));
        InstancedScene::load_observed(spec, progress)?
    };
    // A scene with instances is measured flat and in two levels: its meshes are kept (held
    // once, a fraction of the flat scene) for the two-level builds. One too large to
    // flatten is measured in two levels alone, refereed by its two-level exact BVH, as
    // every scene is when asked for two levels alone.
    let two_level = match config.instances {
        Instances::Flat => None,
        Instances::TwoLevel => Some(placed.clone()),
        // An RBVH of points is built over the flat scene: no two-level candidate.
        Instances::Auto => {
            (placed.instances.len() > 1 && config.points.is_none()).then(|| placed.clone())
        }
    };
    let fits = match config.instances {
        Instances::TwoLevel => None,
        _ => Some(placed.check_flat_fits(provenance::available_memory())),
    };
    let flat = match fits {
        Some(Ok(())) => Some(flat_scene(placed, config, spec, observe)?),
        Some(Err(too_large)) if two_level.is_none() || config.points.is_some() => {
            return Err(too_large)
        }
        Some(Err(too_large)) => {
            let steps = match config.steps {
                true => " (no steps: they are counted for flat structures)",
                false => "",
            };
            observe(Event::Warning(format!(
                "{too_large}; measured in two levels alone, refereed by the two-level exact \
                 BVH{steps}"
            )));
            None
        }
        None => None,
    };
    let mut bench = SceneBench::new(ctx, config, flat, two_level, observe, progress)?;
    for &ray_type in &config.ray_types {
        *measurement += 1;
        let mut numbered = |event| {
            observe(match event {
                Event::Progress(what) => {
                    Event::Progress(format!("[{measurement}/{measurements}] {what}"))
                }
                warning => warning,
            })
        };
        bench.measure(ray_type, &mut numbered)?;
    }
    if let Some(dir) = &config.plot_dir {
        let dir = dir.join(plot::scene_dir_name(bench.view().name(), plot_dirs));
        report.written.extend(bench.write_plots(dir)?);
    }
    // Only now, so that a scene stopped by an error adds no shader without a record.
    for c in &bench.candidates {
        let compiled = c.tracer.compiled();
        if !report
            .shaders
            .iter()
            .any(|s| s.compiled.pipeline == compiled.pipeline)
        {
            report.shaders.push(ShaderRecord {
                method: c.method(),
                compiled,
            });
        }
    }
    report.results.extend(bench.records);
    Ok(())
}

/// `placed` flattened (known to fit in memory) and checked, with `config`'s points added: the
/// scene its flat structures are built from. A point cloud without triangles is refused, since
/// the exact BVH of triangles referees every RBVH.
fn flat_scene(
    placed: InstancedScene,
    config: &BenchConfig,
    spec: &str,
    observe: &mut dyn FnMut(Event),
) -> Result<Scene> {
    let mut scene = placed.into_flat();
    scene.validate()?;
    if scene.triangle_count() == 0 && scene.points.is_some() {
        return Err(Error::param(
            "scenes",
            format!(
                "{} is a point cloud: the bench referees RBVHs against the exact BVH of \
                 triangles, so give the mesh as the scene and the scan as its points \
                 (rbvh bench --scene MESH --points SCAN)",
                scene.name
            ),
        ));
    }
    if let Some(source) = &config.points {
        let label = source.label();
        observe(Event::Progress(format!("{spec}: {label}")));
        scene.add_points(source, config.seed)?;
        // Every row says that its RBVHs are of points, not of the triangles.
        scene.name = format!("{} ({label})", scene.name);
    }
    Ok(scene)
}

/// A structure under test, uploaded. Its host copy is what its CPU twin traces.
struct Candidate {
    structure: Structure,
    /// The RBVH's parameters (its level); None for the exact BVH.
    params: Option<RbvhParams>,
    tracer: Tracer,
    /// Leaks through the seams (plain RBVHs, when asked for).
    seams: Option<SeamRecord>,
    /// For a two-level structure, per instance the index of its first triangle in the flat
    /// scene: its hits name their mesh's triangle and instance, and are compared as the flat
    /// scene's triangle.
    flat_ids: Option<Vec<u32>>,
}

/// Ray `k` of a batch traced by a CPU twin, its reads pushed to the vector.
type TwinTrace<'a> = Box<dyn Fn(usize, &mut Vec<Read>) -> TraceStats + Sync + 'a>;

impl Candidate {
    /// Which structure it is.
    fn method(&self) -> Kind {
        self.structure.kind()
    }

    /// "exact", "rbvh Q2", "rbvh custom": for messages.
    fn label(&self) -> String {
        match &self.params {
            None => self.method().name().into(),
            Some(params) => format!("{} {}", self.method().name(), params.level_label()),
        }
    }

    /// "exact", "exact-instanced", "q2", "q2h" (height-only), "q2_lod", "q2_instanced",
    /// "custom": for file names.
    fn file_stem(&self) -> String {
        match &self.params {
            None => self.method().name().into(),
            Some(params) if self.method() == Kind::RbvhLod => {
                format!("{}_lod", params.level_label().to_ascii_lowercase())
            }
            Some(params) if self.method() == Kind::RbvhInstanced => {
                format!("{}_instanced", params.level_label().to_ascii_lowercase())
            }
            Some(params) => params.level_label().to_ascii_lowercase(),
        }
    }

    /// Traces `rays` with their footprints (read by a level-of-detail candidate); `counters`
    /// through the counting pipeline.
    fn trace(&self, rays: &[Ray], cones: Cones, query: Query, counters: bool) -> Result<Traced> {
        let mut traced = self.tracer.trace_with(rays, cones, query, counters)?;
        if let Some(bases) = &self.flat_ids {
            // A triangle's id is its mesh's; a height field's (LEAF_BIT set) names no triangle.
            for hit in traced
                .hits
                .iter_mut()
                .filter(|h| h.is_hit() && h.id & LEAF_BIT == 0)
            {
                let base = bases.get(hit.instance as usize).copied().unwrap_or(0);
                hit.id = base.saturating_add(hit.id);
            }
        }
        Ok(traced)
    }

    /// Traces `rays` `passes` times back to back, for timing ([`Tracer::trace_repeated`]).
    fn trace_timed(&self, rays: &[Ray], cones: Cones, query: Query, passes: u32) -> Result<Traced> {
        self.tracer.trace_repeated(rays, cones, query, passes)
    }
}

/// One scene's structures, rays and records.
struct SceneBench<'a> {
    config: &'a BenchConfig,
    /// The scene flattened; none for one too large to flatten, measured in two levels alone.
    flat: Option<Scene>,
    /// The scene's meshes and instances, for its two-level candidates; none for a scene without
    /// instances.
    placed: Option<InstancedScene>,
    diagonal: f32,
    /// Per object, its box: what `t_err_object` measures against.
    objects: ObjectBoxes,
    /// The exact BVH first: its host copy is also the CPU reference tracer that referees its
    /// GPU hits.
    candidates: Vec<Candidate>,
    primary: Vec<Ray>,
    /// The cone of every primary ray (its pixel's), for level-of-detail candidates.
    pixel_cone: RayCone,
    exact_primary: Vec<Hit>,
    secondary: Secondary,
    /// Per candidate, the shaded primary image and primary hits, once primary rays are traced.
    renders: Option<Vec<(Image, Vec<Hit>)>>,
    records: Vec<Record>,
}

/// Rays, hits and times of one ray type.
struct Measured {
    rays: Vec<Ray>,
    query: Query,
    /// Per candidate, the warm-up's hits.
    hits: Vec<Vec<Hit>>,
    /// Per candidate, milliseconds per pass of each timed run.
    ms: Vec<Vec<f64>>,
    /// Per candidate, trace passes per timed run.
    passes: Vec<u32>,
    source: TimingSource,
}

impl<'a> SceneBench<'a> {
    /// Builds and uploads every structure and traces the exact primary hits. `two_level`, for a
    /// scene with instances (`scene` is it flattened), is measured beside the flat structures in
    /// two levels too: the exact BVH as method `exact-instanced`, each RBVH as `rbvh-instanced`
    /// at the same parameters.
    fn new(
        ctx: &Context,
        config: &'a BenchConfig,
        flat: Option<Scene>,
        two_level: Option<InstancedScene>,
        observe: &mut dyn FnMut(Event),
        progress: &dyn Progress,
    ) -> Result<SceneBench<'a>> {
        let view = match (&flat, &two_level) {
            (Some(scene), _) => SceneView::Flat(scene),
            (None, Some(placed)) => SceneView::Instanced(placed),
            (None, None) => return Err(Error::param("scene", "no scene to measure".to_string())),
        };
        let name = view.name();
        let diagonal = view.bounds().diagonal();
        if view.triangle_count() == 0 || !(diagonal.is_finite() && diagonal > 0.0) {
            return Err(Error::param(
                "scene",
                format!(
                    "{name}: {} triangles and a bounding-box diagonal of {diagonal}; errors are \
                     measured relative to the diagonal, so it needs an extent",
                    view.triangle_count()
                ),
            ));
        }
        if config.levels.iter().any(|p| p.view_rate > 0.0) {
            // Refused rather than measured as the presets under a name that says refined.
            let why = match &flat {
                None => Some("is measured in two levels alone, which a view cannot refine"),
                Some(scene) if scene.camera.is_none() => Some("has no camera to refine for"),
                Some(scene) if scene.points.is_some() => {
                    Some("is a point cloud, and the view refines triangles")
                }
                Some(_) => None,
            };
            if let Some(why) = why {
                return Err(Error::param("view_rate", format!("{name} {why}")));
            }
        }
        if let Some(warning) = flat.as_ref().and_then(Scene::precision_warning) {
            observe(Event::Warning(warning));
        }
        if flat.is_none() && config.lod.is_some() {
            observe(Event::Warning(format!(
                "{name}: levels of detail are built over a flat RBVH; measured in two levels \
                 alone, no rbvh-lod level is measured"
            )));
        }
        // The referee first: the flat exact BVH, or the two-level one of a scene measured in
        // two levels alone. A two-level candidate's triangle hits are renamed as the flat
        // scene's where the referee is flat.
        let flat_ids = two_level
            .as_ref()
            .filter(|_| flat.is_some())
            .map(InstancedScene::flat_bases);
        let mut candidates = Vec::new();
        if let Some(scene) = &flat {
            observe(Event::Progress(format!("{name}: building the exact BVH")));
            let structure = Structure::build_observed(scene, &Recipe::Exact, progress)?;
            candidates.push(Candidate {
                tracer: Tracer::new_observed(ctx, &structure, progress)?,
                structure,
                params: None,
                seams: None,
                flat_ids: None,
            });
        }
        if let Some(placed) = &two_level {
            observe(Event::Progress(format!(
                "{name}: building the two-level exact BVH"
            )));
            let structure = Structure::from(InstancedBvh::build(placed)?);
            candidates.push(Candidate {
                tracer: Tracer::new_observed(ctx, &structure, progress)?,
                structure,
                params: None,
                seams: None,
                flat_ids: flat_ids.clone(),
            });
        }
        // Secondary rays leave the exact surface by at least the coarsest RBVH's texel: an RBVH
        // surface may lie up to a fraction of a texel off the exact one, and a ray starting
        // closer would meet its own surface. One offset for all, so all trace identical rays.
        let mut surface_offset = 0.0f32;
        let builds: Vec<_> = config
            .levels
            .iter()
            .flat_map(|level| config.texels.iter().map(move |&texels| (level, texels)))
            .collect();
        let last_build = builds.len().saturating_sub(1);
        // What every level shares (the scene's parts, the BVH its rings are sampled by) is made
        // once, at the first level, and dropped after the last level is built.
        let mut shared: Option<RbvhSource> = None;
        // Which triangles lie on closed objects, for the seam rays' referee: found at the first
        // level that counts leaks.
        let mut closed: Option<Vec<bool>> = None;
        for (k, (level, texels)) in builds.into_iter().enumerate() {
            let params = RbvhParams { texels, ..*level };
            let mut flat_levels = Vec::new();
            if let Some(scene) = &flat {
                observe(Event::Progress(format!(
                    "{name}: building RBVH {}",
                    params.level_label()
                )));
                let source = match shared.take() {
                    Some(source) => source,
                    None => RbvhSource::new(scene)?,
                };
                let structure = Structure::build_from(&source, &Recipe::Rbvh(params), progress)?;
                if k < last_build {
                    shared = Some(source);
                }
                let rbvh = structure.rbvh().expect("an RBVH recipe builds an RBVH");
                surface_offset = surface_offset.max(rbvh.texel_size);
                let exact = candidates[0]
                    .structure
                    .bvh()
                    .filter(|_| config.plain && config.seam_rays > 0);
                let seams = exact.and_then(|exact| {
                    observe(Event::Progress(format!(
                        "{name}: {} rays at the seams of RBVH {}",
                        config.seam_rays,
                        params.level_label()
                    )));
                    let closed = closed.get_or_insert_with(|| closed_triangles(scene));
                    seam_leaks(exact, closed, rbvh, config.seam_rays, config.seed)
                });
                let lod = match config.lod.filter(|_| texels == TexelFormat::HeightNormal) {
                    Some(lod_params) => {
                        observe(Event::Progress(format!(
                            "{name}: building levels of detail of {}",
                            params.quality_name()
                        )));
                        Some(structure.with_levels(&lod_params)?)
                    }
                    None => None,
                };
                flat_levels.extend(config.plain.then_some((structure, seams)));
                flat_levels.extend(lod.map(|l| (l, None)));
            }
            let instanced = match &two_level {
                // A level refined for the view is measured flat: a two-level RBVH builds each
                // mesh once for every place it stands.
                Some(placed) if config.plain && params.view_rate == 0.0 => {
                    observe(Event::Progress(format!(
                        "{name}: building the two-level RBVH {}",
                        params.level_label()
                    )));
                    let two = InstancedRbvh::build_observed(placed, &params, progress)?;
                    surface_offset = surface_offset.max(two.texel_size());
                    let seams = match config.seam_rays {
                        0 => None,
                        count => {
                            observe(Event::Progress(format!(
                                "{name}: {count} rays at the seams of the two-level RBVH {}",
                                params.level_label()
                            )));
                            instanced_seam_leaks(placed, &two, &params, count, config.seed)?
                        }
                    };
                    Some((Structure::from(two), seams))
                }
                _ => None,
            };
            for (structure, seams) in flat_levels.into_iter().chain(instanced) {
                let flat_ids = match structure.kind() {
                    Kind::RbvhInstanced => flat_ids.clone(),
                    _ => None,
                };
                candidates.push(Candidate {
                    tracer: with_jumps(
                        Tracer::new_observed(ctx, &structure, progress)?,
                        config.block_jumps,
                    )?,
                    structure,
                    params: Some(params),
                    seams,
                    flat_ids,
                });
            }
        }
        let (width, height) = (config.width, config.height);
        let camera = view.camera_or_framed(width as f32 / height as f32);
        let primary = camera.primary_rays(width, height);
        let pixel_cone = RayCone::pixel(&camera, height);
        let exact_primary = candidates[0].tracer.trace(&primary, Query::Closest)?.hits;
        let secondary = Secondary {
            diagonal,
            surface_offset,
            light: view.light().copied().unwrap_or(DEFAULT_LIGHT),
            ao_radius: config.ao_radius,
            seed: config.seed,
        };
        let objects = match (&flat, &two_level) {
            (Some(scene), _) => ObjectBoxes::Flat(scene.object_bounds()),
            (None, placed) => ObjectBoxes::Placed(
                placed
                    .as_ref()
                    .map(InstancedScene::placed_object_bounds)
                    .unwrap_or_default(),
            ),
        };
        Ok(SceneBench {
            config,
            objects,
            flat,
            placed: two_level,
            diagonal,
            candidates,
            primary,
            pixel_cone,
            exact_primary,
            secondary,
            renders: None,
            records: Vec::new(),
        })
    }

    /// The scene measured: flat, or in instances where it is measured in two levels alone.
    fn view(&self) -> SceneView<'_> {
        match (&self.flat, &self.placed) {
            (Some(scene), _) => SceneView::Flat(scene),
            (None, Some(placed)) => SceneView::Instanced(placed),
            (None, None) => unreachable!("SceneBench::new refuses a bench without a scene"),
        }
    }

    /// Measures every candidate on the rays of `ray_type` and appends their records.
    fn measure(&mut self, ray_type: RayType, observe: &mut dyn FnMut(Event)) -> Result<()> {
        let name = self.view().name().to_string();
        let rays = rays::generate(
            ray_type,
            &self.primary,
            &self.exact_primary,
            &self.secondary,
        );
        if rays.is_empty() {
            observe(Event::Warning(format!(
                "{name}: no primary ray hits the scene, so there are no {} rays; skipped",
                ray_type.name()
            )));
            return Ok(());
        }
        observe(Event::Progress(format!(
            "{name}: {} rays × {} methods × (1 + {} runs)",
            ray_type.name(),
            self.candidates.len(),
            self.config.runs
        )));
        let cone = match ray_type {
            RayType::Primary => self.pixel_cone,
            _ => RayCone {
                width: 0.0,
                spread: self.pixel_cone.spread,
            },
        };
        let cones = Cones::Same(cone);
        let m = self.trace_all(rays, cones, ray_type.query())?;
        if m.source == TimingSource::Wall {
            observe(Event::Warning(format!(
                "{name}, {} rays: the device has no timestamp queries; timing with host wall time \
                 (submit to fence), which includes submission overhead",
                ray_type.name()
            )));
        }
        if ray_type == RayType::Primary {
            let renders = m
                .hits
                .iter()
                .map(|hits| {
                    let image = output::shade(
                        &self.primary,
                        hits,
                        self.config.width,
                        self.config.height,
                        self.view().light(),
                    )?;
                    Ok((image, hits.clone()))
                })
                .collect::<Result<Vec<_>>>()?;
            self.renders = Some(renders);
        }
        let rays_per_run = m.rays.len() as f64;
        let speeds: Vec<Spread> =
            m.ms.iter()
                .map(|runs| {
                    let mrays: Vec<f64> = runs.iter().map(|ms| rays_per_run / (ms * 1e3)).collect();
                    Spread::of(&mrays)
                })
                .collect();
        let exact_cpu =
            self.candidates[0]
                .structure
                .trace_cpu(&m.rays, Cones::None, m.query == Query::Any)?;
        // The pixel each ray belongs to (secondary rays: one per exact primary hit, in order), for
        // the traffic model's screen tiles.
        let pixels: Vec<u32> = if ray_type == RayType::Primary {
            (0..m.rays.len() as u32).collect()
        } else {
            (0..self.exact_primary.len() as u32)
                .filter(|&p| self.exact_primary[p as usize].is_hit())
                .collect()
        };
        let mut counted = Vec::with_capacity(self.candidates.len());
        for c in &self.candidates {
            observe(Event::Progress(format!(
                "{name}: {} rays, counting the work of {}{}",
                ray_type.name(),
                c.label(),
                match (self.config.traffic, self.config.steps) {
                    (true, true) => " and modelling its memory traffic and steps",
                    (true, false) => " and modelling its memory traffic",
                    (false, true) => " and where its steps go",
                    (false, false) => "",
                }
            )));
            let traced = c.trace(&m.rays, cones, m.query, true)?;
            let any = m.query == Query::Any;
            let device = traced.counters.unwrap_or_default();
            let traffic = if self.config.traffic {
                Some(self.traffic(c, &m, cone, &pixels, &device)?)
            } else {
                None
            };
            let steps = match &c.structure {
                _ if !self.config.steps => None,
                Structure::Exact(b) => Some(steps::exact_steps(b, &m.rays, any)),
                Structure::Rbvh(r) => {
                    Some(steps::rbvh_steps(r, &m.rays, any, c.tracer.block_jumps()))
                }
                Structure::RbvhLod(..)
                | Structure::ExactInstanced(_)
                | Structure::RbvhInstanced(_) => None,
            };
            counted.push((MeanCounters::of(&device), traffic, steps));
        }
        for (i, c) in self.candidates.iter().enumerate() {
            let (errors, invalid) = if i == 0 {
                let referee = self.hit_errors(&m, &exact_cpu, &m.hits[0])?;
                (None, validate::invalid_reason_exact(&referee))
            } else {
                let errors = self.hit_errors(&m, &m.hits[0], &m.hits[i])?;
                let image = match (ray_type, &self.renders) {
                    (RayType::Primary, Some(renders)) => {
                        Some(metrics::image_errors(&renders[0].0, &renders[i].0)?)
                    }
                    _ => None,
                };
                let invalid = match c.structure {
                    Structure::ExactInstanced(_) => validate::invalid_reason_exact(&errors),
                    _ => validate::invalid_reason(&errors),
                };
                let summary = |s: Option<Summary>, f: fn(&Summary) -> f64| s.as_ref().map(f);
                let record = Errors {
                    miss_mismatch_rate: errors.miss_mismatch_rate,
                    t_err_mean: summary(errors.t_err, |s| s.mean),
                    t_err_p99: summary(errors.t_err, |s| s.p99),
                    t_err_max: summary(errors.t_err, |s| s.max),
                    t_err_object_mean: summary(errors.t_err_object, |s| s.mean),
                    t_err_object_p99: summary(errors.t_err_object, |s| s.p99),
                    normal_err_deg_mean: summary(errors.normal_err_deg, |s| s.mean),
                    normal_err_deg_p99: summary(errors.normal_err_deg, |s| s.p99),
                    back_facing_rate: (m.query == Query::Closest)
                        .then_some(errors.back_facing_rate),
                    psnr_db: image.map(|e| e.psnr_db),
                    flip_mean: image.map(|e| e.flip_mean),
                };
                (Some(record), invalid)
            };
            if let Some(reason) = &invalid {
                let referee = if i == 0 {
                    "the CPU reference tracer".to_string()
                } else {
                    format!("the {}", self.candidates[0].structure.label())
                };
                observe(Event::Warning(format!(
                    "INVALID: {} on {name}, {} rays, against {referee}: {reason}. Wrong here, not \
                     fast: do not compare its speed.",
                    c.label(),
                    ray_type.name()
                )));
            }
            let exact = &self.candidates[0];
            self.records.push(Record {
                scene: name.clone(),
                triangles: self.view().triangle_count() as u64,
                points: self.view().point_count() as u64,
                method: c.method(),
                quality: c.params.map(|params| params.quality_name().to_string()),
                params: c.params.map(|params| Params::from(&params)),
                lod: (c.method() == Kind::RbvhLod)
                    .then_some(self.config.lod)
                    .flatten(),
                ray_type,
                rays: m.rays.len() as u64,
                mrays_per_s: speeds[i].clone(),
                speedup_vs_exact: speeds[i].median / speeds[0].median,
                build_ms: c.structure.build_ms(),
                memory_bytes: c.structure.memory(),
                memory_ratio_vs_exact: exact.structure.memory().total as f64
                    / c.structure.memory().total.max(1) as f64,
                error: errors,
                valid: invalid.is_none(),
                invalid_reason: invalid,
                timing_source: m.source,
                passes: m.passes[i],
                block_jumps: (!c.method().is_exact()).then(|| c.tracer.block_jumps()),
                counters: counted[i].0,
                traffic: counted[i].1.clone(),
                steps: counted[i].2,
                seams: c.seams,
            });
        }
        Ok(())
    }

    /// The CPU twin of candidate `c` on `m`'s rays: its counters, checked against the device's
    /// (`device`, per ray), and the memory traffic of its reads with the rays taken in 8 × 8
    /// screen tiles of `pixels` (each ray's pixel); every ray's footprint is `cone`.
    fn traffic(
        &self,
        c: &Candidate,
        m: &Measured,
        cone: RayCone,
        pixels: &[u32],
        device: &[crate::probe::RayCounters],
    ) -> Result<TrafficRecord> {
        let any = m.query == Query::Any;
        let (plain_twin, lod_twin);
        let rbvh_arrays = |r: &Rbvh, lod: Option<&Lod>| {
            let lod_bytes = lod.map_or([0, 0], |l| {
                [
                    std::mem::size_of_val(l.nodes.as_slice()) as u64,
                    std::mem::size_of_val(l.texels.as_slice()) as u64,
                ]
            });
            [
                std::mem::size_of_val(r.nodes.as_slice()) as u64,
                r.triangle_bytes(),
                std::mem::size_of_val(r.heightfields.as_slice()) as u64,
                r.atlas_bytes(),
                lod_bytes[0],
                lod_bytes[1],
                0,
            ]
        };
        let (arrays, trace): ([u64; Array::COUNT], TwinTrace) = match &c.structure {
            Structure::Exact(b) => (
                [b.tree_bytes(), b.triangle_bytes(), 0, 0, 0, 0, 0],
                Box::new(move |k, reads| b.trace_probed(&m.rays[k], any, reads).1),
            ),
            Structure::ExactInstanced(b) => (
                [
                    b.tree_bytes(),
                    b.triangle_bytes(),
                    0,
                    0,
                    0,
                    0,
                    b.instance_bytes(),
                ],
                Box::new(move |k, reads| b.trace_probed(&m.rays[k], any, reads).1),
            ),
            Structure::Rbvh(r) => {
                plain_twin = r.device_twin().with_block_jumps(c.tracer.block_jumps());
                let twin = &plain_twin;
                (
                    rbvh_arrays(r, None),
                    Box::new(move |k, reads| twin.trace(&m.rays[k], any, reads).1),
                )
            }
            Structure::RbvhInstanced(two) => {
                plain_twin = two.device_twin().with_block_jumps(c.tracer.block_jumps());
                let twin = &plain_twin;
                let mut arrays = rbvh_arrays(two.parts(), None);
                arrays[Array::Instances as usize] = two.instance_bytes();
                (
                    arrays,
                    Box::new(move |k, reads| twin.trace(&m.rays[k], any, reads).1),
                )
            }
            Structure::RbvhLod(r, lod) => {
                lod_twin = lod.device_twin(r)?.with_block_jumps(c.tracer.block_jumps());
                let twin = &lod_twin;
                (
                    rbvh_arrays(r, Some(lod)),
                    Box::new(move |k, reads| twin.trace(&m.rays[k], any, &cone, reads).1),
                )
            }
        };
        let mut model = TrafficModel::new(arrays, &CACHE_SIZES, DRAM_LINE)?;
        // Screen tiles of 8 × 8 pixels, the rays of the pixels that have one.
        let (width, height) = (self.config.width, self.config.height);
        let mut ray_of_pixel = vec![u32::MAX; width as usize * height as usize];
        for (k, &p) in pixels.iter().enumerate() {
            if let Some(slot) = ray_of_pixel.get_mut(p as usize) {
                *slot = k as u32;
            }
        }
        let order: Vec<usize> = traffic::tile_order(width, height, 8)
            .into_iter()
            .filter_map(|p| ray_of_pixel.get(p as usize).copied())
            .filter(|&k| (k as usize) < m.rays.len())
            .map(|k| k as usize)
            .collect();
        let mut twin_counters = vec![crate::probe::RayCounters::default(); m.rays.len()];
        // Chunks traced in parallel, fed to the model in order.
        for chunk in order.chunks(4096) {
            let traced: Vec<(TraceStats, Vec<Read>)> = chunk
                .par_iter()
                .map(|&k| {
                    let mut reads = Vec::new();
                    let stats = trace(k, &mut reads);
                    (stats, reads)
                })
                .collect();
            for (&k, (stats, reads)) in chunk.iter().zip(&traced) {
                twin_counters[k] = stats.counters;
                model.ray(reads)?;
            }
        }
        let differing = twin_counters
            .iter()
            .zip(device)
            .filter(|(t, d)| t != d)
            .count();
        Ok(TrafficRecord {
            twin_counters: MeanCounters::of(&twin_counters),
            counter_mismatch_rate: differing as f64 / m.rays.len().max(1) as f64,
            traffic: model.report(),
        })
    }

    /// One warm-up trace per candidate (whose hits are kept), which also sizes its runs
    /// ([`passes_for`]), then `runs` interleaved rounds.
    fn trace_all(&self, rays: Vec<Ray>, cones: Cones, query: Query) -> Result<Measured> {
        let min_ms = self.config.min_run_ms;
        let mut hits = Vec::with_capacity(self.candidates.len());
        let mut passes = Vec::with_capacity(self.candidates.len());
        for c in &self.candidates {
            let warm = c.trace(&rays, cones, query, false)?;
            let mut n = passes_for(warm.timing.ms(), 1, min_ms);
            if n > 1 {
                // A first trace can pay for cold caches and clocks: size again, busy.
                n = passes_for(
                    c.trace_timed(&rays, cones, query, n)?.timing.ms(),
                    n,
                    min_ms,
                );
            }
            hits.push(warm.hits);
            passes.push(n);
        }
        let runs = self.config.runs as usize;
        let mut timings: Vec<Vec<Timing>> = vec![Vec::with_capacity(runs); self.candidates.len()];
        for _ in 0..runs {
            for ((c, times), &n) in self.candidates.iter().zip(&mut timings).zip(&passes) {
                times.push(c.trace_timed(&rays, cones, query, n)?.timing);
            }
        }
        let gpu = timings.iter().flatten().all(|t| t.gpu_ms.is_some());
        let ms = timings
            .iter()
            .map(|times| {
                times
                    .iter()
                    .map(|t| t.gpu_ms.filter(|_| gpu).unwrap_or(t.wall_ms))
                    .collect()
            })
            .collect();
        Ok(Measured {
            rays,
            query,
            hits,
            ms,
            passes,
            source: if gpu {
                TimingSource::GpuTimestamps
            } else {
                TimingSource::Wall
            },
        })
    }

    fn hit_errors(&self, m: &Measured, reference: &[Hit], test: &[Hit]) -> Result<HitErrors> {
        let object = |h: &Hit| self.object_diagonal(h);
        metrics::hit_errors(&m.rays, reference, test, self.diagonal, &object, m.query)
    }

    /// The box diagonal of the object `h` (a referee's hit) lies on, world space: of the flat
    /// scene's object, or of the object of the instance's mesh as the instance places it.
    fn object_diagonal(&self, h: &Hit) -> Option<f32> {
        let triangle = usize::try_from(h.id).ok()?;
        let b = match (&self.objects, self.view()) {
            (ObjectBoxes::Flat(boxes), SceneView::Flat(scene)) => {
                *boxes.get(*scene.object_of_triangle.get(triangle)? as usize)?
            }
            (ObjectBoxes::Placed(placed_boxes), SceneView::Instanced(placed)) => {
                let instance = placed.instances.get(h.instance as usize)?;
                let mesh = placed.meshes.get(instance.mesh as usize)?;
                let o = *mesh.object_of_triangle.get(triangle)?;
                *placed_boxes.get(h.instance as usize)?.get(o as usize)?
            }
            _ => return None,
        };
        (!b.is_empty()).then(|| b.diagonal())
    }

    /// Writes into `dir` the exact render (`exact.png`), each level's render and error image
    /// (`q2.png`, `q2_error.png`, …) and the charts; returns the files written.
    fn write_plots(&self, dir: PathBuf) -> Result<Vec<PathBuf>> {
        std::fs::create_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
        let mut written = Vec::new();
        if let Some(renders) = &self.renders {
            let (exact_image, exact_hits) = &renders[0];
            for (c, (image, hits)) in self.candidates.iter().zip(renders) {
                let path = dir.join(format!("{}.png", c.file_stem()));
                output::write_png(&path, image)?;
                written.push(path);
                if c.params.is_some() {
                    let errors = error_image(
                        &self.primary,
                        exact_hits,
                        hits,
                        self.diagonal,
                        exact_image.width,
                        exact_image.height,
                    )?;
                    let path = dir.join(format!("{}_error.png", c.file_stem()));
                    output::write_png(&path, &errors)?;
                    written.push(path);
                }
            }
        }
        written.extend(plot::write_charts(&dir, &self.records)?);
        Ok(written)
    }
}

/// Per object, its box: the flat scene's objects, or per instance its mesh's objects as placed.
enum ObjectBoxes {
    Flat(Vec<Aabb>),
    Placed(Vec<Vec<Aabb>>),
}

/// `count` rays aimed at `rbvh`'s seams ([`Rbvh::seam_rays`]), traced by the CPU twins of the
/// exact BVH and of `rbvh`, and how many leaked and passed through
/// ([`super::seams::count_leaks`]);
/// `closed` per scene triangle as [`closed_triangles`] gives it. None when there is nothing to
/// aim at: no height-field leaf (all triangle leaves), or no
/// triangle for the exact BVH to referee.
fn seam_leaks(
    exact: &Bvh,
    closed: &[bool],
    rbvh: &Rbvh,
    count: usize,
    seed: u64,
) -> Option<SeamRecord> {
    let seam = rbvh.seam_rays(count, seed);
    let (rays, texels) = (&seam.rays, &seam.texels);
    if rays.is_empty() || exact.triangles.is_empty() {
        return None;
    }
    let entries = super::seams::exact_entries(exact, rays, texels, closed);
    let approx = rbvh.trace_cpu(rays, false);
    let leaks = super::seams::count_leaks(exact, rays, &entries, &approx, texels);
    Some(SeamRecord {
        rays: rays.len() as u64,
        leaks: leaks.leaks as u64,
        through: leaks.through as u64,
    })
}

/// The seam leaks of a two-level RBVH: of each placed mesh's RBVH, built alone in the mesh's
/// space at its texel (bit for bit the two-level RBVH's bottom level, `InstancedRbvh`'s unit
/// test), with `count` rays shared among the meshes by their height-field leaves and refereed by
/// the mesh's exact BVH ([`seam_leaks`]). A leak is a property of the mesh's surface in its own
/// space, the same in every instance (a mirrored one too: the flat copy's reversed winding is
/// the mesh's own), so the seam rays scale with each instance as its texels do. None where no
/// mesh has a height field.
fn instanced_seam_leaks(
    placed: &InstancedScene,
    two: &InstancedRbvh,
    params: &RbvhParams,
    count: usize,
    seed: u64,
) -> Result<Option<SeamRecord>> {
    let mut built = Vec::new();
    for (mesh, &texel) in placed.meshes.iter().zip(&two.mesh_texels) {
        if texel > 0.0 {
            let rbvh = Rbvh::build_at(&RbvhSource::new(mesh)?, params, texel, &Quiet)?;
            built.push((mesh, rbvh));
        }
    }
    let leaves: u64 = built
        .iter()
        .map(|(_, r)| u64::from(r.stats.heightfield_leaves))
        .sum();
    let mut total: Option<SeamRecord> = None;
    for (k, (mesh, rbvh)) in built.iter().enumerate() {
        let share = (count as u64 * u64::from(rbvh.stats.heightfield_leaves)) / leaves.max(1);
        if share == 0 {
            continue;
        }
        let exact = Bvh::build(mesh)?;
        let closed = closed_triangles(mesh);
        let mesh_seed = seed ^ (k as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        if let Some(r) = seam_leaks(&exact, &closed, rbvh, share as usize, mesh_seed) {
            let t = total.get_or_insert(SeamRecord {
                rays: 0,
                leaks: 0,
                through: 0,
            });
            t.rays += r.rays;
            t.leaks += r.leaks;
            t.through += r.through;
        }
    }
    Ok(total)
}

/// Most trace passes in one timed run: on lavapipe a pass takes milliseconds, on a large GPU tens
/// of microseconds for a small image; beyond this the run is long enough anyway.
const MAX_PASSES: u32 = 4096;

/// Passes per timed run so that a run lasts at least `min_ms`, from a trace of `passes` passes
/// that took `ms` per pass: one where a pass alone is long enough (lavapipe), more on a fast GPU.
fn passes_for(ms: f64, passes: u32, min_ms: f64) -> u32 {
    if ms.is_nan() || ms <= 0.0 || min_ms <= 0.0 {
        return passes.max(1);
    }
    (min_ms / ms).ceil().clamp(1.0, f64::from(MAX_PASSES)) as u32
}

/// `tracer` with its block jumps set as the bench was asked (`None`: left as the tracer chose).
fn with_jumps(mut tracer: Tracer, block_jumps: Option<bool>) -> Result<Tracer> {
    if let Some(on) = block_jumps {
        tracer.set_block_jumps(on)?;
    }
    Ok(tracer)
}

#[cfg(test)]
mod tests {
    use super::{passes_for, MAX_PASSES};

    #[test]
    fn runs_are_sized_to_last_the_shortest_run() {
        // A pass long enough alone (lavapipe), or no minimum asked: one pass.
        assert_eq!(passes_for(35.0, 1, 20.0), 1);
        assert_eq!(passes_for(0.2, 1, 0.0), 1);
        // A fast GPU: as many passes as fill the run.
        assert_eq!(passes_for(0.5, 1, 20.0), 40);
        assert_eq!(passes_for(0.3, 40, 20.0), 67);
        assert_eq!(passes_for(1e-9, 1, 20.0), MAX_PASSES);
        // No usable time (a zero-length or broken timestamp): keep what was asked.
        assert_eq!(passes_for(0.0, 7, 20.0), 7);
        assert_eq!(passes_for(f64::NAN, 1, 20.0), 1);
    }
}
