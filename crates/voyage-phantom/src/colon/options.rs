//! What colon to make: the options, each drawing what a real exam does, and the check that
//! refuses a combination that cannot make a phantom.

use voyage_core::{Error, Result};

/// What colon to make.
#[derive(Clone, Debug)]
pub struct ColonOptions {
    pub seed: u64,
    /// ≈128³ at 1.5–1.6 mm with the anatomy scaled by ½, for fast tests.
    pub small: bool,
    /// Pools of tagged fluid (+400..+700 HU) with flat air–fluid levels in the dependent
    /// parts of the colon: the rectum, descending and ascending colon supine (posterior);
    /// the sigmoid, transverse colon and caecum prone (anterior).
    pub tagged_fluid: bool,
    /// The patient lies face down (DICOM "HFP"): gravity points anterior (−y), so tagged
    /// fluid pools anteriorly. The volume's geometry does not change.
    pub prone: bool,
    /// Segments (sigmoid, descending, transverse; each at most once) in which a 30 mm
    /// stretch (full size) is collapsed to a tissue cord: N collapses leave the gas in N + 1
    /// pieces.
    pub collapsed: Vec<String>,
    /// Segments (rectum, sigmoid, descending, transverse, ascending, caecum; each at most
    /// once) with a 40–60 mm stretch (full size) filled to the brim with tagged fluid: lumen,
    /// but no gas, so the gas is split there while the lumen goes on.
    pub fluid_filled: Vec<String>,
    /// Segments (sigmoid, descending, transverse; each at most once) with a neck 30 % of
    /// the way along: over 10 mm (full size) the gas narrows to a thread
    /// [`NECK_RADIUS_MM`](super::NECK_RADIUS_MM) in radius, joined but narrower than the
    /// camera's distance from the wall allows (a real sigmoid's spasm).
    pub narrowed: Vec<String>,
    /// Loops of small bowel filled with oral contrast (+300..+600 HU, no gas) in the right
    /// and central lower abdomen and pelvis, some touching the colon near the descending
    /// colon, the terminal ileum opening into the caecum under the level of a caecal pool
    /// (made even without `tagged_fluid`): one bright region with the caecal fluid.
    pub opacified_small_bowel: bool,
    /// The same loops of small bowel full of gas instead: one down the descending colon's
    /// medial wall, wall to wall, and the terminal ileum opening into the caecum, its gas one
    /// with the caecum's (gas refluxed through the ileocaecal valve, as insufflation often
    /// leaves it). Not colon: a held-out exam's small-bowel gas loops beside the colon were
    /// chained into it.
    pub gas_filled_small_bowel: bool,
    /// With `gas_filled_small_bowel`: the terminal ileum ends short of the caecum, its gas
    /// apart from the colon's (a competent valve): loops of gas beside the colon, several
    /// hundred ml at full size, one against the descending colon wall to wall.
    pub closed_ileocaecal_valve: bool,
    /// A rectal catheter from the lower rectum out of the body through a perineum (the body
    /// then ends 4 mm above the first slice): colon gas joins the air outside in 3D.
    pub rectal_tube: bool,
    /// With `rectal_tube`: the perineum lies [`CANAL_MM`](super::CANAL_MM) lower (full
    /// size), and the catheter's way from the rectum to the anus in its skin (about 40 mm) is
    /// held open by gas round it, as an anal canal round a real retention catheter; the volume
    /// reaches that much further down. The colon's gas then ends at the anus.
    pub anal_canal: bool,
    /// With `rectal_tube`: its retention balloon inflated with about 23 ml of air in the
    /// rectum's lowest stretch, wall to wall, its 1 mm plastic skin keeping the rectum's gas
    /// above it apart from the gas below it (and the anal canal's): a held-out prone exam
    /// with a balloon catheter started 62 mm from the anus. Its air is lumen, labelled 12.
    pub rectal_balloon: bool,
    /// Lumps of tagged stool (+500..+900 HU, 4–9 mm at full size) on the wall, two in each
    /// of the rectum, sigmoid, descending, transverse and ascending colon, one of each two
    /// mottled with air: colon content, labelled 11, in the truth's `stool`.
    pub tagged_stool: bool,
    /// A CT table under the patient on the dependent side (posterior supine, anterior prone):
    /// a 2.5 mm shell (+350 HU) round a foam core (−935 HU), 45 mm thick at full size, in
    /// every slice, running out of the field of view on both sides as on a real exam; the
    /// skin lies flat on it over a contact strip, with a wedge of outside air beside it. Not
    /// the patient: label 0, the air round it 1.
    pub table: bool,
    /// 4–8 skin folds: crevices of outside air (label 1) 1–2 mm wide, 15–40 mm deep and
    /// 30–80 mm long at full size, 3–6 on the dependent side beside the table's contact and
    /// 1–2 low in the scan (rising from the perineum beside the rectal catheter's exit, or
    /// without one in the gluteal cleft off the scan's inferior edge); most closed over by skin
    /// in part of their length, where axial slices hold their air enclosed in the body.
    pub skin_folds: bool,
    /// 10 gas-filled diverticula (6 in the sigmoid, 4 in the descending colon): pouches 5–10
    /// mm across (full size) outside the wall on the side away from gravity, each joined to
    /// the lumen by a neck 2–4 mm across through the wall. Colon lumen: a held-out exam's
    /// sigmoid has them.
    pub diverticula: bool,
    /// A few separate small-bowel gas pockets (not colon).
    pub small_bowel_gas: bool,
    /// The bases of both lungs in the top slices (not colon).
    pub lung_bases: bool,
    /// Standard deviation of the CT noise (HU).
    pub noise_hu: f64,
    /// Round the CT (after the noise) to multiples of this many HU, as a windowed 8-bit
    /// export leaves it.
    pub quantize_hu: Option<f64>,
    /// One position of a supine–prone pair (`colon_pair`): supine, the transverse
    /// colon and the sigmoid's anterior loop sag posteriorly by centimetres while folds and
    /// polyps keep their places on the wall (the same place along the colon, the same side of
    /// it in the patient's frame); in either position tagged stool lies on the dependent side.
    pub pair_member: bool,
}

impl Default for ColonOptions {
    fn default() -> Self {
        ColonOptions {
            seed: 1,
            small: false,
            tagged_fluid: false,
            prone: false,
            collapsed: Vec::new(),
            fluid_filled: Vec::new(),
            narrowed: Vec::new(),
            opacified_small_bowel: false,
            gas_filled_small_bowel: false,
            closed_ileocaecal_valve: false,
            rectal_tube: false,
            anal_canal: false,
            rectal_balloon: false,
            tagged_stool: false,
            table: false,
            skin_folds: false,
            diverticula: false,
            small_bowel_gas: true,
            lung_bases: true,
            noise_hu: 20.0,
            quantize_hu: None,
            pair_member: false,
        }
    }
}

/// Segments that `ColonOptions::collapsed` may name.
pub const COLLAPSIBLE: &[&str] = &["sigmoid", "descending", "transverse"];
/// Segments that `ColonOptions::fluid_filled` may name.
pub const FILLABLE: &[&str] = &[
    "rectum",
    "sigmoid",
    "descending",
    "transverse",
    "ascending",
    "cecum",
];

/// Refuses options that cannot make a phantom, with a message that says why.
pub(super) fn check_options(opts: &ColonOptions) -> Result<()> {
    if !(opts.noise_hu >= 0.0 && opts.noise_hu.is_finite()) {
        return Err(Error::invalid(format!(
            "noise {} HU is not a non-negative number",
            opts.noise_hu
        )));
    }
    if let Some(q) = opts.quantize_hu
        && !(q > 0.0 && q.is_finite())
    {
        return Err(Error::invalid(format!(
            "quantisation step {q} HU is not a positive number"
        )));
    }
    let names = |what: &str, list: &[String], allowed: &[&str]| -> Result<()> {
        for (i, n) in list.iter().enumerate() {
            if !allowed.contains(&n.as_str()) {
                return Err(Error::invalid(format!(
                    "{what} segment '{n}': choose from {}",
                    allowed.join(", ")
                )));
            }
            if list[..i].contains(n) {
                return Err(Error::invalid(format!("{what} segment '{n}' named twice")));
            }
        }
        Ok(())
    };
    if opts.opacified_small_bowel && opts.gas_filled_small_bowel {
        return Err(Error::invalid(
            "the small-bowel loops hold contrast or gas, not both: ask for one",
        ));
    }
    if opts.closed_ileocaecal_valve && !opts.gas_filled_small_bowel {
        return Err(Error::invalid(
            "a closed ileocaecal valve keeps the small bowel's gas apart: ask for the gas-filled small bowel too",
        ));
    }
    if opts.anal_canal && !opts.rectal_tube {
        return Err(Error::invalid(
            "an anal canal holds gas round a rectal catheter: ask for the rectal tube too",
        ));
    }
    if opts.rectal_balloon && !opts.rectal_tube {
        return Err(Error::invalid(
            "a retention balloon is the rectal catheter's: ask for the rectal tube too",
        ));
    }
    names("collapsed", &opts.collapsed, COLLAPSIBLE)?;
    names("narrowed", &opts.narrowed, COLLAPSIBLE)?;
    names("fluid-filled", &opts.fluid_filled, FILLABLE)
}
