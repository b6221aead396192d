//! How shaders reach a structure's arrays: storage-buffer bindings, or buffer device addresses
//! for arrays beyond `maxStorageBufferRange` (issue #4: "respect `maxStorageBufferRange` — split
//! or use buffer device addresses for large scenes").
//!
//! Every trace and paint shader is built twice from one body: with bindings
//! (`glsl/trace_rbvh.comp`, …) and with `RBVH_DEVICE_ADDRESS` (`glsl/trace_rbvh_bda.comp`, …), where
//! the accessor macros of the GLSL headers read through `GL_EXT_buffer_reference` pointers whose
//! addresses come in the push constants. The per-trace buffers (rays, hits, status, steps, cones)
//! stay bound in both: the host splits them into batches that fit.

use crate::{Error, Result};

/// How the trace and paint shaders reach the arrays of a structure (nodes, triangles, leaves,
/// atlas, LOD records and columns, colour channel).
///
/// A storage-buffer binding covers at most `maxStorageBufferRange` bytes — 128 MiB on lavapipe and
/// on many mobile and integrated GPUs, 4 GiB on desktop GPUs — while a fine atlas can be larger.
/// Buffer device addresses (Vulkan 1.2, `VK_KHR_buffer_device_address`; GLSL
/// `GL_EXT_buffer_reference`) have no such range: one buffer can then be as large as
/// `maxMemoryAllocationSize`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Addressing {
    /// Bindings while every array fits `maxStorageBufferRange`, device addresses for a structure
    /// where one does not (when the device has them; otherwise a [`Error::DeviceLimit`]).
    #[default]
    Auto,
    /// Bindings only: an array over `maxStorageBufferRange` is a [`Error::DeviceLimit`].
    Bindings,
    /// Device addresses for every structure (an error on a device without `bufferDeviceAddress`).
    DeviceAddress,
}

impl Addressing {
    /// From `RBVH_ADDRESSING`: unset, empty or `auto` → Auto, `bindings` → Bindings, `device` →
    /// DeviceAddress (to try a device's address path, or to measure it against bindings).
    pub fn from_env() -> Result<Addressing> {
        let value = std::env::var("RBVH_ADDRESSING").unwrap_or_default();
        match value.to_ascii_lowercase().as_str() {
            "" | "auto" => Ok(Addressing::Auto),
            "bindings" => Ok(Addressing::Bindings),
            "device" => Ok(Addressing::DeviceAddress),
            _ => Err(Error::param(
                "RBVH_ADDRESSING",
                format!("{value:?} is not one of auto, bindings, device"),
            )),
        }
    }
}

/// How one structure's arrays reach its shader, as [`super::Context::reach`] decided.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Reach {
    /// Each array is a storage-buffer binding.
    Bindings,
    /// Each array is read through its buffer device address.
    DeviceAddresses,
}
