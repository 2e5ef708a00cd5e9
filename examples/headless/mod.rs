//! What the headless study examples (`work_precision`, `stability`, `scaling`) share: their
//! command line and the chart palette. Not an example itself.

#![allow(dead_code)]

use plotters::style::RGBColor;
use std::path::PathBuf;

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

/// `[--quick] [--out DIR] [--sizes A,B,C]`.
pub struct Args {
    /// The short sweep.
    pub quick: bool,
    /// Output directory (created).
    pub out: PathBuf,
    /// Sizes, when given.
    pub sizes: Option<Vec<usize>>,
}

/// Parses the arguments (exits with the usage on an unknown one) and creates the output
/// directory.
pub fn args(name: &str) -> Args {
    let mut a = Args {
        quick: false,
        out: PathBuf::from(format!("target/{name}")),
        sizes: None,
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
            other => {
                eprintln!(
                    "unknown option '{other}'\nusage: {name} [--quick] [--out DIR] [--sizes 32,64,128]"
                );
                std::process::exit(1);
            }
        }
    }
    std::fs::create_dir_all(&a.out).expect("output directory");
    a
}
