//! Gmsh `.msh` reader from MSH 4.1 ASCII and binary seeds (the reader's 4.1 parser): every input
//! ends in a valid mesh or a typed error with file, line (byte offset in binary files) and reason.
#![no_main]

#[allow(dead_code)]
#[path = "../../crates/fem-core/tests/fuzz_readers/check.rs"]
mod check;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    if let Err(violation) = check::check(check::Reader::Gmsh, data) {
        panic!("{violation}");
    }
});
