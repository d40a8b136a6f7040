//! Any byte string given to the rotation cache reader (`RotationSet::
//! from_bytes`, what `ltm render --rotation-cache` reads) must give a set or
//! an error, never a panic; the bytes are tried as given and with their
//! trailing CRC rewritten, so that mutations reach the structural checks
//! behind the checksum. A set that parses writes back the same bytes.
#![no_main]

use libfuzzer_sys::fuzz_target;
use ltm_codec::Limits;
use ltm_relight::rotation::RotationSet;

fuzz_target!(|data: &[u8]| {
    let limits = Limits::with_max_alloc(64 << 20);
    let mut fixed = data.to_vec();
    if fixed.len() >= 4 {
        let body = fixed.len() - 4;
        let crc = crc32fast::hash(&fixed[..body]);
        fixed[body..].copy_from_slice(&crc.to_le_bytes());
    }
    for bytes in [data, &fixed[..]] {
        if let Ok(set) = RotationSet::from_bytes(bytes, &limits) {
            assert_eq!(set.to_bytes(), bytes, "a parsed cache writes back differently");
        }
    }
});
