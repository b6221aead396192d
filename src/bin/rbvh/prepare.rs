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
