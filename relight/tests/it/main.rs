//! ltm-relight's integration tests, one binary (each file a module), so the
//! dependency graph is linked once.

mod basis;
mod envmap;
mod frames;
mod front_door;
mod glossy;
mod lazy;
mod pca;
mod reference;
