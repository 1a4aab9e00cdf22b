//! report.html: self-contained, well formed, and rendered by a browser (headless Chromium,
//! from Debian) with its findings' images in it.

use std::{path::PathBuf, process::Command};

use voyage_export::{
    ColonRead, Exam, HandCorrection, Report, ReportCoverage, ReportFinding, write_report_html,
};
use voyage_view::{Adequacy, CRads, Findings, SegmentSeen, c_rads};

fn temp_dir(name: &str) -> PathBuf {
    let dir =
        std::env::temp_dir().join(format!("voyage-report-test-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A `side`² PNG of one colour.
fn png(side: u32, rgb: [u8; 3]) -> Vec<u8> {
    let img = image::RgbaImage::from_pixel(side, side, image::Rgba([rgb[0], rgb[1], rgb[2], 255]));
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png).unwrap();
    out.into_inner()
}

fn sample() -> Report {
    Report {
        exam: Exam {
            name: "colon <1>.nii.gz".into(),
            series: Some("CT series 2, 412 slices (DICOM)".into()),
            date: Some("2026-11-27".into()),
            by_hand: vec![HandCorrection {
                what: "gas taken in as colon",
                lps_mm: [94.5, 128.25, -279.0],
            }],
        },
        findings: vec![
            ReportFinding {
                label: "M1".into(),
                kind: "polyp".into(),
                size_mm: Some(7.25),
                segment: "sigmoid".into(),
                from_rectum_mm: Some(312.0),
                position_lps_mm: [10.0, -20.5, 300.25],
                note: "<b>not bold</b> & \"quoted\"".into(),
                snapshot_png: png(64, [0, 200, 0]),
            },
            ReportFinding {
                label: "M2".into(),
                kind: "diverticulum".into(),
                size_mm: None,
                segment: "descending".into(),
                from_rectum_mm: None,
                position_lps_mm: [0.0; 3],
                note: String::new(),
                snapshot_png: png(64, [0, 0, 220]),
            },
        ],
        measurements: vec![("L1".into(), 12.5)],
        c_rads: CRads {
            category: "C2",
            reason: "1 polyp(s) of 6–9 mm".into(),
            unsized_polyps: vec![],
        },
        coverage: ReportCoverage {
            session_pct: Some(97.5),
            one_way_pct: Some(76.0),
            two_way_pct: Some(96.0),
            after_review_pct: Some(99.6),
            patches_left: Some(0),
            by_segment: vec![
                SegmentSeen {
                    segment: "rectum",
                    seen_mm2: 9_000.0,
                    total_mm2: 10_000.0,
                },
                SegmentSeen {
                    segment: "sigmoid",
                    seen_mm2: 19_900.0,
                    total_mm2: 20_000.0,
                },
            ],
        },
        colon: ColonRead {
            found_ml: 2400.0,
            centerline_mm: 1650.0,
            left_out_ml: vec![320.0],
            position: Some("prone, head first (HFP), given".into()),
            bridged_mm: vec![("sigmoid".into(), 42.0), ("descending".into(), 120.0)],
            leaves_the_scan: vec!["cecum".into()],
            by_hand: vec![(
                "transverse".into(),
                HandCorrection {
                    what: "gas taken in as colon",
                    lps_mm: [94.5, 128.25, -279.0],
                },
            )],
        },
    }
}

/// Every element opened is closed, in order (void elements aside).
fn balanced(html: &str) -> Result<(), String> {
    let void = ["meta", "img", "br", "!DOCTYPE"];
    let mut stack: Vec<String> = Vec::new();
    for tag in html.split('<').skip(1) {
        let end = tag.find('>').ok_or("unclosed <")?;
        let inner = &tag[..end];
        let name: String = inner
            .trim_start_matches('/')
            .chars()
            .take_while(|c| c.is_ascii_alphanumeric() || *c == '!')
            .collect();
        if void.contains(&name.as_str()) {
            continue;
        }
        if inner.starts_with('/') {
            match stack.pop() {
                Some(open) if open == name => {}
                other => return Err(format!("</{name}> closes {other:?}")),
            }
        } else {
            stack.push(name);
        }
    }
    stack
        .is_empty()
        .then_some(())
        .ok_or(format!("left open: {stack:?}"))
}

#[test]
fn the_report_is_self_contained_and_well_formed() {
    let dir = temp_dir("html");
    let path = dir.join("report.html");
    write_report_html(&path, &sample()).unwrap();
    let html = std::fs::read_to_string(&path).unwrap();
    balanced(&html).unwrap();
    // Nothing outside the file: no links, scripts or sources but data URLs.
    assert!(!html.contains("http://") && !html.contains("https://") && !html.contains("<script"));
    assert_eq!(html.matches("src=\"data:image/png;base64,").count(), 2);
    assert!(html.contains("&lt;b&gt;not bold&lt;/b&gt; &amp; &quot;quoted&quot;"));
    assert!(html.contains("colon &lt;1&gt;.nii.gz"));
    for text in [
        "C2",
        "7.2 mm",
        "sigmoid",
        "31 cm",
        "99.6 %",
        "12.5 mm",
        "diverticulum",
    ] {
        assert!(html.contains(text), "{text} missing");
    }
    // What was read: the colon found against the gas left out, the position, and per
    // segment the mucosa seen and the stretches bridged (a segment only bridged included).
    let colon = &html[html.find("<p id=\"colon\">").unwrap()..];
    assert!(colon.starts_with("<p id=\"colon\">Colon found: 2400 ml of gas, centerline 165 cm. Patient prone, head first (HFP), given.</p>"));
    assert!(html.contains(
        "<p class=\"warn\" id=\"left-out\">Gas left out of the colon that may be colon: 320 ml."
    ));
    // The exam: the series and its date (never a description or a patient's identity).
    assert!(html.contains(
        "<p class=\"study\" id=\"exam\">Study: colon &lt;1&gt;.nii.gz &middot; CT series 2, 412 slices (DICOM) &middot; exam of 2026-11-27 &middot; voyage"
    ));
    // A colon that leaves the scan is said to, not counted as bridged.
    assert!(html.contains("id=\"leaves-the-scan\">The colon leaves the scanned volume (cecum)"));
    for row in [
        "<tr><td>rectum</td><td>100 cm²</td><td>90.0 %</td><td>&mdash;</td><td>&mdash;</td></tr>",
        "<tr><td>sigmoid</td><td>200 cm²</td><td>99.5 %</td><td>42 mm</td><td>&mdash;</td></tr>",
        "<tr><td>descending</td><td>&mdash;</td><td>&mdash;</td><td>120 mm</td><td>&mdash;</td></tr>",
        // A segment only corrected by hand has its row too.
        "<tr><td>transverse</td><td>&mdash;</td><td>&mdash;</td><td>&mdash;</td><td>gas taken in as colon at LPS (94, 128, -279)</td></tr>",
    ] {
        assert!(html.contains(row), "{row} missing");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_browser_renders_the_report_with_its_images() {
    if Command::new("chromium").arg("--version").output().is_err() {
        voyage_phantom::fixtures::skip("chromium not installed (bash scripts/deps.sh installs it)");
        return;
    }
    let dir = temp_dir("chromium");
    let path = dir.join("report.html");
    write_report_html(&path, &sample()).unwrap();
    let shot = dir.join("shot.png");
    let out = Command::new("chromium")
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--hide-scrollbars",
        ])
        .arg(format!("--screenshot={}", shot.display()))
        .arg("--window-size=1200,1400")
        .arg(format!("file://{}", path.display()))
        .env("HOME", &dir)
        .output()
        .unwrap();
    assert!(shot.exists(), "{}", String::from_utf8_lossy(&out.stderr));
    let img = image::open(&shot).unwrap().to_rgb8();
    let count = |rgb: [u8; 3]| {
        img.pixels()
            .filter(|p| p.0.iter().zip(rgb).all(|(&a, b)| a.abs_diff(b) <= 8))
            .count()
    };
    // The two snapshots, drawn at 256 px wide (the page scales them up from 64).
    let (green, blue) = (count([0, 200, 0]), count([0, 0, 220]));
    assert!(
        green > 200 * 200 && blue > 200 * 200,
        "images not drawn: {green} green, {blue} blue pixels"
    );
    // And text: the page is mostly white with dark letters.
    assert!(count([255, 255, 255]) > img.pixels().len() / 3);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The category is judged on what the reading showed in the end. The window's two-way reading
/// at its 90° lens read 89.5 % where after review and over the whole session it read 99.3 %:
/// judged on the flights, a fully reviewed negative exam was C0, which recalls the patient.
#[test]
fn a_reviewed_reading_is_judged_on_what_it_showed_in_the_end() {
    let reviewed = ReportCoverage {
        session_pct: Some(99.3),
        one_way_pct: Some(80.0),
        two_way_pct: Some(89.5),
        after_review_pct: Some(99.3),
        patches_left: Some(0),
        by_segment: Vec::new(),
    };
    let category = |cov: &ReportCoverage| {
        let adequacy = Adequacy {
            read_pct: cov.read_pct(),
            left_out_ml: None,
        };
        c_rads(&Findings::default(), adequacy).category
    };
    assert_eq!(reviewed.read_pct(), Some(99.3));
    assert_eq!(category(&reviewed), "C1");
    let flights_only = ReportCoverage {
        session_pct: None,
        after_review_pct: None,
        ..reviewed
    };
    assert_eq!(category(&flights_only), "C0");
}
