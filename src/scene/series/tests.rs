use super::*;
use crate::values::Attribute;
use glam::DVec3;

fn step(n: usize, v: f64) -> Arc<Step> {
    Arc::new(Step {
        name: format!("s{n}"),
        positions: vec![DVec3::splat(v); n],
        attributes: vec![Attribute {
            name: "a".into(),
            values: vec![v; n],
        }],
    })
}

#[test]
fn cache_keeps_within_its_bound_and_drops_the_oldest() {
    let one = step(10, 1.0).bytes();
    let mut cache = StepCache::new(2 * one);
    cache.insert(0, step(10, 0.0));
    cache.insert(1, step(10, 1.0));
    assert!(cache.get(0).is_some()); // 0 is now the most recent
    cache.insert(2, step(10, 2.0));
    assert_eq!(cache.bytes, 2 * one);
    assert!(
        cache.get(1).is_none(),
        "the least recently used step goes first"
    );
    assert!(cache.get(0).is_some() && cache.get(2).is_some());
    // A step larger than the bound is still held alone.
    cache.insert(3, step(100, 3.0));
    assert_eq!(cache.entries.len(), 1);
}

#[test]
fn memory_series_reports_bounds_counts_and_ranges() {
    let s = TimeSeries::from_steps(vec![(*step(3, -1.0)).clone(), (*step(5, 2.0)).clone()]);
    assert_eq!(s.len(), 2);
    assert_eq!(s.max_count(), 5);
    assert_eq!(s.bounds().min, DVec3::splat(-1.0));
    assert_eq!(s.bounds().max, DVec3::splat(2.0));
    let a = s.attribute("a").unwrap();
    assert_eq!((a.min, a.max), (-1.0, 2.0));
    assert_eq!((a.mean, a.count), ((-3.0 + 5.0 * 2.0) / 8.0, 8));
    assert!(s.step(2).is_err());
}
