//! The `splatray` command line (its arguments and commands: `cli::app`).

mod cli;

use std::process::ExitCode;

fn main() -> ExitCode {
    ExitCode::from(cli::app::run(std::env::args_os()))
}
