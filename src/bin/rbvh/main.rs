//! `rbvh`: render scenes, compare the exact BVH with an RBVH, answer ray files, build, paint,
//! upgrade and benchmark RBVHs.

mod bench;
mod build;
mod compare;
mod flags;
mod outputs;
mod paint;
mod prepare;
mod progress;
mod quality;
mod regress;
mod render;
mod report;
mod shaders;
mod tables;
mod trace;
mod upgrade;

use clap::{CommandFactory, FromArgMatches, Parser, Subcommand};

use crate::flags::Given;

#[derive(Parser)]
#[command(
    name = "rbvh",
    version,
    about = "Rasterized BVH ray casting on Vulkan compute (Novák & Dachsbacher 2012)",
    propagate_version = true
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

// Every command takes negative numbers as values, so that `--texels-per-diagonal -3` reaches the
// range check that explains it instead of clap's "unexpected argument".
#[derive(Subcommand)]
enum Command {
    /// Render a scene to PNG (and optionally EXR with depth and normals).
    #[command(allow_negative_numbers = true)]
    Render(render::Args),
    /// Render a scene lit by a sky (shadows, ambient occlusion) through the exact BVH and an RBVH
    /// into one PNG side by side, and print each one's memory, speed and error.
    #[command(allow_negative_numbers = true)]
    Compare(compare::Args),
    /// Build an RBVH and report its nodes, leaves, texels and memory against the exact BVH.
    #[command(allow_negative_numbers = true)]
    Build(build::Args),
    /// Trace a ray file and write a hit file (formats in docs/cli.md, "Ray and hit files").
    #[command(allow_negative_numbers = true)]
    Trace(trace::Args),
    /// Benchmark the exact BVH and RBVH levels: speed, memory and error on the same rays.
    #[command(allow_negative_numbers = true)]
    Bench(bench::Args),
    /// Paint brush strokes onto an RBVH's surface on the device, and save it (with its colours).
    #[command(allow_negative_numbers = true)]
    Paint(paint::Args),
    /// Render the regression cases and compare them with golden images (FLIP and depth).
    #[command(allow_negative_numbers = true)]
    Regress(regress::Args),
    /// Compile every pipeline (on any device, or AMD's compiler with no GPU: --amd navi21) and
    /// print the registers, spills, code size and waves per SIMD each takes; runs nothing.
    Shaders(shaders::Args),
    /// Write every measured table of README.md, docs/*.md and scenes/README.md from the results
    /// files in docs/results (or check, with --check, that each is what its file makes).
    Tables(tables::Args),
    /// List the built-in scenes, which every command takes for --scene without any file.
    Scenes,
    /// Rewrite a flat .rbvh file of any version as the current one, painted colours and all (a
    /// two-level RBVH's file, written only by the current version, is refused).
    Upgrade(upgrade::Args),
}

fn main() {
    // Rust ignores SIGPIPE, so a write to a pipe whose reader has gone (`rbvh build | head -1`)
    // fails and `println!` panics; the default action ends the process quietly instead, as
    // every Unix tool that writes to a pipe does.
    #[cfg(unix)]
    // SAFETY: before any thread is started; SIG_DFL is a valid disposition for SIGPIPE.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    let matches = Cli::command().get_matches();
    let cli = Cli::from_arg_matches(&matches).unwrap_or_else(|e| e.exit());
    // Which flags were given rather than left at their defaults: a flag that would have no
    // effect is refused, and its default cannot say whether it was asked for.
    let given = matches
        .subcommand()
        .map(|(_, m)| Given::of(m))
        .unwrap_or_default();
    let result = match cli.command {
        Command::Render(a) => render::run(a, &given),
        Command::Compare(a) => compare::run(a, &given),
        Command::Trace(a) => trace::run(a, &given),
        Command::Build(a) => build::run(a),
        Command::Bench(a) => bench::run(a, &given),
        Command::Regress(a) => regress::run(a, &given),
        Command::Paint(a) => paint::run(a, &given),
        Command::Shaders(a) => shaders::run(a),
        Command::Tables(a) => tables::run(a),
        Command::Upgrade(a) => upgrade::run(a),
        Command::Scenes => {
            for name in rbvh::scene::builtin::NAMES {
                println!("{name}");
            }
            Ok(())
        }
    };
    if let Err(e) = result {
        eprintln!("error: {e}");
        // A cause already told by a message above it (the library's errors name their file and
        // say why in one line, and keep the why as their source) is not told again.
        let mut told = vec![e.to_string()];
        for cause in e.chain().skip(1) {
            let cause = cause.to_string();
            if !told.iter().any(|t| t.contains(&cause)) {
                eprintln!("  caused by: {cause}");
                told.push(cause);
            }
        }
        std::process::exit(1);
    }
}
