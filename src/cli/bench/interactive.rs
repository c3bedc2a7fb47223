//! `aarbf bench interactive`: how the viewer feels on this machine, measured without a window.
//! The viewer's own render worker is driven as the window drives it during a drag (a new
//! camera every 1/60 s, the view marked as moving), then released; what the worker publishes
//! is timed.

use std::fmt::Write as _;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use clap::Args;

use super::median;
use crate::backend::BackendKind;
use crate::scene_file::resolve::{DataArgs, FieldOptions, resolve};
use crate::viewer::navigation::orbit;
use crate::viewer::worker::{INTERACTIVE_FRAME, ShownImage};
use crate::viewer::{Interaction, RenderWorker, ViewState};

#[derive(Debug, Args)]
pub struct InteractiveArgs {
    #[command(flatten)]
    pub data: DataArgs,
    #[command(flatten)]
    pub field: FieldOptions,
    #[arg(long, value_enum, default_value = "cpu")]
    pub backend: BackendKind,
    /// The view's full size, WxH (what the window's central panel would be).
    #[arg(long, default_value = "1024x768", value_parser = super::parse_size)]
    pub size: (u32, u32),
    /// Seconds of dragging.
    #[arg(long, default_value_t = 5.0)]
    pub drag_seconds: f64,
    /// Samples per pixel accumulated after the drag.
    #[arg(long, default_value_t = 4)]
    pub spp: u32,
    /// Where interactive.md is written (created if missing).
    #[arg(long, default_value = "interactive")]
    pub out: PathBuf,
    #[arg(long)]
    pub force: bool,
}

/// The window sends a new camera this often during a drag (a 60 Hz display).
const UI_FRAME: Duration = Duration::from_micros(16_667);
/// No phase of the benchmark waits longer than this for the worker.
const PATIENCE: Duration = Duration::from_secs(1800);

/// What the benchmark measured, phase by phase.
struct Measures {
    /// Opening: the first image, and the converged one, after the first `show`.
    first_image: Duration,
    open_converged: Duration,
    backend: String,
    drag: Drag,
    /// After the release: the first full-resolution image, its readback, and the spp.
    first_full: Duration,
    full_readback: Duration,
    converged: Duration,
}

/// What the window saw during the drag.
struct Drag {
    /// Each new preview: when it arrived, the image, and its frame time.
    previews: Vec<(Instant, Arc<ShownImage>, Duration)>,
    readbacks: Vec<f64>,
    /// The longest call of the window thread to the worker.
    window_wait: Duration,
    time: Duration,
}

pub(super) fn run(args: InteractiveArgs) -> anyhow::Result<()> {
    let md = args.out.join("interactive.md");
    crate::io::output::check_writable(&md, args.force)?;
    anyhow::ensure!(args.spp > 0, "--spp must be at least 1");
    anyhow::ensure!(args.drag_seconds > 0.0, "--drag-seconds must be positive");
    let loaded = resolve(&args.data, &args.field)?;
    let mut state = ViewState::of(&loaded, args.backend).map_err(anyhow::Error::msg)?;
    state.settings.width = args.size.0;
    state.settings.height = args.size.1;
    state.spp = args.spp;
    let count = loaded.series.step_info(loaded.step).map_or(0, |i| i.count);
    let name = loaded.data_path.display().to_string();
    let worker = RenderWorker::spawn(Arc::new(loaded.series), Box::new(|| {}));
    let measures = measure(&worker, &mut state, args.drag_seconds)?;
    let out = report(&args, &name, count, state.step, &measures)?;
    std::fs::create_dir_all(&args.out)?;
    crate::io::output::write_atomically(&md, true, |p| std::fs::write(p, &out))?;
    println!("{out}");
    tracing::info!("wrote {}", md.display());
    Ok(())
}

/// Opens the view, drags it for `drag_seconds`, and releases it, timing what the worker
/// publishes.
fn measure(
    worker: &RenderWorker,
    state: &mut ViewState,
    drag_seconds: f64,
) -> anyhow::Result<Measures> {
    let mut generation = 1;
    let idle = Interaction::default();

    // Opening: the first build (and, on a GPU backend, pipeline compilation) and a converged
    // image, as the window shows on start.
    let opened = Instant::now();
    worker.show(state, generation, idle);
    let first = worker.wait_for(PATIENCE, |s| {
        s.generation == generation && s.image.is_some()
    });
    let first_image = opened.elapsed();
    let settled = worker.wait_for(PATIENCE, |s| s.generation == generation && s.converged);
    anyhow::ensure!(
        settled.converged,
        "the worker did not converge: {settled:?}"
    );
    let open_converged = opened.elapsed();
    let backend = first
        .backend
        .clone()
        .map_or_else(|| "?".into(), |(n, d)| format!("{n} ({d})"));

    let drag = drag(
        worker,
        state,
        &mut generation,
        settled.image.clone(),
        drag_seconds,
    );

    // The release: full resolution, accumulated to the spp.
    let released = Instant::now();
    generation += 1;
    worker.show(state, generation, idle);
    let full = worker.wait_for(PATIENCE, |s| {
        s.generation == generation && s.full_resolution && s.image.is_some()
    });
    let first_full = released.elapsed();
    let full_readback = full.readback;
    let done = worker.wait_for(PATIENCE, |s| s.generation == generation && s.converged);
    let converged = released.elapsed();
    anyhow::ensure!(
        full.full_resolution && done.converged,
        "no full image: {done:?}"
    );
    Ok(Measures {
        first_image,
        open_converged,
        backend,
        drag,
        first_full,
        full_readback,
        converged,
    })
}

/// The drag: a new camera every `UI_FRAME` for `seconds`, the view marked as moving; `last`
/// is the image shown before it, so only new previews count.
fn drag(
    worker: &RenderWorker,
    state: &mut ViewState,
    generation: &mut u64,
    mut last: Option<Arc<ShownImage>>,
    seconds: f64,
) -> Drag {
    let moving = Interaction {
        interacting: true,
        ..Interaction::default()
    };
    let mut previews: Vec<(Instant, Arc<ShownImage>, Duration)> = Vec::new();
    let mut readbacks: Vec<f64> = Vec::new();
    let mut window_wait = Duration::ZERO;
    let started = Instant::now();
    while started.elapsed().as_secs_f64() < seconds {
        let tick = Instant::now();
        state.settings.camera = Some(orbit(state.camera(), 4.0, 0.0));
        *generation += 1;
        let call = Instant::now();
        worker.show(state, *generation, moving);
        let shown = worker.shown();
        window_wait = window_wait.max(call.elapsed());
        if let Some(image) = &shown.image
            && last.as_ref().is_none_or(|l| !Arc::ptr_eq(l, image))
            && !shown.full_resolution
        {
            previews.push((Instant::now(), image.clone(), shown.frame_time));
            readbacks.push(shown.readback.as_secs_f64());
            last = Some(image.clone());
        }
        std::thread::sleep(UI_FRAME.saturating_sub(tick.elapsed()));
    }
    Drag {
        previews,
        readbacks,
        window_wait,
        time: started.elapsed(),
    }
}

/// interactive.md: the measures as a table, the steady previews' medians among them.
fn report(
    args: &InteractiveArgs,
    name: &str,
    count: usize,
    step: usize,
    m: &Measures,
) -> anyhow::Result<String> {
    let (drag, previews) = (&m.drag, &m.drag.previews);
    let full_pixels = f64::from(args.size.0) * f64::from(args.size.1);
    // The first previews find the scale; the steady state is the second half.
    let steady = &previews[previews.len() / 2..];
    let intervals: Vec<f64> = steady
        .windows(2)
        .map(|w| (w[1].0 - w[0].0).as_secs_f64())
        .collect();
    let sizes: Vec<f64> = steady
        .iter()
        .map(|(_, i, _)| f64::from(i.width) * f64::from(i.height))
        .collect();
    let frame_times: Vec<f64> = steady.iter().map(|(_, _, t)| t.as_secs_f64()).collect();
    let median_size = median(sizes);
    let side = (median_size / full_pixels).sqrt();
    let backend = &m.backend;
    let mut out = String::new();
    writeln!(out, "# Interactive viewing: {name}\n")?;
    writeln!(
        out,
        "Step {} ({count} particles), view {}x{}, backend {backend}; a drag of {:.1} s (a new \
         camera every {:.1} ms), then {} spp at full resolution. Interactive frames aim at \
         {} ms.\n",
        step,
        args.size.0,
        args.size.1,
        drag.time.as_secs_f64(),
        UI_FRAME.as_secs_f64() * 1e3,
        args.spp,
        INTERACTIVE_FRAME.as_millis()
    )?;
    writeln!(out, "| measure | value |")?;
    writeln!(out, "|---|---|")?;
    writeln!(
        out,
        "| open: first image / converged | {:.2} s / {:.2} s |",
        m.first_image.as_secs_f64(),
        m.open_converged.as_secs_f64()
    )?;
    writeln!(
        out,
        "| window thread, longest call to the worker | {:.3} ms |",
        drag.window_wait.as_secs_f64() * 1e3
    )?;
    writeln!(
        out,
        "| previews during the drag | {} ({:.1} per second) |",
        previews.len(),
        previews.len() as f64 / drag.time.as_secs_f64()
    )?;
    writeln!(
        out,
        "| steady preview interval (median) | {:.1} ms |",
        median(intervals) * 1e3
    )?;
    writeln!(
        out,
        "| steady preview frame time (median) | {:.1} ms |",
        median(frame_times) * 1e3
    )?;
    writeln!(
        out,
        "| steady preview size (median) | {:.0} pixels, {:.0}% of the view's side |",
        median_size,
        side * 100.0
    )?;
    writeln!(
        out,
        "| image to the window (readback and conversion): preview / full | {:.2} ms / {:.2} ms |",
        median(drag.readbacks.clone()) * 1e3,
        m.full_readback.as_secs_f64() * 1e3
    )?;
    writeln!(
        out,
        "| after release: first full image / {} spp | {:.2} s / {:.2} s |",
        args.spp,
        m.first_full.as_secs_f64(),
        m.converged.as_secs_f64()
    )?;
    Ok(out)
}
