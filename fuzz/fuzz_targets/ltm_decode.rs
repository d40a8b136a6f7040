//! Any byte string given to the `.ltm` decoder must give a value or an
//! error, never a panic, a hang or an unbounded allocation.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    ltm_fuzz::decode_through_public_api(data);
});
