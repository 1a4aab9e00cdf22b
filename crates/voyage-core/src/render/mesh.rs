//! The surface laid out for drawing by cell: each cell's triangles are one contiguous range,
//! so a renderer draws a list of cells as a list of ranges (one draw call per cell on a GPU).

use std::ops::Range;

use crate::cells::Cells;
use crate::surface::Surface;

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
}

impl CellMesh {
    pub fn new(surface: &Surface, cells: &Cells) -> Self {
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
        CellMesh { positions: surface.mesh.positions.clone(), normals: surface.mesh.normals.clone(), triangles, cell_ranges, surface_triangle }
    }

    pub fn cells(&self) -> usize {
        self.cell_ranges.len()
    }

    pub fn triangles_in(&self, cells: &[u32]) -> usize {
        cells.iter().map(|&c| self.cell_ranges[c as usize].len()).sum()
    }
}
