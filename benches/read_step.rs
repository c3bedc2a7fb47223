//! Reading one step of particle files as the renderer does (`io::read_step`: open, decode the
//! positions and the attributes asked for into f64, the finiteness check), beside the floors
//! in the same process: reading the file's bytes from the page cache into a buffer, and
//! copying the decoded step in memory. Best of R runs each, after one read that warms the page
//! cache.
//!
//! cargo bench --profile checked --bench read_step -- [--runs R] [--attribute NAME] FILE...
#![expect(
    clippy::print_stdout,
    reason = "a benchmark prints its table to stdout"
)]

use std::io::Read;
use std::path::PathBuf;
use std::time::Instant;

use aarbf::io::{self, AttributeSelection};

fn best_of(runs: usize, mut f: impl FnMut()) -> f64 {
    (0..runs)
        .map(|_| {
            let t = Instant::now();
            f();
            t.elapsed().as_secs_f64()
        })
        .fold(f64::INFINITY, f64::min)
}

fn main() {
    let mut runs = 5;
    let mut selection = AttributeSelection::All;
    let mut files = Vec::new();
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--runs" => runs = args.next().and_then(|r| r.parse().ok()).expect("--runs R"),
            "--attribute" => {
                selection = AttributeSelection::Only(vec![args.next().expect("--attribute NAME")])
            }
            "--bench" => {}
            _ => files.push(PathBuf::from(a)),
        }
    }
    assert!(!files.is_empty(), "give the files to read");
    println!(
        "| file | particles | file MiB | read_step (ms) | floor: file from page cache (ms) | floor: copy the step (ms) | read_step / page cache | read_step / copy |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for file in files {
        let steps = io::list_steps(&file, None).expect("a particle file");
        let step_ref = &steps[0];
        let path = step_ref.path.clone();
        let step = io::read_step(step_ref, &selection).expect("a readable step");
        let read = best_of(runs, || {
            std::hint::black_box(io::read_step(step_ref, &selection).unwrap());
        });
        let mut buffer = Vec::new();
        let page_cache = best_of(runs, || {
            buffer.clear();
            std::fs::File::open(&path)
                .unwrap()
                .read_to_end(&mut buffer)
                .unwrap();
            std::hint::black_box(&buffer);
        });
        let (mut positions, mut values) = (Vec::new(), Vec::new());
        let copy = best_of(runs, || {
            positions.clear();
            positions.extend_from_slice(&step.positions);
            values.clear();
            for a in &step.attributes {
                values.extend_from_slice(&a.values);
            }
            std::hint::black_box((&positions, &values));
        });
        println!(
            "| {} | {} | {:.1} | {:.2} | {:.2} | {:.2} | {:.1}x | {:.1}x |",
            file.display(),
            step.len(),
            buffer.len() as f64 / 1048576.0,
            1e3 * read,
            1e3 * page_cache,
            1e3 * copy,
            read / page_cache,
            read / copy
        );
    }
}
