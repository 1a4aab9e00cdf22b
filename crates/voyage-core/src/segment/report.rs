//! The report: every gas region, kept in the colon (named by where it lies along the colon's
//! course) or left out (classed, with the reason), the rectal tubes, the bridged gaps, what
//! the user must hear of, and the gas components labelled by their compartments.

use glam::DVec3;

use super::{
    Component, ComponentKind, EXCLUDED, Gap, SegmentOptions, SegmentReport, Segmentation,
    bridge::Path,
    chain::{self, Chained, Left},
    compartments::Compartment,
    compartments::{CREVICE_MM, Candidates, Compartments, SMALL_BOWEL_MAX_MM, colon_box},
    components::{Found, report as list_components},
    course::Course,
    runs::{Runs, row_of, run_voxels},
    tube,
    work::{Bbox, lps_box},
};

/// Gas left out of the colon from this size on (ml) gets a warning.
const LARGE_LEFT_ML: f64 = 20.0;

/// The segmentation's reports.
pub(super) struct Report {
    /// Gas regions (with their fluid): the colon's in order, then the rest.
    pub(super) segments: Vec<SegmentReport>,
    pub(super) gaps: Vec<Gap>,
    pub(super) warnings: Vec<String>,
    /// Gas components, largest first (those above `min_report_ml`), and how many smaller.
    pub(super) components: Vec<Component>,
    pub(super) small_components: usize,
    pub(super) last_segment: Option<LastSegment>,
}

/// What names the colon's last segment again once the centerline's end is known: the
/// colon's box and where the segment was entered, both in the patient frame (LPS mm), so
/// any storage order names it alike.
#[derive(Clone, Debug)]
pub struct LastSegment {
    colon_lps: [DVec3; 2],
    entry_lps: DVec3,
    /// The landmark (its place along the colon) that the segment before it ends at: the
    /// last segment is named from there on.
    after: usize,
}

impl Segmentation {
    /// Names the colon's last segment again by where the centerline ends in it (`end_mm`,
    /// volume-local), and says the new name in the warning of the gap before it. The chain
    /// left that segment at the coarse block farthest through its gas from its entry; where
    /// its loops touch, that block can be short of the end the centerline reaches (on
    /// `masks/colon-a`, the transverse colon, where the centerline goes on to the right
    /// colon). An end outside the segment's box leaves it as it was.
    pub(crate) fn name_last_segment(&mut self, end_mm: DVec3) {
        let Some(last) = &self.last_segment else {
            return;
        };
        let geom = self.lumen.geometry();
        let Some(i) = (0..self.segments.len()).max_by_key(|&i| self.segments[i].order) else {
            return;
        };
        let Some(order) = self.segments[i].order else {
            return;
        };
        // Only an end in that segment's gas names it (its box, a voxel's margin round it).
        let [lo, hi] = self.segments[i].extent_lps_mm.map(DVec3::from_array);
        let margin = DVec3::from_array(geom.spacing).max_element();
        let end_lps = geom.local_to_patient(end_mm);
        if end_lps.cmplt(lo - margin).any() || end_lps.cmpgt(hi + margin).any() {
            return;
        }
        let named = Course::new(geom, last.colon_lps);
        let ends = [geom.patient_to_local(last.entry_lps), end_mm];
        let at = named.places_in_order(&ends, last.after);
        let name = segment_name(&named, ends, [at[0], at[1]]);
        let before = order
            .checked_sub(1)
            .and_then(|o| self.gaps.iter().position(|g| g.between == [o, order]));
        match before {
            Some(g) => self.rewarn_gap(g, |s| s.segments[i].label = name),
            None => self.segments[i].label = name,
        }
    }

    /// Each gap measured along the centerline once it is traced: its length becomes the
    /// centerline's arc across it (`spans`, per gap; the bridge's own path wanders through a
    /// fluid-filled stretch: on `ctc/prone-tagged` 172 mm where the centerline crosses it in
    /// 103), and `fluid_filled` says what filled it. Its warning says the same.
    pub(crate) fn measure_gaps_along(&mut self, spans: &[Option<[f64; 2]>], fluid_filled: &[bool]) {
        for (g, (span, &fluid)) in spans.iter().zip(fluid_filled).enumerate() {
            self.rewarn_gap(g, |s| {
                let gap = &mut s.gaps[g];
                if let Some([from, to]) = *span {
                    gap.length_mm = to - from;
                }
                gap.fluid_filled = fluid;
            });
        }
    }

    /// Small bowel beyond the ileocaecal valve was taken out of the lumen after segmentation:
    /// `voxels` (volume indices, ascending), `ml` of it, out of the colon's last segment.
    /// Where that segment is the small bowel's own (its lowest gas among the voxels, and
    /// little more gas than they hold), it is left out with `why`, and the gap bridged to it
    /// goes with its warning (matched before the names change). Otherwise the segment keeps
    /// the rest of its gas, and its point for `--seed` moves to `cecum_lps` where it lay in
    /// the small bowel.
    pub(crate) fn leave_out_beyond_the_cecum(
        &mut self,
        voxels: &[usize],
        ml: f64,
        cecum_lps: DVec3,
        why: &str,
    ) {
        let geom = self.lumen.geometry().clone();
        let Some(last) = (0..self.segments.len())
            .filter(|&i| self.segments[i].kept)
            .max_by_key(|&i| self.segments[i].order)
        else {
            return;
        };
        let Some(order) = self.segments[last].order else {
            return;
        };
        let ijk = geom
            .patient_to_index(DVec3::from_array(self.segments[last].anchor_lps_mm))
            .round();
        let anchored_there = (0..3).all(|a| ijk[a] >= 0.0 && (ijk[a] as usize) < geom.dims[a])
            && voxels
                .binary_search(&geom.index(ijk.x as usize, ijk.y as usize, ijk.z as usize))
                .is_ok();
        if !anchored_there || self.segments[last].gas_ml > OWN_SHARE * ml {
            let s = &mut self.segments[last];
            s.gas_ml = (s.gas_ml - ml).max(0.0);
            if anchored_there {
                s.anchor_lps_mm = cecum_lps.to_array();
            }
            return;
        }
        let to_gone: Vec<usize> = (0..self.gaps.len())
            .filter(|&g| self.gaps[g].between.contains(&order))
            .collect();
        let said: Vec<String> = to_gone.iter().map(|&g| self.gap_warning_now(g)).collect();
        self.warnings.retain(|w| !said.contains(w));
        for &g in to_gone.iter().rev() {
            self.gaps.remove(g);
        }
        let s = &mut self.segments[last];
        s.kept = false;
        s.kind = ComponentKind::SmallBowel;
        s.label = ComponentKind::SmallBowel.name().into();
        s.order = None;
        s.reason = Some(why.into());
        // The last segment is another now, entered elsewhere: it keeps the name it has.
        self.last_segment = None;
    }

    /// Gap `g` changed by `change` (its length, what filled it, a segment's name), and its
    /// warning said again as it now reads.
    fn rewarn_gap(&mut self, g: usize, change: impl FnOnce(&mut Self)) {
        let was = self.gap_warning_now(g);
        change(self);
        let now = self.gap_warning_now(g);
        for w in &mut self.warnings {
            if *w == was {
                w.clone_from(&now);
            }
        }
    }

    /// The warning of gap `g` with the segments' labels as they are.
    fn gap_warning_now(&self, g: usize) -> String {
        let gap = &self.gaps[g];
        let label = |o: usize| {
            self.segments
                .iter()
                .find(|s| s.order == Some(o))
                .map_or("", |s| s.label.as_str())
        };
        gap_warning(gap, label(gap.between[0]), label(gap.between[1]))
    }
}

/// A last segment with at most this many times the gas taken out beyond the cecum is the
/// small bowel's own compartment.
const OWN_SHARE: f64 = 1.25;

/// The reports of the colon chained in `chained` from `parts` and of everything else `found`
/// holds; `gap_voxels`: per gap, the lumen voxels its bridge added.
pub(super) fn report(
    found: Found,
    parts: &Compartments,
    cand: &Candidates,
    chained: &Chained,
    gap_voxels: Vec<Vec<usize>>,
    geom: &crate::Geometry,
    opts: &SegmentOptions,
) -> Report {
    let in_colon = |c: u32| chained.chain.links.iter().any(|l| l.comp == c);
    let colon_lps = colon_box(parts, cand.rectum, in_colon, geom);
    let classes = classes(parts, in_colon, &cand.narrow, geom, &colon_lps);
    let (mut segments, after) = colon_segments(parts, chained, geom, colon_lps);
    let last_segment = chained.chain.links.last().map(|l| LastSegment {
        colon_lps,
        entry_lps: geom.local_to_patient(chained.coarse.centre_mm(l.entry)),
        after,
    });
    segments.extend(left_out(
        parts,
        [&cand.crevice, &cand.narrow],
        &chained.chain.left,
        &classes,
        geom,
        opts,
    ));
    for t in &found.tubes {
        segments.push(tube_report(t, &found.runs, geom, parts.voxel_ml));
    }
    let catheters: Vec<[DVec3; 2]> = found
        .tubes
        .iter()
        .map(|t| [t.entry, t.tip].map(|v| geom.index_to_patient(DVec3::from(v))))
        .collect();
    let (gaps, mut warnings) = gaps(&chained.chain.gaps, gap_voxels, &segments, &catheters, geom);
    warnings.extend(edge_warnings(parts, chained, geom));
    warnings.extend(left_out_warnings(&segments));
    let comps = labelled(found.comps, &parts.of_gas, &classes);
    let (components, small_components) = list_components(comps, opts.min_report_ml);
    Report {
        segments,
        gaps,
        warnings,
        components,
        small_components,
        last_segment,
    }
}

/// Each compartment's class: colon where `in_colon`, small bowel where `narrow`, else
/// [`classify`]'s within the colon's LPS box `colon_lps`.
fn classes(
    parts: &Compartments,
    in_colon: impl Fn(u32) -> bool,
    narrow: &[bool],
    geom: &crate::Geometry,
    colon_lps: &[DVec3; 2],
) -> Vec<ComponentKind> {
    (0..parts.list.len() as u32)
        .map(|c| {
            if in_colon(c) {
                ComponentKind::Colon
            } else if narrow[c as usize] {
                ComponentKind::SmallBowel
            } else {
                classify(&parts.list[c as usize], geom, colon_lps, parts.voxel_ml)
            }
        })
        .collect()
}

/// The colon's segments in order, each named by the landmarks nearest its entry and exit
/// and the one halfway along the course between them (`colon_lps`: the whole colon's box),
/// in the colon's order; and the place of the landmark the last but one ends at.
fn colon_segments(
    parts: &Compartments,
    chained: &Chained,
    geom: &crate::Geometry,
    colon_lps: [DVec3; 2],
) -> (Vec<SegmentReport>, usize) {
    let named = Course::new(geom, colon_lps);
    let coarse = &chained.coarse;
    let links = &chained.chain.links;
    let ends: Vec<DVec3> = links
        .iter()
        .flat_map(|l| [coarse.centre_mm(l.entry), coarse.centre_mm(l.exit)])
        .collect();
    let at = named.places_in_order(&ends, 0);
    let segments = links
        .iter()
        .enumerate()
        .map(|(i, l)| {
            let name = segment_name(
                &named,
                [ends[2 * i], ends[2 * i + 1]],
                [at[2 * i], at[2 * i + 1]],
            );
            let comp = &parts.list[l.comp as usize];
            segment_report(
                comp,
                geom,
                name,
                ComponentKind::Colon,
                Some(i),
                None,
                parts.voxel_ml,
            )
        })
        .collect();
    // The last segment is named again from where the one before it ends.
    let before_last = (links.len() >= 2).then(|| at[2 * links.len() - 3]);
    (segments, before_last.unwrap_or(0))
}

/// A colon segment's name from its entry and exit (volume-local mm), placed at landmarks
/// `at` ([`Course::places_in_order`]), and, between, the landmark halfway along the course
/// (only if it lies between them in the colon's order: the ends are named by place, the
/// middle by course). A segment from rectum to cecum is the whole colon, and a middle name
/// would only suggest it stops there.
fn segment_name(named: &Course, [entry, exit]: [DVec3; 2], at: [usize; 2]) -> String {
    let ends = at.map(Course::landmark_name);
    if ends == ["rectum", "cecum"] {
        return ends.join("–");
    }
    let halfway = named.name_along(0.5 * (named.along(entry) + named.along(exit)));
    let between = match ends.map(Course::order_of) {
        [Some(a), Some(b)] => Course::order_of(halfway).is_some_and(|m| a < m && m < b),
        _ => false,
    };
    // A middle name lies strictly between the ends, so it differs from both.
    match (between, ends[0] == ends[1]) {
        (true, _) => [ends[0], halfway, ends[1]].join("–"),
        (false, true) => ends[0].to_string(),
        (false, false) => ends.join("–"),
    }
}

/// The gas left out of the colon (`left`), most gas first, from `min_report_ml` on: each
/// with its class and why it was left out (`crevice`, `narrow`: per compartment, whether
/// its gas lies in a crevice, whether it is large gas no wider than small bowel's).
fn left_out(
    parts: &Compartments,
    [crevice, narrow]: [&[bool]; 2],
    left: &[(u32, Left)],
    classes: &[ComponentKind],
    geom: &crate::Geometry,
    opts: &SegmentOptions,
) -> Vec<SegmentReport> {
    let voxel_ml = parts.voxel_ml;
    let mut others: Vec<(u32, Left)> = left.to_vec();
    others.sort_by(|a, b| {
        parts.list[b.0 as usize]
            .gas_voxels
            .cmp(&parts.list[a.0 as usize].gas_voxels)
            .then(a.0.cmp(&b.0))
    });
    let mut segments = Vec::new();
    for (c, why) in others {
        let comp = &parts.list[c as usize];
        if (comp.gas_voxels as f64 * voxel_ml) < opts.min_report_ml {
            continue;
        }
        let kind = classes[c as usize];
        let reason = if narrow[c as usize] && why != Left::Excluded {
            format!("no ball wider than {SMALL_BOWEL_MAX_MM:.0} mm fits in its gas: small bowel")
        } else {
            reason(
                why,
                crevice[c as usize],
                comp.gas_voxels as f64 * voxel_ml,
                opts,
            )
        };
        let label = match kind {
            ComponentKind::SmallBowel => "small bowel",
            ComponentKind::Stomach => "stomach",
            _ => "other",
        };
        segments.push(segment_report(
            comp,
            geom,
            label.to_string(),
            kind,
            None,
            Some(reason),
            voxel_ml,
        ));
    }
    segments
}

/// Why a compartment of `gas_ml` is not in the colon, in words.
fn reason(why: Left, crevice: bool, gas_ml: f64, opts: &SegmentOptions) -> String {
    match why {
        Left::TooSmall if crevice => format!(
            "{:.1} ml of gas in a crevice less than {:.0} mm across (a skin fold), not bowel",
            gas_ml,
            2.0 * CREVICE_MM
        ),
        Left::TooSmall => format!(
            "{:.1} ml of gas, less than a colon segment's {} ml",
            gas_ml, opts.chain.min_segment_ml
        ),
        Left::TooFar(d) if d.is_finite() => format!(
            "its nearest end is {d:.0} mm from the colon's end (more than {:.0} mm)",
            opts.chain.max_gap_mm
        ),
        Left::TooFar(_) => "not reached from the colon's end".to_string(),
        Left::BeyondCecum(d) => format!(
            "it lies {d:.0} mm from the colon's end, but the colon already ends at the cecum there"
        ),
        Left::NotOnward(d) => format!(
            "it lies {d:.0} mm from the colon's end, but no bridge from there to it was taken"
        ),
        Left::BridgeTooDear { gap_mm, cost } => format!(
            "the way to it ({gap_mm:.0} mm) crosses fat or bone, not collapsed bowel (cost {cost:.1} per mm)"
        ),
        Left::Excluded => EXCLUDED.to_string(),
    }
}

/// The gaps bridged between consecutive colon segments (`paths`, with the voxels each added,
/// `gap_voxels`), and a warning for each; `catheters`: each rectal tube's entry and tip (LPS).
fn gaps(
    paths: &[Path],
    gap_voxels: Vec<Vec<usize>>,
    segments: &[SegmentReport],
    catheters: &[[DVec3; 2]],
    geom: &crate::Geometry,
) -> (Vec<Gap>, Vec<String>) {
    let lps =
        |v: [usize; 3]| geom.index_to_patient(DVec3::new(v[0] as f64, v[1] as f64, v[2] as f64));
    let mut gaps = Vec::new();
    let mut warnings = Vec::new();
    for (i, (p, voxels)) in paths.iter().zip(gap_voxels).enumerate() {
        let ends = (p.voxels[0], p.voxels[p.voxels.len() - 1]);
        let edge = side_near(ends.0, geom).or_else(|| side_near(ends.1, geom));
        let (from, to) = (lps(ends.0), lps(ends.1));
        let gap = Gap {
            between: [i, i + 1],
            length_mm: p.length_mm,
            from_lps_mm: from.to_array(),
            to_lps_mm: to.to_array(),
            mean_cost: p.mean_cost,
            fluid_filled: false,
            edge_side: edge,
            at_catheter: catheters
                .iter()
                .any(|&c| along_catheter(c, (from + to) * 0.5)),
            voxels,
        };
        warnings.push(gap_warning(
            &gap,
            &segments[i].label,
            &segments[i + 1].label,
        ));
        gaps.push(gap);
    }
    (gaps, warnings)
}

/// A retention balloon's radius and the rectum's wall (mm): how far from a rectal catheter,
/// across the body's long axis, the gas it keeps apart lies.
const CATHETER_REACH_MM: f64 = 40.0;

/// Whether `p` (LPS) lies along rectal catheter `c` (its entry and tip, LPS) inside the body:
/// between their heights, within [`CATHETER_REACH_MM`] of the line between them across.
fn along_catheter(c: [DVec3; 2], p: DVec3) -> bool {
    let [entry, tip] = c;
    let (lo, hi) = (entry.z.min(tip.z), entry.z.max(tip.z));
    if !(lo..=hi).contains(&p.z) || hi - lo < 1.0 {
        return false;
    }
    let on = entry + (tip - entry) * ((p.z - entry.z) / (tip.z - entry.z));
    (p - on).truncate().length() <= CATHETER_REACH_MM
}

/// The warning for `gap`, between the colon segments named `a` and `b`.
fn gap_warning(gap: &Gap, a: &str, b: &str) -> String {
    let [x, y, z] = gap.from_lps_mm;
    let mm = gap.length_mm;
    if gap.at_catheter && gap.edge_side.is_none() {
        return format!(
            "the rectum's gas is kept apart along the rectal catheter (its retention balloon, or the anal canal closed round it): joined through {mm:.0} mm between the {a} and the {b} segment, from LPS ({x:.0}, {y:.0}, {z:.0})"
        );
    }
    match gap.edge_side {
        Some(side) => format!(
            "the colon leaves the scanned volume at the patient's {side}: the {a} and the {b} segment are joined inside it by {mm:.0} mm from LPS ({x:.0}, {y:.0}, {z:.0}); what lies beyond the scan is not read"
        ),
        None => format!(
            "{} stretch bridged: {mm:.0} mm between the {a} and the {b} segment, from LPS ({x:.0}, {y:.0}, {z:.0})",
            if gap.fluid_filled {
                "fluid-filled"
            } else {
                "collapsed or fluid-filled"
            }
        ),
    }
}

/// A colon compartment that reaches the side of the scanned volume: the colon goes on
/// beyond the scan there. One warning per side, naming where.
fn edge_warnings(parts: &Compartments, chained: &Chained, geom: &crate::Geometry) -> Vec<String> {
    let mut sides: Vec<(&'static str, [f64; 3])> = Vec::new();
    for l in &chained.chain.links {
        let b = &parts.list[l.comp as usize].bbox;
        let mid = [0, 1, 2].map(|a| (b.lo[a] + b.hi[a]) / 2);
        let faces = [0, 1, 2]
            .into_iter()
            .flat_map(|a| [(a, b.lo[a]), (a, b.hi[a])]);
        for (axis, at) in faces {
            let mut v = mid;
            v[axis] = at;
            if let Some(side) = side_at(v, geom, 0.0)
                && !sides.iter().any(|(s, _)| *s == side)
            {
                let p = geom.index_to_patient(DVec3::new(v[0] as f64, v[1] as f64, v[2] as f64));
                sides.push((side, p.to_array()));
            }
        }
    }
    sides
        .into_iter()
        .map(|(side, [x, y, z])| {
            format!(
                "the colon reaches the side of the scanned volume at the patient's {side} (about LPS {x:.0}, {y:.0}, {z:.0}): it may go on beyond the scan, and what lies there is not read"
            )
        })
        .collect()
}

/// Within this distance of a side of the scanned volume (mm), a gap's end is at its edge.
const EDGE_MM: f64 = 5.0;

fn side_near(v: [usize; 3], geom: &crate::Geometry) -> Option<&'static str> {
    side_at(v, geom, EDGE_MM)
}

/// The side of the scanned volume within `within_mm` of voxel `v`, named by the patient's
/// direction it faces: the slices' border, or the first or last slice (a scan that ends in the
/// splenic flexure or above the rectum's end).
fn side_at(v: [usize; 3], geom: &crate::Geometry, within_mm: f64) -> Option<&'static str> {
    let sp = geom.spacing_vec();
    for axis in 0..3 {
        let n = geom.dims[axis];
        let near_lo = v[axis] as f64 * sp[axis] <= within_mm;
        let near_hi = (n - 1 - v[axis].min(n - 1)) as f64 * sp[axis] <= within_mm;
        if !(near_lo || near_hi) {
            continue;
        }
        let mut step = DVec3::ZERO;
        step[axis] = if near_hi { 1.0 } else { -1.0 };
        let centre = DVec3::new(v[0] as f64, v[1] as f64, v[2] as f64);
        let out = geom.index_to_patient(centre + step) - geom.index_to_patient(centre);
        return Some(patient_direction(out));
    }
    None
}

/// The patient's direction `d` (LPS) points most along.
fn patient_direction(d: DVec3) -> &'static str {
    let a = d.abs();
    if a.x >= a.y && a.x >= a.z {
        if d.x > 0.0 { "left" } else { "right" }
    } else if a.y >= a.z {
        if d.y > 0.0 { "back" } else { "front" }
    } else if d.z > 0.0 {
        "head end"
    } else {
        "feet end"
    }
}

/// A warning for each large gas region left out of the colon automatically (not by the user).
fn left_out_warnings(segments: &[SegmentReport]) -> Vec<String> {
    segments
        .iter()
        .filter(|s| !s.kept && s.gas_ml >= LARGE_LEFT_ML && s.reason.as_deref() != Some(EXCLUDED))
        .map(|s| {
            format!(
                "{:.0} ml of gas ({}) left out of the colon: {}",
                s.gas_ml,
                s.label,
                s.reason.as_deref().unwrap_or("")
            )
        })
        .collect()
}

/// Gas components, labelled by their compartment's class (`of_gas`, `classes`); lungs stay.
fn labelled(
    mut comps: Vec<Component>,
    of_gas: &[Option<u32>],
    classes: &[ComponentKind],
) -> Vec<Component> {
    for (c, comp) in comps.iter_mut().enumerate() {
        if comp.kind == ComponentKind::Lung {
            continue;
        }
        comp.kind = of_gas[c].map_or(ComponentKind::Other, |x| classes[x as usize]);
    }
    comps
}

/// The anatomical region of a volume-local point within the colon's LPS box.
pub(crate) fn region_of(geom: &crate::Geometry, p: DVec3, colon: &[DVec3; 2]) -> &'static str {
    let q = geom.local_to_patient(p);
    let span = (colon[1] - colon[0]).max(DVec3::splat(1.0));
    let u = (q.x - colon[0].x) / span.x;
    let v = (q.z - colon[0].z) / span.z;
    chain::region(u, v)
}

/// Gas left out of the colon: stomach (high on the left), small bowel (small or narrow), or
/// other.
fn classify(
    comp: &Compartment,
    geom: &crate::Geometry,
    colon: &[DVec3; 2],
    voxel_ml: f64,
) -> ComponentKind {
    let ml = comp.gas_voxels as f64 * voxel_ml;
    let c = geom.local_to_patient(comp.centroid_mm());
    let span = colon[1] - colon[0];
    let high_left = c.z > colon[0].z + 0.7 * span.z && c.x > colon[0].x + 0.5 * span.x;
    if high_left && ml >= LARGE_LEFT_ML {
        return ComponentKind::Stomach;
    }
    // Its length from its box's diagonal; narrow when the mean cross-section is under 25 mm.
    let b = lps_box(geom, &comp.bbox);
    let length = (b[1] - b[0]).length().max(1.0);
    let width = 2.0 * (ml * 1000.0 / (std::f64::consts::PI * length)).sqrt();
    if ml < LARGE_LEFT_ML || width <= 25.0 {
        ComponentKind::SmallBowel
    } else {
        ComponentKind::Other
    }
}

fn segment_report(
    comp: &Compartment,
    geom: &crate::Geometry,
    label: String,
    kind: ComponentKind,
    order: Option<usize>,
    reason: Option<String>,
    voxel_ml: f64,
) -> SegmentReport {
    let b = lps_box(geom, &comp.bbox);
    SegmentReport {
        label,
        kind,
        order,
        gas_ml: comp.gas_voxels as f64 * voxel_ml,
        fluid_ml: (comp.voxels - comp.gas_voxels) as f64 * voxel_ml,
        extent_lps_mm: [b[0].to_array(), b[1].to_array()],
        anchor_lps_mm: geom
            .index_to_patient(DVec3::from_array(comp.lowest.map(|x| x as f64)))
            .to_array(),
        kept: order.is_some(),
        reason,
    }
}

/// A rectal tube as a gas region left out of the colon.
fn tube_report(
    t: &tube::Tube,
    runs: &Runs,
    geom: &crate::Geometry,
    voxel_ml: f64,
) -> SegmentReport {
    let mut bbox: Option<Bbox> = None;
    let voxels = run_voxels(runs, &t.runs);
    for &r in &t.runs {
        let (j, k) = row_of(runs, r);
        let run = runs.runs[r];
        let b = Bbox {
            lo: [run.x0 as usize, j, k],
            hi: [run.x1 as usize - 1, j, k],
        };
        bbox = Some(bbox.map_or(b, |x| x.union(&b)));
    }
    let b = bbox.map_or([DVec3::ZERO; 2], |b| lps_box(geom, &b));
    let lps = |v: [f64; 3]| geom.index_to_patient(DVec3::from_array(v)).to_array();
    let tip = lps(t.tip);
    SegmentReport {
        label: "rectal tube".into(),
        kind: ComponentKind::RectalTube,
        order: None,
        gas_ml: voxels as f64 * voxel_ml,
        fluid_ml: 0.0,
        extent_lps_mm: [b[0].to_array(), b[1].to_array()],
        anchor_lps_mm: lps(t.entry),
        kept: false,
        reason: Some(format!(
            "a rectal tube, {:.0} mm from {} to its tip at LPS ({:.0}, {:.0}, {:.0}): its air is not colon; the rectum starts at its tip",
            t.length_mm,
            if t.from_edge {
                "the scan's edge"
            } else {
                "the skin"
            },
            tip[0],
            tip[1],
            tip[2]
        )),
    }
}
