//! The library's integration tests, one binary (modules as ripgrep's tests/ has them); the
//! tests that count allocations are in tests/alloc, which installs a counting global allocator.

mod bad_inputs;
mod code_shape;
mod curriculum;
mod degenerate;
mod determinism;
mod docs_links;
mod float_roundtrip;
mod k_oracle;
mod learning;
mod nan_guard;
mod policy_portable;
mod props;
mod report_synthetic;
mod robot_k_oracle;
mod shield;
