//! The tests that check a hot path allocates nothing: their own binary, because it installs a
//! counting global allocator (`common::Counting`) for every test in it.

mod common;
mod env_no_alloc;
mod update_no_alloc;

#[global_allocator]
static GLOBAL: common::Counting = common::Counting;
