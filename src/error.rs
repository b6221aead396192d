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
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A file was read but its content is malformed. `line` is 1-based when known.
    #[error("{}{}: {message}", path.display(), line.map(|l| format!(":{l}")).unwrap_or_default())]
    Parse {
        path: PathBuf,
        line: Option<usize>,
        message: String,
    },
    /// Geometry that cannot be traced: NaN/inf vertices, out-of-range indices.
    #[error("{source_name}: {message}")]
    InvalidGeometry {
        source_name: String,
        message: String,
    },
    /// A scene name that is neither a built-in scene nor an existing file.
    #[error("unknown scene {name:?}: not a file, and not a built-in scene (built-in: {known})")]
    UnknownScene { name: String, known: String },
    /// A user parameter out of its documented range.
    #[error("invalid {name}: {message}")]
    InvalidParameter { name: String, message: String },
    /// The Vulkan loader (libvulkan) could not be loaded.
    #[error("cannot load the Vulkan loader (is libvulkan1 installed?): {0}")]
    Loader(String),
    /// No usable Vulkan device, or the requested one is not present.
    #[error("no suitable Vulkan device: {0}")]
    NoDevice(String),
    /// A Vulkan call failed; `resource` says what it was for.
    #[error("Vulkan {call} failed for {resource}: {result}")]
    Vulkan {
        call: &'static str,
        resource: String,
        result: vk::Result,
    },
    /// Device memory could not be allocated.
    #[error("allocating {size} bytes of device memory for {resource} failed: {source}")]
    Allocation {
        resource: String,
        size: u64,
        #[source]
        source: gpu_allocator::AllocationError,
    },
    /// The scene or request exceeds a limit of the device.
    #[error("{resource} needs {required} but the device's {limit} is {available}: {hint}")]
    DeviceLimit {
        resource: String,
        limit: &'static str,
        required: u64,
        available: u64,
        hint: String,
    },
    /// The Vulkan validation layers reported errors (only when they are enabled).
    #[error("Vulkan validation reported {} error(s):\n{}", messages.len(), messages.join("\n"))]
    Validation { messages: Vec<String> },
    /// A traversal was cut short on the GPU for some rays — its stack overflowed, or the device
    /// ended a shader loop early (lavapipe stops an invocation's loops after 65535 iterations) —
    /// so their hits are not trustworthy.
    #[error("traversal of {rays} ray(s) in {resource} was cut short: the stack ({depth} entries) overflowed because the tree is deeper than the stack, or the device ended the traversal loop early (lavapipe stops shader loops after 65535 iterations; trace such rays with the CPU reference)")]
    StackOverflow {
        resource: String,
        depth: u32,
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
