//! The `ltm` binary's slow tier: tests that take minutes or need more than
//! Rust (headless Chromium, a local Slurm, the Mitsuba 3 fixtures). CI runs
//! them with the fast tier (`cargo test --workspace`); `cargo fast` leaves
//! them out.

#[path = "../view_support/mod.rs"]
mod view_support;

mod atlas_mitsuba;
mod glossy_mitsuba;
mod slurm;
mod view_browser;
