//! The device check (`scripts/device-check.sh`), the one command run on a lent GPU machine,
//! end to end here on lavapipe at its smallest size, so the script cannot rot between the
//! rare days a GPU is lent: every stage runs and succeeds, and what comes back has the real
//! run's shape (at most 8 files, the report with each part).

use std::path::Path;
use std::process::Command;

#[test]
fn the_device_check_runs_every_stage_and_writes_its_report() {
    let out = tempfile::tempdir().unwrap();
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let status = Command::new("bash")
        .arg(root.join("scripts/device-check.sh"))
        .arg("--smoke")
        .arg(out.path())
        .env("AARBF", env!("CARGO_BIN_EXE_aarbf"))
        .env("XDG_RUNTIME_DIR", std::env::temp_dir())
        .status()
        .expect("bash runs");
    let log = std::fs::read_to_string(out.path().join("log.txt")).unwrap_or_default();
    assert!(status.success(), "the script failed:\n{log}");

    let files: Vec<String> = std::fs::read_dir(out.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert!(files.len() <= 8, "{files:?}");
    for expected in [
        "report.md",
        "stages.csv",
        "devices.txt",
        "field-agreement.md",
        "results.tar.gz",
        "traversal.png",
    ] {
        assert!(
            files.iter().any(|f| f == expected),
            "{expected} in {files:?}"
        );
    }
    let stages = std::fs::read_to_string(out.path().join("stages.csv")).unwrap();
    let rows: Vec<&str> = stages.lines().skip(1).collect();
    assert_eq!(rows.len(), 13, "{stages}");
    assert!(rows.iter().all(|r| r.contains(",ok,")), "{stages}\n{log}");

    // The field agrees across the backends within what auto precision promises.
    let agreement = std::fs::read_to_string(out.path().join("field-agreement.md")).unwrap();
    let verdicts: Vec<&str> = agreement.lines().filter(|l| l.starts_with("| ")).collect();
    assert_eq!(verdicts.len(), 3, "{agreement}");
    assert!(
        verdicts[1..]
            .iter()
            .all(|l| l.trim_end().ends_with("| yes |")),
        "{agreement}"
    );
    let report = std::fs::read_to_string(out.path().join("report.md")).unwrap();
    for section in [
        "## Stage times",
        "## Field agreement",
        "traversal",
        "baselines",
        "## Playback",
    ] {
        assert!(report.contains(section), "no '{section}' in the report");
    }
}
