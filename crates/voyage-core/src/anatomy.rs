//! The patient frame: which way is inferior, left, anterior, and where gravity pulls.
//!
//! Every anatomical decision (the rectum is the lowest colon gas, fluid lies on the dependent
//! side, the cecum is in the right lower quadrant, the lungs are on top) is made here, in
//! patient LPS, from the volume's direction matrix: never from array order, so the same scan
//! stored another way up gives the same answer.
//!
//! Gravity comes from DICOM PatientPosition (0018,5100) when the scan has it, from the user
//! (`--position`), else from the air–fluid levels in the scan (see `segment`), else supine is
//! assumed and the user is told.

use glam::{DMat3, DVec3};
use serde::Serialize;

use crate::Geometry;

/// DICOM PatientPosition (0018,5100): head or feet first; supine, prone or decubitus.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum PatientPosition {
    Hfs,
    Hfp,
    Ffs,
    Ffp,
    /// Decubitus right: lying on the right side.
    Hfdr,
    Hfdl,
    Ffdr,
    Ffdl,
}

impl PatientPosition {
    pub const ALL: [PatientPosition; 8] = [
        Self::Hfs,
        Self::Hfp,
        Self::Ffs,
        Self::Ffp,
        Self::Hfdr,
        Self::Hfdl,
        Self::Ffdr,
        Self::Ffdl,
    ];

    /// The DICOM code ("HFS", ...), case and surrounding spaces ignored.
    pub fn parse(code: &str) -> Option<PatientPosition> {
        let c = code.trim().trim_end_matches('\0').to_ascii_uppercase();
        Self::ALL.into_iter().find(|p| p.code() == c)
    }

    pub fn code(self) -> &'static str {
        match self {
            Self::Hfs => "HFS",
            Self::Hfp => "HFP",
            Self::Ffs => "FFS",
            Self::Ffp => "FFP",
            Self::Hfdr => "HFDR",
            Self::Hfdl => "HFDL",
            Self::Ffdr => "FFDR",
            Self::Ffdl => "FFDL",
        }
    }

    /// Where gravity pulls, as a unit vector in patient LPS. Head or feet first does not
    /// change it: the patient frame turns with the patient.
    pub fn gravity_lps(self) -> DVec3 {
        match self {
            // Written out: `-DVec3::Y` would carry −0.0 into the reports.
            Self::Hfs | Self::Ffs => DVec3::new(0.0, 1.0, 0.0), // posterior
            Self::Hfp | Self::Ffp => DVec3::new(0.0, -1.0, 0.0), // anterior
            Self::Hfdr | Self::Ffdr => DVec3::new(-1.0, 0.0, 0.0), // the patient's right
            Self::Hfdl | Self::Ffdl => DVec3::new(1.0, 0.0, 0.0),
        }
    }

    /// The position whose gravity is nearest `g` (head first).
    pub fn from_gravity(g: DVec3) -> PatientPosition {
        [Self::Hfs, Self::Hfp, Self::Hfdr, Self::Hfdl]
            .into_iter()
            .max_by(|a, b| a.gravity_lps().dot(g).total_cmp(&b.gravity_lps().dot(g)))
            .unwrap_or(Self::Hfs)
    }

    pub fn describe(self) -> &'static str {
        match self {
            Self::Hfs | Self::Ffs => "supine",
            Self::Hfp | Self::Ffp => "prone",
            Self::Hfdr | Self::Ffdr => "right side down (decubitus)",
            Self::Hfdl | Self::Ffdl => "left side down (decubitus)",
        }
    }
}

/// Where the patient position came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum PositionSource {
    /// DICOM PatientPosition.
    Dicom,
    /// Given by the user (`--position`).
    Given,
    /// Inferred from air–fluid levels: fluid below, air above, across a flat level.
    AirFluidLevels,
    /// Nothing said and no level seen: supine assumed.
    Assumed,
}

impl PositionSource {
    /// Where the position came from, for read-outs.
    pub fn describe(self) -> &'static str {
        match self {
            PositionSource::Dicom => "from the DICOM header",
            PositionSource::Given => "given",
            PositionSource::AirFluidLevels => "from the air–fluid levels",
            PositionSource::Assumed => "assumed",
        }
    }
}

/// The patient's position and gravity, and how they are known.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Orientation {
    pub position: PatientPosition,
    /// Unit vector in patient LPS.
    pub gravity_lps: [f64; 3],
    pub source: PositionSource,
}

impl Orientation {
    pub fn new(position: PatientPosition, source: PositionSource) -> Orientation {
        Orientation {
            position,
            gravity_lps: position.gravity_lps().to_array(),
            source,
        }
    }

    pub fn gravity(&self) -> DVec3 {
        DVec3::from_array(self.gravity_lps)
    }
}

/// Patient directions in a volume's local frame (volume-local mm axes).
#[derive(Clone, Copy, Debug)]
pub struct PatientFrame {
    /// Columns: LPS unit vectors of the volume's i, j, k axes.
    dir: DMat3,
}

impl PatientFrame {
    pub fn of(g: &Geometry) -> PatientFrame {
        PatientFrame {
            dir: g.direction_mat(),
        }
    }

    /// An LPS direction as a volume-local direction.
    pub fn local(&self, lps: DVec3) -> DVec3 {
        self.dir.transpose() * lps
    }

    /// A volume-local direction in LPS.
    pub fn lps(&self, local: DVec3) -> DVec3 {
        self.dir * local
    }

    /// Toward the feet, volume-local.
    pub fn inferior(&self) -> DVec3 {
        self.local(-DVec3::Z)
    }

    /// The voxel axis nearest to an LPS direction, and the sign along it (+1: index rises
    /// that way).
    pub fn nearest_axis(&self, lps: DVec3) -> (usize, i32) {
        let l = self.local(lps);
        let a = (0..3)
            .max_by(|&x, &y| l[x].abs().total_cmp(&l[y].abs()))
            .unwrap_or(2);
        (a, if l[a] >= 0.0 { 1 } else { -1 })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn positions_parse_and_give_gravity() {
        assert_eq!(PatientPosition::parse(" hfp\0"), Some(PatientPosition::Hfp));
        assert_eq!(PatientPosition::parse("XYZ"), None);
        for p in PatientPosition::ALL {
            assert_eq!(PatientPosition::parse(p.code()), Some(p));
            let g = p.gravity_lps();
            assert!((g.length() - 1.0).abs() < 1e-12);
            assert_eq!(PatientPosition::from_gravity(g).gravity_lps(), g);
        }
        assert_eq!(
            PatientPosition::Hfs.gravity_lps(),
            DVec3::new(0.0, 1.0, 0.0)
        );
        assert_eq!(
            PatientPosition::Ffp.gravity_lps(),
            DVec3::new(0.0, -1.0, 0.0)
        );
        assert_eq!(
            PatientPosition::Hfdr.gravity_lps(),
            DVec3::new(-1.0, 0.0, 0.0)
        );
    }

    #[test]
    fn frame_follows_the_direction_matrix() {
        let mut g = Geometry::new([4, 4, 4], [1.0; 3], [0.0; 3]).unwrap();
        // i → R (−x), j → S (+z), k → A (−y): a coronal stack stored oddly.
        g.set_direction_mat(DMat3::from_cols(-DVec3::X, DVec3::Z, -DVec3::Y));
        let f = PatientFrame::of(&g);
        assert!((f.inferior() - DVec3::new(0.0, -1.0, 0.0)).length() < 1e-12);
        assert_eq!(f.nearest_axis(DVec3::Y), (2, -1));
        assert_eq!(f.nearest_axis(-DVec3::X), (0, 1));
    }
}
