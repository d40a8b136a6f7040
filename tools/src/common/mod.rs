//! What the commands share: the run's context, argument groups and value
//! parsers, file checks and atomic outputs, progress bars, the assets and
//! the bake cache.

mod args;
mod assets;
mod bake_cache;
mod ctx;
pub mod exposure;
mod output;
mod paths;
pub mod progress;
pub mod ranges;
pub mod shard;
pub mod size;

pub use args::{commit_all, describe_terms, ImageOutput, TermsArgs};
pub use assets::{assets_dir, env_maps, load_maps, map_files};
pub use bake_cache::bake_cached;
pub use ctx::Ctx;
pub use exposure::Exposure;
pub use output::write_atomic;
pub use paths::{claim_files, claim_files_and_cache, claim_folder};
