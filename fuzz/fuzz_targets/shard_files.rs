//! Any file given to the readers of a sharded compression's files (coded
//! parts, plans, analysis parts) must give a value or an error, never a
//! panic.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    ltm_fuzz::read_shard_files(data);
});
