//! The navigator's state on closing (`--report`): what tests and scripted demonstrations read
//! back. Never anything about the patient's identity.

use std::collections::BTreeMap;

use serde::Serialize;
use voyage_view::Marker;

use super::frame_times::FrameSummary;

#[derive(Serialize)]
pub struct Report {
    /// A study is open.
    pub ready: bool,
    pub error: Option<String>,
    /// Frames drawn since the study became ready (or failed).
    pub frames: u64,
    pub renderer: String,
    /// Camera [x, y, z, qw, qx, qy, qz], volume-local mm.
    pub pose: Option<[f64; 7]>,
    pub playing: Option<bool>,
    /// Poses a script recorded, by name.
    pub recorded: BTreeMap<String, [f64; 7]>,
    pub markers: Vec<MarkerReport>,
    pub measurements_mm: Vec<f64>,
    /// The last 240 frames.
    pub frame_ms: FrameSummary,
    /// Every frame drawn while the automatic flight played.
    pub flying_frame_ms: FrameSummary,
    /// Mean time to draw the view, ms.
    pub render_ms: f64,
    /// The view's rectangle in window points [left, top, right, bottom].
    pub view_rect: Option<[f32; 4]>,
    /// Cells and triangles drawn in the last frame.
    pub cells: usize,
    pub triangles: usize,
    /// The colon's segments, gaps and corrections.
    pub colon: Option<serde_json::Value>,
    /// The patient's sides drawn at the edges of the axial, coronal and sagittal slices in
    /// the last frame (left, right, top, bottom).
    pub slice_letters: [Vec<&'static str>; 3],
    /// The centerline point under the pointer on the scout (lit up there), if any.
    pub scout_hovered: Option<usize>,
    /// What the frames shown showed of the mucosa, and the two-way reading.
    pub coverage: Option<CoverageReport>,
    pub correction_error: Option<String>,
    /// With two positions of an exam open (supine and prone): which.
    pub positions: Option<PositionsReport>,
    /// The status line at the top of the window, as last shown.
    pub status: String,
}

#[derive(Serialize)]
pub struct CoverageReport {
    pub on: bool,
    /// Seen share of the mucosa since the study opened, and in the current flight (%).
    pub session_pct: f64,
    pub flight_pct: f64,
    /// Mean time to mark a frame, ms (coverage's own cost per frame marked).
    pub mark_ms: f64,
    /// Mean time of one step of the two-way reading (ms; 0 before one).
    pub step_ms: f64,
    /// Frames shown from a new pose, and those marked (within the time budget).
    pub frames_asked: u64,
    pub frames_marked: u64,
    pub reading: Option<ReadingReport>,
}

#[derive(Serialize)]
pub struct ReadingReport {
    /// "forward", "backward", "review" or "done".
    pub stage: String,
    pub one_way_pct: Option<f64>,
    pub two_way_pct: Option<f64>,
    pub after_review_pct: Option<f64>,
    /// Unseen patches when the review began, and the visits it made.
    pub patches: usize,
    pub visits: usize,
    /// Glances around the flights took.
    pub glances: usize,
}

#[derive(Serialize)]
pub struct PositionsReport {
    /// "supine", "prone" ...
    pub shown: &'static str,
    pub other: &'static str,
    /// Where the camera's place lies in the other position (its volume-local mm).
    pub linked_mm: Option<[f64; 3]>,
    /// A marker of the other position looked up in the one shown: label, volume-local mm.
    pub looked_up: Option<(String, [f64; 3])>,
    /// The other position's markers (its volume-local mm).
    pub other_markers: Vec<MarkerReport>,
}

#[derive(Serialize)]
pub struct MarkerReport {
    pub label: String,
    pub note: String,
    pub kind: &'static str,
    pub size_mm: Option<f64>,
    pub position_mm: [f64; 3],
}

impl MarkerReport {
    pub fn of(m: &Marker) -> Self {
        MarkerReport {
            label: m.label.clone(),
            note: m.note.clone(),
            kind: m.kind.name(),
            size_mm: m.size_mm,
            position_mm: m.position.to_array(),
        }
    }
}
