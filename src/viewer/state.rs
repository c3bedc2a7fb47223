//! What the viewer shows: one value holding everything a scene file states, so the window,
//! the render worker and `aarbf render --scene` agree on it.

use std::path::PathBuf;

use crate::accel::ClusterSize;
use crate::backend::BackendKind;
use crate::field::FieldSettings;
use crate::io::Format;
use crate::render::{RenderSettings, Resolved};
use crate::scene::Camera;
use crate::scene_file::SceneFile;
use crate::scene_file::resolve::{Resolved as Loaded, scene_sections};
use crate::values::Bounds;

/// Where the shown data comes from (fixed while a series is open).
#[derive(Clone, Debug, PartialEq)]
pub struct DataSource {
    /// The data file, directory or glob pattern the series was opened from, as given.
    pub path: PathBuf,
    /// The format as the user forced it; `None`: detected from the file extensions.
    pub format: Option<Format>,
    /// What was read of files that hold a choice (an HDF5 snapshot's particle type, physical or
    /// comoving units).
    pub read: crate::io::ReadOptions,
}

/// Everything the viewer renders, as a scene file states it.
#[derive(Clone, Debug, PartialEq)]
pub struct ViewState {
    /// The shown step's index in the series (0-based).
    pub step: usize,
    /// How the field is computed and coloured: the attribute and its range, the density, radius and
    /// colour maps, the kernel, the classification.
    pub field: FieldSettings,
    /// The colour map as the user named it: a preset, or a ParaView JSON file.
    pub colormap: String,
    /// Particles per cluster in the acceleration structure.
    pub cluster: ClusterSize,
    /// The camera is always set (the view the user moved to).
    pub settings: RenderSettings,
    /// Samples per pixel to accumulate once the view stops changing.
    pub spp: u32,
    /// How positions are held and the field computed (`auto`, `auto:TOLERANCE`, `f32`, `ds`,
    /// `f64`).
    pub precision: String,
    /// The backend that renders, as the user picked it (`auto` resolved by the worker).
    pub backend: BackendKind,
    /// The periodic box the field wraps at, if any (fixed while a series is open).
    pub periodic: Option<crate::field::PeriodicBox>,
}

impl ViewState {
    /// The state of a freshly resolved scene (flags over the scene file): its camera, or the
    /// default view of the data's bounds.
    pub fn of(loaded: &Loaded, backend: BackendKind) -> Result<ViewState, String> {
        let bounds = loaded.domain();
        let mut settings = loaded.scene.render_settings(bounds)?;
        settings.camera = Some(
            settings
                .camera
                .unwrap_or_else(|| Camera::default_for(bounds)),
        );
        Ok(ViewState {
            step: loaded.step,
            field: loaded.field.clone(),
            colormap: loaded
                .colormap
                .clone()
                .unwrap_or_else(|| loaded.field.color_map.name.clone()),
            cluster: loaded.cluster,
            settings,
            spp: loaded.scene.spp().max(1),
            precision: loaded
                .scene
                .render
                .precision
                .clone()
                .unwrap_or_else(|| "auto".into()),
            backend,
            periodic: loaded.periodic,
        })
    }

    /// The camera of the view (always set in the viewer's state).
    pub fn camera(&self) -> Camera {
        self.settings
            .camera
            .expect("the viewer's state always holds a camera")
    }

    /// The scene file that renders this state's image with `aarbf render --scene`: with
    /// `used`, the automatic values as the worker resolved them; without, left automatic.
    pub fn scene_file(&self, source: &DataSource, used: Option<&Resolved>) -> SceneFile {
        let (data, field) = scene_sections(
            &source.path,
            source.format,
            source.read,
            self.step,
            &self.field,
            self.cluster,
            Some(&self.colormap),
            self.periodic,
        );
        SceneFile::reproducing(
            data,
            field,
            &self.settings,
            used,
            self.camera(),
            self.spp,
            &self.precision,
        )
    }
}

/// The series' bounds when the data is empty: a unit box, so cameras stay valid.
pub fn view_bounds(bounds: Bounds) -> Bounds {
    if bounds.is_empty() {
        Bounds {
            min: glam::DVec3::ZERO,
            max: glam::DVec3::ONE,
        }
    } else {
        bounds
    }
}
