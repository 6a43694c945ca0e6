//! MEDIT `.mesh` reader: every input ends in a valid mesh or a typed error with file, line and
//! reason (the property of `crates/fem-core/tests/fuzz_readers/check.rs`).
#![no_main]

#[allow(dead_code)]
#[path = "../../crates/fem-core/tests/fuzz_readers/check.rs"]
mod check;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    if let Err(violation) = check::check(check::Reader::Medit, data) {
        panic!("{violation}");
    }
});
