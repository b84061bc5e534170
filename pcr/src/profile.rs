//! `pcr profile` (not implemented yet: see the open issue).

/// Arguments of `pcr profile`.
#[derive(clap::Args)]
pub struct Args {}

/// Runs `pcr profile`.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`pcr profile` is not implemented yet")
}
