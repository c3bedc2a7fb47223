//! Opening a series reads each step at most once, ever: the index beside the data answers the
//! next open (and is rebuilt for a file that changed, and ignored when unreadable or
//! unwritable); playback reads ahead on a worker within the cache's bound, delivering the same
//! steps a direct read gives.

use std::path::Path;

use aarbf::io::{self, AttributeSelection};
use aarbf::scene::index::INDEX_FILE;
use aarbf::scene::prefetch::Prefetcher;
use aarbf::scene::{OpenOptions, TimeSeries};

/// Step `k` as post-processing writes it: CSV with a header and 17 significant digits, a
/// particle count that differs per step (not a power of two), positions far from the origin.
fn write_step(dir: &Path, k: usize, salt: f64) -> std::path::PathBuf {
    let n = 97 + 13 * k;
    let mut text = String::from("x,y,z,density,h\n");
    for i in 0..n {
        let t = i as f64 * 0.618_033_988_749_894_9 + k as f64 * 0.1 + salt;
        text.push_str(&format!(
            "{:.16e},{:.16e},{:.16e},{:.16e},{:.16e}\n",
            1.0e6 + t.sin(),
            -2.5e3 + (1.7 * t).cos(),
            t.fract() / 3.0,
            1000.0 + 37.0 * (0.3 * t).sin() + k as f64,
            0.01 + 0.001 * (i % 7) as f64,
        ));
    }
    let path = dir.join(format!("snap_{k}.csv"));
    std::fs::write(&path, text).unwrap();
    path
}

fn write_series(dir: &Path, steps: usize) {
    for k in 0..steps {
        write_step(dir, k, 0.0);
    }
}

fn open(dir: &Path, attributes: AttributeSelection) -> TimeSeries {
    TimeSeries::open(
        dir,
        &OpenOptions {
            attributes,
            ..OpenOptions::default()
        },
    )
    .unwrap()
}

/// Everything a series knows about its steps, for comparing two opens.
fn summary(s: &TimeSeries) -> String {
    format!("{:?} {:?} {:?}", s.steps(), s.attributes(), s.bounds())
}

#[test]
fn the_second_open_reads_no_step_and_knows_the_same_values_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    write_series(dir.path(), 7);
    let first = open(dir.path(), AttributeSelection::All);
    assert_eq!(
        first.steps_decoded(),
        7,
        "a first open reads every step once"
    );
    assert!(
        dir.path().join(INDEX_FILE).is_file(),
        "the index is written"
    );
    let second = open(dir.path(), AttributeSelection::All);
    assert_eq!(second.steps_decoded(), 0, "the index answers every step");
    assert_eq!(summary(&first), summary(&second));
    // The values are those of the steps themselves.
    let steps: Vec<_> = (0..7).map(|k| (*first.step(k).unwrap()).clone()).collect();
    assert_eq!(summary(&TimeSeries::from_steps(steps)), summary(&second));
    // Reading a step after an indexed open decodes just that step, and it equals a direct read.
    let s3 = second.step(3).unwrap();
    assert_eq!(second.steps_decoded(), 1);
    let refs = io::list_steps(dir.path(), None).unwrap();
    assert_eq!(
        *s3,
        io::read_step(&refs[3], &AttributeSelection::All).unwrap()
    );
}

#[test]
fn a_changed_file_is_scanned_again_and_the_rest_come_from_the_index() {
    let dir = tempfile::tempdir().unwrap();
    write_series(dir.path(), 6);
    let before = open(dir.path(), AttributeSelection::All);
    // A simulation rewrites step 4 (other values, another count).
    let path = write_step(dir.path(), 4, 0.37);
    std::fs::write(
        &path,
        std::fs::read_to_string(&path).unwrap() + "1e6,-2500,0.5,2000,0.02\n",
    )
    .unwrap();
    let after = open(dir.path(), AttributeSelection::All);
    assert_eq!(after.steps_decoded(), 1, "only the changed step is read");
    assert_eq!(after.steps()[4].count, before.steps()[4].count + 1);
    assert_eq!(after.attribute("density").unwrap().max, 2000.0);
    // The same as a series opened with no index at all.
    std::fs::remove_file(dir.path().join(INDEX_FILE)).unwrap();
    let fresh = open(dir.path(), AttributeSelection::All);
    assert_eq!(fresh.steps_decoded(), 6);
    assert_eq!(summary(&after), summary(&fresh));
}

#[test]
fn a_selection_is_served_by_an_index_of_every_attribute_but_not_the_reverse() {
    let dir = tempfile::tempdir().unwrap();
    write_series(dir.path(), 4);
    let only =
        |names: &[&str]| AttributeSelection::Only(names.iter().map(|s| s.to_string()).collect());
    let h = open(dir.path(), only(&["h"]));
    assert_eq!(h.steps_decoded(), 4);
    assert_eq!(h.attributes().len(), 1);
    // An index of "h" alone cannot say what else the files hold.
    let all = open(dir.path(), AttributeSelection::All);
    assert_eq!(all.steps_decoded(), 4);
    let again = open(dir.path(), only(&["density", "h"]));
    assert_eq!(again.steps_decoded(), 0, "every attribute is indexed now");
    assert_eq!(
        again
            .attributes()
            .iter()
            .map(|a| a.name.as_str())
            .collect::<Vec<_>>(),
        ["density", "h"],
        "in the order asked for, as a read gives them"
    );
    assert_eq!(again.attribute("h"), h.attribute("h"));
    assert_eq!(
        again.steps()[2].bytes,
        h.steps()[2].bytes + 8 * again.steps()[2].count
    );
}

#[test]
fn an_unreadable_or_unwritable_index_is_ignored() {
    let dir = tempfile::tempdir().unwrap();
    write_series(dir.path(), 3);
    let reference = summary(&open(dir.path(), AttributeSelection::All));
    std::fs::write(dir.path().join(INDEX_FILE), b"{ not json").unwrap();
    let garbled = open(dir.path(), AttributeSelection::All);
    assert_eq!(garbled.steps_decoded(), 3);
    assert_eq!(summary(&garbled), reference);
    assert_eq!(
        open(dir.path(), AttributeSelection::All).steps_decoded(),
        0,
        "a garbled index is replaced"
    );
    // An index that can be neither read nor replaced (a directory in its place).
    std::fs::remove_file(dir.path().join(INDEX_FILE)).unwrap();
    std::fs::create_dir(dir.path().join(INDEX_FILE)).unwrap();
    for _ in 0..2 {
        let s = open(dir.path(), AttributeSelection::All);
        assert_eq!(s.steps_decoded(), 3);
        assert_eq!(summary(&s), reference);
    }
}

#[test]
fn prefetched_playback_reads_each_step_once_within_the_bound_and_in_order() {
    let dir = tempfile::tempdir().unwrap();
    write_series(dir.path(), 9);
    let refs = io::list_steps(dir.path(), None).unwrap();
    let largest = (0..9)
        .map(|k| {
            io::read_step(&refs[k], &AttributeSelection::All)
                .unwrap()
                .bytes()
        })
        .max()
        .unwrap();
    for (bound, name) in [(3 * largest, "three steps"), (largest / 2, "half a step")] {
        // Opened with an index, so every read below is the player's or the worker's.
        open(dir.path(), AttributeSelection::All);
        let series = TimeSeries::open(
            dir.path(),
            &OpenOptions {
                cache_bytes: bound,
                ..OpenOptions::default()
            },
        )
        .unwrap();
        assert_eq!(series.steps_decoded(), 0);
        let order: Vec<usize> = (0..9).collect();
        std::thread::scope(|scope| {
            let prefetcher = Prefetcher::spawn(scope, &series);
            for (k, &step) in order.iter().enumerate() {
                prefetcher.plan(step, order[k + 1..].iter().copied());
                let got = series.step(step).unwrap();
                assert_eq!(
                    *got,
                    io::read_step(&refs[step], &AttributeSelection::All).unwrap(),
                    "{name}: step {step} as a direct read gives it"
                );
                // The cache never holds more than its bound, except a single step larger
                // than it (the last one read is always kept).
                let cached = series.cached_bytes();
                assert!(
                    cached <= bound.max(largest),
                    "{name}: {cached} bytes cached, bound {bound}"
                );
                if bound >= 3 * largest && k + 1 < order.len() {
                    // Give the worker time to read ahead while "rendering".
                    let t = std::time::Instant::now();
                    while !series.is_cached(step + 1) && t.elapsed().as_secs() < 10 {
                        std::thread::sleep(std::time::Duration::from_millis(2));
                    }
                    assert!(
                        series.is_cached(step + 1),
                        "{name}: step {} read ahead",
                        step + 1
                    );
                }
            }
        });
        assert_eq!(
            series.steps_decoded(),
            9,
            "{name}: every step decoded exactly once, by the worker or the player"
        );
    }
}

fn open_in_background(dir: &Path) -> TimeSeries {
    TimeSeries::open(
        dir,
        &OpenOptions {
            background_scan: true,
            ..OpenOptions::default()
        },
    )
    .unwrap()
}

/// A background open returns once the files are listed and the first step is read: it does
/// not wait for the other steps (a broken later step is the scan's error, not the open's),
/// reports its values as provisional until the scan ends, and ends with exactly the values,
/// bit for bit, a waiting open gives, each step decoded once.
#[test]
fn a_background_open_does_not_wait_for_the_steps_and_ends_with_the_same_values() {
    let dir = tempfile::tempdir().unwrap();
    write_series(dir.path(), 12);
    // A step the scan cannot read, so it stops there: the open must not.
    std::fs::write(dir.path().join("snap_9.csv"), "x,y,z,density,h\n1,2\n").unwrap();
    let waiting = TimeSeries::open(dir.path(), &OpenOptions::default());
    let e = waiting
        .err()
        .expect("a waiting open reads every step")
        .to_string();
    assert!(e.contains("snap_9.csv"), "{e}");
    std::fs::remove_file(dir.path().join(INDEX_FILE)).ok();

    let series = open_in_background(dir.path());
    assert_eq!(series.len(), 12, "every step is listed at once");
    let e = series.wait_for_scan().unwrap_err().to_string();
    assert!(
        e.contains("snap_9.csv"),
        "the scan's error names the file: {e}"
    );
    let values = series.values();
    assert!(values.is_provisional(), "a step could not be scanned");
    assert!(!values.steps[9].scanned && values.steps[9].count == 0);
    assert_eq!(values.scanned, 11);
    assert!(
        values
            .error
            .as_deref()
            .is_some_and(|e| e.contains("snap_9.csv"))
    );
    drop(series);

    // Repaired, a background open scans only what the index lacks and ends final.
    write_step(dir.path(), 9, 0.0);
    let series = open_in_background(dir.path());
    series.wait_for_scan().unwrap();
    assert!(!series.values().is_provisional());
    assert_eq!(series.steps_decoded(), 1, "only the repaired step is read");
    std::fs::remove_file(dir.path().join(INDEX_FILE)).unwrap();
    let fresh = open_in_background(dir.path());
    fresh.wait_for_scan().unwrap();
    assert_eq!(
        fresh.steps_decoded(),
        12,
        "each step decoded once, by the open or the scan"
    );
    let reference = open(dir.path(), AttributeSelection::All);
    assert_eq!(summary(&fresh), summary(&reference));
    assert_eq!(fresh.values(), reference.values());

    // Dropping a series mid-scan stops the scan (and never hangs); what it read is indexed.
    std::fs::remove_file(dir.path().join(INDEX_FILE)).unwrap();
    drop(open_in_background(dir.path()));
    let after = open(dir.path(), AttributeSelection::All);
    assert!(after.steps_decoded() <= 12);
    assert_eq!(summary(&after), summary(&reference));
}

/// `rescan` reads every step whatever the index says, and gives the same values.
#[test]
fn a_rescan_reads_every_step_again_and_agrees_with_the_index() {
    let dir = tempfile::tempdir().unwrap();
    write_series(dir.path(), 5);
    let indexed = open(dir.path(), AttributeSelection::All);
    let again = open(dir.path(), AttributeSelection::All);
    assert_eq!(again.steps_decoded(), 0);
    let rescanned = TimeSeries::open(
        dir.path(),
        &OpenOptions {
            rescan: true,
            ..OpenOptions::default()
        },
    )
    .unwrap();
    assert_eq!(rescanned.steps_decoded(), 5);
    assert_eq!(summary(&rescanned), summary(&indexed));
    assert_eq!(
        open(dir.path(), AttributeSelection::All).steps_decoded(),
        0,
        "the index is rewritten"
    );
}
