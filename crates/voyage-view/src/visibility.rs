//! Which cells to draw (paper §4.3), interleaved with drawing them, since the paper's method
//! and ours read the depth buffer that the nearer cells have just written.
//!
//! From the camera's cell two portal sequences run near to far, toward the target and toward
//! the source. Every line of sight from the camera cell into cell b crosses the portals in
//! between in order (cells.rs guarantees the chain), and each portal is stored as a prism
//! holding the whole boundary between its cells. Hence, at a pixel, a triangle beyond a
//! portal can win only if the pixel's centre lies inside the projection of every portal on
//! the way, and only if what is already drawn there is not nearer than the nearest point of
//! the portal (the crossing point lies in the prism, the triangle beyond it on the same ray).
//! Each strategy below drops a cell only when one of these two facts rules out every pixel,
//! so no strategy can change the id buffer; the tests check it pixel for pixel.
//!
//! - `all`: every cell (the paper's MC column).
//! - `lg`: Luebke & Georges: the aggregate cull rectangle (ACR) is the intersection of the
//!   portals' screen rectangles; a sequence stops when it is empty.
//! - `paper`: LG, plus after each cell the ACR's top and bottom rows are dropped while they
//!   are covered: every pixel in them where a ray could reach the next portal (inside its
//!   projected outline) already holds something nearer than where that ray would first meet
//!   the portal's slab; and temporal coherence: the first 80% of last frame's cells of each
//!   sequence are drawn before any test.
//! - `ours`: per row, an interval instead of one rectangle: the intersection of the portals'
//!   projected convex outlines (not their rectangles), trimmed at both ends of every row by
//!   the depth test, with the depth bound taken per pixel where the ray meets the portal's
//!   slab rather than once for the whole portal.
//!
//! A frame is drawn in horizontal bands, one per worker thread, each band an instance of the
//! same problem over its own rows: on `ctc/prone-tagged` at 512², two bands on two cores
//! take ours from 18 to 12 ms a frame (BENCHMARKS.md). A band's windows are narrower than
//! the whole frame's, so the bands together draw no more triangles than one band would.

use std::{fmt, str::FromStr};

use glam::DVec3;
use serde::Serialize;

use super::raster::{Frame, Rasterizer, Rows, SLACK_PX, ScreenRect, View, centres};
use voyage_core::{Cells, convex_hull};

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Strategy {
    All,
    Lg,
    Paper,
    Ours,
}

impl Strategy {
    pub const ALL: [Strategy; 4] = [Strategy::All, Strategy::Lg, Strategy::Paper, Strategy::Ours];

    pub fn name(self) -> &'static str {
        match self {
            Strategy::All => "all",
            Strategy::Lg => "lg",
            Strategy::Paper => "paper",
            Strategy::Ours => "ours",
        }
    }
}

impl fmt::Display for Strategy {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Strategy {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Strategy::ALL
            .into_iter()
            .find(|k| k.name() == s)
            .ok_or_else(|| format!("unknown visibility strategy '{s}' (all, lg, paper, ours)"))
    }
}

/// What one frame drew.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Drawn {
    /// Cells in the order drawn.
    pub cells: Vec<u32>,
    /// Per cell in `cells`, the pixel centres it can show at (the window its portals leave
    /// open; the whole view for the camera's cell): a renderer may leave out what lies
    /// wholly outside ([`crate::View::box_may_show`]).
    pub rects: Vec<ScreenRect>,
    /// Triangles drawn, each once: in a frame drawn in bands, one that reaches into two
    /// bands is set up in both, and counted once.
    pub triangles: usize,
    /// The camera's cell (None: the camera is outside the lumen and everything was drawn).
    pub camera_cell: Option<u32>,
    /// Portals projected, and depth-buffer pixels read.
    pub portals_tested: usize,
    pub depth_pixels_read: usize,
}

/// A portal as visibility uses it: the corners of its prism and its slab.
#[derive(Clone, Debug)]
struct PortalShape {
    corners: Vec<DVec3>,
    normal: DVec3,
    /// The slab is |normal · x − offset| ≤ half_thickness.
    offset: f64,
    half_thickness: f64,
}

/// Per strategy state across frames (temporal coherence) and the portals' shapes.
pub struct Visibility {
    pub strategy: Strategy,
    /// The paper's temporal coherence (on by default for `paper`; ignored otherwise).
    pub coherence: bool,
    portals: Vec<PortalShape>,
    /// Per band of the frame ([`Visibility::draw`]), last frame's camera cell and the cells
    /// each sequence drew beyond it.
    last: Vec<Option<Last>>,
}

type Last = (u32, [Vec<u32>; 2]);

/// Sequences: toward the target (cell + 1, portal = cell) and toward the source.
const TOWARD_TARGET: usize = 0;
const TOWARD_SOURCE: usize = 1;

/// A band of a frame drawn in bands holds at least this many rows: a band costs a walk of
/// the portals, and the triangles that reach into two bands are set up in both.
const MIN_BAND_ROWS: u32 = 128;

impl Visibility {
    pub fn new(cells: &Cells, strategy: Strategy) -> Self {
        let portals = cells
            .portals
            .iter()
            .map(|p| {
                let normal = DVec3::from_array(p.normal);
                PortalShape {
                    corners: p.bounding_points(),
                    normal,
                    offset: normal.dot(DVec3::from_array(p.centre_mm)),
                    half_thickness: p.half_thickness_mm,
                }
            })
            .collect();
        Visibility {
            strategy,
            coherence: strategy == Strategy::Paper,
            portals,
            last: Vec::new(),
        }
    }

    /// Forgets last frame (after a jump).
    pub fn reset(&mut self) {
        self.last.clear();
    }

    /// Draws what this strategy decides is potentially visible into `frame` (cleared first).
    ///
    /// The frame is drawn in horizontal bands, as many as the worker threads (one band
    /// under 2 × [`MIN_BAND_ROWS`] rows), each band walking the portals over its own rows
    /// alone, on a thread of its own.
    /// Whether and at what depth a triangle covers a pixel depends on that triangle alone,
    /// so the bands make the frame drawn whole, pixel for pixel.
    pub fn draw(&mut self, frame: &mut Frame, raster: &Rasterizer, cells: &Cells) -> Drawn {
        frame.clear();
        let n = rayon::current_num_threads()
            .min((frame.height / MIN_BAND_ROWS) as usize)
            .max(1);
        self.last.resize(n, None);
        let mut lasts = std::mem::take(&mut self.last);
        let drawn = if n == 1 {
            self.draw_band(&mut frame.rows(), raster, cells, &mut lasts[0])
        } else {
            let this = &*self;
            // Threads of the frame's own, not the pool's: the window draws while a study
            // opens in the background, and a band queued behind the pool's work would hold
            // the frame up. Each gets a rasterizer of its own (scratch memory).
            let bands: Vec<Drawn> = std::thread::scope(|scope| {
                let mut work = frame.bands(n).into_iter().zip(lasts.iter_mut());
                let (mut first, first_last) = work.next().expect("n ≥ 2 bands");
                let others: Vec<_> = work
                    .map(|(mut rows, last)| {
                        let raster = raster.clone();
                        scope.spawn(move || this.draw_band(&mut rows, &raster, cells, last))
                    })
                    .collect();
                let mut bands = vec![this.draw_band(&mut first, raster, cells, first_last)];
                bands.extend(others.into_iter().map(|h| {
                    h.join()
                        .unwrap_or_else(|panic| std::panic::resume_unwind(panic))
                }));
                bands
            });
            merge_bands(bands, raster, self.strategy == Strategy::Ours)
        };
        self.last = lasts;
        drawn
    }

    /// [`Self::draw`] over one band of rows; `last` is the band's own last frame.
    fn draw_band(
        &self,
        frame: &mut Rows,
        raster: &Rasterizer,
        cells: &Cells,
        last: &mut Option<Last>,
    ) -> Drawn {
        let view = *raster.view();
        let ncells = cells.cells.len() as u32;
        let camera_cell = cells.cell_of_point(view.eye).map(|c| c as u32);
        let mut drawn = Drawn {
            camera_cell,
            ..Drawn::default()
        };
        let whole = ScreenRect::of_rows(&view, frame);
        let Some(home) = camera_cell.filter(|_| self.strategy != Strategy::All) else {
            let all: Vec<u32> = (0..ncells).collect();
            drawn.triangles = raster.draw_cells(frame, &all);
            drawn.rects = vec![whole; all.len()];
            drawn.cells = all;
            *last = None;
            return drawn;
        };
        let mut done = vec![false; ncells as usize];
        // Ours leaves out the chunks of a cell that lie wholly outside the window its
        // portals leave open (the whole view for the camera's cell): they cannot show there.
        let chunks = self.strategy == Strategy::Ours;
        let mut draw = |c: u32, rect: &ScreenRect, drawn: &mut Drawn, frame: &mut Rows| {
            if !done[c as usize] {
                done[c as usize] = true;
                drawn.triangles += if chunks {
                    raster.draw_cell_within(frame, c, rect)
                } else {
                    raster.draw_cell(frame, c)
                };
                drawn.cells.push(c);
                drawn.rects.push(*rect);
            }
        };
        draw(home, &whole, &mut drawn, frame);
        if self.coherence
            && let Some((last_home, seqs)) = &*last
            && *last_home == home
        {
            for seq in seqs {
                let keep = (seq.len() * 4).div_ceil(5);
                for &c in &seq[..keep] {
                    draw(c, &whole, &mut drawn, frame);
                }
            }
        }
        let mut seqs: [Vec<u32>; 2] = [Vec::new(), Vec::new()];
        for (dir, seq) in seqs.iter_mut().enumerate() {
            let mut region = Region::over(frame);
            let mut cell = home;
            while let Some((portal, next)) = beyond(dir, cell, ncells) {
                drawn.portals_tested += 1;
                if !self.narrow(
                    &mut region,
                    portal,
                    frame,
                    &view,
                    &mut drawn.depth_pixels_read,
                ) {
                    break;
                }
                draw(next, &region.bounds(), &mut drawn, frame);
                seq.push(next);
                cell = next;
            }
        }
        *last = Some((home, seqs));
        drawn
    }

    /// The cells to draw when nobody can read the depth buffer between cells (the GPU
    /// draws them all in one pass): the portal chains narrowed by the portals' projections
    /// alone — rectangles for `lg`, convex outlines for `paper` and `ours`. Exact for the
    /// same reason as [`Self::draw`] (a cell is dropped only when no pixel centre lies in
    /// every portal's projection on the way), only less tight.
    pub fn select(&mut self, cells: &Cells, view: &View) -> Drawn {
        let ncells = cells.cells.len() as u32;
        let camera_cell = cells.cell_of_point(view.eye).map(|c| c as u32);
        let mut drawn = Drawn {
            camera_cell,
            ..Drawn::default()
        };
        let whole = ScreenRect::full(view);
        let Some(home) = camera_cell.filter(|_| self.strategy != Strategy::All) else {
            drawn.cells = (0..ncells).collect();
            drawn.rects = vec![whole; ncells as usize];
            return drawn;
        };
        drawn.cells.push(home);
        drawn.rects.push(whole);
        for dir in [TOWARD_TARGET, TOWARD_SOURCE] {
            let mut region = Region::full(view);
            let mut cell = home;
            while let Some((portal, next)) = beyond(dir, cell, ncells) {
                drawn.portals_tested += 1;
                let Some(outline) = project_prism(&self.portals[portal].corners, view) else {
                    break;
                };
                let open = match self.strategy {
                    Strategy::Lg => region.clip_rect(&outline, view),
                    _ => region.clip_hull(&outline, view),
                };
                if !open {
                    break;
                }
                drawn.cells.push(next);
                drawn.rects.push(region.bounds());
                cell = next;
            }
        }
        drawn
    }

    /// Narrows a sequence's region by the next portal; false when nothing can be seen
    /// through it any more.
    fn narrow(
        &self,
        region: &mut Region,
        portal: usize,
        frame: &Rows,
        view: &View,
        reads: &mut usize,
    ) -> bool {
        let shape = &self.portals[portal];
        let Some(outline) = project_prism(&shape.corners, view) else {
            return false;
        };
        match self.strategy {
            Strategy::All => true,
            Strategy::Lg => region.clip_rect(&outline, view),
            Strategy::Paper => {
                region.clip_rect(&outline, view)
                    && region.drop_covered_rows(frame, (shape, &outline), view, reads)
            }
            Strategy::Ours => {
                region.clip_hull(&outline, view)
                    && region.trim_covered(frame, shape, outline.min_depth, view, reads)
            }
        }
    }
}

/// One frame's [`Drawn`] from its bands': the cells in the order the bands first drew them,
/// each with the rectangle round its windows in all bands, and each triangle counted once
/// (one that reaches into two bands is set up in both). `chunks`: the cells were drawn
/// within their windows (ours), not whole.
fn merge_bands(bands: Vec<Drawn>, raster: &Rasterizer, chunks: bool) -> Drawn {
    let mut out = Drawn {
        camera_cell: bands.first().and_then(|b| b.camera_cell),
        ..Drawn::default()
    };
    let mut at = std::collections::HashMap::new();
    let mut windows: Vec<Vec<ScreenRect>> = Vec::new();
    for band in bands {
        out.portals_tested += band.portals_tested;
        out.depth_pixels_read += band.depth_pixels_read;
        for (c, rect) in band.cells.into_iter().zip(band.rects) {
            let k = *at.entry(c).or_insert_with(|| {
                out.cells.push(c);
                windows.push(Vec::new());
                windows.len() - 1
            });
            windows[k].push(rect);
        }
    }
    out.rects = windows.iter().map(|w| ScreenRect::around(w)).collect();
    out.triangles = out
        .cells
        .iter()
        .zip(&windows)
        .map(|(&c, w)| raster.triangles_in(c, chunks.then_some(w.as_slice())))
        .sum();
    out
}

/// The portal from `cell` onward in sequence `dir`, and the cell beyond it (None at the
/// chain's end).
fn beyond(dir: usize, cell: u32, ncells: u32) -> Option<(usize, u32)> {
    match dir {
        TOWARD_TARGET if cell + 1 < ncells => Some((cell as usize, cell + 1)),
        TOWARD_SOURCE if cell > 0 => Some((cell as usize - 1, cell - 1)),
        _ => None,
    }
}

/// The portal's prism on screen: the projected corners' convex hull and the prism's least
/// depth. None when the prism lies wholly behind the eye.
struct Outline {
    hull: Vec<(f64, f64)>,
    min_depth: f64,
}

/// Depth at which a prism reaching behind the eye is cut: its part in front still bounds
/// every ray that crosses it in front of the eye.
const CUT_DEPTH_MM: f64 = 1e-6;

fn project_prism(corners: &[DVec3], view: &View) -> Option<Outline> {
    let eye: Vec<DVec3> = corners.iter().map(|&p| view.to_eye(p)).collect();
    let front = eye.iter().filter(|e| e.z > CUT_DEPTH_MM).count();
    if front == 0 {
        return None;
    }
    let mut pts: Vec<DVec3> = eye.iter().copied().filter(|e| e.z > CUT_DEPTH_MM).collect();
    if front < eye.len() {
        // The prism is the hull of its corners; its part in front of the cut is the hull of
        // the corners in front and of every corner-to-corner segment's crossing of the cut.
        for a in eye.iter().filter(|e| e.z > CUT_DEPTH_MM) {
            for b in eye.iter().filter(|e| e.z <= CUT_DEPTH_MM) {
                let t = (a.z - CUT_DEPTH_MM) / (a.z - b.z);
                let mut x = *a + (*b - *a) * t;
                x.z = CUT_DEPTH_MM;
                pts.push(x);
            }
        }
    }
    let min_depth = pts.iter().map(|e| e.z).fold(f64::INFINITY, f64::min);
    let hull = convex_hull(pts.iter().map(|&e| view.project(e)).collect());
    Some(Outline { hull, min_depth })
}

/// A sequence's region of the screen: per row an inclusive interval of pixel columns
/// (empty when lo > hi), over rows `y0..=y1`.
struct Region {
    y0: i64,
    y1: i64,
    rows: Vec<(i64, i64)>,
}

impl Region {
    /// The whole view, over all the rows it has (a band's or the frame's).
    fn over(frame: &Rows) -> Self {
        Region::spanning(frame.first(), frame.last(), frame.width() as i64)
    }

    /// The whole view.
    fn full(view: &View) -> Self {
        Region::spanning(0, view.height as i64 - 1, view.width as i64)
    }

    /// Every column of rows `y0..=y1`, `width` wide.
    fn spanning(y0: i64, y1: i64, width: i64) -> Self {
        Region {
            y0,
            y1,
            rows: vec![(0, width - 1); (y1 + 1).max(0) as usize],
        }
    }

    fn is_empty(&self) -> bool {
        self.y0 > self.y1
    }

    /// The rectangle around the region's rows.
    fn bounds(&self) -> ScreenRect {
        let rows = (self.y0.max(0)..=self.y1)
            .map(|y| self.rows[y as usize])
            .filter(|r| r.0 <= r.1);
        let (x0, x1) = rows.fold((i64::MAX, i64::MIN), |(a, b), r| (a.min(r.0), b.max(r.1)));
        ScreenRect {
            x0,
            x1,
            y0: self.y0,
            y1: self.y1,
        }
    }

    /// Drops empty rows at the top and bottom.
    fn settle(&mut self) -> bool {
        while self.y0 <= self.y1 && self.rows[self.y0 as usize].0 > self.rows[self.y0 as usize].1 {
            self.y0 += 1;
        }
        while self.y1 >= self.y0 && self.rows[self.y1 as usize].0 > self.rows[self.y1 as usize].1 {
            self.y1 -= 1;
        }
        !self.is_empty()
    }

    /// Intersects with the outline's bounding rectangle (LG, paper).
    fn clip_rect(&mut self, o: &Outline, view: &View) -> bool {
        let (mut x0, mut x1, mut y0, mut y1) = (
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        );
        for &(x, y) in &o.hull {
            x0 = x0.min(x);
            x1 = x1.max(x);
            y0 = y0.min(y);
            y1 = y1.max(y);
        }
        let (c0, c1) = centres(x0, x1, view.width);
        let (r0, r1) = centres(y0, y1, view.height);
        self.y0 = self.y0.max(r0);
        self.y1 = self.y1.min(r1);
        for y in self.y0.max(0)..=self.y1 {
            let row = &mut self.rows[y as usize];
            *row = (row.0.max(c0), row.1.min(c1));
        }
        self.settle()
    }

    /// Intersects with the outline's hull, row by row (ours).
    fn clip_hull(&mut self, o: &Outline, view: &View) -> bool {
        for y in self.y0.max(0)..=self.y1 {
            let cy = y as f64 + 0.5;
            let row = &mut self.rows[y as usize];
            *row = match hull_span(&o.hull, cy) {
                Some((a, b)) => {
                    let (c0, c1) = centres(a, b, view.width);
                    (row.0.max(c0), row.1.min(c1))
                }
                None => (1, 0),
            };
        }
        self.settle()
    }

    /// The paper's Z-buffer step: drops rows at the top and bottom whose pixels are all
    /// covered. The paper counts a pixel covered once a nearer cell wrote it. That alone could
    /// hide a triangle beyond the portal in front of what a concave cell drew, so here a pixel
    /// is covered where its ray cannot meet the portal's prism (outside its outline), or meets
    /// it only behind what is drawn there.
    fn drop_covered_rows(
        &mut self,
        frame: &Rows,
        portal: (&PortalShape, &Outline),
        view: &View,
        reads: &mut usize,
    ) -> bool {
        let (shape, outline) = portal;
        let bound = SlabBound::new(shape, outline.min_depth, view);
        let covered = |y: i64, row: (i64, i64), reads: &mut usize| {
            let Some((a, b)) = hull_span(&outline.hull, y as f64 + 0.5) else {
                return true;
            };
            let (c0, c1) = centres(a, b, view.width);
            (row.0.max(c0)..=row.1.min(c1)).all(|x| {
                *reads += 1;
                bound.hides(frame, view, x, y)
            })
        };
        while self.y0 <= self.y1 && covered(self.y0, self.rows[self.y0 as usize], reads) {
            self.y0 += 1;
        }
        while self.y1 >= self.y0 && covered(self.y1, self.rows[self.y1 as usize], reads) {
            self.y1 -= 1;
        }
        !self.is_empty()
    }

    /// Ours: trims both ends of every row while the pixel is nearer than where its ray can
    /// first meet the portal's slab.
    fn trim_covered(
        &mut self,
        frame: &Rows,
        portal: &PortalShape,
        min_depth: f64,
        view: &View,
        reads: &mut usize,
    ) -> bool {
        let bound = SlabBound::new(portal, min_depth, view);
        for y in self.y0.max(0)..=self.y1 {
            let (mut lo, mut hi) = self.rows[y as usize];
            let hidden = |x: i64, reads: &mut usize| {
                *reads += 1;
                bound.hides(frame, view, x, y)
            };
            while lo <= hi && hidden(lo, reads) {
                lo += 1;
            }
            while hi >= lo && hidden(hi, reads) {
                hi -= 1;
            }
            self.rows[y as usize] = (lo, hi);
        }
        self.settle()
    }
}

/// Where, at the earliest, a pixel's ray can enter a portal's slab: a per-pixel bound that
/// is tighter than the prism's least depth when the portal is seen at a slant (the paper's
/// covered rows and ours's trimmed rows both judge a pixel by it).
struct SlabBound {
    /// Slab plane facing the eye: n·x = c; the eye is on the side n·x < c. None when the
    /// eye is inside the slab (then nothing is bounded).
    plane: Option<(DVec3, f64)>,
    eye_side: f64,
    /// The inverse of the prism's least depth, a hair nearer, so that rounding can never hide
    /// a pixel that sees through.
    prism: f64,
}

impl SlabBound {
    fn new(p: &PortalShape, min_depth: f64, view: &View) -> Self {
        let prism = 1.0 / (min_depth * (1.0 - 1e-6));
        let s = p.normal.dot(view.eye) - p.offset;
        let (n, c) = if s < -p.half_thickness {
            (p.normal, p.offset - p.half_thickness)
        } else if s > p.half_thickness {
            (-p.normal, -(p.offset + p.half_thickness))
        } else {
            return SlabBound {
                plane: None,
                eye_side: 0.0,
                prism,
            };
        };
        SlabBound {
            plane: Some((n, c)),
            eye_side: n.dot(view.eye),
            prism,
        }
    }

    /// Whether what `frame` holds at pixel (x, y) is nearer than where that pixel's ray could
    /// first meet the portal (its slab, and no nearer than the prism): nothing beyond the
    /// portal can show there.
    fn hides(&self, frame: &Rows, view: &View, x: i64, y: i64) -> bool {
        let w = frame.pixel(x, y).inv_depth;
        w > 0.0 && (w as f64) > self.max_inv_depth(view, x, y).min(self.prism)
    }

    /// The largest inverse depth (nearest point) at which the ray through pixel (x, y) can
    /// be in the slab; +∞ when unbounded.
    fn max_inv_depth(&self, view: &View, x: i64, y: i64) -> f64 {
        let Some((n, c)) = self.plane else {
            return f64::INFINITY;
        };
        // Ray eye + s·d with d's forward component 1 (so s is the depth).
        let d = view.pixel_direction(x as u32, y as u32);
        let nd = n.dot(d);
        if nd <= 0.0 {
            // Running parallel to or away from the slab: it never enters it.
            return 0.0;
        }
        let depth = (c - self.eye_side) / nd;
        // A hair nearer, for rounding.
        1.0 / (depth * (1.0 - 1e-6)).max(1e-12)
    }
}

/// The x extent of a convex polygon along the horizontal line y (a line within the slack
/// of the top or bottom vertex counts as touching it).
fn hull_span(hull: &[(f64, f64)], y: f64) -> Option<(f64, f64)> {
    let (ymin, ymax) = hull
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
            (a.min(p.1), b.max(p.1))
        });
    if hull.is_empty() || y < ymin - SLACK_PX || y > ymax + SLACK_PX {
        return None;
    }
    let y = y.clamp(ymin, ymax);
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for (i, &p) in hull.iter().enumerate() {
        if p.1 == y {
            lo = lo.min(p.0);
            hi = hi.max(p.0);
        }
        let q = hull[(i + 1) % hull.len()];
        if (p.1 - y) * (q.1 - y) < 0.0 {
            let x = p.0 + (q.0 - p.0) * (y - p.1) / (q.1 - p.1);
            lo = lo.min(x);
            hi = hi.max(x);
        }
    }
    (lo <= hi).then_some((lo, hi))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hull_spans_cover_the_polygon() {
        let sq = convex_hull(vec![
            (1.0, 1.0),
            (5.0, 1.0),
            (5.0, 5.0),
            (1.0, 5.0),
            (3.0, 3.0),
        ]);
        assert_eq!(sq.len(), 4);
        assert_eq!(hull_span(&sq, 2.0), Some((1.0, 5.0)));
        assert_eq!(hull_span(&sq, 6.0), None);
        let tri = convex_hull(vec![(0.0, 0.0), (10.0, 0.0), (0.0, 10.0)]);
        let (a, b) = hull_span(&tri, 5.0).unwrap();
        assert!((a - 0.0).abs() < 1e-12 && (b - 5.0).abs() < 1e-12);
        assert_eq!(centres(0.2, 2.6, 100), (0, 2));
        assert_eq!(centres(-5.0, -1.0, 100), (1, 0));
    }

    /// A diamond portal 10 mm across, 50 mm ahead of an eye looking down +z, seen at 64²;
    /// the frame holds a wall 20 mm ahead wherever `drawn` says.
    fn diamond_ahead(drawn: impl Fn(i64, i64, (f64, f64)) -> bool) -> (Region, bool) {
        let view = View {
            eye: DVec3::ZERO,
            right: DVec3::X,
            up: DVec3::Y,
            forward: DVec3::Z,
            width: 64,
            height: 64,
            focal: 64.0,
            near: 1.0,
        };
        let outline = [(5.0, 0.0), (0.0, 5.0), (-5.0, 0.0), (0.0, -5.0)];
        let corners: Vec<DVec3> = outline
            .iter()
            .flat_map(|&(x, y)| [DVec3::new(x, y, 49.5), DVec3::new(x, y, 50.5)])
            .collect();
        let shape = PortalShape {
            corners: corners.clone(),
            normal: DVec3::Z,
            offset: 50.0,
            half_thickness: 0.5,
        };
        let projected = project_prism(&corners, &view).unwrap();
        let mut frame = Frame::new(64, 64);
        for y in 0..64 {
            for x in 0..64 {
                let inside = hull_span(&projected.hull, y as f64 + 0.5);
                if drawn(x, y, inside.unwrap_or((1.0, 0.0))) {
                    frame.pixels[(y * 64 + x) as usize].inv_depth = 1.0 / 20.0;
                }
            }
        }
        let mut region = Region::spanning(0, 63, 64);
        let mut reads = 0;
        let open = region.clip_rect(&projected, &view)
            && region.drop_covered_rows(&frame.rows(), (&shape, &projected), &view, &mut reads);
        (region, open)
    }

    #[test]
    fn the_papers_covered_rows_are_judged_within_the_portals_outline() {
        // Drawn nearer than the portal wherever the diamond shows, nothing round it: every
        // row of the rectangle is covered where a ray could reach the portal.
        let (_, open) = diamond_ahead(|x, _, (a, b)| {
            (x as f64 + 0.5) >= a - 1.0 && (x as f64 + 0.5) <= b + 1.0
        });
        assert!(
            !open,
            "the portal is hidden where it shows: nothing beyond it can be seen"
        );
        // One pixel inside the diamond left open in its middle row: the rows above and below
        // it are dropped, that one stays.
        let (region, open) = diamond_ahead(|x, y, (a, b)| {
            (x as f64 + 0.5) >= a - 1.0 && (x as f64 + 0.5) <= b + 1.0 && !(x == 32 && y == 32)
        });
        assert!(open);
        assert_eq!((region.y0, region.y1), (32, 32));
    }

    #[test]
    fn strategy_names_round_trip() {
        for s in Strategy::ALL {
            assert_eq!(s.name().parse::<Strategy>().unwrap(), s);
        }
        assert!("lgx".parse::<Strategy>().is_err());
    }
}
