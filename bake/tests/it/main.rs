//! ltm-bake's integration tests, one binary (each file a module), so the
//! dependency graph is linked once. `common` holds their shared helpers.

mod atlas;
mod bad_input;
mod bake_store;
mod brdf;
mod common;
mod golden;
mod hostile;
mod meshes;
mod scene_doc;
mod texture;
mod transport;
