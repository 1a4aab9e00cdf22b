//! A synthetic colon at a real scan's size, with haustral folds, polyps of known size and
//! the things that make real CT colonography hard (tagged fluid, collapsed and fluid-filled
//! stretches, small-bowel gas and opacified small bowel, lung bases, a prone patient, a
//! rectal catheter, quantised grey levels; see [`ColonOptions`]).
//!
//! Full size: 512×512×400 voxels of 0.75×0.75×1.0 mm (384×384×400 mm), like a clinical
//! scan. Small (for fast tests): 128×128×125 voxels of 1.5×1.5×1.6 mm with the whole
//! anatomy scaled by ½ (lumen radius 6–15 mm, so ≥ 4 voxels); thin features are kept about
//! a voxel thick at least (wall 1.6 mm, fold half-width 1.44 mm), polyps become d/2 + 2.5 mm.
//!
//! Anatomy (identity LPS frame: +x patient left, +y posterior, +z superior), see `KNOTS`:
//! the rectum rises in the midline in front of the sacrum; the sigmoid swings right, dips
//! into the pelvis in front of the rectum, climbs on the left, makes an anterior loop under
//! the transverse colon and reaches the left iliac fossa; the descending colon climbs the
//! left flank posteriorly to the splenic flexure under the left lung; the transverse colon
//! crosses anteriorly to the right, sagging to z ≈ 250 mm; the hepatic flexure (a little
//! lower than the splenic) turns down into the ascending colon on the right, which ends in
//! the wide, blind cecum. 1562 mm long; radius 12–30 mm (rectum and cecum widest, sigmoid
//! and descending narrowest); different loops keep ≥ 10 mm of tissue between their lumens.
//!
//! Haustral folds every 20–30 mm from the sigmoid on (none in the rectum): three crescents
//! between the taeniae, each 3–8 mm deep (at most 45 % of the radius) and ≈ 2–4 mm thick
//! (see [`Fold`](super::tube::Fold)). Eight polyps of 3–12 mm in six segments, three hidden
//! just behind a fold (see `POLYPS`). The truth records everything (see [`Truth`]).
//!
//! Options (all combine):
//! - prone: gravity −y; tagged fluid pools in the sigmoid's and transverse colon's anterior
//!   loops and at the caecal pole instead of posteriorly in the rectum, descending and
//!   ascending colon. Each pool is anchored at its segment's most dependent point, so its
//!   level is flat and gas remains above it.
//! - collapsed: 30 mm of the sigmoid (55 % along), descending (60 %) and/or transverse (50 %)
//!   down to a tissue cord.
//! - fluid-filled: 40–60 mm of a segment filled to the brim (+400..+700 HU), 20–35 % along
//!   it (65–80 % if that meets a collapse).
//! - opacified small bowel: see [`super::small_bowel`]; it brings its own caecal pool.
//! - rectal tube: a catheter from 35 mm up the rectum out through a perineum, which the body
//!   gets only then (4 mm above the first slice, full size): the rectum's end stays ≥ 5 mm
//!   from its skin, its muscle wraps the rectum's end as the pelvic floor does.
//! - table: a CT table (carbon-fibre shell, foam core) under the patient on the dependent
//!   side, the skin pressed flat on it over a contact strip (see [`super::skin`]).
//! - skin folds: 4–8 thin crevices of outside air cut into the skin, on the dependent side
//!   and low in the scan (perineal beside the catheter, or gluteal), some closed over by skin
//!   in part of their length (see [`super::skin`]).
//! - diverticula: 10 pouches of gas through the wall on narrow necks, in the sigmoid and
//!   descending colon, on the side away from gravity.
//! - quantise: the CT rounded to multiples of a step after the noise.

mod anatomy;
mod catheter;
mod dev;
mod diverticula;
mod folds;
mod options;
mod pockets;
mod polyps;
mod pools;
mod stool;
mod streams;
mod stretches;

use glam::DVec3;

use super::{
    Phantom, arr,
    body::{self, Body},
    frame::Frame,
    label, label_counts,
    polyp::place,
    posture::pair_collapsed,
    raster::{Materials, Scene},
    rng::stream_key,
    skin::{self, Obstacles},
    small_bowel,
    truth::{
        BalloonTruth, COORDINATES_NOTE, CollapsedTruth, DistractorTruth, FilledTruth, GapTruth,
        PolypTruth, RectalTubeTruth, RoiTruth, Truth,
    },
    tube::{Blob, Catheter, Ends, Tube},
};
pub use anatomy::MIN_PART_GAP;
pub(crate) use anatomy::pair_axes;
use anatomy::{END_INSET, WALL, check_anatomy, make_axis, make_body, segments};
pub use catheter::CANAL_MM;
use catheter::{CATHETER_HU, FLOOR_Z, make_catheter};
#[doc(hidden)]
pub use dev::{anatomy_report, free_space_map, loop_room_report};
use diverticula::make_diverticula;
use folds::{fold_truth, make_folds};
use options::check_options;
pub use options::{COLLAPSIBLE, ColonOptions, FILLABLE};
use pockets::make_pockets;
pub use polyps::MAX_PROTRUSION;
use polyps::make_polyps;
use pools::make_pools;
use stool::make_stool;
use streams::STREAM_NOISE;
pub use stretches::NECK_RADIUS_MM;
use stretches::{make_collapses, make_filled, make_necks};
use voyage_core::Result;

pub use super::frame::{FULL_DIMS, FULL_SPACING, SMALL_DIMS, SMALL_SCALE, SMALL_SPACING};

/// Makes the colon phantom.
pub fn colon(opts: &ColonOptions) -> Result<Phantom> {
    check_options(opts)?;
    // An anal canal takes the perineum down by its length, and the volume with it.
    let below = if opts.anal_canal { CANAL_MM } else { 0.0 };
    let frame = Frame::reaching_below(opts.small, below)?;
    let floor = opts
        .rectal_tube
        .then(|| frame.pos([0.0, 0.0, FLOOR_Z - below]).z);
    let gravity = if opts.prone { DVec3::NEG_Y } else { DVec3::Y };
    let mut body = make_body(&frame, opts.lung_bases, floor);
    if opts.table {
        body.table = Some(skin::make_table(&frame, &body, gravity));
    }
    let axis = make_axis(&frame, false)?;
    let mut segments = segments(&axis);
    check_anatomy(&frame, &axis, &body)?;
    let mut tube = Tube::new(axis, frame.thin(WALL, 1.0), Ends::Round);
    let necks = make_necks(&frame, &segments, &opts.narrowed)?;
    let (collapsed, placing) = if opts.pair_member {
        // Folds and polyps keep clear of both positions' collapses, so they are the same in
        // both.
        (
            pair_collapsed(&opts.collapsed, Some(opts.prone)),
            pair_collapsed(&opts.collapsed, None),
        )
    } else {
        (opts.collapsed.clone(), opts.collapsed.clone())
    };
    let collapses = make_collapses(&frame, &segments, &collapsed)?;
    tube.collapse = make_collapses(&frame, &segments, &placing)?
        .into_iter()
        .map(|(c, _)| c)
        .chain(necks.iter().cloned())
        .collect();
    let folds = make_folds(&frame, &tube, &segments, opts.seed);
    tube.set_folds(folds);
    let mut polyp_specs = make_polyps(&frame, &mut tube, &segments, opts.seed)?;
    tube.collapse = collapses.iter().map(|(c, _)| c.clone()).collect();
    tube.collapse.extend(necks);
    let mut filled = make_filled(&frame, &tube, &segments, &opts.fluid_filled, opts.seed)?;
    tube.filled = filled.iter().map(|(f, _)| f.clone()).collect();
    let mut collapses = collapses;
    if opts.pair_member && !opts.prone {
        // Everything along the colon was placed on the prone shape; it keeps its place on
        // the wall as the loops sag.
        let mut moved = make_axis(&frame, true)?;
        moved.reframe_like(&tube.axis);
        check_anatomy(&frame, &moved, &body)?;
        let at = |s: f64| tube.axis.arc_on(&moved, s);
        polyp_specs.iter_mut().for_each(|p| p.arc = at(p.arc));
        for (_, t) in &mut collapses {
            (t.start_arc_mm, t.end_arc_mm) = (at(t.start_arc_mm), at(t.end_arc_mm));
        }
        for (_, t) in &mut filled {
            (t.start_arc_mm, t.end_arc_mm) = (at(t.start_arc_mm), at(t.end_arc_mm));
        }
        tube = tube.moved_to(moved);
        segments = self::segments(&tube.axis);
    }
    let (mut blobs, polyps): (Vec<Blob>, Vec<PolypTruth>) =
        polyp_specs.iter().map(|sp| place(&tube, sp)).unzip();
    let catheter = if opts.rectal_tube {
        Some(make_catheter(
            &frame,
            &tube,
            &blobs,
            floor.unwrap_or(0.0),
            opts.anal_canal,
            opts.rectal_balloon,
        )?)
    } else {
        None
    };
    let bowel = if opts.opacified_small_bowel || opts.gas_filled_small_bowel {
        Some(small_bowel::make(
            &frame,
            &tube,
            &body,
            &segments,
            gravity,
            &blobs,
            catheter.as_ref(),
            opts.seed,
        )?)
    } else {
        None
    };
    let bowel = bowel.map(|b| {
        if !opts.gas_filled_small_bowel {
            b
        } else if opts.closed_ileocaecal_valve {
            b.filled_with_gas()
                .closed_at_the_valve(tube.wall_mm, 2.0 * frame.max_spacing())
        } else {
            b.filled_with_gas()
        }
    });
    let pools = make_pools(
        &tube,
        &segments,
        opts,
        gravity,
        // Gas in the ileum does not lie under the caecal pool.
        bowel
            .as_ref()
            .filter(|_| opts.opacified_small_bowel)
            .map(|b| &b.valve),
    );
    let stool = if opts.tagged_stool {
        let dependent = opts.pair_member.then_some(gravity);
        make_stool(&frame, &tube, &segments, &polyps, dependent, opts.seed)?
    } else {
        Vec::new()
    };
    blobs.extend(stool.iter().map(|(b, _)| b.clone()));
    tube.pools = pools.iter().map(|(p, _)| p.clone()).collect();
    // Pockets keep clear of the loops and the catheter as they do of the colon; without
    // either the list is empty and they land where they always did.
    let mut obstacles: Vec<(DVec3, DVec3, f64)> = Vec::new();
    if let Some(b) = &bowel {
        obstacles.extend(
            b.blobs
                .iter()
                .filter_map(|l| l.stalk.map(|(p, q, r)| (p, q, r + l.wall_mm))),
        );
    }
    if let Some(c) = &catheter {
        obstacles.extend(c.points.windows(2).map(|w| (w[0], w[1], c.outer_radius())));
    }
    let diverticula = if opts.diverticula {
        make_diverticula(
            &frame, &tube, &segments, &polyps, gravity, &obstacles, opts.seed,
        )?
    } else {
        Vec::new()
    };
    obstacles.extend(
        diverticula
            .iter()
            .map(|(b, _)| (b.center, b.center, b.radius + b.wall_mm)),
    );
    blobs.extend(diverticula.iter().map(|(b, _)| b.clone()));
    let mut distractors = Vec::new();
    if opts.small_bowel_gas {
        let pockets = make_pockets(&frame, &tube, &body, &obstacles, opts.seed);
        distractors.extend(pockets.iter().map(|b| DistractorTruth {
            kind: "small_bowel_gas".into(),
            center_mm: arr(b.center),
            semi_axes_mm: [b.radius; 3],
            hu: body::AIR,
        }));
        blobs.extend(pockets);
    }
    if let Some(b) = &bowel {
        distractors.extend(b.loops.iter().map(|l| {
            let (lo, hi) = l.axis_mm.iter().fold(
                ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]),
                |(lo, hi), p| {
                    (
                        [0, 1, 2].map(|a| lo[a].min(p[a])),
                        [0, 1, 2].map(|a| hi[a].max(p[a])),
                    )
                },
            );
            DistractorTruth {
                kind: if opts.gas_filled_small_bowel {
                    "small_bowel_gas_loop"
                } else {
                    "opacified_small_bowel"
                }
                .into(),
                center_mm: [0, 1, 2].map(|a| 0.5 * (lo[a] + hi[a])),
                semi_axes_mm: [0, 1, 2].map(|a| 0.5 * (hi[a] - lo[a]) + l.radius_mm + l.wall_mm),
                hu: l.hu,
            }
        }));
        blobs.extend(b.blobs.iter().cloned());
    }
    let skin_folds = if opts.skin_folds {
        let near = Obstacles {
            tube: &tube,
            blobs: &blobs,
            catheter: catheter.as_ref(),
        };
        skin::make_folds(&frame, &body, gravity, &near, opts.seed)
    } else {
        Vec::new()
    };
    body.folds = skin_folds.iter().map(|(f, _)| f.clone()).collect();
    distractors.extend(body.lungs.iter().map(|l| DistractorTruth {
        kind: "lung".into(),
        center_mm: [
            l.center.x,
            l.center.y,
            0.5 * (l.recess + frame.geom.extent_mm().z),
        ],
        semi_axes_mm: [
            l.semi.x,
            l.semi.y,
            0.5 * (frame.geom.extent_mm().z - l.recess),
        ],
        hu: body::LUNG,
    }));
    let noise_roi = fat_roi(&frame, &tube, &blobs, &body, catheter.as_ref());
    let scene = Scene {
        geom: frame.geom.clone(),
        tube: &tube,
        blobs: &blobs,
        catheter: catheter.as_ref(),
        materials: Materials {
            lumen_air: body::AIR,
            wall: body::SOFT_TISSUE,
            polyp: body::SOFT_TISSUE,
            pocket_air: body::AIR,
        },
        background: &body,
        noise_sigma: opts.noise_hu,
        noise_key: stream_key(opts.seed, STREAM_NOISE),
        quantize: opts.quantize_hu,
    };
    let r = scene.render()?;
    let counts = label_counts(&r.labels);
    let ax = &tube.axis;
    let inset = END_INSET * frame.scale;
    let (source_arc, target_arc) = (inset, ax.length - inset);
    let collapsed: Vec<CollapsedTruth> = collapses.into_iter().map(|(_, t)| t).collect();
    let fluid_filled: Vec<FilledTruth> = filled.into_iter().map(|(_, t)| t).collect();
    let mut gas_gaps: Vec<GapTruth> = collapsed
        .iter()
        .map(|c| GapTruth {
            kind: "collapsed".into(),
            segment: c.segment.clone(),
            start_arc_mm: c.start_arc_mm,
            end_arc_mm: c.end_arc_mm,
        })
        .chain(fluid_filled.iter().map(|f| GapTruth {
            kind: "fluid_filled".into(),
            segment: f.segment.clone(),
            start_arc_mm: f.start_arc_mm,
            end_arc_mm: f.end_arc_mm,
        }))
        .collect();
    gas_gaps.sort_by(|a, b| a.start_arc_mm.total_cmp(&b.start_arc_mm));
    let truth = Truth {
        kind: "colon".into(),
        seed: opts.seed,
        coordinates: COORDINATES_NOTE.into(),
        position: if opts.prone { "HFP" } else { "HFS" }.into(),
        gravity_lps: arr(gravity),
        dims: frame.geom.dims,
        spacing_mm: frame.geom.spacing,
        origin_lps_mm: frame.geom.origin,
        direction: frame.geom.direction,
        scale: frame.scale,
        noise_hu: opts.noise_hu,
        quantize_hu: opts.quantize_hu,
        centerline_mm: ax.points.iter().map(|p| arr(*p)).collect(),
        centerline_arc_mm: ax.arc.clone(),
        centerline_radius_mm: ax.radius.clone(),
        centerline_length_mm: ax.length,
        source_mm: arr(ax.point_at(source_arc)),
        target_mm: arr(ax.point_at(target_arc)),
        source_arc_mm: source_arc,
        target_arc_mm: target_arc,
        wall_thickness_mm: tube.wall_mm,
        min_part_gap_mm: ax.min_part_gap(tube.wall_mm, 2).0,
        polyps,
        lumen_voxels: counts[label::LUMEN_AIR as usize]
            + counts[label::LUMEN_FLUID as usize]
            + counts[label::STOOL as usize]
            + counts[label::RECTAL_BALLOON as usize],
        folds: tube.folds.len(),
        fold_list: fold_truth(&tube, &segments),
        segments: segments.clone(),
        fluid_pools: pools.into_iter().map(|(_, t)| t).collect(),
        fluid_voxels: counts[label::LUMEN_FLUID as usize],
        collapsed,
        fluid_filled,
        gas_gaps,
        distractors,
        small_bowel_loops: bowel.as_ref().map_or_else(Vec::new, |b| b.loops.clone()),
        ileocecal_valve_mm: bowel.as_ref().map(|b| arr(b.valve.point)),
        stool: stool.into_iter().map(|(_, t)| t).collect(),
        rectal_tube: catheter.as_ref().map(|c| RectalTubeTruth {
            tip_mm: arr(c.points[0]),
            exit_mm: arr(c.points[c.points.len() - 1]),
            inner_radius_mm: c.inner_radius,
            outer_radius_mm: c.outer_radius(),
            wall_hu: c.hu,
            anus_mm: c.canal.map(|k| {
                let (a, b) = (c.points[c.points.len() - 2], c.points[c.points.len() - 1]);
                arr(b + (a - b) * ((k.floor - b.z) / (a.z - b.z)))
            }),
            balloon: c.balloon.map(|b| BalloonTruth {
                center_mm: arr(b.center),
                radius_mm: b.radius,
                half_length_mm: b.half_length,
                wall_mm: b.wall_mm,
            }),
        }),
        body_floor_z_mm: floor,
        table: body.table.as_ref().map(|t| skin::table_truth(t, &body)),
        skin_folds: skin_folds.into_iter().map(|(_, t)| t).collect(),
        diverticula: diverticula.into_iter().map(|(_, t)| t).collect(),
        noise_roi,
        materials_hu: materials(opts),
        labels: label::legend(),
    };
    Ok(Phantom {
        ct: r.ct,
        lumen: r.lumen,
        labels: r.labels,
        truth,
    })
}

fn materials(opts: &ColonOptions) -> Vec<(String, f64)> {
    let mut m: Vec<(String, f64)> = [
        ("air", body::AIR),
        ("fat", body::FAT),
        ("colon_wall", body::SOFT_TISSUE),
        ("polyp", body::SOFT_TISSUE),
        ("muscle_skin", body::MUSCLE),
        ("cancellous_bone", body::CANCELLOUS),
        ("cortical_bone", body::CORTEX),
        ("disc", body::DISC),
        ("lung", body::LUNG),
    ]
    .into_iter()
    .map(|(n, v)| (n.to_string(), v))
    .collect();
    if opts.rectal_tube {
        m.push(("catheter_plastic".into(), CATHETER_HU));
    }
    if opts.table {
        m.push(("table_shell".into(), body::TABLE_SHELL));
        m.push(("table_foam".into(), body::TABLE_FOAM));
    }
    m
}

/// A 12-voxel box of pure fat (far from colon, pockets, loops, catheter, spine, lungs, skin
/// folds and the rim) for
/// measuring the noise, found by a fixed scan.
fn fat_roi(
    frame: &Frame,
    tube: &Tube,
    blobs: &[Blob],
    body: &Body,
    catheter: Option<&Catheter>,
) -> Option<RoiTruth> {
    let g = &frame.geom;
    let half_vox = 6usize;
    let half = DVec3::from_array(g.spacing) * half_vox as f64;
    let margin = half.length() + 3.0 * frame.max_spacing();
    let ax = &tube.axis;
    let step = 16usize;
    for k in (half_vox..g.dims[2] - half_vox).step_by(step) {
        for j in (half_vox..g.dims[1] - half_vox).step_by(step) {
            for i in (half_vox..g.dims[0] - half_vox).step_by(step) {
                let c = g.index_to_local(DVec3::new(i as f64, j as f64, k as f64));
                let ok = body.skin_sdf(c) + margin <= -body.rim
                    && body.spine.sdf_xy(c) >= margin
                    && body.lungs.iter().all(|l| l.sdf(c) >= margin)
                    && ax
                        .points
                        .iter()
                        .zip(&ax.radius)
                        .all(|(p, r)| p.distance(c) - r - tube.wall_mm >= margin)
                    && blobs
                        .iter()
                        .all(|b| b.center.distance(c) - b.reach() >= margin)
                    && catheter.is_none_or(|t| t.distance(c) - t.outer_radius() >= margin)
                    && body
                        .folds
                        .iter()
                        .all(|f| f.plane_distance(c) - f.half_width - f.lining >= margin);
                if ok {
                    return Some(RoiTruth {
                        min_ijk: [i - half_vox, j - half_vox, k - half_vox],
                        max_ijk: [i + half_vox, j + half_vox, k + half_vox],
                        expected_hu: body::FAT,
                    });
                }
            }
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::raster::Background;

    /// The body with a table and skin folds as [`colon`] makes it (folds clear of the colon
    /// and, with `catheter`, of a rectal catheter leaving through a perineum).
    fn body_on_table(small: bool, prone: bool, catheter: bool) -> Body {
        let frame = Frame::new(small).expect("frame");
        let gravity = if prone { DVec3::NEG_Y } else { DVec3::Y };
        let floor = catheter.then(|| frame.pos([0.0, 0.0, FLOOR_Z]).z);
        let mut body = make_body(&frame, true, floor);
        body.table = Some(skin::make_table(&frame, &body, gravity));
        let tube = Tube::new(
            make_axis(&frame, false).expect("axis"),
            frame.thin(WALL, 1.0),
            Ends::Round,
        );
        let cath =
            floor.map(|f| make_catheter(&frame, &tube, &[], f, false, false).expect("catheter"));
        let near = Obstacles {
            tube: &tube,
            blobs: &[],
            catheter: cath.as_ref(),
        };
        body.folds = skin::make_folds(&frame, &body, gravity, &near, 1)
            .into_iter()
            .map(|(f, _)| f)
            .collect();
        body
    }

    /// The rows' shortcuts (plain air, table, fat) give exactly what [`Background::sample`]
    /// gives, next to the table, the contact strip, the wedge and every skin fold.
    #[test]
    fn rows_with_the_table_and_folds_are_what_sample_gives() {
        for (small, prone, catheter) in [
            (true, true, true),
            (true, false, false),
            (false, true, true),
            (false, false, false),
        ] {
            let frame = Frame::new(small).expect("frame");
            let body = body_on_table(small, prone, catheter);
            assert!(body.folds.len() >= 4, "{} folds", body.folds.len());
            let g = &frame.geom;
            let [nx, ny, nz] = g.dims;
            let [sx, sy, sz] = g.spacing;
            // Every slice of the small phantom; at full size the first ones (perineum, the
            // gluteal folds) and those through each fold's middle.
            let slices: Vec<usize> = if small {
                (0..nz).collect()
            } else {
                (0..8)
                    .chain(body.folds.iter().map(|f| {
                        let mid = f.mouth + f.along * 0.5 * (f.span.0 + f.span.1);
                        ((mid.z / sz).round().max(0.0) as usize).min(nz - 1)
                    }))
                    .collect()
            };
            let (mut hu, mut lab) = (vec![0.0; nx], vec![0u8; nx]);
            for k in slices {
                let z = k as f64 * sz;
                for j in 0..ny {
                    let y = j as f64 * sy;
                    body.fill_row(y, z, sx, &mut hu, &mut lab);
                    for i in 0..nx {
                        let want = body.sample(DVec3::new(i as f64 * sx, y, z));
                        assert!(
                            (hu[i], lab[i]) == want,
                            "small {small} prone {prone}: voxel ({i}, {j}, {k}) row {:?}, sample {want:?}",
                            (hu[i], lab[i])
                        );
                    }
                }
            }
        }
    }
}
