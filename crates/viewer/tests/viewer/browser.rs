//! The page in headless Chromium: placeholder until written.
