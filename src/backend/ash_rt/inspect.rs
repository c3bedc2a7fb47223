//! What the ash backend shows of itself beside the `Backend` trait: the traversal and hit
//! reporting it is set to, its structure's size and timings, and (for tests) the device's
//! prepared arrays, the preparation's stages alone and poisoning.

use glam::DVec3;

use super::*;

impl AshBackend {
    /// Chooses how queries and frames traverse the particles. The RT structure is built in
    /// either case; the LBVH is built (on the CPU) when first needed.
    pub fn set_traversal(&mut self, traversal: Traversal) {
        self.traversal = traversal;
    }

    /// How queries and frames traverse the particles.
    pub fn traversal(&self) -> Traversal {
        self.traversal
    }

    /// Chooses how the RT pipeline reports hits ([`HitReports`]).
    pub fn set_hit_reports(&mut self, reports: HitReports) {
        self.hit_reports = reports;
    }

    /// The LBVH's depth (internal nodes on its longest path), once built.
    pub fn lbvh_depth(&self) -> Option<u32> {
        self.lbvh.as_ref().map(|t| t.depth)
    }

    /// GPU time of the last build or refit, by stage.
    pub fn structure_timings(&self) -> StructureTimings {
        self.structure_timings
    }

    /// Bytes of the BLAS (0 before the first build).
    pub fn blas_bytes(&self) -> u64 {
        self.structure.as_ref().map_or(0, Structure::blas_bytes)
    }

    /// Boxes the BLAS storage and the box buffer are sized for (clusters of the capacity).
    pub fn blas_boxes(&self) -> u32 {
        self.structure.as_ref().map_or(0, |s| s.boxes)
    }

    /// Boxes (primitives) the last build covered: the uploaded step's clusters.
    pub fn blas_active_boxes(&self) -> u32 {
        self.structure.as_ref().map_or(0, |s| s.active)
    }

    /// The local-coordinate origin of the uploaded step (data = local + origin).
    pub fn origin(&self) -> Option<DVec3> {
        self.uploaded.as_ref().map(|u| u.data.origin)
    }

    /// The cluster boxes the box kernel wrote (local coordinates, `[min, max]`), one per slot
    /// of the box buffer (NaN past the step's clusters): for tests against
    /// `accel::ClusterBoxes`.
    pub fn read_boxes(&mut self) -> Result<Vec<[f32; 6]>, BackendError> {
        let n = self.blas_boxes() as u64;
        let bytes = self.buffers.boxes.read(n * BOX_BYTES)?;
        Ok(bytemuck::pod_collect_to_vec::<u8, f32>(&bytes)
            .chunks_exact(6)
            .map(|c| [c[0], c[1], c[2], c[3], c[4], c[5]])
            .collect())
    }

    /// The uploaded step's particles as the device prepared them, in Hilbert order, with the
    /// order (tests).
    pub fn sorted_particles(&mut self) -> Result<SortedParticles, BackendError> {
        let (Some(up), Some(prepare)) = (&self.uploaded, &mut self.prepare) else {
            return Err(BackendError::NothingUploaded(NAME));
        };
        let n = up.data.count as u64;
        let b = &mut self.buffers;
        Ok(SortedParticles {
            points: bytemuck::pod_collect_to_vec(&b.points.read(n * 16)?),
            points_lo: match up.data.double_single {
                true => Some(bytemuck::pod_collect_to_vec(&b.points_lo.read(n * 16)?)),
                false => None,
            },
            radius_attribute: match up.data.has_radius_attribute {
                true => Some(bytemuck::pod_collect_to_vec(&b.radius.read(n * 4)?)),
                false => None,
            },
            volume: match up.data.kernel.is_sph() {
                true => {
                    let offset = up.data.volume_offset();
                    let words: Vec<f32> =
                        bytemuck::pod_collect_to_vec(&b.radius.read((offset as u64 + n) * 4)?);
                    Some(words[offset..].to_vec())
                }
                false => None,
            },
            order: prepare.order(n as usize)?,
        })
    }

    /// Stage 1 of the preparation alone on `points` (f32 local coordinates in xyz), outputs
    /// poisoned first: each particle's Hilbert key and the permutation (tests; the twin is
    /// `shaders::cpu::hilbert_keys`).
    pub fn prepare_hilbert_keys(
        &mut self,
        points: &[[f32; 4]],
        quantizer: &crate::accel::HilbertQuantizer,
    ) -> Result<(Vec<u64>, Vec<u32>), BackendError> {
        self.ensure_prepare(points.len())?;
        match self.prepare.as_mut() {
            Some(p) => p.hilbert_keys(&self.commands, points, quantizer),
            None => Err(BackendError::NothingUploaded(NAME)),
        }
    }

    /// The preparation's radix sort alone on (`keys`, their indices), scratch poisoned first:
    /// the sorted keys and the input index of each (tests; the twin is
    /// `shaders::cpu::radix_sort`).
    pub fn prepare_sort_pairs(
        &mut self,
        keys: &[u32],
    ) -> Result<(Vec<u32>, Vec<u32>), BackendError> {
        self.ensure_prepare(keys.len())?;
        match self.prepare.as_mut() {
            Some(p) => p.sort_pairs(&self.commands, keys),
            None => Err(BackendError::NothingUploaded(NAME)),
        }
    }

    /// Copies every step from host-visible staging memory to device memory before preparing
    /// it, as on a discrete GPU without resizable BAR, even where the device could read the
    /// staging memory in place (tests: the copy path on a device that does not need it).
    pub fn always_copy_staging(&mut self) {
        self.staging = prepare::Staging::AlwaysCopy;
        self.prepare = None;
    }

    /// Fills the prepared particles, their lo parts and radius attribute and the sort's buffers
    /// with 0xFF (tests: poison before an upload).
    pub fn poison_prepared(&mut self) -> Result<(), BackendError> {
        let prepare = self
            .prepare
            .as_mut()
            .ok_or(BackendError::NothingUploaded(NAME))?;
        prepare.poison()?;
        let b = &mut self.buffers;
        for buffer in [&mut b.points, &mut b.points_lo, &mut b.radius] {
            buffer.write(0, &vec![0xFF; buffer.size as usize])?;
        }
        Ok(())
    }
}
