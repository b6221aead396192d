//! The benchmark harness (`rbvh::bench`, `rbvh bench`): a small run on the sphere has every record
//! and field, writes JSON and CSV that parse back and plots that exist; secondary rays start at the
//! exact hits; the validator catches a method that is wrong rather than fast.

mod common;

use std::collections::HashSet;
use std::path::Path;
use std::process::Command;

use rbvh::bench::metrics::hit_errors;
use rbvh::bench::record::csv_columns;
use rbvh::bench::validate::invalid_reason;
use rbvh::bench::{self, BenchConfig, Device, RayType};
use rbvh::bvh::Bvh;
use rbvh::geom::Hit;
use rbvh::gpu::Query;
use rbvh::rays::{generate, offset_origin, Secondary, DEFAULT_LIGHT};
use rbvh::rbvh::RbvhParams;
use rbvh::scene::{Instances, Light, PointSource, Scene};
use rbvh::structure::Kind;

fn small_config(plot: Option<&Path>) -> BenchConfig {
    let mut config = BenchConfig::new(vec!["sphere".into()], Device::Existing(common::context()));
    config.levels = vec![q(0), q(2)];
    config.width = 32;
    config.height = 32;
    config.runs = 2;
    config.seam_rays = 2000;
    config.plot_dir = plot.map(Path::to_path_buf);
    config
}

fn keys(v: &serde_json::Value) -> HashSet<&str> {
    v.as_object()
        .expect("an object")
        .keys()
        .map(String::as_str)
        .collect()
}

fn set<'a>(names: &[&'a str]) -> HashSet<&'a str> {
    names.iter().copied().collect()
}

/// Preset `level`'s parameters.
fn q(level: u32) -> RbvhParams {
    RbvhParams::quality(level).unwrap()
}

#[test]
fn a_small_run_has_every_record_and_writes_json_csv_and_plots() {
    let dir = tempfile::tempdir().unwrap();
    let plots = dir.path().join("plots");
    let report = bench::run(&small_config(Some(&plots))).unwrap();

    // Every method × ray type, in ray-type order, the exact BVH first in each.
    assert_eq!(report.results.len(), 3 * 4);
    for (chunk, ray_type) in report.results.chunks(3).zip(RayType::ALL) {
        let levels: Vec<_> = chunk.iter().map(|r| r.quality.as_deref()).collect();
        assert_eq!(levels, [None, Some("Q0"), Some("Q2")]);
        for r in chunk {
            assert_eq!(r.ray_type, ray_type);
            assert_eq!(r.scene, "sphere");
            assert!(r.rays > 0 && r.triangles > 0);
            let s = &r.mrays_per_s;
            assert!(
                s.min > 0.0 && s.min <= s.median && s.median <= s.max,
                "{s:?}"
            );
            // Every timed run's value, as many as runs, within the spread.
            assert_eq!(s.samples.len(), 2, "{s:?}");
            assert!((1..=4096).contains(&r.passes), "{}", r.passes);
            assert!(s.samples.iter().all(|&v| s.min <= v && v <= s.max), "{s:?}");
            assert!(r.build_ms > 0.0);
            let m = r.memory_bytes;
            assert_eq!(m.total, m.tree + m.atlas + m.triangles);
        }
        let exact = &chunk[0];
        assert_eq!(exact.method, Kind::Exact);
        assert!(exact.error.is_none() && exact.params.is_none());
        // Seam leaks on the RBVH levels alone, the same for each ray type of a level.
        assert!(exact.seams.is_none());
        for r in &chunk[1..] {
            let seams = r.seams.expect("a plain RBVH level's seam leaks");
            assert_eq!(seams.rays, 2000);
            assert!(seams.leaks < 20, "{seams:?}");
        }
        assert_eq!(exact.speedup_vs_exact, 1.0);
        assert_eq!(exact.memory_ratio_vs_exact, 1.0);
        assert_eq!(exact.memory_bytes.atlas, 0);
        assert!(exact.valid, "{:?}", exact.invalid_reason);
        for r in &chunk[1..] {
            assert_eq!(r.method, Kind::Rbvh);
            assert!(r.params.is_some());
            assert!(r.memory_bytes.atlas > 0);
            assert_eq!(r.valid, r.invalid_reason.is_none());
            let e = r.error.expect("rbvh records carry errors");
            assert!((0.0..=1.0).contains(&e.miss_mismatch_rate));
            let primary = ray_type == RayType::Primary;
            assert_eq!(e.psnr_db.is_some(), primary, "{ray_type:?}");
            assert_eq!(e.flip_mean.is_some(), primary, "{ray_type:?}");
            if primary {
                assert!(e.t_err_p99.is_some() && e.normal_err_deg_mean.is_some());
            }
            if ray_type.query() == Query::Any {
                assert!(e.t_err_mean.is_none() && e.normal_err_deg_p99.is_none());
            }
        }
    }

    // JSON parses back with every key of the schema.
    let json_path = dir.path().join("bench.json");
    bench::write_json(&json_path, &report).unwrap();
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json_path).unwrap()).unwrap();
    assert!(keys(&json).is_superset(&set(&[
        "device",
        "driver",
        "date",
        "git",
        "git_dirty",
        "host",
        "version",
        "runs",
        "min_run_ms",
        "results",
        "shaders"
    ])));
    // The host: what decides lavapipe's speed, read from this (Linux) machine.
    assert!(keys(&json["host"]).is_superset(&set(&[
        "cpu",
        "cores",
        "logical_cpus",
        "threads_used",
        "l2_bytes",
        "l3_bytes",
        "memory_bytes",
        "os",
        "virtualized",
        "mesa",
        "llvm"
    ])));
    if cfg!(target_os = "linux") {
        assert!(json["host"]["memory_bytes"].as_u64().unwrap() > 0);
        assert!(json["host"]["logical_cpus"].as_u64().unwrap() > 0);
    }
    if report.provenance.device.contains("llvmpipe") {
        assert!(report.provenance.host.threads_used.is_some());
        assert!(
            report.provenance.host.mesa.is_some() && report.provenance.host.llvm.is_some(),
            "{:?}",
            report.provenance.host
        );
    }
    // One entry per trace pipeline, in the order first used; statistics where the driver gives them.
    let pipelines: Vec<(&str, Kind)> = report
        .shaders
        .iter()
        .map(|s| (s.compiled.shader, s.method))
        .collect();
    assert_eq!(
        pipelines,
        [("trace_exact", Kind::Exact), ("trace_rbvh", Kind::Rbvh)]
    );
    assert!(report.shaders.iter().all(|s| s.compiled.default_variant));
    assert_eq!(json["shaders"].as_array().unwrap().len(), 2);
    let listed = bench::shader_table(&report);
    for s in &report.shaders {
        assert_eq!(
            s.compiled.statistics.is_empty(),
            !listed.contains(&s.compiled.pipeline),
            "{listed}"
        );
    }
    let date = json["date"].as_str().unwrap();
    assert!(date.len() == 20 && date.ends_with('Z') && date.as_bytes()[10] == b'T');
    let results = json["results"].as_array().unwrap();
    assert_eq!(results.len(), report.results.len());
    for r in results {
        assert!(keys(r).is_superset(&set(&[
            "scene",
            "triangles",
            "method",
            "quality",
            "params",
            "ray_type",
            "rays",
            "mrays_per_s",
            "speedup_vs_exact",
            "build_ms",
            "memory_bytes",
            "memory_ratio_vs_exact",
            "error",
            "valid",
            "timing_source",
            "passes",
            "block_jumps",
        ])));
        assert_eq!(
            keys(&r["mrays_per_s"]),
            set(&["median", "min", "max", "samples"]),
            "{r}"
        );
        assert_eq!(
            keys(&r["memory_bytes"]),
            set(&[
                "tree",
                "atlas",
                "triangles",
                "total",
                "texels",
                "narrow_texels"
            ])
        );
        assert!(matches!(
            r["timing_source"].as_str(),
            Some("gpu_timestamps" | "wall")
        ));
        match r["method"].as_str().unwrap() {
            "exact" => {
                assert!(r["error"].is_null() && r["params"].is_null() && r["quality"].is_null());
                assert!(r["block_jumps"].is_null());
            }
            "rbvh" => {
                assert!(keys(&r["error"]).is_superset(&set(&[
                    "miss_mismatch_rate",
                    "t_err_mean",
                    "t_err_p99",
                    "t_err_max",
                    "t_err_object_mean",
                    "t_err_object_p99",
                    "normal_err_deg_mean",
                    "normal_err_deg_p99",
                    "back_facing_rate",
                    "psnr_db",
                    "flip_mean",
                ])));
                assert!(
                    keys(&r["params"]).is_superset(&set(&["texels_per_diagonal", "object_rate"]))
                );
                assert!(matches!(r["quality"].as_str(), Some("Q0" | "Q2")));
                // The device's default (`Tracer::block_jumps`).
                let cpu = common::context().limits().cpu;
                assert_eq!(r["block_jumps"].as_bool(), Some(!cpu));
            }
            other => panic!("method {other}"),
        }
    }

    // CSV, read back by the `csv` crate: the header, then one row per record with as many
    // cells, each led by the report's provenance (the device name holds a comma: quoted).
    let csv_path = dir.path().join("bench.csv");
    bench::write_csv(&csv_path, &report).unwrap();
    let mut reader = csv::Reader::from_path(&csv_path).unwrap();
    let header: Vec<String> = reader.headers().unwrap().iter().map(String::from).collect();
    let columns = csv_columns().unwrap();
    assert_eq!(header, columns);
    let rows: Vec<csv::StringRecord> = reader.records().map(Result::unwrap).collect();
    assert_eq!(rows.len(), report.results.len());
    let column = |name: &str| columns.iter().position(|c| c == name).unwrap();
    for ((row, record), json) in rows.iter().zip(&report.results).zip(results) {
        assert_eq!(row.len(), columns.len(), "{row:?}");
        assert_eq!(&row[0], report.provenance.device, "{row:?}");
        assert_eq!(&row[1], report.provenance.driver, "{row:?}");
        assert_eq!(&row[2], report.provenance.date, "{row:?}");
        assert_eq!(
            &row[column("version")],
            env!("CARGO_PKG_VERSION"),
            "{row:?}"
        );
        // Every row names its host, as the JSON does.
        assert_eq!(
            &row[column("host.cpu")],
            report.provenance.host.cpu.clone().unwrap_or_default(),
            "{row:?}"
        );
        assert_eq!(
            &row[column("host.mesa")],
            report.provenance.host.mesa.clone().unwrap_or_default(),
            "{row:?}"
        );
        assert_eq!(&row[column("scene")], record.scene, "{row:?}");
        // The CSV is the JSON record flattened: the same values under dotted keys.
        for (key, value) in [
            ("mrays_per_s.median", &json["mrays_per_s"]["median"]),
            ("memory_bytes.total", &json["memory_bytes"]["total"]),
            ("counters.nodes", &json["counters"]["nodes"]),
            ("passes", &json["passes"]),
            ("error.t_err_p99", &json["error"]["t_err_p99"]),
            ("params.texels", &json["params"]["texels"]),
        ] {
            let cell = &row[column(key)];
            match value {
                serde_json::Value::Null => assert_eq!(cell, "", "{key} in {row:?}"),
                serde_json::Value::String(s) => assert_eq!(cell, s, "{key} in {row:?}"),
                // The test's JSON parser may round the last digit; the CSV has the full value.
                number => {
                    let (c, j) = (cell.parse::<f64>().unwrap(), number.as_f64().unwrap());
                    assert!((c - j).abs() <= 1e-12 * j.abs(), "{key}: {c} against {j}");
                }
            }
        }
    }

    // Plots: charts and, per level, the render and its error image beside the exact render;
    // no traffic chart without traffic.
    let scene_dir = plots.join("sphere");
    assert!(!report
        .written
        .iter()
        .any(|p| p.to_string_lossy().contains("traffic_")));
    for file in [
        "speed_vs_error.svg",
        "memory_vs_error.svg",
        "speed_vs_error.png",
        "memory_vs_error.png",
        "exact.png",
        "q0.png",
        "q0_error.png",
        "q2.png",
        "q2_error.png",
    ] {
        let path = scene_dir.join(file);
        assert!(
            report.written.contains(&path),
            "{} not listed",
            path.display()
        );
        let bytes = std::fs::read(&path).unwrap();
        if file.ends_with(".svg") {
            assert!(bytes.starts_with(b"<svg"), "{file}");
        } else {
            assert!(bytes.starts_with(b"\x89PNG"), "{file}");
        }
    }

    let table = bench::table(&report);
    assert_eq!(
        table.lines().count(),
        1 + 1 + report.results.len() + 1,
        "{table}"
    );
    // First where it was measured: the host, the device and the commit.
    let host = table.lines().next().unwrap();
    assert_eq!(host, bench::host_line(&report).trim_end());
    assert!(host.contains(&report.provenance.device), "{host}");
    if let Some(cpu) = &report.provenance.host.cpu {
        assert!(host.starts_with(&format!("host: {cpu}")), "{host}");
    }
    // The leaks column, a count on the RBVH lines, and the footnote saying of how many rays.
    assert!(table.lines().nth(1).unwrap().contains("leaks"), "{table}");
    assert!(table.contains("leaks: of 2000 rays"), "{table}");
}

/// With `traffic`, every record carries the CPU twin's counters (equal to the device's) and the
/// memory model's figures, consistent with the structure's size and with each other.
#[test]
fn traffic_records_come_from_a_twin_that_counts_as_the_device() {
    let plots = tempfile::tempdir().unwrap();
    let mut config = small_config(Some(plots.path()));
    config.width = 48;
    config.height = 40;
    config.runs = 1;
    config.ray_types = vec![RayType::Primary, RayType::Shadow];
    config.lod = Some(rbvh::lod::LodParams::default());
    config.traffic = true;
    // Jumps on, which a CPU device does not choose by itself: the twin must follow the tracer.
    config.block_jumps = Some(true);
    let report = bench::run(&config).unwrap();
    assert_eq!(report.results.len(), 2 * 5);
    for r in &report.results {
        let what = format!("{} {:?} {:?}", r.method.name(), r.quality, r.ray_type);
        let t = r.traffic.as_ref().expect("traffic requested");
        assert_eq!(t.counter_mismatch_rate, 0.0, "{what}");
        assert_eq!(t.twin_counters, r.counters, "{what}");
        let c = &r.counters;
        assert!(
            c.nodes > 0.0 && (0.0..=1.0).contains(&c.simd8_utilisation),
            "{what}"
        );
        if r.method == Kind::Exact {
            assert!(
                c.leaves == 0.0 && c.cells == 0.0 && c.triangles > 0.0,
                "{what}"
            );
        } else {
            assert!(
                c.leaves >= c.walks && c.walks > 0.0 && c.cells >= c.cells_tested,
                "{what}"
            );
            assert_eq!(r.block_jumps, Some(true), "{what}");
        }
        let m = &t.traffic;
        assert_eq!(m.rays, r.rays, "{what}");
        assert_eq!(m.structure_bytes, r.memory_bytes.total, "{what}");
        assert!(
            m.working_set_bytes > 0 && m.working_set_bytes <= m.structure_bytes,
            "{what}"
        );
        assert!(m.lines128_per_ray <= m.lines64_per_ray, "{what}");
        assert!(m.bytes_per_ray <= 64.0 * m.lines64_per_ray, "{what}");
        assert_eq!(m.caches.len(), 3);
        let dram: Vec<f64> = m.caches.iter().map(|c| c.dram_bytes_per_ray).collect();
        assert!(dram[0] >= dram[1] && dram[1] >= dram[2], "{what}: {dram:?}");
        // Every line of the working set is fetched at least once.
        assert!(
            dram[2] * m.rays as f64 >= m.working_set_bytes as f64,
            "{what}"
        );
    }
    let work = bench::work_table(&report);
    assert_eq!(work.lines().count(), 1 + report.results.len() + 1, "{work}");

    // A traffic chart per ray type, a line per structure, labelled with its working set.
    for rays in ["primary", "shadow"] {
        let path = plots
            .path()
            .join("sphere")
            .join(format!("traffic_{rays}.svg"));
        assert!(
            report.written.contains(&path),
            "{} not listed",
            path.display()
        );
        let svg = std::fs::read_to_string(&path).unwrap();
        assert!(svg.starts_with("<svg"), "{rays}");
        for label in [
            "exact, set ",
            "Q0, set ",
            "Q2, set ",
            "Q0 LOD, set ",
            "Q2 LOD, set ",
        ] {
            assert!(svg.contains(label), "{rays}: no line labelled {label:?}");
        }
    }
    assert!(!plots.path().join("sphere").join("traffic_ao.svg").exists());
}

#[test]
fn lod_adds_a_valid_rbvh_lod_record_per_level_and_ray_type() {
    let dir = tempfile::tempdir().unwrap();
    let mut config = small_config(Some(dir.path()));
    // Every triangle sampled: the presets trace the sphere exactly from Q3, and a level of detail
    // is built over height fields.
    config.levels = vec![RbvhParams {
        exact_when_cheaper: false,
        ..q(4)
    }];
    // At 32 pixels a side the sphere is about 20 pixels wide and the defaults choose nodes up to
    // 12 pixels across, whole halves of it, whose solid columns move its silhouette: hit/miss on
    // 1.9% of the rays, t p99 4.2% of the diagonal, which the validator rightly calls wrong. At 64
    // pixels the nodes chosen are smaller parts of it, and the trace is valid (no hit/miss
    // disagreement, t p99 0.002%).
    config.width = 64;
    config.height = 64;
    config.lod = Some(rbvh::lod::LodParams::default());
    let report = bench::run(&config).unwrap();
    assert_eq!(report.results.len(), 3 * 4);
    for (chunk, ray_type) in report.results.chunks(3).zip(RayType::ALL) {
        let methods: Vec<_> = chunk.iter().map(|r| r.method.name()).collect();
        assert_eq!(methods, ["exact", "rbvh", "rbvh-lod"], "{ray_type:?}");
        let (plain, lod) = (&chunk[1], &chunk[2]);
        assert!(lod.valid, "{:?}", lod.invalid_reason);
        assert_eq!(lod.quality.as_deref(), Some("Q4"));
        // The coarse columns are counted with the tree.
        assert!(lod.memory_bytes.tree > plain.memory_bytes.tree);
        assert_eq!(lod.memory_bytes.atlas, plain.memory_bytes.atlas);
        assert_eq!(lod.lod, config.lod);
        assert_eq!((chunk[0].lod, plain.lod), (None, None));
    }
    assert!(dir.path().join("sphere").join("q4s_lod.png").exists());
    // Level of detail alone: the same records but the plain level's, and no seam rays aimed.
    let mut alone = small_config(None);
    alone.levels = config.levels.clone();
    alone.ray_types = vec![RayType::Primary];
    alone.width = 64;
    alone.height = 64;
    alone.lod = config.lod;
    alone.plain = false;
    let alone = bench::run(&alone).unwrap();
    let methods: Vec<_> = alone.results.iter().map(|r| r.method.name()).collect();
    assert_eq!(methods, ["exact", "rbvh-lod"]);
    assert!(alone.results.iter().all(|r| r.seams.is_none()));
    assert_eq!(
        alone.results[1].memory_bytes,
        report.results[2].memory_bytes
    );
    let mut neither = small_config(None);
    neither.plain = false;
    let err = bench::run(&neither).unwrap_err().to_string();
    assert!(
        err.contains("plain") && err.contains("no RBVH to measure"),
        "{err}"
    );
    // One line per method, named in the legend (the levels with and without LOD no longer share
    // one zig-zagging line).
    let svg =
        std::fs::read_to_string(dir.path().join("sphere").join("speed_vs_error.svg")).unwrap();
    let texts: Vec<&str> = svg
        .split('<')
        .filter_map(|t| t.strip_prefix("text").and_then(|t| t.split('>').nth(1)))
        .map(str::trim)
        .collect();
    for name in ["rbvh", "rbvh-lod"] {
        assert!(
            texts.contains(&name),
            "no {name:?} in the legend: {texts:?}"
        );
    }
    // The PNG twin draws the same series: RBVH blue, LOD green, the exact BVH red, and text.
    let png = image::open(dir.path().join("sphere").join("speed_vs_error.png"))
        .unwrap()
        .to_rgb8();
    let has = |c: [u8; 3]| png.pixels().any(|p| p.0 == c);
    for (name, colour) in [
        ("rbvh", [0, 0, 255]),
        ("rbvh-lod", [0, 255, 0]),
        ("exact", [255, 0, 0]),
    ] {
        assert!(has(colour), "no {name} series in the PNG chart");
    }
    // The title, drawn with the compiled-in font, darkens the top band (no series reaches it).
    let title_ink = (0..png.width())
        .flat_map(|x| (0..40).map(move |y| (x, y)))
        .filter(|&(x, y)| png.get_pixel(x, y).0.iter().all(|&v| v < 128))
        .count();
    assert!(
        title_ink > 100,
        "{title_ink} dark pixels: no title in the PNG chart"
    );
    let text = bench::table(&report);
    assert!(text.contains("rbvh-lod"), "{text}");
}

#[test]
fn secondary_rays_start_at_the_exact_primary_hits() {
    let scene = Scene::load("sphere").unwrap();
    let diagonal = scene.bounds().diagonal();
    let bvh = Bvh::build(&scene).unwrap();
    let primary = scene.camera_or_framed(1.0).primary_rays(24, 24);
    let exact = bvh.trace_cpu(&primary, false);
    let setup = Secondary {
        diagonal,
        surface_offset: 0.0,
        light: DEFAULT_LIGHT,
        ao_radius: 0.05,
        seed: 9,
    };
    let hit_pixels: Vec<usize> = (0..exact.len()).filter(|&i| exact[i].is_hit()).collect();
    assert!(hit_pixels.len() > 100);
    let Light::Directional { direction } = DEFAULT_LIGHT else {
        panic!("the default light is directional")
    };
    for kind in [RayType::Ao, RayType::Shadow, RayType::Diffuse] {
        let rays = generate(kind, &primary, &exact, &setup);
        assert_eq!(rays.len(), hit_pixels.len());
        for (ray, &pixel) in rays.iter().zip(&hit_pixels).step_by(17) {
            let (p_ray, hit) = (&primary[pixel], &exact[pixel]);
            let point = p_ray.origin() + hit.t * p_ray.dir();
            let mut n = hit.normal().normalize();
            if n.dot(p_ray.dir()) > 0.0 {
                n = -n;
            }
            let expected = offset_origin(point, n, diagonal, 0.0);
            assert!((ray.origin() - expected).length() < 1e-6, "{kind:?}");
            // The offset is small and towards the camera's side of the surface.
            let off = ray.origin() - point;
            assert!(
                off.dot(n) > 0.0 && off.length() < 2e-4 * diagonal,
                "{kind:?}"
            );
            match kind {
                RayType::Ao => {
                    assert!((ray.tmax - 0.05 * diagonal).abs() < 1e-6);
                    assert!(ray.dir().dot(n) > 0.0);
                }
                RayType::Shadow => {
                    assert!((ray.dir() + direction.normalize()).length() < 1e-6);
                    assert_eq!(ray.tmax, f32::INFINITY);
                }
                _ => assert!(ray.dir().dot(n) > 0.0 && ray.tmax == f32::INFINITY),
            }
        }
    }
}

#[test]
fn the_validator_flags_a_method_that_is_wrong_rather_than_fast() {
    let scene = Scene::load("sphere").unwrap();
    let diagonal = scene.bounds().diagonal();
    let bvh = Bvh::build(&scene).unwrap();
    let rays = scene.camera_or_framed(1.0).primary_rays(24, 24);
    let exact = bvh.trace_cpu(&rays, false);
    // The sphere is one object: its diagonal is the scene's.
    let object = |_: &Hit| Some(diagonal);
    let same = hit_errors(&rays, &exact, &exact, diagonal, &object, Query::Closest).unwrap();
    assert_eq!(invalid_reason(&same), None);

    let doubled: Vec<Hit> = exact
        .iter()
        .map(|h| Hit {
            t: if h.is_hit() { 2.0 * h.t } else { h.t },
            ..*h
        })
        .collect();
    let wrong = hit_errors(&rays, &exact, &doubled, diagonal, &object, Query::Closest).unwrap();
    assert_eq!(wrong.t_err, wrong.t_err_object);
    let reason = invalid_reason(&wrong).expect("doubled distances are invalid");
    assert!(reason.contains("distance"), "{reason}");

    let all_miss = vec![Hit::MISS; rays.len()];
    let blind = hit_errors(&rays, &exact, &all_miss, diagonal, &object, Query::Any).unwrap();
    assert!(invalid_reason(&blind).unwrap().contains("hit/miss"));
}

/// Every scene is checked before any work: a missing last scene fails the run before the first
/// scene is loaded or the device is made.
#[test]
fn a_bad_scene_fails_the_run_before_any_work() {
    let mut config = small_config(None);
    config.scenes = vec!["sphere".into(), "/no/such/model.obj".into()];
    let mut events = Vec::new();
    let e = bench::run_observed(
        &config,
        &mut |event| events.push(event),
        &rbvh::progress::Quiet,
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("/no/such/model.obj"), "{e}");
    assert!(events.is_empty(), "work was done first: {events:?}");
}

#[test]
fn bad_configurations_are_errors_naming_the_field() {
    let base = BenchConfig::new(vec!["sphere".into()], Device::Create(Default::default()));
    type Break = fn(&mut BenchConfig);
    let cases: [(&str, Break); 11] = [
        ("scenes", |c| c.scenes.clear()),
        ("width", |c| c.width = 0),
        ("runs", |c| c.runs = 0),
        ("min_run_ms", |c| c.min_run_ms = -1.0),
        ("min_run_ms", |c| c.min_run_ms = f64::NAN),
        ("ao_radius", |c| c.ao_radius = f32::NAN),
        ("texels_per_diagonal", |c| {
            c.levels = vec![RbvhParams {
                texels_per_diagonal: 0.0,
                ..q(2)
            }]
        }),
        ("lod columns", |c| {
            c.lod = Some(rbvh::lod::LodParams {
                columns: 0,
                ..Default::default()
            })
        }),
        ("lod min leaves", |c| {
            c.lod = Some(rbvh::lod::LodParams {
                min_leaves: 0,
                ..Default::default()
            })
        }),
        ("lod bias", |c| {
            c.lod = Some(rbvh::lod::LodParams {
                bias: f32::NAN,
                ..Default::default()
            })
        }),
        ("plot", |c| {
            c.ray_types = vec![RayType::Ao];
            c.plot_dir = Some("p".into());
        }),
    ];
    common::every_case(cases, |(field, break_it)| {
        let mut config = base.clone();
        break_it(&mut config);
        match config.validate() {
            Ok(()) => Err(format!("{field}: accepted")),
            Err(e) => common::ensure(e.to_string().contains(field), || format!("{field}: {e}")),
        }
    });
}

#[test]
fn the_cli_writes_json_and_csv_and_rejects_unknown_ray_types() {
    let dir = tempfile::tempdir().unwrap();
    let (json, csv) = (dir.path().join("b.json"), dir.path().join("b.csv"));
    let out = Command::new(env!("CARGO_BIN_EXE_rbvh"))
        .args(["bench", "--scene", "plane,sphere", "--quality", "Q0"])
        .args([
            "--rays",
            "primary,shadow",
            "--width",
            "16",
            "--height",
            "16",
        ])
        .args(["--runs", "1", "--threads", "1", "--json"])
        .arg(&json)
        .arg("--csv")
        .arg(&csv)
        .env("RBVH_VALIDATION", "auto")
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let table = String::from_utf8_lossy(&out.stdout);
    // A one-line host header, then the table.
    let (host, rest) = table.split_once('\n').unwrap();
    assert!(host.starts_with("host: "), "{table}");
    assert!(rest.starts_with("scene"), "{table}");
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(report["results"].as_array().unwrap().len(), 2 * 2 * 2);
    if report["device"].as_str().unwrap().contains("llvmpipe") {
        assert_eq!(report["host"]["threads_used"], 1);
    }
    assert_eq!(
        std::fs::read_to_string(&csv).unwrap().lines().count(),
        1 + 8
    );

    let bad = Command::new(env!("CARGO_BIN_EXE_rbvh"))
        .args(["bench", "--scene", "sphere", "--rays", "primary,bounce"])
        .output()
        .unwrap();
    assert!(!bad.status.success());
    assert!(String::from_utf8_lossy(&bad.stderr).contains("bounce"));
}

/// A scene with instances is measured flat and in two levels: the two-level exact BVH's records
/// (method `exact-instanced`) follow the exact BVH's in every ray type, hit what it hits (its hits
/// compared as the flat scene's triangles), store each mesh once, and are valid; the two-level
/// RBVH's (`rbvh-instanced`) follow the flat RBVH's at the same level, store each mesh's tiles
/// once, and err as little as the flat one.
#[test]
fn a_scene_with_instances_is_measured_in_two_levels_beside_the_flat_one() {
    let dir = tempfile::tempdir().unwrap();
    let mut config = placed_bench(dir.path());
    config.seam_rays = 4000;
    config.plot_dir = Some(dir.path().join("plots"));
    let report = bench::run(&config).unwrap();
    assert_eq!(report.results.len(), 2 * 4);
    // The charts draw the two-level structures too, each in the legend and in its colour.
    let chart = report
        .written
        .iter()
        .find(|p| p.ends_with("speed_vs_error.svg"))
        .expect("a speed chart");
    let svg = std::fs::read_to_string(chart).unwrap();
    let texts: Vec<&str> = svg
        .split('<')
        .filter_map(|t| t.strip_prefix("text").and_then(|t| t.split('>').nth(1)))
        .map(str::trim)
        .collect();
    for name in ["rbvh", "rbvh-instanced", "exact", "exact-instanced"] {
        assert!(
            texts.contains(&name),
            "no {name:?} in the legend: {texts:?}"
        );
    }
    let png = image::open(chart.with_extension("png")).unwrap().to_rgb8();
    for (name, colour) in [
        ("rbvh-instanced", [255, 0, 255]),
        ("exact-instanced", [128, 0, 0]),
    ] {
        assert!(
            png.pixels().any(|p| p.0 == colour),
            "no {name} series in the PNG chart"
        );
    }
    for chunk in report.results.chunks(4) {
        let (flat, two) = (&chunk[0], &chunk[1]);
        assert_eq!(
            (flat.method, two.method),
            (Kind::Exact, Kind::ExactInstanced)
        );
        let (rbvh, rbvh_two) = (&chunk[2], &chunk[3]);
        assert_eq!(
            (rbvh.method, rbvh_two.method),
            (Kind::Rbvh, Kind::RbvhInstanced)
        );
        assert_eq!(rbvh_two.quality, rbvh.quality);
        // Seam rays aimed at each mesh's RBVH in its own space: none through a closed solid,
        // as with the flat RBVH.
        for (what, r) in [("flat", rbvh), ("two levels", rbvh_two)] {
            let seams = r.seams.expect(what);
            assert!(seams.rays > 3000, "{what}: {seams:?}");
            assert_eq!(seams.through, 0, "{what}: {seams:?}");
        }
        assert!(
            rbvh_two.memory_bytes.texels * 4 < rbvh.memory_bytes.texels * 3,
            "the bumpy sphere rasterized once: {} against {} texels",
            rbvh_two.memory_bytes.texels,
            rbvh.memory_bytes.texels
        );
        let (e, e_two) = (
            rbvh.error.as_ref().unwrap(),
            rbvh_two.error.as_ref().unwrap(),
        );
        assert!(
            e_two.miss_mismatch_rate <= 2.0 * e.miss_mismatch_rate + 0.01,
            "{e_two:?} against the flat {e:?}"
        );
        assert!(two.valid, "{:?}", two.invalid_reason);
        assert_eq!(two.triangles, flat.triangles, "triangles as placed");
        assert!(
            two.memory_bytes.triangles * 3 < flat.memory_bytes.triangles * 2,
            "the bumpy sphere stored once: {} against {} bytes",
            two.memory_bytes.triangles,
            flat.memory_bytes.triangles
        );
        let errors = two.error.as_ref().expect("errors against the exact BVH");
        assert_eq!(errors.miss_mismatch_rate, 0.0, "{errors:?}");
        if let Some(t) = errors.t_err_p99 {
            assert!(t < 1e-5, "{errors:?}");
        }
    }
}

/// The bench of a plane and a bumpy sphere placed twice (once mirrored), written under `dir`:
/// Q2, primary and shadow rays, a small image.
fn placed_bench(dir: &Path) -> BenchConfig {
    let path = dir.join("placed.toml");
    std::fs::write(
        &path,
        "[[mesh]]\nbuiltin = \"plane\"\n\
         [[instance]]\nbuiltin = \"bumpy-sphere\"\ntranslate = [0.5, 0.3, 0.0]\nscale = 0.4\n\
         [[instance]]\nbuiltin = \"bumpy-sphere\"\ntranslate = [-0.5, 0.3, 0.0]\nrotate = [0.0, 60.0, 0.0]\nscale = [-0.3, 0.4, 0.3]\n",
    )
    .unwrap();
    let mut config = BenchConfig::new(
        vec![path.to_str().unwrap().into()],
        Device::Existing(common::context()),
    );
    config.levels = vec![q(2)];
    config.width = 48;
    config.height = 32;
    config.runs = 1;
    config.seam_rays = 0;
    config.ray_types = vec![RayType::Primary, RayType::Shadow];
    config
}

/// Measured in two levels alone (as a scene too large to flatten is, `scenes/dragons-1000.toml`),
/// the two-level exact BVH is the referee, checked against its CPU twin, and the two-level RBVH
/// errs against it as it errs against the flat exact BVH beside the flat scene: the two referees
/// hit alike. Errors relative to each object are measured on the object as its instance places
/// it. Points, levels of detail and levels refined for the view, built over the flat scene, are
/// refused, and so are the steps, which the flat structures' CPU twins count.
#[test]
fn a_scene_measured_in_two_levels_alone_is_refereed_by_the_two_level_exact_bvh() {
    let dir = tempfile::tempdir().unwrap();
    let mut config = placed_bench(dir.path());
    let both = bench::run(&config).unwrap();
    config.instances = Instances::TwoLevel;
    let alone = bench::run(&config).unwrap();
    assert_eq!(alone.results.len(), 2 * 2);
    for (chunk, beside) in alone.results.chunks(2).zip(both.results.chunks(4)) {
        let (exact, rbvh) = (&chunk[0], &chunk[1]);
        assert_eq!(
            (exact.method, rbvh.method),
            (Kind::ExactInstanced, Kind::RbvhInstanced)
        );
        assert!(exact.valid, "{:?}", exact.invalid_reason);
        assert!(exact.error.is_none(), "the referee has no error record");
        assert_eq!(exact.triangles, beside[0].triangles, "triangles as placed");
        assert_eq!(rbvh.memory_bytes, beside[3].memory_bytes);
        let (e, e_beside) = (
            rbvh.error.as_ref().unwrap(),
            beside[3].error.as_ref().unwrap(),
        );
        assert_eq!(e.miss_mismatch_rate, e_beside.miss_mismatch_rate);
        for (a, b) in [
            (e.t_err_p99, e_beside.t_err_p99),
            (e.t_err_object_p99, e_beside.t_err_object_p99),
        ] {
            let (a, b) = (a.unwrap_or(0.0), b.unwrap_or(0.0));
            assert!(
                (a - b).abs() <= 0.05 * b.max(1e-6),
                "{e:?} against {e_beside:?}"
            );
        }
        if rbvh.ray_type == RayType::Primary {
            assert!(e.t_err_object_p99.is_some(), "{e:?}");
        }
    }
    let lod = Some(rbvh::lod::LodParams::default());
    for (points, plain, lod, steps, field) in [
        (
            Some(PointSource::Sampled(1000)),
            true,
            None,
            false,
            "points",
        ),
        (None, false, lod, false, "lod"),
        (None, true, lod, false, "lod"),
        (None, true, None, true, "steps"),
    ] {
        let mut refused = config.clone();
        refused.points = points;
        refused.plain = plain;
        refused.lod = lod;
        refused.steps = steps;
        match bench::run(&refused) {
            Err(rbvh::Error::InvalidParameter { name, .. }) => assert_eq!(name, field),
            other => panic!("{field}: {:?}", other.map(|r| r.results.len())),
        }
    }
    // A level refined for one view is built over the flat scene.
    let mut viewed = config.clone();
    viewed.levels = vec![rbvh::rbvh::RbvhParams {
        view_rate: rbvh::rbvh::VIEW_RATE,
        ..q(2)
    }];
    match bench::run(&viewed) {
        Err(rbvh::Error::InvalidParameter { name, .. }) => assert_eq!(name, "view_rate"),
        other => panic!("view_rate: {:?}", other.map(|r| r.results.len())),
    }
}

/// An RBVH of points is built over the flat scene: a scene with instances benched with `--points`
/// is measured flat alone, with no two-level row built from the meshes' triangles beside it.
#[test]
fn points_measure_a_scene_with_instances_flat() {
    let dir = tempfile::tempdir().unwrap();
    let mut config = placed_bench(dir.path());
    config.points = Some(PointSource::Sampled(4000));
    config.ray_types = vec![RayType::Primary];
    let report = bench::run(&config).unwrap();
    let methods: Vec<Kind> = report.results.iter().map(|r| r.method).collect();
    assert_eq!(methods, [Kind::Exact, Kind::Rbvh]);
    assert_eq!(report.results[1].points, 4000);
}
