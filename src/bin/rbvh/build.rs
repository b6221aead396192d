//! `rbvh build`: builds an RBVH and reports what it costs — nodes, leaves, texels, atlas fill,
//! bytes of tree, atlas and triangles, and the ratio to the exact BVH — optionally saving it.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{Context as _, Result};
use rayon::prelude::*;
use rbvh::bvh::{BuildParams, Bvh, InstancedBvh};
use rbvh::probe::TraceStats;
use rbvh::rbvh::{InstancedRbvh, Rbvh, RbvhParams, RbvhSource, Subdivision};
use rbvh::scene::{InstancedScene, Instances, Scene};

use crate::flags::flag_error;
use crate::outputs::{self, output};
use crate::prepare::{check_view, InstancesArg, PointsArg};
use crate::progress::step;
use crate::quality::Quality;

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Built-in scene name, OBJ/glTF/GLB file, point cloud (.ply, .xyz), or scene file (.toml).
    #[arg(long, default_value = "default")]
    scene: String,
    #[command(flatten)]
    points: PointsArg,
    #[command(flatten)]
    quality: Quality,
    /// Save the built RBVH to this file (load it with --rbvh on render, trace, compare, and paint
    /// for a flat one);
    /// one level in one texel format. Prints no table unless --stats. A scene of instances is
    /// saved as --instances says: its two-level RBVH (every mesh once, and its placements), or
    /// flattened.
    #[arg(long, short)]
    out: Option<PathBuf>,
    /// With --out: which RBVH of a scene of instances is saved: `two-level`, `flat`, or `auto`
    /// (two levels where the scene places a mesh more than once or is too large to flatten, as
    /// render traces it; flat with --view).
    #[arg(long, value_enum, default_value_t = InstancesArg::Auto, requires = "out")]
    instances: InstancesArg,
    /// With --out: print the accounting table too (without --out it is what the command prints).
    #[arg(long, requires = "out")]
    stats: bool,
    /// Also build every level with each subdivision strategy (spatial median, modified SAH, and
    /// median without object split) and report build time and tracing cost: nodes, triangles and
    /// height-field cells per ray, and CPU-reference MRays/s on the scene camera's primary rays.
    #[arg(long)]
    compare_splits: bool,
    /// Also print, after the exact BVH's line and after each level's row (or alone, with --out
    /// and no --stats), how long each of its build's steps took and the time between them: for
    /// an RBVH of triangles the scene's connected parts, the BVH its rings are sampled by and its
    /// open edges and creases (these three once, at the first level, which the later ones share),
    /// then the leaves, the tree over them, the atlas and, for a scene with materials, the colour
    /// channel. Wall times of this command's builds, where a level's `build ms` counts the shared
    /// steps, and the scene's gathering before the first level, into every level as if it were
    /// built alone. Flat builds only (not the two-level lines, nor --compare-splits' rebuilds).
    #[arg(long)]
    timings: bool,
}

pub fn run(a: Args) -> Result<()> {
    outputs::check(
        &[output("--out", a.out.as_deref(), "rbvh")],
        &outputs::scene_inputs(&a.scene, a.points.points.as_ref()),
    )?;
    let placed = step("loading scene", |bar| {
        InstancedScene::load_observed(&a.scene, bar)
    })
    .with_context(|| format!("loading scene {:?}", a.scene))?;
    let table = a.stats || a.out.is_none();
    let levels = a.quality.levels()?;
    let viewed = a.quality.view.is_some();
    if viewed {
        check_view(&a.scene, placed.camera.is_some(), a.points.points.is_some())?;
        anyhow::ensure!(
            Instances::from(a.instances) != Instances::TwoLevel,
            "--instances two-level: --view refines a flat RBVH for one view, and a two-level \
             one builds each mesh once for every place it stands"
        );
    }
    let fits = placed.check_flat_fits(rbvh::bench::provenance::available_memory());
    let two_level_out = a.out.is_some()
        && match Instances::from(a.instances) {
            Instances::TwoLevel => true,
            Instances::Flat => false,
            Instances::Auto => !viewed && (placed.repeats_a_mesh() || fits.is_err()),
        };
    if two_level_out {
        anyhow::ensure!(
            a.points.points.is_none(),
            "--points builds a flat RBVH of points: give --instances flat"
        );
        anyhow::ensure!(
            !a.compare_splits,
            "--compare-splits compares flat RBVHs' subdivisions, and --out saves this scene in two \
             levels: give --instances flat"
        );
        anyhow::ensure!(
            levels.len() == 1,
            "--out saves one level: give a single --quality and a single --texels"
        );
        anyhow::ensure!(
            !a.timings,
            "--timings times flat builds, and --out saves this scene in two levels: give \
             --instances flat"
        );
        return two_levels(&placed, &levels, table, a.out.as_deref());
    }
    // A scene held only in two levels: what only a flat one can give is refused before the
    // two-level lines are built.
    if let Err(e) = &fits {
        anyhow::ensure!(
            !viewed,
            "{e}: --view refines a flat RBVH, and this scene is held in two levels alone"
        );
        anyhow::ensure!(
            a.out.is_none(),
            "{e}; --out with --instances flat saves a flat RBVH"
        );
        anyhow::ensure!(
            a.points.points.is_none() && !a.compare_splits && !a.timings,
            "{e}: --points and --compare-splits build flat RBVHs and --timings times flat builds, \
             and this scene is held in two levels alone"
        );
    }
    // An RBVH of points is built over the flat scene: the two-level lines, of the meshes'
    // triangles, would not be what --points asked for.
    if table && placed.instances.len() > 1 && a.points.points.is_none() && !viewed {
        two_levels(&placed, &levels, true, None)?;
    }
    if let Err(e) = fits {
        // A scene held only in two levels: its lines above are the table.
        eprintln!("no flat structures: {e}");
        return Ok(());
    }
    let mut scene = placed.into_flat();
    scene
        .validate()
        .with_context(|| format!("loading scene {:?}", a.scene))?;
    if viewed {
        // A point cloud's file (.ply, .xyz) is points without --points.
        check_view(&a.scene, true, scene.points.is_some())?;
    }
    a.points.apply(&mut scene)?;
    if let Some(warning) = scene.precision_warning() {
        eprintln!("warning: {warning}");
    }
    anyhow::ensure!(
        a.out.is_none() || levels.len() == 1,
        "--out saves one level: give a single --quality and a single --texels"
    );
    // The exact BVH is built for the table's ratios alone: `--out` without `--stats` saves the
    // RBVH without it (at the paper's scale that was half the command's time). A point cloud has
    // no triangles: nothing for the exact BVH, and no ratio to it.
    let exact_bytes = if !table {
        None
    } else if scene.triangle_count() == 0 {
        println!(
            "{}: {} points, no triangles: no exact BVH to compare with; peak host memory so far {} MB",
            scene.name,
            scene.point_count(),
            peak_host_mb()
        );
        None
    } else {
        let (exact, steps) = timed("building exact BVH", |bar| {
            Bvh::build_observed(&scene, &BuildParams::DEFAULT, bar)
        });
        let exact = exact?;
        let bytes = exact.tree_bytes() + exact.triangle_bytes();
        let points = match scene.point_count() {
            0 => String::new(),
            n => format!(" (RBVHs built from {n} points instead)"),
        };
        println!(
            "{}: {} triangles{points}; exact BVH {} nodes, {:.2} MB (tree + triangles), built in {:.0} ms; peak host memory so far {} MB",
            scene.name,
            scene.triangle_count(),
            exact.nodes.len(),
            mb(bytes),
            exact.build_ms,
            peak_host_mb()
        );
        if a.timings {
            println!("{}", steps.line("exact BVH"));
        }
        Some(bytes)
    };
    if table {
        println!(
            "{:>7} {:>9} {:>9} {:>9} {:>8} {:>9} {:>11} {:>10} {:>7} {:>7} {:>8} {:>9} {:>9} {:>9} {:>9} {:>9} {:>10} {:>9}",
            "level",
            "texel",
            "build ms",
            "nodes",
            "hf",
            "tri leaf",
            "tile texels",
            "atlas",
            "fill",
            "8-bit",
            "B/texel",
            "tree MB",
            "atlas MB",
            "tris MB",
            "parts MB",
            "total MB",
            "vs exact",
            "peak MB"
        );
    }
    // What every level shares (the scene's parts, the BVH its rings are sampled by) is made once.
    let source = RbvhSource::new(&scene).map_err(flag_error)?;
    for params in levels {
        let name = params.level_label();
        let (r, steps) = timed(&format!("building RBVH {name}"), |bar| {
            params.validate().map_err(flag_error)?;
            Rbvh::build_from(&source, &params, bar).map_err(flag_error)
        });
        let r = r?;
        if table {
            println!(
            "{:>7} {:>9.3e} {:>9.0} {:>9} {:>8} {:>9} {:>11} {:>10} {:>6.1}% {:>6.1}% {:>8.2} {:>9.3} {:>9.3} {:>9.3} {:>9.3} {:>9.3} {:>10} {:>9}",
            name,
            r.texel_size,
            r.stats.build_ms,
            r.nodes.len(),
            r.stats.heightfield_leaves,
            r.stats.triangle_leaves,
            r.stats.tile_texels,
            format!("{}x{}", r.atlas.pitch, r.atlas.rows),
            100.0 * r.fill_ratio(),
            100.0 * r.narrow_texels() as f64 / r.stats.tile_texels.max(1) as f64,
            r.bytes_per_texel(),
            mb(r.tree_bytes()),
            mb(r.atlas_bytes()),
            mb(r.triangle_bytes()),
            mb(r.part_bytes()),
            mb(r.total_bytes()),
            exact_bytes.map_or("-".into(), |e| format!(
                "{:.1}x",
                e as f64 / r.total_bytes().max(1) as f64
            )),
            peak_host_mb()
        );
            if r.colours.is_some() {
                println!(
                    "{:>7} colour channel (baked from the scene's materials or its points' colours): {:.3} MB, not in total",
                    name,
                    mb(r.colour_bytes())
                );
            }
        }
        if a.timings {
            println!("{}", steps.line(&name));
        }
        if a.compare_splits {
            compare_splits(&source, &scene, &name, &params)?;
        }
        if let Some(path) = &a.out {
            r.save(path)?;
            eprintln!("wrote {}", path.display());
        }
    }
    Ok(())
}

/// The library's steps of one build as `--timings` prints them: each with its wall time, and
/// the build's whole wall time.
struct Steps {
    steps: Vec<(String, Duration)>,
    total: Duration,
}

impl Steps {
    /// `label took T ms: t1 ms <step 1>; …; r ms between them`.
    fn line(&self, label: &str) -> String {
        let ms = |d: Duration| d.as_secs_f64() * 1e3;
        let listed: Duration = self.steps.iter().map(|s| s.1).sum();
        let mut parts: Vec<String> = self
            .steps
            .iter()
            .map(|(what, d)| format!("{:.0} ms {what}", ms(*d)))
            .collect();
        parts.push(format!(
            "{:.0} ms between them",
            ms(self.total.saturating_sub(listed))
        ));
        format!(
            "{label:>7} took {:.0} ms: {}",
            ms(self.total),
            parts.join("; ")
        )
    }
}

/// Runs `f` under a spinner labelled `what` ([`step`]), timing it and the library's steps in it.
fn timed<T>(what: &str, f: impl FnOnce(&crate::progress::Bar) -> T) -> (T, Steps) {
    let start = Instant::now();
    step(what, |bar| {
        let out = f(bar);
        let steps = bar.timings();
        (
            out,
            Steps {
                steps,
                total: start.elapsed(),
            },
        )
    })
}

/// The two-level structures of a scene with instances (a tree per mesh, a top level over the
/// instances): the exact BVH's, and the RBVH's at each of `levels`: with `print`, what they
/// store and cost beside the flat structures the table goes on to build from the scene
/// flattened (issue "Instances"); with `out`, the (one) two-level RBVH saved there.
fn two_levels(
    placed: &InstancedScene,
    levels: &[RbvhParams],
    print: bool,
    out: Option<&std::path::Path>,
) -> Result<()> {
    let mut exact_bytes = 0;
    if print {
        exact_bytes = two_level_exact(placed)?;
    }
    for params in levels {
        let name = params.level_label();
        let r = step(&format!("building the two-level RBVH {name}"), |bar| {
            params.validate().map_err(flag_error)?;
            InstancedRbvh::build_observed(placed, params, bar).map_err(flag_error)
        })?;
        if print {
            let texels: Vec<String> = r.mesh_texels.iter().map(|t| format!("{t:.3e}")).collect();
            println!(
                "{name:>7} two-level RBVH: mesh texels [{}] (before objects' own rates; world {:.3e}), {} height-field + {} \
                 triangle leaves, {:.2} MB (tree {:.2} + atlas {:.2} + triangles {:.2} + instances \
                 {:.3}), {:.1}x smaller than the two-level exact BVH, built in {:.0} ms; peak host \
                 memory so far {}",
                texels.join(", "),
                r.texel_size(),
                r.stats().heightfield_leaves,
                r.stats().triangle_leaves,
                mb(r.total_bytes()),
                mb(r.tree_bytes()),
                mb(r.atlas_bytes()),
                mb(r.triangle_bytes()),
                mb(r.instance_bytes()),
                exact_bytes as f64 / r.total_bytes().max(1) as f64,
                r.stats().build_ms,
                peak_host_mb()
            );
        }
        if let Some(path) = out {
            r.save(path)?;
            eprintln!(
                "wrote {} (a two-level RBVH: {} meshes, {} instances)",
                path.display(),
                r.meshes.len(),
                r.instances.len()
            );
        }
    }
    Ok(())
}

/// Builds the two-level exact BVH of `placed` and prints its line; its device bytes.
fn two_level_exact(placed: &InstancedScene) -> Result<u64> {
    let two = step("building the two-level exact BVH", |_| {
        InstancedBvh::build(placed).map_err(flag_error)
    })?;
    println!(
        "{}: {} instances of {} meshes, {} triangles as placed, {} stored; two-level exact BVH {} \
         nodes (top level {}, depth {}), {:.2} MB (tree {:.2} + triangles {:.2} + instances {:.3}), \
         built in {:.0} ms; peak host memory so far {} MB",
        placed.name,
        placed.instances.len(),
        placed.meshes.len(),
        placed.placed_triangle_count(),
        placed.stored_triangle_count(),
        two.nodes.len(),
        two.top_nodes,
        two.top_depth,
        mb(two.tree_bytes() + two.triangle_bytes() + two.instance_bytes()),
        mb(two.tree_bytes()),
        mb(two.triangle_bytes()),
        mb(two.instance_bytes()),
        two.build_ms,
        peak_host_mb()
    );
    Ok(two.tree_bytes() + two.triangle_bytes() + two.instance_bytes())
}

/// Build time and tracing cost of each subdivision strategy at `params`' level, on primary rays
/// (the paper measured construction seconds and MRays/s of spatial median against its SAH): the
/// strategies make different leaves, over which each build keeps the cheaper tree.
fn compare_splits(
    source: &RbvhSource,
    scene: &Scene,
    level: &str,
    params: &RbvhParams,
) -> Result<()> {
    let rays = scene.camera_or_framed(4.0 / 3.0).primary_rays(320, 240);
    for (name, subdivision, object_split) in [
        ("median", Subdivision::SpatialMedian, true),
        ("sah", Subdivision::AreaSah, true),
        ("median, no object split", Subdivision::SpatialMedian, false),
    ] {
        let p = RbvhParams {
            subdivision,
            object_split,
            ..*params
        };
        let r = step(&format!("building {level} ({name})"), |_| {
            Rbvh::build_from(source, &p, &rbvh::progress::Quiet).map_err(flag_error)
        })?;
        let start = Instant::now();
        let stats: Vec<TraceStats> = rays.par_iter().map(|ray| r.closest_hit(ray).1).collect();
        let ms = start.elapsed().as_secs_f64() * 1e3;
        let per_ray = |f: fn(&TraceStats) -> u32| {
            stats.iter().map(|s| f(s) as f64).sum::<f64>() / rays.len() as f64
        };
        println!(
            "{level:>7} {name:<24} build {:>6.0} ms, {:>6} nodes, {:>6} leaves; per ray {:>5.2} nodes + {:>5.2} triangles + {:>5.2} cells; CPU {:>6.2} MRays/s",
            r.stats.build_ms,
            r.nodes.len(),
            r.stats.heightfield_leaves + r.stats.triangle_leaves,
            per_ray(|s| s.counters.nodes),
            per_ray(|s| s.counters.triangles),
            per_ray(|s| s.counters.cells),
            rays.len() as f64 / (ms * 1e3)
        );
    }
    Ok(())
}

fn mb(bytes: u64) -> f64 {
    bytes as f64 / 1e6
}

/// The process's peak resident memory so far (Linux's `VmHWM`), in MB, or `-` where the
/// system does not say: the figure a user sizing a machine for a large scene needs.
fn peak_host_mb() -> String {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|status| {
            let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
            let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
            Some(format!("{:.0}", kb as f64 / 1024.0))
        })
        .unwrap_or_else(|| "-".into())
}
