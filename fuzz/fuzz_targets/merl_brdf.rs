//! Any byte string given to the measured BRDF reader
//! (`MeasuredBrdf::from_bytes`, what `ltm render --brdf merl:PATH` reads)
//! must give a table or an error, never a panic.
#![no_main]

use libfuzzer_sys::fuzz_target;
use ltm_codec::Limits;
use ltm_relight::rotation::MeasuredBrdf;

fuzz_target!(|data: &[u8]| {
    let limits = Limits::with_max_alloc(64 << 20);
    let _ = MeasuredBrdf::from_bytes("fuzz", data, &limits);
});
