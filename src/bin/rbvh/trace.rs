//! `rbvh trace`: a ray file in, a hit file out, so that any outside harness can query the tracer.

use std::path::PathBuf;

use anyhow::Result;
use rbvh::gpu::Query;
use rbvh::io;
use rbvh::lod::RayCone;

use crate::prepare::{prepare, report_throughput, Common};
use crate::progress::step;

#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(flatten)]
    common: Common,
    /// Input rays: 8 little-endian f32 each (ox oy oz tmin dx dy dz tmax).
    #[arg(long)]
    rays: PathBuf,
    /// Output hits: t, nx, ny, nz (f32), id (u32), 3 reserved u32 each.
    #[arg(long)]
    hits: PathBuf,
    /// Any-hit (occlusion) query instead of closest hit.
    #[arg(long)]
    any_hit: bool,
    /// Trace with the CPU reference tracer instead of the GPU.
    #[arg(long)]
    cpu: bool,
}

pub fn run(a: Args) -> Result<()> {
    let spread = a.common.lod.lod_spread;
    anyhow::ensure!(
        spread.is_finite() && spread >= 0.0,
        "--lod-spread must be a finite angle of at least 0 (got {spread})"
    );
    let rays = io::read_rays(&a.rays)?;
    let p = prepare(&a.common)?;
    let query = if a.any_hit {
        Query::Any
    } else {
        Query::Closest
    };
    let cones = vec![
        RayCone {
            width: 0.0,
            spread: a.common.lod.lod_spread,
        };
        if p.structure.lod().is_some() {
            rays.len()
        } else {
            0
        }
    ];
    let hits = if a.cpu {
        p.trace_cpu(&rays, &cones, a.any_hit)?
    } else {
        let tracer = step("uploading", |bar| p.tracer(bar))?;
        let traced = step("tracing", |bar| {
            p.trace(&tracer, &rays, || cones.clone(), query, false, bar)
        })?;
        if a.common.source.stats {
            report_throughput(&p, &rays, &cones, query, &traced)?;
        }
        traced.hits
    };
    io::write_hits(&a.hits, &hits)?;
    eprintln!("wrote {} hits to {}", hits.len(), a.hits.display());
    Ok(())
}
