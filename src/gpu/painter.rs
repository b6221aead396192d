//! Painting on the device (`glsl/paint.comp`): the RBVH's atlas and colour channel live in
//! storage buffers; each pass dispatches, per leaf that some brush reaches
//! ([`candidate_leaves`]), one invocation per texel of its tile. The rule is that of
//! [`crate::surface`]'s CPU reference (`Rbvh::paint_cpu`), bit for bit.

use bytemuck::{Pod, Zeroable};

use super::{shaders, Buffer, ComputePipeline, Context, Timing};
use crate::rbvh::GpuHeightfield;
use crate::rbvh::{Rbvh, Texel};
use crate::surface::{blank_colours, candidate_leaves, Brush};
use crate::{Error, Result};

/// Brushes per pass: the shader loops over them per texel, and lavapipe ends a shader loop after
/// 65535 iterations; more brushes are painted in further passes, in order.
pub const MAX_BRUSHES_PER_PASS: usize = 4096;

/// Push constants of `glsl/paint.comp` (80 bytes): the leaf's sample grid
/// ([`crate::rbvh::layout::SampleGrid`]) and where its tile lies.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct PaintParams {
    pub origin: [f32; 3],
    pub atlas_base: u32,
    pub step_u: [f32; 3],
    pub res_u: u32,
    pub step_v: [f32; 3],
    pub res_v: u32,
    pub axis_w: [f32; 3],
    pub h_scale: f32,
    pub texel_offset: u32,
    pub brush_count: u32,
    pub atlas_pitch: u32,
    pub atlas_len: u32,
}
const _: () = assert!(std::mem::size_of::<PaintParams>() == 80);

/// What one [`Painter::paint`] call did.
#[derive(Clone, Copy, Debug, Default)]
pub struct PaintStats {
    /// Leaves dispatched (those some brush reaches).
    pub leaves: u32,
    /// Texels those leaves hold (invocations that did work).
    pub texels: u64,
    /// Summed over passes.
    pub timing: Timing,
}

/// An RBVH's atlas and colour channel on the device, ready to paint.
pub struct Painter {
    pipeline: ComputePipeline,
    leaves: Vec<GpuHeightfield>,
    atlas: Buffer,
    colours: Buffer,
    pitch: u32,
    atlas_len: u32,
}

impl Painter {
    /// Uploads the atlas and the colour channel of `rbvh` (white on every surface texel when it
    /// has none, as [`Rbvh::colour_channel`] creates it).
    pub fn new(ctx: &Context, rbvh: &Rbvh) -> Result<Painter> {
        if let Some(c) = rbvh
            .colours
            .as_ref()
            .filter(|c| c.len() != rbvh.atlas.texels.len())
        {
            return Err(Error::param(
                "rbvh colours",
                format!(
                    "{} colour words for {} atlas texels: the channel must match the atlas",
                    c.len(),
                    rbvh.atlas.texels.len()
                ),
            ));
        }
        let blank;
        let colours = match &rbvh.colours {
            Some(c) => c.as_slice(),
            None => {
                blank = blank_colours(&rbvh.atlas.texels);
                blank.as_slice()
            }
        };
        // A buffer cannot be empty; an empty atlas has no leaf to paint anyway.
        let atlas: &[Texel] = if rbvh.atlas.texels.is_empty() {
            &[Texel::HOLE]
        } else {
            &rbvh.atlas.texels
        };
        let colours = if colours.is_empty() { &[0] } else { colours };
        Ok(Painter {
            pipeline: ComputePipeline::new(
                ctx,
                "paint",
                shaders::PAINT,
                3,
                std::mem::size_of::<PaintParams>() as u32,
            )?,
            leaves: rbvh.leaves.clone(),
            atlas: ctx.upload_storage("RBVH atlas (painting)", atlas)?,
            colours: ctx.upload_storage("RBVH colours", colours)?,
            pitch: rbvh.atlas.pitch,
            atlas_len: rbvh.atlas.texels.len() as u32,
        })
    }

    /// Paints `brushes` (in order: the last brush covering a texel wins).
    pub fn paint(&mut self, brushes: &[Brush]) -> Result<PaintStats> {
        let ctx = self.atlas.context().clone();
        let mut stats = PaintStats::default();
        for batch in brushes.chunks(MAX_BRUSHES_PER_PASS) {
            let leaves = candidate_leaves(&self.leaves, batch);
            if leaves.is_empty() {
                continue;
            }
            let brush_buf = ctx.upload_storage("paint brushes", batch)?;
            let set = self.pipeline.descriptor_set(&[
                (self.atlas.raw(), 0),
                (brush_buf.raw(), 0),
                (self.colours.raw(), 0),
            ])?;
            let timing = ctx.submit("paint", |device, cmd| {
                for &k in &leaves {
                    let leaf = &self.leaves[k as usize];
                    let grid = leaf.grid();
                    let params = PaintParams {
                        origin: grid.origin.to_array(),
                        atlas_base: leaf.atlas_base,
                        step_u: grid.step_u.to_array(),
                        res_u: leaf.res_u,
                        step_v: grid.step_v.to_array(),
                        res_v: leaf.res_v,
                        axis_w: grid.axis_w.to_array(),
                        h_scale: grid.h_scale,
                        texel_offset: 0,
                        brush_count: batch.len() as u32,
                        atlas_pitch: self.pitch,
                        atlas_len: self.atlas_len,
                    };
                    let texels = leaf.res_u.saturating_mul(leaf.res_v);
                    self.pipeline.record(device, cmd, &set, texels, |first| {
                        bytemuck::bytes_of(&PaintParams {
                            texel_offset: first,
                            ..params
                        })
                        .to_vec()
                    });
                }
            })?;
            stats.leaves += leaves.len() as u32;
            stats.texels += leaves
                .iter()
                .map(|&k| {
                    let l = &self.leaves[k as usize];
                    u64::from(l.res_u) * u64::from(l.res_v)
                })
                .sum::<u64>();
            stats.timing.wall_ms += timing.wall_ms;
            stats.timing.gpu_ms = match (stats.timing.gpu_ms, timing.gpu_ms) {
                (Some(a), Some(b)) => Some(a + b),
                (None, b) => b,
                (a, None) => a,
            };
        }
        Ok(stats)
    }

    /// Downloads the colour channel (one word per atlas texel, [`Rbvh::colours`]'s layout).
    pub fn colours(&mut self) -> Result<Vec<u32>> {
        let ctx = self.colours.context().clone();
        let mut colours: Vec<u32> = ctx.read(&mut self.colours)?;
        colours.truncate(self.atlas_len as usize);
        Ok(colours)
    }
}
