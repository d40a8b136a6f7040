//! Like `ltm_decode`, but first rewrites every CRC the input claims
//! (`repair_checksums`) so that mutations get past the checksums and
//! exercise the structural checks behind them.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let mut bytes = data.to_vec();
    ltm_codec::container::repair_checksums(&mut bytes);
    ltm_fuzz::decode_through_public_api(&bytes);
});
