//! The integration tests, one binary for them all (Cargo.toml says why): one module a file,
//! named after what it checks (`cli`, `readers`, `gpu_backends`, ...), or after the backend it
//! drives where a check is for one backend only (`ash_rt`, `wgpu_lbvh`, `render_cpu`). A check
//! every GPU backend must pass is one body run on each (`common::on_every_gpu!`: `NAME::ash`,
//! `NAME::wgpu`). Run one file's tests with `cargo test --profile checked --test suite --
//! readers::`.
//! `tests/ash_validation.rs` is a binary of its own: it provokes a validation message on
//! purpose, and every GPU test here asserts that the process saw none.

mod common;

mod architecture;
mod ash_rt;
mod cli;
mod collections;
mod cpu_f32;
mod device_check;
mod distributed;
mod extremes;
mod field_checks;
mod field_reference;
mod first_contact;
mod fuzz_regressions;
mod gpu_backends;
mod gpu_bricks;
mod gpu_cli;
mod hdf5_snapshots;
mod knn_smoothing;
mod mpirun;
mod noise_convergence;
mod optical_background;
mod parallel_reads;
mod periodic;
mod precision;
mod precision_promise;
mod readers;
mod render_cpu;
mod sequences;
mod series_streaming;
mod sph_kernels;
mod splat_baseline;
mod studies;
mod target_error;
mod target_error_outside;
mod viewer;
mod voxel_baseline;
mod wgpu_lbvh;
mod wgpu_render;
