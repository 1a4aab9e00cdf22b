//! The endoscopic view inside egui: drawn by the wgpu renderer straight into the window's
//! render pass, or by the CPU reference renderer into an egui texture where no GPU renderer
//! is wanted. Either way only the cells the portals let through are drawn (paper §4.3): on
//! the GPU the portal outlines alone decide (`Visibility::select`, and the chunks of those
//! cells outside the view are left out), on the CPU also the depth buffer
//! (`Visibility::draw`); none of it changes a pixel.

use std::time::Instant;

use super::{pixels::WindowGpu, session::Session};
use eframe::egui_wgpu;
use egui::{Color32, ColorImage, Pos2, Rect, TextureHandle, TextureOptions, Vec2};
use glam::DVec3;
use voyage_nav::Camera;
use voyage_render::DrawList;
use voyage_view::{Frame, Lighting, Rasterizer, Shading, View, shade};

/// The view on the window's GPU renderer ([`WindowGpu`]).
struct GpuView {
    /// The mesh uploaded belongs to this session generation.
    uploaded: u64,
}

/// One frame of the endoscopic view, drawn straight into the window's render pass (no
/// texture between: measured, a separate pass plus a copy cost lavapipe more than the
/// window-sized depth buffer this needs).
struct EndoscopeCallback {
    camera: Camera,
    list: DrawList,
    size: [u32; 2],
    lighting: Lighting,
}

impl egui_wgpu::CallbackTrait for EndoscopeCallback {
    fn prepare(
        &self,
        _device: &wgpu::Device,
        _queue: &wgpu::Queue,
        _screen: &egui_wgpu::ScreenDescriptor,
        _encoder: &mut wgpu::CommandEncoder,
        resources: &mut egui_wgpu::CallbackResources,
    ) -> Vec<wgpu::CommandBuffer> {
        if let Some(g) = resources.get::<WindowGpu>() {
            // A size the device refuses leaves the view empty rather than stopping the window.
            let _ = g
                .renderer
                .prepare(&self.camera, self.size[0], self.size[1], &self.lighting);
        }
        Vec::new()
    }

    fn paint(
        &self,
        _info: egui::PaintCallbackInfo,
        pass: &mut wgpu::RenderPass<'static>,
        resources: &egui_wgpu::CallbackResources,
    ) {
        if let Some(g) = resources.get::<WindowGpu>() {
            let _ = g.renderer.draw_in_pass(pass, &self.list);
        }
    }
}

/// What one frame of the view cost and drew.
#[derive(Clone, Copy, Debug, Default)]
pub struct FrameStats {
    pub cells: usize,
    pub triangles: usize,
    /// Wall time to choose the cells and record (GPU) or draw (CPU) the frame.
    pub render_ms: f64,
}

pub struct Endoscope {
    gpu: Option<GpuView>,
    cpu_frame: Option<Frame>,
    cpu_texture: Option<TextureHandle>,
    shading: Shading,
    pub stats: FrameStats,
    /// The cells drawn in the last frame (picking searches them first).
    pub last_cells: Vec<u32>,
    /// Description of the renderer in use, for the read-out and the report.
    pub renderer_name: String,
}

impl Endoscope {
    /// Uses the window's wgpu renderer (a [`WindowGpu`] in its callback resources) when there
    /// is one and `cpu` is false.
    pub fn new(render_state: Option<&egui_wgpu::RenderState>, cpu: bool) -> Self {
        let gpu = render_state.filter(|_| !cpu).and_then(|rs| {
            let name = rs
                .renderer
                .read()
                .callback_resources
                .get::<WindowGpu>()
                .map(|g| format!("GPU: {}", g.renderer.adapter_summary()))?;
            Some((GpuView { uploaded: u64::MAX }, name))
        });
        let (gpu, renderer_name) = match gpu {
            Some((g, name)) => (Some(g), name),
            None => (None, "CPU reference renderer".to_string()),
        };
        Endoscope {
            gpu,
            cpu_frame: None,
            cpu_texture: None,
            shading: Shading::default(),
            stats: FrameStats::default(),
            last_cells: Vec::new(),
            renderer_name,
        }
    }

    pub fn is_gpu(&self) -> bool {
        self.gpu.is_some()
    }

    /// Draws the view of `session`'s camera at `size` physical pixels into `rect` of the
    /// painter. `generation` changes whenever a new study is opened.
    pub fn render(
        &mut self,
        painter: &egui::Painter,
        rect: Rect,
        render_state: Option<&egui_wgpu::RenderState>,
        session: &mut Session,
        generation: u64,
        size: [u32; 2],
    ) -> anyhow::Result<()> {
        let clock = Instant::now();
        let camera = session.camera();
        match (&mut self.gpu, render_state) {
            (Some(gpu), Some(rs)) => {
                if gpu.uploaded != generation {
                    if let Some(g) = rs
                        .renderer
                        .write()
                        .callback_resources
                        .get_mut::<WindowGpu>()
                    {
                        g.renderer.upload(&session.mesh)?;
                    }
                    gpu.uploaded = generation;
                }
                let drawn = session
                    .vis
                    .select(&session.study.cells, &View::new(&camera, size[0], size[1]));
                self.stats.cells = drawn.cells.len();
                // What the GPU is given: the cells' triangles less their chunks outside the
                // view or outside the window the portals leave open.
                let list = rs
                    .renderer
                    .read()
                    .callback_resources
                    .get::<WindowGpu>()
                    .map(|g| {
                        g.renderer
                            .draw_list_within(&drawn, &camera, size[0], size[1])
                    })
                    .transpose()?
                    .unwrap_or_default();
                self.stats.triangles = list.triangles();
                self.last_cells = drawn.cells;
                painter.add(egui_wgpu::Callback::new_paint_callback(
                    rect,
                    EndoscopeCallback {
                        camera,
                        list,
                        size,
                        lighting: *self.shading.lighting(),
                    },
                ));
            }
            _ => {
                let id = self.draw_cpu(painter.ctx(), session, &camera, size);
                painter.image(
                    id,
                    rect,
                    Rect::from_min_max(Pos2::ZERO, Pos2::new(1.0, 1.0)),
                    Color32::WHITE,
                );
            }
        }
        self.stats.render_ms = clock.elapsed().as_secs_f64() * 1e3;
        Ok(())
    }

    fn draw_cpu(
        &mut self,
        ctx: &egui::Context,
        session: &mut Session,
        camera: &Camera,
        size: [u32; 2],
    ) -> egui::TextureId {
        let frame = match &mut self.cpu_frame {
            Some(f) if f.width == size[0] && f.height == size[1] => f,
            slot => slot.insert(Frame::new(size[0], size[1])),
        };
        let raster = Rasterizer::new(
            &session.mesh,
            View::new(camera, size[0], size[1]),
            &self.shading,
        );
        let drawn = session.vis.draw(frame, &raster, &session.study.cells);
        self.stats.cells = drawn.cells.len();
        self.stats.triangles = drawn.triangles;
        self.last_cells = drawn.cells;
        let image =
            ColorImage::from_rgba_unmultiplied([size[0] as usize, size[1] as usize], &shade(frame));
        match &mut self.cpu_texture {
            Some(t) => {
                t.set(image, TextureOptions::LINEAR);
                t.id()
            }
            None => {
                let t = ctx.load_texture("endoscope", image, TextureOptions::LINEAR);
                let id = t.id();
                self.cpu_texture = Some(t);
                id
            }
        }
    }
}

/// Where a point of the colon appears in the view, as a fraction of the view's width and
/// height from its top-left corner (None behind the camera). The inverse of
/// `Camera::pixel_ray`.
pub fn project(camera: &Camera, p: DVec3, aspect: f64) -> Option<Vec2> {
    let pose = &camera.pose;
    let e = p - pose.position;
    let z = e.dot(pose.z_body());
    if z <= camera.near_mm {
        return None;
    }
    let t = camera.tan_half_fov();
    let sx = e.dot(-pose.x_body()) / z / (t * aspect);
    let sy = e.dot(pose.y_body()) / z / t;
    Some(Vec2::new(
        ((sx + 1.0) * 0.5) as f32,
        ((1.0 - sy) * 0.5) as f32,
    ))
}

/// The ray through a point of the view rectangle.
pub fn ray_at(camera: &Camera, rect: Rect, at: Pos2) -> DVec3 {
    let w = rect.width().max(1.0) as f64;
    let h = rect.height().max(1.0) as f64;
    let px = (at.x - rect.left()) as f64;
    let py = (at.y - rect.top()) as f64;
    // pixel_ray takes continuous pixel coordinates of a w × h image; points serve as pixels.
    camera.pixel_ray(px, py, w.round() as u32, h.round() as u32)
}

/// The centerline seen from the camera (paper: drawn in green), as polylines of the points
/// within `reach_mm` that the camera can see.
pub fn visible_centerline(
    session: &Session,
    camera: &Camera,
    rect: Rect,
    reach_mm: f64,
) -> Vec<Vec<Pos2>> {
    let aspect = (rect.width() / rect.height().max(1.0)) as f64;
    let eye = camera.pose.position;
    let mut lines: Vec<Vec<Pos2>> = Vec::new();
    let mut current: Vec<Pos2> = Vec::new();
    let mut last: Option<DVec3> = None;
    for p in &session.study.centerline.points_mm {
        let p = DVec3::from_array(*p);
        // Thin to about one point per 2 mm: the line looks the same and costs less.
        if last.is_some_and(|l| l.distance(p) < 2.0) {
            continue;
        }
        last = Some(p);
        let seen = p.distance(eye) <= reach_mm
            && project(camera, p, aspect).is_some()
            && session.line_of_sight(eye, p, 0.0);
        match seen.then(|| project(camera, p, aspect)).flatten() {
            Some(f) => current.push(rect.min + f * rect.size()),
            None => {
                if current.len() > 1 {
                    lines.push(std::mem::take(&mut current));
                }
                current.clear();
            }
        }
    }
    if current.len() > 1 {
        lines.push(current);
    }
    lines
}

/// A point on the surface is drawn when the camera sees it: the straight line to it runs
/// through the lumen up to the last millimetre or so (the point itself sits on the wall).
pub fn surface_point_on_screen(
    session: &Session,
    camera: &Camera,
    rect: Rect,
    p: DVec3,
) -> Option<Pos2> {
    let aspect = (rect.width() / rect.height().max(1.0)) as f64;
    let f = project(camera, p, aspect)?;
    let skip = 1.5 * session.study.ct.geometry().spacing_vec().max_element();
    session
        .line_of_sight(camera.pose.position, p, skip)
        .then(|| rect.min + f * rect.size())
}

/// A readable label on the view: light text on a dark backing.
pub fn label(painter: &egui::Painter, at: Pos2, text: &str, color: Color32) -> Rect {
    let galley = painter.layout_no_wrap(text.to_string(), egui::FontId::proportional(13.0), color);
    let r = Rect::from_min_size(at, galley.size()).expand(2.0);
    painter.rect_filled(r, 3.0, Color32::from_black_alpha(160));
    painter.galley(at, galley, color);
    r
}
