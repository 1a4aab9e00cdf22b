//! The navigator (paper §5, Fig. 8): `voyage view INPUT` and `voyage demo` open a window
//! with the endoscopic view, the scout and the slices over one study; the study is opened
//! in the background while the window shows the progress.

mod app;
mod corrections;
mod coverage;
mod endoscopy;
mod frame_times;
mod loader;
mod pixels;
mod positions;
mod report;
mod scout;
mod session;
mod slices;

use std::{
    path::PathBuf,
    sync::{Arc, Mutex},
};

use anyhow::{Context as _, bail};
use clap::Args;

use app::{App, Outcome, Script};
pub use loader::Source;

use crate::open::{InputArgs, PointArgs};

/// Options of the window, shared by `view` and `demo`.
#[derive(Args, Debug, Clone, Default)]
pub struct WindowArgs {
    /// Save a PNG of the whole window after --after-frames frames (and any --script), then
    /// close it.
    #[arg(long)]
    pub screenshot: Option<PathBuf>,
    /// Frames to draw, once the study is open, before the screenshot.
    #[arg(long, default_value_t = 60)]
    pub after_frames: u64,
    /// A JSON list of actions to carry out once the study is open (README: "Scripted
    /// actions").
    #[arg(long)]
    pub script: Option<PathBuf>,
    /// Write the navigator's state on closing (pose, markers, measurements, frame times) as
    /// JSON to this file.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Draw the endoscopic view with the CPU reference renderer instead of the GPU.
    #[arg(long)]
    pub cpu: bool,
    /// Window size in pixels, WIDTHxHEIGHT.
    #[arg(long, default_value = "1280x800", value_parser = parse_size)]
    pub size: (u32, u32),
    /// Open with the automatic flight paused.
    #[arg(long)]
    pub paused: bool,
}

fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("{s}: expected WIDTHxHEIGHT, e.g. 1280x800"))?;
    let parse = |v: &str| {
        v.trim()
            .parse::<u32>()
            .ok()
            .filter(|n| (320..=8192).contains(n))
    };
    match (parse(w), parse(h)) {
        (Some(w), Some(h)) => Ok((w, h)),
        _ => Err(format!(
            "{s}: width and height must be whole numbers from 320 to 8192"
        )),
    }
}

#[derive(Args, Debug)]
pub struct ViewArgs {
    /// A CT (DICOM folder or file, NIfTI, MetaImage, NRRD) or a lumen mask (0/1 labels).
    /// Without it the window opens empty; open a file from there.
    pub input: Option<PathBuf>,
    /// Treat the input as a lumen mask, every non-zero label lumen (default: detected when it
    /// holds 0 and one other value, as 0/1 or 0/255; labels 0/1/2... need it).
    #[arg(long)]
    pub mask: bool,
    /// DICOM: which series to load when the folder holds several.
    #[arg(long)]
    pub series: Option<String>,
    #[command(flatten)]
    pub points: PointArgs,
    #[command(flatten)]
    pub window: WindowArgs,
}

pub fn view(a: &ViewArgs) -> anyhow::Result<()> {
    let source = a.input.clone().map(|input| {
        Source::File(InputArgs {
            input,
            mask: a.mask,
            series: a.series.clone(),
            points: a.points.clone(),
        })
    });
    run(source, &a.window)
}

pub fn demo(window: &WindowArgs, small: bool, pair: bool) -> anyhow::Result<()> {
    run(
        Some(Source::Phantom {
            small,
            pair,
            points: Default::default(),
        }),
        window,
    )
}

/// Opens the window and returns when it is closed. In screenshot and script runs, errors met
/// on the way (the study could not be opened, a file could not be written) make the
/// command fail after the window closes.
fn run(source: Option<Source>, w: &WindowArgs) -> anyhow::Result<()> {
    // A script that cannot be read or has an unknown step is refused before the window
    // opens: an unattended run would otherwise wait with nothing to do.
    let script = w.script.as_deref().map(Script::load).transpose()?;
    let outcome = Arc::new(Mutex::new(Outcome::default()));
    let options = eframe::NativeOptions {
        viewport: egui::ViewportBuilder::default()
            .with_inner_size([w.size.0 as f32, w.size.1 as f32])
            .with_min_inner_size([640.0, 480.0])
            .with_title("voyage"),
        renderer: eframe::Renderer::Wgpu,
        // The endoscopic view is drawn inside egui's render pass and needs a depth buffer.
        depth_buffer: 32,
        // Dithering costs every pixel of the window a little more shading on a CPU driver and
        // is not needed for a flat dark interface.
        dithering: false,
        ..Default::default()
    };
    let (args, out) = (w.clone(), outcome.clone());
    eframe::run_native(
        "voyage",
        options,
        Box::new(move |cc| Ok(Box::new(App::new(cc, source, args, script, out)))),
    )
    .map_err(|e| {
        anyhow::anyhow!(
            "cannot open the window: {e} (a display is needed: set DISPLAY, or run under xvfb-run)"
        )
    })?;
    let o = outcome
        .lock()
        .map_err(|_| anyhow::anyhow!("the window's state was lost"))?;
    if let (Some(path), Some(report)) = (&w.report, &o.report) {
        let text = serde_json::to_string_pretty(report)? + "\n";
        voyage_io::write_atomic(path, |f| std::io::Write::write_all(f, text.as_bytes()))
            .with_context(|| path.display().to_string())?;
    }
    let unattended = w.screenshot.is_some() || w.script.is_some();
    if unattended && !o.errors.is_empty() {
        bail!("{}", o.errors.join("; "));
    }
    Ok(())
}
