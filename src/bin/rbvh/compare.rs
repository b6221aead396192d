//! `rbvh compare`: what the project is for, in one command. The scene is lit by a sky through
//! [`rbvh::ibl`] — every pixel's visibility rays ask whether the sky is blocked, which is what
//! casts its shadows and ambient occlusion — once through the exact BVH and once through an
//! RBVH, from the same primary rays, samples and seed; the two pictures go side by side into one
//! PNG (exact left), and each structure's memory, visibility-ray speed and error are printed.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{ensure, Context as _, Result};
use clap::builder::TypedValueParser as _;
use rbvh::bench::metrics::image_errors;
use rbvh::geom::Ray;
use rbvh::gpu::{Query, Tracer};
use rbvh::ibl::{self, Environment, Frame, Rendered, Settings};
use rbvh::lod::{Cones, RayCone};
use rbvh::output;

use crate::flags::Given;
use crate::outputs::{self, output};
use crate::prepare::{prepare, CameraArgs, Common, Loaded, Method};
use crate::progress::step;
use crate::render::{ibl_albedo, instance_offsets, load_environment, progressive, sky_of};

#[derive(clap::Args, Debug)]
#[command(mut_arg("scene", |a| a.help(
    "Scene: a built-in name (`rbvh scenes`), an OBJ/glTF/GLB file or a scene file (.toml); not a \
     point cloud, which has no triangles for the exact BVH (--points builds the RBVH from points \
     sampled over a mesh)"
)))]
#[command(mut_arg("quality", |a| a.help(
    "Quality preset of the RBVH to compare with the exact BVH: one of 0..4 or Q0..Q4 (Q0 \
     coarsest, Q4 finest); not with --rbvh FILE"
)))]
#[command(mut_arg("rbvh", |a| a.help(
    "Compare this saved RBVH (from `rbvh build --out`) instead of building one; the file holds \
     its build parameters, so --quality and the free parameters are refused with it"
)))]
#[command(mut_arg("stats", |a| a.help(
    "Also print the scene, the RBVH (nodes, bytes, build time) and the device on stderr"
)))]
// `exact` is hidden from the help's values, not refused by clap: the command's own refusal says
// why (the exact BVH is always the left picture).
#[command(mut_arg("method", |a| a.default_value("rbvh").value_parser(
    clap::builder::PossibleValuesParser::new([
        clap::builder::PossibleValue::new("exact").hide(true),
        clap::builder::PossibleValue::new("rbvh"),
        clap::builder::PossibleValue::new("rbvh-lod"),
    ])
    .map(|name| match name.as_str() {
        "exact" => Method::Exact,
        "rbvh" => Method::Rbvh,
        _ => Method::RbvhLod,
    })
).help(
    "What to compare with the exact BVH: `rbvh` (a Rasterized BVH at --quality) or `rbvh-lod` \
     (that RBVH traced with level of detail: each ray uses the coarsest representation whose \
     columns are at most 2^--lod-bias of its pixel's footprint wide)"
)))]
pub struct Args {
    #[command(flatten)]
    common: Common,
    #[command(flatten)]
    camera: CameraArgs,
    /// Output PNG: the exact BVH's picture left, the RBVH's right, each --width × --height.
    #[arg(long, short, default_value = "compare.png")]
    out: PathBuf,
    /// Width of each of the two pictures in pixels, 1..=8192 (the PNG is twice as wide).
    #[arg(long, default_value_t = 384)]
    width: u32,
    /// Height of the pictures in pixels, 1..=16384.
    #[arg(long, default_value_t = 256)]
    height: u32,
    /// Visibility rays per pixel, one per pass, 1..=65536: more is smoother, slower, and times
    /// the structures over more passes.
    #[arg(long, default_value_t = 64)]
    samples: u32,
    /// Random seed of the visibility rays' directions (the same for both structures).
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Light the scene by this HDR environment map (EXR, latitude-longitude, +y up) instead of
    /// the procedural sky.
    #[arg(long)]
    env: Option<PathBuf>,
}

pub fn run(a: Args, given: &Given) -> Result<()> {
    let start = Instant::now();
    ensure!(
        (1..=8192).contains(&a.width) && (1..=16384).contains(&a.height),
        "--width must be within 1..=8192 (the PNG holds two pictures side by side) and --height \
         within 1..=16384 (got {}x{})",
        a.width,
        a.height
    );
    ensure!(
        (1..=ibl::MAX_SAMPLES).contains(&a.samples),
        "--samples must be within 1..={} (got {})",
        ibl::MAX_SAMPLES,
        a.samples
    );
    ensure!(
        a.out
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("png")),
        "--out {}: writes PNG, so give it a .png name",
        a.out.display()
    );
    a.common.check(given)?;
    let mut inputs = outputs::source_inputs(&a.common.source);
    inputs.push(("--env", a.env.as_deref()));
    outputs::check(&[output("--out", Some(&a.out), "png")], &inputs)?;
    ensure!(
        a.common.structures.method()? != Method::Exact,
        "--method exact: compare sets an RBVH beside the exact BVH; give rbvh or rbvh-lod"
    );
    // Read the environment before the builds, so a bad file fails at once.
    let env = load_environment(a.env.as_ref())?;
    let p = prepare(&a.common, a.camera.camera()?)?;
    ensure!(
        p.scene().triangle_count() > 0,
        "{} is a point cloud: there are no triangles for an exact BVH to compare its RBVH with",
        p.scene().name()
    );
    let params = p.structure.rbvh_params().context("compare needs an RBVH")?;
    let texel = p.structure.texel_size().context("compare needs an RBVH")?;
    let exact_structure = step("building BVH", |bar| p.build_exact(bar))?;
    let exact_bytes = exact_structure.memory().total;
    let rbvh_bytes = p.structure.memory().total;
    let exact = Tracer::new(p.ctx()?, &exact_structure).context("uploading the exact BVH")?;
    let approx = step("uploading", |bar| p.tracer(bar))?;

    let (width, height) = (a.width, a.height);
    let camera = p.scene().camera_or_framed(width as f32 / height as f32);
    let rays = camera.primary_rays(width, height);
    let cone = RayCone::pixel(&camera, height);
    let (exact_hits, rbvh_hits) = step("tracing", |_| -> Result<_> {
        Ok((
            exact.trace(&rays, Query::Closest)?.hits,
            approx
                .trace_with(&rays, Cones::Same(cone), Query::Closest, false)?
                .hits,
        ))
    })?;
    // One untimed any-hit trace through each first: neither pays for a first dispatch of the
    // visibility pipeline in its timings.
    let warm: Vec<Ray> = rays.iter().take(1024).copied().collect();
    exact.trace(&warm, Query::Any)?;
    approx.trace_with(&warm, Cones::Same(cone), Query::Any, false)?;

    let env = env.unwrap_or_else(|| Environment::Sky(sky_of(p.scene().light())));
    let settings = Settings {
        samples: a.samples,
        seed: a.seed,
        diagonal: p.scene().bounds().diagonal(),
        surface_offset: 0.0,
        cone: Some(cone),
    };
    let exact_albedo = ibl_albedo(p.scene(), &exact_structure, &rays, &exact_hits);
    let rbvh_albedo = ibl_albedo(p.scene(), &p.structure, &rays, &rbvh_hits);
    let exact_frame = Frame {
        width,
        height,
        rays: &rays,
        hits: &exact_hits,
        albedo: &exact_albedo,
        offsets: None,
    };
    let offsets = instance_offsets(&p.structure, &rbvh_hits);
    let rbvh_frame = Frame {
        hits: &rbvh_hits,
        albedo: &rbvh_albedo,
        offsets: offsets.as_deref(),
        ..exact_frame
    };
    // The RBVH's rays leave its surface a texel further out, since it may lie a fraction of a
    // texel off the exact one (as `render --shading ibl` does).
    let rbvh_settings = Settings {
        surface_offset: texel,
        ..settings
    };
    // Pass by pass, alternating which goes first, so that both are timed under the same
    // conditions (another process, a clock that changes) rather than one after the other.
    let (reference, rendered) = progressive("IBL (exact BVH and RBVH)", a.samples, |on_pass| {
        let mut both = ibl::render_side_by_side(
            &[
                (&exact, &exact_frame, &settings),
                (&approx, &rbvh_frame, &rbvh_settings),
            ],
            &env,
            on_pass,
        )?;
        let rendered = both.pop().expect("two renders");
        Ok((both.pop().expect("two renders"), rendered))
    })?;

    let errors = image_errors(&reference.image, &rendered.image)?;
    let mismatched = exact_hits
        .iter()
        .zip(&rbvh_hits)
        .filter(|(e, r)| e.is_hit() != r.is_hit())
        .count();
    let picture = output::side_by_side(&[&reference.image, &rendered.image], 0)?;
    output::write_png(&a.out, &picture)?;

    let level = match p.structure.lod() {
        Some(_) => format!("{} with LOD", params.level_label()),
        None => params.level_label(),
    };
    let (exact_speed, timer) = mrays(&reference);
    let (rbvh_speed, _) = mrays(&rendered);
    let lit = match &a.env {
        Some(path) => format!("lit by {}", path.display()),
        None => "lit by the procedural sky".to_string(),
    };
    let points = match (p.scene().point_count(), &a.common.source.rbvh) {
        (0, _) => String::new(),
        // The file's RBVH was built already: the points are what it is checked against.
        (n, Some(_)) => format!(" (the RBVH's file checked against {n} points)"),
        (n, None) => format!(" (the RBVH's from {n} points)"),
    };
    let layout = match &p.loaded {
        Loaded::Instanced(placed) => format!(
            " as placed, both traced in two levels ({} instances of {} meshes)",
            placed.instances.len(),
            placed.meshes.len()
        ),
        Loaded::Flat(_) => String::new(),
    };
    println!(
        "{}: {} triangles{layout}{points}, {width}x{height} per picture, {lit}, {} visibility \
         rays per pixel (shadows and ambient occlusion), seed {}; device {} ({})",
        p.scene().name(),
        p.scene().triangle_count(),
        a.samples,
        a.seed,
        p.ctx()?.device_name(),
        p.ctx()?.driver()
    );
    let row = |name: &str, memory: String, speed: String, error: String| {
        println!("{name:<12} memory {memory:<26} speed {speed:<38} error {error}");
    };
    row(
        "exact BVH",
        format!("{:.2} MB", mb(exact_bytes)),
        format!("{exact_speed:.2} MRays/s"),
        "FLIP 0, the reference".to_string(),
    );
    row(
        &format!("RBVH {level}"),
        format!(
            "{:.2} MB ({:.2}x smaller)",
            mb(rbvh_bytes),
            exact_bytes as f64 / rbvh_bytes.max(1) as f64
        ),
        format!(
            "{rbvh_speed:.2} MRays/s ({:.2}x the exact BVH's)",
            rbvh_speed / exact_speed.max(f64::MIN_POSITIVE)
        ),
        format!(
            "FLIP {:.4}, PSNR {:.2} dB; primary rays hit/miss mismatch {:.2}% ({mismatched} of {})",
            errors.flip_mean,
            errors.psnr_db,
            100.0 * mismatched as f64 / rays.len() as f64,
            rays.len()
        ),
    );
    println!(
        "(memory: tree, atlas and triangles, as rbvh build and bench count them; speed: {} and {} \
         visibility rays, one per sample of each hit pixel, timed by {timer}, one pass of each in \
         turn; error: the RBVH picture against the exact one)",
        reference.rays, rendered.rays
    );
    eprintln!(
        "wrote {} (exact BVH left, RBVH {level} right) in {:.1} s",
        a.out.display(),
        start.elapsed().as_secs_f64()
    );
    Ok(())
}

/// A render's visibility rays per second, in millions, and what timed them: the device's
/// timestamps where every pass had them, else the host's wait for each trace.
fn mrays(r: &Rendered) -> (f64, &'static str) {
    let (ms, timer) = match r.timing.gpu_ms {
        Some(ms) => (ms, "GPU time"),
        None => (r.timing.wall_ms, "wall time of the traces"),
    };
    (r.rays as f64 / (ms.max(f64::MIN_POSITIVE) * 1e3), timer)
}

fn mb(bytes: u64) -> f64 {
    bytes as f64 / 1e6
}
