//! Oracles before images: the built-in plane and sphere have known depth and normal, and both
//! tracers must reproduce them within the tessellation's own error.

mod common;

use glam::Vec3;
use rbvh::bvh::Bvh;
use rbvh::geom::{Hit, Ray};
use rbvh::gpu::{Query, Tracer};
use rbvh::scene::Scene;
use rbvh::structure::Structure;

fn trace_both(name: &str, rays: &[Ray]) -> [Vec<Hit>; 2] {
    let scene = Scene::builtin(name).unwrap();
    let bvh = Bvh::build(&scene).unwrap();
    let ctx = common::context();
    let cpu = bvh.trace_cpu(rays, false);
    let gpu = Tracer::new(&ctx, &Structure::from(bvh))
        .unwrap()
        .trace(rays, Query::Closest)
        .unwrap()
        .hits;
    [gpu, cpu]
}

#[test]
fn plane_depth_and_normal_are_exact() {
    let (point, normal, half_extent) = common::plane_oracle();
    let mut rng = common::Rng::new(3);
    let rays: Vec<Ray> = (0..4096)
        .map(|_| {
            let u = (rng.next_f32() * 2.0 - 1.0) * 0.95 * half_extent;
            let v = (rng.next_f32() * 2.0 - 1.0) * 0.95 * half_extent;
            let target = point + Vec3::new(u, 0.0, v);
            let mut dir = -rng.unit_vector();
            if dir.dot(normal) > -0.05 {
                dir = -normal;
            }
            let origin = target - dir * (1.0 + 4.0 * rng.next_f32());
            Ray::new(origin, dir, 0.0, f32::INFINITY)
        })
        .collect();
    for (which, hits) in ["GPU", "CPU"].iter().zip(trace_both("plane", &rays)) {
        for (r, h) in rays.iter().zip(&hits) {
            let exact = (point - r.origin()).dot(normal) / r.dir().dot(normal);
            assert!(h.is_hit(), "{which}: {r:?} missed the plane");
            assert!(
                (h.t - exact).abs() <= 1e-5 * exact,
                "{which}: t {} vs {exact}",
                h.t
            );
            assert!(
                h.normal().dot(normal).abs() > 1.0 - 1e-6,
                "{which}: normal {:?}",
                h.normal
            );
        }
    }
}

#[test]
fn sphere_depth_and_normal_within_tessellation_error() {
    let (center, radius, max_chord_error) = common::sphere_oracle();
    let mut rng = common::Rng::new(5);
    let rays: Vec<Ray> = (0..4096)
        .map(|_| {
            let origin = center + rng.unit_vector() * radius * (2.0 + 3.0 * rng.next_f32());
            let target = center + rng.unit_vector() * radius * 0.7 * rng.next_f32();
            Ray::new(origin, (target - origin).normalize(), 0.0, f32::INFINITY)
        })
        .collect();
    for (which, hits) in ["GPU", "CPU"].iter().zip(trace_both("sphere", &rays)) {
        for (r, h) in rays.iter().zip(&hits) {
            assert!(h.is_hit(), "{which}: {r:?} missed the sphere");
            let p = r.origin() + h.t * r.dir();
            let dist = (p - center).length();
            // An inscribed tessellation lies between radius - chord error and radius.
            assert!(
                dist >= radius - max_chord_error - 1e-5 && dist <= radius + 1e-5,
                "{which}: hit point at distance {dist} from the centre"
            );
            // The facets lie inside the true sphere, at most the chord error deep; along a ray that
            // meets the sphere at incidence cosine cos_i, that is at most chord / cos_i further.
            // Rays aim within 0.7 r of the centre, so cos_i >= sqrt(1 - 0.7²) > 0.7: no grazing.
            let oc = r.origin() - center;
            let b = oc.dot(r.dir());
            let t_true = -b - (b * b - (oc.length_squared() - radius * radius)).sqrt();
            let cos_i = (-(oc + t_true * r.dir()).normalize().dot(r.dir())).max(0.7);
            assert!(
                h.t >= t_true - 1e-5 && h.t <= t_true + max_chord_error / cos_i + 1e-5,
                "{which}: t {} vs true sphere {t_true}",
                h.t
            );
            // Outward normal, close to radial.
            assert!(
                h.normal().dot((p - center).normalize()) > 0.998,
                "{which}: normal {:?}",
                h.normal
            );
        }
    }
}
