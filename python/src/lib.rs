//! `aarbf._aarbf`: the Python extension module. It wraps the library the CLI uses (the data
//! handed over becomes the library's [`Step`], the settings its [`SceneFile`], and resolving,
//! field queries and rendering are the library's own calls); the package `aarbf`
//! (`python/aarbf/__init__.py`) adds the NumPy-side conveniences.

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use glam::DVec3;
use numpy::ndarray::{Array2, ArrayView1, ArrayView2, Axis};
use numpy::{IntoPyArray, PyArray2, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::create_exception;
use pyo3::exceptions::{PyOSError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyList};

use aarbf::accel::ClusterSize;
use aarbf::backend::{self, BackendKind, Precision};
use aarbf::cli::field::{Queries, evaluate};
use aarbf::field::{Classification, Kernel, PerParticle, RegularGrid};
use aarbf::io::{At, AttributeSelection, Columns, Format, ParticleType, ReadOptions};
use aarbf::render::RenderSession;
use aarbf::render::target::{ErrorMetric, render_to_target};
use aarbf::scene::{OpenOptions, TimeSeries, UpAxis};
use aarbf::scene_file::periodic::PeriodicSetting;
use aarbf::scene_file::resolve::{
    DataArgs, FieldOptions, Resolved, resolve_in_memory, resolve_scene,
};
use aarbf::scene_file::{CameraSection, MapSpec, RadiusSpec, RangeSpec, SceneFile};
use aarbf::values::{Attribute, Image, Integrator, Light, NoiseKind, Step};

create_exception!(
    _aarbf,
    AarbfError,
    PyValueError,
    "A problem with the data or the settings (the library's message)."
);
create_exception!(
    _aarbf,
    AarbfIOError,
    PyOSError,
    "A file that cannot be read or written (the library's message)."
);
create_exception!(
    _aarbf,
    AarbfWarning,
    pyo3::exceptions::PyUserWarning,
    "What the library warns of (particles dropped, a precision it cannot promise)."
);

// ---------------------------------------------------------------------------------------------
// Errors and the library's log.

/// A library error as a Python exception: `AarbfIOError` (an `OSError`) where a file could not
/// be read or written, else `AarbfError` (a `ValueError`); the message is the library's, with
/// its causes.
fn to_py(e: anyhow::Error) -> PyErr {
    let io = e.chain().any(|c| {
        c.downcast_ref::<std::io::Error>().is_some()
            || c.downcast_ref::<aarbf::io::DataError>()
                .is_some_and(|d| matches!(d.problem, aarbf::io::Problem::Io(_)))
            || c.downcast_ref::<aarbf::io::output::OutputError>().is_some()
    });
    let message = format!("{e:#}");
    if io {
        AarbfIOError::new_err(message)
    } else {
        AarbfError::new_err(message)
    }
}

fn fail(message: impl Into<String>) -> PyErr {
    AarbfError::new_err(message.into())
}

/// Events the library logged since the last [`flush_log`]: (is a warning, message).
static LOG: Mutex<Vec<(bool, String)>> = Mutex::new(Vec::new());

/// Collects the library's `tracing` events (they may come from worker threads without the
/// GIL); [`flush_log`] hands them to Python once the call returns.
struct Collector;

impl<S: tracing::Subscriber> tracing_subscriber::Layer<S> for Collector {
    fn on_event(
        &self,
        event: &tracing::Event<'_>,
        _ctx: tracing_subscriber::layer::Context<'_, S>,
    ) {
        let level = *event.metadata().level();
        if level > tracing::Level::INFO {
            return;
        }
        struct Message(String);
        impl tracing::field::Visit for Message {
            fn record_debug(&mut self, field: &tracing::field::Field, value: &dyn std::fmt::Debug) {
                if field.name() == "message" {
                    self.0 = format!("{value:?}");
                }
            }
        }
        let mut m = Message(String::new());
        event.record(&mut m);
        if let Ok(mut log) = LOG.lock() {
            log.push((level <= tracing::Level::WARN, m.0));
        }
    }
}

/// Warnings become Python warnings (`AarbfWarning`), the rest goes to the `aarbf` logger at
/// INFO (what the CLI prints: the automatic values and how they were derived).
fn flush_log(py: Python<'_>) -> PyResult<()> {
    let events: Vec<(bool, String)> = std::mem::take(&mut *LOG.lock().unwrap());
    if events.is_empty() {
        return Ok(());
    }
    let logger = py
        .import("logging")?
        .call_method1("getLogger", ("aarbf",))?;
    let category = py.get_type::<AarbfWarning>();
    for (warning, message) in events {
        if warning {
            let text = std::ffi::CString::new(message.replace('\0', " ")).unwrap_or_default();
            PyErr::warn(py, category.as_any(), &text, 2)?;
        } else {
            logger.call_method1("info", (message,))?;
        }
    }
    Ok(())
}

/// Runs `f` without the GIL and hands the library's log to Python afterwards.
fn detached<T: Send>(py: Python<'_>, f: impl FnOnce() -> anyhow::Result<T> + Send) -> PyResult<T> {
    let out = py.detach(f);
    flush_log(py)?;
    out.map_err(to_py)
}

// ---------------------------------------------------------------------------------------------
// Arrays in.

/// Positions from an (N, 3) float32 or float64 array of any strides: one copy, into the f64
/// the library holds (float32 converts exactly).
fn positions_of(array: &Bound<'_, PyAny>, what: &str) -> PyResult<Vec<DVec3>> {
    fn rows<T: Copy + Into<f64> + numpy::Element>(a: ArrayView2<'_, T>) -> Vec<DVec3> {
        // C order: one pass over the memory as it lies.
        if let Some(flat) = a.as_slice() {
            return flat
                .chunks_exact(3)
                .map(|r| DVec3::new(r[0].into(), r[1].into(), r[2].into()))
                .collect();
        }
        a.axis_iter(Axis(0))
            .map(|r| DVec3::new(r[0].into(), r[1].into(), r[2].into()))
            .collect()
    }
    let check = |shape: &[usize]| -> PyResult<()> {
        if shape.len() != 2 || shape[1] != 3 {
            return Err(fail(format!(
                "{what} must be an (N, 3) array, got shape {shape:?}"
            )));
        }
        Ok(())
    };
    if let Ok(a) = array.extract::<PyReadonlyArray2<'_, f64>>() {
        check(a.shape())?;
        return Ok(rows(a.as_array()));
    }
    if let Ok(a) = array.extract::<PyReadonlyArray2<'_, f32>>() {
        check(a.shape())?;
        return Ok(rows(a.as_array()));
    }
    Err(fail(format!(
        "{what} must be an (N, 3) float32 or float64 array in native byte order \
         (aarbf.Particles converts other numbers)"
    )))
}

/// A per-particle array of `n` values, float32 or float64 of any stride: one copy into f64.
fn values_of(array: &Bound<'_, PyAny>, what: &str, n: usize) -> PyResult<Vec<f64>> {
    fn copy<T: Copy + Into<f64> + numpy::Element>(a: ArrayView1<'_, T>) -> Vec<f64> {
        match a.as_slice() {
            Some(flat) => flat.iter().map(|&v| v.into()).collect(),
            None => a.iter().map(|&v| v.into()).collect(),
        }
    }
    let values = if let Ok(a) = array.extract::<PyReadonlyArray1<'_, f64>>() {
        copy(a.as_array())
    } else if let Ok(a) = array.extract::<PyReadonlyArray1<'_, f32>>() {
        copy(a.as_array())
    } else {
        return Err(fail(format!(
            "{what} must be a one-dimensional float32 or float64 array of {n} values"
        )));
    };
    if values.len() != n {
        return Err(fail(format!(
            "{what} has {} values for {n} particles",
            values.len()
        )));
    }
    Ok(values)
}

// ---------------------------------------------------------------------------------------------
// Particles and series.

/// One step of particles: positions and named per-particle attributes.
///
/// ``aarbf.Particles(positions, attributes=None, radius=None, smoothing_length=None,
/// name="particles")``
///
/// positions: an (N, 3) float32 or float64 array (kept in double precision where given in
/// double), C or Fortran order, any strides; integers are converted to float64.
/// attributes: a mapping of name to (N,) arrays (temperature, velocity, density, ...).
/// radius: each particle's own radius (the attribute "radius"; a Scene takes it as it is).
/// smoothing_length: SPH smoothing lengths h (the attribute "smoothing_length"; the Scene's
/// default radius is then 2 x their median, an SPH kernel uses h itself).
///
/// Particles with a NaN or infinite position or attribute are dropped with an AarbfWarning,
/// as the CLI's readers drop them; no particles at all is an AarbfError. Properties:
/// ``positions``, ``attributes``, ``names``, ``bounds``, ``name``; ``len()``.
#[pyclass(module = "aarbf._aarbf", frozen)]
struct Particles {
    step: Arc<Step>,
}

#[pymethods]
impl Particles {
    /// Positions (N, 3) and named per-particle attributes (N,): see `aarbf.Particles`'s
    /// documentation (python/aarbf/_aarbf.pyi). Particles with a NaN or infinite position or
    /// attribute are dropped with a warning, as the CLI's readers drop them.
    #[new]
    #[pyo3(signature = (positions, attributes=None, radius=None, smoothing_length=None, name="particles".to_owned()))]
    fn new(
        py: Python<'_>,
        positions: &Bound<'_, PyAny>,
        attributes: Option<&Bound<'_, PyDict>>,
        radius: Option<&Bound<'_, PyAny>>,
        smoothing_length: Option<&Bound<'_, PyAny>>,
        name: String,
    ) -> PyResult<Particles> {
        // Other numbers, widths and byte orders become float32/64 first (aarbf._as_float):
        // float32 and float64 arrays pass as they are, whatever their strides.
        let as_float = py.import("aarbf")?.getattr("_as_float")?;
        let positions = as_float.call1(("positions", positions, 2))?;
        let mut given: Vec<(String, Bound<'_, PyAny>)> = Vec::new();
        if let Some(d) = attributes {
            for (k, v) in d.iter() {
                let key = k.str()?.to_string();
                let v = as_float.call1((format!("attribute '{key}'"), v, 1))?;
                given.push((key, v));
            }
        }
        for (key, v) in [("radius", radius), ("smoothing_length", smoothing_length)] {
            if let Some(v) = v {
                given.push((key.to_owned(), as_float.call1((key, v, 1))?));
            }
        }
        let attributes = given;
        let positions = &positions;
        let positions = positions_of(positions, "positions")?;
        let n = positions.len();
        let mut columns = Vec::with_capacity(attributes.len());
        for (attr, values) in &attributes {
            if columns.iter().any(|a: &Attribute| &a.name == attr) {
                return Err(fail(format!("attribute '{attr}' is given twice")));
            }
            columns.push(Attribute {
                name: attr.clone(),
                values: values_of(values, &format!("attribute '{attr}'"), n)?,
            });
        }
        let label = PathBuf::from(format!("<{name}>"));
        let step = detached(py, || {
            Ok(aarbf::io::finish_step(
                At::new(&label, None),
                &name,
                Columns {
                    positions,
                    attributes: columns,
                    skipped: Vec::new(),
                    // Arrays from Python are checked by finish_step (NaN rows dropped with
                    // a warning).
                    finite: false,
                },
                &AttributeSelection::All,
            )?)
        })?;
        Ok(Particles {
            step: Arc::new(step),
        })
    }

    fn __len__(&self) -> usize {
        self.step.len()
    }

    #[getter]
    fn name(&self) -> String {
        self.step.name.clone()
    }

    /// The positions, (N, 3) float64 (a copy).
    #[getter]
    fn positions<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let flat: Vec<f64> = self
            .step
            .positions
            .iter()
            .flat_map(|p| p.to_array())
            .collect();
        Array2::from_shape_vec((self.step.len(), 3), flat)
            .expect("three per particle")
            .into_pyarray(py)
    }

    /// The attributes' names, in order.
    #[getter]
    fn names(&self) -> Vec<String> {
        self.step
            .attributes
            .iter()
            .map(|a| a.name.clone())
            .collect()
    }

    /// The attributes, name to float64 array (copies).
    #[getter]
    fn attributes<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for a in &self.step.attributes {
            d.set_item(&a.name, a.values.clone().into_pyarray(py))?;
        }
        Ok(d)
    }

    /// (min, max) corners of the positions.
    #[getter]
    fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        let b = self.step.bounds();
        (b.min.to_array(), b.max.to_array())
    }

    fn __repr__(&self) -> String {
        format!(
            "Particles({} particles, attributes: {})",
            self.step.len(),
            if self.step.attributes.is_empty() {
                "none".to_owned()
            } else {
                self.step.attribute_names().join(", ")
            }
        )
    }
}

/// What opens data from files: the CLI's data flags.
#[derive(Clone)]
struct DataSource {
    path: PathBuf,
    format: Option<Format>,
    read: ReadOptions,
    smoothing: Option<aarbf::scene::smoothing::Smoothing>,
    cache_mib: usize,
}

impl DataSource {
    fn args(&self, step: Option<usize>, time: Option<f64>) -> DataArgs {
        DataArgs {
            scene: None,
            data: Some(self.path.clone()),
            format: self.format,
            step,
            time,
            particle_type: Some(self.read.particle_type),
            physical: self.read.physical,
            smoothing: self.smoothing,
            periodic: None,
            no_periodic: false,
            cache_mib: self.cache_mib,
            rescan: false,
        }
    }
}

/// A time series read from files (every format the CLI reads).
#[pyclass(module = "aarbf._aarbf")]
struct Series {
    source: DataSource,
    series: TimeSeries,
}

fn parse<T: std::str::FromStr>(what: &str, text: &str) -> PyResult<T>
where
    T::Err: std::fmt::Display,
{
    text.parse::<T>()
        .map_err(|e| fail(format!("{what} '{text}': {e}")))
}

fn value_enum<T: clap::ValueEnum>(what: &str, text: &str) -> PyResult<T> {
    T::from_str(text, true).map_err(|_| {
        let names: Vec<String> = T::value_variants()
            .iter()
            .filter_map(|v| v.to_possible_value().map(|p| p.get_name().to_owned()))
            .collect();
        fail(format!(
            "{what} '{text}' is not one of: {}",
            names.join(", ")
        ))
    })
}

#[pymethods]
impl Series {
    #[new]
    #[pyo3(signature = (path, format=None, particle_type=None, physical=false, attributes=None, smoothing=None, cache_mib=2048))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        path: PathBuf,
        format: Option<String>,
        particle_type: Option<String>,
        physical: bool,
        attributes: Option<Vec<String>>,
        smoothing: Option<String>,
        cache_mib: usize,
    ) -> PyResult<Series> {
        let source = DataSource {
            path,
            format: format
                .map(|f| value_enum::<Format>("format", &f))
                .transpose()?,
            read: ReadOptions {
                particle_type: particle_type
                    .map(|t| parse::<ParticleType>("particle_type", &t))
                    .transpose()?
                    .unwrap_or_default(),
                physical,
            },
            smoothing: smoothing.map(|s| parse("smoothing", &s)).transpose()?,
            cache_mib,
        };
        let options = OpenOptions {
            format: source.format,
            read: source.read,
            smoothing: source.smoothing,
            attributes: match attributes {
                Some(names) => AttributeSelection::Only(names),
                None => AttributeSelection::All,
            },
            cache_bytes: cache_mib << 20,
            background_scan: false,
            rescan: false,
        };
        let path = source.path.clone();
        let series = detached(py, move || Ok(TimeSeries::open(&path, &options)?))?;
        Ok(Series { source, series })
    }

    fn __len__(&self) -> usize {
        self.series.len()
    }

    /// Step `index` (negative counts from the end) as `Particles`.
    fn __getitem__(&self, py: Python<'_>, index: isize) -> PyResult<Particles> {
        let n = self.series.len() as isize;
        let i = if index < 0 { index + n } else { index };
        if !(0..n).contains(&i) {
            return Err(pyo3::exceptions::PyIndexError::new_err(format!(
                "step {index} does not exist; the series has {n} steps"
            )));
        }
        let step = detached(py, || Ok(self.series.step(i as usize)?))?;
        Ok(Particles { step })
    }

    #[getter]
    fn path(&self) -> PathBuf {
        self.source.path.clone()
    }

    /// Each step's time (a `.pvd`'s timestep, an HDF5 snapshot's Time), or None where the
    /// data records none.
    #[getter]
    fn times(&self) -> Option<Vec<f64>> {
        self.series.times().map(<[f64]>::to_vec)
    }

    /// The attributes of the series (name, min, max over every step).
    #[getter]
    fn attributes(&self) -> Vec<(String, f64, f64)> {
        self.series
            .attributes()
            .into_iter()
            .map(|a| (a.name, a.min, a.max))
            .collect()
    }

    #[getter]
    fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        let b = self.series.bounds();
        (b.min.to_array(), b.max.to_array())
    }

    /// Steps, counts, bounds and attribute ranges, in words.
    fn info(&self) -> String {
        let b = self.series.bounds();
        let steps = self.series.steps();
        let counts: Vec<usize> = steps.iter().map(|s| s.count).collect();
        let mut out = format!(
            "{}: {} steps, {}..{} particles per step\nbounds {:?} .. {:?}\n",
            self.source.path.display(),
            steps.len(),
            counts.iter().min().unwrap_or(&0),
            counts.iter().max().unwrap_or(&0),
            b.min.to_array(),
            b.max.to_array()
        );
        if let Some(t) = self.series.times() {
            out += &format!(
                "times {} .. {}\n",
                t.first().unwrap_or(&0.0),
                t.last().unwrap_or(&0.0)
            );
        }
        for a in self.series.attributes() {
            out += &format!(
                "attribute '{}': [{}, {}] (1st..99th percentile [{}, {}])\n",
                a.name, a.min, a.max, a.p01, a.p99
            );
        }
        out
    }

    fn __repr__(&self) -> String {
        format!(
            "Series('{}', {} steps)",
            self.source.path.display(),
            self.series.len()
        )
    }
}

// ---------------------------------------------------------------------------------------------
// Cameras.

/// Where the camera stands: the scene file's `[camera]` section.
#[pyclass(module = "aarbf._aarbf", frozen, from_py_object)]
#[derive(Clone)]
struct Camera {
    section: CameraSection,
}

#[pymethods]
impl Camera {
    /// Looking from `eye` at `at`, `up` the image's up, `fovy` the vertical field of view in
    /// degrees.
    #[staticmethod]
    #[pyo3(signature = (eye, at, up=(0.0, 0.0, 1.0), fovy=40.0))]
    fn look_at(eye: [f64; 3], at: [f64; 3], up: (f64, f64, f64), fovy: f64) -> PyResult<Camera> {
        let camera = aarbf::scene::Camera {
            eye: DVec3::from(eye),
            at: DVec3::from(at),
            up: DVec3::new(up.0, up.1, up.2),
            fovy,
        };
        camera.frame(16, 16).map_err(|e| fail(e.to_string()))?;
        Ok(Camera {
            section: CameraSection::of(camera),
        })
    }

    /// Around the data's centre at `azimuth` and `elevation` (degrees, about the `up` axis: x,
    /// y, z, -x, -y, -z), `distance` away (None: the data fills the view), as `aarbf render
    /// --up UP --camera-from AZ,EL[,DIST]`.
    #[staticmethod]
    #[pyo3(signature = (azimuth=0.0, elevation=20.0, distance=None, up="z", fovy=40.0))]
    fn orbit(
        azimuth: f64,
        elevation: f64,
        distance: Option<f64>,
        up: &str,
        fovy: f64,
    ) -> PyResult<Camera> {
        let from = match distance {
            Some(d) => format!("{azimuth},{elevation},{d}"),
            None => format!("{azimuth},{elevation}"),
        };
        aarbf::scene_file::parse_camera_from(&from).map_err(fail)?;
        let axis: UpAxis = parse("up", up)?;
        Ok(Camera {
            section: CameraSection {
                from: Some(from),
                up: Some(axis.vector().to_array()),
                up_axis: Some(axis),
                fovy: Some(fovy),
                ..CameraSection::default()
            },
        })
    }

    /// Camera `index` of the paper's `count`-camera benchmark orbit (`--orbit i/n`).
    #[staticmethod]
    fn benchmark(index: usize, count: usize) -> PyResult<Camera> {
        let orbit = format!("{index}/{count}");
        aarbf::scene_file::parse_orbit(&orbit).map_err(fail)?;
        Ok(Camera {
            section: CameraSection {
                orbit: Some(orbit),
                ..CameraSection::default()
            },
        })
    }

    fn __repr__(&self) -> String {
        let s = &self.section;
        if let Some(o) = &s.orbit {
            return format!("Camera.benchmark({o})");
        }
        if let Some(f) = &s.from {
            return format!(
                "Camera.orbit({f}, up={})",
                s.up_axis.map(|a| a.name()).unwrap_or("z")
            );
        }
        format!(
            "Camera.look_at(eye={:?}, at={:?}, up={:?}, fovy={:?})",
            s.eye, s.at, s.up, s.fovy
        )
    }
}

// ---------------------------------------------------------------------------------------------
// Scenes.

/// Where a scene's particles come from.
enum Data {
    Files(DataSource),
    Memory(Vec<Arc<Step>>),
}

/// Particles and a field over them, with what renders them: the scene file's settings,
/// resolved as the CLI resolves them.
#[pyclass(module = "aarbf._aarbf", subclass)]
struct Scene {
    data: Data,
    resolved: Resolved,
    /// The render session, kept between renders on the same backend and precision.
    /// (A backend is `Send` but not `Sync`: the lock makes the scene shareable.)
    session: Mutex<Option<(BackendKind, Precision, RenderSession)>>,
    /// The scene file reproducing the last render (what `aarbf render --save-scene` writes).
    last_render: Option<SceneFile>,
}

/// The Python value of a map: a number, the CLI's text, or (x, y) control points.
fn map_spec(value: &Bound<'_, PyAny>, what: &str) -> PyResult<MapSpec> {
    let spec = if let Ok(v) = value.extract::<f64>() {
        MapSpec::Constant(v)
    } else if let Ok(text) = value.extract::<String>() {
        MapSpec::Text(text)
    } else if let Ok(points) = value.extract::<Vec<(f64, f64)>>() {
        MapSpec::Points(points.into_iter().map(|(x, y)| [x, y]).collect())
    } else {
        return Err(fail(format!(
            "{what}: expected a number, a string like \"ramp\" or \"0:0.5,1:1\", or (x, y) pairs"
        )));
    };
    spec.to_map().map_err(|e| fail(format!("{what}: {e}")))?;
    Ok(spec)
}

fn per_particle(value: &Bound<'_, PyAny>, what: &str) -> PyResult<PerParticle> {
    if let Ok(v) = value.extract::<f64>() {
        return Ok(PerParticle::Constant(v));
    }
    if let Ok(name) = value.extract::<String>() {
        return Ok(PerParticle::Attribute(name));
    }
    Err(fail(format!(
        "{what}: expected a number or an attribute's name"
    )))
}

#[pymethods]
impl Scene {
    /// See `aarbf.Scene` (python/aarbf/__init__.py) for the arguments.
    #[new]
    #[pyo3(signature = (data, scene_file=None, step=None, time=None, attribute=None, attribute_range=None, radius=None, radius_attribute=None, radius_map=None, density_map=None, colormap=None, classification=None, kernel=None, mass=None, density=None, cluster=None, periodic=None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        data: &Bound<'_, PyAny>,
        scene_file: Option<PathBuf>,
        step: Option<usize>,
        time: Option<f64>,
        attribute: Option<String>,
        attribute_range: Option<&Bound<'_, PyAny>>,
        radius: Option<&Bound<'_, PyAny>>,
        radius_attribute: Option<String>,
        radius_map: Option<&Bound<'_, PyAny>>,
        density_map: Option<&Bound<'_, PyAny>>,
        colormap: Option<String>,
        classification: Option<String>,
        kernel: Option<String>,
        mass: Option<&Bound<'_, PyAny>>,
        density: Option<&Bound<'_, PyAny>>,
        cluster: Option<usize>,
        periodic: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Scene> {
        let mut scene = match &scene_file {
            Some(path) => SceneFile::load(path).map_err(|e| to_py(e.into()))?,
            None => SceneFile::default(),
        };
        // The arguments over the scene file's (as the CLI's flags are).
        let d = &mut scene.data;
        if attribute.is_some() {
            d.attribute = attribute;
        }
        if let Some(r) = attribute_range {
            d.attribute_range = Some(if let Ok((lo, hi)) = r.extract::<(f64, f64)>() {
                parse::<RangeSpec>("attribute_range", &format!("{lo},{hi}"))?
            } else {
                parse::<RangeSpec>("attribute_range", &r.extract::<String>()?)?
            });
        }
        if radius_attribute.is_some() {
            d.radius_attribute = radius_attribute;
        }
        if let Some(p) = periodic {
            d.periodic = Some(if let Ok(on) = p.extract::<bool>() {
                PeriodicSetting::Flag(on)
            } else if let Ok(l) = p.extract::<f64>() {
                PeriodicSetting::Box([l; 3])
            } else if let Ok((x, y, z)) = p.extract::<(f64, f64, f64)>() {
                PeriodicSetting::Box([x, y, z])
            } else {
                return Err(fail(
                    "periodic must be True, False, a box length L or (LX, LY, LZ)",
                ));
            });
        }
        let f = &mut scene.field;
        if let Some(r) = radius {
            f.radius = Some(if let Ok(v) = r.extract::<f64>() {
                if !(v.is_finite() && v > 0.0) {
                    return Err(fail(format!("radius {v} must be a positive length")));
                }
                RadiusSpec::Absolute(v)
            } else {
                parse::<RadiusSpec>("radius", &r.extract::<String>()?)?
            });
        }
        if let Some(m) = radius_map {
            f.radius_map = Some(map_spec(m, "radius_map")?);
        }
        if let Some(m) = density_map {
            f.density_map = Some(map_spec(m, "density_map")?);
        }
        if colormap.is_some() {
            f.colormap = colormap;
        }
        if let Some(c) = classification {
            f.classification = Some(value_enum::<Classification>("classification", &c)?);
        }
        if let Some(k) = kernel {
            f.kernel = Some(value_enum::<Kernel>("kernel", &k)?);
        }
        if let Some(m) = mass {
            f.mass = Some(per_particle(m, "mass")?);
        }
        if let Some(m) = density {
            f.density = Some(per_particle(m, "density")?);
        }
        if let Some(k) = cluster {
            f.cluster = Some(parse::<ClusterSize>("cluster", &k.to_string())?);
        }

        // The data: a series opened from files, particles in memory, or the scene file's.
        let (data, memory) = if let Ok(series) = data.cast::<Series>() {
            (Data::Files(series.borrow().source.clone()), None)
        } else if let Ok(p) = data.cast::<Particles>() {
            let steps = vec![p.get().step.clone()];
            (Data::Memory(steps.clone()), Some(steps))
        } else if let Ok(list) = data.cast::<PyList>() {
            let steps = list
                .iter()
                .map(|p| {
                    p.cast::<Particles>()
                        .map(|p| p.get().step.clone())
                        .map_err(|_| fail("a list of data must hold aarbf.Particles"))
                })
                .collect::<PyResult<Vec<_>>>()?;
            if steps.is_empty() {
                return Err(fail("an empty list of particles"));
            }
            (Data::Memory(steps.clone()), Some(steps))
        } else if data.is_none() {
            let path = scene.data.path.clone().ok_or_else(|| {
                fail("no data: pass particles, a series, a path, or a scene file with [data] path")
            })?;
            (
                Data::Files(DataSource {
                    path,
                    format: scene.data.format,
                    read: ReadOptions {
                        particle_type: scene.data.particle_type.unwrap_or_default(),
                        physical: scene.data.physical.unwrap_or(false),
                    },
                    smoothing: scene.data.smoothing,
                    cache_mib: 2048,
                }),
                None,
            )
        } else {
            return Err(fail(
                "data must be aarbf.Particles, a list of them, an aarbf.Series, or None with a scene file",
            ));
        };
        let args = match &data {
            Data::Files(source) => source.args(step, time),
            Data::Memory(_) => DataArgs {
                scene: None,
                data: None,
                format: None,
                step,
                time,
                particle_type: None,
                physical: false,
                smoothing: None,
                periodic: None,
                no_periodic: false,
                cache_mib: 2048,
                rescan: false,
            },
        };
        let resolved = detached(py, move || match memory {
            Some(steps) => {
                let series = TimeSeries::from_shared_steps(steps);
                resolve_in_memory(
                    series,
                    Path::new("<particles>"),
                    scene,
                    &args,
                    &FieldOptions::default(),
                    true,
                )
            }
            None => resolve_scene(scene, &args, &FieldOptions::default(), true),
        })?;
        Ok(Scene {
            data,
            resolved,
            session: Mutex::new(None),
            last_render: None,
        })
    }

    /// The attribute the field carries (None: density only).
    #[getter]
    fn attribute(&self) -> Option<String> {
        self.resolved.field.attribute.clone()
    }

    /// The global radius in data units, as resolved (given, or derived from the data).
    #[getter]
    fn radius(&self) -> f64 {
        self.resolved.field.radius
    }

    /// The attribute's range the colour map spans.
    #[getter]
    fn attribute_range(&self) -> Option<(f64, f64)> {
        self.resolved
            .field
            .attribute_range
            .or_else(|| self.resolved.series_range())
    }

    #[getter]
    fn step(&self) -> usize {
        self.resolved.step
    }

    #[getter]
    fn kernel(&self) -> String {
        self.resolved.field.kernel.to_string()
    }

    #[getter]
    fn cluster(&self) -> usize {
        self.resolved.cluster.get()
    }

    /// The (min, max) corners of the series' bounds.
    #[getter]
    fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        let b = self.resolved.series.bounds();
        (b.min.to_array(), b.max.to_array())
    }

    /// Phi and Theta at `points` ((M, 3), float32 or float64): an (M, 2) float64 array (M, 4:
    /// Phi, r, g, b for pre-classification), exactly what `aarbf field --queries` writes.
    #[pyo3(signature = (points, backend="cpu", precision="auto"))]
    fn field<'py>(
        &self,
        py: Python<'py>,
        points: &Bound<'py, PyAny>,
        backend: &str,
        precision: &str,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let points = positions_of(points, "points")?;
        if let Some(i) = points.iter().position(|p| !p.is_finite()) {
            return Err(fail(format!("query {i} is not finite: {}", points[i])));
        }
        self.evaluate(py, Queries::Points(points), backend, precision)
    }

    /// Phi and Theta at the cell centres of a regular grid of `shape` (nx, ny, nz) cells over
    /// `bounds` ((min, max) corners; default the series' bounds): (nx*ny*nz, 2) rows, x
    /// fastest, as `aarbf field --grid` writes them (the wrapper reshapes them).
    #[pyo3(signature = (shape, bounds=None, backend="cpu", precision="auto"))]
    fn grid_rows<'py>(
        &self,
        py: Python<'py>,
        shape: [usize; 3],
        bounds: Option<([f64; 3], [f64; 3])>,
        backend: &str,
        precision: &str,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        if shape.iter().any(|&d| !(1..=4096).contains(&d)) {
            return Err(fail(format!(
                "grid shape {shape:?}: each side must lie in 1..=4096"
            )));
        }
        let (lo, hi) = match bounds {
            Some((lo, hi)) => (DVec3::from(lo), DVec3::from(hi)),
            None => {
                let b = self.resolved.series.bounds();
                (b.min, b.max)
            }
        };
        if !(lo.is_finite() && hi.is_finite() && lo.cmple(hi).all()) {
            return Err(fail(format!(
                "grid bounds {lo} .. {hi} are not finite ascending corners"
            )));
        }
        let grid = RegularGrid::cell_centred(lo, hi, shape);
        self.evaluate(py, Queries::Grid(grid), backend, precision)
    }

    /// Renders the scene: the linear RGBA image as an (H, W, 4) float32 array, and the
    /// background it was composited over. See `aarbf.Scene.render` for the arguments.
    #[pyo3(signature = (camera=None, width=None, height=None, spp=None, integrator=None, backend="auto", target_error=None, time_budget=None, error_metric=None, seed=None, noise=None, step_size=None, density_scale=None, phi_ref=None, color_by_density=None, light=None, ambient=None, background=None, up=None, precision=None))]
    #[allow(clippy::too_many_arguments)]
    fn render_array<'py>(
        &mut self,
        py: Python<'py>,
        camera: Option<Camera>,
        width: Option<u32>,
        height: Option<u32>,
        spp: Option<u32>,
        integrator: Option<String>,
        backend: &str,
        target_error: Option<f64>,
        time_budget: Option<f64>,
        error_metric: Option<String>,
        seed: Option<u32>,
        noise: Option<String>,
        step_size: Option<f64>,
        density_scale: Option<f64>,
        phi_ref: Option<f64>,
        color_by_density: Option<bool>,
        light: Option<(f64, f64, f64)>,
        ambient: Option<f64>,
        background: Option<(f64, f64, f64)>,
        up: Option<String>,
        precision: Option<String>,
    ) -> PyResult<(Bound<'py, PyAny>, [f64; 3])> {
        // The arguments over the scene file's [render] and [camera] (as the CLI's flags).
        let mut scene = self.resolved.scene.clone();
        let r = &mut scene.render;
        fn over<T>(file: &mut Option<T>, arg: Option<T>) {
            if arg.is_some() {
                *file = arg;
            }
        }
        over(&mut r.width, width);
        over(&mut r.height, height);
        over(&mut r.spp, spp);
        over(
            &mut r.integrator,
            integrator
                .map(|i| value_enum::<Integrator>("integrator", &i))
                .transpose()?,
        );
        over(
            &mut r.noise,
            noise
                .map(|n| value_enum::<NoiseKind>("noise", &n))
                .transpose()?,
        );
        over(&mut r.seed, seed);
        over(&mut r.step_size, step_size);
        over(&mut r.density_scale, density_scale);
        over(&mut r.phi_ref, phi_ref);
        over(&mut r.color_by_density, color_by_density);
        over(&mut r.precision, precision);
        over(&mut r.target_error, target_error);
        over(&mut r.time_budget, time_budget);
        over(
            &mut r.error_metric,
            error_metric
                .map(|m| value_enum::<ErrorMetric>("error_metric", &m))
                .transpose()?,
        );
        let mut l = r.light.unwrap_or_default();
        if let Some((azimuth, elevation, intensity)) = light {
            l = Light {
                azimuth,
                elevation,
                intensity,
                ..l
            };
        }
        l.ambient = ambient.unwrap_or(l.ambient);
        r.light = Some(l);
        if let Some((red, green, blue)) = background {
            r.background = Some([red, green, blue]);
        }
        if let Some(c) = camera {
            scene.camera = c.section.clone();
        }
        if let Some(up) = up {
            let axis: UpAxis = parse("up", &up)?;
            scene.camera.up = Some(axis.vector().to_array());
            scene.camera.up_axis = Some(axis);
        }
        let kind = value_enum::<BackendKind>("backend", backend)?;
        let mut guard = self.session.lock().unwrap_or_else(|e| e.into_inner());
        let session_slot = &mut *guard;
        let resolved = &mut self.resolved;
        let mut interruption: Option<PyErr> = None;
        let interrupted = &mut interruption;
        let rendered = detached(py, move || {
            let bounds = resolved.series.bounds();
            let mut settings = scene.render_settings(bounds).map_err(anyhow::Error::msg)?;
            anyhow::ensure!(
                settings.splat_k.is_none() && settings.voxel_grid.is_none(),
                "the Python package renders the RBFs (the paper's method); `aarbf render --method` renders the baselines"
            );
            let spp = scene.spp();
            anyhow::ensure!(spp > 0, "spp must be at least 1");
            let target = scene.target().map_err(anyhow::Error::msg)?;
            let precision_text = scene
                .render
                .precision
                .clone()
                .unwrap_or_else(|| "auto".into());
            let precision = backend::parse_precision(&precision_text, Precision::RENDER)
                .map_err(anyhow::Error::msg)?;
            let camera = settings
                .camera
                .unwrap_or_else(|| aarbf::scene::Camera::default_for(bounds));
            settings.camera = Some(camera);
            let reuse = matches!(session_slot, Some((k, p, _)) if *k == kind && *p == precision);
            if !reuse {
                *session_slot = None;
                let b = backend::create(kind)?;
                tracing::info!(
                    "backend: {} ({})",
                    b.capabilities().name,
                    b.capabilities().device
                );
                let mut session = RenderSession::new(b, &resolved.series);
                session.set_precision(precision);
                *session_slot = Some((kind, precision, session));
            }
            let session = &mut session_slot.as_mut().expect("set above").2;
            let step = resolved.step;
            resolved.range_for_step(step)?;
            session.show(&resolved.series, step, &resolved.field, resolved.cluster)?;
            let used = session.resolve(&settings)?;
            tracing::info!(
                "settings used: phi_ref {}, step size {}, density scale {}, radius {}",
                used.phi_ref,
                used.step_size,
                used.density_scale,
                resolved.field.radius
            );
            let (image, used_step, used_spp) = match &target {
                Some(target) => {
                    let done = render_to_target(session, &settings, target)?;
                    tracing::info!(
                        "estimated error {:.3e} ({}) at step size {:.4e} and {} spp, in {:.2} s",
                        done.estimate,
                        target.metric.name(),
                        done.step_size,
                        done.spp,
                        done.elapsed.as_secs_f64()
                    );
                    (done.image, Some(done.step_size), done.spp)
                }
                None => {
                    for _ in 0..spp {
                        session.accumulate(&settings, 1)?;
                        // Ctrl-C: Python's signal handlers run between frames.
                        if let Err(e) = Python::attach(|py| py.check_signals()) {
                            *interrupted = Some(e);
                            anyhow::bail!("interrupted");
                        }
                    }
                    (session.image()?, None, spp)
                }
            };
            let (data, field) = resolved.scene_sections();
            let used = aarbf::render::Resolved {
                step_size: used_step.unwrap_or(used.step_size),
                ..used
            };
            let saved = SceneFile::reproducing(
                data,
                field,
                &settings,
                Some(&used),
                camera,
                used_spp,
                &precision_text,
            );
            Ok((image, saved))
        });
        // A KeyboardInterrupt (or what else a signal handler raised) while rendering stays one.
        if let Some(e) = interruption {
            return Err(e);
        }
        let (image, saved) = rendered?;
        drop(guard);
        let background = saved.render.background.unwrap_or([0.0; 3]);
        self.last_render = Some(saved);
        Ok((image_array(py, &image)?, background))
    }

    /// Writes the scene file (TOML) the CLI and the viewer read: after a render, every setting
    /// that render used (what `aarbf render --save-scene` writes), so `aarbf render --scene`
    /// of it gives the same image; before, the data and field as resolved. Particles held in
    /// memory are written beside it first, as VTK XML in float64 (`data` names the file; by
    /// default `<scene stem>_particles_*.vtp`).
    #[pyo3(signature = (path, force=false, data_dir=None))]
    fn save(
        &self,
        py: Python<'_>,
        path: PathBuf,
        force: bool,
        data_dir: Option<PathBuf>,
    ) -> PyResult<()> {
        let mut scene = match &self.last_render {
            Some(s) => s.clone(),
            None => {
                let (data, field) = self.resolved.scene_sections();
                SceneFile {
                    data,
                    field,
                    camera: self.resolved.scene.camera.clone(),
                    render: self.resolved.scene.render.clone(),
                }
            }
        };
        let written = match &self.data {
            Data::Files(_) => None,
            Data::Memory(steps) => Some(steps.clone()),
        };
        let attribute = self.resolved.field.attribute.clone().unwrap_or_default();
        detached(py, move || {
            aarbf::io::output::check_writable(&path, force)?;
            if let Some(steps) = written {
                let dir = data_dir
                    .clone()
                    .or_else(|| path.parent().map(Path::to_path_buf))
                    .unwrap_or_default();
                let stem = format!(
                    "{}_particles",
                    path.file_stem().unwrap_or_default().to_string_lossy()
                );
                let steps: Vec<Step> = steps.iter().map(|s| Step::clone(s)).collect();
                let data_path =
                    aarbf::io::write_series(&dir, &stem, &steps, Format::VtkXml, &attribute)?;
                scene.data.path = Some(std::path::absolute(&data_path)?);
                scene.data.format = None;
            }
            scene.save(&path, force)?;
            Ok(())
        })
    }

    /// The scene file's text (TOML) as [`Scene::save`] would write it (the data path of
    /// particles in memory left out).
    fn to_toml(&self) -> PyResult<String> {
        let scene = match &self.last_render {
            Some(s) => s.clone(),
            None => {
                let (data, field) = self.resolved.scene_sections();
                SceneFile {
                    data,
                    field,
                    camera: self.resolved.scene.camera.clone(),
                    render: self.resolved.scene.render.clone(),
                }
            }
        };
        toml_text(&scene)
    }

    fn __repr__(&self) -> String {
        let f = &self.resolved.field;
        format!(
            "Scene(step {} of {}, {} particles, attribute {}, radius {}, kernel {})",
            self.resolved.step,
            self.resolved.series.len(),
            self.resolved
                .series
                .step_info(self.resolved.step)
                .map_or(0, |s| s.count),
            f.attribute.as_deref().unwrap_or("none (density)"),
            f.radius,
            f.kernel
        )
    }
}

fn toml_text(scene: &SceneFile) -> PyResult<String> {
    let dir = std::env::temp_dir().join(format!("aarbf-py-{}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(|e| to_py(e.into()))?;
    let path = dir.join("scene.toml");
    scene.save(&path, true).map_err(|e| to_py(e.into()))?;
    let text = std::fs::read_to_string(&path).map_err(|e| to_py(e.into()));
    let _ = std::fs::remove_file(&path);
    text
}

impl Scene {
    fn evaluate<'py>(
        &self,
        py: Python<'py>,
        queries: Queries,
        backend: &str,
        precision: &str,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let kind = value_enum::<BackendKind>("backend", backend)?;
        if self.resolved.field.attribute.is_none() {
            return Err(fail(
                "the field carries an attribute: give Scene(..., attribute=NAME)",
            ));
        }
        let resolved = &self.resolved;
        let out = detached(py, || evaluate(resolved, &queries, kind, precision, |_| {}))?;
        let cols = if out.pre { 4 } else { 2 };
        let mut flat = Vec::with_capacity(out.samples.len() * cols);
        for s in &out.samples {
            flat.extend_from_slice(&s[..cols]);
        }
        Ok(Array2::from_shape_vec((out.samples.len(), cols), flat)
            .expect("cols per sample")
            .into_pyarray(py))
    }
}

// ---------------------------------------------------------------------------------------------
// Images.

fn image_array<'py>(py: Python<'py>, image: &Image) -> PyResult<Bound<'py, PyAny>> {
    let flat: Vec<f32> = image.pixels.iter().flatten().copied().collect();
    let array = numpy::ndarray::Array3::from_shape_vec(
        (image.height as usize, image.width as usize, 4),
        flat,
    )
    .expect("four channels per pixel");
    Ok(array.into_pyarray(py).into_any())
}

fn image_of(array: &Bound<'_, PyAny>) -> PyResult<Image> {
    let a = array
        .extract::<numpy::PyReadonlyArray3<'_, f32>>()
        .map_err(|_| fail("an image is an (H, W, 4) float32 array"))?;
    let shape = a.shape();
    if shape[2] != 4 || shape[0] == 0 || shape[1] == 0 {
        return Err(fail(format!(
            "an image is an (H, W, 4) float32 array, got shape {shape:?}"
        )));
    }
    let view = a.as_array();
    let pixels = view
        .outer_iter()
        .flat_map(|row| {
            row.outer_iter()
                .map(|p| [p[0], p[1], p[2], p[3]])
                .collect::<Vec<_>>()
        })
        .collect();
    Ok(Image {
        width: shape[1] as u32,
        height: shape[0] as u32,
        pixels,
    })
}

/// Writes an image as `aarbf render --out` does: .png (8-bit sRGB, opaque; or 16-bit with
/// alpha) or .exr (linear float RGBA, premultiplied, the background taken out).
#[pyfunction]
#[pyo3(signature = (array, path, background=(0.0, 0.0, 0.0), bit_depth=8, force=true))]
fn save_image(
    py: Python<'_>,
    array: &Bound<'_, PyAny>,
    path: PathBuf,
    background: (f64, f64, f64),
    bit_depth: u8,
    force: bool,
) -> PyResult<()> {
    let image = image_of(array)?;
    let background = [background.0, background.1, background.2];
    detached(py, move || {
        let format = aarbf::cli::output_format::OutputFormat::of(&path, bit_depth)?;
        aarbf::io::output::check_writable(&path, force)?;
        format.write(&path, &image, background, None)
    })
}

/// The 8-bit sRGB PNG of an image, as bytes (what `Image._repr_png_` shows in Jupyter).
#[pyfunction]
fn png_bytes<'py>(py: Python<'py>, array: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyBytes>> {
    let image = image_of(array)?;
    let rgb = image.to_srgb8();
    let mut out = std::io::Cursor::new(Vec::new());
    rgb.write_to(&mut out, image::ImageFormat::Png)
        .map_err(|e| fail(e.to_string()))?;
    Ok(PyBytes::new(py, out.get_ref()))
}

/// An .exr image (as `aarbf render` writes them: linear, premultiplied) as an (H, W, 4)
/// float32 array, or a PNG as its sRGB values over 0..1.
#[pyfunction]
fn read_image<'py>(py: Python<'py>, path: PathBuf) -> PyResult<Bound<'py, PyAny>> {
    let decoded = image::open(&path)
        .map_err(|e| AarbfIOError::new_err(format!("{}: {e}", path.display())))?;
    let rgba = decoded.to_rgba32f();
    let (w, h) = rgba.dimensions();
    let array =
        numpy::ndarray::Array3::from_shape_vec((h as usize, w as usize, 4), rgba.into_raw())
            .expect("four channels per pixel");
    Ok(array.into_pyarray(py).into_any())
}

/// The backends this machine has: for each of cpu, wgpu and ash, whether it is available, its
/// device, and whether that device is software (lavapipe) or has ray-tracing hardware.
#[pyfunction]
fn backends(py: Python<'_>) -> PyResult<Vec<Bound<'_, PyDict>>> {
    let found = py.detach(|| {
        [BackendKind::Cpu, BackendKind::Wgpu, BackendKind::Ash]
            .into_iter()
            .map(|kind| {
                (
                    kind,
                    backend::create(kind).map(|b| b.capabilities().clone()),
                )
            })
            .collect::<Vec<_>>()
    });
    flush_log(py)?;
    let auto = found
        .iter()
        .rev()
        .find(|(_, c)| c.as_ref().is_ok_and(|c| !c.software))
        .map(|(k, _)| *k)
        .unwrap_or(BackendKind::Cpu);
    found
        .into_iter()
        .map(|(kind, caps)| {
            let d = PyDict::new(py);
            d.set_item("name", kind.to_string())?;
            d.set_item("available", caps.is_ok())?;
            d.set_item("auto", kind == auto)?;
            match caps {
                Ok(c) => {
                    d.set_item("device", c.device)?;
                    d.set_item("software", c.software)?;
                    d.set_item("hardware_rt", c.hardware_rt)?;
                }
                Err(e) => d.set_item("reason", e.to_string())?,
            }
            Ok(d)
        })
        .collect()
}

#[pymodule]
fn _aarbf(m: &Bound<'_, PyModule>) -> PyResult<()> {
    use tracing_subscriber::layer::SubscriberExt;
    // The library logs through `tracing`; its events reach Python as warnings and log records.
    let _ = tracing::subscriber::set_global_default(tracing_subscriber::registry().with(Collector));
    let py = m.py();
    m.add("AarbfError", py.get_type::<AarbfError>())?;
    m.add("AarbfIOError", py.get_type::<AarbfIOError>())?;
    m.add("AarbfWarning", py.get_type::<AarbfWarning>())?;
    m.add_class::<Particles>()?;
    m.add_class::<Series>()?;
    m.add_class::<Camera>()?;
    m.add_class::<Scene>()?;
    m.add_function(wrap_pyfunction!(save_image, m)?)?;
    m.add_function(wrap_pyfunction!(png_bytes, m)?)?;
    m.add_function(wrap_pyfunction!(read_image, m)?)?;
    m.add_function(wrap_pyfunction!(backends, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
