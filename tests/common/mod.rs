//! What the GPU test files share: requiring a device (a GPU test fails without one, never
//! passes without running), and capturing the messages of wgpu and of the Vulkan validation
//! layers it routes through `log`, so a test can fail on any of them.

#![allow(dead_code)] // each test file uses its own part

/// What a GPU test needs: the device (or backend) `result` holds. Without one the test fails,
/// saying how to get one: a test that did not run must never read as passed.
pub fn require<T, E: std::fmt::Display>(what: &str, result: Result<T, E>) -> T {
    result.unwrap_or_else(|e| {
        panic!(
            "{what} is unavailable: {e}\nGPU tests fail rather than pass without running: \
             `cargo xtask setup` installs a Vulkan driver with ray tracing (Mesa lavapipe) \
             where the machine has none, and `cargo xtask test` runs the suite after it"
        )
    })
}

/// Validation-layer messages (wgpu-hal logs them as warnings or errors) seen in this process.
static DRIVER_MESSAGES: std::sync::Mutex<Vec<String>> = std::sync::Mutex::new(Vec::new());

struct DriverMessages;

impl<S: tracing::Subscriber> tracing_subscriber::Layer<S> for DriverMessages {
    fn on_event(&self, event: &tracing::Event<'_>, _: tracing_subscriber::layer::Context<'_, S>) {
        let meta = event.metadata();
        if *meta.level() > tracing::Level::WARN {
            return;
        }
        struct Text(String);
        impl tracing::field::Visit for Text {
            fn record_debug(&mut self, f: &tracing::field::Field, v: &dyn std::fmt::Debug) {
                self.0.push_str(&format!("{}={v:?} ", f.name()));
            }
        }
        let mut text = Text(format!("{}: ", meta.target()));
        event.record(&mut text);
        // wgpu's `log` records arrive with target "log" and their own in `log.target`.
        if meta.target().starts_with("wgpu") || text.0.contains("log.target=\"wgpu") {
            DRIVER_MESSAGES
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .push(text.0);
        }
    }
}

/// Starts capturing wgpu's messages (and the `log` records of wgpu-hal, through tracing-log);
/// call before the first device is created. Idempotent.
pub fn capture_driver_messages() {
    use tracing_subscriber::layer::SubscriberExt;
    use tracing_subscriber::util::SubscriberInitExt;
    let _ = tracing_subscriber::registry()
        .with(DriverMessages)
        .try_init();
}

/// Fails if the validation layers (on in builds with debug assertions, when installed) or
/// wgpu reported anything so far.
pub fn assert_no_driver_messages() {
    let m = DRIVER_MESSAGES
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .clone();
    assert!(m.is_empty(), "validation / driver messages: {m:#?}");
}
