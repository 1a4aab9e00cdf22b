//! The navigator window, driven as a user drives it, on a virtual display (Xvfb) with
//! Mesa's CPU Vulkan driver: scripted actions (`--script`) and real X events (xdotool).
//! Without Xvfb the tests say so and pass (scripts/deps.sh installs it; CI has it).

use std::{
    io::{BufRead, BufReader},
    path::{Path, PathBuf},
    process::{Child, Command, Stdio},
    time::{Duration, Instant},
};

use glam::{DQuat, DVec3};
use serde_json::Value;

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("voyage-gui-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn have(tool: &str) -> bool {
    Command::new("sh")
        .arg("-c")
        .arg(format!("command -v {tool}"))
        .output()
        .is_ok_and(|o| o.status.success())
}

/// A private X display for one test, closed when dropped.
struct Display {
    server: Child,
    name: String,
}

impl Display {
    /// Xvfb picks a free display itself and writes its number to `-displayfd` only once it
    /// accepts connections: choosing a number here and waiting for its socket raced with
    /// other test processes and with the server's own start (a socket not yet listening).
    fn start() -> Option<Display> {
        if !have("Xvfb") {
            voyage_phantom::fixtures::skip("Xvfb not installed (bash scripts/deps.sh installs it)");
            return None;
        }
        let mut server = Command::new("Xvfb")
            .args([
                "-displayfd",
                "1",
                "-screen",
                "0",
                "1280x800x24",
                "-nolisten",
                "tcp",
            ])
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("start Xvfb");
        let stdout = server.stdout.take().expect("Xvfb's stdout");
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let mut line = String::new();
            let _ = BufReader::new(stdout).read_line(&mut line);
            let _ = tx.send(line);
        });
        match rx.recv_timeout(Duration::from_secs(20)) {
            Ok(line) if line.trim().parse::<u32>().is_ok() => Some(Display {
                server,
                name: format!(":{}", line.trim()),
            }),
            other => {
                let _ = server.kill();
                let _ = server.wait();
                panic!("Xvfb did not report a display within 20 s: {other:?}");
            }
        }
    }
}

impl Drop for Display {
    fn drop(&mut self) {
        let _ = self.server.kill();
        let _ = self.server.wait();
    }
}

fn voyage(display: &Display) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_voyage"));
    c.env("DISPLAY", &display.name)
        .env_remove("WAYLAND_DISPLAY");
    c
}

fn pose(v: &Value) -> (DVec3, DQuat) {
    let a: Vec<f64> = v
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    (
        DVec3::new(a[0], a[1], a[2]),
        DQuat::from_xyzw(a[4], a[5], a[6], a[3]).normalize(),
    )
}

/// How far the view turned toward the screen's right (degrees, negative: left), between two
/// poses: the angle of the new view direction around the old up axis. The screen's right is
/// −x_body (camera.rs).
fn turned_right_deg(before: &Value, after: &Value) -> f64 {
    let (_, q0) = pose(before);
    let (_, q1) = pose(after);
    let (right, forward) = (q0 * -DVec3::X, q0 * DVec3::Z);
    let z1 = q1 * DVec3::Z;
    z1.dot(right).atan2(z1.dot(forward)).to_degrees()
}

/// `voyage ARGS`, which must succeed: its standard output as JSON (null where it is not).
fn cli_json(args: &[&str]) -> Value {
    let out = Command::new(env!("CARGO_BIN_EXE_voyage"))
        .args(args)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "voyage {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap_or(Value::Null)
}

fn read_json(p: &Path) -> Value {
    serde_json::from_str(
        &std::fs::read_to_string(p).unwrap_or_else(|e| panic!("{}: {e}", p.display())),
    )
    .unwrap()
}

/// `voyage phantom colon --small ARGS --out OUT`, which must succeed.
fn small_colon(out: &Path, args: &[&str]) {
    colon(out, &[&["--small"], args].concat());
}

/// `voyage phantom colon ARGS --out OUT`, which must succeed.
fn colon(out: &Path, args: &[&str]) {
    let out = out.to_str().unwrap();
    cli_json(&[&["phantom", "colon"], args, &["--out", out]].concat());
}

/// `voyage view CT ARGS --script` with `steps` (written to DIR/NAME.json), which must
/// succeed; its `--report`.
fn view_script(
    display: &Display,
    ct: &Path,
    args: &[&str],
    steps: Value,
    dir: &Path,
    name: &str,
) -> Value {
    let script = dir.join(format!("{name}.json"));
    std::fs::write(&script, steps.to_string()).unwrap();
    let report = dir.join(format!("{name}.report.json"));
    let out = voyage(display)
        .arg("view")
        .arg(ct)
        .args(args)
        .arg("--script")
        .arg(&script)
        .arg("--report")
        .arg(&report)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    read_json(&report)
}

/// `voyage prep INPUT --out OUT --json`, which must succeed: its summary and its stderr.
fn prep_json(input: &Path, out: &Path) -> (Value, String) {
    let prep = Command::new(env!("CARGO_BIN_EXE_voyage"))
        .arg("prep")
        .arg(input)
        .arg("--out")
        .arg(out)
        .arg("--json")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&prep.stderr).into_owned();
    assert!(prep.status.success(), "{err}");
    (serde_json::from_slice(&prep.stdout).unwrap(), err)
}

/// The endoscopic view's rectangle in the window (x0, y0, x1, y1), from a `--report`.
fn view_rect(report: &Value) -> [f32; 4] {
    let v: Vec<f32> = report["view_rect"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap() as f32)
        .collect();
    [v[0], v[1], v[2], v[3]]
}

/// Mean colour of a rectangle of the screenshot.
fn mean_rgb(img: &image::RgbaImage, r: [f32; 4]) -> [f64; 3] {
    let (mut sum, mut n) = ([0.0f64; 3], 0.0f64);
    for y in r[1] as u32..(r[3] as u32).min(img.height()) {
        for x in r[0] as u32..(r[2] as u32).min(img.width()) {
            let p = img.get_pixel(x, y);
            for c in 0..3 {
                sum[c] += p[c] as f64;
            }
            n += 1.0;
        }
    }
    sum.map(|s| s / n.max(1.0))
}

fn count(img: &image::RgbaImage, r: [f32; 4], pred: impl Fn(&image::Rgba<u8>) -> bool) -> usize {
    let mut n = 0;
    for y in r[1] as u32..(r[3] as u32).min(img.height()) {
        for x in r[0] as u32..(r[2] as u32).min(img.width()) {
            n += pred(img.get_pixel(x, y)) as usize;
        }
    }
    n
}

#[test]
fn scripted_session_steers_marks_measures_exports_and_shows_three_panels() {
    let Some(display) = Display::start() else {
        return;
    };
    let dir = scratch("script");
    let script = dir.join("script.json");
    let export = dir.join("findings");
    std::fs::write(
        &script,
        serde_json::json!([
            {"wait": 5},
            {"record": "start"},
            {"steer": {"at": [0.75, 0.5], "frames": 8}}, {"wait": 10},
            {"record": "after_right"},
            {"steer": {"at": [0.25, 0.5], "frames": 8}}, {"wait": 10},
            {"record": "after_left"},
            {"marker": {"at": [0.5, 0.5], "note": "test marker"}},
            {"measure": {"from": [0.4, 0.55], "to": [0.6, 0.55]}},
            {"export": export},
            {"wait": 3}
        ])
        .to_string(),
    )
    .unwrap();
    let shot = dir.join("window.png");
    let report = dir.join("report.json");
    let out = voyage(&display)
        .args(["demo", "--small", "--paused", "--after-frames", "1"])
        .arg("--script")
        .arg(&script)
        .arg("--screenshot")
        .arg(&shot)
        .arg("--report")
        .arg(&report)
        .output()
        .unwrap();
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(out.status.success(), "{text}");
    let r = read_json(&report);
    assert_eq!(r["ready"], true, "{r}");
    let rec = &r["recorded"];
    let right = turned_right_deg(&rec["start"], &rec["after_right"]);
    let left = turned_right_deg(&rec["after_right"], &rec["after_left"]);
    eprintln!("clicks right turned the view {right:.1}°, then clicks left {left:.1}°");
    assert!(
        right > 3.0,
        "holding the button right of centre turned the camera by {right:.2}° (want right, > 3°)"
    );
    assert!(
        left < -3.0,
        "holding the button left of centre turned the camera by {left:.2}° (want left)"
    );
    assert_eq!(r["markers"].as_array().unwrap().len(), 1, "{r}");
    assert_eq!(r["markers"][0]["note"], "test marker");
    let lengths = r["measurements_mm"].as_array().unwrap();
    assert_eq!(lengths.len(), 1);
    assert!(lengths[0].as_f64().unwrap() > 0.5, "{lengths:?}");
    for f in ["findings.json", "findings.mrk.json", "finding_M1.png"] {
        assert!(export.join(f).is_file(), "{f} not exported");
    }

    // The screenshot: the whole window, with the three panels drawn.
    let img = image::open(&shot).unwrap().to_rgba8();
    assert_eq!((img.width(), img.height()), (1280, 800));
    let view = view_rect(&r);
    let pink = mean_rgb(&img, view);
    assert!(
        pink[0] > 90.0 && pink[0] > pink[1] + 30.0,
        "endoscopic view is not mucosa-coloured: {pink:?}"
    );
    // Scout (right of the view): the green centerline on the dark background.
    let scout = [view[2] + 4.0, view[1], 1280.0, view[3]];
    let green = count(&img, scout, |p| p[1] > 150 && p[0] < 120 && p[2] < 140);
    assert!(
        green > 200,
        "scout shows no centerline ({green} green pixels)"
    );
    // Slices (below the view): CT grey levels, both air (dark) and tissue (light).
    let slices = [view[0], view[3] + 30.0, 1280.0, 800.0];
    let dark = count(&img, slices, |p| p[0] < 40 && p[0] == p[1] && p[1] == p[2]);
    let light = count(&img, slices, |p| p[0] > 140 && p[0] == p[1] && p[1] == p[2]);
    assert!(
        dark > 2000 && light > 2000,
        "slices missing: {dark} dark, {light} light grey pixels"
    );
}

/// The small demo, paused, driven by real X events: started with a script of `steps` and
/// a report, up to its "ready" line on stdout (which it returns).
struct Driven<'a> {
    display: &'a Display,
    child: Child,
    ready: Value,
    report: PathBuf,
}

impl<'a> Driven<'a> {
    /// None (skipped, said) when xdotool is missing.
    fn start(display: &'a Display, dir: &Path, steps: &str) -> Option<Self> {
        if !have("xdotool") {
            voyage_phantom::fixtures::skip(
                "xdotool not installed (bash scripts/deps.sh installs it)",
            );
            return None;
        }
        let script = dir.join("script.json");
        std::fs::write(&script, steps).unwrap();
        let report = dir.join("report.json");
        let mut child = voyage(display)
            .args(["demo", "--small", "--paused"])
            .arg("--script")
            .arg(&script)
            .arg("--report")
            .arg(&report)
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
        let ready: Value = loop {
            let line = lines
                .next()
                .expect("the window closed before it was ready")
                .unwrap();
            if let Ok(v) = serde_json::from_str::<Value>(&line)
                && v["ready"] == true
            {
                break v;
            }
        };
        let driven = Driven {
            display,
            child,
            ready,
            report,
        };
        // No window manager runs on the virtual display: give the window the keyboard focus.
        driven.xdo(&["search", "--name", "^voyage", "windowfocus"]);
        Some(driven)
    }

    fn xdo(&self, args: &[&str]) {
        let ok = Command::new("xdotool")
            .env("DISPLAY", &self.display.name)
            .args(args)
            .status()
            .unwrap()
            .success();
        assert!(ok, "xdotool {args:?}");
    }

    fn move_to(&self, x: f64, y: f64) {
        self.xdo(&["mousemove", &format!("{x:.0}"), &format!("{y:.0}")]);
    }

    /// Closes the window with Ctrl+Q; its report.
    fn quit(mut self) -> Value {
        self.xdo(&["key", "ctrl+q"]);
        let t = Instant::now();
        let status = loop {
            if let Some(s) = self.child.try_wait().unwrap() {
                break s;
            }
            if t.elapsed() > Duration::from_secs(60) {
                let _ = self.child.kill();
                panic!("the window did not close on Ctrl+Q");
            }
            std::thread::sleep(Duration::from_millis(100));
        };
        assert!(status.success());
        read_json(&self.report)
    }
}

#[test]
fn mouse_and_keys_drive_the_window() {
    let Some(display) = Display::start() else {
        return;
    };
    let dir = scratch("xdotool");
    let Some(w) = Driven::start(&display, &dir, r#"[{"record": "start"}]"#) else {
        return;
    };
    let v: Vec<f64> = w.ready["view_px"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    let (cx, cy) = ((v[0] + v[2]) / 2.0, (v[1] + v[3]) / 2.0);
    let right_x = v[0] + 0.75 * (v[2] - v[0]);
    // Hold the left button right of centre for 0.3 s: F_user pulls right and
    // its torque z_body × F_user (Eq. 4) turns the view toward the point held. (Held longer
    // the view keeps turning: the point held moves with the view, as with repeated clicks;
    // 0.6 s turned it ~112°, so a late mouseup on a busy machine could carry it past 180°,
    // where the angle reads as a turn to the left. The script is done by then, so the
    // physics follows the clock, not the frame count.)
    w.move_to(right_x, cy);
    w.xdo(&["mousedown", "1"]);
    std::thread::sleep(Duration::from_millis(300));
    w.xdo(&["mouseup", "1"]);
    // A marker on the surface under the cursor, then quit with Ctrl+Q.
    w.move_to(cx, cy);
    std::thread::sleep(Duration::from_millis(300));
    w.xdo(&["key", "m"]);
    std::thread::sleep(Duration::from_millis(500));
    let r = w.quit();
    let turn = turned_right_deg(&r["recorded"]["start"], &r["pose"]);
    eprintln!(
        "after holding the button right of centre: turned {turn:.1}°; markers {}",
        r["markers"]
    );
    assert!(
        turn > 2.0,
        "the camera turned {turn:.2}° (want right, > 2°)"
    );
    assert_eq!(r["markers"].as_array().unwrap().len(), 1, "{r}");
}

/// Issue 24, item 5: a click near the scout's centerline (12 px off it, where the old 8 px
/// tolerance missed) jumps there; the line under the pointer lights up; a click that misses
/// says so.
#[test]
fn the_scout_picks_generously_lights_the_line_and_says_when_a_click_misses() {
    let Some(display) = Display::start() else {
        return;
    };
    let dir = scratch("scout-pick");
    let Some(w) = Driven::start(&display, &dir, r#"[{"record": "start"}]"#) else {
        return;
    };
    let probe: Vec<[f64; 2]> = serde_json::from_value(w.ready["scout_centerline_px"].clone())
        .expect("the ready line gives the scout's centerline");
    let ([ax, ay], [bx, by]) = (probe[0], probe[1]);
    let len = (bx - ax).hypot(by - ay).max(1e-9);
    let (nx, ny) = (-(by - ay) / len, (bx - ax) / len);
    let (px, py) = (ax + 12.0 * nx, ay + 12.0 * ny);
    w.move_to(px, py);
    std::thread::sleep(Duration::from_millis(300));
    w.xdo(&["click", "1"]);
    std::thread::sleep(Duration::from_millis(500));
    // A click on empty scout (its top right corner): a miss, said.
    w.move_to(1270.0, 60.0);
    std::thread::sleep(Duration::from_millis(300));
    w.xdo(&["click", "1"]);
    std::thread::sleep(Duration::from_millis(500));
    // Back over the line: it lights up.
    w.move_to(px, py);
    std::thread::sleep(Duration::from_millis(500));
    let r = w.quit();
    let (start, _) = pose(&r["recorded"]["start"]);
    let (now, _) = pose(&r["pose"]);
    assert!(
        start.distance(now) > 20.0,
        "the click near the scout's centerline did not jump: {:.1} mm moved",
        start.distance(now)
    );
    let status = r["status"].as_str().unwrap();
    assert!(status.contains("missed the centerline"), "{status}");
    assert!(
        r["scout_hovered"].is_u64(),
        "the centerline under the pointer is not lit: {}",
        r["scout_hovered"]
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn an_unreadable_file_is_reported_in_the_window() {
    let Some(display) = Display::start() else {
        return;
    };
    let dir = scratch("bad");
    let bad = dir.join("broken.nii.gz");
    std::fs::write(&bad, b"not a nifti file").unwrap();
    let shot = dir.join("error.png");
    let out = voyage(&display)
        .arg("view")
        .arg(&bad)
        .arg("--screenshot")
        .arg(&shot)
        .args(["--after-frames", "3"])
        .output()
        .unwrap();
    // The window stayed up, showed the error and saved the screenshot; the unattended run
    // then fails naming the file.
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("broken.nii.gz"), "{err}");
    assert!(shot.is_file(), "no screenshot of the error");
}

/// The window's corrections of the colon found (slice menu, segment list): each reruns the
/// preprocessing in the background, and the colon shown follows; one that cannot be done is
/// shown and leaves the open colon as it was.
#[test]
fn corrections_rerun_the_preprocessing_and_the_colon_follows() {
    let Some(display) = Display::start() else {
        return;
    };
    let dir = scratch("correct");
    let ct = dir.join("collapsed.nii.gz");
    small_colon(&ct, &["--collapsed", "descending"]);
    // The automatic colon: two segments, rectum first; each with a point in its gas.
    let (auto, _) = prep_json(&ct, &dir.join("prep"));
    let segs = auto["segments"].as_array().unwrap();
    assert_eq!(
        segs.iter().filter(|s| s["kept"] == true).count(),
        2,
        "{auto}"
    );
    let anchor = |order: u64| -> Vec<f64> {
        segs.iter().find(|s| s["order"] == order).unwrap()["anchor_lps_mm"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect()
    };
    let far = anchor(1);
    let full = auto["centerline_length_mm"].as_f64().unwrap();

    let run = |name: &str, steps: Value| -> Value {
        view_script(
            &display,
            &ct,
            &["--paused", "--after-frames", "1"],
            steps,
            &dir,
            name,
        )
    };
    // Leaving the far segment out: one segment, a shorter flight; then a point in tissue
    // said to be colon: refused with the reason, the colon stays.
    // (The rectum's lowest gas voxel, 3 mm further down: soft tissue.)
    let rectum = anchor(0);
    let tissue = [rectum[0], rectum[1], rectum[2] - 3.0];
    let r = run(
        "exclude",
        serde_json::json!([{"correct": {"exclude": far}}, {"correct": {"include": tissue}}, {"quit": true}]),
    );
    let colon = &r["colon"];
    let kept = |c: &Value| {
        c["segments"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|s| s["kept"] == true)
            .count()
    };
    assert_eq!(kept(colon), 1, "{colon}");
    assert!(
        colon["segments"]
            .as_array()
            .unwrap()
            .iter()
            .any(|s| s["reason"] == "excluded by the user"),
        "{colon}"
    );
    let len = colon["centerline_mm"].as_f64().unwrap();
    assert!(
        len < 0.7 * full,
        "centerline {len:.0} mm after leaving out the far segment, {full:.0} mm before"
    );
    assert!(
        r["correction_error"]
            .as_str()
            .is_some_and(|e| e.contains("not in gas")),
        "{}",
        r["correction_error"]
    );
    assert_eq!(colon["corrections"]["exclude"].as_array().unwrap().len(), 1);

    // Taken back in, and the flight started higher up the rectosigmoid (a point on the
    // automatic centerline 40 mm along).
    let pts = std::fs::read_to_string(dir.join("prep").join("centerline.json")).unwrap();
    let cl: Value = serde_json::from_str(&pts).unwrap();
    let start = cl["points_lps_mm"]
        .as_array()
        .map(|p| p[p.len() / 20].clone())
        .unwrap_or(Value::Null);
    assert!(
        !start.is_null(),
        "centerline.json has points_lps_mm: {}",
        &pts[..200.min(pts.len())]
    );
    let r = run(
        "include",
        serde_json::json!([{"correct": {"exclude": far}}, {"correct": {"include": far}}, {"correct": {"source": start}}, {"quit": true}]),
    );
    let colon = &r["colon"];
    assert_eq!(kept(colon), 2, "{colon}");
    let at = |v: &Value| DVec3::from_array([0, 1, 2].map(|i| v[i].as_f64().unwrap()));
    let d = at(&colon["start_lps_mm"]).distance(at(&start));
    assert!(d < 3.0, "the flight starts {d:.1} mm from the point chosen");
    let len = colon["centerline_mm"].as_f64().unwrap();
    assert!(
        len < full - 20.0 && len > 0.8 * full,
        "centerline {len:.0} mm starting higher, {full:.0} mm before"
    );
    assert!(r["correction_error"].is_null());
}

/// A tagged exam's slices show the original CT, or on request the cleansed one with what
/// cleansing changed outlined; `--no-cleanse` offers neither.
#[test]
fn slices_show_the_cleansed_ct_and_outline_it_on_request() {
    let Some(display) = Display::start() else {
        return;
    };
    let dir = scratch("cleansed");
    let ct = dir.join("tagged.nii.gz");
    small_colon(&ct, &["--tagged-fluid"]);
    let (plain, cleansed) = (dir.join("plain.png"), dir.join("cleansed.png"));
    let steps = serde_json::json!([
        {"wait": 3},
        {"screenshot": plain},
        {"slices_cleansed": true}, {"slices_outline": true}, {"wait": 3},
        {"screenshot": cleansed},
        {"quit": true}
    ]);
    let view = view_rect(&view_script(
        &display,
        &ct,
        &["--paused"],
        steps,
        &dir,
        "script",
    ));
    let slices = [view[0], view[3] + 30.0, 1280.0, 800.0];
    let outline = |p: &image::Rgba<u8>| p[0] < 30 && p[1] > 180 && p[2] > 230;
    let grey = |p: &image::Rgba<u8>| p[0] == p[1] && p[1] == p[2];
    let (a, b) = (
        image::open(&plain).unwrap().to_rgba8(),
        image::open(&cleansed).unwrap().to_rgba8(),
    );
    assert_eq!(
        count(&a, slices, outline),
        0,
        "outline drawn before it was asked for"
    );
    let outlined = count(&b, slices, outline);
    assert!(outlined > 50, "cleansed voxels outlined: {outlined} pixels");
    // Inside the outline the fluid (bright) became air (dark): fewer light grey pixels.
    let light = |img: &image::RgbaImage| count(img, slices, |p| grey(p) && p[0] > 200);
    assert!(
        light(&b) < light(&a),
        "cleansed slices are not darker where fluid lay: {} vs {}",
        light(&b),
        light(&a)
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The translucency view (T, script step `translucency`) colours a polyp red and a lump of
/// tagged stool green, with a legend; the plain view has neither colour.
#[test]
fn translucency_tells_polyp_from_stool() {
    let Some(display) = Display::start() else {
        return;
    };
    let dir = scratch("translucency");
    let (ct, truth) = (dir.join("stool.nii.gz"), dir.join("truth.json"));
    small_colon(&ct, &["--tagged-stool", "--truth", truth.to_str().unwrap()]);
    let t = read_json(&truth);
    let v3 = |v: &Value| {
        DVec3::new(
            v[0].as_f64().unwrap(),
            v[1].as_f64().unwrap(),
            v[2].as_f64().unwrap(),
        )
    };
    // The largest of a truth list of spheres (polyps, lumps): its centre and radius.
    let largest = |key: &str| {
        let d = |x: &Value| x["diameter_mm"].as_f64().unwrap();
        let x = t[key]
            .as_array()
            .unwrap()
            .iter()
            .max_by(|a, b| d(a).total_cmp(&d(b)))
            .unwrap();
        (x.clone(), v3(&x["center_mm"]), d(x) / 2.0)
    };
    // Facing a sphere on the wall from 6 mm off its surface, along `into` (into the lumen).
    let facing = |c: DVec3, r: f64, into: DVec3| {
        voyage_nav::Pose::looking(c + (r + 6.0) * into, -into, into.any_orthonormal_vector())
            .to_array()
    };
    let (polyp, c, r) = largest("polyps");
    let at_polyp = facing(c, r, v3(&polyp["direction"]));
    let (_, c, r) = largest("stool");
    let axis: Vec<DVec3> = t["centerline_mm"]
        .as_array()
        .unwrap()
        .iter()
        .map(v3)
        .collect();
    let near = axis
        .iter()
        .copied()
        .min_by(|a, b| a.distance(c).total_cmp(&b.distance(c)))
        .unwrap();
    let at_lump = facing(c, r, (near - c).normalize());
    let shots = ["plain", "polyp", "stool"].map(|n| dir.join(format!("{n}.png")));
    let steps = serde_json::json!([
        {"centerline": false}, {"wait": 3}, {"pose": at_polyp}, {"wait": 3}, {"screenshot": shots[0]},
        {"translucency": true}, {"wait": 3}, {"screenshot": shots[1]},
        {"pose": at_lump}, {"wait": 3}, {"screenshot": shots[2]},
        {"quit": true}
    ]);
    let view = view_rect(&view_script(
        &display,
        &ct,
        &["--paused", "--no-cleanse"],
        steps,
        &dir,
        "script",
    ));
    // Encoded colours: the mucosa's green is 0.63 of its red at any light, the
    // translucency's soft tissue 0.33; its stool is green.
    let red = |p: &image::Rgba<u8>| {
        p[0] > 100 && (p[1] as f32) < 0.45 * p[0] as f32 && (p[2] as f32) < 0.45 * p[0] as f32
    };
    let green = |p: &image::Rgba<u8>| {
        p[1] > 100 && (p[0] as f32) < 0.6 * p[1] as f32 && (p[2] as f32) < 0.8 * p[1] as f32
    };
    let [plain, polyp, stool] = shots.map(|s| image::open(&s).unwrap().to_rgba8());
    let (r0, g0) = (count(&plain, view, red), count(&plain, view, green));
    let (r1, g2) = (count(&polyp, view, red), count(&stool, view, green));
    assert!(
        r0 < 20 && g0 < 20,
        "plain view: {r0} red, {g0} green pixels"
    );
    assert!(
        r1 > 500,
        "the polyp is not red under translucency: {r1} pixels"
    );
    assert!(
        g2 > 500,
        "the stool is not green under translucency: {g2} pixels"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Pixels of the scout's unseen-mucosa blue (not the submarine's cyan, not the tissue).
fn unseen_blue(p: &image::Rgba<u8>) -> bool {
    let [r, g, b] = [p[0], p[1], p[2]].map(f32::from);
    b > 90.0 && b > 1.6 * r && b > 1.25 * g && g < 170.0
}

#[test]
fn two_way_reading_runs_to_the_end_and_coverage_rises() {
    let Some(display) = Display::start() else {
        return;
    };
    let dir = scratch("coverage");
    let ct = dir.join("colon.nii.gz");
    small_colon(&ct, &[]);
    let shots = ["partial", "read"].map(|n| dir.join(format!("{n}.png")));
    let export = dir.join("export");
    let steps = serde_json::json!([
        {"play": true}, {"wait": 150}, {"play": false}, {"wait": 2},
        {"screenshot": shots[0]},
        {"two_way": true},
        {"wait": 3},
        {"screenshot": shots[1]},
        {"export": export}, {"wait": 2},
        {"quit": true}
    ]);
    let r = view_script(&display, &ct, &["--paused"], steps, &dir, "script");
    let c = &r["coverage"];
    let reading = &c["reading"];
    let pct = |k: &str| reading[k].as_f64().unwrap_or(f64::NAN);
    let (one, two, after) = (
        pct("one_way_pct"),
        pct("two_way_pct"),
        pct("after_review_pct"),
    );
    eprintln!(
        "window: one way {one:.2} %, two ways {two:.2} %, after review {after:.2} %, {} patches, {} visits, {} glances (a step {:.2} ms); marked {} of {} frames at {:.2} ms",
        reading["patches"],
        reading["visits"],
        reading["glances"],
        c["step_ms"],
        c["frames_marked"],
        c["frames_asked"],
        c["mark_ms"]
    );
    assert_eq!(reading["stage"], "done", "{c}");
    assert!(one < two && two <= after, "{c}");
    assert!(after >= 94.0, "after review {after:.1} %");
    let (patches, visits) = (
        reading["patches"].as_u64().unwrap(),
        reading["visits"].as_u64().unwrap(),
    );
    assert!(visits >= patches, "{c}");
    assert!(c["session_pct"].as_f64().unwrap() >= after - 1e-9);
    assert!(c["step_ms"].as_f64().is_some_and(|ms| ms > 0.0), "{c}");
    // One reading engine: `voyage coverage` on the same file gives the same figures, and
    // `voyage report` the same C-RADS category and coverage table as the window's Export.
    let cli = cli_json(&["coverage", ct.to_str().unwrap(), "--json"]);
    for k in ["one_way_pct", "two_way_pct", "after_review_pct"] {
        let (w, c) = (reading[k].as_f64().unwrap(), cli[k].as_f64().unwrap());
        assert!(
            (w - c).abs() < 1e-9,
            "{k}: window {w} against the CLI's {c}"
        );
    }
    let cli_glances: u64 = cli["glances"]
        .as_array()
        .unwrap()
        .iter()
        .map(|g| g.as_u64().unwrap())
        .sum();
    assert_eq!(reading["glances"].as_u64(), Some(cli_glances), "{cli}");
    let cli_export = dir.join("cli-export");
    cli_json(&[
        "report",
        ct.to_str().unwrap(),
        "--findings",
        export.join("findings.json").to_str().unwrap(),
        "--out",
        cli_export.to_str().unwrap(),
    ]);
    let [window_html, cli_html] =
        [&export, &cli_export].map(|d| std::fs::read_to_string(d.join("report.html")).unwrap());
    let part = |html: &str, from: &str, to: &str| {
        let i = html.find(from).expect(from);
        html[i..i + html[i..].find(to).expect(to)].to_string()
    };
    assert_eq!(
        part(&window_html, "<span id=\"c-rads\">", "</span>"),
        part(&cli_html, "<span id=\"c-rads\">", "</span>")
    );
    let flights_and_review =
        |html: &str| part(html, "<table id=\"coverage\">", "<tr><th>Whole session");
    assert_eq!(
        flights_and_review(&window_html),
        flights_and_review(&cli_html)
    );
    // The scout shows the unseen mucosa in blue: much of it after 150 frames, little after.
    let view = view_rect(&r);
    let scout = [view[2] + 4.0, view[1] + 20.0, 1280.0, view[3]];
    let [partial, read] = shots.map(|s| image::open(&s).unwrap().to_rgba8());
    let (before, left) = (
        count(&partial, scout, unseen_blue),
        count(&read, scout, unseen_blue),
    );
    eprintln!("scout: {before} blue pixels after 150 frames, {left} after the reading");
    assert!(
        before > 5000,
        "the scout shows no unseen mucosa: {before} pixels"
    );
    assert!(
        left * 5 < before,
        "the scout still shows {left} unseen pixels of {before}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The `data:` URLs of a report's images, decoded.
fn embedded_pngs(html: &str) -> Vec<Vec<u8>> {
    let decode = |s: &str| {
        let value = |c: u8| match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' => 62,
            _ => 63,
        } as u32;
        let mut out = Vec::new();
        for chunk in s.as_bytes().chunks(4) {
            let pad = chunk.iter().filter(|&&c| c == b'=').count();
            let n = chunk
                .iter()
                .map(|&c| if c == b'=' { 0 } else { value(c) })
                .fold(0u32, |n, v| n << 6 | v);
            out.extend(&n.to_be_bytes()[1..4 - pad]);
        }
        out
    };
    html.split("src=\"data:image/png;base64,")
        .skip(1)
        .map(|rest| decode(&rest[..rest.find('"').unwrap()]))
        .collect()
}

#[test]
fn the_report_lists_the_polyps_with_sizes_segments_and_c_rads_and_their_views() {
    let Some(display) = Display::start() else {
        return;
    };
    let dir = scratch("report");
    let (ct, truth) = (dir.join("colon.nii.gz"), dir.join("truth.json"));
    // Full size: the small phantom's 1.5 mm voxels and narrow lumen are no place to size a
    // polyp (voyage-view's tests/polyp.rs holds the tool to 0.5 mm on full-size phantoms).
    colon(&ct, &["--truth", truth.to_str().unwrap()]);
    let t = read_json(&truth);
    let v3 = |v: &Value| {
        DVec3::new(
            v[0].as_f64().unwrap(),
            v[1].as_f64().unwrap(),
            v[2].as_f64().unwrap(),
        )
    };
    let d = |x: &Value| x["diameter_mm"].as_f64().unwrap();
    let polyp = t["polyps"]
        .as_array()
        .unwrap()
        .iter()
        .max_by(|a, b| d(a).total_cmp(&d(b)))
        .unwrap()
        .clone();
    let (c, r, into) = (
        v3(&polyp["center_mm"]),
        d(&polyp) / 2.0,
        v3(&polyp["direction"]),
    );
    let facing =
        voyage_nav::Pose::looking(c + (r + 6.0) * into, -into, into.any_orthonormal_vector());
    let export = dir.join("export");
    let steps = serde_json::json!([
        {"centerline": false}, {"pose": facing.to_array()}, {"wait": 3},
        {"polyp": {"at": [0.5, 0.5], "note": "sessile"}},
        {"marker": {"at": [0.5, 0.5], "note": "also seen", "kind": "diverticulum"}},
        {"export": export}, {"wait": 2}, {"quit": true}
    ]);
    let rep = view_script(&display, &ct, &["--paused"], steps, &dir, "script");
    let markers = rep["markers"].as_array().unwrap();
    assert_eq!(markers.len(), 2, "{rep}");
    let size = markers[0]["size_mm"]
        .as_f64()
        .expect("the polyp has a size");
    eprintln!(
        "colon phantom: the {:.1} mm polyp measured {size:.2} mm in the window",
        2.0 * r
    );
    assert!(
        (size - 2.0 * r).abs() <= 0.5,
        "{size:.2} against {:.1}",
        2.0 * r
    );
    assert_eq!(markers[0]["kind"], "polyp");
    let html = std::fs::read_to_string(export.join("report.html")).unwrap();
    let expected = if size >= 10.0 {
        "C3"
    } else if size >= 6.0 {
        "C2"
    } else {
        "C1"
    };
    assert!(
        html.contains(&format!("<span id=\"c-rads\">{expected}</span>")),
        "C-RADS {expected} missing"
    );
    let segment = polyp["segment"].as_str().unwrap();
    let rows: Vec<&str> = html.split("<tr class=\"finding\">").skip(1).collect();
    assert_eq!(rows.len(), 2);
    assert!(
        rows[0].contains("<td>polyp</td>") && rows[0].contains(&format!("<td>{size:.1} mm</td>")),
        "{}",
        rows[0]
    );
    assert!(
        rows[0].contains(&format!("<td>{segment}</td>")),
        "segment {segment} not in {}",
        &rows[0][..300.min(rows[0].len())]
    );
    assert!(rows[1].contains("<td>diverticulum</td>"));
    assert!(html.contains("id=\"coverage\""));
    // The images are the marked views: the snapshots the export wrote, byte for byte.
    let pngs = embedded_pngs(&html);
    assert_eq!(pngs.len(), 2);
    for (png, label) in pngs.iter().zip(["M1", "M2"]) {
        let file = std::fs::read(export.join(format!("finding_{label}.png"))).unwrap();
        assert!(png == &file, "{label}'s image is not its snapshot");
        assert_eq!(image::load_from_memory(png).unwrap().width(), 512);
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Issue 24, item 2: choosing cecum → rectum when the study opens (at the rectum) flies from
/// the cecum, instead of saying "goal reached" and stopping.
#[test]
fn cecum_to_rectum_at_the_start_flies_from_the_cecum() {
    let Some(display) = Display::start() else {
        return;
    };
    let dir = scratch("backward");
    let ct = dir.join("colon.nii.gz");
    small_colon(&ct, &[]);
    let steps = serde_json::json!([
        {"record": "start"}, {"direction": "backward"}, {"play": true}, {"wait": 30},
        {"record": "after"}, {"quit": true}
    ]);
    let r = view_script(&display, &ct, &["--paused"], steps, &dir, "script");
    assert_eq!(
        r["playing"], true,
        "the backward flight stopped at once: {r}"
    );
    let (start, _) = pose(&r["recorded"]["start"]);
    let (after, _) = pose(&r["recorded"]["after"]);
    assert!(
        start.distance(after) > 50.0,
        "the camera stayed by the rectum: {:.0} mm from where it opened",
        start.distance(after)
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `voyage demo --small --paused --script` with `steps`, run in `dir` (written there as
/// script.json), which must succeed; its `--report`.
fn small_demo_script(display: &Display, steps: Value, dir: &Path) -> Value {
    let script = dir.join("script.json");
    std::fs::write(&script, steps.to_string()).unwrap();
    let report = dir.join("report.json");
    let out = voyage(display)
        .current_dir(dir)
        .args(["demo", "--small", "--paused", "--script"])
        .arg(&script)
        .arg("--report")
        .arg(&report)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    read_json(&report)
}

/// O (switch position) on a study of one position says so and keeps the study open: it was
/// dropped, the window showed nothing, and a script waited for a study for ever.
#[test]
fn switching_position_with_one_position_open_keeps_the_study() {
    let Some(display) = Display::start() else {
        return;
    };
    let dir = scratch("one-position");
    let steps = serde_json::json!([{"switch_position": true}, {"wait": 2}, {"quit": true}]);
    let r = small_demo_script(&display, steps, &dir);
    assert_eq!(r["ready"], true, "{r}");
    assert!(r["pose"].is_array(), "{r}");
    assert_eq!(r["status"], "the exam has one position open");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Issue 24, item 7: after Export the window says where the files went, in full, however
/// the folder was given.
#[test]
fn export_says_where_the_files_went_in_full() {
    let Some(display) = Display::start() else {
        return;
    };
    let dir = scratch("export-path");
    let steps = serde_json::json!([{"export": "relative-findings"}, {"wait": 2}, {"quit": true}]);
    let r = small_demo_script(&display, steps, &dir);
    let status = r["status"].as_str().unwrap();
    let full = dir.join("relative-findings");
    assert!(full.join("report.html").is_file());
    assert!(
        status.contains(&full.display().to_string()),
        "the status does not name {}: {status}",
        full.display()
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Issue 24, item 3: the frame statistics count only frames drawn with a study (not the
/// loading), and the read-out's two figures are one measure.
#[test]
fn frame_statistics_count_only_frames_with_a_study() {
    let Some(display) = Display::start() else {
        return;
    };
    let dir = scratch("frames");
    let r = small_demo_script(
        &display,
        serde_json::json!([{"wait": 20}, {"quit": true}]),
        &dir,
    );
    let (counted, drawn) = (
        r["frame_ms"]["frames"].as_u64().unwrap(),
        r["frames"].as_u64().unwrap(),
    );
    assert!(
        counted <= drawn,
        "{counted} frames timed, {drawn} drawn with the study"
    );
    let (mean, fps) = (
        r["frame_ms"]["mean"].as_f64().unwrap(),
        r["frame_ms"]["fps"].as_f64().unwrap(),
    );
    assert!(
        (mean * fps - 1000.0).abs() < 1e-6,
        "mean {mean} ms and {fps} fps disagree"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Issue 24, item 8a: a folder holding two series of the same size loads one by UID order;
/// `prep` and the window both say which, and that another exists.
#[test]
fn a_tie_between_two_series_is_named_in_prep_and_the_window() {
    let dir = scratch("two-series");
    let both = dir.join("both");
    std::fs::create_dir_all(&both).unwrap();
    for seed in ["3", "4"] {
        let series = dir.join(format!("series-{seed}"));
        small_colon(
            &dir.join(format!("colon-{seed}.nii.gz")),
            &["--seed", seed, "--dicom", series.to_str().unwrap()],
        );
        for e in std::fs::read_dir(&series).unwrap() {
            let f = e.unwrap().path();
            let name = format!("{seed}-{}", f.file_name().unwrap().to_string_lossy());
            std::fs::rename(&f, both.join(name)).unwrap();
        }
    }
    let said = |text: &str| text.contains("holds 2 series") && text.contains("tied with");
    let (summary, err) = prep_json(&both, &dir.join("prep"));
    assert!(said(&err), "prep did not name the tie: {err}");
    assert!(
        summary["warnings"]
            .as_array()
            .unwrap()
            .iter()
            .any(|w| said(w.as_str().unwrap())),
        "{summary}"
    );
    let Some(display) = Display::start() else {
        return;
    };
    let r = view_script(
        &display,
        &both,
        &["--paused"],
        serde_json::json!([{"quit": true}]),
        &dir,
        "script",
    );
    let warnings = r["colon"]["warnings"].as_array().unwrap();
    assert!(
        warnings.iter().any(|w| said(w.as_str().unwrap())),
        "the window did not name the tie: {warnings:?}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Length of clear lumen along the view from `pose` (mm, up to 200): how far down the colon
/// the camera looks.
fn clear_view_mm(study: &voyage_core::Study, pose: &Value) -> f64 {
    let (at, q) = self::pose(pose);
    let dir = q * DVec3::Z;
    let mut t = 0.0;
    while t < 200.0 && study.ds.sample(at + dir * t) > 0.0 {
        t += 0.5;
    }
    t
}

/// Issue 24, item 1: a jump and a click on a slice by the wall put the camera on a viewing
/// spot, well off the wall and looking down the colon, not against or at the wall.
#[test]
fn jumps_and_slice_clicks_land_on_a_viewing_spot() {
    let Some(display) = Display::start() else {
        return;
    };
    let dir = scratch("spot");
    let ct = dir.join("colon.nii.gz");
    small_colon(&ct, &[]);
    // The window's own preprocessing, here, to measure where the camera stands.
    let loaded = voyage_io::load(&ct, &Default::default()).unwrap();
    let g = loaded.volume.geometry().clone();
    let study = voyage_core::prepare(loaded.volume, &Default::default(), |_| {}).unwrap();
    let cl = &study.centerline.points_mm;
    let c = DVec3::from_array(cl[cl.len() / 3]);
    let radius = study.ds.sample(c) as f64;
    // A point of the lumen 1.2 mm from the wall, toward the wall nearest the centerline.
    let grad = |p: DVec3| {
        let d = |q: DVec3| study.ds.sample(q) as f64;
        DVec3::new(
            d(p + DVec3::X * 0.5) - d(p - DVec3::X * 0.5),
            d(p + DVec3::Y * 0.5) - d(p - DVec3::Y * 0.5),
            d(p + DVec3::Z * 0.5) - d(p - DVec3::Z * 0.5),
        )
        .normalize()
    };
    let out = -grad(c);
    let mut by_wall = c;
    while study.ds.sample(by_wall + out * 0.2) as f64 > 1.2 {
        by_wall += out * 0.2;
    }
    let lps = g.local_to_patient(by_wall).to_array();
    let steps = serde_json::json!([
        {"jump": 0.6}, {"wait": 60}, {"record": "jump"}, {"move_to": lps}, {"wait": 60}, {"record": "click"}, {"quit": true}
    ]);
    let r = view_script(&display, &ct, &["--paused"], steps, &dir, "script");
    for name in ["jump", "click"] {
        let pose = &r["recorded"][name];
        let (at, _) = self::pose(pose);
        let wall = study.ds.sample(at) as f64;
        let clear = clear_view_mm(&study, pose);
        eprintln!("{name}: {wall:.1} mm from the wall, {clear:.0} mm of lumen ahead");
        assert!(
            clear >= 2.5 * wall,
            "after the {name} the camera looks at the wall: {clear:.0} mm ahead, {wall:.1} mm off it"
        );
        if name == "click" {
            assert!(
                wall >= 0.5 * radius,
                "the click by the wall put the camera {wall:.1} mm from it (lumen radius {radius:.1} mm)"
            );
            assert!(
                at.distance(by_wall) < radius,
                "the camera went far from the click"
            );
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Issue 24, item 4: every slice panel shows the patient's side at all four edges, always,
/// and a prone exam is shown in the standard display (anterior up) with its position named.
#[test]
fn every_slice_shows_its_orientation_letters_and_a_prone_exam_is_named() {
    let Some(display) = Display::start() else {
        return;
    };
    let dir = scratch("letters");
    let ct = dir.join("prone.nii.gz");
    small_colon(&ct, &["--prone"]);
    let shot = dir.join("window.png");
    let steps = serde_json::json!([{"wait": 3}, {"screenshot": shot}, {"quit": true}]);
    let r = view_script(
        &display,
        &ct,
        &["--paused", "--position", "HFP"],
        steps,
        &dir,
        "script",
    );
    assert_eq!(r["colon"]["position"], "HFP", "{}", r["colon"]);
    let letters: Vec<Vec<String>> = serde_json::from_value(r["slice_letters"].clone()).unwrap();
    assert_eq!(
        letters,
        [
            ["R", "L", "A", "P"],
            ["R", "L", "S", "I"],
            ["A", "P", "S", "I"]
        ]
        .map(|p| p.map(String::from).to_vec())
        .to_vec(),
        "letters drawn (left, right, top, bottom) on axial, coronal, sagittal"
    );
    assert!(shot.is_file());
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The truth's centerline point of arc `s`, and the arc of the truth's centerline point
/// nearest `p`.
fn truth_point(t: &Value, s: f64) -> DVec3 {
    let arcs: Vec<f64> = serde_json::from_value(t["centerline_arc_mm"].clone()).unwrap();
    let pts: Vec<[f64; 3]> = serde_json::from_value(t["centerline_mm"].clone()).unwrap();
    DVec3::from_array(pts[arcs.partition_point(|&a| a < s).min(pts.len() - 1)])
}

fn truth_arc(t: &Value, p: DVec3) -> f64 {
    let arcs: Vec<f64> = serde_json::from_value(t["centerline_arc_mm"].clone()).unwrap();
    let pts: Vec<[f64; 3]> = serde_json::from_value(t["centerline_mm"].clone()).unwrap();
    let i = (0..pts.len())
        .min_by(|&a, &b| {
            DVec3::from_array(pts[a])
                .distance(p)
                .total_cmp(&DVec3::from_array(pts[b]).distance(p))
        })
        .unwrap();
    arcs[i]
}

/// Issue 39: a folder holding the exam supine and prone opens both; the other position's
/// scout marks where the camera's place lies in it, O switches there, and a marker is
/// looked up in the other position where the truth puts it.
#[test]
fn both_positions_open_linked_and_a_marker_is_shown_in_the_other() {
    let Some(display) = Display::start() else {
        return;
    };
    let dir = scratch("pair");
    let exam = dir.join("exam");
    let out = |n: &str| dir.join(n).to_str().unwrap().to_string();
    cli_json(&[
        "phantom",
        "colon",
        "--pair",
        "--small",
        "--tagged-fluid",
        "--out",
        &out("p.nii.gz"),
        "--truth",
        &out("p.json"),
        "--dicom",
        exam.to_str().unwrap(),
    ]);
    let (supine, prone, link) = (
        read_json(&dir.join("p-supine.json")),
        read_json(&dir.join("p-prone.json")),
        read_json(&dir.join("p.json")),
    );
    let shot = dir.join("prone.png");
    let exported = dir.join("exported");
    let steps = serde_json::json!([
        {"jump": 0.62}, {"wait": 5}, {"record": "supine"},
        {"marker": {"at": [0.5, 0.5], "note": "look it up", "kind": "polyp"}},
        {"switch_position": true}, {"wait": 5}, {"record": "prone"},
        {"switch_position": true}, {"wait": 5},
        {"show_in_other": "M1"}, {"wait": 10}, {"screenshot": shot.to_str().unwrap()},
        {"marker": {"at": [0.5, 0.5], "note": "the same, prone", "kind": "polyp"}},
        {"export": exported.to_str().unwrap()},
        {"quit": true}
    ]);
    let r = view_script(&display, &exam, &["--paused"], steps, &dir, "script");
    let prone_arc = |s: f64| -> f64 {
        let a: Vec<f64> = serde_json::from_value(link["supine_arc_mm"].clone()).unwrap();
        let b: Vec<f64> = serde_json::from_value(link["prone_arc_mm"].clone()).unwrap();
        b[a.partition_point(|&x| x < s).min(b.len() - 1)]
    };
    // Switching stands the camera where the truth puts the supine camera's place.
    let (at_supine, _) = pose(&r["recorded"]["supine"]);
    let (at_prone, _) = pose(&r["recorded"]["prone"]);
    let want = truth_point(&prone, prone_arc(truth_arc(&supine, at_supine)));
    let off = at_prone.distance(want);
    eprintln!("switched: {off:.1} mm from the truth's place");
    assert!(off <= 12.0, "switched {off:.1} mm from the place");
    // The marker looked up in prone lies by the truth's place of the supine marker.
    assert_eq!(r["positions"]["shown"], "prone", "{r}");
    assert_eq!(r["positions"]["other"], "supine");
    let m = DVec3::from_array(
        serde_json::from_value(r["positions"]["other_markers"][0]["position_mm"].clone()).unwrap(),
    );
    let (label, there): (String, [f64; 3]) =
        serde_json::from_value(r["positions"]["looked_up"].clone()).unwrap();
    assert_eq!(label, "M1 (supine)");
    let there = DVec3::from_array(there);
    let want = truth_point(&prone, prone_arc(truth_arc(&supine, m)));
    let radius = 16.0; // the small colon's widest lumen, with the wall
    assert!(
        there.distance(want) <= radius,
        "M1 looked up {:.1} mm from the truth's centerline point there",
        there.distance(want)
    );
    let img = image::open(&shot).unwrap().to_rgba8();
    assert!(img.width() > 0);
    // The window exported each position into a folder of its name; `voyage report` on the
    // exam lists the finding marked in both positions once, with both places.
    for p in ["supine", "prone"] {
        assert!(exported.join(p).join("findings.json").exists(), "{p}");
    }
    let report = dir.join("report");
    let out = Command::new(env!("CARGO_BIN_EXE_voyage"))
        .arg("report")
        .arg(&exam)
        .arg("--findings")
        .arg(&exported)
        .arg("--out")
        .arg(&report)
        .arg("--no-coverage")
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let html = std::fs::read_to_string(report.join("report.html")).unwrap();
    assert_eq!(html.matches("<tr class=\"finding\">").count(), 1, "{html}");
    assert!(html.contains("look it up") && html.contains("the same, prone"));
    assert!(html.contains("stayed on the wall"), "{html}");
    assert!(report.join("supine").join("report.html").exists());
    std::fs::remove_dir_all(&dir).unwrap();
}
