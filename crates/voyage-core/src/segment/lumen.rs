//! After the chain: the lumen, 0/1. The chained compartments (gas, pools, layers), a tube
//! along each bridge with the tagged fluid filling the stretch it crosses, and the colon's
//! pools made whole ([`whole_pools`]).

use glam::DVec3;

use super::{
    bridge::{Path, lay_bridge},
    chain::Chained,
    compartments::Compartments,
    fluid::{fill_fluid, whole_pools},
    runs::paint,
    work::Bbox,
};
use crate::{Error, Result, Volume};

/// Fluid filling a bridged stretch is taken this far (mm) from the bridge's path.
const FILL_MM: f64 = 25.0;

/// The lumen and what it holds.
pub(super) struct Lumen {
    /// 1 = colon lumen.
    pub(super) mask: Volume<u8>,
    pub(super) voxels: usize,
    /// Voxels of tagged fluid (and of the air–fluid interface) among them.
    pub(super) fluid_voxels: usize,
    /// Its bounding box.
    pub(super) extent: Bbox,
    /// Per gap of the chain: the voxels its bridge added (sorted).
    pub(super) gap_voxels: Vec<Vec<usize>>,
    /// The fluid taken in beyond the pools' columns (ascending).
    pub(super) pools_grown: Vec<usize>,
    /// Radius (mm) of the tube laid along each bridge.
    pub(super) bridge_radius_mm: f64,
}

/// The lumen of the chained compartments in `work` (the working labels, turned to 0/1):
/// with `ct` and `hu` (air, tagged fluid), the fluid on the bridges' way and the whole pools
/// (`gravity_lps` down); an error when the colon holds no voxels.
pub(super) fn lumen(
    mut work: Volume<u8>,
    parts: &Compartments,
    chained: &Chained,
    ct: Option<&Volume<i16>>,
    (air_hu, fluid_hu): (i16, Option<i16>),
    gravity_lps: DVec3,
) -> Result<Lumen> {
    let geom = work.geometry().clone();
    let bridge_radius_mm = 3.0f64.max(1.5 * geom.spacing.iter().cloned().fold(0.0, f64::max));
    let (added, gap_voxels) = bridges(
        &mut work,
        &chained.chain.gaps,
        ct.zip(fluid_hu),
        bridge_radius_mm,
    );
    let links = &chained.chain.links;
    let in_colon: Vec<bool> = {
        let mut v = vec![false; parts.list.len()];
        links.iter().for_each(|l| v[l.comp as usize] = true);
        v
    };
    // A compartment's voxels that are not gas are its pool and layer.
    let colon = || links.iter().map(|l| &parts.list[l.comp as usize]);
    let mut fluid_voxels: usize = colon().map(|c| c.voxels - c.gas_voxels).sum();
    let colon_voxels: usize = colon().map(|c| c.voxels).sum();
    let colon_box: Option<Bbox> = colon().map(|c| c.bbox).reduce(|a, b| a.union(&b));
    let lumen_box = grown_by(colon_box, &geom, &added);
    let bridge_voxels = added.len();
    if let Some(ct) = ct {
        fluid_voxels += added
            .iter()
            .filter(|&&v| ct.data()[v] >= fluid_hu.unwrap_or(i16::MAX))
            .count();
    }
    // Back to 0/1: every label lies in a compartment's runs, or on a bridge.
    let kept = |r: usize| parts.run_comp[r] != u32::MAX && in_colon[parts.run_comp[r] as usize];
    paint(&mut work, &parts.runs, |r| Some(kept(r) as u8));
    for &v in &added {
        work.data_mut()[v] = 1;
    }
    // Whole pools: the colon's fluid beyond the columns under its air.
    let grown = match (ct, fluid_hu) {
        (Some(ct), Some(t)) => whole_pools(&mut work, ct, lumen_box, (air_hu, t), gravity_lps),
        _ => Vec::new(),
    };
    fluid_voxels += grown.len();
    let extent = grown_by(lumen_box, &geom, &grown)
        .ok_or_else(|| Error::invalid("the colon holds no voxels"))?;
    let voxels = colon_voxels + bridge_voxels + grown.len();
    let mut pools_grown = grown;
    pools_grown.sort_unstable();
    Ok(Lumen {
        mask: work,
        voxels,
        fluid_voxels,
        extent,
        gap_voxels,
        pools_grown,
        bridge_radius_mm,
    })
}

/// `bx` grown to hold `voxels` (volume indices).
fn grown_by(bx: Option<Bbox>, geom: &crate::Geometry, voxels: &[usize]) -> Option<Bbox> {
    voxels.iter().fold(bx, |b, &v| {
        let ijk = geom.ijk(v);
        let at = Bbox { lo: ijk, hi: ijk };
        Some(b.map_or(at, |x| x.union(&at)))
    })
}

/// Lays each gap's bridge into `work`: the tagged fluid (of `ct` at or above its HU) filling
/// the stretch it crosses, and a tube of `radius_mm` along its path. Returns the voxels
/// added, in order, and per gap its own (sorted).
fn bridges(
    work: &mut Volume<u8>,
    gaps: &[Path],
    ct: Option<(&Volume<i16>, i16)>,
    radius_mm: f64,
) -> (Vec<usize>, Vec<Vec<usize>>) {
    let mut added = Vec::new();
    let mut gap_voxels: Vec<Vec<usize>> = Vec::new();
    for p in gaps {
        let from = added.len();
        if let Some((ct, t)) = ct {
            fill_fluid(work, &p.voxels, FILL_MM, |i| ct.data()[i] >= t, &mut added);
        }
        lay_bridge(work, &p.voxels, radius_mm, &mut added);
        let mut v = added[from..].to_vec();
        v.sort_unstable();
        gap_voxels.push(v);
    }
    (added, gap_voxels)
}
