//! Large fields and the memory they reuse. The distance fields span the lumen's box (55 M
//! voxels, 218 MB per f32 field on `ctc/prone-tagged`), and a fresh field's first touch costs
//! about as much as filling it: so the stages hand arrays they are done with to the next
//! (`refilled`, `collect_in`), and a field is made with room for a later, larger user.
//!
//! No transparent huge pages are asked for: with the kernel's `defrag=madvise` it compacts
//! memory inside the faulting call, and in a fresh process the first Ds took 640–720 ms in
//! huge pages against 240–255 ms without; whole `prep` and `fly` runs were 4–6 % faster
//! without (BENCHMARKS.md, fourteenth session).

/// A vector of `n` copies of `fill`.
pub fn filled<T: Copy>(n: usize, fill: T) -> Vec<T> {
    filled_with_room(n, n, fill)
}

/// [`filled`] with room for `capacity` values, so that a later user of the memory with a
/// larger layout (a search's padded box after Ds's box) needs no fresh pages.
pub fn filled_with_room<T: Copy>(n: usize, capacity: usize, fill: T) -> Vec<T> {
    let mut v: Vec<T> = Vec::with_capacity(n.max(capacity));
    v.resize(n, fill);
    v
}

/// `n` copies of `fill` in the memory of `reuse` where it is large enough (an array some
/// search is done with), else in a fresh vector.
pub(crate) fn refilled<T: Copy>(reuse: Vec<T>, n: usize, fill: T) -> Vec<T> {
    if reuse.capacity() >= n {
        let mut v = reuse;
        v.clear();
        v.resize(n, fill);
        v
    } else {
        vec![fill; n]
    }
}

/// A vector collected from `iter` of known length `n`.
pub fn collect<T>(n: usize, iter: impl Iterator<Item = T>) -> Vec<T> {
    let mut v: Vec<T> = Vec::with_capacity(n);
    v.extend(iter);
    v
}

/// [`collect`] in the memory of `reuse` where it has room for `n` values (an array some search
/// is done with).
pub(crate) fn collect_in<T>(reuse: Vec<T>, n: usize, iter: impl Iterator<Item = T>) -> Vec<T> {
    if reuse.capacity() >= n {
        let mut v = reuse;
        v.clear();
        v.extend(iter);
        v
    } else {
        collect(n, iter)
    }
}

/// Asks the cache for the line holding `s[at]`, if there is one; nothing else happens.
#[inline(always)]
pub(crate) fn prefetch<T>(s: &[T], at: usize) {
    if at < s.len() {
        prefetch_address(s.as_ptr().wrapping_add(at));
    }
}

pub(crate) use crate::simd::prefetch_address;

/// Hashes voxel indices for maps over a few million of them: one multiply, not SipHash (the
/// keys are not chosen by an adversary, and no result depends on a map's order).
pub type VoxelHash = std::hash::BuildHasherDefault<VoxelHasher>;

#[derive(Default)]
pub struct VoxelHasher(u64);

impl std::hash::Hasher for VoxelHasher {
    fn finish(&self) -> u64 {
        // The table picks buckets by the low bits, and a product's low bits depend only on
        // the key's low bits (voxels a few 512×512 slices apart would share a bucket): the
        // high bits, which mix all of the key's, are turned down to them.
        self.0.rotate_left(26)
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(b as u64);
        }
    }
    fn write_u64(&mut self, i: u64) {
        self.0 = (self.0 ^ i).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    }
    fn write_usize(&mut self, i: usize) {
        self.write_u64(i as u64);
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn filled_and_collected_vectors_hold_their_values() {
        let v = super::filled(3 << 20, 7u32);
        assert_eq!(v.len(), 3 << 20);
        assert!(v.iter().all(|&x| x == 7));
        let w = super::collect(5 << 20, (0..5u32 << 20).map(|x| x as u8));
        assert_eq!(w.len(), 5 << 20);
        assert_eq!(w[257], 1);
    }
}
