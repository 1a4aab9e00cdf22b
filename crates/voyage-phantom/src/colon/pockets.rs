//! Small-bowel gas pockets: gas that is not colon, away from everything else.

use glam::DVec3;

use super::streams::STREAM_GAS;
use crate::{
    body::Body,
    frame::Frame,
    rng::Rng,
    tube::{Blob, BlobKind, Tube, segment_distance},
};

/// A few small-bowel gas pockets (10–20 mm) in the central abdomen, each at least 10 mm
/// (full size) from the colon's lumen, the spine, the lungs, the abdominal wall, each
/// other and the `obstacles` (capsules: ends and radius; opacified loops, the catheter).
/// Rejection sampling with a fixed number of tries and draws: deterministic, and where they
/// always were when there are no obstacles.
pub(super) fn make_pockets(
    frame: &Frame,
    tube: &Tube,
    body: &Body,
    obstacles: &[(DVec3, DVec3, f64)],
    seed: u64,
) -> Vec<Blob> {
    let s = frame.scale;
    let mut rng = Rng::new(seed, STREAM_GAS);
    let wall = frame.thin(1.5, 0.8);
    let clear = 10.0 * s;
    let mut pockets: Vec<Blob> = Vec::new();
    let ax = &tube.axis;
    for _ in 0..400 {
        if pockets.len() == 4 {
            break;
        }
        let r = rng.range(5.0, 10.0) * s;
        let c = frame.pos([
            rng.range(110.0, 274.0),
            rng.range(100.0, 260.0),
            rng.range(60.0, 330.0),
        ]);
        let colon_ok = ax
            .points
            .iter()
            .zip(&ax.radius)
            .step_by(2)
            .all(|(p, rc)| p.distance(c) - rc - r - wall - tube.wall_mm >= clear);
        let body_ok = body.skin_sdf(c) + r + wall + clear <= -body.rim
            && body.spine.sdf_xy(c) >= r + wall + clear
            && body.lungs.iter().all(|l| l.sdf(c) >= r + wall + clear);
        let apart = pockets
            .iter()
            .all(|o| o.center.distance(c) - o.radius - r - 2.0 * wall >= clear);
        let free = obstacles
            .iter()
            .all(|&(a, b, ro)| segment_distance(c, a, b) - ro - r - wall >= clear);
        if colon_ok && body_ok && apart && free {
            pockets.push(Blob {
                kind: BlobKind::Pocket,
                center: c,
                radius: r,
                stalk: None,
                wall_mm: wall,
                content_hu: 0.0,
            });
        }
    }
    pockets
}
