//! Mesh import: the CAD files engineers hold, read into one raw triangle soup in file units.
//!
//! Job: read STL (ASCII and binary), OBJ and VRML 2.0 (`.wrl`, as KiCad's 3D library ships its
//! models) into [`RawMesh`] (vertices in the file's units, polygons fan-triangulated), and refuse
//! bad files with a typed [`MeshError`] naming the file and the defect: unreadable, truncated,
//! malformed (with the line), non-finite coordinates, indices out of range, too many triangles.
//! Repair (welding, orientation, holes) and the conversion to metres are in [`super::repair`].
//!
//! Why VRML and not STEP: electronics libraries ship both, but STEP is a B-rep format whose
//! faces must be tessellated by a geometry kernel (NURBS, trimmed surfaces); no well-kept Rust
//! crate tessellates vendor STEP files reliably, and binding OpenCASCADE would add a C++ toolchain
//! to the build. KiCad's library (tens of thousands of parts) ships every model also as VRML 2.0,
//! which is already triangulated (`IndexedFaceSet`), plain text, and small to parse exactly.
//!
//! The parsers are hand-written rather than taken from `stl_io` and `tobj`: each must name the
//! defect and where it is (line, byte count), never trust a declared count before checking it
//! against the file's size, and stop at [`MAX_TRIANGLES`] while reading (so a file of millions of
//! triangles is refused at once, not parsed into memory first).
//!
//! Units: the file's own (converted by the caller). Frames: the file's.

use std::io::Read;
use std::path::Path;

use super::raw::coordinate;
pub use super::raw::{Defect, MAX_TEXT_BYTES, MAX_TRIANGLES, MAX_VERTICES, MeshError, RawMesh};

/// The mesh formats read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// STL, ASCII or binary.
    Stl,
    /// Wavefront OBJ.
    Obj,
    /// VRML 2.0 (`.wrl`, `.vrml`).
    Vrml,
}

impl Format {
    /// The format of a file name from its extension (case-insensitive), if known.
    pub fn of(path: &Path) -> Option<Format> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        match ext.as_str() {
            "stl" => Some(Format::Stl),
            "obj" => Some(Format::Obj),
            "wrl" | "vrml" => Some(Format::Vrml),
            _ => None,
        }
    }
}

/// Reads a mesh file into a raw triangle soup in the file's units.
pub fn read(path: &Path) -> Result<RawMesh, MeshError> {
    let fail = |d: Defect| MeshError::new(path, d);
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_string();
    let format = Format::of(path).ok_or_else(|| fail(Defect::Format(ext)))?;
    let mut file = std::fs::File::open(path).map_err(|e| fail(Defect::Unreadable(e.to_string())))?;
    let bytes = file
        .metadata()
        .map_err(|e| fail(Defect::Unreadable(e.to_string())))?
        .len();
    if format == Format::Stl {
        // A binary STL announces its triangle count in its header: check it before reading on.
        let mut head = [0u8; 84];
        let n = read_up_to(&mut file, &mut head).map_err(|e| fail(Defect::Unreadable(e.to_string())))?;
        let ascii = head[..n].trim_ascii_start().starts_with(b"solid");
        let count = if n == 84 {
            u32::from_le_bytes([head[80], head[81], head[82], head[83]]) as u64
        } else {
            0
        };
        let binary_size = 84 + 50 * count;
        if !(ascii && bytes != binary_size) {
            if n < 84 {
                return Err(fail(Defect::Truncated(format!(
                    "a binary STL needs an 84-byte header, the file has {bytes} bytes"
                ))));
            }
            if count > MAX_TRIANGLES as u64 {
                return Err(fail(Defect::TooManyTriangles {
                    found: count,
                    cap: MAX_TRIANGLES,
                }));
            }
            if bytes < binary_size {
                return Err(fail(Defect::Truncated(format!(
                    "the binary STL header announces {count} triangles ({binary_size} bytes), the file has {bytes} bytes"
                ))));
            }
            let mut body = vec![0u8; (binary_size - 84) as usize];
            file.read_exact(&mut body)
                .map_err(|e| fail(Defect::Unreadable(e.to_string())))?;
            return stl_binary(&body, count as usize).map_err(fail);
        }
        if bytes > MAX_TEXT_BYTES {
            return Err(fail(Defect::TooLarge {
                bytes,
                cap: MAX_TEXT_BYTES,
            }));
        }
        let mut rest = Vec::new();
        file.read_to_end(&mut rest)
            .map_err(|e| fail(Defect::Unreadable(e.to_string())))?;
        let mut all = head[..n].to_vec();
        all.extend(rest);
        let text = String::from_utf8_lossy(&all);
        // Many CAD exporters begin a binary STL's header with "solid" too: one that fails as
        // text and holds bytes no text has is named as the binary STL it is.
        let binary_bytes = n == 84 && all[84..].iter().any(|&b| b == 0 || b >= 0x80);
        return stl_ascii(&text)
            .map_err(|e| {
                if binary_bytes {
                    Defect::Truncated(format!(
                        "a binary STL whose header begins with \"solid\": its header announces {count} \
                         triangles ({binary_size} bytes), the file has {bytes} bytes"
                    ))
                } else {
                    e
                }
            })
            .map_err(fail);
    }
    if bytes > MAX_TEXT_BYTES {
        return Err(fail(Defect::TooLarge {
            bytes,
            cap: MAX_TEXT_BYTES,
        }));
    }
    let mut all = Vec::new();
    file.read_to_end(&mut all)
        .map_err(|e| fail(Defect::Unreadable(e.to_string())))?;
    let text = String::from_utf8_lossy(&all);
    match format {
        Format::Obj => obj(&text),
        Format::Vrml => super::vrml::parse(&text),
        Format::Stl => unreachable!("STL is read above"),
    }
    .map_err(fail)
}

/// Reads as many bytes as the file has, up to `buf`'s length.
fn read_up_to(file: &mut std::fs::File, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut n = 0;
    while n < buf.len() {
        match file.read(&mut buf[n..])? {
            0 => break,
            k => n += k,
        }
    }
    Ok(n)
}

/// The triangles of a binary STL body (after the 84-byte header).
fn stl_binary(body: &[u8], count: usize) -> Result<RawMesh, Defect> {
    let mut m = RawMesh {
        vertices: Vec::with_capacity(3 * count),
        triangles: Vec::with_capacity(count),
    };
    for t in 0..count {
        let rec = &body[50 * t..50 * t + 50];
        for k in 0..3 {
            let mut v = [0.0; 3];
            for (a, c) in v.iter_mut().enumerate() {
                let o = 12 + 12 * k + 4 * a;
                let x = f32::from_le_bytes([rec[o], rec[o + 1], rec[o + 2], rec[o + 3]]);
                if !x.is_finite() {
                    return Err(Defect::NonFinite {
                        at: format!("triangle {}", t + 1),
                        value: x.to_string(),
                    });
                }
                *c = x as f64;
            }
            m.vertices.push(v);
        }
        let b = 3 * t as u32;
        m.triangles.push([b, b + 1, b + 2]);
    }
    Ok(m)
}

/// The triangles of an ASCII STL (one or more `solid` blocks).
fn stl_ascii(text: &str) -> Result<RawMesh, Defect> {
    let mut m = RawMesh::default();
    let mut tk = StlTokens {
        it: text
            .lines()
            .enumerate()
            .flat_map(|(i, l)| l.split_whitespace().map(move |t| (i + 1, t)))
            .peekable(),
        line: 1,
        cut_tail: !text.ends_with(|c: char| c.is_whitespace()),
    };
    let mut solids = 0;
    let mut in_solid = false;
    // The line of the last `solid` or `endsolid`: the rest of it is the solid's name.
    let mut name_line = 0;
    loop {
        let (l, t) = match tk.it.next() {
            Some(x) => x,
            None if in_solid => {
                return Err(Defect::Truncated(format!(
                    "the ASCII STL ends after line {} inside a solid (no \"endsolid\")",
                    tk.line
                )));
            }
            None if solids > 0 => break,
            None => return Err(Defect::Truncated("the ASCII STL has no \"solid\"".into())),
        };
        tk.line = l;
        if l == name_line {
            continue;
        }
        let word = t.to_ascii_lowercase();
        match (in_solid, word.as_str()) {
            (false, "solid") => {
                in_solid = true;
                solids += 1;
                name_line = l;
            }
            (true, "endsolid") => {
                in_solid = false;
                name_line = l;
            }
            (true, "facet") => {
                stl_facet(&mut tk, &mut m)?;
            }
            _ => {
                let want = if in_solid {
                    "\"facet\" or \"endsolid\""
                } else {
                    "\"solid\""
                };
                let d = Defect::Malformed {
                    at: format!("line {l}"),
                    what: format!("expected {want}, got {t:?}"),
                };
                return Err(tk.or_cut(d));
            }
        }
    }
    Ok(m)
}

/// One `facet normal ... endfacet` after its `facet`: its three vertices and triangle into `m`.
fn stl_facet<'a, I: Iterator<Item = (usize, &'a str)>>(
    tk: &mut StlTokens<'a, I>,
    m: &mut RawMesh,
) -> Result<(), Defect> {
    tk.expect("normal")?;
    for _ in 0..3 {
        tk.get("a normal component")?;
    }
    tk.expect("outer")?;
    tk.expect("loop")?;
    let base = m.vertices.len() as u32;
    for _ in 0..3 {
        tk.expect("vertex")?;
        let mut v = [0.0; 3];
        for c in &mut v {
            *c = tk.number()?;
        }
        m.vertices.push(v);
    }
    tk.expect("endloop")?;
    tk.expect("endfacet")?;
    m.triangles.push([base, base + 1, base + 2]);
    if m.triangles.len() > MAX_TRIANGLES {
        return Err(Defect::TooManyTriangles {
            found: m.triangles.len() as u64,
            cap: MAX_TRIANGLES,
        });
    }
    Ok(())
}

/// The whitespace-separated words of an ASCII STL with their line numbers.
struct StlTokens<'a, I: Iterator<Item = (usize, &'a str)>> {
    it: std::iter::Peekable<I>,
    line: usize,
    /// The file ends inside a token (no whitespace after the last one).
    cut_tail: bool,
}
impl<'a, I: Iterator<Item = (usize, &'a str)>> StlTokens<'a, I> {
    /// A defect at the last token of a file that ends inside it is a truncation.
    fn or_cut(&mut self, d: Defect) -> Defect {
        if self.cut_tail && self.it.peek().is_none() {
            Defect::Truncated(format!("the ASCII STL ends inside a word on line {}", self.line))
        } else {
            d
        }
    }
    fn number(&mut self) -> Result<f64, Defect> {
        let (l, t) = self.get("a coordinate")?;
        coordinate(t, || format!("line {l}")).map_err(|d| self.or_cut(d))
    }
    fn get(&mut self, what: &str) -> Result<(usize, &'a str), Defect> {
        match self.it.next() {
            Some((l, t)) => {
                self.line = l;
                Ok((l, t))
            }
            None => Err(Defect::Truncated(format!(
                "the ASCII STL ends after line {}, expected {what}",
                self.line
            ))),
        }
    }
    fn expect(&mut self, want: &str) -> Result<(), Defect> {
        let (l, t) = self.get(&format!("{want:?}"))?;
        if t.eq_ignore_ascii_case(want) {
            Ok(())
        } else {
            let d = Defect::Malformed {
                at: format!("line {l}"),
                what: format!("expected {want:?}, got {t:?}"),
            };
            Err(self.or_cut(d))
        }
    }
}

/// The faces of a Wavefront OBJ (`v` and `f` lines; polygons fan-triangulated; texture and
/// normal indices ignored; negative indices count back from the last vertex).
fn obj(text: &str) -> Result<RawMesh, Defect> {
    let mut m = RawMesh::default();
    let ends_in_newline = text.ends_with('\n');
    let n_lines = text.lines().count();
    for (i, line) in text.lines().enumerate() {
        let at = || format!("line {}", i + 1);
        let last_cut = i + 1 == n_lines && !ends_in_newline;
        let line = line.split('#').next().unwrap_or("");
        let mut it = line.split_whitespace();
        let Some(key) = it.next() else { continue };
        let bad = |what: String| {
            if last_cut {
                Defect::Truncated(format!("the OBJ's last line {} is cut: {what}", i + 1))
            } else {
                Defect::Malformed { at: at(), what }
            }
        };
        match key {
            "v" => {
                let c: Vec<&str> = it.collect();
                if c.len() < 3 {
                    return Err(bad(format!("a vertex needs 3 coordinates, got {}", c.len())));
                }
                let mut v = [0.0; 3];
                for (a, t) in v.iter_mut().zip(&c) {
                    *a = coordinate(t, at)?;
                }
                m.vertices.push(v);
                if m.vertices.len() > MAX_VERTICES {
                    return Err(Defect::TooManyTriangles {
                        found: m.vertices.len() as u64,
                        cap: MAX_TRIANGLES,
                    });
                }
            }
            "f" => {
                let mut poly = Vec::new();
                for t in it {
                    let idx = t.split('/').next().unwrap_or("");
                    let k: i64 = idx
                        .parse()
                        .map_err(|_| bad(format!("expected a vertex index, got {t:?}")))?;
                    let n = m.vertices.len() as i64;
                    let resolved = if k < 0 { n + k } else { k - 1 };
                    if k == 0 || resolved < 0 || resolved >= n {
                        return Err(Defect::IndexOutOfRange {
                            at: at(),
                            index: k,
                            vertices: m.vertices.len(),
                        });
                    }
                    poly.push(resolved as u32);
                }
                if poly.len() < 3 {
                    return Err(bad(format!("a face needs 3 vertices, got {}", poly.len())));
                }
                for k in 1..poly.len() - 1 {
                    m.triangles.push([poly[0], poly[k], poly[k + 1]]);
                }
                if m.triangles.len() > MAX_TRIANGLES {
                    return Err(Defect::TooManyTriangles {
                        found: m.triangles.len() as u64,
                        cap: MAX_TRIANGLES,
                    });
                }
            }
            _ => {}
        }
    }
    Ok(m)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ascii_stl_reads_and_a_cut_one_is_truncated() {
        let t = "solid a b\n facet normal 0 0 1\n  outer loop\n   vertex 0 0 0\n   vertex 1 0 0\n   vertex 0 1 0\n  endloop\n endfacet\nendsolid a b\n";
        let m = stl_ascii(t).unwrap();
        assert_eq!(m.triangles.len(), 1);
        assert_eq!(m.vertices[1], [1.0, 0.0, 0.0]);
        let cut = &t[..t.len() - 30];
        assert!(
            matches!(stl_ascii(cut), Err(Defect::Truncated(_))),
            "{:?}",
            stl_ascii(cut)
        );
        let nan = t.replace("vertex 1 0 0", "vertex nan 0 0");
        assert!(matches!(stl_ascii(&nan), Err(Defect::NonFinite { .. })));
    }

    #[test]
    fn obj_polygons_are_fanned_and_bad_indices_named() {
        let m = obj("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1/1 2//3 3 -1\n").unwrap();
        assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3]]);
        let e = obj("v 0 0 0\nv 1 0 0\nf 1 2 7\n").unwrap_err();
        assert_eq!(e.to_string(), "face index 7 out of range (2 vertices) at line 3");
        assert!(matches!(
            obj("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2"),
            Err(Defect::Truncated(_))
        ));
    }
}
