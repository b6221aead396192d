//! A submission that does not finish loses the context: the error names the pass and why, every
//! later submission and allocation is refused naming the lost pass, and nothing the device may
//! still use is freed (dropping the context's objects and the context itself leaks them instead
//! of destroying them under the device, which the validation layer would report).

mod common;

use std::time::Duration;

use rbvh::ash::vk;
use rbvh::gpu_allocator::MemoryLocation;
use rbvh::Error;

#[test]
fn a_submission_that_does_not_finish_loses_the_context() {
    let ctx = common::context();
    let bytes = 256 << 20;
    let buffer = ctx
        .create_buffer(
            "filled",
            bytes,
            vk::BufferUsageFlags::TRANSFER_DST,
            MemoryLocation::GpuOnly,
        )
        .unwrap();
    // Work that takes the device far longer than no time at all, waited on for no time at all.
    ctx.set_submit_timeout(Duration::ZERO);
    let fill = |ctx: &rbvh::Context, pass: &str| {
        ctx.submit(pass, |device, cmd| unsafe {
            for _ in 0..16 {
                device.cmd_fill_buffer(cmd, buffer.raw(), 0, vk::WHOLE_SIZE, 7);
            }
        })
    };
    match fill(&ctx, "sixteen fills") {
        Err(Error::DeviceLost { what, pass, reason }) => {
            assert_eq!(
                (what.as_str(), pass.as_str()),
                ("sixteen fills", "sixteen fills")
            );
            assert!(reason.contains("no result within 0 s"), "{reason}");
        }
        other => panic!("expected the context lost, got {other:?}"),
    }
    assert!(ctx.is_lost());
    ctx.set_submit_timeout(Duration::from_secs(600));
    let later = fill(&ctx, "a later fill").unwrap_err().to_string();
    assert!(
        later.starts_with(
            "a later fill: the Vulkan context is lost, since sixteen fills did not finish"
        ),
        "{later}"
    );
    let alloc = ctx
        .create_buffer(
            "later",
            16,
            vk::BufferUsageFlags::STORAGE_BUFFER,
            MemoryLocation::CpuToGpu,
        )
        .unwrap_err()
        .to_string();
    assert!(
        alloc.contains("allocate later") && alloc.contains("sixteen fills"),
        "{alloc}"
    );
    // Nor is memory the device may still write read back, or written.
    let mut host = buffer;
    let read = ctx.read::<u32>(&mut host).unwrap_err().to_string();
    assert!(
        read.starts_with("read filled: the Vulkan context is lost"),
        "{read}"
    );
    let write = ctx.write(&mut host, &[0; 4]).unwrap_err().to_string();
    assert!(
        write.starts_with("write filled: the Vulkan context is lost"),
        "{write}"
    );
    let buffer = host;
    // The fills may still be running: the buffer is left to the driver, not destroyed under
    // them (which the validation layer reports as a buffer in use).
    drop(buffer);
    ctx.check_validation().unwrap();
    drop(ctx);
}
