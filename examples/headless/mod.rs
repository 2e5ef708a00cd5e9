//! What the headless study examples (`work_precision`, `stability`, `scaling`, `auto`) share:
//! their command line, the chart palette and the finite-element bodies they measure. Not an
//! example itself.

#![allow(dead_code)]

use bevy_soft_body::core::build;
use bevy_soft_body::core::fem::NeoHookean;
use bevy_soft_body::core::fem::mesh::TetMesh;
use bevy_soft_body::core::ode::ParticleState;
use bevy_soft_body::core::particles::ParticleModel;
use plotters::coord::Shift;
use plotters::prelude::{BitMapBackend, DrawingArea, DrawingBackend, IntoDrawingArea, SVGBackend};
use plotters::style::RGBColor;
use std::path::{Path, PathBuf};

/// One colour per integrator, in `IntegratorKind::ALL` order (colour-blind-safe set).
pub const PALETTE: [RGBColor; 11] = [
    RGBColor(228, 26, 28),
    RGBColor(55, 126, 184),
    RGBColor(77, 175, 74),
    RGBColor(152, 78, 163),
    RGBColor(255, 127, 0),
    RGBColor(166, 86, 40),
    RGBColor(247, 129, 191),
    RGBColor(80, 80, 80),
    RGBColor(23, 190, 207),
    RGBColor(188, 189, 34),
    RGBColor(0, 0, 140),
];

/// A chart that draws on any plotters backend (PNG and SVG from the same code).
pub trait Chart {
    /// Draws the chart on `root`.
    fn draw<DB: DrawingBackend>(
        &self,
        root: DrawingArea<DB, Shift>,
    ) -> Result<(), Box<dyn std::error::Error>>
    where
        DB::ErrorType: 'static;
}

/// Writes `chart` as `DIR/STEM.png` and `DIR/STEM.svg` of `size` pixels; a failure is printed
/// and the study goes on.
pub fn save(dir: &Path, stem: &str, size: (u32, u32), chart: &impl Chart) {
    for ext in ["png", "svg"] {
        let path = dir.join(format!("{stem}.{ext}"));
        let res = if ext == "svg" {
            chart.draw(SVGBackend::new(&path, size).into_drawing_area())
        } else {
            chart.draw(BitMapBackend::new(&path, size).into_drawing_area())
        };
        if let Err(e) = res {
            eprintln!("chart {}: {e}", path.display());
        }
    }
}

/// A file of the repository (or beside it, `../shared/…`), from the crate's root or the
/// working directory: its path and text.
pub fn read(rel: &str) -> Option<(String, String)> {
    [env!("CARGO_MANIFEST_DIR"), "."].iter().find_map(|root| {
        let path = format!("{root}/{rel}");
        std::fs::read_to_string(&path).ok().map(|t| (path, t))
    })
}

/// A shipped coarse tet mesh (`bunny`, `armadillo`) of Young's modulus `young` (Pa), Poisson
/// ratio `poisson` and 1000 kg/m³, hung by its top 5 % and kicked sideways at 2 m/s per metre
/// of height ([`build::hung_tet_body`]). The examples' materials: `fem_bunny`'s soft rubber
/// is 0.2 MPa, ν = 0.4; `fem_armadillo`'s stiff one 1 MPa, ν = 0.45.
pub fn tet_body(name: &str, young: f64, poisson: f64) -> Option<(ParticleModel, ParticleState)> {
    let (path, text) = read(&format!("assets/meshes/{name}_coarse.mesh"))?;
    let mesh = TetMesh::from_medit(&path, &text).ok()?;
    let mat = NeoHookean {
        young,
        poisson,
        density: 1000.0,
    };
    build::hung_tet_body(&mesh, mat, 2.0).build().ok()
}

/// `[--quick] [--out DIR] [--sizes A,B,C] [--only NAME,NAME]`.
pub struct Args {
    /// The short sweep.
    pub quick: bool,
    /// Output directory (created).
    pub out: PathBuf,
    /// Sizes, when given.
    pub sizes: Option<Vec<usize>>,
    /// Only the problems or scenes of these names, when given.
    pub only: Option<Vec<String>>,
}

impl Args {
    /// True when `name` is to be run (no `--only`, or named in it).
    pub fn wants(&self, name: &str) -> bool {
        self.only
            .as_ref()
            .is_none_or(|o| o.iter().any(|n| n == name))
    }
}

/// Parses the arguments (exits with the usage on an unknown one) and creates the output
/// directory.
pub fn args(name: &str) -> Args {
    let mut a = Args {
        quick: false,
        out: PathBuf::from(format!("target/{name}")),
        sizes: None,
        only: None,
    };
    let mut it = std::env::args().skip(1);
    while let Some(arg) = it.next() {
        match arg.as_str() {
            "--quick" => a.quick = true,
            "--out" => a.out = it.next().map(PathBuf::from).unwrap_or(a.out),
            "--sizes" => {
                a.sizes = Some(
                    it.next()
                        .unwrap_or_default()
                        .split(',')
                        .filter_map(|s| s.parse().ok())
                        .collect(),
                )
            }
            "--only" => {
                a.only = Some(
                    it.next()
                        .unwrap_or_default()
                        .split(',')
                        .map(String::from)
                        .collect(),
                )
            }
            other => {
                eprintln!(
                    "unknown option '{other}'\nusage: {name} [--quick] [--out DIR] [--sizes 32,64,128] [--only a,b]"
                );
                std::process::exit(1);
            }
        }
    }
    std::fs::create_dir_all(&a.out).expect("output directory");
    a
}
