//! VRML 2.0 (`.wrl`) reader: the subset that CAD exporters, KiCad's 3D library among them, write
//! for triangulated solids.
//!
//! Job: tokenise the file, parse its node tree (with `DEF`/`USE`), and collect the triangles of
//! every `Shape`'s `IndexedFaceSet` (`coord Coordinate { point [...] }`, `coordIndex [...]` with
//! `-1` ending each polygon, `ccw`), placed by the `Transform`s around it (`translation`,
//! `rotation` axis-angle, `scale`, `center`; `Group`, `Transform` and `Collision` children).
//! Appearance, materials, normals, colours, lights and viewpoints are read and ignored; line and
//! point sets carry no surface and are skipped; primitive geometry (`Box`, `Sphere`, ...) and
//! `scaleOrientation` are refused as unsupported rather than silently dropped. Several shapes
//! make one part (KiCad writes one shape per material: body, pins, marking).
//!
//! Units: the file's (KiCad: 0.1 inch, i.e. 2.54 mm, per unit). Frames: the file's root frame.

use std::collections::HashMap;

use nalgebra::{Matrix4, Rotation3, Unit, Vector3};

use super::raw::{Defect, MAX_TRIANGLES, MAX_VERTICES, RawMesh, coordinate};

/// The deepest node nesting read (a guard against files built to exhaust the stack).
const MAX_DEPTH: usize = 64;

#[derive(Debug, Clone, PartialEq)]
enum Tok<'a> {
    Open,
    Close,
    OpenList,
    CloseList,
    Word(&'a str),
    Str,
}

/// The tokens of the file with their line numbers (`#` comments, commas and whitespace dropped).
fn tokens(text: &str) -> Result<Vec<(usize, Tok<'_>)>, Defect> {
    let mut out = Vec::new();
    let b = text.as_bytes();
    let (mut i, mut line) = (0, 1);
    while i < b.len() {
        let c = b[i];
        match c {
            b'\n' => {
                line += 1;
                i += 1;
            }
            b'#' => {
                while i < b.len() && b[i] != b'\n' {
                    i += 1;
                }
            }
            b'{' | b'}' | b'[' | b']' => {
                out.push((
                    line,
                    match c {
                        b'{' => Tok::Open,
                        b'}' => Tok::Close,
                        b'[' => Tok::OpenList,
                        _ => Tok::CloseList,
                    },
                ));
                i += 1;
            }
            b'"' => {
                let start = line;
                i += 1;
                while i < b.len() && b[i] != b'"' {
                    if b[i] == b'\\' {
                        i += 1;
                    }
                    if i < b.len() && b[i] == b'\n' {
                        line += 1;
                    }
                    i += 1;
                }
                if i >= b.len() {
                    return Err(Defect::Truncated(format!(
                        "a string opened at line {start} never closes"
                    )));
                }
                i += 1;
                out.push((start, Tok::Str));
            }
            c if c.is_ascii_whitespace() || c == b',' => i += 1,
            _ => {
                let s = i;
                while i < b.len() && !(b[i].is_ascii_whitespace() || b"{}[],#\"".contains(&b[i])) {
                    i += 1;
                }
                out.push((line, Tok::Word(&text[s..i])));
            }
        }
    }
    Ok(out)
}

/// A field value.
#[derive(Debug, Clone)]
enum Value {
    /// Numbers and words (`1 0 0`, `TRUE`, `[0, 1, 2, -1]`), with the line of each.
    Atoms(Vec<(usize, String)>),
    /// Nodes (`SFNode` or `[ ... ]` of nodes).
    Nodes(Vec<Node>),
}

/// A node: its type and fields.
#[derive(Debug, Clone)]
struct Node {
    kind: String,
    line: usize,
    fields: Vec<(String, Value)>,
}

impl Node {
    fn field(&self, name: &str) -> Option<&Value> {
        self.fields.iter().find(|(n, _)| n == name).map(|(_, v)| v)
    }
    fn nodes(&self, name: &str) -> &[Node] {
        match self.field(name) {
            Some(Value::Nodes(n)) => n,
            _ => &[],
        }
    }
    fn numbers(&self, name: &str) -> Result<Option<Vec<f64>>, Defect> {
        match self.field(name) {
            Some(Value::Atoms(a)) => a
                .iter()
                .map(|(l, t)| coordinate(t, || format!("line {l}")))
                .collect::<Result<Vec<_>, _>>()
                .map(Some),
            Some(Value::Nodes(_)) => Err(Defect::Malformed {
                at: format!("line {}", self.line),
                what: format!("{} field {name} must hold numbers, got a node", self.kind),
            }),
            None => Ok(None),
        }
    }
    fn vec3(&self, name: &str, default: [f64; 3]) -> Result<Vector3<f64>, Defect> {
        match self.numbers(name)? {
            None => Ok(Vector3::from(default)),
            Some(v) if v.len() == 3 => Ok(Vector3::new(v[0], v[1], v[2])),
            Some(v) => Err(Defect::Malformed {
                at: format!("line {}", self.line),
                what: format!("{} field {name} needs 3 numbers, got {}", self.kind, v.len()),
            }),
        }
    }
    fn flag(&self, name: &str, default: bool) -> bool {
        match self.field(name) {
            Some(Value::Atoms(a)) => a.first().map_or(default, |(_, t)| t == "TRUE"),
            _ => default,
        }
    }
}

struct Parser<'a> {
    toks: Vec<(usize, Tok<'a>)>,
    at: usize,
    defs: HashMap<String, Node>,
}

impl<'a> Parser<'a> {
    fn peek(&self, k: usize) -> Option<&Tok<'a>> {
        self.toks.get(self.at + k).map(|(_, t)| t)
    }
    fn line(&self) -> usize {
        self.toks.get(self.at).or(self.toks.last()).map_or(1, |(l, _)| *l)
    }
    fn truncated(&self, inside: &str) -> Defect {
        Defect::Truncated(format!(
            "the VRML ends after line {} inside {inside}",
            self.toks.last().map_or(1, |(l, _)| *l)
        ))
    }
    fn bump(&mut self) -> Option<(usize, Tok<'a>)> {
        let t = self.toks.get(self.at).cloned();
        self.at += 1;
        t
    }

    /// A node statement: `[DEF name] Type { fields }` or `USE name`.
    fn node(&mut self, depth: usize) -> Result<Node, Defect> {
        if depth > MAX_DEPTH {
            return Err(Defect::Unsupported(format!(
                "nodes nested deeper than {MAX_DEPTH} levels at line {}",
                self.line()
            )));
        }
        let (line, t) = self.bump().ok_or_else(|| self.truncated("a node"))?;
        let Tok::Word(w) = t else {
            return Err(Defect::Malformed {
                at: format!("line {line}"),
                what: format!("expected a node, got {t:?}"),
            });
        };
        match w {
            "USE" => {
                let (l, t) = self.bump().ok_or_else(|| self.truncated("USE"))?;
                let Tok::Word(name) = t else {
                    return Err(Defect::Malformed {
                        at: format!("line {l}"),
                        what: "USE needs a name".into(),
                    });
                };
                self.defs.get(name).cloned().ok_or_else(|| Defect::Malformed {
                    at: format!("line {l}"),
                    what: format!("USE {name} names no DEF before it"),
                })
            }
            "DEF" => {
                let (l, t) = self.bump().ok_or_else(|| self.truncated("DEF"))?;
                let Tok::Word(name) = t else {
                    return Err(Defect::Malformed {
                        at: format!("line {l}"),
                        what: "DEF needs a name".into(),
                    });
                };
                let n = self.node(depth)?;
                self.defs.insert(name.to_string(), n.clone());
                Ok(n)
            }
            kind => {
                match self.bump() {
                    Some((_, Tok::Open)) => {}
                    Some((l, t)) => {
                        return Err(Defect::Malformed {
                            at: format!("line {l}"),
                            what: format!("expected {{ after {kind}, got {t:?}"),
                        });
                    }
                    None => return Err(self.truncated(kind)),
                }
                let mut node = Node {
                    kind: kind.to_string(),
                    line,
                    fields: Vec::new(),
                };
                loop {
                    let (l, t) = self
                        .bump()
                        .ok_or_else(|| self.truncated(&format!("the {kind} node opened at line {line}")))?;
                    match t {
                        Tok::Close => return Ok(node),
                        Tok::Word(name) => {
                            let v = self.value(depth, kind, line)?;
                            node.fields.push((name.to_string(), v));
                        }
                        t => {
                            return Err(Defect::Malformed {
                                at: format!("line {l}"),
                                what: format!("expected a field of {kind}, got {t:?}"),
                            });
                        }
                    }
                }
            }
        }
    }

    /// Whether the tokens ahead start a node.
    fn node_ahead(&self) -> bool {
        matches!(
            (self.peek(0), self.peek(1)),
            (Some(Tok::Word("DEF" | "USE")), _) | (Some(Tok::Word(_)), Some(Tok::Open))
        )
    }

    /// A field's value: a node, a list in brackets, or the atoms up to the next field name.
    fn value(&mut self, depth: usize, kind: &str, line: usize) -> Result<Value, Defect> {
        let inside = || format!("the {kind} node opened at line {line}");
        if self.node_ahead() {
            return Ok(Value::Nodes(vec![self.node(depth + 1)?]));
        }
        match self.peek(0) {
            None => Err(self.truncated(&inside())),
            Some(Tok::OpenList) => {
                self.at += 1;
                let mut atoms = Vec::new();
                let mut nodes = Vec::new();
                loop {
                    if self.node_ahead() {
                        nodes.push(self.node(depth + 1)?);
                        continue;
                    }
                    match self.bump() {
                        None => return Err(self.truncated(&format!("a list in {}", inside()))),
                        Some((_, Tok::CloseList)) => break,
                        Some((l, Tok::Word(w))) => atoms.push((l, w.to_string())),
                        Some((_, Tok::Str)) => {}
                        Some((l, t)) => {
                            return Err(Defect::Malformed {
                                at: format!("line {l}"),
                                what: format!("unexpected {t:?} in a list"),
                            });
                        }
                    }
                    if atoms.len() > 4 * MAX_VERTICES {
                        return Err(Defect::TooManyTriangles {
                            found: atoms.len() as u64 / 4,
                            cap: MAX_TRIANGLES,
                        });
                    }
                }
                Ok(if nodes.is_empty() {
                    Value::Atoms(atoms)
                } else {
                    Value::Nodes(nodes)
                })
            }
            Some(Tok::Str) => {
                self.at += 1;
                Ok(Value::Atoms(Vec::new()))
            }
            Some(Tok::Word(_)) => {
                // Single values: numbers (as many as follow) or one word (TRUE, FALSE, NULL).
                let mut atoms = Vec::new();
                while let Some((l, Tok::Word(w))) = self.toks.get(self.at).cloned() {
                    let numeric = w.starts_with(|c: char| c.is_ascii_digit() || c == '-' || c == '+' || c == '.')
                        || w.eq_ignore_ascii_case("nan")
                        || w.eq_ignore_ascii_case("inf");
                    if !atoms.is_empty() && !numeric {
                        break;
                    }
                    atoms.push((l, w.to_string()));
                    self.at += 1;
                    if !numeric {
                        break;
                    }
                }
                Ok(Value::Atoms(atoms))
            }
            Some(t) => Err(Defect::Malformed {
                at: format!("line {}", self.line()),
                what: format!("unexpected {t:?} as a field value in {}", inside()),
            }),
        }
    }
}

/// Parses VRML 2.0 text into the triangles of all its shapes, in the root frame.
pub fn parse(text: &str) -> Result<RawMesh, Defect> {
    let head = text.lines().next().unwrap_or("");
    if !head.starts_with("#VRML V2.0") {
        return Err(Defect::Unsupported(format!(
            "not VRML 2.0: the first line must start with \"#VRML V2.0\", got {:?}",
            head.chars().take(40).collect::<String>()
        )));
    }
    let mut p = Parser {
        toks: tokens(text)?,
        at: 0,
        defs: HashMap::new(),
    };
    let mut roots = Vec::new();
    while p.at < p.toks.len() {
        match p.peek(0) {
            Some(Tok::Word("ROUTE")) => {
                // ROUTE a.b TO c.d
                p.at += 4;
            }
            Some(Tok::Word("PROTO" | "EXTERNPROTO")) => {
                return Err(Defect::Unsupported(format!("PROTO at line {}", p.line())));
            }
            _ => roots.push(p.node(0)?),
        }
    }
    let mut mesh = RawMesh::default();
    for n in &roots {
        collect(n, &Matrix4::identity(), &mut mesh)?;
    }
    Ok(mesh)
}

/// The matrix of a Transform node: T C R S C^-1.
fn transform(n: &Node) -> Result<Matrix4<f64>, Defect> {
    let t = n.vec3("translation", [0.0; 3])?;
    let c = n.vec3("center", [0.0; 3])?;
    let s = n.vec3("scale", [1.0; 3])?;
    let r = match n.numbers("rotation")? {
        None => vec![0.0, 0.0, 1.0, 0.0],
        Some(r) if r.len() == 4 => r,
        Some(r) => {
            return Err(Defect::Malformed {
                at: format!("line {}", n.line),
                what: format!("Transform rotation needs 4 numbers (axis, angle), got {}", r.len()),
            });
        }
    };
    if let Some(so) = n.numbers("scaleOrientation")?
        && so.len() == 4
        && so[3] != 0.0
        && !(s.x == s.y && s.y == s.z)
    {
        return Err(Defect::Unsupported(format!(
            "Transform at line {} with a non-uniform scale along a scaleOrientation",
            n.line
        )));
    }
    let axis = Vector3::new(r[0], r[1], r[2]);
    let rot = if axis.norm() > 0.0 && r[3] != 0.0 {
        Rotation3::from_axis_angle(&Unit::new_normalize(axis), r[3]).to_homogeneous()
    } else {
        Matrix4::identity()
    };
    Ok(Matrix4::new_translation(&(t + c)) * rot * Matrix4::new_nonuniform_scaling(&s) * Matrix4::new_translation(&-c))
}

/// Adds the triangles under `n`, placed by `world_from_node`.
fn collect(n: &Node, world_from_node: &Matrix4<f64>, mesh: &mut RawMesh) -> Result<(), Defect> {
    match n.kind.as_str() {
        "Transform" => {
            let m = world_from_node * transform(n)?;
            for c in n.nodes("children") {
                collect(c, &m, mesh)?;
            }
        }
        "Group" | "Collision" | "Anchor" | "Billboard" => {
            for c in n.nodes("children") {
                collect(c, world_from_node, mesh)?;
            }
        }
        "Switch" => {
            // The chosen child only (whichChoice, -1 = none).
            let which = n
                .numbers("whichChoice")?
                .and_then(|v| v.first().copied())
                .unwrap_or(-1.0);
            if which >= 0.0
                && let Some(c) = n.nodes("choice").get(which as usize)
            {
                collect(c, world_from_node, mesh)?;
            }
        }
        "Shape" => {
            for g in n.nodes("geometry") {
                geometry(g, world_from_node, mesh)?;
            }
        }
        _ => {}
    }
    Ok(())
}

/// Adds one geometry node's triangles.
fn geometry(g: &Node, world_from_node: &Matrix4<f64>, mesh: &mut RawMesh) -> Result<(), Defect> {
    match g.kind.as_str() {
        "IndexedFaceSet" => {}
        "IndexedLineSet" | "PointSet" | "Text" => return Ok(()),
        other => {
            return Err(Defect::Unsupported(format!(
                "{other} geometry at line {} (only IndexedFaceSet is read)",
                g.line
            )));
        }
    }
    let Some(coord) = g.nodes("coord").first() else {
        return Err(Defect::Malformed {
            at: format!("line {}", g.line),
            what: "IndexedFaceSet without coord".into(),
        });
    };
    let pts = coord.numbers("point")?.unwrap_or_default();
    if pts.len() % 3 != 0 {
        return Err(Defect::Malformed {
            at: format!("line {}", coord.line),
            what: format!("Coordinate point holds {} numbers, not a multiple of 3", pts.len()),
        });
    }
    let base = mesh.vertices.len();
    let n_pts = pts.len() / 3;
    if base + n_pts > MAX_VERTICES {
        return Err(Defect::TooManyTriangles {
            found: ((base + n_pts) / 3) as u64,
            cap: MAX_TRIANGLES,
        });
    }
    for p in pts.chunks_exact(3) {
        let w = world_from_node.transform_point(&nalgebra::Point3::new(p[0], p[1], p[2]));
        mesh.vertices.push([w.x, w.y, w.z]);
    }
    let ccw = g.flag("ccw", true);
    let idx = match g.field("coordIndex") {
        Some(Value::Atoms(a)) => a.clone(),
        _ => Vec::new(),
    };
    let mut poly: Vec<u32> = Vec::new();
    let flush = |poly: &mut Vec<u32>, mesh: &mut RawMesh| -> Result<(), Defect> {
        if poly.len() >= 3 {
            for k in 1..poly.len() - 1 {
                let t = [poly[0], poly[k], poly[k + 1]];
                mesh.triangles.push(if ccw { t } else { [t[0], t[2], t[1]] });
            }
            if mesh.triangles.len() > MAX_TRIANGLES {
                return Err(Defect::TooManyTriangles {
                    found: mesh.triangles.len() as u64,
                    cap: MAX_TRIANGLES,
                });
            }
        }
        poly.clear();
        Ok(())
    };
    for (l, t) in &idx {
        let k: i64 = t.parse().map_err(|_| Defect::Malformed {
            at: format!("line {l}"),
            what: format!("expected a coordIndex, got {t:?}"),
        })?;
        if k == -1 {
            flush(&mut poly, mesh)?;
        } else if k < 0 || k as usize >= n_pts {
            return Err(Defect::IndexOutOfRange {
                at: format!("line {l}"),
                index: k,
                vertices: n_pts,
            });
        } else {
            poly.push((base + k as usize) as u32);
        }
    }
    flush(&mut poly, mesh)
}

#[cfg(test)]
mod tests {
    use super::*;

    const TWO_SHAPES: &str = "#VRML V2.0 utf8\n# two shapes, one moved\n\
        Shape { appearance Appearance { material DEF M1 Material { diffuseColor 0.1 0.1 0.1 } }\n\
          geometry IndexedFaceSet { creaseAngle 0.5 coordIndex [0,1,2,-1,0,2,3,-1]\n\
            coord DEF C1 Coordinate { point [0 0 0, 1 0 0, 1 1 0, 0 1 0] } } }\n\
        Transform { translation 0 0 2 scale 2 2 2 rotation 0 0 1 1.5707963267948966 children [\n\
          Shape { appearance Appearance { material USE M1 }\n\
            geometry IndexedFaceSet { ccw FALSE coordIndex [0 1 2 -1] coord USE C1 } } ] }\n";

    #[test]
    fn shapes_transforms_and_def_use_are_read() {
        let m = parse(TWO_SHAPES).unwrap();
        assert_eq!(m.vertices.len(), 8);
        assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3], [4, 6, 5]]);
        // (1, 0, 0) scaled by 2, turned 90 degrees about z, lifted by 2: (0, 2, 2).
        let v = m.vertices[5];
        assert!((v[0] - 0.0).abs() < 1e-12 && (v[1] - 2.0).abs() < 1e-12 && (v[2] - 2.0).abs() < 1e-12);
    }

    #[test]
    fn truncated_and_bad_vrml_is_named() {
        let cut = &TWO_SHAPES[..TWO_SHAPES.len() - 40];
        assert!(matches!(parse(cut), Err(Defect::Truncated(_))), "{:?}", parse(cut));
        assert!(matches!(parse("#VRML V1.0 ascii\n"), Err(Defect::Unsupported(_))));
        let nan = TWO_SHAPES.replace("1 1 0, 0 1 0", "1 nan 0, 0 1 0");
        assert!(matches!(parse(&nan), Err(Defect::NonFinite { .. })));
        let boxed = "#VRML V2.0 utf8\nShape { geometry Box { size 1 1 1 } }\n";
        assert!(matches!(parse(boxed), Err(Defect::Unsupported(_))));
        let deep = format!("#VRML V2.0 utf8\n{}", "Group { children [ ".repeat(100));
        assert!(parse(&deep).is_err());
    }
}
