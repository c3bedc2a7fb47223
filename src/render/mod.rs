//! Rendering: cameras, render settings, the integrators (emission–absorption ray marching and
//! single scattering with delta tracking or stochastic ray marching), progressive accumulation
//! and image output. The integrators here are the CPU twin of `shaders_glsl/shared/`.

pub mod camera;
pub mod image;
pub mod integrator;
pub mod session;
pub mod settings;
pub mod tables;

pub use camera::Camera;
pub use image::Accumulator;
pub use integrator::{FieldSampler, FrameParams};
pub use session::RenderSession;
pub use settings::{ColourMode, Integrator, Light, NoiseKind, RenderSettings};
