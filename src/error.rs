//! The library's one error type. Every variant names *what* failed and *where* (a file, a
//! resource, a parameter), so that a user can act on the message without a debugger.

use std::path::PathBuf;

use ash::vk;

/// Everything the library can fail with.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A file could not be read or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file (or directory) that was being opened, read, written or created.
        path: PathBuf,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
    /// A file was read but its content is malformed. `line` is 1-based when known.
    #[error("{}{}: {message}", path.display(), line.map(|l| format!(":{l}")).unwrap_or_default())]
    Parse {
        /// The malformed file.
        path: PathBuf,
        /// 1-based line of the problem in a text format; `None` for binary formats or whole-file
        /// problems.
        line: Option<usize>,
        /// What is wrong, e.g. which record is cut short or which index is out of range.
        message: String,
    },
    /// Geometry that cannot be traced: NaN/inf vertices, out-of-range indices.
    #[error("{source_name}: {message}")]
    InvalidGeometry {
        /// The scene's name or file (with `:line` when the loader knows it).
        source_name: String,
        /// The first offending element (vertex or triangle) and what is wrong with it.
        message: String,
    },
    /// A scene name that is neither a built-in scene nor an existing file.
    #[error("unknown scene {name:?}: not a file, and not a built-in scene (built-in: {known})")]
    UnknownScene {
        /// The name as given by the caller.
        name: String,
        /// The built-in scene names, comma-separated, to show the alternatives.
        known: String,
    },
    /// A user parameter out of its documented range.
    #[error("invalid {name}: {message}")]
    InvalidParameter {
        /// The parameter at fault as the user knows it, e.g. an
        /// [`RbvhParams`](crate::rbvh::RbvhParams) field, or `"scene"` when the input is too large.
        name: String,
        /// The value given and why it is rejected, usually with the valid range.
        message: String,
    },
    /// The Vulkan loader (libvulkan) could not be loaded.
    #[error("cannot load the Vulkan loader (is libvulkan1 installed?): {0}")]
    Loader(String),
    /// No usable Vulkan device, or the requested one is not present.
    #[error("no suitable Vulkan device: {0}")]
    NoDevice(String),
    /// A Vulkan call failed; `resource` says what it was for.
    #[error("Vulkan {call} failed for {resource}: {result}")]
    Vulkan {
        /// The Vulkan entry point that failed, e.g. `"vkCreateComputePipelines"`.
        call: &'static str,
        /// What the call was for: a pipeline, buffer or `"instance"`.
        resource: String,
        /// The `VkResult` the call returned.
        result: vk::Result,
    },
    /// Device memory could not be allocated.
    #[error("allocating {size} bytes of device memory for {resource} failed: {source}")]
    Allocation {
        /// The buffer the memory was for (`"allocator"` when the allocator itself failed).
        resource: String,
        /// Bytes requested; 0 when the allocator itself could not be created.
        size: u64,
        /// The allocator's error.
        #[source]
        source: gpu_allocator::AllocationError,
    },
    /// The scene or request exceeds a limit of the device.
    #[error("{resource} needs {required} but the device's {limit} is {available}: {hint}")]
    DeviceLimit {
        /// The buffer or pipeline that does not fit.
        resource: String,
        /// The `VkPhysicalDeviceLimits` field exceeded, e.g. `"maxStorageBufferRange"`.
        limit: &'static str,
        /// What the resource needs, in the limit's unit (bytes for buffer and push-constant
        /// limits).
        required: u64,
        /// The device's value of `limit`.
        available: u64,
        /// What the user can do about it, e.g. lower the quality or the scene's size.
        hint: String,
    },
    /// The Vulkan validation layers reported errors (only when they are enabled).
    #[error("Vulkan validation reported {} error(s) during {during}:\n{}", messages.len(), messages.join("\n"))]
    Validation {
        /// The pass (a submission, a pipeline's creation) whose calls they came from.
        during: String,
        /// The layers' error messages, in the order they were reported.
        messages: Vec<String>,
    },
    /// The device compiles pipelines but cannot allocate memory or run anything: RADV's "null
    /// hardware" device, which Mesa offers (alone of its AMD devices) while `RADV_FORCE_FAMILY`
    /// names a GPU family, for reading what AMD's compiler makes of the shaders
    /// ([`crate::gpu::compile_every_pipeline`]).
    #[error("{device} compiles pipelines but cannot run them, so it cannot {what}: it is RADV's null device, offered while RADV_FORCE_FAMILY is set; `rbvh shaders` reports what it compiles, and a device that runs is used when RADV_FORCE_FAMILY is unset or another device is named (--device, RBVH_DEVICE)")]
    CompileOnly {
        /// The device's name.
        device: String,
        /// What was asked of it.
        what: String,
    },
    /// A submission did not finish: the device reported itself lost, or gave no result within
    /// the context's timeout ([`Context::set_submit_timeout`](crate::Context::set_submit_timeout)).
    /// The device may still be running it, so from then on the context runs nothing (every
    /// submission and allocation gives this error, `what` naming it) and frees none of its
    /// objects, which the process's end returns to the driver.
    #[error("{what}: the Vulkan context is lost, since {pass} did not finish ({reason}); it runs nothing more, and its objects are left to the driver rather than freed while the device may still use them: create a new context")]
    DeviceLost {
        /// What was asked: the pass that did not finish, or a later one refused.
        what: String,
        /// The submission that did not finish.
        pass: String,
        /// Why it is taken for unfinished: the timeout, or the `VkResult` of the wait.
        reason: String,
    },
    /// A traversal was cut short on the GPU for some rays — its stack overflowed, or the device
    /// ended a shader loop early (lavapipe stops an invocation's loops after 65535 iterations) —
    /// so their hits are not trustworthy.
    #[error("traversal of {rays} ray(s) in {resource} was cut short: the stack ({depth} entries) overflowed because the tree is deeper than the stack, or the device ended the traversal loop early (lavapipe stops shader loops after 65535 iterations; trace such rays with the CPU reference)")]
    StackOverflow {
        /// The traversal pipeline that cut them short.
        resource: String,
        /// Entries in the shaders' traversal stack ([`bvh::STACK_SIZE`](crate::bvh::STACK_SIZE)).
        depth: u32,
        /// How many rays of the dispatch were cut short.
        rays: u32,
    },
}

/// The library's result type.
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    pub(crate) fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            source,
        }
    }

    pub(crate) fn parse(
        path: impl Into<PathBuf>,
        line: Option<usize>,
        message: impl Into<String>,
    ) -> Self {
        Error::Parse {
            path: path.into(),
            line,
            message: message.into(),
        }
    }

    pub(crate) fn param(name: impl Into<String>, message: impl Into<String>) -> Self {
        Error::InvalidParameter {
            name: name.into(),
            message: message.into(),
        }
    }

    pub(crate) fn vk(call: &'static str, resource: impl Into<String>, result: vk::Result) -> Self {
        Error::Vulkan {
            call,
            resource: resource.into(),
            result,
        }
    }
}
