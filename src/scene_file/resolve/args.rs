//! The flags that name the data and define the field, merged over a scene file's sections.

use std::path::PathBuf;

use clap::Args;

use crate::accel::ClusterSize;
use crate::field::{Classification, Kernel, PerParticle};
use crate::io::{Format, ParticleType, ReadOptions};
use crate::scene_file::{DataSection, RadiusSpec, RangeSpec};

/// Where the data comes from.
#[derive(Debug, Clone, Args)]
pub struct DataArgs {
    /// A scene file (TOML) with data and field settings; flags override it.
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// The data: a file, a directory or a glob (a time series sorted naturally).
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// The file format, when the extension does not tell.
    #[arg(long, value_enum)]
    pub format: Option<Format>,
    /// The time step to use (0-based).
    #[arg(long, conflicts_with = "time")]
    pub step: Option<usize>,
    /// The step whose time is nearest T: the `timestep` of a `.pvd` collection, an HDF5
    /// snapshot's `Time`; where the data records no times, a step's time is its index.
    #[arg(long, value_name = "T")]
    pub time: Option<f64>,
    /// The particle type of an HDF5 snapshot: 0..5 or gas, dm, disk, bulge, stars, bh
    /// (default gas).
    #[arg(long, value_name = "TYPE")]
    pub particle_type: Option<ParticleType>,
    /// Read an HDF5 snapshot's comoving positions, smoothing lengths and densities in
    /// physical units (times the scale factor's power each has).
    #[arg(long)]
    pub physical: bool,
    /// Smoothing lengths from neighbours for data without one: `knn:K` (K = 32 by default)
    /// gives each particle h = the distance to its K-th nearest neighbour, as the attribute
    /// `h_knnK`, the per-particle radius unless --radius-attribute names another. Cached in
    /// `.aarbf-smoothing/` beside the data.
    #[arg(long, value_name = "knn:K")]
    pub smoothing: Option<crate::scene::smoothing::Smoothing>,
    /// Wrap the field at the faces of a periodic box: particles near one face are felt across
    /// it, so slices and renders of the box have no seam. `--periodic` alone takes the box an
    /// HDF5 snapshot's header states; `--periodic L` or `LX,LY,LZ` gives the box [0, L) for
    /// any format. Default: on where a snapshot's header says its box is periodic.
    #[arg(long, value_name = "L|LX,LY,LZ", num_args = 0..=1, default_missing_value = "header")]
    pub periodic: Option<crate::scene_file::periodic::PeriodicSpec>,
    /// Treat the data's box as open, even where the snapshot says it is periodic.
    #[arg(long, conflicts_with = "periodic")]
    pub no_periodic: bool,
    /// The most memory, in MiB, that steps read from disk are kept in (the least recently
    /// used go first; a series larger than this plays with memory bounded by it).
    #[arg(long, default_value_t = 2048)]
    pub cache_mib: usize,
    /// Read every step again for the series' bounds and ranges, whatever the index beside the
    /// data says (for files rewritten within the file system's time resolution with the same
    /// size); the index is rewritten.
    #[arg(long)]
    pub rescan: bool,
}

impl DataArgs {
    /// Everything from the scene file at `path` (no flag over it), with a cache of `cache_mib`.
    pub fn of_scene(path: PathBuf, cache_mib: usize) -> DataArgs {
        DataArgs {
            scene: Some(path),
            data: None,
            format: None,
            step: None,
            time: None,
            particle_type: None,
            physical: false,
            smoothing: None,
            periodic: None,
            no_periodic: false,
            cache_mib,
            rescan: false,
        }
    }

    /// What to read from files that hold a choice: the flags over the scene file's.
    pub fn read_options(&self, scene: &DataSection) -> ReadOptions {
        ReadOptions {
            particle_type: self
                .particle_type
                .or(scene.particle_type)
                .unwrap_or_default(),
            physical: self.physical || scene.physical.unwrap_or(false),
        }
    }
}

/// Where the view stands, for the commands that make images (render, view).
#[derive(Debug, Clone, Default, Args)]
pub struct ViewFlags {
    /// The axis pointing up in the image: x, y, z, -x, -y or -z. Default: z (simulation data
    /// is z-up, gravity along -z); planar (2D) data is viewed face on.
    #[arg(long, value_name = "AXIS")]
    pub up: Option<crate::scene::UpAxis>,
    /// The camera at azimuth and elevation (degrees, about the up axis; 0,0 looks from -y with
    /// z up) around the data's centre, and optionally its distance in data units (default:
    /// the data fills the view).
    #[arg(long, value_name = "AZ,EL[,DIST]")]
    pub camera_from: Option<String>,
}

impl ViewFlags {
    /// Writes these flags over a scene file's `[camera]` (flags win).
    pub fn apply(&self, camera: &mut crate::scene_file::CameraSection) -> anyhow::Result<()> {
        if let Some(up) = self.up {
            camera.up = Some(up.vector().to_array());
            camera.up_axis = Some(up);
        }
        if let Some(from) = &self.camera_from {
            crate::scene_file::parse_camera_from(from).map_err(anyhow::Error::msg)?;
            camera.from = Some(from.clone());
            // The flag places the camera: a scene file's eye and target give way to it.
            camera.eye = None;
            camera.at = None;
            camera.orbit = None;
        }
        Ok(())
    }
}

/// How the field is defined.
#[derive(Debug, Clone, Default, Args)]
pub struct FieldOptions {
    /// The attribute the field carries (its colour).
    #[arg(long)]
    pub attribute: Option<String>,
    /// The range the colour map spans: LO,HI; `series` (the least to the largest value over
    /// the series, the default); `robust` (the series' 1st to 99th percentile: outliers do not
    /// wash the rest into one colour); `step` or `robust-step` (the same over the step shown,
    /// each frame of a sequence its own).
    #[arg(long, value_name = "LO,HI|series|robust|step|robust-step")]
    pub attribute_range: Option<RangeSpec>,
    /// Global RBF radius: a length, or a percentage of the series' bounding-box diagonal
    /// ("1.5%"). Default: twice the median smoothing length (h, hsml, SmoothingLength) of the
    /// first step where the data has one, else twice the particles' spacing (the median
    /// nearest-neighbour distance in the first step); 2 with --radius-attribute (radius 2h,
    /// the SPH kernel's support).
    #[arg(long)]
    pub radius: Option<RadiusSpec>,
    /// A per-particle radius (smoothing length) attribute, multiplied by the global radius.
    #[arg(long)]
    pub radius_attribute: Option<String>,
    /// Radius map m(t) in [0, 1]: a number, "ramp", "ramp:a:b" or points "x:y,x:y,...".
    #[arg(long)]
    pub radius_map: Option<String>,
    /// Density map w(t) >= 0, spelled like --radius-map.
    #[arg(long)]
    pub density_map: Option<String>,
    /// Colour map: a preset (viridis, plasma, inferno, magma, turbo, cool-warm, grayscale)
    /// or a ParaView colour-map .json file.
    #[arg(long)]
    pub colormap: Option<String>,
    /// post: average the attribute, then colour it; pre: colour each particle, then average.
    #[arg(long, value_enum)]
    pub classification: Option<Classification>,
    /// Particles per cluster box (1, 2, 4, 8, 16), Hilbert-sorted. Unset: 16 where particles
    /// overlap (4 or more reach a particle centre on average), 4 where they barely do.
    #[arg(long)]
    pub cluster: Option<ClusterSize>,
    /// The kernel: the paper's Gaussian RBF (unnormalised, the default), or an SPH kernel
    /// normalised in 3D and weighted by each particle's volume m/rho, so the field is the SPH
    /// interpolant sarracen and yt compute (support 2h; 3h for the quintic).
    #[arg(long, value_enum)]
    pub kernel: Option<Kernel>,
    /// An SPH kernel's masses: an attribute, or one value for every particle. Default: the
    /// data's Masses, mass or m.
    #[arg(long, value_name = "ATTRIBUTE|VALUE")]
    pub mass: Option<PerParticle>,
    /// An SPH kernel's densities: an attribute, or one value for every particle (1 makes
    /// Phi the SPH density estimate, the sum of m W). Default: the data's Densities, Density
    /// or rho.
    #[arg(long, value_name = "ATTRIBUTE|VALUE")]
    pub density: Option<PerParticle>,
}
