//! Exports that other tools open, over the study, its flights and its reading (`voyage-io`
//! stays the loaders and writers of volumes, below navigation and views). Every file is
//! written atomically (temp + rename). Patient coordinates (LPS mm) are used here, at the
//! edge, and nowhere inside the pipeline. No patient identity is ever written.

mod findings;
pub mod markups;
pub mod mesh;
mod pair;
pub mod report;
pub mod study;
pub mod trajectory;

pub use findings::{export_findings, export_reading, read_findings};
pub use markups::{MarkupsPoint, write_markups_curve};
pub use mesh::{write_ply, write_stl};
pub use pair::{PositionReading, export_pair_reading};
pub use report::{
    ColonRead, Exam, HandCorrection, Report, ReportCoverage, ReportFinding, write_report_html,
};
