//! Test helpers shared by the tests of the ltm crates, used only as a
//! dev-dependency: a raw-store writer, a runner for the `ltm` binary, a
//! small disk that fills up, a deterministic random number generator and
//! a reader of float32 `.npy` fixtures and the 1D Haar basis of the
//! near-field couplings.

#![deny(unsafe_code)]

mod bombs;
mod cli;
mod disk;
pub mod haar;
mod npy;
mod raw;
mod rng;
mod scene;

pub use bombs::ltm_claiming_8192;
pub use cli::{run, run_ok, run_output, Run};
pub use disk::{assert_disk_full_error, SmallDisk};
pub use npy::read_npy_f32;
pub use raw::{block_bytes, write_raw};
pub use rng::Rng;
pub use scene::{blob_obj, scene_toml, TEXTURE_SPHERE_16};
