//! One-shot command submission with GPU timing: record, submit, wait on a fence (bounded), read
//! the timestamps, and turn any validation message into an error naming the pass.

use std::cell::Cell;
use std::sync::atomic::Ordering;
use std::time::Instant;

use ash::vk;

use super::Context;
use crate::{Error, Result};

thread_local! {
    /// Whether this thread is inside [`Context::submit`] (its recording closure included).
    static SUBMITTING: Cell<bool> = const { Cell::new(false) };
}

/// Marks this thread as submitting until dropped (a panicking closure included).
struct Submitting;

impl Submitting {
    fn enter() -> Submitting {
        SUBMITTING.with(|s| s.set(true));
        Submitting
    }
}

impl Drop for Submitting {
    fn drop(&mut self) {
        SUBMITTING.with(|s| s.set(false));
    }
}

/// Timing of one submission.
#[derive(Clone, Copy, Debug, Default)]
pub struct Timing {
    /// Between the two timestamps written around the recorded work (device time).
    pub gpu_ms: Option<f64>,
    /// Submit to fence signalled, as seen by the host.
    pub wall_ms: f64,
}

impl Timing {
    /// The device's time where it can time, else the host's.
    pub fn ms(&self) -> f64 {
        self.gpu_ms.unwrap_or(self.wall_ms)
    }
}

/// RAII for the per-submission objects, so every exit path frees them.
struct Scratch<'a> {
    device: &'a ash::Device,
    pool: vk::CommandPool,
    cmd: vk::CommandBuffer,
    fence: vk::Fence,
    queries: vk::QueryPool,
}

impl Drop for Scratch<'_> {
    fn drop(&mut self) {
        // SAFETY: the fence was waited on (or the submission never happened) before drop.
        unsafe {
            if self.queries != vk::QueryPool::null() {
                self.device.destroy_query_pool(self.queries, None);
            }
            if self.fence != vk::Fence::null() {
                self.device.destroy_fence(self.fence, None);
            }
            if self.cmd != vk::CommandBuffer::null() {
                self.device.free_command_buffers(self.pool, &[self.cmd]);
            }
        }
    }
}

impl Context {
    /// Records `record` into a fresh command buffer between two timestamps, submits it on the
    /// compute queue and waits. `pass` names the work in errors.
    pub fn submit(
        &self,
        pass: &str,
        record: impl FnOnce(&ash::Device, vk::CommandBuffer),
    ) -> Result<Timing> {
        self.check_runnable(pass)?;
        let s = &self.shared;
        let device = &s.device;
        let own = s.own.as_ref().ok_or_else(|| {
            Error::param(
                "context",
                format!("{pass}: an embedded context never submits; record the work into your own command buffer"),
            )
        })?;
        // The command pool and the queue are externally synchronised objects shared by every clone
        // of the context: one submission at a time. A submission asked for from inside another's
        // recording closure, on its thread, would wait for itself: an error instead.
        if SUBMITTING.with(Cell::get) {
            return Err(Error::param(
                "context",
                format!(
                    "{pass}: submitted from inside another submission's recording closure; \
                     record into that closure's command buffer (the *_recorded calls) or submit \
                     after it"
                ),
            ));
        }
        let _serial = own.submit_lock.lock().unwrap_or_else(|p| p.into_inner());
        // Another thread's submission may have lost the context while this one waited for it.
        self.check_runnable(pass)?;
        self.check_validation_of(&format!("the calls before {pass}"))?;
        let _submitting = Submitting::enter();
        let mut scratch = Scratch {
            device,
            pool: own.command_pool,
            cmd: vk::CommandBuffer::null(),
            fence: vk::Fence::null(),
            queries: vk::QueryPool::null(),
        };
        let alloc = vk::CommandBufferAllocateInfo::default()
            .command_pool(own.command_pool)
            .level(vk::CommandBufferLevel::PRIMARY)
            .command_buffer_count(1);
        scratch.cmd = unsafe { device.allocate_command_buffers(&alloc) }
            .map_err(|r| Error::vk("vkAllocateCommandBuffers", pass, r))?[0];
        scratch.fence = unsafe { device.create_fence(&vk::FenceCreateInfo::default(), None) }
            .map_err(|r| Error::vk("vkCreateFence", pass, r))?;
        let timed = s.limits.timestamp_period_ns.is_some();
        if timed {
            let info = vk::QueryPoolCreateInfo::default()
                .query_type(vk::QueryType::TIMESTAMP)
                .query_count(2);
            scratch.queries = unsafe { device.create_query_pool(&info, None) }
                .map_err(|r| Error::vk("vkCreateQueryPool", pass, r))?;
        }
        let cmd = scratch.cmd;
        unsafe {
            device
                .begin_command_buffer(
                    cmd,
                    &vk::CommandBufferBeginInfo::default()
                        .flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT),
                )
                .map_err(|r| Error::vk("vkBeginCommandBuffer", pass, r))?;
            if timed {
                device.cmd_reset_query_pool(cmd, scratch.queries, 0, 2);
                device.cmd_write_timestamp(
                    cmd,
                    vk::PipelineStageFlags::TOP_OF_PIPE,
                    scratch.queries,
                    0,
                );
            }
            // Each submission stands alone: make earlier submissions' device writes visible to
            // this one, and this one's writes visible to the host that reads after the fence.
            let before = [vk::MemoryBarrier::default()
                .src_access_mask(vk::AccessFlags::MEMORY_WRITE)
                .dst_access_mask(vk::AccessFlags::MEMORY_READ | vk::AccessFlags::MEMORY_WRITE)];
            device.cmd_pipeline_barrier(
                cmd,
                vk::PipelineStageFlags::ALL_COMMANDS,
                vk::PipelineStageFlags::ALL_COMMANDS,
                vk::DependencyFlags::empty(),
                &before,
                &[],
                &[],
            );
            record(device, cmd);
            let after = [vk::MemoryBarrier::default()
                .src_access_mask(vk::AccessFlags::MEMORY_WRITE)
                .dst_access_mask(vk::AccessFlags::HOST_READ)];
            device.cmd_pipeline_barrier(
                cmd,
                vk::PipelineStageFlags::ALL_COMMANDS,
                vk::PipelineStageFlags::HOST,
                vk::DependencyFlags::empty(),
                &after,
                &[],
                &[],
            );
            if timed {
                device.cmd_write_timestamp(
                    cmd,
                    vk::PipelineStageFlags::BOTTOM_OF_PIPE,
                    scratch.queries,
                    1,
                );
            }
            device
                .end_command_buffer(cmd)
                .map_err(|r| Error::vk("vkEndCommandBuffer", pass, r))?;
            let cmds = [cmd];
            let submit = [vk::SubmitInfo::default().command_buffers(&cmds)];
            let start = Instant::now();
            let submitted = device.queue_submit(own.queue, &submit, scratch.fence);
            let timeout_ns = own.submit_timeout_ns.load(Ordering::Relaxed);
            let unfinished = match submitted {
                Err(vk::Result::ERROR_DEVICE_LOST) => {
                    Some("vkQueueSubmit: the device is lost".into())
                }
                Err(r) => return Err(Error::vk("vkQueueSubmit", pass, r)),
                Ok(()) => match device.wait_for_fences(&[scratch.fence], true, timeout_ns) {
                    Ok(()) => None,
                    Err(vk::Result::TIMEOUT) => {
                        Some(format!("no result within {} s", timeout_ns as f64 / 1e9))
                    }
                    Err(r) => Some(format!("vkWaitForFences: {r}")),
                },
            };
            if let Some(reason) = unfinished {
                // The device may still run this submission: its command buffer, fence and
                // queries, and every object it uses, must outlive it, so the context is lost
                // and frees nothing from here on (Error::DeviceLost). The first loss is the
                // one every later error names.
                std::mem::forget(scratch);
                own.lost
                    .lock()
                    .unwrap_or_else(|p| p.into_inner())
                    .get_or_insert((pass.to_string(), reason));
                return Err(self.lost_error(pass).expect("marked lost above"));
            }
            let wall_ms = start.elapsed().as_secs_f64() * 1e3;
            let gpu_ms = if timed {
                let mut ticks = [0u64; 2];
                device
                    .get_query_pool_results(
                        scratch.queries,
                        0,
                        &mut ticks,
                        vk::QueryResultFlags::TYPE_64 | vk::QueryResultFlags::WAIT,
                    )
                    .map_err(|r| Error::vk("vkGetQueryPoolResults", pass, r))?;
                s.limits.timestamp_period_ns.map(|p| {
                    ticks_between(ticks[0], ticks[1], s.limits.timestamp_valid_bits) as f64
                        * p
                        * 1e-6
                })
            } else {
                None
            };
            drop(scratch);
            self.check_validation_of(pass)?;
            Ok(Timing { gpu_ms, wall_ms })
        }
    }
}

/// Ticks from timestamp `start` to `end` on a queue whose timestamps keep `valid_bits` bits:
/// they wrap at `2^valid_bits`, so a pass that crosses the wrap counts its own ticks (with 36
/// bits, about an hour on some GPUs), not `2^64` less them.
fn ticks_between(start: u64, end: u64, valid_bits: u32) -> u64 {
    let mask = if valid_bits >= 64 {
        u64::MAX
    } else {
        (1u64 << valid_bits) - 1
    };
    end.wrapping_sub(start) & mask
}

#[cfg(test)]
mod tests {
    use super::ticks_between;

    #[test]
    fn a_pass_across_the_timestamps_wrap_counts_its_own_ticks() {
        assert_eq!(ticks_between(10, 25, 64), 15);
        assert_eq!(ticks_between(10, 25, 36), 15);
        // 36 valid bits: from 5 ticks before the wrap to 7 after it.
        assert_eq!(ticks_between((1 << 36) - 5, 7, 36), 12);
        assert_eq!(ticks_between(u64::MAX - 1, 3, 64), 5);
    }
}
