//! The stack geometry: slices sorted along the slice normal (never by file name or
//! InstanceNumber), the gaps checked, exact copies dropped, and a tilted gantry's slices
//! shifted onto an orthogonal grid.

use glam::DVec3;
use rayon::prelude::*;

use super::header::{Header, Plane, file_name};
use voyage_core::{Error, Geometry, Result, check_dims};
// ---------------------------------------------------------------------------------------------
// Stack geometry
// ---------------------------------------------------------------------------------------------

/// Value given to voxels of a tilt-corrected grid that no acquired slice covers (air).
pub const OUTSIDE_HU: i16 = -1024;

/// Relative and absolute tolerance on slice gaps: a gap may differ from the typical one by at
/// most `max(GAP_TOL_MM, GAP_TOL_REL × gap)`. Real series round their positions to 0.1 mm
/// (a 0.625 mm series then steps 0.6 and 0.7 mm); dcm2niix and ITK accept as much, and the
/// slices are placed at the mean gap, nothing resampled.
pub(super) const GAP_TOL_MM: f64 = 0.1 + 1e-6;
pub(super) const GAP_TOL_REL: f64 = 0.1;
/// Tolerance on direction cosines and pixel spacing agreeing between slices.
pub(super) const COSINE_TOL: f64 = 1e-4;

/// One slice of the stack: a frame of a file.
#[derive(Clone, Debug)]
pub(super) struct SliceRef {
    pub(super) file: usize,
    pub(super) frame: usize,
    pub(super) plane: Plane,
}

/// The slices in order along k, the grid they lie on, and what was noticed.
pub(super) struct Stack {
    pub(super) slices: Vec<SliceRef>,
    pub(super) geometry: Geometry,
    /// In-plane shift (mm along i and j) of slice k+1 relative to slice k when the positions
    /// step off the normal (gantry tilt); `None` for an orthogonal stack.
    pub(super) shear: Option<[f64; 2]>,
    pub(super) notes: Vec<String>,
    /// What the user must see: slices left out.
    pub(super) warnings: Vec<String>,
}

pub(super) fn slice_label(headers: &[Header], s: &SliceRef) -> String {
    let h = &headers[s.file];
    if h.frames > 1 {
        format!("{} frame {}", file_name(&h.path), s.frame + 1)
    } else {
        file_name(&h.path)
    }
}

/// Checks that all slices agree on size, pixel layout, orientation and spacing, sorts them
/// along the normal and checks that the gaps are uniform.
pub(super) fn build_stack(headers: &[Header]) -> Result<Stack> {
    let first = &headers[0];
    for h in &headers[1..] {
        if (h.rows, h.cols) != (first.rows, first.cols) {
            return Err(Error::format(
                &h.path,
                format!(
                    "image size {}×{} differs from {} ({}×{}) in the same series",
                    h.cols,
                    h.rows,
                    file_name(&first.path),
                    first.cols,
                    first.rows
                ),
            ));
        }
    }
    let slices: Vec<SliceRef> = headers
        .iter()
        .enumerate()
        .flat_map(|(file, h)| {
            h.planes.iter().enumerate().map(move |(frame, p)| SliceRef {
                file,
                frame,
                plane: p.clone(),
            })
        })
        .collect();
    let path_of = |s: &SliceRef| headers[s.file].path.clone();
    let mut notes = Vec::new();

    let spacing = common_spacing(headers, &slices)?;
    let [row, col] = common_orientation(headers, &slices, &mut notes)?;
    let normal = row.cross(col);

    let unplaced_frames =
        headers.len() == 1 && slices[1..].iter().all(|s| s.plane.position.is_none());
    if slices.len() == 1 || unplaced_frames {
        return single_file_stack(&headers[0], slices, spacing, [row, col, normal], notes);
    }
    if let Some(s) = slices.iter().find(|s| s.plane.position.is_none()) {
        return Err(Error::format(
            path_of(s),
            format!(
                "{}: ImagePositionPatient is missing",
                slice_label(headers, s)
            ),
        ));
    }
    let mut slices = slices;
    let pos = |s: &SliceRef| s.plane.position.unwrap_or_default();
    slices.sort_by(|a, b| {
        pos(a)
            .dot(normal)
            .total_cmp(&pos(b).dot(normal))
            .then(a.file.cmp(&b.file))
            .then(a.frame.cmp(&b.frame))
    });
    let mut warnings = Vec::new();
    let slices = drop_copies(headers, slices, &mut warnings);

    let steps: Vec<DVec3> = slices.windows(2).map(|w| pos(&w[1]) - pos(&w[0])).collect();
    let gaps: Vec<f64> = steps.iter().map(|s| s.dot(normal)).collect();
    let tilt = tilt_note(headers, &steps, normal);
    check_gaps(headers, &slices, &gaps, tilt.as_deref())?;

    let n = slices.len();
    let total = pos(&slices[n - 1]) - pos(&slices[0]);
    let dz = total.dot(normal) / (n - 1) as f64;
    let drift = (total - normal * total.dot(normal)) / (n - 1) as f64;
    check_straight_line(headers, &slices, &steps, drift, normal, dz)?;
    let shear_mm = [drift.dot(row), drift.dot(col)];
    // Drift over the whole stack, in pixels. Below a quarter pixel it is rounding in the
    // positions (or a tilt too small to matter), and resampling would only blur.
    let drift_px =
        (shear_mm[0].abs() / spacing[0]).max(shear_mm[1].abs() / spacing[1]) * (n - 1) as f64;
    let negligible = drift_px <= 0.25;
    if negligible && drift_px > 0.01 {
        notes
            .push(format!("slice positions drift {drift_px:.2} pixel within the slice plane over the series: ignored"));
    }
    if negligible && let Some(t) = first.gantry_tilt_deg.filter(|t| t.abs() > 0.01) {
        notes.push(format!(
            "GantryDetectorTilt is {t}°, but the slice positions follow the slice normal: no correction needed"
        ));
    }

    let mut geometry = Geometry::new(
        [first.cols, first.rows, n],
        [spacing[0], spacing[1], dz],
        pos(&slices[0]).to_array(),
    )
    .map_err(crate::at(&first.path))?;
    geometry.set_direction_mat(glam::DMat3::from_cols(row, col, normal));
    Ok(Stack {
        slices,
        geometry,
        shear: (!negligible).then_some(shear_mm),
        notes,
        warnings,
    })
}

/// `slices` (sorted along the normal) without the byte-identical copies of a file at the same
/// position (a slice exported twice): each left out is warned about. Two different slices at
/// one position stay, for the gap check to refuse.
pub(super) fn drop_copies(
    headers: &[Header],
    slices: Vec<SliceRef>,
    warnings: &mut Vec<String>,
) -> Vec<SliceRef> {
    let pos = |s: &SliceRef| s.plane.position.unwrap_or_default();
    let same_bytes = |a: &SliceRef, b: &SliceRef| {
        let (pa, pb) = (&headers[a.file].path, &headers[b.file].path);
        matches!((std::fs::read(pa), std::fs::read(pb)), (Ok(x), Ok(y)) if x == y)
    };
    let mut kept: Vec<SliceRef> = Vec::with_capacity(slices.len());
    for s in slices {
        let copy = kept
            .iter()
            .rev()
            .take_while(|k| pos(k).distance(pos(&s)) < 1e-3)
            .find(|k| k.file != s.file && k.frame == s.frame && same_bytes(k, &s));
        if let Some(k) = copy {
            warnings.push(format!(
                "{} is a byte-identical copy of {}: left out",
                slice_label(headers, &s),
                slice_label(headers, k)
            ));
            continue;
        }
        kept.push(s);
    }
    kept
}

/// A single slice, or a multi-frame file whose frames carry no positions: frames are stacked
/// along the normal at SpacingBetweenSlices (else SliceThickness, else 1 mm).
pub(super) fn single_file_stack(
    header: &Header,
    slices: Vec<SliceRef>,
    spacing: [f64; 2],
    axes: [DVec3; 3],
    mut notes: Vec<String>,
) -> Result<Stack> {
    let dz = match header.slice_step {
        Some(s) => s,
        None => {
            notes.push(
                "no SpacingBetweenSlices or SliceThickness: slice spacing assumed to be 1 mm"
                    .into(),
            );
            1.0
        }
    };
    let origin = match slices[0].plane.position {
        Some(p) => p,
        None => {
            notes.push("no ImagePositionPatient: origin set to (0, 0, 0)".into());
            DVec3::ZERO
        }
    };
    if slices.len() > 1 {
        notes.push(format!(
            "frames carry no positions: stacked along the slice normal {dz} mm apart"
        ));
    }
    let mut geometry = Geometry::new(
        [header.cols, header.rows, slices.len()],
        [spacing[0], spacing[1], dz],
        origin.to_array(),
    )
    .map_err(crate::at(&header.path))?;
    geometry.set_direction_mat(glam::DMat3::from_cols(axes[0], axes[1], axes[2]));
    Ok(Stack {
        slices,
        geometry,
        shear: None,
        notes,
        warnings: Vec::new(),
    })
}

/// All slices must share PixelSpacing (the one CT attribute voyage will not guess).
pub(super) fn common_spacing(headers: &[Header], slices: &[SliceRef]) -> Result<[f64; 2]> {
    let first = &slices[0];
    let Some(spacing) = first.plane.spacing else {
        return Err(Error::format(
            &headers[first.file].path,
            "PixelSpacing (0028,0030) is missing: the voxel size is unknown, so distances and polyp sizes could not be measured",
        ));
    };
    for s in slices {
        let ok = s
            .plane
            .spacing
            .is_some_and(|p| (0..2).all(|a| (p[a] - spacing[a]).abs() <= COSINE_TOL * spacing[a]));
        if !ok {
            return Err(Error::format(
                &headers[s.file].path,
                format!(
                    "{}: PixelSpacing {:?} differs from {} ({:?}) in the same series",
                    slice_label(headers, s),
                    s.plane.spacing.map(|p| [p[1], p[0]]),
                    slice_label(headers, first),
                    [spacing[1], spacing[0]]
                ),
            ));
        }
    }
    Ok(spacing)
}

/// All slices must share one orientation; a lone slice without one is taken as axial.
pub(super) fn common_orientation(
    headers: &[Header],
    slices: &[SliceRef],
    notes: &mut Vec<String>,
) -> Result<[DVec3; 2]> {
    let first = &slices[0];
    let Some(orient) = first.plane.orientation else {
        if slices.len() == 1 {
            notes.push("no ImageOrientationPatient: axial orientation assumed".into());
            return Ok([DVec3::X, DVec3::Y]);
        }
        return Err(Error::format(
            &headers[first.file].path,
            format!(
                "{}: ImageOrientationPatient is missing",
                slice_label(headers, first)
            ),
        ));
    };
    for s in slices {
        let same = s.plane.orientation.is_some_and(|o| {
            (o[0] - orient[0]).abs().max_element() <= COSINE_TOL
                && (o[1] - orient[1]).abs().max_element() <= COSINE_TOL
        });
        if !same {
            return Err(Error::format(
                &headers[s.file].path,
                format!(
                    "{}: ImageOrientationPatient differs from {} in the same series (slices are not parallel)",
                    slice_label(headers, s),
                    slice_label(headers, first)
                ),
            ));
        }
    }
    Ok(orient)
}

/// "gantry tilt of 18.5°" when the positions step off the normal, for messages.
pub(super) fn tilt_note(headers: &[Header], steps: &[DVec3], normal: DVec3) -> Option<String> {
    let mean = steps.iter().copied().sum::<DVec3>() / steps.len().max(1) as f64;
    let along = mean.dot(normal);
    let off = (mean - normal * along).length();
    let angle = off.atan2(along.abs()).to_degrees();
    let recorded = headers[0].gantry_tilt_deg.filter(|t| t.abs() > 0.01);
    if angle > 0.05 {
        Some(format!("a gantry tilt of {angle:.1}°"))
    } else {
        recorded.map(|t| format!("a recorded gantry tilt of {t}°"))
    }
}

/// Every gap along the normal must equal the typical one: a duplicate position, a missing
/// slice or an uneven gap is an error naming the two slices around it.
pub(super) fn check_gaps(
    headers: &[Header],
    slices: &[SliceRef],
    gaps: &[f64],
    tilt: Option<&str>,
) -> Result<()> {
    let mut sorted = gaps.to_vec();
    sorted.sort_by(f64::total_cmp);
    let typical = sorted[sorted.len() / 2];
    let tol = GAP_TOL_MM.max(GAP_TOL_REL * typical);
    let z = |s: &SliceRef| s.plane.position.unwrap_or_default();
    let normal_z = |k: usize, n: DVec3| z(&slices[k]).dot(n);
    let orient = slices[0].plane.orientation.unwrap_or([DVec3::X, DVec3::Y]);
    let normal = orient[0].cross(orient[1]);
    let bad: Vec<usize> = (0..gaps.len())
        .filter(|&k| (gaps[k] - typical).abs() > tol || gaps[k] <= tol)
        .collect();
    // Report a duplicate first (the most specific problem), else the worst gap.
    let duplicate = bad.iter().copied().find(|&k| gaps[k] <= tol);
    let worst = bad.iter().copied().max_by(|&a, &b| {
        (gaps[a] - typical)
            .abs()
            .total_cmp(&(gaps[b] - typical).abs())
    });
    let Some(k) = duplicate.or(worst) else {
        return Ok(());
    };
    let (a, b) = (
        slice_label(headers, &slices[k]),
        slice_label(headers, &slices[k + 1]),
    );
    let (za, zb) = (normal_z(k, normal), normal_z(k + 1, normal));
    let gap = gaps[k];
    let mut msg = if gap <= tol {
        format!("two slices at the same position ({za:.2} mm along the slice normal): {a} and {b}")
    } else if typical > tol
        && (gap / typical).round() >= 2.0
        && (gap - (gap / typical).round() * typical).abs() <= tol * 2.0
    {
        let missing = (gap / typical).round() as usize - 1;
        format!(
            "{missing} slice(s) missing: gap of {gap:.2} mm between {a} ({za:.2} mm along the slice normal) and {b} ({zb:.2} mm), where the other slices are {typical:.2} mm apart"
        )
    } else {
        format!(
            "uneven slice gaps: {gap:.2} mm between {a} ({za:.2} mm along the slice normal) and {b} ({zb:.2} mm), but {typical:.2} mm between most slices"
        )
    };
    if bad.len() > 1 {
        msg.push_str(&format!(" ({} irregular gaps in all)", bad.len()));
    }
    if let Some(t) = tilt {
        msg.push_str(&format!("; the series also has {t}"));
    }
    msg.push_str("; a volume needs evenly spaced slices");
    Err(Error::format(&headers[slices[k + 1].file].path, msg))
}

/// With uniform gaps, the in-plane part of each step must be the same too (a constant tilt);
/// anything else means the slices do not lie on one straight line.
pub(super) fn check_straight_line(
    headers: &[Header],
    slices: &[SliceRef],
    steps: &[DVec3],
    drift: DVec3,
    normal: DVec3,
    dz: f64,
) -> Result<()> {
    let tol = GAP_TOL_MM.max(GAP_TOL_REL * dz);
    for (k, s) in steps.iter().enumerate() {
        let off = *s - normal * s.dot(normal);
        if (off - drift).length() > tol {
            return Err(Error::format(
                &headers[slices[k + 1].file].path,
                format!(
                    "slice positions do not lie on a straight line: {} is offset by {:.2} mm within its plane from where {} predicts",
                    slice_label(headers, &slices[k + 1]),
                    (off - drift).length(),
                    slice_label(headers, &slices[k])
                ),
            ));
        }
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// Gantry tilt correction
// ---------------------------------------------------------------------------------------------

/// Undoes a constant in-plane drift of the slices (gantry tilt): slice k is shifted by
/// `-k·shear` within its plane, with linear interpolation, onto a grid widened so that every
/// acquired voxel is kept. The result is orthogonal, with k along the slice normal.
pub(super) fn correct_tilt(
    g: &Geometry,
    data: &[i16],
    shear: [f64; 2],
) -> Result<(Geometry, Vec<i16>, String)> {
    let [nx, ny, nz] = g.dims;
    let last = (nz - 1) as f64;
    // Extent of the drift over the stack, in voxels along i and j.
    let lo = [
        0.0f64.min(shear[0] * last / g.spacing[0]),
        0.0f64.min(shear[1] * last / g.spacing[1]),
    ];
    let hi = [
        0.0f64.max(shear[0] * last / g.spacing[0]),
        0.0f64.max(shear[1] * last / g.spacing[1]),
    ];
    let grow = [
        (hi[0] - lo[0] - 1e-6).ceil().max(0.0) as usize,
        (hi[1] - lo[1] - 1e-6).ceil().max(0.0) as usize,
    ];
    let dims = [nx + grow[0], ny + grow[1], nz];
    check_dims(dims.map(|d| d as u64))?;
    let mut out_geom = g.clone();
    out_geom.dims = dims;
    let m = g.direction_mat();
    let origin = DVec3::from_array(g.origin)
        + m.col(0) * (lo[0] * g.spacing[0])
        + m.col(1) * (lo[1] * g.spacing[1]);
    out_geom.origin = origin.to_array();
    let out_plane = dims[0] * dims[1];
    let mut out = vec![OUTSIDE_HU; out_plane * nz];
    out.par_chunks_mut(out_plane)
        .enumerate()
        .for_each(|(k, dst)| {
            // Output voxel (i', j') of slice k samples input (i' + off_i, j' + off_j).
            let off = [
                lo[0] - k as f64 * shear[0] / g.spacing[0],
                lo[1] - k as f64 * shear[1] / g.spacing[1],
            ];
            let src = &data[k * nx * ny..(k + 1) * nx * ny];
            shift_slice(src, [nx, ny], dst, [dims[0], dims[1]], off);
        });
    let along = g.spacing[2];
    let drift = (shear[0] * shear[0] + shear[1] * shear[1]).sqrt();
    let note = format!(
        "gantry tilt of {:.1}° corrected: slices shifted within their planes by up to {:.1} mm (linear interpolation); grid widened to {}×{}, uncovered voxels set to {OUTSIDE_HU} HU",
        drift.atan2(along).to_degrees(),
        drift * last,
        dims[0],
        dims[1]
    );
    Ok((out_geom, out, note))
}

/// Bilinear resampling of one slice by a constant offset (the weights are the same for every
/// voxel); samples outside the source keep the destination's fill value.
pub(super) fn shift_slice(
    src: &[i16],
    [sx, sy]: [usize; 2],
    dst: &mut [i16],
    [dx, dy]: [usize; 2],
    off: [f64; 2],
) {
    let (fi, fj) = (off[0].floor(), off[1].floor());
    let (wi, wj) = (off[0] - fi, off[1] - fj);
    let (fi, fj) = (fi as isize, fj as isize);
    let at = |i: isize, j: isize| -> Option<f64> {
        (i >= 0 && j >= 0 && (i as usize) < sx && (j as usize) < sy)
            .then(|| f64::from(src[i as usize + sx * j as usize]))
    };
    for j in 0..dy {
        let j0 = j as isize + fj;
        for i in 0..dx {
            let i0 = i as isize + fi;
            let corners = [
                (at(i0, j0), (1.0 - wi) * (1.0 - wj)),
                (at(i0 + 1, j0), wi * (1.0 - wj)),
                (at(i0, j0 + 1), (1.0 - wi) * wj),
                (at(i0 + 1, j0 + 1), wi * wj),
            ];
            let (mut sum, mut weight) = (0.0, 0.0);
            for (v, w) in corners {
                if let Some(v) = v
                    && w > 0.0
                {
                    sum += v * w;
                    weight += w;
                }
            }
            // Keep the fill value unless the sample is mostly inside the acquired slice.
            if weight >= 0.5 {
                dst[i + dx * j] = (sum / weight).round() as i16;
            }
        }
    }
}
