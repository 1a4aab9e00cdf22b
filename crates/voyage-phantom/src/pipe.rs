//! The paper's pipe phantom (§5): "we looped a plastic respirator pipe of 20mm radius
//! inside a water tank ... three small rubber objects of sizes 7mm, 5mm, and 3mm attached
//! to the inner surface of the pipe ... a volume of 512×512×107".
//!
//! Our version: 512×512×107 voxels of 0.7×0.7×1.0 mm (358×358×107 mm). A cylindrical
//! acrylic tank (inner radius 170 mm, 4 mm wall, 4 mm bottom plate) holds water up to
//! z = 100 mm; air lies around, below and above it and touches the volume border. The pipe
//! (inner radius 20 mm, 2.5 mm plastic wall, air inside, both ends capped by flat plastic
//! discs) is coiled as a flat spiral of 1.5 turns whose radius grows 60 mm per turn from
//! 45 mm (so neighbouring turns leave 15 mm of water between their walls), bobbing ±10 mm
//! in z. Three rubber spheres of 7, 5 and 3 mm sit on the inner wall near the middle of
//! the pipe, 40 mm apart, protruding 75 % of their diameter into the lumen (close together,
//! as in the paper's Fig. 10a, where one view shows all three).
//!
//! Truth: the centerline is the pipe's axis, from 1 mm inside one cap to 1 mm inside the
//! other (≈ 850 mm); source and target lie on it 15 mm from its ends.

use glam::DVec3;

use super::{
    Phantom, arr,
    axis::{Axis, Knot},
    label, label_counts,
    polyp::{PolypSpec, place},
    raster::{Background, Materials, Scene},
    rng::{Rng, stream_key},
    truth::{COORDINATES_NOTE, RoiTruth, SegmentTruth, Truth},
    tube::{Ends, Tube},
};
use voyage_core::{Error, Geometry, Result};

pub const DIMS: [usize; 3] = [512, 512, 107];
pub const SPACING: [f64; 3] = [0.7, 0.7, 1.0];
pub const PIPE_RADIUS: f64 = 20.0;
pub const PIPE_WALL: f64 = 2.5;
pub const POLYP_DIAMETERS: [f64; 3] = [7.0, 5.0, 3.0];
/// Source and target lie this far inside the caps (≥ radius / 2).
pub const END_INSET: f64 = 15.0;
pub const NOISE_HU: f64 = 20.0;
/// The caps' inner faces lie this far beyond the centerline's end points.
pub const CAP_MARGIN: f64 = 1.0;

const AIR: f64 = -1000.0;
const WATER: f64 = 0.0;
const PLASTIC: f64 = 150.0;
const ACRYLIC: f64 = 120.0;
const RUBBER: f64 = 80.0;

const TANK_INNER: f64 = 170.0;
const TANK_WALL: f64 = 4.0;
const TANK_FLOOR: (f64, f64) = (1.5, 5.5);
const WATER_LEVEL: f64 = 100.0;
const SPIRAL_START: f64 = 45.0;
const SPIRAL_PITCH: f64 = 60.0;
const SPIRAL_TURNS: f64 = 1.5;
const PIPE_Z: f64 = 53.0;
const PIPE_BOB: f64 = 10.0;

/// Noise and polyp angles come from streams of the seed.
const STREAM_NOISE: u64 = 0x9199_0001;
const STREAM_POLYPS: u64 = 0x9199_0002;

/// The tank: water in an acrylic cylinder, air elsewhere.
struct Tank {
    center: DVec3,
    inv_w: f64,
}

impl Background for Tank {
    fn sample(&self, p: DVec3) -> (f64, u8) {
        let rho = ((p.x - self.center.x).powi(2) + (p.y - self.center.y).powi(2)).sqrt();
        let cylinder = (rho - TANK_INNER - TANK_WALL).max(TANK_FLOOR.0 - p.z);
        let cavity = (rho - TANK_INNER).max(TANK_FLOOR.1 - p.z);
        let shell = cylinder.max(-cavity);
        let water = cavity.max(p.z - WATER_LEVEL);
        let hu = AIR
            + ramp(shell, self.inv_w) * (ACRYLIC - AIR)
            + ramp(water, self.inv_w) * (WATER - AIR);
        let lab = if shell < 0.0 || water < 0.0 {
            label::OTHER
        } else {
            label::OUTSIDE_AIR
        };
        (hu, lab)
    }
}

fn ramp(sdf: f64, inv_w: f64) -> f64 {
    let x = (0.5 - sdf * inv_w).clamp(0.0, 1.0);
    x * x * (3.0 - 2.0 * x)
}

/// Knots of the coiled pipe: a spiral every 30°.
fn spiral_knots(center: DVec3) -> Vec<Knot> {
    let steps = (SPIRAL_TURNS * 12.0).round() as usize;
    (0..=steps)
        .map(|n| {
            let phi = n as f64 * std::f64::consts::TAU / 12.0;
            let r = SPIRAL_START + SPIRAL_PITCH * phi / std::f64::consts::TAU;
            let z = PIPE_Z + PIPE_BOB * (phi / SPIRAL_TURNS / 2.0).sin();
            Knot {
                pos: DVec3::new(center.x + r * phi.cos(), center.y + r * phi.sin(), z),
                radius: PIPE_RADIUS,
            }
        })
        .collect()
}

/// Makes the pipe phantom.
pub fn pipe(seed: u64) -> Result<Phantom> {
    let geom = Geometry::new(DIMS, SPACING, [0.0; 3])?;
    let ext = geom.extent_mm() - geom.spacing_vec();
    let center = DVec3::new(ext.x / 2.0, ext.y / 2.0, 0.0);
    let axis = Axis::through(&spiral_knots(center), 1.0)?;
    check_pipe_axis(&axis)?;
    let mut tube = Tube::new(axis, PIPE_WALL, Ends::Flat);
    tube.end_margin = CAP_MARGIN;
    let mut rng = Rng::new(seed, STREAM_POLYPS);
    let mid = tube.axis.length / 2.0;
    let (blobs, polyps): (Vec<_>, Vec<_>) = POLYP_DIAMETERS
        .iter()
        .enumerate()
        .map(|(n, &d)| {
            let spec = PolypSpec {
                arc: mid + (n as f64 - 1.0) * 40.0,
                angle: rng.range(0.0, std::f64::consts::TAU),
                diameter: d,
                stalk: None,
                segment: "pipe".into(),
                behind_fold: false,
            };
            place(&tube, &spec)
        })
        .unzip();
    let inv_w = 3.0 / SPACING.iter().sum::<f64>();
    let tank = Tank { center, inv_w };
    let scene = Scene {
        geom: geom.clone(),
        tube: &tube,
        blobs: &blobs,
        catheter: None,
        materials: Materials {
            lumen_air: AIR,
            wall: PLASTIC,
            polyp: RUBBER,
            pocket_air: AIR,
        },
        background: &tank,
        noise_sigma: NOISE_HU,
        noise_key: stream_key(seed, STREAM_NOISE),
        quantize: None,
    };
    let r = scene.render()?;
    let counts = label_counts(&r.labels);
    let ax = &tube.axis;
    let (source_arc, target_arc) = (END_INSET, ax.length - END_INSET);
    let truth = Truth {
        kind: "pipe".into(),
        seed,
        coordinates: COORDINATES_NOTE.into(),
        position: "HFS".into(),
        gravity_lps: [0.0, 1.0, 0.0],
        dims: DIMS,
        spacing_mm: SPACING,
        origin_lps_mm: geom.origin,
        direction: geom.direction,
        scale: 1.0,
        noise_hu: NOISE_HU,
        quantize_hu: None,
        centerline_mm: ax.points.iter().map(|p| arr(*p)).collect(),
        centerline_arc_mm: ax.arc.clone(),
        centerline_radius_mm: ax.radius.clone(),
        centerline_length_mm: ax.length,
        source_mm: arr(ax.point_at(source_arc)),
        target_mm: arr(ax.point_at(target_arc)),
        source_arc_mm: source_arc,
        target_arc_mm: target_arc,
        wall_thickness_mm: PIPE_WALL,
        min_part_gap_mm: ax.min_part_gap(PIPE_WALL, 2).0,
        polyps,
        lumen_voxels: counts[label::LUMEN_AIR as usize] + counts[label::LUMEN_FLUID as usize],
        folds: 0,
        fold_list: Vec::new(),
        segments: vec![SegmentTruth {
            name: "pipe".into(),
            start_arc_mm: 0.0,
            end_arc_mm: ax.length,
        }],
        fluid_pools: Vec::new(),
        fluid_voxels: 0,
        collapsed: Vec::new(),
        fluid_filled: Vec::new(),
        gas_gaps: Vec::new(),
        distractors: Vec::new(),
        small_bowel_loops: Vec::new(),
        ileocecal_valve_mm: None,
        stool: Vec::new(),
        rectal_tube: None,
        body_floor_z_mm: None,
        table: None,
        skin_folds: Vec::new(),
        diverticula: Vec::new(),
        noise_roi: Some(water_roi(&geom, center)),
        materials_hu: [
            ("air", AIR),
            ("water", WATER),
            ("pipe_plastic", PLASTIC),
            ("tank_acrylic", ACRYLIC),
            ("rubber_polyp", RUBBER),
        ]
        .into_iter()
        .map(|(n, v)| (n.to_string(), v))
        .collect(),
        labels: label::legend(),
    };
    Ok(Phantom {
        ct: r.ct,
        lumen: r.lumen,
        labels: r.labels,
        truth,
    })
}

/// The coil must not touch itself: ≥ 10 mm of water between the walls of different turns,
/// and bends gentle enough for the tube (curvature radius > outer radius).
fn check_pipe_axis(axis: &Axis) -> Result<()> {
    let (gap, _, _) = axis.min_part_gap(PIPE_WALL, 2);
    if gap < 2.0 * PIPE_WALL + 10.0 {
        return Err(Error::invalid(format!(
            "pipe phantom: turns only {gap:.1} mm apart"
        )));
    }
    let (bend, _) = axis.min_bend_ratio(PIPE_WALL);
    if bend < 1.2 {
        return Err(Error::invalid(format!(
            "pipe phantom: bend too tight (ratio {bend:.2})"
        )));
    }
    Ok(())
}

/// A box of water between the pipe and the tank wall, for measuring noise: towards −y
/// (spiral angle 3π/2) only the first turn passes, at radius 90 mm.
fn water_roi(geom: &Geometry, center: DVec3) -> RoiTruth {
    let c = DVec3::new(center.x, center.y - 135.0, PIPE_Z);
    let half = DVec3::splat(6.0);
    let lo = geom.local_to_index(c - half).round();
    let hi = geom.local_to_index(c + half).round();
    RoiTruth {
        min_ijk: [lo.x as usize, lo.y as usize, lo.z as usize],
        max_ijk: [hi.x as usize, hi.y as usize, hi.z as usize],
        expected_hu: WATER,
    }
}
