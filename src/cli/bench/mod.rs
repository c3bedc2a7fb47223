//! `aarbf bench`: measurements a user runs on their own data and machine.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::Context;
use clap::{Args, Subcommand};

mod dist_shadows;
mod distributed;
mod interactive;
mod study;

pub(super) use study::{tailor_help, warn_of_other_studies_options};

use super::render::step_range;
use crate::backend::{self, BackendKind};
use crate::render::{RenderSession, RenderSettings};
use crate::scene::prefetch::Prefetcher;
use crate::scene::{OpenOptions, TimeSeries};
use crate::scene_file::resolve::{DataArgs, FieldOptions, Resolved, resolve};
use crate::study::Study;
use crate::values::Step;

/// The arguments of `aarbf bench`: which measurement to run.
#[derive(Debug, Args)]
pub struct BenchArgs {
    /// The measurement: `playback` or one of the paper's studies, with its own options.
    #[command(subcommand)]
    pub what: BenchCommand,
}

#[derive(Debug, Subcommand)]
pub enum BenchCommand {
    /// Play a series step by step as a viewer does (the next steps read ahead on a worker
    /// thread) and write where each step's time goes: a CSV with one row per step and stage,
    /// and a Markdown summary with steps per second, each stage's share, the floors (copying
    /// a step in memory, reading its file from the page cache) and peak memory.
    Playback(PlaybackArgs),
    /// Drive the viewer's render worker as a drag does (a new camera every 1/60 s), then
    /// release: preview rate, size and frame time while moving, the time to a full image and
    /// to the spp after, and the longest the window thread waited (interactive.md).
    Interactive(interactive::InteractiveArgs),
    /// The paper's Fig. 9 (blue): frame time vs the global radius at K = 1 and K = 16, over the
    /// benchmark orbit (writes OUT/radius/radius.{csv,md,png}).
    Radius(study::StudyArgs),
    /// Fig. 9 (red) and Tables 1-2: frame, build and refit time and structure bytes vs K.
    Cluster(study::StudyArgs),
    /// Fig. 10a: the RT pipeline vs the LBVH traversal on one device, and the wgpu LBVH.
    Traversal(study::StudyArgs),
    /// Fig. 10b: blue vs white noise, frame time and error against a converged reference.
    Noise(study::StudyArgs),
    /// Build, refit, query and frame time vs N on a log-log plot with fitted exponents.
    Scaling(study::StudyArgs),
    /// Table 3: our method vs the voxel-grid baseline and Knoll et al.'s splatter, with the
    /// structure rebuilt every frame, and each one's image error against a converged reference.
    Baselines(study::StudyArgs),
    /// Speed vs accuracy: every knob's time and error against a converged f64 reference, the
    /// Pareto front, the defaults and --target-error against it.
    Accuracy(study::StudyArgs),
    /// The field error of the backends' f32 and double-single paths against the f64 reference
    /// at radii from 1e-6 to 1e2 of the domain, offsets up to 1e6 and Phi down to f32's
    /// denormals, on f64 and on f32-exact inputs (not the paper's).
    Extremes(study::StudyArgs),
    /// Every study above in turn, with the same options.
    All(study::StudyArgs),
    /// Strong and weak scaling of the distributed renderer (docs/distributed.md): each rank's
    /// bytes, times and memory per stage on the generated dam break, ranks as threads of one
    /// thread each, P ranks on P cores modelled from their own CPU times.
    Distributed(distributed::DistributedArgs),
}

#[derive(Debug, Args)]
pub struct PlaybackArgs {
    #[command(flatten)]
    pub data: DataArgs,
    #[command(flatten)]
    pub field: FieldOptions,
    /// The steps to play, `a..b` or `a..=b` (default: all).
    #[arg(long)]
    pub steps: Option<String>,
    #[arg(long, value_enum, default_value = "auto")]
    pub backend: BackendKind,
    /// Preview size, WxH.
    #[arg(long, default_value = "256x256", value_parser = parse_size)]
    pub size: (u32, u32),
    /// Frames per step.
    #[arg(long, default_value_t = 1)]
    pub spp: u32,
    /// Where playback.csv and playback.md are written (created if missing).
    #[arg(long, default_value = "playback")]
    pub out: PathBuf,
    /// Overwrite existing results.
    #[arg(long)]
    pub force: bool,
}

pub(super) fn parse_size(text: &str) -> Result<(u32, u32), String> {
    let (w, h) = text
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("'{text}' is not WxH"))?;
    let parse = |v: &str| {
        v.trim()
            .parse::<u32>()
            .ok()
            .filter(|&v| (1..=16384).contains(&v))
            .ok_or_else(|| format!("'{text}': sizes are 1..=16384"))
    };
    Ok((parse(w)?, parse(h)?))
}

pub(super) fn run(args: BenchArgs) -> anyhow::Result<()> {
    match args.what {
        BenchCommand::Playback(a) => playback(a),
        BenchCommand::Interactive(a) => interactive::run(a),
        BenchCommand::Radius(a) => study::run(Some(Study::Radius), &a),
        BenchCommand::Cluster(a) => study::run(Some(Study::Cluster), &a),
        BenchCommand::Traversal(a) => study::run(Some(Study::Traversal), &a),
        BenchCommand::Noise(a) => study::run(Some(Study::Noise), &a),
        BenchCommand::Scaling(a) => study::run(Some(Study::Scaling), &a),
        BenchCommand::Baselines(a) => study::run(Some(Study::Baselines), &a),
        BenchCommand::Accuracy(a) => study::run(Some(Study::Accuracy), &a),
        BenchCommand::Extremes(a) => study::run(Some(Study::Extremes), &a),
        BenchCommand::All(a) => study::run(None, &a),
        BenchCommand::Distributed(a) => distributed::run(a),
    }
}

/// The stages of a step change, in the order a step goes through them.
const STAGES: [&str; 7] = [
    "read+decode",
    "wait for step",
    "prepare (cpu)",
    "upload",
    "prepare (device)",
    "build",
    "frame",
];

struct StepTimes {
    step: usize,
    particles: usize,
    bytes: usize,
    /// Seconds per stage of `STAGES`, and the whole step as the player saw it.
    stages: [f64; 7],
    total: f64,
    /// Whether the worker had read the step before the player asked for it.
    prefetched: bool,
}

fn playback(args: PlaybackArgs) -> anyhow::Result<()> {
    let csv = args.out.join("playback.csv");
    let md = args.out.join("playback.md");
    for p in [&csv, &md] {
        crate::io::output::check_writable(p, args.force)?;
    }
    let first_open = first_open(&args.data)?;
    let opened = Instant::now();
    let data = DataArgs {
        rescan: args.data.rescan && first_open.is_none(),
        ..args.data.clone()
    };
    let resolved = resolve(&data, &args.field)?;
    let resolve_time = opened.elapsed();
    let series = &resolved.series;
    let (open_time, open_decoded) = (resolved.opened_in, resolved.decoded_at_open);
    let steps: Vec<usize> = match &args.steps {
        Some(text) => step_range(text, series.len())?.collect(),
        None => (0..series.len()).collect(),
    };
    anyhow::ensure!(!steps.is_empty(), "no steps to play");
    let backend = backend::create(args.backend)?;
    let device = format!(
        "{} ({})",
        backend.capabilities().name,
        backend.capabilities().device
    );
    tracing::info!("backend: {device}");
    let mut session = RenderSession::new(backend, series);
    let settings = RenderSettings {
        width: args.size.0,
        height: args.size.1,
        ..RenderSettings::default()
    };
    // Played as a series opened with its index is: nothing in memory yet, every step read
    // (ahead) during playback.
    series.clear_cache();
    let bar = crate::progress::bar(steps.len() as u64, "playing");
    let played = Instant::now();
    let times = play(&mut session, &resolved, &steps, &settings, args.spp, &bar)?;
    let play_time = played.elapsed();
    bar.finish_and_clear();
    // The image is read back once, as a batch render writes it, and kept for the record.
    let image = session.image()?;
    let peak = peak_resident_bytes();
    let floors = floors(series, &steps)?;

    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let rows = csv_rows(series, &times, &steps, &floors)?;
    crate::io::output::write_atomically(&csv, true, |p| std::fs::write(p, &rows))?;

    let summary = summarise(&Summary {
        args: &args,
        data: &resolved.data_path,
        device: &device,
        series,
        times: &times,
        floors: &floors,
        open_time,
        open_decoded,
        resolve_time,
        first_open,
        play_time,
        peak,
        backend_bytes: {
            let m = session.backend().memory();
            m.particle_bytes + m.structure_bytes + m.image_bytes + m.preparation_bytes
        },
        image_mean: image.pixels.iter().map(|p| p[3]).sum::<f32>() / image.pixels.len() as f32,
    });
    crate::io::output::write_atomically(&md, true, |p| std::fs::write(p, &summary))?;
    println!("{summary}");
    tracing::info!("wrote {} and {}", csv.display(), md.display());
    Ok(())
}

/// With --rescan, first how a first open goes (the index ignored): a background open, which
/// returns after the first step, and the scan it leaves running.
fn first_open(data: &DataArgs) -> anyhow::Result<Option<FirstOpen>> {
    Ok(match &data.data {
        Some(path) if data.rescan => {
            let started = Instant::now();
            let series = TimeSeries::open(
                path,
                &OpenOptions {
                    format: data.format,
                    cache_bytes: data.cache_mib << 20,
                    background_scan: true,
                    rescan: true,
                    ..OpenOptions::default()
                },
            )?;
            let returned = started.elapsed();
            let decoded = series.steps_decoded();
            series.wait_for_scan()?;
            Some(FirstOpen {
                returned,
                decoded,
                scanned: started.elapsed(),
            })
        }
        _ => None,
    })
}

/// Plays `steps` as a viewer does, the next steps read ahead on a worker thread, timing each
/// stage of each step.
fn play(
    session: &mut RenderSession,
    resolved: &Resolved,
    steps: &[usize],
    settings: &RenderSettings,
    spp: u32,
    bar: &indicatif::ProgressBar,
) -> anyhow::Result<Vec<StepTimes>> {
    let series = &resolved.series;
    std::thread::scope(|scope| -> anyhow::Result<Vec<StepTimes>> {
        let prefetcher = Prefetcher::spawn(scope, series);
        let mut times = Vec::with_capacity(steps.len());
        for (k, &step) in steps.iter().enumerate() {
            let started = Instant::now();
            let prefetched = series.is_cached(step);
            prefetcher.plan(step, steps[k + 1..].iter().copied());
            let data = series.step(step)?;
            let wait = started.elapsed();
            session.show(series, step, &resolved.field, resolved.cluster)?;
            let t = session.backend().timings();
            let frame = Instant::now();
            session.accumulate(settings, spp)?;
            let frame = frame.elapsed();
            times.push(StepTimes {
                step,
                particles: data.len(),
                bytes: data.bytes(),
                stages: [
                    series.read_time(step).unwrap_or_default(),
                    wait,
                    t.prepare,
                    t.upload,
                    t.device_prepare,
                    t.build,
                    frame,
                ]
                .map(|d| d.as_secs_f64()),
                total: started.elapsed().as_secs_f64(),
                prefetched,
            });
            bar.inc(1);
        }
        Ok(times)
    })
}

/// playback.csv: a row per step and stage, the whole step, and the floors.
fn csv_rows(
    series: &TimeSeries,
    times: &[StepTimes],
    steps: &[usize],
    floors: &[Floor],
) -> anyhow::Result<String> {
    let mut rows = String::from("step,particles,bytes,stage,seconds\n");
    for t in times {
        for (stage, s) in STAGES.iter().zip(t.stages) {
            writeln!(
                rows,
                "{},{},{},{stage},{s:.6}",
                t.step, t.particles, t.bytes
            )?;
        }
        writeln!(
            rows,
            "{},{},{},step,{:.6}",
            t.step, t.particles, t.bytes, t.total
        )?;
    }
    for (step, f) in steps.iter().zip(floors) {
        let info = series.step_info(*step).expect("a step of the series");
        let (n, bytes) = (info.count, info.bytes);
        writeln!(
            rows,
            "{step},{n},{bytes},floor: copy in memory,{:.6}",
            f.copy
        )?;
        if let Some(r) = f.page_cache {
            writeln!(
                rows,
                "{step},{n},{bytes},floor: read from page cache,{r:.6}"
            )?;
        }
    }
    Ok(rows)
}

struct Floor {
    /// Copying the step's bytes into memory that is already allocated.
    copy: f64,
    /// Reading the step's file (from the page cache: it was just read), if it has one.
    page_cache: Option<f64>,
}

fn floors(series: &TimeSeries, steps: &[usize]) -> anyhow::Result<Vec<Floor>> {
    let mut out = Vec::with_capacity(steps.len());
    let mut positions = Vec::new();
    let mut values = Vec::new();
    for &i in steps {
        let step = series.step(i)?;
        let copy = best_of(3, || copy_step(&step, &mut positions, &mut values));
        let page_cache = match series.step_file(i) {
            Some(path) => {
                let mut buffer = Vec::new();
                Some(best_of(3, || read_file(path, &mut buffer)))
            }
            None => None,
        };
        out.push(Floor { copy, page_cache });
    }
    Ok(out)
}

fn best_of(n: usize, mut f: impl FnMut()) -> f64 {
    (0..n)
        .map(|_| {
            let t = Instant::now();
            f();
            t.elapsed().as_secs_f64()
        })
        .fold(f64::INFINITY, f64::min)
}

fn copy_step(step: &Step, positions: &mut Vec<glam::DVec3>, values: &mut Vec<f64>) {
    positions.clear();
    positions.extend_from_slice(&step.positions);
    values.clear();
    for a in &step.attributes {
        values.extend_from_slice(&a.values);
    }
    std::hint::black_box((positions, values));
}

fn read_file(path: &Path, buffer: &mut Vec<u8>) {
    use std::io::Read;
    buffer.clear();
    if let Ok(mut f) = std::fs::File::open(path) {
        let _ = f.read_to_end(buffer);
    }
    std::hint::black_box(buffer);
}

/// The process's peak resident memory (Linux: VmHWM), if the system reports it.
fn peak_resident_bytes() -> Option<usize> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: usize = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// A background open with the index ignored (`--rescan`).
struct FirstOpen {
    /// Until `open` returned (the files listed, the first step read).
    returned: Duration,
    decoded: usize,
    /// Until the background scan had read every step.
    scanned: Duration,
}

struct Summary<'a> {
    args: &'a PlaybackArgs,
    /// The data played (from `--data` or the scene file; a step's own name, e.g. `0000`,
    /// says nothing).
    data: &'a std::path::Path,
    device: &'a str,
    series: &'a TimeSeries,
    times: &'a [StepTimes],
    floors: &'a [Floor],
    open_time: Duration,
    open_decoded: usize,
    /// Opening and the settings taken from the data (the cluster size, ranges) together.
    resolve_time: Duration,
    first_open: Option<FirstOpen>,
    play_time: Duration,
    peak: Option<usize>,
    backend_bytes: usize,
    image_mean: f32,
}

pub(super) fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn summarise(s: &Summary<'_>) -> String {
    let mut out = String::new();
    // The first step also creates pipelines and buffers and computes the series' automatic
    // values: the rates are over the steps after it (all of them if only one was played).
    let steady = if s.times.len() > 1 {
        &s.times[1..]
    } else {
        s.times
    };
    let max_step = s.series.steps().iter().map(|i| i.bytes).max().unwrap_or(0);
    say_opening_and_rate(&mut out, s, steady, max_step);
    stage_table(&mut out, steady);
    say_floors(&mut out, s, steady);
    say_peak_memory(&mut out, s, max_step);
    let _ = writeln!(
        out,
        "\nLast frame's mean opacity: {:.4} (a check that frames were drawn).",
        s.image_mean
    );
    out
}

fn mib(bytes: usize) -> f64 {
    bytes as f64 / 1048576.0
}

/// The summary's heading, the time to open the series, and the steps per second.
fn say_opening_and_rate(out: &mut String, s: &Summary<'_>, steady: &[StepTimes], max_step: usize) {
    let n = s.times.len();
    let steady_total: f64 = steady.iter().map(|t| t.total).sum();
    let _ = writeln!(out, "# Playback: {}\n", s.data.display());
    let _ = writeln!(
        out,
        "{n} steps of up to {} particles ({:.1} MiB per step in memory), {}x{} at {} spp, \
         backend {}.\n",
        s.series.max_count(),
        mib(max_step),
        s.args.size.0,
        s.args.size.1,
        s.args.spp,
        s.device
    );
    let _ = writeln!(
        out,
        "- opening the series for playback: {:.3} s, {} of {} steps decoded (the rest from the \
         index); with the settings taken from the data (cluster size, ranges): {:.3} s",
        s.open_time.as_secs_f64(),
        s.open_decoded,
        s.series.len(),
        s.resolve_time.as_secs_f64()
    );
    if let Some(f) = &s.first_open {
        let read = median(s.times.iter().map(|t| t.stages[0]).collect());
        let _ = writeln!(
            out,
            "- a first open (--rescan: the index ignored, a background open as the viewer's): \
             returned after {:.3} s with {} of {} steps decoded, {:.1}x one step's read and \
             decode ({:.3} s, the median below); the background scan had every step after {:.3} s",
            f.returned.as_secs_f64(),
            f.decoded,
            s.series.len(),
            f.returned.as_secs_f64() / read,
            read,
            f.scanned.as_secs_f64()
        );
    }
    let _ = writeln!(
        out,
        "- playback: {:.2} steps/s over steps 2..{n} ({:.3} s per step; {:.2} s in all, the \
         first step included); {} of {n} steps were read ahead before the player needed them",
        steady.len() as f64 / steady_total,
        steady_total / steady.len() as f64,
        s.play_time.as_secs_f64(),
        s.times.iter().filter(|t| t.prefetched).count()
    );
}

/// Each stage's median, mean and share of a step, over the steady steps.
fn stage_table(out: &mut String, steady: &[StepTimes]) {
    let steady_total: f64 = steady.iter().map(|t| t.total).sum();
    let _ = writeln!(
        out,
        "\n| stage | median (ms) | mean (ms) | share of a step |"
    );
    let _ = writeln!(out, "|---|---|---|---|");
    for (k, stage) in STAGES.iter().enumerate() {
        let v: Vec<f64> = steady.iter().map(|t| t.stages[k]).collect();
        let mean = v.iter().sum::<f64>() / v.len() as f64;
        let share = if k == 0 {
            // Reading happens on the worker, overlapped with rendering; what it costs the
            // player is the wait.
            "(worker, overlapped)".to_string()
        } else {
            format!("{:.0}%", 100.0 * v.iter().sum::<f64>() / steady_total)
        };
        let _ = writeln!(
            out,
            "| {stage} | {:.2} | {:.2} | {share} |",
            1e3 * median(v.clone()),
            1e3 * mean
        );
    }
    let _ = writeln!(
        out,
        "| whole step | {:.2} | {:.2} | 100% |",
        1e3 * median(steady.iter().map(|t| t.total).collect()),
        1e3 * steady_total / steady.len() as f64
    );
}

/// The floors a step change is measured against: copying a step in memory, reading its file.
fn say_floors(out: &mut String, s: &Summary<'_>, steady: &[StepTimes]) {
    let copy = median(s.floors.iter().map(|f| f.copy).collect());
    let _ = writeln!(out, "\nFloors, per step (median, best of 3 each):\n");
    let _ = writeln!(
        out,
        "- copying the step's bytes in memory: {:.2} ms; CPU work per step change \
         (prepare + upload) is {:.1}x that",
        1e3 * copy,
        median(steady.iter().map(|t| t.stages[2] + t.stages[3]).collect()) / copy
    );
    let page: Vec<f64> = s.floors.iter().filter_map(|f| f.page_cache).collect();
    if !page.is_empty() {
        let _ = writeln!(
            out,
            "- reading the step's file from the page cache: {:.2} ms; reading and decoding it \
             is {:.1}x that",
            1e3 * median(page.clone()),
            median(steady.iter().map(|t| t.stages[0]).collect()) / median(page)
        );
    }
}

/// The peak resident memory beside what bounds it.
fn say_peak_memory(out: &mut String, s: &Summary<'_>, max_step: usize) {
    let bound = s.series.cache_limit();
    match s.peak {
        Some(peak) => {
            let _ = writeln!(
                out,
                "\nPeak resident memory: {:.0} MiB (the step cache's bound {:.0} MiB + the \
                 largest step {:.1} MiB + the backend's buffers {:.1} MiB = {:.0} MiB).",
                mib(peak),
                mib(bound),
                mib(max_step),
                mib(s.backend_bytes),
                mib(bound + max_step + s.backend_bytes)
            );
        }
        None => {
            let _ = writeln!(out, "\nPeak resident memory: not reported by this system.");
        }
    }
}
