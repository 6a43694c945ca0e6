//! Criterion benchmarks, one group per stage, live in `benches/`.
