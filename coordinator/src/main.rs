//! `coordinator`: parses the command line and hands over to the library.

use std::process::ExitCode;

use clap::Parser;
use coordinator::cli::{Cli, run};

fn main() -> ExitCode {
    let cli = Cli::parse();
    // A PHOTONFARM_SIMD this machine cannot run is refused before any work.
    if let Err(e) = photonfarm::engine::Backend::from_env() {
        eprintln!("error: {e}");
        return ExitCode::FAILURE;
    }
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
