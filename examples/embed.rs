//! Plays the engine: creates its own Vulkan instance, device and `gpu-allocator` allocator,
//! generates camera rays with its own compute shader, records the library's RBVH trace into its own
//! command buffer between its own barriers, submits, and shades the hits into a PNG.
//!
//! `cargo run --release --example embed -- [out.png] [scene] [device|bindings]` (defaults:
//! `rbvh-embed.png` in the temporary directory, `default`, and `device`). With `device` the engine
//! is "bindless": it enables buffer device addresses on its device and allocator, when the device
//! has them, and asks the library to read its structures through them too; with `bindings` it
//! enables nothing and the library binds storage buffers. Runs under the validation layer when it
//! is installed and fails on any error it reports; `cargo test` runs it too (see Cargo.toml).

use std::error::Error;
use std::ffi::{c_void, CStr};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

use ash::vk;
use gpu_allocator::vulkan::{
    Allocation, AllocationCreateDesc, AllocationScheme, Allocator, AllocatorCreateDesc,
};
use gpu_allocator::MemoryLocation;
use rbvh::geom::{Hit, Ray};
use rbvh::gpu::{Addressing, BufferView, Context, External, Query, Reach, Tracer};
use rbvh::rbvh::{Rbvh, RbvhParams};
use rbvh::scene::Scene;
use rbvh::structure::Structure;

const WIDTH: u32 = 320;
const HEIGHT: u32 = 240;

/// The engine's ray generation: a pinhole camera, one ray per pixel, in the library's `Ray` layout.
const RAYGEN: &str = r#"
#version 460
layout(local_size_x = 64) in;
struct Ray { vec3 origin; float tmin; vec3 dir; float tmax; };
layout(std430, set = 0, binding = 0) writeonly buffer Rays { Ray rays[]; };
layout(push_constant) uniform Camera { vec4 eye; vec4 corner; vec4 du; vec4 dv; uint width; uint height; } cam;
void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= cam.width * cam.height) { return; }
    vec2 px = vec2(float(i % cam.width) + 0.5, float(i / cam.width) + 0.5);
    vec3 target = cam.corner.xyz + px.x * cam.du.xyz + px.y * cam.dv.xyz;
    rays[i] = Ray(cam.eye.xyz, 0.0, normalize(target - cam.eye.xyz), uintBitsToFloat(0x7F800000u));
}
"#;

static VALIDATION_ERRORS: AtomicUsize = AtomicUsize::new(0);

unsafe extern "system" fn on_message(
    severity: vk::DebugUtilsMessageSeverityFlagsEXT,
    _: vk::DebugUtilsMessageTypeFlagsEXT,
    data: *const vk::DebugUtilsMessengerCallbackDataEXT<'_>,
    _: *mut c_void,
) -> vk::Bool32 {
    if severity.contains(vk::DebugUtilsMessageSeverityFlagsEXT::ERROR) {
        VALIDATION_ERRORS.fetch_add(1, Ordering::SeqCst);
        let msg = unsafe { (*data).message_as_c_str() }.map(|m| m.to_string_lossy().into_owned());
        eprintln!("validation: {}", msg.unwrap_or_default());
    }
    vk::FALSE
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct CameraPush {
    eye: [f32; 4],
    corner: [f32; 4],
    du: [f32; 4],
    dv: [f32; 4],
    width: u32,
    height: u32,
}

fn main() -> Result<(), Box<dyn Error>> {
    let args: Vec<String> = std::env::args().collect();
    let out = args
        .get(1)
        .map(std::path::PathBuf::from)
        .unwrap_or_else(|| std::env::temp_dir().join("rbvh-embed.png"));
    let scene = Scene::load(args.get(2).map_or("default", String::as_str))?;
    let rbvh = Structure::from(Rbvh::build(&scene, &RbvhParams::quality(2)?)?);
    let bindless = match args.get(3).map_or("device", String::as_str) {
        "device" => true,
        "bindings" => false,
        other => return Err(format!("{other:?}: expected device or bindings").into()),
    };

    // --- The engine's own Vulkan setup -------------------------------------------------------
    let entry = unsafe { ash::Entry::load()? };
    let layer: &CStr = c"VK_LAYER_KHRONOS_validation";
    let validate = unsafe { entry.enumerate_instance_layer_properties()? }
        .iter()
        .any(|l| l.layer_name_as_c_str() == Ok(layer));
    let layers = if validate {
        vec![layer.as_ptr()]
    } else {
        vec![]
    };
    let extensions = if validate {
        vec![ash::ext::debug_utils::NAME.as_ptr()]
    } else {
        vec![]
    };
    let app = vk::ApplicationInfo::default().api_version(vk::API_VERSION_1_1);
    let instance = unsafe {
        entry.create_instance(
            &vk::InstanceCreateInfo::default()
                .application_info(&app)
                .enabled_layer_names(&layers)
                .enabled_extension_names(&extensions),
            None,
        )?
    };
    let debug = validate.then(|| ash::ext::debug_utils::Instance::new(&entry, &instance));
    let messenger = match &debug {
        Some(d) => Some(unsafe {
            d.create_debug_utils_messenger(
                &vk::DebugUtilsMessengerCreateInfoEXT::default()
                    .message_severity(vk::DebugUtilsMessageSeverityFlagsEXT::ERROR)
                    .message_type(
                        vk::DebugUtilsMessageTypeFlagsEXT::VALIDATION
                            | vk::DebugUtilsMessageTypeFlagsEXT::GENERAL,
                    )
                    .pfn_user_callback(Some(on_message)),
                None,
            )?
        }),
        None => None,
    };
    let physical_device = unsafe { instance.enumerate_physical_devices()? }
        .into_iter()
        .next()
        .ok_or("no Vulkan device")?;
    let queue_family =
        unsafe { instance.get_physical_device_queue_family_properties(physical_device) }
            .iter()
            .position(|f| f.queue_flags.contains(vk::QueueFlags::COMPUTE))
            .ok_or("no compute queue")? as u32;
    let priorities = [1.0];
    let queues = [vk::DeviceQueueCreateInfo::default()
        .queue_family_index(queue_family)
        .queue_priorities(&priorities)];
    // Device addresses through the KHR extension, so that a Vulkan 1.1 instance suffices.
    let has_addresses = unsafe { instance.enumerate_device_extension_properties(physical_device)? }
        .iter()
        .any(|e| e.extension_name_as_c_str() == Ok(ash::khr::buffer_device_address::NAME));
    let addresses = bindless && has_addresses;
    let device_extensions = [ash::khr::buffer_device_address::NAME.as_ptr()];
    let mut address_features =
        vk::PhysicalDeviceBufferDeviceAddressFeatures::default().buffer_device_address(true);
    let mut device_info = vk::DeviceCreateInfo::default().queue_create_infos(&queues);
    if addresses {
        device_info = device_info
            .enabled_extension_names(&device_extensions)
            .push_next(&mut address_features);
    }
    let device = unsafe { instance.create_device(physical_device, &device_info, None)? };
    let queue = unsafe { device.get_device_queue(queue_family, 0) };
    let allocator = Arc::new(Mutex::new(Allocator::new(&AllocatorCreateDesc {
        instance: instance.clone(),
        device: device.clone(),
        physical_device,
        debug_settings: Default::default(),
        buffer_device_address: addresses,
        allocation_sizes: Default::default(),
    })?));

    // The engine's buffers: rays written by its shader, hits written by the library; both
    // host-visible here so that the engine can shade on the CPU at the end.
    let count = WIDTH * HEIGHT;
    let bytes = count as u64 * 32;
    let (rays_buf, rays_mem) = engine_buffer(&device, &allocator, "engine rays", bytes)?;
    let (hits_buf, hits_mem) = engine_buffer(&device, &allocator, "engine hits", bytes)?;

    // The engine's ray-generation pipeline.
    let spirv = compile(RAYGEN)?;
    let binding = [vk::DescriptorSetLayoutBinding::default()
        .binding(0)
        .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
        .descriptor_count(1)
        .stage_flags(vk::ShaderStageFlags::COMPUTE)];
    let set_layout = unsafe {
        device.create_descriptor_set_layout(
            &vk::DescriptorSetLayoutCreateInfo::default().bindings(&binding),
            None,
        )?
    };
    let push_range = [vk::PushConstantRange::default()
        .stage_flags(vk::ShaderStageFlags::COMPUTE)
        .size(std::mem::size_of::<CameraPush>() as u32)];
    let set_layouts = [set_layout];
    let layout = unsafe {
        device.create_pipeline_layout(
            &vk::PipelineLayoutCreateInfo::default()
                .set_layouts(&set_layouts)
                .push_constant_ranges(&push_range),
            None,
        )?
    };
    let module = unsafe {
        device.create_shader_module(&vk::ShaderModuleCreateInfo::default().code(&spirv), None)?
    };
    let stage = vk::PipelineShaderStageCreateInfo::default()
        .stage(vk::ShaderStageFlags::COMPUTE)
        .module(module)
        .name(c"main");
    let pipeline = unsafe {
        device
            .create_compute_pipelines(
                vk::PipelineCache::null(),
                &[vk::ComputePipelineCreateInfo::default()
                    .stage(stage)
                    .layout(layout)],
                None,
            )
            .map_err(|(_, r)| r)?[0]
    };
    unsafe { device.destroy_shader_module(module, None) };
    let sizes = [vk::DescriptorPoolSize::default()
        .ty(vk::DescriptorType::STORAGE_BUFFER)
        .descriptor_count(1)];
    let pool = unsafe {
        device.create_descriptor_pool(
            &vk::DescriptorPoolCreateInfo::default()
                .max_sets(1)
                .pool_sizes(&sizes),
            None,
        )?
    };
    let set = unsafe {
        device.allocate_descriptor_sets(
            &vk::DescriptorSetAllocateInfo::default()
                .descriptor_pool(pool)
                .set_layouts(&set_layouts),
        )?[0]
    };
    let info = [vk::DescriptorBufferInfo::default()
        .buffer(rays_buf)
        .range(vk::WHOLE_SIZE)];
    unsafe {
        device.update_descriptor_sets(
            &[vk::WriteDescriptorSet::default()
                .dst_set(set)
                .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
                .buffer_info(&info)],
            &[],
        )
    };
    let command_pool = unsafe {
        device.create_command_pool(
            &vk::CommandPoolCreateInfo::default().queue_family_index(queue_family),
            None,
        )?
    };
    let cmd = unsafe {
        device.allocate_command_buffers(
            &vk::CommandBufferAllocateInfo::default()
                .command_pool(command_pool)
                .command_buffer_count(1),
        )?[0]
    };

    // --- The library, on the engine's device --------------------------------------------------
    let ctx = Context::embedded(External {
        instance: instance.clone(),
        device: device.clone(),
        physical_device,
        queue_family,
        allocator: allocator.clone(),
        buffer_device_address: addresses,
        addressing: if addresses {
            Addressing::DeviceAddress
        } else {
            Addressing::Auto
        },
    })?;
    unsafe { device.begin_command_buffer(cmd, &vk::CommandBufferBeginInfo::default())? };
    let mut tracer = Tracer::new_recorded(&ctx, &rbvh, cmd)?;
    let reach = tracer.reach();
    if addresses != (reach == Reach::DeviceAddresses) {
        return Err(format!("the library chose {reach:?}").into());
    }
    let mut trace = tracer.bind(
        BufferView {
            buffer: rays_buf,
            offset: 0,
        },
        BufferView {
            buffer: hits_buf,
            offset: 0,
        },
        count,
    )?;
    let camera = scene.camera_or_framed(WIDTH as f32 / HEIGHT as f32);
    let push = camera_push(&camera);
    unsafe {
        device.cmd_bind_pipeline(cmd, vk::PipelineBindPoint::COMPUTE, pipeline);
        device.cmd_bind_descriptor_sets(
            cmd,
            vk::PipelineBindPoint::COMPUTE,
            layout,
            0,
            &[set],
            &[],
        );
        device.cmd_push_constants(
            cmd,
            layout,
            vk::ShaderStageFlags::COMPUTE,
            0,
            bytemuck::bytes_of(&push),
        );
        device.cmd_dispatch(cmd, count.div_ceil(64), 1, 1);
        // The barrier the library documents before its trace: rays visible to compute reads.
        barrier(
            &device,
            cmd,
            vk::PipelineStageFlags::COMPUTE_SHADER,
            vk::AccessFlags::SHADER_READ,
        );
    }
    tracer.record(cmd, &trace, Query::Closest)?;
    unsafe {
        // ... and after it: hits visible to the host.
        barrier(
            &device,
            cmd,
            vk::PipelineStageFlags::HOST,
            vk::AccessFlags::HOST_READ,
        );
        device.end_command_buffer(cmd)?;
        let fence = device.create_fence(&vk::FenceCreateInfo::default(), None)?;
        let cmds = [cmd];
        device.queue_submit(
            queue,
            &[vk::SubmitInfo::default().command_buffers(&cmds)],
            fence,
        )?;
        device.wait_for_fences(&[fence], true, 60_000_000_000)?;
        device.destroy_fence(fence, None);
    }
    tracer.release_staging();
    let overflowed = trace.take_overflowed_rays()?;

    // --- The engine consumes the hits ---------------------------------------------------------
    let rays: Vec<Ray> =
        bytemuck::cast_slice(&rays_mem.mapped_slice().ok_or("rays not mapped")?[..bytes as usize])
            .to_vec();
    let hits: Vec<Hit> =
        bytemuck::cast_slice(&hits_mem.mapped_slice().ok_or("hits not mapped")?[..bytes as usize])
            .to_vec();
    let hit_count = hits.iter().filter(|h| h.is_hit()).count();
    let image = rbvh::output::shade(&rays, &hits, WIDTH, HEIGHT, scene.light.as_ref())?;
    rbvh::output::write_png(&out, &image)?;
    println!(
        "{hit_count} of {count} rays hit ({reach:?}); {overflowed} overflowed; wrote {}",
        out.display()
    );

    // --- Teardown, engine style: the library's objects first, then the engine's --------------
    drop(trace);
    drop(tracer);
    drop(ctx);
    unsafe {
        device.destroy_command_pool(command_pool, None);
        device.destroy_descriptor_pool(pool, None);
        device.destroy_pipeline(pipeline, None);
        device.destroy_pipeline_layout(layout, None);
        device.destroy_descriptor_set_layout(set_layout, None);
        for (buffer, memory) in [(rays_buf, rays_mem), (hits_buf, hits_mem)] {
            allocator
                .lock()
                .map_err(|_| "allocator poisoned")?
                .free(memory)?;
            device.destroy_buffer(buffer, None);
        }
    }
    drop(allocator);
    unsafe {
        device.destroy_device(None);
        if let (Some(d), Some(m)) = (&debug, messenger) {
            d.destroy_debug_utils_messenger(m, None);
        }
        instance.destroy_instance(None);
    }
    let errors = VALIDATION_ERRORS.load(Ordering::SeqCst);
    if errors > 0 {
        return Err(format!("the validation layer reported {errors} error(s)").into());
    }
    if hit_count == 0 || overflowed > 0 {
        return Err("the trace returned no hits or overflowed".into());
    }
    Ok(())
}

fn engine_buffer(
    device: &ash::Device,
    allocator: &Arc<Mutex<Allocator>>,
    name: &str,
    size: u64,
) -> Result<(vk::Buffer, Allocation), Box<dyn Error>> {
    let buffer = unsafe {
        device.create_buffer(
            &vk::BufferCreateInfo::default()
                .size(size)
                .usage(vk::BufferUsageFlags::STORAGE_BUFFER),
            None,
        )?
    };
    let requirements = unsafe { device.get_buffer_memory_requirements(buffer) };
    let memory = allocator
        .lock()
        .map_err(|_| "allocator poisoned")?
        .allocate(&AllocationCreateDesc {
            name,
            requirements,
            location: MemoryLocation::GpuToCpu,
            linear: true,
            allocation_scheme: AllocationScheme::GpuAllocatorManaged,
        })?;
    unsafe { device.bind_buffer_memory(buffer, memory.memory(), memory.offset())? };
    Ok((buffer, memory))
}

unsafe fn barrier(
    device: &ash::Device,
    cmd: vk::CommandBuffer,
    dst_stage: vk::PipelineStageFlags,
    dst_access: vk::AccessFlags,
) {
    let b = [vk::MemoryBarrier::default()
        .src_access_mask(vk::AccessFlags::SHADER_WRITE)
        .dst_access_mask(dst_access)];
    unsafe {
        device.cmd_pipeline_barrier(
            cmd,
            vk::PipelineStageFlags::COMPUTE_SHADER,
            dst_stage,
            vk::DependencyFlags::empty(),
            &b,
            &[],
            &[],
        )
    };
}

fn camera_push(c: &rbvh::scene::Camera) -> CameraPush {
    let forward = (c.target - c.eye).normalize();
    let right = forward.cross(c.up).normalize();
    let up = right.cross(forward);
    let h = (c.vfov_deg.to_radians() * 0.5).tan();
    let w = h * WIDTH as f32 / HEIGHT as f32;
    let corner = c.eye + forward - right * w + up * h;
    let v4 = |v: glam::Vec3| [v.x, v.y, v.z, 0.0];
    CameraPush {
        eye: v4(c.eye),
        corner: v4(corner),
        du: v4(right * (2.0 * w / WIDTH as f32)),
        dv: v4(-up * (2.0 * h / HEIGHT as f32)),
        width: WIDTH,
        height: HEIGHT,
    }
}

fn compile(source: &str) -> Result<Vec<u32>, Box<dyn Error>> {
    let compiler = shaderc::Compiler::new()?;
    let artifact = compiler.compile_into_spirv(
        source,
        shaderc::ShaderKind::Compute,
        "raygen.comp",
        "main",
        None,
    )?;
    Ok(artifact.as_binary().to_vec())
}
