//! Wavefront OBJ reading through `tobj` (triangulated as fans, like PLY polygons), with the
//! MTL diffuse colour `Kd` (alpha: the dissolve `d`) as the colour of all three corners and
//! `vn` normals when every face corner names one. A material with a `map_Kd` texture gets an
//! entry in the material table ([`MeshInfo::materials`]; entry 0 is "no texture") and its
//! triangles carry their `vt` coordinates (`TRI_HAS_UV`) and that entry's index; `Kd` stays
//! their colour, the factor the texture is multiplied by (the MTL definition). `tobj` loads
//! the whole file into memory: OBJ input costs O(file) memory.
//!
//! Because `tobj` reports errors without a line number, [`scan`] first walks the file once
//! and checks what can be checked cheaply (numbers, finite positions, face indices), so the
//! common errors name their line.

use crate::batch::Emitter;
use crate::refs::Scope;
use crate::{IngestError, Location, MeshInfo};
use std::collections::{HashMap, HashSet};
use std::fs::File;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use voxlod_geom::{
    Material, Triangle, Wrap, DEFAULT_COLOR, MAX_MATERIAL, TRI_HAS_COLORS, TRI_HAS_NORMALS,
    TRI_HAS_UV,
};

pub(crate) struct ObjSource {
    path: PathBuf,
    polygons: u64,
    /// Every face corner names a normal: use the `vn` normals.
    use_normals: bool,
    /// Material name → index in the material table, for the materials with a usable texture.
    textured: HashMap<String, u32>,
    /// Material name → index in the material table, for every material faces use (empty for a
    /// mesh with at most one material and no texture).
    ids: HashMap<String, u32>,
    /// Where its MTL files may be read from.
    scope: Scope,
}

/// What [`scan`] found: the counts of the file's records, and the materials it names.
#[derive(Default)]
struct Scan {
    vertices: u64,
    normals: u64,
    texcoords: u64,
    colored_vertices: u64,
    faces: u64,
    corners_without_normal: u64,
    corners_without_texcoord: u64,
    /// materials (by `usemtl` name) with a face corner without a texture coordinate index
    without_texcoord: HashSet<String>,
    mtllibs: Vec<String>,
    used_materials: HashSet<String>,
    /// The material of the faces that follow (the last `usemtl`; empty before the first).
    current_material: String,
}

fn tokens(line: &str) -> std::str::SplitAsciiWhitespace<'_> {
    line.split_ascii_whitespace()
}

/// Checks the file line by line and counts what it declares.
fn scan(path: &Path) -> Result<Scan, IngestError> {
    let file = File::open(path).map_err(|e| IngestError::io(path, e))?;
    let mut r = BufReader::with_capacity(1 << 18, file);
    let mut s = Scan::default();
    let mut buf = Vec::new();
    let mut line_no = 0u64;
    loop {
        buf.clear();
        if r.read_until(b'\n', &mut buf)
            .map_err(|e| IngestError::io(path, e))?
            == 0
        {
            break;
        }
        line_no += 1;
        let at = Location::Line(line_no);
        // tobj reads lines as UTF-8 and fails without a line number ("read error")
        let line = match std::str::from_utf8(&buf) {
            Ok(l) => l,
            Err(e) => {
                return Err(IngestError::malformed(
                    path,
                    at,
                    format!(
                    "byte {} of the line is not valid UTF-8 text (an OBJ file is UTF-8 or ASCII)",
                    e.valid_up_to() + 1
                ),
                ))
            }
        };
        s.line(path, at, line)?;
    }
    Ok(s)
}

impl Scan {
    /// One line, by its keyword; lines of other kinds are left to tobj.
    fn line(&mut self, path: &Path, at: Location, line: &str) -> Result<(), IngestError> {
        let mut t = tokens(line);
        match t.next() {
            Some("v") => self.vertex(path, at, t)?,
            Some(kw @ ("vn" | "vt")) => self.coordinate(path, at, kw, t)?,
            Some("f") => self.face(path, at, t)?,
            Some("mtllib") => {
                let rest = line.trim().strip_prefix("mtllib").unwrap_or("").trim();
                if !rest.is_empty() {
                    self.mtllibs.push(rest.to_string());
                }
            }
            Some("usemtl") => {
                // the name as tobj takes it: the rest of the line
                let name = line.trim().strip_prefix("usemtl").unwrap_or("").trim();
                if !name.is_empty() {
                    self.used_materials.insert(name.to_string());
                    self.current_material = name.to_string();
                }
            }
            _ => {}
        }
        Ok(())
    }

    /// A `v` record: x y z, then nothing, a weight w ≠ 0, or a colour r g b (what tobj
    /// accepts); the position must be finite.
    fn vertex(
        &mut self,
        path: &Path,
        at: Location,
        t: std::str::SplitAsciiWhitespace<'_>,
    ) -> Result<(), IngestError> {
        let vals: Vec<&str> = t.collect();
        if vals.len() < 3 {
            return Err(IngestError::malformed(
                path,
                at,
                "a vertex needs at least 3 coordinates",
            ));
        }
        if !matches!(vals.len(), 3 | 4 | 6) {
            return Err(IngestError::malformed(
                path,
                at,
                format!(
                    "a vertex has {} values; expected x y z, x y z w or x y z r g b",
                    vals.len()
                ),
            ));
        }
        if vals.len() == 4 && vals[3].parse::<f32>().map_or(true, |w| w == 0.0) {
            return Err(IngestError::malformed(
                path,
                at,
                format!(
                    "the vertex weight w = {} is not a non-zero number",
                    crate::error::quoted(vals[3])
                ),
            ));
        }
        let mut p = [0f64; 3];
        for (k, v) in vals[..3].iter().enumerate() {
            p[k] = v.parse::<f32>().map_err(|_| {
                IngestError::malformed(
                    path,
                    at.clone(),
                    format!("{} is not a number", crate::error::quoted(v)),
                )
            })? as f64;
        }
        if !p.iter().all(|x| x.is_finite()) {
            return Err(IngestError::NonFinite {
                path: path.to_path_buf(),
                at,
                vertex: self.vertices,
                coords: p,
            });
        }
        if vals.len() >= 6 {
            self.colored_vertices += 1;
        }
        self.vertices += 1;
        Ok(())
    }

    /// A `vn` (3 numbers) or `vt` (2 numbers) record.
    fn coordinate(
        &mut self,
        path: &Path,
        at: Location,
        kw: &str,
        t: std::str::SplitAsciiWhitespace<'_>,
    ) -> Result<(), IngestError> {
        let (need, what) = if kw == "vn" {
            (3, "a normal needs 3 numbers (vn x y z)")
        } else {
            (2, "a texture coordinate needs 2 numbers (vt u v)")
        };
        let vals: Vec<&str> = t.take(need).collect();
        if vals.len() < need || vals.iter().any(|v| v.parse::<f32>().is_err()) {
            return Err(IngestError::malformed(path, at, what));
        }
        if kw == "vn" {
            self.normals += 1;
        } else {
            self.texcoords += 1;
        }
        Ok(())
    }

    /// An `f` record: every corner's indices refer to records defined before this line.
    fn face(
        &mut self,
        path: &Path,
        at: Location,
        t: std::str::SplitAsciiWhitespace<'_>,
    ) -> Result<(), IngestError> {
        for (corner, c) in t.enumerate() {
            self.corner(path, &at, corner as u64, c)?;
        }
        self.faces += 1;
        Ok(())
    }

    /// Corner `corner` (`v`, `v/vt`, `v//vn` or `v/vt/vn`) of the face being read.
    fn corner(
        &mut self,
        path: &Path,
        at: &Location,
        corner: u64,
        c: &str,
    ) -> Result<(), IngestError> {
        let parts: Vec<&str> = c.split('/').collect();
        if parts.len() > 3 {
            return Err(IngestError::malformed(
                path,
                at.clone(),
                format!(
                    "face corner {} has more than three /-separated indices (v/vt/vn)",
                    crate::error::quoted(c)
                ),
            ));
        }
        // texture coordinate and normal indices: tobj checks them only after the whole file,
        // without a line number
        for (k, kind, count) in [
            (1, "texture coordinate", self.texcoords),
            (2, "normal", self.normals),
        ] {
            let Some(p) = parts.get(k).filter(|p| !p.is_empty()) else {
                continue;
            };
            let idx: Option<i64> = p.parse().ok();
            let ok = idx.is_some_and(|i| {
                let r = if i < 0 { count as i64 + i } else { i - 1 };
                i != 0 && r >= 0 && (r as u64) < count
            });
            if !ok {
                return Err(IngestError::malformed(
                    path,
                    at.clone(),
                    format!(
                        "face corner {} refers to {kind} {}, but {count} {kind}s are defined before this line (indices are 1..={count}, or -1..=-{count} counting back)",
                        crate::error::quoted(c),
                        crate::error::quoted(p)
                    ),
                ));
            }
        }
        let v = parts[0];
        let has_normal = parts.get(2).is_some_and(|n| !n.is_empty());
        let idx: i64 = v.parse().map_err(|_| {
            IngestError::malformed(
                path,
                at.clone(),
                format!(
                    "face corner {} has no vertex index",
                    crate::error::quoted(c)
                ),
            )
        })?;
        // 1-based, or negative: relative to the vertices read so far
        let resolved = if idx < 0 {
            self.vertices as i64 + idx
        } else {
            idx - 1
        };
        if idx == 0 || resolved < 0 || resolved as u64 >= self.vertices {
            return Err(IngestError::IndexOutOfRange {
                path: path.to_path_buf(),
                at: at.clone(),
                face: self.faces,
                corner,
                index: idx,
                vertices: self.vertices,
            });
        }
        if !has_normal {
            self.corners_without_normal += 1;
        }
        if parts.get(1).is_none_or(|t| t.is_empty()) {
            self.corners_without_texcoord += 1;
            if !self.without_texcoord.contains(&self.current_material) {
                self.without_texcoord.insert(self.current_material.clone());
            }
        }
        Ok(())
    }
}

impl ObjSource {
    pub fn open(path: &Path, scope: &Scope) -> Result<(ObjSource, MeshInfo), IngestError> {
        let s = scan(path)?;
        let mut warnings = Vec::new();
        let mut has_colors = s.colored_vertices > 0 && s.colored_vertices == s.vertices;
        let dir = path.parent().unwrap_or(Path::new("."));
        // entry 0: faces without a material; then every material that faces use, in MTL
        // order (its texture, if it has a usable one, is set below). The table gives both the
        // textures and the per-voxel material channel's ids (docs/FORMAT.md 14.3).
        let mut materials = vec![Material::default()];
        let mut ids: HashMap<String, u32> = HashMap::new();
        let mut textured = HashMap::new();
        let mut too_many = false;
        for lib in &s.mtllibs {
            let p = dir.join(lib);
            let loaded = scope
                .load_mtl(&p)
                .and_then(|r| r.map_err(|e| e.to_string()));
            match loaded {
                Ok((mats, _)) => {
                    has_colors |= mats.iter().any(|m| m.diffuse.is_some() && s.used_materials.contains(&m.name));
                    let mtl_dir = p.parent().unwrap_or(Path::new("."));
                    for m in &mats {
                        if !s.used_materials.contains(&m.name) || ids.contains_key(&m.name) {
                            continue;
                        }
                        if materials.len() > MAX_MATERIAL as usize {
                            too_many = true;
                            continue;
                        }
                        let id = materials.len() as u32;
                        ids.insert(m.name.clone(), id);
                        materials.push(Material {
                            name: m.name.clone(),
                            ..Material::default()
                        });
                        let Some(map) = &m.diffuse_texture else { continue };
                        if s.texcoords > 0 && s.without_texcoord.contains(&m.name) {
                            warnings.push(format!(
                                "material {:?} has a texture (map_Kd) but some of its faces have no texture coordinate index; its Kd is used",
                                m.name
                            ));
                            continue;
                        }
                        let found = crate::texpath::split_mtl_map(map).and_then(|(file, clamp)| {
                            let f = crate::texpath::resolve(mtl_dir, &file)?;
                            scope.check(&f).map(|()| (f, clamp))
                        });
                        match found {
                            Ok((file, clamp)) => {
                                let wrap = if clamp { Wrap::Clamp } else { Wrap::Repeat };
                                textured.insert(m.name.clone(), id);
                                let e = &mut materials[id as usize];
                                e.texture = Some(file);
                                e.wrap = [wrap; 2];
                            }
                            Err(e) => warnings.push(format!(
                                "material {:?} in {}: texture map_Kd {:?} cannot be used ({e}); its Kd is used",
                                m.name,
                                p.display(),
                                map
                            )),
                        }
                    }
                }
                Err(e) => warnings.push(format!(
                    "material library {} cannot be read ({e}); its materials get the default colour",
                    p.display()
                )),
            }
        }
        if too_many {
            warnings.push(format!(
                "more than {MAX_MATERIAL} materials: the others count as no material (id 0) and their textures are ignored"
            ));
        }
        if !s.used_materials.is_empty() && s.mtllibs.is_empty() {
            warnings.push("usemtl without mtllib: materials get the default colour".into());
        }
        if !textured.is_empty() && s.texcoords == 0 {
            warnings.push(
                "materials have textures (map_Kd) but the file has no texture coordinates (vt); their Kd is used"
                    .into(),
            );
        }
        let has_texcoords = !textured.is_empty() && s.texcoords > 0;
        if !has_texcoords {
            textured.clear();
            for m in &mut materials {
                m.texture = None;
            }
        }
        // a mesh with at most one material and no texture: no table, as before materials
        if !has_texcoords && materials.len() <= 2 {
            materials.clear();
            ids.clear();
        }
        let use_normals = s.normals > 0 && s.corners_without_normal == 0;
        if s.normals > 0 && !use_normals {
            warnings.push(format!(
                "{} face corners have no normal index; vertex normals ignored, face normals used",
                s.corners_without_normal
            ));
        }
        let info = MeshInfo {
            path: path.to_path_buf(),
            format: "obj".into(),
            vertices: s.vertices,
            faces: s.faces,
            has_normals: use_normals,
            has_colors,
            has_texcoords,
            materials,
            warnings,
            up: None,
            held: 0,
        };
        Ok((
            ObjSource {
                path: path.to_path_buf(),
                polygons: s.faces,
                use_normals,
                textured,
                ids,
                scope: scope.clone(),
            },
            info,
        ))
    }

    pub fn stream(&self, em: &mut Emitter) -> Result<(), IngestError> {
        let path = &self.path;
        // `..Default::default()` covers fields that tobj features enabled elsewhere may add
        #[allow(clippy::needless_update)]
        let opts = tobj::LoadOptions {
            triangulate: true,
            single_index: false,
            ignore_points: true,
            ignore_lines: true,
            ..Default::default()
        };
        // tobj reads `l 1 2 3` (a polyline) as a polygon face whatever `ignore_lines` says:
        // the lines go to it blanked, as INGEST.md promises (line numbers unchanged).
        let file = File::open(path).map_err(|e| IngestError::io(path, e))?;
        let mut reader = BufReader::with_capacity(
            1 << 16,
            WithoutPolylines {
                inner: BufReader::with_capacity(1 << 18, file),
                line: Vec::new(),
                pos: 0,
            },
        );
        let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
        let (models, materials) = tobj::load_obj_buf(&mut reader, &opts, |m| {
            // refused at open with a warning; the same refusal here
            let refused = |_| Err(tobj::LoadError::OpenFileFailed);
            self.scope.load_mtl(&dir.join(m)).unwrap_or_else(refused)
        })
        .map_err(|e| IngestError::Obj {
            path: path.to_path_buf(),
            // the scan at open checks each line for what tobj refuses, so this is rare
            message: format!("{e} (tobj does not say on which line)"),
        })?;
        // a missing MTL was reported as a warning at open; its materials get the default colour
        let materials = materials.unwrap_or_default();
        em.report(em.bytes_total / 2);
        for m in &models {
            let mesh = &m.mesh;
            let material = mesh.material_id.and_then(|i| materials.get(i));
            let mat = material.and_then(|m| m.diffuse);
            let alpha = material.and_then(|m| m.dissolve).unwrap_or(1.0);
            // the material's entry in the table if it has a usable texture and every corner of
            // this model has a texture coordinate
            let tex = material
                .and_then(|m| self.textured.get(&m.name).copied())
                .filter(|_| {
                    mesh.texcoord_indices.len() == mesh.indices.len() && !mesh.texcoords.is_empty()
                });
            let id = material.and_then(|m| self.ids.get(&m.name).copied());
            let vcol =
                mesh.vertex_color.len() == mesh.positions.len() && !mesh.vertex_color.is_empty();
            let normals = self.use_normals
                && mesh.normal_indices.len() == mesh.indices.len()
                && !mesh.normals.is_empty();
            let mut flags = if normals { TRI_HAS_NORMALS } else { 0 };
            if vcol || mat.is_some() {
                flags |= TRI_HAS_COLORS;
            }
            if tex.is_some() {
                flags |= TRI_HAS_UV;
            }
            let mut mat_color = mat
                .map(|d| rgba8([d[0], d[1], d[2]]))
                .unwrap_or(DEFAULT_COLOR);
            if mat.is_some() {
                mat_color[3] = (alpha * 255.0).round().clamp(0.0, 255.0) as u8;
            }
            let get3 = |a: &[f32], i: usize| -> Option<[f32; 3]> {
                a.get(3 * i..3 * i + 3).map(|s| [s[0], s[1], s[2]])
            };
            for (t, tri) in mesh.indices.chunks_exact(3).enumerate() {
                let tri = [tri[0] as usize, tri[1] as usize, tri[2] as usize];
                if tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2] {
                    em.repeated_index();
                    continue;
                }
                let bad = || IngestError::Obj {
                    path: path.to_path_buf(),
                    message: format!("object {:?} triangle {t} refers to missing data", m.name),
                };
                let mut out = Triangle::new([[0.0; 3]; 3]);
                out.flags = flags;
                if let Some(m) = id {
                    out.set_material(m);
                }
                for (k, &vi) in tri.iter().enumerate() {
                    out.v[k] = get3(&mesh.positions, vi).ok_or_else(bad)?;
                    if normals {
                        out.n[k] = get3(&mesh.normals, mesh.normal_indices[3 * t + k] as usize)
                            .ok_or_else(bad)?;
                    }
                    if tex.is_some() {
                        let ti = mesh.texcoord_indices[3 * t + k] as usize;
                        let uv = mesh.texcoords.get(2 * ti..2 * ti + 2).ok_or_else(bad)?;
                        out.uv[k] = [uv[0], uv[1]];
                    }
                    out.c[k] = if vcol {
                        rgba8(get3(&mesh.vertex_color, vi).ok_or_else(bad)?)
                    } else {
                        mat_color
                    };
                }
                if !out.is_finite() {
                    // the scan refuses non-finite positions; this only guards against tobj disagreeing
                    return Err(IngestError::Obj {
                        path: path.to_path_buf(),
                        message: format!(
                            "object {:?} triangle {t} has a non-finite coordinate",
                            m.name
                        ),
                    });
                }
                em.push(out)?;
            }
        }
        em.stats.polygons = self.polygons;
        Ok(())
    }
}

/// An OBJ text with every polyline (`l …`) line replaced by an empty line.
struct WithoutPolylines<R> {
    inner: R,
    /// The current line, `pos` bytes of it already handed out.
    line: Vec<u8>,
    pos: usize,
}

/// True for a line whose first token is `l`.
fn is_polyline(line: &[u8]) -> bool {
    let t = line.trim_ascii_start();
    t.first() == Some(&b'l') && t.get(1).is_none_or(|b| b.is_ascii_whitespace())
}

impl<R: BufRead> std::io::Read for WithoutPolylines<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        if self.pos == self.line.len() {
            self.line.clear();
            self.pos = 0;
            if self.inner.read_until(b'\n', &mut self.line)? == 0 {
                return Ok(0);
            }
            if is_polyline(&self.line) {
                let nl = self.line.ends_with(b"\n");
                self.line.clear();
                if nl {
                    self.line.push(b'\n');
                }
            }
        }
        let n = buf.len().min(self.line.len() - self.pos);
        buf[..n].copy_from_slice(&self.line[self.pos..self.pos + n]);
        self.pos += n;
        Ok(n)
    }
}

fn rgba8(c: [f32; 3]) -> [u8; 4] {
    let b = |x: f32| (x * 255.0).round().clamp(0.0, 255.0) as u8;
    [b(c[0]), b(c[1]), b(c[2]), 255]
}
