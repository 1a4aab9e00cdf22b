//! The surface on the GPU: one interleaved vertex buffer and one index buffer holding every
//! triangle in cell order, so that drawing a list of cells is a list of index ranges (one
//! `draw_indexed` per run of consecutive pieces), and a new visibility result costs no
//! upload.
//!
//! Each cell is laid out as the [`CellMesh`]'s chunks (compact pieces of the wall), each
//! with its own vertices and bounding box. A
//! cell the portals let through is drawn without the chunks that lie wholly outside the
//! view frustum: they would give no fragment, so the image is the same (exact), and a CPU
//! Vulkan driver is spared shading and binning them.

use std::ops::Range;

use bytemuck::{Pod, Zeroable};
use glam::DVec3;
use voyage_nav::Camera;
use voyage_view::{CellMesh, ScreenRect, View};
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

/// A run of a cell's triangles with its own vertices: its range in the index buffer and
/// the bounding box of its vertices (mm).
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Chunk {
    pub indices: Range<u32>,
    pub lo: [f32; 3],
    pub hi: [f32; 3],
}

/// A [`CellMesh`] uploaded: its buffers, its chunks, and per cell its range in the index
/// buffer (in indices, three per triangle) and its chunks.
pub(crate) struct GpuMesh {
    pub vertices: wgpu::Buffer,
    pub indices: wgpu::Buffer,
    pub cell_indices: Vec<Range<u32>>,
    pub chunks: Vec<Chunk>,
    pub cell_chunks: Vec<Range<usize>>,
}

impl GpuMesh {
    pub fn new(device: &wgpu::Device, mesh: &CellMesh) -> Result<Self, RenderError> {
        check(mesh)?;
        let Layout {
            vertices,
            triangles,
            chunks,
            cell_chunks,
        } = chunked(mesh);
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
            chunks,
            cell_chunks,
        })
    }

    /// See [`draw_ranges`].
    pub fn draw_ranges(&self, cells: &[u32]) -> Result<Vec<Range<u32>>, RenderError> {
        draw_ranges(&self.cell_indices, cells)
    }

    /// The index ranges that draw `cells` (order kept, as [`draw_ranges`]) without their
    /// chunks that lie wholly outside `view`.
    pub fn draw_ranges_in(
        &self,
        cells: &[u32],
        view: &Frustum,
    ) -> Result<Vec<Range<u32>>, RenderError> {
        self.kept_ranges(cells, |_, chunk| !view.excludes(chunk.lo, chunk.hi))
    }

    /// [`Self::draw_ranges_in`], also without the chunks that cannot cover a pixel centre
    /// within their cell's rectangle (`rects[i]` for `cells[i]`, from the portals), widened
    /// by [`RECT_MARGIN_PX`] for the GPU's rounding.
    pub fn draw_ranges_within(
        &self,
        cells: &[u32],
        rects: &[ScreenRect],
        frustum: &Frustum,
        view: &View,
    ) -> Result<Vec<Range<u32>>, RenderError> {
        let grown: Vec<ScreenRect> = rects
            .iter()
            .map(|r| ScreenRect {
                x0: r.x0 - RECT_MARGIN_PX,
                x1: r.x1 + RECT_MARGIN_PX,
                y0: r.y0 - RECT_MARGIN_PX,
                y1: r.y1 + RECT_MARGIN_PX,
            })
            .collect();
        self.kept_ranges(cells, |i, chunk| {
            !frustum.excludes(chunk.lo, chunk.hi)
                && grown
                    .get(i)
                    .is_none_or(|r| view.box_may_show(chunk.lo, chunk.hi, r))
        })
    }

    /// The index ranges of the chunks of `cells` (in order) that `keep(i, chunk)` keeps for
    /// `cells[i]`, runs of consecutive chunks merged.
    fn kept_ranges(
        &self,
        cells: &[u32],
        keep: impl Fn(usize, &Chunk) -> bool,
    ) -> Result<Vec<Range<u32>>, RenderError> {
        let mut out: Vec<Range<u32>> = Vec::with_capacity(cells.len());
        for (i, &c) in cells.iter().enumerate() {
            let chunks = self
                .cell_chunks
                .get(c as usize)
                .ok_or(RenderError::UnknownCell {
                    cell: c,
                    cells: self.cell_chunks.len(),
                })?;
            for chunk in &self.chunks[chunks.clone()] {
                if chunk.indices.is_empty() || !keep(i, chunk) {
                    continue;
                }
                match out.last_mut() {
                    Some(last) if last.end == chunk.indices.start => last.end = chunk.indices.end,
                    _ => out.push(chunk.indices.clone()),
                }
            }
        }
        Ok(out)
    }
}

/// Pixels added on every side of a cell's rectangle before its chunks are tested: the GPU
/// snaps vertices to a sub-pixel grid and transforms them in f32.
const RECT_MARGIN_PX: i64 = 1;

/// The camera's view volume, for excluding boxes that lie wholly outside it.
pub(crate) struct Frustum {
    eye: DVec3,
    /// Camera axes in the world: image right (either sign: the test is symmetric), up,
    /// forward.
    axes: [DVec3; 3],
    /// Half-width and half-height of the image at unit depth.
    tan: [f64; 2],
    near: f64,
    far: f64,
}

impl Frustum {
    pub fn new(camera: &Camera, width: u32, height: u32) -> Self {
        let p = &camera.pose;
        let t = camera.tan_half_fov();
        Frustum {
            eye: p.position,
            axes: [p.x_body(), p.y_body(), p.z_body()],
            tan: [t * width as f64 / height as f64, t],
            near: camera.near_mm,
            far: camera.far_mm,
        }
    }

    /// True when every point of the box lo–hi lies outside one plane of the frustum, with a
    /// margin (1e-3 mm plus 1e-4 of the depth) far above f32 rounding in the GPU's transform:
    /// such a box gives no fragment.
    pub fn excludes(&self, lo: [f32; 3], hi: [f32; 3]) -> bool {
        // Per plane: does some corner lie inside (or within the margin)?
        let mut inside = [false; 6];
        for k in 0..8 {
            let c = DVec3::new(
                if k & 1 == 0 { lo[0] } else { hi[0] } as f64,
                if k & 2 == 0 { lo[1] } else { hi[1] } as f64,
                if k & 4 == 0 { lo[2] } else { hi[2] } as f64,
            ) - self.eye;
            let (x, y, z) = (
                c.dot(self.axes[0]),
                c.dot(self.axes[1]),
                c.dot(self.axes[2]),
            );
            let margin = 1e-3 + 1e-4 * z.abs();
            let (sx, sy) = (z * self.tan[0] + margin, z * self.tan[1] + margin);
            let tests = [
                x <= sx,
                -x <= sx,
                y <= sy,
                -y <= sy,
                z >= self.near - margin,
                z <= self.far + margin,
            ];
            for (seen, ok) in inside.iter_mut().zip(tests) {
                *seen |= ok;
            }
            if inside.iter().all(|&s| s) {
                return false;
            }
        }
        true
    }
}

/// The buffers' contents in chunk order, with each chunk's range and box and each cell's
/// chunks.
struct Layout {
    vertices: Vec<Vertex>,
    triangles: Vec<[u32; 3]>,
    chunks: Vec<Chunk>,
    cell_chunks: Vec<Range<usize>>,
}

/// Lays the mesh out cell by cell and, within a cell, chunk by chunk: the [`CellMesh`]'s own
/// chunks ([`CellMesh::index_cells`]), each chunk's vertices contiguous (a vertex shared by
/// two chunks appears in both) and its triangles indexing only them. A draw of a run of
/// chunks then touches one short stretch of the vertex buffer; with the surface's own vertex
/// order a cell's indices span most of the buffer, and a driver that shades the whole index
/// range of a draw (Mesa's CPU driver does) would shade every vertex of the colon for every
/// run.
fn chunked(mesh: &CellMesh) -> Layout {
    let indexed;
    let mesh = if mesh.is_indexed() {
        mesh
    } else {
        let mut m = mesh.clone();
        m.index_cells();
        indexed = m;
        &indexed
    };
    let vertices = mesh
        .chunk_vertices
        .iter()
        .map(|&v| Vertex {
            position: mesh.positions[v as usize],
            normal: mesh.normals[v as usize],
        })
        .collect();
    let mut triangles: Vec<[u32; 3]> = Vec::with_capacity(mesh.triangles.len());
    let chunks = mesh
        .chunks
        .iter()
        .zip(&mesh.chunk_vertex_ranges)
        .map(|(c, vr)| {
            let begin = triangles.len() as u32 * 3;
            let local = &mesh.local_triangles[c.triangles.start as usize..c.triangles.end as usize];
            triangles.extend(local.iter().map(|t| t.map(|l| l + vr.start)));
            Chunk {
                indices: begin..triangles.len() as u32 * 3,
                lo: c.lo,
                hi: c.hi,
            }
        })
        .collect();
    let cell_chunks = mesh
        .cell_chunks
        .iter()
        .map(|r| r.start as usize..r.end as usize)
        .collect();
    Layout {
        vertices,
        triangles,
        chunks,
        cell_chunks,
    }
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

    use voyage_nav::Pose;

    fn camera() -> Camera {
        // At the origin looking along +x, up +z, 90° vertical field of view.
        Camera::new(Pose::looking(DVec3::ZERO, DVec3::X, DVec3::Z))
    }

    #[test]
    fn boxes_wholly_outside_one_plane_are_excluded() {
        let f = Frustum::new(&camera(), 200, 100); // half-width 2 at unit depth, half-height 1
        let b = |lo: [f32; 3], hi: [f32; 3]| f.excludes(lo, hi);
        // In front, inside.
        assert!(!b([9.0, -1.0, -1.0], [10.0, 1.0, 1.0]));
        // Behind the eye, and in front of the near plane only.
        assert!(b([-10.0, -1.0, -1.0], [-1.0, 1.0, 1.0]));
        assert!(b([0.0, -1.0, -1.0], [0.05, 1.0, 1.0]));
        // Beyond the far plane.
        assert!(b([1001.0, -1.0, -1.0], [1002.0, 1.0, 1.0]));
        // Above the top plane (z > x) and beside the sides (|y| > 2x), either side.
        assert!(b([5.0, -1.0, 5.5], [5.2, 1.0, 7.0]));
        assert!(b([5.0, 10.5, -1.0], [5.0, 12.0, 1.0]));
        assert!(b([5.0, -12.0, -1.0], [5.0, -10.5, 1.0]));
        // A box straddling a plane, or surrounding the eye, stays.
        assert!(!b([5.0, -1.0, 4.0], [6.0, 1.0, 7.0]));
        assert!(!b([-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]));
        // Each corner outside the side or the top plane but neither wholly (a box across a
        // corner of the view): kept, conservatively.
        assert!(!b([5.0, 9.0, 4.0], [5.0, 11.0, 6.0]));
    }

    #[test]
    fn chunks_tile_each_cell_with_their_own_vertices() {
        // Three cells: 2, 2 500 and 0 triangles of a strip, so the middle cell has 5 chunks.
        let n = 2502usize;
        let positions: Vec<[f32; 3]> = (0..n + 2)
            .map(|i| [i as f32, (i % 2) as f32, 0.0])
            .collect();
        let triangles: Vec<[u32; 3]> = (0..n as u32).map(|i| [i, i + 1, i + 2]).collect();
        let mesh = CellMesh {
            normals: vec![[0.0, 0.0, 1.0]; positions.len()],
            positions,
            surface_triangle: (0..n as u32).collect(),
            triangles,
            cell_ranges: vec![0..2, 2..2502, 2502..2502],
            ..CellMesh::default()
        };
        let l = chunked(&mesh);
        assert_eq!(l.cell_chunks, vec![0..1, 1..6, 6..6]);
        assert_eq!(
            l.chunks
                .iter()
                .map(|c| c.indices.len() / 3)
                .collect::<Vec<_>>(),
            vec![2, 512, 512, 512, 512, 452]
        );
        // The same triangles, in the same order, each chunk indexing only its own vertices.
        let mut seen = 0;
        for c in &l.chunks {
            let tris = &l.triangles[c.indices.start as usize / 3..c.indices.end as usize / 3];
            let (lo, hi) = (
                tris.iter().flatten().min().unwrap(),
                tris.iter().flatten().max().unwrap(),
            );
            assert!(l.chunks.iter().filter(|o| o != &c).all(|o| {
                let other = &l.triangles[o.indices.start as usize / 3..o.indices.end as usize / 3];
                other.iter().flatten().all(|v| v < lo || v > hi)
            }));
            for t in tris {
                let want = mesh.triangles[seen];
                assert_eq!(
                    t.map(|v| l.vertices[v as usize].position),
                    want.map(|v| mesh.positions[v as usize])
                );
                for v in t {
                    let p = l.vertices[*v as usize].position;
                    assert!((0..3).all(|a| c.lo[a] <= p[a] && p[a] <= c.hi[a]));
                }
                seen += 1;
            }
        }
        assert_eq!(seen, n);
    }
}
