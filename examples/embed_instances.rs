//! Instances in the engine's own device: one mesh placed 400 times, traced through the two-level
//! exact BVH, and animated: each frame the engine moves every instance, the library rebuilds the
//! top level alone (`InstancedBvh::set_transforms`) and records its upload and the trace into the
//! engine's command buffer (`Tracer::update_instances_recorded`, `Tracer::record`). The meshes'
//! trees are built and uploaded once. Prints what a frame's update costs on the host; the hits of
//! every frame are checked against the CPU twin. `cargo test` runs it too (see Cargo.toml);
//! `examples/embed_minimal.rs` is the same engine with an RBVH.

use std::error::Error;
use std::sync::{Arc, Mutex};
use std::time::Instant;

use rbvh::ash;
use rbvh::ash::vk::{self, PipelineStageFlags as Stage};
use rbvh::glam::{Mat4, Quat, Vec3};
use rbvh::gpu::{Addressing, BufferView};
use rbvh::gpu_allocator::vulkan::{
    Allocation, AllocationCreateDesc, AllocationScheme, Allocator, AllocatorCreateDesc,
};
use rbvh::gpu_allocator::MemoryLocation;
use rbvh::{Context, External, Hit, Query, Ray, Scene, Structure, Tracer};
use rbvh::{Instance, InstancedBvh, InstancedScene};

/// Instances along each side of the grid.
const SIDE: u32 = 20;
/// Frames animated.
const FRAMES: u32 = 4;

/// Instance `k`'s placement at `frame`: a grid of turning, bobbing copies.
fn placement(k: u32, frame: u32) -> Mat4 {
    let (x, z) = ((k % SIDE) as f32 - 0.5 * SIDE as f32, (k / SIDE) as f32);
    let phase = 0.3 * k as f32 + 0.5 * frame as f32;
    Mat4::from_scale_rotation_translation(
        Vec3::splat(0.4),
        Quat::from_rotation_y(phase),
        Vec3::new(x, 0.2 * phase.sin(), -z),
    )
}

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
    let pool_info = vk::CommandPoolCreateInfo::default()
        .queue_family_index(queue_family)
        .flags(vk::CommandPoolCreateFlags::RESET_COMMAND_BUFFER);
    let pool = unsafe { device.create_command_pool(&pool_info, None)? };
    let cmd_info = vk::CommandBufferAllocateInfo::default()
        .command_pool(pool)
        .command_buffer_count(1);
    let cmd = unsafe { device.allocate_command_buffers(&cmd_info)?[0] };

    // The scene: one mesh, held once, placed SIDE × SIDE times.
    let mut scene = InstancedScene {
        name: "grid of blobs".into(),
        meshes: vec![Scene::load("bumpy-sphere")?],
        instances: (0..SIDE * SIDE)
            .map(|k| Instance {
                mesh: 0,
                transform: placement(k, 0),
            })
            .collect(),
        ..InstancedScene::default()
    };
    let mut bvh = InstancedBvh::build(&scene)?;
    let eye = Vec3::new(0.0, 4.0, 6.0);
    let rays: Vec<Ray> = (0..64 * 64)
        .map(|i| {
            let (u, v) = ((i % 64) as f32 / 63.0 - 0.5, (i / 64) as f32 / 63.0);
            let target = Vec3::new(1.6 * SIDE as f32 * u, 0.0, -(SIDE as f32) * v);
            Ray::new(eye, target - eye, 0.0, f32::INFINITY)
        })
        .collect();
    let bytes = std::mem::size_of_val(rays.as_slice());
    let (ray_buffer, mut ray_memory) = engine_buffer(&device, &allocator, "rays", bytes)?;
    let (hit_buffer, hit_memory) = engine_buffer(&device, &allocator, "hits", bytes)?;
    let mapped = ray_memory.mapped_slice_mut().ok_or("rays not mapped")?;
    mapped[..bytes].copy_from_slice(bytemuck::cast_slice(&rays));

    let ctx = Context::embedded(External {
        instance: instance.clone(),
        device: device.clone(),
        physical_device,
        queue_family,
        allocator: allocator.clone(),
        buffer_device_address: false,
        addressing: Addressing::Auto,
    })?;
    let mut tracer = None;
    let mut failures = 0;
    for frame in 0..FRAMES {
        unsafe { device.begin_command_buffer(cmd, &vk::CommandBufferBeginInfo::default())? };
        // The first frame uploads the whole structure; the others move the instances.
        let update = Instant::now();
        let tracer = match tracer.as_mut() {
            None => tracer.insert(Tracer::new_recorded(
                &ctx,
                &Structure::from(bvh.clone()),
                cmd,
            )?),
            Some(tracer) => {
                let moved: Vec<Mat4> = (0..SIDE * SIDE).map(|k| placement(k, frame)).collect();
                bvh.set_transforms(&moved)?;
                tracer.update_instances_recorded(&bvh, cmd)?;
                for (instance, m) in scene.instances.iter_mut().zip(moved) {
                    instance.transform = m;
                }
                tracer
            }
        };
        let update_ms = update.elapsed().as_secs_f64() * 1e3;
        let view = |buffer| BufferView { buffer, offset: 0 };
        let mut trace = tracer.bind(view(ray_buffer), view(hit_buffer), rays.len() as u32)?;
        tracer.record(cmd, &trace, Query::Closest)?;
        let to_host = [vk::MemoryBarrier::default()
            .src_access_mask(vk::AccessFlags::SHADER_WRITE)
            .dst_access_mask(vk::AccessFlags::HOST_READ)];
        unsafe {
            let (compute, host) = (Stage::COMPUTE_SHADER, Stage::HOST);
            device.cmd_pipeline_barrier(cmd, compute, host, Default::default(), &to_host, &[], &[]);
            device.end_command_buffer(cmd)?;
            let fence = device.create_fence(&vk::FenceCreateInfo::default(), None)?;
            let submit = [vk::SubmitInfo::default().command_buffers(std::slice::from_ref(&cmd))];
            device.queue_submit(queue, &submit, fence)?;
            device.wait_for_fences(&[fence], true, u64::MAX)?;
            device.destroy_fence(fence, None);
            device.reset_command_buffer(cmd, vk::CommandBufferResetFlags::empty())?;
        }
        tracer.release_staging();
        let overflowed = trace.take_overflowed_rays()?;
        let mapped = hit_memory.mapped_slice().ok_or("hits not mapped")?;
        let hits: &[Hit] = bytemuck::cast_slice(&mapped[..bytes]);
        let agree = hits
            .iter()
            .zip(&rays)
            .filter(|(g, r)| {
                let c = bvh.closest_hit(r).0;
                (g.id, g.instance, g.t) == (c.id, c.instance, c.t)
            })
            .count();
        let hit_count = hits.iter().filter(|h| h.is_hit()).count();
        println!(
            "frame {frame}: {} instances, top level and upload recorded in {update_ms:.2} ms; \
             {hit_count} of {} rays hit, {agree} as on the CPU",
            scene.instances.len(),
            rays.len()
        );
        if hit_count == 0 || overflowed > 0 || agree != rays.len() {
            failures += 1;
        }
    }

    // The library's objects go before the engine's device.
    drop((tracer, ctx));
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
    if failures > 0 {
        return Err(format!("{failures} frames without hits, overflowing or disagreeing").into());
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
