//! The report as tables for people, one line per record: the numbers that decide the trade —
//! speed and memory relative to the exact BVH, and what they cost in accuracy ([`table`]) — and
//! where each ray's work and memory traffic go ([`work_table`]), and with `--steps` where its
//! steps go ([`steps_table`]).

use std::collections::BTreeSet;
use std::fmt::Write;

use super::record::{BenchReport, Record};
use super::steps::StepsRecord;

/// Columns that lead every table after the scene's, naming the record: header, width (the method
/// column fits `exact-instanced`), and whether values are left-aligned (names) rather than
/// right-aligned (numbers).
const LEAD: [(&str, usize, bool); 3] = [
    ("method", 15, true),
    ("level", 7, true),
    ("ray type", 8, true),
];

/// Columns of [`table`] after the [`LEAD`].
const COLUMNS: [(&str, usize, bool); 15] = [
    ("MRays/s", 8, false),
    ("speedup", 8, false),
    ("mem MB", 8, false),
    ("mem x", 6, false),
    ("B/texel", 7, false),
    ("miss %", 7, false),
    ("t p99 %", 8, false),
    ("obj t p99 %", 11, false),
    ("n err°", 7, false),
    ("backf %", 7, false),
    ("PSNR", 6, false),
    ("FLIP", 6, false),
    ("leaks", 6, false),
    ("through", 7, false),
    ("valid", 5, true),
];

/// Columns of [`work_table`]: the device's counters per ray, then, with `--traffic`, the model's
/// lines per ray, working set and DRAM bytes per ray behind each modelled cache.
const WORK_COLUMNS: [(&str, usize, bool); 13] = [
    ("nodes", 6, false),
    ("leaves", 6, false),
    ("walks", 6, false),
    ("cells", 6, false),
    ("tested", 6, false),
    ("jumps", 6, false),
    ("tris", 6, false),
    ("SIMD8", 6, false),
    ("lines", 6, false),
    ("set MB", 7, false),
    ("DRAM4M", 7, false),
    ("DRAM32M", 7, false),
    ("DRAM72M", 7, false),
];

/// Columns of [`steps_table`]: inner nodes per ray by depth band and their mean depth, then the
/// height-field leaves handed to the march by what came of them, and the leaf boxes at a hit.
const STEPS_COLUMNS: [(&str, usize, bool); 11] = [
    ("d0-7", 6, false),
    ("d8-15", 6, false),
    ("d16-23", 6, false),
    ("d24-31", 6, false),
    ("d32+", 6, false),
    ("depth", 6, false),
    ("missed", 6, false),
    ("empty", 6, false),
    ("behind", 6, false),
    ("near", 6, false),
    ("boxes", 6, false),
];

/// `text` padded to `width`, on the side `left` says.
fn pad(text: &str, width: usize, left: bool) -> String {
    if left {
        format!("{text:<width$}")
    } else {
        format!("{text:>width$}")
    }
}

/// Where the run measured, on one line ([`super::provenance::Provenance::line`]): every table of a
/// run is printed under it, so that a copied table says where it was taken.
pub fn host_line(report: &BenchReport) -> String {
    report.provenance.line() + "\n"
}

/// The table, under the [`host_line`], with a footnote on units.
pub fn table(report: &BenchReport) -> String {
    let sources: BTreeSet<&str> = report
        .results
        .iter()
        .map(|r| r.timing_source.name())
        .collect();
    let passes = report.results.iter().map(|r| r.passes);
    let (fewest, most) = (passes.clone().min().unwrap_or(1), passes.max().unwrap_or(1));
    let passes = if fewest == most {
        format!("{most}")
    } else {
        format!("{fewest}-{most}")
    };
    let shortest = if report.min_run_ms > 0.0 {
        format!(", a run at least {} ms", report.min_run_ms)
    } else {
        String::new()
    };
    let leaks = report
        .results
        .iter()
        .find_map(|r| r.seams)
        .map_or(String::new(), |s| {
            format!(
                "; leaks: of {} rays aimed at each level's seams between leaves, those that \
                 passed through the surface, through: those that passed through the solid \
                 (rbvh::bench::seams)",
                s.rays
            )
        });
    let footnote = format!(
        "MRays/s: median of {} runs of {passes} trace pass(es){shortest} (timing: {}); mem x: \
         exact's bytes / these; B/texel: the atlas's device bytes (unused texels and block \
         ranges included) per tile texel; t p99: hit distance error, % of the scene diagonal (obj: of the \
         diagonal of the object the exact ray hit); n err: mean normal error; backf: hits whose \
         normal faces away from the ray where the exact one faces it, % of the rays; PSNR/FLIP: \
         shaded primary image{leaks}",
        report.runs,
        sources.into_iter().collect::<Vec<_>>().join(" and ")
    );
    host_line(report) + &render(report, &COLUMNS, cells, &footnote)
}

/// Where each record's work went: the device's per-ray counters and, where the run modelled it
/// (`--traffic`), memory traffic.
pub fn work_table(report: &BenchReport) -> String {
    let footnote =
        "per ray (device counters): inner nodes, leaves handed to the march, walks (leaves \
                    past their tile box), cells visited, cells tested (past the height \
                    rejection), block jumps, triangles; SIMD8: steps of a ray over its 8-ray \
                    group's longest. With --traffic (CPU twin, rays in 8x8 tiles): lines = \
                    distinct 128-byte lines per ray; set = the frame's working set; DRAMnM = \
                    bytes per ray from DRAM behind an n MiB LRU cache (a model, see docs/ray-work.md)";
    render(report, &WORK_COLUMNS, work_cells, footnote)
}

/// Where each record's steps went, for the records the run accounted for (`--steps`); empty
/// where none was.
pub fn steps_table(report: &BenchReport) -> String {
    if report.results.iter().all(|r| r.steps.is_none()) {
        return String::new();
    }
    let footnote = "per ray (CPU twin, --steps): inner nodes at tree levels 0-7, 8-15, 16-23, \
                    24-31 and 32 on, and the mean level of a visited node; height-field leaves \
                    handed to the march whose tile box the ray missed, whose surface it did not \
                    meet, met behind the nearest hit, or that held the nearest hit; boxes: leaf \
                    boxes holding a hit's point (1: no overlap there)";
    render(report, &STEPS_COLUMNS, steps_cells, footnote)
}

/// What the driver compiled each trace pipeline into (registers, spills, …: where a GPU's
/// occupancy is decided), one line per pipeline; empty where the device reports nothing.
pub fn shader_table(report: &BenchReport) -> String {
    let mut out = String::new();
    for shader in report
        .shaders
        .iter()
        .filter(|s| !s.compiled.statistics.is_empty())
    {
        let statistics: Vec<String> = shader
            .compiled
            .statistics
            .iter()
            .map(|s| s.to_string())
            .collect();
        out += &format!(
            "{} ({}): {}\n",
            shader.compiled.pipeline,
            shader.method.name(),
            statistics.join(", ")
        );
    }
    if out.is_empty() {
        out
    } else {
        format!("shaders, as the driver compiled them:\n{out}")
    }
}

/// `report`'s records under the [`LEAD`] and `columns`, one line each from its lead and `cells`,
/// then `footnote`.
fn render<const N: usize>(
    report: &BenchReport,
    columns: &[(&str, usize, bool); N],
    cells: fn(&Record) -> [String; N],
    footnote: &str,
) -> String {
    let scene_width = report
        .results
        .iter()
        .map(|r| r.scene.chars().count())
        .chain(["scene".len()])
        .max()
        .unwrap_or(0);
    let mut out = String::new();
    let header: Vec<String> = LEAD
        .iter()
        .chain(columns)
        .map(|&(h, w, l)| pad(h, w, l))
        .collect();
    // Writing to a String cannot fail.
    let _ = writeln!(
        out,
        "{}",
        format!("{:<scene_width$} {}", "scene", header.join(" ")).trim_end()
    );
    for r in &report.results {
        let lead = [
            r.method.name().to_string(),
            r.level_label(),
            r.ray_type.name().to_string(),
        ];
        let cells: Vec<String> = lead
            .iter()
            .chain(&cells(r))
            .zip(LEAD.iter().chain(columns))
            .map(|(c, &(_, w, l))| pad(c, w, l))
            .collect();
        let line = format!("{:<scene_width$} {}", r.scene, cells.join(" "));
        let _ = writeln!(out, "{}", line.trim_end());
    }
    let _ = writeln!(out, "{footnote}");
    out
}

fn cells(r: &Record) -> [String; COLUMNS.len()] {
    let dash = || "-".to_string();
    let num = |v: Option<f64>, digits: usize| v.map_or_else(dash, |v| format!("{v:.digits$}"));
    let e = r.error.as_ref();
    [
        format!("{:.2}", r.mrays_per_s.median),
        format!("{:.2}x", r.speedup_vs_exact),
        format!("{:.2}", r.memory_bytes.total as f64 / 1e6),
        format!("{:.1}", r.memory_ratio_vs_exact),
        match r.memory_bytes.texels {
            0 => dash(),
            n => format!("{:.2}", r.memory_bytes.atlas as f64 / n as f64),
        },
        num(e.map(|e| 100.0 * e.miss_mismatch_rate), 2),
        num(e.and_then(|e| e.t_err_p99).map(|t| 100.0 * t), 3),
        num(e.and_then(|e| e.t_err_object_p99).map(|t| 100.0 * t), 3),
        num(e.and_then(|e| e.normal_err_deg_mean), 1),
        num(e.and_then(|e| e.back_facing_rate).map(|b| 100.0 * b), 3),
        num(e.and_then(|e| e.psnr_db), 1),
        num(e.and_then(|e| e.flip_mean), 3),
        r.seams.map_or_else(dash, |s| s.leaks.to_string()),
        r.seams.map_or_else(dash, |s| s.through.to_string()),
        if r.valid { "yes" } else { "NO" }.into(),
    ]
}

fn work_cells(r: &Record) -> [String; WORK_COLUMNS.len()] {
    let c = &r.counters;
    let t = r.traffic.as_ref().map(|t| &t.traffic);
    let dash = || "-".to_string();
    let dram = |k: usize| {
        t.and_then(|t| t.caches.get(k))
            .map_or_else(dash, |c| format!("{:.0}", c.dram_bytes_per_ray))
    };
    [
        format!("{:.2}", c.nodes),
        format!("{:.2}", c.leaves),
        format!("{:.2}", c.walks),
        format!("{:.2}", c.cells),
        format!("{:.2}", c.cells_tested),
        format!("{:.2}", c.jumps),
        format!("{:.2}", c.triangles),
        format!("{:.0}%", 100.0 * c.simd8_utilisation),
        t.map_or_else(dash, |t| format!("{:.2}", t.lines128_per_ray)),
        t.map_or_else(dash, |t| format!("{:.2}", t.working_set_bytes as f64 / 1e6)),
        dram(0),
        dram(1),
        dram(2),
    ]
}

fn steps_cells(r: &Record) -> [String; STEPS_COLUMNS.len()] {
    let dash = || "-".to_string();
    let num =
        |f: &dyn Fn(&StepsRecord) -> f64| r.steps.map_or_else(dash, |s| format!("{:.2}", f(&s)));
    [
        num(&|s| s.nodes_by_depth[0]),
        num(&|s| s.nodes_by_depth[1]),
        num(&|s| s.nodes_by_depth[2]),
        num(&|s| s.nodes_by_depth[3]),
        num(&|s| s.nodes_by_depth[4]),
        num(&|s| s.node_depth_mean),
        num(&|s| s.leaves_tile_missed),
        num(&|s| s.leaves_no_surface),
        num(&|s| s.leaves_behind),
        num(&|s| s.leaves_nearest),
        num(&|s| s.boxes_at_hit),
    ]
}
