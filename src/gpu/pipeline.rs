//! A compute pipeline over storage buffers (the bindings it names, of set 0) and a push-constant
//! block. The workgroup size is read from the SPIR-V, so the shader is its one source of truth.

use ash::vk;

use super::statistics::{self, ShaderStatistic};
use super::{shaders, spirv, Context};
use crate::{Error, Result};

/// A compute pipeline with its layouts and a small descriptor pool.
pub struct ComputePipeline {
    ctx: Context,
    name: String,
    set_layout: vk::DescriptorSetLayout,
    layout: vk::PipelineLayout,
    pipeline: vk::Pipeline,
    /// The storage-buffer bindings, in the order [`ComputePipeline::descriptor_set`] takes buffers.
    bindings: Vec<u32>,
    push_size: u32,
    local_size_x: u32,
    /// The driver's statistics, where the context captures them.
    statistics: Vec<ShaderStatistic>,
}

impl Drop for ComputePipeline {
    fn drop(&mut self) {
        if self.ctx.shared.is_lost() {
            // The device may still use it (Error::DeviceLost): left to the driver.
            return;
        }
        let d = &self.ctx.shared.device;
        // SAFETY: submissions are synchronous, so nothing is in flight.
        unsafe {
            d.destroy_pipeline(self.pipeline, None);
            d.destroy_pipeline_layout(self.layout, None);
            d.destroy_descriptor_set_layout(self.set_layout, None);
        }
    }
}

impl ComputePipeline {
    /// Creates the pipeline from SPIR-V bytes: storage buffers at `bindings` (a shader built to
    /// read some arrays through device addresses leaves their bindings out), `push_size` bytes of
    /// push constants (checked against the device's `maxPushConstantsSize`).
    pub fn new(
        ctx: &Context,
        name: &str,
        spirv_bytes: &[u8],
        bindings: &[u32],
        push_size: u32,
    ) -> Result<Self> {
        Self::specialized(ctx, name, spirv_bytes, bindings, push_size, &[])
    }

    /// As [`ComputePipeline::new`], with the shader's specialization constants `(constant_id,
    /// value)` set (32-bit values: a `bool` constant takes 0 or 1).
    pub fn specialized(
        ctx: &Context,
        name: &str,
        spirv_bytes: &[u8],
        bindings: &[u32],
        push_size: u32,
        constants: &[(u32, u32)],
    ) -> Result<Self> {
        let words = shaders::words(spirv_bytes).map_err(|e| {
            Error::NoDevice(format!("{name}: the embedded SPIR-V is unreadable: {e}"))
        })?;
        let local_size_x = spirv::reflect(&words)
            .local_size
            .map(|s| s[0])
            .ok_or_else(|| Error::NoDevice(format!("{name}: SPIR-V declares no LocalSize")))?;
        let max_push = ctx.limits().max_push_constants_size;
        if push_size > max_push {
            return Err(Error::DeviceLimit {
                resource: name.to_string(),
                limit: "maxPushConstantsSize",
                required: push_size as u64,
                available: max_push as u64,
                hint: "this device is below the Vulkan minimum of 128 bytes".into(),
            });
        }
        ctx.check_validation_of(&format!("the calls before the creation of pipeline {name}"))?;
        let d = &ctx.shared.device;
        let mut p = ComputePipeline {
            ctx: ctx.clone(),
            name: name.to_string(),
            set_layout: vk::DescriptorSetLayout::null(),
            layout: vk::PipelineLayout::null(),
            pipeline: vk::Pipeline::null(),
            bindings: bindings.to_vec(),
            push_size,
            local_size_x,
            statistics: Vec::new(),
        };
        let layout_bindings: Vec<_> = bindings
            .iter()
            .map(|&b| {
                vk::DescriptorSetLayoutBinding::default()
                    .binding(b)
                    .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
                    .descriptor_count(1)
                    .stage_flags(vk::ShaderStageFlags::COMPUTE)
            })
            .collect();
        p.set_layout = unsafe {
            d.create_descriptor_set_layout(
                &vk::DescriptorSetLayoutCreateInfo::default().bindings(&layout_bindings),
                None,
            )
        }
        .map_err(|r| Error::vk("vkCreateDescriptorSetLayout", name, r))?;
        let ranges = [vk::PushConstantRange::default()
            .stage_flags(vk::ShaderStageFlags::COMPUTE)
            .size(push_size)];
        let set_layouts = [p.set_layout];
        let mut layout_info = vk::PipelineLayoutCreateInfo::default().set_layouts(&set_layouts);
        if push_size > 0 {
            layout_info = layout_info.push_constant_ranges(&ranges);
        }
        p.layout = unsafe { d.create_pipeline_layout(&layout_info, None) }
            .map_err(|r| Error::vk("vkCreatePipelineLayout", name, r))?;
        let module = unsafe {
            d.create_shader_module(&vk::ShaderModuleCreateInfo::default().code(&words), None)
        }
        .map_err(|r| Error::vk("vkCreateShaderModule", name, r))?;
        let entries: Vec<vk::SpecializationMapEntry> = constants
            .iter()
            .enumerate()
            .map(|(k, &(id, _))| {
                vk::SpecializationMapEntry::default()
                    .constant_id(id)
                    .offset(4 * k as u32)
                    .size(4)
            })
            .collect();
        let data: Vec<u8> = constants
            .iter()
            .flat_map(|&(_, value)| value.to_ne_bytes())
            .collect();
        let specialization = vk::SpecializationInfo::default()
            .map_entries(&entries)
            .data(&data);
        let mut stage = vk::PipelineShaderStageCreateInfo::default()
            .stage(vk::ShaderStageFlags::COMPUTE)
            .module(module)
            .name(c"main");
        if !constants.is_empty() {
            stage = stage.specialization_info(&specialization);
        }
        let capture = ctx.limits().pipeline_statistics;
        let flags = if capture {
            vk::PipelineCreateFlags::CAPTURE_STATISTICS_KHR
        } else {
            vk::PipelineCreateFlags::empty()
        };
        let info = [vk::ComputePipelineCreateInfo::default()
            .flags(flags)
            .stage(stage)
            .layout(p.layout)];
        let created = unsafe { d.create_compute_pipelines(vk::PipelineCache::null(), &info, None) };
        unsafe { d.destroy_shader_module(module, None) };
        p.pipeline = created.map_err(|(_, r)| Error::vk("vkCreateComputePipelines", name, r))?[0];
        if capture {
            // SAFETY: created above with CAPTURE_STATISTICS on a device that enabled the extension.
            p.statistics = unsafe { statistics::query(&ctx.shared.instance, d, p.pipeline) };
        }
        ctx.check_validation_of(&format!("the creation of pipeline {name}"))?;
        Ok(p)
    }

    /// The name given at creation, which errors and timings report.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// What the driver compiled this pipeline into (registers, spills, instructions), where the
    /// context asked for it ([`super::DeviceLimits::pipeline_statistics`]); else empty.
    pub fn statistics(&self) -> &[ShaderStatistic] {
        &self.statistics
    }

    /// Workgroup width declared by the shader.
    pub fn local_size_x(&self) -> u32 {
        self.local_size_x
    }

    /// Binds `buffers` to the pipeline's bindings, in order, and dispatches `invocations` threads (see
    /// [`ComputePipeline::record`]) in one timed submission of the context's own.
    pub fn run(
        &self,
        buffers: &[(vk::Buffer, u64)],
        invocations: u32,
        push: impl Fn(u32) -> Vec<u8>,
    ) -> Result<super::Timing> {
        self.run_repeated(buffers, invocations, 1, push)
    }

    /// [`ComputePipeline::run`] with the work recorded `times` times back to back in the one
    /// submission, a barrier between (each pass sees the last one's writes, as successive frames
    /// would); the timing returned is per pass (the total over `times`). A fast GPU finishes one
    /// pass of a frame's rays in a fraction of a millisecond, which timestamps resolve poorly and
    /// which leaves it idle, clocked down, between submissions; repeated passes keep it busy for
    /// as long as the caller needs to time it.
    pub fn run_repeated(
        &self,
        buffers: &[(vk::Buffer, u64)],
        invocations: u32,
        times: u32,
        push: impl Fn(u32) -> Vec<u8>,
    ) -> Result<super::Timing> {
        if times == 0 {
            return Err(Error::param(
                "times",
                format!("{}: needs at least one pass", self.name),
            ));
        }
        let set = self.descriptor_set(buffers)?;
        let timing = self.ctx.submit(&self.name, |device, cmd| {
            for pass in 0..times {
                if pass > 0 {
                    let barrier = [vk::MemoryBarrier::default()
                        .src_access_mask(vk::AccessFlags::SHADER_WRITE)
                        .dst_access_mask(
                            vk::AccessFlags::SHADER_READ | vk::AccessFlags::SHADER_WRITE,
                        )];
                    // SAFETY: `cmd` is recording (inside `submit`).
                    unsafe {
                        device.cmd_pipeline_barrier(
                            cmd,
                            vk::PipelineStageFlags::COMPUTE_SHADER,
                            vk::PipelineStageFlags::COMPUTE_SHADER,
                            vk::DependencyFlags::empty(),
                            &barrier,
                            &[],
                            &[],
                        )
                    };
                }
                self.record(device, cmd, &set, invocations, &push);
            }
        })?;
        let per_pass = |ms: f64| ms / f64::from(times);
        Ok(super::Timing {
            gpu_ms: timing.gpu_ms.map(per_pass),
            wall_ms: per_pass(timing.wall_ms),
        })
    }

    /// A descriptor set (in a pool of its own, freed with it) binding `buffers` — each a buffer
    /// and the offset its view starts at, to its end — to the pipeline's bindings, in order.
    pub fn descriptor_set(&self, buffers: &[(vk::Buffer, u64)]) -> Result<DescriptorSet> {
        let whole: Vec<(vk::Buffer, u64, u64)> = buffers
            .iter()
            .map(|&(b, offset)| (b, offset, vk::WHOLE_SIZE))
            .collect();
        self.descriptor_set_ranged(&whole)
    }

    /// [`ComputePipeline::descriptor_set`] with each buffer's range in bytes from its offset
    /// (`vk::WHOLE_SIZE`: to the buffer's end): an engine's buffer may be larger than the
    /// device's `maxStorageBufferRange`, which a descriptor's range must not exceed.
    pub fn descriptor_set_ranged(
        &self,
        buffers: &[(vk::Buffer, u64, u64)],
    ) -> Result<DescriptorSet> {
        if buffers.len() != self.bindings.len() {
            return Err(Error::param(
                "buffers",
                format!(
                    "{} takes {} buffers, got {}",
                    self.name,
                    self.bindings.len(),
                    buffers.len()
                ),
            ));
        }
        let d = &self.ctx.shared.device;
        let sizes = [vk::DescriptorPoolSize::default()
            .ty(vk::DescriptorType::STORAGE_BUFFER)
            .descriptor_count((self.bindings.len() as u32).max(1))];
        let pool = unsafe {
            d.create_descriptor_pool(
                &vk::DescriptorPoolCreateInfo::default()
                    .max_sets(1)
                    .pool_sizes(&sizes),
                None,
            )
        }
        .map_err(|r| Error::vk("vkCreateDescriptorPool", self.name.as_str(), r))?;
        let mut owned = DescriptorSet {
            ctx: self.ctx.clone(),
            pool,
            set: vk::DescriptorSet::null(),
        };
        let set_layouts = [self.set_layout];
        owned.set = unsafe {
            d.allocate_descriptor_sets(
                &vk::DescriptorSetAllocateInfo::default()
                    .descriptor_pool(pool)
                    .set_layouts(&set_layouts),
            )
        }
        .map_err(|r| Error::vk("vkAllocateDescriptorSets", self.name.as_str(), r))?[0];
        let set = owned.set;
        let infos: Vec<[vk::DescriptorBufferInfo; 1]> = buffers
            .iter()
            .map(|&(b, offset, range)| {
                [vk::DescriptorBufferInfo::default()
                    .buffer(b)
                    .offset(offset)
                    .range(range)]
            })
            .collect();
        let writes: Vec<_> = infos
            .iter()
            .zip(&self.bindings)
            .map(|(info, &binding)| {
                vk::WriteDescriptorSet::default()
                    .dst_set(set)
                    .dst_binding(binding)
                    .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
                    .buffer_info(info)
            })
            .collect();
        unsafe { d.update_descriptor_sets(&writes, &[]) };
        Ok(owned)
    }

    /// Records into `cmd`: bind the pipeline and `set`, then dispatch `invocations` threads in as
    /// many dispatches as `maxComputeWorkGroupCount[0]` requires; `push` builds the push constants
    /// of each dispatch from its first invocation. No barriers: the caller orders the work.
    pub fn record(
        &self,
        device: &ash::Device,
        cmd: vk::CommandBuffer,
        set: &DescriptorSet,
        invocations: u32,
        push: impl Fn(u32) -> Vec<u8>,
    ) {
        let max_groups = self.ctx.limits().max_compute_work_group_count[0].max(1);
        let per_dispatch = max_groups.saturating_mul(self.local_size_x);
        // SAFETY: `cmd` is in the recording state (the caller's contract) and every handle here
        // lives at least as long as `self` and `set`.
        unsafe {
            device.cmd_bind_pipeline(cmd, vk::PipelineBindPoint::COMPUTE, self.pipeline);
            device.cmd_bind_descriptor_sets(
                cmd,
                vk::PipelineBindPoint::COMPUTE,
                self.layout,
                0,
                &[set.set],
                &[],
            );
            let mut first = 0u32;
            while first < invocations {
                let n = (invocations - first).min(per_dispatch);
                let constants = push(first);
                debug_assert_eq!(constants.len(), self.push_size as usize);
                if self.push_size > 0 {
                    device.cmd_push_constants(
                        cmd,
                        self.layout,
                        vk::ShaderStageFlags::COMPUTE,
                        0,
                        &constants,
                    );
                }
                device.cmd_dispatch(cmd, n.div_ceil(self.local_size_x), 1, 1);
                first += n;
            }
        }
    }
}

/// A descriptor set with the pool it came from; dropping it frees both, so it must outlive every
/// command buffer that uses it.
pub struct DescriptorSet {
    ctx: Context,
    pool: vk::DescriptorPool,
    set: vk::DescriptorSet,
}

impl Drop for DescriptorSet {
    fn drop(&mut self) {
        if self.ctx.shared.is_lost() {
            // The device may still use it (Error::DeviceLost): left to the driver.
            return;
        }
        // SAFETY: the owner guarantees no pending command buffer uses the set any more.
        unsafe {
            self.ctx
                .shared
                .device
                .destroy_descriptor_pool(self.pool, None)
        };
    }
}
