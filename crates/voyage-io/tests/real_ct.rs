//! A real, routine abdominal CT (not insufflated, 3 mm): the gas voyage takes for the colon
//! must lie in the colon (an automatic segmenter's colon mask is beside the CT), and nothing
//! may come from the lungs or from outside the body.

use voyage_core::{ComponentKind, SegmentOptions, segment};
use voyage_io::{LoadOptions, load};

#[test]
fn abdomen_gas_found_in_the_colon() {
    let Some(data) = voyage_phantom::fixtures::shared_data() else {
        return;
    };
    let dir = data.join("ct");
    let ct = load(&dir.join("abdomen-3mm.nii.gz"), &LoadOptions::default())
        .unwrap()
        .volume;
    let colon = load(
        &dir.join("abdomen-3mm-colon.nii.gz"),
        &LoadOptions::default(),
    )
    .unwrap()
    .volume;
    assert_eq!(ct.geometry().dims, colon.geometry().dims);
    let s = segment(&ct, &SegmentOptions::default()).unwrap();
    assert!(!s.from_mask);
    let lumen = s.lumen.data();
    let inside = lumen
        .iter()
        .zip(colon.data())
        .filter(|&(&l, &c)| l != 0 && c != 0)
        .count();
    let frac = inside as f64 / s.lumen_voxels as f64;
    assert!(
        s.lumen_voxels > 1000,
        "only {} voxels of gas",
        s.lumen_voxels
    );
    assert!(
        frac > 0.9,
        "only {:.1}% of the gas found lies in the colon mask",
        100.0 * frac
    );
    // Nothing from outside the body: no lumen voxel on the border of any slice.
    let [nx, ny, nz] = s.lumen.dims();
    for k in 0..nz {
        for j in 0..ny {
            for i in [0, nx - 1] {
                assert_eq!(s.lumen.get(i, j, k), 0);
            }
        }
        for i in 0..nx {
            for j in [0, ny - 1] {
                assert_eq!(s.lumen.get(i, j, k), 0);
            }
        }
    }
    // Nothing from the lungs: the chosen component is colon, and no lung-like gas (mostly
    // between −950 and −500 HU) is in it.
    assert_eq!(
        s.components
            .iter()
            .filter(|c| c.kind == ComponentKind::Colon)
            .count(),
        1
    );
    let colon_comp = s
        .components
        .iter()
        .find(|c| c.kind == ComponentKind::Colon)
        .unwrap();
    assert!(
        colon_comp.dark_fraction.unwrap() > 0.3,
        "the chosen gas looks like lung"
    );
}
