//! `huddle fusion`: (being built).

use anyhow::{bail, Result};
use clap::Args;

#[derive(Args, Debug)]
pub struct FusionArgs {}

pub fn run(_args: FusionArgs) -> Result<()> {
    bail!("huddle fusion is not built yet")
}
