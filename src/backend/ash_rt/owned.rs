//! A brick's share of a distributed frame on the ash backend ([`Backend::render_owned`],
//! [`Backend::owned_depth`]): one launch over the brick's rectangle, its brick, output
//! and inputs in one buffer reached by device address ([`BrickLaunch`]), read back as f64:
//! `owned.rgen` on the RT pipeline, or `lbvh_owned.comp` with [`super::Traversal::Lbvh`].
//! Nothing is accumulated.
//!
//! [`Backend::render_owned`]: crate::backend::Backend::render_owned
//! [`Backend::owned_depth`]: crate::backend::Backend::owned_depth

use std::time::Instant;

use super::AshBackend;
use super::buffers::addressed;
use super::context::device_error;
use super::launch::Launch;
use super::pipelines::Push;
use crate::backend::BackendError;
use crate::backend::shaders::SpecConstants;
use crate::backend::shaders::brick::BrickLaunch;
use crate::values::FrameParams;

impl AshBackend {
    /// Runs one brick launch of `frame` (the share's own frame: its integrator picks the
    /// kernel's variant) and returns its output's bytes.
    pub(super) fn run_owned(
        &mut self,
        frame: &FrameParams,
        launch: &BrickLaunch,
    ) -> Result<Vec<u8>, BackendError> {
        self.built()?;
        if launch.rect.is_empty() {
            return Ok(Vec::new());
        }
        let (w, h) = (launch.rect.width(), launch.rect.height());
        let invocations = u64::from(w) * u64::from(h);
        if invocations > u64::from(self.ctx.info.max_dispatch_invocations) {
            return Err(device_error(
                "a brick's share",
                format!(
                    "{w} x {h} pixels exceed the device's dispatch limit of {} invocations",
                    self.ctx.info.max_dispatch_invocations
                ),
            ));
        }
        let bytes = launch.io.len() as u64;
        if bytes > self.ctx.info.max_allocation {
            return Err(device_error(
                "a brick's share",
                format!(
                    "its buffer of {bytes} bytes exceeds this device's largest allocation ({} \
                     bytes)",
                    self.ctx.info.max_allocation
                ),
            ));
        }
        self.write_params(Some(frame))?;
        let mut io = addressed(&self.ctx, "brick", bytes)?;
        io.write(0, &launch.io)?;
        let spec = self.spec(
            SpecConstants::integrator_id(frame.integrator),
            SpecConstants::colour_id(frame.colour),
            SpecConstants::noise_id(frame.noise),
        )?;
        let push = Push {
            owned_address: io.address,
            ..Push::default()
        };
        let started = Instant::now();
        let gpu = self.launch(Launch::Owned, spec, push, (io.raw, 0), (w, h))?;
        let all = io.read(BrickLaunch::OUTPUT_OFFSET + launch.output_bytes())?;
        self.timings.frame = if self.ctx.info.timestamp_period.is_some() {
            gpu
        } else {
            started.elapsed()
        };
        Ok(all[BrickLaunch::OUTPUT_OFFSET as usize..].to_vec())
    }
}
