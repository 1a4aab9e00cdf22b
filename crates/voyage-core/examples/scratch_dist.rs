use std::time::Instant;
use voyage_core::{distance, field::bounding_box, Geometry, Volume};
fn main() {
    let raw = std::fs::read("/tmp/colon-a.u8").unwrap();
    let g = Geometry::new([512, 512, 321], [0.820312, 0.820312, 1.25], [0.0; 3]).unwrap();
    let m = Volume::from_vec(g, raw).unwrap();
    for _ in 0..3 {
        let t = Instant::now();
        let grid = bounding_box(&m, 1, |v| v != 0).unwrap();
        let t_bb = t.elapsed();
        let t = Instant::now();
        let ds = distance::distance_to_wall(&m).unwrap();
        let t_ds = t.elapsed();
        let t = Instant::now();
        let idx = ds.data.iter().position(|&d| d > 0.0).unwrap();
        let src = ds.grid.global_of_index(idx);
        let geo = distance::geodesic_distance(&m, &grid, src).unwrap();
        let t_dt = t.elapsed();
        println!("box {:?} bb {:?} ds {:?} dt {:?} reached {} max {}", grid.dims, t_bb, t_ds, t_dt, geo.reached, geo.max_mm);
    }
}
