//! The subcommands.

#[cfg(feature = "bench")]
mod bench;
mod coverage;
mod fly;
mod info;
mod phantom;
pub mod prep;
pub mod render;
mod report;

use std::path::PathBuf;

use clap::{Parser, Subcommand};

#[derive(Parser, Debug)]
#[command(
    name = "voyage",
    version,
    about = "Interactive virtual colonoscopy (Hong et al., Virtual Voyage, 1997)"
)]
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
    /// Open the navigator window on a CT or a lumen mask (the main command).
    View(crate::gui::ViewArgs),
    /// Open the navigator on the built-in colon phantom, made on the fly; with --headless,
    /// write the phantom to a folder, preprocess it and compare with its truth instead.
    Demo {
        /// Make the small (≈128³) phantom instead of the full-size one.
        #[arg(long)]
        small: bool,
        /// No window: write the phantom into --out, read it back, preprocess it and compare
        /// the result with the phantom's truth.
        #[arg(long)]
        headless: bool,
        /// Folder to write the phantom into (with --headless).
        #[arg(long, default_value = "voyage-demo")]
        out: PathBuf,
        /// The phantom supine and prone, as an exam scans it twice (with tagged fluid and
        /// stool): both open, linked; O switches between them at the same place.
        #[arg(long, conflicts_with = "headless")]
        pair: bool,
        #[command(flatten)]
        window: crate::gui::WindowArgs,
    },
    /// Preprocess a CT or lumen mask: colon, distance fields, centerline, surface, cells.
    Prep(prep::PrepArgs),
    /// Fly the camera through the colon automatically (both ways by default).
    Fly(fly::FlyArgs),
    /// How much of the mucosa the automatic reading shows: one way, both ways, and after a
    /// review of every unseen patch (with a pose that shows each).
    Coverage(coverage::CoverageArgs),
    /// The reading's report (report.html) from the findings the window exported: sizes,
    /// segments, C-RADS, each marker's view, and the coverage of a two-way reading.
    Report(report::ReportArgs),
    /// Benchmarks against reference libraries.
    #[cfg(feature = "bench")]
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
        Command::View(a) => crate::gui::view(&a),
        Command::Demo {
            small,
            headless: true,
            out,
            ..
        } => phantom::demo(&out, small),
        Command::Demo {
            small,
            pair,
            window,
            ..
        } => crate::gui::demo(&window, small, pair),
        Command::Prep(a) => prep::run(&a),
        Command::Fly(a) => fly::run(&a),
        Command::Coverage(a) => coverage::run(&a),
        Command::Report(a) => report::run(&a),
        #[cfg(feature = "bench")]
        Command::Bench(a) => bench::run(&a),
        Command::Render(a) => render::render(&a),
        Command::Movie(a) => render::movie(&a),
    }
}
