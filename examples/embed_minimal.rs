//! The smallest embedding: the engine's own Vulkan device and allocator; the library builds an
//! RBVH, uploads it and records a trace into the engine's command buffer; the engine submits and
//! reads the hits from its own buffer. `examples/embed.rs` shows the whole contract (rays made on
//! the device, device addresses, the validation layer, shading). `cargo test` runs this one too.

use std::error::Error;
use std::sync::{Arc, Mutex};

use rbvh::ash;
use rbvh::ash::vk::{self, PipelineStageFlags as Stage};
use rbvh::gpu::{Addressing, BufferView};
use rbvh::gpu_allocator::vulkan::{
    Allocation, AllocationCreateDesc, AllocationScheme, Allocator, AllocatorCreateDesc,
};
use rbvh::gpu_allocator::MemoryLocation;
use rbvh::lod::Cones;
use rbvh::{Context, External, Hit, Query, Rbvh, RbvhParams, Scene, Structure, Tracer};

fn main() -> Result<(), Box<dyn Error>> {
    // The engine: instance, device, queue, allocator and a command buffer.
    let entry = unsafe { ash::Entry::load()? };
    let app = vk::ApplicationInfo::default().api_version(vk::API_VERSION_1_1);
    let instance_info = vk::InstanceCreateInfo::default().application_info(&app);
    let instance = unsafe { entry.create_instance(&instance_info, None)? };
    let devices = unsafe { instance.enumerate_physical_devices()? };
    let physical_device = *devices.first().ok_or("no Vulkan device")?;
    let queue_family =
        unsafe { instance.get_physical_device_queue_family_properties(physical_device) }
            .iter()
            .position(|f| f.queue_flags.contains(vk::QueueFlags::COMPUTE))
            .ok_or("no compute queue")? as u32;
    let queues = [vk::DeviceQueueCreateInfo::default()
        .queue_family_index(queue_family)
        .queue_priorities(&[1.0])];
    let device_info = vk::DeviceCreateInfo::default().queue_create_infos(&queues);
    let device = unsafe { instance.create_device(physical_device, &device_info, None)? };
    let queue = unsafe { device.get_device_queue(queue_family, 0) };
    let allocator = Arc::new(Mutex::new(Allocator::new(&AllocatorCreateDesc {
        instance: instance.clone(),
        device: device.clone(),
        physical_device,
        debug_settings: Default::default(),
        buffer_device_address: false,
        allocation_sizes: Default::default(),
    })?));
    let pool_info = vk::CommandPoolCreateInfo::default().queue_family_index(queue_family);
    let pool = unsafe { device.create_command_pool(&pool_info, None)? };
    let cmd_info = vk::CommandBufferAllocateInfo::default()
        .command_pool(pool)
        .command_buffer_count(1);
    let cmd = unsafe { device.allocate_command_buffers(&cmd_info)?[0] };

    // The engine's rays and hits, 32 bytes each, in its own host-visible buffers.
    let scene = Scene::load("sphere")?;
    let rays = scene.camera_or_framed(1.0).primary_rays(64, 64);
    let bytes = std::mem::size_of_val(rays.as_slice());
    let (ray_buffer, mut ray_memory) = engine_buffer(&device, &allocator, "rays", bytes)?;
    let (hit_buffer, hit_memory) = engine_buffer(&device, &allocator, "hits", bytes)?;
    let mapped = ray_memory.mapped_slice_mut().ok_or("rays not mapped")?;
    mapped[..bytes].copy_from_slice(bytemuck::cast_slice(&rays));

    // The library: the engine's device wrapped, the RBVH uploaded and traced in `cmd`.
    let ctx = Context::embedded(External {
        instance: instance.clone(),
        device: device.clone(),
        physical_device,
        queue_family,
        allocator: allocator.clone(),
        buffer_device_address: false,
        addressing: Addressing::Auto,
    })?;
    let rbvh = Structure::from(Rbvh::build(&scene, &RbvhParams::quality(2)?)?);
    unsafe { device.begin_command_buffer(cmd, &vk::CommandBufferBeginInfo::default())? };
    let mut tracer = Tracer::new_recorded(&ctx, &rbvh, cmd)?;
    let view = |buffer| BufferView { buffer, offset: 0 };
    let mut trace = tracer.bind(view(ray_buffer), view(hit_buffer), rays.len() as u32)?;
    tracer.record(cmd, &trace, Query::Closest)?;

    // The engine again: make the hits visible to the host, submit, wait, read.
    let to_host = [vk::MemoryBarrier::default()
        .src_access_mask(vk::AccessFlags::SHADER_WRITE)
        .dst_access_mask(vk::AccessFlags::HOST_READ)];
    let (compute, host) = (Stage::COMPUTE_SHADER, Stage::HOST);
    unsafe {
        device.cmd_pipeline_barrier(cmd, compute, host, Default::default(), &to_host, &[], &[]);
        device.end_command_buffer(cmd)?;
        let fence = device.create_fence(&vk::FenceCreateInfo::default(), None)?;
        let submit = [vk::SubmitInfo::default().command_buffers(std::slice::from_ref(&cmd))];
        device.queue_submit(queue, &submit, fence)?;
        device.wait_for_fences(&[fence], true, u64::MAX)?;
        device.destroy_fence(fence, None);
    }
    tracer.release_staging();
    let overflowed = trace.take_overflowed_rays()?;
    let mapped = hit_memory.mapped_slice().ok_or("hits not mapped")?;
    let hits: Vec<Hit> = bytemuck::cast_slice(&mapped[..bytes]).to_vec();
    // The CPU reference caster agrees on every ray.
    let same = |(g, c): &(&Hit, Hit)| (g.id, g.t) == (c.id, c.t);
    let agree = hits
        .iter()
        .zip(rbvh.trace_cpu(&rays, Cones::None, false)?)
        .filter(same)
        .count();
    let hit_count = hits.iter().filter(|h| h.is_hit()).count();
    println!("{hit_count} of {} hit, {agree} as on the CPU", rays.len());

    // The library's objects go before the engine's device.
    drop((trace, tracer, ctx));
    unsafe {
        for (buffer, memory) in [(ray_buffer, ray_memory), (hit_buffer, hit_memory)] {
            allocator.lock().map_err(|_| "poisoned")?.free(memory)?;
            device.destroy_buffer(buffer, None);
        }
        drop(allocator);
        device.destroy_command_pool(pool, None);
        device.destroy_device(None);
        instance.destroy_instance(None);
    }
    if hit_count == 0 || overflowed > 0 || agree != rays.len() {
        return Err("no hits, an overflow, or a disagreement with the CPU".into());
    }
    Ok(())
}

/// A storage buffer of the engine's, host-visible.
fn engine_buffer(
    device: &ash::Device,
    allocator: &Arc<Mutex<Allocator>>,
    name: &str,
    size: usize,
) -> Result<(vk::Buffer, Allocation), Box<dyn Error>> {
    let info = vk::BufferCreateInfo::default()
        .size(size as u64)
        .usage(vk::BufferUsageFlags::STORAGE_BUFFER);
    let buffer = unsafe { device.create_buffer(&info, None)? };
    let requirements = unsafe { device.get_buffer_memory_requirements(buffer) };
    let desc = AllocationCreateDesc {
        name,
        requirements,
        location: MemoryLocation::CpuToGpu,
        linear: true,
        allocation_scheme: AllocationScheme::GpuAllocatorManaged,
    };
    let memory = allocator.lock().map_err(|_| "poisoned")?.allocate(&desc)?;
    unsafe { device.bind_buffer_memory(buffer, memory.memory(), memory.offset())? };
    Ok((buffer, memory))
}
