#!/usr/bin/env python3
"""The cleansing figures of a tagged exam against a given colon mask, and where they come from.

usage: cleanse_figures.py CT.nii.gz COLON.nii.gz PREP_DIR [--top N]

CT is the exam, COLON its given colon mask (same grid), PREP_DIR what `voyage prep CT --out
PREP_DIR` wrote (cleansed.nii.gz, written where the exam holds tagged fluid, and
centerline.json). Prints:

- tagged material left: voxels above 200 HU in the cleansed CT inside COLON dilated by 4
  voxels (6-connected steps), as a share of those above 200 HU there before;
- voxels changed outside the colon: voxels the cleansing changed outside COLON dilated by 12
  voxels, as a share of the voxels there;

and, for each, the largest connected pieces (26-connected) with their volume, how much of
them COLON holds, and the nearest point of the centerline (its arc from the rectum end and
its distance): a piece the centerline runs through is on the colon's course.
"""
import json
import sys

import nibabel as nib
import numpy as np
import scipy.ndimage as ndi
from scipy.spatial import cKDTree

TAGGED_HU = 200


def voxels_lps(img, idx):
    """Voxel indices (n, 3) → LPS mm (NIfTI's affine is RAS)."""
    ras = idx @ img.affine[:3, :3].T + img.affine[:3, 3]
    return ras * np.array([-1.0, -1.0, 1.0])


def pieces(what, img, mask, centerline, arc, top, voxel_ml):
    """The largest pieces of `what`; `mask` None where they all lie outside it."""
    lab, _ = ndi.label(what, structure=np.ones((3, 3, 3)))
    sizes = np.bincount(lab.ravel())
    sizes[0] = 0
    for label in np.argsort(-sizes)[:top]:
        if sizes[label] == 0:
            break
        idx = np.argwhere(lab == label)
        d, k = centerline.query(voxels_lps(img, idx.astype(float)))
        near = np.argmin(d)
        in_mask = "" if mask is None else ", %3.0f %% in the mask" % (100.0 * mask[tuple(idx.T)].mean())
        print(
            "    %7.2f ml (%4.1f %%)%s, centerline %5.1f mm away at arc %5.0f mm"
            % (sizes[label] * voxel_ml, 100.0 * sizes[label] / what.sum(), in_mask, d[near], arc[k[near]])
        )


def main():
    args = sys.argv[1:]
    top = 8
    if "--top" in args:
        i = args.index("--top")
        top = int(args[i + 1])
        del args[i : i + 2]
    ct_path, mask_path, prep = args
    img = nib.load(ct_path)
    ct = np.asanyarray(img.dataobj).astype(np.int16)
    try:
        cleansed = np.asanyarray(nib.load(prep + "/cleansed.nii.gz").dataobj).astype(np.int16)
    except FileNotFoundError:
        sys.exit(prep + "/cleansed.nii.gz not found: prep cleanses only an exam with tagged fluid")
    mask = np.asanyarray(nib.load(mask_path).dataobj) > 0
    if not (ct.shape == cleansed.shape == mask.shape):
        sys.exit("the CT, the mask and the cleansed CT are not on one grid")
    cl = json.load(open(prep + "/centerline.json"))
    centerline = cKDTree(np.array(cl["points_lps_mm"]))
    arc = np.array(cl["arc_mm"])
    voxel_ml = float(np.prod(img.header.get_zooms()[:3])) / 1000.0
    steps = ndi.generate_binary_structure(3, 1)

    near = ndi.binary_dilation(mask, steps, iterations=4)
    before = ((ct > TAGGED_HU) & near).sum()
    left = (cleansed > TAGGED_HU) & near
    print(
        "tagged material left: %.2f %% (%d of %d voxels above %d HU in the mask dilated by 4)"
        % (100.0 * left.sum() / max(before, 1), left.sum(), before, TAGGED_HU)
    )
    pieces(left, img, mask, centerline, arc, top, voxel_ml)

    outside = ~ndi.binary_dilation(mask, steps, iterations=12)
    changed = (ct != cleansed) & outside
    print(
        "changed outside the colon: %.4f %% (%d of %d voxels outside the mask dilated by 12)"
        % (100.0 * changed.sum() / outside.sum(), changed.sum(), outside.sum())
    )
    pieces(changed, img, None, centerline, arc, top, voxel_ml)


if __name__ == "__main__":
    main()
