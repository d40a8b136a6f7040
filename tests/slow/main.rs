//! The facade's slow tier: end-to-end tests against the Mitsuba 3 fixtures.
//! `cargo test --workspace` (and CI) runs them with the fast tier;
//! `cargo fast` leaves them out.

mod nearfield;
