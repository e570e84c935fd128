//! The material table of a PLY mesh (docs/INGEST.md "Per-face data", docs/TEXTURES.md): from
//! the face element's `material` / `material_index` values with the names that header comments
//! give them (`comment material 3 = wood`, as the shared Munich city has), or from the
//! MeshLab/OpenMVS `comment TextureFile NAME` lines (with a per-face `texnumber` choosing among
//! several). Entry 0 is "no material", as for OBJ; a mesh with at most one material and no
//! usable texture keeps an empty table. Whatever the file has but this reader cannot use is a
//! warning naming the file.

use crate::ply_header::{Header, Kind, Scalar};
use crate::IngestError;
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use voxlod_geom::{Material, MAX_MATERIAL, TRI_HAS_UV, TRI_MATERIAL_SHIFT};

/// What the header and the face data give the triangles.
#[derive(Debug, Default)]
pub(crate) struct PlyMaterials {
    pub materials: Vec<Material>,
    /// Flags every triangle gets beyond the vertex ones: `TRI_HAS_UV` when a texture is used,
    /// and material 1 when one texture (without a material key) covers the whole mesh.
    pub flags: u32,
    /// Some triangles carry face colours.
    pub face_colors: bool,
    pub warnings: Vec<String>,
}

/// `comment material N = NAME` (or `comment material N NAME`): N and NAME.
fn material_name(comment: &str) -> Option<(i64, String)> {
    let rest = comment.strip_prefix("material")?;
    let rest = rest.strip_prefix(char::is_whitespace)?.trim_start();
    let (n, name) = rest.split_once(char::is_whitespace)?;
    let name = name.trim_start();
    let name = name
        .strip_prefix('=')
        .map_or(name, str::trim_start)
        .trim_end();
    Some((n.parse().ok()?, name.to_string())).filter(|(_, s)| !s.is_empty())
}

/// The `TextureFile` comments' file names, in header order.
fn texture_files(header: &Header) -> Vec<String> {
    header
        .comments
        .iter()
        .filter_map(|c| c.strip_prefix("TextureFile"))
        .filter(|r| r.starts_with(char::is_whitespace))
        .map(|r| r.trim().to_string())
        .filter(|r| !r.is_empty())
        .collect()
}

/// Builds the table and completes each face element's [`crate::ply_header::FaceData`] (the
/// `texnumber` key, the sorted key values, unused colours). `scan(element, property, type)`
/// returns the distinct values of an integer property over the element's records.
pub(crate) fn material_table(
    path: &Path,
    scope: &crate::refs::Scope,
    header: &mut Header,
    scan: &mut dyn FnMut(&Header, usize, usize, Scalar) -> Result<BTreeSet<i64>, IngestError>,
) -> Result<PlyMaterials, IngestError> {
    // The material rules in their order of precedence.
    let mut out = PlyMaterials::default();
    // the caller prefixes the input's name to every warning
    let warn = |out: &mut PlyMaterials, w: String| out.warnings.push(w);
    let names: BTreeMap<i64, String> = header
        .comments
        .iter()
        .filter_map(|c| material_name(c))
        .collect();
    let dir = path.parent().unwrap_or(Path::new("."));
    let textures: Vec<(String, Result<PathBuf, String>)> = texture_files(header)
        .into_iter()
        .map(|n| {
            let found = crate::texpath::resolve(dir, &n).and_then(|f| scope.check(&f).map(|()| f));
            (n, found)
        })
        .collect();
    for (n, found) in &textures {
        if let Err(e) = found {
            warn(&mut out, format!("texture {n:?} (comment TextureFile) cannot be used ({e}); its faces keep their colour"));
        }
    }
    let faces: Vec<usize> = header
        .layout
        .sources
        .iter()
        .filter(|s| !s.2)
        .map(|s| s.0)
        .collect();
    let vertex_colors = header.layout.has_colors;
    let mut by_texture = false;
    let mut face_uv = false;
    let mut values = BTreeSet::new();
    for &ei in &faces {
        let list = header
            .layout
            .sources
            .iter()
            .find(|s| s.0 == ei)
            .map_or(0, |s| s.1);
        let el = &mut header.elements[ei];
        let texnumber = el.props.iter().position(|p| {
            p.name == "texnumber" && matches!(p.kind, Kind::Scalar(t) if !t.is_float())
        });
        if let (None, Some(pi), false) = (el.data.key, texnumber, textures.is_empty()) {
            let Kind::Scalar(t) = el.props[pi].kind else {
                unreachable!()
            };
            el.data.key = Some((pi, t));
            by_texture = true;
        }
        let d = &el.data;
        let used = |pi: usize| {
            pi == list
                || d.key.map(|k| k.0) == Some(pi)
                || d.texcoord == Some(pi)
                || d.color.iter().any(|c| c.map(|c| c.0) == Some(pi))
        };
        let unused: Vec<&str> = el
            .props
            .iter()
            .enumerate()
            .filter(|(pi, _)| !used(*pi))
            .map(|(_, p)| p.name.as_str())
            .collect();
        if !unused.is_empty() {
            warn(
                &mut out,
                format!("{} properties not used: {}", el.name, unused.join(", ")),
            );
        }
        if el.data.color[0].is_some() && vertex_colors {
            el.data.color = [None; 4];
            warn(
                &mut out,
                format!(
                    "the {} element's colours are not used: the vertex colours are",
                    el.name
                ),
            );
        }
        out.face_colors |= el.data.color[0].is_some();
        face_uv |= el.data.texcoord.is_some();
        if let Some((pi, ty)) = el.data.key {
            values.extend(scan(header, ei, pi, ty)?);
        }
    }
    let keyed = faces
        .iter()
        .any(|&ei| header.elements[ei].data.key.is_some());
    if keyed && !by_texture {
        values.extend(names.keys().copied());
    }
    let vertex_uv = header.layout.has_texcoords;
    if face_uv && vertex_uv {
        warn(
            &mut out,
            "the vertex texture coordinates are not used: the faces' texcoord lists are".into(),
        );
    }
    let has_uv = face_uv || vertex_uv;
    // the table: one entry per key value, or one for the texture of an unkeyed mesh
    let mut materials = vec![Material::default()];
    let usable = |i: usize| textures.get(i).and_then(|t| t.1.as_ref().ok()).cloned();
    if keyed {
        values.retain(|&v| v >= 0);
        if values.len() > MAX_MATERIAL as usize {
            warn(&mut out, format!("more than {MAX_MATERIAL} material values: the largest count as no material (id 0)"));
        }
        let keys: Vec<i64> = values.iter().copied().take(MAX_MATERIAL as usize).collect();
        if !by_texture && textures.len() > 1 {
            warn(&mut out, "several TextureFile comments and no per-face texnumber: only the first texture is used".into());
        }
        for &v in &keys {
            let (name, texture) = if by_texture {
                let n = textures
                    .get(v as usize)
                    .map_or(format!("texture {v}"), |t| t.0.clone());
                (n, usize::try_from(v).ok().and_then(usable))
            } else {
                (
                    names.get(&v).cloned().unwrap_or(format!("material {v}")),
                    usable(0),
                )
            };
            materials.push(Material {
                name,
                texture,
                ..Material::default()
            });
        }
        for &ei in &faces {
            header.elements[ei].data.keys = keys.clone();
        }
    } else if !textures.is_empty() {
        if textures.len() > 1 {
            warn(&mut out, "several TextureFile comments and no per-face texnumber: only the first texture is used".into());
        }
        materials.push(Material {
            name: textures[0].0.clone(),
            texture: usable(0),
            ..Material::default()
        });
    }
    let textured = materials.iter().any(|m| m.texture.is_some());
    match (has_uv, textured) {
        (true, true) => {
            out.flags |= TRI_HAS_UV;
            if !keyed {
                out.flags |= 1 << TRI_MATERIAL_SHIFT;
            }
        }
        (true, false) if textures.is_empty() => warn(&mut out, "texture coordinates are not used: the header names no texture (comment TextureFile)".into()),
        (true, false) => warn(&mut out, "texture coordinates are not used: no texture could be read".into()),
        (false, true) => warn(&mut out, "the texture (comment TextureFile) is not used: the file has no texture coordinates (vertex u v / s t, or a face texcoord list)".into()),
        (false, false) => {}
    }
    if !(has_uv && textured) {
        materials.iter_mut().for_each(|m| m.texture = None);
        // at most one material and no texture: no table, every triangle material 0
        if materials.len() <= 2 {
            materials.clear();
            out.flags &= !(u32::MAX << TRI_MATERIAL_SHIFT);
            for &ei in &faces {
                header.elements[ei].data.keys.clear();
                header.elements[ei].data.key = None;
            }
        }
    }
    out.materials = materials;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::material_name;

    #[test]
    fn material_names_from_comments() {
        assert_eq!(
            material_name("material 0 = marble"),
            Some((0, "marble".into()))
        );
        assert_eq!(
            material_name("material 12 red brick "),
            Some((12, "red brick".into()))
        );
        assert_eq!(material_name("material 3 ="), None);
        assert_eq!(material_name("materials 3 = x"), None);
        assert_eq!(material_name("material x = y"), None);
    }
}
