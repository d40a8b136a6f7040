//! Any file given to the raw-store reader must open with an error or be
//! read whole (every block verified, every row reached), never panic.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    ltm_fuzz::read_raw_store(data);
});
