//! `voyage`: interactive virtual colonoscopy. This binary is a thin layer over
//! `voyage-core`: it parses the command line, calls the library, and prints results.
//! No algorithm lives here.

mod cmd;
mod gui;
mod open;

use std::process::ExitCode;

use clap::Parser;

/// Bounds what a DICOM parser may allocate while it reads one file (`voyage_io`'s
/// `GuardedAllocator`); the system allocator otherwise.
#[global_allocator]
static ALLOCATOR: voyage_io::GuardedAllocator = voyage_io::GuardedAllocator;

fn main() -> ExitCode {
    quiet_vulkan_layer();
    voyage_io::install_panic_hook();
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

/// Mesa's device-select Vulkan layer prints "XDG_RUNTIME_DIR is invalid" on machines without
/// a desktop session (CI, servers) although nothing is wrong; wgpu chooses the adapter
/// itself, so the layer is not needed.
fn quiet_vulkan_layer() {
    if std::env::var_os("NODEVICE_SELECT").is_none()
        && std::env::var_os("XDG_RUNTIME_DIR").is_none()
    {
        // SAFETY: first thing in main, before any other thread exists.
        unsafe { std::env::set_var("NODEVICE_SELECT", "1") };
    }
}
