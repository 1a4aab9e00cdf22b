//! `voyage`: interactive virtual colonoscopy. This binary is a thin layer over
//! `voyage-core`: it parses the command line, calls the library, and prints results.
//! No algorithm lives here.

mod cmd;

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    voyage_core::error::install_panic_hook();
    let cli = cmd::Cli::parse();
    match cmd::run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // One line: the chain of causes joined, naming the file where there is one.
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
