//! `pcr ik`, `pcr fk`, `pcr workspace` (in progress).

/// Arguments of `pcr ik`.
#[derive(clap::Args)]
pub struct IkArgs {}
/// Arguments of `pcr fk`.
#[derive(clap::Args)]
pub struct FkArgs {}
/// Arguments of `pcr workspace`.
#[derive(clap::Args)]
pub struct WorkspaceArgs {}

/// Runs `pcr ik`.
pub fn run_ik(_a: IkArgs) -> anyhow::Result<()> {
    anyhow::bail!("not implemented yet")
}
/// Runs `pcr fk`.
pub fn run_fk(_a: FkArgs) -> anyhow::Result<()> {
    anyhow::bail!("not implemented yet")
}
/// Runs `pcr workspace`.
pub fn run_workspace(_a: WorkspaceArgs) -> anyhow::Result<()> {
    anyhow::bail!("not implemented yet")
}
