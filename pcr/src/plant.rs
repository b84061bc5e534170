//! `pcr plant` (not implemented yet: see the open issue).

/// Arguments of `pcr plant`.
#[derive(clap::Args)]
pub struct Args {}

/// Runs `pcr plant`.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`pcr plant` is not implemented yet")
}
