//! The voxel-grid baseline of the paper's Table 3: the particles splatted into a regular grid
//! with the same kernel (the sums Phi and Σ theta_i phi_i at every cell centre), then
//! ray-marched with the same integrators, noise and transfer functions as the RBF renderer,
//! sampling the grid by trilinear interpolation between cell centres instead of querying the
//! particles. Every backend does both through [`super::Backend::voxelize`] and
//! [`super::Backend::render_voxels`]; this file holds what they share: where the cells lie
//! ([`VoxelGeometry`]), the grid of sums as the host holds it, and the sampling rule
//! ([`VoxelGrid::trilinear`], the CPU twin of `field_query` in
//! `shaders_glsl/shared/voxel_sample.glsl`).
//!
//! What the grid loses is what a voxel renderer loses: detail finer than a cell (the
//! quantisation the paper names), and Theta blurred across cells, since the sums are
//! interpolated and divided afterwards. As the grid grows the image converges to the RBF
//! image (tests/voxel_baseline.rs). The grid spans the march box (the series' bounds grown by
//! the frame's margin) with cubic cells, `n` along its longest side; the callers re-voxelise
//! it for every step (the studies for every frame, as the paper's comparison does).

use glam::DVec3;

use super::BackendError;
use crate::field::RegularGrid;

/// The largest grid side accepted (a 1024³ grid holds 16 GiB of f32 sums).
pub const MAX_GRID: usize = 1024;

/// Cells per slab when the host splats: bounds the f64 sums held at once to a slab's worth.
const SLAB_CELLS: usize = 1 << 22;

/// Where a grid's cells lie: cell-centred over `lo..hi`, `dims` cells along each axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VoxelGeometry {
    /// The grid's least corner (a cell's outer face), data units.
    pub lo: DVec3,
    /// The grid's largest corner, data units.
    pub hi: DVec3,
    /// Cells along x, y and z.
    pub dims: [usize; 3],
}

impl VoxelGeometry {
    /// The grid over `lo..hi` with cubic cells, `n` cells along its longest side; `backend`
    /// names who refuses an `n` outside `1..=MAX_GRID`.
    pub fn new(
        backend: &'static str,
        lo: DVec3,
        hi: DVec3,
        n: usize,
    ) -> Result<VoxelGeometry, BackendError> {
        if n == 0 || n > MAX_GRID {
            return Err(BackendError::Device {
                backend,
                message: format!(
                    "a voxel grid of {n} cells along its longest side; 1..={MAX_GRID} are allowed"
                ),
            });
        }
        Ok(VoxelGeometry {
            lo,
            hi,
            dims: Self::dims_for(lo, hi, n),
        })
    }

    /// The dimensions of a grid with cubic cells, `n` cells along the longest side of `lo..hi`.
    pub fn dims_for(lo: DVec3, hi: DVec3, n: usize) -> [usize; 3] {
        let extent = (hi - lo).max(DVec3::splat(1e-300));
        let longest = extent.max_element();
        extent
            .to_array()
            .map(|e| ((n as f64 * e / longest).round() as usize).clamp(1, n))
    }

    /// The cell size along each axis.
    pub fn cell(&self) -> DVec3 {
        (self.hi - self.lo)
            / DVec3::new(
                self.dims[0] as f64,
                self.dims[1] as f64,
                self.dims[2] as f64,
            )
    }

    /// The first cell's centre.
    pub fn first_centre(&self) -> DVec3 {
        self.lo + 0.5 * self.cell()
    }

    /// How many cells the grid has.
    pub fn cells(&self) -> usize {
        self.dims.iter().product()
    }

    /// Bytes of the grid's sums (four f32 per cell).
    pub fn bytes(&self) -> usize {
        self.cells() * std::mem::size_of::<[f32; 4]>()
    }

    /// The cell centres of `layers` layers from layer `first` along z, as a grid.
    pub fn slab(&self, first: usize, layers: usize) -> RegularGrid {
        let cell = self.cell();
        let lo = self.lo + DVec3::new(0.0, 0.0, first as f64 * cell.z);
        let hi = DVec3::new(self.hi.x, self.hi.y, lo.z + layers as f64 * cell.z);
        RegularGrid::cell_centred(lo, hi, [self.dims[0], self.dims[1], layers])
    }
}

/// A grid of the field's sums at cell centres, f32 as a GPU voxel renderer keeps them.
#[derive(Clone, Debug)]
pub struct VoxelGrid {
    geometry: VoxelGeometry,
    /// The first cell's centre.
    origin: DVec3,
    /// Cell size.
    cell: DVec3,
    /// Phi and the three Theta numerators per cell, x fastest.
    sums: Vec<[f32; 4]>,
}

impl VoxelGrid {
    /// The grid of `sums` (Phi and the Theta numerators per cell, x fastest).
    pub fn from_sums(geometry: VoxelGeometry, sums: Vec<[f32; 4]>) -> VoxelGrid {
        assert_eq!(sums.len(), geometry.cells(), "one sum per cell");
        VoxelGrid {
            origin: geometry.first_centre(),
            cell: geometry.cell(),
            geometry,
            sums,
        }
    }

    /// The grid whose sums `query` gives for each slab of cell centres (the host's splat:
    /// slab by slab along z, so a slab's f64 sums are all it holds beside the grid).
    pub fn splat_with(
        geometry: VoxelGeometry,
        mut query: impl FnMut(&RegularGrid) -> Result<Vec<(f64, [f64; 3])>, BackendError>,
    ) -> Result<VoxelGrid, BackendError> {
        let dims = geometry.dims;
        let layer = dims[0] * dims[1];
        let per_slab = (SLAB_CELLS / layer).max(1);
        let mut sums = Vec::with_capacity(geometry.cells());
        let mut z = 0;
        while z < dims[2] {
            let layers = per_slab.min(dims[2] - z);
            sums.extend(
                query(&geometry.slab(z, layers))?
                    .into_iter()
                    .map(|(phi, num)| [phi as f32, num[0] as f32, num[1] as f32, num[2] as f32]),
            );
            z += layers;
        }
        Ok(VoxelGrid::from_sums(geometry, sums))
    }

    /// Where its cells lie.
    pub fn geometry(&self) -> VoxelGeometry {
        self.geometry
    }

    /// Cells along x, y and z.
    pub fn dims(&self) -> [usize; 3] {
        self.geometry.dims
    }

    /// Phi and the Theta numerators per cell, x fastest.
    pub fn sums(&self) -> &[[f32; 4]] {
        &self.sums
    }

    /// Bytes the grid holds.
    pub fn bytes(&self) -> usize {
        self.sums.len() * std::mem::size_of::<[f32; 4]>()
    }

    fn at(&self, i: [usize; 3]) -> [f32; 4] {
        let d = self.geometry.dims;
        self.sums[i[0] + d[0] * (i[1] + d[1] * i[2])]
    }

    /// Phi and the Theta numerators at `x`: trilinear interpolation of the sums between cell
    /// centres (clamped to the outer cells' centres at the grid's faces); the CPU backend
    /// samples the grid through it (`FieldSampler`). Twin: `voxel_field` in
    /// `shaders_glsl/shared/voxel_sample.glsl`, statement for statement.
    pub fn trilinear(&self, x: DVec3) -> (f64, [f64; 3]) {
        let dims = self.geometry.dims;
        let g = (x - self.origin) / self.cell;
        let mut base = [0usize; 3];
        let mut frac = [0.0f64; 3];
        for a in 0..3 {
            let max = (dims[a] - 1) as f64;
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
                    if dims[a] == 1 {
                        w = 0.0;
                    }
                    i[a] = (base[a] + 1).min(dims[a] - 1);
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cells_are_cubic_with_n_along_the_longest_side() {
        let d = VoxelGeometry::dims_for(DVec3::ZERO, DVec3::new(2.0, 1.0, 0.5), 64);
        assert_eq!(d, [64, 32, 16]);
        let d = VoxelGeometry::dims_for(DVec3::ZERO, DVec3::new(1.0, 1e-9, 1.0), 8);
        assert_eq!(d, [8, 1, 8]);
        for n in [0, MAX_GRID + 1] {
            let e = VoxelGeometry::new("cpu", DVec3::ZERO, DVec3::ONE, n).unwrap_err();
            assert!(e.to_string().contains("1..=1024"), "{e}");
        }
    }

    #[test]
    fn trilinear_sampling_reproduces_a_linear_field() {
        // A grid holding f(x) = x + 2y + 3z at its centres: trilinear sampling is exact.
        let geometry = VoxelGeometry {
            lo: DVec3::ZERO,
            hi: DVec3::new(5.0, 4.0, 3.0),
            dims: [5, 4, 3],
        };
        let dims = geometry.dims;
        let origin = geometry.first_centre();
        assert_eq!(origin, DVec3::splat(0.5));
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
        let grid = VoxelGrid::from_sums(geometry, sums);
        for p in [
            DVec3::new(1.3, 2.2, 1.7),
            DVec3::new(0.5, 0.5, 0.5),
            DVec3::new(4.5, 3.5, 2.5),
        ] {
            let (phi, num) = grid.trilinear(p);
            assert!((phi - (p.x + 2.0 * p.y + 3.0 * p.z)).abs() < 1e-4, "{p}");
            assert!((num[0] - 1.0).abs() < 1e-6);
        }
        // Outside, the faces' values.
        let (phi, _) = grid.trilinear(DVec3::new(-3.0, 0.5, 0.5));
        assert!((phi - (0.5 + 1.0 + 1.5)).abs() < 1e-4);
    }
}
