//! The cache of steps read from disk.

use super::*;

/// Least-recently-used steps, bounded in bytes. The step last inserted is always kept, even
/// when it alone exceeds the bound, so a caller never loads the same step twice in a row.
pub(super) struct StepCache {
    pub(super) limit: usize,
    pub(super) bytes: usize,
    pub(super) entries: VecDeque<(usize, Arc<Step>)>,
    /// Steps some thread is reading now.
    pub(super) loading: HashSet<usize>,
    pub(super) read_times: HashMap<usize, Duration>,
}

impl StepCache {
    pub(super) fn new(limit: usize) -> StepCache {
        StepCache {
            limit,
            bytes: 0,
            entries: VecDeque::new(),
            loading: HashSet::new(),
            read_times: HashMap::new(),
        }
    }

    pub(super) fn get(&mut self, index: usize) -> Option<Arc<Step>> {
        let pos = self.entries.iter().position(|(i, _)| *i == index)?;
        let entry = self.entries.remove(pos)?;
        let step = entry.1.clone();
        self.entries.push_back(entry);
        Some(step)
    }

    pub(super) fn contains(&self, index: usize) -> bool {
        self.entries.iter().any(|(i, _)| *i == index)
    }

    pub(super) fn insert(&mut self, index: usize, step: Arc<Step>) {
        if self.limit == 0 {
            return;
        }
        self.bytes += step.bytes();
        self.entries.push_back((index, step));
        while self.bytes > self.limit && self.entries.len() > 1 {
            let (_, old) = self.entries.pop_front().unwrap();
            self.bytes -= old.bytes();
        }
    }
}
