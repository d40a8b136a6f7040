//! Any byte string given to the `.npy` header parser must give a header or
//! an error, never a panic.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let mut r = data;
    if let Ok(h) = ltm_codec::npy::read_npy_header(&mut r) {
        assert!(h.data_offset <= 12 + (1 << 16));
    }
});
