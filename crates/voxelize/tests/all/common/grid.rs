//! Real meshes on the tool's grid, for this crate's tests only (`#[path]`-included by them: the
//! GPU crate's tests include `common/mod.rs` by path and do not depend on voxlod-ingest).

use voxlod_geom::Triangle;

/// The triangles of a mesh (read by `voxlod-ingest`, with their attributes) in the grid
/// coordinates the tool uses (`Grid::fit` of the bounds, `to_grid`), at `res`.
pub fn mesh_in_grid(path: &std::path::Path, res: u32) -> Vec<Triangle> {
    let src = voxlod_ingest::MeshSource::open(path).unwrap();
    let mut tris = Vec::new();
    src.stream(
        &mut |b: &[Triangle]| {
            tris.extend_from_slice(b);
            Ok(())
        },
        &mut |_, _| {},
    )
    .unwrap();
    let mut bounds = voxlod_geom::Bounds::default();
    bounds.add_triangles(&tris);
    let g = voxlod_geom::Grid::fit(&bounds, res).unwrap();
    for t in &mut tris {
        t.v = t.v.map(|p| g.to_grid(p));
    }
    tris
}
