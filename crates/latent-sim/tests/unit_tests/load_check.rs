//! The model loader's property, shared by the mutation test and the cargo-fuzz target
//! `fuzz/fuzz_targets/model.rs`: every input ends in a model or a typed error, never a panic,
//! and a model that loads builds a simulator (or a typed error) that steps (or fails typed).
//!
//! The first byte chooses what the rest is: even, a whole file; odd, a payload behind an intact
//! header ([`ReducedModel::from_payload`]): a fuzzer cannot forge the checksums that stand in
//! front of the decoder and the model's checks.

use latent_sim::{Interactive, ReducedModel};

pub fn check(data: &[u8]) {
    let Some((&mode, rest)) = data.split_first() else {
        return;
    };
    let loaded = if mode % 2 == 0 {
        ReducedModel::from_bytes(rest)
    } else {
        ReducedModel::from_payload(rest)
    };
    if let Ok(model) = loaded
        && let Ok(mut sim) = model.simulator()
    {
        let _ = sim.step();
    }
}
