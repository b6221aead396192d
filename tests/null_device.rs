//! Shader statistics without a GPU: RADV's null device (Mesa's "null hardware", offered while
//! `RADV_FORCE_FAMILY` names an AMD family) compiles every pipeline the library has with AMD's
//! real compiler and reports what each became. This file is its own process, so the variable set
//! here reaches no other test; its one test runs the steps in order, since Mesa reads the variables
//! when an instance is made.
//!
//! Where RADV is not installed the test is skipped, saying why — unless `RBVH_REQUIRE_NULL_DEVICE`
//! is set, as `.ci/run` sets it: CI installs RADV through `.ci/setup`, so a skip there fails.

mod common;

use rbvh::bench::shaders::{column_value, COLUMNS};
use rbvh::gpu::{compile_every_pipeline, Context, ContextOptions, ShaderStatistic, Validation};
use rbvh::structure::Structure;
use rbvh::Error;

/// The results file of the project's reference (Mesa's RADV on navi21, wave64), kept at the
/// commit's shaders.
const REFERENCE: &str = "docs/results/shaders-navi21-wave64.json";

fn options(device: Option<&str>) -> ContextOptions {
    ContextOptions {
        device_name: device.map(str::to_string),
        validation: Validation::IfInstalled,
        ..ContextOptions::default()
    }
}

#[test]
fn every_pipeline_compiles_on_the_null_device_and_reports_its_registers() {
    if !common::radv_or_skip() {
        return;
    }
    // SAFETY (of the environment): set before any Vulkan call of this process, which has no
    // other test; Mesa reads them when the instance enumerates its devices.
    std::env::set_var("RADV_FORCE_FAMILY", "navi21");
    std::env::set_var("MESA_SHADER_CACHE_DISABLE", "true");
    std::env::remove_var("RADV_PERFTEST");

    // Unnamed, the null device is never chosen: lavapipe is, and traces.
    let runnable = Context::new(&options(None)).expect("lavapipe beside the null device");
    assert!(
        !runnable.limits().compile_only,
        "{}",
        runnable.device_name()
    );
    drop(runnable);

    let ctx = Context::new(&options(Some("RADV"))).expect("RADV's null device, named");
    assert!(ctx.limits().compile_only, "{}", ctx.device_name());
    assert!(ctx.limits().pipeline_statistics, "RADV reports statistics");

    // What must run fails with an error that names the device and the step, not a crash.
    let scene = rbvh::scene::Scene::load("sphere").unwrap();
    let exact = Structure::from(rbvh::bvh::Bvh::build(&scene).unwrap());
    match rbvh::gpu::Tracer::new(&ctx, &exact) {
        Err(Error::CompileOnly { device, what }) => {
            assert_eq!(device, ctx.device_name());
            assert!(what.contains("BVH nodes"), "{what}");
        }
        Err(e) => panic!("expected a compile-only error, got {e}"),
        Ok(_) => panic!("the null device uploaded a structure"),
    }

    let pipelines = compile_every_pipeline(&ctx).unwrap();
    let shaders: std::collections::BTreeSet<&str> = pipelines.iter().map(|p| p.shader).collect();
    assert_eq!(
        shaders,
        [
            "paint",
            "trace_exact",
            "trace_exact_instances",
            "trace_rbvh",
            "trace_rbvh_instances",
            "trace_rbvh_lod"
        ]
        .into()
    );
    assert!(
        pipelines.iter().any(|p| p.reach == "device_addresses"),
        "RADV has device addresses: their variants are compiled too"
    );
    for p in &pipelines {
        let registers = column_value(&p.statistics, COLUMNS[0].1);
        assert!(
            matches!(registers, Some(v) if v.to_string().parse::<u64>().unwrap_or(0) > 0),
            "{}: no registers in {:?}",
            p.pipeline,
            p.statistics
        );
    }
    // The default exact tracer is the one the bench times on a GPU.
    assert!(pipelines
        .iter()
        .any(|p| p.pipeline == "trace_exact" && p.default_variant));

    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(root.join(REFERENCE)).unwrap_or_else(|e| {
        panic!("{REFERENCE}: {e} (write it with rbvh shaders --amd navi21 --json {REFERENCE})")
    });
    let file: serde_json::Value = serde_json::from_str(&text).unwrap();
    if file["driver"].as_str() != Some(ctx.driver()) {
        eprintln!(
            "{REFERENCE} was compiled by {}, this is {}: not compared",
            file["driver"],
            ctx.driver()
        );
        return;
    }
    // Bounds a regression would cross, with the reference's driver (issue "Faster than the
    // exact BVH on a GPU"): the exact tracer's stack stays out of its registers (at most 56
    // VGPRs, 48 at bc95e65, nothing spilled; 184 when its two stacks sat in registers), and no
    // RBVH tracer goes back above what it took once the world ray, the hit's normal source and
    // the level-of-detail cone were kept beside the stack, or spills (56, with or without level
    // of detail: docs/speed.md, "Words kept beside the stack"; 64 and 72 since c82964f, "The
    // leaf tested where it is met"; 96–128 with 37–77 SGPRs spilled before values the walk
    // inlined stopped being carried from leaf to leaf). Counting or not: the counting pipelines
    // took 8 more, then 16 once the counters grew to 10 words, until they counted in their
    // buffers' records ("Counters out of the registers").
    let number = |p: &rbvh::gpu::CompiledPipeline, column: usize| {
        column_value(&p.statistics, COLUMNS[column].1)
            .map_or(0, |v| v.to_string().parse::<u64>().unwrap_or(u64::MAX))
    };
    for p in &pipelines {
        let (vgprs, spilled) = (number(p, 0), number(p, 2) + number(p, 3));
        // Every trace pipeline, the two-level ones within the flat ones' bounds (since the
        // instance hooks return their results with one exit and the hit's instance is named
        // where the ray leaves it; the exact one took 56, the RBVH one 72, before: docs/speed.md,
        // "The two-level exact tracer's registers", "The two-level RBVH tracer's registers").
        if !matches!(
            p.shader,
            "trace_exact"
                | "trace_exact_instances"
                | "trace_rbvh"
                | "trace_rbvh_lod"
                | "trace_rbvh_instances"
        ) {
            continue;
        }
        assert!(
            vgprs <= 56 && spilled == 0,
            "{}: {vgprs} VGPRs, {spilled} spilled",
            p.pipeline
        );
    }
    // The ratio: every RBVH trace pipeline, timed or counting, takes at most 1.25 times
    // the exact tracer's registers, of the same levels, reached the same way and counting alike
    // (56 against 48 since d8d2c94, 1.33 times before; in two levels 56 against 48, 72 against 56
    // before; counting, 56 against 48 since the counters left the registers, 72 before).
    for p in &pipelines {
        let referee = match p.shader {
            "trace_rbvh" | "trace_rbvh_lod" => "trace_exact",
            "trace_rbvh_instances" => "trace_exact_instances",
            _ => continue,
        };
        let counting = |q: &rbvh::gpu::CompiledPipeline| q.pipeline.contains("counting");
        let exact = pipelines
            .iter()
            .find(|e| e.shader == referee && e.reach == p.reach && counting(e) == counting(p))
            .expect("an exact tracer of the same levels reached the same way, counting alike");
        assert!(
            4 * number(p, 0) <= 5 * number(exact, 0),
            "{}: {} VGPRs against the exact tracer's {}",
            p.pipeline,
            number(p, 0),
            number(exact, 0)
        );
    }
    // The reference results file holds this commit's statistics wherever this Mesa made it.
    let recorded: Vec<(String, Vec<String>)> = file["pipelines"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| {
            let stats: Vec<ShaderStatistic> =
                serde_json::from_value(p["statistics"].clone()).unwrap();
            (p["pipeline"].as_str().unwrap().to_string(), shown(&stats))
        })
        .collect();
    let now: Vec<(String, Vec<String>)> = pipelines
        .iter()
        .map(|p| (p.pipeline.clone(), shown(&p.statistics)))
        .collect();
    assert_eq!(
        recorded, now,
        "{REFERENCE} is not what this commit's shaders compile to: rerun \
         `rbvh shaders --amd navi21 --json {REFERENCE}` (and the wave32 file) and `rbvh tables`"
    );
}

/// The statistics a table shows, as text, in [`COLUMNS`] order.
fn shown(statistics: &[ShaderStatistic]) -> Vec<String> {
    COLUMNS
        .iter()
        .map(|(_, names)| column_value(statistics, names).map_or("-".into(), |v| v.to_string()))
        .collect()
}
