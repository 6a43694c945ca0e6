//! Gmsh `.msh` reader from MSH 2.2 ASCII seeds (the reader's own line parser): every input
//! ends in a valid mesh or a typed error with file, line (byte offset in binary files) and reason.
#![no_main]

#[allow(dead_code)]
#[path = "../../crates/fem-core/tests/fuzz_readers/check.rs"]
mod check;

libfuzzer_sys::fuzz_target!(
    init: {
        // libfuzzer-sys aborts on every panic, even one caught later. The reader contains
        // panics inside mshio (catch_unwind) and reports them as parse errors, so let those
        // unwind; any other panic still aborts and is reported as a crash.
        let abort = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if !info.location().is_some_and(|l| l.file().contains("mshio")) {
                abort(info);
            }
        }));
    },
    |data: &[u8]| {
        if let Err(violation) = check::check(check::Reader::Gmsh, data) {
            panic!("{violation}");
        }
    }
);
