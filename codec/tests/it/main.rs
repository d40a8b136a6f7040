//! ltm-codec's integration tests, one binary (each file a module), so the
//! dependency graph is linked once.

mod codec;
mod hostile;
mod mesh;
mod nearfield;
mod npy;
mod pca;
mod surface;
mod wavelet;
