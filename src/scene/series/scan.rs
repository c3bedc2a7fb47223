//! The background scan of a series' steps, and the attribute ranges it merges.

use super::*;

/// The background scan: reads the `missing` steps (in parallel, each kept in the cache while
/// it fits), publishing the values after each, then writes the index.
pub(super) fn scan(
    shared: &Shared,
    mut stats: Vec<Option<StepStats>>,
    missing: &[usize],
    mut index: SeriesIndex,
) {
    let Source::Files {
        steps,
        selection,
        smoothing,
    } = &shared.source
    else {
        unreachable!("only a series of files is scanned")
    };
    let failed = Mutex::new(None::<DataError>);
    let found = Mutex::new(Vec::with_capacity(missing.len()));
    missing.par_iter().for_each(|&i| {
        // A step that cannot be read does not stop the others: their values are still known.
        if shared.cancel.load(Ordering::Relaxed) {
            return;
        }
        let r = &steps[i];
        let stamp = FileStamp::of(&r.path);
        match read_file_step(r, selection, *smoothing) {
            Ok(step) => {
                shared.decoded.fetch_add(1, Ordering::Relaxed);
                let step_stats = StepStats::of(&step, selection);
                shared.cache.lock().unwrap().insert(i, Arc::new(step));
                shared.loaded.notify_all();
                let mut values = shared.values.write().unwrap();
                values.steps[i] = StepInfo::of(r, Some(&step_stats));
                values.scanned += 1;
                values.bounds = values.bounds.union(step_stats.bounds);
                // Provisional until the end, where they are merged again in step order.
                merge_ranges(&mut values.attributes, &step_stats);
                found.lock().unwrap().push((i, step_stats, stamp));
            }
            Err(e) => {
                failed.lock().unwrap().get_or_insert(e);
            }
        }
    });
    for (i, s, stamp) in found.into_inner().unwrap() {
        index.insert(&steps[i], stamp, &s);
        stats[i] = Some(s);
    }
    index.save();
    // The ranges merged in step order, whatever order the steps were read in.
    {
        let mut values = shared.values.write().unwrap();
        values.attributes = series_ranges(stats.iter().flatten());
        let failed = failed.into_inner().unwrap();
        values.error = failed.as_ref().map(ToString::to_string);
        *shared.scan_error.lock().unwrap() = failed;
    }
    *shared.scan_running.lock().unwrap() = false;
    shared.scan_finished.notify_all();
}

/// The series-wide range and mean of each attribute, merged from the steps' statistics in
/// step order (so the same statistics, scanned or from the index, give the same values).
pub(super) fn series_ranges<'a>(steps: impl Iterator<Item = &'a StepStats>) -> Vec<AttributeInfo> {
    let mut ranges: Vec<AttributeInfo> = Vec::new();
    for step in steps {
        merge_ranges(&mut ranges, step);
    }
    ranges
}

/// Adds one step's attribute statistics to series-wide ranges.
pub(super) fn merge_ranges(ranges: &mut Vec<AttributeInfo>, step: &StepStats) {
    for a in &step.attributes {
        match ranges.iter_mut().find(|r| r.name == a.name) {
            Some(r) => {
                r.min = r.min.min(a.min);
                r.max = r.max.max(a.max);
                r.p01 = r.p01.min(a.p01);
                r.p99 = r.p99.max(a.p99);
                let total = r.count + a.count;
                r.mean = (r.mean * r.count as f64 + a.mean * a.count as f64) / total as f64;
                r.count = total;
            }
            None => ranges.push(a.clone()),
        }
    }
}
