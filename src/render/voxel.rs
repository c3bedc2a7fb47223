//! The voxel-grid baseline of the paper's Table 3: the particles splatted into a regular grid
//! with the same kernel (the sums Phi and Σ theta_i phi_i at every cell centre, from
//! [`Backend::query_grid`]: on the CPU backend a scatter of each particle onto the cells it
//! reaches), then ray-marched with the same integrators, noise and transfer functions as the
//! RBF renderer ([`crate::backend::cpu::integrators::render_pixel_with`]), sampling the grid by
//! trilinear interpolation between cell centres instead of querying the particles.
//!
//! What the grid loses is what a voxel renderer loses: detail finer than a cell (the
//! quantisation the paper names), and Theta blurred across cells, since the sums are
//! interpolated and divided afterwards. As the grid grows the image converges to the RBF
//! image (tests/voxel_baseline.rs). The grid spans the march box (the series' bounds grown by
//! the frame's margin) with cubic cells, `n` along its longest side; it is re-voxelised for
//! every step, as the paper's time-series comparison does every frame.

use glam::DVec3;
use rayon::prelude::*;

use crate::backend::cpu::integrators::{FieldSampler, PixelScratch, render_pixel_with};
use crate::backend::{Backend, BackendError};
use crate::field::RegularGrid;
use crate::values::{FrameParams, Image};

/// The largest grid side accepted (a 1024³ grid holds 16 GiB of f32 sums).
pub const MAX_GRID: usize = 1024;

/// Cells per slab when splatting: bounds the f64 sums held at once to a slab's worth.
const SLAB_CELLS: usize = 1 << 22;

/// A grid of the field's sums at cell centres, f32 as a GPU voxel renderer keeps them.
pub struct VoxelGrid {
    /// The first cell's centre.
    origin: DVec3,
    /// Cell size.
    cell: DVec3,
    dims: [usize; 3],
    /// Phi and the three Theta numerators per cell, x fastest.
    sums: Vec<[f32; 4]>,
}

impl VoxelGrid {
    /// The dimensions of a grid with cubic cells, `n` cells along the longest side of `lo..hi`.
    pub fn dims_for(lo: DVec3, hi: DVec3, n: usize) -> [usize; 3] {
        let extent = (hi - lo).max(DVec3::splat(1e-300));
        let longest = extent.max_element();
        extent
            .to_array()
            .map(|e| ((n as f64 * e / longest).round() as usize).clamp(1, n))
    }

    /// Splats the particles `backend` holds into a grid over `lo..hi`, `n` cells along its
    /// longest side, slab by slab along z.
    pub fn voxelize(
        backend: &mut dyn Backend,
        lo: DVec3,
        hi: DVec3,
        n: usize,
    ) -> Result<VoxelGrid, BackendError> {
        if n == 0 || n > MAX_GRID {
            return Err(BackendError::Device {
                backend: "voxel",
                message: format!(
                    "a grid of {n} cells along its longest side; 1..={MAX_GRID} are allowed"
                ),
            });
        }
        let dims = Self::dims_for(lo, hi, n);
        let cell = (hi - lo) / DVec3::new(dims[0] as f64, dims[1] as f64, dims[2] as f64);
        let layer = dims[0] * dims[1];
        let per_slab = (SLAB_CELLS / layer).max(1);
        let mut sums = Vec::with_capacity(layer * dims[2]);
        let mut z = 0;
        while z < dims[2] {
            let layers = per_slab.min(dims[2] - z);
            let slab_lo = lo + DVec3::new(0.0, 0.0, z as f64 * cell.z);
            let slab_hi = DVec3::new(hi.x, hi.y, slab_lo.z + layers as f64 * cell.z);
            let grid = RegularGrid::cell_centred(slab_lo, slab_hi, [dims[0], dims[1], layers]);
            sums.extend(
                backend
                    .query_grid(&grid)?
                    .into_iter()
                    .map(|(phi, num)| [phi as f32, num[0] as f32, num[1] as f32, num[2] as f32]),
            );
            z += layers;
        }
        Ok(VoxelGrid {
            origin: lo + 0.5 * cell,
            cell,
            dims,
            sums,
        })
    }

    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }

    /// Bytes the grid holds.
    pub fn bytes(&self) -> usize {
        self.sums.len() * std::mem::size_of::<[f32; 4]>()
    }

    fn at(&self, i: [usize; 3]) -> [f32; 4] {
        self.sums[i[0] + self.dims[0] * (i[1] + self.dims[1] * i[2])]
    }
}

impl FieldSampler for VoxelGrid {
    type Ray = ();

    /// The whole interval: the grid does not skip empty space (as the baseline it models).
    fn begin(
        &self,
        _: &mut (),
        _: DVec3,
        _: DVec3,
        t0: f64,
        t1: f64,
        occupied: &mut Vec<(f64, f64)>,
    ) {
        occupied.push((t0, t1));
    }

    /// Trilinear interpolation of the sums between cell centres (clamped to the outer cells'
    /// centres at the grid's faces).
    fn sample(&self, _: &mut (), origin: DVec3, dir: DVec3, t: f64) -> (f64, [f64; 3]) {
        let x = origin + dir * t;
        let g = (x - self.origin) / self.cell;
        let mut base = [0usize; 3];
        let mut frac = [0.0f64; 3];
        for a in 0..3 {
            let max = (self.dims[a] - 1) as f64;
            let c = g[a].clamp(0.0, max);
            let b = c.floor().min((max - 1.0).max(0.0));
            base[a] = b as usize;
            frac[a] = c - b;
        }
        let mut out = [0.0f64; 4];
        for corner in 0..8 {
            let mut w = 1.0;
            let mut i = base;
            for a in 0..3 {
                let hi = corner >> a & 1 == 1;
                if hi {
                    if self.dims[a] == 1 {
                        w = 0.0;
                    }
                    i[a] = (base[a] + 1).min(self.dims[a] - 1);
                    w *= frac[a];
                } else {
                    w *= 1.0 - frac[a];
                }
            }
            if w > 0.0 {
                let v = self.at(i);
                for c in 0..4 {
                    out[c] += w * f64::from(v[c]);
                }
            }
        }
        (out[0], [out[1], out[2], out[3]])
    }
}

/// Renders frames of a voxel grid with the CPU integrators and accumulates them.
pub struct VoxelRenderer {
    pub grid: VoxelGrid,
    /// Width, height, frames, and the per-pixel sums.
    accumulated: Option<(u32, u32, u32, Vec<[f64; 4]>)>,
}

impl VoxelRenderer {
    pub fn new(grid: VoxelGrid) -> VoxelRenderer {
        VoxelRenderer {
            grid,
            accumulated: None,
        }
    }

    /// Renders one frame (rayon over rows) and adds it to the accumulation; a frame of
    /// another size restarts it.
    pub fn render(&mut self, frame: &FrameParams) {
        let (w, h) = (frame.width, frame.height);
        let grid = &self.grid;
        let rows: Vec<Vec<[f64; 4]>> = (0..h)
            .into_par_iter()
            .map_init(PixelScratch::default, |scratch, y| {
                (0..w)
                    .map(|x| render_pixel_with(frame, grid, x, y, scratch))
                    .collect()
            })
            .collect();
        let pixels: Vec<[f64; 4]> = rows.into_iter().flatten().collect();
        match &mut self.accumulated {
            Some((aw, ah, frames, sums)) if (*aw, *ah) == (w, h) => {
                for (s, p) in sums.iter_mut().zip(&pixels) {
                    for c in 0..4 {
                        s[c] += p[c];
                    }
                }
                *frames += 1;
            }
            slot => *slot = Some((w, h, 1, pixels)),
        }
    }

    /// Restarts the accumulation.
    pub fn reset(&mut self) {
        self.accumulated = None;
    }

    /// The mean of the frames so far (`None` before the first).
    pub fn image(&self) -> Option<Image> {
        self.accumulated.as_ref().map(|(w, h, frames, sums)| {
            let n = f64::from(*frames);
            Image {
                width: *w,
                height: *h,
                pixels: sums.iter().map(|s| s.map(|v| (v / n) as f32)).collect(),
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cells_are_cubic_with_n_along_the_longest_side() {
        let d = VoxelGrid::dims_for(DVec3::ZERO, DVec3::new(2.0, 1.0, 0.5), 64);
        assert_eq!(d, [64, 32, 16]);
        let d = VoxelGrid::dims_for(DVec3::ZERO, DVec3::new(1.0, 1e-9, 1.0), 8);
        assert_eq!(d, [8, 1, 8]);
    }

    #[test]
    fn trilinear_sampling_reproduces_a_linear_field() {
        // A grid holding f(x) = x + 2y + 3z at its centres: trilinear sampling is exact.
        let dims = [5, 4, 3];
        let origin = DVec3::splat(0.5);
        let cell = DVec3::ONE;
        let mut sums = Vec::new();
        for z in 0..dims[2] {
            for y in 0..dims[1] {
                for x in 0..dims[0] {
                    let p = origin + DVec3::new(x as f64, y as f64, z as f64);
                    let f = (p.x + 2.0 * p.y + 3.0 * p.z) as f32;
                    sums.push([f, 1.0, 0.0, 0.0]);
                }
            }
        }
        let grid = VoxelGrid {
            origin,
            cell,
            dims,
            sums,
        };
        for p in [
            DVec3::new(1.3, 2.2, 1.7),
            DVec3::new(0.5, 0.5, 0.5),
            DVec3::new(4.5, 3.5, 2.5),
        ] {
            let (phi, num) = grid.sample(&mut (), p, DVec3::X, 0.0);
            assert!((phi - (p.x + 2.0 * p.y + 3.0 * p.z)).abs() < 1e-4, "{p}");
            assert!((num[0] - 1.0).abs() < 1e-6);
        }
        // Outside, the faces' values.
        let (phi, _) = grid.sample(&mut (), DVec3::new(-3.0, 0.5, 0.5), DVec3::X, 0.0);
        assert!((phi - (0.5 + 1.0 + 1.5)).abs() < 1e-4);
    }
}
