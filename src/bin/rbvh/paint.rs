//! `rbvh paint`: brush strokes aimed through the scene's render camera, traced with the RBVH on
//! the device, painted into its colour channel on the device (`glsl/paint.comp`), saved; with
//! optional renders before and after.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context as _, Result};
use rbvh::bvh::LEAF_BIT;
use rbvh::geom::{Hit, Ray};
use rbvh::gpu::{Painter, Query, Tracer};
use rbvh::surface::{strokes, Brush};
use rbvh::{output, preview};

use crate::flags::Given;
use crate::outputs::{self, output};
use crate::prepare::{
    check_image_size, prepare, two_level_file, CameraArgs, Common, InstancesArg, Method, Prepared,
};
use crate::progress::step;
use crate::quality::TexelsArg;

#[derive(clap::Args, Debug)]
#[command(mut_arg("rbvh", |a| a.help(
    "Paint this saved RBVH (from `rbvh build --out`) instead of building one; it is painted as it \
     was built, so --quality and the free parameters are refused with it. An RBVH paint builds \
     samples every triangle (paint is stored in texels), as --sample-all does elsewhere"
)))]
#[command(mut_arg("stats", |a| a.help(
    "Print the scene, the RBVH (nodes, bytes, build time) and the device"
)))]
#[command(mut_arg("texels", |a| a.help(
    "What each atlas texel holds: paint takes `normals` (height and normal, the default) alone, \
     since a height-only RBVH keeps no colours to paint"
)))]
// Paint samples every triangle it builds (paint is stored in texels): --sample-all is what it
// does anyway, so it is hidden and refused rather than accepted for nothing.
#[command(mut_arg("sample_all", |a| a.hide(true)))]
// The presets' rules for tracing triangles exactly choose what is not sampled: with every
// triangle sampled they have nothing to choose, so they are hidden and refused too.
#[command(mut_arg("exact_from_texels", |a| a.hide(true)))]
#[command(mut_arg("exact_edge_fraction", |a| a.hide(true)))]
#[command(mut_arg("exact_crease", |a| a.hide(true)))]
#[command(mut_arg("instances", |a| a.hide_possible_values(true).help(
    "How a scene with instances is painted: flat, every placement copied in place with texels \
     of its own (`auto` and `flat` alike; `two-level` is refused: a mesh's texels held once \
     would paint every instance of it)"
)))]
// Paint writes a plain RBVH's texels: the one method it takes is the default, and levels of
// detail (which have no texels to paint) are not built.
#[command(mut_arg("method", |a| a.default_value("rbvh").hide(true)))]
#[command(mut_arg("lod_columns", |a| a.hide(true)))]
#[command(mut_arg("lod_min_leaves", |a| a.hide(true)))]
#[command(mut_arg("lod_bias", |a| a.hide(true)))]
pub struct Args {
    #[command(flatten)]
    common: Common,
    #[command(flatten)]
    camera: CameraArgs,
    /// Strokes file (format in docs/cli.md, "Surface data and painting").
    #[arg(long)]
    strokes: PathBuf,
    /// The painted RBVH file to write.
    #[arg(long, short)]
    out: PathBuf,
    /// Also render the RBVH before painting to this PNG.
    #[arg(long)]
    before: Option<PathBuf>,
    /// Also render the RBVH after painting to this PNG.
    #[arg(long)]
    after: Option<PathBuf>,
    /// Image width that the strokes' screen positions and the renders use, 1..=16384.
    #[arg(long, default_value_t = 800)]
    width: u32,
    /// Image height that the strokes' screen positions and the renders use, 1..=16384.
    #[arg(long, default_value_t = 600)]
    height: u32,
}

pub fn run(a: Args, given: &Given) -> Result<()> {
    check_image_size(a.width, a.height)?;
    a.common.check(given)?;
    // The RBVH file may be painted in place: it is read whole before the painted one replaces it.
    let source = &a.common.source;
    let mut inputs = outputs::scene_inputs(&source.scene, source.points.points.as_ref()).to_vec();
    inputs.push(("--strokes", Some(&a.strokes)));
    outputs::check(
        &[
            output("--out", Some(&a.out), "rbvh"),
            output("--before", a.before.as_deref(), "png"),
            output("--after", a.after.as_deref(), "png"),
        ],
        &inputs,
    )?;
    anyhow::ensure!(
        a.common.structures.method()? == Method::Rbvh,
        "--method: paint paints an RBVH's texels, so it takes rbvh alone (the exact BVH has no \
         texels, levels of detail none to paint)"
    );
    anyhow::ensure!(
        !given.has("sample_all"),
        "--sample-all: paint samples every triangle it builds anyway (paint is stored in texels)"
    );
    if let Some(flag) = given.first(&["exact_from_texels", "exact_edge_fraction", "exact_crease"]) {
        bail!(
            "{flag}: paint samples every triangle it builds (paint is stored in texels), so no \
             triangle is traced exactly for it to choose"
        );
    }
    anyhow::ensure!(
        !a.common
            .structures
            .quality
            .texels
            .contains(&TexelsArg::Height),
        "--texels height: a height-only RBVH keeps no colours to paint (paint takes normals, the \
         default)"
    );
    anyhow::ensure!(
        a.common.source.instances != InstancesArg::TwoLevel,
        "--instances two-level: paint paints a flat RBVH (a mesh's texels held once would paint \
         every instance of it); give --instances flat or auto"
    );
    if let Some(path) = &a.common.source.rbvh {
        anyhow::ensure!(
            !two_level_file(path)?,
            "--rbvh {}: a two-level RBVH (each mesh's texels held once, shown by every instance \
             of it); paint paints a flat RBVH: build one with rbvh build --instances flat --out",
            path.display()
        );
    }
    let dabs = strokes::load(&a.strokes)?;
    // Painting writes the RBVH's texels: no other structure, no coarse levels of detail (which
    // have none to paint), and every triangle a height field can hold sampled (`--sample-all`),
    // or the walls and floors the presets trace exactly would take no paint. A file given with
    // `--rbvh` is painted as it was built.
    let mut common = a.common.clone();
    common.structures.quality.sample_all = true;
    common.source.instances = InstancesArg::Flat;
    let mut p = prepare(&common, a.camera.camera()?)?;
    let camera = p.scene().camera_or_framed(a.width as f32 / a.height as f32);
    let tracer = Tracer::new(p.ctx()?, &p.structure).context("uploading the RBVH")?;

    let (rays, hits) = if a.before.is_some() || a.after.is_some() {
        let rays = camera.primary_rays(a.width, a.height);
        let hits = step("tracing", |_| tracer.trace(&rays, Query::Closest))?.hits;
        (rays, hits)
    } else {
        (Vec::new(), Vec::new())
    };
    if let Some(path) = &a.before {
        write_render(path, &p, &rays, &hits, &a)?;
    }

    // Aim: one ray per dab through the same camera; a dab whose ray misses paints nothing.
    let stroke_rays: Vec<_> = dabs
        .iter()
        .map(|d| {
            camera.ray(
                d.screen.x * a.width as f32,
                d.screen.y * a.height as f32,
                a.width,
                a.height,
            )
        })
        .collect();
    let stroke_hits = tracer.trace(&stroke_rays, Query::Closest)?.hits;
    let diagonal = p.scene().bounds().diagonal();
    let brushes: Vec<Brush> = dabs
        .iter()
        .zip(&stroke_rays)
        .zip(&stroke_hits)
        .filter(|(_, h)| h.is_hit())
        .map(|((d, r), h)| Brush::new(r.origin() + r.dir() * h.t, d.radius * diagonal, d.colour))
        .collect();
    let missed = dabs.len() - brushes.len();
    if missed > 0 {
        eprintln!(
            "warning: {missed} of {} dabs aim past the surface and paint nothing",
            dabs.len()
        );
    }
    // Triangle leaves (where height fields did not fit) have no texels to hold paint; the exact
    // parts beside a height field show its texels.
    let parts = p
        .structure
        .rbvh()
        .map(rbvh::rbvh::Rbvh::part_leaves)
        .unwrap_or_default();
    let on_triangles = stroke_hits
        .iter()
        .filter(|h| h.is_hit() && h.id & LEAF_BIT == 0 && !parts.contains_key(&h.id))
        .count();
    if on_triangles > 0 {
        // A file built by the presets (`rbvh build --out`) keeps its large triangles exact.
        let advice = match p.structure.rbvh() {
            Some(r) if r.params.exact_when_cheaper => {
                " (this RBVH traces triangles exactly where cheaper: build it with --sample-all to paint them)"
            }
            _ => "",
        };
        eprintln!(
            "warning: {on_triangles} of {} dabs land on triangle leaves, which have no texels: paint shows only on the height-field surface around them{advice}",
            dabs.len()
        );
    }

    let Some(rbvh) = p.structure.rbvh_mut() else {
        bail!("painting needs an RBVH");
    };
    let start = Instant::now();
    let mut painter = Painter::sharing(&tracer, rbvh)?;
    let stats = painter.paint(&brushes)?;
    rbvh.colours = Some(painter.colours()?);
    let wall_ms = start.elapsed().as_secs_f64() * 1e3;
    eprintln!(
        "painted {} dabs: {} leaves, {} texels visited; GPU {}, {wall_ms:.1} ms with upload and download",
        brushes.len(),
        stats.leaves,
        stats.texels,
        stats
            .timing
            .gpu_ms
            .map_or_else(|| "untimed".to_string(), |ms| format!("{ms:.2} ms")),
    );
    rbvh.save(&a.out)
        .with_context(|| format!("saving {}", a.out.display()))?;
    eprintln!("wrote {}", a.out.display());

    if let Some(path) = &a.after {
        write_render(path, &p, &rays, &hits, &a)?;
    }
    Ok(())
}

/// The before or after picture: the preview shading of `hits` with the RBVH's colours.
fn write_render(path: &Path, p: &Prepared, rays: &[Ray], hits: &[Hit], a: &Args) -> Result<()> {
    let image = preview::shade(p.scene(), &p.structure, rays, hits, a.width, a.height)?;
    output::write_png(path, &image)?;
    eprintln!("wrote {}", path.display());
    Ok(())
}
