//! What every command receives besides its own arguments.

use ltm_codec::Limits;

/// The run's context, built once from the global flags and passed to every
/// command.
#[derive(Clone, Debug)]
pub struct Ctx {
    /// The decoding limits of this run (`--max-memory`), passed to every
    /// library call that opens a file.
    pub limits: Limits,
}

impl Ctx {
    /// A context with these limits.
    pub fn new(limits: Limits) -> Ctx {
        Ctx { limits }
    }

    /// The decoding limits of this run.
    pub fn limits(&self) -> &Limits {
        &self.limits
    }
}
