//! Secondary rays from primary hits, as the benchmark, the image-based lighting and engines trace
//! them. The benchmark starts all of them at the *exact* BVH's primary hits, so that every method
//! under test answers the same questions and differences in their answers are differences in the
//! methods, not in the rays.
//!
//! * **primary** — one camera ray per pixel, closest hit.
//! * **ao** — ambient occlusion: a short cosine-distributed ray (`ao_radius` × the scene's
//!   bounding-box diagonal) per hit pixel, any hit.
//! * **shadow** — towards the light, any hit: along the light for a directional light (unbounded),
//!   or the segment to a point light (`tmax` = 1 with the unnormalised direction `light − origin`,
//!   so the light itself is excluded by the half-open `[tmin, tmax)`). Scenes without a light use
//!   [`DEFAULT_LIGHT`].
//! * **diffuse** — an unbounded cosine-distributed bounce per hit pixel, closest hit.
//!
//! Pixels whose exact primary ray missed have no secondary ray, so secondary batches have one ray
//! per exact hit, in pixel order.
//!
//! Directions are random but reproducible: each ray draws from its own SplitMix64 stream (Steele,
//! Lea & Flood, "Fast splittable pseudorandom number generators", OOPSLA 2014) seeded by a hash of
//! (seed, ray type, pixel index), so a ray does not depend on the thread count or on which other
//! rays exist. Cosine-distributed directions use Malley's method — uniform points on the unit disk
//! lifted to the hemisphere (Pharr, Jakob & Humphreys, *Physically Based Rendering*, 4th ed.,
//! §A.5.3).

use std::str::FromStr;

use glam::Vec3;
use rayon::prelude::*;
use serde::Serialize;

use crate::geom::{Hit, Ray};
use crate::gpu::Query;
use crate::random::{cosine_direction_from, mix64, SplitMix64, GOLDEN_GAMMA};
use crate::scene::Light;
use crate::{Error, Result};

/// What a batch of rays is for. The discriminants are fixed: they salt each ray's random stream,
/// so reordering the variants must not change the rays.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum RayType {
    /// One camera ray per pixel, closest hit.
    Primary = 0,
    /// Ambient occlusion: a cosine-distributed ray of length `ao_radius × diagonal` per exact
    /// hit, any hit.
    Ao = 1,
    /// Towards the scene's light (or [`DEFAULT_LIGHT`]) per exact hit, any hit.
    Shadow = 2,
    /// An unbounded cosine-distributed bounce per exact hit, closest hit.
    Diffuse = 3,
}

impl RayType {
    /// Every ray type, in the order the benchmark traces and reports them.
    pub const ALL: [RayType; 4] = [
        RayType::Primary,
        RayType::Ao,
        RayType::Shadow,
        RayType::Diffuse,
    ];

    /// The name used on the command line and in the records.
    pub fn name(self) -> &'static str {
        match self {
            RayType::Primary => "primary",
            RayType::Ao => "ao",
            RayType::Shadow => "shadow",
            RayType::Diffuse => "diffuse",
        }
    }

    /// Occlusion rays (ao, shadow) only ask whether anything is in the way.
    pub fn query(self) -> Query {
        match self {
            RayType::Primary | RayType::Diffuse => Query::Closest,
            RayType::Ao | RayType::Shadow => Query::Any,
        }
    }
}

impl FromStr for RayType {
    type Err = Error;

    fn from_str(s: &str) -> Result<RayType> {
        RayType::ALL
            .into_iter()
            .find(|t| t.name().eq_ignore_ascii_case(s.trim()))
            .ok_or_else(|| {
                Error::param(
                    "ray type",
                    format!("{s:?} is not one of primary, ao, shadow, diffuse"),
                )
            })
    }
}

/// The light of scenes that have none: a directional light from above, slightly to the left and
/// front of the framing camera's view (which looks from +x, +y, +z), so shadows fall visibly to the
/// side of objects. `direction` is the way the light travels.
pub const DEFAULT_LIGHT: Light = Light::Directional {
    direction: Vec3::new(0.4, -0.8, -0.45),
};

/// What secondary rays need besides the primary rays and their exact hits.
#[derive(Clone, Copy, Debug)]
pub struct Secondary {
    /// The scene's bounding-box diagonal: the unit of the origin offset and the AO length.
    pub diagonal: f32,
    /// Extra origin offset for approximate surfaces: the largest texel size of the RBVHs measured
    /// (0 with the exact BVH alone). See [`offset_origin`].
    pub surface_offset: f32,
    /// Target of the shadow rays.
    pub light: Light,
    /// AO ray length as a fraction of `diagonal`.
    pub ao_radius: f32,
    /// Seed of the direction streams; the same seed gives the same rays on any thread count.
    pub seed: u64,
}

/// The rays of `kind`: for primary, `primary` itself; otherwise one secondary ray per hit in
/// `exact` (the exact BVH's closest hits of `primary`), in order.
pub fn generate(kind: RayType, primary: &[Ray], exact: &[Hit], setup: &Secondary) -> Vec<Ray> {
    // How each kind aims from an offset origin on the visible side (`normal`): direction, tmax.
    type Aim<'a> = &'a (dyn Fn(Vec3, Vec3, &mut SplitMix64) -> (Vec3, f32) + Sync);
    let ao_length = setup.ao_radius * setup.diagonal;
    let aim: Aim = match kind {
        RayType::Primary => return primary.to_vec(),
        RayType::Ao => &|_, normal, rng| (cosine_direction_from(normal, rng), ao_length),
        RayType::Diffuse => &|_, normal, rng| (cosine_direction_from(normal, rng), f32::INFINITY),
        RayType::Shadow => &|origin, _, _| match setup.light {
            Light::Directional { direction } => (-direction.normalize_or_zero(), f32::INFINITY),
            Light::Point { position } => (position - origin, 1.0),
        },
    };
    primary
        .par_iter()
        .zip(exact)
        .enumerate()
        .filter(|(_, (_, hit))| hit.is_hit())
        .map(|(index, (ray, hit))| {
            let point = ray.origin() + hit.t * ray.dir();
            let normal = facing_normal(ray, hit);
            let origin = offset_origin(point, normal, setup.diagonal, setup.surface_offset);
            let (dir, tmax) = aim(origin, normal, &mut ray_rng(setup.seed, kind, index));
            Ray::new(origin, dir, 0.0, tmax)
        })
        .collect()
}

/// The unit geometric normal of `hit`, flipped to the side `ray` arrived from: the visible side.
pub fn facing_normal(ray: &Ray, hit: &Hit) -> Vec3 {
    let n = hit.normal().normalize_or_zero();
    if n.dot(ray.dir()) > 0.0 {
        -n
    } else {
        n
    }
}

/// Moves a hit `point` off its surface along `normal` (the visible side), so that a secondary ray
/// does not re-hit the triangle it starts on through rounding of `t` ("self-intersection").
///
/// The offset is `1e-4 × diagonal + 4 ulp(max |point_i|) + surface_offset`. The first term is
/// relative to the scene's size, like the rounding error of the hit point for geometry at that
/// scale; the second takes over when the scene sits far from the origin, where the first could be
/// smaller than the spacing of representable coordinates and the offset would round away; the
/// third is one texel of the coarsest RBVH measured, whose reconstructed surface may lie a
/// fraction of a texel off the exact one (the RBVH's own acne scale). AO and diffuse rays
/// leave into the hemisphere of `normal`, away from the surface; a shadow ray towards a light
/// behind the surface crosses it and is, rightly, occluded.
pub fn offset_origin(point: Vec3, normal: Vec3, diagonal: f32, surface_offset: f32) -> Vec3 {
    let epsilon =
        1.0e-4 * diagonal + 4.0 * f32::EPSILON * point.abs().max_element() + surface_offset;
    point + epsilon * normal
}

/// The stream of one ray: a hash of (seed, kind, index).
fn ray_rng(seed: u64, kind: RayType, index: usize) -> SplitMix64 {
    let salt = (kind as u64 + 1).wrapping_mul(GOLDEN_GAMMA);
    SplitMix64::new(mix64(seed ^ mix64(salt ^ index as u64)))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hit(t: f32, normal: Vec3) -> Hit {
        Hit {
            t,
            normal: normal.to_array(),
            id: 0,
            ..Hit::MISS
        }
    }

    #[test]
    fn names_round_trip() {
        for t in RayType::ALL {
            assert_eq!(t.name().parse::<RayType>().unwrap(), t);
        }
        assert!("AO".parse::<RayType>().is_ok());
        assert!("bounce".parse::<RayType>().is_err());
    }

    #[test]
    fn secondary_rays_are_deterministic_and_skip_misses() {
        let primary = vec![Ray::new(Vec3::new(0.0, 0.0, 5.0), Vec3::NEG_Z, 0.0, f32::INFINITY); 3];
        let exact = vec![hit(5.0, Vec3::Z), Hit::MISS, hit(5.0, Vec3::NEG_Z)];
        let setup = Secondary {
            diagonal: 2.0,
            surface_offset: 0.0,
            light: Light::Point {
                position: Vec3::new(0.0, 3.0, 0.0),
            },
            ao_radius: 0.05,
            seed: 1,
        };
        for kind in [RayType::Ao, RayType::Shadow, RayType::Diffuse] {
            let rays = generate(kind, &primary, &exact, &setup);
            assert_eq!(rays, generate(kind, &primary, &exact, &setup));
            assert_eq!(rays.len(), 2);
            for r in &rays {
                // Both normals (one wound away from the ray) face +z after flipping.
                assert!((r.origin().z - 2.0e-4).abs() < 1e-6, "{:?}", r.origin());
            }
        }
        let shadow = generate(RayType::Shadow, &primary, &exact, &setup);
        assert_eq!(shadow[0].tmax, 1.0);
        assert!((shadow[0].origin() + shadow[0].dir() - Vec3::new(0.0, 3.0, 0.0)).length() < 1e-6);
        let ao = generate(RayType::Ao, &primary, &exact, &setup);
        assert!((ao[0].tmax - 0.1).abs() < 1e-7);
    }

    #[test]
    fn the_offset_grows_with_distance_from_the_origin() {
        let near = offset_origin(Vec3::ZERO, Vec3::Y, 1.0, 0.0);
        assert!((near.y - 1.0e-4).abs() < 1e-9);
        let far_point = Vec3::new(1.0e6, 0.0, 0.0);
        let far = offset_origin(far_point, Vec3::X, 1.0, 0.0);
        assert!(far.x > far_point.x, "the offset rounded away");
    }
}
