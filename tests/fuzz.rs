//! Mutation fuzzing on stable Rust: the scene JSON reader and every tet-mesh reader get
//! thousands of damaged versions of valid files (bytes flipped, ranges deleted or repeated,
//! numbers replaced by NaN, inf, huge, negative or zero values, truncation) and must answer
//! each with `Ok` or an error naming file and line — never a panic — and whatever they accept
//! must be usable (indices in range, every tet positively oriented, scenes that build or
//! report). The same inputs drive the cargo-fuzz targets in `fuzz/` (nightly, not in CI):
//! `cargo +nightly fuzz run medit -- -max_total_time=300`.

use bevy_soft_body::core::build;
use bevy_soft_body::core::fem::NeoHookean;
use bevy_soft_body::core::fem::element::signed_volume;
use bevy_soft_body::core::fem::mesh::TetMesh;
use bevy_soft_body::core::scene::Scene;
use glam::DVec3;

mod common;

/// The shared generator, with this file's way of drawing an index.
struct Rng(common::Rng);
impl Rng {
    fn below(&mut self, n: usize) -> usize {
        self.0.below_raw(n)
    }
}

const NASTY: [&str; 12] = [
    "NaN",
    "inf",
    "-inf",
    "1e308",
    "-1e308",
    "0",
    "-1",
    "99999999999",
    "4294967296",
    "1e-320",
    "",
    "x",
];

/// One random damage to `text`.
fn mutate(text: &str, r: &mut Rng) -> String {
    let mut b = text.as_bytes().to_vec();
    let n = b.len().max(1);
    match r.below(6) {
        0 => {
            let i = r.below(n);
            if i < b.len() {
                b[i] ^= 1 << r.below(7);
            }
        }
        1 => {
            let i = r.below(n);
            let j = (i + r.below(64)).min(b.len());
            b.drain(i.min(b.len())..j);
        }
        2 => {
            let i = r.below(n).min(b.len());
            let j = (i + r.below(64)).min(b.len());
            let chunk = b[i..j].to_vec();
            b.splice(i..i, chunk);
        }
        3 => b.truncate(r.below(n)),
        _ => {
            // Replace a whitespace-separated token by a nasty number.
            let s = String::from_utf8_lossy(&b).into_owned();
            let toks: Vec<(usize, usize)> = s
                .match_indices(|c: char| !c.is_whitespace())
                .map(|(i, _)| i)
                .fold(Vec::new(), |mut acc: Vec<(usize, usize)>, i| {
                    match acc.last_mut() {
                        Some(l) if l.1 == i => l.1 = i + 1,
                        _ => acc.push((i, i + 1)),
                    }
                    acc
                });
            if let Some(&(a, e)) = toks.get(r.below(toks.len())) {
                let nasty = NASTY[r.below(NASTY.len())];
                return format!("{}{}{}", &s[..a], nasty, &s[e..]);
            }
            return s;
        }
    }
    String::from_utf8_lossy(&b).into_owned()
}

/// What every accepted mesh must satisfy.
fn check_mesh(m: &TetMesh) {
    assert!(!m.tets.is_empty());
    for t in &m.tets {
        assert!(t.iter().all(|&i| (i as usize) < m.vertices.len()));
        let x = t.map(|i| DVec3::from_array(m.vertices[i as usize]));
        assert!(signed_volume(x) > 0.0);
    }
    assert!(m.vertices.iter().flatten().all(|c| c.is_finite()));
    // The boundary and a scene from it work too.
    let _ = m.boundary();
    let _ = m.to_scene("fuzz", NeoHookean::default()).build();
}

fn run(name: &str, seeds: &[String], cases: usize, f: &dyn Fn(&str) -> bool) {
    let mut r = Rng(common::Rng(0x5eed ^ name.len() as u64));
    let (mut panics, mut accepted) = (0, 0);
    for k in 0..cases {
        let mut text = seeds[k % seeds.len()].clone();
        for _ in 0..1 + r.below(3) {
            text = mutate(&text, &mut r);
        }
        match std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| f(&text))) {
            Ok(ok) => accepted += ok as usize,
            Err(_) => {
                panics += 1;
                eprintln!("{name}: panic on input:\n{text}\n---");
            }
        }
    }
    println!("{name}: {cases} damaged inputs, {accepted} accepted, {panics} panics");
    assert_eq!(panics, 0);
    // Some damage is harmless (a changed digit): the readers must not refuse everything.
    assert!(accepted > 0 && accepted < cases);
}

fn small_mesh() -> TetMesh {
    TetMesh::tet_box([1.0, 0.5, 0.5], [2, 1, 1]).unwrap()
}

#[test]
fn mesh_readers_survive_damaged_files() {
    let m = small_mesh();
    run(
        "medit",
        &[m.to_medit()],
        20_000,
        &|t| match TetMesh::from_medit("f.mesh", t) {
            Ok(mesh) => {
                check_mesh(&mesh);
                true
            }
            Err(e) => {
                assert!(!e.file.is_empty() && !e.message.is_empty());
                false
            }
        },
    );
    run(
        "gmsh",
        &[m.to_gmsh(2), m.to_gmsh(4)],
        20_000,
        &|t| match TetMesh::from_gmsh("f.msh", t) {
            Ok(mesh) => {
                check_mesh(&mesh);
                true
            }
            Err(e) => {
                assert!(!e.file.is_empty() && !e.message.is_empty());
                false
            }
        },
    );
    let (node, ele) = m.to_tetgen();
    // One input holds both files, split at a line `===`.
    run("tetgen", &[format!("{node}===\n{ele}")], 20_000, &|t| {
        let (a, b) = t.split_once("===\n").unwrap_or((t, ""));
        match TetMesh::from_tetgen("f.node", a, "f.ele", b) {
            Ok(mesh) => {
                check_mesh(&mesh);
                true
            }
            Err(e) => {
                assert!(!e.file.is_empty() && !e.message.is_empty());
                false
            }
        }
    });
}

#[test]
fn scene_reader_survives_damaged_json() {
    let seeds = vec![
        build::pendulum(1.0, 1.0, 100.0, 0.5).to_json(),
        build::chain(&build::ChainParams::default())
            .unwrap()
            .to_json(),
        small_mesh()
            .to_scene("box", NeoHookean::default())
            .to_json(),
    ];
    run("scene", &seeds, 20_000, &|t| {
        match Scene::from_json(t) {
            // Accepted scenes build, or report why not.
            Ok(s) => {
                let _ = s.build();
                true
            }
            Err(_) => false,
        }
    });
}

/// The cargo-fuzz seed corpus in `fuzz/corpus/` is what the writers produce today (so the
/// nightly fuzzers start from valid files of the current formats). `WRITE_FUZZ_CORPUS=1 cargo
/// test --test fuzz` rewrites it.
#[test]
fn fuzz_corpus_is_current() {
    let m = small_mesh();
    let (node, ele) = m.to_tetgen();
    let seeds = [
        ("medit", "box.mesh", m.to_medit()),
        ("gmsh", "box_v2.msh", m.to_gmsh(2)),
        ("gmsh", "box_v4.msh", m.to_gmsh(4)),
        ("tetgen", "box.node_ele", format!("{node}===\n{ele}")),
        (
            "scene_json",
            "pendulum.json",
            build::pendulum(1.0, 1.0, 100.0, 0.5).to_json(),
        ),
        (
            "scene_json",
            "box.json",
            m.to_scene("box", NeoHookean::default()).to_json(),
        ),
    ];
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/corpus");
    let write = std::env::var("WRITE_FUZZ_CORPUS").is_ok();
    for (target, name, text) in seeds {
        let path = dir.join(target).join(name);
        if write {
            std::fs::create_dir_all(path.parent().unwrap()).unwrap();
            std::fs::write(&path, &text).unwrap();
        }
        let stored = std::fs::read_to_string(&path).unwrap_or_default();
        assert_eq!(
            stored,
            text,
            "{} is stale: run WRITE_FUZZ_CORPUS=1 cargo test --test fuzz",
            path.display()
        );
    }
}
