//! TetGen `.node` / `.ele`: reading and writing.

use super::tokens::Tokens;
use super::{MeshError, TetMesh, finish};

impl TetMesh {
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
}
