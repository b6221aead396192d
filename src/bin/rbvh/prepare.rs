//! What every command does first: pick the device, load the scene, build the acceleration
//! structure — with a spinner on long steps (hidden when stderr is not a terminal).

use std::time::{Duration, Instant};

use anyhow::{Context as _, Result};
use clap::{Args, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};
use rbvh::bvh::Bvh;
use rbvh::gpu::{Context, ContextOptions, Validation};
use rbvh::scene::Scene;

/// Options shared by the commands that trace.
#[derive(Args, Clone, Debug)]
pub struct Common {
    /// Built-in scene name, OBJ/glTF/GLB file, or scene file (.toml).
    #[arg(long, default_value = "default")]
    pub scene: String,
    /// Acceleration structure to trace through.
    #[arg(long, value_enum, default_value_t = Method::Exact)]
    pub method: Method,
    /// Vulkan device to use: any part of its name (default: $RBVH_DEVICE, else the best GPU, else lavapipe).
    #[arg(long)]
    pub device: Option<String>,
    /// Run the Vulkan validation layer and fail on any error it reports.
    #[arg(long)]
    pub validate: bool,
    /// Print timings and ray throughput.
    #[arg(long)]
    pub stats: bool,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Method {
    /// Exact triangle BVH (the reference).
    Exact,
}

pub struct Prepared {
    pub scene: Scene,
    pub bvh: Bvh,
    pub ctx: Context,
}

/// Runs `f` under a spinner labelled `what`.
pub fn step<T>(what: &str, f: impl FnOnce() -> T) -> T {
    let bar = ProgressBar::new_spinner().with_message(what.to_string());
    bar.set_style(
        ProgressStyle::with_template("{spinner} {msg} {elapsed}").expect("static template"),
    );
    bar.enable_steady_tick(Duration::from_millis(120));
    let out = f();
    bar.finish_and_clear();
    out
}

pub fn prepare(c: &Common) -> Result<Prepared> {
    let t = Instant::now();
    let scene = step("loading scene", || Scene::load(&c.scene))
        .with_context(|| format!("loading scene {:?}", c.scene))?;
    let load_ms = t.elapsed().as_secs_f64() * 1e3;
    let bvh = step("building BVH", || Bvh::build(&scene))?;
    let ctx = Context::new(&ContextOptions {
        device_name: c
            .device
            .clone()
            .or_else(|| ContextOptions::default().device_name),
        validation: if c.validate {
            Validation::Required
        } else {
            Validation::from_env()
        },
    })
    .context("creating the Vulkan device")?;
    if c.stats {
        eprintln!(
            "scene {}: {} triangles, loaded in {load_ms:.1} ms; BVH {} nodes, depth {}, built in {:.1} ms; {} + {} bytes",
            scene.name,
            scene.triangle_count(),
            bvh.nodes.len(),
            bvh.depth,
            bvh.build_ms,
            bvh.tree_bytes(),
            bvh.triangle_bytes()
        );
        eprintln!("device: {} ({})", ctx.device_name(), ctx.driver());
    }
    Ok(Prepared { scene, bvh, ctx })
}

/// Prints throughput of the GPU trace and of the CPU reference on the same rays, and their ratio.
pub fn print_throughput(rays: usize, gpu_ms: Option<f64>, wall_ms: f64, cpu_ms: f64) {
    let mrays = |ms: f64| rays as f64 / (ms * 1e3);
    match gpu_ms {
        Some(g) => eprintln!(
            "trace: {rays} rays, GPU {g:.2} ms = {:.2} MRays/s (wall {wall_ms:.2} ms); CPU reference {cpu_ms:.2} ms = {:.2} MRays/s; GPU/CPU = {:.2}x",
            mrays(g),
            mrays(cpu_ms),
            cpu_ms / g
        ),
        None => eprintln!(
            "trace: {rays} rays, wall {wall_ms:.2} ms = {:.2} MRays/s (no GPU timestamps); CPU reference {:.2} MRays/s",
            mrays(wall_ms),
            mrays(cpu_ms)
        ),
    }
}

/// RBVH quality: presets, optionally adjusted by free parameters (which make the level "custom").
#[derive(Args, Clone, Debug)]
pub struct Quality {
    /// Quality preset(s): 0..4 or Q0..Q4 (Q0 coarsest, Q4 finest), comma-separated, or `all`.
    #[arg(long, default_value = "2", value_delimiter = ',')]
    pub quality: Vec<String>,
    /// Free parameter: sampling rate in texels along the scene's bounding-box diagonal.
    #[arg(long)]
    pub texels_per_diagonal: Option<f32>,
    /// Free parameter: cone-of-normals criterion with this maximum angle to the axis (degrees).
    #[arg(long, conflicts_with = "min_area_ratio")]
    pub max_angle: Option<f32>,
    /// Free parameter: projected-area criterion A⊥/A ≥ this ratio.
    #[arg(long)]
    pub min_area_ratio: Option<f32>,
    /// Free parameter: where to split.
    #[arg(long, value_enum)]
    pub split: Option<SplitArg>,
    /// Free parameter: allow fusing separate parts into one height field.
    #[arg(long)]
    pub no_object_split: bool,
    /// Free parameter: most samples per tile side.
    #[arg(long)]
    pub max_tile: Option<u32>,
    /// Free parameter: unrepresentable sets smaller than this many texels stay triangles.
    #[arg(long)]
    pub min_leaf_texels: Option<f32>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum SplitArg {
    /// Middle of the longest axis.
    Median,
    /// The paper's modified (surface-area weighted) SAH.
    Sah,
}

impl Quality {
    fn is_custom(&self) -> bool {
        self.texels_per_diagonal.is_some()
            || self.max_angle.is_some()
            || self.min_area_ratio.is_some()
            || self.split.is_some()
            || self.no_object_split
            || self.max_tile.is_some()
            || self.min_leaf_texels.is_some()
    }

    /// The requested levels, named `Q0`…`Q4` (or `custom` when free parameters change a preset),
    /// each validated.
    pub fn levels(&self) -> Result<Vec<(String, rbvh::rbvh::RbvhParams)>> {
        use rbvh::rbvh::{RbvhParams, Refinement, Subdivision};
        let mut levels = Vec::new();
        for q in &self.quality {
            let q = q.trim();
            if q.eq_ignore_ascii_case("all") {
                levels.extend(0..5);
                continue;
            }
            let digits = q.strip_prefix(['Q', 'q']).unwrap_or(q);
            let level: u32 = digits.parse().ok().filter(|l| *l <= 4).ok_or_else(|| {
                anyhow::anyhow!("--quality {q:?} is not a preset: use 0..4, Q0..Q4 or all")
            })?;
            levels.push(level);
        }
        anyhow::ensure!(!levels.is_empty(), "--quality names no level");
        anyhow::ensure!(
            !self.is_custom() || levels.len() == 1,
            "free parameters adjust one preset: give a single --quality with them"
        );
        levels
            .into_iter()
            .map(|level| {
                let mut p = RbvhParams::quality(level)?;
                if let Some(r) = self.texels_per_diagonal {
                    p.texels_per_diagonal = r;
                }
                if let Some(a) = self.max_angle {
                    p.refinement = Refinement::NormalCone { max_angle_deg: a };
                }
                if let Some(r) = self.min_area_ratio {
                    p.refinement = Refinement::ProjectedArea { min_ratio: r };
                }
                if let Some(s) = self.split {
                    p.subdivision = match s {
                        SplitArg::Median => Subdivision::SpatialMedian,
                        SplitArg::Sah => Subdivision::AreaSah,
                    };
                }
                if self.no_object_split {
                    p.object_split = false;
                }
                if let Some(m) = self.max_tile {
                    p.max_tile = m;
                }
                if let Some(m) = self.min_leaf_texels {
                    p.min_leaf_texels = m;
                }
                p.validate()?;
                let name = if self.is_custom() {
                    "custom".to_string()
                } else {
                    format!("Q{level}")
                };
                Ok((name, p))
            })
            .collect()
    }
}
