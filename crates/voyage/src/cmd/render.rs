//! `voyage render` (one endoscopic frame to a PNG) and `voyage movie` (every frame of an
//! automatic flight), on the CPU reference renderer or, with `--gpu`, on wgpu.

use std::{
    path::{Path, PathBuf},
    process::Command,
};

use anyhow::{Context, Result, bail};
use clap::{Args, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};
use voyage_core::Study;
use voyage_nav::{Camera, Direction, Flight, Pose, fly, potential_field};
use voyage_render::GpuRenderer;
use voyage_view::{
    CellMesh, CloseupBox, Frame, Material, Rasterizer, Shading, Strategy, TranslucencyOptions,
    View, Visibility, render_translucency, shade, surface_point,
};

use super::{fly::PhysicsArgs, prep::load_and_prepare};
use crate::open::{InputArgs, Prepared};

#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum OneDirection {
    /// Rectum → cecum.
    Forward,
    /// Cecum → rectum.
    Backward,
}

impl OneDirection {
    fn direction(self) -> Direction {
        match self {
            OneDirection::Forward => Direction::Forward,
            OneDirection::Backward => Direction::Backward,
        }
    }
}

/// How frames are drawn: shared by `render` and `movie`.
#[derive(Args, Debug, Clone)]
pub struct ViewArgs {
    /// Image width and height in pixels.
    #[arg(long, default_value_t = 512)]
    pub width: u32,
    #[arg(long, default_value_t = 512)]
    pub height: u32,
    /// Vertical field of view in degrees (up to 140).
    #[arg(long, default_value_t = 90.0)]
    pub fov: f64,
    /// Visibility strategy: all, lg, paper or ours (the image is the same with each).
    #[arg(long, default_value = "ours", value_parser = parse_strategy)]
    pub strategy: Strategy,
    /// Draw with the GPU renderer (wgpu; Vulkan or GL, including Mesa's CPU driver).
    #[arg(long)]
    pub gpu: bool,
}

fn parse_strategy(s: &str) -> Result<Strategy, String> {
    s.parse()
}

impl ViewArgs {
    fn check(&self) -> Result<()> {
        anyhow::ensure!(
            (16..=8192).contains(&self.width) && (16..=8192).contains(&self.height),
            "--width and --height must lie in 16..8192"
        );
        anyhow::ensure!(
            self.fov.is_finite() && self.fov >= 10.0 && self.fov <= Camera::MAX_FOV_DEG,
            "--fov must lie in 10..{}",
            Camera::MAX_FOV_DEG
        );
        Ok(())
    }

    fn camera(&self, pose: Pose) -> Camera {
        Camera::new(pose).with_fov(self.fov)
    }
}

#[derive(Args, Debug)]
pub struct RenderArgs {
    #[command(flatten)]
    pub input: InputArgs,
    /// Frame N (from 0) of the automatic flight.
    #[arg(long, conflicts_with = "pose", required_unless_present = "pose")]
    pub frame: Option<usize>,
    /// Which flight --frame counts along.
    #[arg(long, value_enum, default_value_t = OneDirection::Forward)]
    pub direction: OneDirection,
    /// A camera pose x,y,z,qw,qx,qy,qz: position in the study's local mm (the scan turned so
    /// that its axes run to the patient's left, back and head) and orientation (z_body =
    /// view, y_body = up), as in the "poses" of `voyage fly --out`.
    #[arg(long)]
    pub pose: Option<String>,
    /// The PNG to write.
    #[arg(long)]
    pub out: PathBuf,
    /// Lay the translucency view over the frame: the surface within 15 mm of the point at the
    /// view's centre, coloured by what lies beneath it (soft tissue red, fat yellow, tagged
    /// or mottled stool green, ordinary wall blue).
    #[arg(long)]
    pub translucency: bool,
    #[command(flatten)]
    pub view: ViewArgs,
    #[command(flatten)]
    pub physics: PhysicsArgs,
}

#[derive(Args, Debug)]
pub struct MovieArgs {
    #[command(flatten)]
    pub input: InputArgs,
    #[arg(long, value_enum, default_value_t = OneDirection::Forward)]
    pub direction: OneDirection,
    /// Folder for frame_00000.png, ... and flight.mp4 (when ffmpeg is installed).
    #[arg(long)]
    pub out: PathBuf,
    /// Keep every n-th frame of the flight.
    #[arg(long, default_value_t = 1)]
    pub every: usize,
    /// Stop after this many frames.
    #[arg(long)]
    pub max_frames: Option<usize>,
    /// Skip the .mp4 even when ffmpeg is there.
    #[arg(long)]
    pub no_mp4: bool,
    #[command(flatten)]
    pub view: ViewArgs,
    #[command(flatten)]
    pub physics: PhysicsArgs,
}

fn parse_pose(s: &str) -> Result<Pose> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .with_context(|| format!("--pose {s}"))?;
    let a: [f64; 7] = v
        .try_into()
        .map_err(|_| anyhow::anyhow!("--pose {s}: expected seven numbers x,y,z,qw,qx,qy,qz"))?;
    Pose::from_array(a)
        .with_context(|| format!("--pose {s}: not a position and a non-zero quaternion"))
}

/// Draws frames with either renderer; the visibility strategy runs on the CPU in both cases
/// (it reads the depth buffer of the cells drawn so far).
pub struct Renderer<'a> {
    study: &'a Study,
    mesh: CellMesh,
    vis: Visibility,
    frame: Frame,
    gpu: Option<GpuRenderer>,
    shading: Shading,
}

impl<'a> Renderer<'a> {
    pub fn new(study: &'a Study, v: &ViewArgs) -> Result<Self> {
        let mesh = CellMesh::new(&study.surface, &study.cells);
        let gpu = if v.gpu {
            let mut g = GpuRenderer::new_headless()?;
            g.upload(&mesh)?;
            eprintln!("GPU: {}", g.adapter_summary());
            Some(g)
        } else {
            None
        };
        Ok(Renderer {
            study,
            vis: Visibility::new(&study.cells, v.strategy),
            frame: Frame::new(v.width, v.height),
            mesh,
            gpu,
            shading: Shading::default(),
        })
    }

    /// RGBA8, top row first.
    pub fn draw(&mut self, camera: &Camera) -> Result<Vec<u8>> {
        let (w, h) = (self.frame.width, self.frame.height);
        let view = View::new(camera, w, h);
        let raster = Rasterizer::new(&self.mesh, view, &self.shading);
        let drawn = self.vis.draw(&mut self.frame, &raster, &self.study.cells);
        match &mut self.gpu {
            Some(g) => Ok(g.render(camera, &drawn.cells, w, h, self.shading.lighting())?),
            None => Ok(shade(&self.frame)),
        }
    }
}

fn flight(study: &Study, physics: &PhysicsArgs, dir: OneDirection, input: &Path) -> Result<Flight> {
    let opts = physics.options()?.fitted_to(study);
    let field = potential_field(study, opts.safety.min_wall_mm)
        .with_context(|| input.display().to_string())?;
    fly(&field, &study.centerline, dir.direction(), &opts)
        .with_context(|| format!("{}: {} flight", input.display(), dir.direction().name()))
}

pub fn render(a: &RenderArgs) -> Result<()> {
    a.view.check()?;
    let pose = a.pose.as_deref().map(parse_pose).transpose()?;
    let wall = a.physics.options()?.safety.min_wall_mm;
    let Prepared { study, .. } = load_and_prepare(&a.input, Some(wall))?;
    let pose = match (pose, a.frame) {
        (Some(p), _) => p,
        (None, Some(n)) => {
            let f = flight(&study, &a.physics, a.direction, &a.input.input)?;
            match f.poses.get(n) {
                Some(p) => *p,
                None => bail!(
                    "--frame {n}: the {} flight has {} frames (0..{})",
                    a.direction.direction().name(),
                    f.poses.len(),
                    f.poses.len().saturating_sub(1)
                ),
            }
        }
        (None, None) => bail!("give --frame N or --pose"),
    };
    let mut r = Renderer::new(&study, &a.view)?;
    let camera = a.view.camera(pose);
    let mut rgba = r.draw(&camera)?;
    if a.translucency {
        translucency_over(&study, &camera, &mut rgba, a.view.width, a.view.height)?;
    }
    voyage_io::write_png(&a.out, &rgba, a.view.width, a.view.height)?;
    println!(
        "wrote {} ({}×{}, {})",
        a.out.display(),
        a.view.width,
        a.view.height,
        if a.view.gpu { "GPU" } else { "CPU" }
    );
    Ok(())
}

/// Blends the translucency view of the box around the surface point at the view's centre
/// over `rgba` and says how many pixels each class has.
fn translucency_over(
    study: &Study,
    camera: &Camera,
    rgba: &mut [u8],
    width: u32,
    height: u32,
) -> Result<()> {
    let opts = TranslucencyOptions::default();
    let ct = study.cleansed_ct();
    let centre = surface_point(
        &ct,
        camera.pose.position,
        camera.pose.z_body(),
        200.0,
        opts.air_hu,
    )
    .context("--translucency: no surface at the view's centre within 200 mm")?;
    let t = render_translucency(
        &ct,
        &study.segmentation.lumen,
        camera,
        &CloseupBox::around(centre, voyage_view::HALF_SIZE_MM),
        width,
        height,
        &opts,
    );
    blend_over(rgba, &t.rgba);
    let counts = t.counts();
    let parts: Vec<String> = Material::ALL
        .iter()
        .zip(counts)
        .map(|(m, n)| format!("{} {n}", m.name()))
        .collect();
    println!(
        "translucency around {} (pixels): {}",
        ct.geometry().describe_point(centre),
        parts.join(", ")
    );
    Ok(())
}

/// `over` (straight alpha) composited onto the opaque `under`, both RGBA8.
fn blend_over(under: &mut [u8], over: &[u8]) {
    for (u, o) in under.chunks_exact_mut(4).zip(over.chunks_exact(4)) {
        let a = o[3] as u32;
        for c in 0..3 {
            u[c] = ((o[c] as u32 * a + u[c] as u32 * (255 - a) + 127) / 255) as u8;
        }
    }
}

pub fn movie(a: &MovieArgs) -> Result<()> {
    a.view.check()?;
    anyhow::ensure!(a.every >= 1, "--every must be at least 1");
    let wall = a.physics.options()?.safety.min_wall_mm;
    let Prepared { study, .. } = load_and_prepare(&a.input, Some(wall))?;
    let f = flight(&study, &a.physics, a.direction, &a.input.input)?;
    std::fs::create_dir_all(&a.out)
        .with_context(|| format!("{}: cannot create the folder", a.out.display()))?;
    let poses: Vec<Pose> = f
        .poses
        .iter()
        .copied()
        .step_by(a.every)
        .take(a.max_frames.unwrap_or(usize::MAX))
        .collect();
    let mut r = Renderer::new(&study, &a.view)?;
    let bar = if std::io::IsTerminal::is_terminal(&std::io::stderr()) {
        ProgressBar::new(poses.len() as u64)
    } else {
        ProgressBar::hidden()
    };
    bar.set_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} frames {eta}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    for (i, pose) in poses.iter().enumerate() {
        let rgba = r.draw(&a.view.camera(*pose))?;
        voyage_io::write_png(
            &a.out.join(format!("frame_{i:05}.png")),
            &rgba,
            a.view.width,
            a.view.height,
        )?;
        bar.inc(1);
    }
    bar.finish_and_clear();
    println!(
        "wrote {} frames to {} ({} flight {})",
        poses.len(),
        a.out.display(),
        a.direction.direction().name(),
        if f.reached {
            "reached the goal"
        } else {
            "did not reach the goal"
        }
    );
    if !a.no_mp4 {
        let fps = a.physics.fps / a.every as f64;
        match encode_mp4(&a.out, fps) {
            Ok(Some(p)) => println!("wrote {}", p.display()),
            Ok(None) => println!("ffmpeg not found: no .mp4 (the PNG frames are there)"),
            Err(e) => eprintln!("warning: no .mp4: {e:#}"),
        }
    }
    Ok(())
}

/// flight.mp4 from the frames with ffmpeg, when it is installed (None when it is not).
fn encode_mp4(dir: &Path, fps: f64) -> Result<Option<PathBuf>> {
    if Command::new("ffmpeg").arg("-version").output().is_err() {
        return Ok(None);
    }
    let out = dir.join("flight.mp4");
    let tmp = dir.join(".flight.tmp.mp4");
    let status = Command::new("ffmpeg")
        .args([
            "-y",
            "-loglevel",
            "error",
            "-framerate",
            &format!("{fps}"),
            "-i",
        ])
        .arg(dir.join("frame_%05d.png"))
        .args([
            "-c:v",
            "libx264",
            "-pix_fmt",
            "yuv420p",
            "-vf",
            "pad=ceil(iw/2)*2:ceil(ih/2)*2",
        ])
        .arg(&tmp)
        .status()
        .context("running ffmpeg")?;
    if !status.success() {
        let _ = std::fs::remove_file(&tmp);
        bail!("ffmpeg failed ({status})");
    }
    std::fs::rename(&tmp, &out).with_context(|| format!("{}", out.display()))?;
    Ok(Some(out))
}
