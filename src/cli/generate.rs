//! `huddle completions SHELL` and `huddle man`: shell completions (clap_complete) and the
//! man page (clap_mangen), both generated from the same clap definitions as the parser.

use std::io::Write;

use anyhow::Result;
use clap::Args;
use clap_complete::Shell;

/// `huddle completions SHELL`
#[derive(Args, Debug)]
pub struct CompletionsArgs {
    /// The shell: bash, zsh, fish, elvish or powershell.
    pub shell: Shell,
}

/// `huddle man`
#[derive(Args, Debug)]
pub struct ManArgs {}

/// Writes the completion script for `args.shell` to stdout.
pub fn completions(args: CompletionsArgs, mut cmd: clap::Command) -> Result<()> {
    let mut buf = Vec::new();
    clap_complete::generate(args.shell, &mut cmd, "huddle", &mut buf);
    std::io::stdout().lock().write_all(&buf)?;
    Ok(())
}

/// Writes the man page (roff, section 1) to stdout: `huddle man > huddle.1`.
pub fn man(_args: ManArgs, cmd: clap::Command) -> Result<()> {
    let mut buf = Vec::new();
    clap_mangen::Man::new(cmd).render(&mut buf)?;
    std::io::stdout().lock().write_all(&buf)?;
    Ok(())
}
