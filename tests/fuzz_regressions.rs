//! Every input a fuzzer ever found trouble with (tests/fuzz_regressions/<target>/*), and the
//! seed corpus, read again: each must give a step or an error naming the problem, never a panic.

use aarbf::io::{Format, read_bytes};

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
            let format = format_of(&name).unwrap_or_else(|| {
                panic!("{}: unknown fuzz target directory", target.path().display())
            });
            for file in std::fs::read_dir(target.path()).unwrap().flatten() {
                let data = std::fs::read(file.path()).unwrap();
                let result =
                    std::panic::catch_unwind(|| read_bytes(format, &data).map(|s| s.len()));
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
