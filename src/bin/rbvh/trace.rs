//! `rbvh trace`: a ray file in, a hit file out, so that any outside harness can query the tracer.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Result;
use rbvh::gpu::Query;
use rbvh::io;
use rbvh::lod::{Cones, RayCone};

use crate::flags::Given;
use crate::outputs;
use crate::prepare::{prepare, prepare_cpu, Common, Method};
use crate::progress::step;
use crate::report::{report_counters, report_throughput};

#[derive(clap::Args, Debug)]
#[command(mut_arg("method", |a| a.help(
    "Structure to trace through: `exact` (the exact triangle BVH, the referee), `rbvh` (a \
     Rasterized BVH at --quality), `rbvh-lod` (that RBVH traced with level of detail: each ray \
     uses the coarsest representation whose columns are at most 2^--lod-bias of its footprint \
     wide, a cone of --lod-spread); one of them"
)))]
#[command(mut_arg("stats", |a| a.help(
    "Print the scene, the structure (nodes, bytes, build time), the device, and the trace's time \
     and MRays/s: on the GPU also the CPU reference's on the same rays (and for an RBVH \
     the exact BVH's); with --cpu the CPU tracer's"
)))]
pub struct Args {
    #[command(flatten)]
    common: Common,
    /// With --method rbvh-lod: the cone spread of every ray of the file (radians per unit of t;
    /// their width at t = 0 is 0), which picks the level of detail each ray traces.
    #[arg(long, default_value_t = 1e-3)]
    lod_spread: f32,
    /// Input rays: 8 little-endian f32 each (ox oy oz tmin dx dy dz tmax).
    #[arg(long)]
    rays: PathBuf,
    /// Output hits: t, nx, ny, nz (f32), id (u32), instance (u32), 2 reserved u32 each.
    #[arg(long)]
    hits: PathBuf,
    /// Any-hit (occlusion) query instead of closest hit.
    #[arg(long)]
    any_hit: bool,
    /// Trace with the CPU reference tracer instead of the GPU: no Vulkan device is opened (so no
    /// --device or --validate).
    #[arg(long, conflicts_with_all = ["device", "validate"])]
    cpu: bool,
}

pub fn run(a: Args, given: &Given) -> Result<()> {
    a.common.check(given)?;
    let mut inputs = outputs::source_inputs(&a.common.source);
    inputs.push(("--rays", Some(&a.rays)));
    outputs::check(
        &[outputs::Output {
            flag: "--hits",
            path: Some(&a.hits),
            ext: None,
        }],
        &inputs,
    )?;
    anyhow::ensure!(
        !given.has("lod_spread") || a.common.structures.has(Method::RbvhLod),
        "--lod-spread is the rays' footprint for level of detail, and --method asks for none: use \
         --method rbvh-lod"
    );
    let spread = a.lod_spread;
    anyhow::ensure!(
        spread.is_finite() && spread >= 0.0,
        "--lod-spread must be a finite angle of at least 0 (got {spread})"
    );
    let rays = io::read_rays(&a.rays)?;
    let p = if a.cpu {
        prepare_cpu(&a.common)?
    } else {
        prepare(&a.common, None)?
    };
    let query = if a.any_hit {
        Query::Any
    } else {
        Query::Closest
    };
    let cones = Cones::Same(RayCone { width: 0.0, spread });
    let hits = if a.cpu {
        let t = Instant::now();
        let hits = step("tracing on the CPU", |_| {
            p.trace_cpu(&rays, cones, a.any_hit)
        })?;
        if a.common.source.stats {
            let ms = t.elapsed().as_secs_f64() * 1e3;
            eprintln!(
                "trace (CPU reference, {}): {} rays, {ms:.2} ms = {:.2} MRays/s",
                p.structure.label(),
                rays.len(),
                rays.len() as f64 / (ms.max(f64::MIN_POSITIVE) * 1e3)
            );
        }
        hits
    } else {
        let tracer = step("uploading", |bar| p.tracer(bar))?;
        let traced = step("tracing", |bar| {
            p.trace(&tracer, &rays, cones, query, false, bar)
        })?;
        if a.common.source.stats {
            report_throughput(&p, &rays, cones, query, &traced)?;
            // Counted in a trace of their own, as render does: the timed one compiles the
            // counting away.
            let counted = step("counting each ray's work", |bar| {
                p.trace(&tracer, &rays, cones, query, true, bar)
            })?;
            if let Some(c) = &counted.counters {
                report_counters(p.structure.label(), c);
            }
        }
        traced.hits
    };
    io::write_hits(&a.hits, &hits)?;
    eprintln!("wrote {} hits to {}", hits.len(), a.hits.display());
    Ok(())
}
