//! Tet meshes: Gmsh `.msh` (v2 ASCII and v4 ASCII), Medit `.mesh` and TetGen `.node`/`.ele`
//! readers, boundary extraction with outward orientation, procedural boxes and beams, and the
//! conversion to a [`Scene`] (lumped masses from the density).
//!
//! Readers never panic: a malformed file (truncated, wrong counts, indices out of range,
//! non-finite or huge coordinates, flat or inverted tets) gives a [`MeshError`] naming the file
//! and line.

use super::NeoHookean;
use super::element::signed_volume;
use crate::core::scene::{ParticleDesc, Scene, Surface, TetDesc};
use glam::DVec3;
use std::collections::HashMap;
use std::fmt;

/// Coordinates above this magnitude (m) are refused: squared and cubed in volumes and
/// energies, they would overflow or swamp every other digit.
pub const MAX_COORDINATE: f64 = 1e6;

/// Vertex or tet counts above this are refused before anything is allocated (a header that
/// claims 10⁹ tets must not exhaust memory).
pub const MAX_COUNT: usize = 10_000_000;

/// A tetrahedral mesh: vertices, positively oriented tets, and the boundary surface.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TetMesh {
    /// Vertex positions (m).
    pub vertices: Vec<[f64; 3]>,
    /// Tets as four vertex indices, each with positive volume
    /// (`dot(b − a, (c − a) × (d − a)) > 0`).
    pub tets: Vec<[u32; 4]>,
}

/// What is wrong with a mesh file, and where.
#[derive(Clone, Debug, PartialEq)]
pub struct MeshError {
    /// The file (or a name given by the caller).
    pub file: String,
    /// 1-based line (0 when the problem is not on one line).
    pub line: usize,
    /// What is wrong.
    pub message: String,
}

impl fmt::Display for MeshError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.line > 0 {
            write!(f, "{}:{}: {}", self.file, self.line, self.message)
        } else {
            write!(f, "{}: {}", self.file, self.message)
        }
    }
}

impl std::error::Error for MeshError {}

/// Whitespace-separated tokens with their line numbers; `#` starts a comment to the end of
/// the line (TetGen, Medit).
struct Tokens<'a> {
    file: &'a str,
    toks: Vec<(usize, &'a str)>,
    pos: usize,
    last_line: usize,
}

impl<'a> Tokens<'a> {
    fn new(file: &'a str, text: &'a str, comments: bool) -> Self {
        let mut toks = Vec::new();
        for (n, line) in text.lines().enumerate() {
            let line = if comments {
                line.split('#').next().unwrap_or("")
            } else {
                line
            };
            toks.extend(line.split_whitespace().map(|t| (n + 1, t)));
        }
        let last_line = text.lines().count().max(1);
        Self {
            file,
            toks,
            pos: 0,
            last_line,
        }
    }

    fn err(&self, line: usize, message: impl Into<String>) -> MeshError {
        MeshError {
            file: self.file.to_string(),
            line,
            message: message.into(),
        }
    }

    fn line(&self) -> usize {
        self.toks.get(self.pos).map_or(self.last_line, |t| t.0)
    }

    fn next(&mut self, what: &str) -> Result<(usize, &'a str), MeshError> {
        match self.toks.get(self.pos) {
            Some(&t) => {
                self.pos += 1;
                Ok(t)
            }
            None => Err(self.err(
                self.last_line,
                format!("file ends where {what} was expected (truncated?)"),
            )),
        }
    }

    fn peek(&self) -> Option<&'a str> {
        self.toks.get(self.pos).map(|t| t.1)
    }

    fn int(&mut self, what: &str) -> Result<i64, MeshError> {
        let (line, t) = self.next(what)?;
        t.parse::<i64>()
            .map_err(|_| self.err(line, format!("{what}: `{t}` is not an integer")))
    }

    fn count(&mut self, what: &str) -> Result<usize, MeshError> {
        let line = self.line();
        let n = self.int(what)?;
        if n < 0 || n as u64 > MAX_COUNT as u64 {
            return Err(self.err(
                line,
                format!("{what}: {n} is not a count between 0 and {MAX_COUNT}"),
            ));
        }
        Ok(n as usize)
    }

    fn real(&mut self, what: &str) -> Result<f64, MeshError> {
        let (line, t) = self.next(what)?;
        let v = t
            .parse::<f64>()
            .map_err(|_| self.err(line, format!("{what}: `{t}` is not a number")))?;
        if !v.is_finite() || v.abs() > MAX_COORDINATE {
            return Err(self.err(
                line,
                format!("{what}: `{t}` is not finite or exceeds {MAX_COORDINATE:e} in magnitude"),
            ));
        }
        Ok(v)
    }

    fn point(&mut self, what: &str) -> Result<[f64; 3], MeshError> {
        Ok([self.real(what)?, self.real(what)?, self.real(what)?])
    }

    fn expect(&mut self, word: &str) -> Result<(), MeshError> {
        let (line, t) = self.next(word)?;
        if t != word {
            return Err(self.err(line, format!("expected `{word}`, found `{t}`")));
        }
        Ok(())
    }

    /// Skips tokens up to the end of the current line.
    fn skip_line(&mut self, line: usize) {
        while self.toks.get(self.pos).is_some_and(|t| t.0 == line) {
            self.pos += 1;
        }
    }
}

/// Checks index ranges, orientation and volume; flips every tet of a file whose tets are all
/// negatively oriented (a whole-file convention); rejects flat tets and mixed orientation.
fn finish(
    file: &str,
    vertices: Vec<[f64; 3]>,
    tets: Vec<([i64; 4], usize)>,
    base: i64,
) -> Result<TetMesh, MeshError> {
    let err = |line: usize, message: String| MeshError {
        file: file.to_string(),
        line,
        message,
    };
    if tets.is_empty() {
        return Err(err(0, "the mesh has no tetrahedra".into()));
    }
    let n = vertices.len() as i64;
    let mut out = Vec::with_capacity(tets.len());
    let mut vols = Vec::with_capacity(tets.len());
    for (k, (t, line)) in tets.iter().enumerate() {
        let mut v = [0u32; 4];
        for (o, &i) in v.iter_mut().zip(t) {
            let i0 = i - base;
            if i0 < 0 || i0 >= n {
                return Err(err(
                    *line,
                    format!(
                        "tet {k}: vertex index {i} is out of range ({} vertices, first index {base})",
                        vertices.len()
                    ),
                ));
            }
            *o = i0 as u32;
        }
        for a in 0..4 {
            for b in a + 1..4 {
                if v[a] == v[b] {
                    return Err(err(*line, format!("tet {k}: vertex {} repeats", t[a])));
                }
            }
        }
        let x = v.map(|i| DVec3::from_array(vertices[i as usize]));
        vols.push(signed_volume(x));
        out.push(v);
    }
    let negative = vols.iter().filter(|v| **v < 0.0).count();
    let flip = negative == vols.len();
    for (k, vol) in vols.iter().enumerate() {
        let vol = if flip { -vol } else { *vol };
        let x = out[k].map(|i| DVec3::from_array(vertices[i as usize]));
        let scale = (x[1] - x[0])
            .length()
            .max((x[2] - x[0]).length())
            .max((x[3] - x[0]).length());
        if vol.is_nan() || vol <= 1e-12 * scale.powi(3) {
            return Err(err(
                tets[k].1,
                format!(
                    "tet {k}: rest volume {vol:e} is not positive ({} of {} tets are negatively oriented)",
                    negative,
                    vols.len()
                ),
            ));
        }
    }
    if flip {
        for t in &mut out {
            t.swap(2, 3);
        }
    }
    Ok(TetMesh {
        vertices,
        tets: out,
    })
}

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

    /// Reads TetGen's `.node` and `.ele` pair. Indices start at the first node's number (0 or
    /// 1); attributes and boundary markers are skipped; second-order (10-node) tets use their
    /// four corners.
    pub fn from_tetgen(
        node_file: &str,
        node_text: &str,
        ele_file: &str,
        ele_text: &str,
    ) -> Result<Self, MeshError> {
        let mut t = Tokens::new(node_file, node_text, true);
        let hl = t.line();
        let n = t.count("node count")?;
        let dim = t.int("dimension")?;
        if dim != 3 {
            return Err(t.err(hl, format!("dimension {dim}: only 3 is supported")));
        }
        let attrs = t.count("attribute count")?;
        let markers = t.count("boundary marker flag")?;
        if markers > 1 || attrs > 1000 {
            return Err(t.err(hl, "bad header: attributes or boundary marker flag"));
        }
        let mut vertices = Vec::with_capacity(n);
        let mut base = 0;
        let mut ids = Vec::with_capacity(n);
        for k in 0..n {
            let l = t.line();
            let id = t.int("node number")?;
            if k == 0 {
                base = id;
            } else if id != base + k as i64 {
                return Err(t.err(
                    l,
                    format!(
                        "node number {id}: expected {} (nodes in order)",
                        base + k as i64
                    ),
                ));
            }
            ids.push(id);
            vertices.push(t.point("node coordinate")?);
            for _ in 0..attrs + markers {
                t.next("node attribute")?;
            }
        }
        let mut e = Tokens::new(ele_file, ele_text, true);
        let hl = e.line();
        let m = e.count("tetrahedron count")?;
        let per = e.count("nodes per tetrahedron")?;
        if per != 4 && per != 10 {
            return Err(e.err(hl, format!("{per} nodes per tetrahedron: only 4 or 10")));
        }
        let attrs = e.count("region attribute flag")?;
        if attrs > 1000 {
            return Err(e.err(hl, "bad header: attribute count"));
        }
        let mut tets = Vec::with_capacity(m);
        for _ in 0..m {
            let l = e.line();
            e.int("tetrahedron number")?;
            let mut v = [0i64; 4];
            for i in &mut v {
                *i = e.int("tetrahedron vertex")?;
            }
            for _ in 4..per {
                e.int("tetrahedron vertex")?;
            }
            for _ in 0..attrs {
                e.next("tetrahedron attribute")?;
            }
            tets.push((v, l));
        }
        finish(ele_file, vertices, tets, base).map_err(|mut err| {
            if err.line == 0 {
                err.file = format!("{node_file} + {ele_file}");
            }
            err
        })
    }

    /// Reads a Gmsh `.msh` file, format 2 (2.2) or 4 (4.1), ASCII. Only 4-node tetrahedra
    /// (element type 4) are kept; other elements are skipped. Node tags may be any positive
    /// integers.
    pub fn from_gmsh(file: &str, text: &str) -> Result<Self, MeshError> {
        let mut t = Tokens::new(file, text, false);
        let mut version = None;
        let mut nodes: Vec<[f64; 3]> = Vec::new();
        let mut tag_index: HashMap<i64, usize> = HashMap::new();
        let mut tets: Vec<([i64; 4], usize)> = Vec::new();
        while let Some(word) = t.peek() {
            let (line, _) = t.next(word)?;
            match word {
                "$MeshFormat" => {
                    let (vl, v) = t.next("format version")?;
                    let v: f64 = v
                        .parse()
                        .map_err(|_| t.err(vl, format!("format version `{v}` is not a number")))?;
                    let binary = t.int("file type")?;
                    t.int("data size")?;
                    if binary != 0 {
                        return Err(t.err(vl, "binary .msh files are not supported; save as ASCII"));
                    }
                    if !(2.0..3.0).contains(&v) && !(4.0..5.0).contains(&v) {
                        return Err(
                            t.err(vl, format!("format {v}: only 2.x and 4.x are supported"))
                        );
                    }
                    version = Some(v.floor() as u32);
                    t.expect("$EndMeshFormat")?;
                }
                "$Nodes" => {
                    let Some(ver) = version else {
                        return Err(t.err(line, "$Nodes before $MeshFormat"));
                    };
                    if ver == 2 {
                        let n = t.count("node count")?;
                        nodes.reserve(n);
                        for _ in 0..n {
                            let l = t.line();
                            let tag = t.int("node tag")?;
                            if tag_index.insert(tag, nodes.len()).is_some() {
                                return Err(t.err(l, format!("node tag {tag} repeats")));
                            }
                            nodes.push(t.point("node coordinate")?);
                        }
                    } else {
                        let blocks = t.count("entity block count")?;
                        let n = t.count("node count")?;
                        t.int("minimum node tag")?;
                        t.int("maximum node tag")?;
                        nodes.reserve(n);
                        for _ in 0..blocks {
                            t.int("entity dimension")?;
                            t.int("entity tag")?;
                            let parametric = t.int("parametric flag")?;
                            let bl = t.line();
                            let k = t.count("nodes in block")?;
                            if parametric != 0 {
                                return Err(t.err(bl, "parametric nodes are not supported"));
                            }
                            let mut tags = Vec::with_capacity(k);
                            for _ in 0..k {
                                tags.push((t.line(), t.int("node tag")?));
                            }
                            for (l, tag) in tags {
                                if tag_index.insert(tag, nodes.len()).is_some() {
                                    return Err(t.err(l, format!("node tag {tag} repeats")));
                                }
                                nodes.push(t.point("node coordinate")?);
                            }
                        }
                        if nodes.len() != n {
                            return Err(t.err(
                                line,
                                format!("header says {n} nodes, blocks hold {}", nodes.len()),
                            ));
                        }
                    }
                    t.expect("$EndNodes")?;
                }
                "$Elements" => {
                    let Some(ver) = version else {
                        return Err(t.err(line, "$Elements before $MeshFormat"));
                    };
                    let map = |t: &Tokens, l: usize, tag: i64| -> Result<i64, MeshError> {
                        tag_index.get(&tag).map(|i| *i as i64).ok_or_else(|| {
                            t.err(
                                l,
                                format!("element refers to node tag {tag}, which does not exist"),
                            )
                        })
                    };
                    if ver == 2 {
                        let n = t.count("element count")?;
                        for _ in 0..n {
                            let l = t.line();
                            t.int("element number")?;
                            let ty = t.int("element type")?;
                            let ntags = t.count("tag count")?;
                            for _ in 0..ntags {
                                t.int("element tag")?;
                            }
                            if ty == 4 {
                                let mut v = [0i64; 4];
                                for i in &mut v {
                                    let tag = t.int("tetrahedron node")?;
                                    *i = map(&t, l, tag)?;
                                }
                                tets.push((v, l));
                            } else {
                                t.skip_line(l);
                            }
                        }
                    } else {
                        let blocks = t.count("entity block count")?;
                        t.count("element count")?;
                        t.int("minimum element tag")?;
                        t.int("maximum element tag")?;
                        for _ in 0..blocks {
                            t.int("entity dimension")?;
                            t.int("entity tag")?;
                            let ty = t.int("element type")?;
                            let k = t.count("elements in block")?;
                            for _ in 0..k {
                                let l = t.line();
                                t.int("element tag")?;
                                if ty == 4 {
                                    let mut v = [0i64; 4];
                                    for i in &mut v {
                                        let tag = t.int("tetrahedron node")?;
                                        *i = map(&t, l, tag)?;
                                    }
                                    tets.push((v, l));
                                } else {
                                    t.skip_line(l);
                                }
                            }
                        }
                    }
                    t.expect("$EndElements")?;
                }
                w if w.starts_with('$') && !w.starts_with("$End") => {
                    // An optional section: skip to its end marker.
                    let end = format!("$End{}", &w[1..]);
                    loop {
                        let (_, x) = t.next(&end)?;
                        if x == end {
                            break;
                        }
                    }
                }
                other => return Err(t.err(line, format!("unexpected `{other}`"))),
            }
        }
        if version.is_none() {
            return Err(t.err(0, "no $MeshFormat section: not a Gmsh file"));
        }
        finish(file, nodes, tets, 0)
    }

    /// Reads a file by its extension: `.msh`, `.mesh`, or `.node`/`.ele` (either name; the
    /// other is found beside it).
    pub fn load(path: &std::path::Path) -> Result<Self, MeshError> {
        let name = path.display().to_string();
        let read = |p: &std::path::Path| {
            std::fs::read_to_string(p).map_err(|e| MeshError {
                file: p.display().to_string(),
                line: 0,
                message: e.to_string(),
            })
        };
        match path.extension().and_then(|e| e.to_str()) {
            Some("msh") => Self::from_gmsh(&name, &read(path)?),
            Some("mesh") => Self::from_medit(&name, &read(path)?),
            Some("node") | Some("ele") => {
                let node = path.with_extension("node");
                let ele = path.with_extension("ele");
                Self::from_tetgen(
                    &node.display().to_string(),
                    &read(&node)?,
                    &ele.display().to_string(),
                    &read(&ele)?,
                )
            }
            _ => Err(MeshError {
                file: name,
                line: 0,
                message: "unknown tet-mesh extension (expected .msh, .mesh, .node or .ele)".into(),
            }),
        }
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

    /// Writes Gmsh `.msh` text, format 2.2 (`version` 2) or 4.1 (any other), ASCII, node tags
    /// from 1 (round trips through [`TetMesh::from_gmsh`]).
    pub fn to_gmsh(&self, version: u32) -> String {
        let n = self.vertices.len();
        let m = self.tets.len();
        let mut s = String::new();
        if version == 2 {
            s += "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n";
            s += &format!("{n}\n");
            for (i, v) in self.vertices.iter().enumerate() {
                s += &format!("{} {} {} {}\n", i + 1, v[0], v[1], v[2]);
            }
            s += &format!("$EndNodes\n$Elements\n{m}\n");
            for (k, t) in self.tets.iter().enumerate() {
                s += &format!(
                    "{} 4 2 0 1 {} {} {} {}\n",
                    k + 1,
                    t[0] + 1,
                    t[1] + 1,
                    t[2] + 1,
                    t[3] + 1
                );
            }
        } else {
            s += "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Nodes\n";
            s += &format!("1 {n} 1 {n}\n3 1 0 {n}\n");
            for i in 0..n {
                s += &format!("{}\n", i + 1);
            }
            for v in &self.vertices {
                s += &format!("{} {} {}\n", v[0], v[1], v[2]);
            }
            s += &format!("$EndNodes\n$Elements\n1 {m} 1 {m}\n3 1 4 {m}\n");
            for (k, t) in self.tets.iter().enumerate() {
                s += &format!(
                    "{} {} {} {} {}\n",
                    k + 1,
                    t[0] + 1,
                    t[1] + 1,
                    t[2] + 1,
                    t[3] + 1
                );
            }
        }
        s + "$EndElements\n"
    }

    /// Writes TetGen `.node` and `.ele` text, indices from 1 (round trips through
    /// [`TetMesh::from_tetgen`]).
    pub fn to_tetgen(&self) -> (String, String) {
        let mut node = format!("{} 3 0 0\n", self.vertices.len());
        for (i, v) in self.vertices.iter().enumerate() {
            node += &format!("{} {} {} {}\n", i + 1, v[0], v[1], v[2]);
        }
        let mut ele = format!("{} 4 0\n", self.tets.len());
        for (k, t) in self.tets.iter().enumerate() {
            ele += &format!(
                "{} {} {} {} {}\n",
                k + 1,
                t[0] + 1,
                t[1] + 1,
                t[2] + 1,
                t[3] + 1
            );
        }
        (node, ele)
    }

    /// Faces that belong to exactly one tet, wound counter-clockwise seen from outside.
    pub fn boundary(&self) -> Vec<[u32; 3]> {
        let mut faces: HashMap<[u32; 3], ([u32; 3], u32)> = HashMap::new();
        for t in &self.tets {
            let [a, b, c, d] = *t;
            for f in [[a, c, b], [a, b, d], [a, d, c], [b, c, d]] {
                let mut key = f;
                key.sort_unstable();
                faces.entry(key).or_insert((f, 0)).1 += 1;
            }
        }
        let mut out: Vec<[u32; 3]> = faces
            .into_values()
            .filter(|(_, n)| *n == 1)
            .map(|(f, _)| f)
            .collect();
        out.sort_unstable();
        out
    }

    /// Total volume (m³).
    pub fn volume(&self) -> f64 {
        self.tets
            .iter()
            .map(|t| signed_volume(t.map(|i| DVec3::from_array(self.vertices[i as usize]))))
            .sum()
    }

    /// Axis-aligned bounds `(min, max)`.
    pub fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for v in &self.vertices {
            for c in 0..3 {
                lo[c] = lo[c].min(v[c]);
                hi[c] = hi[c].max(v[c]);
            }
        }
        (lo, hi)
    }

    /// The mesh scaled by `s` and moved by `offset` (`x ↦ s x + offset`).
    pub fn transformed(mut self, s: f64, offset: [f64; 3]) -> Self {
        for v in &mut self.vertices {
            for c in 0..3 {
                v[c] = v[c] * s + offset[c];
            }
        }
        self
    }

    /// A box `[0, size]` of `cells` cubes per axis, each split into six tets around its main
    /// diagonal (Kuhn/Freudenthal: conforming across cubes). More vertices than
    /// [`MAX_PARTICLES`](crate::core::scene::MAX_PARTICLES), or a size that is not positive and
    /// finite, is refused before anything is allocated.
    pub fn tet_box(
        size: [f64; 3],
        cells: [usize; 3],
    ) -> Result<Self, crate::core::build::BuildError> {
        let [nx, ny, nz] = cells.map(|c| c.max(1));
        let limit = crate::core::scene::MAX_PARTICLES;
        let count = (nx as u128 + 1)
            .saturating_mul(ny as u128 + 1)
            .saturating_mul(nz as u128 + 1);
        if count > limit as u128 {
            return Err(crate::core::build::BuildError(format!(
                "tet box: {nx}×{ny}×{nz} cells need {count} vertices, more than the limit of {limit}"
            )));
        }
        if !size.iter().all(|s| s.is_finite() && *s > 0.0) {
            return Err(crate::core::build::BuildError(format!(
                "tet box: size {size:?} must be positive and finite"
            )));
        }
        let idx = |i: usize, j: usize, k: usize| ((i * (ny + 1) + j) * (nz + 1) + k) as u32;
        let mut vertices = Vec::with_capacity((nx + 1) * (ny + 1) * (nz + 1));
        for i in 0..=nx {
            for j in 0..=ny {
                for k in 0..=nz {
                    vertices.push([
                        size[0] * i as f64 / nx as f64,
                        size[1] * j as f64 / ny as f64,
                        size[2] * k as f64 / nz as f64,
                    ]);
                }
            }
        }
        let perms = [
            [0, 1, 2],
            [0, 2, 1],
            [1, 0, 2],
            [1, 2, 0],
            [2, 0, 1],
            [2, 1, 0],
        ];
        let mut tets = Vec::with_capacity(6 * nx * ny * nz);
        for i in 0..nx {
            for j in 0..ny {
                for k in 0..nz {
                    for p in perms {
                        let mut c = [i, j, k];
                        let mut t = [idx(c[0], c[1], c[2]); 4];
                        for (s, &axis) in p.iter().enumerate() {
                            c[axis] += 1;
                            t[s + 1] = idx(c[0], c[1], c[2]);
                        }
                        let x = t.map(|v| DVec3::from_array(vertices[v as usize]));
                        if signed_volume(x) < 0.0 {
                            t.swap(2, 3);
                        }
                        tets.push(t);
                    }
                }
            }
        }
        Ok(Self { vertices, tets })
    }

    /// A beam along x: length `length`, square section of side `side`, `n` cells along its
    /// length and `m` across each side, with its clamped end at x = 0 and its section centred
    /// on the x axis.
    pub fn beam(
        length: f64,
        side: f64,
        n: usize,
        m: usize,
    ) -> Result<Self, crate::core::build::BuildError> {
        Ok(Self::tet_box([length, side, side], [n, m, m])?
            .transformed(1.0, [0.0, -side / 2.0, -side / 2.0]))
    }

    /// The mesh as a scene of one elastic body: one particle per vertex with its lumped mass
    /// `Σ ρ V / 4`, the tets with the body's material, and the boundary as the surface.
    pub fn to_scene(&self, name: &str, material: NeoHookean) -> Scene {
        let mut mass = vec![0.0; self.vertices.len()];
        for t in &self.tets {
            let x = t.map(|i| DVec3::from_array(self.vertices[i as usize]));
            let m = super::element::lumped_mass(material.density, signed_volume(x));
            for &i in t {
                mass[i as usize] += m;
            }
        }
        Scene {
            name: name.into(),
            gravity: [0.0, -9.81, 0.0],
            particles: self
                .vertices
                .iter()
                .zip(&mass)
                .map(|(p, m)| ParticleDesc {
                    position: *p,
                    velocity: [0.0; 3],
                    mass: *m,
                    // A vertex no tet uses has no mass: hold it still.
                    pinned: *m == 0.0,
                })
                .collect(),
            tets: self
                .tets
                .iter()
                .map(|t| TetDesc {
                    vertices: t.map(|i| i as usize),
                    material: None,
                })
                .collect(),
            material: Some(material),
            surface: Some(Surface {
                triangles: self.boundary(),
                uvs: vec![],
            }),
            ..Default::default()
        }
    }
}
