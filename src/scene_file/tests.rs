use super::*;

#[test]
fn parses_a_full_scene_and_resolves_paths() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("s.toml");
    std::fs::write(
        &path,
        r#"
[data]
path = "d/x.particles"
step = 3
attribute = "velocity"
attribute_range = [0.0, 2.0]
[field]
radius = "1.5%"
radius_map = [[0.0, 0.5], [1.0, 1.0]]
density_map = "ramp"
colormap = "maps/m.json"
classification = "pre"
cluster = 8
"#,
    )
    .unwrap();
    let s = SceneFile::load(&path).unwrap();
    assert_eq!(s.data.path.unwrap(), dir.path().join("d/x.particles"));
    assert_eq!(s.data.step, Some(3));
    assert_eq!(s.field.radius, Some(RadiusSpec::PercentOfDiagonal(1.5)));
    assert_eq!(
        s.field.radius_map.unwrap().to_map().unwrap().eval(0.5),
        0.75
    );
    assert_eq!(
        s.field.density_map.unwrap().to_map().unwrap().eval(0.25),
        0.25
    );
    assert!(s.field.colormap.unwrap().ends_with("maps/m.json"));
    assert_eq!(s.field.classification, Some(Classification::Pre));
    assert_eq!(s.field.cluster.unwrap().get(), 8);
}

#[test]
fn ranges_read_as_pairs_or_words_and_write_back_the_same() {
    for (text, spec) in [
        ("[-13800.0, 22800.0]", RangeSpec::Fixed(-13800.0, 22800.0)),
        ("\"series\"", RangeSpec::Series),
        ("\"robust\"", RangeSpec::Robust),
        ("\"step\"", RangeSpec::Step),
        ("\"robust-step\"", RangeSpec::RobustStep),
    ] {
        let file: SceneFile =
            toml::from_str(&format!("[data]\nattribute_range = {text}\n")).unwrap();
        assert_eq!(file.data.attribute_range, Some(spec), "{text}");
        let again: SceneFile = toml::from_str(&toml::to_string(&file).unwrap()).unwrap();
        assert_eq!(again, file);
        assert_eq!(spec.to_string().parse::<RangeSpec>().unwrap(), spec);
    }
    // 17 digits survive the round trip.
    let tight: RangeSpec = "0.10000000000000001,0.29999999999999999".parse().unwrap();
    assert_eq!(tight, RangeSpec::Fixed(0.1, 0.3));
    assert_eq!(tight.to_string().parse::<RangeSpec>().unwrap(), tight);
    for bad in ["\"widest\"", "[2.0, 1.0]", "\"1,nan\""] {
        let e = toml::from_str::<SceneFile>(&format!("[data]\nattribute_range = {bad}\n"));
        assert!(e.is_err(), "{bad}");
    }
}

#[test]
fn unknown_fields_and_bad_values_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("s.toml");
    std::fs::write(&path, "[field]\nradus = 1.0\n").unwrap();
    let e = SceneFile::load(&path).unwrap_err().to_string();
    assert!(e.contains("radus") && e.contains("s.toml"), "{e}");
    std::fs::write(&path, "[field]\ncluster = 3\n").unwrap();
    let e = SceneFile::load(&path).unwrap_err().to_string();
    assert!(e.contains("cluster size 3"), "{e}");
    std::fs::write(&path, "[field]\nradius = \"-2%\"\n").unwrap();
    assert!(SceneFile::load(&path).is_err());
}
