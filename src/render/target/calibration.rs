//! One targeted render's progress (`Run`), and the calibration that picks its step: the images
//! at `dt0`, `2 dt0` and `4 dt0`, grown until the bias they measure is settled.

use super::*;

pub(super) struct Run<'a> {
    pub(super) session: &'a mut dyn ChunkRenderer,
    pub(super) settings: RenderSettings,
    pub(super) target: Target,
    pub(super) dt0: f64,
    pub(super) work: f64,
}

impl Run<'_> {
    pub(super) fn at(&self, dt: f64, seed: u32) -> RenderSettings {
        RenderSettings {
            step_size: Some(dt),
            seed,
            ..self.settings.clone()
        }
    }

    pub(super) fn out_of_time(&self) -> bool {
        self.target
            .time_budget
            .is_some_and(|b| self.session.elapsed() >= b)
    }

    /// Extends the image's sequence of `level` to `frames` frames (or fewer when the time
    /// budget runs out: whole chunks of one frame then), and its companion where the noise
    /// needs it, and records the noise.
    pub(super) fn extend(&mut self, level: &mut Level, frames: u32) -> Result<(), RenderError> {
        let before = level.a.frames;
        let companion_follows = level.needs_companion_at(frames);
        while level.a.frames < frames {
            let mut count = frames - level.a.frames;
            if let Some(budget) = self.target.time_budget {
                if level.a.frames == 0 {
                    // A fresh level's frame time is unknown: one frame measures it.
                    count = 1;
                } else {
                    // Chunks of at most half the time left, at the frame time measured so
                    // far: a chunk that runs slower than measured (a busy machine) overshoots
                    // the budget by at most its share of that half, and the next one measures
                    // again.
                    let left = budget.saturating_sub(self.session.elapsed()).as_secs_f64();
                    let step_time = level.step_time().max(1e-9);
                    if left < step_time {
                        break;
                    }
                    count = count.min(((0.5 * left / step_time).floor() as u32).max(1));
                }
            }
            count = count.min(level.a.chunk_room());
            let started = self.session.elapsed();
            let settings = self.at(level.dt, level.a.seed);
            let image = self
                .session
                .render_frames(&settings, level.a.frames, count, false)?;
            level.a.add(&image, count);
            level.seconds += (self.session.elapsed() - started).as_secs_f64();
            self.work += f64::from(count) * self.dt0 / level.dt;
            if companion_follows {
                self.extend_companion(level)?;
            }
        }
        // A budget that stopped the sequence short of `frames` may need the companion where
        // it did not follow.
        if level.needs_companion_at(level.a.frames) {
            self.extend_companion(level)?;
        }
        if level.a.frames > before || level.history.is_empty() {
            let noise = match level.measure_noise(&self.settings) {
                Some(noise) => noise,
                None => {
                    // The noise sits in too few pixels for a quarter of them to measure it:
                    // a second sequence of the whole image does, from its first frame.
                    level.measure_by_pair();
                    self.extend_companion(level)?;
                    level
                        .measure_noise(&self.settings)
                        .expect("a pair always measures")
                }
            };
            level.history.push((level.a.frames, noise));
        }
        Ok(())
    }

    /// Brings the companion of `level` to as many frames as its image's sequence.
    pub(super) fn extend_companion(&mut self, level: &mut Level) -> Result<(), RenderError> {
        let started = self.session.elapsed();
        let (to, dt) = (level.a.frames, level.dt);
        let (sequence, on_lattice) = match &mut level.companion {
            Companion::Pair(b) => (b, false),
            Companion::Lattice(b) => (b, true),
        };
        if sequence.frames >= to {
            return Ok(());
        }
        let count = to - sequence.frames;
        let settings = self.at(dt, sequence.seed);
        let (image, share) = if on_lattice {
            let (w, h) = (settings.width, settings.height);
            let (lw, lh) = half_lattice_size(w, h);
            let image = self
                .session
                .render_frames(&settings, sequence.frames, count, true)?;
            (image, f64::from(lw * lh) / f64::from(w * h))
        } else {
            let image = self
                .session
                .render_frames(&settings, sequence.frames, count, false)?;
            (image, 1.0)
        };
        sequence.add(&image, count);
        level.seconds += (self.session.elapsed() - started).as_secs_f64();
        self.work += share * f64::from(count) * self.dt0 / dt;
        Ok(())
    }

    /// Whether the session accepts step `dt` (the march's sample bound).
    pub(super) fn allowed(&self, dt: f64) -> bool {
        self.session.resolve(&self.at(dt, 0)).is_ok()
    }
}

/// Grows the calibration images that the bias at step `dt0 · 2^j` rests on (the images at
/// `dt0` and `2 dt0`, or `dt0` and `4 dt0` for `j = 2`), after the render at that step met
/// the target while its bias was not settled ([`StepBias::settled`]): the noisier of the two
/// (the chosen step's image counts with its final frames) to four times its frames, at most
/// to the other's noise, or both to twice where they are about as noisy. Returns whether
/// anything was rendered (false at the sample limit).
pub(super) fn grow_calibration(
    run: &mut Run<'_>,
    levels: &mut [Level; 3],
    j: i32,
) -> Result<bool, RenderError> {
    let other = if j == 2 { 2 } else { 1 };
    let cycle = mask_cycle(&run.settings);
    let (n0, n1) = (levels[0].noise(), levels[other].noise());
    let mut grown = false;
    let even = n0 >= 0.7 * n1 && n1 >= 0.7 * n0;
    let plan = [(0, n0 >= 0.7 * n1, n1), (other, n1 >= 0.7 * n0, n0)];
    for (i, grow, towards) in plan {
        if !grow {
            continue;
        }
        let level = &mut levels[i];
        let reached = level.a.frames;
        let factor = if even { 3 } else { 4 };
        let mut wanted = f64::from(reached * factor);
        if !even {
            wanted =
                wanted.min(level.convergence().frames_for(towards) / f64::from(level.spp_at(1)));
        }
        let frames = stop_at(
            wanted.max(f64::from(reached + 1)).ceil() as u32,
            reached,
            cycle,
        )
        .min(run.target.max_spp / level.spp_at(1))
        .max(reached);
        if frames > reached {
            run.extend(level, frames)?;
            grown = true;
        }
    }
    Ok(grown)
}

/// The step (`dt0 · 2^j`) and samples per pixel of the least predicted time to the target, or
/// the least predicted error within the budget, from the calibration.
pub(super) fn choose_step(
    run: &Run<'_>,
    levels: &[Level; 3],
    bias: &StepBias,
    e_rmse: Option<f64>,
    step_fixed: bool,
    finer: &Option<(i32, Level)>,
) -> (i32, f64) {
    let (target, dt0) = (run.target, run.dt0);
    let steps: Vec<i32> = if step_fixed {
        vec![0]
    } else {
        (-3..=2).collect()
    };
    let fine = &levels[0];
    let mut best: Option<(f64, i32, f64)> = None; // (score, j, spp)
    for &j in &steps {
        let dt = dt0 * 2f64.powi(j);
        if !run.allowed(dt) {
            continue;
        }
        let level = usize::try_from(j)
            .ok()
            .and_then(|j| levels.get(j))
            .or_else(|| finer.as_ref().filter(|(k, _)| *k == j).map(|(_, l)| l));
        let convergence = level.map_or(fine.convergence(), Level::convergence);
        let frame_time = level.map_or(fine.frame_time() * 2f64.powi(-j), Level::frame_time);
        let b = bias.at(dt);
        // Twice dt0 on its estimated bias (the default step resolves the kernel with room to
        // spare: its doubling's bias stayed below 0.3 of the noise in every scene measured);
        // four times only where the bias is known to fit, noise and all.
        let b_choice = if j > 1 { bias.bound(dt) } else { b };
        let held = level.map_or(0, Level::spp);
        let (score, spp) = match (e_rmse, target.time_budget) {
            (Some(e), _) => {
                if b_choice * b_choice > BIAS_SHARE * e * e {
                    continue;
                }
                let spp = convergence.frames_for((e * e - b * b).sqrt()).ceil();
                ((spp - f64::from(held)).max(0.0) * frame_time, spp)
            }
            (None, Some(budget)) => {
                let left = budget.saturating_sub(run.session.elapsed()).as_secs_f64();
                let spp = f64::from(held) + left / frame_time.max(1e-9);
                let noise = convergence.noise_at(spp);
                (b_choice * b_choice + noise * noise, spp)
            }
            (None, None) => unreachable!("checked: a target has an error or a budget"),
        };
        tracing::debug!(
            "targeted: step x{:.3}: bias {b:.3e} (bound {:.3e}), noise {:.3e} at {} spp falling at rate {:.2}, frame {:.3e} s: {spp} spp, score {score:.3e}",
            2f64.powi(j),
            bias.bound(dt),
            convergence.noise,
            convergence.frames,
            convergence.rate,
            frame_time,
        );
        if best.is_none_or(|(s, _, _)| score < s) {
            best = Some((score, j, spp));
        }
    }
    // A target no step reaches within its bias share: the finest allowed step.
    match best {
        Some((_, j, spp)) => (j, spp),
        None => {
            let j = steps
                .iter()
                .copied()
                .find(|&j| run.allowed(dt0 * 2f64.powi(j)))
                .unwrap_or(0);
            tracing::warn!(
                "the target error is below the march's estimated bias at every step tried; rendering at the finest"
            );
            (j, f64::from(target.max_spp))
        }
    }
}

/// What the calibration chose, for the render to the target.
pub(super) struct Chosen {
    pub(super) bias: StepBias,
    /// The estimated bias at the chosen step.
    pub(super) b: f64,
    /// Two calibration images a step apart (the coarser first): a realisation of the bias
    /// for the FLIP estimate.
    pub(super) bias_images: (Image, Image),
    pub(super) calibration: Duration,
}

/// Renders `level` from `spp` samples on, checking the estimate and going on while it falls
/// short of the target.
pub(super) fn finish(
    run: &mut Run<'_>,
    level: &mut Level,
    mut spp: f64,
    chosen: Chosen,
) -> Result<Targeted, RenderError> {
    let Chosen {
        bias,
        b,
        bias_images,
        calibration,
    } = chosen;
    let target = run.target;
    let dt = level.dt;
    // Render, check, and go on while the estimate falls short.
    let spinner = crate::progress::spinner("rendering to the target");
    // Whether the sequences stop only at the ends of mask cycles (see `stop_at`).
    let mut cycle = mask_cycle(&run.settings);
    loop {
        let (frames, no_cycle_fits) = next_stop(run, level, spp, cycle);
        run.extend(level, frames)?;
        let image = level.image(&run.settings);
        let noise = level.noise();
        let estimate = estimate(run, level, &image, b, &bias_images);
        spinner.set_message(format!(
            "{} spp at step {dt:.3e}: estimated error {estimate:.3e}{}",
            level.spp(),
            target
                .error
                .map_or(String::new(), |e| format!(" (target {e:.3e})"))
        ));
        let met = target.error.is_none_or(|e| estimate <= e);
        let reached = level.a.frames;
        // Where completing the first cycle brought the noise down no faster than independent
        // samples would (the integrator draws most of its numbers from white noise, as delta
        // tracking does), whole cycles buy nothing: stop anywhere from here.
        if let (Some(d), [.., earlier, now]) = (cycle, level.history.as_slice())
            && now.0 == d
            && earlier.0 < d
            && Convergence::of(*earlier, *now).rate < STRATIFIED_RATE
        {
            cycle = None;
        }
        tracing::debug!(
            "targeted: {reached} frames a sequence at step {dt:.3e}: noise {noise:.3e}, estimate {estimate:.3e}"
        );
        let finished = (target.error.is_some() && met)
            || run.out_of_time()
            || level.spp() >= target.max_spp
            || reached < frames
            || no_cycle_fits;
        if finished {
            spinner.finish_and_clear();
            return Ok(Targeted {
                image,
                step_size: dt,
                spp: level.spp(),
                estimate,
                noise_rmse: noise,
                bias,
                convergence: level.convergence(),
                met,
                elapsed: run.session.elapsed(),
                calibration,
                work: run.work,
            });
        }
        spp = predict_spp(&target, level, noise, estimate, b, cycle);
    }
}

/// The frames a sequence of `level` renders to next, predicted to need `spp` samples, and
/// whether a time budget has room for no further mask cycle.
fn next_stop(run: &Run<'_>, level: &Level, spp: f64, cycle: Option<u32>) -> (u32, bool) {
    let target = run.target;
    let before = level.a.frames;
    let mut frames = stop_at(level.frames_for(spp), before, cycle)
        .clamp(1, target.max_spp / level.spp_at(1))
        .max(before);
    // Past the first cycle a budget starts only the cycles that fit in the time left: an
    // incomplete one would make the image worse, not better.
    let mut no_cycle_fits = false;
    if let (Some(budget), Some(d)) = (target.time_budget, cycle)
        && before >= d
    {
        let left = budget.saturating_sub(run.session.elapsed()).as_secs_f64();
        let cycles = (left / (f64::from(d) * level.step_time()).max(1e-9)).floor();
        frames = frames.min(before + d * cycles.min(f64::from(u32::MAX / d)) as u32);
        no_cycle_fits = frames == before;
    }
    (frames, no_cycle_fits)
}

/// The estimated error of `image`, `level`'s image, in the target's metric, with the bias `b`
/// at its step.
fn estimate(
    run: &Run<'_>,
    level: &Level,
    image: &Image,
    b: f64,
    bias_images: &(Image, Image),
) -> f64 {
    match run.target.metric {
        ErrorMetric::Rmse => level.noise().hypot(b),
        ErrorMetric::Flip => {
            // One realisation of the noise ((A - B) / 2) and of the bias (the calibration
            // difference from dt0 to 2 dt0, scaled to the bias at this step) added.
            let (a, bb) = level
                .pair_images(&run.settings)
                .expect("FLIP targets measure their noise by a pair");
            let scale = b / bias_images.0.rmse(&bias_images.1).max(1e-30);
            let disturbed =
                image
                    .offset_by(&a, &bb, 0.5)
                    .offset_by(&bias_images.0, &bias_images.1, scale);
            image.flip(&disturbed)
        }
    }
}

/// The samples a render short of the target goes on to: predicted again from the noise
/// measured now (a budget alone renders on until the time is spent). At whole mask cycles the
/// noise falls as N^-1/2 from here.
fn predict_spp(
    target: &Target,
    level: &Level,
    noise: f64,
    estimate: f64,
    b: f64,
    cycle: Option<u32>,
) -> f64 {
    let now = f64::from(level.spp());
    let reached = level.a.frames;
    let convergence = match cycle {
        Some(d) if reached >= d && reached.is_multiple_of(d) => Convergence {
            frames: level.spp(),
            noise,
            rate: 0.5,
        },
        _ => level.convergence(),
    };
    let predicted = match (target.error, target.metric) {
        (Some(e), ErrorMetric::Rmse) => {
            convergence.frames_for((e * e - b * b).max(0.1 * e * e).sqrt())
        }
        (Some(e), ErrorMetric::Flip) => now * (estimate / e).powf(1.0 / convergence.rate),
        (None, _) => 2.0 * now,
    };
    if predicted.is_finite() {
        // At most doubling: the prediction's rate is of the frames so far.
        predicted.clamp(now + 2.0, 2.0 * now)
    } else {
        2.0 * now
    }
}

/// RMSE per unit of the target's metric, from a calibration level's noise (FLIP grows about
/// linearly with small errors).
pub(super) fn rmse_per_unit(metric: ErrorMetric, level: &Level, settings: &RenderSettings) -> f64 {
    match metric {
        ErrorMetric::Rmse => 1.0,
        ErrorMetric::Flip => {
            let (a, b) = level
                .pair_images(settings)
                .expect("FLIP targets measure their noise by a pair");
            let image = level.image(settings);
            let flip = image.flip(&image.offset_by(&a, &b, 0.5));
            if flip > 0.0 && level.noise().is_finite() {
                level.noise() / flip
            } else {
                1.0
            }
        }
    }
}
