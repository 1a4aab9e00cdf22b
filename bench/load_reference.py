#!/usr/bin/env python3
"""Reference timings for `voyage bench load`: pydicom+numpy on a DICOM series folder and
nibabel on a .nii.gz, each producing an int16 HU array, as a Python user would.

Prints one JSON object: {"dicom_s": [...], "nifti_s": [...], "dicom_shape": ..., "nifti_shape": ...}
with one wall-clock time per repeat (seconds).
"""
import json
import os
import sys
import time

import numpy as np


def load_dicom_series(folder):
    import pydicom

    slices = [pydicom.dcmread(os.path.join(folder, f)) for f in os.listdir(folder)]
    # Sort by position along the slice normal, as voyage does.
    def along_normal(ds):
        o = np.array(ds.ImageOrientationPatient, dtype=float)
        n = np.cross(o[:3], o[3:])
        return float(np.dot(n, np.array(ds.ImagePositionPatient, dtype=float)))

    slices.sort(key=along_normal)
    vol = np.empty((len(slices), slices[0].Rows, slices[0].Columns), dtype=np.int16)
    for k, ds in enumerate(slices):
        slope = float(getattr(ds, "RescaleSlope", 1.0))
        inter = float(getattr(ds, "RescaleIntercept", 0.0))
        px = ds.pixel_array
        if slope == 1.0:
            vol[k] = px + np.int16(inter) if inter else px
        else:
            vol[k] = np.round(px * slope + inter).astype(np.int16)
    return vol


def load_nifti(path):
    import nibabel as nib

    img = nib.load(path)
    return np.asanyarray(img.dataobj).astype(np.int16, copy=False)


def timed(fn, arg, repeats):
    times, shape = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        a = fn(arg)
        times.append(time.perf_counter() - t0)
        shape = list(a.shape)
        del a
    return times, shape


def main():
    folder, nii, repeats = sys.argv[1], sys.argv[2], int(sys.argv[3]) if len(sys.argv) > 3 else 3
    dicom_s, dicom_shape = timed(load_dicom_series, folder, repeats)
    nifti_s, nifti_shape = timed(load_nifti, nii, repeats)
    print(json.dumps({"dicom_s": dicom_s, "nifti_s": nifti_s,
                      "dicom_shape": dicom_shape, "nifti_shape": nifti_shape}))


if __name__ == "__main__":
    main()
