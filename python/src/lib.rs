//! `voxlod._voxlod`: the Rust side of the `voxlod` Python package. It wraps
//! [`voxlod_format::Reader`] (every check of `Reader::open` and of each node read applies) and
//! [`voxlod_check::verify`], and hands numbers to Python as numpy arrays; `voxlod/__init__.py`
//! builds the user-facing API (the structured node array, docstrings) on top of it.
//!
//! Errors become `voxlod.VoxlodError` carrying the Rust message unchanged (it names the file and
//! the node). Decoding releases the GIL, so Python threads may decode nodes in parallel.

use std::path::PathBuf;

use numpy::{IntoPyArray, PyArrayMethods};
use pyo3::create_exception;
use pyo3::exceptions::{PyException, PyFileNotFoundError, PyKeyError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use voxlod_format::triangles::oct_decode;
use voxlod_format::{FormatError, Reader as RustReader, CHUNK, MODE_CONSERVATIVE};

create_exception!(
    _voxlod,
    VoxlodError,
    PyException,
    "A voxlod file could not be read: its message names the file and what is wrong."
);

/// A reader error as `VoxlodError`; a file that does not exist as `FileNotFoundError`, which
/// `voxlod/__init__.py` turns into `voxlod.VoxlodFileNotFoundError` (both at once).
fn err(e: FormatError) -> PyErr {
    match &e {
        FormatError::Io { source, .. } if source.kind() == std::io::ErrorKind::NotFound => {
            PyFileNotFoundError::new_err(e.to_string())
        }
        _ => VoxlodError::new_err(e.to_string()),
    }
}

/// A flat vector as an `rows × cols` numpy array.
fn table<'py, T: numpy::Element>(
    py: Python<'py>,
    flat: Vec<T>,
    cols: usize,
) -> PyResult<Bound<'py, PyAny>> {
    assert_eq!(flat.len() % cols, 0, "a table of {cols} columns");
    let rows = flat.len() / cols;
    Ok(flat.into_pyarray(py).reshape([rows, cols])?.into_any())
}

/// An opened, validated voxlod file (see `voxlod.Reader`).
#[pyclass(frozen, module = "voxlod._voxlod")]
struct Reader {
    inner: RustReader,
}

impl Reader {
    /// `read` of node `(level, x, y, z)` without the GIL (`KeyError` naming the file when there
    /// is no such node, `VoxlodError` when reading fails).
    fn read<T: Send>(
        &self,
        py: Python<'_>,
        (level, x, y, z): (u32, u32, u32, u32),
        read: impl FnOnce(&RustReader, usize) -> Result<T, FormatError> + Send,
    ) -> PyResult<T> {
        let index = self.inner.find(level, [x, y, z]).ok_or_else(|| {
            PyKeyError::new_err(format!(
                "{}: no node at level {level}, position ({x}, {y}, {z}) (the file has {} levels)",
                self.inner.path().display(),
                self.inner.spec().levels
            ))
        })?;
        py.detach(|| read(&self.inner, index)).map_err(err)
    }

    /// `level` as a level of this file, or `ValueError` naming the file and the levels it has.
    fn check_level(&self, level: i64) -> PyResult<u32> {
        let levels = self.inner.spec().levels;
        u32::try_from(level)
            .ok()
            .filter(|&l| l < levels)
            .ok_or_else(|| {
                PyValueError::new_err(format!(
                    "{}: there is no level {level}: the file's levels are 0 (the leaves) to {} (the root)",
                    self.inner.path().display(),
                    levels.saturating_sub(1)
                ))
            })
    }
}

#[pymethods]
impl Reader {
    #[new]
    fn new(py: Python<'_>, path: PathBuf) -> PyResult<Self> {
        let inner = py.detach(|| RustReader::open(&path)).map_err(err)?;
        Ok(Reader { inner })
    }

    #[getter]
    fn path(&self) -> PathBuf {
        self.inner.path().to_owned()
    }
    #[getter]
    fn resolution(&self) -> u32 {
        self.inner.spec().resolution
    }
    #[getter]
    fn levels(&self) -> u32 {
        self.inner.spec().levels
    }
    #[getter]
    fn mode(&self) -> &'static str {
        if self.inner.spec().mode == MODE_CONSERVATIVE {
            "conservative"
        } else {
            "thin"
        }
    }
    #[getter]
    fn origin(&self) -> (f64, f64, f64) {
        let o = self.inner.spec().origin;
        (o[0], o[1], o[2])
    }
    #[getter]
    fn voxel_size(&self) -> f64 {
        self.inner.spec().voxel_size
    }
    #[getter]
    fn format_version(&self) -> u32 {
        self.inner.header().version
    }
    #[getter]
    fn total_voxels(&self) -> u64 {
        self.inner.total_voxels()
    }
    #[getter]
    fn file_size(&self) -> u64 {
        self.inner.file_size()
    }
    #[getter]
    fn channels(&self) -> Vec<u32> {
        self.inner.channel_ids()
    }
    #[getter]
    fn has_materials(&self) -> bool {
        self.inner.has_materials()
    }
    #[getter]
    fn has_source_triangles(&self) -> bool {
        self.inner.has_source_triangles()
    }
    /// The manifest as JSON text (the wrapper parses it).
    #[getter]
    fn manifest_json(&self) -> String {
        String::from_utf8_lossy(self.inner.manifest_bytes()).into_owned()
    }

    /// The node index as a dict of equal-length numpy columns.
    fn node_columns<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let nodes = self.inner.nodes();
        let col = |f: &dyn Fn(usize) -> u32| (0..nodes.len()).map(f).collect::<Vec<u32>>();
        let d = PyDict::new(py);
        d.set_item("level", col(&|i| nodes[i].level).into_pyarray(py))?;
        d.set_item("x", col(&|i| nodes[i].x).into_pyarray(py))?;
        d.set_item("y", col(&|i| nodes[i].y).into_pyarray(py))?;
        d.set_item("z", col(&|i| nodes[i].z).into_pyarray(py))?;
        d.set_item("voxels", col(&|i| nodes[i].voxel_count).into_pyarray(py))?;
        let masks: Vec<u8> = nodes.iter().map(|e| e.child_mask as u8).collect();
        d.set_item("child_mask", masks.into_pyarray(py))?;
        let offsets: Vec<u64> = nodes.iter().map(|e| e.payload_offset).collect();
        d.set_item("payload_offset", offsets.into_pyarray(py))?;
        let sizes: Vec<u64> = nodes.iter().map(|e| e.payload_size).collect();
        d.set_item("payload_size", sizes.into_pyarray(py))?;
        let bmin: Vec<u8> = nodes.iter().flat_map(|e| e.bounds().0).collect();
        d.set_item("bounds_min", table(py, bmin, 3)?)?;
        let bmax: Vec<u8> = nodes.iter().flat_map(|e| e.bounds().1).collect();
        d.set_item("bounds_max", table(py, bmax, 3)?)?;
        let tris = (0..nodes.len())
            .map(|i| self.inner.node_source_triangle_count(i))
            .collect::<Vec<u32>>();
        d.set_item("source_triangles", tris.into_pyarray(py))?;
        Ok(d)
    }

    /// Every voxel of level `level` as one set of arrays: see `voxlod.Reader.level`.
    fn level<'py>(&self, py: Python<'py>, level: i64) -> PyResult<Bound<'py, PyDict>> {
        let level = self.check_level(level)?;
        let nodes = self.inner.nodes();
        let at_level: Vec<usize> = (0..nodes.len())
            .filter(|&i| nodes[i].level == level)
            .collect();
        let total: usize = at_level
            .iter()
            .map(|&i| nodes[i].voxel_count as usize)
            .sum();
        let materials = self.inner.has_materials();
        let r = &self.inner;
        let cols = py
            .detach(|| -> Result<_, FormatError> {
                let mut pos = Vec::with_capacity(3 * total);
                let mut normal = Vec::with_capacity(3 * total);
                let mut color = Vec::with_capacity(4 * total);
                let mut mask = Vec::with_capacity(total);
                let mut node = Vec::with_capacity(total);
                let mut material = Vec::with_capacity(if materials { total } else { 0 });
                let mut buf = Vec::new();
                for &i in &at_level {
                    r.read_node_into(i, &mut buf)?;
                    let e = &nodes[i];
                    let origin = [e.x, e.y, e.z].map(|c| c * CHUNK);
                    for v in &buf {
                        let p = v.pos();
                        pos.extend((0..3).map(|a| origin[a] + p[a] as u32));
                        normal.extend(v.normal_f32());
                        color.extend(v.rgba());
                        mask.push(v.mask());
                    }
                    node.extend(std::iter::repeat_n(i as u32, buf.len()));
                    if materials {
                        match r.read_materials(i)? {
                            Some(m) => material.extend(m),
                            None => material.extend(std::iter::repeat_n(0, buf.len())),
                        }
                    }
                }
                Ok((pos, normal, color, mask, node, material))
            })
            .map_err(err)?;
        let (pos, normal, color, mask, node, material) = cols;
        let d = PyDict::new(py);
        d.set_item("pos", table(py, pos, 3)?)?;
        d.set_item("face_mask", mask.into_pyarray(py))?;
        d.set_item("normal", table(py, normal, 3)?)?;
        d.set_item("color", table(py, color, 4)?)?;
        if materials {
            d.set_item("material", material.into_pyarray(py))?;
        }
        d.set_item("node", node.into_pyarray(py))?;
        Ok(d)
    }

    /// Decodes node `(level, x, y, z)`: see `voxlod.Reader.decode`.
    fn decode<'py>(
        &self,
        py: Python<'py>,
        level: u32,
        x: u32,
        y: u32,
        z: u32,
    ) -> PyResult<Bound<'py, PyDict>> {
        let (voxels, materials) = self.read(py, (level, x, y, z), |r, i| {
            Ok((r.read_node(i)?, r.read_materials(i)?))
        })?;
        let n = voxels.len();
        let origin = [x, y, z].map(|c| c * CHUNK);
        let mut pos = Vec::with_capacity(3 * n);
        let mut normal = Vec::with_capacity(3 * n);
        let mut color = Vec::with_capacity(4 * n);
        for v in &voxels {
            let p = v.pos();
            pos.extend((0..3).map(|a| origin[a] + p[a] as u32));
            normal.extend(v.normal_f32());
            color.extend(v.rgba());
        }
        let mask: Vec<u8> = voxels.iter().map(|v| v.mask()).collect();
        let d = PyDict::new(py);
        d.set_item("pos", table(py, pos, 3)?)?;
        d.set_item("face_mask", mask.into_pyarray(py))?;
        d.set_item("normal", table(py, normal, 3)?)?;
        d.set_item("color", table(py, color, 4)?)?;
        if let Some(m) = materials {
            d.set_item("material", m.into_pyarray(py))?;
        }
        Ok(d)
    }

    /// The source triangles of leaf `(0, x, y, z)`: see `voxlod.Reader.source_triangles`.
    fn source_triangles<'py>(
        &self,
        py: Python<'py>,
        level: u32,
        x: u32,
        y: u32,
        z: u32,
    ) -> PyResult<Option<Bound<'py, PyDict>>> {
        let read = |r: &RustReader, i| r.source_triangles(i);
        let Some(mesh) = self.read(py, (level, x, y, z), read)? else {
            return Ok(None);
        };
        let origin = [x, y, z].map(|c| (c * CHUNK) as f64);
        let positions: Vec<f64> = (0..mesh.positions.len() as u32)
            .flat_map(|i| {
                let p = mesh.position(i);
                [origin[0] + p[0], origin[1] + p[1], origin[2] + p[2]]
            })
            .collect();
        let d = PyDict::new(py);
        d.set_item("positions", table(py, positions, 3)?)?;
        let tris: Vec<u32> = mesh.triangles.iter().flatten().copied().collect();
        d.set_item("triangles", table(py, tris, 3)?)?;
        let normals = mesh.normals.map(|n| {
            let flat: Vec<f32> = n.iter().flat_map(|&c| oct_decode(c)).collect();
            table(py, flat, 3)
        });
        d.set_item("normals", normals.transpose()?)?;
        let colors = mesh.colors.map(|c| table(py, c.concat(), 4));
        d.set_item("colors", colors.transpose()?)?;
        let materials = mesh.materials.map(|m| m.into_pyarray(py));
        d.set_item("materials", materials)?;
        Ok(Some(d))
    }

    /// Runs every check of `voxlod verify`: see `voxlod.Reader.verify`.
    fn verify<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let path = self.inner.path().to_owned();
        let r = py.detach(|| voxlod_check::verify(&path));
        let d = PyDict::new(py);
        d.set_item("ok", r.ok())?;
        d.set_item("nodes", r.nodes)?;
        d.set_item("nodes_decoded", r.nodes_decoded)?;
        d.set_item("voxels", r.voxels)?;
        d.set_item("parents_checked", r.parents_checked)?;
        d.set_item("leaf_voxels_checked", r.leaf_voxels_checked)?;
        d.set_item("materials_checked", r.materials_checked)?;
        d.set_item("source_triangles_checked", r.source_triangles_checked)?;
        let problems: Vec<String> = r.problems.iter().map(|p| p.to_string()).collect();
        d.set_item("problems", problems)?;
        Ok(d)
    }

    fn __repr__(&self) -> String {
        let s = self.inner.spec();
        format!(
            "voxlod.Reader('{}': {}³ {}, {} levels, {} nodes, {} voxels)",
            self.inner.path().display(),
            s.resolution,
            self.mode(),
            s.levels,
            self.inner.nodes().len(),
            self.inner.total_voxels()
        )
    }
}

/// The compiled half of the `voxlod` package; import `voxlod`, not this.
#[pymodule]
fn _voxlod(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Reader>()?;
    m.add("VoxlodError", m.py().get_type::<VoxlodError>())?;
    m.add("CHUNK", CHUNK)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
