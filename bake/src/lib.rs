//! `ltm-bake`: ray-traces a scene's light-transport matrix — one row per
//! pixel, one column per cubemap texel of a distant environment — and
//! streams it into the raw store of [`ltm_codec::raw`].
//!
//! A scene is a TOML file ([`scene`]) naming OBJ/PLY meshes, quads,
//! Lambertian and glossy materials ([`material`]), a pinhole camera and the
//! lighting resolution. [`Scene::build`] loads it into a BVH traced with
//! watertight ray/triangle intersection and checks that the camera is not
//! inside geometry ([`inside`]); [`bake`] computes the rows ([`transport`]
//! defines them precisely) in parallel blocks and writes them to
//! `PATH.partial`, resuming an interrupted bake of the same inputs
//! ([`identity`]), then renames the file to `PATH`.
//!
//! ```no_run
//! use ltm_bake::{bake, BakeOptions, Scene, SceneDesc};
//! let desc = SceneDesc::load("scene.toml".as_ref())?;
//! let scene = Scene::build(&desc)?;
//! bake(&scene, "scene.raw".as_ref(), &BakeOptions::default(), ltm_codec::Progress::NONE)?;
//! # Ok::<(), ltm_bake::BakeError>(())
//! ```

#![forbid(unsafe_code)]
#![warn(missing_docs)]

mod atlas;
mod bake;
mod bvh;
mod error;
pub mod identity;
pub mod inside;
mod intersect;
pub mod material;
mod mesh;
mod packet;
pub mod plane;
mod ply;
mod rows;
pub mod sampling;
pub mod scene;
mod sphere;
pub mod texture;
pub mod transport;
mod world;

pub use atlas::AtlasQuality;
pub use bake::{
    bake, bake_part, raw_header, receiver_mesh, row_surface, BakeOptions, BakeReport, BlockBaker,
    DEFAULT_BLOCK_BYTES,
};
pub use error::{BakeError, Result};
pub use inside::INSIDE_LIMIT;
pub use ltm_codec::raw::{RestartReason, ResumeState};
pub use plane::{LightPlane, PlaneRow};
pub use rows::{RowSample, RowSource};
pub use scene::{LightPlaneDesc, Overrides, Receivers, SceneDesc, DEFAULT_SCENE_TOML};
pub use texture::{TexelMap, TexelStats};
pub use transport::RowStats;
pub use world::{Camera, Hit, MeshStats, Scene, SceneStats};
