//! The trade at a glance: per scene, charts of speed and memory against accuracy, a line per
//! method (RBVH, RBVH with level of detail, the RBVH in two levels) through its levels, named in
//! a legend, with the exact BVH (and the two-level one, where a scene has instances) marked at
//! zero error — the curves the paper's evaluation draws (Novák & Dachsbacher
//! 2012, §6).
//!
//! * `speed_vs_error`: primary-ray MRays/s (median) against the hit-distance error p99;
//! * `memory_vs_error`: total bytes of the structure against the same error;
//! * with `--traffic`, `traffic_<rays>` per ray type: the DRAM bytes per ray that the cache
//!   model (`bench::traffic`) predicts against the cache's capacity, one line per method and
//!   level, with each structure's working set in its label.
//!
//! Accuracy is measured on primary rays (closest hits), since the distance error of occlusion
//! rays is not defined (see `bench::metrics`). Levels that failed validation are labelled
//! "(invalid)".
//!
//! Each chart is written twice, drawn by the same code: `.svg` for pages and zooming, `.png` for
//! whatever shows no SVG (terminals, issue trackers, slides). The PNG's text is drawn with a font
//! compiled in (Ubuntu Light from `epaint_default_fonts`), not looked up on the system, so a
//! machine without fonts draws the same picture.

use std::collections::HashSet;
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use ::image::codecs::png::PngEncoder;
use ::image::{ExtendedColorType, ImageEncoder};
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::FontStyle;

use super::record::Record;
use crate::io::write_atomically;
use crate::rays::RayType;
use crate::structure::Kind;
use crate::{Error, Result};

/// One marker of a chart.
struct Point {
    label: String,
    /// Hit-distance error p99, in percent of the scene diagonal.
    x: f64,
    y: f64,
    method: Kind,
}

/// Chart size: pixels of the PNG, user units of the SVG.
const SIZE: (u32, u32) = (720, 480);

/// The font family every chart's text names; [`register_font`] backs it for drawing.
const FAMILY: &str = "sans-serif";

/// Gives plotters the compiled-in font for [`FAMILY`] (it measures text with it for both formats
/// and rasterizes the PNG's with it), once per process; the outcome is kept for later charts.
fn register_font() -> std::result::Result<(), String> {
    static REGISTERED: OnceLock<std::result::Result<(), String>> = OnceLock::new();
    REGISTERED
        .get_or_init(|| {
            plotters::style::register_font(
                FAMILY,
                FontStyle::Normal,
                epaint_default_fonts::UBUNTU_LIGHT,
            )
            .map_err(|_| "the compiled-in chart font (Ubuntu Light) is not a valid font".into())
        })
        .clone()
}

/// What one chart shows.
enum Chart<'a> {
    /// Speed or memory (`y_desc`) against the error, per method and level.
    Accuracy {
        title: String,
        y_desc: &'a str,
        points: Vec<Point>,
    },
    /// Modelled DRAM traffic against cache capacity, a line per structure.
    Traffic { title: String, lines: Vec<Line> },
}

type DrawResult = std::result::Result<(), Box<dyn std::error::Error>>;

impl Chart<'_> {
    fn draw<DB: DrawingBackend>(&self, root: DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        match self {
            Chart::Accuracy {
                title,
                y_desc,
                points,
            } => draw(root, title, y_desc, points),
            Chart::Traffic { title, lines } => draw_traffic(root, title, lines),
        }
    }

    /// Writes `<stem>.svg` and `<stem>.png` into `dir`, atomically, returning both paths.
    fn write(&self, dir: &Path, stem: &str) -> Result<[PathBuf; 2]> {
        let svg_path = dir.join(format!("{stem}.svg"));
        register_font().map_err(|e| Error::io(&svg_path, io::Error::other(e)))?;
        let mut svg = String::new();
        self.draw(SVGBackend::with_string(&mut svg, SIZE).into_drawing_area())
            .map_err(|e| Error::io(&svg_path, io::Error::other(e.to_string())))?;
        write_atomically(&svg_path, |w| w.write_all(svg.as_bytes()))?;

        let png_path = dir.join(format!("{stem}.png"));
        let mut rgb = vec![0u8; 3 * SIZE.0 as usize * SIZE.1 as usize];
        self.draw(BitMapBackend::with_buffer(&mut rgb, SIZE).into_drawing_area())
            .map_err(|e| Error::io(&png_path, io::Error::other(e.to_string())))?;
        write_atomically(&png_path, |w| {
            PngEncoder::new(w)
                .write_image(&rgb, SIZE.0, SIZE.1, ExtendedColorType::Rgb8)
                .map_err(io::Error::other)
        })?;
        Ok([svg_path, png_path])
    }
}

/// Writes the charts for one scene's `records` into `dir`, returning the files written: the two
/// against accuracy from its primary-ray records (a level without a defined error, no ray hit by
/// both, is left out), and a traffic chart per ray type whose records carry traffic.
pub fn write_charts(dir: &Path, records: &[Record]) -> Result<Vec<PathBuf>> {
    let primary: Vec<&Record> = records
        .iter()
        .filter(|r| r.ray_type == RayType::Primary)
        .collect();
    let scene = records.first().map_or("", |r| r.scene.as_str());
    let points = |y: &dyn Fn(&Record) -> f64| -> Vec<Point> {
        primary
            .iter()
            .filter_map(|r| {
                // The two-level exact BVH is held to rounding against the flat one
                // (`validate::invalid_reason_exact`): drawn at zero error beside it.
                let exact = r.method.is_exact();
                let x = if exact {
                    0.0
                } else {
                    100.0 * r.error.as_ref()?.t_err_p99?
                };
                let level = match r.method {
                    Kind::Exact => "exact".to_string(),
                    Kind::ExactInstanced => "exact, two levels".to_string(),
                    _ => r.level_label(),
                };
                Some(Point {
                    label: if r.valid {
                        level
                    } else {
                        format!("{level} (invalid)")
                    },
                    x,
                    y: y(r),
                    method: r.method,
                })
            })
            .collect()
    };
    let charts = [
        (
            "speed_vs_error",
            Chart::Accuracy {
                title: format!("{scene}: primary-ray speed vs accuracy"),
                y_desc: "MRays/s (median)",
                points: points(&|r| r.mrays_per_s.median),
            },
        ),
        (
            "memory_vs_error",
            Chart::Accuracy {
                title: format!("{scene}: memory vs accuracy"),
                y_desc: "memory (MB)",
                points: points(&|r| r.memory_bytes.total as f64 / 1e6),
            },
        ),
    ];
    let mut written = Vec::new();
    for (stem, chart) in charts {
        written.extend(chart.write(dir, stem)?);
    }
    for ray_type in RayType::ALL {
        let lines: Vec<Line> = records
            .iter()
            .filter(|r| r.ray_type == ray_type)
            .filter_map(|r| {
                let traffic = &r.traffic.as_ref()?.traffic;
                let level = r.level_label();
                let name = match r.method {
                    Kind::Exact => "exact".to_string(),
                    Kind::ExactInstanced => "exact, two levels".to_string(),
                    Kind::Rbvh => level,
                    Kind::RbvhLod => format!("{level} LOD"),
                    Kind::RbvhInstanced => format!("{level}, two levels"),
                };
                Some(Line {
                    label: format!(
                        "{name}, set {:.2} MB",
                        traffic.working_set_bytes as f64 / 1e6
                    ),
                    points: traffic
                        .caches
                        .iter()
                        .map(|c| (c.capacity_bytes as f64 / MIB, c.dram_bytes_per_ray))
                        .collect(),
                    exact: r.method == Kind::Exact,
                })
            })
            .collect();
        if lines.iter().all(|l| l.points.is_empty()) {
            continue;
        }
        let chart = Chart::Traffic {
            title: format!("{scene}: modelled DRAM traffic, {} rays", ray_type.name()),
            lines,
        };
        written.extend(chart.write(dir, &format!("traffic_{}", ray_type.name()))?);
    }
    Ok(written)
}

const MIB: f64 = 1024.0 * 1024.0;

/// One structure's line of a traffic chart: (cache MiB, DRAM bytes per ray) per modelled cache.
struct Line {
    label: String,
    points: Vec<(f64, f64)>,
    exact: bool,
}

/// Draws a traffic chart onto `root`: capacity on a log axis, since the modelled caches span an
/// order of magnitude (4 to 72 MiB).
fn draw_traffic<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    title: &str,
    lines: &[Line],
) -> DrawResult
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    let all = || lines.iter().flat_map(|l| l.points.iter().copied());
    let x_min = all().map(|p| p.0).fold(f64::INFINITY, f64::min);
    let x_max = all().map(|p| p.0).fold(0.0, f64::max);
    let y_max = (1.15 * all().map(|p| p.1).fold(0.0, f64::max)).max(1e-3);
    let mut chart = ChartBuilder::on(&root)
        .caption(title, (FAMILY, 20))
        .margin(16)
        .x_label_area_size(48)
        .y_label_area_size(72)
        .build_cartesian_2d((0.8 * x_min..1.6 * x_max).log_scale(), 0.0..y_max)?;
    chart
        .configure_mesh()
        .x_desc("cache capacity (MiB, LRU, 128-byte lines)")
        .y_desc("DRAM bytes per ray (model)")
        .draw()?;
    let font = (FAMILY, 13).into_font();
    for (k, line) in lines.iter().enumerate() {
        let colour = if line.exact {
            RED.to_rgba()
        } else {
            Palette99::pick(k).to_rgba()
        };
        chart.draw_series(LineSeries::new(line.points.iter().copied(), colour))?;
        chart.draw_series(
            line.points
                .iter()
                .map(|&p| Circle::new(p, 4, colour.filled())),
        )?;
        // Labelled at the smallest cache, on the left, where the label has the chart's width.
        if let Some(&first) = line.points.first() {
            chart.draw_series(std::iter::once(
                EmptyElement::at(first) + Text::new(line.label.clone(), (8, -16), font.clone()),
            ))?;
        }
    }
    root.present()?;
    Ok(())
}

/// Draws a speed or memory chart against the error onto `root`.
fn draw<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    title: &str,
    y_desc: &str,
    points: &[Point],
) -> DrawResult
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    // Room above the largest values for their labels, and on the right for the legend (upper
    // right), which would otherwise cover the coarsest level; a floor keeps an all-zero axis
    // drawable.
    let top = |v: f64, room: f64| (room * v).max(1e-3);
    let x_max = top(points.iter().map(|p| p.x).fold(0.0, f64::max), 1.4);
    let y_max = top(points.iter().map(|p| p.y).fold(0.0, f64::max), 1.15);
    let mut chart = ChartBuilder::on(&root)
        .caption(title, (FAMILY, 20))
        .margin(16)
        .x_label_area_size(48)
        .y_label_area_size(72)
        .build_cartesian_2d(0.0..x_max, 0.0..y_max)?;
    chart
        .configure_mesh()
        .x_desc("hit distance error, p99 (% of scene diagonal)")
        .y_desc(y_desc)
        .draw()?;
    // One line per method through its levels, in order of error, each in the legend; the exact
    // BVHs a marker at zero error.
    let font = (FAMILY, 13).into_font();
    for (method, colour) in [
        (Kind::Rbvh, BLUE.to_rgba()),
        (Kind::RbvhLod, GREEN.to_rgba()),
        (Kind::RbvhInstanced, MAGENTA.to_rgba()),
        (Kind::Exact, RED.to_rgba()),
        (Kind::ExactInstanced, RGBColor(128, 0, 0).to_rgba()),
    ] {
        let mut mine: Vec<&Point> = points.iter().filter(|p| p.method == method).collect();
        if mine.is_empty() {
            continue;
        }
        mine.sort_by(|a, b| a.x.total_cmp(&b.x));
        let series = if method.is_exact() {
            chart.draw_series(
                mine.iter()
                    .map(|p| TriangleMarker::new((p.x, p.y), 7, colour.filled())),
            )?
        } else {
            chart.draw_series(LineSeries::new(mine.iter().map(|p| (p.x, p.y)), colour))?
        };
        series
            .label(method.name())
            .legend(move |(x, y)| Rectangle::new([(x, y - 4), (x + 16, y + 4)], colour.filled()));
        chart.draw_series(mine.iter().map(|p| {
            let marker = if method.is_exact() {
                TriangleMarker::new((0, 0), 7, colour.filled()).into_dyn()
            } else {
                Circle::new((0, 0), 4, colour.filled()).into_dyn()
            };
            EmptyElement::at((p.x, p.y))
                + marker
                + Text::new(p.label.clone(), (8, -16), font.clone())
        }))?;
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .label_font((FAMILY, 13))
        .draw()?;
    root.present()?;
    Ok(())
}

/// A directory name for scene `name` that is not in `used` (which it joins): letters, digits,
/// `-`, `_` and `.` kept, anything else (path separators included) as `_`, and `-2`, `-3`, …
/// appended when two scenes share a name.
pub fn scene_dir_name(name: &str, used: &mut HashSet<String>) -> String {
    let base: String = name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.') {
                c
            } else {
                '_'
            }
        })
        .collect();
    let base = if base.trim_matches('.').is_empty() {
        "scene".to_string()
    } else {
        base
    };
    let mut candidate = base.clone();
    let mut n = 2;
    while !used.insert(candidate.clone()) {
        candidate = format!("{base}-{n}");
        n += 1;
    }
    candidate
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scene_directories_are_safe_and_distinct() {
        let mut used = HashSet::new();
        assert_eq!(scene_dir_name("sphere", &mut used), "sphere");
        assert_eq!(scene_dir_name("sphere", &mut used), "sphere-2");
        assert_eq!(scene_dir_name("../a b.obj", &mut used), ".._a_b.obj");
        assert_eq!(scene_dir_name("..", &mut used), "scene");
    }
}
