//! `rbvh build`: builds an RBVH and reports what it costs — nodes, leaves, texels, atlas fill,
//! bytes of tree, atlas and triangles, and the ratio to the exact BVH — optionally saving it.

use std::path::PathBuf;

use anyhow::{Context as _, Result};
use rbvh::bvh::Bvh;
use rbvh::rbvh::Rbvh;
use rbvh::scene::Scene;

use crate::prepare::{step, Quality};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Built-in scene name, OBJ/glTF/GLB file, or scene file (.toml).
    #[arg(long, default_value = "default")]
    scene: String,
    #[command(flatten)]
    quality: Quality,
    /// Save the built RBVH to this file (load it with --rbvh on render/trace).
    #[arg(long, short)]
    out: Option<PathBuf>,
    /// Print the accounting table (printed anyway when there is no --out).
    #[arg(long)]
    stats: bool,
}

pub fn run(a: Args) -> Result<()> {
    let scene = step("loading scene", || Scene::load(&a.scene))
        .with_context(|| format!("loading scene {:?}", a.scene))?;
    let levels = a.quality.levels()?;
    anyhow::ensure!(
        a.out.is_none() || levels.len() == 1,
        "--out saves one level: give a single --quality"
    );
    let table = a.stats || a.out.is_none();
    let exact = step("building exact BVH", || Bvh::build(&scene))?;
    let exact_bytes = exact.tree_bytes() + exact.triangle_bytes();
    if table {
        println!(
            "{}: {} triangles; exact BVH {} nodes, {:.2} MB (tree + triangles), built in {:.0} ms",
            scene.name,
            scene.triangle_count(),
            exact.nodes.len(),
            mb(exact_bytes),
            exact.build_ms
        );
        println!(
            "{:>6} {:>9} {:>9} {:>8} {:>9} {:>11} {:>10} {:>7} {:>9} {:>9} {:>9} {:>9} {:>10}",
            "level",
            "build ms",
            "nodes",
            "hf",
            "tri leaf",
            "tile texels",
            "atlas",
            "fill",
            "tree MB",
            "atlas MB",
            "tris MB",
            "total MB",
            "vs exact"
        );
    }
    for (name, params) in levels {
        let r = step(&format!("building RBVH {name}"), || {
            Rbvh::build(&scene, &params)
        })?;
        if table {
            println!(
            "{:>6} {:>9.0} {:>9} {:>8} {:>9} {:>11} {:>10} {:>6.1}% {:>9.3} {:>9.3} {:>9.3} {:>9.3} {:>9.1}x",
            name,
            r.stats.build_ms,
            r.nodes.len(),
            r.stats.heightfield_leaves,
            r.stats.triangle_leaves,
            r.stats.tile_texels,
            format!("{}x{}", r.atlas.pitch, r.atlas.rows),
            100.0 * r.fill_ratio(),
            mb(r.tree_bytes()),
            mb(r.atlas_bytes()),
            mb(r.triangle_bytes()),
            mb(r.total_bytes()),
            exact_bytes as f64 / r.total_bytes().max(1) as f64
        );
        }
        if let Some(path) = &a.out {
            r.save(path)?;
            eprintln!("wrote {}", path.display());
        }
    }
    Ok(())
}

fn mb(bytes: u64) -> f64 {
    bytes as f64 / 1e6
}
