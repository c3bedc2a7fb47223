//! The validation messenger of the ash backend catches API misuse: without this check, the
//! other tests' "zero validation messages" would pass just as well with no messenger at all.
//! A process of its own, since the misuse leaves a message in the process-wide list.

use aarbf::backend::ash_rt;
use ash::vk;

mod common;

#[test]
fn the_messenger_reports_a_deliberate_misuse() {
    let ctx = common::require(
        "a Vulkan device with ray-tracing pipelines",
        ash_rt::context::shared(),
    );
    if std::env::var("AARBF_VK_VALIDATION").as_deref() == Ok("0") {
        eprintln!("SKIPPED: AARBF_VK_VALIDATION=0 turns the validation layer off");
        return;
    }
    assert!(
        ctx.validation,
        "the Khronos validation layer is not installed (Debian: vulkan-validationlayers; \
         `cargo xtask setup` installs it); set AARBF_VK_VALIDATION=0 to run without it"
    );
    assert!(ash_rt::validation_messages().is_empty());
    // A zero-sized buffer: VUID-VkBufferCreateInfo-size-00912.
    let info = vk::BufferCreateInfo::default()
        .size(0)
        .usage(vk::BufferUsageFlags::STORAGE_BUFFER);
    // SAFETY: invalid on purpose; the layer reports it, and the driver tolerates it.
    if let Ok(buffer) = unsafe { ctx.device.create_buffer(&info, None) } {
        // SAFETY: the buffer is unused.
        unsafe { ctx.device.destroy_buffer(buffer, None) };
    }
    let messages = ash_rt::validation_messages();
    assert!(
        messages
            .iter()
            .any(|m| m.contains("VUID-VkBufferCreateInfo-size-00912")),
        "{messages:?}"
    );
}
