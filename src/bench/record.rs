//! What a benchmark run produces, and its two file formats.
//!
//! # JSON (`--json`)
//!
//! One object: the run's provenance, then one record per (scene, method, level, ray type).
//!
//! | key | type | meaning |
//! |---|---|---|
//! | `device`, `driver` | string | the Vulkan device and driver, as they report themselves |
//! | `date` | string | start of the run, UTC, ISO 8601 (`2025-01-31T12:00:00Z`) |
//! | `git` | string \| null | `RBVH_COMMIT` where set, else `git rev-parse HEAD` in the working directory; null outside a repository |
//! | `git_dirty` | bool \| null | whether tracked files other than documentation (`docs/`, `*.md`) differed from that commit (uncommitted code was measured); null outside a repository or with `RBVH_COMMIT` |
//! | `host` | object | the machine ([`super::provenance::Host`]): `cpu`, `cores`, `logical_cpus`, `threads_used` (the threads lavapipe traces on: `LP_NUM_THREADS` else one per CPU, at most Mesa's 32; null on other devices), `l2_bytes`, `l3_bytes`, `memory_bytes`, `os`, `virtualized`, `mesa`, `llvm`; null where the system does not tell |
//! | `version` | string | this crate's version |
//! | `runs` | int | timed runs per record, after one warm-up |
//! | `min_run_ms` | number | shortest timed run asked for, in milliseconds (records' `passes`) |
//! | `width`, `height` | int | primary-ray image size |
//! | `ao_radius` | number | AO ray length, fraction of the scene diagonal |
//! | `seed` | int | seed of the secondary rays' directions |
//! | `results` | array | the records below |
//! | `shaders` | array | each trace pipeline used, once: `method`, then as `rbvh shaders` reports every pipeline ([`CompiledPipeline`]): `pipeline` (the shader and its variant), `shader`, `reach`, `specialization`, `default_variant`, `statistics` (`name`, `value` pairs in the driver's words: registers, spills, code size; empty where the device does not report them) |
//!
//! Each record:
//!
//! | key | type | meaning |
//! |---|---|---|
//! | `scene` | string | scene name (built-in name, file name, or the scene file's `name`) |
//! | `triangles` | int | triangles in the scene |
//! | `points` | int | points the RBVHs were built from (`--points`: sampled over the triangles, or a scan's file); 0: built from the triangles |
//! | `method` | `"exact"` \| `"rbvh"` \| `"rbvh-lod"` \| `"exact-instanced"` \| `"rbvh-instanced"` | exact triangle BVH, RBVH, RBVH traced with level of detail, or a scene of instances' two-level exact BVH or RBVH |
//! | `quality` | null \| `"Q0"`…`"Q4"` \| `"custom"` | RBVH level; null for exact |
//! | `params` | object \| null | RBVH build parameters (below); null for exact |
//! | `lod` | object \| null | level-of-detail parameters (below); null but for `rbvh-lod` |
//! | `ray_type` | `"primary"` \| `"ao"` \| `"shadow"` \| `"diffuse"` | see [`crate::rays`] |
//! | `rays` | int | rays per dispatch |
//! | `mrays_per_s` | {`median`,`min`,`max`,`samples`} | million rays per second over the timed runs; `samples` each run's, in run order |
//! | `speedup_vs_exact` | number | median MRays/s over the exact BVH's, same rays, same run (1 for exact) |
//! | `build_ms` | number | CPU build time of the structure |
//! | `memory_bytes` | {`tree`,`atlas`,`triangles`,`total`,`texels`,`narrow_texels`} | bytes uploaded: nodes (+ height-field leaf records for RBVH), atlas texels, triangles, their sum; the tiles' texels and those of them stored with 8-bit heights (the narrow band; 0 for exact) |
//! | `memory_ratio_vs_exact` | number | exact total / this total (above 1: smaller than exact) |
//! | `error` | object \| null | errors against the exact BVH on the same rays (below); null for exact |
//! | `valid` | bool | false when the hits are wrong rather than approximate (`bench::validate`); for exact: whether the GPU agrees with the CPU reference tracer to rounding (`validate::invalid_reason_exact`) |
//! | `invalid_reason` | string \| null | why `valid` is false |
//! | `timing_source` | `"gpu_timestamps"` \| `"wall"` | GPU timestamp queries, or host wall time (submit to fence) when the device cannot time |
//! | `passes` | int | trace passes per timed run, back to back in one submission (as many as make a run last `min_run_ms`); `mrays_per_s` is per pass |
//! | `block_jumps` | bool \| null | whether the march jumped over blocks ([`crate::gpu::Tracer::block_jumps`]); null for exact |
//! | `counters` | object | per-ray means of the device's counters ([`crate::probe::MeanCounters`]: `nodes`, `leaves`, `walks`, `cells`, `cells_tested`, `jumps`, `triangle_leaves`, `triangles`, `instances`, `top_nodes`, `simd8_utilisation`) |
//! | `traffic` | object \| null | with `--traffic`: `twin_counters` (the CPU twin's, same keys), `counter_mismatch_rate`, and `traffic` (the cache model's figures, [`super::traffic::Traffic`]); else null |
//! | `steps` | object \| null | with `--steps`, for exact and plain RBVH records: where a ray's steps go ([`super::steps::StepsRecord`]: `nodes_by_depth` (inner nodes per ray at tree levels 0–7, 8–15, 16–23, 24–31, 32 on), `node_depth_mean`, the height-field leaves handed to the march by what came of them (`leaves_tile_missed`, `leaves_no_surface`, `leaves_behind`, `leaves_nearest`), `boxes_at_hit`); else null |
//!
//! `params`: `texels_per_diagonal`, `refinement` (`"normal_cone"` \| `"projected_area"`),
//! `max_angle_deg` (normal cone, else null), `min_ratio` (projected area, else null),
//! `subdivision` (`"spatial_median"` \| `"area_sah"`), `object_split`, `max_tile`,
//! `min_leaf_texels`, `sampled_criterion_texels`, `texels` (`"height_normal"` \| `"height"`),
//! `exact_when_cheaper`, `exact_from_texels`, `exact_edge_fraction`, `exact_crease_deg`,
//! `view_rate` — the fields of [`RbvhParams`].
//!
//! `lod` (`rbvh-lod` records, else null): `columns`, `min_leaves`, `bias` — the fields of
//! [`LodParams`].
//!
//! `error` (definitions in `bench::metrics`): `miss_mismatch_rate` (fraction of rays hit by one
//! side only); `t_err_mean`, `t_err_p99`, `t_err_max` (`|t − t_exact|` over rays both hit, as a
//! fraction of the scene's bounding-box diagonal); `t_err_object_mean`, `t_err_object_p99` (the
//! same over the diagonal of the object the exact ray hit); `normal_err_deg_mean`,
//! `normal_err_deg_p99` (degrees); `back_facing_rate` (rays both hit whose normal faces away from
//! the ray while the exact one faces it, over all rays); `psnr_db`, `flip_mean` (shaded primary
//! images, 8-bit sRGB). The distance and normal errors and `back_facing_rate` are null for any-hit
//! ray types (ao, shadow), the distance and normal errors also when no ray was hit by both; the image
//! metrics are null except for primary rays, and `psnr_db` is also null for identical images
//! (+∞ dB; `flip_mean` is then 0).
//!
//! # CSV (`--csv`)
//!
//! RFC 4180: a header line ([`csv_columns`]), then one line per record: first the run's provenance
//! (`device`, `driver`, `date`, `git`, `git_dirty`, the host's fields as `host.cpu`,
//! `host.l3_bytes`, …, then `version`), so that rows from several runs can be pasted
//! into one table, then the record's fields flattened, nested keys joined by `.`
//! (`params.*`, `mrays_per_s.*`, `memory_bytes.*`, `error.*`, `counters.*`,
//! `traffic.twin_counters.*`, the modelled caches by position as `traffic.caches.N.*`,
//! `steps.*`). The run's settings (`runs`, `min_run_ms`, image size, `ao_radius`, `seed`), the per-run `samples` and the steps' `nodes_by_depth` bands are in the JSON only. Null
//! is an empty cell (as the PSNR of identical images, null in the JSON too).

use std::io::Write;
use std::path::{Path, PathBuf};

use serde::Serialize;

use crate::structure::Kind;
pub use crate::structure::Memory;

use super::provenance::Provenance;
use super::steps::StepsRecord;
use super::traffic::{CacheTraffic, Traffic, CACHE_SIZES};
use crate::gpu::CompiledPipeline;
use crate::io::write_atomically;
use crate::lod::LodParams;
use crate::probe::MeanCounters;
use crate::rays::RayType;
use crate::rbvh::{level_name, RbvhParams, Refinement, Subdivision, TexelFormat};
use crate::{Error, Result};

/// A whole run: provenance and records.
#[derive(Clone, Debug, Serialize)]
pub struct BenchReport {
    /// Where and when: device, driver, date, commit, host (with lavapipe's threads), version.
    #[serde(flatten)]
    pub provenance: Provenance,
    /// Timed runs per record, after one warm-up
    /// ([`BenchConfig::runs`](super::BenchConfig::runs)).
    pub runs: u32,
    /// Shortest timed run asked for, in milliseconds
    /// ([`BenchConfig::min_run_ms`](super::BenchConfig::min_run_ms)).
    pub min_run_ms: f64,
    /// Primary-ray image width in pixels.
    pub width: u32,
    /// Primary-ray image height in pixels.
    pub height: u32,
    /// AO ray length as a fraction of each scene's bounding-box diagonal.
    pub ao_radius: f32,
    /// Seed of the secondary rays' directions.
    pub seed: u64,
    /// One record per (scene, method, level, ray type), in the order measured.
    pub results: Vec<Record>,
    /// Each trace pipeline the run used, once, with what the driver compiled it into.
    pub shaders: Vec<ShaderRecord>,
    /// Charts and images written under the plot directory (not part of the JSON).
    #[serde(skip)]
    pub written: Vec<PathBuf>,
}

/// One (scene, method, level, ray type).
#[derive(Clone, Debug, Serialize)]
pub struct Record {
    /// Scene name: built-in name, file name, or the scene file's `name`.
    pub scene: String,
    /// Triangles in the scene.
    pub triangles: u64,
    /// Points the scene's RBVHs were built from (a point cloud's, or sampled from the triangles
    /// by [`BenchConfig::points`](super::BenchConfig::points)); 0: built from the triangles.
    pub points: u64,
    /// Which structure traced the rays.
    pub method: Kind,
    /// RBVH level, `"Q0"`…`"Q4"` or `"custom"` ([`RbvhParams::quality_name`](crate::rbvh::RbvhParams::quality_name)); None for
    /// exact.
    pub quality: Option<String>,
    /// RBVH build parameters; None for exact.
    pub params: Option<Params>,
    /// How the levels of detail were built and chosen, for `rbvh-lod` records.
    pub lod: Option<LodParams>,
    /// What the rays are for; secondary rays start at the exact BVH's primary hits.
    pub ray_type: RayType,
    /// Rays per dispatch: pixels for primary rays, exact primary hits for secondary rays.
    pub rays: u64,
    /// Million rays per second of each timed run (rays / dispatch time).
    pub mrays_per_s: Spread,
    /// Median MRays/s over the exact BVH's on the same rays in the same run; 1 for exact.
    pub speedup_vs_exact: f64,
    /// CPU build time in milliseconds (RBVH plus levels of detail for `rbvh-lod`).
    pub build_ms: f64,
    /// Bytes of the structure as uploaded.
    pub memory_bytes: Memory,
    /// The exact BVH's total bytes over this structure's: above 1, smaller than exact.
    pub memory_ratio_vs_exact: f64,
    /// Errors against the exact BVH on the same rays; None for exact.
    pub error: Option<Errors>,
    /// False when the hits are wrong rather than approximate ([`super::validate`]); for exact,
    /// whether the GPU agrees with the CPU reference tracer to rounding.
    pub valid: bool,
    /// Why `valid` is false; None when valid.
    pub invalid_reason: Option<String>,
    /// What the runs' times were measured with, the same for every method of a ray type.
    pub timing_source: TimingSource,
    /// Trace passes per timed run, back to back in one submission; the run's time is per pass
    /// ([`BenchConfig::min_run_ms`](super::BenchConfig::min_run_ms)).
    pub passes: u32,
    /// Whether the device march jumped over blocks; None for the exact BVH.
    pub block_jumps: Option<bool>,
    /// Per-ray means of the device's counters (its counting pipeline, on the same rays).
    pub counters: MeanCounters,
    /// The CPU twin's counters and memory traffic, with `--traffic`.
    pub traffic: Option<TrafficRecord>,
    /// Where a ray's steps go (the CPU twin's account), with `--steps`; None for
    /// level-of-detail records.
    pub steps: Option<StepsRecord>,
    /// Leaks through the seams between height fields, for RBVH records, flat and two-level (the same for each
    /// ray type of a level); None for the other methods, or with no seam rays asked for.
    pub seams: Option<SeamRecord>,
}

/// Rays aimed at an RBVH level's seams between leaves and how many leaked through the surface
/// ([`super::seams`]: the exact BVH finds the ray entering the solid a texel or more from
/// its origin and passing half a texel or more inside, and the RBVH finds nothing within two
/// texels behind the entry), and how many of those passed through the solid (nothing within two
/// texels behind the exit either).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct SeamRecord {
    /// Rays aimed at the leaves' rims.
    pub rays: u64,
    /// Of those, the ones that leaked.
    pub leaks: u64,
    /// Of the leaks, the ones the RBVH did not meet before they left the solid: light through
    /// a closed object for shadow and ambient-occlusion rays.
    pub through: u64,
}

/// A trace pipeline the run used and what the driver compiled it into
/// ([`crate::gpu::CompiledPipeline`], as [`crate::gpu::compile_every_pipeline`] and `rbvh
/// shaders` report every pipeline): on a GPU its registers bound how many rays run at once,
/// which no per-ray counter shows.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ShaderRecord {
    /// The first method traced with it.
    pub method: Kind,
    /// The pipeline, its variant and the driver's statistics (empty where the device does not
    /// report them, `VK_KHR_pipeline_executable_properties`).
    #[serde(flatten)]
    pub compiled: CompiledPipeline,
}

/// What the CPU twin measured on a record's rays ([`super::BenchConfig::traffic`]).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TrafficRecord {
    /// Per-ray means of the twin's counters: the device's, when the two agree.
    pub twin_counters: MeanCounters,
    /// Fraction of rays whose twin counters differ from the device's (0 but where the device's
    /// last-bit rounding changes a hit).
    pub counter_mismatch_rate: f64,
    /// The traffic model's figures (`bench::traffic`).
    #[serde(flatten)]
    pub traffic: Traffic,
}

/// What the timed runs were measured with.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum TimingSource {
    /// GPU timestamp queries around the trace dispatches (uploads and read-back excluded).
    GpuTimestamps,
    /// Host wall time from submit to fence, when the device cannot time; includes submission
    /// overhead.
    Wall,
}

impl TimingSource {
    /// `"gpu_timestamps"` or `"wall"`: the `timing_source` of the JSON and CSV records.
    pub fn name(self) -> &'static str {
        match self {
            TimingSource::GpuTimestamps => "gpu_timestamps",
            TimingSource::Wall => "wall",
        }
    }
}

/// Median, minimum and maximum over the timed runs, and every run's value in the order run.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Spread {
    /// Median of `samples`; the mean of the middle two for an even count.
    pub median: f64,
    /// Smallest of `samples`.
    pub min: f64,
    /// Largest of `samples`.
    pub max: f64,
    /// Every timed run's value, in the order run (CSV: not written).
    pub samples: Vec<f64>,
}

impl Spread {
    /// Of non-empty `values` (the harness times at least one run); the median of an even count
    /// is the mean of the middle two.
    pub(crate) fn of(values: &[f64]) -> Spread {
        let mut v = values.to_vec();
        v.sort_by(f64::total_cmp);
        let n = v.len();
        let median = if n % 2 == 1 {
            v[n / 2]
        } else {
            0.5 * (v[n / 2 - 1] + v[n / 2])
        };
        Spread {
            median,
            min: v[0],
            max: v[n - 1],
            samples: values.to_vec(),
        }
    }
}

/// [`RbvhParams`] with named enums, for the records.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Params {
    /// Sampling rate: texels along the scene's bounding-box diagonal.
    pub texels_per_diagonal: f32,
    /// Each object's least sampling rate along its own box diagonal, as a fraction of
    /// `texels_per_diagonal`, 0 for none ([`RbvhParams::object_rate`]).
    pub object_rate: f32,
    /// Leaf refinement criterion: `"normal_cone"` or `"projected_area"`.
    pub refinement: &'static str,
    /// Largest angle between a triangle normal and the projection axis, in degrees; None unless
    /// `refinement` is `"normal_cone"`.
    pub max_angle_deg: Option<f32>,
    /// Smallest projected-to-true area ratio `A⊥ / A`, in (0, 1]; None unless `refinement` is
    /// `"projected_area"`.
    pub min_ratio: Option<f32>,
    /// Subdivision rule: `"spatial_median"` or `"area_sah"`.
    pub subdivision: &'static str,
    /// Whether separate parts are never fused into one height field
    /// ([`RbvhParams::object_split`]).
    pub object_split: bool,
    /// Most texels along one side of a tile ([`RbvhParams::max_tile`]).
    pub max_tile: u32,
    /// Box diagonal in texels below which a set that is no height field stays triangles
    /// ([`RbvhParams::min_leaf_texels`]).
    pub min_leaf_texels: f32,
    /// Box diagonal in texels up to which a set whose triangles fail the criterion is judged on
    /// its sampled surface ([`RbvhParams::sampled_criterion_texels`]).
    pub sampled_criterion_texels: f32,
    /// What each texel holds: `"height_normal"` or `"height"` ([`RbvhParams::texels`]).
    pub texels: &'static str,
    /// Whether triangles are traced exactly where that costs fewer bytes than sampling them
    /// ([`RbvhParams::exact_when_cheaper`]).
    pub exact_when_cheaper: bool,
    /// The size in texels from which a triangle is traced exactly, 0 for what 96 bytes buy
    /// ([`RbvhParams::exact_from_texels`]).
    pub exact_from_texels: f32,
    /// The fraction of its object's diagonal from which a triangle's longest edge makes it
    /// traced exactly, 0 for none ([`RbvhParams::exact_edge_fraction`]).
    pub exact_edge_fraction: f32,
    /// The crease angle in degrees from which a triangle is traced exactly, 0 for none
    /// ([`RbvhParams::exact_crease_deg`]).
    pub exact_crease_deg: f32,
    /// Texels across the view's field at a triangle's distance, 0 for none
    /// ([`RbvhParams::view_rate`]).
    pub view_rate: f32,
}

impl From<&RbvhParams> for Params {
    fn from(p: &RbvhParams) -> Params {
        let (refinement, max_angle_deg, min_ratio) = match p.refinement {
            Refinement::NormalCone { max_angle_deg } => ("normal_cone", Some(max_angle_deg), None),
            Refinement::ProjectedArea { min_ratio } => ("projected_area", None, Some(min_ratio)),
        };
        Params {
            texels_per_diagonal: p.texels_per_diagonal,
            object_rate: p.object_rate,
            refinement,
            max_angle_deg,
            min_ratio,
            subdivision: match p.subdivision {
                Subdivision::SpatialMedian => "spatial_median",
                Subdivision::AreaSah => "area_sah",
            },
            object_split: p.object_split,
            max_tile: p.max_tile,
            min_leaf_texels: p.min_leaf_texels,
            sampled_criterion_texels: p.sampled_criterion_texels,
            texels: p.texels.name(),
            exact_when_cheaper: p.exact_when_cheaper,
            exact_from_texels: p.exact_from_texels,
            exact_edge_fraction: p.exact_edge_fraction,
            exact_crease_deg: p.exact_crease_deg,
            view_rate: p.view_rate,
        }
    }
}

impl Record {
    /// The level as tables and charts show it: `-` for exact, else its [`level_name`]
    /// (`"Q2"`, `"Q2h"`, `"Q2s"`, `"Q2v"`), as [`RbvhParams::level_label`] names the same level.
    pub fn level_label(&self) -> String {
        let Some(q) = &self.quality else {
            return "-".into();
        };
        let params = self.params.as_ref();
        level_name(
            q,
            params.is_some_and(|p| p.texels == TexelFormat::Height.name()),
            params.is_some_and(|p| !p.exact_when_cheaper),
            params.is_some_and(|p| p.view_rate > 0.0),
        )
    }
}

/// Errors against the exact BVH (see the module docs for which are null when).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Errors {
    /// Fraction of rays hit by one side and missed by the other, in [0, 1].
    pub miss_mismatch_rate: f64,
    /// Mean `|t − t_exact| · |dir|` over rays both hit, as a fraction of the scene diagonal.
    pub t_err_mean: Option<f64>,
    /// Nearest-rank 99th percentile of the same distance error.
    pub t_err_p99: Option<f64>,
    /// Largest distance error, as a fraction of the scene diagonal.
    pub t_err_max: Option<f64>,
    /// Mean `|t − t_exact| · |dir|` as a fraction of the diagonal of the object the exact ray
    /// hit: the error a preset that samples each object for its size promises.
    pub t_err_object_mean: Option<f64>,
    /// Nearest-rank 99th percentile of the same object-relative error.
    pub t_err_object_p99: Option<f64>,
    /// Mean angle between the geometric normals (as wound) over rays both hit, in degrees.
    pub normal_err_deg_mean: Option<f64>,
    /// Nearest-rank 99th percentile of the normal angle error, in degrees.
    pub normal_err_deg_p99: Option<f64>,
    /// Rays both hit whose normal faces away from the ray while the exact one faces it, over
    /// all rays: the dark specks of a shaded image. Null for any-hit ray types.
    pub back_facing_rate: Option<f64>,
    /// +∞ for identical images, which JSON writes as null.
    pub psnr_db: Option<f64>,
    /// Mean of FLIP's per-pixel error map between the shaded primary images, in [0, 1].
    pub flip_mean: Option<f64>,
}

/// Writes `report` as pretty-printed JSON, atomically.
pub fn write_json(path: &Path, report: &BenchReport) -> Result<()> {
    write_atomically(path, |w| {
        serde_json::to_writer_pretty(&mut *w, report)?;
        writeln!(w)
    })
}

/// The run's provenance that leads every CSV row, as (column, cell): [`Provenance`]'s fields by
/// their JSON keys, the host's as `host.cpu`, ….
fn provenance(report: &BenchReport) -> Result<Vec<(String, String)>> {
    let value = serde_json::to_value(&report.provenance)
        .map_err(|e| Error::param("bench provenance", format!("cannot serialize it: {e}")))?;
    let mut flat = Vec::new();
    flatten("", &value, &mut flat);
    Ok(flat.into_iter().map(|(k, v)| (k, cell(&v))).collect())
}

/// The CSV header: the provenance, then the dotted key of every value of a record's JSON with
/// every section present (see the module docs), in the record's field order.
pub fn csv_columns() -> Result<Vec<String>> {
    let mut columns: Vec<String> = provenance(&BenchReport::empty())?
        .into_iter()
        .map(|(c, _)| c)
        .collect();
    let mut cells = Vec::new();
    flatten("", &json_of(&Record::with_every_section())?, &mut cells);
    columns.extend(cells.into_iter().map(|(key, _)| key));
    Ok(columns)
}

impl BenchReport {
    /// A report of no run, whose provenance has every column (the CSV header's).
    fn empty() -> BenchReport {
        BenchReport {
            provenance: Provenance::default(),
            runs: 0,
            min_run_ms: 0.0,
            width: 0,
            height: 0,
            ao_radius: 0.0,
            seed: 0,
            results: Vec::new(),
            shaders: Vec::new(),
            written: Vec::new(),
        }
    }
}

/// A record's JSON value: the one serialization both files are written from.
fn json_of(record: &Record) -> Result<serde_json::Value> {
    serde_json::to_value(record)
        .map_err(|e| Error::param("bench record", format!("cannot serialize it: {e}")))
}

/// Appends every value below `value` as (dotted key, value): objects by key, arrays of objects by
/// position, arrays of numbers (the per-run samples) not at all.
fn flatten(prefix: &str, value: &serde_json::Value, out: &mut Vec<(String, serde_json::Value)>) {
    use serde_json::Value;
    let key = |k: &str| {
        if prefix.is_empty() {
            k.to_string()
        } else {
            format!("{prefix}.{k}")
        }
    };
    match value {
        Value::Object(map) => {
            for (k, v) in map {
                flatten(&key(k), v, out);
            }
        }
        Value::Array(items) => {
            for (k, v) in items.iter().enumerate().filter(|(_, v)| v.is_object()) {
                flatten(&key(&k.to_string()), v, out);
            }
        }
        leaf => out.push((prefix.to_string(), leaf.clone())),
    }
}

/// A CSV cell: strings as they are, numbers and booleans as JSON writes them, null empty.
fn cell(value: &serde_json::Value) -> String {
    match value {
        serde_json::Value::Null => String::new(),
        serde_json::Value::String(s) => s.clone(),
        other => other.to_string(),
    }
}

impl Record {
    /// A record with every optional section present (its values meaningless), whose JSON keys
    /// are the CSV's columns: a run writes the same header whatever it measured.
    fn with_every_section() -> Record {
        let counters = MeanCounters::default();
        Record {
            scene: String::new(),
            triangles: 0,
            points: 0,
            method: Kind::RbvhLod,
            quality: None,
            params: RbvhParams::quality(0).ok().as_ref().map(Params::from),
            lod: Some(LodParams::default()),
            ray_type: RayType::Primary,
            rays: 0,
            mrays_per_s: Spread::of(&[0.0]),
            speedup_vs_exact: 0.0,
            build_ms: 0.0,
            memory_bytes: Memory::default(),
            memory_ratio_vs_exact: 0.0,
            error: Some(Errors::default()),
            valid: true,
            invalid_reason: None,
            timing_source: TimingSource::GpuTimestamps,
            passes: 1,
            block_jumps: None,
            counters,
            traffic: Some(TrafficRecord {
                twin_counters: counters,
                counter_mismatch_rate: 0.0,
                traffic: Traffic {
                    caches: CACHE_SIZES
                        .iter()
                        .map(|&capacity_bytes| CacheTraffic {
                            capacity_bytes,
                            ..CacheTraffic::default()
                        })
                        .collect(),
                    ..Traffic::default()
                },
            }),
            steps: Some(StepsRecord::default()),
            seams: Some(SeamRecord {
                rays: 0,
                leaks: 0,
                through: 0,
            }),
        }
    }
}

/// Writes `report`'s records as CSV (see the module docs), atomically.
pub fn write_csv(path: &Path, report: &BenchReport) -> Result<()> {
    let columns = csv_columns()?;
    let provenance: Vec<String> = provenance(report)?.into_iter().map(|(_, c)| c).collect();
    let lead = provenance.len();
    let rows = report
        .results
        .iter()
        .map(|record| {
            let mut cells = Vec::new();
            flatten("", &json_of(record)?, &mut cells);
            let by_key: std::collections::HashMap<String, serde_json::Value> =
                cells.into_iter().collect();
            Ok(provenance
                .iter()
                .cloned()
                .chain(
                    columns[lead..]
                        .iter()
                        .map(|c| by_key.get(c).map(cell).unwrap_or_default()),
                )
                .collect::<Vec<String>>())
        })
        .collect::<Result<Vec<_>>>()?;
    write_atomically(path, |w| {
        let mut csv = csv::Writer::from_writer(w);
        csv.write_record(&columns)?;
        for row in &rows {
            csv.write_record(row)?;
        }
        csv.flush()
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn medians_of_odd_and_even_counts() {
        assert_eq!(
            Spread::of(&[3.0, 1.0, 2.0]),
            Spread {
                median: 2.0,
                min: 1.0,
                max: 3.0,
                samples: vec![3.0, 1.0, 2.0],
            }
        );
        assert_eq!(Spread::of(&[4.0, 1.0, 2.0, 3.0]).median, 2.5);
    }

    #[test]
    fn a_height_only_level_is_labelled_with_its_suffix() {
        let mut r = Record::with_every_section();
        assert_eq!(r.level_label(), "-");
        r.quality = Some("Q2".into());
        assert_eq!(r.level_label(), "Q2");
        let height = RbvhParams {
            texels: TexelFormat::Height,
            ..RbvhParams::quality(2).unwrap()
        };
        r.params = Some(Params::from(&height));
        assert_eq!(r.level_label(), "Q2h");
        let sampled = RbvhParams {
            exact_when_cheaper: false,
            ..RbvhParams::quality(2).unwrap()
        };
        r.params = Some(Params::from(&sampled));
        assert_eq!(r.level_label(), "Q2s");
        let viewed = RbvhParams {
            view_rate: 384.0,
            ..sampled
        };
        r.params = Some(Params::from(&viewed));
        assert_eq!(r.level_label(), "Q2sv");
    }

    #[test]
    fn every_section_gives_a_column_and_no_column_twice() {
        let columns = csv_columns().unwrap();
        for c in [
            "device",
            "git_dirty",
            "host.cpu",
            "host.l3_bytes",
            "host.llvm",
            "scene",
            "mrays_per_s.median",
            "params.texels",
            "lod.bias",
            "error.psnr_db",
            "counters.nodes",
            "traffic.twin_counters.nodes",
            "traffic.caches.2.dram_bytes_per_ray",
            "steps.node_depth_mean",
            "steps.leaves_behind",
        ] {
            assert!(columns.iter().any(|k| k == c), "{c} not in {columns:?}");
        }
        assert!(!columns.iter().any(|k| k.contains("samples")));
        assert!(!columns.iter().any(|k| k.contains("nodes_by_depth")));
        let unique: std::collections::HashSet<&String> = columns.iter().collect();
        assert_eq!(unique.len(), columns.len());
    }
}
