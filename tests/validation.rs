//! The validation layer is wired up: a deliberately invalid command (a barrier whose access mask
//! does not fit its stage, harmless to the driver) must come back as `Error::Validation` naming the
//! problem, not pass silently. Every other GPU test relies on this to fail on validation errors.
//! A submission asked for from inside another's recording closure is an error, not a hang. An
//! error names the pass it came from, and one raised before a submission is not named for it.

mod common;

use rbvh::Error;

#[test]
fn validation_errors_fail_the_submission() {
    let ctx = common::context();
    if !ctx.validation_enabled() {
        // Rust's test harness has no runtime skip: say it (shown with --nocapture).
        eprintln!(
            "SKIPPED validation_errors_fail_the_submission: VK_LAYER_KHRONOS_validation is not \
             installed (Debian: vulkan-validationlayers, which .ci/setup installs); this test \
             checked nothing"
        );
        return;
    }
    let result = ctx.submit("deliberately invalid barrier", |device, cmd| unsafe {
        let barrier = [
            ash::vk::MemoryBarrier::default().src_access_mask(ash::vk::AccessFlags::SHADER_WRITE)
        ];
        device.cmd_pipeline_barrier(
            cmd,
            ash::vk::PipelineStageFlags::TRANSFER,
            ash::vk::PipelineStageFlags::TRANSFER,
            ash::vk::DependencyFlags::empty(),
            &barrier,
            &[],
            &[],
        );
    });
    match result {
        Err(Error::Validation { during, messages }) => {
            assert_eq!(during, "deliberately invalid barrier");
            assert!(
                messages.iter().any(|m| m.contains("vkCmdPipelineBarrier")),
                "{messages:?}"
            )
        }
        other => panic!("expected a validation error, got {other:?}"),
    }
    // The context stays usable, and clean submissions pass.
    ctx.submit("empty", |_, _| {}).unwrap();
}

#[test]
fn a_submission_inside_another_is_an_error_not_a_hang() {
    let ctx = common::context();
    let mut inner = None;
    ctx.submit("outer", |_, _| {
        inner = Some(ctx.submit("inner", |_, _| {}));
    })
    .unwrap();
    let e = inner.unwrap().unwrap_err().to_string();
    assert!(
        e.contains("inner") && e.contains("recording closure"),
        "{e}"
    );
    // The context stays usable.
    ctx.submit("after", |_, _| {}).unwrap();
}

#[test]
fn errors_of_calls_before_a_submission_are_not_named_for_it() {
    let ctx = common::context();
    if !ctx.validation_enabled() {
        eprintln!(
            "SKIPPED errors_of_calls_before_a_submission_are_not_named_for_it: \
             VK_LAYER_KHRONOS_validation is not installed; this test checked nothing"
        );
        return;
    }
    // A buffer with no usage at all is invalid (VkBufferCreateInfo's usage must not be 0),
    // reported when it is created, outside any submission.
    let _unused = ctx
        .create_buffer(
            "no usage",
            16,
            ash::vk::BufferUsageFlags::empty(),
            rbvh::gpu_allocator::MemoryLocation::CpuToGpu,
        )
        .unwrap();
    match ctx.submit("clean", |_, _| {}) {
        Err(Error::Validation { during, messages }) => {
            assert_eq!(during, "the calls before clean");
            assert!(
                messages.iter().any(|m| m.contains("vkCreateBuffer")),
                "{messages:?}"
            );
        }
        other => panic!("expected the buffer's validation error, got {other:?}"),
    }
    ctx.submit("clean", |_, _| {}).unwrap();
}
