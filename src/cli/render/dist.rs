//! `aarbf render --ranks N`, and `mpirun -np N aarbf render` in a build with the `mpi` feature:
//! the distributed renderer ([`crate::dist`]) with N ranks, as threads of this process or as the
//! processes of an MPI job. Each rank reads its share of the step's records (`[rN/P,
//! (r+1)N/P)`, [`crate::io::read_step_part`]), and from there on sees the others only through
//! the communicator: decomposition, particle exchange, its brick's render, direct-send
//! compositing; rank 0 writes the image. A failing rank ends every rank, naming itself. The
//! automatic values that come from the first step (Phi_ref without `--phi-ref`, the cluster
//! size without `--cluster`) are computed by the ranks from their parts of it
//! ([`crate::dist::auto`]): no process reads a whole step for them.

use std::sync::{Mutex, MutexGuard};
use std::time::Instant;

use anyhow::{Context, bail, ensure};

use super::RenderArgs;
use super::plan::Frame;
use crate::backend::cpu::CpuBackend;
use crate::backend::{Backend, BackendKind, Precision};
use crate::cli::output_format::OutputFormat;
use crate::dist::balance::pilot_size;
use crate::dist::knn::RankLengths;
use crate::dist::step_stats;
use crate::dist::target::{converged_reference_on, render_to_target_on};
use crate::dist::{
    Balance, Comm, CostModel, DistError, DistImage, DistScene, DistShadows, RankReport,
    prepare_brick, render_piloted, run_local, shadow_map_for,
};
use crate::field::FieldSettings;
use crate::io::Part;
use crate::io::{AttributeSelection, DataError, Problem, StepRef};
use crate::render::converged::{ParticlesDigest, Reference, ReferenceOptions};
use crate::render::legend::Legend;
use crate::render::target::Targeted;
use crate::render::{AutoValues, FrameBasis, Method, RenderSettings};
use crate::scene::StepsScan;
use crate::scene::TimeSeries;
use crate::scene::index::StepStats;
use crate::scene::smoothing::Smoothing;
use crate::scene_file::resolve::{
    DataReads, FirstStep, FirstStepFacts, Resolved, positive, smoothing_length_in,
};
use crate::values::{FrameParams, Integrator};

/// `--dist-shadows`: how shadow rays cross the bricks of a distributed render.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ShadowsAcross {
    /// Through every brick, by a light map scanned from the light ([`DistShadows::PrefixMap`]).
    PrefixMap,
    /// Through the ray's own brick only ([`DistShadows::Local`]).
    Local,
}

/// The shadows `args` ask for: by default a light map as fine as the image
/// ([`shadow_map_for`]).
fn shadows(args: &RenderArgs, settings: &RenderSettings) -> anyhow::Result<DistShadows> {
    let size = args
        .shadow_map
        .unwrap_or_else(|| shadow_map_for(settings.width, settings.height));
    ensure!(
        (1..=16384).contains(&size),
        "--shadow-map {size}: the light map's side is 1 to 16384 texels"
    );
    match args.dist_shadows.unwrap_or(ShadowsAcross::PrefixMap) {
        ShadowsAcross::PrefixMap => Ok(DistShadows::PrefixMap(size)),
        ShadowsAcross::Local => {
            ensure!(
                args.shadow_map.is_none(),
                "--shadow-map sizes the light map of --dist-shadows prefix-map; --dist-shadows \
                 local has none"
            );
            Ok(DistShadows::Local)
        }
    }
}

/// How the ranks of a distributed render run.
pub(super) enum Ranks {
    /// `--ranks N`: threads of this process.
    Threads(usize),
    /// The processes of an MPI job (`mpirun -np N aarbf render`), this one among them.
    #[cfg(feature = "mpi")]
    Mpi(crate::dist::MpiComm),
}

impl Ranks {
    /// How the user asked for the ranks, for messages.
    fn asked_by(&self) -> &'static str {
        match self {
            Ranks::Threads(_) => "--ranks",
            #[cfg(feature = "mpi")]
            Ranks::Mpi(_) => "mpirun",
        }
    }

    fn size(&self) -> usize {
        match self {
            Ranks::Threads(n) => *n,
            #[cfg(feature = "mpi")]
            Ranks::Mpi(comm) => comm.size(),
        }
    }

    /// The ranks this process runs: all of them as threads, or itself in an MPI job.
    fn local_count(&self) -> usize {
        match self {
            Ranks::Threads(n) => (*n).max(1),
            #[cfg(feature = "mpi")]
            Ranks::Mpi(_) => 1,
        }
    }
}

/// Whether, and how, this render is distributed: `--ranks N`, or the processes of the MPI job
/// this one was started in. A build without MPI started by an MPI launcher refuses, since each
/// process would render the whole image and write the same file.
pub(super) fn ranks(args: &RenderArgs) -> anyhow::Result<Option<Ranks>> {
    let Some(launched) = crate::dist::launched_size() else {
        return Ok(args.ranks.map(Ranks::Threads));
    };
    ensure!(
        args.ranks.is_none(),
        "--ranks runs the ranks as threads of one process, and this one was started by an MPI \
         launcher ({launched} processes): use one or the other"
    );
    mpi_job(launched)
}

#[cfg(feature = "mpi")]
fn mpi_job(launched: usize) -> anyhow::Result<Option<Ranks>> {
    let Some(comm) = crate::dist::MpiComm::init() else {
        bail!("MPI did not initialise at thread level Funneled ({launched} processes)");
    };
    // The cores of a node are shared among its ranks (rayon would start one thread a core
    // in each), unless the user said otherwise.
    if std::env::var_os("RAYON_NUM_THREADS").is_none() {
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        let local = crate::dist::node_local_size().unwrap_or(1).max(1);
        let threads = (cores / local).max(1);
        if rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build_global()
            .is_ok()
        {
            tracing::debug!("{threads} threads a rank ({cores} cores, {local} ranks a node)");
        }
    }
    Ok(Some(Ranks::Mpi(comm)))
}

#[cfg(not(feature = "mpi"))]
fn mpi_job(launched: usize) -> anyhow::Result<Option<Ranks>> {
    if launched <= 1 {
        return Ok(None);
    }
    bail!(
        "aarbf was started as one of {launched} MPI processes, but this build has no MPI \
         support: each process would render the whole image. Rebuild with `cargo xtask setup \
         --mpi && cargo build --release --features mpi`, or run one process with --ranks \
         {launched} (ranks as threads; docs/distributed.md)"
    )
}

/// `compute` on every rank, each holding its communicator: as threads of this process, rank 0's
/// result (every rank's is the same); under MPI, this process's, a failure ending the job.
fn on_every_rank<T: Send>(
    ranks: &Ranks,
    what: &str,
    compute: impl Fn(&dyn Comm) -> Result<T, DistError> + Sync,
) -> anyhow::Result<T> {
    match ranks {
        Ranks::Threads(n) => {
            let mut results = run_local(*n, |comm| compute(comm)).context(what.to_owned())?;
            Ok(results.swap_remove(0))
        }
        #[cfg(feature = "mpi")]
        Ranks::Mpi(comm) => match compute(comm) {
            Ok(value) => Ok(value),
            Err(e) => {
                comm.abort(&format!("{what}: {e}"));
                unreachable!("MPI_Abort returned");
            }
        },
    }
}

/// The automatic values of `field` over `series` ([`AutoValues::with_phi_ref`]), Phi_ref (unless
/// `given`) computed by the ranks from their parts of the first step ([`crate::dist::auto`]).
fn auto_values(
    ranks: &Ranks,
    series: &TimeSeries,
    field: &FieldSettings,
    given: Option<f64>,
) -> anyhow::Result<AutoValues> {
    on_every_rank(ranks, "Phi_ref from the ranks' parts of step 0", |comm| {
        crate::dist::auto::auto_values(comm, series, field, given)
    })
}

/// The mean overlap that chooses the cluster size ([`crate::render::auto::mean_overlap`]),
/// computed by the ranks from their parts of the first step ([`crate::dist::auto`]).
pub(super) fn mean_overlap(
    ranks: &Ranks,
    series: &TimeSeries,
    field: &FieldSettings,
) -> anyhow::Result<f64> {
    on_every_rank(
        ranks,
        "the mean overlap from the ranks' parts of step 0",
        |comm| crate::dist::auto::mean_overlap(comm, series, field),
    )
}

/// The ranks learn what resolving needs from their parts of the data: the statistics of the
/// steps the series' index lacks ([`crate::dist::step_stats`]) and the mean overlap.
impl DataReads for Ranks {
    fn steps_scan(&self) -> Option<&dyn StepsScan> {
        Some(self)
    }

    fn mean_overlap(&self, series: &TimeSeries, field: &FieldSettings) -> anyhow::Result<f64> {
        mean_overlap(self, series, field)
    }

    /// Each rank reads its part of the step with every attribute: the names, and the median of
    /// a smoothing length over the parts ([`crate::dist::order::median`]).
    fn first_step(&self, first: &StepRef) -> anyhow::Result<FirstStep> {
        on_every_rank(
            self,
            "the first step's attributes from the ranks' parts",
            |comm| {
                let part = crate::io::read_step_part(
                    first,
                    &AttributeSelection::All,
                    Part::new(comm.rank(), comm.size()),
                )?
                .step;
                let names: Vec<String> = part
                    .attribute_names()
                    .iter()
                    .map(|n| n.to_string())
                    .collect();
                let smoothing_length = match smoothing_length_in(&names) {
                    Some(name) => {
                        let values = part.attribute(name).map_or(&[][..], |a| &a.values[..]);
                        let median = crate::dist::order::median(comm, &positive(values))?;
                        Some((name.to_owned(), median))
                    }
                    None => None,
                };
                Ok(FirstStep::FromParts(FirstStepFacts {
                    names,
                    smoothing_length,
                }))
            },
        )
    }

    fn first_step_spacing(&self, series: &TimeSeries) -> anyhow::Result<Option<f64>> {
        on_every_rank(
            self,
            "the particles' spacing from the ranks' parts",
            |comm| crate::dist::auto::first_step_spacing(comm, series),
        )
    }
}

impl StepsScan for Ranks {
    fn stats(
        &self,
        steps: &[StepRef],
        which: &[usize],
        selection: &AttributeSelection,
        smoothing: Option<Smoothing>,
    ) -> Result<Vec<StepStats>, DataError> {
        let scan = |comm: &dyn Comm| {
            let (stats, decoded) = step_stats::of_parts(comm, steps, which, selection, smoothing)?;
            tracing::debug!(
                "rank {} decoded {decoded} records scanning {} steps the index lacks",
                comm.rank(),
                which.len()
            );
            Ok(stats)
        };
        let as_data_error = |e: DistError| {
            e.into_data_error(|other| {
                DataError::new(
                    &steps[which.first().copied().unwrap_or(0)].path,
                    None,
                    Problem::Malformed(format!("the ranks' scan of the series: {other}")),
                )
            })
        };
        if which.len() > 1 {
            tracing::info!(
                "scanning {} steps the series' index lacks, each rank its part of each",
                which.len()
            );
        }
        match self {
            Ranks::Threads(n) => run_local(*n, |comm| scan(comm))
                .map(|mut stats| stats.swap_remove(0))
                .map_err(as_data_error),
            #[cfg(feature = "mpi")]
            Ranks::Mpi(comm) => match scan(comm) {
                Ok(stats) => Ok(stats),
                // A name the data lacks is every rank's answer (each reads the same header):
                // said as a single process says it (the caller may try another spelling).
                Err(DistError::Read(e))
                    if matches!(e.problem, Problem::MissingAttribute { .. }) =>
                {
                    Err(e)
                }
                Err(e) => {
                    comm.abort(&format!("scanning the series: {e}"));
                    unreachable!("MPI_Abort returned");
                }
            },
        }
    }

    fn writes_index(&self) -> bool {
        match self {
            Ranks::Threads(_) => true,
            #[cfg(feature = "mpi")]
            Ranks::Mpi(comm) => comm.rank() == 0,
        }
    }
}

/// Refuses what the distributed renderer does not do yet, naming it.
fn check_supported(
    args: &RenderArgs,
    settings: &RenderSettings,
    ranks: &Ranks,
) -> anyhow::Result<()> {
    let how = ranks.asked_by();
    ensure!(ranks.size() >= 1, "{how} needs at least 1 rank");
    ensure!(
        args.method == Method::Rbf && settings.splat_k.is_none() && settings.voxel_grid.is_none(),
        "{how} renders with --method rbf (the baselines are not distributed)"
    );
    ensure!(
        args.save_scene.is_none(),
        "{how}: --save-scene is not distributed yet; save the scene from a single-rank render"
    );
    Ok(())
}

/// Renders each planned image with `ranks` ranks and writes it from rank 0.
#[allow(clippy::too_many_arguments)]
pub(super) fn run(
    args: &RenderArgs,
    mut resolved: Resolved,
    mut settings: RenderSettings,
    frames: &[Frame],
    format: OutputFormat,
    draw_legend: bool,
    precision: Precision,
    ranks: Ranks,
) -> anyhow::Result<()> {
    let size = ranks.size();
    check_supported(args, &settings, &ranks)?;
    let shadows = shadows(args, &settings)?;
    if settings.integrator == Integrator::Ea
        && (args.dist_shadows.is_some() || args.shadow_map.is_some())
    {
        tracing::warn!(
            "--dist-shadows and --shadow-map have no effect on emission-absorption, which casts \
             no shadow rays (--integrator marching, delta or ss-reference does)"
        );
    }
    let spp = resolved.scene.spp();
    let target = resolved.scene.target().map_err(anyhow::Error::msg)?;
    let how = match &ranks {
        Ranks::Threads(_) => format!("{size} ranks as threads of this process"),
        #[cfg(feature = "mpi")]
        Ranks::Mpi(comm) => format!("rank {} of {size} MPI processes", comm.rank()),
    };
    let shading = match (settings.integrator, shadows) {
        (Integrator::Ea, _) => "emission-absorption".to_owned(),
        (_, DistShadows::PrefixMap(m)) => format!(
            "single scattering, shadows across bricks by a {m}x{m} light map (--dist-shadows \
             prefix-map)"
        ),
        (_, DistShadows::Local) => {
            "single scattering, shadows within each brick only (--dist-shadows local)".to_owned()
        }
    };
    // Each rank renders its brick on a backend of its own, made once and kept for every
    // image: on the CPU, or on the process's GPU device (one device per process, shared by
    // the ranks that are its threads; under MPI each process opens its own).
    let threads = matches!(ranks, Ranks::Threads(_));
    let slots: Vec<Mutex<Option<Box<dyn Backend>>>> =
        (0..ranks.local_count()).map(|_| Mutex::new(None)).collect();
    // The kind the first rank's backend turned out to be: the other ranks that are threads of
    // this process take it without choosing (and saying so) again.
    let (backend_name, backend_kind) = if args.reference {
        // The reference is the CPU backend's f64 image, whatever --backend says (as one
        // process makes it).
        (
            "cpu backend in f64 (--reference)".to_owned(),
            BackendKind::Cpu,
        )
    } else {
        let mut slot = lock(&slots[0]);
        let backend = slot.insert(crate::backend::create(args.backend)?);
        let capabilities = backend.capabilities();
        let kind = <BackendKind as clap::ValueEnum>::from_str(capabilities.name, false)
            .map_err(anyhow::Error::msg)?;
        (
            format!("{} backend ({})", capabilities.name, capabilities.device),
            kind,
        )
    };
    tracing::info!(
        "distributed: {how}, {backend_name}, {shading}, bricks balanced by {} (--balance)",
        args.balance
    );
    if let Some(b) = &resolved.periodic {
        tracing::info!(
            "periodic box from {:?} of sides {:?}: each rank wraps its particles into it and \
             exchanges their images across the faces as particles",
            b.min.to_array(),
            b.size.to_array()
        );
    }
    // With --balance cost, what the last image measured: the next one's decomposition.
    let mut cost: Option<CostModel> = None;
    let mut auto_for: Option<(FieldSettings, AutoValues)> = None;
    for frame in frames {
        let started = Instant::now();
        settings.camera = Some(frame.camera);
        resolved.range_for_step(frame.step)?;
        // Phi_ref is a statistic of the first step: computed once for each field (a per-step
        // attribute range changes it) unless --phi-ref gives it, by the ranks from their parts
        // of the step, so that no process reads it whole. A whole step that opening the series
        // left in its cache (the scan of a series without an index) is not kept while the
        // ranks read their parts.
        let auto = match &auto_for {
            Some((field, auto)) if AutoValues::same_for(field, &resolved.field) => *auto,
            _ => {
                let auto =
                    auto_values(&ranks, &resolved.series, &resolved.field, settings.phi_ref)?;
                tracing::info!(
                    "phi_ref {} ({})",
                    auto.phi_ref,
                    if settings.phi_ref.is_some() {
                        "set".to_owned()
                    } else {
                        format!("automatic, from the {size} ranks' parts of step 0")
                    }
                );
                // The ranks' parts of the step about to be rendered stay: its render starts
                // from them (the first step's, read once for the automatic values above).
                resolved.series.clear_cache_but_parts_of(Some(frame.step));
                auto_for = Some((resolved.field.clone(), auto));
                auto
            }
        };
        let basis = FrameBasis {
            bounds: resolved.domain(),
            max_count: resolved.series.max_count(),
            periodic: resolved.periodic.is_some(),
            field: &resolved.field,
            auto,
        };
        let used = basis.resolve(&settings)?;
        let scene = DistScene {
            field: &resolved.field,
            cluster: resolved.cluster,
            series_bounds: resolved.series.bounds(),
            series_range: resolved.series_range(),
            precision,
            periodic: resolved.periodic,
            shadows,
        };
        // A render of a set number of frames (not to a target, nor the reference): its frames,
        // and balanced by cost, the first image's pilot (every later one starts from the image
        // before it).
        let fixed_frames = if target.is_none() && !args.reference {
            let params: Vec<FrameParams> = (0..spp)
                .map(|f| basis.frame_params(&settings, f))
                .collect::<Result<_, _>>()?;
            let pilot = if args.balance == Balance::Cost && cost.is_none() {
                let (width, height) = pilot_size(settings.width, settings.height);
                let small = RenderSettings {
                    width,
                    height,
                    ..settings.clone()
                };
                Some(basis.frame_params(&small, 0)?)
            } else {
                None
            };
            Some((params, pilot))
        } else {
            None
        };
        let rank_body = |comm: &dyn Comm| -> Result<RankDone, DistError> {
            let part = Part::new(comm.rank(), comm.size());
            let local = match resolved.series.take_kept_part(frame.step, part) {
                Some(kept) => kept,
                None => {
                    resolved
                        .series
                        .step_part(frame.step, part, &RankLengths { comm })?
                        .step
                }
            };
            if args.reference {
                // The converged reference: the brick once, in f64 on the CPU, and every rank
                // runs the single process's search on the chunks' images rank 0 sends it.
                let digest = ParticlesDigest::of(&local);
                let scene = DistScene {
                    precision: Precision::F64,
                    ..scene
                };
                let mut cpu = CpuBackend::new();
                let brick = prepare_brick(comm, &mut cpu, &local, &scene, None)?;
                drop(local);
                let options = ReferenceOptions {
                    tolerance: args.reference_tolerance,
                    ..ReferenceOptions::default()
                };
                let reference = converged_reference_on(
                    comm, &mut cpu, &brick, &scene, basis, &settings, &options, digest,
                )?;
                return Ok(RankDone::Reference(reference));
            }
            // Ranks as threads have a slot each; an MPI process's one rank the first.
            let mut slot = lock(&slots[if threads { comm.rank() } else { 0 }]);
            let backend = match &mut *slot {
                Some(b) => b,
                None => slot.insert(crate::backend::create(backend_kind)?),
            };
            let Some(target) = &target else {
                let (params, pilot) = fixed_frames
                    .as_ref()
                    .expect("a render of set frames plans them");
                return render_piloted(
                    comm,
                    &mut **backend,
                    local,
                    &scene,
                    params,
                    pilot.as_ref(),
                    cost.as_ref(),
                )
                .map(|(image, measured)| RankDone::Frames(image, measured));
            };
            // A targeted render: the brick once, then every rank runs the controller on the
            // chunks' images rank 0 sends it.
            let brick = prepare_brick(comm, &mut **backend, &local, &scene, cost.as_ref())?;
            drop(local);
            let done = render_to_target_on(
                comm,
                &mut **backend,
                &brick,
                &scene,
                basis,
                &settings,
                target,
            )?;
            Ok(RankDone::Targeted((comm.rank() == 0).then_some(done)))
        };
        let done = match &ranks {
            Ranks::Threads(n) => run_local(*n, |comm| rank_body(comm))
                .with_context(|| format!("distributed render of step {}", frame.step))?
                .swap_remove(0),
            #[cfg(feature = "mpi")]
            Ranks::Mpi(comm) => match rank_body(comm) {
                Ok(done) => done,
                Err(e) => {
                    comm.abort(&format!("distributed render of step {}: {e}", frame.step));
                    unreachable!("MPI_Abort returned");
                }
            },
        };
        // Rank 0 writes the image; under MPI the other ranks go on to the next.
        let (image, spp_done) = match done {
            RankDone::Frames(image, measured) => {
                if args.balance == Balance::Cost {
                    cost = Some(measured);
                }
                let Some(image) = image else {
                    ensure!(!threads, "rank 0 returned no image");
                    continue;
                };
                log_reports(&image.reports);
                (image.image(), spp)
            }
            RankDone::Reference(reference) => {
                let Some(reference) = reference else {
                    ensure!(!threads, "rank 0 returned no image");
                    continue;
                };
                super::image::say_reference(frame.step, &reference);
                let spp = reference.spp;
                (reference.image.expect("a reference holds its image"), spp)
            }
            RankDone::Targeted(done) => {
                let Some(done) = done else {
                    ensure!(!threads, "rank 0 returned no image");
                    continue;
                };
                let target = target.as_ref().expect("a targeted render has a target");
                super::image::say_targeted(frame.step, target, &done);
                (done.image, done.spp)
            }
        };
        let legend = draw_legend.then(|| {
            Legend::of_field(
                &resolved.field,
                resolved.series_range(),
                resolved.range.label(),
                settings.colour_by_density,
                used.phi_ref,
            )
        });
        format.write(&frame.path, &image, settings.background, legend.as_ref())?;
        tracing::info!(
            "step {}: {} ({}x{}, {spp_done} spp, {size} ranks) in {:.2} s",
            frame.step,
            frame.path.display(),
            settings.width,
            settings.height,
            started.elapsed().as_secs_f64()
        );
    }
    Ok(())
}

/// What a rank's render of one image returns: its part of a render of a set number of frames
/// (rank 0's image, and what it measured for the next decomposition), of a targeted render or
/// of the converged reference (rank 0's result).
enum RankDone {
    Frames(Option<DistImage>, CostModel),
    Targeted(Option<Targeted>),
    Reference(Option<Reference>),
}

/// Each rank's counts and times, and the ghosts and imbalance over all.
fn log_reports(reports: &[RankReport]) {
    for (rank, r) in reports.iter().enumerate() {
        tracing::info!(
            "rank {rank}: read {}, owns {}, {} ghosts; sent {:.1} MiB of particles, {:.1} MiB of tiles, {:.1} MiB of light map; exchange {:.3} s, build {:.3} s, light map {:.3} s, render {:.3} s, composite {:.3} s",
            r.read,
            r.owned,
            r.ghosts,
            r.particle_bytes as f64 / 1048576.0,
            r.tile_bytes as f64 / 1048576.0,
            r.shadow_map_bytes as f64 / 1048576.0,
            r.exchange_seconds,
            r.build_seconds,
            r.shadow_map_seconds,
            r.render_seconds,
            r.composite_seconds
        );
    }
    let owned: u64 = reports.iter().map(|r| r.owned).sum();
    let ghosts: u64 = reports.iter().map(|r| r.ghosts).sum();
    let max_owned = reports.iter().map(|r| r.owned).max().unwrap_or(0);
    let mean_owned = owned as f64 / reports.len().max(1) as f64;
    let render: Vec<f64> = reports.iter().map(|r| r.render_seconds).collect();
    tracing::info!(
        "{} particles owned once each, {ghosts} ghosts ({:.1}%); largest brick {:.3} x the mean; \
         slowest render {:.3} x the mean",
        owned,
        100.0 * ghosts as f64 / owned.max(1) as f64,
        max_owned as f64 / mean_owned.max(1e-300),
        CostModel::imbalance(&render)
    );
}

/// A rank's backend slot, taken whatever a panicking rank left in it (the render reports the
/// panic; the slot holds a backend or none).
fn lock(slot: &Mutex<Option<Box<dyn Backend>>>) -> MutexGuard<'_, Option<Box<dyn Backend>>> {
    slot.lock().unwrap_or_else(|e| e.into_inner())
}
