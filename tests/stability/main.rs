//! Numerical stability at the extremes (issue 6): watertightness, signed zeros and denormals,
//! grazing rays and tile seams, scale and offset, secondary rays, degenerate and adversarial
//! geometry, parameter extremes and invalid rays. Every test states its bound in its doc comment
//! and asserts it on the exact path and the RBVH path (where it applies), on the GPU ([`Tracer`])
//! and on the CPU reference. Scenes are small and rays few, so the suite runs in seconds.

#[path = "../common/mod.rs"]
mod common;

use std::process::Command;

use glam::{DVec3, Mat4, Vec3};
use rbvh::bvh::{BuildParams, Bvh, STACK_SIZE};
use rbvh::geom::{intersect_triangle, Hit, Ray, RayShear};
use rbvh::gpu::{Context, Query, Tracer};
use rbvh::lod::Cones;
use rbvh::rbvh::{Rbvh, RbvhParams, Refinement};
use rbvh::scene::Scene;
use rbvh::structure::Structure;
use rbvh::Error;
use std::sync::Arc;

mod degenerate_geometry;
mod invalid_rays;
mod parameter_extremes;
mod scale_and_offset;
mod seams;
mod secondary_rays;
mod tiny_components;
mod watertight;

// Helpers shared by the modules.

const PATHS: [&str; 2] = ["GPU", "CPU"];

/// The exact path's answers to `rays` (`exact` holds the exact BVH): GPU, then CPU.
fn exact_hits(ctx: &Context, exact: &Structure, rays: &[Ray], query: Query) -> [Vec<Hit>; 2] {
    assert!(exact.bvh().is_some(), "{}", exact.label());
    let gpu = Tracer::new(ctx, exact)
        .unwrap()
        .trace(rays, query)
        .unwrap()
        .hits;
    [
        gpu,
        exact
            .trace_cpu(rays, Cones::None, query == Query::Any)
            .unwrap(),
    ]
}

/// The RBVH path's answers to `rays`: GPU, then CPU.
fn rbvh_hits(ctx: &Context, r: &Arc<Rbvh>, rays: &[Ray], query: Query) -> [Vec<Hit>; 2] {
    let gpu = Tracer::new(ctx, &Structure::from(r.clone()))
        .unwrap()
        .trace(rays, query)
        .unwrap()
        .hits;
    [gpu, r.trace_cpu(rays, query == Query::Any)]
}

/// Preset `level` with every triangle sampled ([`common::sampled_preset`]): these tests hold
/// height fields to extremes, on meshes (planes, slabs, a few large triangles) that the presets
/// would trace exactly.
fn q(level: u32) -> RbvhParams {
    common::sampled_preset(level)
}

fn mesh(name: &str, positions: &[Vec3], triangles: &[[u32; 3]]) -> Scene {
    let mut s = Scene::new(name);
    s.push_object(name, positions, triangles);
    s
}

/// A hit record is well formed: a miss is exactly [`Hit::MISS`]; a hit has a finite, non-negative
/// `t` and a finite unit normal. Never a NaN anywhere.
fn assert_well_formed(what: &str, ray: &Ray, h: &Hit) {
    if h.is_hit() {
        assert!(
            h.t.is_finite() && h.t >= 0.0,
            "{what}: {ray:?} hit at t {}",
            h.t
        );
        assert!(
            h.normal().is_finite() && (h.normal().length() - 1.0).abs() < 1e-3,
            "{what}: {ray:?} normal {:?}",
            h.normal
        );
    } else {
        assert_eq!(*h, Hit::MISS, "{what}: {ray:?}");
    }
}

/// First intersection of the ray `o + t d` with the sphere (`c`, `r`), in f64, in units of `d`.
fn sphere_t(o: Vec3, d: Vec3, c: DVec3, r: f64) -> Option<f64> {
    let (o, d) = (o.as_dvec3(), d.as_dvec3());
    let oc = o - c;
    let a = d.dot(d);
    let b = oc.dot(d);
    let disc = b * b - a * (oc.dot(oc) - r * r);
    (disc >= 0.0).then(|| (-b - disc.sqrt()) / a)
}

/// A unit vector perpendicular to `n` (any).
fn tangent(n: Vec3) -> Vec3 {
    n.any_orthonormal_vector()
}

/// Hit/miss disagreements between two answers, and how many shared hits differ in `t` by more
/// than `rel`.
fn disagreements(a: &[Hit], b: &[Hit], rel: f32) -> (usize, usize) {
    let hit_miss = a
        .iter()
        .zip(b)
        .filter(|(x, y)| x.is_hit() != y.is_hit())
        .count();
    let t = a
        .iter()
        .zip(b)
        .filter(|(x, y)| x.is_hit() && y.is_hit() && (x.t - y.t).abs() > rel * y.t)
        .count();
    (hit_miss, t)
}
