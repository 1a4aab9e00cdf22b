//! The slice panel (paper §5): axial, coronal and sagittal CT slices through the submarine,
//! shown the way radiologists read them (the patient's right on the screen's left; anterior
//! up on axial slices, head up on the others), with a crosshair at the submarine, window /
//! level presets and drag, scroll through slices, and a click in the lumen to move there.
//! A tagged exam's slices show the original CT or the cleansed one (a toggle: readers check
//! both), with the cleansed voxels outlined on request.
//! A right click offers the corrections of the colon found: start or end the flight there,
//! take the gas there in or leave it out.
//!
//! Only the widget is here: the presets, the drag, scroll and clicks, the crosshair, the
//! menu and the letters drawn. The reslicing (which index axis runs where on the screen,
//! the grey images, cleansing's changes and outlines) is voyage-view's [`SliceLayout`] and
//! [`slice_image`].

use egui::{Color32, Pos2, Rect, Sense, Stroke, Vec2};
use glam::DVec3;
use voyage_core::{Cleansing, Geometry, Volume};
use voyage_view::{Plane, SliceLayout, SliceShading, changes_in_plane, slice_image};

use super::{corrections::Correction, pixels::PanelImage};

/// What a click on a slice asks for.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SliceAction {
    /// Move the submarine to this point (volume-local mm).
    MoveTo(DVec3),
    /// Correct the colon found, and preprocess again.
    Correct(Correction),
}

/// Window / level presets (HU): name, width, centre.
pub const PRESETS: [(&str, f64, f64); 3] = [
    ("Colon", 1600.0, -300.0),
    ("Lung", 1500.0, -600.0),
    ("Soft tissue", 400.0, 40.0),
];

const SCROLL_PER_SLICE: f32 = 24.0;

struct SliceView {
    plane: Plane,
    /// Slices scrolled away from the submarine's.
    offset: i64,
    /// Scrolling not yet turned into slices (points).
    scroll: f32,
    image: PanelImage,
    /// What the image shows: slice, window, level, size in pixels, cleansed, outlined.
    shows: Option<(usize, f64, f64, [usize; 2], bool, bool)>,
    /// Where the context menu was opened (volume-local mm).
    menu_at: Option<DVec3>,
}

pub struct SlicePanel {
    views: [SliceView; 3],
    /// The edge letters drawn on each slice in the last frame (axial, coronal, sagittal; empty
    /// until drawn), for the window's report.
    pub letters_drawn: [Vec<&'static str>; 3],
    pub window: f64,
    pub level: f64,
    /// Show the cleansed CT (where cleansing changed anything), and outline what it changed.
    pub cleansed: bool,
    pub outline: bool,
}

/// The CT the slices read, what cleansing changed in it, and how the patient lay (named
/// above the slices, e.g. "prone (HFP)").
#[derive(Clone, Copy)]
pub struct SliceSource<'a> {
    pub ct: &'a Volume<i16>,
    pub cleansing: &'a Cleansing,
    pub position: &'a str,
}

impl SlicePanel {
    /// `image_keys`: the three slices' slots among the window's pixel images; `gpu`: the
    /// window's renderer holds them.
    pub fn new(image_keys: [u64; 3], gpu: bool) -> Self {
        let views = std::array::from_fn(|i| SliceView {
            plane: Plane::ALL[i],
            offset: 0,
            scroll: 0.0,
            image: PanelImage::new(image_keys[i], Plane::ALL[i].name(), gpu),
            shows: None,
            menu_at: None,
        });
        SlicePanel {
            views,
            letters_drawn: Default::default(),
            window: PRESETS[0].1,
            level: PRESETS[0].2,
            cleansed: false,
            outline: false,
        }
    }

    /// Back to the slices through the submarine (after it moved somewhere new).
    pub fn follow(&mut self) {
        for v in &mut self.views {
            v.offset = 0;
        }
    }

    /// The slices show another volume (the exam's other position): every image is drawn
    /// again, whatever it showed.
    pub fn volume_changed(&mut self) {
        self.follow();
        for v in &mut self.views {
            v.shows = None;
        }
    }

    /// The three slices side by side; returns what a click asked for, if anything. `busy`:
    /// a correction is being preprocessed (no other is offered meanwhile).
    pub fn show(
        &mut self,
        ui: &mut egui::Ui,
        src: SliceSource,
        at: DVec3,
        busy: bool,
    ) -> Option<SliceAction> {
        let ct = src.ct;
        ui.horizontal(|ui| {
            ui.label("W/L:");
            for (name, w, l) in PRESETS {
                if ui.selectable_label(self.window == w && self.level == l, name).clicked() {
                    (self.window, self.level) = (w, l);
                }
            }
            if !src.cleansing.is_empty() {
                ui.separator();
                ui.checkbox(&mut self.cleansed, "Cleansed").on_hover_text("show the CT with the colon's tagged fluid made air (the surface is cut from it); off: the original");
                ui.checkbox(&mut self.outline, "Outline").on_hover_text("outline the voxels cleansing changed");
            }
            ui.label(format!("W {:.0} L {:.0}", self.window, self.level)).on_hover_text("drag on a slice: ←→ window, ↑↓ level; scroll: slices; click in the colon: go there; right click: start / end here, gas is colon or not");
            ui.separator();
            ui.label(format!("patient {}: shown anterior up, patient's right on the left", src.position));
        });
        let mut clicked = None;
        let width = ui.available_width() / 3.0 - 6.0;
        // No taller than what the panel shows: the bottom rows and letters were cut off.
        let visible = ui.clip_rect().bottom() - ui.cursor().top() - 8.0;
        let height = ui.available_height().min(visible).max(32.0);
        ui.horizontal(|ui| {
            for i in 0..3 {
                let (rect, response) =
                    ui.allocate_exact_size(Vec2::new(width, height), Sense::click_and_drag());
                if let Some(p) = self.show_one(ui, i, src, at, rect, &response) {
                    clicked = Some(SliceAction::MoveTo(p));
                }
                if let Some(c) = self.menu(i, ct.geometry(), &response, busy) {
                    clicked = Some(SliceAction::Correct(c));
                }
            }
        });
        clicked
    }

    fn show_one(
        &mut self,
        ui: &egui::Ui,
        i: usize,
        src: SliceSource,
        at: DVec3,
        rect: Rect,
        response: &egui::Response,
    ) -> Option<DVec3> {
        let ct = src.ct;
        let g = ct.geometry();
        let plane = self.views[i].plane;
        let lay = SliceLayout::of(g, plane);
        let dims = ct.dims();
        let at_index = g.local_to_index(at).round();
        if response.dragged_by(egui::PointerButton::Primary) {
            let d = response.drag_delta();
            self.window = (self.window * (1.0 + d.x as f64 * 0.005)).clamp(1.0, 8000.0);
            self.level = (self.level - d.y as f64 * 2.0).clamp(-1500.0, 3000.0);
        }
        if response.hovered() {
            // A wheel notch is some tens of points of smooth scrolling: one slice per notch.
            let v = &mut self.views[i];
            v.scroll += ui.input(|i| i.smooth_scroll_delta.y);
            while v.scroll.abs() >= SCROLL_PER_SLICE {
                v.offset += v.scroll.signum() as i64;
                v.scroll -= v.scroll.signum() * SCROLL_PER_SLICE;
            }
        }
        let fixed = (at_index[lay.fixed] as i64 + self.views[i].offset)
            .clamp(0, dims[lay.fixed] as i64 - 1) as usize;
        self.views[i].offset = fixed as i64 - at_index[lay.fixed] as i64;
        let [nx, ny] = lay.image_voxels(dims);
        let (sx, sy) = (g.spacing[lay.x.0], g.spacing[lay.y.0]);
        let size_mm = Vec2::new((nx as f64 * sx) as f32, (ny as f64 * sy) as f32);
        let scale = (rect.width() / size_mm.x).min((rect.height() - 16.0) / size_mm.y);
        // The image at the size it is shown, on whole pixels: drawn pixel for pixel.
        let ppp = ui.ctx().pixels_per_point();
        let shown = Rect::from_center_size(rect.center() + Vec2::new(0.0, 8.0), size_mm * scale);
        let px = [
            ((shown.width() * ppp).round() as usize).max(1),
            ((shown.height() * ppp).round() as usize).max(1),
        ];
        let image_rect = Rect::from_min_size(
            ((shown.min.to_vec2() * ppp).round() / ppp).to_pos2(),
            Vec2::new(px[0] as f32, px[1] as f32) / ppp,
        );
        let (cleansed, outline) = (
            self.cleansed && !src.cleansing.is_empty(),
            self.outline && !src.cleansing.is_empty(),
        );
        let key = (fixed, self.window, self.level, px, cleansed, outline);
        let view = &mut self.views[i];
        if view.shows != Some(key) {
            let changes = (cleansed || outline)
                .then(|| changes_in_plane(src.cleansing, ct.dims(), lay.fixed, fixed));
            let shown = SliceShading {
                window: self.window,
                level: self.level,
                size: px,
                changes: changes.as_ref(),
                cleansed,
                outline,
            };
            view.image.set(slice_image(ct, lay, fixed, &shown));
            view.shows = Some(key);
        }
        let painter = ui.painter_at(rect);
        view.image.paint(&painter, image_rect.min);
        // Index → screen: the voxel centre's place in the image.
        let to_screen = |ix: f64, iy: f64| {
            let [u, v] = lay.fraction_of(dims, ix, iy);
            Pos2::new(
                image_rect.left() + u * image_rect.width(),
                image_rect.top() + v * image_rect.height(),
            )
        };
        let c = to_screen(at_index[lay.x.0], at_index[lay.y.0]);
        let cross = Stroke::new(1.0, Color32::from_rgba_unmultiplied(60, 220, 255, 170));
        painter.line_segment(
            [Pos2::new(image_rect.left(), c.y), Pos2::new(c.x - 6.0, c.y)],
            cross,
        );
        painter.line_segment(
            [
                Pos2::new(c.x + 6.0, c.y),
                Pos2::new(image_rect.right(), c.y),
            ],
            cross,
        );
        painter.line_segment(
            [Pos2::new(c.x, image_rect.top()), Pos2::new(c.x, c.y - 6.0)],
            cross,
        );
        painter.line_segment(
            [
                Pos2::new(c.x, c.y + 6.0),
                Pos2::new(c.x, image_rect.bottom()),
            ],
            cross,
        );
        let label = format!(
            "{} {}/{}{}",
            plane.name(),
            fixed + 1,
            dims[lay.fixed],
            if view.offset != 0 {
                format!(" ({:+})", view.offset)
            } else {
                String::new()
            }
        );
        painter.text(
            rect.left_top() + Vec2::new(4.0, 2.0),
            egui::Align2::LEFT_TOP,
            label,
            egui::FontId::proportional(11.0),
            Color32::from_gray(200),
        );
        self.letters_drawn[i] = edge_letters(&painter, image_rect, plane);

        // Screen → the voxel centre under it (the nearest, so a point given back to
        // segmentation lies in the voxel the user saw).
        let to_local = |p: Pos2| {
            let fraction = [
                (p.x - image_rect.left()) / image_rect.width(),
                (p.y - image_rect.top()) / image_rect.height(),
            ];
            g.index_to_local(lay.voxel_at(dims, fraction, fixed))
        };
        if response.secondary_clicked() {
            view.menu_at = response
                .interact_pointer_pos()
                .filter(|p| image_rect.contains(*p))
                .map(to_local);
        }
        if response.clicked() {
            let p = response.interact_pointer_pos()?;
            return image_rect.contains(p).then(|| to_local(p));
        }
        None
    }

    /// The right-click menu of slice `i`: the corrections at the point clicked.
    fn menu(
        &mut self,
        i: usize,
        g: &Geometry,
        response: &egui::Response,
        busy: bool,
    ) -> Option<Correction> {
        let at = self.views[i].menu_at?;
        let lps = g.local_to_patient(at).to_array();
        let mut chosen = None;
        response.context_menu(|ui| {
            ui.label(
                egui::RichText::new(format!(
                    "LPS ({:.0}, {:.0}, {:.0}) mm",
                    lps[0], lps[1], lps[2]
                ))
                .small(),
            );
            ui.add_enabled_ui(!busy, |ui| {
                let items = [
                    ("Start here (rectum end)", Correction::Source(lps)),
                    ("End here (cecum end)", Correction::Target(lps)),
                    ("This gas is colon", Correction::Include(lps)),
                    ("This gas is not colon", Correction::Exclude(lps)),
                ];
                for (text, c) in items {
                    if ui.button(text).clicked() {
                        chosen = Some(c);
                        ui.close();
                    }
                }
            });
        });
        chosen
    }
}

/// Draws the patient's side at each edge of a slice image, white on a dark plate so that it
/// reads over bright tissue as over air; returns the letters drawn (left, right, top,
/// bottom).
fn edge_letters(painter: &egui::Painter, image: Rect, plane: Plane) -> Vec<&'static str> {
    let [left, right, top, bottom] = plane.edge_letters();
    let inset = 3.0;
    let places = [
        (
            left,
            Pos2::new(image.left() + inset, image.center().y),
            egui::Align2::LEFT_CENTER,
        ),
        (
            right,
            Pos2::new(image.right() - inset, image.center().y),
            egui::Align2::RIGHT_CENTER,
        ),
        (
            top,
            Pos2::new(image.center().x, image.top() + inset),
            egui::Align2::CENTER_TOP,
        ),
        (
            bottom,
            Pos2::new(image.center().x, image.bottom() - inset),
            egui::Align2::CENTER_BOTTOM,
        ),
    ];
    let font = egui::FontId::proportional(12.0);
    let mut drawn = Vec::with_capacity(4);
    for (letter, at, align) in places {
        let galley = painter.layout_no_wrap(letter.to_string(), font.clone(), Color32::WHITE);
        let text = align.anchor_size(at, galley.size());
        painter.rect_filled(text.expand(2.0), 2.0, Color32::from_black_alpha(170));
        painter.galley(text.min, galley, Color32::WHITE);
        drawn.push(letter);
    }
    drawn
}
