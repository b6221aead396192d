//! `rbvh render`: primary rays from the scene's (or a framing) camera, shaded to PNG; EXR with
//! depth and normals; a traversal-cost heat map.

use std::path::PathBuf;

use anyhow::{ensure, Result};
use clap::ValueEnum;
use rbvh::geom::{Hit, Ray};
use rbvh::gpu::Query;
use rbvh::output::{self, Image};
use rbvh::scene::Scene;
use rbvh::surface::hit_albedo;

use crate::prepare::{prepare, report_steps, report_throughput, step, Common, Structure};

#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(flatten)]
    common: Common,
    /// Output PNG.
    #[arg(long, short, default_value = "render.png")]
    out: PathBuf,
    /// Also write an EXR with R,G,B, Z (hit distance) and N.X,N.Y,N.Z.
    #[arg(long)]
    exr: Option<PathBuf>,
    /// Also write a PNG heat map of traversal steps (nodes visited + triangles tested) per pixel.
    #[arg(long)]
    heatmap: Option<PathBuf>,
    #[arg(long, default_value_t = 800)]
    width: u32,
    #[arg(long, default_value_t = 600)]
    height: u32,
    #[arg(long, value_enum, default_value_t = Shading::Lambert)]
    shading: Shading,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum Shading {
    /// Diffuse under the scene's light (or a headlight).
    Lambert,
    /// Geometric normals as colours.
    Normals,
}

pub fn run(a: Args) -> Result<()> {
    ensure!(
        (1..=16384).contains(&a.width) && (1..=16384).contains(&a.height),
        "--width and --height must be within 1..=16384 (got {}x{})",
        a.width,
        a.height
    );
    let p = prepare(&a.common)?;
    let camera = p.scene.camera_or_framed(a.width as f32 / a.height as f32);
    let rays = camera.primary_rays(a.width, a.height);
    let tracer = p.structure.tracer(&p.ctx)?;
    let traced = step("tracing", || {
        tracer.trace_with(&rays, Query::Closest, a.heatmap.is_some())
    })?;
    if a.common.stats {
        report_throughput(&p, &rays, Query::Closest, &traced)?;
        if let Some(steps) = &traced.steps {
            report_steps(steps);
        }
    }
    let image = match a.shading {
        Shading::Lambert => lambert(
            &p.scene,
            &p.structure,
            &rays,
            &traced.hits,
            a.width,
            a.height,
        )?,
        Shading::Normals => output::shade_normals(&rays, &traced.hits, a.width, a.height)?,
    };
    output::write_png(&a.out, &image)?;
    eprintln!("wrote {}", a.out.display());
    if let Some(path) = &a.exr {
        output::write_exr(path, &image, &traced.hits)?;
        eprintln!("wrote {}", path.display());
    }
    if let (Some(path), Some(steps)) = (&a.heatmap, &traced.steps) {
        output::write_png(path, &output::heatmap(steps, a.width, a.height, None)?)?;
        eprintln!("wrote {}", path.display());
    }
    Ok(())
}

/// The preview shading, with the base colour of the hit surfaces as albedo when the scene has
/// materials or the RBVH a colour channel (`rbvh::surface::hit_albedo`), else plain grey.
pub fn lambert(
    scene: &Scene,
    structure: &Structure,
    rays: &[Ray],
    hits: &[Hit],
    width: u32,
    height: u32,
) -> Result<Image> {
    let rbvh = match structure {
        Structure::Rbvh(r) => Some(&**r),
        Structure::Exact(_) => None,
    };
    let light = scene.light.as_ref();
    Ok(match hit_albedo(scene, rbvh, rays, hits) {
        Some(albedo) => output::shade_with_albedo(rays, hits, width, height, light, &albedo)?,
        None => output::shade(rays, hits, width, height, light)?,
    })
}
