//! The change list every step writes to and reads from: changed voxels (volume indices,
//! ascending) with their values, read back slice by slice or voxel by voxel, and new
//! changes merged in.

/// Slice `k` (of `out.len()` values) of `hu` with `changes` in (volume indices ascending,
/// and their values).
pub(super) fn slice_with(
    hu: &[i16],
    (voxels, values): (&[u32], &[i16]),
    k: usize,
    out: &mut [i16],
) {
    let (lo, hi) = ((out.len() * k) as u32, (out.len() * (k + 1)) as u32);
    out.copy_from_slice(&hu[lo as usize..hi as usize]);
    let from = voxels.partition_point(|&v| v < lo);
    let to = voxels.partition_point(|&v| v < hi);
    for (&v, &x) in voxels[from..to].iter().zip(&values[from..to]) {
        out[(v - lo) as usize] = x;
    }
}

/// A voxel's value once cleansed, from the change list `voxels` (ascending) / `values`.
pub(super) fn value_after(voxels: &[u32], values: &[i16], hu: &[i16], v: usize) -> i16 {
    voxels
        .binary_search(&(v as u32))
        .map_or(hu[v], |n| values[n])
}

/// Writes `changes` (voxel and new value, ascending, each voxel once) over the change list
/// `voxels` / `values` (ascending, each value other than the voxel's original `hu`): a new
/// value replaces the one listed, and a voxel given back its original value leaves the list.
pub(super) fn overwrite(
    voxels: &mut Vec<u32>,
    values: &mut Vec<i16>,
    hu: &[i16],
    changes: &[(u32, i16)],
) {
    if changes.is_empty() {
        return;
    }
    let capacity = voxels.len() + changes.len();
    let (mut out_voxels, mut out_values) =
        (Vec::with_capacity(capacity), Vec::with_capacity(capacity));
    let mut old = 0;
    for &(v, h) in changes {
        // The listed voxels before v stay as they are: none holds its original value.
        let mut to = old;
        while voxels.get(to).is_some_and(|&w| w < v) {
            to += 1;
        }
        out_voxels.extend_from_slice(&voxels[old..to]);
        out_values.extend_from_slice(&values[old..to]);
        old = to + (voxels.get(to) == Some(&v)) as usize;
        if hu[v as usize] != h {
            out_voxels.push(v);
            out_values.push(h);
        }
    }
    out_voxels.extend_from_slice(&voxels[old..]);
    out_values.extend_from_slice(&values[old..]);
    (*voxels, *values) = (out_voxels, out_values);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;
    use std::collections::BTreeMap;

    /// Random change lists over 200 voxels of values 0..4, against the definition: the new
    /// values win, and a voxel back at its original value leaves the list.
    #[test]
    fn overwrite_is_the_merge_without_originals() {
        let mut rng = Rng::new(35, 1);
        let mut pick = |n: u64| rng.next_u64() % n;
        for _ in 0..200 {
            let hu: Vec<i16> = (0..200).map(|_| pick(4) as i16).collect();
            let (mut old, mut changes) = (Vec::new(), Vec::new());
            for v in 0..200u32 {
                let (h, listed, changed) = (pick(4) as i16, pick(3) == 0, pick(4) == 0);
                if listed && hu[v as usize] != h {
                    old.push((v, h));
                }
                if changed {
                    changes.push((v, pick(4) as i16));
                }
            }
            let mut want: BTreeMap<u32, i16> = old.iter().copied().collect();
            want.extend(changes.iter().copied());
            want.retain(|&v, h| hu[v as usize] != *h);
            let (mut voxels, mut values): (Vec<u32>, Vec<i16>) = old.into_iter().unzip();
            overwrite(&mut voxels, &mut values, &hu, &changes);
            let got: Vec<(u32, i16)> = voxels.into_iter().zip(values).collect();
            assert_eq!(got, want.into_iter().collect::<Vec<_>>());
        }
    }
}
