//! The surface laid out for drawing by cell: each cell's triangles are one contiguous range,
//! so a renderer draws a list of cells as a list of ranges (one draw call per cell on a GPU).

use std::ops::Range;

use glam::Vec3;

use voyage_core::{Cells, Surface};

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
    /// For the CPU rasterizer, which transforms each vertex once per cell rather than once
    /// per triangle: cell c's vertices are `cell_vertices[cell_vertex_ranges[c]]` and
    /// `local_triangles[t]` indexes them (empty until [`CellMesh::index_cells`]).
    pub cell_vertices: Vec<u32>,
    pub cell_vertex_ranges: Vec<Range<u32>>,
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

    /// Builds the per-cell vertex lists (see `cell_vertices`).
    pub fn index_cells(&mut self) {
        let mut local = vec![u32::MAX; self.positions.len()];
        self.cell_vertices.clear();
        self.cell_vertex_ranges.clear();
        self.local_triangles = Vec::with_capacity(self.triangles.len());
        for range in &self.cell_ranges {
            let start = self.cell_vertices.len();
            for t in &self.triangles[range.start as usize..range.end as usize] {
                let l = t.map(|v| {
                    let slot = &mut local[v as usize];
                    if *slot == u32::MAX {
                        *slot = (self.cell_vertices.len() - start) as u32;
                        self.cell_vertices.push(v);
                    }
                    *slot
                });
                self.local_triangles.push(l);
            }
            for &v in &self.cell_vertices[start..] {
                local[v as usize] = u32::MAX;
            }
            self.cell_vertex_ranges
                .push(start as u32..self.cell_vertices.len() as u32);
        }
    }

    /// Whether [`CellMesh::index_cells`] matches the triangles.
    pub fn is_indexed(&self) -> bool {
        self.local_triangles.len() == self.triangles.len()
            && self.cell_vertex_ranges.len() == self.cell_ranges.len()
    }

    /// The surface's own normals (the CT gradient), unsmoothed.
    pub fn unsmoothed(surface: &Surface, cells: &Cells) -> Self {
        let mut triangles = Vec::with_capacity(surface.mesh.triangles.len());
        let mut surface_triangle = Vec::with_capacity(surface.mesh.triangles.len());
        let mut cell_ranges = Vec::with_capacity(cells.cells.len());
        for cell in &cells.cells {
            let start = triangles.len() as u32;
            for &t in &cell.triangles {
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
