//! What the camera sees, without a GPU: the reference rasterizer (depth and triangle-id buffers), the
//! endoscope shading both renderers share, the surface laid out by cell, and the visibility
//! strategies that choose which cells to draw (paper §4.3); close-up volume rendering of
//! the CT in a small box (paper Fig. 9); and the translucency view, the surface coloured by
//! what lies beneath it.
//! Coverage of the mucosa: what the frames shown have shown, the unseen patches and a pose
//! for each ([`Coverage`]); the reading that marks it, stepped by the CLI and the window alike
//! ([`ReadingRun`]).
//! Markers and measurements ([`Findings`]) are picked on the same surface ([`pick`]).
//! The window's panels drawn on the CPU, without a window toolkit: the scout, the colon
//! from outside ([`ScoutMesh`], [`scout_image`]), and the CT resliced for the slices
//! ([`SliceLayout`], [`slice_image`]).

mod both;
mod closeup;
mod coverage;
mod findings;
mod link;
mod mesh;
mod polyp;
mod raster;
mod reading;
mod rgba;
mod scout;
mod shading;
mod slices;
#[cfg(feature = "survey")]
mod survey;
mod translucency;
mod visibility;

pub use both::{
    ARC_BIN_MM, BothCoverage, LinkedFinding, MOVED_ANGLE_DEG, MOVED_MM, MucosaMap, Read,
    SAME_FINDING_ARC_MM, SAME_FINDING_MM, SECTORS, both_coverage, both_readings, link_findings,
};
pub use closeup::{CloseupBox, MAX_HALF_SIZE_MM, TfPoint, TransferFunction, render_closeup};
pub use coverage::{
    Coverage, CoverageOptions, GLANCE_EVERY_MM, GLANCE_MIN_MM2, GLANCE_TURN_DEG, GLANCE_WAYS,
    Glances, Lumen, Patch, READING_FOV_DEG, REVIEW_MIN_MM2, Reader, SegmentSeen, glance_turns,
    viewing_poses,
};
pub use findings::{
    Adequacy, C0_BELOW_COVERAGE_PCT, CRads, FindingKind, Findings, Hit, Marker, Measurement,
    c_rads, pick,
};
pub use link::{Link, STEP_MM as LINK_STEP_MM, centerline_at};
pub use mesh::{CHUNK_TRIANGLES, CellMesh, Chunk, DISPLAY_NORMAL_PASSES, smooth_normals};
pub use polyp::{MIN_HEIGHT_MM, PolypSize, measure_polyp};
pub use raster::{
    Frame, NO_TRIANGLE, Pixel, Rasterizer, ScreenRect, Shading, View, render_rgba, shade,
};
pub use reading::{
    POSES_PER_VISIT, READING_PX, REVIEW_ROUNDS, Reading, ReadingMove, ReadingProgress, ReadingRun,
    ReadingStep, Scene, Visit, patch_pose, read_both_ways,
};
pub use rgba::Rgba;
pub use scout::{ScoutCanvas, ScoutMesh, ScoutOrbit, ScoutProjection, scout_image};
pub use shading::{Lighting, encode};
pub use slices::{Plane, SliceLayout, SliceShading, changes_in_plane, slice_image};
#[cfg(feature = "survey")]
pub use survey::{StrategyStats, Survey, look_around, survey};
pub use translucency::{
    HALF_SIZE_MM, Material, Surfel, Translucency, TranslucencyOptions, render_translucency,
    surface_point,
};
pub use visibility::{Drawn, Strategy, Visibility};
