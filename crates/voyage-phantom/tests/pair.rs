//! The phantom pair (issue 39): one colon supine and prone, its truth linking the two.

use glam::DVec3;
use voyage_phantom::{
    ColonOptions, Truth,
    pair::{PairTruth, colon_pair},
};

fn point_at(t: &Truth, s: f64) -> DVec3 {
    let i = t
        .centerline_arc_mm
        .partition_point(|&a| a < s)
        .min(t.centerline_mm.len() - 1);
    DVec3::from_array(t.centerline_mm[i])
}

#[test]
fn the_pair_is_one_colon_that_moved_its_fluid_and_stool_with_the_patient() {
    let pair = colon_pair(&ColonOptions {
        seed: 4,
        tagged_fluid: true,
        tagged_stool: true,
        ..Default::default()
    })
    .unwrap();
    let (s, p, link) = (&pair.supine.truth, &pair.prone.truth, &pair.truth);
    assert_eq!((s.position.as_str(), p.position.as_str()), ("HFS", "HFP"));
    // The link's arcs rise on both sides and span both centerlines.
    for arcs in [&link.supine_arc_mm, &link.prone_arc_mm] {
        assert!(arcs.windows(2).all(|w| w[1] > w[0]));
    }
    assert!((link.supine_arc_mm.last().unwrap() - s.centerline_length_mm).abs() < 1.0);
    assert!((link.prone_arc_mm.last().unwrap() - p.centerline_length_mm).abs() < 1.0);
    assert_eq!(PairTruth::from_json(&link.to_json()).unwrap(), *link);
    // The mobile loops moved by centimetres, the fixed parts (rectum, ascending) not.
    let moved = |name: &str| {
        let seg = s.segments.iter().find(|g| g.name == name).unwrap();
        let mut most: f64 = 0.0;
        let mut arc = seg.start_arc_mm;
        while arc < seg.end_arc_mm {
            most = most.max(point_at(s, arc).distance(point_at(p, link.prone_arc(arc))));
            arc += 2.0;
        }
        most
    };
    let (transverse, sigmoid, rectum) = (moved("transverse"), moved("sigmoid"), moved("rectum"));
    eprintln!(
        "moved: transverse {transverse:.1} mm, sigmoid {sigmoid:.1} mm, rectum {rectum:.1} mm"
    );
    assert!(transverse >= 18.0 && sigmoid >= 10.0 && rectum <= 1.0);
    // Polyps keep their place on the wall: the same place along the colon, the same side.
    for (a, b) in s.polyps.iter().zip(&p.polyps) {
        assert_eq!(a.segment, b.segment);
        assert!(
            (link.prone_arc(a.arc_mm) - b.arc_mm).abs() < 1.0,
            "{}",
            a.segment
        );
        let (da, db) = (
            DVec3::from_array(a.direction),
            DVec3::from_array(b.direction),
        );
        assert!(da.angle_between(db).to_degrees() < 30.0, "{}", a.segment);
    }
    // Stool lies on each position's dependent side; the fluid's pools change sides too.
    for t in [s, p] {
        let gravity = DVec3::from_array(t.gravity_lps);
        for lump in &t.stool {
            let c = DVec3::from_array(lump.center_mm);
            let axis = point_at(t, lump.arc_mm);
            let side = (c - axis).normalize();
            // Round the colon, gravity's side: where the colon runs along gravity, none.
            let t = (point_at(t, lump.arc_mm + 3.0) - point_at(t, lump.arc_mm - 3.0)).normalize();
            let down = gravity - t * gravity.dot(t);
            if down.length() > 0.3 {
                assert!(
                    side.dot(down.normalize()) > 0.8,
                    "{} stool not on the dependent side: {:.2}",
                    lump.segment,
                    side.dot(down.normalize())
                );
            }
        }
        for pool in &t.fluid_pools {
            assert_eq!(pool.gravity_lps, t.gravity_lps);
        }
    }
    // A stretch collapsed in one position is open in the other.
    let collapsed = |t: &Truth| {
        t.collapsed
            .iter()
            .map(|c| c.segment.clone())
            .collect::<Vec<_>>()
    };
    assert_eq!(collapsed(s), ["descending"]);
    assert_eq!(collapsed(p), ["sigmoid"]);
}
