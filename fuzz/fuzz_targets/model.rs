//! The model file loader (`latent_sim::ReducedModel::from_bytes`): every input ends in a model or
//! a typed error, never a panic; a model that loads is built into a simulator and stepped once
//! (the property of `crates/latent-sim/tests/unit_tests/load_check.rs`).
#![no_main]

#[path = "../../crates/latent-sim/tests/unit_tests/load_check.rs"]
mod load_check;

libfuzzer_sys::fuzz_target!(|data: &[u8]| load_check::check(data));
