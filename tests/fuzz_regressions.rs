//! Every input a fuzzer ever found trouble with (tests/fuzz_regressions/<target>/*), and the
//! seed corpus, read again: each must give a step or an error naming the problem, never a
//! panic, and never an allocation the input does not justify (what `-malloc_limit_mb` checks
//! under the fuzzer: here a counting allocator records the largest single request).

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

use aarbf::io::{Format, pvd, read_bytes};

/// The system allocator, remembering the largest allocation since the last reset.
struct Largest;

static LARGEST: AtomicUsize = AtomicUsize::new(0);

// SAFETY: forwards to the system allocator unchanged.
unsafe impl GlobalAlloc for Largest {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        LARGEST.fetch_max(layout.size(), Ordering::Relaxed);
        // SAFETY: the caller's contract, passed on.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: as above.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        LARGEST.fetch_max(layout.size(), Ordering::Relaxed);
        // SAFETY: as above.
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        LARGEST.fetch_max(new_size, Ordering::Relaxed);
        // SAFETY: as above.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static ALLOCATOR: Largest = Largest;

/// The most one read may allocate at once for an input of `len` bytes: a fixed allowance for
/// buffers and tables, plus what decoding the input could honestly need (text numbers become
/// f32 columns; compressed VTK arrays inflate, up to the reader's MAX_INFLATION of 4096).
fn allowance(format: Format, len: usize) -> usize {
    let per_byte = if format == Format::VtkXml { 4096 } else { 256 };
    (16 << 20) + per_byte * len
}

/// What a target reads: a particle format, or a `.pvd` collection's text.
#[derive(Clone, Copy, PartialEq)]
enum Input {
    Particles(Format),
    Collection,
}

impl Input {
    fn of(target: &str) -> Option<Input> {
        match target {
            "read_pvd" => Some(Input::Collection),
            _ => format_of(target).map(Input::Particles),
        }
    }

    /// Reads `data`: the particles read, or the entries listed, or the error's text.
    fn read(self, data: &[u8]) -> Result<usize, String> {
        match self {
            Input::Particles(format) => read_bytes(format, data)
                .map(|s| s.len())
                .map_err(|e| e.to_string()),
            Input::Collection => pvd::parse(data).map(|e| e.len()),
        }
    }

    fn allowance(self, len: usize) -> usize {
        match self {
            Input::Particles(format) => allowance(format, len),
            // Entries hold the input's own strings.
            Input::Collection => (16 << 20) + 256 * len,
        }
    }
}

fn format_of(target: &str) -> Option<Format> {
    Some(match target {
        "read_particles" => Format::Particles,
        "read_vtk_xml" => Format::VtkXml,
        "read_vtk_legacy" => Format::Vtk,
        "read_csv" => Format::Csv,
        "read_ply" => Format::Ply,
        "read_raw" => Format::Raw,
        "read_npy" => Format::Npy,
        _ => return None,
    })
}

#[test]
fn fuzz_findings_and_seeds_never_panic() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut checked = 0;
    for base in [root.join("tests/fuzz_regressions"), root.join("fuzz/seeds")] {
        let Ok(targets) = std::fs::read_dir(&base) else {
            continue;
        };
        for target in targets.flatten() {
            let name = target.file_name().to_string_lossy().into_owned();
            let input = Input::of(&name).unwrap_or_else(|| {
                panic!("{}: unknown fuzz target directory", target.path().display())
            });
            for file in std::fs::read_dir(target.path()).unwrap().flatten() {
                let data = std::fs::read(file.path()).unwrap();
                LARGEST.store(0, Ordering::Relaxed);
                let started = std::time::Instant::now();
                let result = std::panic::catch_unwind(|| input.read(&data));
                // Not a performance check: a bound far above any honest read of a small file
                // (the fuzzer's -timeout is 10 s), so a pathological parse or a loop fails.
                assert!(
                    started.elapsed().as_secs() < 5,
                    "{}: reading took {:.1} s",
                    file.path().display(),
                    started.elapsed().as_secs_f64()
                );
                let largest = LARGEST.load(Ordering::Relaxed);
                assert!(
                    largest <= input.allowance(data.len()),
                    "{}: one allocation of {largest} bytes for a {}-byte input",
                    file.path().display(),
                    data.len()
                );
                match result {
                    Ok(Ok(_)) => {}
                    Ok(Err(e)) => assert!(!e.to_string().is_empty()),
                    Err(_) => panic!("{}: the reader panicked", file.path().display()),
                }
                checked += 1;
            }
        }
    }
    assert!(
        checked > 0,
        "the seed corpus (fuzz/seeds) should not be empty"
    );
}

/// The file VTK itself wrote (tests/data/vtk_written.vtu: base64 appended zlib blocks, read by
/// offset), damaged 400 ways (bytes changed in its XML header and in its data, digits changed
/// in its offsets and sizes, the file cut short): every read gives a step or an error, never a
/// panic, and allocates no more than the input justifies.
#[test]
fn a_damaged_vtk_written_file_never_panics_or_over_allocates() {
    use rand::{Rng, SeedableRng};
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let original = std::fs::read(root.join("tests/data/vtk_written.vtu")).unwrap();
    let header_end = original
        .windows(13)
        .position(|w| w == b"<AppendedData")
        .unwrap();
    let mut rng = rand_pcg::Pcg64::seed_from_u64(7);
    let (mut ok, mut errors) = (0, 0);
    for round in 0..400 {
        let mut data = original.clone();
        match round % 4 {
            // A byte of the XML header.
            0 => {
                let i = rng.random_range(0..header_end);
                data[i] = rng.random();
            }
            // A digit of the header (offsets, counts, components) made another digit.
            1 => {
                let digits: Vec<usize> = (0..header_end)
                    .filter(|&i| data[i].is_ascii_digit())
                    .collect();
                let i = digits[rng.random_range(0..digits.len())];
                data[i] = b'0' + rng.random_range(0..10u8);
            }
            // A few bytes of the appended data.
            2 => {
                for _ in 0..rng.random_range(1..8) {
                    let i = rng.random_range(header_end..data.len());
                    data[i] = rng.random();
                }
            }
            // Cut short.
            _ => data.truncate(rng.random_range(0..data.len())),
        }
        LARGEST.store(0, Ordering::Relaxed);
        let result =
            std::panic::catch_unwind(|| read_bytes(Format::VtkXml, &data).map(|s| s.len()));
        let largest = LARGEST.load(Ordering::Relaxed);
        assert!(
            largest <= allowance(Format::VtkXml, data.len()),
            "round {round}: one allocation of {largest} bytes for a {}-byte input",
            data.len()
        );
        match result {
            Ok(Ok(_)) => ok += 1,
            Ok(Err(e)) => {
                assert!(!e.to_string().is_empty());
                errors += 1;
            }
            Err(_) => panic!("round {round}: the reader panicked"),
        }
    }
    eprintln!("damaged VTK-written file: {ok} of 400 read, {errors} refused");
    // Both outcomes occur (a changed digit of a RangeMin is harmless; a cut file is not).
    assert!(ok > 0 && errors > 0, "{ok} read, {errors} refused");
}
