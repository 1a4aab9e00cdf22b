//! The marks cleansing keeps in the lumen volume's spare bits (bit 0 is the lumen): where the
//! pools are and what lies near them, and the lumps of stool. Every step reads them; all are
//! cleared before cleansing returns.

/// Marks in the lumen volume's spare bits while cleansing runs (cleared before it returns):
/// within two voxels of a pool, a pool's core, and the pool.
pub(super) const NEAR: u8 = 2;
pub(super) const CORE: u8 = 4;
pub(super) const POOL: u8 = 8;
/// A lump of stool's tagged voxels and the air pockets inside it (`SOLID`), and with them
/// their partial-volume skin (`LUMP`).
pub(super) const SOLID: u8 = 16;
pub(super) const LUMP: u8 = 32;
/// All of them: what cleansing clears before it returns.
pub(super) const ALL: u8 = NEAR | CORE | POOL | SOLID | LUMP;

/// The marks each row of a box holds (the bits of its voxels, or-ed; a row runs along the
/// first axis): the passes over the colon's box skip the rows that hold none, since pools
/// and lumps fill a small part of it (on `ctc/prone-tagged`, a box of 55 M voxels).
pub(super) struct RowMarks {
    lo: [usize; 2],
    rows: usize,
    bits: Vec<u8>,
}

impl RowMarks {
    /// The rows of voxels `lo..=hi` of `m`, a volume `nx` × `ny` voxels in plane.
    pub(super) fn of(m: &[u8], [nx, ny]: [usize; 2], lo: [usize; 3], hi: [usize; 3]) -> Self {
        let rows = hi[1] - lo[1] + 1;
        let mut bits = Vec::with_capacity(rows * (hi[2] - lo[2] + 1));
        for k in lo[2]..=hi[2] {
            for j in lo[1]..=hi[1] {
                let row = nx * (j + ny * k);
                // A plain fold: it compiles to vector code, where `any` stops early and does
                // not.
                bits.push(m[row + lo[0]..=row + hi[0]].iter().fold(0, |a, &x| a | x));
            }
        }
        RowMarks {
            lo: [lo[1], lo[2]],
            rows,
            bits,
        }
    }

    /// Whether row (j, k), inside the box, holds any of the marks `bits`.
    pub(super) fn any(&self, j: usize, k: usize, bits: u8) -> bool {
        self.bits[(j - self.lo[0]) + self.rows * (k - self.lo[1])] & bits != 0
    }
}

/// Where each row of a box holds voxels with any of some bits: the first and last along the
/// first axis (a row runs along it). Bright voxels (bone, contrast) fill much of the colon's
/// box and most lie far from its lumen: a pass that needs lumen near skips them by row.
pub(super) struct RowSpans {
    lo: [usize; 3],
    hi: [usize; 3],
    /// Per row (j, k) of the box: first and last; `(1, 0)` where the row holds none.
    spans: Vec<(u32, u32)>,
}

impl RowSpans {
    /// The rows of voxels `lo..=hi` of `m`, a volume `nx` × `ny` voxels in plane, with any
    /// of `bits`.
    pub(super) fn of(
        m: &[u8],
        [nx, ny]: [usize; 2],
        lo: [usize; 3],
        hi: [usize; 3],
        bits: u8,
    ) -> Self {
        const CHUNK: usize = 32;
        let has = |c: &[u8]| c.iter().fold(0, |a, &x| a | x) & bits != 0;
        let mut spans = Vec::with_capacity((hi[1] - lo[1] + 1) * (hi[2] - lo[2] + 1));
        for k in lo[2]..=hi[2] {
            for j in lo[1]..=hi[1] {
                let start = nx * (j + ny * k) + lo[0];
                let row = &m[start..=start + hi[0] - lo[0]];
                // Chunk by chunk (folds that compile to vector code), then within the chunk.
                let first = row.chunks(CHUNK).position(has).map(|c| {
                    c * CHUNK
                        + row[c * CHUNK..]
                            .iter()
                            .position(|&x| x & bits != 0)
                            .unwrap()
                });
                let span = match first {
                    None => (1, 0),
                    Some(f) => {
                        let from_end = row[f..].rchunks(CHUNK).position(has).unwrap_or(0);
                        let end = row.len() - from_end * CHUNK;
                        let chunk_start = end.saturating_sub(CHUNK).max(f);
                        let last = chunk_start
                            + row[chunk_start..end]
                                .iter()
                                .rposition(|&x| x & bits != 0)
                                .unwrap();
                        ((lo[0] + f) as u32, (lo[0] + last) as u32)
                    }
                };
                spans.push(span);
            }
        }
        RowSpans { lo, hi, spans }
    }

    /// Row (j, k)'s first and last voxel with the bits; None where it holds none or lies
    /// outside the box.
    pub(super) fn get(&self, j: usize, k: usize) -> Option<(usize, usize)> {
        if !(self.lo[1]..=self.hi[1]).contains(&j) || !(self.lo[2]..=self.hi[2]).contains(&k) {
            return None;
        }
        let rows = self.hi[1] - self.lo[1] + 1;
        let (a, b) = self.spans[(j - self.lo[1]) + rows * (k - self.lo[2])];
        (a <= b).then_some((a as usize, b as usize))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    /// Random bits in a small volume: each row's span is its first and last voxel with the
    /// bits asked, inside the box, by definition; rows of 40 voxels cross the chunks.
    #[test]
    fn row_spans_are_the_first_and_last_voxels_with_the_bits() {
        let [nx, ny, nz] = [77, 6, 5];
        let mut rng = Rng::new(25, 1);
        for share in [3, 40, 400] {
            let m: Vec<u8> = (0..nx * ny * nz)
                .map(|_| {
                    let r = rng.next_u64();
                    if r.is_multiple_of(share) {
                        1 | (r >> 8) as u8 & 6
                    } else {
                        (r >> 8) as u8 & 6
                    }
                })
                .collect();
            let (lo, hi) = ([3, 1, 0], [42, 5, 3]);
            let spans = RowSpans::of(&m, [nx, ny], lo, hi, 1);
            for k in 0..nz {
                for j in 0..ny {
                    let inside = (lo[1]..=hi[1]).contains(&j) && (lo[2]..=hi[2]).contains(&k);
                    let with: Vec<usize> = (lo[0]..=hi[0])
                        .filter(|&i| inside && m[i + nx * (j + ny * k)] & 1 != 0)
                        .collect();
                    let want = with.first().copied().zip(with.last().copied());
                    assert_eq!(spans.get(j, k), want, "1 in {share}, row ({j}, {k})");
                }
            }
        }
    }
}
