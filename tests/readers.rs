//! Readers against files written the way other tools write them, and every bad-input case
//! with the text of its error.

use std::io::Write;
use std::path::{Path, PathBuf};

use aarbf::io::{self, AttributeSelection, Format, StepRef};
use aarbf::scene::{OpenOptions, TimeSeries};
use aarbf::values::{Attribute, Step};
use base64::Engine;
use glam::DVec3;

fn b64(bytes: &[u8]) -> String {
    base64::engine::general_purpose::STANDARD.encode(bytes)
}

fn f32_bytes(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

fn read(path: &Path) -> Result<Step, io::DataError> {
    let steps = io::list_steps(path, None)?;
    io::read_step(&steps[0], &AttributeSelection::All)
}

fn err_text(path: &Path) -> String {
    read(path).expect_err("the read should fail").to_string()
}

const POINTS: [f32; 9] = [0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.5, 7.0, -8.0];
const MASS: [f32; 3] = [10.0, 20.0, 30.0];
const VEL: [f32; 9] = [1.0, 2.0, 2.0, 0.0, 0.0, 0.0, 3.0, 4.0, 0.0];

fn check_three_points(step: &Step) {
    assert_eq!(
        step.positions,
        vec![
            DVec3::new(0.0, 1.0, 2.0),
            DVec3::new(3.0, 4.0, 5.0),
            DVec3::new(6.5, 7.0, -8.0)
        ]
    );
    assert_eq!(step.attribute("mass").unwrap().values, MASS.map(f64::from));
}

fn check_velocity(step: &Step) {
    assert_eq!(
        step.attribute("velocity_x").unwrap().values,
        [1.0, 0.0, 3.0]
    );
    assert_eq!(
        step.attribute("velocity_magnitude").unwrap().values,
        [3.0, 0.0, 5.0]
    );
}

/// A VTK XML poly data file; `arrays` renders each DataArray (Points first, then mass,
/// velocity) given (name, components, values).
fn vtp(
    dir: &Path,
    name: &str,
    header_attrs: &str,
    arrays: [String; 3],
    appended: Option<Vec<u8>>,
) -> PathBuf {
    let mut text = format!(
        r#"<?xml version="1.0"?>
<VTKFile type="PolyData" version="1.0" byte_order="LittleEndian" {header_attrs}>
  <PolyData>
    <Piece NumberOfPoints="3" NumberOfVerts="0" NumberOfLines="0" NumberOfStrips="0" NumberOfPolys="0">
      <PointData Scalars="mass">
        {}
        {}
      </PointData>
      <Points>
        {}
      </Points>
    </Piece>
  </PolyData>
"#,
        arrays[1], arrays[2], arrays[0]
    )
    .into_bytes();
    if let Some(data) = appended {
        text.extend_from_slice(b"  <AppendedData encoding=\"raw\">\n   _");
        text.extend_from_slice(&data);
        text.extend_from_slice(b"\n  </AppendedData>\n");
    }
    text.extend_from_slice(b"</VTKFile>\n");
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

const ARRAYS: [(&str, usize, &[f32]); 3] = [
    ("Points", 3, &POINTS),
    ("mass", 1, &MASS),
    ("velocity", 3, &VEL),
];

#[test]
fn vtk_xml_in_every_encoding() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let tag = |name: &str, comps: usize, rest: &str| {
        format!(r#"<DataArray type="Float32" Name="{name}" NumberOfComponents="{comps}" {rest}"#)
    };

    // ascii
    let ascii = ARRAYS.map(|(n, c, v)| {
        let values: Vec<String> = v.iter().map(|x| x.to_string()).collect();
        format!(
            "{} format=\"ascii\">{}</DataArray>",
            tag(n, c, ""),
            values.join(" ")
        )
    });
    // inline binary: base64 of (UInt32 byte count + data)
    let binary = ARRAYS.map(|(n, c, v)| {
        let data = f32_bytes(v);
        let mut block = (data.len() as u32).to_le_bytes().to_vec();
        block.extend(data);
        format!(
            "{} format=\"binary\">{}</DataArray>",
            tag(n, c, ""),
            b64(&block)
        )
    });
    // inline binary with UInt64 headers
    let binary64 = ARRAYS.map(|(n, c, v)| {
        let data = f32_bytes(v);
        let mut block = (data.len() as u64).to_le_bytes().to_vec();
        block.extend(data);
        format!(
            "{} format=\"binary\">{}</DataArray>",
            tag(n, c, ""),
            b64(&block)
        )
    });
    // zlib-compressed binary: base64(header [nblocks, blocksize, lastsize, compsize]) then
    // base64(compressed data), as vtkZLibDataCompressor writes it.
    let zlib = ARRAYS.map(|(n, c, v)| {
        let data = f32_bytes(v);
        let mut enc = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
        enc.write_all(&data).unwrap();
        let compressed = enc.finish().unwrap();
        let header: Vec<u8> = [
            1u32,
            data.len() as u32,
            data.len() as u32,
            compressed.len() as u32,
        ]
        .iter()
        .flat_map(|x| x.to_le_bytes())
        .collect();
        format!(
            "{} format=\"binary\">{}{}</DataArray>",
            tag(n, c, ""),
            b64(&header),
            b64(&compressed)
        )
    });
    // appended raw: each array is (UInt32 byte count + data) at its offset
    let mut appended = Vec::new();
    let mut offsets = Vec::new();
    for (_, _, v) in ARRAYS {
        offsets.push(appended.len());
        let data = f32_bytes(v);
        appended.extend((data.len() as u32).to_le_bytes());
        appended.extend(data);
    }
    let raw: Vec<String> = ARRAYS
        .iter()
        .zip(&offsets)
        .map(|((n, c, _), o)| format!("{}format=\"appended\" offset=\"{o}\"/>", tag(n, *c, "")))
        .collect();
    let raw: [String; 3] = raw.try_into().unwrap();

    // appended raw, zlib-compressed (ParaView's default for .vtp): per array the header
    // [nblocks, blocksize, lastsize, compsize] then the compressed block.
    let mut appended_z = Vec::new();
    let mut offsets_z = Vec::new();
    for (_, _, v) in ARRAYS {
        offsets_z.push(appended_z.len());
        let data = f32_bytes(v);
        let mut enc = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
        enc.write_all(&data).unwrap();
        let compressed = enc.finish().unwrap();
        for x in [
            1u64,
            data.len() as u64,
            data.len() as u64,
            compressed.len() as u64,
        ] {
            appended_z.extend(x.to_le_bytes());
        }
        appended_z.extend(compressed);
    }
    let raw_z: Vec<String> = ARRAYS
        .iter()
        .zip(&offsets_z)
        .map(|((n, c, _), o)| format!("{}format=\"appended\" offset=\"{o}\"/>", tag(n, *c, "")))
        .collect();
    let raw_z: [String; 3] = raw_z.try_into().unwrap();

    let files = [
        vtp(
            d,
            "appended_zlib.vtp",
            r#"header_type="UInt64" compressor="vtkZLibDataCompressor""#,
            raw_z,
            Some(appended_z),
        ),
        vtp(d, "ascii.vtp", "", ascii, None),
        vtp(d, "binary.vtp", r#"header_type="UInt32""#, binary, None),
        vtp(d, "binary64.vtp", r#"header_type="UInt64""#, binary64, None),
        vtp(
            d,
            "zlib.vtp",
            r#"header_type="UInt32" compressor="vtkZLibDataCompressor""#,
            zlib,
            None,
        ),
        vtp(
            d,
            "appended.vtp",
            r#"header_type="UInt32""#,
            raw,
            Some(appended),
        ),
    ];
    for f in &files {
        let step = read(f).unwrap_or_else(|e| panic!("{}: {e}", f.display()));
        check_three_points(&step);
        check_velocity(&step);
    }
}

#[test]
fn vtk_unstructured_grid_and_vtp_writer_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("grid.vtu");
    std::fs::write(
        &path,
        r#"<?xml version="1.0"?>
<VTKFile type="UnstructuredGrid" version="1.0" byte_order="LittleEndian" header_type="UInt32">
  <UnstructuredGrid>
    <Piece NumberOfPoints="3" NumberOfCells="0">
      <PointData><DataArray type="Float64" Name="mass" format="ascii">10 20 30</DataArray></PointData>
      <Points><DataArray type="Float64" NumberOfComponents="3" format="ascii">0 1 2 3 4 5 6.5 7 -8</DataArray></Points>
      <Cells>
        <DataArray type="Int64" Name="connectivity" format="ascii"></DataArray>
        <DataArray type="Int64" Name="offsets" format="ascii"></DataArray>
        <DataArray type="UInt8" Name="types" format="ascii"></DataArray>
      </Cells>
    </Piece>
  </UnstructuredGrid>
</VTKFile>
"#,
    )
    .unwrap();
    check_three_points(&read(&path).unwrap());

    let step = Step {
        name: "s".into(),
        positions: vec![
            DVec3::new(0.0, 1.0, 2.0),
            DVec3::new(3.0, 4.0, 5.0),
            DVec3::new(6.5, 7.0, -8.0),
        ],
        attributes: vec![Attribute {
            name: "mass".into(),
            values: MASS.map(f64::from).to_vec(),
        }],
    };
    let out = dir.path().join("written.vtp");
    io::vtk::write_vtp(&out, &step).unwrap();
    check_three_points(&read(&out).unwrap());
}

#[test]
fn legacy_vtk_ascii_and_binary() {
    let dir = tempfile::tempdir().unwrap();
    let ascii = dir.path().join("a.vtk");
    std::fs::write(
        &ascii,
        "# vtk DataFile Version 3.0\nparticles\nASCII\nDATASET POLYDATA\nPOINTS 3 float\n0 1 2 3 4 5 6.5 7 -8\n\
         POINT_DATA 3\nSCALARS mass float 1\nLOOKUP_TABLE default\n10 20 30\nVECTORS velocity float\n1 2 2 0 0 0 3 4 0\n",
    )
    .unwrap();
    let step = read(&ascii).unwrap();
    check_three_points(&step);
    check_velocity(&step);

    // Legacy binary data is big-endian.
    let be = |v: &[f32]| -> Vec<u8> { v.iter().flat_map(|x| x.to_be_bytes()).collect() };
    let mut bytes =
        b"# vtk DataFile Version 3.0\nparticles\nBINARY\nDATASET POLYDATA\nPOINTS 3 float\n"
            .to_vec();
    bytes.extend(be(&POINTS));
    bytes.extend(b"\nPOINT_DATA 3\nSCALARS mass float 1\nLOOKUP_TABLE default\n");
    bytes.extend(be(&MASS));
    bytes.extend(b"\n");
    let binary = dir.path().join("b.vtk");
    std::fs::write(&binary, bytes).unwrap();
    check_three_points(&read(&binary).unwrap());

    // A count far beyond the file is refused before anything is allocated for it.
    let huge = dir.path().join("huge.vtk");
    std::fs::write(
        &huge,
        "# vtk DataFile Version 3.0\nx\nBINARY\nDATASET POLYDATA\nPOINTS 4000000000 float\n",
    )
    .unwrap();
    let e = err_text(&huge);
    assert!(
        e.contains("huge.vtk")
            && e.contains("VTK point count 4000000000 is larger than the file can hold"),
        "{e}"
    );
}

#[test]
fn csv_with_header_paraview_columns_and_errors() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("p.csv");
    std::fs::write(
        &path,
        "# exported\nx,y,z,mass,label\n0,1,2,10,a\n3,4,5,20,b\n6.5,7,-8,30,c\n",
    )
    .unwrap();
    let step = read(&path).unwrap();
    check_three_points(&step);
    assert!(
        step.attribute("label").is_none(),
        "text columns are not attributes"
    );

    let pv = dir.path().join("pv.csv");
    std::fs::write(
        &pv,
        "\"mass\",\"Points:0\",\"Points:1\",\"Points:2\"\n10,0,1,2\n20,3,4,5\n30,6.5,7,-8\n",
    )
    .unwrap();
    check_three_points(&read(&pv).unwrap());

    let bad = dir.path().join("bad.csv");
    std::fs::write(&bad, "x,y,z,mass\n0,1,2,10\n3,oops,5,20\n").unwrap();
    let e = err_text(&bad);
    assert!(
        e.contains("bad.csv")
            && e.contains("line 3")
            && e.contains("'y'")
            && e.contains("'oops' is not a number"),
        "{e}"
    );

    let nopos = dir.path().join("nopos.csv");
    std::fs::write(&nopos, "a,b,c\n1,2,3\n").unwrap();
    let e = err_text(&nopos);
    assert!(
        e.contains("wrong dimensionality") && e.contains("x, y, z"),
        "{e}"
    );

    let ragged = dir.path().join("ragged.csv");
    std::fs::write(&ragged, "x,y,z\n1,2,3\n1,2\n").unwrap();
    let e = err_text(&ragged);
    assert!(
        e.contains("ragged.csv") && e.contains("2 fields but the header has 3"),
        "{e}"
    );
}

fn ply_header(format: &str, extra: &str) -> String {
    format!(
        "ply\nformat {format} 1.0\ncomment made by a scanner\nelement vertex 3\nproperty float x\nproperty float y\n\
         property float z\nproperty double mass\nproperty list uchar int ignored\n{extra}end_header\n"
    )
}

#[test]
fn ply_ascii_and_binary_both_endians() {
    let dir = tempfile::tempdir().unwrap();
    let ascii = dir.path().join("a.ply");
    std::fs::write(
        &ascii,
        ply_header(
            "ascii",
            "element face 1\nproperty list uchar int vertex_indices\n",
        ) + "0 1 2 10 0\n3 4 5 20 2 7 8\n6.5 7 -8 30 1 9\n3 0 1 2\n",
    )
    .unwrap();
    check_three_points(&read(&ascii).unwrap());

    for (format, big) in [("binary_little_endian", false), ("binary_big_endian", true)] {
        let mut bytes = ply_header(format, "").into_bytes();
        for i in 0..3 {
            for v in &POINTS[i * 3..i * 3 + 3] {
                bytes.extend(if big {
                    v.to_be_bytes()
                } else {
                    v.to_le_bytes()
                });
            }
            let m = MASS[i] as f64;
            bytes.extend(if big {
                m.to_be_bytes()
            } else {
                m.to_le_bytes()
            });
            bytes.push(1); // list of one int
            bytes.extend(if big {
                5i32.to_be_bytes()
            } else {
                5i32.to_le_bytes()
            });
        }
        let path = dir.path().join(format!("{format}.ply"));
        std::fs::write(&path, &bytes).unwrap();
        check_three_points(&read(&path).unwrap());

        // Cut short: the error says which row.
        let cut = dir.path().join(format!("cut_{format}.ply"));
        std::fs::write(&cut, &bytes[..bytes.len() - 6]).unwrap();
        let e = err_text(&cut);
        assert!(e.contains("truncated") && e.contains("row 2"), "{e}");
    }

    let huge = dir.path().join("huge.ply");
    std::fs::write(&huge, "ply\nformat binary_little_endian 1.0\nelement vertex 999999999999\nproperty float x\nproperty float y\nproperty float z\nend_header\n").unwrap();
    let e = err_text(&huge);
    assert!(
        e.contains("count 999999999999 is larger than the file can hold"),
        "{e}"
    );
}

#[test]
fn raw_and_npy() {
    let dir = tempfile::tempdir().unwrap();
    let raw = dir.path().join("k.raw");
    let mut bytes = Vec::new();
    for i in 0..3 {
        bytes.extend(f32_bytes(&POINTS[i * 3..i * 3 + 3]));
        bytes.extend(MASS[i].to_le_bytes());
    }
    std::fs::write(&raw, &bytes).unwrap();
    let step = read(&raw).unwrap();
    assert_eq!(step.positions[2], DVec3::new(6.5, 7.0, -8.0));
    assert_eq!(step.attribute("w").unwrap().values, MASS.map(f64::from));
    std::fs::write(&raw, &bytes[..bytes.len() - 3]).unwrap();
    let e = err_text(&raw);
    assert!(e.contains("k.raw") && e.contains("truncated"), "{e}");

    // float64 and float32, C order
    let npy = dir.path().join("p.npy");
    let data: Vec<f64> = (0..3)
        .flat_map(|i| {
            [
                POINTS[i * 3] as f64,
                POINTS[i * 3 + 1] as f64,
                POINTS[i * 3 + 2] as f64,
                MASS[i] as f64,
            ]
        })
        .collect();
    io::npy::write_matrix(&npy, 3, 4, &data).unwrap();
    let step = read(&npy).unwrap();
    assert_eq!(step.positions[1], DVec3::new(3.0, 4.0, 5.0));
    assert_eq!(step.attribute("col3").unwrap().values, MASS.map(f64::from));
    let data32: Vec<f32> = data.iter().map(|&x| x as f32).collect();
    io::npy::write_matrix(&npy, 3, 4, &data32).unwrap();
    assert_eq!(
        read(&npy).unwrap().attribute("col3").unwrap().values,
        MASS.map(f64::from)
    );

    // Fortran order, as numpy.asfortranarray writes it: a hand-made header.
    let mut header = "{'descr': '<f8', 'fortran_order': True, 'shape': (3, 4), }".to_string();
    while !(10 + header.len() + 1).is_multiple_of(64) {
        header.push(' ');
    }
    header.push('\n');
    let mut f = b"\x93NUMPY\x01\x00".to_vec();
    f.extend((header.len() as u16).to_le_bytes());
    f.extend(header.as_bytes());
    for c in 0..4 {
        for r in 0..3 {
            f.extend(data[r * 4 + c].to_le_bytes());
        }
    }
    std::fs::write(&npy, &f).unwrap();
    let step = read(&npy).unwrap();
    assert_eq!(step.positions[2], DVec3::new(6.5, 7.0, -8.0));
    assert_eq!(step.attribute("col3").unwrap().values, MASS.map(f64::from));

    // wrong dimensionality
    io::npy::write_matrix(&npy, 3, 2, &[0.0; 6]).unwrap();
    let e = err_text(&npy);
    assert!(
        e.contains("wrong dimensionality")
            && e.contains("at least 3 columns")
            && e.contains("found 2"),
        "{e}"
    );
    // a shape the file cannot hold
    let mut header =
        "{'descr': '<f8', 'fortran_order': False, 'shape': (100000000000, 4), }".to_string();
    while !(10 + header.len() + 1).is_multiple_of(64) {
        header.push(' ');
    }
    header.push('\n');
    let mut f = b"\x93NUMPY\x01\x00".to_vec();
    f.extend((header.len() as u16).to_le_bytes());
    f.extend(header.as_bytes());
    f.extend([0u8; 64]);
    std::fs::write(&npy, &f).unwrap();
    let e = err_text(&npy);
    assert!(
        e.contains("array element count 400000000000 is larger than the file can hold"),
        "{e}"
    );
}

fn write_particles_step(path: &Path, count: u64, records: &[[f32; 4]]) {
    let mut b = count.to_le_bytes().to_vec();
    for r in records {
        b.extend(f32_bytes(r));
    }
    std::fs::write(path, b).unwrap();
}

#[test]
fn particles_format_and_its_bad_inputs() {
    let dir = tempfile::tempdir().unwrap();
    let header = dir.path().join("run.particles");
    std::fs::write(&header, "10\n2\n\n").unwrap();
    write_particles_step(
        &dir.path().join("run.particles_10"),
        2,
        &[[0.0, 0.0, 0.0, 1.0], [1.0, 1.0, 1.0, 2.0]],
    );
    write_particles_step(
        &dir.path().join("run.particles_2"),
        1,
        &[[0.5, 0.5, 0.5, 3.0]],
    );
    let steps = io::list_steps(&header, None).unwrap();
    assert_eq!(
        steps.iter().map(|s| s.name.as_str()).collect::<Vec<_>>(),
        ["10", "2"],
        "header order is kept"
    );
    let s = io::read_step(&steps[0], &AttributeSelection::All).unwrap();
    assert_eq!(s.len(), 2);
    assert_eq!(s.attribute("attribute").unwrap().values, [1.0, 2.0]);

    let step = |name: &str| StepRef {
        path: io::particles::step_path(&header, name),
        format: Format::Particles,
        name: name.into(),
        read: io::ReadOptions::default(),
        time: None,
    };
    let read_named = |name: &str| {
        io::read_step(&step(name), &AttributeSelection::All)
            .unwrap_err()
            .to_string()
    };

    // truncated: fewer bytes than the count needs
    write_particles_step(
        &dir.path().join("run.particles_t"),
        3,
        &[[0.0; 4], [0.0; 4]],
    );
    let e = read_named("t");
    assert!(
        e.contains("run.particles_t")
            && e.contains("step 't'")
            && e.contains(
                "particle count 3 is larger than the file can hold (32 bytes allow at most 2)"
            ),
        "{e}"
    );
    // a count far larger than the file: refused before allocating
    write_particles_step(&dir.path().join("run.particles_huge"), u64::MAX / 2, &[]);
    let e = read_named("huge");
    assert!(
        e.contains("step 'huge'") && e.contains("larger than the file can hold"),
        "{e}"
    );
    // shorter than the count itself
    std::fs::write(dir.path().join("run.particles_short"), [1u8, 2, 3]).unwrap();
    let e = read_named("short");
    assert!(
        e.contains("truncated") && e.contains("u64 particle count"),
        "{e}"
    );
    // empty step
    write_particles_step(&dir.path().join("run.particles_e"), 0, &[]);
    let e = read_named("e");
    assert!(
        e.contains("step 'e'") && e.contains("step holds no particles"),
        "{e}"
    );
    // missing step file
    let e = read_named("missing");
    assert!(
        e.contains("run.particles_missing") && e.contains("cannot read"),
        "{e}"
    );
    // NaN/Inf positions: dropped, not passed on
    write_particles_step(
        &dir.path().join("run.particles_nan"),
        4,
        &[
            [f32::NAN, 0.0, 0.0, 1.0],
            [0.0, f32::INFINITY, 0.0, 1.0],
            [0.0, 0.0, 0.0, f32::NAN],
            [1.0, 2.0, 3.0, 4.0],
        ],
    );
    let s = io::read_step(&step("nan"), &AttributeSelection::All).unwrap();
    assert_eq!(s.positions, vec![DVec3::new(1.0, 2.0, 3.0)]);
    assert_eq!(s.attribute("attribute").unwrap().values, [4.0]);
    write_particles_step(
        &dir.path().join("run.particles_allnan"),
        1,
        &[[f32::NAN, 0.0, 0.0, 1.0]],
    );
    let e = read_named("allnan");
    assert!(
        e.contains("all 1 particles were dropped (1 with NaN/Inf positions)"),
        "{e}"
    );
    // missing attribute
    let e = io::read_step(
        &step("10"),
        &AttributeSelection::Only(vec!["density".into()]),
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("step '10'")
            && e.contains("attribute 'density' not found; the data has: 'attribute'"),
        "{e}"
    );
    // header that is not text / lists nothing
    let bad_header = dir.path().join("bad.particles");
    std::fs::write(&bad_header, [0xffu8, 0xfe, 0x00]).unwrap();
    let e = err_text(&bad_header);
    assert!(
        e.contains("bad.particles") && e.contains("not UTF-8"),
        "{e}"
    );
    std::fs::write(&bad_header, "\n\n").unwrap();
    assert!(err_text(&bad_header).contains("lists no steps"));
}

#[test]
fn unknown_and_mixed_formats() {
    let dir = tempfile::tempdir().unwrap();
    let odd = dir.path().join("data.xyz");
    std::fs::write(&odd, "1 2 3").unwrap();
    let e = err_text(&odd);
    assert!(
        e.contains("data.xyz") && e.contains("unknown format") && e.contains("--format"),
        "{e}"
    );
    // --format makes an unknown extension readable
    let steps = io::list_steps(&odd, Some(Format::Raw)).unwrap();
    assert_eq!(steps[0].format, Format::Raw);
    assert!(
        "nonsense"
            .parse::<Format>()
            .unwrap_err()
            .contains("known: particles, vtk-xml")
    );

    std::fs::write(dir.path().join("a.csv"), "x,y,z\n1,2,3\n").unwrap();
    std::fs::write(dir.path().join("b.ply"), "ply\n").unwrap();
    let e = io::list_steps(dir.path(), None).unwrap_err().to_string();
    assert!(e.contains("mixes formats"), "{e}");
    assert_eq!(
        io::list_steps(dir.path(), Some(Format::Csv)).unwrap().len(),
        1
    );
    let empty = tempfile::tempdir().unwrap();
    let e = io::list_steps(empty.path(), None).unwrap_err().to_string();
    assert!(e.contains("no particle files here"), "{e}");
}

fn one_particle_csv(dir: &Path, name: &str, x: f32) {
    std::fs::write(dir.join(name), format!("x,y,z,s\n{x},0,0,{x}\n")).unwrap();
}

#[test]
fn series_from_a_directory_or_glob_sort_naturally_and_load_lazily() {
    let dir = tempfile::tempdir().unwrap();
    for (name, x) in [
        ("step10.csv", 10.0),
        ("step2.csv", 2.0),
        ("step1.csv", 1.0),
        ("notes.txt", 0.0),
    ] {
        one_particle_csv(dir.path(), name, x);
    }
    let names = |p: &Path| {
        io::list_steps(p, None)
            .unwrap()
            .into_iter()
            .map(|s| s.name)
            .collect::<Vec<_>>()
    };
    assert_eq!(names(dir.path()), ["step1", "step2", "step10"]);
    assert_eq!(names(&dir.path().join("step1*.csv")), ["step1", "step10"]);

    let series = TimeSeries::open(
        dir.path(),
        &OpenOptions {
            cache_bytes: 1,
            ..OpenOptions::default()
        },
    )
    .unwrap();
    assert_eq!(series.len(), 3);
    assert_eq!(series.bounds().max.x, 10.0);
    let s = series.attribute("s").unwrap();
    assert_eq!((s.min, s.max), (1.0, 10.0));
    assert!(
        series.cached_bytes() <= 2 * 16,
        "the cache holds at most one step beyond its bound"
    );
    assert_eq!(series.step(1).unwrap().positions[0].x, 2.0);
    assert_eq!(series.step(2).unwrap().positions[0].x, 10.0);
    let e = series.step(3).unwrap_err().to_string();
    assert!(e.contains("step 3 does not exist"), "{e}");

    // A later step that lacks the first step's attribute is named.
    std::fs::write(dir.path().join("step11.csv"), "x,y,z,t\n1,0,0,1\n").unwrap();
    let e = TimeSeries::open(dir.path(), &OpenOptions::default())
        .err()
        .unwrap()
        .to_string();
    assert!(
        e.contains("step11.csv") && e.contains("attribute 's' not found"),
        "{e}"
    );
}

/// Every writer's file reads back as written: bit for bit in the formats that hold doubles
/// (VTK Float64, CSV's shortest round-trip text, PLY double, NumPy f64), to f32 in the two
/// whose format is f32 (`.particles`, `.raw`).
#[test]
fn every_writer_reads_back() {
    let steps = aarbf::scene::synth::Generator::DambreakDemo.generate(300, 2, 7);
    for format in [
        Format::Particles,
        Format::VtkXml,
        Format::Csv,
        Format::Ply,
        Format::Raw,
        Format::Npy,
    ] {
        let dir = tempfile::tempdir().unwrap();
        let path = io::write_series(dir.path(), "db", &steps, format, "velocity").unwrap();
        let series = TimeSeries::open(&path, &OpenOptions::default())
            .unwrap_or_else(|e| panic!("{format}: {e}"));
        assert_eq!(series.len(), 2, "{format}");
        let back = series.step(1).unwrap();
        let f32_format = matches!(format, Format::Particles | Format::Raw);
        let stored = |v: f64| if f32_format { f64::from(v as f32) } else { v };
        let positions: Vec<DVec3> = steps[1]
            .positions
            .iter()
            .map(|p| DVec3::from_array(p.to_array().map(stored)))
            .collect();
        assert_eq!(back.positions, positions, "{format}");
        let velocity = back
            .attribute("velocity")
            .or(back.attribute("attribute"))
            .or(back.attribute("w"))
            .or(back.attribute("col3"))
            .unwrap();
        let expected: Vec<f64> = steps[1]
            .attribute("velocity")
            .unwrap()
            .values
            .iter()
            .map(|&v| stored(v))
            .collect();
        assert_eq!(velocity.values, expected, "{format}");
    }
}

/// A read of some attributes decodes only those, and gives them exactly as a read of all:
/// in every format that holds several; a missing one is named with everything the file holds,
/// decoded or not; and a column that is not selected is not looked at (a text cell in it is
/// no error).
#[test]
fn a_selection_decodes_only_its_attributes_and_names_the_rest() {
    let steps = aarbf::scene::synth::Generator::DambreakDemo.generate(211, 1, 4);
    for (format, second) in [
        (Format::VtkXml, "neighbours"),
        (Format::Csv, "neighbours"),
        (Format::Ply, "neighbours"),
        (Format::Npy, "col4"),
    ] {
        let dir = tempfile::tempdir().unwrap();
        let path = io::write_series(dir.path(), "db", &steps, format, "velocity").unwrap();
        let refs = io::list_steps(&path, None).unwrap();
        let all = io::read_step(&refs[0], &AttributeSelection::All).unwrap();
        assert!(all.attributes.len() >= 2, "{format}");
        let only = AttributeSelection::Only(vec![second.to_owned()]);
        let some = io::read_step(&refs[0], &only).unwrap();
        assert_eq!(some.positions, all.positions, "{format}");
        assert_eq!(some.attributes.len(), 1, "{format}");
        assert_eq!(
            Some(&some.attributes[0]),
            all.attribute(second),
            "{format}: the selected attribute as a full read gives it"
        );
        let e = io::read_step(&refs[0], &AttributeSelection::Only(vec!["nope".into()]))
            .unwrap_err()
            .to_string();
        for a in &all.attributes {
            assert!(e.contains(&format!("'{}'", a.name)), "{format}: {e}");
        }
    }

    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("labels.csv");
    std::fs::write(&csv, "x,y,z,s,note\n0,0,0,1,2\n1,0,0,2,3\n2,0,0,3,n/a\n").unwrap();
    let refs = io::list_steps(&csv, None).unwrap();
    let s = io::read_step(&refs[0], &AttributeSelection::Only(vec!["s".into()])).unwrap();
    assert_eq!(s.attributes[0].values, [1.0, 2.0, 3.0]);
    let e = io::read_step(&refs[0], &AttributeSelection::All)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("line 4, column 'note': 'n/a' is not a number"),
        "{e}"
    );
}

/// A `.vtu` as VTK's XML writer lays it out by default (what ParaView's "Save Data" writes):
/// raw appended data, `header_type="UInt64"`, zlib in blocks (here 64 bytes, so arrays span
/// several), Float64 points, pieces of 5, 7 and 0 points, cell arrays and field data beside
/// the point data. `garbage` names a point-data array whose compressed bytes are not zlib.
fn vtu_as_vtk_writes_it(
    dir: &Path,
    name: &str,
    big_endian: bool,
    compressed: bool,
    garbage: &str,
) -> PathBuf {
    struct Arr {
        name: &'static str,
        ty: &'static str,
        comps: usize,
        bytes: Vec<u8>,
    }
    let e8 = |v: f64| {
        if big_endian {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        }
    };
    let int = |v: u64| -> Vec<u8> {
        if big_endian {
            v.to_be_bytes().to_vec()
        } else {
            v.to_le_bytes().to_vec()
        }
    };
    let mut appended = Vec::new();
    let mut xml = format!(
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"{}\" header_type=\"UInt64\"{}>\n  <UnstructuredGrid>\n    <FieldData>\n",
        if big_endian {
            "BigEndian"
        } else {
            "LittleEndian"
        },
        if compressed {
            " compressor=\"vtkZLibDataCompressor\""
        } else {
            ""
        }
    );
    let put = |arr: &Arr, appended: &mut Vec<u8>, corrupt: bool| -> String {
        let offset = appended.len();
        if compressed {
            let blocks: Vec<&[u8]> = arr.bytes.chunks(64).collect();
            let mut packed = Vec::new();
            for b in &blocks {
                let mut enc =
                    flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
                enc.write_all(b).unwrap();
                let mut z = enc.finish().unwrap();
                if corrupt {
                    z.iter_mut().for_each(|x| *x = 0xA5);
                }
                packed.push(z);
            }
            appended.extend(int(blocks.len() as u64));
            appended.extend(int(64));
            // The last block's size, 0 when it is full (VTK's convention).
            appended.extend(int(blocks.last().map_or(0, |b| b.len() % 64) as u64));
            for z in &packed {
                appended.extend(int(z.len() as u64));
            }
            for z in packed {
                appended.extend(z);
            }
        } else {
            appended.extend(int(arr.bytes.len() as u64));
            appended.extend(&arr.bytes);
        }
        format!(
            "<DataArray type=\"{}\" Name=\"{}\" NumberOfComponents=\"{}\" format=\"appended\" RangeMin=\"0\" RangeMax=\"1\" offset=\"{offset}\"/>\n",
            arr.ty, arr.name, arr.comps
        )
    };
    xml += &put(
        &Arr {
            name: "TimeValue",
            ty: "Float64",
            comps: 1,
            bytes: e8(0.25).to_vec(),
        },
        &mut appended,
        false,
    );
    xml += "    </FieldData>\n";
    for (piece, n) in [(0usize, 5usize), (1, 7), (2, 0)] {
        xml += &format!(
            "    <Piece NumberOfPoints=\"{n}\" NumberOfCells=\"{n}\">\n      <PointData Scalars=\"density\">\n"
        );
        let ids: Vec<usize> = (0..n).map(|i| 100 * piece + i).collect();
        let density: Vec<u8> = ids
            .iter()
            .flat_map(|&i| e8(1.0 / 3.0 + i as f64 * 1e-9))
            .collect();
        let id64: Vec<u8> = ids
            .iter()
            .flat_map(|&i| int(i as u64 * 1_000_000_007))
            .collect();
        let kind: Vec<u8> = ids.iter().map(|&i| (i % 3) as u8).collect();
        let velocity: Vec<u8> = ids
            .iter()
            .flat_map(|&i| [i as f32, -(i as f32), 0.5])
            .flat_map(|v| {
                if big_endian {
                    v.to_be_bytes()
                } else {
                    v.to_le_bytes()
                }
            })
            .collect();
        for (arr, corrupt) in [
            (
                Arr {
                    name: "density",
                    ty: "Float64",
                    comps: 1,
                    bytes: density,
                },
                false,
            ),
            (
                Arr {
                    name: "id",
                    ty: "Int64",
                    comps: 1,
                    bytes: id64,
                },
                false,
            ),
            (
                Arr {
                    name: "type",
                    ty: "UInt8",
                    comps: 1,
                    bytes: kind,
                },
                false,
            ),
            (
                Arr {
                    name: "velocity",
                    ty: "Float32",
                    comps: 3,
                    bytes: velocity.clone(),
                },
                false,
            ),
            (
                Arr {
                    name: "pressure",
                    ty: "Float32",
                    comps: 1,
                    bytes: velocity[..4 * n].to_vec(),
                },
                garbage == "pressure",
            ),
            // 64 bytes a point: compressed, every block (of 64 bytes) is full.
            (
                Arr {
                    name: "tensor",
                    ty: "Float32",
                    comps: 16,
                    bytes: ids
                        .iter()
                        .flat_map(|&i| (0..16).map(move |c| (i * 16 + c) as f32))
                        .flat_map(|v| {
                            if big_endian {
                                v.to_be_bytes()
                            } else {
                                v.to_le_bytes()
                            }
                        })
                        .collect(),
                },
                false,
            ),
        ] {
            xml += &put(&arr, &mut appended, corrupt);
        }
        xml += "      </PointData>\n      <CellData>\n";
        xml += &put(
            &Arr {
                name: "cell_id",
                ty: "Int32",
                comps: 1,
                bytes: (0..n as u32)
                    .flat_map(|i| {
                        if big_endian {
                            i.to_be_bytes()
                        } else {
                            i.to_le_bytes()
                        }
                    })
                    .collect(),
            },
            &mut appended,
            false,
        );
        xml += "      </CellData>\n      <Points>\n";
        let points: Vec<u8> = ids
            .iter()
            .flat_map(|&i| [1.0e6 + 0.1 * i as f64, -2.5e5 + 1.0 / 7.0, 1e-3 * i as f64])
            .flat_map(e8)
            .collect();
        xml += &put(
            &Arr {
                name: "Points",
                ty: "Float64",
                comps: 3,
                bytes: points,
            },
            &mut appended,
            false,
        );
        xml += "      </Points>\n      <Cells>\n";
        xml += &put(
            &Arr {
                name: "connectivity",
                ty: "Int64",
                comps: 1,
                bytes: (0..n as u64).flat_map(int).collect(),
            },
            &mut appended,
            false,
        );
        xml += "      </Cells>\n    </Piece>\n";
    }
    xml += "  </UnstructuredGrid>\n  <AppendedData encoding=\"raw\">\n   _";
    let mut bytes = xml.into_bytes();
    bytes.extend(appended);
    bytes.extend(b"\n  </AppendedData>\n</VTKFile>\n");
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    path
}

#[test]
fn vtk_appended_data_is_read_by_offset_and_only_as_selected() {
    let dir = tempfile::tempdir().unwrap();
    let ids: Vec<usize> = (0..5).chain(100..107).collect();
    for (big_endian, compressed) in [(false, true), (true, true), (false, false), (true, false)] {
        let path = vtu_as_vtk_writes_it(dir.path(), "grid.vtu", big_endian, compressed, "");
        let what = format!("big endian {big_endian}, zlib {compressed}");
        let step = read(&path).unwrap_or_else(|e| panic!("{what}: {e}"));
        // Every digit of the Float64 points and of the Float64 and Int64 arrays survives.
        let want: Vec<DVec3> = ids
            .iter()
            .map(|&i| DVec3::new(1.0e6 + 0.1 * i as f64, -2.5e5 + 1.0 / 7.0, 1e-3 * i as f64))
            .collect();
        assert_eq!(step.positions, want, "{what}");
        let density: Vec<f64> = ids.iter().map(|&i| 1.0 / 3.0 + i as f64 * 1e-9).collect();
        assert_eq!(step.attribute("density").unwrap().values, density, "{what}");
        let id: Vec<f64> = ids
            .iter()
            .map(|&i| (i as u64 * 1_000_000_007) as f64)
            .collect();
        assert_eq!(step.attribute("id").unwrap().values, id, "{what}");
        let kind: Vec<f64> = ids.iter().map(|&i| (i % 3) as f64).collect();
        assert_eq!(step.attribute("type").unwrap().values, kind, "{what}");
        let vy: Vec<f64> = ids.iter().map(|&i| -(i as f64)).collect();
        assert_eq!(step.attribute("velocity_y").unwrap().values, vy, "{what}");
        let t15: Vec<f64> = ids.iter().map(|&i| (i * 16 + 15) as f64).collect();
        assert_eq!(step.attribute("tensor_15").unwrap().values, t15, "{what}");
        // Cell and field arrays are not particles' attributes.
        assert!(step.attribute("cell_id").is_none() && step.attribute("TimeValue").is_none());
    }
    // An array whose bytes are not zlib is never read unless asked for.
    // A header longer than one read of the file (here a 100 KB comment) is found across reads.
    let path = vtu_as_vtk_writes_it(dir.path(), "bad_pressure.vtu", false, true, "pressure");
    let text = std::fs::read(&path).unwrap();
    let first_line = text.iter().position(|&b| b == b'\n').unwrap() + 1;
    let mut padded = text[..first_line].to_vec();
    padded.extend(format!("<!-- {} -->\n", "x".repeat(100_000)).into_bytes());
    padded.extend(&text[first_line..]);
    std::fs::write(&path, padded).unwrap();
    let refs = io::list_steps(&path, None).unwrap();
    let only = AttributeSelection::Only(vec!["density".into()]);
    let step = io::read_step(&refs[0], &only).unwrap();
    assert_eq!(step.attributes.len(), 1);
    assert_eq!(step.positions.len(), 12);
    let e = err_text(&path);
    assert!(
        e.contains("bad_pressure.vtu")
            && e.contains("array 'pressure' block 0")
            && e.contains("inflate"),
        "{e}"
    );
    // A file cut short names the array that lies past its end.
    let whole = std::fs::read(dir.path().join("grid.vtu")).unwrap();
    let cut = dir.path().join("cut.vtu");
    let appended = whole
        .windows(13)
        .position(|w| w == b"<AppendedData")
        .unwrap();
    std::fs::write(&cut, &whole[..appended + (whole.len() - appended) / 2]).unwrap();
    let e = err_text(&cut);
    assert!(
        e.contains("cut.vtu") && e.contains("past the end of the file"),
        "{e}"
    );
}

/// A file VTK itself wrote (tests/data/write_vtk_fixture.py: vtkXMLUnstructuredGridWriter at its
/// defaults, base64 appended zlib data in several blocks), read by offset to the last digit.
#[test]
fn a_vtu_written_by_vtk_reads_to_the_last_digit() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/vtk_written.vtu");
    let step = read(&path).unwrap();
    let n = 4100;
    let want: Vec<DVec3> = (0..n)
        .map(|i| DVec3::new(1.0e6 + 0.1 * i as f64, -2.5e5 + 1.0 / 7.0, 1e-3 * i as f64))
        .collect();
    assert_eq!(step.positions, want);
    let density: Vec<f64> = (0..n).map(|i| 1.0 / 3.0 + i as f64 * 1e-9).collect();
    assert_eq!(step.attribute("density").unwrap().values, density);
    let id: Vec<f64> = (0..n).map(|i| (i as u64 * 1_000_000_007) as f64).collect();
    assert_eq!(step.attribute("id").unwrap().values, id);
    let kind: Vec<f64> = (0..n).map(|i| (i % 3) as f64).collect();
    assert_eq!(step.attribute("kind").unwrap().values, kind);
    let vy: Vec<f64> = (0..n).map(|i| -(i as f64)).collect();
    assert_eq!(step.attribute("velocity_y").unwrap().values, vy);
    assert!(step.attribute("cell_id").is_none() && step.attribute("TimeValue").is_none());
    // One attribute asked for: the others are named, not decoded.
    let refs = io::list_steps(&path, None).unwrap();
    let only = io::read_step(&refs[0], &AttributeSelection::Only(vec!["kind".into()])).unwrap();
    assert_eq!(only.attributes.len(), 1);
    assert_eq!(only.positions, want);
}

/// Files NumPy wrote (tests/data/write_numpy_fixtures.py): a big-endian Fortran-order float64
/// array, an int64 array and a big-endian binary PLY from a structured array, each read to the
/// last bit against the same values as 17-digit text, reading only the arrays asked for.
#[test]
fn numpy_written_files_read_exactly() {
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data");
    let text = read(&data.join("numpy_particles.csv")).unwrap();
    assert_eq!(text.len(), 1001);
    let column = |name: &str| text.attribute(name).unwrap().values.clone();

    let npy = io::list_steps(&data.join("numpy_fortran_be.npy"), None).unwrap();
    let step = io::read_step(&npy[0], &AttributeSelection::Only(vec!["col4".into()])).unwrap();
    assert_eq!(step.positions, text.positions);
    assert_eq!(
        step.attribute("col4").unwrap().values,
        column("temperature")
    );
    assert!(step.attribute("col3").is_none(), "col3 was not asked for");
    let all = io::read_step(&npy[0], &AttributeSelection::All).unwrap();
    assert_eq!(all.attribute("col3").unwrap().values, column("density"));
    let m = io::npy::read_matrix(io::At::new(&data.join("numpy_fortran_be.npy"), None)).unwrap();
    assert_eq!((m.rows, m.cols), (1001, 5));
    assert_eq!(m.row(1000)[4], column("temperature")[1000]);

    let ints = read(&data.join("numpy_int64.npy")).unwrap();
    assert_eq!(ints.positions[6], DVec3::new(24.0, 25.0, 26.0) * 1000003.0);
    assert_eq!(ints.attribute("col3").unwrap().values[6], 27.0 * 1000003.0);

    let ply = io::list_steps(&data.join("numpy_struct_be.ply"), None).unwrap();
    let step = io::read_step(&ply[0], &AttributeSelection::Only(vec!["density".into()])).unwrap();
    assert_eq!(step.positions, text.positions);
    assert_eq!(
        step.attribute("density").unwrap().values,
        column("density32")
    );
    assert!(step.attribute("id").is_none());
    let all = io::read_step(&ply[0], &AttributeSelection::All).unwrap();
    assert_eq!(all.attribute("flag").unwrap().values, column("flag"));
    assert_eq!(all.attribute("id").unwrap().values, column("id"));

    // Cut inside the last row: the error names the file, the count and what the file holds.
    let dir = tempfile::tempdir().unwrap();
    let bytes = std::fs::read(data.join("numpy_struct_be.ply")).unwrap();
    let cut = dir.path().join("cut.ply");
    std::fs::write(&cut, &bytes[..bytes.len() - 5]).unwrap();
    let e = err_text(&cut);
    assert!(
        e.contains("cut.ply") && e.contains("count 1001") && e.contains("at most 1000"),
        "{e}"
    );
    // An element type NumPy has but particles cannot be (complex): named in the error.
    let mut npy = std::fs::read(data.join("numpy_int64.npy")).unwrap();
    let at = npy.windows(3).position(|w| w == b"<i8").unwrap();
    npy[at..at + 3].copy_from_slice(b"<c8");
    let complex = dir.path().join("complex.npy");
    std::fs::write(&complex, &npy).unwrap();
    let e = err_text(&complex);
    assert!(e.contains("complex.npy") && e.contains("<c8"), "{e}");
}
