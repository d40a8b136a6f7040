//! `ltm bake`.

use clap::Args;

/// Arguments of `ltm bake`.
#[derive(Args)]
pub struct BakeArgs {
    /// Scene description (TOML).
    pub scene: std::path::PathBuf,
}

pub fn run(_args: BakeArgs) -> anyhow::Result<()> {
    anyhow::bail!("bake is not implemented yet")
}
