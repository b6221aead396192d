//! Markdown tables made from results files, written into the documents that name them — so that
//! no measured figure in a document is typed by hand (`rbvh tables`; the repository's
//! `docs/results/README.md` describes the files and the blocks).
//!
//! A block in a document:
//!
//! ```markdown
//! <!-- table docs/results/bench-dragon.json view=ratios rays=primary,shadow -->
//! (generated: the table, then a line saying where and when it was measured)
//! <!-- /table -->
//! ```
//!
//! The file is either raw results — the JSON `rbvh bench --json` or `rbvh shaders --json` wrote,
//! which a *view* turns into a table — or a *transcribed* measurement whose raw file was not kept
//! (`{"transcribed": {source, commit, host, device, note}, "columns", "align", "rows"}`), shown as
//! it was recorded, or that no view makes from its raw files, named by an optional
//! `transcribed.raw` (a list of paths). Either way the line under the table names the commit and the host.

use std::io::Write as _;
use std::path::{Component, Path, PathBuf};

use serde_json::Value;

use super::provenance::Provenance;
use super::shaders::{column_value, COLUMNS};
use super::transcribed;
use crate::gpu::ShaderStatistic;
use crate::{Error, Result};

/// What a view or caption makes, or what is wrong with the results file (the caller names the
/// file and the document's line).
type Made<T> = std::result::Result<T, String>;

/// The comment that opens a generated block, before the results file's path.
pub const OPEN: &str = "<!-- table ";
/// The comment that closes a generated block.
pub const CLOSE: &str = "<!-- /table -->";
/// The comment that marks the next table as holding no measurement (a layout, a list, pictures).
pub const NOT_A_MEASUREMENT: &str = "<!-- not a measurement -->";

/// A document whose blocks differ from what their files make.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Stale {
    /// The document, relative to the root.
    pub document: PathBuf,
    /// 1-based line of each differing block's opening comment.
    pub lines: Vec<usize>,
}

/// The documents of a repository that hold measurements: `README.md`, `scenes/README.md` and
/// `docs/*.md`, those that exist, relative to `root`.
pub fn documents(root: &Path) -> Result<Vec<PathBuf>> {
    let mut found: Vec<PathBuf> = ["README.md", "scenes/README.md"]
        .iter()
        .map(PathBuf::from)
        .filter(|p| root.join(p).is_file())
        .collect();
    let docs = root.join("docs");
    if docs.is_dir() {
        let mut md: Vec<PathBuf> = std::fs::read_dir(&docs)
            .map_err(|e| Error::io(&docs, e))?
            .flatten()
            .map(|e| e.path())
            .filter(|p| p.extension().is_some_and(|e| e == "md"))
            .filter_map(|p| p.strip_prefix(root).ok().map(Path::to_path_buf))
            .collect();
        md.sort();
        found.extend(md);
    }
    Ok(found)
}

/// Regenerates every block of every document of [`documents`] under `root`: writes the documents
/// that change unless `check`, and returns them either way (empty: every table is what its file
/// makes).
pub fn update(root: &Path, check: bool) -> Result<Vec<Stale>> {
    let mut stale = Vec::new();
    for document in documents(root)? {
        let path = root.join(&document);
        let text = std::fs::read_to_string(&path).map_err(|e| Error::io(&path, e))?;
        let (regenerated, lines) = regenerate(root, &document, &text)?;
        if !lines.is_empty() {
            if !check {
                crate::io::write_atomically(&path, |w| w.write_all(regenerated.as_bytes()))?;
            }
            stale.push(Stale { document, lines });
        }
    }
    Ok(stale)
}

/// `text` (of `document`, relative to `root`) with each block's content made from its file, and
/// the 1-based lines of the blocks that changed.
pub fn regenerate(root: &Path, document: &Path, text: &str) -> Result<(String, Vec<usize>)> {
    let lines: Vec<&str> = text.lines().collect();
    let mut out = String::with_capacity(text.len());
    let mut changed = Vec::new();
    let mut fenced = false;
    let mut k = 0;
    while k < lines.len() {
        let line = lines[k];
        out.push_str(line);
        out.push('\n');
        if line.trim_start().starts_with("```") {
            fenced = !fenced;
        }
        let spec = match line.trim().strip_prefix(OPEN) {
            Some(spec) if !fenced => spec,
            _ => {
                k += 1;
                continue;
            }
        };
        let at = |m: String| Error::parse(document, Some(k + 1), m);
        let spec = spec
            .strip_suffix("-->")
            .ok_or_else(|| at("a table comment ends with -->".into()))?;
        // The block ends at the first close; an opening before it means this one lost its close,
        // and writing would swallow what lies between.
        let end = lines[k + 1..]
            .iter()
            .position(|l| l.trim() == CLOSE || l.trim().starts_with(OPEN))
            .map(|e| k + 1 + e)
            .filter(|&e| lines[e].trim() == CLOSE)
            .ok_or_else(|| at(format!("no {CLOSE} before the next block or the end")))?;
        let block = Block::parse(spec).map_err(at)?;
        let made = block.render(root, document).map_err(at)?;
        if lines[k + 1..end].join("\n") != made.trim_end_matches('\n') {
            changed.push(k + 1);
        }
        out.push_str(&made);
        out.push_str(CLOSE);
        out.push('\n');
        k = end + 1;
    }
    if !text.ends_with('\n') && out.ends_with('\n') {
        out.pop();
    }
    Ok((out, changed))
}

/// Lines of `text` that begin a markdown table (a `|` line followed by an alignment row) outside
/// every generated block and not marked [`NOT_A_MEASUREMENT`] on the line before: tables typed by
/// hand.
pub fn unmarked_tables(text: &str) -> Vec<usize> {
    let lines: Vec<&str> = text.lines().collect();
    let mut inside = false;
    let mut fenced = false;
    let mut found = Vec::new();
    for (k, line) in lines.iter().enumerate() {
        let t = line.trim();
        if t.starts_with("```") {
            fenced = !fenced;
        }
        if fenced {
            continue;
        }
        if t.starts_with(OPEN) {
            inside = true;
        } else if t == CLOSE {
            inside = false;
        }
        let header = t.starts_with('|')
            && lines.get(k + 1).is_some_and(|next| is_alignment_row(next))
            && (k == 0 || !lines[k - 1].trim().starts_with('|'));
        if header && !inside && (k == 0 || lines[k - 1].trim() != NOT_A_MEASUREMENT) {
            found.push(k + 1);
        }
    }
    found
}

fn is_alignment_row(line: &str) -> bool {
    let t = line.trim();
    t.starts_with('|') && t.contains('-') && t.chars().all(|c| matches!(c, '|' | '-' | ':' | ' '))
}

/// A block's comment: the results file (for `view=ratios`, several, comma-separated: repeated
/// invocations whose ratios are shown as medians and ranges) and, for raw results, the view and
/// its filters.
#[derive(Clone, Debug, PartialEq, Eq)]
struct Block {
    files: Vec<PathBuf>,
    view: Option<String>,
    filters: Vec<(String, Vec<String>)>,
}

impl Block {
    fn parse(spec: &str) -> std::result::Result<Block, String> {
        let mut words = spec.split_whitespace();
        let files = words
            .next()
            .ok_or("a table comment names its results file")?;
        let mut block = Block {
            files: files.split(',').map(PathBuf::from).collect(),
            view: None,
            filters: Vec::new(),
        };
        for word in words {
            let (key, value) = word
                .split_once('=')
                .ok_or_else(|| format!("{word:?}: options are key=value"))?;
            let values: Vec<String> = value.split(',').map(str::to_string).collect();
            match key {
                "view" => block.view = Some(value.to_string()),
                "scene" | "rays" | "levels" | "pipelines" => {
                    block.filters.push((key.to_string(), values))
                }
                _ => {
                    return Err(format!(
                        "unknown option {key:?} (view, scene, rays, levels, pipelines)"
                    ))
                }
            }
        }
        Ok(block)
    }

    fn filter(&self, key: &str) -> Option<&[String]> {
        self.filters
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_slice())
    }

    /// The block's content: the table, a blank line and the line saying where it was measured;
    /// or what is wrong with a results file, naming it.
    fn render(&self, root: &Path, document: &Path) -> Made<String> {
        let mut jsons = Vec::new();
        let mut links = Vec::new();
        for file in &self.files {
            let name = file.display();
            let text = std::fs::read_to_string(root.join(file))
                .map_err(|e| format!("results file {name}: {e}"))?;
            let json: Value = serde_json::from_str(&text)
                .map_err(|e| format!("results file {name}:{}: {e}", e.line()))?;
            jsons.push(json);
            let link = relative(document.parent().unwrap_or(Path::new("")), file);
            links.push(link.to_string_lossy().replace('\\', "/"));
        }
        let names: Vec<String> = self.files.iter().map(|f| f.display().to_string()).collect();
        let made = match jsons.as_slice() {
            [json] if json.get("transcribed").is_some() => {
                if self.view.is_some() || !self.filters.is_empty() {
                    Err("a transcribed file is shown as recorded: no view or filters".to_string())
                } else {
                    transcribed::table(json).and_then(|(header, align, rows)| {
                        let caption = transcribed::caption(&json["transcribed"])?;
                        Ok((markdown(&header, &align, &rows), caption))
                    })
                }
            }
            _ if jsons.iter().any(|j| j.get("transcribed").is_some()) => {
                Err("a transcribed file is shown alone".to_string())
            }
            _ if self.view.as_deref() == Some("glance") => self
                .view_table(&jsons)
                .and_then(|table| Ok((table, glance_caption(&jsons, |r| self.keeps(r))?))),
            _ => self
                .view_table(&jsons)
                .and_then(|table| Ok((table, measured_caption(&jsons, true)?))),
        };
        let (table, caption) =
            made.map_err(|m| format!("results file {}: {m}", names.join(", ")))?;
        let links: Vec<String> = links
            .iter()
            .enumerate()
            .map(|(k, l)| match k {
                0 => format!("[results]({l})"),
                _ => format!("[{}]({l})", k + 1),
            })
            .collect();
        Ok(format!(
            "{table}\n<sub>{caption} ({})</sub>\n",
            links.join(", ")
        ))
    }

    fn view_table(&self, jsons: &[Value]) -> Made<String> {
        let view = self.view.as_deref().unwrap_or("summary");
        if jsons.len() > 1 && view != "ratios" && view != "glance" {
            return Err(format!(
                "view={view} shows one file; several make medians in view=ratios or view=glance"
            ));
        }
        if view == "shaders" {
            return shaders_table(&jsons[0], self.filter("pipelines"));
        }
        let runs = jsons
            .iter()
            .map(|json| {
                json["results"]
                    .as_array()
                    .map(|records| records.iter().filter(|r| self.keeps(r)).collect())
                    .ok_or_else(|| {
                        "neither bench results (`results`), shader results (`pipelines`) nor \
                         transcribed"
                            .to_string()
                    })
            })
            .collect::<Made<Vec<Vec<&Value>>>>()?;
        if runs.iter().any(Vec::is_empty) {
            return Err("no record passes the block's filters".to_string());
        }
        match view {
            "summary" => Ok(summary_table(&runs[0])),
            "work" => Ok(work_table(&runs[0])),
            "steps" => steps_table(&runs[0]),
            "ratios" => Ok(ratios_table(&runs)),
            "glance" => Ok(glance_table(&runs)),
            other => Err(format!(
                "unknown view {other:?} (summary, work, steps, ratios, glance, shaders)"
            )),
        }
    }

    /// Whether a bench record passes the block's filters.
    fn keeps(&self, record: &Value) -> bool {
        let ok = |key: &str, value: String| self.filter(key).is_none_or(|v| v.contains(&value));
        ok("scene", text(&record["scene"]))
            && ok("rays", text(&record["ray_type"]))
            && ok("levels", level(record))
    }
}

/// `path` (relative to the root) as seen from the folder `from` (relative to the root).
fn relative(from: &Path, path: &Path) -> PathBuf {
    let from: Vec<Component> = from.components().collect();
    let to: Vec<Component> = path.components().collect();
    let common = from.iter().zip(&to).take_while(|(a, b)| a == b).count();
    let mut out = PathBuf::new();
    for _ in common..from.len() {
        out.push("..");
    }
    for c in &to[common..] {
        out.push(c.as_os_str());
    }
    out
}

/// A JSON value as a cell: strings as they are, null as `-`.
fn text(v: &Value) -> String {
    match v {
        Value::Null => "-".into(),
        Value::String(s) => s.clone(),
        other => other.to_string(),
    }
}

/// A record's level as the bench tables write it: `exact`, `exact, two levels` (a scene's with
/// instances, method `exact-instanced`), `Q2`, `Q2h` (height-only), `Q2s`
/// (every triangle a height field can hold sampled, `exact_when_cheaper` false), `Q2v` (refined
/// for the scene's view, `view_rate` above 0), `Q2 LOD`, `Q2, two levels` (`rbvh-instanced`).
/// Records made before `exact_when_cheaper` existed have no such field and no `s`: they were
/// the presets of their commit, which the table's caption names.
fn level(record: &Value) -> String {
    let Some(q) = record["quality"].as_str() else {
        // The exact BVH, or a scene's with instances in two levels (`exact-instanced`).
        return match record["method"].as_str() {
            Some("exact-instanced") => "exact, two levels".into(),
            _ => "exact".into(),
        };
    };
    let name = crate::rbvh::level_name(
        q,
        record["params"]["texels"].as_str() == Some("height"),
        record["params"]["exact_when_cheaper"].as_bool() == Some(false),
        record["params"]["view_rate"]
            .as_f64()
            .is_some_and(|r| r > 0.0),
    );
    match record["method"].as_str() {
        Some("rbvh-lod") => format!("{name} LOD"),
        Some("rbvh-instanced") => format!("{name}, two levels"),
        _ => name,
    }
}

fn num(v: &Value, scale: f64, digits: usize) -> String {
    v.as_f64()
        .map_or("-".into(), |x| format!("{:.digits$}", x * scale))
}

/// Markdown table lines: the header, the alignment row (`r` right-aligned, else left), rows.
fn markdown<H: AsRef<str>>(header: &[H], align: &[char], rows: &[Vec<String>]) -> String {
    let row = |cells: &[String]| format!("| {} |", cells.join(" | "));
    let header: Vec<String> = header.iter().map(|h| h.as_ref().to_string()).collect();
    let mut out = vec![row(&header)];
    out.push(format!(
        "|{}|",
        header
            .iter()
            .enumerate()
            .map(|(i, _)| match align.get(i) {
                Some('r') => "---:",
                Some('c') => ":-:",
                _ => "---",
            })
            .collect::<Vec<_>>()
            .join("|")
    ));
    out.extend(rows.iter().map(|r| row(r)));
    out.join("\n") + "\n"
}

fn summary_table(records: &[&Value]) -> String {
    let header = [
        "scene",
        "method",
        "level",
        "rays",
        "MRays/s",
        "× exact",
        "MB",
        "× less",
        "miss %",
        "t p99 %",
        "normal °",
        "PSNR",
        "FLIP",
        "leaks",
        "through",
        "valid",
    ];
    let rows: Vec<Vec<String>> = records
        .iter()
        .map(|r| {
            let e = &r["error"];
            vec![
                text(&r["scene"]),
                text(&r["method"]),
                match level(r).as_str() {
                    "exact" => "-".into(),
                    l => l.to_string(),
                },
                text(&r["ray_type"]),
                num(&r["mrays_per_s"]["median"], 1.0, 2),
                format!("{}×", num(&r["speedup_vs_exact"], 1.0, 2)),
                num(&r["memory_bytes"]["total"], 1e-6, 2),
                num(&r["memory_ratio_vs_exact"], 1.0, 1),
                num(&e["miss_mismatch_rate"], 100.0, 2),
                num(&e["t_err_p99"], 100.0, 3),
                num(&e["normal_err_deg_mean"], 1.0, 1),
                num(&e["psnr_db"], 1.0, 1),
                num(&e["flip_mean"], 1.0, 3),
                r["seams"]["leaks"]
                    .as_u64()
                    .map_or("-".into(), |v| v.to_string()),
                r["seams"]["through"]
                    .as_u64()
                    .map_or("-".into(), |v| v.to_string()),
                if r["valid"].as_bool() == Some(true) {
                    "yes"
                } else {
                    "**no**"
                }
                .into(),
            ]
        })
        .collect();
    let align: Vec<char> = "llllrrrrrrrrrrrl".chars().collect();
    markdown(&header, &align, &rows)
}

fn work_table(records: &[&Value]) -> String {
    let header = [
        "scene",
        "level",
        "rays",
        "nodes",
        "leaves",
        "cells",
        "tested",
        "jumps",
        "triangles",
        "SIMD8",
    ];
    let rows: Vec<Vec<String>> = records
        .iter()
        .map(|r| {
            let c = &r["counters"];
            vec![
                text(&r["scene"]),
                level(r),
                text(&r["ray_type"]),
                num(&c["nodes"], 1.0, 2),
                num(&c["leaves"], 1.0, 2),
                num(&c["cells"], 1.0, 2),
                num(&c["cells_tested"], 1.0, 2),
                num(&c["jumps"], 1.0, 2),
                num(&c["triangles"], 1.0, 2),
                format!("{}%", num(&c["simd8_utilisation"], 100.0, 0)),
            ]
        })
        .collect();
    let align: Vec<char> = "lllrrrrrrr".chars().collect();
    markdown(&header, &align, &rows)
}

/// Where each record's steps go (`rbvh bench --steps`, [`super::steps::StepsRecord`]): inner nodes
/// a ray by depth band and their mean depth, the leaves handed to the march by what came of
/// them, and the leaf boxes at a hit; an error when a record has none.
fn steps_table(records: &[&Value]) -> Made<String> {
    let header = [
        "scene",
        "level",
        "rays",
        "nodes",
        "levels 0–7",
        "8–15",
        "16–23",
        "24–31",
        "32+",
        "mean level",
        "leaves",
        "tile missed",
        "no surface",
        "behind",
        "nearest",
        "boxes at hit",
    ];
    let rows = records
        .iter()
        .map(|r| {
            let s = &r["steps"];
            if s.is_null() {
                return Err(format!(
                    "{} {} {} has no steps (measured without --steps)",
                    text(&r["scene"]),
                    level(r),
                    text(&r["ray_type"])
                ));
            }
            let band = |k: usize| s["nodes_by_depth"][k].as_f64().unwrap_or(f64::NAN);
            Ok(vec![
                text(&r["scene"]),
                level(r),
                text(&r["ray_type"]),
                num(&r["counters"]["nodes"], 1.0, 2),
                format!("{:.2}", band(0)),
                format!("{:.2}", band(1)),
                format!("{:.2}", band(2)),
                format!("{:.2}", band(3)),
                format!("{:.2}", band(4)),
                num(&s["node_depth_mean"], 1.0, 1),
                num(&r["counters"]["leaves"], 1.0, 2),
                num(&s["leaves_tile_missed"], 1.0, 2),
                num(&s["leaves_no_surface"], 1.0, 2),
                num(&s["leaves_behind"], 1.0, 2),
                num(&s["leaves_nearest"], 1.0, 2),
                num(&s["boxes_at_hit"], 1.0, 2),
            ])
        })
        .collect::<Made<Vec<Vec<String>>>>()?;
    let align: Vec<char> = "lllrrrrrrrrrrrrr".chars().collect();
    Ok(markdown(&header, &align, &rows))
}

/// A row per (scene, ray type): the exact BVH's MRays/s, then each level's speed over it. Of
/// several invocations (`runs`, each one file's records), the median and, in brackets, the range:
/// each ratio is taken within one invocation, interleaved, and they scatter between invocations.
/// A bench of a scene with instances traced in two levels alone has no flat exact BVH: its
/// referee, the two-level exact BVH, gives the MRays/s then (its own column says 1.00).
fn ratios_table(runs: &[Vec<&Value>]) -> String {
    let mut levels: Vec<String> = Vec::new();
    let mut keys: Vec<(String, String)> = Vec::new();
    for r in runs.iter().flatten() {
        let l = level(r);
        if l != "exact" && !levels.contains(&l) {
            levels.push(l);
        }
        let key = (text(&r["scene"]), text(&r["ray_type"]));
        if !keys.contains(&key) {
            keys.push(key);
        }
    }
    let mut header = vec!["scene, rays".to_string(), "exact MRays/s".to_string()];
    header.extend(levels.iter().map(|l| format!("{l} × exact")));
    let rows: Vec<Vec<String>> = keys
        .iter()
        .map(|(scene, rays)| {
            // The records of (scene, rays, level) in every invocation that has one.
            let found = |l: &str| -> Vec<&Value> {
                runs.iter()
                    .filter_map(|run| {
                        run.iter().copied().find(|r| {
                            text(&r["scene"]) == *scene
                                && text(&r["ray_type"]) == *rays
                                && level(r) == l
                        })
                    })
                    .collect()
            };
            let spread = |records: &[&Value], value: fn(&Value) -> Option<f64>| {
                let mut v: Vec<f64> = records.iter().filter_map(|r| value(r)).collect();
                v.sort_by(f64::total_cmp);
                match (median(v.iter().copied()), v.len()) {
                    (None, _) => "-".to_string(),
                    (Some(m), 1) => format!("{m:.2}"),
                    (Some(m), n) => format!("{m:.2} ({:.2}–{:.2})", v[0], v[n - 1]),
                }
            };
            let exact = found("exact");
            let referee = if exact.is_empty() {
                found("exact, two levels")
            } else {
                exact
            };
            let mut row = vec![
                format!("{scene}, {rays}"),
                spread(&referee, |r| r["mrays_per_s"]["median"].as_f64()),
            ];
            row.extend(levels.iter().map(|l| {
                let records = found(l);
                let ratio = spread(&records, |r| r["speedup_vs_exact"].as_f64());
                if records.iter().all(|r| r["valid"].as_bool() == Some(true)) {
                    ratio
                } else {
                    format!("{ratio} (invalid)")
                }
            }));
            row
        })
        .collect();
    let align: Vec<char> = std::iter::once('l')
        .chain(std::iter::repeat('r'))
        .take(header.len())
        .collect();
    markdown(&header, &align, &rows)
}

/// The trade at a glance: a row per (scene, level), the exact BVH first, with what the level
/// costs (megabytes, and how many times smaller than the exact BVH), what it buys (its speed
/// over the exact BVH's, a column per ray type measured) and what it gives up (its primary
/// rays' hit-distance error p99 and FLIP, and whether the bench judged every ray type valid).
/// Speeds are medians over the invocations (`runs`) that hold the record; sizes and errors are
/// deterministic, so any invocation's. The exact BVH's speed cells give its MRays/s.
fn glance_table(runs: &[Vec<&Value>]) -> String {
    let mut keys: Vec<(String, String)> = Vec::new();
    let mut rays: Vec<String> = Vec::new();
    for r in runs.iter().flatten() {
        let key = (text(&r["scene"]), level(r));
        if !keys.contains(&key) {
            keys.push(key);
        }
        let ray = text(&r["ray_type"]);
        if !rays.contains(&ray) {
            rays.push(ray);
        }
    }
    // Exact first within each scene, the levels in the order the files hold them.
    let scenes: Vec<String> = keys.iter().fold(Vec::new(), |mut v, (scene, _)| {
        if !v.contains(scene) {
            v.push(scene.clone());
        }
        v
    });
    keys.sort_by_key(|(scene, l)| {
        (
            scenes.iter().position(|s| s == scene),
            l != "exact",
            keys_order(runs, scene, l),
        )
    });
    let mut header: Vec<String> = ["scene", "level", "MB", "× smaller"]
        .map(String::from)
        .to_vec();
    header.extend(rays.iter().map(|ray| format!("{ray} × exact")));
    header.extend(["t p99 %", "FLIP", "valid"].map(String::from));
    let rows: Vec<Vec<String>> = keys
        .iter()
        .map(|(scene, l)| {
            let records: Vec<&Value> = runs
                .iter()
                .flatten()
                .copied()
                .filter(|r| text(&r["scene"]) == *scene && level(r) == *l)
                .collect();
            let first = records[0];
            let primary = records
                .iter()
                .find(|r| r["ray_type"].as_str() == Some("primary"))
                .copied();
            let exact = l == "exact";
            let mut row = vec![
                scene.clone(),
                if exact { "exact BVH".into() } else { l.clone() },
                num(&first["memory_bytes"]["total"], 1e-6, 2),
                if exact {
                    "1".into()
                } else {
                    num(&first["memory_ratio_vs_exact"], 1.0, 1)
                },
            ];
            row.extend(rays.iter().map(|ray| {
                let of_ray: Vec<&Value> = records
                    .iter()
                    .copied()
                    .filter(|r| text(&r["ray_type"]) == *ray)
                    .collect();
                if exact {
                    median(
                        of_ray
                            .iter()
                            .filter_map(|r| r["mrays_per_s"]["median"].as_f64()),
                    )
                    .map_or("-".into(), |m| format!("{m:.2} MRays/s"))
                } else {
                    median(of_ray.iter().filter_map(|r| r["speedup_vs_exact"].as_f64()))
                        .map_or("-".into(), |m| format!("{m:.2}×"))
                }
            }));
            let error = primary.map(|r| &r["error"]);
            row.push(error.map_or("-".into(), |e| num(&e["t_err_p99"], 100.0, 3)));
            row.push(error.map_or("-".into(), |e| num(&e["flip_mean"], 1.0, 3)));
            row.push(
                if records.iter().all(|r| r["valid"].as_bool() == Some(true)) {
                    "yes"
                } else {
                    "**no**"
                }
                .into(),
            );
            row
        })
        .collect();
    let align: Vec<char> = "ll"
        .chars()
        .chain(std::iter::repeat('r'))
        .take(header.len() - 1)
        .chain(std::iter::once('l'))
        .collect();
    markdown(&header, &align, &rows)
}

/// Where `level` of `scene` first appears in the files, so that a glance keeps their order.
fn keys_order(runs: &[Vec<&Value>], scene: &str, level_name: &str) -> usize {
    runs.iter()
        .flatten()
        .position(|r| text(&r["scene"]) == scene && level(r) == level_name)
        .unwrap_or(usize::MAX)
}

/// The median of `values`, None when there are none.
fn median(values: impl Iterator<Item = f64>) -> Option<f64> {
    let mut v: Vec<f64> = values.collect();
    v.sort_by(f64::total_cmp);
    let n = v.len();
    match n {
        0 => None,
        _ if n % 2 == 1 => Some(v[n / 2]),
        _ => Some(0.5 * (v[n / 2 - 1] + v[n / 2])),
    }
}

/// The line under a glance: one [`measured_caption`] per group of files that share a host,
/// device and settings, each naming the scenes it measured, so that a glance may set side by side
/// a small scene measured three times and the paper's scale measured once, or two machines,
/// and still say where every row was taken.
fn glance_caption(jsons: &[Value], keeps: impl Fn(&Value) -> bool) -> Made<String> {
    let key = |j: &Value| {
        [
            &j["host"],
            &j["device"],
            &j["driver"],
            &j["width"],
            &j["height"],
            &j["runs"],
        ]
        .map(|v| v.to_string())
    };
    let mut groups: Vec<Vec<Value>> = Vec::new();
    for json in jsons {
        match groups.iter_mut().find(|g| key(&g[0]) == key(json)) {
            Some(group) => group.push(json.clone()),
            None => groups.push(vec![json.clone()]),
        }
    }
    let parts = groups
        .iter()
        .map(|group| {
            let mut scenes: Vec<String> = Vec::new();
            for r in group
                .iter()
                .flat_map(|j| j["results"].as_array().into_iter().flatten())
                .filter(|r| keeps(r))
            {
                let scene = text(&r["scene"]);
                if !scenes.contains(&scene) {
                    scenes.push(scene);
                }
            }
            Ok(format!(
                "{}: {}",
                scenes.join(", "),
                measured_caption(group, false)?
            ))
        })
        .collect::<Made<Vec<String>>>()?;
    Ok(parts.join(" "))
}

/// `rbvh shaders` results: a row per pipeline (`pipelines=default`: the variants the tracers use
/// by default), with the statistics of [`COLUMNS`] that any row has.
fn shaders_table(json: &Value, which: Option<&[String]>) -> Made<String> {
    let pipelines = json["pipelines"]
        .as_array()
        .ok_or_else(|| "view=shaders needs rbvh shaders results".to_string())?;
    let only_default = which.is_some_and(|w| w.iter().any(|p| p == "default"));
    let rows: Vec<(String, Vec<ShaderStatistic>)> = pipelines
        .iter()
        .filter(|p| !only_default || p["default_variant"].as_bool() == Some(true))
        .map(|p| {
            let statistics: Vec<ShaderStatistic> =
                serde_json::from_value(p["statistics"].clone()).unwrap_or_default();
            (format!("`{}`", text(&p["pipeline"])), statistics)
        })
        .collect();
    let shown: Vec<&(&str, &[&str])> = COLUMNS
        .iter()
        .filter(|(_, names)| rows.iter().any(|(_, s)| column_value(s, names).is_some()))
        .collect();
    let mut header = vec!["pipeline".to_string()];
    header.extend(shown.iter().map(|(h, _)| h.to_string()));
    let cells: Vec<Vec<String>> = rows
        .iter()
        .map(|(name, s)| {
            let mut row = vec![name.clone()];
            row.extend(
                shown
                    .iter()
                    .map(|(_, n)| column_value(s, n).map_or("-".into(), |v| v.to_string())),
            );
            row
        })
        .collect();
    let align: Vec<char> = std::iter::once('l')
        .chain(std::iter::repeat('r'))
        .take(header.len())
        .collect();
    Ok(markdown(&header, &align, &cells))
}

/// The line under a view of raw results: the tool, commit, date, host and device; of several
/// invocations, how many, and only where they share host, device and settings (ratios from
/// different machines are not pooled). `ranges`: whether the table brackets each median's range.
fn measured_caption(jsons: &[Value], ranges: bool) -> Made<String> {
    let mut provenances = Vec::new();
    for json in jsons {
        if !json["host"].is_object() {
            return Err("raw results name their host (`host`)".to_string());
        }
        let p: Provenance = serde_json::from_value(json.clone())
            .map_err(|e| format!("its provenance (device, date, git, host): {e}"))?;
        provenances.push(p);
    }
    let first = &provenances[0];
    let settings = |j: &Value| [&j["width"], &j["height"], &j["runs"]].map(text);
    if provenances
        .iter()
        .any(|p| p.host != first.host || p.device != first.device || p.driver != first.driver)
        || jsons.iter().any(|j| settings(j) != settings(&jsons[0]))
    {
        return Err(
            "the files differ in host, device or settings: their ratios are not pooled".to_string(),
        );
    }
    let distinct = |values: Vec<String>| {
        let mut unique: Vec<String> = Vec::new();
        for v in values {
            if !unique.contains(&v) {
                unique.push(v);
            }
        }
        unique.join(", ")
    };
    let commits = distinct(provenances.iter().map(Provenance::commit_label).collect());
    let dates = distinct(
        provenances
            .iter()
            .map(|p| p.date.get(..10).unwrap_or(&p.date).to_string())
            .collect(),
    );
    let json = &jsons[0];
    let (tool, details) = if json.get("pipelines").is_some() {
        ("rbvh shaders", String::new())
    } else {
        (
            "rbvh bench",
            format!(
                ", {}×{} primary rays, median of {} runs",
                text(&json["width"]),
                text(&json["height"]),
                text(&json["runs"])
            ),
        )
    };
    let invocations = match (jsons.len(), ranges) {
        (1, _) => String::new(),
        (n, true) => format!(" (medians of {n} invocations, their range in brackets)"),
        (n, false) => format!(" (medians of {n} invocations)"),
    };
    Ok(format!(
        "Measured by `{tool}`{invocations} at {commits} on {dates}{details}; host: {}; device: {} ({}).",
        first.host.summary(),
        first.device,
        first.driver
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn relative_links_from_each_folder() {
        let f = Path::new("docs/results/x.json");
        assert_eq!(relative(Path::new(""), f), Path::new("docs/results/x.json"));
        assert_eq!(relative(Path::new("docs"), f), Path::new("results/x.json"));
        assert_eq!(
            relative(Path::new("scenes"), f),
            Path::new("../docs/results/x.json")
        );
    }

    /// A level is named by what its record says: `s` only where `exact_when_cheaper` is false, not
    /// where the field is missing (records from before it, their commit's presets).
    #[test]
    fn levels_are_named_by_their_records() {
        let record = |params: Value, method: &str| serde_json::json!({"quality": "Q2", "params": params, "method": method});
        let cases = [
            (serde_json::json!({"texels": "height_normal"}), "rbvh", "Q2"),
            (
                serde_json::json!({"exact_when_cheaper": true}),
                "rbvh",
                "Q2",
            ),
            (
                serde_json::json!({"exact_when_cheaper": false}),
                "rbvh",
                "Q2s",
            ),
            (
                serde_json::json!({"texels": "height", "exact_when_cheaper": false}),
                "rbvh-lod",
                "Q2hs LOD",
            ),
            (
                serde_json::json!({"texels": "height"}),
                "rbvh-instanced",
                "Q2h, two levels",
            ),
            (serde_json::json!({"view_rate": 384.0}), "rbvh", "Q2v"),
            (serde_json::json!({"view_rate": 0.0}), "rbvh", "Q2"),
            (
                serde_json::json!({"texels": "height", "view_rate": 384.0}),
                "rbvh-lod",
                "Q2hv LOD",
            ),
        ];
        for (params, method, name) in cases {
            assert_eq!(level(&record(params, method)), name);
        }
        assert_eq!(level(&serde_json::json!({"method": "exact"})), "exact");
        assert_eq!(
            level(&serde_json::json!({"method": "exact-instanced"})),
            "exact, two levels"
        );
    }

    #[test]
    fn tables_typed_by_hand_are_found() {
        let text = "intro\n| a | b |\n|---|--:|\n| 1 | 2 |\n\n<!-- not a measurement -->\n| x |\n|---|\n\n```\n| c |\n|---|\n```\n<!-- table f.json -->\n| d |\n|---|\n<!-- /table -->\n";
        assert_eq!(unmarked_tables(text), vec![2]);
    }

    #[test]
    fn a_block_without_its_close_is_refused_not_written_over() {
        let root = Path::new("/nonexistent");
        let doc = Path::new("x.md");
        let lost = "<!-- table a.json -->\nprose\n<!-- table b.json -->\n<!-- /table -->\n";
        let e = regenerate(root, doc, lost).unwrap_err().to_string();
        assert!(
            e.contains("x.md:1") && e.contains("no <!-- /table -->"),
            "{e}"
        );
        // Inside a fence a block is an example, not a block.
        let fenced = "```markdown\n<!-- table a.json -->\n```\n";
        assert_eq!(
            regenerate(root, doc, fenced).unwrap(),
            (fenced.to_string(), vec![])
        );
        let missing = "<!-- table a.json -->\n<!-- /table -->\n";
        let e = regenerate(root, doc, missing).unwrap_err().to_string();
        assert!(
            e.contains("x.md:1") && e.contains("results file a.json"),
            "{e}"
        );
    }

    #[test]
    fn several_invocations_give_medians_and_ranges_from_one_host() {
        let record = |quality: Option<&str>, mrays: f64, speedup: f64| {
            serde_json::json!({
                "scene": "s", "ray_type": "primary", "quality": quality, "method":
                if quality.is_some() { "rbvh" } else { "exact" }, "params": null,
                "mrays_per_s": {"median": mrays}, "speedup_vs_exact": speedup, "valid": true
            })
        };
        let runs: Vec<Vec<Value>> = [(2.0, 1.5), (3.0, 1.1), (4.0, 1.2)]
            .iter()
            .map(|&(m, x)| vec![record(None, m, 1.0), record(Some("Q2"), m * x, x)])
            .collect();
        let refs: Vec<Vec<&Value>> = runs.iter().map(|r| r.iter().collect()).collect();
        let table = ratios_table(&refs);
        assert!(
            table.contains("| s, primary | 3.00 (2.00–4.00) | 1.20 (1.10–1.50) |"),
            "{table}"
        );
        let file = |cpu: &str| {
            serde_json::json!({"device": "d", "driver": "v", "date": "2026-12-01T00:00:00Z",
                "git": "abc", "host": {"cpu": cpu}, "width": 8, "height": 8, "runs": 3,
                "results": []})
        };
        // In two levels alone, the two-level exact BVH is the referee whose speed is shown.
        let (mut exact, mut two) = (record(None, 2.5, 1.0), record(Some("Q2"), 2.0, 0.8));
        (exact["method"], two["method"]) = ("exact-instanced".into(), "rbvh-instanced".into());
        let table = ratios_table(&[vec![&exact, &two]]);
        assert!(
            table.contains("| s, primary | 2.50 | 1.00 | 0.80 |"),
            "{table}"
        );
        let caption = measured_caption(&[file("x"), file("x")], true).unwrap();
        assert!(caption.contains("medians of 2 invocations"), "{caption}");
        assert!(measured_caption(&[file("x"), file("y")], true).is_err());
    }

    /// A glance puts the exact BVH first in each scene, takes the median speed of the
    /// invocations that hold a record, and names every group of files it pools in its caption.
    #[test]
    fn a_glance_shows_each_scene_exact_first_and_names_every_host() {
        let record = |scene: &str, quality: Option<&str>, rays: &str, speedup: f64| {
            serde_json::json!({
                "scene": scene, "ray_type": rays, "quality": quality, "method":
                if quality.is_some() { "rbvh" } else { "exact" }, "params": null,
                "mrays_per_s": {"median": 2.0 * speedup}, "speedup_vs_exact": speedup,
                "memory_bytes": {"total": 4.0e6 / speedup}, "memory_ratio_vs_exact": speedup,
                "error": {"t_err_p99": 0.005, "flip_mean": 0.04}, "valid": rays == "primary"
            })
        };
        let small: Vec<Vec<Value>> = [1.5, 1.1, 1.2]
            .iter()
            .map(|&x| {
                vec![
                    record("small", Some("Q2"), "primary", x),
                    record("small", None, "primary", 1.0),
                    record("small", Some("Q2"), "shadow", 2.0 * x),
                    record("small", None, "shadow", 1.0),
                ]
            })
            .collect();
        let large = [record("large", None, "primary", 1.0)];
        let mut runs: Vec<Vec<&Value>> = small.iter().map(|r| r.iter().collect()).collect();
        runs.push(large.iter().collect());
        let table = glance_table(&runs);
        let lines: Vec<&str> = table.lines().collect();
        assert_eq!(
            lines[0],
            "| scene | level | MB | × smaller | primary × exact | shadow × exact | t p99 % | FLIP | valid |"
        );
        assert!(
            lines[2].starts_with("| small | exact BVH | 4.00 | 1 | 2.00 MRays/s |"),
            "{table}"
        );
        assert_eq!(
            lines[3], "| small | Q2 | 2.67 | 1.5 | 1.20× | 2.40× | 0.500 | 0.040 | **no** |",
            "{table}"
        );
        assert!(lines[4].starts_with("| large | exact BVH |"), "{table}");
        let file = |cpu: &str, scene: &str| {
            serde_json::json!({"device": "d", "driver": "v", "date": "2026-12-01T00:00:00Z",
                "git": "abc", "host": {"cpu": cpu}, "width": 8, "height": 8, "runs": 3,
                "results": [{"scene": scene}]})
        };
        let caption = glance_caption(
            &[file("x", "small"), file("x", "small"), file("y", "large")],
            |_| true,
        )
        .unwrap();
        assert!(
            caption.starts_with("small: Measured by `rbvh bench` (medians of 2 invocations) at"),
            "{caption}"
        );
        assert!(
            caption.contains(" large: Measured by `rbvh bench` at abc"),
            "{caption}"
        );
    }

    #[test]
    fn block_options_are_checked() {
        let b = Block::parse("docs/results/a.json,b.json view=ratios rays=primary,shadow").unwrap();
        assert_eq!(
            b.files,
            [Path::new("docs/results/a.json"), Path::new("b.json")]
        );
        assert_eq!(b.view.as_deref(), Some("ratios"));
        assert_eq!(b.filter("rays").unwrap(), ["primary", "shadow"]);
        assert!(Block::parse("a.json colour=red").is_err());
        assert!(Block::parse("").is_err());
    }
}
