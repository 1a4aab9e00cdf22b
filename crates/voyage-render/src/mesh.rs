//! The surface on the GPU: one interleaved vertex buffer and one index buffer holding every
//! triangle in cell order, so that drawing a list of cells is a list of index ranges (one
//! `draw_indexed` per run of consecutive cells), and a new visibility result costs no upload.

use std::ops::Range;

use bytemuck::{Pod, Zeroable};
use voyage_core::render::CellMesh;
use wgpu::util::DeviceExt;

use crate::error::RenderError;

/// One vertex as the shader reads it: `@location(0)` position (mm), `@location(1)` normal.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub(crate) struct Vertex {
    pub position: [f32; 3],
    pub normal: [f32; 3],
}

impl Vertex {
    pub const ATTRIBUTES: [wgpu::VertexAttribute; 2] =
        wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3];

    pub fn layout() -> wgpu::VertexBufferLayout<'static> {
        wgpu::VertexBufferLayout {
            array_stride: std::mem::size_of::<Vertex>() as wgpu::BufferAddress,
            step_mode: wgpu::VertexStepMode::Vertex,
            attributes: &Self::ATTRIBUTES,
        }
    }
}

/// A [`CellMesh`] uploaded: its buffers and, per cell, its range in the index buffer
/// (in indices, three per triangle).
pub(crate) struct GpuMesh {
    pub vertices: wgpu::Buffer,
    pub indices: wgpu::Buffer,
    pub cell_indices: Vec<Range<u32>>,
}

impl GpuMesh {
    pub fn new(device: &wgpu::Device, mesh: &CellMesh) -> Result<Self, RenderError> {
        check(mesh)?;
        let (vertices, triangles) = cell_ordered(mesh);
        let max = device.limits().max_buffer_size;
        let vertex_bytes = (vertices.len() * std::mem::size_of::<Vertex>()) as u64;
        let index_bytes = (mesh.triangles.len() * 12) as u64;
        for needed in [vertex_bytes, index_bytes] {
            if needed > max {
                return Err(RenderError::MeshTooLarge { needed, max });
            }
        }
        // An empty buffer is legal but awkward to bind; a mesh without triangles still gets
        // one zero vertex and one degenerate triangle that no range ever draws.
        let vertex_data: &[u8] = if vertices.is_empty() {
            &[0; 24]
        } else {
            bytemuck::cast_slice(&vertices)
        };
        let index_data: &[u8] = if triangles.is_empty() {
            &[0; 12]
        } else {
            bytemuck::cast_slice(&triangles)
        };
        let vertices = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("voyage surface vertices"),
            contents: vertex_data,
            usage: wgpu::BufferUsages::VERTEX,
        });
        let indices = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("voyage surface indices"),
            contents: index_data,
            usage: wgpu::BufferUsages::INDEX,
        });
        let cell_indices = mesh
            .cell_ranges
            .iter()
            .map(|r| r.start * 3..r.end * 3)
            .collect();
        Ok(GpuMesh {
            vertices,
            indices,
            cell_indices,
        })
    }

    /// See [`draw_ranges`].
    pub fn draw_ranges(&self, cells: &[u32]) -> Result<Vec<Range<u32>>, RenderError> {
        draw_ranges(&self.cell_indices, cells)
    }
}

/// The vertices and triangles laid out cell by cell: each cell's vertices contiguous (a
/// vertex shared by two cells appears in both) and its triangles indexing only them. A draw
/// of a run of cells then touches one short stretch of the vertex buffer; with the surface's
/// own vertex order a cell's indices span most of the buffer, and a driver that shades the
/// whole index range of a draw (Mesa's CPU driver does) would shade every vertex of the
/// colon for every run of cells.
fn cell_ordered(mesh: &CellMesh) -> (Vec<Vertex>, Vec<[u32; 3]>) {
    let vertex = |v: u32| Vertex { position: mesh.positions[v as usize], normal: mesh.normals[v as usize] };
    if !mesh.is_indexed() {
        return (mesh.positions.iter().enumerate().map(|(v, _)| vertex(v as u32)).collect(), mesh.triangles.clone());
    }
    let vertices: Vec<Vertex> = mesh.cell_vertices.iter().map(|&v| vertex(v)).collect();
    let mut triangles = Vec::with_capacity(mesh.triangles.len());
    for (range, vrange) in mesh.cell_ranges.iter().zip(&mesh.cell_vertex_ranges) {
        for t in &mesh.local_triangles[range.start as usize..range.end as usize] {
            triangles.push(t.map(|l| vrange.start + l));
        }
    }
    (vertices, triangles)
}

/// The index ranges that draw `cells`, in the order given, with consecutive cells that are
/// also consecutive in the buffer merged into one range and empty cells dropped. The order is
/// kept: at equal depth the first drawn triangle wins (compare Less), as in the CPU renderer.
pub(crate) fn draw_ranges(
    cell_indices: &[Range<u32>],
    cells: &[u32],
) -> Result<Vec<Range<u32>>, RenderError> {
    let mut out: Vec<Range<u32>> = Vec::with_capacity(cells.len());
    for &c in cells {
        let r = cell_indices
            .get(c as usize)
            .ok_or(RenderError::UnknownCell {
                cell: c,
                cells: cell_indices.len(),
            })?;
        if r.is_empty() {
            continue;
        }
        match out.last_mut() {
            Some(last) if last.end == r.start => last.end = r.end,
            _ => out.push(r.clone()),
        }
    }
    Ok(out)
}

/// Checks what the GPU would otherwise read out of bounds or draw twice.
fn check(mesh: &CellMesh) -> Result<(), RenderError> {
    let n = mesh.positions.len();
    if mesh.normals.len() != n {
        return Err(RenderError::BadMesh(format!(
            "{} positions but {} normals",
            n,
            mesh.normals.len()
        )));
    }
    if let Some(t) = mesh
        .triangles
        .iter()
        .find(|t| t.iter().any(|&v| v as usize >= n))
    {
        return Err(RenderError::BadMesh(format!(
            "triangle {t:?} names a vertex beyond the {n} vertices"
        )));
    }
    let mut next = 0;
    for (c, r) in mesh.cell_ranges.iter().enumerate() {
        if r.start != next || r.end < r.start {
            return Err(RenderError::BadMesh(format!(
                "cell {c}'s triangles {r:?} do not follow on from {next}"
            )));
        }
        next = r.end;
    }
    if next as usize != mesh.triangles.len() {
        return Err(RenderError::BadMesh(format!(
            "the cells hold {next} triangles; the mesh has {}",
            mesh.triangles.len()
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn consecutive_cells_merge_and_order_is_kept() {
        let cells = [0..3, 3..3, 3..9, 9..12];
        assert_eq!(draw_ranges(&cells, &[0, 1, 2, 3]).unwrap(), vec![0..12]);
        assert_eq!(draw_ranges(&cells, &[3, 0, 2]).unwrap(), vec![9..12, 0..9]);
        assert_eq!(draw_ranges(&cells, &[2, 0]).unwrap(), vec![3..9, 0..3]);
        assert_eq!(draw_ranges(&cells, &[1]).unwrap(), Vec::<Range<u32>>::new());
        assert!(matches!(
            draw_ranges(&cells, &[4]),
            Err(RenderError::UnknownCell { cell: 4, cells: 4 })
        ));
    }
}
