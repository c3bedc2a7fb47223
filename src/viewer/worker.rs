//! The render worker: a thread that owns the backend and the rendering session, so the window
//! never waits for a frame. The window sends the state it wants shown; the worker renders it
//! progressively and publishes the latest image with what it cost.
//!
//! While the user drags (or the series plays), the worker renders at a reduced resolution it
//! chooses after every frame so frames take about [`INTERACTIVE_FRAME`] on this backend, one
//! sample each; when input stops it renders at full resolution and accumulates up to the
//! state's spp (OSPRay Studio's and ParaView's level of detail do the same).

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, Sender};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use super::state::ViewState;
use crate::backend::{self, BackendError, BackendKind, MemoryReport, Precision, Timings};
use crate::field::{FieldInputs, normalise};
use crate::render::{RenderError, RenderSession, Resolved, StepChange};
use crate::scene::TimeSeries;
use crate::scene::prefetch::Prefetcher;

/// The frame time interactive rendering aims for (20 frames per second).
pub const INTERACTIVE_FRAME: Duration = Duration::from_millis(50);
/// Interactive images are never smaller than this fraction of the full image's side.
const MIN_SCALE: f64 = 1.0 / 16.0;
/// While accumulating at full resolution, the image is read back at most this often (each
/// readback copies the whole accumulation).
const PUBLISH_INTERVAL: Duration = Duration::from_millis(150);
/// Bins of the attribute histogram behind the map editors.
pub const HISTOGRAM_BINS: usize = 64;

/// How the user is moving the view.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Interaction {
    /// A drag or scroll is under way: render fast, at reduced resolution.
    pub interacting: bool,
    /// The series plays forward (`Some(true)`) or backward; the worker reads ahead that way.
    pub playing: Option<bool>,
    /// Playback wraps around at the ends.
    pub looping: bool,
}

enum Request {
    Show {
        state: Box<ViewState>,
        generation: u64,
        interaction: Interaction,
    },
    Screenshot(PathBuf),
    Quit,
}

/// An sRGB image the window can show.
#[derive(Clone, Debug, PartialEq)]
pub struct ShownImage {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// RGBA, 8 bits a channel, sRGB, opaque.
    pub rgba: Vec<u8>,
}

/// The distribution of the field's attribute in the shown step.
#[derive(Clone, Debug, PartialEq)]
pub struct Histogram {
    /// Particles per bin of the normalised attribute t over [0, 1] (outside values clamp to
    /// the end bins).
    pub counts: Vec<u32>,
    /// The attribute's range in this step (for "range: this step").
    pub step_range: (f64, f64),
    /// Its 1st to 99th percentile in this step (for "range: robust step").
    pub step_robust_range: (f64, f64),
}

/// What the worker has to show: the latest image and what it cost.
#[derive(Clone, Debug, Default)]
pub struct Shown {
    /// The state generation the image and figures belong to.
    pub generation: u64,
    /// The latest image (`None` before the first frame); a reduced one while the user interacts.
    pub image: Option<Arc<ShownImage>>,
    /// Frames accumulated in the image.
    pub spp: u32,
    /// Whether `image` is at the state's full size (false while interacting).
    pub full_resolution: bool,
    /// The state's full image size (what `image` is a reduced version of while interacting).
    pub full_size: (u32, u32),
    /// Time from the state's change to this image.
    pub since_change: Duration,
    /// The last frame's render time.
    pub frame_time: Duration,
    /// Reading the accumulation back and converting it for the window, per published image:
    /// the copy that brings a GPU backend's image to the window.
    pub readback: Duration,
    /// The backend's name and device.
    pub backend: Option<(String, String)>,
    /// The backend's phase timings as of the latest published image.
    pub timings: Timings,
    /// The memory the backend holds for the shown step.
    pub memory: MemoryReport,
    /// The step shown, after its build (or refit), and what that took.
    pub step: Option<usize>,
    /// The latest step change that cost work (maps, a refit or a build), and how long showing the
    /// step took with it; kept while later states need none.
    pub step_change: Option<(StepChange, Duration)>,
    /// How the backend holds the step's positions and sums its terms, with the error bound, as text
    /// (`None` before a step is uploaded).
    pub positions: Option<String>,
    /// The automatic values as resolved for the state (what a saved scene records).
    pub used: Option<Resolved>,
    /// The histogram of the field's attribute in the shown step (`None` when the field has no
    /// attribute).
    pub histogram: Option<Arc<Histogram>>,
    /// Problems and fallbacks, newest last; the window shows them.
    pub messages: Vec<String>,
    /// When the worker refused a state, the one it went back to (the window adopts it).
    pub reverted: Option<Box<ViewState>>,
    /// Work in progress that blocks frames (a backend starting, a step building).
    pub busy: Option<String>,
    /// Screenshots written, in order.
    pub screenshots: Vec<PathBuf>,
    /// The state and the accumulation are complete: the worker waits for a change.
    pub converged: bool,
}

/// The handle the window holds.
pub struct RenderWorker {
    requests: Sender<Request>,
    shown: Arc<Mutex<Shown>>,
    /// Raised with every new state: a full-resolution frame in progress is abandoned for it
    /// (where the backend can stop mid-frame), so the view answers within one preview.
    superseded: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl RenderWorker {
    /// Starts a worker over `series`; `notify` is called whenever there is something new to
    /// show (the window asks egui to repaint).
    pub fn spawn(series: Arc<TimeSeries>, notify: Box<dyn Fn() + Send>) -> RenderWorker {
        let (requests, incoming) = mpsc::channel();
        let shown = Arc::new(Mutex::new(Shown::default()));
        let published = shown.clone();
        let superseded = Arc::new(AtomicBool::new(false));
        let flag = superseded.clone();
        let thread = std::thread::Builder::new()
            .name("aarbf-render".into())
            .spawn(move || {
                let mut worker = Worker {
                    series: &series,
                    session: None,
                    out: Outbox {
                        shown: published,
                        notify,
                    },
                    seconds_per_pixel: None,
                    used: None,
                    superseded: flag,
                    applied: None,
                    last_good: None,
                    histogram: None,
                };
                worker.run(&incoming);
            })
            .expect("cannot start the render thread");
        RenderWorker {
            requests,
            shown,
            superseded,
            thread: Some(thread),
        }
    }

    /// Asks for `state` to be shown; `generation` identifies it in [`Shown`].
    pub fn show(&self, state: &ViewState, generation: u64, interaction: Interaction) {
        self.superseded.store(true, Ordering::Relaxed);
        let _ = self.requests.send(Request::Show {
            state: Box::new(state.clone()),
            generation,
            interaction,
        });
    }

    /// Writes the current accumulation at full resolution to `path` (PNG) once it has at
    /// least one full-resolution frame.
    pub fn screenshot(&self, path: PathBuf) {
        let _ = self.requests.send(Request::Screenshot(path));
    }

    /// A copy of what there is to show.
    pub fn shown(&self) -> Shown {
        self.shown.lock().unwrap().clone()
    }

    /// Takes the messages and the reverted state out (each is shown once).
    pub fn take_news(&self) -> (Vec<String>, Option<Box<ViewState>>) {
        let mut s = self.shown.lock().unwrap();
        (std::mem::take(&mut s.messages), s.reverted.take())
    }

    /// Waits until `done` holds for what is shown, or `timeout` passes; returns the last.
    pub fn wait_for(&self, timeout: Duration, done: impl Fn(&Shown) -> bool) -> Shown {
        let start = Instant::now();
        loop {
            let s = self.shown();
            if done(&s) || start.elapsed() > timeout {
                return s;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    }
}

impl Drop for RenderWorker {
    fn drop(&mut self) {
        let _ = self.requests.send(Request::Quit);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// Where the worker publishes, and how it tells the window.
struct Outbox {
    shown: Arc<Mutex<Shown>>,
    notify: Box<dyn Fn() + Send>,
}

impl Outbox {
    fn publish(&self, f: impl FnOnce(&mut Shown)) {
        f(&mut self.shown.lock().unwrap());
        (self.notify)();
    }

    fn say(&self, message: String) {
        tracing::warn!("{message}");
        self.publish(|s| s.messages.push(message));
    }
}

/// What a histogram depends on: the step, the attribute and the range it is normalised over.
type HistogramKey = (usize, Option<String>, Option<(f64, f64)>);

struct Worker<'a> {
    series: &'a TimeSeries,
    session: Option<(BackendKind, RenderSession)>,
    out: Outbox,
    /// What a frame at the state's own step size costs per pixel on this backend and scene,
    /// measured on the last frame: it sizes the next interactive frame.
    seconds_per_pixel: Option<f64>,
    /// The automatic values of the applied state (its step size, which previews coarsen).
    used: Option<Resolved>,
    superseded: Arc<AtomicBool>,
    /// The state the session holds, and its generation.
    applied: Option<(ViewState, u64)>,
    last_good: Option<ViewState>,
    /// The histogram of the shown step's attribute, and what it was made for.
    histogram: Option<(HistogramKey, Option<Arc<Histogram>>)>,
}

/// What the worker is asked for now.
struct Wanted {
    state: ViewState,
    generation: u64,
    interaction: Interaction,
    changed_at: Instant,
}

impl Worker<'_> {
    fn run(&mut self, incoming: &Receiver<Request>) {
        std::thread::scope(|scope| {
            let prefetcher = Prefetcher::spawn(scope, self.series);
            let mut wanted: Option<Wanted> = None;
            let mut screenshots: Vec<PathBuf> = Vec::new();
            let mut idle = true;
            let mut last_publish = Instant::now();
            loop {
                // Take every request there is; wait for one only when there is nothing to do.
                let mut next = if idle {
                    match incoming.recv() {
                        Ok(r) => Some(r),
                        Err(_) => return,
                    }
                } else {
                    None
                };
                self.superseded.store(false, Ordering::Relaxed);
                loop {
                    let request = match next.take() {
                        Some(r) => r,
                        None => match incoming.recv_timeout(Duration::ZERO) {
                            Ok(r) => r,
                            Err(RecvTimeoutError::Timeout) => break,
                            Err(RecvTimeoutError::Disconnected) => return,
                        },
                    };
                    match request {
                        Request::Quit => return,
                        Request::Screenshot(path) => screenshots.push(path),
                        Request::Show {
                            state,
                            generation,
                            interaction,
                        } => {
                            let same = wanted.as_ref().is_some_and(|w| w.state == *state);
                            let changed_at = match &wanted {
                                Some(w) if same => w.changed_at,
                                _ => Instant::now(),
                            };
                            wanted = Some(Wanted {
                                state: *state,
                                generation,
                                interaction,
                                changed_at,
                            });
                        }
                    }
                }
                let Some(want) = wanted.as_mut() else {
                    idle = true;
                    continue;
                };
                if self.applied.as_ref().is_none_or(|(s, _)| *s != want.state) {
                    if let Err(e) = self.apply(&want.state, want.generation) {
                        self.refuse(want, e);
                        idle = self.session.is_none();
                        continue;
                    }
                    let upcoming =
                        upcoming_steps(want.state.step, self.series.len(), want.interaction);
                    prefetcher.plan(want.state.step, upcoming);
                }
                self.applied.as_mut().unwrap().1 = want.generation;
                match self.frame(want, &mut screenshots, &mut last_publish) {
                    Ok(done) => idle = done,
                    Err(RenderError::Backend(BackendError::Abandoned)) => idle = false,
                    Err(e) => {
                        self.refuse(want, e);
                        idle = self.session.is_none();
                    }
                }
            }
        });
    }

    /// Makes the session hold `state`: the backend it names (started if it changed), the
    /// step and field (built, refit or only re-mapped, as the change needs).
    fn apply(&mut self, state: &ViewState, generation: u64) -> Result<(), RenderError> {
        if self
            .session
            .as_ref()
            .is_none_or(|(k, _)| *k != state.backend)
        {
            self.out
                .publish(|s| s.busy = Some(format!("starting the {} backend", state.backend)));
            let backend = match backend::create(state.backend) {
                Ok(b) => b,
                Err(e) => {
                    self.out.publish(|s| s.busy = None);
                    return Err(e.into());
                }
            };
            let caps = backend.capabilities();
            self.out
                .publish(|s| s.backend = Some((caps.name.to_owned(), caps.device.clone())));
            self.session = Some((state.backend, RenderSession::new(backend, self.series)));
        }
        let (_, session) = self.session.as_mut().unwrap();
        let precision = backend::parse_precision(&state.precision, Precision::RENDER)
            .map_err(RenderError::Settings)?;
        session.set_precision(precision);
        session.set_periodic(state.periodic);
        let building = self
            .applied
            .as_ref()
            .is_none_or(|(b, _)| b.field != state.field || b.step != state.step);
        if building {
            self.out
                .publish(|s| s.busy = Some(format!("preparing step {}", state.step)));
        }
        let started = Instant::now();
        let result = session.show(self.series, state.step, &state.field, state.cluster);
        let took = started.elapsed();
        let used = result.and_then(|change| Ok((change, session.resolve(&state.settings)?)));
        let (change, used) = match used {
            Ok(u) => u,
            Err(e) => {
                self.out.publish(|s| s.busy = None);
                return Err(e);
            }
        };
        let positions = session.backend().representation().map(|p| p.to_string());
        let histogram = self.histogram(state)?;
        self.applied = Some((state.clone(), generation));
        self.last_good = Some(state.clone());
        self.used = Some(used);
        self.out.publish(|s| {
            s.busy = None;
            s.used = Some(used);
            s.positions = positions;
            s.step = Some(state.step);
            if change != StepChange::None {
                s.step_change = Some((change, took));
            }
            s.histogram = histogram;
        });
        Ok(())
    }

    /// The histogram of the state's attribute in its step (made again only when the step,
    /// attribute or range changed).
    fn histogram(&mut self, state: &ViewState) -> Result<Option<Arc<Histogram>>, RenderError> {
        let key = (
            state.step,
            state.field.attribute.clone(),
            state.field.attribute_range,
        );
        if let Some((k, h)) = &self.histogram
            && *k == key
        {
            return Ok(h.clone());
        }
        let step = self.series.step(state.step)?;
        let series_range = state
            .field
            .attribute
            .as_deref()
            .and_then(|a| self.series.attribute(a))
            .map(|a| (a.min, a.max));
        let inputs = FieldInputs::check(&step, &state.field, series_range)
            .map_err(|e| RenderError::Settings(e.to_string()))?;
        let histogram = inputs.attribute.map(|a| {
            let mut counts = vec![0u32; HISTOGRAM_BINS];
            let mut lo = f64::INFINITY;
            let mut hi = f64::NEG_INFINITY;
            for &v in &a.values {
                lo = lo.min(v);
                hi = hi.max(v);
                let t = normalise(v, inputs.range).clamp(0.0, 1.0);
                let bin = ((t * HISTOGRAM_BINS as f64) as usize).min(HISTOGRAM_BINS - 1);
                counts[bin] += 1;
            }
            Arc::new(Histogram {
                counts,
                step_range: if lo <= hi { (lo, hi) } else { (0.0, 0.0) },
                step_robust_range: crate::scene::index::robust_range(&a.values)
                    .unwrap_or((0.0, 0.0)),
            })
        });
        self.histogram = Some((key, histogram.clone()));
        Ok(histogram)
    }

    /// A state was refused: say why and go back to the last state that worked (or, when the
    /// backend itself failed, to the CPU backend).
    fn refuse(&mut self, want: &mut Wanted, error: RenderError) {
        // The session may hold part of the refused state (a step built before its settings
        // failed): whatever comes next is applied in full.
        self.applied = None;
        // The device failing, not the field or settings it was given (which every backend
        // refuses alike).
        let backend_failed = matches!(
            &error,
            RenderError::Backend(e) if !matches!(e, BackendError::Field(_))
        );
        if backend_failed && want.state.backend != BackendKind::Cpu {
            self.out.say(format!(
                "the {} backend failed: {error}; falling back to the CPU backend",
                want.state.backend
            ));
            self.session = None;
            want.state.backend = BackendKind::Cpu;
        } else if let Some(good) = self.last_good.clone().filter(|g| *g != want.state) {
            self.out
                .say(format!("{error}; showing the previous settings"));
            want.state = good;
        } else {
            self.out.say(error.to_string());
            self.session = None;
            return;
        }
        let state = Box::new(want.state.clone());
        self.out.publish(|s| s.reverted = Some(state));
    }

    /// Renders one frame of the wanted state; returns whether the accumulation is complete.
    fn frame(
        &mut self,
        want: &Wanted,
        screenshots: &mut Vec<PathBuf>,
        last_publish: &mut Instant,
    ) -> Result<bool, RenderError> {
        let (_, session) = self.session.as_mut().unwrap();
        let full = (want.state.settings.width, want.state.settings.height);
        let interactive = want.interaction.interacting || want.interaction.playing.is_some();
        let mut settings = want.state.settings.clone();
        let mut coarsening = 1.0;
        if interactive {
            let full_pixels = f64::from(full.0) * f64::from(full.1);
            let (scale, steps) = self
                .seconds_per_pixel
                .map_or((0.25, 1.0), |cost| level_of_detail(cost, full_pixels));
            settings.width = ((f64::from(full.0) * scale).round() as u32).max(1);
            settings.height = ((f64::from(full.1) * scale).round() as u32).max(1);
            if steps > 1.0
                && let Some(used) = self.used
            {
                settings.step_size = Some(used.step_size * steps);
                coarsening = steps;
            }
        }
        // Previews are short and always finished; a full-resolution frame gives way to a new
        // state.
        session.backend_mut().set_abandon_flag(if interactive {
            None
        } else {
            Some(self.superseded.clone())
        });
        let full_resolution = (settings.width, settings.height) == full;
        let converged =
            full_resolution && !interactive && session.frames_of(&settings) >= want.state.spp;
        if !converged {
            let started = Instant::now();
            session.accumulate(&settings, 1)?;
            let took = started.elapsed();
            // Normalised to the full march: a frame's cost grows with its samples per ray.
            let pixels = f64::from(settings.width) * f64::from(settings.height);
            self.seconds_per_pixel = Some(took.as_secs_f64() * coarsening / pixels);
            self.out.publish(|s| s.frame_time = took);
        }
        let frames = session.frames();
        let done = full_resolution && !interactive && frames >= want.state.spp;
        let publish =
            interactive || done || last_publish.elapsed() >= PUBLISH_INTERVAL || frames == 1;
        if publish && (!converged || self.out.shown.lock().unwrap().generation != want.generation) {
            let started = Instant::now();
            let image = session.image()?;
            let rgb = image.to_srgb8();
            let rgba = rgb.pixels().flat_map(|p| [p[0], p[1], p[2], 255]).collect();
            let readback = started.elapsed();
            *last_publish = Instant::now();
            let shown = Arc::new(ShownImage {
                width: image.width,
                height: image.height,
                rgba,
            });
            let timings = session.backend().timings();
            let memory = session.backend().memory();
            let since = want.changed_at.elapsed();
            let generation = want.generation;
            self.out.publish(|s| {
                s.generation = generation;
                s.image = Some(shown);
                s.spp = frames;
                s.full_resolution = full_resolution;
                s.full_size = full;
                s.since_change = since;
                s.readback = readback;
                s.timings = timings;
                s.memory = memory;
                s.converged = done;
            });
        }
        if full_resolution && frames > 0 && !screenshots.is_empty() {
            let image = session.image()?;
            for path in screenshots.drain(..) {
                match crate::io::output::write_png(&path, &image, true) {
                    Ok(()) => self.out.publish(|s| s.screenshots.push(path)),
                    Err(e) => self.out.say(format!("screenshot: {e}")),
                }
            }
        }
        Ok(done)
    }
}

/// The interactive level of detail for a frame budget of [`INTERACTIVE_FRAME`], from what a
/// full-step frame costs per pixel (`seconds_per_pixel`) and the full image's pixels: the
/// image's scale (fraction of its side) and how many times the step size grows. Resolution
/// goes first, down to a quarter of the side; then samples along the ray, up to 8x fewer (as
/// VTK's volume mappers lengthen the sample distance to keep an update rate); then resolution
/// again, down to [`MIN_SCALE`].
pub fn level_of_detail(seconds_per_pixel: f64, full_pixels: f64) -> (f64, f64) {
    const FIRST_SCALE: f64 = 0.25;
    const MAX_COARSENING: f64 = 8.0;
    let budget = INTERACTIVE_FRAME.as_secs_f64();
    let cost = seconds_per_pixel.max(1e-12) * full_pixels.max(1.0);
    let scale = (budget / cost).sqrt();
    if scale >= FIRST_SCALE {
        return (scale.min(1.0), 1.0);
    }
    let coarsening = cost * FIRST_SCALE * FIRST_SCALE / budget;
    if coarsening <= MAX_COARSENING {
        return (FIRST_SCALE, coarsening);
    }
    (
        (budget * MAX_COARSENING / cost).sqrt().max(MIN_SCALE),
        MAX_COARSENING,
    )
}

/// The steps playback shows next, in order (read ahead while the current one renders).
fn upcoming_steps(current: usize, len: usize, interaction: Interaction) -> Vec<usize> {
    const AHEAD: usize = 4;
    let Some(forward) = interaction.playing else {
        return Vec::new();
    };
    let mut out = Vec::new();
    let mut s = current;
    for _ in 0..AHEAD.min(len.saturating_sub(1)) {
        s = match (forward, s) {
            (true, s) if s + 1 < len => s + 1,
            (true, _) if interaction.looping => 0,
            (false, 0) if interaction.looping => len - 1,
            (false, s) if s > 0 => s - 1,
            _ => break,
        };
        out.push(s);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_level_of_detail_meets_the_budget_resolution_first() {
        let budget = INTERACTIVE_FRAME.as_secs_f64();
        let full = 1024.0 * 768.0;
        let frame = |cost: f64, (scale, steps): (f64, f64)| cost * full * scale * scale / steps;
        // Cheap: full resolution.
        assert_eq!(level_of_detail(budget / full / 2.0, full), (1.0, 1.0));
        // 4x over budget: half the side, every sample.
        let (s, k) = level_of_detail(4.0 * budget / full, full);
        assert!((s - 0.5).abs() < 1e-12 && k == 1.0);
        // 64x over: a quarter of the side and 4x the step, on budget.
        let cost = 64.0 * budget / full;
        let lod = level_of_detail(cost, full);
        assert_eq!(lod.0, 0.25);
        assert!((lod.1 - 4.0).abs() < 1e-9);
        assert!((frame(cost, lod) - budget).abs() < 1e-9);
        // 1000x over: 8x the step and a smaller image, on budget.
        let cost = 1000.0 * budget / full;
        let lod = level_of_detail(cost, full);
        assert_eq!(lod.1, 8.0);
        assert!(lod.0 < 0.25 && (frame(cost, lod) - budget).abs() < 1e-9);
        // Beyond what the smallest preview can do: the smallest preview.
        assert_eq!(level_of_detail(1e6 * budget / full, full), (MIN_SCALE, 8.0));
    }

    #[test]
    fn playback_reads_ahead_in_its_direction_and_wraps_only_when_looping() {
        let play = |forward, looping| Interaction {
            interacting: false,
            playing: Some(forward),
            looping,
        };
        assert_eq!(upcoming_steps(3, 10, play(true, false)), [4, 5, 6, 7]);
        assert_eq!(upcoming_steps(8, 10, play(true, false)), [9]);
        assert_eq!(upcoming_steps(8, 10, play(true, true)), [9, 0, 1, 2]);
        assert_eq!(upcoming_steps(1, 10, play(false, false)), [0]);
        assert_eq!(upcoming_steps(1, 10, play(false, true)), [0, 9, 8, 7]);
        assert_eq!(upcoming_steps(0, 1, play(true, true)), Vec::<usize>::new());
        assert!(upcoming_steps(3, 10, Interaction::default()).is_empty());
    }
}
