//! 3D Slicer markups JSON (`.mrk.json`, schema v1.0.3): curves (the centerline), point
//! lists (findings' markers) and lines (findings' measurements), in LPS.

use std::path::Path;

use serde_json::{Value, json};

use voyage_core::Result;
use voyage_io::write_atomic;

pub const MARKUPS_SCHEMA: &str = "https://raw.githubusercontent.com/slicer/slicer/master/Modules/Loadable/Markups/Resources/Schema/markups-schema-v1.0.3.json#";

/// One control point: a label, an LPS position (mm), and a description.
#[derive(Clone, Debug)]
pub struct MarkupsPoint {
    pub label: String,
    pub position_lps: [f64; 3],
    pub description: String,
}

/// The JSON of one markups node of the given type ("Curve", "Fiducial", ...).
pub fn markups_node(kind: &str, name: &str, points: &[MarkupsPoint], color: [f64; 3]) -> Value {
    let control_points: Vec<Value> = points
        .iter()
        .enumerate()
        .map(|(i, p)| {
            json!({
                "id": (i + 1).to_string(),
                "label": p.label,
                "description": p.description,
                "associatedNodeID": "",
                "position": p.position_lps,
                "orientation": [-1.0, -0.0, -0.0, -0.0, -1.0, -0.0, 0.0, 0.0, 1.0],
                "selected": true,
                "locked": true,
                "visibility": true,
                "positionStatus": "defined"
            })
        })
        .collect();
    json!({
        "type": kind,
        "name": name,
        "coordinateSystem": "LPS",
        "coordinateUnits": "mm",
        "locked": true,
        "fixedNumberOfControlPoints": false,
        "labelFormat": "%N-%d",
        "lastUsedControlPointNumber": points.len(),
        "controlPoints": control_points,
        "measurements": [],
        "display": {
            "visibility": true,
            "opacity": 1.0,
            "color": color,
            "selectedColor": color,
            "propertiesLabelVisibility": false,
            "pointLabelsVisibility": false,
            "textScale": 3.0,
            "glyphType": "Sphere3D",
            "glyphScale": 1.0,
            "glyphSize": 2.0,
            "useGlyphScale": true,
            "lineThickness": 0.2
        }
    })
}

/// A line between two points (a measurement), carrying its length as Slicer's "length"
/// measurement so that Slicer shows the number without recomputing it.
pub fn markups_line_node(name: &str, a: MarkupsPoint, b: MarkupsPoint, color: [f64; 3]) -> Value {
    let length = (glam::DVec3::from_array(a.position_lps)
        - glam::DVec3::from_array(b.position_lps))
    .length();
    let mut node = markups_node("Line", name, &[a, b], color);
    node["fixedNumberOfControlPoints"] = json!(true);
    node["measurements"] = json!([{
        "name": "length",
        "enabled": true,
        "value": length,
        "units": "mm",
        "printFormat": "%-#4.4g%s"
    }]);
    node
}

/// Writes a markups file holding one node.
pub fn write_markups(path: &Path, node: Value) -> Result<()> {
    write_markups_nodes(path, vec![node])
}

/// Writes a markups file holding several nodes (Slicer loads each as its own markups node).
pub fn write_markups_nodes(path: &Path, nodes: Vec<Value>) -> Result<()> {
    let doc = json!({ "@schema": MARKUPS_SCHEMA, "markups": nodes });
    let text = serde_json::to_string_pretty(&doc).expect("markups JSON is plain data") + "\n";
    write_atomic(path, |w| w.write_all(text.as_bytes()))
}

/// A curve through the points (the centerline: green, as in the paper).
pub fn write_markups_curve(path: &Path, name: &str, points: &[MarkupsPoint]) -> Result<()> {
    write_markups(path, markups_node("Curve", name, points, [0.0, 0.9, 0.2]))
}
