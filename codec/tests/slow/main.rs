//! ltm-codec's slow tier: integration tests that take many seconds each.
//! `cargo test --workspace` (and CI) runs them with the fast tier;
//! `cargo fast` leaves them out.

mod shard;
