//! PLY headers (Turk's format as `rply` and every mesh tool reads it): the one writer of the
//! header lines, so each exporter and test states only its elements and properties.

use std::fmt::Write;

/// A PLY header being built: the format line, then comments, elements and their properties
/// in the order they are added; [`PlyHeader::end`] gives the text with `end_header`.
///
/// ```
/// let mut h = voxlod_io::PlyHeader::binary_le();
/// h.comment("two triangles")
///     .element("vertex", 4)
///     .properties("float", &["x", "y", "z"])
///     .element("face", 2)
///     .list("uchar", "int", "vertex_indices");
/// assert_eq!(
///     h.end(),
///     "ply\nformat binary_little_endian 1.0\ncomment two triangles\nelement vertex 4\n\
///      property float x\nproperty float y\nproperty float z\nelement face 2\n\
///      property list uchar int vertex_indices\nend_header\n"
/// );
/// ```
#[derive(Clone, Debug)]
pub struct PlyHeader {
    text: String,
}

impl PlyHeader {
    /// A binary little-endian PLY.
    pub fn binary_le() -> PlyHeader {
        PlyHeader {
            text: "ply\nformat binary_little_endian 1.0\n".into(),
        }
    }

    /// An ASCII PLY.
    pub fn ascii() -> PlyHeader {
        PlyHeader {
            text: "ply\nformat ascii 1.0\n".into(),
        }
    }

    /// A `comment` line (`text` must not contain a line break).
    pub fn comment(&mut self, text: &str) -> &mut PlyHeader {
        debug_assert!(!text.contains('\n'), "a PLY comment is one line");
        let _ = writeln!(self.text, "comment {text}");
        self
    }

    /// An `element` line: `count` records of `name`, whose properties follow.
    pub fn element(&mut self, name: &str, count: u64) -> &mut PlyHeader {
        let _ = writeln!(self.text, "element {name} {count}");
        self
    }

    /// One scalar `property` of type `ty` (`float`, `uchar`, `int`, ...).
    pub fn property(&mut self, ty: &str, name: &str) -> &mut PlyHeader {
        let _ = writeln!(self.text, "property {ty} {name}");
        self
    }

    /// Scalar properties of one type, in order (`x`, `y`, `z`).
    pub fn properties(&mut self, ty: &str, names: &[&str]) -> &mut PlyHeader {
        for n in names {
            self.property(ty, n);
        }
        self
    }

    /// A `property list` with a `count` type and an `item` type (`uchar int vertex_indices`).
    pub fn list(&mut self, count: &str, item: &str, name: &str) -> &mut PlyHeader {
        let _ = writeln!(self.text, "property list {count} {item} {name}");
        self
    }

    /// The header text, ending with `end_header` and its line break.
    pub fn end(&self) -> String {
        format!("{}end_header\n", self.text)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_ascii_header_with_a_conditional_property() {
        for alpha in [false, true] {
            let mut h = PlyHeader::ascii();
            h.element("vertex", 3)
                .properties("uchar", &["red", "green"]);
            if alpha {
                h.property("uchar", "alpha");
            }
            let want = format!(
                "ply\nformat ascii 1.0\nelement vertex 3\nproperty uchar red\n\
                 property uchar green\n{}end_header\n",
                if alpha { "property uchar alpha\n" } else { "" }
            );
            assert_eq!(h.end(), want);
        }
    }
}
