//! The surface laid out for drawing by cell: each cell's triangles are one contiguous range,
//! so a renderer draws a list of cells as a list of ranges (one draw call per cell on a GPU).
//!
//! Within a cell the triangles run in Morton order of their centroids, cut into chunks of
//! at most [`CHUNK_TRIANGLES`] with their bounding boxes: a chunk is a compact piece of the
//! wall, so a renderer can leave out the chunks that lie wholly outside what a cell can show
//! (beside or behind the camera, or outside the window its portals leave open).

use std::ops::Range;

use glam::Vec3;

use voyage_core::{Cells, Surface};

/// Triangles per chunk: small enough that the part of a cell outside a portal's window
/// falls away, large enough that the per-frame tests and a GPU's draw calls stay few.
pub const CHUNK_TRIANGLES: usize = 512;

/// A run of a cell's triangles and the bounding box of their vertices (mm).
#[derive(Clone, Debug, PartialEq)]
pub struct Chunk {
    pub triangles: Range<u32>,
    pub lo: [f32; 3],
    pub hi: [f32; 3],
}

#[derive(Clone, Debug, Default)]
pub struct CellMesh {
    /// Volume-local mm, shared with the surface.
    pub positions: Vec<[f32; 3]>,
    /// Unit normals pointing into the lumen.
    pub normals: Vec<[f32; 3]>,
    /// Triangles sorted by cell; (b − a) × (c − a) points into the lumen, toward the camera.
    pub triangles: Vec<[u32; 3]>,
    /// `triangles[cell_ranges[c]]` are cell c's triangles.
    pub cell_ranges: Vec<Range<u32>>,
    /// Draw index → triangle index in the surface.
    pub surface_triangle: Vec<u32>,
    /// Each cell's triangles in runs of at most [`CHUNK_TRIANGLES`],
    /// with their boxes; `chunks[cell_chunks[c]]` are cell c's (empty until
    /// [`CellMesh::index_cells`]).
    pub chunks: Vec<Chunk>,
    pub cell_chunks: Vec<Range<u32>>,
    /// For the CPU rasterizer, which transforms each vertex once per chunk rather than once
    /// per triangle: chunk k's vertices are `chunk_vertices[chunk_vertex_ranges[k]]` and
    /// `local_triangles[t]` indexes them.
    pub chunk_vertices: Vec<u32>,
    pub chunk_vertex_ranges: Vec<Range<u32>>,
    pub local_triangles: Vec<[u32; 3]>,
}

/// Normal smoothing passes [`CellMesh::new`] applies: the marching-cubes surface of a
/// clinical scan (worse, of a 0/1 mask) is terraced voxel by voxel, and per-voxel normals
/// shade every terrace. Two passes average over about two voxels, which hides terraces but
/// not a 3 mm polyp; positions are untouched (nothing is simplified).
pub const DISPLAY_NORMAL_PASSES: usize = 2;

impl CellMesh {
    pub fn new(surface: &Surface, cells: &Cells) -> Self {
        let mut mesh = Self::unsmoothed(surface, cells);
        mesh.normals = smooth_normals(&mesh.normals, &mesh.triangles, DISPLAY_NORMAL_PASSES);
        mesh
    }

    /// Builds the chunks and their vertex lists (see `chunks`, `chunk_vertices`).
    pub fn index_cells(&mut self) {
        let mut local = vec![u32::MAX; self.positions.len()];
        self.chunks.clear();
        self.cell_chunks.clear();
        self.chunk_vertices.clear();
        self.chunk_vertex_ranges.clear();
        self.local_triangles = Vec::with_capacity(self.triangles.len());
        for c in 0..self.cell_ranges.len() {
            let first = self.chunks.len() as u32;
            for run in chunk_runs(self.cell_ranges[c].clone()) {
                let start = self.chunk_vertices.len();
                let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
                for t in &self.triangles[run.start as usize..run.end as usize] {
                    let l = t.map(|v| {
                        let slot = &mut local[v as usize];
                        if *slot == u32::MAX {
                            *slot = (self.chunk_vertices.len() - start) as u32;
                            self.chunk_vertices.push(v);
                            let p = self.positions[v as usize];
                            for a in 0..3 {
                                lo[a] = lo[a].min(p[a]);
                                hi[a] = hi[a].max(p[a]);
                            }
                        }
                        *slot
                    });
                    self.local_triangles.push(l);
                }
                for &v in &self.chunk_vertices[start..] {
                    local[v as usize] = u32::MAX;
                }
                self.chunk_vertex_ranges
                    .push(start as u32..self.chunk_vertices.len() as u32);
                self.chunks.push(Chunk {
                    triangles: run,
                    lo,
                    hi,
                });
            }
            self.cell_chunks.push(first..self.chunks.len() as u32);
        }
    }

    /// Whether [`CellMesh::index_cells`] matches the triangles.
    pub fn is_indexed(&self) -> bool {
        self.local_triangles.len() == self.triangles.len()
            && self.cell_chunks.len() == self.cell_ranges.len()
    }

    /// The surface's own normals (the CT gradient), unsmoothed.
    pub fn unsmoothed(surface: &Surface, cells: &Cells) -> Self {
        let mut triangles = Vec::with_capacity(surface.mesh.triangles.len());
        let mut surface_triangle = Vec::with_capacity(surface.mesh.triangles.len());
        let mut cell_ranges = Vec::with_capacity(cells.cells.len());
        for cell in &cells.cells {
            let start = triangles.len() as u32;
            for t in morton_order(surface, &cell.triangles) {
                triangles.push(surface.mesh.triangles[t as usize]);
                surface_triangle.push(t);
            }
            cell_ranges.push(start..triangles.len() as u32);
        }
        let mut mesh = CellMesh {
            positions: surface.mesh.positions.clone(),
            normals: surface.mesh.normals.clone(),
            triangles,
            cell_ranges,
            surface_triangle,
            ..CellMesh::default()
        };
        mesh.index_cells();
        mesh
    }

    pub fn cells(&self) -> usize {
        self.cell_ranges.len()
    }

    pub fn triangles_in(&self, cells: &[u32]) -> usize {
        cells
            .iter()
            .map(|&c| self.cell_ranges[c as usize].len())
            .sum()
    }
}

/// A cell's triangles (its range) in runs of at most [`CHUNK_TRIANGLES`]: its chunks.
fn chunk_runs(cell: Range<u32>) -> impl Iterator<Item = Range<u32>> {
    (cell.start..cell.end)
        .step_by(CHUNK_TRIANGLES)
        .map(move |s| s..(s + CHUNK_TRIANGLES as u32).min(cell.end))
}

/// Side of the grid the Morton order quantises centroids to (mm).
const MORTON_CELL_MM: f32 = 1.0;

/// `tris` (surface triangle indices) in Morton order of their centroids on a
/// [`MORTON_CELL_MM`] grid (ties in their given order): runs of consecutive triangles are
/// then compact pieces of the wall.
fn morton_order(surface: &Surface, tris: &[u32]) -> Vec<u32> {
    let m = &surface.mesh;
    let centroid = |t: u32| {
        let v = m.triangles[t as usize].map(|i| Vec3::from_array(m.positions[i as usize]));
        (v[0] + v[1] + v[2]) / 3.0
    };
    let lo = tris
        .iter()
        .map(|&t| centroid(t))
        .fold(Vec3::splat(f32::INFINITY), Vec3::min);
    let mut keyed: Vec<(u64, u32)> = tris
        .iter()
        .map(|&t| {
            let q = ((centroid(t) - lo) / MORTON_CELL_MM).max(Vec3::ZERO);
            (morton3(q.x as u32, q.y as u32, q.z as u32), t)
        })
        .collect();
    keyed.sort_by_key(|&(k, _)| k);
    keyed.into_iter().map(|(_, t)| t).collect()
}

/// Interleaves the low 21 bits of x, y and z.
fn morton3(x: u32, y: u32, z: u32) -> u64 {
    fn spread(v: u32) -> u64 {
        let mut v = (v & 0x1f_ffff) as u64;
        v = (v | v << 32) & 0x1f_0000_0000_ffff;
        v = (v | v << 16) & 0x1f_0000_ff00_00ff;
        v = (v | v << 8) & 0x100f_00f0_0f00_f00f;
        v = (v | v << 4) & 0x10c3_0c30_c30c_30c3;
        v = (v | v << 2) & 0x1249_2492_4924_9249;
        v
    }
    spread(x) | spread(y) << 1 | spread(z) << 2
}

/// Averages each vertex normal with those of the triangles around it, `passes` times.
pub fn smooth_normals(
    normals: &[[f32; 3]],
    triangles: &[[u32; 3]],
    passes: usize,
) -> Vec<[f32; 3]> {
    let mut cur: Vec<Vec3> = normals.iter().map(|&n| Vec3::from_array(n)).collect();
    for _ in 0..passes {
        let mut acc = cur.clone();
        for t in triangles {
            let sum = cur[t[0] as usize] + cur[t[1] as usize] + cur[t[2] as usize];
            for &v in t {
                acc[v as usize] += sum;
            }
        }
        for (c, a) in cur.iter_mut().zip(&acc) {
            *c = a.normalize_or(*c);
        }
    }
    cur.into_iter().map(|n| n.to_array()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn morton_codes_interleave_the_axes() {
        assert_eq!(morton3(1, 0, 0), 1);
        assert_eq!(morton3(0, 1, 0), 2);
        assert_eq!(morton3(0, 0, 1), 4);
        assert_eq!(morton3(3, 0, 0), 0b1001);
        assert_eq!(morton3(0x1f_ffff, 0, 0), 0x1249_2492_4924_9249);
    }
}
