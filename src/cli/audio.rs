//! `huddle audio`: (being built).

use anyhow::{bail, Result};
use clap::Args;

#[derive(Args, Debug)]
pub struct AudioArgs {}

pub fn run(_args: AudioArgs) -> Result<()> {
    bail!("huddle audio is not built yet")
}
