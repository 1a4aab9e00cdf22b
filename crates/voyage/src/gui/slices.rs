//! The slice panel (paper §5): axial, coronal and sagittal CT slices through the submarine,
//! shown the way radiologists read them (the patient's right on the screen's left; anterior
//! up on axial slices, head up on the others), with a crosshair at the submarine, window /
//! level presets and drag, scroll through slices, and a click in the lumen to move there.
//! A tagged exam's slices show the original CT or the cleansed one (a toggle: readers check
//! both), with the cleansed voxels outlined on request.
//! A right click offers the corrections of the colon found: start or end the flight there,
//! take the gas there in or leave it out.

use std::collections::HashMap;

use egui::{Color32, Pos2, Rect, Sense, Stroke, Vec2};
use glam::DVec3;
use voyage_core::{Cleansing, Geometry, Volume};

use super::{
    corrections::Correction,
    pixels::{PanelImage, Rgba},
};

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

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Plane {
    Axial,
    Coronal,
    Sagittal,
}

impl Plane {
    pub const ALL: [Plane; 3] = [Plane::Axial, Plane::Coronal, Plane::Sagittal];
    pub fn name(self) -> &'static str {
        match self {
            Plane::Axial => "axial",
            Plane::Coronal => "coronal",
            Plane::Sagittal => "sagittal",
        }
    }

    /// The patient's side at the image's left, right, top and bottom edges, as [`layout`]
    /// puts it in the standard display whatever way the patient lay or the data is stored:
    /// right on the left, anterior up on axial slices, head up on the others.
    pub fn edge_letters(self) -> [&'static str; 4] {
        match self {
            Plane::Axial => ["R", "L", "A", "P"],
            Plane::Coronal => ["R", "L", "S", "I"],
            Plane::Sagittal => ["A", "P", "S", "I"],
        }
    }
}

/// How a plane's image maps to voxel indices: which index axis runs along the screen's x
/// and y (and whether reversed), and which is fixed.
#[derive(Clone, Copy, Debug)]
struct Layout {
    x: (usize, bool),
    y: (usize, bool),
    fixed: usize,
}

/// For patient axis a (L, P, S): the index axis nearest to it and whether the index grows
/// with the patient coordinate.
fn patient_axes(g: &Geometry) -> [(usize, bool); 3] {
    let d = g.direction_mat();
    std::array::from_fn(|a| {
        let row = [d.x_axis[a], d.y_axis[a], d.z_axis[a]];
        let c = (0..3)
            .max_by(|&i, &j| row[i].abs().total_cmp(&row[j].abs()))
            .unwrap_or(a);
        (c, row[c] >= 0.0)
    })
}

fn layout(g: &Geometry, plane: Plane) -> Layout {
    let [l, p, s] = patient_axes(g);
    // (axis, patient coordinate grows toward screen +x / +y (down)).
    let along = |(c, grows): (usize, bool), want_growing: bool| (c, grows != want_growing);
    match plane {
        Plane::Axial => Layout {
            x: along(l, true),
            y: along(p, true),
            fixed: s.0,
        },
        Plane::Coronal => Layout {
            x: along(l, true),
            y: along(s, false),
            fixed: p.0,
        },
        Plane::Sagittal => Layout {
            x: along(p, true),
            y: along(s, false),
            fixed: l.0,
        },
    }
}

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
        let lay = layout(g, plane);
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
        let (nx, ny) = (dims[lay.x.0], dims[lay.y.0]);
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
            let shown = Shown {
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
        // Index ↔ screen: pixel centres at (u + 0.5) / n of the image.
        let to_screen = |ix: f64, iy: f64| {
            let u = if lay.x.1 { nx as f64 - 1.0 - ix } else { ix };
            let v = if lay.y.1 { ny as f64 - 1.0 - iy } else { iy };
            Pos2::new(
                image_rect.left() + ((u + 0.5) / nx as f64) as f32 * image_rect.width(),
                image_rect.top() + ((v + 0.5) / ny as f64) as f32 * image_rect.height(),
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
            let u = ((p.x - image_rect.left()) / image_rect.width()) as f64 * nx as f64 - 0.5;
            let v = ((p.y - image_rect.top()) / image_rect.height()) as f64 * ny as f64 - 0.5;
            let mut ijk = [0.0; 3];
            ijk[lay.x.0] = if lay.x.1 { nx as f64 - 1.0 - u } else { u };
            ijk[lay.y.0] = if lay.y.1 { ny as f64 - 1.0 - v } else { v };
            ijk[lay.fixed] = fixed as f64;
            g.index_to_local(DVec3::from_array(ijk).round())
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

/// How a slice is shown: window / level (HU), size in pixels, and cleansing's changes in its
/// plane (voxel index → cleansed HU), shown in place of the CT's values and/or outlined.
struct Shown<'a> {
    window: f64,
    level: f64,
    size: [usize; 2],
    changes: Option<&'a HashMap<usize, i16>>,
    cleansed: bool,
    outline: bool,
}

/// Cleansing's changes in the plane where index axis `axis` is `at`.
fn changes_in_plane(
    c: &Cleansing,
    dims: [usize; 3],
    axis: usize,
    at: usize,
) -> HashMap<usize, i16> {
    let stride = [1, dims[0], dims[0] * dims[1]][axis];
    c.voxels()
        .iter()
        .zip(c.values())
        .filter(|&(&v, _)| (v as usize / stride) % dims[axis] == at)
        .map(|(&v, &h)| (v as usize, h))
        .collect()
}

/// Outline colour of the cleansed voxels.
const OUTLINE: [u8; 4] = [0, 210, 255, 255];

/// The grey image of one slice under a window / level, `size` pixels (the slice's
/// orientation on screen), each pixel the voxel under its centre (no interpolation, as a
/// slice viewer with interpolation off: a mask stays two-valued, and a slice shown smaller
/// than the CT reads one voxel per pixel, not all of them).
fn slice_image(ct: &Volume<i16>, lay: Layout, fixed: usize, shown: &Shown) -> Rgba {
    let size = shown.size;
    let dims = ct.dims();
    let stride = [1, dims[0], dims[0] * dims[1]];
    // Per image column (row): the offset in the data of the voxels under it.
    let offsets = |m: usize, (axis, reversed): (usize, bool)| -> Vec<usize> {
        let n = dims[axis];
        (0..m)
            .map(|u| {
                let c = voxel_under(u, n, m);
                (if reversed { n - 1 - c } else { c }) * stride[axis]
            })
            .collect()
    };
    let (xs, ys) = (offsets(size[0], lay.x), offsets(size[1], lay.y));
    let data = ct.data();
    let base = fixed * stride[lay.fixed];
    let lo = (shown.level - 0.5 * shown.window) as f32;
    let k = (255.0 / shown.window.max(1.0)) as f32;
    let changed = |v: usize| shown.changes.and_then(|c| c.get(&v).copied());
    let mut bytes = Vec::with_capacity(size[0] * size[1] * 4);
    for (y, &r) in ys.iter().enumerate() {
        let row = base + r;
        for (x, &c) in xs.iter().enumerate() {
            let v = row + c;
            let new = changed(v);
            // A changed voxel whose neighbour on screen is not: the outline.
            let edge = shown.outline
                && new.is_some()
                && [
                    (x.wrapping_sub(1), y),
                    (x + 1, y),
                    (x, y.wrapping_sub(1)),
                    (x, y + 1),
                ]
                .iter()
                .any(|&(a, b)| {
                    a >= size[0] || b >= size[1] || changed(base + ys[b] + xs[a]).is_none()
                });
            if edge {
                bytes.extend_from_slice(&OUTLINE);
                continue;
            }
            let hu = match new {
                Some(h) if shown.cleansed => h,
                _ => data[v],
            };
            let g = ((hu as f32 - lo) * k).clamp(0.0, 255.0) as u8;
            bytes.extend_from_slice(&[g, g, g, 255]);
        }
    }
    Rgba { size, bytes }
}

/// The voxel (of `n` along an axis) under the centre of pixel `u` of `m` pixels spanning
/// the `n` voxels.
fn voxel_under(u: usize, n: usize, m: usize) -> usize {
    (((2 * u + 1) * n) / (2 * m)).min(n - 1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn identity_geometry_reads_radiologically() {
        let g = Geometry::new([4, 5, 6], [1.0; 3], [0.0; 3]).unwrap();
        // Axial: L grows to the screen's right (patient's right on the left), P downward.
        let a = layout(&g, Plane::Axial);
        assert_eq!((a.x, a.y, a.fixed), ((0, false), (1, false), 2));
        // Coronal and sagittal: head up, so k runs upward (reversed on screen).
        let c = layout(&g, Plane::Coronal);
        assert_eq!((c.x, c.y, c.fixed), ((0, false), (2, true), 1));
        let s = layout(&g, Plane::Sagittal);
        assert_eq!((s.x, s.y, s.fixed), ((1, false), (2, true), 0));
    }

    #[test]
    fn flipped_axes_are_undone() {
        // A RAS-stored volume: i → right (−L), j → anterior (−P).
        let mut g = Geometry::new([4, 5, 6], [1.0; 3], [0.0; 3]).unwrap();
        g.set_direction_mat(glam::DMat3::from_diagonal(DVec3::new(-1.0, -1.0, 1.0)));
        let a = layout(&g, Plane::Axial);
        assert_eq!((a.x, a.y), ((0, true), (1, true)));
    }

    /// A volume whose voxel (i, j, k) holds i + 10 j + 100 k.
    fn numbered(dims: [usize; 3]) -> Volume<i16> {
        let g = Geometry::new(dims, [1.0; 3], [0.0; 3]).unwrap();
        let data = (0..dims[2])
            .flat_map(|k| {
                (0..dims[1])
                    .flat_map(move |j| (0..dims[0]).map(move |i| (i + 10 * j + 100 * k) as i16))
            })
            .collect();
        Volume::from_vec(g, data).unwrap()
    }

    /// The value a grey pixel stands for under window 255, level 127.5 (grey = value).
    fn value(img: &Rgba, x: usize, y: usize) -> i16 {
        let p = &img.bytes[4 * (y * img.size[0] + x)..][..4];
        assert_eq!(
            (p[0], p[1], p[2], p[3]),
            (p[0], p[0], p[0], 255),
            "grey and opaque"
        );
        p[0] as i16
    }

    #[test]
    fn each_pixel_shows_the_voxel_under_its_centre() {
        // Same size: every voxel once. Half size: voxels 1, 3, 5, ... Double: each twice.
        assert_eq!(
            (0..6).map(|u| voxel_under(u, 6, 6)).collect::<Vec<_>>(),
            vec![0, 1, 2, 3, 4, 5]
        );
        assert_eq!(
            (0..3).map(|u| voxel_under(u, 6, 3)).collect::<Vec<_>>(),
            vec![1, 3, 5]
        );
        assert_eq!(
            (0..4).map(|u| voxel_under(u, 2, 4)).collect::<Vec<_>>(),
            vec![0, 0, 1, 1]
        );
        assert_eq!(voxel_under(0, 5, 1), 2);
    }

    #[test]
    fn slice_images_read_the_fixed_plane_in_screen_order() {
        let ct = numbered([6, 5, 2]);
        let g = ct.geometry().clone();
        // Axial slice k = 1 at full size: x = i, y = j, values i + 10 j + 100.
        let plain = |size| Shown {
            window: 255.0,
            level: 127.5,
            size,
            changes: None,
            cleansed: false,
            outline: false,
        };
        let a = slice_image(&ct, layout(&g, Plane::Axial), 1, &plain([6, 5]));
        for (x, y) in [(0, 0), (5, 0), (2, 3), (5, 4)] {
            assert_eq!(value(&a, x, y), (x + 10 * y + 100) as i16);
        }
        // Coronal slice j = 2: x = i, y = k reversed (head up): the top row is k = 1.
        let c = slice_image(&ct, layout(&g, Plane::Coronal), 2, &plain([6, 2]));
        assert_eq!(value(&c, 4, 0), 4 + 20 + 100);
        assert_eq!(value(&c, 4, 1), 4 + 20);
        // Sagittal slice i = 3 at half width: x = j under each pixel's centre (1, 3), y = k reversed.
        let s = slice_image(&ct, layout(&g, Plane::Sagittal), 3, &plain([2, 2]));
        assert_eq!(value(&s, 0, 0), 3 + 10 + 100);
        assert_eq!(value(&s, 1, 1), 3 + 30);
    }
}
