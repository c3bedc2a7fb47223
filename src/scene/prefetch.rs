//! Reading ahead of playback: a worker thread reads and decodes the steps a player will show
//! next into the series' cache while the current one renders, never holding more than the
//! cache's byte bound.

use std::sync::{Arc, Condvar, Mutex};
use std::thread::{Scope, ScopedJoinHandle};

use super::TimeSeries;

#[derive(Default)]
struct Plan {
    /// The step the player shows now (it holds it, in the cache or not).
    current: usize,
    /// The steps to show next, in playback order.
    upcoming: Vec<usize>,
    /// Bumped by every new plan, so the worker drops an old one between two reads.
    generation: u64,
    stop: bool,
}

/// A worker that keeps the next steps of a playback in the series' cache.
///
/// It reads the planned steps in order while the current step, the planned steps already
/// read and the next one fit the cache's bound together: what the cache drops to make room
/// are the steps already shown (the least recently used), never the current one or one read
/// for later, and memory stays within the bound plus the step the player holds. It stops at
/// the first step that does not fit or fails to read (the player reads that one itself, and
/// sees its error there).
pub struct Prefetcher<'scope> {
    plan: Arc<(Mutex<Plan>, Condvar)>,
    worker: Option<ScopedJoinHandle<'scope, ()>>,
}

impl<'scope> Prefetcher<'scope> {
    /// Starts the worker on `scope`, with nothing planned yet.
    pub fn spawn<'env>(scope: &'scope Scope<'scope, 'env>, series: &'env TimeSeries) -> Self {
        let plan = Arc::new((Mutex::new(Plan::default()), Condvar::new()));
        let shared = plan.clone();
        let worker = scope.spawn(move || prefetch(series, &shared));
        Prefetcher {
            plan,
            worker: Some(worker),
        }
    }

    /// The player shows `current` now: read `upcoming` (in this order) ahead of it,
    /// replacing the previous plan.
    pub fn plan(&self, current: usize, upcoming: impl IntoIterator<Item = usize>) {
        let (lock, wake) = &*self.plan;
        let mut plan = lock.lock().unwrap();
        plan.current = current;
        plan.upcoming = upcoming.into_iter().collect();
        plan.generation += 1;
        wake.notify_one();
    }
}

impl Drop for Prefetcher<'_> {
    fn drop(&mut self) {
        let (lock, wake) = &*self.plan;
        lock.lock().unwrap().stop = true;
        wake.notify_one();
        if let Some(w) = self.worker.take() {
            let _ = w.join();
        }
    }
}

fn prefetch(series: &TimeSeries, plan: &(Mutex<Plan>, Condvar)) {
    let (lock, wake) = plan;
    let mut done = u64::MAX;
    loop {
        let (current, upcoming, generation) = {
            let mut p = lock.lock().unwrap();
            while !p.stop && p.generation == done {
                p = wake.wait(p).unwrap();
            }
            if p.stop {
                return;
            }
            (p.current, p.upcoming.clone(), p.generation)
        };
        let bytes = |i: usize| series.step_info(i).map_or(0, |s| s.bytes);
        let mut held = bytes(current);
        // The current step and those read for later, most recently used: making room for the
        // next drops steps already shown.
        let mut keep = vec![current];
        for index in upcoming {
            if lock.lock().unwrap().generation != generation || index >= series.len() {
                break;
            }
            if held + bytes(index) > series.cache_limit() {
                break;
            }
            held += bytes(index);
            if series.is_cached(index) {
                keep.push(index);
                continue;
            }
            series.touch(&keep);
            keep.push(index);
            if let Err(e) = series.step(index) {
                tracing::debug!("prefetch of step {index} stopped: {e}");
                break;
            }
        }
        done = generation;
    }
}
