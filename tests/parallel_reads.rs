//! Each rank of a distributed render reads its part of a step (`io::read_step_part`, issue 49):
//! on files as NumPy, h5py, GADGET-style writers and text writers make them, for P = 1..9 and
//! 16 ranks, the parts put together in rank order are the whole step's records, and each part
//! decoded no more than its share: exactly its records `[rN/P, (r+1)N/P)` for fixed-size
//! records, HDF5, VTK XML appended and inline data (of a compressed array, the blocks that hold
//! them; of ascii values, its own, those before them counted), legacy VTK, binary PLY with
//! lists and ascii PLY meshes (vertices followed by faces) or with lists; for CSV and ascii PLY
//! ending in its vertex rows of scalars the records whose first byte lies in its share of the
//! body's bytes, at most `ceil(N/P · longest row / shortest row) + 1`. Formats read whole
//! decode N records on every rank, and say so.

use std::path::Path;

use aarbf::io::{self, AttributeSelection, Part, ReadOptions, StepRef};
use aarbf::values::{Attribute, Step};
use glam::DVec3;

use crate::common;

const RANKS: [usize; 10] = [1, 2, 3, 4, 5, 6, 7, 8, 9, 16];

/// How many records a part may decode.
#[derive(Clone, Copy, Debug)]
enum Bound {
    /// Exactly its own records.
    Exact,
    /// Records by bytes: at most ceil(N/P · longest / shortest record) + 1.
    Bytes { longest: usize, shortest: usize },
}

fn only(names: &[&str]) -> AttributeSelection {
    AttributeSelection::Only(names.iter().map(|n| n.to_string()).collect())
}

fn the_step(path: &Path) -> StepRef {
    let mut steps = io::list_steps(path, None).unwrap();
    assert_eq!(steps.len(), 1, "{}", path.display());
    steps.remove(0)
}

/// The records of `parts`, one after another.
fn joined(parts: &[Step], like: &Step) -> Step {
    Step {
        name: like.name.clone(),
        positions: parts.iter().flat_map(|p| p.positions.clone()).collect(),
        attributes: like
            .attributes
            .iter()
            .enumerate()
            .map(|(k, a)| Attribute {
                name: a.name.clone(),
                values: parts
                    .iter()
                    .flat_map(|p| {
                        assert_eq!(p.attributes[k].name, a.name);
                        p.attributes[k].values.clone()
                    })
                    .collect(),
            })
            .collect(),
    }
}

/// Every part count of [`RANKS`]: the parts joined are `io::read_step`'s step, bit for bit,
/// and each decoded what `bound` allows. `records`: the records the file holds (N, before
/// non-finite ones are dropped).
fn check_parts(step: &StepRef, selection: &AttributeSelection, records: usize, bound: Bound) {
    let whole = io::read_step(step, selection).unwrap();
    for ranks in RANKS {
        let mut parts = Vec::new();
        let mut decoded = 0;
        for rank in 0..ranks {
            let part = io::read_step_part(step, selection, Part::new(rank, ranks))
                .unwrap_or_else(|e| panic!("{}: rank {rank} of {ranks}: {e}", step.name));
            let share = Part::new(rank, ranks).range(records).len();
            let limit = match bound {
                Bound::Exact => share,
                Bound::Bytes { longest, shortest } => {
                    (records * longest).div_ceil(ranks * shortest) + 1
                }
            };
            match bound {
                Bound::Exact => assert_eq!(part.decoded, share, "{} {rank}/{ranks}", step.name),
                Bound::Bytes { .. } => assert!(
                    part.decoded <= limit,
                    "{}: rank {rank} of {ranks} decoded {} records, more than {limit}",
                    step.name,
                    part.decoded
                ),
            }
            assert!(part.step.len() <= part.decoded.min(limit));
            decoded += part.decoded;
            parts.push(part.step);
        }
        assert_eq!(decoded, records, "{}: {ranks} ranks", step.name);
        let together = joined(&parts, &whole);
        assert_eq!(together.positions, whole.positions, "{} {ranks}", step.name);
        assert_eq!(
            together.attributes, whole.attributes,
            "{} {ranks}",
            step.name
        );
    }
}

fn data(name: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(name)
}

/// Row lengths of a text file's body (the lines after its first), newline included.
fn row_lengths(path: &Path) -> (usize, usize) {
    let text = std::fs::read_to_string(path).unwrap();
    let lengths: Vec<usize> = text
        .split_inclusive('\n')
        .skip(1)
        .filter(|l| !l.trim().is_empty())
        .map(str::len)
        .collect();
    (
        *lengths.iter().max().unwrap(),
        *lengths.iter().min().unwrap(),
    )
}

#[test]
fn numpy_arrays_are_read_by_row_ranges_in_either_order() {
    // Fortran order, big-endian float64, 1001 x 5 (numpy.save of numpy.asfortranarray).
    let fortran = the_step(&data("numpy_fortran_be.npy"));
    check_parts(&fortran, &AttributeSelection::All, 1001, Bound::Exact);
    check_parts(&fortran, &only(&["col4"]), 1001, Bound::Exact);
    // int64, 7 x 4: fewer rows than ranks, so some parts are empty.
    let small = the_step(&data("numpy_int64.npy"));
    check_parts(&small, &AttributeSelection::All, 7, Bound::Exact);
    let empty = io::read_step_part(&small, &AttributeSelection::All, Part::new(0, 16)).unwrap();
    assert_eq!((empty.step.len(), empty.decoded), (0, 0));
    assert_eq!(empty.step.attributes[0].name, "col3");
    // C order with non-finite rows (numpy.save's layout): dropped within each part as in the
    // whole step.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("c_order.npy");
    let n = 1003;
    let mut values = Vec::new();
    for i in 0..n {
        let x = i as f64 * 0.1 + 1.0 / 3.0;
        let bad = if i % 97 == 5 { f64::NAN } else { 1.0 };
        let inf = if i % 211 == 7 { f64::INFINITY } else { 2.0 };
        values.extend([x, bad * x.sin(), -x, x * x, inf]);
    }
    common::write_numpy(&path, n, 5, &values);
    let c = the_step(&path);
    check_parts(&c, &AttributeSelection::All, n, Bound::Exact);
    check_parts(&c, &only(&["col3"]), n, Bound::Exact);
}

#[test]
fn binary_records_are_read_by_byte_ranges() {
    let dir = tempfile::tempdir().unwrap();
    let n = 1009;
    let step = Step {
        name: "s".into(),
        positions: (0..n)
            .map(|i| DVec3::new(i as f64 * 0.25, 1.0 - i as f64, 0.5))
            .collect(),
        attributes: vec![Attribute {
            name: "rho".into(),
            values: (0..n)
                .map(|i| if i == 500 { f32::NAN as f64 } else { i as f64 })
                .collect(),
        }],
    };
    let raw = dir.path().join("knoll.raw");
    io::raw::write_step(&raw, &step, "rho").unwrap();
    check_parts(&the_step(&raw), &AttributeSelection::All, n, Bound::Exact);
    let header = dir.path().join("run.particles");
    io::particles::write_series(&header, std::slice::from_ref(&step), "rho").unwrap();
    check_parts(
        &the_step(&header),
        &AttributeSelection::All,
        n,
        Bound::Exact,
    );
    // Binary big-endian PLY of scalar properties from a NumPy structured array.
    let ply = the_step(&data("numpy_struct_be.ply"));
    check_parts(&ply, &AttributeSelection::All, 1001, Bound::Exact);
    check_parts(&ply, &only(&["id"]), 1001, Bound::Exact);
}

#[test]
fn csv_is_read_by_byte_ranges_moved_to_line_starts() {
    // 17-digit text from NumPy's repr, 1001 rows.
    let path = data("numpy_particles.csv");
    let (longest, shortest) = row_lengths(&path);
    let bound = Bound::Bytes { longest, shortest };
    check_parts(&the_step(&path), &AttributeSelection::All, 1001, bound);
    check_parts(&the_step(&path), &only(&["temperature"]), 1001, bound);

    // Comments and blank lines, CRLF line ends, a missing value (NaN, dropped), a label
    // column (not numeric in the first record: not an attribute), fewer rows than ranks.
    let dir = tempfile::tempdir().unwrap();
    let mut text = String::from("# written by a script\r\nlabel,x,y,z,rho\r\n");
    for i in 0..11 {
        let rho = if i == 4 {
            String::new()
        } else {
            format!("{}", 0.1 * i as f64)
        };
        text.push_str(&format!(
            "p{i},{:.17e},{},-{i}.5,{rho}\r\n",
            i as f64 / 3.0,
            i * 7
        ));
        if i == 6 {
            text.push_str("# a comment between records\r\n\r\n");
        }
    }
    let odd = dir.path().join("odd.csv");
    std::fs::write(&odd, &text).unwrap();
    let whole = io::read_step(&the_step(&odd), &AttributeSelection::All).unwrap();
    assert_eq!(whole.len(), 10);
    assert_eq!(whole.attribute_names(), ["rho"]);
    // A comment line counts as a record for the byte bound.
    let (longest, shortest) = (row_lengths(&odd).0, 4);
    check_parts(
        &the_step(&odd),
        &AttributeSelection::All,
        11,
        Bound::Bytes { longest, shortest },
    );
}

#[test]
fn a_bad_record_in_a_part_is_named_by_its_byte_offset() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.csv");
    let mut text = String::from("x,y,z\n");
    for i in 0..100 {
        text.push_str(&format!("{i},{i},{i}\n"));
    }
    let at = text.len();
    text.push_str("1,two,3\n");
    std::fs::write(&path, &text).unwrap();
    let step = the_step(&path);
    let err = io::read_step(&step, &AttributeSelection::All)
        .unwrap_err()
        .to_string();
    assert!(err.contains("line 102") && err.contains("'two'"), "{err}");
    let err = io::read_step_part(&step, &AttributeSelection::All, Part::new(1, 2))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("bad.csv") && err.contains(&format!("byte {at}")) && err.contains("'two'"),
        "{err}"
    );
}

#[test]
fn vtk_appended_data_written_by_pysph_and_vtk_is_read_by_rows_of_its_blocks() {
    // PySPH: raw appended, zlib, Float64, 960 points (one block an array).
    let pysph = the_step(&data("sph_runs/pysph_dam_break/fluid_00000.vtp"));
    let n = io::read_step(&pysph, &AttributeSelection::All)
        .unwrap()
        .len();
    assert_eq!(n, 960);
    check_parts(&pysph, &AttributeSelection::All, n, Bound::Exact);
    check_parts(&pysph, &only(&["rho"]), n, Bound::Exact);
    // VTK 9.7's writer: base64 appended, zlib in 32 KiB blocks, 4100 points (every array
    // spans several blocks), Float64, Int64, UInt8 and a 3-component Float32 array.
    let vtk = the_step(&data("vtk_written.vtu"));
    let whole = io::read_step(&vtk, &AttributeSelection::All).unwrap();
    assert_eq!(whole.len(), 4100);
    assert_eq!(
        whole.attribute_names(),
        [
            "density",
            "id",
            "kind",
            "velocity_x",
            "velocity_y",
            "velocity_z",
            "velocity_magnitude"
        ]
    );
    check_parts(&vtk, &AttributeSelection::All, 4100, Bound::Exact);
    check_parts(&vtk, &only(&["velocity_y"]), 4100, Bound::Exact);
    check_parts(&vtk, &only(&["density"]), 4100, Bound::Exact);
}

/// How [`write_appended`] writes a VTK XML file's appended data.
#[derive(Clone, Copy, Debug)]
struct Appended {
    /// Bytes of a size integer: 4 (`UInt32`) or 8 (`UInt64`, pyevtk's).
    header_bytes: usize,
    big_endian: bool,
    /// Base64 text (VTK's `EncodeAppendedData`), else raw bytes after the `_`.
    base64: bool,
    /// Compressed in blocks of this many bytes, else uncompressed.
    zlib_block: Option<usize>,
    /// The compressor of those blocks.
    codec: Codec,
}

/// A particle's position, `rho`, `pressure`, `id` and `velocity`.
type Particle = ([f64; 3], f32, f64, i32, [f32; 3]);

/// The particles [`write_appended`] writes, by their index in the whole step: position, and
/// the values of `rho` (Float32, NaN at 700), `pressure` (Float64), `id` (Int32) and
/// `velocity` (3 x Float32).
fn particle(g: usize) -> Particle {
    let t = g as f64 * 0.37;
    let rho = if g == 700 {
        f32::NAN
    } else {
        g as f32 * 0.5 + 0.1
    };
    (
        [t.sin() * 1e3, t.cos() / 3.0, -(g as f64) * 1e-7],
        rho,
        1.0 / (g as f64 + 3.0),
        g as i32 - 500,
        [g as f32 * 0.1, -(g as f32), 2.5],
    )
}

/// The step [`write_appended`]'s file holds: [`particle`]s `0..n`.
fn particles_step(n: usize) -> Step {
    let all: Vec<_> = (0..n).map(particle).collect();
    let column = |name: &str, f: &dyn Fn(&Particle) -> f64| Attribute {
        name: name.into(),
        values: all.iter().map(f).collect(),
    };
    Step {
        name: "s".into(),
        positions: all.iter().map(|p| DVec3::from_array(p.0)).collect(),
        attributes: vec![
            column("rho", &|p| p.1 as f64),
            column("pressure", &|p| p.2),
            column("id", &|p| p.3 as f64),
            column("velocity_x", &|p| p.4[0] as f64),
            column("velocity_y", &|p| p.4[1] as f64),
            column("velocity_z", &|p| p.4[2] as f64),
            column("velocity_magnitude", &|p| {
                let v = p.4.map(f64::from);
                (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
            }),
        ],
    }
}

/// Writes an unstructured grid of [`particle`]s in pieces of `pieces` points (VTK writes one
/// a rank, empty for idle ranks), byte by byte as pyevtk and VTK's XML writer do: every array
/// appended (points, cells, point data); uncompressed, an array is its size and its bytes;
/// zlib, a header (blocks, block size, last block's size, each block's compressed size) and
/// the blocks; base64, each of those runs encoded on its own. `corrupt`: an array's name and
/// a block of it, in the first piece, whose compressed bytes are replaced by garbage.
/// VTK's compressors: each writes the same header and blocks, each block in its own format.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Codec {
    /// `vtkZLibDataCompressor`: a zlib stream a block.
    Zlib,
    /// `vtkLZ4DataCompressor`: LZ4's raw block format a block (`LZ4_compress_default`).
    Lz4,
    /// `vtkLZMADataCompressor`: an .xz stream a block (`lzma_easy_buffer_encode`, CRC64).
    Lzma,
}

impl Codec {
    /// Its `compressor` attribute.
    fn attribute(self) -> &'static str {
        match self {
            Codec::Zlib => " compressor=\"vtkZLibDataCompressor\"",
            Codec::Lz4 => " compressor=\"vtkLZ4DataCompressor\"",
            Codec::Lzma => " compressor=\"vtkLZMADataCompressor\"",
        }
    }

    /// One block compressed as VTK does.
    fn compress(self, chunk: &[u8]) -> Vec<u8> {
        use std::io::Write;
        match self {
            Codec::Zlib => {
                let mut z =
                    flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
                z.write_all(chunk).unwrap();
                z.finish().unwrap()
            }
            Codec::Lz4 => lz4_flex::block::compress(chunk),
            Codec::Lzma => {
                let mut z = xz2::write::XzEncoder::new(Vec::new(), 6);
                z.write_all(chunk).unwrap();
                z.finish().unwrap()
            }
        }
    }
}

/// `data` as VTK's compressors (and meshio) write it in blocks of `size` bytes: the header
/// (the block count, the block size, the last block's size, full or not, and each block's
/// compressed size, each number written by `int`) and the blocks, each compressed by `codec`,
/// block `corrupt` overwritten with garbage.
fn zlib_blocks(
    data: &[u8],
    size: usize,
    codec: Codec,
    int: &dyn Fn(usize) -> Vec<u8>,
    corrupt: Option<usize>,
) -> (Vec<u8>, Vec<u8>) {
    let mut blocks: Vec<Vec<u8>> = data.chunks(size).map(|c| codec.compress(c)).collect();
    if let Some(block) = corrupt {
        blocks[block].iter_mut().for_each(|b| *b = 0x5a);
    }
    let last = data.len() - blocks.len().saturating_sub(1) * size;
    let mut head = [int(blocks.len()), int(size), int(last)].concat();
    for b in &blocks {
        head.extend(int(b.len()));
    }
    (head, blocks.concat())
}

fn write_appended(path: &Path, pieces: &[usize], how: Appended, corrupt: Option<(&str, usize)>) {
    use base64::Engine;
    let int = |v: usize| -> Vec<u8> {
        let v = v as u64;
        let bytes = if how.big_endian {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        };
        if how.big_endian {
            bytes[8 - how.header_bytes..].to_vec()
        } else {
            bytes[..how.header_bytes].to_vec()
        }
    };
    let mut appended: Vec<u8> = Vec::new();
    let mut xml = String::new();
    let add = |appended: &mut Vec<u8>, name: &str, piece: usize, data: Vec<u8>| -> usize {
        let offset = appended.len();
        let runs: Vec<Vec<u8>> = match how.zlib_block {
            None => vec![[int(data.len()), data].concat()],
            Some(size) => {
                let bad =
                    corrupt.and_then(|(bad, block)| (bad == name && piece == 0).then_some(block));
                let (head, blocks) = zlib_blocks(&data, size, how.codec, &int, bad);
                vec![head, blocks]
            }
        };
        for run in runs {
            if how.base64 {
                let text = base64::engine::general_purpose::STANDARD.encode(&run);
                appended.extend(text.into_bytes());
            } else {
                appended.extend(run);
            }
        }
        offset
    };
    let num = |v: f64, ty: &str| -> Vec<u8> {
        match (ty, how.big_endian) {
            ("Float64", false) => v.to_le_bytes().to_vec(),
            ("Float64", true) => v.to_be_bytes().to_vec(),
            ("Float32", false) => (v as f32).to_le_bytes().to_vec(),
            ("Float32", true) => (v as f32).to_be_bytes().to_vec(),
            ("Int32", false) => (v as i32).to_le_bytes().to_vec(),
            ("Int32", true) => (v as i32).to_be_bytes().to_vec(),
            ("UInt8", _) => vec![v as u8],
            _ => unreachable!(),
        }
    };
    let array = |appended: &mut Vec<u8>,
                 xml: &mut String,
                 piece: usize,
                 name: &str,
                 ty: &str,
                 components: usize,
                 values: Vec<f64>| {
        let data: Vec<u8> = values.iter().flat_map(|&v| num(v, ty)).collect();
        let offset = add(appended, name, piece, data);
        xml.push_str(&format!(
            "        <DataArray type=\"{ty}\" Name=\"{name}\" NumberOfComponents=\"{components}\" \
             format=\"appended\" offset=\"{offset}\"/>\n"
        ));
    };
    let mut first = 0;
    for (piece, &n) in pieces.iter().enumerate() {
        let rows: Vec<_> = (first..first + n).map(particle).collect();
        first += n;
        xml.push_str(&format!(
            "    <Piece NumberOfPoints=\"{n}\" NumberOfCells=\"{n}\">\n      <Points>\n"
        ));
        let points = rows.iter().flat_map(|p| p.0).collect();
        array(
            &mut appended,
            &mut xml,
            piece,
            "points",
            "Float64",
            3,
            points,
        );
        xml.push_str("      </Points>\n      <Cells>\n");
        let cells = (0..n).map(|i| i as f64).collect();
        array(
            &mut appended,
            &mut xml,
            piece,
            "connectivity",
            "Int32",
            1,
            cells,
        );
        let offsets = (1..=n).map(|i| i as f64).collect();
        array(
            &mut appended,
            &mut xml,
            piece,
            "offsets",
            "Int32",
            1,
            offsets,
        );
        array(
            &mut appended,
            &mut xml,
            piece,
            "types",
            "UInt8",
            1,
            vec![1.0; n],
        );
        xml.push_str("      </Cells>\n      <PointData>\n");
        let rho = rows.iter().map(|p| p.1 as f64).collect();
        array(&mut appended, &mut xml, piece, "rho", "Float32", 1, rho);
        let pressure = rows.iter().map(|p| p.2).collect();
        array(
            &mut appended,
            &mut xml,
            piece,
            "pressure",
            "Float64",
            1,
            pressure,
        );
        let id = rows.iter().map(|p| p.3 as f64).collect();
        array(&mut appended, &mut xml, piece, "id", "Int32", 1, id);
        let velocity = rows.iter().flat_map(|p| p.4.map(f64::from)).collect();
        array(
            &mut appended,
            &mut xml,
            piece,
            "velocity",
            "Float32",
            3,
            velocity,
        );
        xml.push_str("      </PointData>\n    </Piece>\n");
    }
    let mut out = format!(
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" \
         byte_order=\"{}\" header_type=\"{}\"{}>\n  <UnstructuredGrid>\n",
        if how.big_endian {
            "BigEndian"
        } else {
            "LittleEndian"
        },
        if how.header_bytes == 8 {
            "UInt64"
        } else {
            "UInt32"
        },
        if how.zlib_block.is_some() {
            how.codec.attribute()
        } else {
            ""
        }
    )
    .into_bytes();
    out.extend(xml.into_bytes());
    out.extend(
        format!(
            "  </UnstructuredGrid>\n  <AppendedData encoding=\"{}\">\n   _",
            if how.base64 { "base64" } else { "raw" }
        )
        .into_bytes(),
    );
    out.extend(appended);
    out.extend(b"\n  </AppendedData>\n</VTKFile>\n");
    std::fs::write(path, out).unwrap();
}

#[test]
fn vtk_appended_data_of_several_pieces_is_read_by_the_rows_of_each_piece() {
    let dir = tempfile::tempdir().unwrap();
    let pieces = [997, 0, 1003];
    let expected = particles_step(2000);
    let plain = Appended {
        header_bytes: 4,
        big_endian: false,
        base64: false,
        zlib_block: None,
        codec: Codec::Zlib,
    };
    // pyevtk's (raw, UInt64 sizes); big-endian; VTK's base64 (each array one run); zlib in
    // blocks of 100 bytes, which split rows of 4, 8 and 12 bytes, raw and base64 (the
    // blocks one run after the header's).
    let kinds = [
        Appended {
            header_bytes: 8,
            ..plain
        },
        Appended {
            big_endian: true,
            ..plain
        },
        Appended {
            base64: true,
            ..plain
        },
        Appended {
            zlib_block: Some(100),
            ..plain
        },
        Appended {
            header_bytes: 8,
            base64: true,
            zlib_block: Some(100),
            ..plain
        },
        // VTK's other compressors, raw and base64.
        Appended {
            zlib_block: Some(100),
            codec: Codec::Lz4,
            ..plain
        },
        Appended {
            header_bytes: 8,
            base64: true,
            zlib_block: Some(100),
            codec: Codec::Lz4,
            ..plain
        },
        Appended {
            zlib_block: Some(100),
            codec: Codec::Lzma,
            ..plain
        },
        Appended {
            base64: true,
            zlib_block: Some(1000),
            codec: Codec::Lzma,
            ..plain
        },
    ];
    for (k, how) in kinds.into_iter().enumerate() {
        let path = dir.path().join(format!("pieces_{k}.vtu"));
        write_appended(&path, &pieces, how, None);
        let step = the_step(&path);
        let whole = io::read_step(&step, &AttributeSelection::All).unwrap();
        // The whole step is what was written (rho's NaN at 700 dropped).
        let kept: Vec<usize> = (0..2000).filter(|&g| g != 700).collect();
        assert_eq!(whole.len(), kept.len(), "{how:?}");
        assert!(
            kept.iter()
                .enumerate()
                .all(|(i, &g)| whole.positions[i] == expected.positions[g]),
            "{how:?}"
        );
        for (a, e) in whole.attributes.iter().zip(&expected.attributes) {
            assert_eq!(a.name, e.name, "{how:?}");
            let e: Vec<f64> = kept.iter().map(|&g| e.values[g]).collect();
            assert_eq!(a.values, e, "{how:?}: {}", a.name);
        }
        assert_eq!(whole.attributes.len(), expected.attributes.len());
        check_parts(&step, &AttributeSelection::All, 2000, Bound::Exact);
        check_parts(&step, &only(&["velocity_z", "id"]), 2000, Bound::Exact);
        check_parts(&step, &only(&["pressure"]), 2000, Bound::Exact);
    }
}

#[test]
fn a_bad_block_or_a_truncated_file_in_a_vtk_part_is_an_error_naming_the_file_and_array() {
    let dir = tempfile::tempdir().unwrap();
    let how = Appended {
        header_bytes: 4,
        big_endian: false,
        base64: false,
        zlib_block: Some(100),
        codec: Codec::Zlib,
    };
    // pressure's block 40 is its bytes 4000..4100: the first piece's rows 500..512; each
    // compressor's corrupt block named by the whole read and the parts that hold it (rank 1
    // of 4 is a later part).
    for codec in [Codec::Zlib, Codec::Lz4, Codec::Lzma] {
        let how = Appended { codec, ..how };
        let name = format!("bad_block_{codec:?}.vtu");
        let path = dir.path().join(&name);
        write_appended(&path, &[997, 1003], how, Some(("pressure", 40)));
        let step = the_step(&path);
        let selection = only(&["pressure"]);
        for err in [
            io::read_step(&step, &selection).unwrap_err(),
            io::read_step_part(&step, &selection, Part::new(0, 2)).unwrap_err(),
            io::read_step_part(&step, &selection, Part::new(1, 4)).unwrap_err(),
        ] {
            let err = err.to_string();
            // The codec named too.
            let codec_name = match codec {
                Codec::Zlib => "zlib",
                Codec::Lz4 => "LZ4",
                Codec::Lzma => "LZMA",
            };
            assert!(
                err.contains(&name)
                    && err.contains("'pressure' block 40")
                    && err.contains(&format!("its {codec_name} data")),
                "{err}"
            );
        }
        // The ranks whose rows lie in other blocks do not inflate that one.
        for (rank, ranks) in [(1, 2), (0, 4), (2, 4)] {
            let part = io::read_step_part(&step, &selection, Part::new(rank, ranks))
                .unwrap_or_else(|e| panic!("rank {rank} of {ranks}: {e}"));
            assert_eq!(part.decoded, Part::new(rank, ranks).range(2000).len());
        }
    }
    // Cut inside the second piece's arrays: every rank refuses (each array is checked to lie
    // in the file), naming the file.
    let good = dir.path().join("good.vtu");
    write_appended(&good, &[997, 1003], how, None);
    let bytes = std::fs::read(&good).unwrap();
    let cut = dir.path().join("cut.vtu");
    std::fs::write(&cut, &bytes[..bytes.len() * 3 / 4]).unwrap();
    let step = the_step(&cut);
    for part in [Part::new(1, 2), Part::new(0, 3)] {
        let err = io::read_step_part(&step, &AttributeSelection::All, part)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("cut.vtu") && err.contains("past the end of the file"),
            "{err}"
        );
    }
}

/// Rewrites [`write_appended`]'s uncompressed file of `pieces` (UInt32 sizes, little-endian)
/// so that each piece's `points` and `pressure` are inline base64 arrays (`format="binary"`,
/// their size and bytes one run), the other arrays still appended: a file mixing both.
fn mix_inline(path: &Path, pieces: &[usize]) {
    use base64::Engine;
    let bytes = std::fs::read(path).unwrap();
    let split = bytes
        .windows(13)
        .position(|w| w == b"<AppendedData")
        .unwrap();
    let mut xml = String::from_utf8(bytes[..split].to_vec()).unwrap();
    let (mut cursor, mut first) = (0, 0);
    for &n in pieces {
        let rows: Vec<_> = (first..first + n).map(particle).collect();
        first += n;
        let points: Vec<f64> = rows.iter().flat_map(|p| p.0).collect();
        let pressure: Vec<f64> = rows.iter().map(|p| p.2).collect();
        for (name, components, values) in [("points", 3, points), ("pressure", 1, pressure)] {
            let at = cursor + xml[cursor..].find(&format!("Name=\"{name}\"")).unwrap();
            let start = xml[..at].rfind("<DataArray").unwrap();
            let end = at + xml[at..].find("/>").unwrap() + 2;
            let data: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
            let run = [(data.len() as u32).to_le_bytes().to_vec(), data].concat();
            let tag = format!(
                "<DataArray type=\"Float64\" Name=\"{name}\" NumberOfComponents=\"{components}\" \
                 format=\"binary\">\n{}\n</DataArray>",
                base64::engine::general_purpose::STANDARD.encode(&run)
            );
            xml.replace_range(start..end, &tag);
            cursor = start + tag.len();
        }
    }
    let mut out = xml.into_bytes();
    out.extend(&bytes[split..]);
    std::fs::write(path, out).unwrap();
}

/// A file mixing inline arrays (the points, `pressure`) with appended ones, raw or base64, in
/// pieces of unequal sizes: a part reads each kind by its rows, and the parts joined are
/// vtkio's whole read bit for bit.
#[test]
fn vtk_xml_mixing_appended_and_inline_arrays_is_read_by_rows() {
    let dir = tempfile::tempdir().unwrap();
    let pieces = [997, 0, 1003];
    for base64 in [false, true] {
        let how = Appended {
            header_bytes: 4,
            big_endian: false,
            base64,
            zlib_block: None,
            codec: Codec::Zlib,
        };
        let path = dir.path().join(format!("mixed_{base64}.vtu"));
        write_appended(&path, &pieces, how, None);
        mix_inline(&path, &pieces);
        let step = the_step(&path);
        let whole = io::read_step(&step, &AttributeSelection::All)
            .unwrap_or_else(|e| panic!("base64 {base64}: {e}"));
        assert_eq!(whole.len(), 1999, "rho's NaN dropped");
        assert_eq!(whole.attribute_names(), particles_step(1).attribute_names());
        check_parts(&step, &AttributeSelection::All, 2000, Bound::Exact);
        check_parts(
            &step,
            &only(&["pressure", "velocity_z"]),
            2000,
            Bound::Exact,
        );
        check_parts(&step, &only(&["id"]), 2000, Bound::Exact);
    }
}

/// Writes [`particle`]s `0..n` as VTK's legacy writer does in binary (big-endian): POINTS
/// double, the cells (`modern`: VTK 5.1's OFFSETS and CONNECTIVITY of int64, else the older
/// one list of int32; `grid`: an unstructured grid's CELLS and CELL_TYPES, else poly data's
/// VERTICES), CELL_DATA, then POINT_DATA with SCALARS float and its LOOKUP_TABLE, VECTORS
/// double and a FIELD of an int and a double array, each block followed by a newline.
/// A legacy file of `write_legacy_binary`'s or `write_legacy_ascii`'s arrays (`whole`, its
/// step read whole): its attributes as vtkio names them, and every selection's parts exact.
fn check_legacy_parts(step: &StepRef, whole: &Step, n: usize) {
    assert_eq!(
        whole.attribute_names(),
        [
            "density",
            "velocity_x",
            "velocity_y",
            "velocity_z",
            "velocity_magnitude",
            "id",
            "pressure"
        ]
    );
    check_parts(step, &AttributeSelection::All, n, Bound::Exact);
    check_parts(step, &only(&["velocity_magnitude"]), n, Bound::Exact);
    check_parts(step, &only(&["pressure", "density"]), n, Bound::Exact);
}

fn write_legacy_binary(path: &Path, n: usize, grid: bool, modern: bool) {
    let rows: Vec<_> = (0..n).map(particle).collect();
    let version = if modern { "5.1" } else { "4.2" };
    let mut out = format!(
        "# vtk DataFile Version {version}\nvtk output\nBINARY\nDATASET {}\nPOINTS {n} double\n",
        if grid {
            "UNSTRUCTURED_GRID"
        } else {
            "POLYDATA"
        }
    )
    .into_bytes();
    let block = |out: &mut Vec<u8>, data: Vec<u8>| {
        out.extend(data);
        out.push(b'\n');
    };
    block(
        &mut out,
        rows.iter()
            .flat_map(|p| p.0)
            .flat_map(f64::to_be_bytes)
            .collect(),
    );
    let cells = if grid { "CELLS" } else { "VERTICES" };
    if modern {
        out.extend(format!("{cells} {} {n}\nOFFSETS vtktypeint64\n", n + 1).into_bytes());
        block(
            &mut out,
            (0..=n as i64).flat_map(i64::to_be_bytes).collect(),
        );
        out.extend(b"CONNECTIVITY vtktypeint64\n");
        block(&mut out, (0..n as i64).flat_map(i64::to_be_bytes).collect());
    } else {
        out.extend(format!("{cells} {n} {}\n", 2 * n).into_bytes());
        block(
            &mut out,
            (0..n as i32)
                .flat_map(|i| [1, i])
                .flat_map(i32::to_be_bytes)
                .collect(),
        );
    }
    if grid {
        out.extend(format!("CELL_TYPES {n}\n").into_bytes());
        block(
            &mut out,
            vec![1i32; n]
                .into_iter()
                .flat_map(i32::to_be_bytes)
                .collect(),
        );
    }
    out.extend(
        format!("CELL_DATA {n}\nSCALARS cell_id int 1\nLOOKUP_TABLE default\n").into_bytes(),
    );
    block(&mut out, (0..n as i32).flat_map(i32::to_be_bytes).collect());
    out.extend(
        format!("POINT_DATA {n}\nSCALARS density float 1\nLOOKUP_TABLE default\n").into_bytes(),
    );
    block(
        &mut out,
        rows.iter().flat_map(|p| p.1.to_be_bytes()).collect(),
    );
    out.extend(b"VECTORS velocity double\n");
    block(
        &mut out,
        rows.iter()
            .flat_map(|p| p.4.map(f64::from))
            .flat_map(f64::to_be_bytes)
            .collect(),
    );
    out.extend(format!("FIELD FieldData 2\nid 1 {n} int\n").into_bytes());
    block(
        &mut out,
        rows.iter().flat_map(|p| p.3.to_be_bytes()).collect(),
    );
    out.extend(format!("pressure 1 {n} double\n").into_bytes());
    block(
        &mut out,
        rows.iter().flat_map(|p| p.2.to_be_bytes()).collect(),
    );
    std::fs::write(path, out).unwrap();
}

/// A part of a legacy binary file is read by offset; the whole step is vtkio's, so the parts
/// joined are checked against vtkio's reading.
#[test]
fn legacy_binary_vtk_is_read_by_the_rows_of_each_block() {
    let dir = tempfile::tempdir().unwrap();
    let n = 1013;
    for (grid, modern) in [(false, false), (true, false), (false, true), (true, true)] {
        let path = dir.path().join(format!("legacy_{grid}_{modern}.vtk"));
        write_legacy_binary(&path, n, grid, modern);
        let step = the_step(&path);
        let whole = io::read_step(&step, &AttributeSelection::All)
            .unwrap_or_else(|e| panic!("grid {grid}, modern {modern}: {e}"));
        assert_eq!(whole.len(), n - 1, "rho's NaN dropped");
        check_legacy_parts(&step, &whole, n);
    }
}

/// What VTK 9 writes after its points and after an array of information keys: a METADATA
/// block of INFORMATION lines, ended by an empty line.
const LEGACY_METADATA: &str = "METADATA\nINFORMATION 2\nNAME L2_NORM_RANGE LOCATION vtkDataArray\n\
     DATA 2 0.865742 1.73177\nNAME L2_NORM_FINITE_RANGE LOCATION vtkDataArray\n\
     DATA 2 0.865742 1.73177\n\n";

/// Writes [`particle`]s `0..n` as VTK's legacy writer does, ascii (9 values a line, doubles of
/// 17 digits) or binary (big-endian): poly data, POINTS double and a METADATA block, VTK 5.1's
/// VERTICES, a CELL_DATA (before POINT_DATA where `cells_first`, else after it) of SCALARS,
/// COLOR_SCALARS and TENSORS, and POINT_DATA of SCALARS float (its LOOKUP_TABLE named, a
/// METADATA block after its values), COLOR_SCALARS of 3 (ascii: floats; binary: unsigned
/// char), TENSORS double, TEXTURE_COORDINATES of 2 float, and a LOOKUP_TABLE `table` of
/// `table_size` colours (4 values each: ascii floats, binary unsigned char). Each block ends
/// with a line end.
fn write_legacy_sections(path: &Path, n: usize, ascii: bool, cells_first: bool, table_size: usize) {
    let rows: Vec<_> = (0..n).map(particle).collect();
    let mut out = format!(
        "# vtk DataFile Version 5.1\nvtk output\n{}\nDATASET POLYDATA\nPOINTS {n} double\n",
        if ascii { "ASCII" } else { "BINARY" }
    )
    .into_bytes();
    // Values of a VTK type: ascii 9 a line, binary big-endian bytes.
    let block = |out: &mut Vec<u8>, ty: &str, values: Vec<f64>| {
        if ascii {
            for (i, v) in values.iter().enumerate() {
                let text = match ty {
                    "double" => format!("{v:.16e}"),
                    "float" => format!("{:?}", *v as f32),
                    _ => format!("{}", *v as i64),
                };
                out.extend(text.into_bytes());
                out.push(if i % 9 == 8 { b'\n' } else { b' ' });
            }
        } else {
            for &v in &values {
                match ty {
                    "double" => out.extend(v.to_be_bytes()),
                    "float" => out.extend((v as f32).to_be_bytes()),
                    "int" => out.extend((v as i32).to_be_bytes()),
                    "vtktypeint64" => out.extend((v as i64).to_be_bytes()),
                    "unsigned_char" => out.push(v as u8),
                    _ => unreachable!(),
                }
            }
        }
        out.push(b'\n');
    };
    // Colours: ascii floats in [0, 1], binary bytes.
    let colour_type = if ascii { "float" } else { "unsigned_char" };
    let colour = |g: usize, c: usize| {
        let byte = ((g * 7 + c * 31) % 256) as f64;
        if ascii { byte / 255.0 } else { byte }
    };
    block(&mut out, "double", rows.iter().flat_map(|p| p.0).collect());
    out.extend(LEGACY_METADATA.as_bytes());
    out.extend(format!("VERTICES {} {n}\nOFFSETS vtktypeint64\n", n + 1).into_bytes());
    block(
        &mut out,
        "vtktypeint64",
        (0..=n).map(|i| i as f64).collect(),
    );
    out.extend(b"CONNECTIVITY vtktypeint64\n");
    block(&mut out, "vtktypeint64", (0..n).map(|i| i as f64).collect());
    let cell_data = |out: &mut Vec<u8>| {
        out.extend(
            format!("CELL_DATA {n}\nSCALARS cell_id int 1\nLOOKUP_TABLE default\n").into_bytes(),
        );
        block(out, "int", (0..n).map(|i| i as f64).collect());
        out.extend(b"COLOR_SCALARS cell_rgba 4\n");
        block(
            out,
            colour_type,
            (0..4 * n).map(|k| colour(k / 4, k % 4)).collect(),
        );
        out.extend(b"TENSORS cell_stress float\n");
        block(out, "float", (0..9 * n).map(|k| k as f64 * 0.25).collect());
    };
    if cells_first {
        cell_data(&mut out);
    }
    out.extend(
        format!("POINT_DATA {n}\nSCALARS density float 1\nLOOKUP_TABLE table\n").into_bytes(),
    );
    // vtkio reads no NaN in ascii: rho's becomes 0.5 there.
    let rho = |p: &Particle| {
        if ascii && p.1.is_nan() {
            0.5
        } else {
            p.1 as f64
        }
    };
    block(&mut out, "float", rows.iter().map(rho).collect());
    out.extend(LEGACY_METADATA.as_bytes());
    out.extend(b"COLOR_SCALARS rgb 3\n");
    block(
        &mut out,
        colour_type,
        (0..3 * n).map(|k| colour(k / 3, k % 3)).collect(),
    );
    out.extend(b"TENSORS stress double\n");
    block(
        &mut out,
        "double",
        (0..9 * n)
            .map(|k| rows[k / 9].2 * (k % 9) as f64 - 1e-3)
            .collect(),
    );
    out.extend(b"TEXTURE_COORDINATES uv 2 float\n");
    block(
        &mut out,
        "float",
        (0..2 * n).map(|k| rows[k / 2].4[k % 2] as f64).collect(),
    );
    out.extend(format!("LOOKUP_TABLE table {table_size}\n").into_bytes());
    block(
        &mut out,
        colour_type,
        (0..4 * table_size).map(|k| colour(k / 4, k % 4)).collect(),
    );
    if !cells_first {
        cell_data(&mut out);
    }
    std::fs::write(path, out).unwrap();
}

/// The attributes of [`write_legacy_sections`]'s point data, as the whole read (vtkio's) names
/// them, the lookup table's where it has a colour a point.
fn legacy_section_names(table: bool) -> Vec<String> {
    let mut names = vec!["density".to_owned()];
    names.extend(["rgb_x", "rgb_y", "rgb_z", "rgb_magnitude"].map(String::from));
    names.extend((0..9).map(|i| format!("stress_{i}")));
    names.extend(["uv_0", "uv_1"].map(String::from));
    if table {
        names.extend((0..4).map(|i| format!("table_{i}")));
    }
    names
}

/// Legacy files of every section VTK writes (COLOR_SCALARS, TENSORS, TEXTURE_COORDINATES, a
/// lookup table, METADATA blocks, CELL_DATA before or after POINT_DATA), ascii and binary, are
/// read by rows: each part decodes exactly its share, and the parts joined are vtkio's whole
/// read bit for bit, with its attributes in its order.
#[test]
fn legacy_vtk_of_every_section_vtk_writes_is_read_by_rows() {
    let dir = tempfile::tempdir().unwrap();
    let n = 1013;
    for ascii in [false, true] {
        for cells_first in [false, true] {
            let path = dir
                .path()
                .join(format!("sections_{ascii}_{cells_first}.vtk"));
            write_legacy_sections(&path, n, ascii, cells_first, n);
            let step = the_step(&path);
            let whole = io::read_step(&step, &AttributeSelection::All)
                .unwrap_or_else(|e| panic!("ascii {ascii}, cells first {cells_first}: {e}"));
            // Binary: rho's NaN dropped.
            assert_eq!(whole.len(), if ascii { n } else { n - 1 });
            assert_eq!(whole.attribute_names(), legacy_section_names(true));
            check_parts(&step, &AttributeSelection::All, n, Bound::Exact);
            check_parts(
                &step,
                &only(&["stress_8", "rgb_magnitude"]),
                n,
                Bound::Exact,
            );
            check_parts(&step, &only(&["uv_1", "table_3"]), n, Bound::Exact);
        }
    }
    // The same sections in a structured grid (DIMENSIONS, no cells).
    for ascii in [false, true] {
        let poly = dir.path().join(format!("poly_{ascii}.vtk"));
        write_legacy_sections(&poly, n, ascii, false, n);
        let bytes = std::fs::read(&poly).unwrap();
        let at = |word: &[u8]| bytes.windows(word.len()).position(|w| w == word).unwrap();
        let mut grid = bytes[..at(b"DATASET")].to_vec();
        grid.extend(format!("DATASET STRUCTURED_GRID\nDIMENSIONS {n} 1 1\n").into_bytes());
        grid.extend(&bytes[at(b"POINTS")..at(b"VERTICES")]);
        grid.extend(&bytes[at(b"POINT_DATA")..]);
        let path = dir.path().join(format!("grid_{ascii}.vtk"));
        std::fs::write(&path, grid).unwrap();
        let step = the_step(&path);
        let whole = io::read_step(&step, &AttributeSelection::All).unwrap();
        assert_eq!(whole.attribute_names(), legacy_section_names(true));
        check_parts(&step, &AttributeSelection::All, n, Bound::Exact);
    }
    // A lookup table of 7 colours, not one a point: kept, it is refused by the whole read and
    // every part alike; left out, the rest is read by rows.
    for ascii in [false, true] {
        let path = dir.path().join(format!("table_{ascii}.vtk"));
        write_legacy_sections(&path, n, ascii, false, 7);
        let step = the_step(&path);
        let whole = io::read_step(&step, &AttributeSelection::All)
            .unwrap_err()
            .to_string();
        assert!(whole.contains("'table' has 28 values"), "{whole}");
        for part in [Part::new(0, 1), Part::new(2, 3)] {
            let err = io::read_step_part(&step, &AttributeSelection::All, part)
                .unwrap_err()
                .to_string();
            assert_eq!(err, whole);
        }
        let names = legacy_section_names(false);
        let names: Vec<&str> = names.iter().map(String::as_str).collect();
        let whole = io::read_step(&step, &only(&names)).unwrap();
        assert_eq!(whole.attribute_names(), legacy_section_names(false));
        check_parts(&step, &only(&names), n, Bound::Exact);
    }
}

/// A legacy section whose count runs past the end of the file is refused by a part, naming the
/// file, the section and where it starts.
#[test]
fn a_legacy_section_running_past_the_end_is_named_by_a_part() {
    let dir = tempfile::tempdir().unwrap();
    for ascii in [false, true] {
        let good = dir.path().join(format!("good_{ascii}.vtk"));
        write_legacy_sections(&good, 101, ascii, false, 101);
        let bytes = std::fs::read(&good).unwrap();
        // Cut inside the tensors' values.
        let word = b"TEXTURE_COORDINATES";
        let at = bytes.windows(word.len()).position(|w| w == word).unwrap() - 40;
        let path = dir.path().join(format!("cut_{ascii}.vtk"));
        std::fs::write(&path, &bytes[..at]).unwrap();
        let step = the_step(&path);
        assert!(io::read_step(&step, &AttributeSelection::All).is_err());
        for part in [Part::new(0, 2), Part::new(1, 2)] {
            let err = io::read_step_part(&step, &AttributeSelection::All, part)
                .unwrap_err()
                .to_string();
            assert!(
                err.contains(&format!("cut_{ascii}.vtk"))
                    && err.contains("array 'stress' should hold 909 values")
                    && err.contains("from byte"),
                "{err}"
            );
        }
    }
}

/// How [`write_inline`] writes a VTK XML file's inline arrays.
#[derive(Clone, Copy, Debug)]
struct Inline {
    /// Bytes of a size integer: 4 (`UInt32`, VTK's) or 8 (`UInt64`, meshio's).
    header_bytes: usize,
    /// Compressed in blocks of this many bytes (meshio's and VTK's `compressor`).
    zlib_block: Option<usize>,
    /// The compressor of those blocks.
    codec: Codec,
    /// `format="ascii"` with this many values a line, else `format="binary"` (base64).
    ascii: Option<usize>,
}

/// A value as text, as VTK and meshio write them: Float64 with 17 significant digits, Float32
/// with the digits that round-trip it, NaN as `nan`, integers as integers.
fn ascii_value(v: f64, ty: &str) -> String {
    match ty {
        _ if v.is_nan() => "nan".into(),
        "Float64" => format!("{v:.16e}"),
        "Float32" => format!("{:?}", v as f32),
        _ => format!("{}", v as i64),
    }
}

/// Writes an unstructured grid of [`particle`]s in pieces of `pieces` points, every array
/// inline in its `<DataArray>` as meshio and VTK's `SetDataModeToBinary`/`Ascii` write them:
/// base64 of an uncompressed array's size and bytes (one run), or of a compressed array's
/// header and then of its zlib blocks (two runs, encoded one after the other), on a line of
/// its own; or ascii, `ascii` values a line whatever the record size. Points are Float64, the
/// cells' connectivity and offsets Int64 and types UInt8 (meshio's), point data `rho`
/// Float32, `pressure` Float64, `id` Int32 and `velocity` 3 x Float32. `corrupt`: an array's
/// name and a zlib block of it, in the first piece, whose bytes are replaced by garbage.
fn write_inline(path: &Path, pieces: &[usize], how: Inline, corrupt: Option<(&str, usize)>) {
    use base64::Engine;
    let int = |v: usize| (v as u64).to_le_bytes()[..how.header_bytes].to_vec();
    let b64 = |b: &[u8]| base64::engine::general_purpose::STANDARD.encode(b);
    let array =
        |xml: &mut String, piece: usize, name: &str, ty: &str, comps: usize, values: Vec<f64>| {
            let format = if how.ascii.is_some() {
                "ascii"
            } else {
                "binary"
            };
            xml.push_str(&format!(
                "        <DataArray type=\"{ty}\" Name=\"{name}\" NumberOfComponents=\"{comps}\" \
             format=\"{format}\">\n"
            ));
            if let Some(per_line) = how.ascii {
                for (i, &v) in values.iter().enumerate() {
                    xml.push_str(if i % per_line == 0 { "          " } else { " " });
                    xml.push_str(&ascii_value(v, ty));
                    if i % per_line == per_line - 1 || i + 1 == values.len() {
                        xml.push('\n');
                    }
                }
            } else {
                let data: Vec<u8> = values
                    .iter()
                    .flat_map(|&v| match ty {
                        "Float64" => v.to_le_bytes().to_vec(),
                        "Float32" => (v as f32).to_le_bytes().to_vec(),
                        "Int32" => (v as i32).to_le_bytes().to_vec(),
                        "Int64" => (v as i64).to_le_bytes().to_vec(),
                        "UInt8" => vec![v as u8],
                        _ => unreachable!(),
                    })
                    .collect();
                xml.push_str("          ");
                match how.zlib_block {
                    None => xml.push_str(&b64(&[int(data.len()), data].concat())),
                    Some(size) => {
                        let bad = corrupt
                            .and_then(|(bad, block)| (bad == name && piece == 0).then_some(block));
                        let (head, blocks) = zlib_blocks(&data, size, how.codec, &int, bad);
                        xml.push_str(&b64(&head));
                        xml.push_str(&b64(&blocks));
                    }
                }
                xml.push('\n');
            }
            xml.push_str("        </DataArray>\n");
        };
    let mut xml = format!(
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"0.1\" \
         byte_order=\"LittleEndian\" header_type=\"{}\"{}>\n  <UnstructuredGrid>\n",
        if how.header_bytes == 8 {
            "UInt64"
        } else {
            "UInt32"
        },
        if how.zlib_block.is_some() {
            how.codec.attribute()
        } else {
            ""
        }
    );
    let mut first = 0;
    for (piece, &n) in pieces.iter().enumerate() {
        let rows: Vec<_> = (first..first + n).map(particle).collect();
        first += n;
        xml.push_str(&format!(
            "    <Piece NumberOfPoints=\"{n}\" NumberOfCells=\"{n}\">\n      <Points>\n"
        ));
        let points = rows.iter().flat_map(|p| p.0).collect();
        array(&mut xml, piece, "points", "Float64", 3, points);
        xml.push_str("      </Points>\n      <Cells>\n");
        array(
            &mut xml,
            piece,
            "connectivity",
            "Int64",
            1,
            (0..n).map(|i| i as f64).collect(),
        );
        array(
            &mut xml,
            piece,
            "offsets",
            "Int64",
            1,
            (1..=n).map(|i| i as f64).collect(),
        );
        array(&mut xml, piece, "types", "UInt8", 1, vec![1.0; n]);
        xml.push_str("      </Cells>\n      <PointData>\n");
        array(
            &mut xml,
            piece,
            "rho",
            "Float32",
            1,
            rows.iter().map(|p| p.1 as f64).collect(),
        );
        array(
            &mut xml,
            piece,
            "pressure",
            "Float64",
            1,
            rows.iter().map(|p| p.2).collect(),
        );
        array(
            &mut xml,
            piece,
            "id",
            "Int32",
            1,
            rows.iter().map(|p| p.3 as f64).collect(),
        );
        let velocity = rows.iter().flat_map(|p| p.4.map(f64::from)).collect();
        array(&mut xml, piece, "velocity", "Float32", 3, velocity);
        xml.push_str("      </PointData>\n    </Piece>\n");
    }
    xml.push_str("  </UnstructuredGrid>\n</VTKFile>\n");
    std::fs::write(path, xml).unwrap();
}

/// Inline arrays as meshio writes them (UInt64 sizes; zlib in blocks, the last partial, or
/// uncompressed; ascii one value a line) and as VTK does (UInt32 sizes; ascii 6 values a line),
/// and 7 values a line, which splits records of 3 across lines: a part decodes only its rows
/// (of base64, the groups and zlib blocks that hold them; of ascii, its own values, those
/// before them counted), and the parts joined are vtkio's whole read bit for bit.
#[test]
fn vtk_inline_arrays_are_read_by_the_rows_of_each_piece() {
    let dir = tempfile::tempdir().unwrap();
    let pieces = [997, 0, 1003];
    let binary = Inline {
        header_bytes: 8,
        zlib_block: None,
        codec: Codec::Zlib,
        ascii: None,
    };
    let kinds = [
        Inline {
            zlib_block: Some(1000),
            ..binary
        },
        binary,
        Inline {
            header_bytes: 4,
            ..binary
        },
        Inline {
            header_bytes: 4,
            zlib_block: Some(100),
            ..binary
        },
        // VTK's other compressors (the whole step, vtkio's, decompresses them too).
        Inline {
            header_bytes: 4,
            zlib_block: Some(100),
            codec: Codec::Lz4,
            ..binary
        },
        Inline {
            zlib_block: Some(1000),
            codec: Codec::Lzma,
            ..binary
        },
        Inline {
            ascii: Some(1),
            ..binary
        },
        Inline {
            ascii: Some(6),
            ..binary
        },
        Inline {
            ascii: Some(7),
            ..binary
        },
    ];
    let expected = particles_step(2000);
    for (k, how) in kinds.into_iter().enumerate() {
        let path = dir.path().join(format!("inline_{k}.vtu"));
        // vtkio (the whole read) cannot inflate an empty compressed array (0 blocks): it
        // underflows computing its size, so the compressed files have no empty piece.
        let pieces: &[usize] = if how.zlib_block.is_some() {
            &[997, 1003]
        } else {
            &pieces
        };
        write_inline(&path, pieces, how, None);
        let step = the_step(&path);
        let whole = io::read_step(&step, &AttributeSelection::All)
            .unwrap_or_else(|e| panic!("{how:?}: {e}"));
        // The whole step is what was written (rho's NaN at 700 dropped).
        assert_eq!(whole.len(), 1999, "{how:?}");
        assert_eq!(
            whole.attribute_names(),
            expected.attribute_names(),
            "{how:?}"
        );
        if how.ascii.is_none() {
            assert_eq!(whole.positions[..700], expected.positions[..700], "{how:?}");
        }
        check_parts(&step, &AttributeSelection::All, 2000, Bound::Exact);
        check_parts(&step, &only(&["velocity_z", "id"]), 2000, Bound::Exact);
        check_parts(&step, &only(&["pressure"]), 2000, Bound::Exact);
    }
    // Our own writer's (vtkio's: poly data, zlib, one block an array).
    let step = particles_step(37);
    let step = Step {
        attributes: step.attributes[1..3].to_vec(),
        ..step
    };
    let vtp = dir.path().join("ours.vtp");
    io::vtk::write_vtp(&vtp, &step).unwrap();
    assert!(!std::fs::read_to_string(&vtp).unwrap().contains("appended"));
    check_parts(&the_step(&vtp), &AttributeSelection::All, 37, Bound::Exact);
}

/// Errors in a part of inline arrays name the file and the array: a value that is not a
/// number in a later part's rows (only the part that parses it refuses), a corrupt zlib block
/// (only the parts whose rows it holds), an array cut short, and too few values.
#[test]
fn a_bad_value_block_or_cut_in_an_inline_vtk_part_is_an_error_naming_the_file_and_array() {
    let dir = tempfile::tempdir().unwrap();
    let ascii = Inline {
        header_bytes: 4,
        zlib_block: None,
        codec: Codec::Zlib,
        ascii: Some(6),
    };
    let good = dir.path().join("good.vtu");
    write_inline(&good, &[997, 1003], ascii, None);
    let text = std::fs::read_to_string(&good).unwrap();
    // Record 1900's pressure (rank 3 of 4's rows) spoiled.
    let value = ascii_value(particle(1900).2, "Float64");
    assert_eq!(text.matches(&value).count(), 1);
    let bad = dir.path().join("bad_value.vtu");
    std::fs::write(&bad, text.replace(&value, &format!("{value}x"))).unwrap();
    let step = the_step(&bad);
    let err = io::read_step_part(&step, &AttributeSelection::All, Part::new(3, 4))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("bad_value.vtu") && err.contains("'pressure'") && err.contains(&value),
        "{err}"
    );
    for rank in 0..3 {
        let part = io::read_step_part(&step, &AttributeSelection::All, Part::new(rank, 4))
            .unwrap_or_else(|e| panic!("rank {rank} of 4: {e}"));
        assert_eq!(part.decoded, 500);
    }
    assert!(io::read_step(&step, &AttributeSelection::All).is_err());

    // One value fewer: every part refuses, naming the array.
    let short = dir.path().join("short.vtu");
    std::fs::write(&short, text.replacen(&format!(" {value}"), "", 1)).unwrap();
    let step = the_step(&short);
    for part in [Part::new(0, 2), Part::new(1, 2)] {
        let err = io::read_step_part(&step, &only(&["pressure"]), part)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("short.vtu") && err.contains("'pressure' holds 1002 values"),
            "{err}"
        );
    }

    // Cut inside the second piece's pressure, ascii and base64.
    for (k, how) in [
        ascii,
        Inline {
            ascii: None,
            ..ascii
        },
    ]
    .into_iter()
    .enumerate()
    {
        let good = dir.path().join(format!("good_{k}.vtu"));
        write_inline(&good, &[997, 1003], how, None);
        let bytes = std::fs::read(&good).unwrap();
        let text = String::from_utf8_lossy(&bytes);
        let second = text.rfind("Name=\"pressure\"").unwrap();
        let cut = dir.path().join(format!("cut_{k}.vtu"));
        std::fs::write(&cut, &bytes[..second + 200]).unwrap();
        let step = the_step(&cut);
        for part in [Part::new(0, 2), Part::new(1, 2)] {
            let err = io::read_step_part(&step, &AttributeSelection::All, part)
                .unwrap_err()
                .to_string();
            assert!(
                err.contains(&format!("cut_{k}.vtu")) && err.contains("'pressure'"),
                "{err}"
            );
        }
    }

    // Base64 wrapped in lines of 76 characters (whitespace inside it) is left to vtkio, whole,
    // for a part as for the whole step: both give vtkio's answer (0.7.0-rc2 refuses it).
    let plain = dir.path().join("plain.vtu");
    write_inline(
        &plain,
        &[997, 1003],
        Inline {
            ascii: None,
            ..ascii
        },
        None,
    );
    let text = std::fs::read_to_string(&plain).unwrap();
    let wrapped: String = text
        .lines()
        .map(|line| {
            let trimmed = line.trim_start();
            if trimmed.len() > 76 && !trimmed.starts_with('<') {
                let chars: Vec<char> = trimmed.chars().collect();
                let lines: Vec<String> = chars.chunks(76).map(|c| c.iter().collect()).collect();
                lines.join("\n")
            } else {
                line.to_owned()
            }
        })
        .collect::<Vec<_>>()
        .join("\n");
    let wrapped_path = dir.path().join("wrapped.vtu");
    std::fs::write(&wrapped_path, wrapped).unwrap();
    let step = the_step(&wrapped_path);
    let whole = io::read_step(&step, &AttributeSelection::All).map_err(|e| e.to_string());
    let part = io::read_step_part(&step, &AttributeSelection::All, Part::new(1, 3))
        .map(|p| p.decoded)
        .map_err(|e| e.to_string());
    match (&whole, &part) {
        (Err(w), Err(p)) => assert!(w == p && w.contains("wrapped.vtu") && w.contains("Base64")),
        _ => panic!("whole {whole:?}, part {part:?}"),
    }

    // pressure's block 40 is its bytes 4000..4100: the first piece's rows 500..512.
    // Each compressor's corrupt block, in a later part's rows, is named by the parts that
    // hold it.
    for codec in [Codec::Zlib, Codec::Lz4, Codec::Lzma] {
        let how = Inline {
            header_bytes: 8,
            zlib_block: Some(100),
            codec,
            ascii: None,
        };
        let path = dir.path().join(format!("bad_block_{codec:?}.vtu"));
        write_inline(&path, &[997, 1003], how, Some(("pressure", 40)));
        let step = the_step(&path);
        let selection = only(&["pressure"]);
        for part in [Part::new(0, 2), Part::new(1, 4)] {
            let err = io::read_step_part(&step, &selection, part)
                .unwrap_err()
                .to_string();
            assert!(
                err.contains(&format!("bad_block_{codec:?}.vtu"))
                    && err.contains("'pressure' block 40"),
                "{err}"
            );
        }
        assert!(io::read_step(&step, &selection).is_err());
        for (rank, ranks) in [(1, 2), (0, 4), (2, 4)] {
            let part = io::read_step_part(&step, &selection, Part::new(rank, ranks))
                .unwrap_or_else(|e| panic!("rank {rank} of {ranks}: {e}"));
            assert_eq!(part.decoded, Part::new(rank, ranks).range(2000).len());
        }
    }
}

/// Writes [`particle`]s `0..n` as VTK's legacy writer does in ascii: poly data, POINTS double,
/// `per_line` values a line (VTK: 9), the vertices (`modern`: VTK 5.1's OFFSETS and
/// CONNECTIVITY, else the older `1 i` list), then POINT_DATA with SCALARS float and its
/// LOOKUP_TABLE, VECTORS double and a FIELD of an int and a double array; lines end in
/// `line_end`. rho's NaN (which vtkio's legacy reader refuses as text) is written 0.5.
fn write_legacy_ascii(path: &Path, n: usize, per_line: usize, line_end: &str, modern: bool) {
    let rows: Vec<_> = (0..n).map(particle).collect();
    let version = if modern { "5.1" } else { "3.0" };
    let mut out = format!(
        "# vtk DataFile Version {version}\nvtk output\nASCII\nDATASET POLYDATA\nPOINTS {n} double\n"
    );
    let values = |out: &mut String, values: Vec<String>| {
        for (i, v) in values.iter().enumerate() {
            out.push_str(v);
            out.push(if i % per_line == per_line - 1 || i + 1 == values.len() {
                '\n'
            } else {
                ' '
            });
        }
    };
    let doubles = |v: Vec<f64>| v.iter().map(|v| format!("{v:.16e}")).collect();
    let ints = |v: Vec<i64>| v.iter().map(|v| v.to_string()).collect();
    values(&mut out, doubles(rows.iter().flat_map(|p| p.0).collect()));
    if modern {
        out.push_str(&format!("VERTICES {} {n}\nOFFSETS vtktypeint64\n", n + 1));
        values(&mut out, ints((0..=n as i64).collect()));
        out.push_str("CONNECTIVITY vtktypeint64\n");
        values(&mut out, ints((0..n as i64).collect()));
    } else {
        out.push_str(&format!("VERTICES {n} {}\n", 2 * n));
        values(&mut out, ints((0..n as i64).flat_map(|i| [1, i]).collect()));
    }
    out.push_str(&format!(
        "POINT_DATA {n}\nSCALARS density float 1\nLOOKUP_TABLE default\n"
    ));
    let rho = |p: &Particle| if p.1.is_nan() { 0.5 } else { p.1 };
    values(
        &mut out,
        rows.iter().map(|p| format!("{:?}", rho(p))).collect(),
    );
    out.push_str("VECTORS velocity double\n");
    values(
        &mut out,
        doubles(rows.iter().flat_map(|p| p.4.map(f64::from)).collect()),
    );
    out.push_str(&format!("FIELD FieldData 2\nid 1 {n} int\n"));
    values(&mut out, ints(rows.iter().map(|p| p.3 as i64).collect()));
    out.push_str(&format!("pressure 1 {n} double\n"));
    values(&mut out, doubles(rows.iter().map(|p| p.2).collect()));
    std::fs::write(path, out.replace('\n', line_end)).unwrap();
}

/// Legacy ascii VTK as VTK writes it (9 values a line) and one value a line with CRLF line
/// ends: a part counts the values before its rows and parses only its own; the parts joined
/// are vtkio's whole read bit for bit.
#[test]
fn legacy_ascii_vtk_is_read_by_counting_to_the_rows_of_each_section() {
    let dir = tempfile::tempdir().unwrap();
    let n = 1013;
    for (per_line, line_end, modern) in [(9, "\n", true), (1, "\r\n", false), (9, "\n", false)] {
        let path = dir.path().join(format!("ascii_{per_line}_{modern}.vtk"));
        write_legacy_ascii(&path, n, per_line, line_end, modern);
        let step = the_step(&path);
        let whole = io::read_step(&step, &AttributeSelection::All)
            .unwrap_or_else(|e| panic!("{per_line} a line, modern {modern}: {e}"));
        assert_eq!(whole.len(), n);
        check_legacy_parts(&step, &whole, n);
    }
}

/// A value that is not a number in a later part's rows of a legacy ascii file is refused by
/// the part that parses it, naming the file, the array and its byte; too few values, by every
/// part, naming the section.
#[test]
fn a_bad_value_in_a_legacy_ascii_part_is_an_error_naming_the_file_and_array() {
    let dir = tempfile::tempdir().unwrap();
    let n = 1013;
    let good = dir.path().join("good.vtk");
    write_legacy_ascii(&good, n, 9, "\n", true);
    let text = std::fs::read_to_string(&good).unwrap();
    let value = format!("{:.16e}", particle(900).2);
    assert_eq!(text.matches(&value).count(), 1);
    let bad = dir.path().join("bad.vtk");
    // vtkio's whole read refuses it too (a value must end at whitespace).
    let spoiled = format!("{value}x");
    std::fs::write(&bad, text.replace(&value, &spoiled)).unwrap();
    let step = the_step(&bad);
    let err = io::read_step_part(&step, &AttributeSelection::All, Part::new(3, 4))
        .unwrap_err()
        .to_string();
    let at = text.find(&value).unwrap();
    assert!(
        err.contains("bad.vtk")
            && err.contains("array 'pressure'")
            && err.contains(&spoiled)
            && err.contains(&format!("byte {at}")),
        "{err}"
    );
    for rank in 0..3 {
        io::read_step_part(&step, &AttributeSelection::All, Part::new(rank, 4))
            .unwrap_or_else(|e| panic!("rank {rank} of 4: {e}"));
    }
    assert!(io::read_step(&step, &AttributeSelection::All).is_err());

    // A point's z left out: the POINTS run into the next section's keyword.
    let short = dir.path().join("short.vtk");
    let z = format!(" {:.16e}", particle(5).0[2]);
    std::fs::write(&short, text.replacen(&z, "", 1)).unwrap();
    let step = the_step(&short);
    for part in [Part::new(0, 2), Part::new(1, 2)] {
        let err = io::read_step_part(&step, &AttributeSelection::All, part)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("short.vtk") && err.contains("the POINTS") && err.contains("'VERTICES'"),
            "{err}"
        );
    }

    // Cut inside the last array: every part refuses, naming it and where its values stop.
    let cut = dir.path().join("cut.vtk");
    std::fs::write(&cut, &text[..text.len() - 1000]).unwrap();
    let step = the_step(&cut);
    for part in [Part::new(0, 2), Part::new(1, 2)] {
        let err = io::read_step_part(&step, &AttributeSelection::All, part)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("cut.vtk")
                && err.contains("array 'pressure' should hold 1013 values")
                && err.contains("the file ends after"),
            "{err}"
        );
    }
}

/// An ascii PLY as plyfile writes a NumPy structured array: a comment, float, double and int
/// properties, one vertex a line with every digit, the vertex element last.
fn write_ascii_ply(path: &Path, n: usize, line_end: &str, after: &str) {
    let mut text = format!(
        "ply{line_end}format ascii 1.0{line_end}comment written by plyfile{line_end}\
         element vertex {n}{line_end}property float x{line_end}property float y{line_end}\
         property float z{line_end}property double density{line_end}property int id{line_end}"
    );
    if !after.is_empty() {
        text.push_str(&format!(
            "element face 1{line_end}property list uchar int vertex_indices{line_end}"
        ));
    }
    text.push_str(&format!("end_header{line_end}"));
    for i in 0..n {
        let t = i as f64 * 0.731;
        let (x, y, z) = ((t.sin() * 1e4) as f32, (t.cos() / 7.0) as f32, -(i as f32));
        let density = if i == 10 { f64::NAN } else { 1e-3 / (t + 1.0) };
        text.push_str(&format!(
            "{x:?} {y:?} {z:?} {density:?} {}{line_end}",
            i as i64 - 300
        ));
    }
    text.push_str(after);
    std::fs::write(path, text).unwrap();
}

#[test]
fn ascii_ply_with_the_vertex_element_last_is_read_by_byte_ranges_moved_to_line_starts() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cloud.ply");
    let n = 1013;
    write_ascii_ply(&path, n, "\n", "");
    let text = std::fs::read_to_string(&path).unwrap();
    let body = &text[text.find("end_header\n").unwrap() + 11..];
    let lengths: Vec<usize> = body.split_inclusive('\n').map(str::len).collect();
    assert_eq!(lengths.len(), n);
    let (longest, shortest) = (
        *lengths.iter().max().unwrap(),
        *lengths.iter().min().unwrap(),
    );
    let bound = Bound::Bytes { longest, shortest };
    let step = the_step(&path);
    let whole = io::read_step(&step, &AttributeSelection::All).unwrap();
    assert_eq!(whole.len(), n - 1);
    assert_eq!(whole.attribute_names(), ["density", "id"]);
    assert_eq!(whole.attributes[1].values[0], -300.0);
    check_parts(&step, &AttributeSelection::All, n, bound);
    check_parts(&step, &only(&["id"]), n, bound);

    // CRLF line ends, a blank line, no newline after the last row, fewer rows than ranks.
    let crlf = dir.path().join("crlf.ply");
    write_ascii_ply(&crlf, 11, "\r\n", "");
    let mut bytes = std::fs::read(&crlf).unwrap();
    bytes.truncate(bytes.len() - 2);
    let line = bytes.iter().rposition(|&c| c == b'\n').unwrap() + 1;
    bytes.splice(line..line, *b"  \r\n");
    std::fs::write(&crlf, bytes).unwrap();
    check_parts(
        &the_step(&crlf),
        &AttributeSelection::All,
        11,
        Bound::Bytes {
            longest,
            shortest: 4,
        },
    );

    // Rows of one length and N = 1008 (a multiple of every P but 5): the shares' ends fall on
    // line starts exactly, where a row must go to the part that starts with it, once.
    let fixed = dir.path().join("fixed.ply");
    let mut text = String::from(
        "ply\nformat ascii 1.0\nelement vertex 1008\nproperty int x\nproperty int y\n\
         property int z\nproperty double density\nend_header\n",
    );
    for i in 0..1008 {
        text.push_str(&format!(
            "{i:06} {:06} 000007 {:+.15e}\n",
            2 * i,
            1.0 / (i as f64 + 1.0)
        ));
    }
    std::fs::write(&fixed, text).unwrap();
    let row = row_lengths(&fixed).0;
    check_parts(
        &the_step(&fixed),
        &AttributeSelection::All,
        1008,
        Bound::Bytes {
            longest: row,
            shortest: row,
        },
    );

    // A row belongs to the part whose share holds its first byte: where every share starts a
    // line, a part's rows are exactly its share.
    let step = the_step(&fixed);
    for ranks in [2, 3, 4, 6, 7, 8, 9, 16] {
        for rank in 0..ranks {
            let part = io::read_step_part(&step, &AttributeSelection::All, Part::new(rank, ranks));
            let share = Part::new(rank, ranks).range(1008).len();
            assert_eq!(part.unwrap().decoded, share, "rank {rank} of {ranks}");
        }
    }

    // A face element after the vertices: read by counted lines, each part exactly its rows
    // (more in ascii_ply_meshes_and_lists_are_read_by_counted_lines).
    let faces = dir.path().join("faces.ply");
    write_ascii_ply(&faces, 101, "\n", "3 0 1 2\n");
    check_parts(
        &the_step(&faces),
        &AttributeSelection::All,
        101,
        Bound::Exact,
    );
}

#[test]
fn a_bad_row_in_an_ascii_ply_part_is_named_by_its_byte_offset() {
    let dir = tempfile::tempdir().unwrap();
    let good = dir.path().join("good.ply");
    write_ascii_ply(&good, 200, "\n", "");
    let text = std::fs::read_to_string(&good).unwrap();
    let row = |i: usize| {
        let body = text.find("end_header\n").unwrap() + 11;
        body + text[body..]
            .split_inclusive('\n')
            .take(i)
            .map(str::len)
            .sum::<usize>()
    };
    // A value that is not a number; a row short of a value.
    let at = row(150);
    let end = at + text[at..].find(' ').unwrap();
    let bad = format!("{}1.5e{}", &text[..at], &text[end..]);
    let at_short = row(160);
    let short_end = at_short + text[at_short..].find('\n').unwrap();
    let cut = at_short + text[at_short..short_end].rfind(' ').unwrap();
    let short = format!("{}{}", &text[..cut], &text[short_end..]);
    for (name, text, at, what) in [
        ("bad.ply", bad, at, "'1.5e' (property 'x') is not a number"),
        (
            "short.ply",
            short,
            at_short,
            "4 values, but the element has 5",
        ),
    ] {
        let path = dir.path().join(name);
        std::fs::write(&path, text).unwrap();
        let step = the_step(&path);
        assert!(io::read_step(&step, &AttributeSelection::All).is_err());
        let err = io::read_step_part(&step, &AttributeSelection::All, Part::new(1, 2))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains(name) && err.contains(&format!("byte {at}")) && err.contains(what),
            "{err}"
        );
        // The first half's rows are fine.
        io::read_step_part(&step, &AttributeSelection::All, Part::new(0, 2)).unwrap();
    }
}

/// How a writer lays out an ascii mesh: vertices, then `element face` with
/// `property list uchar int vertex_indices`.
#[derive(Clone, Copy)]
struct AsciiMesh {
    line_end: &'static str,
    /// Faces after the vertices (`None`: the vertex element is the last).
    faces: Option<usize>,
    /// A list property in the vertex element (texture coordinates of 0 to 3 items).
    vertex_list: bool,
    /// A space after each row's last value (MeshLab's VCG writer).
    trailing_space: bool,
    /// A line break after the last line.
    final_newline: bool,
    /// Doubles as `{:.16e}` (17 significant digits, as plyfile's `%.17g`), else `{:?}`.
    digits17: bool,
    /// An element of lists before the vertices (two materials' ids).
    before: bool,
}

const PLYFILE_MESH: AsciiMesh = AsciiMesh {
    line_end: "\n",
    faces: Some(675),
    vertex_list: false,
    trailing_space: false,
    final_newline: true,
    digits17: true,
    before: false,
};

/// An ascii mesh as plyfile, Open3D and MeshLab write one: comments, double, float and int
/// vertex properties (x, y, z, maybe a list, density, id), one row a line, then faces.
fn write_ascii_mesh(path: &Path, n: usize, m: AsciiMesh) {
    let mut lines = vec![
        "ply".to_string(),
        "format ascii 1.0".into(),
        "comment VCGLIB generated".into(),
        "comment Created by Open3D and plyfile alike".into(),
    ];
    if m.before {
        lines.push("element material 2".into());
        lines.push("property list uchar int ids".into());
    }
    lines.extend([
        format!("element vertex {n}"),
        "property double x".into(),
        "property double y".into(),
        "property float z".into(),
    ]);
    if m.vertex_list {
        lines.push("property list uchar float texture_u".into());
    }
    lines.extend(["property double density".into(), "property int id".into()]);
    if let Some(faces) = m.faces {
        lines.push(format!("element face {faces}"));
        lines.push("property list uchar int vertex_indices".into());
    }
    lines.push("end_header".into());
    if m.before {
        lines.push("0".into());
        lines.push("2 7 11".into());
    }
    let double = |v: f64| {
        if m.digits17 {
            format!("{v:.16e}")
        } else {
            format!("{v:?}")
        }
    };
    let space = if m.trailing_space { " " } else { "" };
    for i in 0..n {
        let t = i as f64 * 0.731;
        let density = if i == 10 { f64::NAN } else { 1e-3 / (t + 1.0) };
        let mut row = format!(
            "{} {} {:?}",
            double(t.sin() * 1e4),
            double(t.cos() / 7.0),
            -(i as f32) * 0.1
        );
        if m.vertex_list {
            row.push_str(&format!(" {}", i % 4));
            for k in 0..i % 4 {
                row.push_str(&format!(" {:?}", k as f32 * 0.25 + i as f32));
            }
        }
        row.push_str(&format!(" {} {}{space}", double(density), i as i64 - 300));
        lines.push(row);
    }
    for f in 0..m.faces.unwrap_or(0) {
        lines.push(format!(
            "3 {} {} {}{space}",
            f % n,
            (f + 1) % n,
            (f * 7) % n
        ));
    }
    let mut text = lines.join(m.line_end);
    if m.final_newline {
        text.push_str(m.line_end);
    }
    std::fs::write(path, text).unwrap();
}

/// A binary PLY of `n` vertices (float x, double y, float z, maybe a list of 0 to 4 ints,
/// double density, int id), maybe after an element of lists (materials), then faces.
fn write_binary_ply(path: &Path, n: usize, big: bool, before: bool, vertex_list: bool) {
    let order = if big { "big" } else { "little" };
    let mut header = format!("ply\nformat binary_{order}_endian 1.0\ncomment made by a test\n");
    if before {
        header.push_str(
            "element material 5\nproperty list uchar int ids\nproperty float shininess\n",
        );
    }
    header.push_str(
        "element vertex N\nproperty float x\nproperty double y\nproperty float z\n"
            .replace('N', &n.to_string())
            .as_str(),
    );
    if vertex_list {
        header.push_str("property list uchar int neighbours\n");
    }
    header.push_str(&format!(
        "property double density\nproperty int id\nelement face {}\n\
         property list uchar int vertex_indices\nend_header\n",
        n / 2
    ));
    let mut bytes = header.into_bytes();
    macro_rules! put {
        ($v:expr) => {
            bytes.extend(if big {
                $v.to_be_bytes()
            } else {
                $v.to_le_bytes()
            })
        };
    }
    if before {
        for m in 0..5u8 {
            bytes.push(m * 3);
            for k in 0..m as i32 * 3 {
                put!(k);
            }
            put!(m as f32 * 0.5);
        }
    }
    for i in 0..n {
        let t = i as f64 * 0.731;
        put!((t.sin() * 1e4) as f32);
        put!(t.cos() / 7.0);
        put!(-(i as f32) * 0.1);
        if vertex_list {
            bytes.push((i % 5) as u8);
            for k in 0..(i % 5) as i32 {
                put!(i as i32 + k);
            }
        }
        put!(if i == 10 { f64::NAN } else { 1e-3 / (t + 1.0) });
        put!(i as i32 - 300);
    }
    for f in 0..(n / 2) as i32 {
        bytes.push(3);
        for k in [f, f + 1, f + 2] {
            put!(k);
        }
    }
    std::fs::write(path, bytes).unwrap();
}

#[test]
fn ascii_ply_meshes_and_lists_are_read_by_counted_lines() {
    let dir = tempfile::tempdir().unwrap();
    let n = 1013;
    let open3d = AsciiMesh {
        line_end: "\r\n",
        trailing_space: true,
        final_newline: false,
        digits17: false,
        ..PLYFILE_MESH
    };
    let with_list = AsciiMesh {
        vertex_list: true,
        faces: Some(3),
        ..PLYFILE_MESH
    };
    let list_last = AsciiMesh {
        vertex_list: true,
        faces: None,
        final_newline: false,
        ..PLYFILE_MESH
    };
    let no_faces = AsciiMesh {
        faces: Some(0),
        ..PLYFILE_MESH
    };
    let materials = AsciiMesh {
        before: true,
        vertex_list: true,
        ..open3d
    };
    for (name, mesh, rows) in [
        ("plyfile.ply", PLYFILE_MESH, n),
        ("open3d.ply", open3d, n),
        ("list.ply", with_list, n),
        ("list_last.ply", list_last, n),
        ("no_faces.ply", no_faces, n),
        ("materials.ply", materials, n),
        ("few.ply", open3d, 5),
    ] {
        let path = dir.path().join(name);
        write_ascii_mesh(&path, rows, mesh);
        let step = the_step(&path);
        let whole = io::read_step(&step, &AttributeSelection::All).unwrap();
        assert_eq!(whole.len(), rows - usize::from(rows > 10), "{name}");
        assert_eq!(whole.attribute_names(), ["density", "id"], "{name}");
        assert_eq!(whole.attributes[1].values[0], -300.0, "{name}");
        check_parts(&step, &AttributeSelection::All, rows, Bound::Exact);
        check_parts(&step, &only(&["id"]), rows, Bound::Exact);
        check_parts(&step, &only(&[]), rows, Bound::Exact);
    }
}

#[test]
fn binary_ply_with_lists_is_read_by_stepping_over_the_rows_before_the_part() {
    let dir = tempfile::tempdir().unwrap();
    let n = 1013;
    for big in [false, true] {
        for (before, vertex_list) in [(false, true), (true, true), (true, false)] {
            let path = dir
                .path()
                .join(format!("lists_{big}_{before}_{vertex_list}.ply"));
            write_binary_ply(&path, n, big, before, vertex_list);
            let step = the_step(&path);
            let whole = io::read_step(&step, &AttributeSelection::All).unwrap();
            assert_eq!(whole.len(), n - 1);
            assert_eq!(whole.attribute_names(), ["density", "id"]);
            assert_eq!(whole.attributes[1].values[0], -300.0);
            assert_eq!(whole.positions[n - 2].z, -((n - 1) as f32 * 0.1) as f64);
            check_parts(&step, &AttributeSelection::All, n, Bound::Exact);
            check_parts(&step, &only(&["density"]), n, Bound::Exact);
        }
    }
}

/// The error of rank `rank` of `ranks` reading `path`.
fn part_error(path: &Path, rank: usize, ranks: usize) -> String {
    io::read_step_part(
        &the_step(path),
        &AttributeSelection::All,
        Part::new(rank, ranks),
    )
    .unwrap_err()
    .to_string()
}

#[test]
fn a_bad_row_or_a_short_file_in_a_ply_part_is_named_by_its_line_or_byte() {
    let dir = tempfile::tempdir().unwrap();
    let good = dir.path().join("good.ply");
    write_ascii_mesh(&good, 200, PLYFILE_MESH);
    let text = std::fs::read_to_string(&good).unwrap();
    let header_lines = text[..text.find("end_header\n").unwrap()].lines().count() + 1;
    // Row i's byte offset and line number.
    let row = |i: usize| {
        let body = text.find("end_header\n").unwrap() + 11;
        let at = body
            + text[body..]
                .split_inclusive('\n')
                .take(i)
                .map(str::len)
                .sum::<usize>();
        (at, header_lines + i + 1)
    };
    // A value that is not a number; a row short of a value; fewer vertex rows than the header
    // says (the part reads a face as a vertex row).
    let (at, line) = row(150);
    let end = at + text[at..].find(' ').unwrap();
    let bad = format!("{}1.5e{}", &text[..at], &text[end..]);
    let (at_short, line_short) = row(160);
    let short_end = at_short + text[at_short..].find('\n').unwrap();
    let cut = at_short + text[at_short..short_end].rfind(' ').unwrap();
    let short = format!("{}{}", &text[..cut], &text[short_end..]);
    // (Row 200 is the first face.)
    let few = text.replace("element vertex 200", "element vertex 201");
    let (at_few, line_few) = row(200);
    for (name, text, at, line, row, what) in [
        (
            "bad.ply",
            bad,
            at,
            line,
            150,
            "'1.5e' (property 'x') is not a number",
        ),
        (
            "short.ply",
            short,
            at_short,
            line_short,
            160,
            "4 values, but the element has 5 properties",
        ),
        (
            "few.ply",
            few,
            at_few,
            line_few,
            200,
            "4 values, but the element has 5 properties",
        ),
    ] {
        let path = dir.path().join(name);
        std::fs::write(&path, &text).unwrap();
        // One process reads ascii values one after another across lines: a row short of a
        // value takes the next row's first, and it may reach the end of the faces unrefused.
        if name == "bad.ply" {
            assert!(io::read_step(&the_step(&path), &AttributeSelection::All).is_err());
        }
        let err = part_error(&path, 1, 2);
        assert!(
            err.contains(name)
                && err.contains(&format!("row {row}, line {line} (byte {at})"))
                && err.contains(what),
            "{err}"
        );
        // The first half's rows are fine.
        io::read_step_part(&the_step(&path), &AttributeSelection::All, Part::new(0, 2)).unwrap();
    }

    // The file ends before the vertex rows do: the part that needs them says where.
    let list_last = AsciiMesh {
        vertex_list: true,
        faces: None,
        ..PLYFILE_MESH
    };
    let cut = dir.path().join("cut.ply");
    write_ascii_mesh(&cut, 200, list_last);
    let text = std::fs::read_to_string(&cut).unwrap();
    let text = text.replace("element vertex 200", "element vertex 210");
    std::fs::write(&cut, &text).unwrap();
    let err = part_error(&cut, 2, 3);
    let lines = text.lines().count();
    assert!(
        err.contains("cut.ply")
            && err.contains("truncated")
            && err.contains(&format!(
                "'vertex' has 210 rows in the header, but the file ends after line {lines} (byte {}) with 200 of them",
                text.len()
            )),
        "{err}"
    );
    io::read_step_part(&the_step(&cut), &AttributeSelection::All, Part::new(0, 3)).unwrap();

    // A list count past the end of the file, in the vertex element's last row and in the
    // element before it; and a file cut in a row.
    let binary = dir.path().join("binary.ply");
    write_binary_ply(&binary, 100, false, true, true);
    let bytes = std::fs::read(&binary).unwrap();
    let body = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .unwrap()
        + 11;
    // Material m: 1 + 12 m + 4 bytes; vertex i: 4 + 8 + 4 + 1 + 4 (i % 5) + 8 + 4.
    let vertex = |i: usize| {
        body + (0..5).map(|m| 5 + 12 * m).sum::<usize>()
            + (0..i).map(|i| 29 + 4 * (i % 5)).sum::<usize>()
    };
    let mut long_list = bytes[..vertex(100)].to_vec();
    long_list[vertex(99) + 16] = 200;
    // In a file of 8 vertices, material 2's 255 ints run past the end.
    let small = dir.path().join("small.ply");
    write_binary_ply(&small, 8, false, true, true);
    let mut long_material = std::fs::read(&small).unwrap();
    let small_body = long_material
        .windows(11)
        .position(|w| w == b"end_header\n")
        .unwrap()
        + 11;
    long_material[small_body + 5 + 17] = 255;
    for (name, bytes, rank, what) in [
        (
            "long_list.ply",
            long_list,
            3,
            format!(
                "PLY element 'vertex' row 99, property 'neighbours': its list of 200 items at byte {}",
                vertex(99) + 16
            ),
        ),
        (
            "long_material.ply",
            long_material,
            0,
            format!(
                "PLY element 'material' row 2, property 'ids': its list of 255 items at byte {}",
                small_body + 5 + 17
            ),
        ),
        (
            "cut_binary.ply",
            bytes[..vertex(77) + 10].to_vec(),
            3,
            format!(
                "PLY element 'vertex' row 77, property 'y': its value at byte {}",
                vertex(77) + 4
            ),
        ),
    ] {
        let path = dir.path().join(name);
        std::fs::write(&path, &bytes).unwrap();
        assert!(io::read_step(&the_step(&path), &AttributeSelection::All).is_err());
        let err = part_error(&path, rank, 4);
        assert!(
            err.contains(name)
                && err.contains(&what)
                && err.contains(&format!(
                    "runs past the end of the file ({} bytes)",
                    bytes.len()
                )),
            "{err}"
        );
    }
}

#[cfg(feature = "hdf5")]
#[test]
fn hdf5_snapshots_are_read_by_hyperslabs_across_their_files() {
    use io::ParticleType;
    // h5py's SWIFT-like snapshot: chunked, gzip + shuffle, 203 gas and 50 dark matter.
    let swift = data("h5py_swift/snap_0000.hdf5");
    check_parts(
        &the_step(&swift),
        &AttributeSelection::All,
        203,
        Bound::Exact,
    );
    check_parts(&the_step(&swift), &only(&["Densities"]), 203, Bound::Exact);
    let dark = io::list_steps_reading(
        &swift,
        None,
        ReadOptions {
            particle_type: "1".parse::<ParticleType>().unwrap(),
            physical: false,
        },
    )
    .unwrap()
    .remove(0);
    check_parts(&dark, &AttributeSelection::All, 50, Bound::Exact);

    // GADGET-style, over three files, one of them empty (compressed coordinates, contiguous
    // float32 velocities read straight from the file, masses from the mass table).
    let dir = tempfile::tempdir().unwrap();
    crate::hdf5_snapshots::write_gadget_snapshot(dir.path(), 0, &[301, 0, 422], 0.5);
    let first = dir.path().join("snap_000.0.hdf5");
    check_parts(
        &the_step(&first),
        &AttributeSelection::All,
        723,
        Bound::Exact,
    );
    let velocities = only(&["Velocities_x", "Masses"]);
    check_parts(&the_step(&first), &velocities, 723, Bound::Exact);
    // Rank 1 of 2 reads only the third file's rows.
    let part = io::read_step_part(&the_step(&first), &velocities, Part::new(1, 2)).unwrap();
    assert_eq!(part.decoded, 723 - 361);
    assert_eq!(part.step.attributes[0].values[0], 361.0);
}

/// Smoothing lengths from neighbours need the neighbours in other parts: the ranks find them
/// together (`aarbf::dist::knn`), each reading only its part, and each part's lengths are the
/// single process's, bit for bit; they are cached beside the data at each part's offset, and a
/// later read takes each part's share of the cache.
#[test]
fn a_series_with_neighbour_smoothing_reads_only_its_parts() {
    use aarbf::dist::comm::Comm;
    use aarbf::dist::knn::RankLengths;
    use aarbf::scene::smoothing::{self, Smoothing};
    use aarbf::scene::{OpenOptions, TimeSeries};
    let runs = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/sph_runs/gadget_like");
    // GADGET-like NumPy, N x 5 float64 (1000 particles), no smoothing length of its own.
    for neighbours in [16, 40] {
        let smoothing = Smoothing { neighbours };
        let (single, ranked) = (
            copied(&runs, &["snapshot_000.npy"]),
            copied(&runs, &["snapshot_000.npy"]),
        );
        let open = |dir: &Path, attributes| {
            TimeSeries::open(
                &dir.join("snapshot_000.npy"),
                &OpenOptions {
                    smoothing: Some(smoothing),
                    attributes,
                    ..OpenOptions::default()
                },
            )
            .unwrap()
        };
        let whole = open(single.path(), AttributeSelection::All)
            .step(0)
            .unwrap();
        let name = smoothing.attribute();
        assert!(whole.attribute(&name).is_some());
        let n = whole.len();
        // The ranks' series, opened from an index the single process did not write (each
        // opening reads the first step whole; the parts are read below, once the cache of
        // whole steps is cleared).
        let series = open(ranked.path(), AttributeSelection::All);
        series.clear_cache();
        let cache_file = || {
            std::fs::read_dir(ranked.path().join(smoothing::CACHE_DIR))
                .unwrap()
                .map(|e| e.unwrap().path())
                .find(|p| {
                    p.to_string_lossy()
                        .ends_with(&format!(".k{neighbours}.f64"))
                })
                .unwrap()
        };
        // No cache: the ranks compute the lengths.
        std::fs::remove_file(cache_file()).unwrap();
        for ranks in RANKS {
            let parts = aarbf::dist::run_local(ranks, |comm| {
                let part = Part::new(comm.rank(), comm.size());
                let read = series.step_part(0, part, &RankLengths { comm })?;
                assert_eq!(read.decoded, part.range(n).len(), "rank {part:?}");
                Ok(read.step)
            })
            .unwrap();
            let together = joined(&parts, &whole);
            assert_eq!(together.positions, whole.positions, "{ranks} ranks");
            assert_eq!(
                together.attributes, whole.attributes,
                "{ranks} ranks, K {neighbours}"
            );
        }
        // The ranks wrote the cache: the whole step's lengths, in the file's order.
        let step = series.step_ref(0).unwrap();
        assert_eq!(
            smoothing::cached_part(step, neighbours, n, 0..n).unwrap(),
            whole.attribute(&name).unwrap().values
        );
        // A later read takes each part's share of it: cached values made recognisable (the
        // header kept) come back in order.
        let path = cache_file();
        let mut bytes = std::fs::read(&path).unwrap();
        let header = bytes.len() - 8 * n;
        for (i, chunk) in bytes[header..].chunks_exact_mut(8).enumerate() {
            chunk.copy_from_slice(&(1.0 + i as f64).to_le_bytes());
        }
        // Written over in place, so that the data file's stamp still matches.
        std::fs::write(&path, &bytes).unwrap();
        let parts = aarbf::dist::run_local(3, |comm| {
            let part = Part::new(comm.rank(), comm.size());
            Ok(series.step_part(0, part, &RankLengths { comm })?.step)
        })
        .unwrap();
        let h: Vec<f64> = parts
            .iter()
            .flat_map(|p| p.attribute(&name).unwrap().values.clone())
            .collect();
        assert_eq!(h, (0..n).map(|i| 1.0 + i as f64).collect::<Vec<_>>());
        // Without the lengths in the selection, the part alone is read.
        let without = open(ranked.path(), only(&["col3"]));
        let part = aarbf::dist::run_local(3, |comm| {
            let part = Part::new(comm.rank(), comm.size());
            Ok(without.step_part(0, part, &RankLengths { comm })?)
        })
        .unwrap()
        .swap_remove(1);
        assert_eq!(part.decoded, Part::new(1, 3).range(n).len());
        assert_eq!(part.step.attribute_names(), ["col3"]);
    }
}

/// Ranks that scan a series from their parts ([`aarbf::dist::step_stats`]) as threads, keeping
/// the most records any rank decoded in one call and the records the whole steps scanned held.
struct ScanByRanks {
    ranks: usize,
    most_decoded: std::sync::Mutex<Vec<(usize, usize)>>,
}

impl aarbf::scene::StepsScan for ScanByRanks {
    fn stats(
        &self,
        steps: &[StepRef],
        which: &[usize],
        selection: &AttributeSelection,
        smoothing: Option<aarbf::scene::smoothing::Smoothing>,
    ) -> Result<Vec<aarbf::scene::index::StepStats>, io::DataError> {
        let found = aarbf::dist::run_local(self.ranks, |comm| {
            aarbf::dist::step_stats::of_parts(comm, steps, which, selection, smoothing)
        })
        .unwrap();
        let records: usize = found[0].0.iter().map(|s| s.count).sum();
        let decoded = found.iter().map(|(_, d)| *d).max().unwrap();
        self.most_decoded.lock().unwrap().push((decoded, records));
        for (stats, _) in &found[1..] {
            assert_eq!(stats, &found[0].0, "every rank finds the same statistics");
        }
        Ok(found.into_iter().next().unwrap().0)
    }
}

/// A copy of the series files `names` of `from` in a new directory (no index beside them).
fn copied(from: &Path, names: &[&str]) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    for n in names {
        std::fs::copy(from.join(n), dir.path().join(n)).unwrap();
    }
    dir
}

#[test]
fn a_series_without_an_index_is_scanned_from_the_ranks_parts_bit_for_bit() {
    use aarbf::scene::{OpenOptions, TimeSeries};
    let runs = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/sph_runs");
    // As SWIFT-like CSV (%.17g, 500, 503, 497, 511 rows), GADGET-like NumPy (N x 5 float64,
    // 1000 .. 1003 rows) and h5py's SWIFT snapshots (HDF5 hyperslabs) hold them.
    let series: [(std::path::PathBuf, Vec<&str>, &str); 3] = [
        (
            runs.join("swift_like"),
            vec![
                "output_0000.csv",
                "output_0001.csv",
                "output_0002.csv",
                "output_0003.csv",
            ],
            "output_*.csv",
        ),
        (
            runs.join("gadget_like"),
            vec![
                "snapshot_000.npy",
                "snapshot_001.npy",
                "snapshot_002.npy",
                "snapshot_003.npy",
                "snapshot_004.npy",
            ],
            "snapshot_*.npy",
        ),
        (
            Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/h5py_swift"),
            vec!["snap_0000.hdf5", "snap_0001.hdf5"],
            "snap_*.hdf5",
        ),
    ];
    for (from, names, pattern) in &series {
        for selection in [AttributeSelection::All, only(&[])] {
            let options = OpenOptions {
                attributes: selection.clone(),
                ..OpenOptions::default()
            };
            let whole_dir = copied(from, names);
            let whole = TimeSeries::open(&whole_dir.path().join(pattern), &options).unwrap();
            assert!(whole.steps_decoded() >= 1);
            for ranks in [2, 3, 5, 8] {
                let dir = copied(from, names);
                let path = dir.path().join(pattern);
                let scan = ScanByRanks {
                    ranks,
                    most_decoded: Default::default(),
                };
                let by_ranks = TimeSeries::open_scanned_by(&path, &options, &scan).unwrap();
                let what = format!("{} over {ranks} ranks, {selection:?}", from.display());
                assert_eq!(by_ranks.values(), whole.values(), "{what}");
                assert_eq!(by_ranks.steps_decoded(), 0, "{what}: no step read whole");
                // Each call's rank decoded at most its share of each step (CSV: by bytes, rows
                // of similar lengths: within a few records).
                for &(decoded, records) in scan.most_decoded.lock().unwrap().iter() {
                    let steps = names.len();
                    assert!(
                        decoded <= records.div_ceil(ranks) + 4 * steps,
                        "{what}: a rank decoded {decoded} of {records} records"
                    );
                }
                // The index the ranks wrote serves a later open, which reads nothing.
                let reopened = TimeSeries::open(&path, &options).unwrap();
                assert_eq!(reopened.steps_decoded(), 0, "{what}");
                assert_eq!(reopened.values(), whole.values(), "{what}");
            }
        }
    }
    // Smoothing lengths from neighbours: the ranks find them together; the statistics of
    // 'h_knn16' (its robust range and mean set the colours and the radius) are the whole
    // step's, bit for bit, and no step is read whole.
    let (from, names, pattern) = &series[1];
    let options = OpenOptions {
        smoothing: Some("knn:16".parse().unwrap()),
        ..OpenOptions::default()
    };
    let whole = TimeSeries::open(&copied(from, names).path().join(pattern), &options).unwrap();
    assert!(
        whole
            .values()
            .attributes
            .iter()
            .any(|a| a.name == "h_knn16")
    );
    for ranks in [3, 8] {
        let dir = copied(from, names);
        let scan = ScanByRanks {
            ranks,
            most_decoded: Default::default(),
        };
        let by_ranks =
            TimeSeries::open_scanned_by(&dir.path().join(pattern), &options, &scan).unwrap();
        assert_eq!(
            by_ranks.values(),
            whole.values(),
            "knn:16 over {ranks} ranks"
        );
        assert_eq!(by_ranks.steps_decoded(), 0, "knn:16 over {ranks} ranks");
    }
}

#[test]
fn a_ply_cut_anywhere_is_an_error_or_a_step_in_every_part_never_a_panic() {
    let dir = tempfile::tempdir().unwrap();
    let ascii = dir.path().join("ascii.ply");
    let mesh = AsciiMesh {
        before: true,
        vertex_list: true,
        faces: Some(4),
        ..PLYFILE_MESH
    };
    write_ascii_mesh(&ascii, 12, mesh);
    let binary = dir.path().join("binary.ply");
    write_binary_ply(&binary, 12, true, true, true);
    for path in [ascii, binary] {
        let bytes = std::fs::read(&path).unwrap();
        let body = bytes
            .windows(11)
            .position(|w| w == b"end_header\n")
            .unwrap()
            + 11;
        let cut = dir.path().join("cut.ply");
        for len in body..bytes.len() {
            std::fs::write(&cut, &bytes[..len]).unwrap();
            let step = the_step(&cut);
            for ranks in [1, 2, 3, 5] {
                for rank in 0..ranks {
                    if let Err(e) =
                        io::read_step_part(&step, &AttributeSelection::All, Part::new(rank, ranks))
                    {
                        assert!(e.to_string().contains("cut.ply"), "{e}");
                    }
                }
            }
        }
    }
}

/// The whole step's read against rank 1's and rank 3's of 4 on a 1M-vertex ascii mesh (2M
/// faces after the vertices) and a 1M binary PLY with a list in each vertex row: the median of
/// three, for docs/distributed.md. `cargo test --profile checked --test suite --
/// parallel_reads::ply_part_read_times --ignored --nocapture`.
#[test]
#[ignore = "a measurement (docs/distributed.md, PLY parts), not a guard"]
fn ply_part_read_times() {
    let dir = tempfile::tempdir().unwrap();
    let n = 1_000_000;
    let ascii = dir.path().join("mesh.ply");
    let mesh = AsciiMesh {
        faces: Some(2 * n),
        ..PLYFILE_MESH
    };
    write_ascii_mesh(&ascii, n, mesh);
    let binary = dir.path().join("lists.ply");
    write_binary_ply(&binary, n, false, false, true);
    for path in [&ascii, &binary] {
        let step = the_step(path);
        let time = |part: Option<Part>| {
            let mut times: Vec<f64> = (0..3)
                .map(|_| {
                    let t = std::time::Instant::now();
                    match part {
                        None => assert_eq!(
                            io::read_step(&step, &AttributeSelection::All)
                                .unwrap()
                                .len(),
                            n - 1
                        ),
                        Some(p) => assert_eq!(
                            io::read_step_part(&step, &AttributeSelection::All, p)
                                .unwrap()
                                .decoded,
                            n / 4
                        ),
                    }
                    t.elapsed().as_secs_f64()
                })
                .collect();
            times.sort_by(f64::total_cmp);
            times[1]
        };
        eprintln!(
            "{} ({} bytes): whole {:.3} s, rank 1 of 4 {:.3} s, rank 3 of 4 {:.3} s",
            path.file_name().unwrap().to_string_lossy(),
            std::fs::metadata(path).unwrap().len(),
            time(None),
            time(Some(Part::new(1, 4))),
            time(Some(Part::new(3, 4)))
        );
    }
}

/// The figures in docs/distributed.md: for 1M particles of each kind read by rows, the whole
/// step's read (vtkio's) against rank 1 of 4's part, one read each after a read to warm the
/// page cache. `cargo test --profile checked --test suite -- --ignored --nocapture
/// parallel_reads::inline_and_legacy_ascii_part_reads_timed`.
#[test]
#[ignore = "timing, for the docs: about a minute"]
fn inline_and_legacy_ascii_part_reads_timed() {
    let dir = tempfile::tempdir().unwrap();
    let n = 1_000_000;
    let binary = Inline {
        header_bytes: 8,
        zlib_block: None,
        codec: Codec::Zlib,
        ascii: None,
    };
    let mut files = Vec::new();
    for (label, how) in [
        (
            "inline base64 zlib (meshio, 32 KiB blocks)",
            Inline {
                zlib_block: Some(32768),
                ..binary
            },
        ),
        ("inline base64", binary),
        (
            "inline ascii, 6 a line",
            Inline {
                ascii: Some(6),
                ..binary
            },
        ),
    ] {
        let path = dir.path().join(format!("{}.vtu", files.len()));
        write_inline(&path, &[n], how, None);
        files.push((label, path));
    }
    let legacy = dir.path().join("legacy.vtk");
    write_legacy_ascii(&legacy, n, 9, "\n", true);
    files.push(("legacy ascii, 9 a line", legacy));
    for (label, path) in files {
        let step = the_step(&path);
        let all = AttributeSelection::All;
        io::read_step(&step, &all).unwrap();
        let t = std::time::Instant::now();
        let whole = io::read_step(&step, &all).unwrap();
        let whole_s = t.elapsed().as_secs_f64();
        let t = std::time::Instant::now();
        let part = io::read_step_part(&step, &all, Part::new(1, 4)).unwrap();
        let part_s = t.elapsed().as_secs_f64();
        assert_eq!(part.decoded, n / 4);
        let size = std::fs::metadata(&path).unwrap().len() as f64 / 1e6;
        eprintln!(
            "{label}: {size:.0} MB, whole {whole_s:.3} s ({} records), rank 1 of 4 {part_s:.3} s",
            whole.len()
        );
    }
}
