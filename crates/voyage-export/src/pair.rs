//! The reading of an exam scanned in two positions (supine and prone): each position's own
//! export in a folder of its name ([`super::export_reading`]), and `report.html` over both:
//! every finding once, with its place in each position it was marked in and whether it moved
//! between them more than the colon around it (probably stool); the C-RADS category of the
//! findings, each counted once; each position's coverage and both together.

use std::path::{Path, PathBuf};

use voyage_core::{LEFT_OUT_DOUBT_ML, Result, Study};
use voyage_io::write_atomic;
use voyage_view::{
    Adequacy, BothCoverage, Findings, Link, LinkedFinding, Marker, c_rads, link_findings,
};

use super::{
    findings::{export_reading, placed, snapshot_names},
    report::{Exam, ReportCoverage, STYLE, base64, escape, exam_line},
};

/// One position of the exam, read.
pub struct PositionReading<'a> {
    /// "supine", "prone" ...
    pub name: &'static str,
    pub study: &'a Study,
    pub exam: &'a Exam,
    pub findings: &'a Findings,
    pub coverage: ReportCoverage,
}

/// Writes each position's export into `dir/NAME/` and the report over both into
/// `dir/report.html`. `link` maps `a`'s arcs to `b`'s; `both` is the coverage over both
/// positions at each stage of the reading named (e.g. "one way"); `snapshot(p, i, marker)`
/// draws marker i of position p (0: `a`). Returns the paths written.
pub fn export_pair_reading(
    dir: &Path,
    a: PositionReading,
    b: PositionReading,
    link: &Link,
    both: &[(&str, BothCoverage)],
    mut snapshot: impl FnMut(usize, usize, &Marker) -> Result<(u32, u32, Vec<u8>)>,
) -> Result<Vec<PathBuf>> {
    if a.name == b.name {
        return Err(voyage_core::Error::invalid(format!(
            "{}: both positions are {}: each needs a folder of its own",
            dir.display(),
            a.name
        )));
    }
    let mut out = Vec::new();
    let mut pngs: Vec<Vec<Vec<u8>>> = Vec::new();
    for (p, r) in [&a, &b].into_iter().enumerate() {
        let sub = dir.join(r.name);
        out.extend(export_reading(
            &sub,
            r.findings,
            r.study,
            r.exam,
            r.coverage.clone(),
            |i, m| snapshot(p, i, m),
        )?);
        pngs.push(
            snapshot_names(&r.findings.markers)
                .iter()
                .map(|n| std::fs::read(sub.join(n)).unwrap_or_default())
                .collect(),
        );
    }
    let linked = link_findings(
        link,
        a.study,
        b.study,
        &a.findings.markers,
        &b.findings.markers,
    );
    let html = pair_report_html(&a, &b, &linked, both, &pngs);
    let path = dir.join("report.html");
    write_atomic(&path, |w| w.write_all(html.as_bytes()))?;
    out.push(path);
    Ok(out)
}

/// The findings counted once: a finding marked in both positions is the larger of its two.
fn counted_once(a: &Findings, b: &Findings, linked: &[LinkedFinding]) -> Findings {
    let markers = linked
        .iter()
        .filter_map(|f| {
            let ma = f.a.map(|i| &a.markers[i]);
            let mb = f.b.map(|j| &b.markers[j]);
            match (ma, mb) {
                (Some(x), Some(y)) if y.size_mm > x.size_mm => Some(y.clone()),
                (Some(x), _) => Some(x.clone()),
                (None, y) => y.cloned(),
            }
        })
        .collect();
    Findings {
        markers,
        measurements: a
            .measurements
            .iter()
            .chain(&b.measurements)
            .cloned()
            .collect(),
    }
}

fn pair_report_html(
    a: &PositionReading,
    b: &PositionReading,
    linked: &[LinkedFinding],
    both: &[(&str, BothCoverage)],
    pngs: &[Vec<Vec<u8>>],
) -> String {
    let once = counted_once(a.findings, b.findings, linked);
    let read_pct = both
        .last()
        .map(|(_, c)| c.combined_pct)
        .or(a.coverage.read_pct());
    let left_out_ml = [a.study, b.study]
        .iter()
        .filter_map(|s| {
            s.segmentation
                .largest_left_out(LEFT_OUT_DOUBT_ML)
                .map(|x| x.gas_ml)
        })
        .reduce(f64::max);
    let category = c_rads(
        &once,
        Adequacy {
            read_pct,
            left_out_ml,
        },
    );
    let mut h =
        String::from("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n");
    h.push_str(&format!(
        "<title>CT colonography report: {} and {}</title>\n",
        escape(&a.exam.name),
        escape(&b.exam.name)
    ));
    h.push_str(STYLE);
    // The positions' cells hold a place, a note and a view: they wrap.
    h.push_str("<style>\n#findings td:nth-child(n+3){white-space:normal}\n#findings img{width:200px}\n</style>\n");
    h.push_str("</head>\n<body>\n<h1>CT colonography report</h1>\n");
    for (r, id) in [(a, "exam-a"), (b, "exam-b")] {
        h.push_str(&format!(
            "<p class=\"study\" id=\"{id}\">{}: {}</p>\n",
            r.name,
            exam_line(r.exam)
        ));
    }
    h.push_str(&format!(
        "<h2>Category: <span id=\"c-rads\">{}</span></h2>\n<p>{} (each finding counted once over both positions)</p>\n",
        category.category,
        escape(&category.reason)
    ));
    if !category.unsized_polyps.is_empty() {
        h.push_str(&format!(
            "<p class=\"warn\">Polyps without a size: {}. The category holds only if they are under 6 mm.</p>\n",
            escape(&category.unsized_polyps.join(", "))
        ));
    }
    h.push_str(&coverage_html(a, b, both));
    h.push_str(&findings_html(a, b, linked, pngs));
    h.push_str(&format!(
        "<p class=\"foot\">Each position's own report: {}/report.html and {}/report.html. Positions: DICOM patient LPS, mm; arcs along each position's centerline from its rectum end.</p>\n</body>\n</html>\n",
        a.name, b.name
    ));
    h
}

fn coverage_html(
    a: &PositionReading,
    b: &PositionReading,
    both: &[(&str, BothCoverage)],
) -> String {
    if both.is_empty() {
        return "<h2>Coverage of the mucosa</h2>\n<p id=\"coverage\">Not measured.</p>\n".into();
    }
    let mut h = format!(
        "<h2>Coverage of the mucosa</h2>\n<p>Mucosa unseen in one position but seen in the other, where the link between them puts it, counts as seen.</p>\n<table id=\"coverage\">\n<tr><th></th><th>{0}</th><th>{1}</th><th>{0} with {1}</th><th>{1} with {0}</th><th>Together</th></tr>\n",
        a.name, b.name
    );
    for (stage, c) in both {
        h.push_str(&format!(
            "<tr><th>{}</th><td>{:.1} %</td><td>{:.1} %</td><td>{:.1} %</td><td>{:.1} %</td><td>{:.1} %</td></tr>\n",
            escape(stage),
            c.a_pct,
            c.b_pct,
            c.a_with_b_pct,
            c.b_with_a_pct,
            c.combined_pct
        ));
    }
    h.push_str("</table>\n");
    h
}

fn findings_html(
    a: &PositionReading,
    b: &PositionReading,
    linked: &[LinkedFinding],
    pngs: &[Vec<Vec<u8>>],
) -> String {
    if linked.is_empty() {
        return "<h2>Findings</h2>\n<p>None marked.</p>\n".into();
    }
    let mut h = format!(
        "<h2>Findings</h2>\n<table id=\"findings\">\n<tr><th>Kind</th><th>Size</th><th>{}</th><th>{}</th><th>Between the positions</th></tr>\n",
        a.name, b.name
    );
    for f in linked {
        let ma = f.a.map(|i| (i, &a.findings.markers[i]));
        let mb = f.b.map(|j| (j, &b.findings.markers[j]));
        let first = ma.or(mb).map(|(_, m)| m);
        let kind = first.map_or("", |m| m.kind.name());
        let size = [ma, mb]
            .iter()
            .flatten()
            .filter_map(|(_, m)| m.size_mm)
            .reduce(f64::max)
            .map_or("&mdash;".to_string(), |s| format!("{s:.1} mm"));
        let cell = |r: &PositionReading, at: Option<(usize, &Marker)>, p: usize| match at {
            None => "not marked".to_string(),
            Some((i, m)) => {
                let (segment, arc) = placed(m, r.study);
                let arc = arc.map_or(String::new(), |s| {
                    format!(", {:.0} cm from the rectum end", s / 10.0)
                });
                let [x, y, z] = r
                    .study
                    .ct
                    .geometry()
                    .local_to_patient(m.position)
                    .to_array();
                let img =
                    pngs[p]
                        .get(i)
                        .filter(|png| !png.is_empty())
                        .map_or(String::new(), |png| {
                            format!(
                                "<br><img alt=\"view of {}\" src=\"data:image/png;base64,{}\">",
                                escape(&m.label),
                                base64(png)
                            )
                        });
                format!(
                    "{} &middot; {}{arc} &middot; LPS {x:.1}, {y:.1}, {z:.1}{}{img}",
                    escape(&m.label),
                    escape(segment),
                    if m.note.is_empty() {
                        String::new()
                    } else {
                        format!(" &middot; {}", escape(&m.note))
                    }
                )
            }
        };
        let moved = match (f.moved_mm, f.moved_deg) {
            (Some(mm), Some(deg)) if f.probably_stool => format!(
                "<span class=\"warn\">moved {mm:.0} mm, {deg:.0}° round the colon: probably stool</span>"
            ),
            (Some(mm), Some(deg)) => format!("stayed on the wall ({mm:.0} mm, {deg:.0}°)"),
            _ => "seen in one position".to_string(),
        };
        h.push_str(&format!(
            "<tr class=\"finding\"><td>{}</td><td>{size}</td><td>{}</td><td>{}</td><td>{moved}</td></tr>\n",
            escape(kind),
            cell(a, ma, 0),
            cell(b, mb, 1)
        ));
    }
    h.push_str("</table>\n");
    h
}
