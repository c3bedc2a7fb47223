//! What every study's measuring code shares: the loop over data sets and backends, the
//! benchmark orbit, the warm-up and repetitions of timed frames, builds and refits, and the
//! rows they give. A study says what it varies and what it measures.

use std::sync::OnceLock;

use indicatif::ProgressBar;

use super::{DataSpec, Dataset, Device, Options, Recorder, Row, StudyError, value};
use crate::backend::{self, BackendKind};
use crate::render::{RenderSession, RenderSettings};
use crate::scene::Camera;
use crate::values::{Bounds, NoiseKind};

/// What the rows of one measurement share: the device it ran on, what distinguishes its line
/// beside the backend, the data set and the settings (the study's own, in its columns'
/// order). Its rows differ only in what was measured ([`Measurement::row`]).
#[derive(Clone, Debug)]
pub struct Measurement {
    /// The device it ran on.
    pub device: Device,
    /// What distinguishes its line beside the backend (empty: nothing).
    pub variant: String,
    /// The data set's name.
    pub data: String,
    /// The step measured.
    pub step: usize,
    /// Particles in the step.
    pub n: usize,
    /// The study's settings as (column, value), in its columns' order.
    pub settings: Vec<(&'static str, String)>,
}

impl Measurement {
    /// A measurement of `ds` on `device` under `settings`, with no variant.
    pub fn new(device: Device, ds: &Dataset, settings: Vec<(&'static str, String)>) -> Measurement {
        Measurement {
            device,
            variant: String::new(),
            data: ds.name.clone(),
            step: ds.step,
            n: ds.n,
            settings,
        }
    }

    /// The same measurement as the line `variant`.
    pub fn variant(self, variant: impl Into<String>) -> Measurement {
        Measurement {
            variant: variant.into(),
            ..self
        }
    }

    /// The row of `values` (one per repetition) of `metric` in `unit`.
    pub fn row(&self, metric: &'static str, unit: &'static str, values: Vec<f64>) -> Row {
        Row {
            device: self.device.clone(),
            variant: self.variant.clone(),
            data: self.data.clone(),
            step: self.step,
            n: self.n,
            settings: self.settings.clone(),
            metric,
            unit,
            values,
        }
    }
}

/// What a study's measuring code works with.
pub struct Ctx<'a> {
    /// How the study runs.
    pub options: &'a Options,
    /// Where the rows go.
    pub recorder: &'a mut Recorder,
    /// The data sets to measure.
    pub data: &'a [DataSpec],
    /// The backends to measure.
    pub backends: &'a [BackendKind],
}

impl<'a> Ctx<'a> {
    /// Runs `measure` once for every data set and backend asked for, with the data set loaded
    /// and a new session on the backend: the loop most studies share.
    pub fn each_session(
        &mut self,
        mut measure: impl FnMut(
            &mut Ctx<'a>,
            &Dataset,
            &mut RenderSession,
            Device,
        ) -> Result<(), StudyError>,
    ) -> Result<(), StudyError> {
        let (data, backends) = (self.data, self.backends);
        for spec in data {
            let ds = self.load(spec)?;
            for &kind in backends {
                let mut session = session(kind, &ds)?;
                let device = device_of(&session);
                measure(self, &ds, &mut session, device)?;
            }
        }
        Ok(())
    }

    /// Records `values` of `metric` in `unit` for `measurement`.
    pub fn record(
        &mut self,
        measurement: &Measurement,
        metric: &'static str,
        unit: &'static str,
        values: Vec<f64>,
    ) -> Result<(), StudyError> {
        self.recorder.record(measurement.row(metric, unit, values))
    }

    /// Loads data set `spec` as the options ask.
    pub fn load(&self, spec: &DataSpec) -> Result<Dataset, StudyError> {
        let o = self.options;
        Dataset::load(spec, o.count, o.step, o.attribute.as_deref(), o.radius)
    }

    /// A progress bar over `len` measurements.
    pub fn bar(&self, len: usize, study: &str) -> ProgressBar {
        crate::progress::bar(len as u64, study)
    }

    /// The settings of a timed frame.
    pub fn frame_settings(&self, noise: NoiseKind) -> RenderSettings {
        RenderSettings {
            width: self.options.image.0,
            height: self.options.image.1,
            integrator: self.options.integrator,
            noise,
            ..RenderSettings::default()
        }
    }
}

/// The backends to measure: those asked for (each must work), or every one this machine has.
pub fn backends(asked: &[BackendKind]) -> Result<Vec<BackendKind>, StudyError> {
    if !asked.is_empty() {
        let mut out: Vec<BackendKind> = Vec::new();
        for &b in asked {
            if b == BackendKind::Auto {
                return Err(StudyError::Invalid(
                    "a study compares named backends: pass --backend cpu, wgpu or ash".into(),
                ));
            }
            if !out.contains(&b) {
                out.push(b);
            }
        }
        return Ok(out);
    }
    static PRESENT: OnceLock<Vec<BackendKind>> = OnceLock::new();
    Ok(PRESENT
        .get_or_init(|| {
            [BackendKind::Cpu, BackendKind::Wgpu, BackendKind::Ash]
                .into_iter()
                .filter(|&k| match backend::create(k) {
                    Ok(_) => true,
                    Err(e) => {
                        tracing::warn!("{k}: not measured ({e})");
                        false
                    }
                })
                .collect()
        })
        .clone())
}

/// How a backend's times are taken.
pub fn timer(caps: &crate::backend::Capabilities) -> &'static str {
    use crate::backend::FrameTimer;
    match (caps.name, caps.frame_timer) {
        ("ash", FrameTimer::DeviceTimestamps) => "device timestamps",
        ("wgpu", FrameTimer::DeviceTimestamps) => {
            "device timestamps for frames, builds, refits and queries; wall clock for uploads"
        }
        (_, FrameTimer::SubmitToCompletion) => "wall clock, submit to completion",
        _ => "wall clock",
    }
}

/// The device a session's backend runs on.
pub fn device_of(session: &RenderSession) -> Device {
    let caps = session.backend().capabilities();
    Device::of(caps.name, &caps.device, timer(caps))
}

/// The paper's benchmark orbit: `count` cameras on a Fibonacci hemisphere around `bounds`
/// (50 in the paper).
pub fn cameras(bounds: Bounds, count: usize) -> Vec<Camera> {
    (0..count)
        .map(|i| Camera::benchmark_orbit(bounds, i, count, 45.0))
        .collect()
}

/// The mean frame time over `cameras` (ms), once per repetition, after one untimed frame.
/// One frame per camera, restarted for each (1 spp), as the paper times its orbit.
pub fn frame_times(
    session: &mut RenderSession,
    settings: &RenderSettings,
    cameras: &[Camera],
    repetitions: usize,
) -> Result<Vec<f64>, StudyError> {
    let at = |c: &Camera| RenderSettings {
        camera: Some(*c),
        ..settings.clone()
    };
    // The warm-up: lavapipe compiles the pipeline of this configuration now.
    session.accumulate(&at(&cameras[0]), 1)?;
    let mut out = Vec::with_capacity(repetitions);
    for _ in 0..repetitions {
        let mut sum = 0.0;
        for c in cameras {
            // A new camera restarts the accumulation: each frame is a first frame.
            session.accumulate(&at(c), 1)?;
            sum += session.backend().timings().frame.as_secs_f64();
        }
        out.push(1e3 * sum / cameras.len() as f64);
    }
    Ok(out)
}

/// Build and refit times (ms) of `repetitions` each on `session`, for `data`'s step under
/// `field` with `cluster`: the untimed warm-up build first, then rebuilds; then refits after
/// a radius change to `wider` and back, the first untimed. Leaves the step shown under `field`.
pub fn build_and_refit_times(
    session: &mut RenderSession,
    data: &Dataset,
    field: &crate::field::FieldSettings,
    wider: &crate::field::FieldSettings,
    cluster: crate::accel::ClusterSize,
    repetitions: usize,
) -> Result<(Vec<f64>, Vec<f64>), StudyError> {
    session.show(&data.series, data.step, field, cluster)?;
    let mut builds = Vec::new();
    for _ in 0..repetitions {
        session.backend_mut().build()?;
        builds.push(ms(session.backend().timings().build));
    }
    session.show(&data.series, data.step, wider, cluster)?;
    let mut refits = Vec::new();
    for i in 0..repetitions {
        let f = if i % 2 == 0 { field } else { wider };
        session.show(&data.series, data.step, f, cluster)?;
        refits.push(ms(session.backend().timings().refit));
    }
    session.show(&data.series, data.step, field, cluster)?;
    Ok((builds, refits))
}

/// The settings columns of a study whose rows are timed frames: the study's own (what it
/// varies), then the frames' ([`with_frame_settings`]).
macro_rules! frame_columns {
    ($($own:literal),* $(,)?) => {
        &[
            $($own,)*
            "width",
            "height",
            "integrator",
            "noise",
            "spp",
            "cameras",
            "step_size",
        ]
    };
}
pub(crate) use frame_columns;

/// A timed frame row's settings: `own` (what the study varies), then the frames' (the
/// options' image size and integrator, blue noise, 1 spp, the orbit's cameras, the march step
/// the session used), in [`frame_columns`]' order.
pub fn with_frame_settings(
    mut own: Vec<(&'static str, String)>,
    o: &Options,
    step_size: f64,
) -> Vec<(&'static str, String)> {
    let frame: &[&'static str] = frame_columns!();
    own.extend(frame.iter().copied().zip([
        o.image.0.to_string(),
        o.image.1.to_string(),
        format!("{:?}", o.integrator).to_lowercase(),
        "stbn".into(),
        "1".into(),
        o.cameras.to_string(),
        value(step_size),
    ]));
    own
}

/// Milliseconds of a duration.
pub fn ms(d: std::time::Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

/// A new session on `kind` over `data`'s series.
pub fn session(kind: BackendKind, data: &Dataset) -> Result<RenderSession, StudyError> {
    Ok(RenderSession::new(backend::create(kind)?, &data.series))
}
