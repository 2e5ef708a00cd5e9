//! Gmsh `.msh`, formats 2.2 and 4.1 (ASCII): reading and writing.

use super::tokens::Tokens;
use super::{MeshError, TetMesh, finish};
use std::collections::HashMap;

impl TetMesh {
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
}
