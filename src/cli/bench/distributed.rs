//! `aarbf bench distributed`: strong and weak scaling of the distributed renderer
//! (docs/distributed.md), each rank's bytes, times and memory per stage, on the generated
//! dam break.
//!
//! The ranks run as threads of this process (`LocalComm`), each in a pool of one thread, so a
//! rank's stage times are the CPU time of its own thread: its work alone, however many ranks
//! share this machine's cores (waiting in a collective sleeps and is not charged). The time
//! of P ranks on P cores is then modelled as the slowest rank's work plus the communication,
//! `α · messages + β · bytes`, with α and β measured on the communicator here.

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::Context;
use clap::Args;

use super::parse_size;
use crate::accel::ClusterSize;
use crate::backend::Precision;
use crate::backend::cpu::CpuBackend;
use crate::dist::balance::pilot_size;
use crate::dist::{
    Balance, Comm, CommExt, CostModel, DEFAULT_SHADOW_MAP, DistImage, DistScene, DistShadows,
    RankReport, render_piloted, run_local,
};
use crate::field::FieldSettings;
use crate::render::{AutoValues, FrameBasis, RenderSettings};
use crate::scene::TimeSeries;
use crate::scene::synth::Generator;
use crate::values::FrameParams;
use crate::values::Integrator;

/// The arguments of `aarbf bench distributed`.
#[derive(Debug, Args)]
pub struct DistributedArgs {
    /// The rank counts, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "1,2,4,8")]
    pub ranks: Vec<usize>,
    /// Particles of the strong-scaling step (the generated dam break's third step).
    #[arg(long, default_value_t = 1_000_000)]
    pub count: usize,
    /// Particles a rank in the weak-scaling runs (P ranks render P times as many); 0 skips
    /// them.
    #[arg(long, default_value_t = 250_000)]
    pub weak_count: usize,
    /// Image size, WxH.
    #[arg(long, default_value = "1024x1024", value_parser = parse_size)]
    pub size: (u32, u32),
    /// Frames accumulated (samples per pixel).
    #[arg(long, default_value_t = 1)]
    pub frames: u32,
    /// Early ray termination: the opacity a ray stops at (a brick stops where a bound of the
    /// bricks' in front times its own reaches it, from a coarse pass before the render); 1
    /// composites every sample.
    #[arg(long, default_value_t = 0.99)]
    pub opacity_threshold: f64,
    /// What the bricks are balanced by: `count` (equal particles) or `cost` (equal render
    /// time, measured by two pilot renders at a quarter of the size, which are not timed).
    #[arg(long, value_enum, default_value_t = Balance::Count)]
    pub balance: Balance,
    /// The particles' radius as a fraction of the step's diagonal.
    #[arg(long, default_value_t = 0.01)]
    pub radius: f64,
    /// The integrator: `ea`, or single scattering (`marching`, `delta`, `ss-reference`),
    /// whose runs add the light map of shadows across bricks to each rank's stages.
    #[arg(long, value_enum, default_value_t = Integrator::Ea)]
    pub integrator: Integrator,
    /// The light map's side in the scaling runs of single scattering.
    #[arg(long, value_name = "M", default_value_t = DEFAULT_SHADOW_MAP)]
    pub shadow_map: u32,
    /// Single scattering: the light map sides whose images are compared with the single
    /// rank's (FLIP, RMSE) at each rank count above 1, beside shadows from each ray's own brick
    /// only (`local`); `--shadow-maps` with no value skips the comparison.
    #[arg(long, value_delimiter = ',', num_args = 0.., default_value = "256,512,1024,2048")]
    pub shadow_maps: Vec<u32>,
    /// Where distributed.csv (a row per run and rank) and distributed.md are written.
    #[arg(long, default_value = "distributed")]
    pub out: PathBuf,
    /// Overwrite existing results.
    #[arg(long)]
    pub force: bool,
}

/// The communicator's cost: `α` seconds a message and `β` seconds a byte.
#[derive(Clone, Copy, Debug)]
struct Link {
    alpha: f64,
    beta: f64,
}

/// One rank of one run: its report and its read.
struct RankRow {
    report: RankReport,
    read_cpu_seconds: f64,
}

/// One run: P ranks on a step of N particles.
struct Run {
    scaling: &'static str,
    ranks: usize,
    particles: usize,
    rows: Vec<RankRow>,
}

impl RankRow {
    /// The rank's own work over every stage, in CPU seconds.
    fn work(&self) -> f64 {
        let r = &self.report;
        self.read_cpu_seconds
            + r.exchange_cpu_seconds
            + r.build_cpu_seconds
            + r.render_cpu_seconds
            + r.composite_cpu_seconds
            + r.shadow_map_cpu_seconds
    }
}

impl Run {
    fn slowest(&self) -> &RankRow {
        self.rows
            .iter()
            .max_by(|a, b| a.work().total_cmp(&b.work()))
            .expect("a run has ranks")
    }

    /// Messages a rank sends: P - 1 in each collective (the sample's all-gather, the
    /// exchange, the precision's all-gather, a composite a frame, the gathers of the image
    /// and the reports; with single scattering, the light map's scan, and for stochastic
    /// marching the scan of the depth in front each frame).
    fn messages(&self, frames: u32, integrator: Integrator) -> f64 {
        let collectives = 5
            + frames
            + match integrator {
                Integrator::Ea => 0,
                Integrator::Marching => 1 + frames,
                Integrator::Delta | Integrator::SsReference => 1,
            };
        ((self.ranks - 1) as f64) * f64::from(collectives)
    }

    /// The modelled communication: the rank that sends most, at the link's α and β.
    fn communication(&self, link: Link, frames: u32, integrator: Integrator) -> f64 {
        let bytes = self
            .rows
            .iter()
            .map(|r| r.report.particle_bytes + r.report.tile_bytes + r.report.shadow_map_bytes)
            .max()
            .unwrap_or(0);
        link.alpha * self.messages(frames, integrator) + link.beta * bytes as f64
    }

    /// The modelled time on P cores: the slowest rank's work plus the communication.
    fn modelled(&self, link: Link, frames: u32, integrator: Integrator) -> f64 {
        self.slowest().work() + self.communication(link, frames, integrator)
    }

    fn owned(&self) -> u64 {
        self.rows.iter().map(|r| r.report.owned).sum()
    }

    fn ghost_fraction(&self) -> f64 {
        let ghosts: u64 = self.rows.iter().map(|r| r.report.ghosts).sum();
        ghosts as f64 / self.owned().max(1) as f64
    }

    /// The largest brick against the mean, by particles owned.
    fn imbalance(&self) -> f64 {
        let max = self.rows.iter().map(|r| r.report.owned).max().unwrap_or(0);
        max as f64 * self.ranks as f64 / self.owned().max(1) as f64
    }
}

pub(super) fn run(args: DistributedArgs) -> anyhow::Result<()> {
    anyhow::ensure!(
        !args.ranks.is_empty() && args.ranks.iter().all(|&p| p >= 1),
        "--ranks takes rank counts of at least 1, e.g. 1,2,4,8"
    );
    anyhow::ensure!(
        args.count > 0 && args.radius > 0.0 && args.frames > 0,
        "--count, --radius and --frames must be positive"
    );
    let csv = args.out.join("distributed.csv");
    let md = args.out.join("distributed.md");
    for p in [&csv, &md] {
        crate::io::output::check_writable(p, args.force)?;
    }
    let link = measure_link()?;
    tracing::info!(
        "the communicator here: α = {:.1} µs a message, β = {:.2} GB/s",
        link.alpha * 1e6,
        1e-9 / link.beta
    );
    anyhow::ensure!(
        (1..=16384).contains(&args.shadow_map)
            && args.shadow_maps.iter().all(|m| (1..=16384).contains(m)),
        "light map sides are 1 to 16384 texels"
    );
    let mut runs = Vec::new();
    let mut plan: Vec<(&'static str, usize, usize)> = args
        .ranks
        .iter()
        .map(|&p| ("strong", p, args.count))
        .collect();
    if args.weak_count > 0 {
        plan.extend(args.ranks.iter().map(|&p| ("weak", p, args.weak_count * p)));
    }
    let bar = crate::progress::bar(plan.len() as u64, "distributed runs");
    for (scaling, ranks, particles) in plan {
        runs.push(run_one(&args, scaling, ranks, particles)?);
        bar.inc(1);
    }
    bar.finish_and_clear();
    let peak = super::peak_resident_bytes();

    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    crate::io::output::write_atomically(&csv, true, |p| std::fs::write(p, csv_rows(&runs)))?;
    let mut summary = summarise(&args, &runs, link, peak);
    if args.integrator != Integrator::Ea && !args.shadow_maps.is_empty() {
        let (series, step, field) = dam_break(&args, args.count)?;
        let (frames, _) = frames_of(&args, &series, &field)?;
        let scene = scene_of(&series, &field, DistShadows::Local);
        let compared =
            super::dist_shadows::compare(&step, &scene, &frames, &args.ranks, &args.shadow_maps)?;
        let path = args.out.join("shadows.csv");
        crate::io::output::write_atomically(&path, args.force, |p| {
            std::fs::write(p, super::dist_shadows::csv_rows(&compared))
        })?;
        summary.push_str(&super::dist_shadows::summarise(
            &format!(
                "{} on the strong-scaling step ({} particles, {}x{}, {} frame(s))",
                integrator_name(args.integrator),
                args.count,
                args.size.0,
                args.size.1,
                args.frames
            ),
            &compared,
        ));
    }
    crate::io::output::write_atomically(&md, true, |p| std::fs::write(p, &summary))?;
    #[expect(clippy::print_stdout, reason = "the summary is the command's output")]
    {
        println!("{summary}");
    }
    Ok(())
}

/// Renders one run: the dam break of `particles` split among `ranks`, each rank in a pool of
/// one thread.
fn run_one(
    args: &DistributedArgs,
    scaling: &'static str,
    ranks: usize,
    particles: usize,
) -> anyhow::Result<Run> {
    let (series, step, field) = dam_break(args, particles)?;
    let (frames, pilot) = frames_of(args, &series, &field)?;
    let scene = scene_of(&series, &field, DistShadows::PrefixMap(args.shadow_map));
    tracing::info!("{scaling} scaling: {particles} particles, {ranks} ranks");
    let results = run_local(ranks, |comm| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .map_err(|e| crate::dist::DistError::NotDistributed(e.to_string()))?;
        pool.install(|| {
            let clock = crate::dist::clock::StageClock::start();
            let local = crate::dist::slice_of(&step, comm.rank(), comm.size());
            let (_, read_cpu_seconds) = clock.stop();
            let (image, _) = render_piloted(
                comm,
                &mut CpuBackend::new(),
                local,
                &scene,
                &frames,
                pilot.as_ref(),
                None,
            )?;
            Ok((read_cpu_seconds, image))
        })
    })
    .with_context(|| format!("{ranks} ranks on {particles} particles"))?;
    let reads: Vec<f64> = results.iter().map(|(read, _)| *read).collect();
    let image: Option<DistImage> = results.into_iter().find_map(|(_, image)| image);
    let image = image.context("rank 0 returned no image")?;
    let rows = image
        .reports
        .iter()
        .zip(reads)
        .map(|(&report, read_cpu_seconds)| RankRow {
            report,
            read_cpu_seconds,
        })
        .collect();
    Ok(Run {
        scaling,
        ranks,
        particles,
        rows,
    })
}

/// The generated dam break of `particles` (its third step) and the field at `--radius`.
fn dam_break(
    args: &DistributedArgs,
    particles: usize,
) -> anyhow::Result<(
    TimeSeries,
    std::sync::Arc<crate::values::Step>,
    FieldSettings,
)> {
    const STEP: usize = 2;
    let series = TimeSeries::from_steps(Generator::DambreakDemo.generate(particles, STEP + 1, 1));
    let step = series.step(STEP)?;
    let field = FieldSettings::new(Some("velocity"), args.radius * step.bounds().diagonal());
    Ok((series, step, field))
}

/// What every rank of a run renders with: the CPU backend in f32, K = 16.
fn scene_of<'a>(
    series: &TimeSeries,
    field: &'a FieldSettings,
    shadows: DistShadows,
) -> DistScene<'a> {
    DistScene {
        field,
        cluster: ClusterSize::new(16).expect("16 is a cluster size"),
        series_bounds: series.bounds(),
        series_range: series.attribute("velocity").map(|a| (a.min, a.max)),
        precision: Precision::F32,
        periodic: None,
        shadows,
    }
}

/// The frames of a run: the default view of the step's series; and with `--balance cost`,
/// the pilot frame that measures the first decomposition's cost.
fn frames_of(
    args: &DistributedArgs,
    series: &TimeSeries,
    field: &FieldSettings,
) -> anyhow::Result<(Vec<FrameParams>, Option<FrameParams>)> {
    let settings = RenderSettings {
        width: args.size.0,
        height: args.size.1,
        opacity_threshold: args.opacity_threshold,
        integrator: args.integrator,
        ..RenderSettings::default()
    };
    let basis = FrameBasis {
        bounds: series.bounds(),
        max_count: series.max_count(),
        periodic: false,
        field,
        auto: AutoValues::of(series, field)?,
    };
    let frames = (0..args.frames)
        .map(|f| basis.frame_params(&settings, f))
        .collect::<Result<_, _>>()?;
    let pilot = match args.balance {
        Balance::Count => None,
        Balance::Cost => {
            let (width, height) = pilot_size(args.size.0, args.size.1);
            let small = RenderSettings {
                width,
                height,
                ..settings
            };
            Some(basis.frame_params(&small, 0)?)
        }
    };
    Ok((frames, pilot))
}

/// α and β of the communicator here: two ranks exchange messages of 0 B to 8 MiB in
/// all-to-all-v, each size timed 9 times; a least-squares line through the medians.
fn measure_link() -> anyhow::Result<Link> {
    const SIZES: [usize; 6] = [0, 1 << 10, 1 << 14, 1 << 18, 1 << 21, 1 << 23];
    let times = run_local(2, |comm| {
        let mut medians = Vec::new();
        for size in SIZES {
            let mut send = vec![Vec::new(), Vec::new()];
            send[1 - comm.rank()] = vec![1u8; size];
            let mut t: Vec<f64> = (0..9)
                .map(|_| {
                    let started = std::time::Instant::now();
                    comm.all_to_all_of(&send)
                        .map(|_| started.elapsed().as_secs_f64())
                })
                .collect::<Result<_, _>>()?;
            t.sort_by(f64::total_cmp);
            medians.push(t[t.len() / 2]);
        }
        Ok(medians)
    })?
    .swap_remove(0);
    let n = SIZES.len() as f64;
    let xs = SIZES.map(|s| s as f64);
    let (mx, my) = (xs.iter().sum::<f64>() / n, times.iter().sum::<f64>() / n);
    let sxy: f64 = xs
        .iter()
        .zip(&times)
        .map(|(x, y)| (x - mx) * (y - my))
        .sum();
    let sxx: f64 = xs.iter().map(|x| (x - mx).powi(2)).sum();
    let beta = (sxy / sxx).max(0.0);
    // The latency is what an empty message takes, never below zero.
    let alpha = (my - beta * mx).max(0.0).max(times[0].min(1e-3));
    Ok(Link { alpha, beta })
}

fn csv_rows(runs: &[Run]) -> String {
    let mut out = String::from(
        "scaling,ranks,particles,rank,read,owned,ghosts,particle_bytes,tile_bytes,memory_bytes,\
         shadow_map_bytes,read_cpu_s,exchange_cpu_s,build_cpu_s,shadow_map_cpu_s,render_cpu_s,\
         composite_cpu_s,exchange_wall_s,build_wall_s,shadow_map_wall_s,render_wall_s,\
         composite_wall_s\n",
    );
    for run in runs {
        for (rank, row) in run.rows.iter().enumerate() {
            let r = &row.report;
            let _ = writeln!(
                out,
                "{},{},{},{rank},{},{},{},{},{},{},{},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6}",
                run.scaling,
                run.ranks,
                run.particles,
                r.read,
                r.owned,
                r.ghosts,
                r.particle_bytes,
                r.tile_bytes,
                r.memory_bytes,
                r.shadow_map_bytes,
                row.read_cpu_seconds,
                r.exchange_cpu_seconds,
                r.build_cpu_seconds,
                r.shadow_map_cpu_seconds,
                r.render_cpu_seconds,
                r.composite_cpu_seconds,
                r.exchange_seconds,
                r.build_seconds,
                r.shadow_map_seconds,
                r.render_seconds,
                r.composite_seconds,
            );
        }
    }
    out
}

fn summarise(args: &DistributedArgs, runs: &[Run], link: Link, peak: Option<usize>) -> String {
    let mut md = String::new();
    let (w, h) = args.size;
    let _ = writeln!(
        md,
        "# Distributed rendering: scaling\n\n`aarbf bench distributed --ranks {} --count {} \
         --weak-count {} --size {w}x{h} --frames {} --radius {} --opacity-threshold {} --balance {} \
         --integrator {}{}`: the generated dam break's third step, radius {} of its diagonal, CPU \
         backend (f32, K = 16), {}, {w}x{h}, {} frame(s).\n\nEach rank runs as a thread of one process in a pool of one thread; its \
         times are its thread's CPU seconds, its work alone however many ranks share the cores. \
         T(P) models P ranks on P cores: the slowest rank's work plus the communication, \
         α·messages + β·bytes of the rank that sends most, with α = {:.1} µs and β = 1/({:.2} GB/s) \
         measured on this communicator (threads in one process). A rank's memory is its brick's \
         particles, its backend's arrays and structures and its largest layer.\n",
        args.ranks
            .iter()
            .map(usize::to_string)
            .collect::<Vec<_>>()
            .join(","),
        args.count,
        args.weak_count,
        args.frames,
        args.radius,
        args.opacity_threshold,
        args.balance,
        integrator_name(args.integrator),
        if args.integrator == Integrator::Ea {
            String::new()
        } else {
            format!(" --shadow-map {}", args.shadow_map)
        },
        args.radius,
        match args.integrator {
            Integrator::Ea => "emission-absorption".to_owned(),
            _ => format!(
                "single scattering ({}) with shadows across bricks by a {m}x{m} light map",
                integrator_name(args.integrator),
                m = args.shadow_map
            ),
        },
        args.frames,
        link.alpha * 1e6,
        1e-9 / link.beta.max(1e-30),
    );
    for scaling in ["strong", "weak"] {
        let these: Vec<&Run> = runs.iter().filter(|r| r.scaling == scaling).collect();
        let Some(base) = these.iter().find(|r| r.ranks == 1).or(these.first()) else {
            continue;
        };
        let t1 = base.modelled(link, args.frames, args.integrator);
        let _ = writeln!(
            md,
            "\n## {} scaling\n\n| P | particles | ghosts | largest brick / mean | slowest render / mean | slowest rank: read, exchange, build, light map, render, composite (s) | communication (ms) | T(P) (s) | efficiency | composite a frame, slowest (ms) | memory a rank, max (MiB) |\n|---|---|---|---|---|---|---|---|---|---|---|",
            if scaling == "strong" {
                "Strong"
            } else {
                "Weak"
            }
        );
        for run in &these {
            let s = &run.slowest();
            let r = &s.report;
            let t = run.modelled(link, args.frames, args.integrator);
            let efficiency = if scaling == "strong" {
                t1 * base.ranks as f64 / (run.ranks as f64 * t)
            } else {
                t1 / t
            };
            let composite = run
                .rows
                .iter()
                .map(|r| r.report.composite_cpu_seconds)
                .fold(0.0, f64::max)
                / f64::from(args.frames);
            let memory = run
                .rows
                .iter()
                .map(|r| r.report.memory_bytes)
                .max()
                .unwrap_or(0);
            let _ = writeln!(
                md,
                "| {} | {} | {:.1}% | {:.3} | {:.3} | {:.3}, {:.3}, {:.3}, {:.3}, {:.3}, {:.3} | {:.2} | {:.3} | {:.2} | {:.1} | {:.1} |",
                run.ranks,
                run.particles,
                100.0 * run.ghost_fraction(),
                run.imbalance(),
                CostModel::imbalance(
                    &run.rows
                        .iter()
                        .map(|r| r.report.render_cpu_seconds)
                        .collect::<Vec<_>>()
                ),
                s.read_cpu_seconds,
                r.exchange_cpu_seconds,
                r.build_cpu_seconds,
                r.shadow_map_cpu_seconds,
                r.render_cpu_seconds,
                r.composite_cpu_seconds,
                1e3 * run.communication(link, args.frames, args.integrator),
                t,
                efficiency,
                1e3 * composite,
                memory as f64 / 1048576.0,
            );
        }
    }
    if let Some(peak) = peak {
        let _ = writeln!(
            md,
            "\nPeak resident memory of the whole benchmark (every run's ranks in one process, \
             one run at a time): {:.0} MiB.",
            peak as f64 / 1048576.0
        );
    }
    md
}

/// The integrator's name as `--integrator` takes it.
fn integrator_name(integrator: Integrator) -> String {
    use clap::ValueEnum as _;
    integrator
        .to_possible_value()
        .map_or_else(|| format!("{integrator:?}"), |v| v.get_name().to_owned())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(owned: u64, ghosts: u64, render: f64, bytes: u64) -> RankRow {
        RankRow {
            report: RankReport {
                owned,
                ghosts,
                render_cpu_seconds: render,
                particle_bytes: bytes,
                ..RankReport::default()
            },
            read_cpu_seconds: 0.5,
        }
    }

    /// The model takes the slowest rank's work and the busiest sender's bytes.
    #[test]
    fn the_model_is_the_slowest_rank_plus_the_busiest_link() {
        let run = Run {
            scaling: "strong",
            ranks: 3,
            particles: 300,
            rows: vec![
                row(90, 9, 1.0, 10),
                row(120, 3, 2.0, 5),
                row(90, 0, 1.5, 1000),
            ],
        };
        let link = Link {
            alpha: 1e-3,
            beta: 1e-6,
        };
        assert_eq!(run.slowest().work(), 2.5);
        let comm = 1e-3 * 2.0 * 6.0 + 1e-6 * 1000.0;
        assert!((run.communication(link, 1, Integrator::Ea) - comm).abs() < 1e-15);
        assert!((run.modelled(link, 1, Integrator::Ea) - (2.5 + comm)).abs() < 1e-12);
        // Stochastic marching adds the light map's scan and a depth scan a frame.
        let comm = 1e-3 * 2.0 * 8.0 + 1e-6 * 1000.0;
        assert!((run.communication(link, 1, Integrator::Marching) - comm).abs() < 1e-15);
        assert!((run.ghost_fraction() - 12.0 / 300.0).abs() < 1e-15);
        assert!((run.imbalance() - 1.2).abs() < 1e-12);
    }
}
