#![no_main]
//! Fuzzes the ply reader: any bytes must give a step or an error, never a panic, a hang or
//! an allocation the input does not justify (run with -malloc_limit_mb, see `cargo xtask fuzz`).

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = aarbf::io::read_bytes(aarbf::io::Format::Ply, data);
});
