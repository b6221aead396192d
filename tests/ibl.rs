//! Image-based lighting (`rbvh::ibl`) against closed forms, for determinism, for the error of RBVH
//! visibility against the exact BVH's, and on bad input.

mod common;

use std::f64::consts::PI;
use std::path::Path;

use glam::Vec3;
use rbvh::bench::metrics::image_errors;
use rbvh::bvh::Bvh;
use rbvh::geom::{Hit, Ray};
use rbvh::gpu::{Context, Query, Tracer};
use rbvh::ibl::{self, Environment, Frame, LatLongMap, Settings, Sky};
use rbvh::output::Image;
use rbvh::rbvh::Rbvh;
use rbvh::scene::Scene;
use rbvh::structure::Structure;
use rbvh::Error;

const WIDTH: u32 = 64;
const HEIGHT: u32 = 48;

/// A structure uploaded for tracing, with the origin offset its surfaces need.
struct Uploaded {
    tracer: Tracer,
    surface_offset: f32,
}

/// The exact BVH (`None`) or the RBVH at quality `Some(level)` of `scene`, every triangle
/// sampled ([`common::sampled_preset`]): these scenes are planes and boxes of a few large
/// triangles, which the presets trace exactly, and the tests' subject is lighting through
/// height fields.
fn structure(ctx: &Context, scene: &Scene, level: Option<u32>) -> Uploaded {
    match level {
        None => Uploaded {
            tracer: Tracer::new(ctx, &Structure::from(Bvh::build(scene).unwrap())).unwrap(),
            surface_offset: 0.0,
        },
        Some(q) => {
            let rbvh = Rbvh::build(scene, &common::sampled_preset(q)).unwrap();
            let surface_offset = rbvh.texel_size;
            Uploaded {
                tracer: Tracer::new(ctx, &Structure::from(rbvh)).unwrap(),
                surface_offset,
            }
        }
    }
}

/// Traces `rays` (a `width × height` image) through `s` and lights the hits by `env` with a
/// uniform `albedo`.
#[allow(clippy::too_many_arguments)]
fn render_rays(
    s: &Uploaded,
    scene: &Scene,
    rays: &[Ray],
    (width, height): (u32, u32),
    env: &Environment,
    albedo: f32,
    samples: u32,
    seed: u64,
) -> (Image, Vec<Hit>) {
    let hits = s.tracer.trace(rays, Query::Closest).unwrap().hits;
    let albedo = vec![Vec3::splat(albedo); rays.len()];
    let frame = Frame {
        width,
        height,
        rays,
        hits: &hits,
        albedo: &albedo,
        offsets: None,
    };
    let settings = Settings {
        samples,
        seed,
        diagonal: scene.bounds().diagonal(),
        surface_offset: s.surface_offset,
        cone: None,
    };
    let mut passes = 0;
    let rendered = ibl::render(&s.tracer, &frame, env, &settings, |pass| {
        passes += 1;
        assert_eq!((pass.done, pass.total), (passes, samples));
    })
    .unwrap();
    assert_eq!(passes, samples, "one observed pass per sample");
    (rendered.image, hits)
}

/// [`render_rays`] with the scene's framing camera at [`WIDTH`] × [`HEIGHT`].
fn render_camera(
    s: &Uploaded,
    scene: &Scene,
    env: &Environment,
    samples: u32,
    seed: u64,
) -> (Image, Vec<Hit>) {
    let rays = scene
        .camera_or_framed(WIDTH as f32 / HEIGHT as f32)
        .primary_rays(WIDTH, HEIGHT);
    render_rays(s, scene, &rays, (WIDTH, HEIGHT), env, 0.8, samples, seed)
}

/// White furnace: nothing occludes the upper hemisphere of a lone plane, so under a constant
/// environment `L` with albedo 1 every cosine-weighted sample estimates exactly `L`
/// (see `ibl::render`), and every hit pixel must be `L` up to rounding, whatever the structure.
#[test]
fn a_lone_plane_in_a_white_furnace_reflects_the_furnace_exactly() {
    let ctx = common::context();
    let scene = Scene::load("plane").unwrap();
    let l = Vec3::new(0.5, 1.0, 2.0);
    let env = Environment::Uniform(l);
    let rays = scene
        .camera_or_framed(WIDTH as f32 / HEIGHT as f32)
        .primary_rays(WIDTH, HEIGHT);
    for level in [None, Some(0), Some(4)] {
        let s = structure(&ctx, &scene, level);
        let (image, hits) = render_rays(&s, &scene, &rays, (WIDTH, HEIGHT), &env, 1.0, 8, 3);
        let hit_count = hits.iter().filter(|h| h.is_hit()).count();
        assert!(hit_count > 300, "{level:?}: only {hit_count} pixels hit");
        for (i, (p, h)) in image.pixels.iter().zip(&hits).enumerate() {
            let error = ((*p - l) / l).abs().max_element();
            assert!(
                error < 1e-5,
                "{level:?}: pixel {i} (hit {}) is {p}",
                h.is_hit()
            );
        }
    }
}

/// The fraction of a cosine-weighted hemisphere at the origin that sees through a rectangle
/// `a × b` parallel to the surface at height `c`, one of whose corners is straight above: the
/// form factor from a differential area to a parallel rectangle (Howell, *A Catalog of Radiation
/// Heat Transfer Configuration Factors*, case B-3).
fn corner_form_factor(a: f64, b: f64, c: f64) -> f64 {
    let (x, y) = (a / c, b / c);
    let (sx, sy) = ((1.0 + x * x).sqrt(), (1.0 + y * y).sqrt());
    (x / sx * (y / sx).atan() + y / sy * (x / sy).atan()) / (2.0 * PI)
}

/// An open-top box: the floor [-1, 1]² at y = 0 and four walls up to y = `height`.
fn open_box(height: f32) -> Scene {
    let mut scene = Scene::new("open box");
    let quad = |corners: [Vec3; 4]| (corners, [[0u32, 1, 2], [0, 2, 3]]);
    let h = height;
    let quads = [
        [
            (-1.0, 0.0, -1.0),
            (1.0, 0.0, -1.0),
            (1.0, 0.0, 1.0),
            (-1.0, 0.0, 1.0),
        ],
        [
            (-1.0, 0.0, -1.0),
            (1.0, 0.0, -1.0),
            (1.0, h, -1.0),
            (-1.0, h, -1.0),
        ],
        [
            (-1.0, 0.0, 1.0),
            (1.0, 0.0, 1.0),
            (1.0, h, 1.0),
            (-1.0, h, 1.0),
        ],
        [
            (-1.0, 0.0, -1.0),
            (-1.0, 0.0, 1.0),
            (-1.0, h, 1.0),
            (-1.0, h, -1.0),
        ],
        [
            (1.0, 0.0, -1.0),
            (1.0, 0.0, 1.0),
            (1.0, h, 1.0),
            (1.0, h, -1.0),
        ],
    ];
    for (i, q) in quads.iter().enumerate() {
        let (corners, triangles) = quad(q.map(|(x, y, z)| Vec3::new(x, y, z)));
        scene.push_object(format!("side {i}"), &corners, &triangles);
    }
    scene.validate().unwrap();
    scene
}

/// Occlusion with a closed form: a point (x, 0, z) on the floor of an open box of height h sees
/// the sky only through the opening, so its cosine-weighted unoccluded fraction is the form
/// factor to the opening — four [`corner_form_factor`] rectangles (1 ∓ x) × (1 ∓ z) at height h.
/// Under a constant environment of 1 with albedo 1 a pixel is the fraction of its N samples
/// that escape: a binomial mean with variance F(1 − F)/N. The mean over M pixels of
/// (pixel − F) then has standard deviation √(Σ F(1 − F)/N) / M (about 0.002 here), and 5 of
/// them bound it; each pixel is also held to Hoeffding's bound at a 10⁻⁶ failure rate over
/// all pixels, √(ln(2M/10⁻⁶) / 2N). The RBVH levels must meet the same bounds: their origins
/// are offset by a texel, and walls and floor are separate height fields. Measured (lavapipe,
/// seed 5): mean offsets −0.0019 exact, −0.0012 Q0 and Q2, −0.0018 Q4, against σ = 0.0019.
#[test]
fn the_floor_of_an_open_box_sees_the_sky_through_its_opening() {
    let ctx = common::context();
    let h = 1.0;
    let scene = open_box(h);
    let (side, samples) = (32u32, 64u32);
    // Orthographic rays straight down onto a grid strictly inside the walls.
    let at = |i: u32| -0.95 + 1.9 * (i as f32 + 0.5) / side as f32;
    let rays: Vec<Ray> = (0..side)
        .flat_map(|j| (0..side).map(move |i| (i, j)))
        .map(|(i, j)| {
            Ray::new(
                Vec3::new(at(i), 2.0, at(j)),
                Vec3::NEG_Y,
                0.0,
                f32::INFINITY,
            )
        })
        .collect();
    let expected: Vec<f64> = rays
        .iter()
        .map(|r| {
            let (x, z) = (f64::from(r.origin().x), f64::from(r.origin().z));
            [
                (1.0 - x, 1.0 - z),
                (1.0 - x, 1.0 + z),
                (1.0 + x, 1.0 - z),
                (1.0 + x, 1.0 + z),
            ]
            .iter()
            .map(|&(a, b)| corner_form_factor(a, b, f64::from(h)))
            .sum()
        })
        .collect();
    let env = Environment::Uniform(Vec3::ONE);
    let (m, n) = (rays.len() as f64, f64::from(samples));
    let hoeffding = ((2.0 * m / 1e-6).ln() / (2.0 * n)).sqrt();
    let sigma = expected
        .iter()
        .map(|f| f * (1.0 - f) / n)
        .sum::<f64>()
        .sqrt()
        / m;
    for level in [None, Some(0), Some(2), Some(4)] {
        let s = structure(&ctx, &scene, level);
        let (image, hits) = render_rays(&s, &scene, &rays, (side, side), &env, 1.0, samples, 5);
        assert!(hits
            .iter()
            .all(|h| h.is_hit() && h.normal()[1].abs() > 0.999));
        let mut worst = 0.0f64;
        let mut sum_diff = 0.0;
        for (p, &f) in image.pixels.iter().zip(&expected) {
            assert!(p.x == p.y && p.y == p.z);
            let v = f64::from(p.x);
            worst = worst.max((v - f).abs());
            sum_diff += v - f;
        }
        let mean_diff = sum_diff / m;
        assert!(
            worst < hoeffding,
            "{level:?}: a pixel is off by {worst} (bound {hoeffding})"
        );
        assert!(
            mean_diff.abs() < 5.0 * sigma,
            "{level:?}: the mean escaping fraction is off by {mean_diff} (σ = {sigma})"
        );
    }
}

fn bits(image: &Image) -> Vec<[u32; 3]> {
    image
        .pixels
        .iter()
        .map(|p| p.to_array().map(f32::to_bits))
        .collect()
}

/// The same seed gives the same image bit for bit; another seed another image.
#[test]
fn renders_are_deterministic_for_a_seed() {
    let ctx = common::context();
    let scene = Scene::load("default").unwrap();
    let env = Environment::Sky(Sky::default());
    for level in [None, Some(2)] {
        let s = structure(&ctx, &scene, level);
        let first = render_camera(&s, &scene, &env, 3, 42).0;
        let again = render_camera(&s, &scene, &env, 3, 42).0;
        let other = render_camera(&s, &scene, &env, 3, 43).0;
        assert_eq!(bits(&first), bits(&again), "{level:?}");
        assert_ne!(bits(&first), bits(&other), "{level:?}");
    }
}

/// Rendered side by side, pass by pass, the exact BVH and an RBVH give each the image it gives
/// alone, bit for bit, with its own rays counted; every pass is heard once with both jobs' rays;
/// jobs of different sample counts are refused.
#[test]
fn side_by_side_renders_are_the_renders_alone() {
    let ctx = common::context();
    let scene = Scene::load("default").unwrap();
    let env = Environment::Sky(Sky::default());
    let (exact, rbvh) = (
        structure(&ctx, &scene, None),
        structure(&ctx, &scene, Some(2)),
    );
    let rays = scene
        .camera_or_framed(WIDTH as f32 / HEIGHT as f32)
        .primary_rays(WIDTH, HEIGHT);
    let hits = |s: &Uploaded| s.tracer.trace(&rays, Query::Closest).unwrap().hits;
    let (exact_hits, rbvh_hits) = (hits(&exact), hits(&rbvh));
    let albedo = vec![Vec3::splat(0.8); rays.len()];
    let frame = |hits| Frame {
        width: WIDTH,
        height: HEIGHT,
        rays: &rays,
        hits,
        albedo: &albedo,
        offsets: None,
    };
    let (exact_frame, rbvh_frame) = (frame(&exact_hits), frame(&rbvh_hits));
    let settings = |s: &Uploaded| Settings {
        samples: 3,
        seed: 7,
        diagonal: scene.bounds().diagonal(),
        surface_offset: s.surface_offset,
        cone: None,
    };
    let (exact_settings, rbvh_settings) = (settings(&exact), settings(&rbvh));
    let mut passes = Vec::new();
    let both = ibl::render_side_by_side(
        &[
            (&exact.tracer, &exact_frame, &exact_settings),
            (&rbvh.tracer, &rbvh_frame, &rbvh_settings),
        ],
        &env,
        |pass| passes.push((pass.done, pass.rays)),
    )
    .unwrap();
    let alone = [
        ibl::render(&exact.tracer, &exact_frame, &env, &exact_settings, |_| {}).unwrap(),
        ibl::render(&rbvh.tracer, &rbvh_frame, &env, &rbvh_settings, |_| {}).unwrap(),
    ];
    let hit = |h: &[Hit]| h.iter().filter(|h| h.is_hit()).count();
    let per_pass = hit(&exact_hits) + hit(&rbvh_hits);
    assert_eq!(passes, [(1, per_pass), (2, per_pass), (3, per_pass)]);
    for (side, one) in both.iter().zip(&alone) {
        assert_eq!(bits(&side.image), bits(&one.image));
        assert_eq!(side.rays, one.rays);
    }
    let fewer = Settings {
        samples: 2,
        ..rbvh_settings
    };
    assert!(ibl::render_side_by_side(
        &[
            (&exact.tracer, &exact_frame, &exact_settings),
            (&rbvh.tracer, &rbvh_frame, &fewer),
        ],
        &env,
        |_| {},
    )
    .is_err());
}

/// The RBVH's IBL image against the exact BVH's at the same samples and seed, on the default
/// scene at 64×48 with 8 samples under the default sky. Measured (lavapipe): FLIP Q0 0.0100,
/// Q2 0.0080, Q4 0.0057 (PSNR 33.9, 35.7, 39.9 dB); the bounds are about twice those, and the
/// finest level must not be worse than the coarsest.
#[test]
fn rbvh_ibl_stays_close_to_the_exact_render() {
    let ctx = common::context();
    let scene = Scene::load("default").unwrap();
    let env = Environment::Sky(Sky::default());
    let (samples, seed) = (8, 1);
    let exact = render_camera(&structure(&ctx, &scene, None), &scene, &env, samples, seed).0;
    let mut flips = Vec::new();
    for (level, max_flip) in [(0, 0.02), (2, 0.016), (4, 0.012)] {
        let s = structure(&ctx, &scene, Some(level));
        let image = render_camera(&s, &scene, &env, samples, seed).0;
        let errors = image_errors(&exact, &image).unwrap();
        eprintln!(
            "Q{level}: FLIP {:.4}, PSNR {:.2} dB",
            errors.flip_mean, errors.psnr_db
        );
        assert!(errors.flip_mean < max_flip, "Q{level}: {errors:?}");
        flips.push(errors.flip_mean);
    }
    assert!(flips[2] <= flips[0], "{flips:?}");
}

/// A constant map loaded from an EXR file lights like the constant environment it holds.
#[test]
fn an_exr_map_lights_like_its_radiance() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("env.exr");
    exr::prelude::write_rgb_file(&path, 16, 8, |_, _| (0.25f32, 0.5f32, 1.0f32)).unwrap();
    let env = Environment::load(&path).unwrap();
    match &env {
        Environment::Map(m) => assert_eq!((m.width(), m.height()), (16, 8)),
        other => panic!("{other:?}"),
    }
    let l = Vec3::new(0.25, 0.5, 1.0);
    for d in [Vec3::Y, Vec3::NEG_Z, Vec3::new(0.6, -0.3, 0.2)] {
        assert!((env.radiance(d) - l).abs().max_element() < 1e-6);
    }
    let ctx = common::context();
    let scene = Scene::load("plane").unwrap();
    let s = structure(&ctx, &scene, None);
    let (image, _) = render_camera(&s, &scene, &env, 2, 0);
    assert!(image
        .pixels
        .iter()
        .all(|p| ((*p - l).abs().max_element() < 1e-5)
            || ((*p - 0.8 * l).abs().max_element() < 1e-5)));
}

fn load_error(path: &Path) -> (Error, String) {
    let err = Environment::load(path).unwrap_err();
    let text = err.to_string();
    assert!(
        text.contains(&path.display().to_string()),
        "the error names no file: {text}"
    );
    (err, text)
}

#[test]
fn bad_environment_maps_are_refused_with_the_file_named() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("missing.exr");
    assert!(matches!(load_error(&missing).0, Error::Io { .. }));

    let garbage = dir.path().join("garbage.exr");
    std::fs::write(&garbage, b"v/1\x01 not an OpenEXR file at all").unwrap();
    let (err, text) = load_error(&garbage);
    assert!(matches!(err, Error::Parse { .. }), "{text}");

    let truncated = dir.path().join("truncated.exr");
    let good = dir.path().join("good.exr");
    exr::prelude::write_rgb_file(&good, 8, 4, |_, _| (1.0f32, 1.0f32, 1.0f32)).unwrap();
    let bytes = std::fs::read(&good).unwrap();
    std::fs::write(&truncated, &bytes[..bytes.len() / 2]).unwrap();
    assert!(matches!(load_error(&truncated).0, Error::Parse { .. }));

    let nan = dir.path().join("nan.exr");
    exr::prelude::write_rgb_file(&nan, 8, 4, |x, y| {
        let v = if (x, y) == (5, 2) { f32::NAN } else { 1.0 };
        (1.0f32, v, 1.0f32)
    })
    .unwrap();
    let (err, text) = load_error(&nan);
    assert!(matches!(err, Error::Parse { .. }), "{text}");
    assert!(text.contains("texel (5, 2)"), "{text}");

    let infinite = dir.path().join("inf.exr");
    exr::prelude::write_rgb_file(&infinite, 8, 4, |_, _| (f32::INFINITY, 1.0f32, 1.0f32)).unwrap();
    assert!(load_error(&infinite).1.contains("texel (0, 0)"));

    let luminance = dir.path().join("luminance.exr");
    {
        use exr::prelude::*;
        let y = AnyChannel::new("Y", FlatSamples::F32(vec![1.0; 8]));
        let channels = AnyChannels::sort(SmallVec::from_vec(vec![y]));
        let layer = Layer::new(
            (4, 2),
            LayerAttributes::default(),
            Encoding::FAST_LOSSLESS,
            channels,
        );
        Image::from_layer(layer)
            .write()
            .to_file(&luminance)
            .unwrap();
    }
    let (err, text) = load_error(&luminance);
    assert!(matches!(err, Error::Parse { .. }), "{text}");
    assert!(text.contains("R, G and B"), "{text}");

    let (err, text) = load_error(dir.path());
    assert!(matches!(err, Error::Parse { .. }), "{text}");

    let empty = LatLongMap::new(0, 0, vec![], Path::new("in memory")).unwrap_err();
    assert!(empty.to_string().contains("0×0"), "{empty}");
}

#[test]
fn bad_render_parameters_are_refused() {
    let ctx = common::context();
    let scene = Scene::load("plane").unwrap();
    let s = structure(&ctx, &scene, None);
    let rays = scene.camera_or_framed(1.0).primary_rays(8, 8);
    let hits = s.tracer.trace(&rays, Query::Closest).unwrap().hits;
    let albedo = vec![Vec3::splat(ibl::GREY); rays.len()];
    let frame = Frame {
        width: 8,
        height: 8,
        rays: &rays,
        hits: &hits,
        albedo: &albedo,
        offsets: None,
    };
    let good = Settings {
        samples: 1,
        seed: 0,
        diagonal: scene.bounds().diagonal(),
        surface_offset: 0.0,
        cone: None,
    };
    let env = Environment::Sky(Sky::default());
    let fails = |frame: &Frame, settings: &Settings, name: &str| match ibl::render(
        &s.tracer,
        frame,
        &env,
        settings,
        |_| {},
    ) {
        Err(Error::InvalidParameter { name: n, message }) => {
            assert_eq!(n, name, "{message}")
        }
        other => panic!("{name}: {other:?}"),
    };
    assert!(ibl::render(&s.tracer, &frame, &env, &good, |_| {}).is_ok());
    for samples in [0, ibl::MAX_SAMPLES + 1] {
        fails(&frame, &Settings { samples, ..good }, "samples");
    }
    fails(
        &frame,
        &Settings {
            diagonal: f32::NAN,
            ..good
        },
        "diagonal",
    );
    fails(
        &frame,
        &Settings {
            surface_offset: -1.0,
            cone: None,
            ..good
        },
        "surface offset",
    );
    fails(&Frame { width: 9, ..frame }, &good, "rays");
    fails(
        &Frame {
            hits: &hits[1..],
            ..frame
        },
        &good,
        "hits",
    );
    fails(
        &Frame {
            albedo: &albedo[1..],
            ..frame
        },
        &good,
        "albedo",
    );
    let mut bad_albedo = albedo.clone();
    bad_albedo[3] = Vec3::NAN;
    fails(
        &Frame {
            albedo: &bad_albedo,
            ..frame
        },
        &good,
        "albedo",
    );
    // Offsets per pixel: one each, finite and non-negative.
    let mut offsets = vec![0.01f32; albedo.len()];
    fails(
        &Frame {
            offsets: Some(&offsets[1..]),
            ..frame
        },
        &good,
        "offsets",
    );
    offsets[2] = -1.0;
    fails(
        &Frame {
            offsets: Some(&offsets),
            ..frame
        },
        &good,
        "surface offset",
    );
}
