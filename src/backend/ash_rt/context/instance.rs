//! The Vulkan instance, with the Khronos validation layer and its messenger where they are
//! wanted and installed, and the process-wide list of what the layer reported.

use std::ffi::{CStr, c_char, c_void};
use std::sync::Mutex;

use ash::{ext, vk};

use super::ContextError;

const VALIDATION_LAYER: &CStr = c"VK_LAYER_KHRONOS_validation";

/// The validation messenger and the loader that destroys it.
pub(super) type Messenger = (ext::debug_utils::Instance, vk::DebugUtilsMessengerEXT);

static MESSAGES: Mutex<Vec<String>> = Mutex::new(Vec::new());

/// Every validation warning and error reported in this process so far.
pub fn validation_messages() -> Vec<String> {
    MESSAGES.lock().unwrap_or_else(|e| e.into_inner()).clone()
}

unsafe extern "system" fn debug_callback(
    severity: vk::DebugUtilsMessageSeverityFlagsEXT,
    kind: vk::DebugUtilsMessageTypeFlagsEXT,
    data: *const vk::DebugUtilsMessengerCallbackDataEXT<'_>,
    _user: *mut c_void,
) -> vk::Bool32 {
    // SAFETY: the layer passes a valid callback-data struct whose strings live for the call.
    let message = unsafe {
        data.as_ref()
            .and_then(|d| d.message_as_c_str())
            .map(|m| m.to_string_lossy().into_owned())
            .unwrap_or_default()
    };
    if severity.intersects(
        vk::DebugUtilsMessageSeverityFlagsEXT::WARNING
            | vk::DebugUtilsMessageSeverityFlagsEXT::ERROR,
    ) {
        tracing::error!("Vulkan validation ({kind:?}, {severity:?}): {message}");
        MESSAGES
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .push(format!("{severity:?} {kind:?}: {message}"));
    } else {
        tracing::trace!("Vulkan ({kind:?}): {message}");
    }
    vk::FALSE
}

/// Whether contexts run the Khronos validation layer: `AARBF_VK_VALIDATION=0|1`, else in
/// builds with debug assertions.
pub(super) fn validation_wanted() -> bool {
    match std::env::var("AARBF_VK_VALIDATION").as_deref() {
        Ok("0") => false,
        Ok("1") => true,
        _ => cfg!(debug_assertions),
    }
}

/// Whether validation runs: `wanted`, and the loader offers the layer and `VK_EXT_debug_utils`.
pub(super) fn validation_usable(entry: &ash::Entry, wanted: bool) -> bool {
    // SAFETY: plain queries of the loader.
    let layers = unsafe { entry.enumerate_instance_layer_properties() }.unwrap_or_default();
    let have_layer = layers
        .iter()
        .any(|l| l.layer_name_as_c_str().is_ok_and(|n| n == VALIDATION_LAYER));
    let instance_extensions =
        unsafe { entry.enumerate_instance_extension_properties(None) }.unwrap_or_default();
    let have_debug_utils = instance_extensions.iter().any(|e| {
        e.extension_name_as_c_str()
            .is_ok_and(|n| n == ext::debug_utils::NAME)
    });
    if !have_layer && cfg!(debug_assertions) {
        tracing::info!(
            "the Khronos validation layer is not installed (Debian: vulkan-validationlayers); running without it"
        );
    }
    wanted && have_layer && have_debug_utils
}

/// What the messenger reports: errors, warnings and information, of every kind.
fn messenger_info() -> vk::DebugUtilsMessengerCreateInfoEXT<'static> {
    vk::DebugUtilsMessengerCreateInfoEXT::default()
        .message_severity(
            vk::DebugUtilsMessageSeverityFlagsEXT::ERROR
                | vk::DebugUtilsMessageSeverityFlagsEXT::WARNING
                | vk::DebugUtilsMessageSeverityFlagsEXT::INFO,
        )
        .message_type(
            vk::DebugUtilsMessageTypeFlagsEXT::GENERAL
                | vk::DebugUtilsMessageTypeFlagsEXT::VALIDATION
                | vk::DebugUtilsMessageTypeFlagsEXT::PERFORMANCE,
        )
        .pfn_user_callback(Some(debug_callback))
}

/// The instance (and messenger) while a context is being made: dropped, it destroys them, so a
/// creation that fails half way leaves nothing behind; [`InstanceGuard::release`] hands them
/// to the finished context.
pub(super) struct InstanceGuard {
    instance: Option<ash::Instance>,
    debug: Option<Messenger>,
}

impl InstanceGuard {
    /// A Vulkan 1.2 instance, with the validation layer and its messenger when `validation`.
    pub(super) fn create(
        entry: &ash::Entry,
        validation: bool,
    ) -> Result<InstanceGuard, ContextError> {
        let app = vk::ApplicationInfo::default()
            .application_name(c"aarbf")
            .engine_name(c"aarbf")
            .api_version(vk::API_VERSION_1_2);
        let layer_names: Vec<*const c_char> = if validation {
            vec![VALIDATION_LAYER.as_ptr()]
        } else {
            Vec::new()
        };
        let extension_names: Vec<*const c_char> = if validation {
            vec![ext::debug_utils::NAME.as_ptr()]
        } else {
            Vec::new()
        };
        let mut messenger_info = messenger_info();
        let mut create = vk::InstanceCreateInfo::default()
            .application_info(&app)
            .enabled_layer_names(&layer_names)
            .enabled_extension_names(&extension_names);
        if validation {
            // Also reports on instance creation and destruction.
            create = create.push_next(&mut messenger_info);
        }
        // SAFETY: the create info and everything it points to outlive the call.
        let instance = unsafe { entry.create_instance(&create, None) }
            .map_err(|e| ContextError::failed("creating the Vulkan instance", e))?;
        let mut guard = InstanceGuard {
            instance: Some(instance),
            debug: None,
        };
        if validation {
            let loader = ext::debug_utils::Instance::new(entry, guard.instance());
            // SAFETY: a valid create info; the callback is a plain function. On failure the
            // guard destroys the instance, from which nothing was created yet.
            let messenger =
                unsafe { loader.create_debug_utils_messenger(&messenger_info, None) }
                    .map_err(|e| ContextError::failed("creating the validation messenger", e))?;
            guard.debug = Some((loader, messenger));
        }
        Ok(guard)
    }

    pub(super) fn instance(&self) -> &ash::Instance {
        self.instance.as_ref().expect("held until released")
    }

    /// The instance and messenger, now the context's to destroy.
    pub(super) fn release(mut self) -> (ash::Instance, Option<Messenger>) {
        let instance = self.instance.take().expect("held until released");
        (instance, self.debug.take())
    }
}

impl Drop for InstanceGuard {
    fn drop(&mut self) {
        // SAFETY: reached only when creation failed; nothing made from the instance survives.
        unsafe {
            if let Some((loader, m)) = self.debug.take() {
                loader.destroy_debug_utils_messenger(m, None);
            }
            if let Some(i) = self.instance.take() {
                i.destroy_instance(None);
            }
        }
    }
}
