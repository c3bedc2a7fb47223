//! aarbf: attribute-aware RBF volume rendering of time-series particle data.
//!
//! The method is Morrical et al., "Attribute-Aware RBFs: Interactive Visualization of Time
//! Series Particle Volumes Using RT Core Range Queries" (IEEE VIS 2023). The modules follow the
//! data flow: [`io`] (readers) → [`scene`] (time series, maps, scene file) → [`accel`]
//! (Hilbert keys, clusters, CPU BVH) → [`field`] (the f64 reference field every backend is
//! tested against) → backends and rendering → [`cli`].

pub mod accel;
pub mod backend;
pub mod cli;
pub mod field;
pub mod io;
pub mod noise;
pub mod progress;
pub mod render;
pub mod scene;
pub mod shaders;
