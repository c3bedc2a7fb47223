#![no_main]
//! Fuzzes the vtk_xml reader: any bytes must give a step or an error, never a panic, a hang or
//! an allocation the input does not justify (run with -malloc_limit_mb, see `cargo xtask fuzz`).

use libfuzzer_sys::fuzz_target;

mod contained_panics;

fuzz_target!(init: contained_panics::contain_vtkio_panics(), |data: &[u8]| {
    let _ = aarbf::io::read_bytes(aarbf::io::Format::VtkXml, data);
});
