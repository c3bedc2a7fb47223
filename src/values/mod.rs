//! Plain value types every layer uses: bounding boxes, a step of particles as it lives in
//! memory, what one frame is, images, and the baked map tables every backend looks maps up in.
//! They sit at the bottom of the data flow (`io` → `scene` → `accel` → `field` → `backend` →
//! `render` → `cli`), so any layer may use them; they use nothing of the crate above them.

pub mod bounds;
pub mod color_space;
pub mod exact;
pub mod frame;
pub mod image;
pub mod kernel;
pub mod region;
pub mod shader_constants;
pub mod step;
pub mod tables;

pub use bounds::Bounds;
pub use frame::{CameraFrame, ColourMode, FrameParams, Integrator, Light, NoiseKind};
pub use image::Image;
pub use kernel::Kernel;
pub use region::{HalfOpenBox, PixelRect};
pub use step::{Attribute, Step, value_range};
