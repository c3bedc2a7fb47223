//! Random numbers for the renderer: spatiotemporal blue noise and hashed white noise.
//!
//! The renderer draws one random number per pixel, per frame, per decision (ray-marching
//! jitter, free-flight distance). Drawn from a spatiotemporal blue-noise (STBN) mask, the error
//! of each frame is blue in screen space (high-frequency, so it looks fine and blurs away) and
//! each pixel's numbers over consecutive frames are well spread over [0, 1), so a temporal
//! accumulation converges faster than with white noise.
//!
//! - [`stbn`] generates masks with Ulichney's void-and-cluster algorithm (R. Ulichney, "The
//!   void-and-cluster method for dither array generation", Proc. SPIE 1913, 1993) driven by the
//!   separable spatiotemporal energy of Wolfe et al. (A. Wolfe, N. Morrical, T. Akenine-Möller,
//!   R. Ramamoorthi, "Spatiotemporal Blue Noise Masks", EGSR 2022): a 2D Gaussian within each
//!   slice plus a 1D Gaussian along time within each pixel, σ = 1.9, toroidal in all three
//!   axes. One addition of ours, *column balance*, gives every pixel exactly one rank in each
//!   band of W·H consecutive ranks, so its D values over time are stratified (one per 1/D,
//!   up to the per-slice renormalisation) rather than merely blue in time. The masks are our
//!   own; NVIDIA's published masks are not used.
//! - [`mask`] holds [`BlueNoiseMask`] (lookup, asset format, the shipped mask);
//! - [`mod@white`] is the stateless white-noise hash, for decisions past the mask's one scalar per
//!   pixel and frame, and as the baseline the tests compare against.
//!
//! Each mask slice's values are a permutation-like uniform set, `(rank_in_slice + 0.5) / (W·H)`
//! stored as u16 (see [`stbn::mask_from_ranks`]), so every slice's histogram is exactly uniform
//! and lookups return f32 in [0, 1).
//!
//! # The shipped mask
//!
//! `assets/stbn_128x128x64.bin` (2 MiB + 16 bytes, [`BlueNoiseMask::builtin`]) is the
//! 128 x 128 x 64 mask of seed 1 and σ = 1.9. Regenerate it with
//!
//! ```sh
//! aarbf stbn --width 128 --height 128 --depth 64 --seed 1 --out assets/stbn_128x128x64.bin
//! ```
//!
//! which calls [`stbn::generate`] then [`BlueNoiseMask::write`]; the test
//! `noise::stbn::tests::builtin_mask_is_reproducible` checks that the generator still
//! reproduces the shipped file bit for bit.
//!
//! # GPU twins
//!
//! `shaders_glsl/shared/noise.glsl` holds `white_noise` (bit-identical to [`white::white`])
//! and `stbn_value` (the same lookup as [`BlueNoiseMask::get`] over the values packed two per
//! u32, [`BlueNoiseMask::packed_words`]). They are line-for-line copies: edit both together.

pub mod mask;
pub mod stbn;
pub mod white;

pub use mask::{BlueNoiseMask, NoiseError};
pub use white::white;
