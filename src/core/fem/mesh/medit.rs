//! Medit `.mesh` (ASCII): reading and writing.

use super::tokens::Tokens;
use super::{MeshError, TetMesh, finish};

impl TetMesh {
    /// Reads a Medit `.mesh` (ASCII): `Vertices` (x y z ref), `Tetrahedra` (four 1-based
    /// indices and a ref); other sections are skipped.
    pub fn from_medit(file: &str, text: &str) -> Result<Self, MeshError> {
        let mut t = Tokens::new(file, text, true);
        let mut vertices = Vec::new();
        let mut tets = Vec::new();
        let mut dim = 3;
        while let Some(word) = t.peek() {
            let (line, _) = t.next(word)?;
            match word {
                "MeshVersionFormatted" => {
                    t.int("MeshVersionFormatted")?;
                }
                "Dimension" => dim = t.int("Dimension")?,
                "Vertices" => {
                    if dim != 3 {
                        return Err(t.err(line, format!("Dimension {dim}: only 3 is supported")));
                    }
                    let n = t.count("vertex count")?;
                    vertices.reserve(n);
                    for _ in 0..n {
                        vertices.push(t.point("vertex coordinate")?);
                        t.int("vertex reference")?;
                    }
                }
                "Tetrahedra" => {
                    let n = t.count("tetrahedron count")?;
                    tets.reserve(n);
                    for _ in 0..n {
                        let l = t.line();
                        let mut v = [0i64; 4];
                        for i in &mut v {
                            *i = t.int("tetrahedron vertex")?;
                        }
                        t.int("tetrahedron reference")?;
                        tets.push((v, l));
                    }
                }
                "Triangles" | "Edges" | "Corners" | "Ridges" | "RequiredVertices"
                | "Quadrilaterals" | "Hexahedra" | "Normals" | "Tangents" => {
                    let per = match word {
                        "Triangles" => 4,
                        "Edges" => 3,
                        "Quadrilaterals" => 5,
                        "Hexahedra" => 9,
                        "Normals" | "Tangents" => 3,
                        _ => 1,
                    };
                    let n = t.count(word)?;
                    for _ in 0..n * per {
                        t.next(word)?;
                    }
                }
                "End" => break,
                other => {
                    return Err(t.err(line, format!("unknown section `{other}`")));
                }
            }
        }
        if vertices.is_empty() {
            return Err(t.err(0, "no `Vertices` section"));
        }
        finish(file, vertices, tets, 1)
    }

    /// Writes Medit `.mesh` text (round trips through [`TetMesh::from_medit`]).
    pub fn to_medit(&self) -> String {
        let mut s = String::from("MeshVersionFormatted 1\nDimension 3\nVertices\n");
        s += &format!("{}\n", self.vertices.len());
        for v in &self.vertices {
            s += &format!("{} {} {} 0\n", v[0], v[1], v[2]);
        }
        s += &format!("Tetrahedra\n{}\n", self.tets.len());
        for t in &self.tets {
            s += &format!("{} {} {} {} 0\n", t[0] + 1, t[1] + 1, t[2] + 1, t[3] + 1);
        }
        s + "End\n"
    }
}
