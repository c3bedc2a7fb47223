//! Where the data comes from: a path, or a series already in memory, and its first step read
//! whole where a default needs the names of the data's attributes.

use std::path::PathBuf;

use anyhow::Context;

use super::DataReads;
use super::args::DataArgs;
use super::first_step::FirstStep;
use crate::io::{Format, ReadOptions};
use crate::scene::TimeSeries;
use crate::scene_file::SceneFile;
use crate::values::Step;

/// The data before its series opens, and how to read it.
pub(super) struct Source {
    /// A series already in memory (the Python package's arrays); `None` reads `path`.
    pub memory: Option<TimeSeries>,
    /// The data's path, or the name that stands for it in messages.
    pub path: PathBuf,
    pub format: Option<Format>,
    /// What to read of files that hold a choice (an HDF5 snapshot's particle type).
    pub read: ReadOptions,
}

impl Source {
    /// The series in memory, or the path the flags or the scene file give.
    pub(super) fn new(
        scene: &SceneFile,
        memory: Option<(TimeSeries, PathBuf)>,
        data: &DataArgs,
    ) -> anyhow::Result<Source> {
        let (memory, path) = match memory {
            Some((series, name)) => (Some(series), name),
            None => (
                None,
                data.data.clone().or(scene.data.path.clone()).context(
                    "no data given: pass --data <path> or a --scene file with [data] path",
                )?,
            ),
        };
        Ok(Source {
            memory,
            path,
            format: data.format.or(scene.data.format),
            read: data.read_options(&scene.data),
        })
    }

    /// The first step with every attribute it holds, as the defaults see it: from memory, or
    /// from its file as `reads` reads it.
    pub(super) fn first_step(&self, reads: &dyn DataReads) -> anyhow::Result<Option<FirstStep>> {
        if let Some(series) = &self.memory {
            return Ok(series.first_step_in_full()?.map(FirstStep::Whole));
        }
        let refs = crate::io::list_steps_reading(&self.path, self.format, self.read)?;
        refs.first()
            .map(|first| reads.first_step(first))
            .transpose()
    }
}

/// The names of a step's attributes (none without a step).
pub(super) fn names_of(step: Option<&Step>) -> Vec<String> {
    step.map(|s| s.attribute_names().iter().map(|n| n.to_string()).collect())
        .unwrap_or_default()
}
