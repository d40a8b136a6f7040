//! The `ltm` binary's fast tier of integration tests, one binary (each file
//! a module), so the dependency graph is linked once. The tests that take
//! many seconds or need Chromium, Slurm or the Mitsuba fixtures are the
//! `slow` binary (`tools/tests/slow/`); `cargo test --workspace` runs both.

#[path = "../view_support/mod.rs"]
mod view_support;

mod area_light;
mod cli;
mod cli_usability;
mod hostile;
mod readers;
mod readme;
mod reliability;
mod shard;
mod shard_compress;
mod texture_cli;
mod view_api;
