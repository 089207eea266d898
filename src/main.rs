//! The `splatray` command line: the library's [`splatray::run_cli`] (its
//! arguments and commands are the library's private `cli` module).

use std::process::ExitCode;

fn main() -> ExitCode {
    ExitCode::from(splatray::run_cli(std::env::args_os()))
}
