//! The validation messenger of the ash backend catches API misuse: without this check, the
//! other tests' "zero validation messages" would pass just as well with no messenger at all.
//! A process of its own, since the misuse leaves a message in the process-wide list.

use aarbf::backend::ash_rt;
use ash::vk;

#[test]
fn the_messenger_reports_a_deliberate_misuse() {
    let ctx = match ash_rt::context::shared() {
        Ok(c) => c,
        Err(e) if std::env::var_os("CI").is_some() => {
            panic!("CI is set, but the ash backend is unavailable: {e}")
        }
        Err(e) => {
            eprintln!("SKIPPED (no Vulkan ray-tracing device; set CI to make this fail): {e}");
            return;
        }
    };
    if !ctx.validation {
        eprintln!("SKIPPED: the Khronos validation layer is not installed");
        assert!(
            std::env::var_os("CI").is_none()
                || std::env::var("AARBF_VK_VALIDATION").as_deref() == Ok("0"),
            "CI runs with the validation layer (vulkan-validationlayers)"
        );
        return;
    }
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
