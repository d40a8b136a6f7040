//! The `ltm` binary's slow tier: tests that need more than Rust (headless
//! Chromium, a local Slurm, the Mitsuba 3 fixtures) or take many seconds
//! each (the memory budget under an address-space limit, the server under
//! thousands of hostile connections). CI runs them with the fast tier
//! (`cargo test --workspace`); `cargo fast` leaves them out.

#[path = "../view_support/mod.rs"]
mod view_support;

mod atlas_mitsuba;
mod budget;
mod glossy_mitsuba;
mod point;
mod slurm;
mod view_browser;
mod view_server;
