#![no_main]
//! Fuzzes the `.pvd` collection parser: any bytes must give a list of entries or an error,
//! never a panic, a hang or an allocation the input does not justify.

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = aarbf::io::pvd::parse(data);
});
