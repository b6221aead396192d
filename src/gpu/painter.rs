//! Painting on the device (`glsl/paint.comp`): the RBVH's atlas and colour channel live in
//! storage buffers, bound or — when one is over `maxStorageBufferRange` — read through their device
//! addresses (`glsl/paint_bda.comp`, [`Reach`]); each pass dispatches, per leaf that some brush reaches
//! ([`candidate_leaves`]), one invocation per texel of its tile. The rule is that of
//! [`crate::surface`]'s CPU reference (`Rbvh::paint_cpu`), bit for bit.

use std::sync::Arc;

use bytemuck::{Pod, Zeroable};

use ash::vk;

use super::bindings;
use super::parts::atlas_sizes;
use super::pipeline::DescriptorSet;
use super::{shaders, Buffer, BufferView, ComputePipeline, Context, Reach, Timing, Tracer};
use crate::rbvh::GpuHeightfield;
use crate::rbvh::{Rbvh, Texel, TexelFormat};
use crate::surface::{blank_colours, candidate_leaves, Brush};
use crate::{Error, Result};

/// Brushes per pass: the shader loops over them per texel, and lavapipe ends a shader loop after
/// 65535 iterations; more brushes are painted in further passes, in order.
pub const MAX_BRUSHES_PER_PASS: usize = 4096;

/// Push constants of `glsl/paint_main.glsl` (112 bytes): the leaf's sample grid
/// ([`crate::rbvh::layout::SampleGrid`]), where its tile lies, and the device addresses of the
/// atlas and the colours (zero where they are bound).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct PaintParams {
    /// GLSL `pc.origin`: the leaf frame's world-space origin
    /// ([`SampleGrid::origin`](crate::rbvh::layout::SampleGrid::origin)).
    pub origin: [f32; 3],
    /// GLSL `atlas_base`: atlas index of the tile's texel (0, 0).
    pub atlas_base: u32,
    /// GLSL `step_u`: world vector of one texel step along `u`.
    pub step_u: [f32; 3],
    /// GLSL `res_u`: texels of the tile along `u` (also the row length of the invocation index).
    pub res_u: u32,
    /// GLSL `step_v`: world vector of one texel step along `v`.
    pub step_v: [f32; 3],
    /// GLSL `res_v`: texels of the tile along `v`.
    pub res_v: u32,
    /// GLSL `axis_w`: unit world-space height axis of the leaf.
    pub axis_w: [f32; 3],
    /// GLSL `h_scale`: world height per height-code quantum.
    pub h_scale: f32,
    /// GLSL `texel_offset`: tile texel (`j · res_u + i`) of this dispatch's first invocation;
    /// dispatches are split at `maxComputeWorkGroupCount`.
    pub texel_offset: u32,
    /// GLSL `brush_count`: brushes in the bound brush buffer, at most [`MAX_BRUSHES_PER_PASS`].
    pub brush_count: u32,
    /// GLSL `atlas_pitch`: texels per atlas row ([`Atlas::pitch`](crate::rbvh::Atlas::pitch)).
    pub atlas_pitch: u32,
    /// GLSL `atlas_len`: texels in the atlas; reads at or beyond it are skipped.
    pub atlas_len: u32,
    /// GLSL `atlas_wide_len`: texels before the atlas's bands of packed heights
    /// ([`Atlas::wide_len`](crate::rbvh::Atlas::wide_len)).
    pub atlas_wide_len: u32,
    /// GLSL `atlas_end12`: texels before the end of the atlas's 12-bit band
    /// ([`Atlas::bands`](crate::rbvh::Atlas::bands)).
    pub atlas_end12: u32,
    /// GLSL `atlas_end10`: texels before the end of the atlas's 10-bit band.
    pub atlas_end10: u32,
    /// GLSL `reserved`: zero, so that the addresses are 8-byte aligned.
    pub reserved: u32,
    /// GLSL `atlas_address` (`uvec2`, low word first): the atlas's device address; 0 when bound.
    pub atlas_address: u64,
    /// GLSL `colours_address` (`uvec2`, low word first): the colour channel's device address; 0
    /// when bound.
    pub colours_address: u64,
}
const _: () = assert!(std::mem::size_of::<PaintParams>() == 112);

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

/// What [`Painter::record`] recorded and the device still reads: keep it until the command buffer
/// has executed.
pub struct PaintRecording {
    _set: DescriptorSet,
    _brushes: Buffer,
    _staging: Option<Buffer>,
}

/// The atlas and colour channel of `rbvh` as the painter uploads them: the atlas as the trace
/// shaders read it ([`Rbvh::atlas_words`]), the channel checked against the atlas (or white on
/// every surface texel when there is none, as [`Rbvh::colour_channel`] creates it), and neither
/// empty (a buffer cannot be; an empty atlas has no leaf to paint anyway).
fn channel_data(rbvh: &Rbvh) -> Result<(Vec<u32>, Vec<u32>)> {
    no_height_only(rbvh)?;
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
    let mut colours = match &rbvh.colours {
        Some(c) => c.clone(),
        None => blank_colours(&rbvh.atlas.texels),
    };
    let mut atlas = rbvh.atlas_words();
    if atlas.is_empty() {
        atlas.push(Texel::HOLE.0);
    }
    if colours.is_empty() {
        colours.push(0);
    }
    Ok((atlas, colours))
}

/// A height-only RBVH ([`crate::rbvh::TexelFormat::Height`]) keeps no colour channel (and its
/// atlas holds no normals, which the paint shader reads as those of the other format).
fn no_height_only(rbvh: &Rbvh) -> Result<()> {
    if rbvh.params.texels == TexelFormat::Height {
        return Err(Error::param(
            "rbvh",
            "a height-only RBVH keeps no colours to paint: build it with normals (--texels normals, the \
             default)",
        ));
    }
    Ok(())
}

const ATLAS: &str = "RBVH atlas (painting)";
const COLOURS: &str = "RBVH colours";

/// The paint shader's SPIR-V for an atlas and colours reached by `reach`.
pub(crate) fn shader_spirv(reach: Reach) -> &'static [u8] {
    match reach {
        Reach::Bindings => shaders::PAINT,
        Reach::DeviceAddresses => shaders::PAINT_BDA,
    }
}

/// How the atlas and the colours reach the paint shader ([`Context::reach`]), both checked, from
/// the bytes of the buffers that will hold them.
fn reach_of(ctx: &Context, atlas_bytes: u64, colours: &[u32]) -> Result<Reach> {
    ctx.reach(&[
        (ATLAS, atlas_bytes),
        (COLOURS, std::mem::size_of_val(colours) as u64),
    ])
}

/// [`own_parts`]: the atlas's words, the colour words, their reach and the atlas's sizes
/// ([`atlas_sizes`]).
type OwnParts = (Vec<u32>, Vec<u32>, Reach, [u32; 4]);

/// The atlas, colour words, reach and sizes of a painter that uploads its own atlas
/// ([`Painter::new`], [`Painter::record_new`]).
fn own_parts(ctx: &Context, rbvh: &Rbvh) -> Result<OwnParts> {
    let sizes = atlas_sizes(rbvh)?;
    let (atlas, colours) = channel_data(rbvh)?;
    let reach = reach_of(
        ctx,
        std::mem::size_of_val(atlas.as_slice()) as u64,
        &colours,
    )?;
    Ok((atlas, colours, reach, sizes))
}

/// [`shared_parts`]: the context, the tracer's atlas, the colour words, their reach and the
/// atlas's sizes ([`atlas_sizes`]).
type SharedParts = (Context, Arc<Buffer>, Vec<u32>, Reach, [u32; 4]);

/// The context, shared atlas, colour words, reach and sizes of [`Painter::sharing`]: the tracer must hold
/// `rbvh`'s atlas (same pitch, texel count and bands).
fn shared_parts(tracer: &Tracer, rbvh: &Rbvh) -> Result<SharedParts> {
    no_height_only(rbvh)?;
    let Some((atlas, pitch, len, ends)) = tracer.atlas() else {
        return Err(Error::param(
            "tracer",
            "an exact-BVH tracer has no atlas to paint: share an RBVH tracer",
        ));
    };
    let sizes = atlas_sizes(rbvh)?;
    let [wide, end12, end10, our_len] = sizes;
    let ours = (rbvh.atlas.pitch, our_len, [wide, end12, end10]);
    if (pitch, len, ends) != ours {
        return Err(Error::param(
            "tracer",
            format!(
                "its atlas ({len} texels, its bands ending at {ends:?}, pitch {pitch}) is not \
                 this RBVH's ({} texels, bands ending at {:?}, pitch {})",
                ours.1, ours.2, ours.0
            ),
        ));
    }
    let (_, colours) = channel_data(rbvh)?;
    let ctx = atlas.context().clone();
    // The tracer's buffer, block ranges included, is what gets bound.
    let reach = reach_of(&ctx, atlas.size(), &colours)?;
    Ok((ctx, atlas.clone(), colours, reach, sizes))
}

/// An RBVH's atlas and colour channel on the device, ready to paint.
pub struct Painter {
    pipeline: ComputePipeline,
    reach: Reach,
    /// Device addresses of the atlas and the colours with [`Reach::DeviceAddresses`], else zero.
    addresses: (u64, u64),
    heightfields: Vec<GpuHeightfield>,
    /// Its own upload, or the atlas of the tracer it shares ([`Painter::sharing`]).
    atlas: Arc<Buffer>,
    colours: Buffer,
    pitch: u32,
    atlas_len: u32,
    /// Where the atlas's 16-, 12- and 10-bit bands end ([`atlas_sizes`]): GLSL `atlas_wide_len`,
    /// `atlas_end12` and `atlas_end10`.
    atlas_ends: [u32; 3],
}

impl Painter {
    /// Uploads the atlas and the colour channel of `rbvh` (white on every surface texel when it
    /// has none, as [`Rbvh::colour_channel`] creates it).
    pub fn new(ctx: &Context, rbvh: &Rbvh) -> Result<Painter> {
        let (atlas, colours, reach, sizes) = own_parts(ctx, rbvh)?;
        let atlas = ctx.upload_unchecked(ATLAS, bytemuck::cast_slice(&atlas))?;
        let colours = ctx.upload_unchecked(COLOURS, bytemuck::cast_slice(&colours))?;
        Self::with_buffers(ctx, rbvh, reach, Arc::new(atlas), colours, sizes)
    }

    /// As [`Painter::new`], painting with the atlas `tracer` (made by [`Tracer::new`] for `rbvh`,
    /// with or without levels of detail) already holds on the device: only the colour channel is uploaded,
    /// which saves the atlas's size again on the device.
    pub fn sharing(tracer: &Tracer, rbvh: &Rbvh) -> Result<Painter> {
        let (ctx, atlas, colours, reach, sizes) = shared_parts(tracer, rbvh)?;
        let colours = ctx.upload_unchecked(COLOURS, bytemuck::cast_slice(&colours))?;
        Self::with_buffers(&ctx, rbvh, reach, atlas, colours, sizes)
    }

    /// Embedded use: as [`Painter::sharing`], *recording* any staging copy of the colours into
    /// `cmd` as [`Painter::record_new`] does; the returned staging buffers must live until `cmd`
    /// has executed. An error records nothing, as for `record_new`.
    pub fn record_sharing(
        tracer: &Tracer,
        rbvh: &Rbvh,
        cmd: vk::CommandBuffer,
    ) -> Result<(Painter, Vec<Buffer>)> {
        let (ctx, atlas, colours, reach, sizes) = shared_parts(tracer, rbvh)?;
        let (colours, write) =
            ctx.upload_unchecked_prepared(COLOURS, bytemuck::cast_slice(&colours))?;
        let painter = Self::with_buffers(&ctx, rbvh, reach, atlas, colours, sizes)?;
        let staging: Vec<Buffer> = write.record(&ctx, cmd).into_iter().collect();
        if !staging.is_empty() {
            ctx.record_transfer_to_compute(cmd);
        }
        Ok((painter, staging))
    }

    /// Bytes this painter holds on the device: the colour channel, and the atlas unless it shares
    /// a tracer's.
    pub fn device_bytes(&self) -> u64 {
        let own_atlas = if Arc::strong_count(&self.atlas) == 1 {
            self.atlas.size()
        } else {
            0
        };
        self.colours.size() + own_atlas
    }

    /// Embedded use: as [`Painter::new`] with the context's (the engine's) allocator, *recording*
    /// any staging copies into `cmd`, followed by a barrier that makes them visible to compute
    /// shaders; nothing is submitted. Paint with [`Painter::record`]. The staging buffers are
    /// returned and must live until `cmd` has executed. An error records nothing: every step
    /// that can fail comes before the first copy is recorded.
    pub fn record_new(
        ctx: &Context,
        rbvh: &Rbvh,
        cmd: vk::CommandBuffer,
    ) -> Result<(Painter, Vec<Buffer>)> {
        let (atlas, colours, reach, sizes) = own_parts(ctx, rbvh)?;
        let (atlas, write_a) =
            ctx.upload_unchecked_prepared(ATLAS, bytemuck::cast_slice(&atlas))?;
        let (colours, write_c) =
            ctx.upload_unchecked_prepared(COLOURS, bytemuck::cast_slice(&colours))?;
        let painter = Self::with_buffers(ctx, rbvh, reach, Arc::new(atlas), colours, sizes)?;
        let staging: Vec<Buffer> = [write_a, write_c]
            .into_iter()
            .filter_map(|w| w.record(ctx, cmd))
            .collect();
        if !staging.is_empty() {
            ctx.record_transfer_to_compute(cmd);
        }
        Ok((painter, staging))
    }

    fn with_buffers(
        ctx: &Context,
        rbvh: &Rbvh,
        reach: Reach,
        atlas: Arc<Buffer>,
        colours: Buffer,
        [wide, end12, end10, atlas_len]: [u32; 4],
    ) -> Result<Painter> {
        let address = |b: &Buffer| {
            b.device_address()
                .ok_or_else(|| Error::NoDevice(format!("{}: no device address", b.name())))
        };
        let addresses = match reach {
            Reach::Bindings => (0, 0),
            Reach::DeviceAddresses => (address(&atlas)?, address(&colours)?),
        };
        Ok(Painter {
            pipeline: ComputePipeline::new(
                ctx,
                "paint",
                shader_spirv(reach),
                bindings::paint(reach),
                std::mem::size_of::<PaintParams>() as u32,
            )?,
            reach,
            addresses,
            heightfields: rbvh.heightfields.clone(),
            atlas,
            colours,
            pitch: rbvh.atlas.pitch,
            atlas_len,
            atlas_ends: [wide, end12, end10],
        })
    }

    /// How the atlas and the colours reach the shader (see [`Context::reach`]).
    pub fn reach(&self) -> Reach {
        self.reach
    }

    /// The device buffer of the colour channel (one word per atlas texel, [`Rbvh::colours`]'s
    /// layout), for an engine that reads the paint on the device. Painting writes it at
    /// `COMPUTE_SHADER` with `SHADER_WRITE`.
    pub fn colour_buffer(&self) -> BufferView {
        BufferView {
            buffer: self.colours.raw(),
            offset: 0,
        }
    }

    /// Embedded use: records the painting of `brushes` (at most [`MAX_BRUSHES_PER_PASS`]; in
    /// order, each composited over the texel, see [`crate::rgba::over`]) into the engine's `cmd`: a recorded upload of the
    /// brushes, a transfer-to-compute barrier where one was needed, and one dispatch per leaf they
    /// reach, after a compute-to-compute barrier, so that a recording composites over the paint
    /// of the shaders recorded before it (another recording's, past [`MAX_BRUSHES_PER_PASS`]).
    /// No barrier follows: the engine orders its readers of [`Painter::colour_buffer`]. The
    /// returned recording must live until `cmd` has executed; an error records nothing.
    pub fn record(&self, cmd: vk::CommandBuffer, brushes: &[Brush]) -> Result<PaintRecording> {
        if brushes.len() > MAX_BRUSHES_PER_PASS {
            return Err(Error::param(
                "brushes",
                format!(
                    "{} brushes in one recording; record at most {MAX_BRUSHES_PER_PASS} at a time",
                    brushes.len()
                ),
            ));
        }
        let ctx = self.atlas.context().clone();
        let bytes: &[u8] = bytemuck::cast_slice(brushes);
        ctx.check_storage_range(
            "paint brushes",
            bytes.len() as u64,
            "split the work into smaller batches or a smaller scene",
        )?;
        let (brush_buf, write) = ctx.upload_unchecked_prepared("paint brushes", bytes)?;
        let set = self.descriptor_set(&brush_buf)?;
        // Recorded once nothing can fail: an error leaves `cmd` as it was.
        let staging = write.record(&ctx, cmd);
        if staging.is_some() {
            ctx.record_transfer_to_compute(cmd);
        }
        let leaves = candidate_leaves(&self.heightfields, brushes);
        ctx.record_compute_to_compute(cmd);
        self.record_leaves(ctx.device(), cmd, &set, &leaves, brushes.len() as u32);
        Ok(PaintRecording {
            _set: set,
            _brushes: brush_buf,
            _staging: staging,
        })
    }

    /// The descriptor set of one pass: the atlas, `brushes` and the colours, or only `brushes`
    /// where the other two are reached through their device addresses.
    fn descriptor_set(&self, brushes: &Buffer) -> Result<DescriptorSet> {
        match self.reach {
            Reach::Bindings => self.pipeline.descriptor_set(&[
                (self.atlas.raw(), 0),
                (brushes.raw(), 0),
                (self.colours.raw(), 0),
            ]),
            Reach::DeviceAddresses => self.pipeline.descriptor_set(&[(brushes.raw(), 0)]),
        }
    }

    /// One dispatch per leaf in `leaves`, one invocation per texel of its tile.
    fn record_leaves(
        &self,
        device: &ash::Device,
        cmd: vk::CommandBuffer,
        set: &DescriptorSet,
        leaves: &[u32],
        brush_count: u32,
    ) {
        let (atlas_address, colours_address) = self.addresses;
        for &k in leaves {
            let Some(leaf) = self.heightfields.get(k as usize) else {
                continue;
            };
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
                brush_count,
                atlas_pitch: self.pitch,
                atlas_len: self.atlas_len,
                atlas_wide_len: self.atlas_ends[0],
                atlas_end12: self.atlas_ends[1],
                atlas_end10: self.atlas_ends[2],
                reserved: 0,
                atlas_address,
                colours_address,
            };
            let texels = leaf.res_u.saturating_mul(leaf.res_v);
            self.pipeline.record(device, cmd, set, texels, |first| {
                bytemuck::bytes_of(&PaintParams {
                    texel_offset: first,
                    ..params
                })
                .to_vec()
            });
        }
    }

    /// Paints `brushes` in order, each composited over the texels it covers
    /// ([`crate::rgba::over`]; an opaque brush replaces them).
    pub fn paint(&mut self, brushes: &[Brush]) -> Result<PaintStats> {
        let ctx = self.atlas.context().clone();
        let mut stats = PaintStats::default();
        for batch in brushes.chunks(MAX_BRUSHES_PER_PASS) {
            let leaves = candidate_leaves(&self.heightfields, batch);
            if leaves.is_empty() {
                continue;
            }
            let brush_buf = ctx.upload_storage("paint brushes", batch)?;
            let set = self.descriptor_set(&brush_buf)?;
            let timing = ctx.submit("paint", |device, cmd| {
                self.record_leaves(device, cmd, &set, &leaves, batch.len() as u32);
            })?;
            stats.leaves += leaves.len() as u32;
            stats.texels += leaves
                .iter()
                .map(|&k| {
                    let l = &self.heightfields[k as usize];
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
