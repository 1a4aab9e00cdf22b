#!/usr/bin/env python3
"""Pictures of a centerline inside its lumen, to look at.

usage: centerline_views.py LUMEN.nii.gz CENTERLINE.json OUT.png

LUMEN and CENTERLINE as `voyage prep` writes them (lumen.nii.gz, centerline.json). Draws
two depth-shaded projections of the lumen (coronal: looking from the front, the patient's
right on the image's left; sagittal: looking from the patient's left, anterior on the left),
the centerline in red with its arc length every 100 mm, the source green, the target blue.
"""
import json
import sys

import nibabel as nib
import numpy as np
from PIL import Image, ImageDraw


def main():
    lumen_path, cl_path, out = sys.argv[1:4]
    img = nib.load(lumen_path)
    a = np.asanyarray(img.dataobj) > 0  # (i, j, k): voyage writes LPS-identity volumes as i→L
    sp = np.array(img.header.get_zooms()[:3], dtype=float)
    cl = json.load(open(cl_path))
    pts = np.array(cl["points_mm"]) / sp  # volume-local mm → voxel index
    arc = np.array(cl["arc_mm"])
    panels = []
    # coronal: project along j (posterior); show i (L→) horizontally, k (S) up.
    for axis, (h, v) in ((1, (0, 2)), (0, (1, 2))):
        occ = a.any(axis=axis)
        first = np.argmax(a, axis=axis).astype(float)
        shade = np.where(occ, 255 - 160 * first / max(a.shape[axis], 1), 0).astype(np.uint8)
        shade = shade.T[::-1]  # rows: k from top (superior) down; columns: h
        scale = (sp[h], sp[v])
        w, hgt = int(shade.shape[1] * scale[0]), int(shade.shape[0] * scale[1])
        im = Image.fromarray(shade).convert("RGB").resize((w, hgt))
        d = ImageDraw.Draw(im)
        xy = [(p[h] * scale[0], (a.shape[v] - 1 - p[v]) * scale[1]) for p in pts]
        d.line(xy, fill=(255, 0, 0), width=3)
        for q, c in ((xy[0], (0, 255, 0)), (xy[-1], (0, 0, 255))):
            d.ellipse([q[0] - 6, q[1] - 6, q[0] + 6, q[1] + 6], fill=c)
        mark = 100.0
        for (x, y), s in zip(xy, arc):
            if s >= mark:
                d.text((x + 3, y), str(int(mark)), fill=(255, 255, 0))
                mark += 100.0
        panels.append(im)
    W = sum(p.width for p in panels)
    H = max(p.height for p in panels)
    sheet = Image.new("RGB", (W, H))
    x = 0
    for p in panels:
        sheet.paste(p, (x, 0))
        x += p.width
    sheet.save(out)


if __name__ == "__main__":
    main()
