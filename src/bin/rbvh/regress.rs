//! `rbvh regress`: render the regression cases and compare them with the goldens (or, with
//! `--bless`, replace the goldens), print a table, and fail when any case fails.

use std::path::PathBuf;

use anyhow::{bail, ensure, Context as _, Result};
use clap::ValueEnum;
use rbvh::gpu::Context;
use rbvh::regress::{self, Config, Method, Mode, Tolerance};

use crate::prepare::{context_options, Given};
use crate::progress::step;

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Scenes to render (built-in names or files), repeatable or comma-separated; replaces the
    /// shipped set (default, sphere, blob).
    #[arg(long, value_delimiter = ',')]
    scene: Vec<String>,
    /// Methods, comma-separated; `rbvh` runs every --quality level.
    #[arg(long, value_enum, value_delimiter = ',', default_values_t = [MethodArg::Exact, MethodArg::Rbvh, MethodArg::RbvhLod])]
    method: Vec<MethodArg>,
    /// RBVH quality presets: 0..4 or Q0..Q4, comma-separated, or `all` (for the methods rbvh and
    /// rbvh-lod: refused when --method names neither).
    #[arg(long, value_delimiter = ',', default_values_t = ["0".to_string(), "2".to_string(), "4".to_string()])]
    quality: Vec<String>,
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

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum MethodArg {
    /// Exact triangle BVH.
    Exact,
    /// Rasterized BVH, at each --quality level.
    Rbvh,
    /// Rasterized BVH traced with level of detail, at each --quality level.
    RbvhLod,
}

/// The methods asked for, in the order given: each `rbvh` expands to the --quality levels.
fn methods(a: &Args) -> Result<Vec<Method>> {
    let mut levels = Vec::new();
    for q in &a.quality {
        let q = q.trim();
        if q.eq_ignore_ascii_case("all") {
            levels.extend(0..5);
            continue;
        }
        let digits = q.strip_prefix(['Q', 'q']).unwrap_or(q);
        match digits.parse::<u32>() {
            Ok(level) if level <= 4 => levels.push(level),
            _ => bail!("--quality {q:?} is not a preset: use 0..4, Q0..Q4 or all"),
        }
    }
    let mut methods = Vec::new();
    for m in &a.method {
        match m {
            MethodArg::Exact => methods.push(Method::EXACT),
            MethodArg::Rbvh => {
                ensure!(!levels.is_empty(), "--method rbvh needs a --quality level");
                methods.extend(levels.iter().map(|&l| Method::rbvh(l)));
            }
            MethodArg::RbvhLod => {
                ensure!(
                    !levels.is_empty(),
                    "--method rbvh-lod needs a --quality level"
                );
                methods.extend(levels.iter().map(|&l| Method::rbvh_lod(l)));
            }
        }
    }
    Ok(methods)
}

pub fn run(a: Args, given: &Given) -> Result<()> {
    ensure!(
        !given.has("quality") || a.method.iter().any(|m| *m != MethodArg::Exact),
        "--quality picks the RBVH levels, and --method names no RBVH: add rbvh or rbvh-lod to --method"
    );
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
    config.validate()?;
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
