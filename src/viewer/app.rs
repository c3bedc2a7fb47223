//! The viewer's window: the render in the centre, the controls on the left, what things cost
//! at the bottom. The window only edits a [`ViewState`] and shows what the render worker
//! publishes; it never waits for a frame.

use crate::render::legend::Legend;
use crate::scene_file::RangeSpec;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use egui::{Color32, ColorImage, Sense, TextureHandle, TextureOptions};

use super::map_editor::map_editor;
use super::navigation::{self, AxisView};
use super::state::{DataSource, ViewState, view_bounds};
use super::worker::{Interaction, RenderWorker, Shown, ShownImage};
use crate::accel::ClusterSize;
use crate::backend::BackendKind;
use crate::field::Classification;
use crate::render::{Method, StepChange};
use crate::scene::maps::{ColorMap, DensityMap, OpticalDensityMap, PRESETS, RadiusMap};
use crate::scene::{Camera, TimeSeries};
use crate::scene_file::resolve::{DataArgs, FieldOptions, Resolved as Loaded, resolve};
use crate::values::{Integrator, NoiseKind};

mod panels;

/// How long after the last wheel event the view still counts as moving.
const SCROLL_SETTLE: Duration = Duration::from_millis(250);
/// The status bar's height in points: a line of figures and a line for the newest message.
const STATUS_HEIGHT: f32 = 48.0;
/// The backends a user may pick (`auto` as `aarbf render` resolves it; the panel names the
/// one it chose).
const BACKENDS: [BackendKind; 4] = [
    BackendKind::Auto,
    BackendKind::Cpu,
    BackendKind::Wgpu,
    BackendKind::Ash,
];

/// Where the attribute is normalised over.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RangeMode {
    /// Its range over the whole series (the default).
    Series,
    /// Its range in the shown step, fixed when chosen.
    Step,
    /// The series' 1st to 99th percentile (of its lowest and highest step).
    Robust,
    /// The shown step's 1st to 99th percentile, fixed when chosen.
    RobustStep,
    /// A range the user types.
    Fixed,
}

/// Options the viewer was started with that are not part of a scene.
#[derive(Clone, Debug)]
pub struct ViewOptions {
    /// The cache bound for steps read from disk, MiB.
    pub cache_mib: usize,
}

/// The viewer's window contents: the [`ViewState`] the panels edit, the [`RenderWorker`] that
/// renders it, and the window's own controls (playback, the range mode, the paths typed).
pub struct ViewerApp {
    ctx: egui::Context,
    options: ViewOptions,
    source: DataSource,
    series: Arc<TimeSeries>,
    attributes_in_data: Vec<String>,
    /// What is shown: the panels edit it, the worker's refusals revert it, and every frame sends it
    /// to the worker when it changed (with a new generation).
    pub state: ViewState,
    generation: u64,
    sent: Option<(ViewState, Interaction)>,
    worker: RenderWorker,
    texture: Option<TextureHandle>,
    /// Whether the colour legend is drawn over the image.
    show_legend: bool,
    texture_of: Option<Arc<ShownImage>>,
    /// What the worker had to show when this frame began.
    shown: Shown,
    /// Playback: the direction while playing, whether it wraps, steps per second.
    playing: Option<bool>,
    looping: bool,
    rate: f64,
    last_step_at: Instant,
    last_scroll: Option<Instant>,
    log_y: bool,
    range_mode: RangeMode,
    /// The paths typed into the state panel.
    pub scene_path: String,
    /// The image file the screenshot button writes (PNG), as typed; it starts beside `scene_path`.
    pub screenshot_path: String,
    paraview_path: String,
    messages: Vec<String>,
}

impl ViewerApp {
    /// Opens the viewer on `loaded` with `backend` (as the user picked it, `auto` included) and
    /// starts the render worker; an error when the scene's state cannot be made (its render
    /// settings, or the attributes the data holds, cannot be read).
    pub fn new(
        ctx: &egui::Context,
        loaded: Loaded,
        backend: BackendKind,
        options: ViewOptions,
    ) -> Result<ViewerApp, String> {
        let state = ViewState::of(&loaded, backend)?;
        let attributes_in_data = loaded
            .series
            .attributes_in_data()
            .map_err(|e| e.to_string())?;
        let source = DataSource {
            path: loaded.data_path.clone(),
            format: loaded.format,
            read: loaded.read,
        };
        let series = Arc::new(loaded.series);
        let worker = spawn_worker(ctx, &series);
        let range_mode = match loaded.range {
            RangeSpec::Series => RangeMode::Series,
            RangeSpec::Robust => RangeMode::Robust,
            RangeSpec::Step => RangeMode::Step,
            RangeSpec::RobustStep => RangeMode::RobustStep,
            RangeSpec::Fixed(..) => RangeMode::Fixed,
        };
        let scene_path = std::env::current_dir()
            .unwrap_or_default()
            .join("aarbf-view.toml");
        Ok(ViewerApp {
            ctx: ctx.clone(),
            options,
            source,
            series,
            attributes_in_data,
            state,
            generation: 0,
            sent: None,
            worker,
            texture: None,
            show_legend: true,
            texture_of: None,
            shown: Shown::default(),
            playing: None,
            looping: true,
            rate: 10.0,
            last_step_at: Instant::now(),
            last_scroll: None,
            log_y: true,
            range_mode,
            screenshot_path: scene_path.with_extension("png").display().to_string(),
            scene_path: scene_path.display().to_string(),
            paraview_path: String::new(),
            messages: Vec::new(),
        })
    }

    /// The render worker, for its [`Shown`] output and for screenshots.
    pub fn worker(&self) -> &RenderWorker {
        &self.worker
    }

    /// The generation of the state last sent to the worker (what [`super::worker::Shown`]
    /// images carry).
    pub fn generation(&self) -> u64 {
        self.generation
    }

    /// The newest messages said to the user (at most six, oldest first): the worker's problems and
    /// fallbacks, and what the panels did or failed to do.
    pub fn messages(&self) -> &[String] {
        &self.messages
    }

    fn say(&mut self, message: String) {
        tracing::info!("{message}");
        self.messages.push(message);
        let excess = self.messages.len().saturating_sub(6);
        self.messages.drain(..excess);
    }

    /// The whole window, inside `ui` (eframe's root, or a test harness's).
    pub fn ui(&mut self, ui: &mut egui::Ui) {
        let (news, reverted) = self.worker.take_news();
        // One look at the worker's output per frame, for every panel.
        self.shown = self.worker.shown();
        for m in news {
            self.say(m);
        }
        if let Some(state) = reverted {
            self.state = *state;
        }
        self.advance_playback(ui.ctx());
        // A fixed height: what the status bar says never changes the view's size (and with it
        // the image and its accumulation).
        egui::Panel::bottom("status")
            .exact_size(STATUS_HEIGHT)
            .show(ui, |ui| self.status_bar(ui));
        egui::Panel::left("controls")
            .resizable(true)
            .default_size(320.0)
            .show(ui, |ui| {
                egui::ScrollArea::vertical().show(ui, |ui| self.controls(ui));
            });
        egui::CentralPanel::default()
            .frame(egui::Frame::NONE.fill(Color32::BLACK))
            .show(ui, |ui| self.view(ui));
        self.send(ui.ctx());
    }

    /// Sends the state to the worker when it or the way the user moves changed.
    fn send(&mut self, ctx: &egui::Context) {
        let scrolling = self
            .last_scroll
            .is_some_and(|t| t.elapsed() < SCROLL_SETTLE);
        let dragging = ctx.dragged_id().is_some();
        let interaction = Interaction {
            interacting: dragging || scrolling,
            playing: self.playing,
            looping: self.looping,
        };
        if scrolling {
            // Settle to full resolution once the wheel stops, without further input.
            ctx.request_repaint_after(SCROLL_SETTLE);
        }
        if self.sent.as_ref() != Some(&(self.state.clone(), interaction)) {
            if self.sent.as_ref().is_none_or(|(s, _)| *s != self.state) {
                self.generation += 1;
            }
            self.worker.show(&self.state, self.generation, interaction);
            self.sent = Some((self.state.clone(), interaction));
        }
    }

    fn advance_playback(&mut self, ctx: &egui::Context) {
        let Some(forward) = self.playing else {
            return;
        };
        let len = self.series.len();
        let interval = Duration::from_secs_f64(1.0 / self.rate.max(0.01));
        // A step is shown once its frame is out: playback never outruns the renderer.
        let current_shown =
            self.shown.generation == self.generation && self.shown.step == Some(self.state.step);
        if current_shown && self.last_step_at.elapsed() >= interval {
            let next = match (forward, self.state.step) {
                (true, s) if s + 1 < len => Some(s + 1),
                (true, _) if self.looping => Some(0),
                (false, 0) if self.looping => Some(len - 1),
                (false, s) if s > 0 => Some(s - 1),
                _ => None,
            };
            match next {
                Some(s) => self.state.step = s,
                None => self.playing = None,
            }
            self.last_step_at = Instant::now();
        }
        ctx.request_repaint_after(interval / 4);
    }

    fn status_bar(&mut self, ui: &mut egui::Ui) {
        let s = &self.shown;
        ui.horizontal(|ui| {
            if let Some(busy) = &s.busy {
                ui.spinner();
                ui.label(busy);
            }
            let (w, h) = s.full_size;
            let res = match &s.image {
                Some(i) if !s.full_resolution => {
                    format!("preview {}x{} of {w}x{h}", i.width, i.height)
                }
                Some(_) => format!("{w}x{h}"),
                None => "no image yet".into(),
            };
            ui.label(format!(
                "{res} · {} spp{} · {:.2} s",
                s.spp,
                if s.converged { " (done)" } else { "" },
                s.since_change.as_secs_f64()
            ));
            ui.separator();
            ui.label(format!(
                "frame {:.1} ms · readback {:.1} ms",
                ms(s.frame_time),
                ms(s.readback)
            ));
            if let Some((change, took)) = s.step_change {
                let what = match change {
                    StepChange::Build => "build",
                    StepChange::Refit => "refit",
                    StepChange::Maps => "maps",
                    StepChange::None => "none",
                };
                ui.separator();
                ui.label(format!("{what} {:.1} ms", ms(took)));
            }
        });
        // The newest message on its own line; the others on hover.
        let newest = self.messages.last().cloned().unwrap_or_default();
        let line = ui.colored_label(ui.visuals().warn_fg_color, newest);
        if self.messages.len() > 1 {
            line.on_hover_text(self.messages.join("\n"));
        }
    }

    fn view(&mut self, ui: &mut egui::Ui) {
        let size = ui.available_size();
        let ppp = ui.ctx().pixels_per_point();
        let width = ((size.x * ppp).round() as u32).clamp(1, 16384);
        let height = ((size.y * ppp).round() as u32).clamp(1, 16384);
        self.state.settings.width = width;
        self.state.settings.height = height;
        let (rect, response) = ui.allocate_exact_size(size, Sense::click_and_drag());
        response.widget_info(|| egui::WidgetInfo::labeled(egui::Role::Image, true, "render view"));
        let image = self.shown.image.clone();
        if let Some(image) = &image
            && self
                .texture_of
                .as_ref()
                .is_none_or(|t| !Arc::ptr_eq(t, image))
        {
            let colour = ColorImage::from_rgba_unmultiplied(
                [image.width as usize, image.height as usize],
                &image.rgba,
            );
            match &mut self.texture {
                Some(t) => t.set(colour, TextureOptions::LINEAR),
                None => {
                    self.texture = Some(ui.ctx().load_texture(
                        "render",
                        colour,
                        TextureOptions::LINEAR,
                    ));
                }
            }
            self.texture_of = Some(image.clone());
        }
        if let Some(t) = &self.texture {
            ui.painter().image(
                t.id(),
                rect,
                egui::Rect::from_min_max(egui::pos2(0.0, 0.0), egui::pos2(1.0, 1.0)),
                Color32::WHITE,
            );
            if self.show_legend {
                super::legend::paint(ui.painter(), rect, &self.legend());
            }
        }
        let camera = self.state.camera();
        let delta = response.drag_delta() * ppp;
        let (dx, dy) = (f64::from(delta.x), f64::from(delta.y));
        let pan = response.dragged_by(egui::PointerButton::Secondary)
            || response.dragged_by(egui::PointerButton::Middle)
            || (response.dragged_by(egui::PointerButton::Primary)
                && ui.input(|i| i.modifiers.shift));
        let mut moved = camera;
        if (dx, dy) != (0.0, 0.0) {
            moved = if pan {
                navigation::pan(camera, dx, dy, f64::from(height))
            } else {
                navigation::orbit(camera, dx, dy)
            };
        }
        if response.hovered() {
            let scroll = ui.input(|i| i.smooth_scroll_delta.y);
            if scroll != 0.0 {
                moved = navigation::dolly(moved, f64::from(scroll));
                self.last_scroll = Some(Instant::now());
            }
        }
        if moved != camera {
            self.state.settings.camera = Some(moved);
        }
    }

    /// The field's attribute over the whole series (its ranges), if the field carries one.
    fn series_attribute(&self) -> Option<crate::scene::AttributeInfo> {
        self.state
            .field
            .attribute
            .as_deref()
            .and_then(|a| self.series.attribute(a))
    }

    /// What the colours of the image show, as `--legend` says it.
    fn legend(&self) -> Legend {
        let series_range = self.series_attribute().map(|a| (a.min, a.max));
        let range_is = match self.range_mode {
            RangeMode::Series => "series range",
            RangeMode::Step => "step range",
            RangeMode::Robust => "series 1-99%",
            RangeMode::RobustStep => "step 1-99%",
            RangeMode::Fixed => "set range",
        };
        Legend::of_field(
            &self.state.field,
            series_range,
            range_is,
            self.state.settings.colour_by_density,
            self.shown.used.map_or(1.0, |u| u.phi_ref),
        )
    }

    /// Writes the state as a scene file `aarbf render --scene` renders to the same image.
    pub fn save_scene(&mut self, path: &Path) -> Result<(), String> {
        let shown = self.worker.shown();
        let used = shown
            .used
            .filter(|_| shown.generation == self.generation)
            .ok_or("save: the current state has not been rendered yet; try again in a moment")?;
        self.state
            .scene_file(&self.source, Some(&used))
            .save(path, true)
            .map_err(|e| e.to_string())?;
        self.say(format!("saved {}", path.display()));
        Ok(())
    }

    /// Replaces the state (and the data, if the scene names other data) by a scene file's.
    pub fn load_scene(&mut self, path: &Path) -> Result<(), String> {
        let data = DataArgs::of_scene(path.to_path_buf(), self.options.cache_mib);
        self.reload(&data, &FieldOptions::default())?;
        self.say(format!("loaded {}", path.display()));
        Ok(())
    }

    /// A new attribute is a new selection of the data: opened again, with the rest of the
    /// state kept (through a scene file of it, as any reload).
    fn change_attribute(&mut self, attribute: Option<String>) {
        let dir = match tempfile::tempdir() {
            Ok(d) => d,
            Err(e) => return self.say(format!("cannot change the attribute: {e}")),
        };
        let path = dir.path().join("state.toml");
        let mut scene = self.state.scene_file(&self.source, None);
        scene.data.attribute = attribute;
        // The range belonged to the old attribute.
        scene.data.attribute_range = None;
        self.range_mode = RangeMode::Series;
        let result = scene
            .save(&path, true)
            .map_err(|e| e.to_string())
            .and_then(|()| {
                let data = DataArgs::of_scene(path.clone(), self.options.cache_mib);
                self.reload(&data, &FieldOptions::default())
            });
        if let Err(e) = result {
            self.say(format!("cannot change the attribute: {e}"));
        }
    }

    fn reload(&mut self, data: &DataArgs, field: &FieldOptions) -> Result<(), String> {
        let loaded = resolve(data, field).map_err(|e| format!("{e:#}"))?;
        let mut state = ViewState::of(&loaded, self.state.backend)?;
        // The window's size is the window's, not the file's.
        state.settings.width = self.state.settings.width;
        state.settings.height = self.state.settings.height;
        let same_data = loaded.data_path == self.source.path
            && loaded.format == self.source.format
            && loaded.read == self.source.read
            && loaded.series.len() == self.series.len()
            && loaded.field.attribute == self.state.field.attribute
            && loaded.field.radius_attribute == self.state.field.radius_attribute;
        if !same_data {
            self.attributes_in_data = loaded
                .series
                .attributes_in_data()
                .map_err(|e| e.to_string())?;
            self.source = DataSource {
                path: loaded.data_path.clone(),
                format: loaded.format,
                read: loaded.read,
            };
            self.series = Arc::new(loaded.series);
            self.worker = spawn_worker(&self.ctx, &self.series);
            self.sent = None;
            self.texture_of = None;
        }
        self.range_mode = if state.field.attribute_range.is_some() {
            RangeMode::Fixed
        } else {
            RangeMode::Series
        };
        self.state = state;
        Ok(())
    }
}

fn spawn_worker(ctx: &egui::Context, series: &Arc<TimeSeries>) -> RenderWorker {
    let repaint = ctx.clone();
    RenderWorker::spawn(series.clone(), Box::new(move || repaint.request_repaint()))
}

/// The precisions the quality panel offers (`backend::parse_precision` spells them), and what
/// each means.
const PRECISIONS: [(&str, &str); 5] = [
    (
        "auto",
        "the cheapest representation whose whole error bound meets the tolerance: f32, compensated sums or double-single (GPU), f64 (CPU)",
    ),
    (
        "f32",
        "f32 local coordinates and plain f32 sums whatever the error: the fastest",
    ),
    (
        "f32c",
        "f32 local coordinates, compensated sums (GPU; the CPU's f32 sums are blocked in f64 anyway)",
    ),
    ("f64", "the CPU's f64 reference (double-single on a GPU)"),
    ("ds", "double-single positions on a GPU (f64 on the CPU)"),
];

fn integrator_name(i: Integrator) -> &'static str {
    match i {
        Integrator::Ea => "emission-absorption",
        Integrator::Delta => "single scattering, delta tracking",
        Integrator::Marching => "single scattering, stochastic marching",
        Integrator::SsReference => "single scattering, reference",
    }
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

fn mib(bytes: usize) -> f64 {
    bytes as f64 / f64::from(1u32 << 20)
}

fn method_name(m: Method) -> &'static str {
    match m {
        Method::Rbf => "RBF (attribute-aware)",
        Method::Voxel => "voxel grid (baseline)",
        Method::Splat => "splat (Knoll et al.'s baseline)",
    }
}
