//! Ground truth that comes with every phantom, serialisable to JSON.
//!
//! All points are in volume-local millimetres (x = i·sx, y = j·sy, z = k·sz); the origin
//! and direction given alongside turn them into LPS patient coordinates:
//! `lps = origin + direction · local`.

use serde::{Deserialize, Serialize};

/// What the JSON says about its coordinates.
pub const COORDINATES_NOTE: &str = "All *_mm points are volume-local millimetres: x = i*spacing[0], y = j*spacing[1], \
z = k*spacing[2] (voxel centres). Patient LPS = origin_lps_mm + direction * local (direction columns are the LPS \
unit vectors of the i, j, k axes; identity here: +x patient left, +y posterior, +z superior). Arc lengths are mm \
along the centerline from its first point.";

#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct Truth {
    /// "pipe" or "colon".
    pub kind: String,
    pub seed: u64,
    pub coordinates: String,
    /// Patient position as DICOM (0018,5100) says it: "HFS" (head first, supine) or "HFP"
    /// (prone). The volume's geometry is the same for both (identity LPS).
    #[serde(default = "hfs")]
    pub position: String,
    /// Unit vector of gravity in LPS: [0, 1, 0] (posterior) supine, [0, −1, 0] prone. Tagged
    /// fluid pools on that side of each air–fluid level.
    #[serde(default = "supine_gravity")]
    pub gravity_lps: [f64; 3],
    pub dims: [usize; 3],
    pub spacing_mm: [f64; 3],
    pub origin_lps_mm: [f64; 3],
    /// Row-major; columns are the LPS unit vectors of i, j, k.
    pub direction: [[f64; 3]; 3],
    /// Size of the anatomy relative to the full-size model (0.5 for the small colon).
    pub scale: f64,
    pub noise_hu: f64,
    /// The CT's values are rounded to multiples of this step (after the noise), if given.
    #[serde(default)]
    pub quantize_hu: Option<f64>,
    /// The tube's axis, source end first, vertices at most 1 mm apart. It runs on through
    /// collapsed and fluid-filled stretches: the true path through every gap in the gas.
    pub centerline_mm: Vec<[f64; 3]>,
    pub centerline_arc_mm: Vec<f64>,
    /// Nominal lumen radius at each centerline point (without folds, collapse or polyps).
    pub centerline_radius_mm: Vec<f64>,
    pub centerline_length_mm: f64,
    pub source_mm: [f64; 3],
    pub target_mm: [f64; 3],
    pub source_arc_mm: f64,
    pub target_arc_mm: f64,
    /// Thickness of the colon (or pipe) wall.
    pub wall_thickness_mm: f64,
    /// Smallest lumen-to-lumen distance between different parts of the tube (nominal radii).
    pub min_part_gap_mm: f64,
    pub polyps: Vec<PolypTruth>,
    /// Voxels of the ground-truth lumen mask.
    pub lumen_voxels: usize,
    /// Number of haustral folds.
    pub folds: usize,
    pub fold_list: Vec<FoldTruth>,
    /// Named parts of the tube along the centerline, in order.
    pub segments: Vec<SegmentTruth>,
    pub fluid_pools: Vec<PoolTruth>,
    /// Lumen voxels filled with tagged fluid (label 3).
    pub fluid_voxels: usize,
    /// Collapsed stretches (no lumen), in order along the centerline. Older files with one
    /// object or null here read as a list of one or none.
    #[serde(default, deserialize_with = "one_or_many")]
    pub collapsed: Vec<CollapsedTruth>,
    /// Stretches filled to the brim with tagged fluid (lumen, but no gas), in order.
    #[serde(default)]
    pub fluid_filled: Vec<FilledTruth>,
    /// Where the colon's gas is interrupted while its path goes on (collapsed and
    /// fluid-filled stretches), sorted by arc length.
    #[serde(default)]
    pub gas_gaps: Vec<GapTruth>,
    /// Things that are not colon: small-bowel gas pockets and opacified small-bowel loops
    /// (kind "opacified_small_bowel", one entry per loop: the box around it), lung bases.
    pub distractors: Vec<DistractorTruth>,
    /// Opacified small-bowel loops (label 9): each loop's axis and radii.
    #[serde(default)]
    pub small_bowel_loops: Vec<LoopTruth>,
    /// Where the terminal ileum opens into the caecum (on the caecal lumen's surface, on the
    /// dependent side, under the caecal pool's level), with opacified small bowel.
    #[serde(default)]
    pub ileocecal_valve_mm: Option<[f64; 3]>,
    /// Lumps of tagged stool on the wall (label 11), with `tagged_stool`.
    #[serde(default)]
    pub stool: Vec<StoolTruth>,
    /// The rectal catheter, if any (its air is label 10).
    #[serde(default)]
    pub rectal_tube: Option<RectalTubeTruth>,
    /// Height (z, mm) of the skin of the perineum under which there is only outside air, if
    /// the body has one (with a rectal catheter); otherwise the body fills every slice.
    #[serde(default)]
    pub body_floor_z_mm: Option<f64>,
    /// The CT table under the patient, if any (its voxels are label 0, the air around it 1).
    #[serde(default)]
    pub table: Option<TableTruth>,
    /// Skin folds: crevices of outside air (label 1) cut into the body.
    #[serde(default)]
    pub skin_folds: Vec<SkinFoldTruth>,
    /// Diverticula: pouches of the colon's gas outside its wall (colon lumen, label 2).
    #[serde(default)]
    pub diverticula: Vec<DiverticulumTruth>,
    /// A box of homogeneous tissue (inclusive voxel ranges) for measuring noise.
    pub noise_roi: Option<RoiTruth>,
    /// Noise-free HU of the materials.
    pub materials_hu: Vec<(String, f64)>,
    /// Meaning of the label volume's values.
    pub labels: Vec<(u8, String)>,
}

#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct PolypTruth {
    /// Centre of the polyp's head (a sphere).
    pub center_mm: [f64; 3],
    pub diameter_mm: f64,
    /// Name of the segment it sits in.
    pub segment: String,
    /// On the far side of a fold when flying source → target (hidden from afar).
    pub behind_fold: bool,
    pub arc_mm: f64,
    /// Angle around the axis, in the centerline's rotation-minimising frame.
    pub angle_rad: f64,
    /// Where it meets the nominal wall.
    pub base_mm: [f64; 3],
    /// Unit vector from the base into the lumen.
    pub direction: [f64; 3],
    /// How far the head reaches in from the nominal wall.
    pub protrusion_mm: f64,
    /// "sessile" or "pedunculated".
    pub shape: String,
    /// Pedunculated: length of the stalk between the wall and the head.
    pub stalk_length_mm: f64,
}

#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct FoldTruth {
    pub arc_mm: f64,
    /// Half the fold's thickness at its base.
    pub half_width_mm: f64,
    /// Frame angle of the first taenia (crescents lie between taeniae).
    pub phase_rad: f64,
    /// Depth of each of the three crescents.
    pub depth_mm: [f64; 3],
    /// Shift of each crescent along the axis.
    pub offset_mm: [f64; 3],
    pub segment: String,
}

#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct SegmentTruth {
    pub name: String,
    pub start_arc_mm: f64,
    pub end_arc_mm: f64,
}

#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct PoolTruth {
    pub segment: String,
    pub start_arc_mm: f64,
    pub end_arc_mm: f64,
    /// The air–fluid level, the plane y = level_y_mm. The fluid lies on the side gravity
    /// points to: y > level for a supine patient (posterior), y < level prone (anterior).
    pub level_y_mm: f64,
    /// Gravity (LPS unit vector) for this pool: fluid where (y − level_y_mm)·gravity_lps[1] > 0.
    #[serde(default = "supine_gravity")]
    pub gravity_lps: [f64; 3],
    pub hu: f64,
}

#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct FilledTruth {
    pub segment: String,
    /// Lumen filled with fluid (label 3, truth lumen) between these arc lengths: no gas.
    pub start_arc_mm: f64,
    pub end_arc_mm: f64,
    pub hu: f64,
}

#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct GapTruth {
    /// "collapsed" (no lumen) or "fluid_filled" (lumen full of fluid).
    pub kind: String,
    pub segment: String,
    pub start_arc_mm: f64,
    pub end_arc_mm: f64,
}

#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct DiverticulumTruth {
    pub segment: String,
    /// Where along the colon's axis its neck leaves the lumen.
    pub arc_mm: f64,
    /// The pouch: a sphere of gas outside the colon's wall (volume-local mm), in a wall of its
    /// own as thick as the colon's.
    pub center_mm: [f64; 3],
    pub radius_mm: f64,
    /// The neck: gas this wide in radius through the wall, from `mouth_mm` (on the lumen's
    /// nominal surface) to the pouch's centre.
    pub neck_radius_mm: f64,
    pub mouth_mm: [f64; 3],
}

#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct StoolTruth {
    /// The lump's sphere (volume-local mm); it sits on the wall, its centre half a radius
    /// inside the lumen, like a sessile polyp's.
    pub center_mm: [f64; 3],
    pub diameter_mm: f64,
    pub segment: String,
    pub arc_mm: f64,
    /// Tagged material's HU; mottled lumps hold pockets of air.
    pub hu: f64,
    pub mottled: bool,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct LoopTruth {
    /// The loop's axis (a polyline; the loop is every point within `radius_mm` of it).
    pub axis_mm: Vec<[f64; 3]>,
    pub radius_mm: f64,
    pub wall_mm: f64,
    pub hu: f64,
    pub length_mm: f64,
    /// The terminal ileum: its last point lies inside the caecum.
    pub enters_cecum: bool,
    /// Touches the colon's outer wall (wall to wall, no opening).
    pub touches_colon: bool,
}

#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct RectalTubeTruth {
    /// The open tip inside the rectum.
    pub tip_mm: [f64; 3],
    /// The open outer end, just outside the skin of the perineum.
    pub exit_mm: [f64; 3],
    pub inner_radius_mm: f64,
    pub outer_radius_mm: f64,
    /// HU of its plastic wall.
    pub wall_hu: f64,
    /// Where the anal canal's gas round it opens in the skin (`anal_canal`): the anus.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub anus_mm: Option<[f64; 3]>,
    /// Its retention balloon, if inflated (its air is label 12, lumen).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub balloon: Option<BalloonTruth>,
}

/// A rectal catheter's retention balloon: an ellipsoid of air round the rectum's axis.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct BalloonTruth {
    pub center_mm: [f64; 3],
    /// Across the rectum, and half its length along it.
    pub radius_mm: f64,
    pub half_length_mm: f64,
    /// Its plastic skin, outside the radius.
    pub wall_mm: f64,
}

#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct TableTruth {
    /// The body's dependent side, where the table lies: "posterior" (supine) or "anterior"
    /// (prone).
    pub side: String,
    /// The plane y = top_y_mm is the table's top, on which the body rests; its far face is
    /// at y = bottom_y_mm. It spans every slice.
    pub top_y_mm: f64,
    pub bottom_y_mm: f64,
    pub x_range_mm: [f64; 2],
    /// A shell this thick around the foam.
    pub shell_mm: f64,
    pub shell_hu: f64,
    pub foam_hu: f64,
    /// Where the skin lies flat on the table; beside it a wedge of outside air narrows to
    /// nothing between skin and table.
    pub contact_x_mm: [f64; 2],
}

#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct SkinFoldTruth {
    /// "dependent" (beside the table's contact), "perineal" (rising from the perineum beside
    /// the rectal catheter's exit) or "gluteal" (beside the posterior midline, from below the
    /// scan's first slice).
    pub region: String,
    /// Where its mid-plane meets the skin, and the unit vectors into the body and along it:
    /// its air is the slab within width_mm / 2 of the rectangle mouth + u·inward + l·along,
    /// 0 ≤ u ≤ depth_mm, span_mm[0] ≤ l ≤ span_mm[1].
    pub mouth_mm: [f64; 3],
    pub inward: [f64; 3],
    pub along: [f64; 3],
    pub depth_mm: f64,
    pub width_mm: f64,
    pub span_mm: [f64; 2],
    /// Over this stretch of l a bridge of skin bridge_mm thick closes its mouth: there its
    /// air is enclosed in the body in the slices across it; None: open all along.
    pub closed_mm: Option<[f64; 2]>,
    pub bridge_mm: f64,
}

#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct CollapsedTruth {
    pub segment: String,
    /// No lumen at all between these arc lengths.
    pub start_arc_mm: f64,
    pub end_arc_mm: f64,
    /// The lumen narrows to nothing over this length on either side.
    pub taper_mm: f64,
}

#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct DistractorTruth {
    /// "small_bowel_gas", "opacified_small_bowel" or "lung".
    pub kind: String,
    pub center_mm: [f64; 3],
    /// Semi-axes of its bounding ellipsoid (a sphere for gas pockets).
    pub semi_axes_mm: [f64; 3],
    pub hu: f64,
}

#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct RoiTruth {
    pub min_ijk: [usize; 3],
    pub max_ijk: [usize; 3],
    pub expected_hu: f64,
}

fn hfs() -> String {
    "HFS".into()
}

fn supine_gravity() -> [f64; 3] {
    [0.0, 1.0, 0.0]
}

/// `collapsed` as a list, also from the older single object or null.
fn one_or_many<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Vec<CollapsedTruth>, D::Error> {
    #[derive(Deserialize)]
    #[serde(untagged)]
    enum OneOrMany {
        Many(Vec<CollapsedTruth>),
        One(CollapsedTruth),
        None(()),
    }
    Ok(match OneOrMany::deserialize(d)? {
        OneOrMany::Many(v) => v,
        OneOrMany::One(c) => vec![c],
        OneOrMany::None(()) => Vec::new(),
    })
}

impl Truth {
    /// The mouth of the ileocecal valve where opacified small bowel opens into the caecum
    /// (volume-local mm) and the terminal ileum's radius (mm); None without small bowel.
    pub fn valve_mouth(&self) -> Option<(glam::DVec3, f64)> {
        let ileum = self
            .small_bowel_loops
            .iter()
            .filter(|l| l.enters_cecum)
            .map(|l| l.radius_mm)
            .fold(0.0, f64::max);
        self.ileocecal_valve_mm
            .map(|p| (glam::DVec3::from_array(p), ileum))
    }

    /// Pretty JSON. Serialising plain numbers and strings cannot fail; if it ever did, the
    /// error comes back as a JSON object so that callers never panic.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).unwrap_or_else(|e| {
            serde_json::json!({ "error": format!("cannot serialise truth: {e}") }).to_string()
        })
    }

    /// Parses what [`Truth::to_json`] wrote.
    pub fn from_json(text: &str) -> voyage_core::Result<Truth> {
        serde_json::from_str(text)
            .map_err(|e| voyage_core::Error::invalid(format!("truth JSON: {e}")))
    }

    /// Name of the segment that contains arc length `s`.
    pub fn segment_at(&self, s: f64) -> Option<&str> {
        self.segments
            .iter()
            .find(|g| s >= g.start_arc_mm && s <= g.end_arc_mm)
            .map(|g| g.name.as_str())
    }
}
