use std::time::Instant;
use voyage_core::{prep, Geometry, Volume};
fn main() {
    let raw = std::fs::read("/tmp/colon-a.u8").unwrap();
    let g = Geometry::new([512, 512, 321], [0.820312, 0.820312, 1.25], [0.0; 3]).unwrap();
    let m = Volume::from_vec(g, raw.iter().map(|&v| v as i16).collect()).unwrap();
    for _ in 0..2 {
        let t = Instant::now();
        let s = prep::prepare(m.clone(), &Default::default(), |st| eprint!("{} ", st.name())).unwrap();
        eprintln!();
        println!("{:?} total {:?}", s.timings, t.elapsed());
        println!("lumen {} comps {} src {:?} dst {:?} cl {:.0} mm pts {} tris {} verts {} cells {}", s.segmentation.lumen_voxels, s.segmentation.components.len(), s.source_mm(), s.target_mm(), s.centerline.length_mm, s.centerline.points_mm.len(), s.surface.mesh.triangles.len(), s.surface.mesh.positions.len(), s.cells.cells.len());
    }
}
