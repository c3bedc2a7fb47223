//! `aarbf view`: the interactive viewer (egui through eframe, wgpu for the window).
//!
//! - [`state`]: what is shown, as one value the scene file holds;
//! - [`worker`]: the thread that owns the backend and renders progressively, at reduced
//!   resolution while the user drags;
//! - [`app`]: the window (panels, the view, the status bar);
//! - [`navigation`]: trackball, pan, dolly and axis views;
//! - [`map_editor`]: the control-point editor for the density, radius and optical maps.

pub mod app;
pub mod legend;
pub mod map_editor;
pub mod navigation;
pub mod state;
pub mod worker;

use std::path::PathBuf;
use std::sync::{Arc, Mutex};

pub use app::{ViewOptions, ViewerApp};
pub use state::{DataSource, ViewState};
pub use worker::{Interaction, RenderWorker, Shown};

use crate::backend::BackendKind;
use crate::scene_file::resolve::Resolved as Loaded;

/// The viewer could not run.
#[derive(Debug, thiserror::Error)]
pub enum ViewerError {
    /// eframe could not open or run the window (no display, no adapter, or the app failed to
    /// start); its message.
    #[error("viewer window: {0}")]
    Window(String),
    /// The screenshot asked for with [`WindowOptions::screenshot`] was not written.
    #[error("window screenshot {path}: {problem}")]
    Screenshot {
        /// Where the screenshot was to be written.
        path: PathBuf,
        /// Why it was not: the write failed, or the window closed before the render converged.
        problem: String,
    },
}

/// How the window opens.
#[derive(Clone, Debug)]
pub struct WindowOptions {
    /// Inner size in points.
    pub size: [f32; 2],
    /// Write a screenshot of the whole window here once the render has converged, then close
    /// (for documentation and for the window test).
    pub screenshot: Option<PathBuf>,
}

/// Opens the viewer's window on `loaded` and returns when it is closed.
pub fn run(
    loaded: Loaded,
    backend: BackendKind,
    options: ViewOptions,
    window: WindowOptions,
) -> Result<(), ViewerError> {
    let mut setup = eframe::egui_wgpu::WgpuSetupCreateNew::without_display_handle();
    setup.instance_descriptor.flags = crate::backend::wgpu_lbvh::instance_flags();
    let mut native = eframe::NativeOptions {
        viewport: egui::ViewportBuilder::default()
            .with_title("aarbf")
            .with_inner_size(window.size),
        renderer: eframe::Renderer::Wgpu,
        ..Default::default()
    };
    native.wgpu_options.wgpu_setup = eframe::egui_wgpu::WgpuSetup::CreateNew(setup);
    let screenshot_result: Arc<Mutex<Option<Result<(), String>>>> = Arc::default();
    let result = screenshot_result.clone();
    let screenshot = window.screenshot.clone();
    eframe::run_native(
        "aarbf",
        native,
        Box::new(move |cc| {
            let app = ViewerApp::new(&cc.egui_ctx, loaded, backend, options)?;
            Ok(Box::new(Window {
                app,
                screenshot,
                requested: false,
                result,
            }))
        }),
    )
    .map_err(|e| ViewerError::Window(e.to_string()))?;
    match (window.screenshot, screenshot_result.lock().unwrap().take()) {
        (Some(path), Some(Err(problem))) => Err(ViewerError::Screenshot { path, problem }),
        (Some(path), None) => Err(ViewerError::Screenshot {
            path,
            problem: "the window closed before the render converged".into(),
        }),
        _ => Ok(()),
    }
}

/// The eframe application: the viewer, and the optional screenshot of the window.
struct Window {
    app: ViewerApp,
    screenshot: Option<PathBuf>,
    requested: bool,
    result: Arc<Mutex<Option<Result<(), String>>>>,
}

impl eframe::App for Window {
    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut eframe::Frame) {
        self.app.ui(ui);
        let Some(path) = self.screenshot.clone() else {
            return;
        };
        let shown = self.app.worker().shown();
        if !self.requested && shown.converged && shown.generation == self.app.generation() {
            self.requested = true;
            let ctx = ui.ctx().clone();
            let result = self.result.clone();
            ui.ctx().request_screenshot(move |image| {
                let written = write_colour_image(&path, &image);
                *result.lock().unwrap() = Some(written);
                ctx.send_viewport_cmd(egui::ViewportCommand::Close);
                ctx.request_repaint();
            });
            ui.ctx().request_repaint();
        }
    }
}

/// Writes an egui image (sRGB RGBA) as a PNG, atomically.
fn write_colour_image(path: &std::path::Path, image: &egui::ColorImage) -> Result<(), String> {
    let [w, h] = image.size;
    let rgba: Vec<u8> = image.pixels.iter().flat_map(|c| c.to_array()).collect();
    let buffer = image::RgbaImage::from_raw(w as u32, h as u32, rgba)
        .ok_or("the window image has the wrong size")?;
    crate::io::output::write_image(path, buffer.into(), image::ImageFormat::Png, true)
        .map_err(|e| e.to_string())
}
