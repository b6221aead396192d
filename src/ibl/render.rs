//! The progressive IBL integrator: Lambertian surfaces lit by an [`Environment`], with the
//! visibility of every sample ray answered by a [`Tracer`] — the exact BVH or an RBVH, which is
//! where an approximate structure pays off most: occlusion rays ask only *whether* something is
//! in the way, so a surface a fraction of a texel off changes almost nothing.
//!
//! For a Lambertian surface of albedo ρ the outgoing radiance is
//! `L_o = ρ/π ∫_Ω L_env(ω) V(ω) cos θ dω`. Drawing ω with density `cos θ / π` (see
//! [`super::sampling`]) turns each sample's estimate into `ρ · L_env(ω) · V(ω)`: the cosine and
//! the π cancel (Pharr, Jakob & Humphreys, *Physically Based Rendering*, 4th ed., §13.10 on
//! cosine-weighted importance sampling). A pixel is the mean over its samples. Without
//! occlusion under a constant environment every sample is exact, which is the white-furnace test.

use std::time::Instant;

use glam::{DVec3, Vec3};
use rayon::prelude::*;

use super::environment::Environment;
use super::sampling::sample_direction;
use crate::geom::{Hit, Ray};
use crate::gpu::{Query, Timing, Tracer};
use crate::lod::{Cones, RayCone};
use crate::output::Image;
use crate::rays::{facing_normal, offset_origin};
use crate::{Error, Result};

/// Most samples per pixel: far past convergence for any picture, and a bound on how long a
/// render may be asked to run (the per-pixel sums are `f64`, so precision does not bound it).
pub const MAX_SAMPLES: u32 = 1 << 16;

/// The picture to light: one primary ray per pixel (row-major, top row first), its closest hit
/// through the structure being rendered, and the surface's albedo at that pixel (ignored where
/// the ray missed; `rbvh render` passes the surfaces' base colour times [`super::GREY`]).
#[derive(Clone, Copy, Debug)]
pub struct Frame<'a> {
    /// Image width in pixels; at least 1.
    pub width: u32,
    /// Image height in pixels; at least 1.
    pub height: u32,
    /// The primary rays, `width × height` of them; a missed one looks up the environment.
    pub rays: &'a [Ray],
    /// Their closest hits through the structure being rendered, one per ray.
    pub hits: &'a [Hit],
    /// Linear RGB albedo ρ per pixel, finite and non-negative (1 reflects all light).
    pub albedo: &'a [Vec3],
    /// Per pixel, the extra origin offset of its visibility rays, replacing
    /// [`Settings::surface_offset`] where given: a two-level RBVH's is each hit instance's texel
    /// ([`crate::structure::Structure::surface_offset`]). Finite and non-negative.
    pub offsets: Option<&'a [f32]>,
}

/// How to sample.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Settings {
    /// Visibility rays per hit pixel, one per pass: `1..=MAX_SAMPLES`.
    pub samples: u32,
    /// Selects the random directions; the same seed gives the same image.
    pub seed: u64,
    /// The scene's bounding-box diagonal: the scale of the origin offset (see
    /// [`crate::rays::offset_origin`]).
    pub diagonal: f32,
    /// Extra origin offset for an approximate surface: the RBVH's texel size, 0 for the exact
    /// BVH. Without it an RBVH surface, which may lie a fraction of a texel off the exact one,
    /// would shadow itself.
    pub surface_offset: f32,
    /// The footprint of the primary rays (their pixel's cone), read only by a tracer with levels
    /// of detail ([`crate::structure::Structure::RbvhLod`]), which needs it. Each visibility ray
    /// then gets a cone
    /// from its origin with this spread and no width, so that the surface a ray leaves is never
    /// coarsened under it. The cone is not widened by the sampling lobe as ray cones for glossy
    /// bounces are (Akenine-Möller et al. 2019): solid coarse columns then swallow concave
    /// neighbourhoods, and the default scene's FLIP against the exact render rose from 0.006 to
    /// 0.045.
    pub cone: Option<RayCone>,
}

/// What the observer of a render hears after each pass.
#[derive(Clone, Copy, Debug)]
pub struct Pass {
    /// Passes (samples per pixel) done so far, `1..=total`.
    pub done: u32,
    /// Passes the render will make: [`Settings::samples`].
    pub total: u32,
    /// Visibility rays traced in this pass: one per hit pixel.
    pub rays: usize,
    /// This pass's trace.
    pub timing: Timing,
}

/// A finished render.
#[derive(Clone, Debug)]
pub struct Rendered {
    /// Linear radiance per pixel: the lit surface, or the environment where the primary ray
    /// missed.
    pub image: Image,
    /// Visibility rays traced in all.
    pub rays: u64,
    /// The traces summed over the passes (GPU time only if every pass had timestamps).
    pub timing: Timing,
    /// Host time of the whole render: ray generation, traces and accumulation.
    pub wall_ms: f64,
}

/// Renders `frame` under `env` with `settings.samples` passes of one cosine-distributed
/// visibility ray per hit pixel, traced through `tracer` as any-hit queries; `on_pass` is called
/// after each pass (for progress). The result depends only on the inputs and the seed.
///
/// Each ray starts at the primary hit point moved off the surface along the normal facing the
/// camera ([`crate::rays::offset_origin`]) and is unbounded: whatever it meets occludes
/// the environment. Fails with [`Error::InvalidParameter`] on a sample count outside
/// `1..=MAX_SAMPLES`, a non-finite or non-positive diagonal, a negative or non-finite offset,
/// per-pixel inputs of the wrong length or a non-finite or negative albedo, and with the
/// tracer's errors.
pub fn render(
    tracer: &Tracer,
    frame: &Frame,
    env: &Environment,
    settings: &Settings,
    on_pass: impl FnMut(&Pass),
) -> Result<Rendered> {
    let mut rendered = render_side_by_side(&[(tracer, frame, settings)], env, on_pass)?;
    Ok(rendered.remove(0))
}

/// [`render`] of several structures at once (the exact BVH and an RBVH, say), pass by pass: each
/// pass traces every job's visibility rays, starting with a different job each pass, so that
/// their trace times are taken under the same conditions (a clock that changes, another process)
/// rather than one render after the other, and a speed ratio of the two is a side-by-side one.
/// Each job's image is the one [`render`] makes of it alone. The jobs take the same number of
/// samples; `on_pass` hears each pass with every job's rays and trace times summed, and each
/// render's `wall_ms` is the host time of them all.
pub fn render_side_by_side(
    jobs: &[(&Tracer, &Frame, &Settings)],
    env: &Environment,
    mut on_pass: impl FnMut(&Pass),
) -> Result<Vec<Rendered>> {
    let start = Instant::now();
    let Some(samples) = jobs.first().map(|(_, _, s)| s.samples) else {
        return Ok(Vec::new());
    };
    if jobs.iter().any(|(_, _, s)| s.samples != samples) {
        return Err(Error::param(
            "samples",
            "renders side by side take the same number of samples".to_string(),
        ));
    }
    let mut states = jobs
        .iter()
        .map(|(_, frame, settings)| Accumulation::new(frame, settings))
        .collect::<Result<Vec<_>>>()?;
    for sample in 0..samples {
        let mut pass = Pass {
            done: sample + 1,
            total: samples,
            rays: 0,
            timing: Timing {
                gpu_ms: Some(0.0),
                wall_ms: 0.0,
            },
        };
        for k in 0..jobs.len() {
            let job = (k + sample as usize) % jobs.len();
            let (tracer, _, settings) = jobs[job];
            let timing = states[job].pass(tracer, env, settings, sample)?;
            pass.rays += states[job].starts.len();
            pass.timing = add(pass.timing, timing);
        }
        on_pass(&pass);
    }
    let wall_ms = start.elapsed().as_secs_f64() * 1e3;
    Ok(states
        .into_iter()
        .zip(jobs)
        .map(|(state, (_, frame, settings))| state.finish(frame, env, settings, wall_ms))
        .collect())
}

/// Two traces' times summed (GPU time only if both had timestamps).
fn add(a: Timing, b: Timing) -> Timing {
    Timing {
        wall_ms: a.wall_ms + b.wall_ms,
        gpu_ms: a.gpu_ms.zip(b.gpu_ms).map(|(a, b)| a + b),
    }
}

/// One render in progress: the fixed part of every visibility ray of a hit pixel (its pixel
/// index, origin and normal), each pixel's sum of unoccluded radiance, and the traces' times.
struct Accumulation {
    starts: Vec<(u64, Vec3, Vec3)>,
    /// Every visibility ray's footprint.
    cone: Option<RayCone>,
    sums: Vec<DVec3>,
    timing: Timing,
}

impl Accumulation {
    fn new(frame: &Frame, settings: &Settings) -> Result<Accumulation> {
        check(frame, settings)?;
        let starts: Vec<(u64, Vec3, Vec3)> = frame
            .rays
            .par_iter()
            .zip(frame.hits)
            .enumerate()
            .filter(|(_, (_, hit))| hit.is_hit())
            .map(|(pixel, (ray, hit))| {
                let point = ray.origin() + hit.t * ray.dir();
                let mut normal = facing_normal(ray, hit);
                if normal == Vec3::ZERO {
                    // A degenerate normal: face the camera, so the pixel is still lit sensibly.
                    normal = -ray.dir().normalize_or_zero();
                }
                let offset = frame
                    .offsets
                    .map_or(settings.surface_offset, |offsets| offsets[pixel]);
                let origin = offset_origin(point, normal, settings.diagonal, offset);
                (pixel as u64, origin, normal)
            })
            .collect();
        let cone = settings.cone.map(|c| RayCone {
            width: 0.0,
            spread: c.spread,
        });
        Ok(Accumulation {
            sums: vec![DVec3::ZERO; starts.len()],
            starts,
            cone,
            timing: Timing {
                gpu_ms: Some(0.0),
                wall_ms: 0.0,
            },
        })
    }

    /// Traces pass `sample`'s visibility rays and adds what they see; returns the trace's time.
    fn pass(
        &mut self,
        tracer: &Tracer,
        env: &Environment,
        settings: &Settings,
        sample: u32,
    ) -> Result<Timing> {
        let rays: Vec<Ray> = self
            .starts
            .par_iter()
            .map(|&(pixel, origin, normal)| {
                let dir = sample_direction(normal, settings.seed, pixel, sample);
                Ray::new(origin, dir, 0.0, f32::INFINITY)
            })
            .collect();
        let cones = self.cone.map_or(Cones::None, Cones::Same);
        let traced = tracer.trace_with(&rays, cones, Query::Any, false)?;
        self.sums
            .par_iter_mut()
            .zip(&rays)
            .zip(&traced.hits)
            .filter(|(_, hit)| !hit.is_hit())
            .for_each(|((sum, ray), _)| *sum += env.radiance(ray.dir()).as_dvec3());
        self.timing = add(self.timing, traced.timing);
        Ok(traced.timing)
    }

    fn finish(
        self,
        frame: &Frame,
        env: &Environment,
        settings: &Settings,
        wall_ms: f64,
    ) -> Rendered {
        let mut pixels: Vec<Vec3> = frame
            .rays
            .par_iter()
            .map(|ray| env.radiance(ray.dir()))
            .collect();
        let samples = f64::from(settings.samples);
        for (&(pixel, _, _), sum) in self.starts.iter().zip(&self.sums) {
            let pixel = pixel as usize;
            pixels[pixel] = frame.albedo[pixel] * (*sum / samples).as_vec3();
        }
        Rendered {
            image: Image {
                width: frame.width,
                height: frame.height,
                pixels,
            },
            rays: self.starts.len() as u64 * u64::from(settings.samples),
            timing: self.timing,
            wall_ms,
        }
    }
}

/// The parameter checks of [`render`].
fn check(frame: &Frame, settings: &Settings) -> Result<()> {
    if !(1..=MAX_SAMPLES).contains(&settings.samples) {
        return Err(Error::param(
            "samples",
            format!(
                "{} samples per pixel: use 1..={MAX_SAMPLES}",
                settings.samples
            ),
        ));
    }
    if !(settings.diagonal.is_finite() && settings.diagonal > 0.0) {
        return Err(Error::param(
            "diagonal",
            format!("{} is not a positive finite scene size", settings.diagonal),
        ));
    }
    if !(settings.surface_offset.is_finite() && settings.surface_offset >= 0.0) {
        return Err(Error::param(
            "surface offset",
            format!(
                "{} is not a non-negative finite distance",
                settings.surface_offset
            ),
        ));
    }
    let pixels = u64::from(frame.width) * u64::from(frame.height);
    if pixels == 0 {
        return Err(Error::param(
            "image size",
            format!(
                "{}×{} is empty; images need at least one pixel",
                frame.width, frame.height
            ),
        ));
    }
    if let Some(offsets) = frame.offsets {
        if let Some((k, x)) = offsets
            .iter()
            .enumerate()
            .find(|(_, x)| !(x.is_finite() && **x >= 0.0))
        {
            return Err(Error::param(
                "surface offset",
                format!("pixel {k}'s offset {x} is not a non-negative finite distance"),
            ));
        }
    }
    let offsets = frame.offsets.map(|o| ("offsets", o.len()));
    for (what, len) in [
        ("rays", frame.rays.len()),
        ("hits", frame.hits.len()),
        ("albedo", frame.albedo.len()),
    ]
    .into_iter()
    .chain(offsets)
    {
        if len as u64 != pixels {
            return Err(Error::param(
                what,
                format!(
                    "{len} {what} for a {}×{} image, which has {pixels} pixels",
                    frame.width, frame.height
                ),
            ));
        }
    }
    if let Some(i) = frame
        .albedo
        .iter()
        .position(|a| !a.is_finite() || a.min_element() < 0.0)
    {
        return Err(Error::param(
            "albedo",
            format!(
                "pixel {i} has albedo {}: it must be finite and non-negative",
                frame.albedo[i]
            ),
        ));
    }
    Ok(())
}
