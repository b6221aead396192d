//! Storage buffers through `gpu-allocator`. Data goes in and out directly where device memory is
//! host-visible and coherent (lavapipe, resizable-BAR GPUs), and through a staging buffer and a
//! transfer command everywhere else (discrete GPUs).

use ash::vk;
use gpu_allocator::vulkan::{Allocation, AllocationCreateDesc, AllocationScheme};
use gpu_allocator::MemoryLocation;

use super::Context;
use crate::progress::{Progress, Quiet};
use crate::{Error, Result};

/// Bytes written per step of an upload: the progress it reports moves this often, and no staging
/// buffer is larger (a 1.8 GB exact BVH goes through one 64 MiB staging buffer, not a copy of
/// itself in host memory).
const UPLOAD_CHUNK: usize = 64 << 20;

/// A device buffer. Dropping it frees its memory; it keeps its [`Context`] alive meanwhile.
pub struct Buffer {
    ctx: Context,
    name: String,
    raw: vk::Buffer,
    allocation: Option<Allocation>,
    size: u64,
}

impl std::fmt::Debug for Buffer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Buffer")
            .field("name", &self.name)
            .field("size", &self.size)
            .finish()
    }
}

impl Buffer {
    /// The Vulkan handle, for binding or recording commands; valid while `self` lives.
    pub fn raw(&self) -> vk::Buffer {
        self.raw
    }

    /// Size in bytes as created: the requested size, but at least 4.
    pub fn size(&self) -> u64 {
        self.size
    }

    /// The name given at creation, used in error messages and allocator reports.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The buffer's device address, for shaders that read it through `GL_EXT_buffer_reference`;
    /// None unless the context has device addresses ([`super::DeviceLimits::buffer_device_address`]).
    pub fn device_address(&self) -> Option<u64> {
        let get = self.ctx.shared.get_address?;
        let info = vk::BufferDeviceAddressInfo::default().buffer(self.raw);
        // SAFETY: the buffer is alive and was created with SHADER_DEVICE_ADDRESS usage (every
        // storage buffer is, on a context with device addresses).
        Some(unsafe { get(self.ctx.shared.device.handle(), &info) })
    }

    /// The context the buffer belongs to.
    pub fn context(&self) -> &Context {
        &self.ctx
    }

    /// Mapped, coherent memory of this buffer, when it has some.
    fn host_slice_mut(&mut self) -> Option<&mut [u8]> {
        let a = self.allocation.as_mut()?;
        if !a
            .memory_properties()
            .contains(vk::MemoryPropertyFlags::HOST_COHERENT)
        {
            return None;
        }
        let size = self.size as usize;
        a.mapped_slice_mut().map(|s| &mut s[..size])
    }
}

impl Drop for Buffer {
    fn drop(&mut self) {
        let s = &self.ctx.shared;
        if s.is_lost() {
            // The device may still use it (Error::DeviceLost): left to the driver.
            return;
        }
        if let Some(a) = self.allocation.take() {
            // An error here means a double free inside gpu-allocator's bookkeeping; nothing to do.
            let _ = s
                .allocator
                .lock()
                .unwrap_or_else(|p| p.into_inner())
                .free(a);
        }
        // SAFETY: every submission that used the buffer was waited on before returning.
        unsafe { s.device.destroy_buffer(self.raw, None) };
    }
}

/// A write made ready for an engine's command buffer ([`Context::prepare_write`]): nothing left
/// to do where the buffer's memory took the bytes at once, else a staging buffer holding them
/// and the copy's destination and size, which [`PreparedWrite::record`] records.
#[must_use = "the copy is not recorded until PreparedWrite::record"]
pub(crate) struct PreparedWrite {
    copy: Option<(Buffer, vk::Buffer, u64)>,
}

impl PreparedWrite {
    /// Whether the bytes are already in the buffer (its memory host-visible): no copy to record.
    pub(crate) fn is_done(&self) -> bool {
        self.copy.is_none()
    }

    /// Records the copy from the staging buffer into `cmd` (in the recording state), if any, and
    /// returns that staging buffer, which must live until `cmd` has executed.
    pub(crate) fn record(self, ctx: &Context, cmd: vk::CommandBuffer) -> Option<Buffer> {
        let (staging, dst, size) = self.copy?;
        if size > 0 {
            let region = [vk::BufferCopy::default().size(size)];
            // SAFETY: `cmd` is recording (the caller's contract); the staging buffer is returned
            // to outlive it, and the destination is the caller's buffer, which must too.
            unsafe {
                ctx.shared
                    .device
                    .cmd_copy_buffer(cmd, staging.raw, dst, &region)
            };
        }
        Some(staging)
    }
}

impl Context {
    /// Creates a buffer of at least `size` bytes (Vulkan forbids empty buffers, so 0 becomes 4).
    pub fn create_buffer(
        &self,
        name: &str,
        size: u64,
        usage: vk::BufferUsageFlags,
        location: MemoryLocation,
    ) -> Result<Buffer> {
        self.check_runnable(&format!("allocate {name}"))?;
        let size = size.max(4);
        let device = &self.shared.device;
        let usage = if self.shared.get_address.is_some()
            && usage.contains(vk::BufferUsageFlags::STORAGE_BUFFER)
        {
            usage | vk::BufferUsageFlags::SHADER_DEVICE_ADDRESS
        } else {
            usage
        };
        let info = vk::BufferCreateInfo::default()
            .size(size)
            .usage(usage)
            .sharing_mode(vk::SharingMode::EXCLUSIVE);
        let raw = unsafe { device.create_buffer(&info, None) }
            .map_err(|r| Error::vk("vkCreateBuffer", name, r))?;
        let requirements = unsafe { device.get_buffer_memory_requirements(raw) };
        let allocation = self
            .shared
            .allocator
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .allocate(&AllocationCreateDesc {
                name,
                requirements,
                location,
                linear: true,
                allocation_scheme: AllocationScheme::GpuAllocatorManaged,
            });
        let allocation = match allocation {
            Ok(a) => a,
            Err(source) => {
                unsafe { device.destroy_buffer(raw, None) };
                return Err(Error::Allocation {
                    resource: name.to_string(),
                    size,
                    source,
                });
            }
        };
        // Own the buffer from here on, so that a bind failure frees both.
        let buffer = Buffer {
            ctx: self.clone(),
            name: name.to_string(),
            raw,
            allocation: Some(allocation),
            size,
        };
        let a = buffer.allocation.as_ref().expect("just set");
        unsafe { device.bind_buffer_memory(raw, a.memory(), a.offset()) }
            .map_err(|r| Error::vk("vkBindBufferMemory", name, r))?;
        Ok(buffer)
    }

    /// A device-local storage buffer holding `data`, checked against `maxStorageBufferRange`.
    pub fn upload_storage<T: bytemuck::Pod>(&self, name: &str, data: &[T]) -> Result<Buffer> {
        let bytes: &[u8] = bytemuck::cast_slice(data);
        self.check_storage_range(
            name,
            bytes.len() as u64,
            "split the work into smaller batches or a smaller scene",
        )?;
        self.upload_unchecked(name, bytes)
    }

    /// As [`Context::upload_storage`], without the range check: for arrays whose reach the caller
    /// has checked ([`Context::reach`]).
    pub(crate) fn upload_unchecked(&self, name: &str, bytes: &[u8]) -> Result<Buffer> {
        self.upload_observed(name, bytes, &Quiet)
    }

    /// As [`Context::upload_unchecked`], telling `progress` of the bytes as they are written (the
    /// caller begins and ends the step).
    pub(crate) fn upload_observed(
        &self,
        name: &str,
        bytes: &[u8],
        progress: &dyn Progress,
    ) -> Result<Buffer> {
        let usage = vk::BufferUsageFlags::STORAGE_BUFFER
            | vk::BufferUsageFlags::TRANSFER_DST
            | vk::BufferUsageFlags::TRANSFER_SRC;
        let mut buffer =
            self.create_buffer(name, bytes.len() as u64, usage, MemoryLocation::GpuOnly)?;
        self.write_observed(&mut buffer, bytes, progress)?;
        Ok(buffer)
    }

    /// Records into `cmd` (in the recording state) a barrier that makes transfer writes (recorded
    /// uploads) visible to compute shaders, which read and write what was uploaded.
    pub fn record_transfer_to_compute(&self, cmd: vk::CommandBuffer) {
        self.record_barrier(
            cmd,
            (
                vk::PipelineStageFlags::TRANSFER,
                vk::AccessFlags::TRANSFER_WRITE,
            ),
            (
                vk::PipelineStageFlags::COMPUTE_SHADER,
                vk::AccessFlags::SHADER_READ | vk::AccessFlags::SHADER_WRITE,
            ),
        );
    }

    /// Records into `cmd` (recording) a barrier that makes the compute shaders' writes recorded
    /// before it visible to those recorded after it, which read and write the same memory: what
    /// painting again over an earlier recording's paint needs (`Painter::record`).
    pub fn record_compute_to_compute(&self, cmd: vk::CommandBuffer) {
        self.record_barrier(
            cmd,
            (
                vk::PipelineStageFlags::COMPUTE_SHADER,
                vk::AccessFlags::SHADER_WRITE,
            ),
            (
                vk::PipelineStageFlags::COMPUTE_SHADER,
                vk::AccessFlags::SHADER_READ | vk::AccessFlags::SHADER_WRITE,
            ),
        );
    }

    /// Records into `cmd` (recording) a barrier that makes the compute shaders' reads recorded
    /// before it finish before transfers recorded after it write: what rewriting a buffer that
    /// earlier traces read needs (`Tracer::update_instances_recorded`).
    pub fn record_compute_to_transfer(&self, cmd: vk::CommandBuffer) {
        self.record_barrier(
            cmd,
            (
                vk::PipelineStageFlags::COMPUTE_SHADER,
                vk::AccessFlags::SHADER_READ,
            ),
            (
                vk::PipelineStageFlags::TRANSFER,
                vk::AccessFlags::TRANSFER_WRITE,
            ),
        );
    }

    /// One global memory barrier from `(stage, access)` `before` to `after`, recorded into `cmd`.
    fn record_barrier(
        &self,
        cmd: vk::CommandBuffer,
        before: (vk::PipelineStageFlags, vk::AccessFlags),
        after: (vk::PipelineStageFlags, vk::AccessFlags),
    ) {
        let barrier = [vk::MemoryBarrier::default()
            .src_access_mask(before.1)
            .dst_access_mask(after.1)];
        // SAFETY: `cmd` is recording (the callers' contract).
        unsafe {
            self.device().cmd_pipeline_barrier(
                cmd,
                before.0,
                after.0,
                vk::DependencyFlags::empty(),
                &barrier,
                &[],
                &[],
            )
        };
    }

    /// A device-local storage buffer holding `data`, for an embedded context that never submits:
    /// written directly where the memory is host-visible, otherwise through a staging buffer whose
    /// copy is *recorded* into `cmd` (in the recording state). The staging buffer is returned and
    /// must live until `cmd` has executed; the caller also orders the copy before its readers.
    pub fn upload_storage_recorded<T: bytemuck::Pod>(
        &self,
        name: &str,
        data: &[T],
        cmd: vk::CommandBuffer,
    ) -> Result<(Buffer, Option<Buffer>)> {
        let bytes: &[u8] = bytemuck::cast_slice(data);
        self.check_storage_range(
            name,
            bytes.len() as u64,
            "split the work into smaller batches or a smaller scene",
        )?;
        let (buffer, write) = self.upload_unchecked_prepared(name, bytes)?;
        Ok((buffer, write.record(self, cmd)))
    }

    /// [`Context::upload_storage_recorded`]'s fallible half, without the range check (for arrays
    /// whose reach the caller has checked, [`Context::reach`]): the buffer, and its bytes written
    /// or staged ([`Context::prepare_write`]), for a recording call to record the copy once
    /// nothing can fail.
    pub(crate) fn upload_unchecked_prepared(
        &self,
        name: &str,
        bytes: &[u8],
    ) -> Result<(Buffer, PreparedWrite)> {
        // TRANSFER_SRC too: a painter's colours are read back by a copy where the memory is
        // not host-visible (`Painter::colours`).
        let usage = vk::BufferUsageFlags::STORAGE_BUFFER
            | vk::BufferUsageFlags::TRANSFER_DST
            | vk::BufferUsageFlags::TRANSFER_SRC;
        let mut buffer =
            self.create_buffer(name, bytes.len() as u64, usage, MemoryLocation::GpuOnly)?;
        let write = self.prepare_write(&mut buffer, bytes)?;
        Ok((buffer, write))
    }

    /// Writes `bytes` at the start of `buffer` (made with `TRANSFER_DST` usage) for an embedded
    /// context that never submits: directly where its memory is host-visible, otherwise through a
    /// staging buffer whose copy is *recorded* into `cmd` (in the recording state). The staging
    /// buffer is returned and must live until `cmd` has executed; the caller orders the copy
    /// after the buffer's last readers and before its next ones. More bytes than the buffer
    /// holds are an error, and an error records nothing.
    pub fn write_recorded(
        &self,
        buffer: &mut Buffer,
        bytes: &[u8],
        cmd: vk::CommandBuffer,
    ) -> Result<Option<Buffer>> {
        Ok(self.prepare_write(buffer, bytes)?.record(self, cmd))
    }

    /// [`Context::write_recorded`]'s fallible half: checks the bytes fit, then writes them
    /// where `buffer`'s memory is host-visible or fills a staging buffer with them, recording
    /// nothing. The library's recording calls take every fallible step before they record any
    /// copy ([`PreparedWrite::record`]), so that an error leaves the engine's command buffer as
    /// it was, not holding copies into buffers the error freed.
    pub(crate) fn prepare_write(&self, buffer: &mut Buffer, bytes: &[u8]) -> Result<PreparedWrite> {
        fits(buffer, bytes)?;
        self.check_runnable(&format!("write {}", buffer.name))?;
        if let Some(dst) = buffer.host_slice_mut() {
            dst[..bytes.len()].copy_from_slice(bytes);
            return Ok(PreparedWrite { copy: None });
        }
        let staging_name = format!("staging for {}", buffer.name);
        let mut staging = self.create_buffer(
            &staging_name,
            bytes.len().max(4) as u64,
            vk::BufferUsageFlags::TRANSFER_SRC,
            MemoryLocation::CpuToGpu,
        )?;
        staging.host_slice_mut().ok_or_else(|| {
            Error::NoDevice(format!("{staging_name}: no host-visible coherent memory"))
        })?[..bytes.len()]
            .copy_from_slice(bytes);
        Ok(PreparedWrite {
            copy: Some((staging, buffer.raw, bytes.len() as u64)),
        })
    }

    /// A host-visible storage buffer of `size` bytes, zero-filled from the host (no submission):
    /// small status words that the host reads back after the device wrote them.
    pub fn host_storage(&self, name: &str, size: u64) -> Result<Buffer> {
        let usage = vk::BufferUsageFlags::STORAGE_BUFFER;
        let mut buffer = self.create_buffer(name, size, usage, MemoryLocation::GpuToCpu)?;
        buffer
            .host_slice_mut()
            .ok_or_else(|| Error::NoDevice(format!("{name}: no host-visible coherent memory")))?
            .fill(0);
        Ok(buffer)
    }

    /// A device-local storage buffer of `size` bytes, zero-filled.
    pub fn zeroed_storage(&self, name: &str, size: u64) -> Result<Buffer> {
        self.check_storage_range(name, size, "split the work into smaller batches")?;
        let usage = vk::BufferUsageFlags::STORAGE_BUFFER
            | vk::BufferUsageFlags::TRANSFER_DST
            | vk::BufferUsageFlags::TRANSFER_SRC;
        let buffer = self.create_buffer(name, size, usage, MemoryLocation::GpuOnly)?;
        let raw = buffer.raw;
        self.submit(&format!("clear {name}"), |device, cmd| unsafe {
            device.cmd_fill_buffer(cmd, raw, 0, vk::WHOLE_SIZE, 0);
        })?;
        Ok(buffer)
    }

    /// Writes `bytes` at the start of `buffer`, directly or through a staging buffer; more bytes
    /// than the buffer holds are an error.
    pub fn write(&self, buffer: &mut Buffer, bytes: &[u8]) -> Result<()> {
        self.write_observed(buffer, bytes, &Quiet)
    }

    /// [`Context::write`] in steps of [`UPLOAD_CHUNK`] bytes, each reported to `progress` once
    /// written; through a staging buffer, each step is one copy submitted and waited for, so the
    /// staging buffer is reused and holds at most one step.
    fn write_observed(
        &self,
        buffer: &mut Buffer,
        bytes: &[u8],
        progress: &dyn Progress,
    ) -> Result<()> {
        fits(buffer, bytes)?;
        // A lost context's device may still read it (Error::DeviceLost).
        self.check_runnable(&format!("write {}", buffer.name))?;
        if bytes.is_empty() {
            return Ok(());
        }
        if let Some(dst) = buffer.host_slice_mut() {
            for (dst, chunk) in dst.chunks_mut(UPLOAD_CHUNK).zip(bytes.chunks(UPLOAD_CHUNK)) {
                dst[..chunk.len()].copy_from_slice(chunk);
                progress.advance(chunk.len() as u64);
            }
            return Ok(());
        }
        let name = format!("staging for {}", buffer.name);
        let mut staging = self.create_buffer(
            &name,
            bytes.len().min(UPLOAD_CHUNK) as u64,
            vk::BufferUsageFlags::TRANSFER_SRC,
            MemoryLocation::CpuToGpu,
        )?;
        let (src, dst) = (staging.raw, buffer.raw);
        for (k, chunk) in bytes.chunks(UPLOAD_CHUNK).enumerate() {
            staging.host_slice_mut().ok_or_else(|| {
                Error::NoDevice(format!("{name}: no host-visible coherent memory"))
            })?[..chunk.len()]
                .copy_from_slice(chunk);
            let region = [vk::BufferCopy::default()
                .dst_offset((k * UPLOAD_CHUNK) as u64)
                .size(chunk.len() as u64)];
            // SAFETY: both buffers are alive, the region lies inside each, and `submit` waits for
            // the copy, so the staging buffer is free again for the next step.
            self.submit(&format!("upload {}", buffer.name), |device, cmd| unsafe {
                device.cmd_copy_buffer(cmd, src, dst, &region);
            })?;
            progress.advance(chunk.len() as u64);
        }
        Ok(())
    }

    /// Reads `buffer` back as `T`s (its whole size, rounded down to whole elements).
    pub fn read<T: bytemuck::Pod>(&self, buffer: &mut Buffer) -> Result<Vec<T>> {
        // A lost context's device may still write it (Error::DeviceLost).
        self.check_runnable(&format!("read {}", buffer.name))?;
        let elem = std::mem::size_of::<T>() as u64;
        let len = (buffer.size / elem * elem) as usize;
        let mut out = vec![T::zeroed(); len / elem as usize];
        let out_bytes: &mut [u8] = bytemuck::cast_slice_mut(&mut out);
        if let Some(src) = buffer.host_slice_mut() {
            out_bytes.copy_from_slice(&src[..len]);
            return Ok(out);
        }
        let name = format!("readback of {}", buffer.name);
        let mut staging = self.create_buffer(
            &name,
            len as u64,
            vk::BufferUsageFlags::TRANSFER_DST,
            MemoryLocation::GpuToCpu,
        )?;
        let (src, dst) = (buffer.raw, staging.raw);
        let region = [vk::BufferCopy::default().size(len as u64)];
        self.submit(&format!("download {}", buffer.name), |device, cmd| unsafe {
            device.cmd_copy_buffer(cmd, src, dst, &region);
        })?;
        let src = staging
            .host_slice_mut()
            .ok_or_else(|| Error::NoDevice(format!("{name}: no host-visible coherent memory")))?;
        out_bytes.copy_from_slice(&src[..len]);
        Ok(out)
    }
}

/// An error unless `bytes` fit `buffer` from its start.
fn fits(buffer: &Buffer, bytes: &[u8]) -> Result<()> {
    if bytes.len() as u64 > buffer.size {
        return Err(Error::param(
            "write",
            format!(
                "{} bytes do not fit the {}-byte buffer {}",
                bytes.len(),
                buffer.size,
                buffer.name
            ),
        ));
    }
    Ok(())
}
