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
