//! `rbvh regress`: render the regression cases and compare them with the goldens (or, with
//! `--bless`, replace the goldens), print a table, and fail when any case fails.

use std::path::PathBuf;

use anyhow::{bail, ensure, Context as _, Result};
use rbvh::gpu::Context;
use rbvh::regress::{self, Config, Method, Mode, Tolerance};

use crate::flags::{flag_error, Given, BUILD_FLAGS, LOD_FLAGS};
use crate::prepare::{self, context_options, Structures};
use crate::progress::step;
use crate::quality::presets;

#[derive(clap::Args, Debug)]
#[command(mut_arg("method", |a| a.default_value("exact,rbvh,rbvh-lod").help(
    "Structures, comma-separated: `exact` (the exact triangle BVH), `rbvh` (every --quality \
     preset), `rbvh-lod` (every --quality preset traced with level of detail, its default \
     parameters: each pixel's ray uses the coarsest representation whose columns are at most \
     half its footprint wide)"
)))]
#[command(mut_arg("quality", |a| a.default_value("0,2,4").help(
    "RBVH quality presets: 0..4 or Q0..Q4, comma-separated, or `all` (for the methods rbvh and \
     rbvh-lod: refused when --method names neither)"
)))]
// The goldens are of the presets as shipped: the flags that change a preset or its levels of
// detail are refused (`run`), and kept out of the help.
#[command(mut_args(|a| if a.get_id() == "quality" || !is_structure_flag(a.get_id().as_str()) {
    a
} else {
    a.hide(true)
}))]
pub struct Args {
    /// Scenes to render (built-in names or files), repeatable or comma-separated; replaces the
    /// shipped set (default, sphere, blob).
    #[arg(long, value_delimiter = ',')]
    scene: Vec<String>,
    #[command(flatten)]
    structures: Structures,
    /// Folder of the golden images (<case>.png) and depths (<case>_depth.exr).
    #[arg(long, default_value = regress::GOLDEN_DIR)]
    golden: PathBuf,
    /// Folder for failing cases' renders and error pictures (none are written with --bless).
    #[arg(long, default_value = "regress-out")]
    out: PathBuf,
    /// Image width in pixels (goldens are compared at the size they were blessed at).
    #[arg(long, default_value_t = regress::WIDTH)]
    width: u32,
    /// Image height in pixels.
    #[arg(long, default_value_t = regress::HEIGHT)]
    height: u32,
    /// Write the renders as the new goldens instead of comparing (so no tolerances, and no --out).
    #[arg(
        long,
        conflicts_with_all = ["out", "max_flip_mean", "max_outliers", "depth_tolerance", "max_depth_off"]
    )]
    bless: bool,
    /// Most mean FLIP error per image.
    #[arg(long, default_value_t = Tolerance::default().flip_mean)]
    max_flip_mean: f64,
    /// Most share of pixels (0..1) whose FLIP error exceeds 0.1.
    #[arg(long, default_value_t = Tolerance::default().outlier_fraction)]
    max_outliers: f64,
    /// Relative hit-distance error above which a pixel's depth is off.
    #[arg(long, default_value_t = Tolerance::default().depth_relative)]
    depth_tolerance: f64,
    /// Most share of pixels (0..1) whose depth is off.
    #[arg(long, default_value_t = Tolerance::default().depth_outlier_fraction)]
    max_depth_off: f64,
    /// Vulkan device to use: any part of its name (default: $RBVH_DEVICE, else the best GPU, else lavapipe).
    #[arg(long)]
    device: Option<String>,
    /// Run the Vulkan validation layer and fail on any error it reports.
    #[arg(long)]
    validate: bool,
}

/// Whether clap id `id` is one of the flags that say how a structure is built.
fn is_structure_flag(id: &str) -> bool {
    BUILD_FLAGS.contains(&id) || LOD_FLAGS.contains(&id)
}

/// The cases' methods, in the order given: each RBVH method at every --quality preset.
fn methods(a: &Args) -> Result<Vec<Method>> {
    let levels = presets(&a.structures.quality.quality)?;
    let mut methods = Vec::new();
    for m in &a.structures.method {
        match m {
            prepare::Method::Exact => methods.push(Method::EXACT),
            prepare::Method::Rbvh => methods.extend(levels.iter().map(|&l| Method::rbvh(l))),
            prepare::Method::RbvhLod => methods.extend(levels.iter().map(|&l| Method::rbvh_lod(l))),
        }
    }
    Ok(methods)
}

pub fn run(a: Args, given: &Given) -> Result<()> {
    let changes: Vec<&str> = BUILD_FLAGS
        .into_iter()
        .chain(LOD_FLAGS)
        .filter(|id| *id != "quality")
        .collect();
    if let Some(flag) = given.first(&changes) {
        bail!("{flag}: regress compares the presets as shipped with their goldens; give --quality");
    }
    a.structures.check(given, false)?;
    let scenes = if a.scene.is_empty() {
        regress::SCENES.iter().map(|s| s.to_string()).collect()
    } else {
        a.scene.clone()
    };
    let config = Config {
        cases: regress::cross(&scenes, &methods(&a)?),
        golden_dir: a.golden.clone(),
        out_dir: a.out.clone(),
        width: a.width,
        height: a.height,
        tolerance: Tolerance {
            flip_mean: a.max_flip_mean,
            outlier_fraction: a.max_outliers,
            depth_relative: a.depth_tolerance,
            depth_outlier_fraction: a.max_depth_off,
            ..Tolerance::default()
        },
        mode: if a.bless { Mode::Bless } else { Mode::Compare },
    };
    config.validate().map_err(flag_error)?;
    let ctx = Context::new(&context_options(a.device.as_deref(), a.validate)?)
        .context("creating the Vulkan device")?;
    eprintln!(
        "{} {} case(s) at {}×{} on {} ({})",
        if a.bless { "blessing" } else { "comparing" },
        config.cases.len(),
        config.width,
        config.height,
        ctx.device_name(),
        ctx.driver()
    );
    let report = step("rendering", |_| regress::run(&ctx, &config))?;
    print!("{}", report.table());
    if a.bless {
        eprintln!("wrote the goldens to {}", config.golden_dir.display());
    }
    let failed = report.failures().count();
    ensure!(
        failed == 0,
        "{failed} of {} case(s) failed; renders and error pictures are in {}",
        report.cases.len(),
        config.out_dir.display()
    );
    Ok(())
}
