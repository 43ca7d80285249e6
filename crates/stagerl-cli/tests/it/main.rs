//! The command-line tool's integration tests, one binary (modules as ripgrep's tests/ has them).

mod agent_config_cli;
mod bad_inputs_cli;
mod bench_obstacles;
mod cli;
mod common;
mod concurrency;
mod corrupt_checkpoint;
mod edited_config;
mod export_cli;
mod output_errors;
mod plan_cli;
mod report_cli;
mod reproduce;
mod resume;
mod shield_cli;
mod sigterm_resume;
mod simd_levels;
mod special_files;
mod stale_results;
mod stops;
mod tensorboard_resume;
mod view_browser;
