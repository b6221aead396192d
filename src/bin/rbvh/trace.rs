//! `rbvh trace`: a ray file in, a hit file out, so that any outside harness can query the tracer.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context as _, Result};
use rbvh::gpu::{ExactTracer, Query};
use rbvh::io;

use crate::prepare::{prepare, print_throughput, step, Common};

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
    let rays = io::read_rays(&a.rays)?;
    let p = prepare(&a.common)?;
    let query = if a.any_hit {
        Query::Any
    } else {
        Query::Closest
    };
    let hits = if a.cpu {
        p.bvh.trace_cpu(&rays, a.any_hit)
    } else {
        let tracer = ExactTracer::new(&p.ctx, &p.bvh).context("uploading the BVH")?;
        let traced = step("tracing", || tracer.trace(&rays, query))?;
        if a.common.stats {
            let t = Instant::now();
            std::hint::black_box(p.bvh.trace_cpu(&rays, a.any_hit));
            print_throughput(
                rays.len(),
                traced.timing.gpu_ms,
                traced.timing.wall_ms,
                t.elapsed().as_secs_f64() * 1e3,
            );
        }
        traced.hits
    };
    io::write_hits(&a.hits, &hits)?;
    eprintln!("wrote {} hits to {}", hits.len(), a.hits.display());
    Ok(())
}
