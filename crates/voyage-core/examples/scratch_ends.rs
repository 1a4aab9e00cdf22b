use voyage_core::{prep, Geometry, Volume};
fn main() {
    let raw = std::fs::read("/tmp/colon-a.u8").unwrap();
    let g = Geometry::new([512, 512, 321], [0.820312, 0.820312, 1.25], [0.0; 3]).unwrap();
    let m = Volume::from_vec(g, raw.iter().map(|&v| v as i16).collect()).unwrap();
    let s = prep::prepare(m, &Default::default(), |_| {}).unwrap();
    println!("len {}", s.centerline.length_mm);
    let pts: Vec<String> = s.centerline.points_mm.iter().map(|p| format!("{:.2} {:.2} {:.2}", p[0]/0.820312, p[1]/0.820312, p[2]/1.25)).collect();
    std::fs::write("/tmp/cl.txt", pts.join("\n")).unwrap();
}
