//! Legacy VTK reader (classic and 5.1 cell layouts): every input ends in a valid mesh or a typed
//! error with file, line and reason.
#![no_main]

#[allow(dead_code)]
#[path = "../../crates/fem-core/tests/fuzz_readers/check.rs"]
mod check;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    if let Err(violation) = check::check(check::Reader::Vtk, data) {
        panic!("{violation}");
    }
});
