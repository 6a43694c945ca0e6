//! The boundary surface of a mesh in the numbering a renderer wants: its own vertex list, and
//! triangles indexing into it.

/// Surface vertices (mesh indices, increasing) and triangles over them (indices into
/// [`Surface::vertices`], outward).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Surface {
    vertices: Vec<usize>,
    triangles: Vec<[u32; 3]>,
}

impl Surface {
    /// From triangles over the mesh's vertices (all below `num_vertices`).
    pub(crate) fn new(triangles: &[[usize; 3]], num_vertices: usize) -> Self {
        let mut vertices: Vec<usize> = triangles.iter().flatten().copied().collect();
        vertices.sort_unstable();
        vertices.dedup();
        let mut local = vec![u32::MAX; num_vertices];
        for (i, &v) in vertices.iter().enumerate() {
            local[v] = i as u32;
        }
        let triangles = triangles.iter().map(|t| t.map(|v| local[v])).collect();
        Self {
            vertices,
            triangles,
        }
    }

    /// The mesh indices of the surface vertices, increasing.
    pub fn vertices(&self) -> &[usize] {
        &self.vertices
    }

    /// The triangles, indices into [`Self::vertices`].
    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }
}
