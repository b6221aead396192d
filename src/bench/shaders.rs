//! `rbvh shaders`: every pipeline the library has, compiled on a device
//! ([`crate::gpu::compile_every_pipeline`]), with the run's provenance — a results file of what
//! the driver made of each (registers, spills, code size, scratch, waves per SIMD), and its table.
//!
//! On RADV's null device (`RADV_FORCE_FAMILY=navi21`, Mesa's "null hardware") this is AMD's real
//! compiler on a machine without an AMD GPU: deterministic for a given Mesa, so a change's cost in
//! registers is known before any GPU is at hand. Mesa 22.3's RADV on navi21, wave64, is the
//! project's reference (the repository's `docs/results/shaders-*.json`).

use std::io::Write;
use std::path::Path;

use serde::Serialize;

use super::provenance::Provenance;
use crate::gpu::{
    compile_every_pipeline, CompiledPipeline, Context, ShaderStatistic, StatisticValue,
};
use crate::io::write_atomically;
use crate::Result;

/// What `rbvh shaders` measured: where, and every pipeline.
#[derive(Clone, Debug, Serialize)]
pub struct ShaderReport {
    /// Where and when: device, driver, date, commit, host, version.
    #[serde(flatten)]
    pub provenance: Provenance,
    /// Whether the device only compiles (RADV's null device).
    pub compile_only: bool,
    /// `RADV_FORCE_FAMILY`, where set: the AMD family compiled for.
    pub amd_family: Option<String>,
    /// `RADV_PERFTEST`, where set (`cswave32` compiles compute shaders for wave32).
    pub radv_perftest: Option<String>,
    /// Every pipeline, in [`compile_every_pipeline`]'s order.
    pub pipelines: Vec<CompiledPipeline>,
}

/// Compiles every pipeline on `ctx` and describes the run.
pub fn shader_report(ctx: &Context) -> Result<ShaderReport> {
    let provenance = Provenance::of(ctx);
    let pipelines = compile_every_pipeline(ctx)?;
    let env = |name: &str| std::env::var(name).ok().filter(|v| !v.is_empty());
    let compile_only = ctx.limits().compile_only;
    Ok(ShaderReport {
        provenance,
        compile_only,
        amd_family: env("RADV_FORCE_FAMILY").filter(|_| compile_only),
        radv_perftest: env("RADV_PERFTEST").filter(|_| ctx.driver().starts_with("radv")),
        pipelines,
    })
}

/// Writes `report` as pretty-printed JSON, atomically.
pub fn write_shader_json(path: &Path, report: &ShaderReport) -> Result<()> {
    write_atomically(path, |w| {
        serde_json::to_writer_pretty(&mut *w, report)?;
        writeln!(w)
    })
}

/// The statistics a table shows, as (header, the drivers' names for it): RADV's (ACO) and
/// NVIDIA's words. Registers decide occupancy; spills and scratch mean memory traffic; waves per
/// SIMD is RADV's occupancy (wave32 slots on GFX10+: halve it for wave64).
pub const COLUMNS: [(&str, &[&str]); 10] = [
    ("registers", &["VGPRs", "Register Count"]),
    ("SGPRs", &["Pre-Sched SGPRs"]),
    ("spilled VGPRs", &["Spilled VGPRs"]),
    ("spilled SGPRs", &["Spilled SGPRs"]),
    ("private VGPRs", &["PrivMem VGPRs"]),
    ("code bytes", &["Code size", "Binary Size"]),
    ("scratch bytes", &["Scratch size", "Local Memory Size"]),
    ("LDS bytes", &["LDS size", "Shared Memory Size"]),
    ("waves/SIMD", &["Subgroups per SIMD"]),
    ("instructions", &["Instructions"]),
];

/// The value of the statistic a column shows, where the pipeline has it.
pub fn column_value<'a>(
    statistics: &'a [ShaderStatistic],
    names: &[&str],
) -> Option<&'a StatisticValue> {
    names
        .iter()
        .find_map(|n| statistics.iter().find(|s| s.name == *n))
        .map(|s| &s.value)
}

/// The report as a table for people: the host line, then a row per pipeline with the
/// [`COLUMNS`] any pipeline has (the rest are in the JSON).
pub fn shader_report_table(report: &ShaderReport) -> String {
    let shown: Vec<&(&str, &[&str])> = COLUMNS
        .iter()
        .filter(|(_, names)| {
            report
                .pipelines
                .iter()
                .any(|p| column_value(&p.statistics, names).is_some())
        })
        .collect();
    let name_width = report
        .pipelines
        .iter()
        .map(|p| p.pipeline.len())
        .chain(["pipeline".len()])
        .max()
        .unwrap_or(0);
    let mut out = report.provenance.line();
    if let Some(family) = &report.amd_family {
        out += &format!("; null device for {family}");
    }
    if let Some(perftest) = &report.radv_perftest {
        out += &format!("; RADV_PERFTEST={perftest}");
    }
    out.push('\n');
    let mut header = format!("{:<name_width$}", "pipeline");
    for (h, _) in &shown {
        header += &format!(" {h:>w$}", w = h.len().max(6));
    }
    out += header.trim_end();
    out.push('\n');
    for p in &report.pipelines {
        let mut line = format!("{:<name_width$}", p.pipeline);
        for (h, names) in &shown {
            let cell =
                column_value(&p.statistics, names).map_or("-".to_string(), |v| v.to_string());
            line += &format!(" {cell:>w$}", w = h.len().max(6));
        }
        out += line.trim_end();
        out.push('\n');
    }
    if shown.is_empty() {
        out += "(the driver reports no statistics: VK_KHR_pipeline_executable_properties is not offered)\n";
    }
    out
}
