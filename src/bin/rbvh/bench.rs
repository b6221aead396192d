//! `rbvh bench`: speed, memory and accuracy of the exact BVH and RBVH levels on the same rays,
//! as a table, JSON, CSV, charts and error images (the library's `rbvh::bench`).

use std::path::PathBuf;

use crate::outputs::{self, output};
use crate::progress::Bar;
use anyhow::{Context as _, Result};
use rbvh::bench::{self, BenchConfig, BenchReport, Device, Event, RayType};
use rbvh::gpu::Context;
use rbvh::scene::PointSource;

use crate::flags::{flag_error, Given};
use crate::prepare::{context_options, InstancesArg, Method, PointsArg, Structures};

#[derive(clap::Args, Debug)]
#[command(mut_arg("quality", |a| a.default_value("all")))]
#[command(mut_arg("method", |a| a.default_value("exact,rbvh").help(
    "Structures to measure, comma-separated: `exact` (the exact triangle BVH: always measured, \
     it is the referee of every other; for a scene with instances (a scene file's [[instance]] \
     tables, a glTF's nodes sharing a mesh, `grove-instanced`) its two-level exact BVH, \
     `exact-instanced`, is measured beside it), `rbvh` (every --quality level in every --texels \
     format; for a scene with instances each level in two levels too, `rbvh-instanced`), \
     `rbvh-lod` (each level with normals traced with level of detail: primary rays with their \
     pixel's cone, secondary rays with its spread from their origin)"
)))]
pub struct Args {
    /// Scenes: built-in names, OBJ/glTF/GLB files or scene files (.toml); repeat or comma-separate.
    #[arg(long, default_value = "default", value_delimiter = ',')]
    scene: Vec<String>,
    #[command(flatten)]
    structures: Structures,
    #[command(flatten)]
    points: PointsArg,
    /// How a scene with instances is measured: `auto` (flat and in two levels, and in two levels
    /// alone, refereed by the two-level exact BVH, where the flat copy would not fit the host's
    /// memory; flat alone with --points, whose RBVHs are built over the flat scene), `flat` (flat
    /// alone), `two-level` (in two levels alone; not with --points, rbvh-lod or --steps).
    #[arg(long, value_enum, default_value_t = InstancesArg::Auto)]
    instances: InstancesArg,
    /// Ray types to trace, comma-separated: primary, ao, shadow, diffuse.
    #[arg(
        long,
        default_value = "primary,ao,shadow,diffuse",
        value_delimiter = ','
    )]
    rays: Vec<RayType>,
    /// Primary-ray image width (secondary rays start at its exact hits).
    #[arg(long, default_value_t = 256)]
    width: u32,
    /// Primary-ray image height.
    #[arg(long, default_value_t = 256)]
    height: u32,
    /// Timed runs per method and ray type, after one warm-up.
    #[arg(long, default_value_t = 5)]
    runs: u32,
    /// Shortest timed run (ms): a faster trace is repeated back to back within each run, so that a fast GPU is timed busy; 0: one pass per run.
    #[arg(long, default_value_t = 20.0)]
    min_run_ms: f64,
    /// Ambient-occlusion ray length, as a fraction of the scene's bounding-box diagonal (for ao
    /// rays: refused when --rays has none).
    #[arg(long, default_value_t = 0.05)]
    ao_radius: f32,
    /// Seed of the random directions of ao and diffuse rays, of the seam rays and of --points N's
    /// samples (default: a fixed seed, so runs repeat; refused where none of them is traced).
    #[arg(long)]
    seed: Option<u64>,
    /// Lavapipe worker threads (sets LP_NUM_THREADS; default: Mesa's, one per CPU). Refused on
    /// other devices, which do not read it.
    #[arg(long)]
    threads: Option<u32>,
    /// Vulkan device to use: any part of its name (default: $RBVH_DEVICE, else the best GPU, else lavapipe).
    #[arg(long)]
    device: Option<String>,
    /// Run the Vulkan validation layer and fail on any error it reports.
    #[arg(long)]
    validate: bool,
    /// Write the report as JSON (schema in docs/benchmarks.md).
    #[arg(long)]
    json: Option<PathBuf>,
    /// Write the records as CSV.
    #[arg(long)]
    csv: Option<PathBuf>,
    /// Write per-scene charts (SVG) and renders and error images (PNG) under this directory.
    #[arg(long)]
    plot: Option<PathBuf>,
    /// Also model each method's memory traffic from its CPU twin's reads: cache lines per ray,
    /// working set, DRAM bytes per ray behind 4, 32 and 72 MiB caches (slower: a CPU trace each).
    #[arg(long)]
    traffic: bool,
    /// Also say where each ray's steps go, from the CPU twins of the exact BVH and each RBVH
    /// level traced without level of detail (flat structures: not the two-level ones, not
    /// rbvh-lod): inner nodes by tree depth, the leaves handed to the march by what came of them
    /// (tile box missed, no surface met, surface behind the nearest hit, the nearest), and the
    /// leaf boxes holding a hit's point (slower: a CPU trace each).
    #[arg(long)]
    steps: bool,
    /// Rays aimed at each RBVH level's seams between leaves (their rims and corners), traced by
    /// the CPU twins of the level and of the exact BVH: the `leaks` column counts those that
    /// passed through the surface, `through` those of them that passed through the solid as
    /// well (light through a closed object for shadow and AO rays). 0: skip.
    #[arg(long, default_value_t = 100_000)]
    seam_rays: usize,
    /// Block jumps in the RBVH march: on or off (default: off on CPU implementations such as
    /// lavapipe, on elsewhere). The hits are the same; to measure what they are worth on a device.
    #[arg(long, value_name = "on|off", hide_possible_values = true,
          value_parser = clap::builder::BoolishValueParser::new())]
    block_jumps: Option<bool>,
    /// Exit 0 even when a measurement is INVALID (its hits wrong rather than approximate); by
    /// default the command then fails, after writing the table, JSON, CSV and charts.
    #[arg(long)]
    allow_invalid: bool,
}

pub fn run(a: Args, given: &Given) -> Result<()> {
    a.structures.check(given, false)?;
    let inputs: Vec<outputs::Named> = a
        .scene
        .iter()
        .flat_map(|scene| outputs::scene_inputs(scene, a.points.points.as_ref()))
        .collect();
    outputs::check(
        &[
            output("--json", a.json.as_deref(), "json"),
            output("--csv", a.csv.as_deref(), "csv"),
        ],
        &inputs,
    )?;
    // Found only once every scene was measured, a --plot that is a file lost the whole run.
    if let Some(plot) = a.plot.as_deref().filter(|p| p.exists() && !p.is_dir()) {
        anyhow::bail!(
            "--plot {}: a file is there; --plot names the folder the charts go to",
            plot.display()
        );
    }
    let (plain, lod) = (
        a.structures.has(Method::Rbvh),
        a.structures.has(Method::RbvhLod),
    );
    anyhow::ensure!(
        plain || lod,
        "--method exact: bench measures RBVHs beside the exact BVH (which it always measures, \
         the referee); add rbvh or rbvh-lod"
    );
    anyhow::ensure!(
        plain || !given.has("seam_rays"),
        "--seam-rays aims at the seams of the levels traced without level of detail, and \
         --method measures none: add rbvh to --method"
    );
    if a.instances == InstancesArg::TwoLevel {
        anyhow::ensure!(
            !a.steps,
            "--steps: where steps go is counted by the flat structures' CPU twins, and \
             --instances two-level measures none: give --instances auto or flat"
        );
        anyhow::ensure!(
            !lod,
            "--method rbvh-lod: levels of detail are built over a flat RBVH, and --instances \
             two-level measures none: measure rbvh instead of rbvh-lod, or give --instances auto \
             or flat"
        );
    }
    anyhow::ensure!(
        !given.has("ao_radius") || a.rays.contains(&RayType::Ao),
        "--ao-radius is the length of ambient-occlusion rays, and --rays traces none: add ao to \
         --rays"
    );
    let seeded = a.rays.contains(&RayType::Ao)
        || a.rays.contains(&RayType::Diffuse)
        || (plain && a.seam_rays > 0)
        || matches!(a.points.points, Some(PointSource::Sampled(_)));
    anyhow::ensure!(
        !given.has("seed") || seeded,
        "--seed draws the directions of ao and diffuse rays, the seam rays (of the levels rbvh \
         measures) and --points N's samples, and this run has none of them: add ao or diffuse \
         to --rays{}",
        if plain && a.seam_rays == 0 {
            ", or give --seam-rays more than 0"
        } else {
            ""
        }
    );
    if let Some(threads) = a.threads {
        anyhow::ensure!(threads >= 1, "--threads must be at least 1");
        // Mesa reads LP_NUM_THREADS when the Vulkan device is created, so it must be set before
        // that. It is set here, first, while the process is still single-threaded: nothing has
        // started rayon's pool or the driver's threads yet, and setenv racing a getenv in another
        // thread is undefined behaviour in C.
        std::env::set_var("LP_NUM_THREADS", threads.to_string());
    }
    let quality = &a.structures.quality;
    let levels = quality.quality_levels()?;
    let options = context_options(a.device.as_deref(), a.validate)?;
    let device = match a.threads {
        None => Device::Create(options),
        // Only lavapipe reads LP_NUM_THREADS: the device is made here, after it is set, to say
        // so before anything is measured on another.
        Some(_) => {
            let ctx = Context::new(&options).context("creating the Vulkan device")?;
            anyhow::ensure!(
                ctx.device_name().contains("llvmpipe"),
                "--threads sets lavapipe's worker threads (LP_NUM_THREADS), and {} does not read \
                 it: drop --threads",
                ctx.device_name()
            );
            Device::Existing(ctx)
        }
    };
    let mut config = BenchConfig::new(
        a.scene.iter().map(|s| s.trim().to_string()).collect(),
        device,
    );
    config.levels = levels;
    config.texels = quality.texel_formats();
    anyhow::ensure!(
        plain || !config.texels.contains(&rbvh::rbvh::TexelFormat::Height),
        "--texels height builds levels only --method rbvh measures (a height-only level has no \
         level of detail): add rbvh to --method"
    );
    anyhow::ensure!(
        !lod || config
            .texels
            .contains(&rbvh::rbvh::TexelFormat::HeightNormal),
        "--method rbvh-lod measures levels with normals in their texels, and --texels height \
         builds none: add normals to --texels (--texels normals,height) or drop rbvh-lod"
    );
    config.ray_types = a.rays.clone();
    config.width = a.width;
    config.height = a.height;
    config.runs = a.runs;
    config.min_run_ms = a.min_run_ms;
    config.ao_radius = a.ao_radius;
    if let Some(seed) = a.seed {
        config.seed = seed;
    }
    config.plot_dir = a.plot.clone();
    config.plain = plain;
    config.lod = lod.then(|| a.structures.lod.params());
    config.traffic = a.traffic;
    config.steps = a.steps;
    config.seam_rays = a.seam_rays;
    config.block_jumps = a.block_jumps;
    config.points = a.points.points.clone();
    config.instances = a.instances.into();

    let bar = Bar::new("benchmark");
    let result = bench::run_keeping(
        &config,
        &mut |event| match event {
            Event::Progress(what) => bar.set_label(what),
            Event::Warning(what) if what.starts_with("INVALID") => {
                bar.println(&format!("!!!!!!!! {what}"))
            }
            Event::Warning(what) => bar.println(&format!("warning: {what}")),
        },
        &bar,
    );
    bar.finish();
    let (report, stopped) = result.map_err(flag_error).context("benchmark")?;
    let written = report_and_write(&report, &a);
    let Some(error) = stopped else {
        let invalid = written?;
        anyhow::ensure!(
            invalid == 0 || a.allow_invalid,
            "{invalid} measurement(s) INVALID (--allow-invalid to exit 0 all the same)"
        );
        return Ok(());
    };
    let mut measured: Vec<&str> = report.results.iter().map(|r| r.scene.as_str()).collect();
    measured.dedup();
    let kept = match (
        &written,
        a.json.is_some() || a.csv.is_some() || a.plot.is_some(),
    ) {
        (Err(e), _) => format!("shown above, but writing them failed: {e:#}"),
        (Ok(_), true) => "shown and written above".to_string(),
        (Ok(_), false) => "shown above (--json, --csv or --plot keeps them)".to_string(),
    };
    Err(flag_error(error)).context(format!(
        "benchmark stopped: the results of the scene(s) measured before ({}: {} records) are {kept}",
        measured.join(", "),
        report.results.len()
    ))
}

/// Prints `report`'s tables and writes the files `a` asks for; returns the invalid
/// measurements' count.
fn report_and_write(report: &BenchReport, a: &Args) -> Result<usize> {
    print!("{}", bench::table(report));
    println!();
    print!("{}", bench::work_table(report));
    let steps = bench::steps_table(report);
    if !steps.is_empty() {
        println!();
        print!("{steps}");
    }
    print!("{}", bench::shader_table(report));
    let invalid = report.results.iter().filter(|r| !r.valid).count();
    if invalid > 0 {
        eprintln!(
            "!!!!!!!! {invalid} measurement(s) INVALID: their hits are wrong (see above); their speeds mean nothing"
        );
    }
    if let Some(path) = &a.json {
        bench::write_json(path, report)?;
        eprintln!("wrote {}", path.display());
    }
    if let Some(path) = &a.csv {
        bench::write_csv(path, report)?;
        eprintln!("wrote {}", path.display());
    }
    for path in &report.written {
        eprintln!("wrote {}", path.display());
    }
    Ok(invalid)
}
