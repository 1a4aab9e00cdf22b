//! Runs every visibility strategy over a list of cameras, checks each one's triangle-id
//! buffer against drawing everything, and counts what each drew: the exactness proof and
//! the figures of the paper's Table 1, shared by the tests and `voyage bench render`.

use std::time::Instant;

use glam::{DQuat, DVec3};
use serde::Serialize;

use super::{
    mesh::CellMesh,
    raster::{Frame, Rasterizer, Shading, View, shade},
    shading::Lighting,
    visibility::{Strategy, Visibility},
};
use voyage_core::{Cells, rng::Rng};
use voyage_nav::{Camera, Pose};

#[derive(Clone, Debug, Serialize)]
pub struct StrategyStats {
    pub strategy: Strategy,
    pub frames: usize,
    pub mean_triangles: f64,
    pub max_triangles: usize,
    pub mean_cells: f64,
    /// Mean triangles of `all` over mean triangles of this strategy (the paper's MC : ours).
    pub ratio_to_all: f64,
    /// Frames whose id buffer differs from `all`'s, and the differing pixels over all frames.
    pub inexact_frames: usize,
    pub differing_pixels: usize,
    /// Visibility and rasterization, one thread (ms per frame, mean and max).
    pub draw_ms_mean: f64,
    pub draw_ms_max: f64,
    /// Depth-buffer pixels the strategy read per frame.
    pub depth_pixels_read: f64,
    /// Cells drawn in each frame, when asked for (to replay them on a GPU).
    #[serde(skip)]
    pub cell_lists: Vec<Vec<u32>>,
}

#[derive(Clone, Debug, Serialize)]
pub struct Survey {
    pub width: u32,
    pub height: u32,
    pub frames: usize,
    pub strategies: Vec<StrategyStats>,
    /// Copying the frame out as an image (ms); the lighting itself is done per vertex while
    /// drawing, so it is inside each strategy's draw time.
    pub shade_ms_mean: f64,
    /// Every strategy's id buffer equalled `all`'s in every frame.
    pub exact: bool,
}

impl Survey {
    pub fn get(&self, s: Strategy) -> Option<&StrategyStats> {
        self.strategies.iter().find(|x| x.strategy == s)
    }
}

/// Draws each camera with `all` and with every other strategy (each keeping its own state
/// from frame to frame, as in a flight) and compares the id buffers.
pub fn survey(
    mesh: &CellMesh,
    cells: &Cells,
    cameras: &[Camera],
    width: u32,
    height: u32,
    strategies: &[Strategy],
    keep_lists: bool,
) -> Survey {
    let lighting = Lighting::default();
    let mut order = vec![Strategy::All];
    order.extend(strategies.iter().copied().filter(|&s| s != Strategy::All));
    let mut vis: Vec<Visibility> = order.iter().map(|&s| Visibility::new(cells, s)).collect();
    let mut stats: Vec<StrategyStats> = order
        .iter()
        .map(|&strategy| StrategyStats {
            strategy,
            frames: 0,
            mean_triangles: 0.0,
            max_triangles: 0,
            mean_cells: 0.0,
            ratio_to_all: 0.0,
            inexact_frames: 0,
            differing_pixels: 0,
            draw_ms_mean: 0.0,
            draw_ms_max: 0.0,
            depth_pixels_read: 0.0,
            cell_lists: Vec::new(),
        })
        .collect();
    let mut reference = Frame::new(width, height);
    let mut frame = Frame::new(width, height);
    let mut shade_ms = 0.0;
    let shading = Shading::new(&lighting);
    for camera in cameras {
        let view = View::new(camera, width, height);
        let raster = Rasterizer::new(mesh, view, &shading);
        for (k, (v, st)) in vis.iter_mut().zip(stats.iter_mut()).enumerate() {
            let target = if k == 0 { &mut reference } else { &mut frame };
            let t = Instant::now();
            let drawn = v.draw(target, &raster, cells);
            let ms = t.elapsed().as_secs_f64() * 1e3;
            st.frames += 1;
            st.mean_triangles += drawn.triangles as f64;
            st.max_triangles = st.max_triangles.max(drawn.triangles);
            st.mean_cells += drawn.cells.len() as f64;
            st.draw_ms_mean += ms;
            st.draw_ms_max = st.draw_ms_max.max(ms);
            st.depth_pixels_read += drawn.depth_pixels_read as f64;
            if keep_lists {
                st.cell_lists.push(drawn.cells);
            }
            if k > 0 {
                let diff = frame.id_differences(&reference);
                if diff > 0 {
                    st.inexact_frames += 1;
                    st.differing_pixels += diff;
                }
            }
        }
        let t = Instant::now();
        std::hint::black_box(shade(&reference));
        shade_ms += t.elapsed().as_secs_f64() * 1e3;
    }
    let n = cameras.len().max(1) as f64;
    for st in &mut stats {
        st.mean_triangles /= n;
        st.mean_cells /= n;
        st.draw_ms_mean /= n;
        st.depth_pixels_read /= n;
    }
    let all = stats[0].mean_triangles;
    for st in &mut stats {
        st.ratio_to_all = if st.mean_triangles > 0.0 {
            all / st.mean_triangles
        } else {
            0.0
        };
    }
    let exact = stats.iter().all(|s| s.inexact_frames == 0);
    Survey {
        width,
        height,
        frames: cameras.len(),
        strategies: stats,
        shade_ms_mean: shade_ms / n,
        exact,
    }
}

/// Random look-around: at `n` positions taken evenly from `poses`, a view in a uniformly
/// random direction with a random roll.
pub fn look_around(poses: &[Pose], n: usize, seed: u64) -> Vec<Pose> {
    let mut rng = Rng::new(seed, 0x100C_A200);
    if poses.is_empty() {
        return Vec::new();
    }
    (0..n)
        .map(|i| {
            let at = poses[i * poses.len() / n.max(1)].position;
            let forward = loop {
                let d = DVec3::new(rng.gauss(), rng.gauss(), rng.gauss());
                if d.length() > 1e-6 {
                    break d.normalize();
                }
            };
            let roll = DQuat::from_axis_angle(forward, rng.uniform() * std::f64::consts::TAU);
            let up = roll * forward.any_orthonormal_vector();
            Pose::looking(at, forward, up)
        })
        .collect()
}
