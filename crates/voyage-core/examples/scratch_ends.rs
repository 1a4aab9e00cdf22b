use voyage_core::{prep, Geometry, Volume};
fn main() {
    let raw = std::fs::read("/tmp/colon-a.u8").unwrap();
    let g = Geometry::new([512, 512, 321], [0.820312, 0.820312, 1.25], [0.0; 3]).unwrap();
    let m = Volume::from_vec(g, raw.iter().map(|&v| v as i16).collect()).unwrap();
    let mut o = prep::PrepOptions::default();
    let t: Vec<f64> = std::env::args().skip(1).map(|a| a.parse().unwrap()).collect();
    if t.len() == 3 { o.endpoints.target_mm = Some(glam::DVec3::new(t[0]*0.820312, t[1]*0.820312, t[2]*1.25)); }
    let s = prep::prepare(m, &o, |_| {}).unwrap();
    println!("len {} src {:?} dst {:?}\n{:?}", s.centerline.length_mm, s.source, s.target, s.timings);
    let pts: Vec<String> = s.centerline.points_mm.iter().map(|p| format!("{:.2} {:.2} {:.2}", p[0]/0.820312, p[1]/0.820312, p[2]/1.25)).collect();
    std::fs::write("/tmp/cl.txt", pts.join("\n")).unwrap();
}
