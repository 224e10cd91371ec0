//! `huddle completions SHELL` and `huddle man`: shell completions (clap_complete) and the
//! man page (clap_mangen), both generated from the same clap definitions as the parser.

use std::io::Write;

use anyhow::{Context, Result};
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
pub struct ManArgs {
    /// Write one page per subcommand into this directory (`huddle.1`, `huddle-get.1`,
    /// `huddle-set.1`, ...) instead of printing the top page: `huddle man --dir
    /// ~/.local/share/man/man1`, then `man huddle-set`.
    #[arg(long, value_name = "DIR")]
    pub dir: Option<std::path::PathBuf>,
}

/// Writes the completion script for `args.shell` to stdout.
pub fn completions(args: CompletionsArgs, mut cmd: clap::Command) -> Result<()> {
    let mut buf = Vec::new();
    clap_complete::generate(args.shell, &mut cmd, "huddle", &mut buf);
    std::io::stdout().lock().write_all(&buf)?;
    Ok(())
}

/// Writes the man page (roff, section 1) to stdout: `huddle man > huddle.1`; with
/// `--dir`, every subcommand's page into that directory.
pub fn man(args: ManArgs, cmd: clap::Command) -> Result<()> {
    if let Some(dir) = args.dir {
        std::fs::create_dir_all(&dir)
            .with_context(|| format!("cannot create {}", dir.display()))?;
        clap_mangen::generate_to(cmd, &dir)
            .with_context(|| format!("cannot write man pages into {}", dir.display()))?;
        return Ok(());
    }
    let mut buf = Vec::new();
    clap_mangen::Man::new(cmd).render(&mut buf)?;
    std::io::stdout().lock().write_all(&buf)?;
    Ok(())
}
