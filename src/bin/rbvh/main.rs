//! `rbvh`: render scenes, answer ray files, and (later) build and benchmark RBVHs.

mod bench;
mod build;
mod paint;
mod prepare;
mod regress;
mod render;
mod trace;

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "rbvh",
    version,
    about = "Rasterized BVH ray casting on Vulkan compute (Novák & Dachsbacher 2012)"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Render a scene to PNG (and optionally EXR with depth and normals).
    Render(render::Args),
    /// Build an RBVH and report its nodes, leaves, texels and memory against the exact BVH.
    Build(build::Args),
    /// Trace a ray file and write a hit file (formats in README.md).
    Trace(trace::Args),
    /// Benchmark the exact BVH and RBVH levels: speed, memory and error on the same rays.
    Bench(bench::Args),
    /// Paint brush strokes onto an RBVH's surface on the device, and save it (with its colours).
    Paint(paint::Args),
    /// Render the regression cases and compare them with golden images (FLIP and depth).
    Regress(regress::Args),
}

fn main() {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Render(a) => render::run(a),
        Command::Trace(a) => trace::run(a),
        Command::Build(a) => build::run(a),
        Command::Bench(a) => bench::run(a),
        Command::Regress(a) => regress::run(a),
        Command::Paint(a) => paint::run(a),
    };
    if let Err(e) = result {
        eprintln!("error: {e}");
        for cause in e.chain().skip(1) {
            eprintln!("  caused by: {cause}");
        }
        std::process::exit(1);
    }
}
