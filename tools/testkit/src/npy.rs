//! Float32 `.npy` fixtures (made by the scripts of `tools/validate/`).

use std::path::Path;

/// A float32 `.npy` file's shape and values; panics (a test helper) when
/// the file is missing, not float32, or shorter than its shape.
pub fn read_npy_f32(path: &Path) -> (Vec<usize>, Vec<f32>) {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let header = ltm_codec::npy::read_npy_header(&mut &bytes[..]).unwrap();
    assert_eq!(
        header.dtype,
        ltm_codec::npy::NpyDtype::F32,
        "{}",
        path.display()
    );
    let values: Vec<f32> = bytes[header.data_offset..]
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
        .collect();
    assert_eq!(values.len(), header.shape.iter().product::<usize>());
    (header.shape, values)
}
