//! The reading's report as one self-contained HTML file (`report.html`): the findings with
//! their kind, size, segment and distance from the rectum end, each with its snapshot
//! embedded; the measurements; the exam's C-RADS category; the coverage of the mucosa. It
//! opens in any browser without other files. It names the study by its file name only and
//! carries no patient identity.

use std::path::Path;

use voyage_core::Result;
use voyage_view::{CRads, SegmentSeen};

use voyage_io::write_atomic;

/// One finding as the report lists it.
#[derive(Clone, Debug)]
pub struct ReportFinding {
    pub label: String,
    /// "polyp", "mass", "diverticulum" or "other".
    pub kind: String,
    pub size_mm: Option<f64>,
    pub segment: String,
    /// Along the centerline from its rectum end (about the anal verge), mm.
    pub from_rectum_mm: Option<f64>,
    pub position_lps_mm: [f64; 3],
    pub note: String,
    /// The view from the marker's pose, as PNG bytes.
    pub snapshot_png: Vec<u8>,
}

/// What the reading's coverage came to (%); None where it was not measured.
#[derive(Clone, Debug, Default)]
pub struct ReportCoverage {
    pub session_pct: Option<f64>,
    pub one_way_pct: Option<f64>,
    pub two_way_pct: Option<f64>,
    pub after_review_pct: Option<f64>,
    /// Unseen patches left (≥ the listing threshold).
    pub patches_left: Option<usize>,
    /// The mucosa seen per segment by the figure [`ReportCoverage::read_pct`] gives (empty:
    /// not measured).
    pub by_segment: Vec<SegmentSeen>,
}

impl ReportCoverage {
    /// The share of the mucosa the reading showed in the end (%): after its review, else over
    /// the whole session, else both flights.
    pub fn read_pct(&self) -> Option<f64> {
        self.after_review_pct
            .or(self.session_pct)
            .or(self.two_way_pct)
    }
}

/// What the report says of the exam besides the colon: the file, the series and the date
/// when the file has them, and the corrections made by hand. Never the patient's identity
/// (nor the series' free-text description, which can hold it).
#[derive(Clone, Debug, Default)]
pub struct Exam {
    /// The study's file or folder name.
    pub name: String,
    /// The series read, e.g. "CT series 2, 412 slices (DICOM)".
    pub series: Option<String>,
    /// YYYY-MM-DD.
    pub date: Option<String>,
    /// The corrections made by hand before this reading, in the order given.
    pub by_hand: Vec<HandCorrection>,
}

/// One correction made by hand to the colon found: a start, an end, gas taken in or left out.
#[derive(Clone, Debug, PartialEq)]
pub struct HandCorrection {
    /// e.g. "gas taken in as colon".
    pub what: &'static str,
    pub lps_mm: [f64; 3],
}

#[derive(Clone, Debug)]
pub struct Report {
    pub exam: Exam,
    pub findings: Vec<ReportFinding>,
    /// (label, length mm).
    pub measurements: Vec<(String, f64)>,
    pub c_rads: CRads,
    pub coverage: ReportCoverage,
    pub colon: ColonRead,
}

/// What of the exam was read: the colon found and the gas left out of it, the patient's
/// position, and per segment its bridged stretches.
#[derive(Clone, Debug, Default)]
pub struct ColonRead {
    /// Gas in the colon found (ml), and its centerline's length (mm).
    pub found_ml: f64,
    pub centerline_mm: f64,
    /// Gas regions of [`voyage_core::LEFT_OUT_DOUBT_ML`] or more left out (ml), largest first.
    pub left_out_ml: Vec<f64>,
    /// The patient's position and where it was read from.
    pub position: Option<String>,
    /// Collapsed or fluid-filled stretches bridged, per segment: (segment, mm).
    pub bridged_mm: Vec<(String, f64)>,
    /// Where the colon leaves the scanned volume (one entry per place): the segment.
    pub leaves_the_scan: Vec<String>,
    /// The corrections made by hand, each with the segment it lies in.
    pub by_hand: Vec<(String, HandCorrection)>,
}

impl ColonRead {
    /// The colon of `study` as prep found it, after the corrections `by_hand`.
    pub fn of(study: &voyage_core::Study, by_hand: &[HandCorrection]) -> ColonRead {
        let seg = &study.segmentation;
        let mut left_out_ml: Vec<f64> = seg
            .left_out(voyage_core::LEFT_OUT_DOUBT_ML)
            .map(|s| s.gas_ml)
            .collect();
        left_out_ml.sort_by(|a, b| b.total_cmp(a));
        let mut bridged_mm: Vec<(String, f64)> = Vec::new();
        let mut leaves_the_scan = Vec::new();
        for (gap, name) in seg.gaps.iter().zip(study.gap_segments()) {
            let name = name.unwrap_or("colon").to_string();
            if gap.at_edge() {
                // Not bridged: the colon goes on outside the scan.
                leaves_the_scan.push(name);
                continue;
            }
            match bridged_mm.iter_mut().find(|(n, _)| *n == name) {
                Some((_, mm)) => *mm += gap.length_mm,
                None => bridged_mm.push((name, gap.length_mm)),
            }
        }
        ColonRead {
            found_ml: seg
                .segments
                .iter()
                .filter(|s| s.kept)
                .map(|s| s.gas_ml)
                .sum(),
            centerline_mm: study.centerline.length_mm,
            left_out_ml,
            position: Some(format!(
                "{} ({}), {}",
                seg.orientation.position.describe(),
                seg.orientation.position.code(),
                seg.orientation.source.describe()
            )),
            bridged_mm,
            leaves_the_scan,
            by_hand: by_hand
                .iter()
                .map(|c| {
                    let local = study
                        .ct
                        .geometry()
                        .patient_to_local(glam::DVec3::from_array(c.lps_mm));
                    (study.segment_at(local).to_string(), c.clone())
                })
                .collect(),
        }
    }
}

/// Writes `report` as self-contained HTML to `path` (atomically).
pub fn write_report_html(path: &Path, report: &Report) -> Result<()> {
    let html = report_html(report);
    write_atomic(path, |w| w.write_all(html.as_bytes()))
}

/// The report's HTML text.
pub fn report_html(r: &Report) -> String {
    let mut h = String::new();
    h.push_str("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n");
    h.push_str(&format!(
        "<title>CT colonography report: {}</title>\n",
        escape(&r.exam.name)
    ));
    h.push_str(STYLE);
    h.push_str("</head>\n<body>\n");
    h.push_str(&format!(
        "<h1>CT colonography report</h1>\n<p class=\"study\" id=\"exam\">{} &middot; voyage {}</p>\n",
        exam_line(&r.exam),
        env!("CARGO_PKG_VERSION")
    ));
    h.push_str(&format!(
        "<h2>Category: <span id=\"c-rads\">{}</span></h2>\n<p>{}</p>\n",
        r.c_rads.category,
        escape(&r.c_rads.reason)
    ));
    if !r.c_rads.unsized_polyps.is_empty() {
        h.push_str(&format!(
            "<p class=\"warn\">Polyps without a size: {}. The category holds only if they are under 6 mm.</p>\n",
            escape(&r.c_rads.unsized_polyps.join(", "))
        ));
    }
    h.push_str(&coverage_html(&r.coverage));
    h.push_str(&colon_html(&r.colon, &r.coverage.by_segment));
    h.push_str(&findings_html(&r.findings));
    if !r.measurements.is_empty() {
        h.push_str("<h2>Measurements</h2>\n<table>\n<tr><th>Label</th><th>Length</th></tr>\n");
        for (label, mm) in &r.measurements {
            h.push_str(&format!(
                "<tr><td>{}</td><td>{mm:.1} mm</td></tr>\n",
                escape(label)
            ));
        }
        h.push_str("</table>\n");
    }
    h.push_str(
        "<p class=\"foot\">C-RADS: ACR CT Colonography Reporting and Data System (Zalis et al., Radiology 2005). Sizes: largest 3D diameter of the segmented polyp head. Positions: DICOM patient LPS, mm.</p>\n",
    );
    h.push_str("</body>\n</html>\n");
    h
}

/// "Study: NAME · SERIES · exam of DATE", each part where known.
pub(crate) fn exam_line(e: &Exam) -> String {
    let mut parts = vec![format!("Study: {}", escape(&e.name))];
    if let Some(s) = &e.series {
        parts.push(escape(s));
    }
    if let Some(d) = &e.date {
        parts.push(format!("exam of {}", escape(d)));
    }
    parts.join(" &middot; ")
}

pub(crate) const STYLE: &str = "<style>\nbody{font-family:sans-serif;margin:2em;max-width:60em;color:#222}\ntable{border-collapse:collapse;margin:1em 0}\nth,td{border:1px solid #bbb;padding:.3em .6em;text-align:left;vertical-align:top}\ntd:nth-child(-n+4){white-space:nowrap}\nimg{width:256px;height:auto}\n.warn{color:#a40}\n.study,.foot{color:#666;font-size:.9em}\n</style>\n";

fn coverage_html(c: &ReportCoverage) -> String {
    let pct = |v: Option<f64>| v.map_or("not measured".to_string(), |x| format!("{x:.1} %"));
    let mut h = String::from("<h2>Coverage of the mucosa</h2>\n<table id=\"coverage\">\n");
    for (what, v) in [
        ("One way (rectum to cecum)", c.one_way_pct),
        ("Both ways", c.two_way_pct),
        ("After the review of unseen patches", c.after_review_pct),
        ("Whole session", c.session_pct),
    ] {
        h.push_str(&format!("<tr><th>{what}</th><td>{}</td></tr>\n", pct(v)));
    }
    if let Some(n) = c.patches_left {
        h.push_str(&format!(
            "<tr><th>Unseen patches left</th><td>{n}</td></tr>\n"
        ));
    }
    h.push_str("</table>\n");
    h
}

/// The colon read: what was found against what was left out, and per segment the mucosa
/// seen and the stretches bridged.
fn colon_html(c: &ColonRead, seen: &[SegmentSeen]) -> String {
    let mut h = String::from("<h2>The colon read</h2>\n<p id=\"colon\">");
    h.push_str(&format!(
        "Colon found: {:.0} ml of gas, centerline {:.0} cm.",
        c.found_ml,
        c.centerline_mm / 10.0
    ));
    if let Some(p) = &c.position {
        h.push_str(&format!(" Patient {}.", escape(p)));
    }
    h.push_str("</p>\n");
    if !c.left_out_ml.is_empty() {
        let list: Vec<String> = c
            .left_out_ml
            .iter()
            .map(|ml| format!("{ml:.0} ml"))
            .collect();
        h.push_str(&format!(
            "<p class=\"warn\" id=\"left-out\">Gas left out of the colon that may be colon: {}. The coverage is of the colon found only.</p>\n",
            list.join(", ")
        ));
    }
    if !c.leaves_the_scan.is_empty() {
        h.push_str(&format!(
            "<p class=\"warn\" id=\"leaves-the-scan\">The colon leaves the scanned volume ({}): what lies outside it was not read.</p>\n",
            escape(&c.leaves_the_scan.join(", "))
        ));
    }
    let mut names: Vec<&str> = seen.iter().map(|s| s.segment).collect();
    for name in c
        .bridged_mm
        .iter()
        .map(|(n, _)| n)
        .chain(c.by_hand.iter().map(|(n, ..)| n))
    {
        if !names.contains(&name.as_str()) {
            names.push(name);
        }
    }
    if names.is_empty() {
        return h;
    }
    h.push_str("<table id=\"segments\">\n<tr><th>Segment</th><th>Mucosa</th><th>Seen</th><th>Bridged (collapsed or under fluid)</th><th>Corrected by hand</th></tr>\n");
    for name in names {
        let row = seen.iter().find(|s| s.segment == name);
        let area = row.map_or("&mdash;".to_string(), |s| {
            format!("{:.0} cm²", s.total_mm2 / 100.0)
        });
        let pct = row.map_or("&mdash;".to_string(), |s| format!("{:.1} %", s.percent()));
        let bridged = c
            .bridged_mm
            .iter()
            .find(|(n, _)| n == name)
            .map_or("&mdash;".to_string(), |(_, mm)| format!("{mm:.0} mm"));
        let hand: Vec<String> = c
            .by_hand
            .iter()
            .filter(|(n, ..)| n == name)
            .map(|(_, c)| {
                let [x, y, z] = c.lps_mm;
                format!("{} at LPS ({x:.0}, {y:.0}, {z:.0})", c.what)
            })
            .collect();
        let hand = if hand.is_empty() {
            "&mdash;".to_string()
        } else {
            escape(&hand.join("; "))
        };
        h.push_str(&format!(
            "<tr><td>{}</td><td>{area}</td><td>{pct}</td><td>{bridged}</td><td>{hand}</td></tr>\n",
            escape(name)
        ));
    }
    h.push_str("</table>\n");
    h
}

fn findings_html(findings: &[ReportFinding]) -> String {
    if findings.is_empty() {
        return "<h2>Findings</h2>\n<p>None marked.</p>\n".into();
    }
    let mut h = String::from(
        "<h2>Findings</h2>\n<table id=\"findings\">\n<tr><th>Label</th><th>Kind</th><th>Size</th><th>Segment</th><th>From the rectum end</th><th>Position (LPS)</th><th>Note</th><th>View</th></tr>\n",
    );
    for f in findings {
        let size = f
            .size_mm
            .map_or("&mdash;".to_string(), |s| format!("{s:.1} mm"));
        let arc = f
            .from_rectum_mm
            .map_or("&mdash;".to_string(), |a| format!("{:.0} cm", a / 10.0));
        let [x, y, z] = f.position_lps_mm;
        h.push_str(&format!(
            "<tr class=\"finding\"><td>{}</td><td>{}</td><td>{size}</td><td>{}</td><td>{arc}</td><td>{x:.1}, {y:.1}, {z:.1}</td><td>{}</td><td><img alt=\"view of {}\" src=\"data:image/png;base64,{}\"></td></tr>\n",
            escape(&f.label),
            escape(&f.kind),
            escape(&f.segment),
            escape(&f.note),
            escape(&f.label),
            base64(&f.snapshot_png)
        ));
    }
    h.push_str("</table>\n");
    h
}

/// Text made safe inside HTML elements and attribute values.
pub fn escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            _ => out.push(c),
        }
    }
    out
}

/// Standard base64 (RFC 4648, with padding), for the images' data URLs. Hand-written: no
/// base64 crate is among the project's dependencies, and this is all the report needs.
pub fn base64(bytes: &[u8]) -> String {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for chunk in bytes.chunks(3) {
        let b = [
            chunk[0],
            chunk.get(1).copied().unwrap_or(0),
            chunk.get(2).copied().unwrap_or(0),
        ];
        let n = (b[0] as u32) << 16 | (b[1] as u32) << 8 | b[2] as u32;
        for i in 0..4 {
            if i <= chunk.len() {
                out.push(ALPHABET[(n >> (18 - 6 * i) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_matches_rfc_4648() {
        for (raw, enc) in [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ] {
            assert_eq!(base64(raw.as_bytes()), enc);
        }
        assert_eq!(base64(&[0xff, 0xfe, 0x00]), "//4A");
    }

    #[test]
    fn notes_cannot_break_out_of_the_page() {
        assert_eq!(
            escape("<script>alert('x')</script> & \"q\""),
            "&lt;script&gt;alert(&#39;x&#39;)&lt;/script&gt; &amp; &quot;q&quot;"
        );
    }
}
