//! aarbf: attribute-aware RBF volume rendering of time-series particle data.
//!
//! The method is Morrical et al., "Attribute-Aware RBFs: Interactive Visualization of Time
//! Series Particle Volumes Using RT Core Range Queries" (IEEE VIS 2023). The modules follow the
//! data flow, each using only those before it (`tests/architecture.rs` holds the code to it):
//!
//! - [`values`] (plain value types: bounds, steps, frames, images, map tables), [`progress`]
//!   and [`noise`] (blue and white noise) at the bottom;
//! - [`io`]: readers and writers;
//! - [`scene`]: time series, maps, cameras, synthetic data;
//! - [`accel`]: Hilbert keys, clusters, the CPU BVH, the grid of cells;
//! - [`field`]: the f64 reference field every backend is tested against;
//! - [`backend`]: the `Backend` trait, its CPU, wgpu and ash implementations, and the shaders
//!   with their CPU twins;
//! - [`render`]: the rendering session (what each change costs, the automatic settings);
//! - [`dist`]: distributed rendering (k-d bricks, ghost particles, direct-send compositing)
//!   over a communicator: threads in one process, or the processes of an MPI job;
//! - [`cli`], [`viewer`], [`study`] (the paper's benchmark studies) and [`scene_file`] (which
//!   composes all of the above) at the top.

pub mod accel;
pub mod backend;
#[expect(
    clippy::print_stdout,
    reason = "the command line prints its results to stdout"
)]
pub mod cli;
pub mod dist;
pub mod field;
pub mod io;
pub mod noise;
pub mod progress;
pub mod render;
pub mod scene;
pub mod scene_file;
pub mod study;
pub mod values;
pub mod viewer;
