//! The subcommands.

mod bench;
mod bench_fly;
mod bench_prep;
mod bench_render;
mod fly;
mod info;
mod phantom;
mod prep;
mod render;

use std::path::PathBuf;

use clap::{Parser, Subcommand};

#[derive(Parser, Debug)]
#[command(name = "voyage", version, about = "Interactive virtual colonoscopy (Hong et al., Virtual Voyage, 1997)")]
pub struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Describe a CT volume: dims, spacing, orientation, HU range, series (never patient name or ID).
    Info(info::InfoArgs),
    /// Make a synthetic phantom with ground truth (the paper's pipe, or a full colon).
    Phantom(phantom::PhantomArgs),
    /// Make the colon phantom in ./voyage-demo and describe it (the default job).
    Demo {
        /// Folder to write the phantom into.
        #[arg(long, default_value = "voyage-demo")]
        out: PathBuf,
        /// Make the small (≈128³) phantom instead of the full-size one.
        #[arg(long)]
        small: bool,
    },
    /// Preprocess a CT or lumen mask: colon, distance fields, centerline, surface, cells.
    Prep(prep::PrepArgs),
    /// Fly the camera through the colon automatically (both ways by default).
    Fly(fly::FlyArgs),
    /// Benchmarks against reference libraries.
    Bench(bench::BenchArgs),
    /// One endoscopic frame to a PNG: frame N of the automatic flight, or a given pose.
    Render(render::RenderArgs),
    /// Every frame of an automatic flight as PNGs, and an .mp4 when ffmpeg is installed.
    Movie(render::MovieArgs),
}

pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Info(a) => info::run(&a),
        Command::Phantom(a) => phantom::run(&a),
        Command::Demo { out, small } => phantom::demo(&out, small),
        Command::Prep(a) => prep::run(&a),
        Command::Fly(a) => fly::run(&a),
        Command::Bench(a) => bench::run(&a),
        Command::Render(a) => render::render(&a),
        Command::Movie(a) => render::movie(&a),
    }
}
