//! What `--stats` prints after a trace (render, trace): the device's speed beside the CPU
//! reference's and the exact BVH's on the same rays, and the per-ray counters.

use std::time::Instant;

use anyhow::Result;
use rbvh::geom::Ray;
use rbvh::gpu::{Query, Traced, Tracer};
use rbvh::lod::Cones;
use rbvh::probe::{MeanCounters, RayCounters};
use rbvh::structure::Structure;

use crate::prepare::Prepared;

/// `--stats` after a trace: GPU MRays/s, the CPU reference's on the same rays and their ratio;
/// for an RBVH also the exact BVH's GPU MRays/s on the same rays, and the speedup; with level of
/// detail also the RBVH's without it.
pub fn report_throughput(
    p: &Prepared,
    rays: &[Ray],
    cones: Cones,
    query: Query,
    traced: &Traced,
) -> Result<()> {
    let mrays = |ms: f64| rays.len() as f64 / (ms * 1e3);
    let any = query == Query::Any;
    let t = Instant::now();
    std::hint::black_box(p.trace_cpu(rays, cones, any)?);
    let cpu_ms = t.elapsed().as_secs_f64() * 1e3;
    let Some(gpu_ms) = traced.timing.gpu_ms else {
        eprintln!(
            "trace: {} rays, wall {:.2} ms = {:.2} MRays/s (no GPU timestamps); CPU reference {:.2} MRays/s",
            rays.len(),
            traced.timing.wall_ms,
            mrays(traced.timing.wall_ms),
            mrays(cpu_ms)
        );
        return Ok(());
    };
    eprintln!(
        "trace: {} rays, GPU {gpu_ms:.2} ms = {:.2} MRays/s; CPU reference {cpu_ms:.2} ms = {:.2} MRays/s; GPU/CPU = {:.2}x",
        rays.len(),
        mrays(gpu_ms),
        mrays(cpu_ms),
        cpu_ms / gpu_ms
    );
    if let Structure::RbvhLod(r, _) = &p.structure {
        let plain = Tracer::new(p.ctx()?, &Structure::from(r.clone()))?.trace(rays, query)?;
        if let Some(plain_ms) = plain.timing.gpu_ms {
            eprintln!(
                "same RBVH without level of detail: GPU {plain_ms:.2} ms = {:.2} MRays/s; LOD speedup {:.2}x",
                mrays(plain_ms),
                plain_ms / gpu_ms
            );
        }
    }
    let approximate = !p.structure.kind().is_exact();
    if approximate && p.scene().triangle_count() == 0 {
        eprintln!("no exact BVH to compare with: the scene is a point cloud, without triangles");
    } else if approximate {
        let structure = p.build_exact(&rbvh::progress::Quiet)?;
        let label = structure.label();
        let exact = Tracer::new(p.ctx()?, &structure)?;
        let timed = exact.trace(rays, query)?;
        if let Some(exact_ms) = timed.timing.gpu_ms {
            eprintln!(
                "{label} on the same rays: GPU {exact_ms:.2} ms = {:.2} MRays/s; RBVH speedup {:.2}x",
                mrays(exact_ms),
                exact_ms / gpu_ms
            );
        }
        if let Some(c) = exact.trace_with(rays, Cones::None, query, true)?.counters {
            report_counters(label, &c);
        }
    }
    Ok(())
}

/// `--stats` with per-ray counters (`what` names the structure): the mean of each, the heat map's
/// steps (mean and maximum), and how well 8-wide SIMD (lavapipe's subgroup) would be used by
/// consecutive rays, since a group runs as long as its longest ray.
pub fn report_counters(what: &str, counters: &[RayCounters]) {
    if counters.is_empty() {
        return;
    }
    let m = MeanCounters::of(counters);
    let max = counters.iter().map(RayCounters::steps).max().unwrap_or(0);
    eprintln!(
        "{what}: per ray {:.2} nodes, {:.2} leaves marched ({:.2} past their tile box), {:.2} cells ({:.2} tested, {:.2} block jumps), {:.2} triangle leaves, {:.2} triangles; steps (nodes + triangles + cells) mean {:.1}, max {max}; SIMD-8 utilisation {:.0}%",
        m.nodes,
        m.leaves,
        m.walks,
        m.cells,
        m.cells_tested,
        m.jumps,
        m.triangle_leaves,
        m.triangles,
        m.nodes + m.triangles + m.cells,
        100.0 * m.simd8_utilisation
    );
}
