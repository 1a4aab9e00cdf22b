#!/usr/bin/env python3
"""Reference timings for `voyage bench prep`, on the same lumen mask voyage uses.

usage: prep_reference.py MASK.nii.gz SOURCE_I,J,K REPEATS

The mask is cropped to the lumen's bounding box grown by one voxel (as voyage works), and
each library runs single-threaded where it has a choice:
  ds:      scipy.ndimage.distance_transform_edt, edt.edt (exact anisotropic EDT)
  dt:      dijkstra3d.euclidean_distance_field (26-connected, anisotropic) from SOURCE
  surface: skimage.measure.marching_cubes (level 0.5), VTK vtkFlyingEdges3D (0.5)
Prints one JSON object: {"name": {"ms": median, "runs": [...], "extra": ...}, ...}.
"""
import json
import os
import sys
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np
import nibabel as nib


def median_ms(fn, repeats):
    runs = []
    out = None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        runs.append((time.perf_counter() - t0) * 1e3)
    runs.sort()
    return runs[len(runs) // 2], runs, out


def main():
    path, src, repeats = sys.argv[1], sys.argv[2], int(sys.argv[3]) if len(sys.argv) > 3 else 3
    img = nib.load(path)
    mask = np.asanyarray(img.dataobj) > 0  # (i, j, k)
    sp = tuple(float(z) for z in img.header.get_zooms()[:3])
    nz = np.nonzero(mask)
    lo = [max(int(a.min()) - 1, 0) for a in nz]
    hi = [min(int(a.max()) + 2, n) for a, n in zip(nz, mask.shape)]
    box = np.ascontiguousarray(mask[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]])
    s = tuple(int(x) for x in src.split(","))
    s = (s[0] - lo[0], s[1] - lo[1], s[2] - lo[2])
    out = {"box": list(box.shape), "lumen_voxels": int(box.sum())}

    from scipy import ndimage
    ms, runs, _ = median_ms(lambda: ndimage.distance_transform_edt(box, sampling=sp), repeats)
    out["scipy_edt"] = {"ms": ms, "runs": runs}

    import edt
    ms, runs, _ = median_ms(lambda: edt.edt(box, anisotropy=sp, black_border=True, parallel=1), repeats)
    out["edt"] = {"ms": ms, "runs": runs}

    import dijkstra3d
    ms, runs, d = median_ms(lambda: dijkstra3d.euclidean_distance_field(box, source=s, anisotropy=sp), repeats)
    out["dijkstra3d"] = {"ms": ms, "runs": runs, "max_mm": float(d[np.isfinite(d) & box].max())}

    from skimage import measure
    f = box.astype(np.float32)
    ms, runs, res = median_ms(lambda: measure.marching_cubes(f, level=0.5, spacing=sp), repeats)
    out["skimage_marching_cubes"] = {"ms": ms, "runs": runs, "triangles": int(len(res[1]))}

    import vtk
    from vtk.util import numpy_support
    vimg = vtk.vtkImageData()
    vimg.SetDimensions(*box.shape)
    vimg.SetSpacing(*sp)
    arr = numpy_support.numpy_to_vtk(f.ravel(order="F"), deep=True)
    vimg.GetPointData().SetScalars(arr)
    # Flying edges runs on vtkSMPTools, not vtkMultiThreader: both are held to one thread.
    vtk.vtkMultiThreader.SetGlobalMaximumNumberOfThreads(1)
    vtk.vtkSMPTools.Initialize(1)

    def flying_edges():
        fe = vtk.vtkFlyingEdges3D()
        fe.SetInputData(vimg)
        fe.SetValue(0, 0.5)
        fe.ComputeNormalsOn()
        fe.Update()
        return fe.GetOutput().GetNumberOfCells()

    ms, runs, ntri = median_ms(flying_edges, repeats)
    out["vtk_flying_edges"] = {"ms": ms, "runs": runs, "triangles": int(ntri)}
    print(json.dumps(out))


if __name__ == "__main__":
    main()
