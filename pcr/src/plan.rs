//! `pcr plan` (not implemented yet: see the open issue).

/// Arguments of `pcr plan`.
#[derive(clap::Args)]
pub struct Args {}

/// Runs `pcr plan`.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`pcr plan` is not implemented yet")
}
