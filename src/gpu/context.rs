//! The headless Vulkan context: instance, optional validation with a debug messenger, device
//! selection, one compute queue, a command pool and the `gpu-allocator` allocator.
//!
//! [`Context`] is a cheap handle (`Arc`); every buffer and pipeline keeps one, so the device and
//! instance are destroyed only after the last resource made from them — the correct order by
//! construction, whatever order the user drops things in.

use std::ffi::CStr;
#[cfg(feature = "loaded")]
use std::ffi::{c_char, c_void, CString};
use std::mem::ManuallyDrop;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use ash::vk;
use gpu_allocator::vulkan::Allocator;
#[cfg(feature = "loaded")]
use gpu_allocator::vulkan::AllocatorCreateDesc;

use super::{Addressing, Reach};
use crate::{Error, Result};

/// Whether to run the Khronos validation layer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Validation {
    /// Never load the layer (what [`Validation::from_env`] gives when `RBVH_VALIDATION` is unset).
    Off,
    /// On when `VK_LAYER_KHRONOS_validation` is installed, silently off otherwise.
    IfInstalled,
    /// On, and an error when the layer is missing.
    Required,
}

impl Validation {
    /// From `RBVH_VALIDATION`: `1`/`on`/`true`/`yes`/`required` → Required, `auto` →
    /// IfInstalled, unset, empty, `0`/`off`/`false`/`no` → Off; anything else an error naming the
    /// variable, since a misspelt request for the layer would otherwise turn it off unsaid.
    pub fn from_env() -> Result<Self> {
        let value = std::env::var("RBVH_VALIDATION").unwrap_or_default();
        match value.to_ascii_lowercase().as_str() {
            "1" | "on" | "true" | "yes" | "required" => Ok(Validation::Required),
            "auto" => Ok(Validation::IfInstalled),
            "" | "0" | "off" | "false" | "no" => Ok(Validation::Off),
            _ => Err(Error::param(
                "RBVH_VALIDATION",
                format!(
                    "{value:?} is not one of required (1, on, true, yes), auto, off (0, false, no)"
                ),
            )),
        }
    }
}

/// How to create a [`Context`].
#[derive(Clone, Debug)]
pub struct ContextOptions {
    /// Pick the first device whose name contains this (case-insensitive); `RBVH_DEVICE` when None.
    /// Without either, a discrete GPU is preferred, then integrated, virtual, and CPU (lavapipe).
    pub device_name: Option<String>,
    /// Whether to load the Khronos validation layer; `RBVH_VALIDATION` by default (Off when it
    /// is not understood; [`Validation::from_env`] reports that).
    pub validation: Validation,
    /// How shaders reach a structure's arrays; see [`Addressing`]. `RBVH_ADDRESSING` by default
    /// (Auto when it is unset or not understood; [`Addressing::from_env`] reports the latter).
    pub addressing: Addressing,
}

impl Default for ContextOptions {
    fn default() -> Self {
        ContextOptions {
            device_name: std::env::var("RBVH_DEVICE").ok().filter(|s| !s.is_empty()),
            validation: Validation::from_env().unwrap_or(Validation::Off),
            addressing: Addressing::from_env().unwrap_or_default(),
        }
    }
}

/// What the device can do that our code depends on.
#[derive(Clone, Copy, Debug)]
pub struct DeviceLimits {
    /// `maxStorageBufferRange`: the largest storage-buffer binding, bytes; larger arrays need
    /// device addresses ([`Addressing`]).
    pub max_storage_buffer_range: u64,
    /// The largest single allocation, which bounds a buffer read through its device address.
    pub max_memory_allocation_size: u64,
    /// Whether this context can read buffers through device addresses (the device has
    /// `bufferDeviceAddress` and this context enabled it, or the engine said it did).
    pub buffer_device_address: bool,
    /// `maxComputeWorkGroupCount`: workgroups per dispatch along x, y, z; the pipelines split
    /// larger dispatches along x.
    pub max_compute_work_group_count: [u32; 3],
    /// `maxPushConstantsSize`, bytes (at least 128 by the Vulkan spec).
    pub max_push_constants_size: u32,
    /// `minStorageBufferOffsetAlignment`, bytes: what a storage binding's offset must be a
    /// multiple of.
    pub min_storage_buffer_offset_alignment: u64,
    /// Nanoseconds per timestamp tick; None when the queue cannot time.
    pub timestamp_period_ns: Option<f64>,
    /// The queue's `timestampValidBits` (36 to 64 where it can time): timestamps wrap at
    /// `2^bits` ticks, so a difference is taken modulo that.
    pub timestamp_valid_bits: u32,
    /// Whether the device is a CPU implementation (lavapipe, SwiftShader). Such SIMD code runs
    /// every branch of a divergent `if` and every loop at least once, whether or not a lane needs
    /// it, so the tracers leave the march's block jumps out there ([`crate::gpu::Tracer`]).
    pub cpu: bool,
    /// Whether the device only compiles: RADV's null device ([`Error::CompileOnly`]), which is
    /// never chosen unless named. Pipelines are made as anywhere else, with their statistics;
    /// buffers and submissions fail with that error.
    pub compile_only: bool,
    /// Whether this context asked the driver for its pipelines' statistics
    /// (`VK_KHR_pipeline_executable_properties`, enabled where the device offers it; never for an
    /// embedded context): see [`crate::gpu::ComputePipeline::statistics`].
    pub pipeline_statistics: bool,
}

pub(crate) struct Shared {
    pub instance: ash::Instance,
    pub device: ash::Device,
    /// Dropped first in `Drop`, before the device it allocates from.
    pub allocator: ManuallyDrop<Arc<Mutex<Allocator>>>,
    pub limits: DeviceLimits,
    pub device_name: String,
    pub driver: String,
    pub addressing: Addressing,
    /// `vkGetBufferDeviceAddress` (core or KHR), when device addresses are enabled.
    pub get_address: Option<vk::PFN_vkGetBufferDeviceAddress>,
    /// What a standalone context created, and so destroys; None for an embedded context, which
    /// borrows the engine's instance and device and never submits.
    pub own: Option<Owned>,
}

/// The parts of a standalone context that an embedded one does not have.
pub(crate) struct Owned {
    /// Keeps libvulkan loaded for as long as any handle lives.
    pub _entry: ash::Entry,
    pub debug: Option<(ash::ext::debug_utils::Instance, vk::DebugUtilsMessengerEXT)>,
    /// Boxed so its address, handed to the messenger callback, stays put.
    pub messages: Box<Mutex<Vec<String>>>,
    pub queue: vk::Queue,
    pub command_pool: vk::CommandPool,
    /// Serialises use of `command_pool` and `queue` (both externally synchronised in Vulkan).
    pub submit_lock: Mutex<()>,
    /// How long [`Context::submit`] waits for a submission, in nanoseconds
    /// ([`Context::set_submit_timeout`]).
    pub submit_timeout_ns: AtomicU64,
    /// The pass whose submission did not finish, and why: from then on the context is lost
    /// ([`Error::DeviceLost`]).
    pub lost: Mutex<Option<(String, String)>>,
}

/// An engine's own Vulkan objects, for [`Context::embedded`]. The engine keeps them alive (and
/// destroys them) after every `rbvh` object made from the context is dropped.
pub struct External {
    /// The engine's instance (Vulkan 1.1 or later).
    pub instance: ash::Instance,
    /// The engine's logical device, created from `physical_device`.
    pub device: ash::Device,
    /// The physical device behind `device`; its limits become [`Context::limits`].
    pub physical_device: vk::PhysicalDevice,
    /// The family of the queue the engine will submit the recorded commands on (it must support
    /// compute).
    pub queue_family: u32,
    /// The engine's `gpu-allocator` allocator for `device`; every library buffer is allocated
    /// from it.
    pub allocator: Arc<Mutex<Allocator>>,
    /// Whether the engine enabled the `bufferDeviceAddress` feature on `device` (Vulkan 1.2 or
    /// `VK_KHR_buffer_device_address`) and created `allocator` with `buffer_device_address`: the
    /// context then reads structures too large for a storage-buffer binding through device
    /// addresses ([`Addressing::Auto`]); without, they are a [`Error::DeviceLimit`].
    pub buffer_device_address: bool,
    /// How the library's shaders reach structures ([`Addressing::DeviceAddress`] needs
    /// `buffer_device_address`).
    pub addressing: Addressing,
}

/// A Vulkan device ready for compute. Cloning shares it.
#[derive(Clone)]
pub struct Context {
    pub(crate) shared: Arc<Shared>,
}

impl std::fmt::Debug for Context {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Context")
            .field("device", &self.shared.device_name)
            .field("driver", &self.shared.driver)
            .finish()
    }
}

impl Context {
    /// Wraps an engine's own instance, device and allocator. Nothing is created but what the
    /// library's own objects need (buffers, pipelines, descriptor sets), all through the engine's
    /// allocator and device; nothing is ever submitted — the tracer records into the engine's
    /// command buffers ([`crate::gpu::Tracer::new_recorded`], [`crate::gpu::Tracer::record`]) — and
    /// nothing of the engine's is destroyed. Validation is the engine's business: its messenger
    /// sees our calls like its own.
    pub fn embedded(external: External) -> Result<Context> {
        let families = unsafe {
            external
                .instance
                .get_physical_device_queue_family_properties(external.physical_device)
        };
        let compute = families
            .get(external.queue_family as usize)
            .is_some_and(|f| f.queue_flags.contains(vk::QueueFlags::COMPUTE));
        if !compute {
            return Err(Error::param(
                "queue_family",
                format!(
                    "{} is not a compute queue family of this device",
                    external.queue_family
                ),
            ));
        }
        let (mut limits, device_name, driver) = describe(
            &external.instance,
            external.physical_device,
            external.queue_family,
        );
        if external.addressing == Addressing::DeviceAddress && !external.buffer_device_address {
            return Err(Error::param(
                "addressing",
                "Addressing::DeviceAddress needs buffer_device_address (the engine's device and \
                 allocator with device addresses)",
            ));
        }
        let get_address = if external.buffer_device_address {
            let found = address_function(&external.instance, &external.device);
            if found.is_none() {
                return Err(Error::param(
                    "buffer_device_address",
                    "the device has neither vkGetBufferDeviceAddress nor \
                     vkGetBufferDeviceAddressKHR: enable Vulkan 1.2 or VK_KHR_buffer_device_address",
                ));
            }
            found
        } else {
            None
        };
        limits.buffer_device_address = get_address.is_some();
        Ok(Context {
            shared: Arc::new(Shared {
                instance: external.instance,
                device: external.device,
                allocator: ManuallyDrop::new(external.allocator),
                limits,
                device_name,
                driver,
                addressing: external.addressing,
                get_address,
                own: None,
            }),
        })
    }
}

#[cfg(feature = "loaded")]
const VALIDATION_LAYER: &CStr = c"VK_LAYER_KHRONOS_validation";

#[cfg(feature = "loaded")]
unsafe extern "system" fn debug_callback(
    severity: vk::DebugUtilsMessageSeverityFlagsEXT,
    _types: vk::DebugUtilsMessageTypeFlagsEXT,
    data: *const vk::DebugUtilsMessengerCallbackDataEXT<'_>,
    user: *mut c_void,
) -> vk::Bool32 {
    if severity.contains(vk::DebugUtilsMessageSeverityFlagsEXT::ERROR)
        && !data.is_null()
        && !user.is_null()
    {
        // SAFETY: `user` is the boxed mutex owned by `Shared`, which outlives the messenger.
        let sink = unsafe { &*(user as *const Mutex<Vec<String>>) };
        let msg = unsafe { (*data).message_as_c_str() }
            .map(|m| m.to_string_lossy().into_owned())
            .unwrap_or_default();
        if let Ok(mut v) = sink.lock() {
            v.push(msg);
        }
    }
    vk::FALSE
}

impl Context {
    /// Creates an instance and device of its own, headless (feature `loaded`, on by default).
    #[cfg(feature = "loaded")]
    pub fn new(options: &ContextOptions) -> Result<Context> {
        // SAFETY: loading libvulkan runs its initialisers; this is the documented way with ash.
        let entry = unsafe { ash::Entry::load() }.map_err(|e| Error::Loader(e.to_string()))?;
        let layer_present = unsafe { entry.enumerate_instance_layer_properties() }
            .map_err(|r| Error::vk("vkEnumerateInstanceLayerProperties", "instance", r))?
            .iter()
            .any(|l| l.layer_name_as_c_str() == Ok(VALIDATION_LAYER));
        let validate = match options.validation {
            Validation::Off => false,
            Validation::IfInstalled => layer_present,
            Validation::Required if layer_present => true,
            Validation::Required => {
                return Err(Error::NoDevice(
                    "validation was required but VK_LAYER_KHRONOS_validation is not installed \
                     (Debian: apt-get install vulkan-validationlayers)"
                        .into(),
                ))
            }
        };
        let app_name = CString::new("rbvh").expect("static name");
        let app = vk::ApplicationInfo::default()
            .application_name(&app_name)
            .engine_name(&app_name)
            .api_version(vk::API_VERSION_1_1);
        let layers = if validate {
            vec![VALIDATION_LAYER.as_ptr()]
        } else {
            vec![]
        };
        let extensions = if validate {
            vec![ash::ext::debug_utils::NAME.as_ptr()]
        } else {
            vec![]
        };
        let create = vk::InstanceCreateInfo::default()
            .application_info(&app)
            .enabled_layer_names(&layers)
            .enabled_extension_names(&extensions);
        let instance = unsafe { entry.create_instance(&create, None) }
            .map_err(|r| Error::vk("vkCreateInstance", "instance", r))?;
        // From here on, a failure must destroy what exists: build `Shared` step by step.
        let mut partial = Partial {
            entry: Some(entry),
            instance: Some(instance),
            debug: None,
            messages: Box::new(Mutex::new(Vec::new())),
        };
        if validate {
            partial.attach_messenger()?;
        }
        partial.finish(options)
    }

    /// The device's name as the driver reports it (`VkPhysicalDeviceProperties::deviceName`).
    pub fn device_name(&self) -> &str {
        &self.shared.device_name
    }

    /// Driver name and version as the driver reports them.
    pub fn driver(&self) -> &str {
        &self.shared.driver
    }

    /// The device's limits that this crate checks against, read once at creation.
    pub fn limits(&self) -> &DeviceLimits {
        &self.shared.limits
    }

    /// How shaders reach structures made with this context.
    pub fn addressing(&self) -> Addressing {
        self.shared.addressing
    }

    /// Whether this context's own validation messenger is attached (never for an embedded one).
    pub fn validation_enabled(&self) -> bool {
        self.shared.own.as_ref().is_some_and(|o| o.debug.is_some())
    }

    /// Whether this context borrows an engine's device ([`Context::embedded`]): it then never
    /// submits, and work is recorded into the engine's command buffers instead.
    pub fn is_embedded(&self) -> bool {
        self.shared.own.is_none()
    }

    /// The raw device, for callers that record their own commands.
    pub fn device(&self) -> &ash::Device {
        &self.shared.device
    }

    /// Errors reported by the validation layer since the last check, as an error value.
    /// [`Context::submit`] and pipeline creation check after their own calls (naming their
    /// pass), and a submission before its own, so that its errors are not taken for those of
    /// calls made since the last submission (an upload's buffer, a descriptor set).
    pub fn check_validation(&self) -> Result<()> {
        self.check_validation_of("the calls since the last check")
    }

    /// [`Context::check_validation`], the error saying its messages came `during` this.
    pub(crate) fn check_validation_of(&self, during: &str) -> Result<()> {
        let Some(own) = &self.shared.own else {
            return Ok(());
        };
        let messages = std::mem::take(&mut *own.messages.lock().unwrap_or_else(|p| p.into_inner()));
        if messages.is_empty() {
            Ok(())
        } else {
            Err(Error::Validation {
                during: during.to_string(),
                messages,
            })
        }
    }

    /// Fails with [`Error::DeviceLost`], saying it cannot do `what`, once a submission did not
    /// finish, and with [`Error::CompileOnly`] on a device that only compiles
    /// ([`DeviceLimits::compile_only`]).
    pub fn check_runnable(&self, what: &str) -> Result<()> {
        if let Some(lost) = self.lost_error(what) {
            return Err(lost);
        }
        if self.shared.limits.compile_only {
            return Err(Error::CompileOnly {
                device: self.shared.device_name.clone(),
                what: what.to_string(),
            });
        }
        Ok(())
    }

    /// Fails with [`Error::DeviceLimit`] when a storage buffer of `bytes` exceeds the device's
    /// `maxStorageBufferRange` (lavapipe does not enforce it; real GPUs and validation do).
    pub fn check_storage_range(&self, resource: &str, bytes: u64, hint: &str) -> Result<()> {
        let available = self.shared.limits.max_storage_buffer_range;
        if bytes > available {
            return Err(Error::DeviceLimit {
                resource: resource.to_string(),
                limit: "maxStorageBufferRange",
                required: bytes,
                available,
                hint: hint.to_string(),
            });
        }
        Ok(())
    }
}

#[cfg(feature = "loaded")]
/// The instance-level half of a context under construction; cleans up on early return.
struct Partial {
    entry: Option<ash::Entry>,
    instance: Option<ash::Instance>,
    debug: Option<(ash::ext::debug_utils::Instance, vk::DebugUtilsMessengerEXT)>,
    messages: Box<Mutex<Vec<String>>>,
}

#[cfg(feature = "loaded")]
impl Drop for Partial {
    fn drop(&mut self) {
        // SAFETY: only reached on failure, when nothing else holds these handles.
        unsafe {
            if let Some((loader, messenger)) = self.debug.take() {
                loader.destroy_debug_utils_messenger(messenger, None);
            }
            if let Some(instance) = self.instance.take() {
                instance.destroy_instance(None);
            }
        }
    }
}

#[cfg(feature = "loaded")]
impl Partial {
    fn instance(&self) -> &ash::Instance {
        self.instance
            .as_ref()
            .expect("instance exists until finish")
    }

    fn attach_messenger(&mut self) -> Result<()> {
        let loader = ash::ext::debug_utils::Instance::new(
            self.entry.as_ref().expect("entry"),
            self.instance(),
        );
        let info = vk::DebugUtilsMessengerCreateInfoEXT::default()
            .message_severity(
                vk::DebugUtilsMessageSeverityFlagsEXT::ERROR
                    | vk::DebugUtilsMessageSeverityFlagsEXT::WARNING,
            )
            .message_type(
                vk::DebugUtilsMessageTypeFlagsEXT::GENERAL
                    | vk::DebugUtilsMessageTypeFlagsEXT::VALIDATION
                    | vk::DebugUtilsMessageTypeFlagsEXT::PERFORMANCE,
            )
            .pfn_user_callback(Some(debug_callback))
            .user_data(&*self.messages as *const Mutex<Vec<String>> as *mut c_void);
        let messenger = unsafe { loader.create_debug_utils_messenger(&info, None) }
            .map_err(|r| Error::vk("vkCreateDebugUtilsMessengerEXT", "validation messenger", r))?;
        self.debug = Some((loader, messenger));
        Ok(())
    }

    fn finish(mut self, options: &ContextOptions) -> Result<Context> {
        let instance = self.instance().clone();
        let (physical_device, queue_family) =
            pick_device(&instance, options.device_name.as_deref())?;
        let (mut limits, device_name, driver) = describe(&instance, physical_device, queue_family);
        let addresses = has_buffer_device_address(&instance, physical_device);
        if options.addressing == Addressing::DeviceAddress && !addresses {
            return Err(Error::NoDevice(format!(
                "{device_name} has no bufferDeviceAddress (VK_KHR_buffer_device_address), which \
                 Addressing::DeviceAddress needs"
            )));
        }
        let priorities = [1.0f32];
        let queue_info = [vk::DeviceQueueCreateInfo::default()
            .queue_family_index(queue_family)
            .queue_priorities(&priorities)];
        let statistics = offers_pipeline_statistics(&instance, physical_device);
        let extensions: Vec<*const c_char> = [
            addresses.then_some(ash::khr::buffer_device_address::NAME),
            statistics.then_some(ash::khr::pipeline_executable_properties::NAME),
        ]
        .into_iter()
        .flatten()
        .map(|name| name.as_ptr())
        .collect();
        let mut address_features =
            vk::PhysicalDeviceBufferDeviceAddressFeatures::default().buffer_device_address(true);
        let mut statistics_features =
            vk::PhysicalDevicePipelineExecutablePropertiesFeaturesKHR::default()
                .pipeline_executable_info(true);
        let mut device_info = vk::DeviceCreateInfo::default()
            .queue_create_infos(&queue_info)
            .enabled_extension_names(&extensions);
        if addresses {
            device_info = device_info.push_next(&mut address_features);
        }
        if statistics {
            device_info = device_info.push_next(&mut statistics_features);
        }
        let device = unsafe { instance.create_device(physical_device, &device_info, None) }
            .map_err(|r| Error::vk("vkCreateDevice", device_name.clone(), r))?;
        let get_address = if addresses {
            address_function(&instance, &device)
        } else {
            None
        };
        limits.buffer_device_address = get_address.is_some();
        limits.pipeline_statistics = statistics;
        let queue = unsafe { device.get_device_queue(queue_family, 0) };
        let pool_info = vk::CommandPoolCreateInfo::default()
            .queue_family_index(queue_family)
            .flags(vk::CommandPoolCreateFlags::RESET_COMMAND_BUFFER);
        let command_pool = match unsafe { device.create_command_pool(&pool_info, None) } {
            Ok(p) => p,
            Err(r) => {
                unsafe { device.destroy_device(None) };
                return Err(Error::vk("vkCreateCommandPool", "command pool", r));
            }
        };
        let allocator = Allocator::new(&AllocatorCreateDesc {
            instance: instance.clone(),
            device: device.clone(),
            physical_device,
            debug_settings: Default::default(),
            buffer_device_address: get_address.is_some(),
            allocation_sizes: Default::default(),
        });
        let allocator = match allocator {
            Ok(a) => a,
            Err(e) => {
                unsafe {
                    device.destroy_command_pool(command_pool, None);
                    device.destroy_device(None);
                }
                return Err(Error::Allocation {
                    resource: "allocator".into(),
                    size: 0,
                    source: e,
                });
            }
        };
        let shared = Shared {
            instance: self.instance.take().expect("instance"),
            device,
            allocator: ManuallyDrop::new(Arc::new(Mutex::new(allocator))),
            limits,
            device_name,
            driver,
            addressing: options.addressing,
            get_address,
            own: Some(Owned {
                _entry: self.entry.take().expect("entry"),
                debug: self.debug.take(),
                messages: std::mem::replace(&mut self.messages, Box::new(Mutex::new(Vec::new()))),
                queue,
                command_pool,
                submit_lock: Mutex::new(()),
                submit_timeout_ns: AtomicU64::new(DEFAULT_SUBMIT_TIMEOUT_NS),
                lost: Mutex::new(None),
            }),
        };
        Ok(Context {
            shared: Arc::new(shared),
        })
    }
}

/// Name, driver and the limits our code depends on, of `pd` with compute queue `family`.
fn describe(
    instance: &ash::Instance,
    pd: vk::PhysicalDevice,
    family: u32,
) -> (DeviceLimits, String, String) {
    let props = unsafe { instance.get_physical_device_properties(pd) };
    let device_name = props
        .device_name_as_c_str()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let driver = driver_string(instance, pd, &props);
    let families = unsafe { instance.get_physical_device_queue_family_properties(pd) };
    let timestamp_bits = families
        .get(family as usize)
        .map_or(0, |f| f.timestamp_valid_bits);
    let mut maintenance3 = vk::PhysicalDeviceMaintenance3Properties::default();
    let mut props2 = vk::PhysicalDeviceProperties2::default().push_next(&mut maintenance3);
    unsafe { instance.get_physical_device_properties2(pd, &mut props2) };
    let limits = DeviceLimits {
        max_storage_buffer_range: props.limits.max_storage_buffer_range as u64,
        max_memory_allocation_size: maintenance3.max_memory_allocation_size,
        buffer_device_address: false,
        max_compute_work_group_count: props.limits.max_compute_work_group_count,
        max_push_constants_size: props.limits.max_push_constants_size,
        min_storage_buffer_offset_alignment: props.limits.min_storage_buffer_offset_alignment,
        timestamp_period_ns: (timestamp_bits > 0 && props.limits.timestamp_period > 0.0)
            .then_some(props.limits.timestamp_period as f64),
        timestamp_valid_bits: timestamp_bits,
        cpu: props.device_type == vk::PhysicalDeviceType::CPU,
        compile_only: is_null_device(instance, pd),
        pipeline_statistics: false,
    };
    (limits, device_name, driver)
}

/// Whether `pd` offers `VK_KHR_pipeline_executable_properties` with `pipelineExecutableInfo`.
#[cfg(feature = "loaded")]
fn offers_pipeline_statistics(instance: &ash::Instance, pd: vk::PhysicalDevice) -> bool {
    if !offers_extension(instance, pd, ash::khr::pipeline_executable_properties::NAME) {
        return false;
    }
    let mut executable = vk::PhysicalDevicePipelineExecutablePropertiesFeaturesKHR::default();
    let mut features = vk::PhysicalDeviceFeatures2::default().push_next(&mut executable);
    unsafe { instance.get_physical_device_features2(pd, &mut features) };
    executable.pipeline_executable_info == vk::TRUE
}

/// Whether `pd` lists the device extension `name`.
fn offers_extension(instance: &ash::Instance, pd: vk::PhysicalDevice, name: &CStr) -> bool {
    unsafe { instance.enumerate_device_extension_properties(pd) }
        .unwrap_or_default()
        .iter()
        .any(|e| e.extension_name_as_c_str() == Ok(name))
}

/// The driver's `VkDriverId`, where the device reports it (Vulkan 1.2 or
/// `VK_KHR_driver_properties`).
fn driver_id(instance: &ash::Instance, pd: vk::PhysicalDevice) -> Option<vk::DriverId> {
    if !offers_extension(instance, pd, ash::khr::driver_properties::NAME) {
        return None;
    }
    let mut driver = vk::PhysicalDeviceDriverProperties::default();
    let mut props2 = vk::PhysicalDeviceProperties2::default().push_next(&mut driver);
    unsafe { instance.get_physical_device_properties2(pd, &mut props2) };
    Some(driver.driver_id)
}

/// Whether `pd` is RADV's null device: while `RADV_FORCE_FAMILY` is set, Mesa's RADV enumerates
/// that device alone ("null hardware" of the family named, with AMD's real compiler behind it)
/// in place of any AMD GPU, so a RADV device then is the null one.
fn is_null_device(instance: &ash::Instance, pd: vk::PhysicalDevice) -> bool {
    std::env::var_os("RADV_FORCE_FAMILY").is_some_and(|f| !f.is_empty())
        && driver_id(instance, pd) == Some(vk::DriverId::MESA_RADV)
}

fn driver_string(
    instance: &ash::Instance,
    pd: vk::PhysicalDevice,
    props: &vk::PhysicalDeviceProperties,
) -> String {
    let mut driver = vk::PhysicalDeviceDriverProperties::default();
    // The driver's name is Vulkan 1.2 or VK_KHR_driver_properties; a device with neither gets
    // only its API version, rather than a query the validation layer would flag.
    if offers_extension(instance, pd, ash::khr::driver_properties::NAME) {
        let mut props2 = vk::PhysicalDeviceProperties2::default().push_next(&mut driver);
        unsafe { instance.get_physical_device_properties2(pd, &mut props2) };
    }
    let name = driver
        .driver_name_as_c_str()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let info = driver
        .driver_info_as_c_str()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let api = props.api_version;
    format!(
        "{name} {info} (Vulkan {}.{}.{})",
        vk::api_version_major(api),
        vk::api_version_minor(api),
        vk::api_version_patch(api)
    )
    .trim()
    .to_string()
}

#[cfg(feature = "loaded")]
/// Whether `pd` offers `VK_KHR_buffer_device_address` with its `bufferDeviceAddress` feature (every
/// Vulkan 1.2 device does; a 1.1 device may). Extension and feature are what this crate's own
/// context enables, so that a Vulkan 1.1 instance suffices.
fn has_buffer_device_address(instance: &ash::Instance, pd: vk::PhysicalDevice) -> bool {
    if !offers_extension(instance, pd, ash::khr::buffer_device_address::NAME) {
        return false;
    }
    let mut address = vk::PhysicalDeviceBufferDeviceAddressFeatures::default();
    let mut features = vk::PhysicalDeviceFeatures2::default().push_next(&mut address);
    unsafe { instance.get_physical_device_features2(pd, &mut features) };
    address.buffer_device_address == vk::TRUE
}

/// `vkGetBufferDeviceAddress` of `device`: the KHR command where the extension is enabled (as this
/// crate's own context does, on a Vulkan 1.1 instance), else the core one (an engine's Vulkan 1.2
/// device without the extension).
fn address_function(
    instance: &ash::Instance,
    device: &ash::Device,
) -> Option<vk::PFN_vkGetBufferDeviceAddress> {
    [c"vkGetBufferDeviceAddressKHR", c"vkGetBufferDeviceAddress"]
        .iter()
        .find_map(|name| {
            // SAFETY: both names have the signature of PFN_vkGetBufferDeviceAddress.
            unsafe { instance.get_device_proc_addr(device.handle(), name.as_ptr()) }
                .map(|f| unsafe { std::mem::transmute::<_, vk::PFN_vkGetBufferDeviceAddress>(f) })
        })
}

#[cfg(feature = "loaded")]
/// Chooses a device with a compute queue: by name when asked, else by type preference.
fn pick_device(
    instance: &ash::Instance,
    wanted: Option<&str>,
) -> Result<(vk::PhysicalDevice, u32)> {
    let devices = unsafe { instance.enumerate_physical_devices() }
        .map_err(|r| Error::vk("vkEnumeratePhysicalDevices", "instance", r))?;
    let mut candidates = Vec::new();
    for pd in devices {
        let props = unsafe { instance.get_physical_device_properties(pd) };
        let name = props
            .device_name_as_c_str()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        let families = unsafe { instance.get_physical_device_queue_family_properties(pd) };
        // Prefer a compute queue that can also time (timestamps) — every lavapipe/GPU queue can.
        let family = families
            .iter()
            .enumerate()
            .filter(|(_, f)| f.queue_flags.contains(vk::QueueFlags::COMPUTE))
            .max_by_key(|(_, f)| f.timestamp_valid_bits > 0)
            .map(|(i, _)| i as u32);
        let rank = match props.device_type {
            vk::PhysicalDeviceType::DISCRETE_GPU => 0,
            vk::PhysicalDeviceType::INTEGRATED_GPU => 1,
            vk::PhysicalDeviceType::VIRTUAL_GPU => 2,
            vk::PhysicalDeviceType::CPU => 3,
            _ => 4,
        };
        if props.api_version < vk::API_VERSION_1_1 {
            continue;
        }
        if let Some(family) = family {
            candidates.push((rank, name, pd, family, is_null_device(instance, pd)));
        }
    }
    let names = || {
        candidates
            .iter()
            .map(|c| c.1.clone())
            .collect::<Vec<_>>()
            .join(", ")
    };
    if candidates.is_empty() {
        return Err(Error::NoDevice(
            "no Vulkan 1.1 device with a compute queue (for a CPU device: apt-get install mesa-vulkan-drivers)".into(),
        ));
    }
    if let Some(w) = wanted {
        let w = w.to_lowercase();
        return candidates
            .iter()
            .find(|c| c.1.to_lowercase().contains(&w))
            .map(|c| (c.2, c.3))
            .ok_or_else(|| {
                Error::NoDevice(format!(
                    "no device name contains {w:?}; available: {}",
                    names()
                ))
            });
    }
    // A device that only compiles is taken when named, never by preference.
    match candidates.iter().min_by_key(|c| (c.4, c.0)) {
        Some(c) if !c.4 => Ok((c.2, c.3)),
        _ => Err(Error::NoDevice(format!(
            "the only device, {}, is RADV's null device (RADV_FORCE_FAMILY is set): it compiles \
             pipelines but cannot run them; name it to compile only (`rbvh shaders --device \
             RADV`), or unset RADV_FORCE_FAMILY",
            names()
        ))),
    }
}

impl Drop for Shared {
    fn drop(&mut self) {
        // A lost context's device may still run the submission that did not finish, on memory
        // the allocator would free and a device we would destroy: all of it is left to the
        // driver (the process's end) instead (Error::DeviceLost). Its own parts too, which
        // dropping the fields would free: the loader's library (closing libvulkan under the
        // device) and the messages the validation messenger still writes to.
        if self.is_lost() {
            std::mem::forget(self.own.take());
            return;
        }
        // SAFETY: the last handle is gone, so no buffer, pipeline or submission of ours is alive.
        // The allocator (our reference to it) goes before the device it allocates from; an owned
        // context then destroys its pool, device, messenger and instance, in that order.
        unsafe {
            // Nothing ever ran on a device that only compiles, and RADV's null device crashes
            // in vkDeviceWaitIdle.
            if self.own.is_some() && !self.limits.compile_only {
                let _ = self.device.device_wait_idle();
            }
            ManuallyDrop::drop(&mut self.allocator);
            if let Some(mut own) = self.own.take() {
                self.device.destroy_command_pool(own.command_pool, None);
                self.device.destroy_device(None);
                if let Some((loader, messenger)) = own.debug.take() {
                    loader.destroy_debug_utils_messenger(messenger, None);
                }
                self.instance.destroy_instance(None);
            }
        }
    }
}

impl Context {
    /// How a structure with `arrays` (name, bytes) reaches its shader under this context's
    /// [`Addressing`], checked before anything is uploaded: an array too large for the chosen way
    /// is a [`Error::DeviceLimit`] naming it, the limit and what would help.
    pub fn reach(&self, arrays: &[(&str, u64)]) -> Result<Reach> {
        let limits = self.limits();
        let over_range = arrays
            .iter()
            .any(|&(_, bytes)| bytes > limits.max_storage_buffer_range);
        let reach = match self.addressing() {
            Addressing::DeviceAddress => Reach::DeviceAddresses,
            Addressing::Auto if over_range && limits.buffer_device_address => {
                Reach::DeviceAddresses
            }
            Addressing::Auto | Addressing::Bindings => Reach::Bindings,
        };
        for &(name, bytes) in arrays {
            match reach {
                Reach::Bindings => {
                    let hint = match self.addressing() {
                        Addressing::Bindings => {
                            "the context was made with Addressing::Bindings; Addressing::Auto reads \
                             such arrays through buffer device addresses"
                        }
                        _ => {
                            "this device has no bufferDeviceAddress to read larger arrays through; \
                             lower the quality or the scene's size"
                        }
                    };
                    self.check_storage_range(name, bytes, hint)?;
                }
                Reach::DeviceAddresses => {
                    if bytes > limits.max_memory_allocation_size {
                        return Err(Error::DeviceLimit {
                            resource: name.to_string(),
                            limit: "maxMemoryAllocationSize",
                            required: bytes,
                            available: limits.max_memory_allocation_size,
                            hint: "one array must fit one allocation: lower the quality or the \
                                   scene's size"
                                .into(),
                        });
                    }
                }
            }
        }
        Ok(reach)
    }
}

/// How long one submission may take before we call it hung, unless
/// [`Context::set_submit_timeout`] says otherwise. Every shader loop is bounded, so only a driver
/// fault (or a dispatch far larger than any the harness makes) gets here; the error names the
/// pass instead of hanging the process.
const DEFAULT_SUBMIT_TIMEOUT_NS: u64 = 600 * 1_000_000_000;

impl Context {
    /// How long [`Context::submit`] waits for one submission (600 s unless set): past it, the
    /// submission is taken for hung and the context for lost ([`Error::DeviceLost`]), rather
    /// than the process waiting on a faulty driver for ever. Every shader loop is bounded, so a
    /// submission that takes longer is a device fault or a dispatch far beyond the harness's.
    /// An embedded context never submits, and this changes nothing there.
    pub fn set_submit_timeout(&self, timeout: Duration) {
        if let Some(own) = &self.shared.own {
            let ns = u64::try_from(timeout.as_nanos()).unwrap_or(u64::MAX);
            own.submit_timeout_ns.store(ns, Ordering::Relaxed);
        }
    }

    /// Whether a submission of this context did not finish ([`Error::DeviceLost`]): it then
    /// runs nothing more, and frees none of its objects.
    pub fn is_lost(&self) -> bool {
        self.shared.is_lost()
    }

    /// The error that a lost context gives for `what`; None while it is not lost.
    pub(crate) fn lost_error(&self, what: &str) -> Option<Error> {
        let lost = self
            .shared
            .own
            .as_ref()?
            .lost
            .lock()
            .unwrap_or_else(|p| p.into_inner());
        lost.as_ref().map(|(pass, reason)| Error::DeviceLost {
            what: what.to_string(),
            pass: pass.clone(),
            reason: reason.clone(),
        })
    }
}

impl Shared {
    /// Whether a submission did not finish: the device may still run it, so nothing it might
    /// use is freed ([`Error::DeviceLost`]).
    pub(crate) fn is_lost(&self) -> bool {
        self.own
            .as_ref()
            .is_some_and(|own| own.lost.lock().unwrap_or_else(|p| p.into_inner()).is_some())
    }
}
