//! The report as a table for people: one line per record, the numbers that decide the trade —
//! speed and memory relative to the exact BVH, and what they cost in accuracy.

use std::collections::BTreeSet;
use std::fmt::Write;

use super::record::{BenchReport, Record};

/// Columns after the scene's: header, width, and whether values are left-aligned (names) rather
/// than right-aligned (numbers).
const COLUMNS: [(&str, usize, bool); 13] = [
    ("method", 8, true),
    ("level", 6, true),
    ("ray type", 8, true),
    ("MRays/s", 8, false),
    ("speedup", 8, false),
    ("mem MB", 8, false),
    ("mem x", 6, false),
    ("miss %", 7, false),
    ("t p99 %", 8, false),
    ("n err°", 7, false),
    ("PSNR", 6, false),
    ("FLIP", 6, false),
    ("valid", 5, true),
];

/// `text` padded to `width`, on the side `left` says.
fn pad(text: &str, width: usize, left: bool) -> String {
    if left {
        format!("{text:<width$}")
    } else {
        format!("{text:>width$}")
    }
}

/// The table, with a header line and a footnote on units.
pub fn table(report: &BenchReport) -> String {
    let scene_width = report
        .results
        .iter()
        .map(|r| r.scene.chars().count())
        .chain(["scene".len()])
        .max()
        .unwrap_or(0);
    let mut out = String::new();
    let header: Vec<String> = COLUMNS.iter().map(|&(h, w, l)| pad(h, w, l)).collect();
    // Writing to a String cannot fail.
    let _ = writeln!(
        out,
        "{}",
        format!("{:<scene_width$} {}", "scene", header.join(" ")).trim_end()
    );
    for r in &report.results {
        let cells: Vec<String> = cells(r)
            .iter()
            .zip(COLUMNS)
            .map(|(c, (_, w, l))| pad(c, w, l))
            .collect();
        let line = format!("{:<scene_width$} {}", r.scene, cells.join(" "));
        let _ = writeln!(out, "{}", line.trim_end());
    }
    let sources: BTreeSet<&str> = report
        .results
        .iter()
        .map(|r| r.timing_source.name())
        .collect();
    let _ = writeln!(
        out,
        "MRays/s: median of {} runs (timing: {}); mem x: exact's bytes / these; t p99: hit \
         distance error, % of the scene diagonal; n err: mean normal error; PSNR/FLIP: shaded \
         primary image",
        report.runs,
        sources.into_iter().collect::<Vec<_>>().join(" and ")
    );
    out
}

fn cells(r: &Record) -> [String; COLUMNS.len()] {
    let dash = || "-".to_string();
    let num = |v: Option<f64>, digits: usize| v.map_or_else(dash, |v| format!("{v:.digits$}"));
    let e = r.error.as_ref();
    [
        r.method.name().into(),
        r.quality.clone().unwrap_or_else(dash),
        r.ray_type.name().into(),
        format!("{:.2}", r.mrays_per_s.median),
        format!("{:.2}x", r.speedup_vs_exact),
        format!("{:.2}", r.memory_bytes.total as f64 / 1e6),
        format!("{:.1}", r.memory_ratio_vs_exact),
        num(e.map(|e| 100.0 * e.miss_mismatch_rate), 2),
        num(e.and_then(|e| e.t_err_p99).map(|t| 100.0 * t), 3),
        num(e.and_then(|e| e.normal_err_deg_mean), 1),
        num(e.and_then(|e| e.psnr_db), 1),
        num(e.and_then(|e| e.flip_mean), 3),
        if r.valid { "yes" } else { "NO" }.into(),
    ]
}
