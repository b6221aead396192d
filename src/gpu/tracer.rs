//! Traces rays on the device: through the exact BVH (`glsl/trace_exact.comp`), an RBVH
//! (`glsl/trace_rbvh.comp`), or an RBVH with level of detail (`glsl/trace_rbvh_lod.comp`). All
//! share the push constants ([`TraceParams`]) and the bindings after the structure's own buffers:
//! rays, hits, status, the per-ray counters' first record; the LOD trace then binds the LOD
//! records and columns and the per-ray cones; every trace then binds the counters' second record
//! ([`CounterRecord`]; each binding numbered once, in `glsl/bindings.glsl`:
//! [`super::bindings`]). Counting each ray's work ([`RayCounters`]) takes a second pipeline of the
//! same shader, made on first use, with the specialization constant `rbvh_count` set: the timed
//! pipeline compiles the counting away. Each shader has a `_bda` twin that reads the structure's
//! arrays through buffer device addresses rather than bindings, for arrays over
//! `maxStorageBufferRange` ([`Reach`]). The RBVH shaders' block jumps are a second specialization
//! constant, `rbvh_block_jumps` ([`Tracer::block_jumps`]).

use std::borrow::Cow;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, OnceLock};

use ash::vk;

use super::bindings;
use super::buffer::PreparedWrite;
use super::compiled::{variant_name, CompiledPipeline};
use super::parts::{with_parts, TraceParams};
use super::pipeline::DescriptorSet;
use super::{shaders, Buffer, ComputePipeline, Context, Reach, Timing};
use crate::bvh::{GpuInstance, GpuNode, InstancedBvh, STACK_SIZE};
use crate::geom::{Hit, Ray};
use crate::lod::Cones;
use crate::probe::RayCounters;
use crate::progress::{step, Progress, Quiet};
use crate::rbvh::InstancedRbvh;
use crate::rbvh::TexelFormat;
use crate::structure::{Kind, Structure};
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
    /// One hit per ray, in ray order; [`Hit::MISS`] where nothing was hit.
    pub hits: Vec<Hit>,
    /// Per ray, what its traversal did, when asked for (traced by the counting pipeline).
    pub counters: Option<Vec<RayCounters>>,
    /// Summed over batches; see [`Timing`].
    pub timing: Timing,
}

const FLAG_ANY_HIT: u32 = 1;

/// Most rays per submission of [`Tracer::trace_observed`]: 262,144 rays are a thread for each
/// of the ~270k a large GPU keeps resident (132 SMs × 2048 on an H100), so a watched trace is
/// not starved of parallelism, while a 1024×768 frame still reports its progress three times.
pub const OBSERVED_BATCH: usize = 1 << 18;

/// The next [`Tracer`]'s id.
static NEXT_TRACER: AtomicU64 = AtomicU64::new(0);

/// `constant_id` of the trace shaders' `rbvh_count` (`glsl/trace_*_main.glsl`).
const COUNT_CONSTANT_ID: u32 = 0;
/// `constant_id` of the RBVH trace shaders' `rbvh_block_jumps` (`glsl/trace_rbvh_main.glsl`).
const JUMPS_CONSTANT_ID: u32 = 1;

/// `constant_id` of the plain RBVH trace shaders' `rbvh_height_only`
/// (`glsl/trace_rbvh_main.glsl`): the atlas holds no normals, and a hit's normal is its cell
/// triangle's ([`Atlas::device_words`](crate::rbvh::Atlas::device_words)).
const HEIGHT_ONLY_CONSTANT_ID: u32 = 2;

/// One of a ray's two counter records as the trace shaders keep them (`glsl/trace_io.glsl`):
/// [`RayCounters`]' first eight words in the first binding's, its last two (then six reserved) in
/// the second's. 32 bytes, as a ray and a hit are: with one 40-byte record the counting pipelines
/// took a register more on RADV, likely the second offset held through the walk (docs/speed.md,
/// "Counters out of the registers").
type CounterRecord = [u32; 8];
const _: () = assert!(std::mem::size_of::<CounterRecord>() == std::mem::size_of::<Ray>());

/// A ray's counters from its two records.
fn ray_counters(head: &CounterRecord, tail: &CounterRecord) -> RayCounters {
    let mut words = [0u32; 10];
    words[..8].copy_from_slice(head);
    words[8..].copy_from_slice(&tail[..2]);
    bytemuck::cast(words)
}

/// The name of `kind`'s trace shader (its pipeline's name).
pub(crate) fn shader_name(kind: Kind) -> &'static str {
    match kind {
        Kind::Exact => "trace_exact",
        Kind::ExactInstanced => "trace_exact_instances",
        Kind::RbvhInstanced => "trace_rbvh_instances",
        Kind::Rbvh => "trace_rbvh",
        Kind::RbvhLod => "trace_rbvh_lod",
    }
}

/// The SPIR-V of `kind`'s trace shader for arrays reached by `reach`.
pub(crate) fn shader_spirv(kind: Kind, reach: Reach) -> &'static [u8] {
    match (kind, reach) {
        (Kind::Exact, Reach::Bindings) => shaders::TRACE_EXACT,
        (Kind::Exact, Reach::DeviceAddresses) => shaders::TRACE_EXACT_BDA,
        (Kind::ExactInstanced, Reach::Bindings) => shaders::TRACE_EXACT_INSTANCES,
        (Kind::ExactInstanced, Reach::DeviceAddresses) => shaders::TRACE_EXACT_INSTANCES_BDA,
        (Kind::Rbvh, Reach::Bindings) => shaders::TRACE_RBVH,
        (Kind::Rbvh, Reach::DeviceAddresses) => shaders::TRACE_RBVH_BDA,
        (Kind::RbvhLod, Reach::Bindings) => shaders::TRACE_RBVH_LOD,
        (Kind::RbvhLod, Reach::DeviceAddresses) => shaders::TRACE_RBVH_LOD_BDA,
        (Kind::RbvhInstanced, Reach::Bindings) => shaders::TRACE_RBVH_INSTANCES,
        (Kind::RbvhInstanced, Reach::DeviceAddresses) => shaders::TRACE_RBVH_INSTANCES_BDA,
    }
}

/// The specialization constants of `kind`'s trace shader as (GLSL name, `constant_id`, value):
/// `rbvh_count` to `counting` (the pipeline that counts each ray's work; the timed one compiles
/// the counting away), for the RBVH kinds `rbvh_block_jumps` to `block_jumps`, and for a plain
/// RBVH (flat or in two levels) `rbvh_height_only` to its texel format `texels`.
pub(crate) fn specialization(
    (kind, texels): (Kind, TexelFormat),
    block_jumps: bool,
    counting: bool,
) -> Vec<(&'static str, u32, u32)> {
    let mut constants = vec![("rbvh_count", COUNT_CONSTANT_ID, u32::from(counting))];
    if !kind.is_exact() {
        constants.push((
            "rbvh_block_jumps",
            JUMPS_CONSTANT_ID,
            u32::from(block_jumps),
        ));
    }
    if matches!(kind, Kind::Rbvh | Kind::RbvhInstanced) {
        constants.push((
            "rbvh_height_only",
            HEIGHT_ONLY_CONSTANT_ID,
            u32::from(texels == TexelFormat::Height),
        ));
    }
    constants
}

/// The trace pipeline of `shader`'s `spirv` with its [`specialization`], named for its variant
/// ([`super::compiled::variant_name`]: `trace_rbvh jumps height`, `trace_exact counting`).
pub(crate) fn make_pipeline(
    ctx: &Context,
    shader: (Kind, TexelFormat),
    reach: Reach,
    spirv: &[u8],
    block_jumps: bool,
    counting: bool,
) -> Result<ComputePipeline> {
    let constants = specialization(shader, block_jumps, counting);
    let name = variant_name(shader_name(shader.0), &constants, reach);
    let ids: Vec<(u32, u32)> = constants.iter().map(|&(_, id, v)| (id, v)).collect();
    ComputePipeline::specialized(
        ctx,
        &name,
        spirv,
        &bindings::trace(shader.0, reach),
        std::mem::size_of::<TraceParams>() as u32,
        &ids,
    )
}

/// An acceleration structure uploaded to the device, with its trace pipeline.
pub struct Tracer {
    ctx: Context,
    /// This tracer among every one the process made: a [`TraceBinding`] holds its tracer's, since
    /// its descriptor set fits that tracer's pipeline and structure alone.
    id: u64,
    reach: Reach,
    /// What it traces, and the texel format its RBVH's atlas holds (which the plain RBVH shader
    /// is specialised for).
    shader: (Kind, TexelFormat),
    pipeline: ComputePipeline,
    /// The shader `pipeline` was made from, for the counting pipeline.
    spirv: Cow<'static, [u8]>,
    /// The same shader specialised to count each ray's work, made on first use.
    counting: OnceLock<ComputePipeline>,
    /// Whether the RBVH march jumps over blocks the ray passes above or below.
    block_jumps: bool,
    /// The structure's leading arrays, in the shader's binding order (shared: a [`super::Painter`]
    /// may paint with the RBVH's atlas).
    structure: Vec<Arc<Buffer>>,
    /// Level of detail: the LOD records and columns, bound after the per-trace buffers (but the
    /// counters' second record) and followed by the per-ray cones.
    lod: Option<[Arc<Buffer>; 2]>,
    /// Sizes the shader needs (`ray_offset`, `ray_count` and `flags` are set per dispatch).
    sizes: TraceParams,
    /// Staging buffers of recorded uploads ([`Tracer::new_recorded`]), kept until released.
    staging: Vec<Buffer>,
}

/// A view of an engine-owned buffer: the buffer and the byte offset the data starts at (a
/// multiple of `minStorageBufferOffsetAlignment`).
#[derive(Clone, Copy, Debug)]
pub struct BufferView {
    /// The engine's buffer, created with `STORAGE_BUFFER` usage; the view covers the bound
    /// rays' or hits' bytes from `offset` ([`Tracer::bind`]).
    pub buffer: vk::Buffer,
    /// Byte offset of the first element in `buffer`.
    pub offset: u64,
}

/// Engine-owned ray and hit buffers bound for [`Tracer::record`]. It owns the descriptor set and a
/// small status buffer, so it must outlive every command buffer it was recorded into.
pub struct TraceBinding {
    /// The [`Tracer::id`] of the tracer that bound it.
    tracer: u64,
    set: DescriptorSet,
    status: Buffer,
    count: u32,
    /// Keeps the (unused) per-ray counters bindings valid.
    _counters: Buffer,
}

impl TraceBinding {
    /// Rays whose traversal overflowed its stack in the traces recorded with this binding since the
    /// last call (0 for any tree built by this crate); resets the count. Call only once the
    /// engine's submission has completed.
    pub fn take_overflowed_rays(&mut self) -> Result<u32> {
        let ctx = self.status.context().clone();
        let count = ctx.read::<u32>(&mut self.status)?[0];
        ctx.write(&mut self.status, &[0; 4])?;
        Ok(count)
    }
}

/// What [`Tracer::update_instances`] writes of a two-level structure, and what it checks the
/// uploaded one against: made from an [`InstancedBvh`] or an [`InstancedRbvh`].
pub struct Placement<'a> {
    kind: Kind,
    /// The structure's name, for messages.
    label: &'static str,
    /// Both levels' nodes (the top level's first).
    nodes: &'a [GpuNode],
    top_nodes: u32,
    /// The triangle slots the shader was given.
    triangles: usize,
    instances: &'a [GpuInstance],
    /// Which of the structure's arrays holds the instances.
    instances_array: usize,
}

impl<'a> From<&'a InstancedBvh> for Placement<'a> {
    fn from(bvh: &'a InstancedBvh) -> Self {
        Placement {
            kind: Kind::ExactInstanced,
            label: "two-level exact BVH",
            nodes: &bvh.nodes,
            top_nodes: bvh.top_nodes,
            triangles: bvh.triangles.len(),
            instances: &bvh.instances,
            instances_array: 2,
        }
    }
}

impl<'a> From<&'a InstancedRbvh> for Placement<'a> {
    fn from(two: &'a InstancedRbvh) -> Self {
        let rbvh = two.parts();
        Placement {
            kind: Kind::RbvhInstanced,
            label: "two-level RBVH",
            nodes: &rbvh.nodes,
            top_nodes: two.top_nodes,
            triangles: rbvh.triangles.len(),
            instances: &two.instances,
            instances_array: 4,
        }
    }
}

impl Tracer {
    /// Uploads `structure` (its arrays reached as [`Context::reach`] decides) with the crate's
    /// own trace shader for it: the exact BVH's nodes and triangles; an RBVH's nodes,
    /// triangle-leaf triangles, height-field leaves and atlas; with levels of detail, also their
    /// records and columns (traces then take the rays' footprints, [`Cones`], in [`Tracer::trace_with`]).
    pub fn new(ctx: &Context, structure: &Structure) -> Result<Self> {
        Self::new_observed(ctx, structure, &Quiet)
    }

    /// [`Tracer::new`], reporting the upload to `progress` as one step counting bytes (written
    /// in 64 MiB steps, so a structure of gigabytes shows a moving bar).
    pub fn new_observed(
        ctx: &Context,
        structure: &Structure,
        progress: &dyn Progress,
    ) -> Result<Self> {
        with_parts(structure, |shader, sizes, arrays| {
            Self::uploaded(ctx, shader, None, arrays, sizes, progress)
        })
    }

    /// As [`Tracer::new`], with another build of the structure's trace shader (same bindings and
    /// push constants): for checking modified shaders, e.g. that image regression catches a
    /// broken one. Fails where the structure must be reached through device addresses, which
    /// that build cannot.
    pub fn with_shader(ctx: &Context, structure: &Structure, spirv: &[u8]) -> Result<Self> {
        with_parts(structure, |shader, sizes, arrays| {
            Self::uploaded(ctx, shader, Some(spirv), arrays, sizes, &Quiet)
        })
    }

    /// Embedded use: uploads `structure` with the context's (the engine's) allocator,
    /// *recording* any staging copies into `cmd`, followed by a barrier that makes them visible
    /// to compute shaders. Nothing is submitted. Call [`Tracer::release_staging`] once `cmd` has
    /// executed. With levels of detail, bind the engine's rays, hits and cones with
    /// [`Tracer::bind_with_cones`]. An error records nothing: every step that can fail comes
    /// before the first copy is recorded.
    pub fn new_recorded(
        ctx: &Context,
        structure: &Structure,
        cmd: vk::CommandBuffer,
    ) -> Result<Self> {
        with_parts(structure, |shader, sizes, arrays| {
            Self::recorded(ctx, shader, arrays, sizes, cmd)
        })
    }

    /// How the structure's arrays reach the shader: bound, or through device addresses (when one
    /// is over `maxStorageBufferRange`, or the context asks for them; see [`Context::reach`]).
    pub fn reach(&self) -> Reach {
        self.reach
    }

    /// Whether the march jumps over 8 × 8-cell blocks of the atlas that the ray passes wholly
    /// above or below (`src/rbvh/ranges.rs`); the hits are the same either way. On by default,
    /// except on CPU implementations ([`super::DeviceLimits::cpu`]): lavapipe runs the jump's
    /// code in every step of every lane's walk, and without it traces 3–15% faster on the bench
    /// scenes at Q0–Q2 (the jumps still win on long marches: Q4 AO rays, grazing views). Always
    /// false for the exact BVH, which has no march.
    pub fn block_jumps(&self) -> bool {
        self.block_jumps
    }

    /// The trace pipeline, its variant and what the driver compiled it into (registers,
    /// spills, …; no statistics where the context does not capture them,
    /// [`super::DeviceLimits::pipeline_statistics`]): what [`super::compile_every_pipeline`] says
    /// of the same variant.
    pub fn compiled(&self) -> CompiledPipeline {
        let constants = specialization(self.shader, self.block_jumps, false);
        CompiledPipeline::of(
            &self.pipeline,
            shader_name(self.shader.0),
            self.reach,
            &constants,
            self.block_jumps != self.ctx.limits().cpu || self.shader.0.is_exact(),
        )
    }

    /// Turns the block jumps on or off (see [`Tracer::block_jumps`]), remaking the pipeline: do it
    /// before recording traces into command buffers. Fails for the exact BVH when asked to turn
    /// them on.
    pub fn set_block_jumps(&mut self, on: bool) -> Result<()> {
        if on == self.block_jumps {
            return Ok(());
        }
        if self.shader.0.is_exact() {
            return Err(Error::param(
                "block_jumps",
                "the exact BVH has no march to jump in",
            ));
        }
        self.pipeline = make_pipeline(&self.ctx, self.shader, self.reach, &self.spirv, on, false)?;
        self.block_jumps = on;
        self.counting = OnceLock::new();
        Ok(())
    }

    /// Uploads `arrays` (every one checked before the first is uploaded) as one step of
    /// `progress` counting their bytes, and makes the pipeline; `spirv` replaces the bindings
    /// build of the kind's shader.
    fn uploaded(
        ctx: &Context,
        shader: (Kind, TexelFormat),
        spirv: Option<&[u8]>,
        arrays: &[(&str, &[u8])],
        sizes: TraceParams,
        progress: &dyn Progress,
    ) -> Result<Self> {
        let reach = reach_of(ctx, arrays)?;
        let spirv =
            match (spirv, reach) {
                (None, _) => Cow::Borrowed(shader_spirv(shader.0, reach)),
                (Some(s), Reach::Bindings) => Cow::Owned(s.to_vec()),
                (Some(_), Reach::DeviceAddresses) => return Err(Error::param(
                    "trace shader",
                    "a replacement shader binds the RBVH's arrays, but this RBVH must be reached \
                     through device addresses",
                )),
            };
        let total = arrays.iter().map(|(_, bytes)| bytes.len() as u64).sum();
        let structure = step(progress, "uploading the structure (bytes)", total, || {
            arrays
                .iter()
                .map(|(array, bytes)| ctx.upload_observed(array, bytes, progress).map(Arc::new))
                .collect::<Result<Vec<_>>>()
        })?;
        Self::assemble(ctx, shader, reach, spirv, structure, sizes)
    }

    fn recorded(
        ctx: &Context,
        shader: (Kind, TexelFormat),
        arrays: &[(&str, &[u8])],
        sizes: TraceParams,
        cmd: vk::CommandBuffer,
    ) -> Result<Self> {
        let reach = reach_of(ctx, arrays)?;
        let mut structure = Vec::new();
        let mut writes = Vec::new();
        for (array, bytes) in arrays {
            let (buffer, write) = ctx.upload_unchecked_prepared(array, bytes)?;
            structure.push(Arc::new(buffer));
            writes.push(write);
        }
        let spirv = Cow::Borrowed(shader_spirv(shader.0, reach));
        let mut tracer = Self::assemble(ctx, shader, reach, spirv, structure, sizes)?;
        // Recorded once nothing can fail: an error leaves `cmd` as it was.
        tracer.staging = writes
            .into_iter()
            .filter_map(|w| w.record(ctx, cmd))
            .collect();
        if !tracer.staging.is_empty() {
            ctx.record_transfer_to_compute(cmd);
        }
        Ok(tracer)
    }

    /// Frees the staging buffers of a recorded upload; call once that command buffer has executed.
    pub fn release_staging(&mut self) {
        self.staging.clear();
    }

    /// Moves the instances of an uploaded two-level structure: writes `placed`'s top level and
    /// instance records (the uploaded [`InstancedBvh`] or [`InstancedRbvh`] after its
    /// `set_transforms`) over the device's, and leaves the meshes' trees where they are (issue
    /// "Instances": build the bottom levels once, move instances, rebuild and upload the top
    /// level alone). Submits and waits, both arrays' copies in one submission. Fails for any
    /// other structure, and for a structure whose arrays are not the uploaded ones' sizes
    /// (another scene); an error before the submission leaves the structure as it was.
    pub fn update_instances<'b>(&mut self, placed: impl Into<Placement<'b>>) -> Result<()> {
        let writes = self.prepare_instance_update(&placed.into())?;
        if writes.iter().all(PreparedWrite::is_done) {
            return Ok(());
        }
        let ctx = self.ctx.clone();
        // The staging buffers outlive the submission, which `submit` waits for.
        let mut staging = Vec::new();
        ctx.submit("update instances", |_, cmd| {
            staging.extend(writes.into_iter().filter_map(|w| w.record(&ctx, cmd)));
        })?;
        Ok(())
    }

    /// [`Tracer::update_instances`] for an engine's command buffer `cmd` (recording): records a
    /// barrier after the compute reads of the old placement, the copies from staging buffers
    /// (kept until [`Tracer::release_staging`]) and a barrier that makes them visible to compute
    /// shaders. Where the structure's memory is host-visible it is written at once instead: call
    /// it when no submitted trace still reads the structure. An error leaves the structure and
    /// `cmd` as they were.
    pub fn update_instances_recorded<'b>(
        &mut self,
        placed: impl Into<Placement<'b>>,
        cmd: vk::CommandBuffer,
    ) -> Result<()> {
        let writes = self.prepare_instance_update(&placed.into())?;
        let ctx = self.ctx.clone();
        ctx.record_compute_to_transfer(cmd);
        for write in writes {
            self.staging.extend(write.record(&ctx, cmd));
        }
        ctx.record_transfer_to_compute(cmd);
        Ok(())
    }

    /// An instance update's fallible half, shared by the submitting and the recording calls:
    /// both arrays' buffers checked before either is written, then each written where its memory
    /// is host-visible or staged, with no copy recorded or submitted. Neither write can fail
    /// after the other: their sizes are the uploaded ones (instance_update), and the two buffers
    /// share a memory type, both written directly or both staged. So an error leaves the
    /// structure as it was, on a discrete GPU too (the submitting call used to copy the top level
    /// before it staged the instances).
    fn prepare_instance_update(&mut self, placed: &Placement<'_>) -> Result<Vec<PreparedWrite>> {
        let (top, instances) = self.instance_update(placed)?;
        let ctx = self.ctx.clone();
        let arrays = [(0, top), (placed.instances_array, instances)];
        for (k, _) in arrays {
            self.structure_mut(k)?;
        }
        arrays
            .into_iter()
            .map(|(k, bytes)| ctx.prepare_write(self.structure_mut(k)?, bytes))
            .collect()
    }

    /// The bytes an instance update writes (the top level's nodes, the instance records), once
    /// this tracer is checked to hold a two-level structure of `placed`'s kind and sizes.
    fn instance_update<'b>(&self, placed: &Placement<'b>) -> Result<(&'b [u8], &'b [u8])> {
        if self.shader.0 != placed.kind {
            return Err(Error::param(
                "instances",
                format!(
                    "this tracer traces {} structure, not a {}",
                    self.shader.0.name(),
                    placed.label
                ),
            ));
        }
        let uploaded = (
            self.sizes.node_count as usize,
            self.sizes.tri_count as usize,
            self.sizes.instance_count as usize,
        );
        let given = (placed.nodes.len(), placed.triangles, placed.instances.len());
        if given != uploaded {
            return Err(Error::param(
                "instances",
                format!(
                    "(nodes, triangles, instances) {given:?} are not the uploaded structure's \
                     {uploaded:?}: upload another scene with Tracer::new"
                ),
            ));
        }
        let top = placed
            .nodes
            .get(..placed.top_nodes as usize)
            .ok_or_else(|| {
                Error::param("instances", "the top level has more nodes than the tree")
            })?;
        Ok((
            bytemuck::cast_slice(top),
            bytemuck::cast_slice(placed.instances),
        ))
    }

    /// The structure's array `k`, to write: not shared with a painter (only an RBVH's atlas is).
    fn structure_mut(&mut self, k: usize) -> Result<&mut Buffer> {
        self.structure
            .get_mut(k)
            .and_then(Arc::get_mut)
            .ok_or_else(|| Error::param("instances", format!("structure array {k} is shared")))
    }

    /// Binds engine-owned buffers for [`Tracer::record`]: `count` rays (32 bytes each, the
    /// [`Ray`] layout) read from `rays`, `count` hits (the [`Hit`] layout) written to `hits`.
    pub fn bind(&self, rays: BufferView, hits: BufferView, count: u32) -> Result<TraceBinding> {
        self.expect_lod(
            false,
            "trace binding",
            "a level-of-detail tracer needs the rays' cones: use Tracer::bind_with_cones",
        )?;
        self.bind_views(rays, hits, None, count)
    }

    /// As [`Tracer::bind`], with the rays' footprints: `count` cones (the
    /// [`crate::lod::RayCone`] layout, 8 bytes each) read from `cones` by a level-of-detail
    /// tracer ([`Tracer::new_recorded`] of an RBVH with levels of detail), which needs them, and
    /// ignored by any other, so that an engine binds what its rays carry whatever it traces (as
    /// [`Tracer::trace_with`] takes them).
    pub fn bind_with_cones(
        &self,
        rays: BufferView,
        hits: BufferView,
        cones: BufferView,
        count: u32,
    ) -> Result<TraceBinding> {
        let cones = self.lod.is_some().then_some(cones);
        self.bind_views(rays, hits, cones, count)
    }

    fn bind_views(
        &self,
        rays: BufferView,
        hits: BufferView,
        cones: Option<BufferView>,
        count: u32,
    ) -> Result<TraceBinding> {
        let align = self.ctx.limits().min_storage_buffer_offset_alignment.max(1);
        // Each view's bytes for `count` rays: bound as the descriptor's range (an engine's
        // buffer may exceed maxStorageBufferRange, which a range to its end would too).
        let bytes = |per_ray: u64| (u64::from(count) * per_ray).max(per_ray);
        let sized = [
            ("rays", Some(rays), bytes(32)),
            ("hits", Some(hits), bytes(32)),
            ("cones", cones, bytes(8)),
        ];
        for (what, view, range) in sized {
            let Some(view) = view else { continue };
            if view.offset % align != 0 {
                return Err(Error::param(
                    what,
                    format!(
                        "offset {} is not a multiple of minStorageBufferOffsetAlignment ({align})",
                        view.offset
                    ),
                ));
            }
            self.ctx.check_storage_range(
                &format!("the {count} rays' {what}"),
                range,
                "bind fewer rays at a time",
            )?;
        }
        let status = self.ctx.host_storage("trace status", 4)?;
        let counters = self.ctx.create_buffer(
            "per-ray counters (unused)",
            4,
            vk::BufferUsageFlags::STORAGE_BUFFER,
            gpu_allocator::MemoryLocation::GpuOnly,
        )?;
        let views = self.views(
            [
                (rays.buffer, rays.offset, bytes(32)),
                (hits.buffer, hits.offset, bytes(32)),
                (status.raw(), 0, vk::WHOLE_SIZE),
                (counters.raw(), 0, vk::WHOLE_SIZE),
                (counters.raw(), 0, vk::WHOLE_SIZE),
            ],
            cones.map(|c| (c.buffer, c.offset, bytes(8))),
        );
        Ok(TraceBinding {
            tracer: self.id,
            set: self.pipeline.descriptor_set_ranged(&views)?,
            status,
            count,
            _counters: counters,
        })
    }

    /// Records the trace of `binding`'s rays into the engine's `cmd` (in the recording state).
    /// Nothing is submitted and no barrier is recorded; the engine orders the work:
    /// * before: its writes of the rays must be made available to `COMPUTE_SHADER` /
    ///   `SHADER_READ` (and a recorded upload, [`Tracer::new_recorded`], must precede this in
    ///   submission order — it ends with its own transfer-to-compute barrier);
    /// * after: the hits are written at `COMPUTE_SHADER` with `SHADER_WRITE`; add a barrier from
    ///   there to whatever reads them (a shader, a transfer, or `HOST` / `HOST_READ`).
    ///
    /// A binding made by another tracer is refused (its set holds that tracer's structure, in its
    /// pipeline's layout), and nothing is recorded.
    pub fn record(
        &self,
        cmd: vk::CommandBuffer,
        binding: &TraceBinding,
        query: Query,
    ) -> Result<()> {
        if binding.tracer != self.id {
            return Err(Error::param(
                "binding",
                "made by another tracer, for its structure and pipeline: bind the rays and hits \
                 with the tracer that records them (Tracer::bind)",
            ));
        }
        let flags = match query {
            Query::Closest => 0,
            Query::Any => FLAG_ANY_HIT,
        };
        let n = binding.count;
        self.pipeline
            .record(self.ctx.device(), cmd, &binding.set, n, |first| {
                bytemuck::bytes_of(&TraceParams {
                    ray_offset: first,
                    ray_count: n,
                    flags,
                    ..self.sizes
                })
                .to_vec()
            });
        Ok(())
    }

    fn assemble(
        ctx: &Context,
        shader: (Kind, TexelFormat),
        reach: Reach,
        spirv: Cow<'static, [u8]>,
        mut structure: Vec<Arc<Buffer>>,
        mut sizes: TraceParams,
    ) -> Result<Self> {
        if reach == Reach::DeviceAddresses {
            for (&slot, buffer) in address_slots(shader.0).iter().zip(&structure) {
                sizes.addresses[slot] = buffer.device_address().ok_or_else(|| {
                    Error::NoDevice(format!("{}: no device address", buffer.name()))
                })?;
            }
        }
        // The LOD shader binds the last two structure arrays (records and columns) and the cones
        // after the per-trace buffers (but the counters' second record, bound last).
        let kind = shader.0;
        let lod = if kind == Kind::RbvhLod {
            let tail = structure.split_off(structure.len().saturating_sub(2));
            let [records, columns]: [Arc<Buffer>; 2] = tail
                .try_into()
                .map_err(|_| Error::param("lod", "the LOD trace needs its two arrays"))?;
            Some([records, columns])
        } else {
            None
        };
        let block_jumps = !kind.is_exact() && !ctx.limits().cpu;
        let pipeline = make_pipeline(ctx, shader, reach, &spirv, block_jumps, false)?;
        Ok(Tracer {
            ctx: ctx.clone(),
            id: NEXT_TRACER.fetch_add(1, Ordering::Relaxed),
            reach,
            shader,
            pipeline,
            spirv,
            counting: OnceLock::new(),
            block_jumps,
            structure,
            lod,
            sizes,
            staging: Vec::new(),
        })
    }

    /// The counting pipeline, made on first use.
    fn counting_pipeline(&self) -> Result<&ComputePipeline> {
        if let Some(p) = self.counting.get() {
            return Ok(p);
        }
        let pipeline = make_pipeline(
            &self.ctx,
            self.shader,
            self.reach,
            &self.spirv,
            self.block_jumps,
            true,
        )?;
        Ok(self.counting.get_or_init(|| pipeline))
    }

    /// The buffers of one trace in the pipeline's binding order ([`bindings::trace`]): the
    /// structure's when bound, the per-trace four (rays, hits, status, the counters' first
    /// record), then the LOD arrays when bound and the cones, then the counters' second record
    /// (`per_trace`'s fifth).
    fn views(
        &self,
        per_trace: [(vk::Buffer, u64, u64); 5],
        cones: Option<(vk::Buffer, u64, u64)>,
    ) -> Vec<(vk::Buffer, u64, u64)> {
        let bound = self.reach == Reach::Bindings;
        let [rays, hits, status, counters_head, counters_tail] = per_trace;
        let mut views: Vec<(vk::Buffer, u64, u64)> = Vec::new();
        if bound {
            views.extend(self.structure.iter().map(|b| (b.raw(), 0, vk::WHOLE_SIZE)));
        }
        views.extend([rays, hits, status, counters_head]);
        if bound {
            views.extend(
                self.lod
                    .iter()
                    .flatten()
                    .map(|b| (b.raw(), 0, vk::WHOLE_SIZE)),
            );
        }
        views.extend(cones);
        views.push(counters_tail);
        views
    }

    /// Fails, naming `what` and saying `hint`, unless this tracer has levels of detail exactly
    /// when `lod` says so: the two kinds take different inputs (cones or none).
    fn expect_lod(&self, lod: bool, what: &str, hint: &str) -> Result<()> {
        if self.lod.is_some() == lod {
            Ok(())
        } else {
            Err(Error::param(what, hint))
        }
    }

    /// Whether `cones` suit this tracer: a level-of-detail tracer needs footprints, one valid
    /// cone per ray or one for all ([`Error::InvalidParameter`] naming `trace` otherwise);
    /// another ignores them.
    fn check_trace_cones(&self, rays: &[Ray], cones: Cones) -> Result<()> {
        if self.lod.is_none() {
            return Ok(());
        }
        if !cones.is_some() {
            return Err(Error::param(
                "cones",
                "a level-of-detail tracer needs the rays' footprints: pass Cones to \
                 Tracer::trace_with",
            ));
        }
        cones.check(rays)
    }

    /// Bytes of the structure (and its levels of detail) on the device.
    pub fn device_bytes(&self) -> u64 {
        self.structure
            .iter()
            .chain(self.lod.iter().flatten())
            .map(|b| b.size())
            .sum()
    }

    /// The RBVH atlas on the device with its pitch, texel count and the ends of its 16-, 12- and
    /// 10-bit bands, for a painter that shares it ([`super::Painter::sharing`]); None for the
    /// exact BVH.
    pub(crate) fn atlas(&self) -> Option<(&Arc<Buffer>, u32, u32, [u32; 3])> {
        let sz = &self.sizes;
        self.structure.get(3).map(|b| {
            let ends = [sz.atlas_wide_len, sz.atlas_end12, sz.atlas_end10];
            (b, sz.atlas_pitch, sz.atlas_len, ends)
        })
    }

    /// Traces `rays` without footprints or per-ray counters: [`Tracer::trace_with`] with
    /// neither (so not through levels of detail, which need the rays' footprints).
    pub fn trace(&self, rays: &[Ray], query: Query) -> Result<Traced> {
        self.trace_with(rays, Cones::None, query, false)
    }

    /// Traces `rays`, in batches that fit `maxStorageBufferRange`. `cones` are the rays'
    /// footprints: read with levels of detail (which need them, see [`crate::lod`]), ignored by
    /// any other structure, so that a caller passes what its rays carry whatever it traces.
    /// `counters` also returns what each ray's traversal did (through the counting pipeline,
    /// whose timing is not that of a trace without). Fails with [`Error::StackOverflow`] if any
    /// ray overflowed its stack.
    pub fn trace_with<'c>(
        &self,
        rays: &[Ray],
        cones: impl Into<Cones<'c>>,
        query: Query,
        counters: bool,
    ) -> Result<Traced> {
        let cones = cones.into();
        self.check_trace_cones(rays, cones)?;
        self.trace_batches(rays, cones, query, counters, None, 1)
    }

    /// [`Tracer::trace_with`] without counters, each batch traced `passes` times back to back in
    /// its submission ([`super::ComputePipeline::run_repeated`]): the hits are the same, and the
    /// timing is per pass. For timing a fast GPU, where one pass over a frame's rays is too short
    /// to time well.
    pub fn trace_repeated<'c>(
        &self,
        rays: &[Ray],
        cones: impl Into<Cones<'c>>,
        query: Query,
        passes: u32,
    ) -> Result<Traced> {
        let cones = cones.into();
        self.check_trace_cones(rays, cones)?;
        self.trace_batches(rays, cones, query, false, None, passes)
    }

    /// [`Tracer::trace_with`], reporting the rays traced to `progress`: in batches of at most
    /// [`OBSERVED_BATCH`] rays, each its own submission, so that a trace of seconds shows how far
    /// it is (the timing is the batches' sum).
    pub fn trace_observed<'c>(
        &self,
        rays: &[Ray],
        cones: impl Into<Cones<'c>>,
        query: Query,
        counters: bool,
        progress: &dyn Progress,
    ) -> Result<Traced> {
        let cones = cones.into();
        self.check_trace_cones(rays, cones)?;
        step(progress, "tracing rays", rays.len() as u64, || {
            self.trace_batches(rays, cones, query, counters, Some(progress), 1)
        })
    }

    fn trace_batches(
        &self,
        rays: &[Ray],
        cones: Cones,
        query: Query,
        counters: bool,
        progress: Option<&dyn Progress>,
        passes: u32,
    ) -> Result<Traced> {
        // Batches bounded by the largest per-ray buffer (each record of the counters is as large
        // as a ray).
        let per_ray = std::mem::size_of::<Ray>() as u64;
        let batch =
            (self.ctx.limits().max_storage_buffer_range / per_ray).clamp(1, 1 << 22) as usize;
        let batch = if progress.is_some() {
            batch.min(OBSERVED_BATCH)
        } else {
            batch
        };
        let mut out = Traced {
            hits: Vec::with_capacity(rays.len()),
            counters: counters.then(|| Vec::with_capacity(rays.len())),
            timing: Timing::default(),
        };
        for (k, chunk) in rays.chunks(batch).enumerate() {
            let chunk_cones = cones.slice(k * batch..k * batch + chunk.len());
            let (hits, chunk_counters, timing) =
                self.trace_batch(chunk, chunk_cones, query, counters, passes)?;
            out.hits.extend(hits);
            if let (Some(all), Some(c)) = (out.counters.as_mut(), chunk_counters) {
                all.extend(c);
            }
            out.timing.wall_ms += timing.wall_ms;
            out.timing.gpu_ms = match (out.timing.gpu_ms, timing.gpu_ms) {
                (Some(a), Some(b)) => Some(a + b),
                (None, b) if out.hits.len() == chunk.len() => b,
                _ => None,
            };
            if let Some(progress) = progress {
                progress.advance(chunk.len() as u64);
            }
        }
        Ok(out)
    }

    fn trace_batch(
        &self,
        rays: &[Ray],
        cones: Cones,
        query: Query,
        counters: bool,
        passes: u32,
    ) -> Result<(Vec<Hit>, Option<Vec<RayCounters>>, Timing)> {
        let pipeline = if counters {
            self.counting_pipeline()?
        } else {
            &self.pipeline
        };
        let n = rays.len() as u32;
        let ray_buf = self.ctx.upload_storage("rays", rays)?;
        let mut hit_buf = self.ctx.zeroed_storage(
            "hits",
            rays.len() as u64 * std::mem::size_of::<Hit>() as u64,
        )?;
        let mut status = self.ctx.zeroed_storage("trace status", 4)?;
        let counter_bytes = if counters {
            rays.len() as u64 * std::mem::size_of::<CounterRecord>() as u64
        } else {
            4
        };
        let mut counters_head = self.ctx.zeroed_storage("per-ray counters", counter_bytes)?;
        let mut counters_tail = self
            .ctx
            .zeroed_storage("per-ray counters, second record", counter_bytes)?;
        let flags = match query {
            Query::Closest => 0,
            Query::Any => FLAG_ANY_HIT,
        };
        let cone_buf = match cones.per_ray(rays.len()).filter(|_| self.lod.is_some()) {
            Some(c) => Some(self.ctx.upload_storage("ray cones", &c)?),
            None => None,
        };
        // The library's own buffers, each the batch's size, are bound whole.
        let whole = |b: &Buffer| (b.raw(), 0, vk::WHOLE_SIZE);
        let per_trace = [&ray_buf, &hit_buf, &status, &counters_head, &counters_tail].map(whole);
        let views: Vec<(vk::Buffer, u64)> = (self.views(per_trace, cone_buf.as_ref().map(whole)))
            .into_iter()
            .map(|(b, offset, _)| (b, offset))
            .collect();
        let timing = pipeline.run_repeated(&views, n, passes, |first| {
            bytemuck::bytes_of(&TraceParams {
                ray_offset: first,
                ray_count: n,
                flags,
                ..self.sizes
            })
            .to_vec()
        })?;
        // Every pass counts its overflowing rays again.
        let overflow = self.ctx.read::<u32>(&mut status)?[0] / passes;
        if overflow > 0 {
            return Err(Error::StackOverflow {
                resource: pipeline.name().into(),
                depth: STACK_SIZE,
                rays: overflow,
            });
        }
        let mut hits: Vec<Hit> = self.ctx.read(&mut hit_buf)?;
        hits.truncate(rays.len());
        let counters = if counters {
            let head: Vec<CounterRecord> = self.ctx.read(&mut counters_head)?;
            let tail: Vec<CounterRecord> = self.ctx.read(&mut counters_tail)?;
            Some(
                head.iter()
                    .zip(&tail)
                    .take(rays.len())
                    .map(|(head, tail)| ray_counters(head, tail))
                    .collect(),
            )
        } else {
            None
        };
        Ok((hits, counters, timing))
    }
}

/// Where in [`TraceParams::addresses`] each of `kind`'s arrays goes, in their binding order.
fn address_slots(kind: Kind) -> &'static [usize] {
    match kind {
        Kind::Exact => &[0, 1],
        Kind::ExactInstanced => &[0, 1, 6],
        Kind::Rbvh => &[0, 1, 2, 3],
        Kind::RbvhLod => &[0, 1, 2, 3, 4, 5],
        Kind::RbvhInstanced => &[0, 1, 2, 3, 6],
    }
}

/// How a structure's `arrays` reach the shader ([`Context::reach`]), every one checked.
fn reach_of(ctx: &Context, arrays: &[(&str, &[u8])]) -> Result<Reach> {
    let sizes: Vec<(&str, u64)> = arrays
        .iter()
        .map(|&(name, bytes)| (name, bytes.len() as u64))
        .collect();
    ctx.reach(&sizes)
}
