//! `rbvh render`: primary rays from the scene's (or a framing) camera, shaded to PNG; EXR with
//! depth and normals; a traversal-cost heat map. `--shading ibl` lights the picture by an
//! environment through [`rbvh::ibl`], with a progress bar over the sample passes.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{ensure, Context as _, Result};
use clap::ValueEnum;
use glam::Vec3;
use indicatif::{ProgressBar, ProgressStyle};
use rbvh::bench::metrics::image_errors;
use rbvh::geom::{Hit, Ray};
use rbvh::gpu::{Query, Tracer};
use rbvh::ibl::{self, Environment, Frame, Settings, Sky};
use rbvh::lod::{Cones, RayCone};
use rbvh::output::{self, Image};
use rbvh::preview;
use rbvh::probe::RayCounters;
use rbvh::scene::{Light, SceneView};
use rbvh::structure::{Kind, Structure};
use rbvh::surface::hit_albedo;

use crate::flags::Given;
use crate::outputs::{self, output};
use crate::prepare::{check_image_size, prepare, CameraArgs, Common, Prepared};
use crate::progress::step;
use crate::report::{report_counters, report_throughput};

#[derive(clap::Args, Debug)]
#[command(mut_arg("method", |a| a.help(
    "Structure to trace through: `exact` (the exact triangle BVH, the referee), `rbvh` (a \
     Rasterized BVH at --quality), `rbvh-lod` (that RBVH traced with level of detail: each \
     pixel's ray uses the coarsest representation whose columns are at most 2^--lod-bias of the \
     pixel's footprint wide); one of them"
)))]
#[command(mut_arg("stats", |a| a.help(
    "Print the scene, the structure (nodes, bytes, build time), the device, the primary trace's \
     time and MRays/s against the CPU reference's (for an RBVH also the exact BVH's on the \
     same rays) and each ray's work; with --shading ibl also the visibility rays' (and for an \
     RBVH the exact reference render's, with the RBVH image's FLIP and PSNR against it)"
)))]
pub struct Args {
    #[command(flatten)]
    common: Common,
    #[command(flatten)]
    camera: CameraArgs,
    /// Output PNG.
    #[arg(long, short, default_value = "render.png")]
    out: PathBuf,
    /// Also write an EXR with R,G,B, Z (hit distance) and N.X,N.Y,N.Z.
    #[arg(long)]
    exr: Option<PathBuf>,
    /// Also write a PNG heat map of traversal steps (nodes visited + triangles tested + cells
    /// stepped) per pixel, with a colour bar labelled with its scale.
    #[arg(long)]
    heatmap: Option<PathBuf>,
    /// With --heatmap: the heat map's scale, this many steps or more dark red (default: the
    /// largest count), so that two renders' maps compare.
    #[arg(long, requires = "heatmap", value_parser = clap::value_parser!(u32).range(1..))]
    heatmap_max: Option<u32>,
    /// Image width in pixels, 1..=16384.
    #[arg(long, default_value_t = 800)]
    width: u32,
    /// Image height in pixels, 1..=16384.
    #[arg(long, default_value_t = 600)]
    height: u32,
    /// How the picture is shaded from the primary rays' hits.
    #[arg(long, value_enum, default_value_t = Shading::Lambert)]
    shading: Shading,
    /// With --shading ibl: an HDR environment map (EXR, latitude-longitude, +y up) instead of the
    /// procedural sky.
    #[arg(long)]
    env: Option<PathBuf>,
    /// With --shading ibl: visibility rays per pixel, one per progressive pass [default: 16].
    #[arg(long)]
    samples: Option<u32>,
    /// With --shading ibl: random seed; the same seed gives the same image [default: 0].
    #[arg(long)]
    seed: Option<u64>,
}

impl Args {
    fn samples(&self) -> u32 {
        self.samples.unwrap_or(16)
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum Shading {
    /// Diffuse under the scene's light (or a headlight).
    Lambert,
    /// Geometric normals as colours.
    Normals,
    /// Image-based lighting: diffuse under --env (or a procedural sky), --samples visibility rays
    /// per pixel through --method; with --stats and --method rbvh also the exact reference's time
    /// and the RBVH image's FLIP and PSNR against it.
    Ibl,
}

pub fn run(a: Args, given: &Given) -> Result<()> {
    check_image_size(a.width, a.height)?;
    a.common.check(given)?;
    let mut inputs = outputs::source_inputs(&a.common.source);
    inputs.push(("--env", a.env.as_deref()));
    outputs::check(
        &[
            output("--out", Some(&a.out), "png"),
            output("--exr", a.exr.as_deref(), "exr"),
            output("--heatmap", a.heatmap.as_deref(), "png"),
        ],
        &inputs,
    )?;
    for (set, flag) in [
        (a.env.is_some(), "--env"),
        (a.samples.is_some(), "--samples"),
        (a.seed.is_some(), "--seed"),
    ] {
        ensure!(
            !set || a.shading == Shading::Ibl,
            "{flag} is for an image-based render: add --shading ibl"
        );
    }
    ensure!(
        (1..=ibl::MAX_SAMPLES).contains(&a.samples()),
        "--samples must be within 1..={} (got {})",
        ibl::MAX_SAMPLES,
        a.samples()
    );
    // Read the environment before the (possibly long) build, so a bad file fails at once.
    let env = load_environment(a.env.as_ref())?;
    let p = prepare(&a.common, a.camera.camera()?)?;
    let camera = p.scene().camera_or_framed(a.width as f32 / a.height as f32);
    let rays = camera.primary_rays(a.width, a.height);
    let tracer = step("uploading", |bar| p.tracer(bar))?;
    let cone = RayCone::pixel(&camera, a.height);
    let cones = Cones::Same(cone);
    let traced = step("tracing", |bar| {
        p.trace(&tracer, &rays, cones, Query::Closest, false, bar)
    })?;
    // Counted in a trace of their own: the timed one compiles the counting away.
    let counters = if a.heatmap.is_some() || a.common.source.stats {
        step("counting each ray's work", |bar| {
            p.trace(&tracer, &rays, cones, Query::Closest, true, bar)
        })?
        .counters
    } else {
        None
    };
    if a.common.source.stats {
        report_throughput(&p, &rays, cones, Query::Closest, &traced)?;
        if let Some(c) = &counters {
            report_counters(p.structure.label(), c);
        }
    }
    let image = match a.shading {
        Shading::Lambert => preview::shade(
            p.scene(),
            &p.structure,
            &rays,
            &traced.hits,
            a.width,
            a.height,
        )?,
        Shading::Normals => output::shade_normals(&rays, &traced.hits, a.width, a.height)?,
        Shading::Ibl => {
            let env = env.unwrap_or_else(|| Environment::Sky(sky_of(p.scene().light())));
            render_ibl(&a, &p, &tracer, &rays, &traced.hits, &env, cone)?
        }
    };
    output::write_png(&a.out, &image)?;
    eprintln!("wrote {}", a.out.display());
    if let Some(path) = &a.exr {
        output::write_exr(path, &image, &traced.hits)?;
        eprintln!("wrote {}", path.display());
    }
    if let (Some(path), Some(counters)) = (&a.heatmap, &counters) {
        let steps: Vec<u32> = counters.iter().map(RayCounters::steps).collect();
        let max = a
            .heatmap_max
            .unwrap_or_else(|| steps.iter().copied().max().unwrap_or(0))
            .max(1);
        let map = output::heatmap(&steps, a.width, a.height, Some(max))?;
        output::write_png(path, &output::with_colour_bar(&map, max))?;
        eprintln!(
            "wrote {} (steps per pixel, 0 to {max} on its colour bar)",
            path.display()
        );
    }
    Ok(())
}

/// The IBL albedo per pixel: the neutral grey ([`ibl::GREY`]) times the surfaces' base colour
/// where the scene or RBVH has one, as the Lambert preview shades.
pub(crate) fn ibl_albedo(
    scene: SceneView,
    structure: &Structure,
    rays: &[Ray],
    hits: &[Hit],
) -> Vec<Vec3> {
    let grey = Vec3::splat(ibl::GREY);
    match hit_albedo(scene, structure, rays, hits) {
        Some(colours) => colours.into_iter().map(|c| grey * c).collect(),
        None => vec![grey; rays.len()],
    }
}

/// For a two-level RBVH, per pixel the offset its visibility rays leave the surface by: the hit
/// instance's texel ([`Structure::surface_offset`]), which scales with the instance; none for
/// any other structure, whose one offset is the settings'.
pub(crate) fn instance_offsets(structure: &Structure, hits: &[Hit]) -> Option<Vec<f32>> {
    (structure.kind() == Kind::RbvhInstanced)
        .then(|| hits.iter().map(|h| structure.surface_offset(h)).collect())
}

/// The environment map of `--env`, if given, with an error naming the file.
pub(crate) fn load_environment(path: Option<&PathBuf>) -> Result<Option<Environment>> {
    path.map(|path| {
        step("loading environment map", |_| Environment::load(path))
            .with_context(|| format!("loading environment map {}", path.display()))
    })
    .transpose()
}

/// The procedural sky with its sun where the scene's directional light comes from, else where
/// the default light does.
pub(crate) fn sky_of(light: Option<&Light>) -> Sky {
    match light {
        Some(Light::Directional { direction }) => Sky::towards(-*direction),
        _ => Sky::default(),
    }
}

/// The IBL render of `hits` through `tracer`, with its `--stats` (see [`compare_with_exact`]).
fn render_ibl(
    a: &Args,
    p: &Prepared,
    tracer: &Tracer,
    rays: &[Ray],
    hits: &[Hit],
    env: &Environment,
    cone: RayCone,
) -> Result<Image> {
    let texel = p.structure.texel_size();
    let surface_offset = texel.unwrap_or(0.0);
    // The surfaces' base colour where the scene or RBVH has one, else the neutral grey.
    let albedo = ibl_albedo(p.scene(), &p.structure, rays, hits);
    let settings = Settings {
        samples: a.samples(),
        seed: a.seed.unwrap_or(0),
        diagonal: p.scene().bounds().diagonal(),
        surface_offset,
        cone: Some(cone),
    };
    let offsets = instance_offsets(&p.structure, hits);
    let frame = Frame {
        width: a.width,
        height: a.height,
        rays,
        hits,
        albedo: &albedo,
        offsets: offsets.as_deref(),
    };
    let label = format!("IBL ({})", p.structure.label());
    let rendered = progressive(&label, a.samples(), |on_pass| {
        ibl::render(tracer, &frame, env, &settings, on_pass)
    })?;
    if a.common.source.stats {
        report_ibl("this render", &rendered);
        if texel.is_some() {
            compare_with_exact(p, env, &frame, &settings, &rendered)?;
        }
    }
    Ok(rendered.image)
}

/// `--stats` for an RBVH's IBL render: the exact BVH renders the same frame, samples and seed
/// from its own primary hits (and without the texel offset), then both times, their ratio, and
/// the RBVH image's FLIP and PSNR against the exact one are printed.
fn compare_with_exact(
    p: &Prepared,
    env: &Environment,
    frame: &Frame,
    settings: &Settings,
    rendered: &ibl::Rendered,
) -> Result<()> {
    if p.scene().triangle_count() == 0 {
        eprintln!("no exact BVH to compare with: the scene is a point cloud, without triangles");
        return Ok(());
    }
    let t = Instant::now();
    let structure = step("building BVH", |bar| p.build_exact(bar))?;
    let exact = Tracer::new(p.ctx()?, &structure).context("uploading the exact BVH")?;
    let setup_ms = t.elapsed().as_secs_f64() * 1e3;
    let exact_hits = exact.trace(frame.rays, Query::Closest)?.hits;
    let exact_albedo = ibl_albedo(p.scene(), &structure, frame.rays, &exact_hits);
    let exact_frame = Frame {
        hits: &exact_hits,
        albedo: &exact_albedo,
        offsets: None,
        ..*frame
    };
    let exact_settings = Settings {
        surface_offset: 0.0,
        ..*settings
    };
    let reference = progressive("IBL (exact reference)", settings.samples, |on_pass| {
        ibl::render(&exact, &exact_frame, env, &exact_settings, on_pass)
    })?;
    eprintln!("exact BVH built and uploaded in {setup_ms:.1} ms");
    report_ibl("exact reference", &reference);
    let errors = image_errors(&reference.image, &rendered.image)?;
    let ratio = |exact: f64, rbvh: f64| exact / rbvh.max(f64::MIN_POSITIVE);
    let gpu = match (reference.timing.gpu_ms, rendered.timing.gpu_ms) {
        (Some(e), Some(r)) => format!("GPU {:.2}x, ", ratio(e, r)),
        _ => String::new(),
    };
    eprintln!(
        "IBL RBVH vs exact at {} samples, seed {}: speed {gpu}wall {:.2}x; FLIP {:.4}, PSNR {:.2} dB",
        settings.samples,
        settings.seed,
        ratio(reference.wall_ms, rendered.wall_ms),
        errors.flip_mean,
        errors.psnr_db
    );
    Ok(())
}

/// Runs `render` under a progress bar over its `samples` passes (hidden when stderr is not a
/// terminal).
pub(crate) fn progressive<T>(
    label: &str,
    samples: u32,
    render: impl FnOnce(&mut dyn FnMut(&ibl::Pass)) -> rbvh::Result<T>,
) -> Result<T> {
    let bar = ProgressBar::new(u64::from(samples)).with_message(label.to_string());
    bar.set_style(
        ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len} samples {elapsed}")
            .expect("static template"),
    );
    bar.enable_steady_tick(Duration::from_millis(120));
    let out = render(&mut |pass: &ibl::Pass| bar.set_position(u64::from(pass.done)));
    bar.finish_and_clear();
    Ok(out?)
}

/// `--stats` of one IBL render: its visibility rays, their trace time, and the host time of the
/// sample passes (ray generation, traces, accumulation; the primary trace is not included).
pub(crate) fn report_ibl(what: &str, r: &ibl::Rendered) {
    let gpu = match r.timing.gpu_ms {
        Some(ms) => format!(
            "GPU {ms:.2} ms = {:.2} MRays/s",
            r.rays as f64 / (ms.max(f64::MIN_POSITIVE) * 1e3)
        ),
        None => "no GPU timestamps".to_string(),
    };
    eprintln!(
        "IBL {what}: {} visibility rays, {gpu}; passes wall {:.1} ms",
        r.rays, r.wall_ms
    );
}
