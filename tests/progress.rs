//! Progress reports add up: every counted step ends, and the units advanced are the units
//! announced (a bar that stops at 97% or runs past 100% misleads the user it is for).

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::sync::Mutex;

mod common;

use rbvh::bvh::{BuildParams, Bvh};
use rbvh::gpu::{Query, Tracer, OBSERVED_BATCH};
use rbvh::lod::{Cones, Lod, LodParams, RayCone};
use rbvh::progress::Progress;
use rbvh::rbvh::{Rbvh, RbvhParams};
use rbvh::scene::Scene;
use rbvh::structure::Structure;

/// Steps as (what, announced total, units advanced), in order; advances may come from any thread.
#[derive(Default)]
struct Tally {
    steps: Mutex<Vec<(String, u64, u64)>>,
    open: Mutex<Option<(String, u64)>>,
    advanced: AtomicU64,
}

impl Progress for Tally {
    fn begin(&self, what: &str, total: u64) {
        let mut open = self.open.lock().unwrap();
        assert!(open.is_none(), "{what} began inside {open:?}");
        *open = Some((what.to_string(), total));
        self.advanced.store(0, Ordering::SeqCst);
    }
    fn advance(&self, done: u64) {
        assert!(
            self.open.lock().unwrap().is_some(),
            "advance outside a step"
        );
        self.advanced.fetch_add(done, Ordering::SeqCst);
    }
    fn end(&self) {
        let (what, total) = self.open.lock().unwrap().take().expect("end without begin");
        let advanced = self.advanced.load(Ordering::SeqCst);
        self.steps.lock().unwrap().push((what, total, advanced));
    }
}

impl Tally {
    /// The counted steps (total > 0), each checked to have advanced exactly its total.
    fn counted(&self) -> Vec<String> {
        assert!(self.open.lock().unwrap().is_none(), "a step never ended");
        let steps = self.steps.lock().unwrap();
        for (what, total, advanced) in steps.iter() {
            if *total > 0 {
                assert_eq!(advanced, total, "{what}");
            }
        }
        steps
            .iter()
            .filter(|s| s.1 > 0)
            .map(|s| format!("{} {}", s.0, s.1))
            .collect()
    }
}

#[test]
fn builds_count_every_triangle_once() {
    let scene = Scene::load("default").unwrap();
    let n = scene.triangle_count() as u64;

    let tally = Tally::default();
    Bvh::build_observed(&scene, &BuildParams::DEFAULT, &tally).unwrap();
    assert_eq!(
        tally.counted(),
        [format!("building the exact BVH (triangles) {n}")]
    );

    for level in [0, 4] {
        let tally = Tally::default();
        let observed =
            Rbvh::build_observed(&scene, &RbvhParams::quality(level).unwrap(), &tally).unwrap();
        assert_eq!(
            tally.counted(),
            [format!("building the RBVH (triangles into leaves) {n}")]
        );
        // Watching changes nothing.
        let plain = Rbvh::build(&scene, &RbvhParams::quality(level).unwrap()).unwrap();
        assert_eq!(observed.nodes, plain.nodes);
        assert_eq!(observed.atlas.texels, plain.atlas.texels);
    }
}

#[test]
fn a_scene_file_counts_its_meshes_and_reads_a_repeated_mesh_once_to_the_same_scene() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("twice.toml");
    std::fs::write(
        &path,
        "[[mesh]]\nbuiltin = \"blob\"\n\n\
         [[mesh]]\nbuiltin = \"blob\"\ntranslate = [3.0, 0.0, 0.0]\n\n\
         [[mesh]]\nbuiltin = \"sphere\"\nscale = 0.5\n",
    )
    .unwrap();
    let tally = Tally::default();
    let scene = Scene::load_observed(path.to_str().unwrap(), &tally).unwrap();
    assert_eq!(
        tally.counted(),
        [format!("loading the meshes of {} 3", path.display())]
    );

    let blob = Scene::load("blob").unwrap();
    let sphere = Scene::load("sphere").unwrap();
    let (b, s) = (blob.triangle_count(), sphere.triangle_count());
    assert_eq!(scene.triangle_count(), 2 * b + s);
    for t in 0..b {
        let original = blob.triangle(t);
        let [first, second] = [scene.triangle(t), scene.triangle(b + t)];
        for k in 0..3 {
            assert_eq!(first[k], original[k]);
            assert_eq!(second[k], original[k] + glam::Vec3::new(3.0, 0.0, 0.0));
        }
    }
    let last = scene.triangle(2 * b);
    let expected = sphere.triangle(0);
    for k in 0..3 {
        assert!((last[k] - 0.5 * expected[k]).length() < 1e-6);
    }
}

#[test]
fn a_watched_trace_counts_its_rays_in_batches_and_answers_as_an_unwatched_one() {
    let ctx = common::context();
    let scene = Scene::load("sphere").unwrap();
    let camera = scene.camera_or_framed(1.0);
    // More than two batches, the last one partial.
    let rays = camera.primary_rays(768, 768);
    assert!(rays.len() > 2 * OBSERVED_BATCH && rays.len() % OBSERVED_BATCH != 0);
    let rbvh = Arc::new(Rbvh::build(&scene, &RbvhParams::quality(2).unwrap()).unwrap());

    let tracer = Tracer::new(&ctx, &Structure::from(rbvh.clone())).unwrap();
    let tally = Tally::default();
    let watched = tracer
        .trace_observed(&rays, Cones::None, Query::Closest, false, &tally)
        .unwrap();
    assert_eq!(tally.counted(), [format!("tracing rays {}", rays.len())]);
    assert_eq!(
        watched.hits,
        tracer.trace(&rays, Query::Closest).unwrap().hits
    );

    let lod = Lod::build(&rbvh, &LodParams::default()).unwrap();
    let tracer = Tracer::new(&ctx, &Structure::with_lod(rbvh, lod)).unwrap();
    let cones = vec![RayCone::pixel(&camera, 768); rays.len()];
    let tally = Tally::default();
    let watched = tracer
        .trace_observed(&rays, &cones, Query::Closest, true, &tally)
        .unwrap();
    assert_eq!(tally.counted(), [format!("tracing rays {}", rays.len())]);
    let plain = tracer
        .trace_with(&rays, &cones, Query::Closest, true)
        .unwrap();
    assert_eq!(watched.hits, plain.hits);
    assert_eq!(watched.counters, plain.counters);
    // A level-of-detail tracer without cones is refused, as trace_with refuses it.
    assert!(tracer
        .trace_observed(&rays, Cones::None, Query::Closest, false, &tally)
        .is_err());
}

/// An upload is one counted step of the structure's bytes on the device (an RBVH's atlas with
/// its blocks' height ranges), and the uploaded structure traces as the unwatched one does.
#[test]
fn an_upload_counts_the_bytes_of_every_array() {
    let ctx = common::context();
    let scene = Scene::load("sphere").unwrap();
    let rays = scene.camera_or_framed(1.0).primary_rays(64, 64);
    let bvh = Bvh::build(&scene).unwrap();
    let rbvh = Arc::new(Rbvh::build(&scene, &RbvhParams::quality(1).unwrap()).unwrap());
    let lod = Lod::build(&rbvh, &LodParams::default()).unwrap();
    let rbvh_bytes =
        rbvh.tree_bytes() + rbvh.triangle_bytes() + 4 * rbvh.atlas_words().len() as u64;
    let exact_bytes = bvh.tree_bytes() + bvh.triangle_bytes();
    let cases = [
        (Structure::from(bvh), exact_bytes),
        (Structure::from(rbvh.clone()), rbvh_bytes),
    ];
    for (structure, bytes) in cases {
        let tally = Tally::default();
        let watched = Tracer::new_observed(&ctx, &structure, &tally).unwrap();
        assert_eq!(
            tally.counted(),
            [format!("uploading the structure (bytes) {bytes}")],
            "{}",
            structure.label()
        );
        let plain = Tracer::new(&ctx, &structure).unwrap();
        assert_eq!(
            watched.trace(&rays, Query::Closest).unwrap().hits,
            plain.trace(&rays, Query::Closest).unwrap().hits
        );
    }
    // With levels of detail the nodes carry their columns and the columns are uploaded too: more
    // bytes, all of them counted (Tally checks that the advances add up to the total).
    let tally = Tally::default();
    Tracer::new_observed(&ctx, &Structure::with_lod(rbvh, lod), &tally).unwrap();
    let counted = tally.counted();
    assert_eq!(counted.len(), 1, "{counted:?}");
    let total: u64 = counted[0].rsplit(' ').next().unwrap().parse().unwrap();
    assert!(total > rbvh_bytes, "{counted:?}");
}

/// Uploads are written in 64 MiB steps: an array of more than one step (its last one partial)
/// reads back whole, and a write larger than its buffer is an error, not a panic.
#[test]
fn an_upload_of_several_steps_reads_back_whole() {
    let ctx = common::context();
    let words: Vec<u32> = (0..(64u32 << 20) / 4 + 1003)
        .map(|k| k.wrapping_mul(0x9E37_79B9))
        .collect();
    let mut buffer = ctx.upload_storage("several steps", &words).unwrap();
    assert_eq!(ctx.read::<u32>(&mut buffer).unwrap(), words);
    let mut small = ctx.upload_storage("small", &[1u32, 2]).unwrap();
    let err = ctx
        .write(&mut small, bytemuck::cast_slice(&[1u32, 2, 3]))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("12 bytes do not fit the 8-byte buffer small"),
        "{err}"
    );
}
