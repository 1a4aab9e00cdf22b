//! Reading both positions: findings seen in both are one finding with two places, a lump
//! that moved more than the colon around it is probably stool, and mucosa unseen in one
//! position but seen in the other counts as seen.
//!
//! Both go through the [`Link`]: a finding's place in the other position is where the link
//! puts it ([`Link::show_in`]); the mucosa is compared on a common map, each triangle binned
//! by its place along the colon (arc through the link) and its side round it (the angle
//! from the patient's anterior about the centerline), which is what stays put when the colon
//! moves.

use glam::DVec3;
use rayon::prelude::*;
use serde::Serialize;

use super::{
    coverage::Coverage,
    findings::{FindingKind, Marker},
    link::{Link, centerline_at},
    mesh::CellMesh,
    reading::Reading,
};
use voyage_core::{OFF_WALL_MM, Study};

/// Two findings, one in each position, are the same one only when the second lies within
/// this much of where the link puts the first along the colon (mm of arc) ...
pub const SAME_FINDING_ARC_MM: f64 = 40.0;
/// ... and within this distance of it (mm), or across the lumen there (twice its radius
/// and this much more): stool rolls across a wide cecum.
pub const SAME_FINDING_MM: f64 = 60.0;
/// A finding that moved round the colon by more than this angle (degrees) between the
/// positions moved by itself: probably stool, which rolls to the dependent side; a polyp
/// stays on the wall. So is one farther than [`MOVED_MM`] from where the link puts it: the
/// link's own error is within that along the colon (its p95 on the phantom pair is 7 mm,
/// its bound 25 mm), and a polyp lies within 3.3 mm of its place.
pub const MOVED_ANGLE_DEG: f64 = 60.0;
pub const MOVED_MM: f64 = 25.0;

/// A finding in one position, the other or both.
#[derive(Clone, Debug, Serialize)]
pub struct LinkedFinding {
    /// Its index in the first position's markers, and in the second's.
    pub a: Option<usize>,
    pub b: Option<usize>,
    /// Where the link puts the first's in the second position (local mm of the second,
    /// [`OFF_WALL_MM`] off the wall).
    #[serde(skip)]
    pub expected_in_b: Option<DVec3>,
    /// How far the second lies from where the link puts the first (mm), and round the
    /// colon (degrees).
    pub moved_mm: Option<f64>,
    pub moved_deg: Option<f64>,
    /// It moved between the positions more than the colon around it did.
    pub probably_stool: bool,
}

/// Pairs the findings of two positions (`a`'s markers `fa`, `b`'s `fb`, positions in each
/// study's local mm): each pair the nearest to where the link puts the first, of a kind that
/// can be the same thing, within [`SAME_FINDING_ARC_MM`] along the colon and
/// [`SAME_FINDING_MM`] (or across the lumen) of it; the rest alone. First position's order, then the second's unpaired.
pub fn link_findings(
    link: &Link,
    a: &Study,
    b: &Study,
    fa: &[Marker],
    fb: &[Marker],
) -> Vec<LinkedFinding> {
    let expected: Vec<Option<(DVec3, f64)>> = fa
        .iter()
        .map(|m| {
            let at = link.show_in(a, b, in_lumen(m))?;
            Some((at, link.map(a.arc_at(in_lumen(m))?)))
        })
        .collect();
    let arc_b: Vec<Option<f64>> = fb.iter().map(|m| b.arc_at(in_lumen(m))).collect();
    let mut pairs: Vec<(f64, usize, usize)> = Vec::new();
    for (i, e) in expected.iter().enumerate() {
        let Some((at, arc)) = e else { continue };
        let across = SAME_FINDING_MM.max(2.0 * radius_at(b, *arc) + SAME_FINDING_MM / 4.0);
        for (j, m) in fb.iter().enumerate() {
            let d = at.distance(in_lumen(m));
            let along = arc_b[j].map_or(f64::INFINITY, |s| (s - arc).abs());
            if same_kind(fa[i].kind, m.kind) && d <= across && along <= SAME_FINDING_ARC_MM {
                pairs.push((d, i, j));
            }
        }
    }
    pairs.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)).then(x.2.cmp(&y.2)));
    let (mut partner_a, mut taken_b) = (vec![None; fa.len()], vec![false; fb.len()]);
    for (_, i, j) in pairs {
        if partner_a[i].is_none() && !taken_b[j] {
            partner_a[i] = Some(j);
            taken_b[j] = true;
        }
    }
    let mut out: Vec<LinkedFinding> = (0..fa.len())
        .map(|i| {
            let expected_in_b = expected[i].map(|(p, _)| p);
            let (moved_mm, moved_deg) = match (partner_a[i], expected_in_b) {
                (Some(j), Some(e)) => {
                    let seen = in_lumen(&fb[j]);
                    (Some(e.distance(seen)), Some(angle_round(b, e, seen)))
                }
                _ => (None, None),
            };
            LinkedFinding {
                a: Some(i),
                b: partner_a[i],
                expected_in_b,
                moved_mm,
                moved_deg,
                probably_stool: moved_mm.is_some_and(|d| d > MOVED_MM)
                    || moved_deg.is_some_and(|d| d > MOVED_ANGLE_DEG),
            }
        })
        .collect();
    out.extend(
        (0..fb.len())
            .filter(|&j| !taken_b[j])
            .map(|j| LinkedFinding {
                a: None,
                b: Some(j),
                expected_in_b: None,
                moved_mm: None,
                moved_deg: None,
                probably_stool: false,
            }),
    );
    out
}

/// The lumen's radius (Ds on the centerline, mm) at arc `s` of `study`.
fn radius_at(study: &Study, s: f64) -> f64 {
    let cl = &study.centerline;
    let i = cl
        .arc_mm
        .partition_point(|&a| a < s)
        .min(cl.radius_mm.len().saturating_sub(1));
    cl.radius_mm.get(i).copied().unwrap_or(0.0)
}

/// A marker's point moved off the wall into the lumen, where places along the colon are
/// read.
fn in_lumen(m: &Marker) -> DVec3 {
    m.position + m.normal * OFF_WALL_MM
}

/// Kinds that can be one thing seen twice: a polyp, a mass and an unnamed lump may be one
/// thing called differently in each position; a diverticulum is only ever a diverticulum.
fn same_kind(x: FindingKind, y: FindingKind) -> bool {
    let raised = |k: FindingKind| k != FindingKind::Diverticulum;
    x == y || (raised(x) && raised(y))
}

/// The angle (degrees) between two points round `study`'s colon, about the centerline near
/// them.
fn angle_round(study: &Study, p: DVec3, q: DVec3) -> f64 {
    let Some(s) = study.arc_at(0.5 * (p + q)) else {
        return 0.0;
    };
    let (c, t) = centerline_at(study, s);
    let (u, v) = (across(t, p - c), across(t, q - c));
    if u == DVec3::ZERO || v == DVec3::ZERO {
        return 0.0;
    }
    u.dot(v).clamp(-1.0, 1.0).acos().to_degrees()
}

/// The unit direction of `v` across the axis of way `t` (zero along it).
fn across(t: DVec3, v: DVec3) -> DVec3 {
    (v - t * v.dot(t)).normalize_or_zero()
}

/// Mucosa binned along the colon every this many mm of arc ...
pub const ARC_BIN_MM: f64 = 5.0;
/// ... and round it in this many sectors.
pub const SECTORS: usize = 12;

/// Where each triangle of a position's surface lies on the common map: its arc and sector
/// (None for a triangle no centerline serves). The default maps nothing.
#[derive(Clone, Debug, Default)]
pub struct MucosaMap {
    place: Vec<Option<(f64, usize)>>,
}

impl MucosaMap {
    /// Bins every triangle of `mesh` (`study`'s surface by cell, draw order).
    pub fn of(study: &Study, mesh: &CellMesh) -> MucosaMap {
        let place = (0..mesh.triangles.len())
            .into_par_iter()
            .map(|t| {
                let [p, q, r] = mesh.triangles[t].map(|v| vertex(mesh, v));
                let n = (q - p).cross(r - p).normalize_or_zero();
                let at = (p + q + r) / 3.0 + n * OFF_WALL_MM;
                let s = study.arc_at(at)?;
                Some((s, sector(study, s, at)))
            })
            .collect();
        MucosaMap { place }
    }
}

fn vertex(mesh: &CellMesh, v: u32) -> DVec3 {
    DVec3::from_array(mesh.positions[v as usize].map(f64::from))
}

/// The sector round the colon at arc `s` of the point `p`: the angle about the centerline
/// from the patient's anterior, toward the patient's left. Both positions' study storages
/// run along the patient's L, P, S, so the sectors mean the same side in both.
fn sector(study: &Study, s: f64, p: DVec3) -> usize {
    let (c, t) = centerline_at(study, s);
    // Where the colon runs front to back, the patient's left stands in for the anterior.
    let front = match across(t, DVec3::NEG_Y) {
        f if f.length_squared() > 0.1 => f,
        _ => across(t, DVec3::X),
    };
    let side = t.cross(front);
    let r = p - c;
    let angle = r
        .dot(side)
        .atan2(r.dot(front))
        .rem_euclid(std::f64::consts::TAU);
    ((angle / std::f64::consts::TAU * SECTORS as f64) as usize).min(SECTORS - 1)
}

/// How much of each bin of one position's map was seen: (seen, whole) mm².
struct Bins {
    area: Vec<(f64, f64)>,
}

impl Bins {
    fn of(map: &MucosaMap, seen: &Coverage, length_mm: f64) -> Bins {
        let n = (length_mm / ARC_BIN_MM).ceil() as usize + 1;
        let mut area = vec![(0.0, 0.0); n * SECTORS];
        for (t, place) in map.place.iter().enumerate() {
            let Some((s, k)) = *place else { continue };
            let cell = &mut area[bin(s, k, n)];
            let a = seen.area_of(t as u32) as f64;
            cell.1 += a;
            if seen.is_seen(t as u32) {
                cell.0 += a;
            }
        }
        Bins { area }
    }

    /// Whether most of the mucosa at arc `s`, sector `k` was seen.
    fn seen(&self, s: f64, k: usize) -> bool {
        let n = self.area.len() / SECTORS;
        let (seen, whole) = self.area[bin(s, k, n)];
        whole > 0.0 && seen >= 0.5 * whole
    }
}

fn bin(s: f64, k: usize, n: usize) -> usize {
    let i = ((s / ARC_BIN_MM).max(0.0) as usize).min(n - 1);
    i * SECTORS + k
}

/// One position of a pair, read.
pub struct Read<'a> {
    pub study: &'a Study,
    pub map: &'a MucosaMap,
    pub seen: &'a Coverage,
}

/// Coverage of each position and of both together (percent of the mucosa's area).
#[derive(Clone, Copy, Debug, Serialize)]
pub struct BothCoverage {
    pub a_pct: f64,
    pub b_pct: f64,
    /// Each position's mucosa seen in it or, through the link, in the other.
    pub a_with_b_pct: f64,
    pub b_with_a_pct: f64,
    /// Both positions' mucosa together, each seen in either.
    pub combined_pct: f64,
}

/// Coverage over both positions: mucosa unseen in one but seen in the other (where the link
/// puts it, the same side round the colon) counts as seen. `link` maps `a`'s arcs to `b`'s.
pub fn both_coverage(link: &Link, a: &Read, b: &Read) -> BothCoverage {
    let back = link.reversed();
    let (a_bins, b_bins) = (
        Bins::of(a.map, a.seen, a.study.centerline.length_mm),
        Bins::of(b.map, b.seen, b.study.centerline.length_mm),
    );
    let with_other = |r: &Read, other: &Bins, link: &Link| -> (f64, f64) {
        r.map
            .place
            .iter()
            .enumerate()
            .fold((0.0, 0.0), |(seen, whole), (t, place)| {
                let a = r.seen.area_of(t as u32) as f64;
                let by_other = place.is_some_and(|(s, k)| other.seen(link.map(s), k));
                let yes = r.seen.is_seen(t as u32) || by_other;
                (seen + if yes { a } else { 0.0 }, whole + a)
            })
    };
    let (sa, wa) = with_other(a, &b_bins, link);
    let (sb, wb) = with_other(b, &a_bins, &back);
    let pct = |x: f64, w: f64| if w > 0.0 { 100.0 * x / w } else { 0.0 };
    BothCoverage {
        a_pct: a.seen.percent(),
        b_pct: b.seen.percent(),
        a_with_b_pct: pct(sa, wa),
        b_with_a_pct: pct(sb, wb),
        combined_pct: pct(sa + sb, wa + wb),
    }
}

/// [`both_coverage`] at each stage of two positions' readings (each its study, map and
/// reading): one way, both ways, after the review.
pub fn both_readings(
    link: &Link,
    a: (&Study, &MucosaMap, &Reading),
    b: (&Study, &MucosaMap, &Reading),
) -> [BothCoverage; 3] {
    let stage = |pick: fn(&Reading) -> &Coverage| {
        let (x, y) = (
            Read {
                study: a.0,
                map: a.1,
                seen: pick(a.2),
            },
            Read {
                study: b.0,
                map: b.1,
                seen: pick(b.2),
            },
        );
        both_coverage(link, &x, &y)
    };
    [
        stage(|r| &r.one_way),
        stage(|r| &r.two_way),
        stage(|r| &r.after_review),
    ]
}
