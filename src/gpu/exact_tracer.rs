//! Traces rays through the exact BVH with `glsl/trace_exact.comp`.

use bytemuck::{Pod, Zeroable};

use super::{shaders, Buffer, ComputePipeline, Context, Timing};
use crate::bvh::{Bvh, STACK_SIZE};
use crate::geom::{Hit, Ray};
use crate::{Error, Result};

/// What a ray asks for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Query {
    /// The nearest hit in `[tmin, tmax)`.
    Closest,
    /// Any hit in `[tmin, tmax)` (occlusion): traversal stops at the first one found.
    Any,
}

/// Hits of a batch, with the GPU time of the trace dispatches alone (uploads excluded).
#[derive(Clone, Debug)]
pub struct Traced {
    pub hits: Vec<Hit>,
    /// Per ray: nodes visited + triangles tested, when asked for.
    pub steps: Option<Vec<u32>>,
    /// Summed over batches; see [`Timing`].
    pub timing: Timing,
}

/// Push constants of `trace_exact.comp` (16 bytes).
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct Params {
    ray_offset: u32,
    ray_count: u32,
    node_count: u32,
    flags: u32,
}

const FLAG_ANY_HIT: u32 = 1;
const FLAG_STEPS: u32 = 2;

/// The exact BVH uploaded to the device, with its pipeline.
pub struct ExactTracer {
    ctx: Context,
    pipeline: ComputePipeline,
    nodes: Buffer,
    triangles: Buffer,
    node_count: u32,
}

impl ExactTracer {
    /// Uploads `bvh` (nodes and triangles, each checked against `maxStorageBufferRange`).
    pub fn new(ctx: &Context, bvh: &Bvh) -> Result<Self> {
        if bvh.depth > STACK_SIZE {
            return Err(Error::param(
                "bvh",
                format!("depth {} exceeds the traversal stack", bvh.depth),
            ));
        }
        let hint = "the scene is too large for one storage buffer on this device";
        ctx.check_storage_range("BVH nodes", bvh.tree_bytes(), hint)?;
        ctx.check_storage_range("BVH triangles", bvh.triangle_bytes(), hint)?;
        Ok(ExactTracer {
            ctx: ctx.clone(),
            pipeline: ComputePipeline::new(ctx, "trace_exact", shaders::TRACE_EXACT, 6, 16)?,
            nodes: ctx.upload_storage("BVH nodes", &bvh.nodes)?,
            triangles: ctx.upload_storage("BVH triangles", &bvh.triangles)?,
            node_count: bvh.nodes.len() as u32,
        })
    }

    /// Bytes on the device: nodes and triangles.
    pub fn device_bytes(&self) -> u64 {
        self.nodes.size() + self.triangles.size()
    }

    pub fn trace(&self, rays: &[Ray], query: Query) -> Result<Traced> {
        self.trace_with(rays, query, false)
    }

    /// Traces `rays`, in batches that fit `maxStorageBufferRange`; `steps` also returns the per-ray
    /// traversal cost. Fails with [`Error::StackOverflow`] if any ray overflowed its stack.
    pub fn trace_with(&self, rays: &[Ray], query: Query, steps: bool) -> Result<Traced> {
        let ray_size = std::mem::size_of::<Ray>() as u64;
        let batch =
            (self.ctx.limits().max_storage_buffer_range / ray_size).clamp(1, 1 << 22) as usize;
        let mut out = Traced {
            hits: Vec::with_capacity(rays.len()),
            steps: steps.then(|| Vec::with_capacity(rays.len())),
            timing: Timing::default(),
        };
        for chunk in rays.chunks(batch) {
            let (hits, chunk_steps, timing) = self.trace_batch(chunk, query, steps)?;
            out.hits.extend(hits);
            if let (Some(all), Some(s)) = (out.steps.as_mut(), chunk_steps) {
                all.extend(s);
            }
            out.timing.wall_ms += timing.wall_ms;
            out.timing.gpu_ms = match (out.timing.gpu_ms, timing.gpu_ms) {
                (Some(a), Some(b)) => Some(a + b),
                (None, b) if out.hits.len() == chunk.len() => b,
                _ => None,
            };
        }
        Ok(out)
    }

    fn trace_batch(
        &self,
        rays: &[Ray],
        query: Query,
        steps: bool,
    ) -> Result<(Vec<Hit>, Option<Vec<u32>>, Timing)> {
        let n = rays.len() as u32;
        let ray_buf = self.ctx.upload_storage("rays", rays)?;
        let mut hit_buf = self.ctx.zeroed_storage(
            "hits",
            rays.len() as u64 * std::mem::size_of::<Hit>() as u64,
        )?;
        let mut status = self.ctx.zeroed_storage("trace status", 4)?;
        let mut steps_buf = self.ctx.zeroed_storage(
            "per-ray steps",
            if steps { rays.len() as u64 * 4 } else { 4 },
        )?;
        let flags = match query {
            Query::Closest => 0,
            Query::Any => FLAG_ANY_HIT,
        } | if steps { FLAG_STEPS } else { 0 };
        let timing = self.pipeline.run(
            &[
                &self.nodes,
                &self.triangles,
                &ray_buf,
                &hit_buf,
                &status,
                &steps_buf,
            ],
            n,
            |first| {
                bytemuck::bytes_of(&Params {
                    ray_offset: first,
                    ray_count: n,
                    node_count: self.node_count,
                    flags,
                })
                .to_vec()
            },
        )?;
        let overflow = self.ctx.read::<u32>(&mut status)?[0];
        if overflow > 0 {
            return Err(Error::StackOverflow {
                resource: "trace_exact".into(),
                depth: STACK_SIZE,
                rays: overflow,
            });
        }
        let mut hits: Vec<Hit> = self.ctx.read(&mut hit_buf)?;
        hits.truncate(rays.len());
        let steps = if steps {
            let mut s: Vec<u32> = self.ctx.read(&mut steps_buf)?;
            s.truncate(rays.len());
            Some(s)
        } else {
            None
        };
        Ok((hits, steps, timing))
    }
}
