//! A series handed to a writer a run of particles at a time (so a step need never be whole in
//! memory), and the check that the runs make up the step.

use std::borrow::Cow;

use indicatif::ProgressBar;

use crate::values::Step;

/// A series to write, handed over a step or a run of particles at a time, so that a step larger
/// than memory allows can be written without ever being whole: generated data computes each
/// run on demand. A slice of steps is one (each step a single run).
pub trait SeriesSource {
    /// How many steps.
    fn step_count(&self) -> usize;
    /// How many particles step `step` has.
    fn step_len(&self, step: usize) -> usize;
    /// Calls `write` on step `step`'s particles in order, a run at a time, every run with the
    /// same attributes; stops at the first error.
    fn for_each_chunk(
        &self,
        step: usize,
        write: &mut dyn FnMut(&Step) -> std::io::Result<()>,
    ) -> std::io::Result<()>;
    /// Step `step` whole, for the formats that cannot be written a run at a time.
    fn whole_step(&self, step: usize) -> Cow<'_, Step>;
}

impl SeriesSource for [Step] {
    fn step_count(&self) -> usize {
        self.len()
    }
    fn step_len(&self, step: usize) -> usize {
        self[step].len()
    }
    fn for_each_chunk(
        &self,
        step: usize,
        write: &mut dyn FnMut(&Step) -> std::io::Result<()>,
    ) -> std::io::Result<()> {
        write(&self[step])
    }
    fn whole_step(&self, step: usize) -> Cow<'_, Step> {
        Cow::Borrowed(&self[step])
    }
}

/// Calls `write` on each run of step `step` of `source`, advancing `bar` by its particles; an
/// error if the runs do not add up to the step's length (the file's header already gave it).
pub(super) fn write_step_chunks(
    source: &(impl SeriesSource + ?Sized),
    step: usize,
    bar: &ProgressBar,
    mut write: impl FnMut(&Step) -> std::io::Result<()>,
) -> std::io::Result<()> {
    let expected = source.step_len(step);
    let mut written = 0;
    source.for_each_chunk(step, &mut |chunk| {
        write(chunk)?;
        written += chunk.len();
        bar.inc(chunk.len() as u64);
        Ok(())
    })?;
    if written != expected {
        return Err(std::io::Error::other(format!(
            "step {step} was to have {expected} particles, its runs held {written}"
        )));
    }
    Ok(())
}
