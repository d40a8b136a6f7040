//! The one front door: [`open`] takes any `.ltm` file, from a path or from
//! bytes in memory, and returns the relighter of its mode behind the
//! [`Relight`] trait, charged to one memory budget.

use crate::error::Result;
use crate::frame::Relight;
use crate::pca::PcaRelighter;
use crate::relighter::Relighter;
use ltm_codec::{Limits, LtmFile};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Where an `.ltm` file comes from: a path (read whole into memory) or its bytes
/// (from a network, an archive, a wasm host).
#[derive(Clone, Debug)]
pub enum Source {
    /// A file on disk.
    Path(PathBuf),
    /// A whole file held in memory.
    Bytes(Arc<[u8]>),
}

impl Source {
    /// Opens and validates the file ([`LtmFile::open_with_limits`] or
    /// [`LtmFile::from_bytes`]), charging its bytes (a path's copy) and tables
    /// to `limits`.
    pub fn open(self, limits: &Limits) -> Result<LtmFile> {
        Ok(match self {
            Source::Path(p) => LtmFile::open_with_limits(&p, limits)?,
            Source::Bytes(b) => LtmFile::from_bytes(b, limits)?,
        })
    }
}

impl From<&Path> for Source {
    fn from(p: &Path) -> Source {
        Source::Path(p.to_path_buf())
    }
}

impl From<PathBuf> for Source {
    fn from(p: PathBuf) -> Source {
        Source::Path(p)
    }
}

impl From<&PathBuf> for Source {
    fn from(p: &PathBuf) -> Source {
        Source::Path(p.clone())
    }
}

impl From<Vec<u8>> for Source {
    fn from(b: Vec<u8>) -> Source {
        Source::Bytes(b.into())
    }
}

impl From<Arc<[u8]>> for Source {
    fn from(b: Arc<[u8]>) -> Source {
        Source::Bytes(b)
    }
}

impl From<&[u8]> for Source {
    fn from(b: &[u8]) -> Source {
        Source::Bytes(b.into())
    }
}

/// Opens any `.ltm` file as a relighter: [`PcaRelighter`] for `pca` files,
/// the wavelet [`Relighter`] otherwise. The file, the relighter's buffers
/// and every frame it makes are charged to `limits` (clones share one
/// budget: a program opening several files passes clones of one
/// `Limits`). [`Relight::term_basis`] and [`Relight::face_res`] say how to
/// light it.
pub fn open(source: impl Into<Source>, limits: &Limits) -> Result<Box<dyn Relight + Send + Sync>> {
    open_file(source.into().open(limits)?, limits)
}

/// [`open`] for a file already opened (whose metadata or surface data the
/// caller reads too): the relighter of its mode, charged to `limits`.
pub fn open_file(file: LtmFile, limits: &Limits) -> Result<Box<dyn Relight + Send + Sync>> {
    if file.pca().is_some() {
        Ok(Box::new(PcaRelighter::new(&file, limits)?))
    } else {
        Ok(Box::new(Relighter::new(file, limits)?))
    }
}
