//! The potential field V (paper §3.2, Eq. 2) that carries the submarine:
//!
//! V(X) = Ct·Dt(X) + Cs·(ρ/Ds(X) − 1)²  where 0 < Ds(X) < ρ,  else Ct·Dt(X).
//!
//! Ds is the study's; Dt is over the navigable core, made by `prepare` (`Study::nav`, see
//! `voyage_core::navigable`). Only the distances are stored; V is evaluated from them at each
//! sample, so Ct, Cs and ρ change at any moment without recomputing anything. Two storages of the lumen voxels'
//! distances sit behind one trait so that they can be measured against each other
//! (`voyage bench fly`): the paper's list of lumen voxels sorted by index and found by binary
//! search (`SortedStore`, with the dense box, behind the feature `layouts`), and 8³ bricks over the lumen's box where only bricks holding
//! lumen are allocated ([`BrickStore`], the one navigation uses: it answers a lookup with two
//! array reads instead of ~22 probes, at about the same memory).
//!
//! **At the lumen's edge.** Samples are trilinear over the eight voxels around X
//! (the paper's reconstruction). A corner outside the lumen counts as Ds = 0 (it is wall, as
//! in the EDT), so Ds falls smoothly to 0 toward the wall. Dt is not defined outside the
//! lumen, so it is interpolated over the lumen corners only, their weights renormalised
//! (continuous, because a corner's weight goes to zero where it drops out). Where Ds falls
//! below [`DS_FLOOR_MM`], Eq. 2 is evaluated at the floor: the repulsion stays finite and
//! steep instead of vanishing at Ds = 0 as Eq. 2 read literally would.

use glam::DVec3;
use serde::{Deserialize, Serialize};

use voyage_core::{BrickIndex, Error, Geometry, Navigable, Result, Study};

/// Ds below this (mm) is evaluated as this in Eq. 2.
pub const DS_FLOOR_MM: f64 = 0.05;

/// Which Dt drives the flight.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Direction {
    /// Rectum → cecum: Dt to the target.
    Forward,
    /// Cecum → rectum: Dt to the source.
    Backward,
}

impl Direction {
    pub fn reversed(self) -> Self {
        match self {
            Direction::Forward => Direction::Backward,
            Direction::Backward => Direction::Forward,
        }
    }
    fn slot(self) -> usize {
        match self {
            Direction::Forward => 0,
            Direction::Backward => 1,
        }
    }
    pub fn name(self) -> &'static str {
        match self {
            Direction::Forward => "forward",
            Direction::Backward => "backward",
        }
    }
}

/// The coefficients of Eq. 2.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PotentialParams {
    /// Ct: strength of the pull toward the target (per mm of Dt).
    pub ct: f64,
    /// Cs: strength of the push away from the wall.
    pub cs: f64,
    /// ρ: reach of the wall's push (mm).
    pub rho: f64,
}

impl Default for PotentialParams {
    fn default() -> Self {
        PotentialParams {
            ct: 240.0,
            cs: 240.0,
            rho: 25.0,
        }
    }
}

impl PotentialParams {
    /// Eq. 2 for given distances (mm).
    #[inline]
    pub fn value(&self, ds: f64, dt: f64) -> f64 {
        let ds = ds.max(DS_FLOOR_MM);
        let repulsion = if ds < self.rho {
            let r = self.rho / ds - 1.0;
            self.cs * r * r
        } else {
            0.0
        };
        self.ct * dt + repulsion
    }
}

/// The stored distances of one lumen voxel: Ds, and Dt to the target and to the source.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Voxel {
    pub ds: f32,
    pub dt: [f32; 2],
}

/// A place to look up lumen voxels' distances by volume voxel.
pub trait DistanceStore: Send + Sync {
    /// The distances at volume voxel `g`, None outside the lumen (or outside the volume).
    fn get(&self, g: [i64; 3]) -> Option<Voxel>;
    /// Heap bytes held.
    fn bytes(&self) -> usize;
    fn voxels(&self) -> usize;
}

/// Navigable voxels (lumen with finite Dt both ways over the core), brick by brick: `f`
/// hears of each with its volume voxel.
pub(crate) fn navigable_voxels(
    study: &Study,
    nav: &Navigable,
    mut f: impl FnMut([usize; 3], Voxel),
) {
    let ds = &study.ds;
    let [to_t, to_s] = [nav.dt[0].values(), nav.dt[1].values()];
    // The core's Dt lie in Ds's bricks, slot for slot.
    assert!(to_t.len() == ds.values().len() && to_s.len() == ds.values().len());
    for (at, &d) in ds.values().iter().enumerate() {
        let (t, s) = (to_t[at], to_s[at]);
        if d > 0.0 && t.is_finite() && s.is_finite() {
            let l = ds.box_voxel(BrickIndex(at));
            f(
                [0, 1, 2].map(|a| l[a] + ds.grid.lo[a]),
                Voxel { ds: d, dt: [t, s] },
            );
        }
    }
}

const BRICK_SHIFT: usize = 3;
const BRICK: usize = 1 << BRICK_SHIFT;
const BRICK_VOXELS: usize = BRICK * BRICK * BRICK;
const NO_BRICK: u32 = u32::MAX;
pub(crate) const OUTSIDE: Voxel = Voxel {
    ds: 0.0,
    dt: [f32::INFINITY; 2],
};

/// 8×8×8 bricks over the lumen's box; a table gives each brick's slot, and only bricks that
/// hold lumen have one. Non-lumen voxels inside a brick hold Ds = 0.
pub struct BrickStore {
    lo: [i64; 3],
    /// Bricks per axis.
    nb: [i64; 3],
    table: Vec<u32>,
    bricks: Vec<Voxel>,
    voxels: usize,
}

impl BrickStore {
    pub fn new(study: &Study, nav: &Navigable) -> Result<Self> {
        let grid = &study.ds.grid;
        let lo = grid.lo.map(|x| x as i64);
        let nb = grid.dims.map(|x| x.div_ceil(BRICK) as i64);
        let mut table = vec![NO_BRICK; (nb[0] * nb[1] * nb[2]) as usize];
        let mut bricks: Vec<Voxel> = Vec::new();
        let mut voxels = 0;
        navigable_voxels(study, nav, |g, v| {
            let l = [0, 1, 2].map(|a| g[a] as i64 - lo[a]);
            let t = Self::brick_of(nb, l);
            if table[t] == NO_BRICK {
                table[t] = (bricks.len() / BRICK_VOXELS) as u32;
                bricks.resize(bricks.len() + BRICK_VOXELS, OUTSIDE);
            }
            bricks[table[t] as usize * BRICK_VOXELS + Self::within(l)] = v;
            voxels += 1;
        });
        if bricks.len() / BRICK_VOXELS >= NO_BRICK as usize {
            return Err(Error::invalid("too many bricks for a 32-bit table"));
        }
        bricks.shrink_to_fit();
        Ok(BrickStore {
            lo,
            nb,
            table,
            bricks,
            voxels,
        })
    }
    #[inline]
    fn brick_of(nb: [i64; 3], l: [i64; 3]) -> usize {
        let b = l.map(|x| x >> BRICK_SHIFT);
        (b[0] + nb[0] * (b[1] + nb[1] * b[2])) as usize
    }
    #[inline]
    fn within(l: [i64; 3]) -> usize {
        let m = BRICK as i64 - 1;
        ((l[0] & m) + BRICK as i64 * ((l[1] & m) + BRICK as i64 * (l[2] & m))) as usize
    }
    pub fn bricks(&self) -> usize {
        self.bricks.len() / BRICK_VOXELS
    }
}

impl DistanceStore for BrickStore {
    #[inline]
    fn get(&self, g: [i64; 3]) -> Option<Voxel> {
        let l = [g[0] - self.lo[0], g[1] - self.lo[1], g[2] - self.lo[2]];
        if (0..3).any(|a| l[a] < 0 || (l[a] >> BRICK_SHIFT) >= self.nb[a]) {
            return None;
        }
        let slot = self.table[Self::brick_of(self.nb, l)];
        if slot == NO_BRICK {
            return None;
        }
        let v = self.bricks[slot as usize * BRICK_VOXELS + Self::within(l)];
        (v.ds > 0.0).then_some(v)
    }
    fn bytes(&self) -> usize {
        self.table.capacity() * 4 + self.bricks.capacity() * std::mem::size_of::<Voxel>()
    }
    fn voxels(&self) -> usize {
        self.voxels
    }
}

/// Distances reconstructed at a point (trilinear over the eight voxels around it).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample {
    /// Ds (mm); non-lumen corners count as 0.
    pub ds: f64,
    /// Dt (mm) over the lumen corners, renormalised; None when no corner is lumen.
    pub dt: Option<f64>,
    /// How many of the eight corners are lumen voxels.
    pub lumen_corners: u32,
}

/// Eq. 2 over a distance store, in volume-local mm.
pub struct PotentialField<S: DistanceStore = BrickStore> {
    store: S,
    spacing: DVec3,
    dims: [usize; 3],
}

impl<S: DistanceStore> PotentialField<S> {
    pub fn new(store: S, geometry: &Geometry) -> Self {
        PotentialField {
            store,
            spacing: geometry.spacing_vec(),
            dims: geometry.dims,
        }
    }
    pub fn store(&self) -> &S {
        &self.store
    }
    pub fn spacing(&self) -> DVec3 {
        self.spacing
    }
    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }

    /// Ds and Dt at `mm` for `dir`.
    #[inline]
    pub fn sample(&self, mm: DVec3, dir: Direction) -> Sample {
        let p = mm / self.spacing;
        let base = p.floor();
        let t = p - base;
        let b = [base.x as i64, base.y as i64, base.z as i64];
        let (mut ds, mut dt, mut wt, mut n) = (0.0, 0.0, 0.0, 0);
        for c in 0..8 {
            let o = [c & 1, (c >> 1) & 1, (c >> 2) & 1];
            let w = (if o[0] == 1 { t.x } else { 1.0 - t.x })
                * (if o[1] == 1 { t.y } else { 1.0 - t.y })
                * (if o[2] == 1 { t.z } else { 1.0 - t.z });
            if let Some(v) = self.store.get([b[0] + o[0], b[1] + o[1], b[2] + o[2]]) {
                ds += w * v.ds as f64;
                dt += w * v.dt[dir.slot()] as f64;
                wt += w;
                n += 1;
            }
        }
        let dt = if n == 0 {
            None
        } else if wt > 0.0 {
            Some(dt / wt)
        } else {
            // X sits exactly on the far faces of lumen corners that carry no weight.
            self.nearest_dt(b, dir)
        };
        Sample {
            ds,
            dt,
            lumen_corners: n,
        }
    }

    fn nearest_dt(&self, b: [i64; 3], dir: Direction) -> Option<f64> {
        (0..8)
            .find_map(|c| {
                self.store
                    .get([b[0] + (c & 1), b[1] + ((c >> 1) & 1), b[2] + ((c >> 2) & 1)])
            })
            .map(|v| v.dt[dir.slot()] as f64)
    }

    /// Ds at `mm` (mm).
    #[inline]
    pub fn ds(&self, mm: DVec3) -> f64 {
        self.sample(mm, Direction::Forward).ds
    }

    /// V at `mm` (Eq. 2). Dt falls back to `dt_fallback` where no corner is lumen.
    #[inline]
    pub fn value_with(
        &self,
        mm: DVec3,
        params: &PotentialParams,
        dir: Direction,
        dt_fallback: f64,
    ) -> f64 {
        let s = self.sample(mm, dir);
        params.value(s.ds, s.dt.unwrap_or(dt_fallback))
    }

    /// V at `mm` (Eq. 2); None where no corner is lumen.
    pub fn value(&self, mm: DVec3, params: &PotentialParams, dir: Direction) -> Option<f64> {
        let s = self.sample(mm, dir);
        s.dt.map(|dt| params.value(s.ds, dt))
    }

    /// ∇V by central differences over half a voxel on each axis (the paper's estimate).
    /// A side sample with no lumen corner takes the centre's Dt (the Ds there is 0, so the
    /// repulsion still points inward).
    pub fn gradient(&self, mm: DVec3, params: &PotentialParams, dir: Direction) -> DVec3 {
        let half = 0.5 * self.spacing;
        let centre_dt = self.sample(mm, dir).dt.unwrap_or(0.0);
        let mut g = DVec3::ZERO;
        for a in 0..3 {
            let mut h = DVec3::ZERO;
            h[a] = half[a];
            let plus = self.value_with(mm + h, params, dir, centre_dt);
            let minus = self.value_with(mm - h, params, dir, centre_dt);
            g[a] = (plus - minus) / (2.0 * h[a]);
        }
        g
    }

    /// ∇Ds by central differences (for the wall's normal when a step is clipped).
    pub fn ds_gradient(&self, mm: DVec3) -> DVec3 {
        let mut g = DVec3::ZERO;
        for a in 0..3 {
            let mut h = DVec3::ZERO;
            h[a] = 0.5 * self.spacing[a];
            g[a] = (self.ds(mm + h) - self.ds(mm - h)) / (2.0 * h[a]);
        }
        g
    }

    /// Whether all eight voxels around `mm` are lumen: the camera's cube lies wholly on the
    /// air side of the surface.
    #[inline]
    pub fn in_lumen_cube(&self, mm: DVec3) -> bool {
        let p = mm / self.spacing;
        let b = p.floor();
        let b = [b.x as i64, b.y as i64, b.z as i64];
        (0..8).all(|c| {
            self.store
                .get([b[0] + (c & 1), b[1] + ((c >> 1) & 1), b[2] + ((c >> 2) & 1)])
                .is_some()
        })
    }
}

/// The field navigation uses: bricks over the navigable core for a camera kept
/// `min_wall_mm` from the wall.
pub fn potential_field(study: &Study, min_wall_mm: f64) -> Result<PotentialField<BrickStore>> {
    let nav = study.navigable(min_wall_mm)?;
    Ok(PotentialField::new(
        BrickStore::new(study, &nav)?,
        study.ct.geometry(),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eq2_is_continuous_at_rho_and_steep_near_the_wall() {
        let p = PotentialParams {
            ct: 2.0,
            cs: 5.0,
            rho: 10.0,
        };
        assert_eq!(p.value(10.0, 3.0), 6.0);
        assert!((p.value(10.0 - 1e-9, 3.0) - 6.0).abs() < 1e-6);
        assert_eq!(p.value(5.0, 0.0), 5.0); // Cs·(10/5 − 1)²
        assert!(p.value(0.1, 0.0) > p.value(0.2, 0.0));
        assert_eq!(p.value(0.0, 0.0), p.value(DS_FLOOR_MM, 0.0));
        assert!(p.value(0.0, 0.0).is_finite());
    }
}
