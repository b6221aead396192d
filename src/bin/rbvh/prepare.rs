//! What every command does first: pick the device, load the scene, build the acceleration
//! structure — with a spinner on long steps (hidden when stderr is not a terminal).

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context as _, Result};

use crate::flags::{flag_error, Given, BUILD_FLAGS, LOD_FLAGS};
use crate::progress::step;
use crate::quality::{presets, Quality};
use clap::{Args, ValueEnum};
use rbvh::bench::provenance::Provenance;
use rbvh::geom::{Hit, Ray};
use rbvh::glam::Vec3;
use rbvh::gpu::{Addressing, Context, ContextOptions, Query, Reach, Traced, Tracer, Validation};
use rbvh::lod::{Cones, LodParams};
use rbvh::points::MIN_POINTS;
use rbvh::rbvh::{InstancedRbvh, Rbvh, RbvhParams, TexelFormat};
use rbvh::scene::{
    Camera, InstancedScene, Instances, PointSource, Scene, SceneView, DEFAULT_VFOV_DEG,
};
use rbvh::structure::Recipe;

/// Options shared by the commands that trace through one structure (`render`, `trace`, `compare`,
/// `paint`): one level, in one texel format.
#[derive(Args, Clone, Debug)]
#[command(mut_arg("quality", |a| a.help(
    "Quality preset of the RBVH: one of 0..4 or Q0..Q4 (Q0 coarsest, Q4 finest); for an RBVH \
     this command builds, not for one loaded with --rbvh"
)))]
#[command(mut_arg("method", |a| a.help(
    "Structure to trace through: `exact` (the exact triangle BVH, the referee), `rbvh` (a \
     Rasterized BVH at --quality), `rbvh-lod` (that RBVH traced with level of detail: each ray \
     uses the coarsest representation whose columns are at most 2^--lod-bias of its footprint \
     wide); one of them"
)))]
#[command(mut_arg("texels", |a| a.help(
    "What each atlas texel holds: `normals` (height and normal: 8-, 10-, 12- or 16-bit \
     heights by tile, and a 16-bit normal where the texel is not a hole) or `height` (height alone, 1 to 2 bytes: facet normals, no colours, no \
     levels of detail); one of the two, since this command traces one RBVH (build and bench take \
     both, comma-separated)"
)))]
#[command(mut_arg("sample_all", |a| a.help(
    "Sample every triangle a height field can hold, as the paper does (the level is named with \
     an `s`, e.g. Q2s). Presets trace triangles exactly where that costs fewer bytes than \
     sampling them (a triangle covering at least 24 texels, 48 height-only, and a set whose \
     tiles would cost more than its triangles) and on a crease of 30° or more spanning 2 texels"
)))]
pub struct Common {
    #[command(flatten)]
    pub source: Source,
    #[command(flatten)]
    pub structures: Structures,
}

impl Common {
    /// Refuses the flags that would have no effect ([`Structures::check`]).
    pub fn check(&self, given: &Given) -> Result<()> {
        self.structures.check(given, self.source.rbvh.is_some())
    }
}

/// Which structure: `--method`, `--quality` with the free parameters and `--texels`, and how
/// levels of detail are built. Every command that traces takes this group, with the same flags,
/// help and refusals, and makes its [`Recipe`]s from it; commands differ only in their defaults
/// and in how many structures they take (`render`, `trace`, `compare` and `paint` one; `bench`
/// and `regress` several).
#[derive(Args, Clone, Debug)]
pub struct Structures {
    /// Structure to trace through: `exact` (the exact triangle BVH, the referee), `rbvh` (a
    /// Rasterized BVH at --quality), `rbvh-lod` (that RBVH traced with level of detail: each ray
    /// uses the coarsest representation whose columns are at most 2^--lod-bias of its footprint
    /// wide); comma-separated where a command measures several.
    #[arg(long, value_enum, value_delimiter = ',', default_value = "exact")]
    pub method: Vec<Method>,
    #[command(flatten)]
    pub quality: Quality,
    #[command(flatten)]
    pub lod: LodBuildArgs,
}

impl Structures {
    /// The one method of a command that traces one structure.
    pub fn method(&self) -> Result<Method> {
        match self.method.as_slice() {
            [method] => Ok(*method),
            _ => anyhow::bail!("--method: this command traces one structure, give one method"),
        }
    }

    /// Whether `method` is asked for.
    pub fn has(&self, method: Method) -> bool {
        self.method.contains(&method)
    }

    /// The recipe of a command that traces one structure built from the scene: the method at
    /// the one --quality level, in the one --texels format.
    pub fn recipe(&self) -> Result<Recipe> {
        let method = self.method()?;
        if method == Method::Exact {
            return Ok(Recipe::Exact);
        }
        let mut levels = self.quality.levels()?;
        if levels.len() != 1 {
            // The flag that named more than one.
            let presets = presets(&self.quality.quality)?.len();
            anyhow::ensure!(
                presets == 1,
                "--quality names {presets} levels: give one level to trace"
            );
            anyhow::bail!("--texels names two texel formats: give one to trace");
        }
        Ok(method.recipe(levels.remove(0), self.lod.params()))
    }

    /// Refuses what would have no effect: the build flags where no RBVH is built (only the exact
    /// BVH asked for, or `--rbvh FILE` loading one built already, with the parameters it was
    /// built with), and the level-of-detail flags without `rbvh-lod`.
    pub fn check(&self, given: &Given, loaded: bool) -> Result<()> {
        if loaded {
            anyhow::ensure!(
                !self.has(Method::Exact) || !given.has("method"),
                "--method exact traces the exact BVH, but --rbvh names an RBVH to trace: give one of them"
            );
            if let Some(flag) = given.first(&BUILD_FLAGS) {
                anyhow::bail!(
                    "{flag} says how to build an RBVH, but --rbvh loads one built already (with \
                     the parameters it was built with): drop {flag}, or drop --rbvh to build one"
                );
            }
        } else if self.method.iter().all(|m| *m == Method::Exact) {
            if let Some(flag) = given.first(&BUILD_FLAGS) {
                anyhow::bail!(
                    "{flag} says how to build an RBVH, but --method exact traces the exact BVH: \
                     use --method rbvh"
                );
            }
        }
        if !self.has(Method::RbvhLod) {
            if let Some(flag) = given.first(&LOD_FLAGS) {
                anyhow::bail!(
                    "{flag} says how levels of detail are built and chosen, and --method asks for \
                     none: use --method rbvh-lod"
                );
            }
        }
        Ok(())
    }
}

/// Where the scene and its RBVH come from, and the device: what every command that traces one
/// structure takes.
#[derive(Args, Clone, Debug)]
pub struct Source {
    /// Built-in scene name (`rbvh scenes` lists them), OBJ/glTF/GLB file, point cloud (.ply,
    /// .xyz; traced through an RBVH of its points), or scene file (.toml).
    #[arg(long, default_value = "default")]
    pub scene: String,
    #[command(flatten)]
    pub points: PointsArg,
    /// Trace this saved RBVH (from `rbvh build --out`) instead of building one (implies --method
    /// rbvh, or give rbvh-lod; the file holds its build parameters, so --quality and the free
    /// parameters are refused with it).
    #[arg(long)]
    pub rbvh: Option<PathBuf>,
    /// How a scene whose meshes are placed by instances (a scene file, a glTF file, a built-in
    /// such as grove-instanced) is traced: `two-level` (each mesh held once, a top level over its
    /// placements), `flat` (every placement copied in place), or `auto`: two levels where the
    /// scene places a mesh more than once and the method traces them (exact, rbvh), else flat
    /// (levels of detail, --points, --view and a flat RBVH's --rbvh are flat; a two-level
    /// RBVH's file is traced in two levels). In two levels a hit's id is a triangle of its instance's mesh.
    #[arg(long, value_enum, default_value_t = InstancesArg::Auto)]
    pub instances: InstancesArg,
    /// Vulkan device to use: any part of its name (default: $RBVH_DEVICE, else the best GPU, else lavapipe).
    #[arg(long)]
    pub device: Option<String>,
    /// Run the Vulkan validation layer and fail on any error it reports.
    #[arg(long)]
    pub validate: bool,
    /// Print the scene, the structure (nodes, bytes, build time), the device, and timings and ray
    /// throughput (for an RBVH also the exact BVH's on the same rays).
    #[arg(long)]
    pub stats: bool,
}

/// Where the camera stands, for the commands that make rays from one (`render`, `paint`,
/// `compare`; `trace` takes its rays from a file).
#[derive(Args, Clone, Debug)]
pub struct CameraArgs {
    /// Camera position x,y,z (with --camera-target), for a mesh without a scene file or to
    /// replace the scene's camera; without it, the scene's camera or a framing view.
    #[arg(
        long,
        value_name = "X,Y,Z",
        value_delimiter = ',',
        num_args = 1,
        requires = "camera_target"
    )]
    pub camera_eye: Option<Vec<f32>>,
    /// The point the camera looks at, x,y,z (with --camera-eye).
    #[arg(
        long,
        value_name = "X,Y,Z",
        value_delimiter = ',',
        num_args = 1,
        requires = "camera_eye"
    )]
    pub camera_target: Option<Vec<f32>>,
    /// The direction that is up in the picture, x,y,z (with --camera-eye) [default: 0,1,0]: for a
    /// view along the y axis, which +y cannot roll, say 0,0,-1 looking down.
    #[arg(
        long,
        value_name = "X,Y,Z",
        value_delimiter = ',',
        num_args = 1,
        requires = "camera_eye"
    )]
    pub camera_up: Option<Vec<f32>>,
    /// The camera's vertical field of view in degrees (with --camera-eye) [default: 40].
    #[arg(long, requires = "camera_eye")]
    pub vfov: Option<f32>,
}

impl CameraArgs {
    /// The camera the flags describe, when they describe one (+y up unless --camera-up).
    pub fn camera(&self) -> Result<Option<Camera>> {
        let (Some(eye), Some(target)) = (&self.camera_eye, &self.camera_target) else {
            return Ok(None);
        };
        let point = |flag: &str, v: &[f32]| -> Result<Vec3> {
            anyhow::ensure!(
                v.len() == 3,
                "{flag}: give three numbers x,y,z (got {})",
                v.len()
            );
            Ok(Vec3::from_slice(v))
        };
        let (eye, target) = (
            point("--camera-eye", eye)?,
            point("--camera-target", target)?,
        );
        let up = match &self.camera_up {
            Some(up) => point("--camera-up", up)?,
            None => Vec3::Y,
        };
        let vfov = self.vfov.unwrap_or(DEFAULT_VFOV_DEG);
        Camera::look_at(eye, target, up, vfov)
            .map(Some)
            .map_err(|fault| {
                anyhow::anyhow!("--camera-eye/--camera-target/--camera-up/--vfov: {fault}")
            })
    }
}

/// `--points`: an RBVH of points sampled from the scene, or of a scan of it, refereed by the exact
/// BVH of its triangles.
#[derive(Args, Clone, Debug)]
pub struct PointsArg {
    /// Build the RBVH from points instead of the scene's triangles, which the exact BVH keeps: N
    /// points sampled uniformly over them (with their normals and colours), as from a scan, or a
    /// scan of the same object from a .ply/.xyz file (such as the PLY of the vertices the mesh
    /// was made from).
    #[arg(long, value_name = "N|FILE", value_parser = parse_points)]
    pub points: Option<PointSource>,
}

/// `--points`' value: a count of at least 3, or a file.
fn parse_points(value: &str) -> Result<PointSource, String> {
    match value.parse::<u64>() {
        Ok(count) if count >= MIN_POINTS as u64 && count <= 1 << 30 => {
            Ok(PointSource::Sampled(count as usize))
        }
        Ok(count) => Err(format!(
            "{count} points: sample {MIN_POINTS} to 2^30, or name a .ply/.xyz file"
        )),
        Err(_) => Ok(PointSource::File(PathBuf::from(value))),
    }
}

/// The seed of `--points`' sampling, fixed so that a command line names one RBVH.
pub const POINTS_SEED: u64 = 0x5EED_2012;

impl PointsArg {
    /// `scene` with `--points` added to it, if asked for.
    pub fn apply(&self, scene: &mut Scene) -> Result<()> {
        if let Some(source) = &self.points {
            step(&format!("adding {}", source.label()), |_| {
                scene.add_points(source, POINTS_SEED)
            })
            .context("--points")?;
        }
        Ok(())
    }
}

/// How levels of detail are built and chosen (with `--method rbvh-lod`): see
/// `rbvh::lod::LodParams`.
#[derive(Args, Clone, Debug)]
pub struct LodBuildArgs {
    /// Columns along the longer side of every coarse node's grid.
    #[arg(long, default_value_t = LodParams::default().columns)]
    pub lod_columns: u32,
    /// Fewest leaves below a node for it to get a coarse grid.
    #[arg(long, default_value_t = LodParams::default().min_leaves)]
    pub lod_min_leaves: u32,
    /// A node is chosen where its column is at most 2^bias footprints wide: -1 puts two columns in
    /// a footprint, 0 one (lower: sharper and slower; higher: coarser and faster).
    #[arg(long, default_value_t = LodParams::default().bias, allow_negative_numbers = true)]
    pub lod_bias: f32,
}

impl LodBuildArgs {
    pub fn params(&self) -> LodParams {
        LodParams {
            columns: self.lod_columns,
            min_leaves: self.lod_min_leaves,
            bias: self.lod_bias,
        }
    }
}

/// `--method`: which kind of structure ([`rbvh::structure::Kind`], spelt as bench records spell
/// it), the one value enum of every command's `--method`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Method {
    /// Exact triangle BVH (the referee).
    Exact,
    /// Rasterized BVH at --quality.
    Rbvh,
    /// Rasterized BVH at --quality, traced with level of detail.
    RbvhLod,
}

impl Method {
    /// What it builds with an RBVH level `params` and levels of detail `lod` (each read only by
    /// the kinds that have them).
    pub fn recipe(self, params: RbvhParams, lod: LodParams) -> Recipe {
        match self {
            Method::Exact => Recipe::Exact,
            Method::Rbvh => Recipe::Rbvh(params),
            Method::RbvhLod => Recipe::RbvhLod(params, lod),
        }
    }
}

/// `--instances`: how a scene of instances is traced ([`Instances`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum InstancesArg {
    /// Two levels where the scene places a mesh more than once and the method traces them.
    Auto,
    /// Every placement copied in place: one flat triangle list.
    Flat,
    /// Each mesh held once, a top level over its placements.
    TwoLevel,
}

impl From<InstancesArg> for Instances {
    fn from(a: InstancesArg) -> Instances {
        match a {
            InstancesArg::Auto => Instances::Auto,
            InstancesArg::Flat => Instances::Flat,
            InstancesArg::TwoLevel => Instances::TwoLevel,
        }
    }
}

/// The scene as loaded: flat, or its meshes and placements kept for a two-level structure. One
/// per command, so the variants' sizes do not matter.
#[allow(clippy::large_enum_variant)]
pub enum Loaded {
    Flat(Scene),
    Instanced(InstancedScene),
}

impl Loaded {
    /// What shading, framing and messages read of it.
    pub fn view(&self) -> SceneView<'_> {
        match self {
            Loaded::Flat(scene) => SceneView::Flat(scene),
            Loaded::Instanced(placed) => SceneView::Instanced(placed),
        }
    }
}

use rbvh::structure::Structure;

pub struct Prepared {
    /// The scene, flat or placed by instances (then traced in two levels).
    pub loaded: Loaded,
    /// With `--method rbvh-lod`, the RBVH with its levels of detail.
    pub structure: Structure,
    /// The Vulkan device; none for a CPU trace ([`prepare_cpu`]).
    ctx: Option<Context>,
}

impl Prepared {
    /// The scene traced, flat or placed by instances.
    pub fn scene(&self) -> SceneView<'_> {
        self.loaded.view()
    }

    /// The exact BVH of the same scene, laid out as the structure traced is (flat, or in two
    /// levels): the referee of an RBVH's picture and speed.
    pub fn build_exact(&self, progress: &dyn rbvh::progress::Progress) -> Result<Structure> {
        Ok(match &self.loaded {
            Loaded::Flat(scene) => Structure::build_observed(scene, &Recipe::Exact, progress)?,
            Loaded::Instanced(placed) => {
                Structure::build_instanced(placed, &Recipe::Exact, progress)?
            }
        })
    }

    /// The Vulkan device the structure is traced on.
    pub fn ctx(&self) -> Result<&Context> {
        self.ctx
            .as_ref()
            .context("no Vulkan device was opened: this command traces on the CPU")
    }

    /// The structure uploaded, with its levels of detail when there are any, its bytes counted
    /// on `progress`. Says so on stderr when the structure is too large for storage-buffer
    /// bindings and is read through buffer device addresses instead.
    pub fn tracer(&self, progress: &dyn rbvh::progress::Progress) -> Result<Tracer> {
        let ctx = self.ctx()?;
        let tracer = Tracer::new_observed(ctx, &self.structure, progress)
            .with_context(|| format!("uploading the {}", self.structure.label()))?;
        if tracer.reach() == Reach::DeviceAddresses && ctx.addressing() == Addressing::Auto {
            eprintln!(
                "note: an array of the structure exceeds maxStorageBufferRange ({} bytes); it is \
                 read through buffer device addresses",
                ctx.limits().max_storage_buffer_range
            );
        }
        Ok(tracer)
    }

    /// Traces `rays` through `tracer` (from [`Prepared::tracer`]), counting them on `progress`;
    /// `cones` are their footprints (read with level of detail).
    pub fn trace(
        &self,
        tracer: &Tracer,
        rays: &[Ray],
        cones: Cones,
        query: Query,
        counters: bool,
        progress: &dyn rbvh::progress::Progress,
    ) -> Result<Traced> {
        Ok(tracer.trace_observed(rays, cones, query, counters, progress)?)
    }

    /// The CPU reference of [`Prepared::trace`].
    pub fn trace_cpu(&self, rays: &[Ray], cones: Cones, any_hit: bool) -> Result<Vec<Hit>> {
        Ok(self.structure.trace_cpu(rays, cones, any_hit)?)
    }
}

/// The device the user named (`--device`, else `RBVH_DEVICE`), with validation required by
/// `--validate` or set by `RBVH_VALIDATION`, and addressing set by `RBVH_ADDRESSING`.
pub fn context_options(device: Option<&str>, validate: bool) -> Result<ContextOptions> {
    Ok(ContextOptions {
        device_name: device
            .map(str::to_string)
            .or_else(|| ContextOptions::default().device_name),
        validation: if validate {
            Validation::Required
        } else {
            Validation::from_env()?
        },
        addressing: Addressing::from_env()?,
    })
}

/// Checks an image size given by `--width` and `--height`.
pub fn check_image_size(width: u32, height: u32) -> Result<()> {
    anyhow::ensure!(
        (1..=16384).contains(&width) && (1..=16384).contains(&height),
        "--width and --height must be within 1..=16384 (got --width {width} --height {height})"
    );
    Ok(())
}

/// `--view` refines an RBVH of triangles for the scene's camera: refused, naming the scene, where
/// it has none (the RBVH would be the preset's, named as refined) or the RBVH is built from
/// points (`--points`, or a point cloud's file).
pub fn check_view(scene: &str, has_camera: bool, points: bool) -> Result<()> {
    anyhow::ensure!(
        has_camera,
        "--view refines for the scene's camera, and {scene:?} has none: give it one ([camera] in \
         a scene file, or --camera-eye and --camera-target where the command takes them)"
    );
    anyhow::ensure!(
        !points,
        "--view refines triangles for the scene's camera, and the RBVH of {scene:?} is built from \
         points"
    );
    Ok(())
}

/// `spec` loaded flat, as [`Scene::load_observed`] loads it: a scene file's instances flattened
/// once they are known to fit in host memory ([`InstancedScene::into_flat_checked`]), so that a
/// scene of instances too large to copy in place (`scenes/dragons-1000.toml`) is refused by name
/// rather than killed by the system part way.
pub fn load_flat(spec: &str, progress: &dyn rbvh::progress::Progress) -> Result<Scene> {
    Scene::load_observed(spec, progress).map_err(flag_error)
}

/// The scene `c` names, kept in instances or flattened as `--instances` says ([`Instances`]):
/// a scene that may place meshes (a scene file, a glTF file, a built-in scene) is loaded with
/// its instances, and kept so where it places a mesh more than once (or two levels are asked
/// for) and the method traces two levels; anything else is loaded flat ([`load_flat`]). Each is
/// decoded once: a glTF file's nodes say whether it repeats a mesh before either loader decodes
/// its buffers ([`InstancedScene::would_repeat_a_mesh`], which reads its JSON).
fn load(c: &Common, progress: &dyn rbvh::progress::Progress) -> Result<Loaded> {
    let spec = c.source.scene.as_str();
    // A saved two-level RBVH is traced with the scene of instances it was built from.
    let two_level_rbvh = match &c.source.rbvh {
        Some(path) => two_level_file(path)?.then_some(path),
        None => None,
    };
    if let Some(path) = two_level_rbvh {
        anyhow::ensure!(
            c.source.points.points.is_none(),
            "--points: {} holds a two-level RBVH of the scene's triangles; an RBVH of points is \
             flat (build one with rbvh build --points ... --out)",
            path.display()
        );
        anyhow::ensure!(
            Instances::from(c.source.instances) != Instances::Flat,
            "--instances flat: {} holds a two-level RBVH, traced over the scene's instances",
            path.display()
        );
        anyhow::ensure!(
            c.structures.method()? != Method::RbvhLod,
            "--method rbvh-lod: levels of detail are built over a flat RBVH, and {} holds a \
             two-level one",
            path.display()
        );
        let placed = InstancedScene::load_observed(spec, progress).map_err(flag_error)?;
        placed.validate().map_err(flag_error)?;
        return Ok(Loaded::Instanced(placed));
    }
    let flat_for = if c.structures.method()? == Method::RbvhLod {
        Some("--method rbvh-lod (levels of detail are built over a flat RBVH)")
    } else if c.structures.quality.view.is_some() {
        Some("--view (an RBVH refined for one view is built over the flat scene)")
    } else if c.source.points.points.is_some() {
        Some("--points (the RBVH of points sampled from, or scanned of, the flat scene)")
    } else if c.source.rbvh.is_some() {
        Some("--rbvh with a flat RBVH's file")
    } else {
        None
    };
    let instances = Instances::from(c.source.instances);
    match (instances, flat_for) {
        (Instances::TwoLevel, Some(why)) => anyhow::bail!(
            "--instances two-level: {why} traces the scene flat; give --instances flat or auto"
        ),
        (Instances::Flat, _) | (Instances::Auto, Some(_)) => {
            return Ok(Loaded::Flat(load_flat(spec, progress)?))
        }
        _ => {}
    }
    let extension = std::path::Path::new(spec)
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    let may_place = match extension.as_deref() {
        Some("toml" | "gltf" | "glb") => true,
        Some(_) => false,
        None => Scene::check(spec).is_ok() && !spec.contains(['/', '\\']),
    };
    // Under `auto`, a glTF file whose nodes share no mesh (told from its nodes alone) is
    // decoded once, flat.
    if instances == Instances::Auto
        && (!may_place
            || InstancedScene::would_repeat_a_mesh(spec).map_err(flag_error)? == Some(false))
    {
        return Ok(Loaded::Flat(load_flat(spec, progress)?));
    }
    let placed = InstancedScene::load_observed(spec, progress).map_err(flag_error)?;
    if instances == Instances::TwoLevel || placed.repeats_a_mesh() {
        placed.validate().map_err(flag_error)?;
        return Ok(Loaded::Instanced(placed));
    }
    Ok(Loaded::Flat(match extension.as_deref() {
        Some("toml") => flatten(placed)?,
        // A built-in scene that places nothing is the scene `InstancedScene::single` wraps;
        // anything else is loaded flat by its own loader, as without instances.
        _ => match placed.into_single() {
            Some(scene) if extension.is_none() => scene,
            _ => load_flat(spec, progress)?,
        },
    }))
}

/// Whether the RBVH file at `path` holds a two-level RBVH, from its section table alone
/// ([`rbvh::rbvh::file::holds_instances`]: false for bytes that are no RBVH file, which its
/// loader then refuses by name); an error naming it where it cannot be read.
pub fn two_level_file(path: &std::path::Path) -> Result<bool> {
    rbvh::rbvh::file::holds_instances(path)
        .with_context(|| format!("reading RBVH {}", path.display()))
}

/// `placed` flattened once it is known to fit in host memory
/// ([`InstancedScene::check_flat_fits`]), and checked.
fn flatten(placed: InstancedScene) -> Result<Scene> {
    placed.into_flat_checked().map_err(flag_error)
}

/// The scene, its structure and the device, as `c` says; `camera` (from [`CameraArgs`]) replaces
/// the scene's camera when given.
pub fn prepare(c: &Common, camera: Option<Camera>) -> Result<Prepared> {
    prepare_on(c, camera, true)
}

/// [`prepare`] for a trace on the CPU: no Vulkan device is opened, so none is needed.
pub fn prepare_cpu(c: &Common) -> Result<Prepared> {
    prepare_on(c, None, false)
}

fn prepare_on(c: &Common, camera: Option<Camera>, device: bool) -> Result<Prepared> {
    let t = Instant::now();
    let method = c.structures.method()?;
    // Every parameter before the scene is loaded and anything built (which may take minutes).
    if c.source.rbvh.is_none() {
        c.structures.recipe()?.validate().map_err(flag_error)?;
    } else if method == Method::RbvhLod {
        c.structures.lod.params().validate().map_err(flag_error)?;
    }
    let loaded = step("loading scene", |bar| load(c, bar))
        .with_context(|| format!("loading scene {:?}", c.source.scene))?;
    let mut scene = match loaded {
        Loaded::Flat(scene) => scene,
        Loaded::Instanced(placed) => return prepare_instanced(c, placed, camera, device, t),
    };
    anyhow::ensure!(
        c.source.points.points.is_none() || method != Method::Exact || c.source.rbvh.is_some(),
        "--points builds the RBVH from points: add --method rbvh (the exact BVH traces the triangles)"
    );
    if camera.is_some() {
        scene.camera = camera;
    }
    if c.structures.quality.view.is_some() {
        check_view(
            &c.source.scene,
            scene.camera.is_some(),
            c.source.points.points.is_some() || scene.points.is_some(),
        )?;
    }
    c.source.points.apply(&mut scene)?;
    let load_ms = t.elapsed().as_secs_f64() * 1e3;
    if let Some(warning) = scene.precision_warning() {
        eprintln!("warning: {warning}");
    }
    let t = Instant::now();
    let structure = match &c.source.rbvh {
        Some(path) => {
            let r = step("loading RBVH", |_| Rbvh::load(path))
                .with_context(|| format!("loading RBVH {}", path.display()))?;
            r.check_built_from(&scene).with_context(|| {
                format!("RBVH {} with scene {:?}", path.display(), c.source.scene)
            })?;
            if scene.surface.is_some()
                && r.colours.is_none()
                && r.params.texels == TexelFormat::HeightNormal
            {
                eprintln!(
                    "warning: {} has materials but the RBVH file has no colour channel: its \
                     height-field surfaces show white (rebuild it from this scene to bake colours)",
                    scene.name
                );
            }
            Structure::from(r)
        }
        None if method == Method::Exact
            && scene.triangle_count() == 0
            && scene.points.is_some() =>
        {
            anyhow::bail!(
                "{} is a point cloud: there are no triangles for the exact BVH; trace it with --method rbvh",
                scene.name
            )
        }
        None => {
            // The levels of detail are built below, for a loaded RBVH as for a built one.
            let recipe = match c.structures.recipe()? {
                Recipe::RbvhLod(params, _) => Recipe::Rbvh(params),
                recipe => recipe,
            };
            let what = match recipe {
                Recipe::Exact => "building BVH",
                _ => "building RBVH",
            };
            step(what, |bar| {
                Structure::build_observed(&scene, &recipe, bar).map_err(flag_error)
            })?
        }
    };
    let structure_ms = t.elapsed().as_secs_f64() * 1e3;
    let structure = if method == Method::RbvhLod {
        let params = c.structures.lod.params();
        step("building levels of detail", |_| {
            structure.with_levels(&params).map_err(flag_error)
        })?
    } else {
        structure
    };
    let ctx = open_device(c, device)?;
    if c.source.stats {
        eprintln!(
            "scene {}: {} triangles, {} points, loaded in {load_ms:.1} ms",
            scene.name,
            scene.triangle_count(),
            scene.point_count()
        );
        report_structure(c, &structure, structure_ms, ctx.as_ref());
    }
    Ok(Prepared {
        loaded: Loaded::Flat(scene),
        structure,
        ctx,
    })
}

/// [`prepare`] of a scene kept in instances: its two-level structure.
fn prepare_instanced(
    c: &Common,
    mut placed: InstancedScene,
    camera: Option<Camera>,
    device: bool,
    loading: Instant,
) -> Result<Prepared> {
    if camera.is_some() {
        placed.camera = camera;
    }
    let load_ms = loading.elapsed().as_secs_f64() * 1e3;
    let t = Instant::now();
    let structure = match &c.source.rbvh {
        Some(path) => {
            let mut two = step("loading RBVH", |_| InstancedRbvh::load(path))
                .with_context(|| format!("loading RBVH {}", path.display()))?;
            two.check_built_from(&placed).with_context(|| {
                format!("RBVH {} with scene {:?}", path.display(), c.source.scene)
            })?;
            Structure::from(two)
        }
        None => {
            let recipe = c.structures.recipe()?;
            let what = match recipe {
                Recipe::Exact => "building the two-level BVH",
                _ => "building the two-level RBVH",
            };
            step(what, |bar| {
                Structure::build_instanced(&placed, &recipe, bar).map_err(flag_error)
            })?
        }
    };
    let structure_ms = t.elapsed().as_secs_f64() * 1e3;
    let ctx = open_device(c, device)?;
    if c.source.stats {
        eprintln!(
            "scene {}: {} instances of {} meshes, {} triangles as placed ({} held), loaded in \
             {load_ms:.1} ms",
            placed.name,
            placed.instances.len(),
            placed.meshes.len(),
            placed.placed_triangle_count(),
            placed.stored_triangle_count()
        );
        report_structure(c, &structure, structure_ms, ctx.as_ref());
    }
    Ok(Prepared {
        loaded: Loaded::Instanced(placed),
        structure,
        ctx,
    })
}

/// The Vulkan device `c` names, when the command traces on one.
fn open_device(c: &Common, device: bool) -> Result<Option<Context>> {
    if !device {
        return Ok(None);
    }
    let options = context_options(c.source.device.as_deref(), c.source.validate)?;
    Ok(Some(
        Context::new(&options).context("creating the Vulkan device")?,
    ))
}

/// `--stats` of the structure built or loaded in `structure_ms`: its nodes, leaves and bytes,
/// its levels of detail, and the host and device it runs on.
fn report_structure(c: &Common, structure: &Structure, structure_ms: f64, ctx: Option<&Context>) {
    {
        match structure {
            Structure::Exact(bvh) => eprintln!(
                "exact BVH: {} nodes, depth {}, built in {:.1} ms, {} + {} bytes (tree + triangles)",
                bvh.nodes.len(),
                bvh.depth,
                bvh.build_ms,
                bvh.tree_bytes(),
                bvh.triangle_bytes()
            ),
            Structure::ExactInstanced(bvh) => eprintln!(
                "two-level exact BVH: {} instances of {} meshes, {} nodes (top level {}, depth {}), \
                 built in {:.1} ms, {} + {} + {} bytes (tree + triangles + instances)",
                bvh.instances.len(),
                bvh.meshes.len(),
                bvh.nodes.len(),
                bvh.top_nodes,
                bvh.top_depth,
                bvh.build_ms,
                bvh.tree_bytes(),
                bvh.triangle_bytes(),
                bvh.instance_bytes()
            ),
            Structure::RbvhInstanced(two) => eprintln!(
                "two-level RBVH: {} instances of {} meshes, top level {} nodes (depth {}), {} \
                 height-field + {} triangle leaves, built in {:.1} ms, {} bytes (tree {}, atlas {}, \
                 triangles {}, instances {})",
                two.instances.len(),
                two.meshes.len(),
                two.top_nodes,
                two.top_depth,
                two.stats().heightfield_leaves,
                two.stats().triangle_leaves,
                two.stats().build_ms,
                two.total_bytes(),
                two.tree_bytes(),
                two.atlas_bytes(),
                two.triangle_bytes(),
                two.instance_bytes()
            ),
            Structure::Rbvh(r) | Structure::RbvhLod(r, _) => eprintln!(
                "RBVH: {} nodes, {} height-field + {} triangle leaves, depth {}, {}, {} bytes (tree {}, atlas {}, triangles {})",
                r.nodes.len(),
                r.stats.heightfield_leaves,
                r.stats.triangle_leaves,
                r.depth,
                match &c.source.rbvh {
                    Some(path) => format!(
                        "loaded from {} in {structure_ms:.1} ms (built in {:.1} ms when it was made)",
                        path.display(),
                        r.stats.build_ms
                    ),
                    None => format!("built in {:.1} ms", r.stats.build_ms),
                },
                r.total_bytes(),
                r.tree_bytes(),
                r.atlas_bytes(),
                r.triangle_bytes()
            ),
        }
        if let Some(lod) = structure.lod() {
            eprintln!(
                "levels of detail: {} coarse nodes, {} columns, built in {:.1} ms, {} bytes",
                lod.stats.coarse_nodes,
                lod.stats.columns,
                lod.stats.build_ms,
                lod.bytes()
            );
        }
        // The line the bench prints above its tables: host, device, driver, commit and date.
        if let Some(ctx) = ctx {
            eprintln!("{}", Provenance::of(ctx).line());
        }
    }
}
