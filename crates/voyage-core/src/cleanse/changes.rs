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
/// `voxels` / `values` (ascending): a new value replaces the one listed, and a voxel given
/// back its original value `hu` leaves the list.
pub(super) fn overwrite(
    voxels: &mut Vec<u32>,
    values: &mut Vec<i16>,
    hu: &[i16],
    changes: &[(u32, i16)],
) {
    if changes.is_empty() {
        return;
    }
    let mut all: Vec<(u32, i16)> = Vec::with_capacity(voxels.len() + changes.len());
    let mut old = voxels
        .iter()
        .copied()
        .zip(values.iter().copied())
        .peekable();
    let mut new = changes.iter().copied().peekable();
    loop {
        let next = match (old.peek(), new.peek()) {
            (Some(&(a, _)), Some(&(b, _))) if a < b => old.next(),
            (Some(&(a, _)), Some(&(b, _))) if a == b => {
                old.next();
                new.next()
            }
            (Some(_), None) => old.next(),
            (_, Some(_)) => new.next(),
            (None, None) => break,
        };
        all.extend(next.filter(|&(v, h)| hu[v as usize] != h));
    }
    (*voxels, *values) = all.into_iter().unzip();
}
