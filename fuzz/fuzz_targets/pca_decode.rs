//! `pca` files: a valid small `pca` file (made once, in process) is mutated
//! by the input, read as (offset `u16`, xor byte) triples applied to the
//! bytes after the header, every CRC is rewritten (`repair_checksums`) so
//! that the mutations of the PCA chunks (shapes, scales, varint streams,
//! zstd frames) reach the checks behind the checksums, and the result is
//! opened with `LtmFile::from_bytes` and reconstructed.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some(mut bytes) = ltm_fuzz::small_pca_file() else {
        return;
    };
    let body = bytes.len().saturating_sub(24).max(1);
    for m in data.chunks_exact(3) {
        let at = 24 + u16::from_le_bytes([m[0], m[1]]) as usize % body;
        if let Some(b) = bytes.get_mut(at) {
            *b ^= m[2];
        }
    }
    ltm_codec::container::repair_checksums(&mut bytes);
    ltm_fuzz::decode_through_public_api(&bytes);
});
