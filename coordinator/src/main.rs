//! `coordinator`: parses the command line and hands over to the library.

use std::process::ExitCode;

use clap::Parser;
use coordinator::cli::{Cli, run};

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
