//! The viewer's tests, one binary: the protocol driven by a Rust client, and the page driven by
//! headless Chromium.

mod browser;
mod common;
mod protocol;
