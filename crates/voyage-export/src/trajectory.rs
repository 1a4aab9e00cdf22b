//! Flight trajectories: one pose per frame, for movies, renders and other tools.

use std::path::Path;

use serde_json::json;

use voyage_core::{Geometry, Result};
use voyage_io::write_atomic;
use voyage_nav::Flight;

/// Writes `flights` as JSON: per flight its summary and its poses `[x, y, z, qw, qx, qy, qz]`
/// in volume-local mm (q turns the body frame into the volume's: z_body is the view
/// direction, y_body the up vector), and the camera positions in patient LPS mm.
pub fn write_trajectory(
    path: &Path,
    flights: &[Flight],
    geometry: &Geometry,
    fps: f64,
) -> Result<()> {
    let flights: Vec<_> = flights
        .iter()
        .map(|f| {
            json!({
                "summary": f,
                "poses": f.poses.iter().map(|p| p.to_array()).collect::<Vec<_>>(),
                "positions_lps_mm": f.poses.iter().map(|p| geometry.local_to_patient(p.position).to_array()).collect::<Vec<_>>(),
            })
        })
        .collect();
    let doc = json!({
        "frame": "poses: study-local mm (x = i·sx, y = j·sy, z = k·sz with the scan turned so that i, j, k run to the patient's left, back and head) and a unit quaternion [qw, qx, qy, qz] from the camera's body frame (z_body = view direction, y_body = up, x_body = y_body × z_body, the viewer's left) to the volume's axes; positions_lps_mm: DICOM patient LPS",
        "fps": fps,
        "volume": {
            "dims": geometry.dims,
            "spacing_mm": geometry.spacing,
            "origin_lps_mm": geometry.origin,
            "direction": geometry.direction_mat().to_cols_array(),
        },
        "flights": flights,
    });
    let text = serde_json::to_string(&doc)
        .map_err(|e| voyage_core::Error::invalid(format!("trajectory: {e}")))?
        + "\n";
    write_atomic(path, |w| w.write_all(text.as_bytes()))
}

/// Reads the poses of every flight of a trajectory file written by [`write_trajectory`].
pub fn read_poses(path: &Path) -> Result<Vec<Vec<voyage_nav::Pose>>> {
    let text = std::fs::read_to_string(path).map_err(|e| voyage_core::Error::io(path, e))?;
    let bad =
        |what: &str| voyage_core::Error::format(path, format!("not a voyage trajectory: {what}"));
    let doc: serde_json::Value = serde_json::from_str(&text).map_err(|e| bad(&e.to_string()))?;
    let flights = doc
        .get("flights")
        .and_then(|f| f.as_array())
        .ok_or_else(|| bad("no \"flights\" list"))?;
    flights
        .iter()
        .map(|f| {
            let poses = f
                .get("poses")
                .and_then(|p| p.as_array())
                .ok_or_else(|| bad("a flight without \"poses\""))?;
            poses
                .iter()
                .map(|p| {
                    let a: Vec<f64> = p
                        .as_array()
                        .map(|a| a.iter().filter_map(|v| v.as_f64()).collect())
                        .unwrap_or_default();
                    let arr: [f64; 7] = a
                        .try_into()
                        .map_err(|_| bad("a pose is not seven numbers"))?;
                    voyage_nav::Pose::from_array(arr)
                        .ok_or_else(|| bad("a pose with a zero or non-finite quaternion"))
                })
                .collect()
        })
        .collect()
}
