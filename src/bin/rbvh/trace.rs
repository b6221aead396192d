//! `rbvh trace`: a ray file in, a hit file out, so that any outside harness can query the tracer.

use std::path::PathBuf;

use anyhow::Result;
use rbvh::gpu::Query;
use rbvh::io;

use crate::prepare::{prepare, report_throughput, step, Common};

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
        p.structure.trace_cpu(&rays, a.any_hit)
    } else {
        let tracer = p.structure.tracer(&p.ctx)?;
        let traced = step("tracing", || tracer.trace(&rays, query))?;
        if a.common.stats {
            report_throughput(&p, &rays, query, &traced)?;
        }
        traced.hits
    };
    io::write_hits(&a.hits, &hits)?;
    eprintln!("wrote {} hits to {}", hits.len(), a.hits.display());
    Ok(())
}
