//! Finding the texture file a material names (OBJ `map_Kd`, PLY `comment TextureFile`).
//!
//! Exports name textures relative to the material file, often with Windows separators, and
//! often in another letter case than the file on disk (a scene made on a case-insensitive
//! file system: Sponza's MTL says `SP_LUK.JPG` for `sp_luk.JPG`). The exact path is tried
//! first; if it does not exist, each path component is matched case-insensitively against
//! its folder's entries (the first match in sorted order, so the result does not depend on
//! the directory's listing order).

use std::path::{Component, Path, PathBuf};

/// The file option arguments of an MTL texture statement (`map_Kd -s 1 1 1 -clamp on
/// file.png`): how many values each option takes at most. The values are skipped; `-clamp`
/// is reported to the caller.
const OPTIONS: [(&str, usize); 11] = [
    ("-blendu", 1),
    ("-blendv", 1),
    ("-boost", 1),
    ("-cc", 1),
    ("-clamp", 1),
    ("-mm", 2),
    ("-o", 3),
    ("-s", 3),
    ("-t", 3),
    ("-texres", 1),
    ("-imfchan", 1),
];

/// An MTL texture statement's argument split into its file name and whether `-clamp on` was
/// given; `Err` names an option this reader does not know.
pub(crate) fn split_mtl_map(arg: &str) -> Result<(String, bool), String> {
    let mut toks: Vec<&str> = arg.split_ascii_whitespace().collect();
    let mut clamp = false;
    let mut i = 0;
    while i < toks.len() && toks[i].starts_with('-') && toks[i].len() > 1 {
        let Some(&(name, max)) = OPTIONS.iter().find(|(n, _)| *n == toks[i]) else {
            if toks[i] == "-bm" {
                i += 2;
                continue;
            }
            return Err(format!("unknown texture option {}", toks[i]));
        };
        i += 1;
        let mut taken = 0;
        while taken < max && i < toks.len() - 1 {
            let t = toks[i];
            let is_value = t.parse::<f32>().is_ok() || t == "on" || t == "off" || t.len() == 1;
            if !is_value {
                break;
            }
            if name == "-clamp" {
                clamp = t == "on";
            }
            i += 1;
            taken += 1;
        }
    }
    toks.drain(..i);
    if toks.is_empty() {
        return Err("no file name".into());
    }
    Ok((toks.join(" "), clamp))
}

/// The existing file `name` (relative to `dir` unless absolute; `\` read as `/`), matched
/// case-insensitively where the exact path does not exist. `Err` says what was looked for.
pub(crate) fn resolve(dir: &Path, name: &str) -> Result<PathBuf, String> {
    let name = name.trim().trim_matches('"').replace('\\', "/");
    let rel = Path::new(&name);
    let exact = dir.join(rel);
    if exact.is_file() {
        return Ok(exact);
    }
    // component by component, case-insensitively
    let mut at = if rel.is_absolute() {
        PathBuf::from("/")
    } else {
        dir.to_path_buf()
    };
    for c in rel.components() {
        match c {
            Component::RootDir | Component::Prefix(_) => {}
            Component::CurDir => {}
            Component::ParentDir => at.push(".."),
            Component::Normal(part) => {
                let direct = at.join(part);
                if direct.exists() {
                    at = direct;
                    continue;
                }
                let want = part.to_string_lossy().to_lowercase();
                let mut found: Vec<PathBuf> = std::fs::read_dir(&at)
                    .into_iter()
                    .flatten()
                    .flatten()
                    .filter(|e| e.file_name().to_string_lossy().to_lowercase() == want)
                    .map(|e| e.path())
                    .collect();
                found.sort();
                match found.into_iter().next() {
                    Some(p) => at = p,
                    None => {
                        return Err(format!(
                            "{} does not exist (nor in another letter case)",
                            exact.display()
                        ))
                    }
                }
            }
        }
    }
    if at.is_file() {
        Ok(at)
    } else {
        Err(format!("{} is not a file", at.display()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn options_are_skipped() {
        assert_eq!(split_mtl_map("a b.png").unwrap(), ("a b.png".into(), false));
        assert_eq!(
            split_mtl_map("-s 1 1 1 -clamp on tex.jpg").unwrap(),
            ("tex.jpg".into(), true)
        );
        assert_eq!(split_mtl_map("-bm 0.5 n.png").unwrap().0, "n.png");
        assert!(split_mtl_map("-zz 1 x.png").is_err());
        assert!(split_mtl_map("-s 1 1 1").unwrap().0 == "1");
    }

    #[test]
    fn case_insensitive_fallback() {
        let d = tempfile::tempdir().unwrap();
        std::fs::create_dir(d.path().join("Tex")).unwrap();
        std::fs::write(d.path().join("Tex/Brick.JPG"), b"x").unwrap();
        assert_eq!(
            resolve(d.path(), "tex\\brick.jpg").unwrap(),
            d.path().join("Tex/Brick.JPG")
        );
        assert_eq!(
            resolve(d.path(), "Tex/Brick.JPG").unwrap(),
            d.path().join("Tex/Brick.JPG")
        );
        let e = resolve(d.path(), "tex/missing.png").unwrap_err();
        assert!(e.contains("missing.png"), "{e}");
    }
}
